// libFuzzer harness of the scene-file parser: the input is a scene file's text. Every input must end in
// a ResolvedRun or a spadgen::Error; any other exception, a crash, a sanitizer report or a resolved scene
// file that does not resolve to itself is a finding.
#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  const std::string path = spadgen::fuzz::scene_path();
  try {
    const spadgen::scenes::ResolvedRun r = spadgen::scenes::parse_scene_text(text, path);
    spadgen::fuzz::check_resolves_to_itself(r, path);
  } catch (const spadgen::Error& e) {
    spadgen::fuzz::refused(e);
  }
  return 0;
}
