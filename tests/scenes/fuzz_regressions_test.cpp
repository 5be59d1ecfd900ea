// The reproducers of the fuzzers' findings (fuzz/regressions/<harness>/), read as the harnesses read them,
// in the ordinary build: each must end in a result or a spadgen::Error naming the problem, never in another
// exception; a scene that resolves must resolve to itself. New findings only need their file added there.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "scenes/scene.h"
#include "scenes/scene_file.h"

namespace spadgen::scenes {
namespace {

namespace fs = std::filesystem;

const fs::path kSource = SPADGEN_SOURCE_DIR;

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::vector<fs::path> reproducers(const std::string& harness) {
  std::vector<fs::path> files;
  const fs::path dir = kSource / "fuzz/regressions" / harness;
  if (fs::exists(dir))
    for (const auto& e : fs::directory_iterator(dir))
      if (e.is_regular_file()) files.push_back(e.path());
  return files;
}

// "" when `f` returns or throws spadgen::Error; else what it threw.
template <class F>
std::string other_exception(F&& f) {
  try {
    f();
  } catch (const Error&) {
  } catch (const std::exception& e) {
    return e.what();
  } catch (...) {
    return "an exception of unknown type";
  }
  return "";
}

void expect_resolves_to_itself(const ResolvedRun& r, const std::string& path) {
  EXPECT_EQ(parse_scene_text(r.resolved.dump(), path).resolved, r.resolved);
}

TEST(FuzzRegressions, SetLinesEndInAResultOrAnError) {
  const std::string base = slurp(kSource / "scenes/paper/multi_object.json");
  const std::string path = (kSource / "scenes/paper/fuzz_input.json").string();
  const std::vector<fs::path> files = reproducers("set");
  EXPECT_FALSE(files.empty());
  for (const fs::path& f : files) {
    std::vector<std::string> lines;
    std::istringstream in(slurp(f));
    for (std::string line; std::getline(in, line);) lines.push_back(line);
    EXPECT_EQ(other_exception([&] { expect_resolves_to_itself(parse_scene_text(base, path, lines), path); }), "") << f;
  }
}

TEST(FuzzRegressions, SceneFilesEndInAResultOrAnError) {
  const std::string path = (kSource / "scenes/paper/fuzz_input.json").string();
  for (const fs::path& f : reproducers("scene_file"))
    EXPECT_EQ(other_exception([&] { expect_resolves_to_itself(parse_scene_text(slurp(f), path), path); }), "") << f;
}

TEST(FuzzRegressions, GltfFilesEndInASceneOrAnError) {
  for (const fs::path& f : reproducers("gltf"))
    EXPECT_EQ(other_exception([&] { parse_gltf(slurp(f), (fs::temp_directory_path() / "fuzz_input.gltf").string()); }), "") << f;
}

}  // namespace
}  // namespace spadgen::scenes
