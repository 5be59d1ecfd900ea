// What the harnesses share: where the shipped scenes are, and the promises a parser keeps on success,
// checked on every input the fuzzer finds valid (a broken promise stops the harness like a crash).
#pragma once
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "core/error.h"
#include "scenes/scene_file.h"

namespace spadgen::fuzz {

// A scene file "in" scenes/paper/ (it need not exist): glTF names in the inputs resolve there.
inline std::string scene_path() { return std::string(SPADGEN_SOURCE_DIR) + "/scenes/paper/fuzz_input.json"; }

// With SPADGEN_FUZZ_VERBOSE=1 in the environment, each refused input's message is printed (to see what a
// seed or a reproducer exercises: `SPADGEN_FUZZ_VERBOSE=1 fuzz_gltf FILE...`).
inline void refused(const Error& e) {
  static const bool verbose = std::getenv("SPADGEN_FUZZ_VERBOSE") != nullptr;
  if (verbose) std::fprintf(stderr, "refused: %s\n", e.what());
}

[[noreturn]] inline void broken(const std::string& what) {
  std::fprintf(stderr, "spadgen fuzz: broken promise: %s\n", what.c_str());
  std::abort();
}

// `spadgen sense` parses the resolved scene file a run records in metadata.json: it must be valid and
// resolve to itself.
inline void check_resolves_to_itself(const scenes::ResolvedRun& r, const std::string& path) {
  const std::string text = r.resolved.dump();
  scenes::ResolvedRun again;
  try {
    again = scenes::parse_scene_text(text, path);
  } catch (const Error& e) {
    broken("the resolved scene file is refused: " + std::string(e.what()) + "\n" + text);
  }
  if (again.resolved != r.resolved) broken("the resolved scene file resolves differently:\n" + text + "\n" + again.resolved.dump());
}

}  // namespace spadgen::fuzz
