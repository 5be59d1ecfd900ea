// libFuzzer harness of the dataset-file parser: the input is a dataset file's text, read as if it lay in
// examples/datasets/ (so "../../scenes/paper/flat_target.json" names a shipped scene). Every input must end
// in a DatasetSpec or a spadgen::Error. On a spec, the promises `dataset plan` and `dataset run` rely on:
// - its resolved file (what the dataset folder's dataset.json records) is a dataset file that resolves
//   to itself;
// - samples 0, 1 and the last are functions of the index alone (made twice, equal), each random value
//   within its distribution's support, the seeds within 53 bits;
// - each of those samples' scene file resolves with its overrides, or is refused with a spadgen::Error
//   (an invalid sample, which a run records in failed/).
// Anything else, a crash or a sanitizer report, is a finding.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "datasets/dataset.h"
#include "fuzz_common.h"

namespace {

using spadgen::datasets::Distribution;
using spadgen::fuzz::broken;

void check_draw(const spadgen::datasets::RandomAxis& r, const nlohmann::ordered_json& v) {
  const Distribution& d = r.dist;
  const std::string where = "sample value " + v.dump() + " of /random/" + r.key;
  if (d.kind == Distribution::Kind::Choice) {
    for (const auto& c : d.choices)
      if (nlohmann::ordered_json::parse(c.dump()) == v) return;
    broken(where + ": not one of the choices " + d.choices.dump());
  }
  if (!v.is_number()) broken(where + ": not a number");
  const double x = v.get<double>();
  if (!std::isfinite(x)) broken(where + ": not finite");
  switch (d.kind) {
    case Distribution::Kind::Uniform:
    case Distribution::Kind::LogUniform: {
      // a + (b - a) u with u < 1 may round to b itself; exp(log) may round past either end by a few ulps
      const double tol = 1e-12 * std::max(std::fabs(d.a), std::fabs(d.b));
      if (x < d.a - tol || x > d.b + tol) broken(where + ": outside [" + std::to_string(d.a) + ", " + std::to_string(d.b) + "]");
      break;
    }
    case Distribution::Kind::UniformInt:
      if (!v.is_number_integer() || x < d.a || x > d.b) broken(where + ": not an integer in [a, b]");
      break;
    case Distribution::Kind::Normal:
      if ((d.min && x < *d.min) || (d.max && x > *d.max)) broken(where + ": outside [min, max]");
      break;
    case Distribution::Kind::Choice: break;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  const std::string path = std::string(SPADGEN_SOURCE_DIR) + "/examples/datasets/fuzz_input.json";
  spadgen::datasets::DatasetSpec spec;
  try {
    spec = spadgen::datasets::parse_dataset_text(text, path);
  } catch (const spadgen::Error& e) {
    spadgen::fuzz::refused(e);
    return 0;
  }
  const int64_t n = spec.count();
  if (n < 1 || n > spadgen::datasets::kMaxSamples) broken("a dataset of " + std::to_string(n) + " samples");
  if (spec.scenes.empty() || spec.scenes.size() != spec.scene_names.size()) broken("scenes and their names differ");
  try {
    const spadgen::datasets::DatasetSpec again = spadgen::datasets::parse_dataset_text(spec.resolved.dump(), path);
    if (again.resolved != spec.resolved)
      broken("the resolved dataset file resolves differently:\n" + spec.resolved.dump() + "\n" + again.resolved.dump());
  } catch (const spadgen::Error& e) {
    broken("the resolved dataset file is refused: " + std::string(e.what()) + "\n" + spec.resolved.dump());
  }
  for (const int64_t i : {int64_t{0}, std::min<int64_t>(1, n - 1), n - 1}) {
    spadgen::datasets::Sample s;
    try {
      s = spadgen::datasets::make_sample(spec, i);
    } catch (const spadgen::Error& e) {  // a truncated normal that no draw fell into
      spadgen::fuzz::refused(e);
      continue;
    }
    const spadgen::datasets::Sample t = spadgen::datasets::make_sample(spec, i);
    if (s.overrides != t.overrides || s.parameters != t.parameters || s.seed != t.seed)
      broken("sample " + std::to_string(i) + " differs when made again");
    if (s.scene < 0 || size_t(s.scene) >= spec.scenes.size()) broken("sample " + std::to_string(i) + ": no such scene");
    for (const auto& r : spec.random) {
      if (!s.parameters.contains(r.key)) broken("sample " + std::to_string(i) + " lacks /random/" + r.key);
      check_draw(r, s.parameters[r.key]);
    }
    for (const uint64_t seed : {s.seed, s.light_seed, s.chip_seed, s.noise_seed})
      if (seed > (uint64_t{1} << 53)) broken("sample " + std::to_string(i) + ": a seed beyond 2^53");
    try {
      (void)spadgen::scenes::load_scene_file(spec.scenes[size_t(s.scene)], s.overrides);
    } catch (const spadgen::Error& e) {
      spadgen::fuzz::refused(e);
    }
  }
  return 0;
}
