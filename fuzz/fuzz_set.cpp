// libFuzzer harness of the `--set KEY=VALUE` overrides: each line of the input is one override, applied to
// the shipped scene multi_object.json (as `spadgen run scenes/paper/multi_object.json --set LINE ...`).
// Every input must end in a ResolvedRun or a spadgen::Error; the resolved scene file must resolve to itself.
#include <cstddef>
#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "fuzz_common.h"

namespace {

std::string g_scene_text;

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  std::ifstream in(std::string(SPADGEN_SOURCE_DIR) + "/scenes/paper/multi_object.json");
  std::ostringstream s;
  s << in.rdbuf();
  g_scene_text = s.str();
  if (g_scene_text.empty()) spadgen::fuzz::broken("cannot read scenes/paper/multi_object.json");
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<std::string> overrides;
  const std::string input(reinterpret_cast<const char*>(data), size);
  for (size_t start = 0; start <= input.size();) {
    size_t end = input.find('\n', start);
    if (end == std::string::npos) end = input.size();
    overrides.push_back(input.substr(start, end - start));
    start = end + 1;
  }
  const std::string path = spadgen::fuzz::scene_path();
  try {
    const spadgen::scenes::ResolvedRun r = spadgen::scenes::parse_scene_text(g_scene_text, path, overrides);
    spadgen::fuzz::check_resolves_to_itself(r, path);
  } catch (const spadgen::Error& e) {
    spadgen::fuzz::refused(e);
  }
  return 0;
}
