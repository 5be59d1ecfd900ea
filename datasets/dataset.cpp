#include "datasets/dataset.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <limits>
#include <optional>
#include <set>
#include <sstream>

#include "core/error.h"
#include "core/units.h"
#include "core/rng.h"
#include "scenes/input.h"
#include "scenes/key_path.h"
#include "scenes/scene.h"
#include "scenes/scene_file.h"

namespace spadgen::datasets {
namespace fs = std::filesystem;
using json = nlohmann::json;
using ojson = nlohmann::ordered_json;

namespace {

using scenes::kMaxSeed;

// A uniform double in [0, 1) with 53 random bits.
double uniform01(Rng& r) { return static_cast<double>(r.next_u64() >> 11) * 0x1p-53; }

double normal_cdf(double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); }

std::string describe(const json& v) {
  std::string s = v.dump();
  if (s.size() > 60) s = s.substr(0, 57) + "...";
  return s;
}

struct Reader {
  std::string file;
  // The file's mistakes so far: each part of the file (a top-level key, a key of set, grid or random) is read
  // on its own (each()), so that one reading names them all, as a scene file's does.
  mutable std::vector<std::string> errors;
  [[noreturn]] void fail(const std::string& where, const std::string& what) const {
    throw Error(file + ": " + where + ": " + what);
  }
  template <class F>
  void each(F&& read_part) const {
    try {
      read_part();
    } catch (const Error& e) {
      errors.push_back(e.what());
    }
  }
  // Stops with every mistake found (one: as it is; several: counted, one per line).
  void stop_on_errors() const {
    if (errors.empty()) return;
    if (errors.size() == 1) throw Error(errors.front());
    std::string out = std::to_string(errors.size()) + " errors in the dataset file:";
    for (const std::string& e : errors) {  // (one per line: run_command keeps them)
      out += '\n';
      out += scenes::one_line(e);
    }
    throw Error(out);
  }
  double number(const json& v, const std::string& where, const std::string& expected) const {
    if (!v.is_number() || !std::isfinite(v.get<double>())) fail(where, "found " + describe(v) + ", expected " + expected);
    return v.get<double>();
  }
  // also: what else the key takes (seeds.*: ' or "per_sample"', which their messages left out but for a string)
  uint64_t seed(const json& v, const std::string& where, const std::string& also = "") const {
    if (!v.is_number_unsigned() && !(v.is_number_integer() && v.get<int64_t>() >= 0))
      fail(where, "found " + describe(v) + ", expected an integer in [0, 2^53]" + also);
    const uint64_t s = v.get<uint64_t>();
    if (s > kMaxSeed) fail(where, "found " + describe(v) + ", expected an integer in [0, 2^53]" + also);
    return s;
  }
};

// Keys a dataset controls itself.
bool is_seed_key(const std::string& key) { return key == "seed" || key.rfind("seeds.", 0) == 0; }

Distribution read_distribution(const Reader& rd, const json& v, const std::string& where) {
  if (!v.is_object() || v.size() < 1)
    rd.fail(where, "found " + describe(v) + ", expected a distribution: {\"uniform\": [a, b]}, {\"log_uniform\": [a, b]}, "
                   "{\"normal\": [mean, sigma], \"min\": lo, \"max\": hi}, {\"uniform_int\": [a, b]} or {\"choice\": [v1, v2, ...]}");
  static const std::vector<std::string> kinds = {"uniform", "log_uniform", "normal", "uniform_int", "choice"};
  std::string kind;
  for (auto it = v.begin(); it != v.end(); ++it) {
    if (std::find(kinds.begin(), kinds.end(), it.key()) != kinds.end()) {
      if (!kind.empty()) rd.fail(where, "has both \"" + kind + "\" and \"" + it.key() + "\"; expected one distribution");
      kind = it.key();
    } else if (it.key() != "min" && it.key() != "max") {
      const std::string near = scenes::closest(it.key(), {"uniform", "log_uniform", "normal", "uniform_int", "choice", "min", "max"});
      rd.fail(where + "/" + it.key(), "unknown key" + (near.empty() ? "; expected one of uniform, log_uniform, normal, uniform_int, choice (and min, max with normal)"
                                                                   : "; did you mean " + near + "?"));
    }
  }
  if (kind.empty()) rd.fail(where, "expected one of uniform, log_uniform, normal, uniform_int, choice");
  Distribution d;
  const json& p = v.at(kind);
  const std::string at = where + "/" + kind;
  if (kind == "choice") {
    if (!p.is_array() || p.empty()) rd.fail(at, "found " + describe(p) + ", expected a non-empty array of values");
    d.kind = Distribution::Kind::Choice;
    d.choices = p;
  } else {
    if (!p.is_array() || p.size() != 2)
      rd.fail(at, "found " + describe(p) + ", expected " + (kind == "normal" ? "[mean, sigma]" : "[a, b]"));
    d.a = rd.number(p[0], at + "/0", "a number");
    d.b = rd.number(p[1], at + "/1", "a number");
    if (kind == "uniform") {
      d.kind = Distribution::Kind::Uniform;
      if (!(d.b > d.a)) rd.fail(at, "found [" + describe(p[0]) + ", " + describe(p[1]) + "], expected a < b");
    } else if (kind == "log_uniform") {
      d.kind = Distribution::Kind::LogUniform;
      if (!(d.a > 0 && d.b > d.a)) rd.fail(at, "found " + describe(p) + ", expected 0 < a < b");
    } else if (kind == "uniform_int") {
      d.kind = Distribution::Kind::UniformInt;
      if (d.a != std::floor(d.a) || d.b != std::floor(d.b) || !(d.b >= d.a) || std::fabs(d.a) > 9e15 || std::fabs(d.b) > 9e15)
        rd.fail(at, "found " + describe(p) + ", expected integers a <= b (both included) within +-9e15 (beyond, a double "
                    "no longer counts every integer)");
    } else {
      d.kind = Distribution::Kind::Normal;
      if (!(d.b > 0)) rd.fail(at, "found sigma " + describe(p[1]) + ", expected sigma > 0");
    }
  }
  for (const char* bound : {"min", "max"}) {
    if (!v.contains(bound)) continue;
    if (d.kind != Distribution::Kind::Normal)
      rd.fail(where + "/" + bound, "is only for \"normal\" (a truncated normal); the " + kind + " distribution has its bounds already");
    (std::string(bound) == "min" ? d.min : d.max) = rd.number(v.at(bound), where + "/" + bound, "a number");
  }
  if (d.kind == Distribution::Kind::Normal) {
    if (d.min && d.max && !(*d.min < *d.max))
      rd.fail(where, "has min " + describe(v.at("min")) + " and max " + describe(v.at("max")) + "; expected min < max");
    const double lo = d.min ? (*d.min - d.a) / d.b : -INFINITY, hi = d.max ? (*d.max - d.a) / d.b : INFINITY;
    const double mass = normal_cdf(hi) - normal_cdf(lo);
    if (!(mass >= 1e-3))
      rd.fail(where, "keeps a fraction " + std::to_string(mass) +
                         " of the normal distribution between min and max; expected at least 0.001 (widen min and max, or move the mean)");
  }
  return d;
}

double in_range(const Distribution& d, double x) { return x >= d.b ? std::nextafter(d.b, d.a) : std::max(x, d.a); }

json draw(const Distribution& d, Rng& r, const std::string& where) {
  switch (d.kind) {
    // [a, b): rounding can reach b, or for a log-uniform fall below a, in ranges a few ulps wide
    case Distribution::Kind::Uniform: return in_range(d, d.a + (d.b - d.a) * uniform01(r));
    case Distribution::Kind::LogUniform: return in_range(d, std::exp(std::log(d.a) + (std::log(d.b) - std::log(d.a)) * uniform01(r)));
    case Distribution::Kind::UniformInt: {
      const double n = d.b - d.a + 1.0;
      const auto k = static_cast<int64_t>(std::min(std::floor(uniform01(r) * n), n - 1.0));
      return static_cast<int64_t>(d.a) + k;
    }
    case Distribution::Kind::Choice: {
      const double n = static_cast<double>(d.choices.size());
      const auto k = static_cast<size_t>(std::min(std::floor(uniform01(r) * n), n - 1.0));
      return d.choices[k];
    }
    case Distribution::Kind::Normal:
      // Box-Muller, one value per pair; rejection for the truncation (its mass was checked to be >= 0.001).
      for (int attempt = 0; attempt < 100000; ++attempt) {
        const double u1 = 1.0 - uniform01(r), u2 = uniform01(r);
        const double x = d.a + d.b * std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * 3.141592653589793 * u2);
        if ((!d.min || x >= *d.min) && (!d.max || x <= *d.max)) return x;
      }
      throw Error(where + ": no draw fell between min and max in 100000 attempts");
  }
  return nullptr;
}

std::string folder_of(int64_t index) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "samples/%06lld", static_cast<long long>(index));
  return buf;
}

// v with every float that holds an integer (6.0, -3.0; up to 2^53 in magnitude, not -0.0) as that integer.
// JSON's 6 and 6.0 are one value, and equal values must make the same sample: its hash is of the resolved
// scene's text, where 6.0 and 6 differ (a dataset file saved again by another tool, Python's json.dump
// writes 6.0, made every sample stale and generated again).
json integral_numbers_as_integers(json v) {
  if (v.is_structured()) {
    for (json& e : v) e = integral_numbers_as_integers(std::move(e));
  } else if (v.is_number_float()) {
    const double d = v.get<double>();
    if (std::trunc(d) == d && std::abs(d) <= 9007199254740992.0 && !(d == 0.0 && std::signbit(d)))
      return json(static_cast<int64_t>(d));
  }
  return v;
}

}  // namespace

const std::vector<DatasetKey>& dataset_keys() {
  static const std::vector<DatasetKey> keys = {
      {"description", "string", "\"\"", "free text, copied into the dataset card (dataset.md)"},
      {"seed", "integer in [0, 2^53]", "0", "the dataset seed: every sample's random draws and seeds derive from it and the sample's index"},
      {"scenes", "array of files", "required", "base scene files, relative to the dataset file; with several, the scene is the outermost grid axis (parameter `scene`)"},
      {"samples", "integer in [1, 1e8] or null", "null", "number of samples; sample i takes grid cell i mod (number of cells) and its own random draws; null = one sample per grid cell"},
      {"set", "object: key -> value", "{}", "scene-file keys (dotted, as --set writes them) set for every sample"},
      {"grid", "object: key -> array of values", "{}", "scene-file keys and their values, combined as a grid (the last key varies fastest)"},
      {"random", "object: key -> distribution", "{}", "scene-file keys drawn per sample (distributions below), from the dataset seed, the sample index and the key"},
      {"seeds.light", "integer or \"per_sample\"", "\"per_sample\"", "seed of the light transport for every sample; \"per_sample\": the sample's seed"},
      {"seeds.chip", "integer or \"per_sample\"", "\"per_sample\"", "seed of the chip's fixed pattern; an integer gives every sample the same chip (one camera)"},
      {"seeds.noise", "integer or \"per_sample\"", "\"per_sample\"", "seed of the temporal noise; realisation r of a sample uses noise seed + r (a fixed one: at most 2^53 - (repeats - 1))"},
      {"repeats", "integer in [1, 1000]", "1", "realisations of the temporal noise per rendered sample (`spadgen sense` on the saved light: the light is rendered once)"},
  };
  return keys;
}

int64_t DatasetSpec::grid_cells() const {
  int64_t n = static_cast<int64_t>(scenes.size());
  for (const GridAxis& g : grid)
    if (__builtin_mul_overflow(n, static_cast<int64_t>(g.values.size()), &n)) return std::numeric_limits<int64_t>::max();
  return n;
}

int64_t DatasetSpec::count() const { return samples.value_or(grid_cells()); }

int64_t DatasetSpec::samples_of_scene(size_t i) const {
  const int64_t cells = grid_cells(), per_scene = cells / static_cast<int64_t>(scenes.size());
  const int64_t rest = count() % cells - static_cast<int64_t>(i) * per_scene;
  return count() / cells * per_scene + std::clamp(rest, int64_t{0}, per_scene);
}

std::string DatasetSpec::coverage_warning() const {
  const int64_t cells = grid_cells(), n = count();
  if (n >= cells) return "";
  std::string none;  // the scene files no sample takes
  size_t unsampled = 0;
  for (size_t i = 0; i < scenes.size(); ++i)
    if (samples_of_scene(i) == 0) none += (unsampled++ ? ", " : "") + scene_names[i];
  const std::string cell_range = n + 1 == cells ? "cell " + std::to_string(n) : "cells " + std::to_string(n) + "-" + std::to_string(cells - 1);
  return file + ": samples (" + std::to_string(n) + ") is fewer than the " + std::to_string(cells) +
         " grid cells (scenes outermost, the last grid key fastest): " + cell_range + " make no sample" +
         (unsampled ? std::string(unsampled == 1 ? ", nor does the scene file " : ", nor do the scene files ") + none : std::string()) +
         "; \"samples\": null makes one per cell, a multiple of " + std::to_string(cells) + " as many of each";
}

DatasetSpec parse_dataset_text(const std::string& text, const std::string& path) {
  const Reader rd{path.empty() ? "<dataset>" : path, {}};
  // checked: depth, duplicate keys, numbers; a number written with a fraction of zero (6.0) read as the
  // integer (6), so that it makes the same samples
  const json doc = integral_numbers_as_integers(scenes::parse_json(text, rd.file));
  // The same text with the keys in the file's order, which orders the axes.
  const ojson ordered = ojson::parse(text, nullptr, true, /*ignore_comments=*/true);
  const auto keys_of = [&](const char* section) {
    std::vector<std::string> k;
    if (ordered.contains(section) && ordered[section].is_object())
      for (auto it = ordered[section].begin(); it != ordered[section].end(); ++it) k.push_back(it.key());
    return k;
  };
  if (!doc.is_object()) throw Error(rd.file + ": expected a JSON object at the top, found " + describe(doc));
  std::vector<std::string> known;
  for (const DatasetKey& k : dataset_keys())
    if (k.key.find('.') == std::string::npos) known.push_back(k.key);
  known.push_back("seeds");
  for (auto it = doc.begin(); it != doc.end(); ++it)
    if (std::find(known.begin(), known.end(), it.key()) == known.end())
      rd.each([&] {
        const std::string near = scenes::closest(it.key(), known);
        rd.fail("/" + it.key(), "unknown key" + (near.empty() ? "; the keys of a dataset file are: description, seed, scenes, "
                                                                "samples, set, grid, random, seeds, repeats"
                                                              : "; did you mean " + near + "?"));
      });

  DatasetSpec s;
  s.file = path.empty() ? "" : scenes::normal_path(path);
  const std::string dir = path.empty() ? "." : fs::path(s.file).parent_path().string();
  rd.each([&] {
    if (doc.contains("description")) {
      if (!doc["description"].is_string()) rd.fail("/description", "found " + describe(doc["description"]) + ", expected a string");
      s.description = doc["description"].get<std::string>();
    }
  });
  rd.each([&] {
    if (doc.contains("seed")) s.seed = rd.seed(doc["seed"], "/seed");
  });
  bool scenes_read = false;  // the keys' values are checked against the first scene file: none without a valid list
  rd.each([&] {
    if (!doc.contains("scenes")) rd.fail("/scenes", "missing; expected an array of scene files (relative to the dataset file)");
    const json& sc = doc["scenes"];
    if (!sc.is_array() || sc.empty()) rd.fail("/scenes", "found " + describe(sc) + ", expected a non-empty array of scene files");
    for (size_t i = 0; i < sc.size(); ++i) {
      const std::string at = "/scenes/" + std::to_string(i);
      if (!sc[i].is_string() || sc[i].get<std::string>().empty()) rd.fail(at, "found " + describe(sc[i]) + ", expected a file name");
      const std::string name = sc[i].get<std::string>();
      // A NUL byte ends a path for the system: the file opened would be another than the one named.
      if (name.find('\0') != std::string::npos)
        rd.fail(at, "found '" + scenes::printable(name) + "', which holds a NUL byte; expected a file name without one");
      fs::path p(name);
      if (p.is_relative()) p = fs::path(dir) / p;
      const std::string full = scenes::normal_path(p.string());
      const std::string problem = scenes::file_problem(full, scenes::kMaxSceneFileBytes);
      if (!problem.empty()) rd.fail(at, "the scene file " + full + " " + problem + "; expected a path relative to the dataset file");
      // (the same file under two spellings too: "paper/x.json" and "paper/../paper/x.json" had doubled the grid)
      if (const auto same = std::find(s.scenes.begin(), s.scenes.end(), full); same != s.scenes.end())
        rd.fail(at, "lists " + full + " twice (as /scenes/" + std::to_string(same - s.scenes.begin()) +
                        " too); expected each scene file once");
      s.scenes.push_back(full);
      s.scene_names.push_back(name);
    }
    scenes_read = true;
  });
  rd.each([&] {
    if (doc.contains("samples") && !doc["samples"].is_null()) {
      const json& n = doc["samples"];
      if (!n.is_number_integer() && !n.is_number_unsigned()) rd.fail("/samples", "found " + describe(n) + ", expected an integer in [1, 1e8] or null");
      const int64_t v = n.get<int64_t>();
      if (v < 1 || v > kMaxSamples) rd.fail("/samples", "found " + describe(n) + ", expected an integer in [1, 1e8] or null");
      s.samples = v;
    }
  });
  rd.each([&] {
    if (doc.contains("repeats")) {
      const json& r = doc["repeats"];
      if (!r.is_number_integer() && !r.is_number_unsigned()) rd.fail("/repeats", "found " + describe(r) + ", expected an integer in [1, 1000]");
      const int64_t v = r.get<int64_t>();
      if (v < 1 || v > 1000) rd.fail("/repeats", "found " + describe(r) + ", expected an integer in [1, 1000]");
      s.repeats = static_cast<int>(v);
    }
  });
  rd.each([&] {
    if (doc.contains("seeds")) {
      const json& sd = doc["seeds"];
      if (!sd.is_object()) rd.fail("/seeds", "found " + describe(sd) + ", expected an object {\"light\": ..., \"chip\": ..., \"noise\": ...}");
      for (auto it = sd.begin(); it != sd.end(); ++it) {
        const std::string at = "/seeds/" + it.key();
        std::optional<uint64_t>* slot = it.key() == "light" ? &s.light_seed : it.key() == "chip" ? &s.chip_seed
                                                                          : it.key() == "noise" ? &s.noise_seed : nullptr;
        if (!slot) {
          const std::string near = scenes::closest(it.key(), {"light", "chip", "noise"});
          rd.fail(at, "unknown key" + (near.empty() ? "; the seeds are light, chip and noise" : "; did you mean " + near + "?"));
        }
        if (it.value().is_string() && it.value().get<std::string>() == "per_sample") continue;
        if (it.value().is_string()) rd.fail(at, "found " + describe(it.value()) + ", expected an integer in [0, 2^53] or \"per_sample\"");
        *slot = rd.seed(it.value(), at, " or \"per_sample\"");
      }
      // realisation r uses noise seed + r: the last must be a seed too (it failed every sample after rendering)
      if (s.noise_seed && *s.noise_seed + uint64_t(s.repeats - 1) > kMaxSeed)
        rd.fail("/seeds/noise", "found " + std::to_string(*s.noise_seed) + ", and realisation " + std::to_string(s.repeats - 1) +
                                    " (repeats " + std::to_string(s.repeats) + ") would use noise seed + " +
                                    std::to_string(s.repeats - 1) + ", past 2^53; expected at most " +
                                    std::to_string(kMaxSeed - uint64_t(s.repeats - 1)));
    }
  });

  // The scene-file keys: dotted as --set writes them; the dataset owns the seeds.
  const auto check_key = [&](const std::string& section, const std::string& key) {
    const std::string at = "/" + section + "/" + key;
    if (key.empty()) rd.fail(at, "expected a scene-file key such as laser.average_power_mW");
    if (is_seed_key(key))
      rd.fail(at, "the dataset sets every sample's seeds: use the dataset file's \"seed\" and \"seeds\" keys instead");
    return at;
  };
  // Checks `key=value` overrides against the first scene file, with the scene file's own checks (each value
  // alone: a value that makes some samples invalid with other keys is those samples' failure, not the file's).
  // A mistake of the first scene file itself is its own, named once at /scenes/0 (not the keys', unless the
  // dataset's keys mend it: then the keys are checked with it as they are).
  std::optional<std::string> own_mistake;
  // The others a value may need (one end of the time window in set, the other in grid): the set's values and
  // each grid key's first, as a sample has them. A value refused alone is checked again among them, and is the
  // file's mistake only when it fails there too (the pair was refused at both places, and the window's end
  // could not be varied; the probe samples below check the combinations).
  std::vector<std::string> others;
  for (const char* section : {"set", "grid"})
    if (doc.contains(section) && doc[section].is_object())
      for (const auto& [key, value] : doc[section].items()) {
        if (std::string(section) == "set") others.push_back(key + "=" + value.dump());
        else if (value.is_array() && !value.empty()) others.push_back(key + "=" + value.front().dump());
      }
  const auto check_values = [&](const std::string& at, const std::vector<std::string>& overrides, const std::string& hint = "") {
    if (!scenes_read) return;
    try {
      (void)scenes::load_scene_file(s.scenes.front(), overrides);
    } catch (const Error& e) {
      try {  // among the others (the overrides given last: theirs win)
        std::vector<std::string> among = others;
        among.insert(among.end(), overrides.begin(), overrides.end());
        (void)scenes::load_scene_file(s.scenes.front(), among);
        return;
      } catch (const Error&) {
      }
      if (!own_mistake) {
        own_mistake = "";
        try {
          (void)scenes::load_scene_file(s.scenes.front(), {});
        } catch (const Error& own) {
          own_mistake = own.what();
          rd.fail("/scenes/0", own.what());
        }
      }
      if (!own_mistake->empty()) return;  // named once, above
      const std::string what = e.what();
      rd.fail(at, "with the scene file " + s.scene_names.front() + ": " + what +
                      (what.find("expected an integer") != std::string::npos ? hint : std::string()));
    }
  };
  // Each value once: one key under two spellings (materials.plate.roughness and materials."plate".roughness),
  // or a whole [x, y, z] key and one of its components, is one value set twice (the index would list the
  // one and the sample render the other).
  std::vector<std::pair<std::string, scenes::KeyPath>> seen;
  const auto once = [&](const std::string& at, const std::string& key) {
    scenes::KeyPath kp;
    try {
      kp = scenes::parse_key_path(key);
    } catch (const Error&) {
      return;  // the scene file's check names what is wrong with it
    }
    for (const auto& [other, p] : seen) {
      const size_t n = std::min(p.names.size(), kp.names.size());
      if (!std::equal(p.names.begin(), p.names.begin() + std::ptrdiff_t(n), kp.names.begin())) continue;
      if (p.names.size() == kp.names.size() && p.component && kp.component && *p.component != *kp.component) continue;
      rd.fail(at, "varies " + key + (other == key ? " a second time" : ", which " + other + " varies too") +
                      "; expected each key in one of set, grid and random");
    }
    seen.emplace_back(key, kp);
  };
  // The key (as the file spells it) that sets `names` whole, or "".
  const auto spelling_of = [&](const std::vector<std::string>& names) {
    for (const auto& [key, p] : seen)
      if (p.names == names && !p.component) return key;
    return std::string();
  };
  if (doc.contains("set") && !doc["set"].is_object())
    rd.each([&] { rd.fail("/set", "found " + describe(doc["set"]) + ", expected an object of scene-file keys and values"); });
  if (doc.contains("set") && doc["set"].is_object()) {
    const json& st = doc["set"];
    std::vector<std::string> all;
    for (const std::string& key : keys_of("set")) {
      const auto it = st.find(key);
      rd.each([&] {
        (void)check_key("set", it.key());
        once("/set/" + it.key(), it.key());
        s.set.emplace_back(it.key(), it.value());
        all.push_back(it.key() + "=" + it.value().dump());
      });
    }
    // The whole set together first (a key may need another of the set: both ends of the time window); when
    // it fails, each key alone names its own mistake.
    bool together = true;
    try {
      if (scenes_read) (void)scenes::load_scene_file(s.scenes.front(), all);
    } catch (const Error&) {
      together = false;
    }
    if (!together) {  // with the grid's first values (the other end of the window may be there)
      together = true;
      try {
        if (scenes_read) (void)scenes::load_scene_file(s.scenes.front(), others);
      } catch (const Error&) {
        together = false;
      }
    }
    if (!together) {
      // each key alone; one found wrong is left out of the samples the checks below make (it failed them all)
      std::vector<std::pair<std::string, json>> right;
      for (size_t i = 0; i < all.size(); ++i) {
        const size_t errors = rd.errors.size();
        rd.each([&] { check_values("/set/" + s.set[i].first, {all[i]}); });
        if (rd.errors.size() == errors) right.push_back(s.set[i]);
      }
      s.set = std::move(right);
    }
  }
  if (doc.contains("grid") && !doc["grid"].is_object())
    rd.each([&] { rd.fail("/grid", "found " + describe(doc["grid"]) + ", expected an object of scene-file keys and arrays of values"); });
  if (doc.contains("grid") && doc["grid"].is_object()) {
    const json& g = doc["grid"];
    for (const std::string& key : keys_of("grid")) {
      const auto it = g.find(key);
      rd.each([&] {
        const std::string at = check_key("grid", it.key());
        once(at, it.key());
        if (!it.value().is_array() || it.value().empty())
          rd.fail(at, "found " + describe(it.value()) + ", expected a non-empty array of values");
        for (size_t i = 0; i < it.value().size(); ++i)
          check_values(at + "/" + std::to_string(i), {it.key() + "=" + it.value()[i].dump()});
        s.grid.push_back({it.key(), it.value()});
      });
    }
  }
  if (doc.contains("random") && !doc["random"].is_object())
    rd.each([&] { rd.fail("/random", "found " + describe(doc["random"]) + ", expected an object of scene-file keys and distributions"); });
  if (doc.contains("random") && doc["random"].is_object()) {
    const json& r = doc["random"];
    for (const std::string& key : keys_of("random")) {
      const auto it = r.find(key);
      rd.each([&] {
        const std::string at = check_key("random", it.key());
        once(at, it.key());
        const Distribution d = read_distribution(rd, it.value(), at);
        // The ends of the range must be valid values (a key's range check catches most mistakes here).
        std::vector<json> probes;
        if (d.kind == Distribution::Kind::Choice) probes.assign(d.choices.begin(), d.choices.end());
        else if (d.kind == Distribution::Kind::UniformInt) probes = {static_cast<int64_t>(d.a), static_cast<int64_t>(d.b)};
        else if (d.kind == Distribution::Kind::Normal) probes = {d.min.value_or(d.a), d.max.value_or(d.a)};
        else probes = {d.a, d.b};
        for (const json& p : probes) check_values(at, {it.key() + "=" + p.dump()});
        // A continuous draw gives values with fractions: one inside the range (not a round one), which an
        // integer key refuses (uniform [600, 700] on camera.width_px passed with its integer ends, and the
        // dataset failed on its first samples).
        if (d.kind == Distribution::Kind::Uniform || d.kind == Distribution::Kind::LogUniform || d.kind == Distribution::Kind::Normal) {
          const double lo = d.kind == Distribution::Kind::Normal ? d.min.value_or(d.a) : d.a;
          const double hi = d.kind == Distribution::Kind::Normal ? d.max.value_or(d.a + d.b) : d.b;
          if (hi > lo) {
            check_values(at, {it.key() + "=" + json(lo + (hi - lo) / kPi).dump()},
                         "; a continuous distribution draws fractions: for an integer key use {\"uniform_int\": [a, b]}");
          }
        }
        // An untruncated side of a normal reaches any value (40 sigma stands for it): a key with a bound there
        // needs min or max, or some samples fail.
        if (d.kind == Distribution::Kind::Normal)
          for (const char* side : {"min", "max"}) {
            if (std::string(side) == "min" ? d.min.has_value() : d.max.has_value()) continue;
            const double far = d.a + (std::string(side) == "min" ? -40.0 : 40.0) * d.b;
            try {
              (void)scenes::load_scene_file(s.scenes.front(), {it.key() + "=" + json(far).dump()});
            } catch (const Error& e) {
              rd.fail(at, std::string("a normal without \"") + side + "\" can give any value " + (std::string(side) == "min" ? "below" : "above") +
                              " its mean, and the key has a bound there (at " + json(far).dump() + ": " + e.what() +
                              "); give \"" + side + "\" (a truncated normal)");
            }
          }
        s.random.push_back({it.key(), d, it.value()});
      });
    }
  }
  // Realisations re-sample the noise from each sample's saved light, so `repeats` saves it (outputs.light
  // true for every sample): the file may say so too, not otherwise. (Not of keys found wrong above: a value of
  // outputs.light that is no boolean was named, and told to be set true, twice.)
  if (rd.errors.empty()) rd.each([&] {
    if (const std::string light = spelling_of({"outputs", "light"}); s.repeats > 1 && !light.empty()) {
      const auto in_set = std::find_if(s.set.begin(), s.set.end(), [&](const auto& kv) { return kv.first == light; });
      const std::string why = "repeats " + std::to_string(s.repeats) + " re-samples each sample's noise from its saved light, which it saves";
      if (in_set == s.set.end())
        rd.fail("/repeats", "is " + std::to_string(s.repeats) + ", and outputs.light varies per sample (grid or random); " + why +
                                " in every sample: remove outputs.light from grid and random");
      if (in_set->second != json(true))
        rd.fail("/set/" + light, "is " + in_set->second.dump() + ", but " + why + ": set it true, or remove it");
    }
  });
  if (!scenes_read) rd.stop_on_errors();
  // Names of glTF nodes and materials are known only to the glTF: each scene is loaded once with the
  // edits of its first valid sample, so that a misspelt name fails here rather than in every sample (and
  // beside the file's other mistakes: the keys found wrong above are left out of the samples here). A
  // sample whose values make an invalid scene together (a crop outside a sensor a grid shrinks) is
  // recorded in failed/ when it runs, as a failed run is; when its scene's first 16 samples all do, the
  // mistake is the dataset's and it is refused here.
  // Checked first: the probes below step through the samples a grid's cells at a time (a grid of 2^64
  // cells wrapped to 0 cells, and looped for ever).
  if (s.grid_cells() > kMaxSamples) {
    double cells = static_cast<double>(s.scenes.size());
    for (const GridAxis& g : s.grid) cells *= static_cast<double>(g.values.size());
    std::ostringstream n;
    n << std::setprecision(cells < 1e15 ? 15 : 3) << cells;
    rd.each([&] { rd.fail("/grid", "has " + n.str() + " cells (the scene files times each key's values); expected at most 1e8"); });
    rd.stop_on_errors();
  }
  for (size_t k = 0; k < s.scenes.size(); ++k) {
    const std::vector<int64_t> probes = probe_samples(s, k);
    if (probes.empty()) break;
    rd.each([&] {
      std::optional<scenes::ResolvedRun> r;
      std::string why;
      for (size_t j = 0; !r && j < probes.size(); ++j) {
        try {
          r = scenes::load_scene_file(s.scenes[k], make_sample(s, probes[j]).overrides);
        } catch (const Error& e) {
          if (why.empty()) why = e.what();
        }
      }
      // (where mistakes were named above, the probes' failures are theirs: not named again)
      if (!r) {
        if (!rd.errors.empty()) return;
        throw Error(rd.file + ": " + invalid_probes_message(s, k, probes, why));
      }
      if (r->config.edits.nodes.empty() && r->config.edits.materials.empty()) return;
      try {
        (void)scenes::load_gltf(r->config.gltf_path, r->config.gltf_scene, r->config.edits);
      } catch (const scenes::EditError& e) {
        // the dataset's key that edits the node or material (/random/nodes.plat.translation_m[2]; it named
        // "scenes/0" and the scene file's /nodes/plat)
        const std::string prefix = e.section + "." + e.name + ".";
        std::string where;
        for (const auto& [key, v] : s.set)
          if (where.empty() && key.rfind(prefix, 0) == 0) where = "/set/" + key;
        for (const GridAxis& g : s.grid)
          if (where.empty() && g.key.rfind(prefix, 0) == 0) where = "/grid/" + g.key;
        for (const RandomAxis& ra : s.random)
          if (where.empty() && ra.key.rfind(prefix, 0) == 0) where = "/random/" + ra.key;
        rd.fail(where.empty() ? "/scenes/" + std::to_string(k) : where,
                "the nodes and materials the dataset varies, in " + s.scene_names[k] + ": " + e.what());
      } catch (const Error& e) {
        rd.fail("/scenes/" + std::to_string(k), "the nodes and materials the dataset varies, in " + s.scene_names[k] + ": " + e.what());
      }
    });
  }
  rd.stop_on_errors();

  // The resolved file, every default explicit.
  ojson& o = s.resolved;
  o["description"] = s.description;
  o["seed"] = s.seed;
  o["scenes"] = s.scene_names;
  o["samples"] = s.samples ? ojson(*s.samples) : ojson(nullptr);
  o["set"] = ojson::object();
  for (const auto& [k, v] : s.set) o["set"][k] = ojson::parse(v.dump());
  o["grid"] = ojson::object();
  for (const GridAxis& g : s.grid) o["grid"][g.key] = ojson::parse(g.values.dump());
  o["random"] = ojson::object();
  for (const RandomAxis& r : s.random) o["random"][r.key] = ojson::parse(r.spec.dump());
  const auto seed_json = [](const std::optional<uint64_t>& v) { return v ? ojson(*v) : ojson("per_sample"); };
  o["seeds"] = {{"light", seed_json(s.light_seed)}, {"chip", seed_json(s.chip_seed)}, {"noise", seed_json(s.noise_seed)}};
  o["repeats"] = s.repeats;
  return s;
}

DatasetSpec load_dataset_file(const std::string& path) {
  if (scenes::invalid_utf8_at(path) != std::string::npos)
    throw Error("dataset file " + scenes::printable(path) + ": its name is not valid UTF-8 text; rename it");
  return parse_dataset_text(scenes::read_file_bounded(path, scenes::kMaxSceneFileBytes, "dataset file"), path);
}

std::vector<int64_t> probe_samples(const DatasetSpec& spec, size_t scene) {
  const int64_t cells = spec.grid_cells(), per_scene = cells / static_cast<int64_t>(spec.scenes.size());
  const int64_t first = static_cast<int64_t>(scene) * per_scene;
  std::vector<int64_t> out;
  for (int64_t base = first; out.size() < size_t{kProbeSamples} && base < spec.count(); base += cells)
    for (int64_t i = base; i < base + per_scene && i < spec.count() && out.size() < size_t{kProbeSamples}; ++i) out.push_back(i);
  return out;
}

std::string invalid_probes_message(const DatasetSpec& spec, size_t scene, const std::vector<int64_t>& probes,
                                   const std::string& why) {
  // A key the dataset gives is named at its place in the dataset file (the message begins with the file), as a
  // failing sample's error names it (it said "--set outputs.transient", which no one gave).
  const std::string named = named_in_dataset_file(spec, why);
  const std::string what = named != why ? named.substr(spec.file.size() + 2) : "with the scene file " + spec.scene_names[scene] + ": " + why;
  // (with the parameters the dataset gave it, as plan lists them)
  return sample_text(make_sample(spec, probes.at(0))) + ": " + what +
         (probes.size() > 1 ? " (and the next " + std::to_string(probes.size() - 1) + " samples of this scene fail too)" : "");
}

std::string Sample::folder() const { return folder_of(index); }

std::string Sample::repeat_folder(int r) const {
  char buf[16];
  std::snprintf(buf, sizeof buf, "_r%02d", r);
  return folder_of(index) + buf;
}

std::string sample_text(const Sample& s) {
  std::string given;
  for (const auto& [key, value] : s.parameters.items())
    if (key != "scene") given += (given.empty() ? " (" : ", ") + key + " " + (value.is_string() ? value.get<std::string>() : value.dump());
  return "sample " + std::to_string(s.index) + (given.empty() ? std::string() : given + ")");
}

std::string named_in_dataset_file(const DatasetSpec& spec, const std::string& error) {
  if (!error.starts_with("--set ")) return error;
  const size_t colon = error.find(": ");
  if (colon == std::string::npos) return error;
  const std::string key = error.substr(6, colon - 6);
  std::string section;
  for (const auto& [k, v] : spec.set)
    if (k == key) section = "set";
  for (const GridAxis& a : spec.grid)
    if (a.key == key) section = "grid";
  for (const RandomAxis& a : spec.random)
    if (a.key == key) section = "random";
  return section.empty() ? error : spec.file + ": /" + section + "/" + key + error.substr(colon);
}

Sample make_sample(const DatasetSpec& spec, int64_t index) {
  if (index < 0 || index >= spec.count())
    throw Error("sample " + std::to_string(index) + " is not in the dataset (it has " + std::to_string(spec.count()) + " samples)");
  Sample s;
  s.index = index;
  // Grid cell: the scene outermost, the last grid key fastest.
  int64_t cell = index % spec.grid_cells();
  std::vector<size_t> pick(spec.grid.size());
  for (size_t a = spec.grid.size(); a-- > 0;) {
    const auto n = static_cast<int64_t>(spec.grid[a].values.size());
    pick[a] = static_cast<size_t>(cell % n);
    cell /= n;
  }
  s.scene = static_cast<int>(cell);
  s.parameters["scene"] = spec.scene_names[size_t(s.scene)];
  for (const auto& [k, v] : spec.set) s.overrides.push_back(k + "=" + v.dump());
  for (size_t a = 0; a < spec.grid.size(); ++a) {
    const json& v = spec.grid[a].values[pick[a]];
    s.overrides.push_back(spec.grid[a].key + "=" + v.dump());
    s.parameters[spec.grid[a].key] = ojson::parse(v.dump());
  }
  for (const RandomAxis& r : spec.random) {
    // keyed by the key's one spelling (nodes."a".x is nodes.a.x): two files that spell it differently draw alike
    std::string canonical = r.key;
    try {
      canonical = scenes::parse_key_path(r.key).text();
    } catch (const Error&) {
    }  // (a key that does not parse never reaches a sample: the file's check refused it)
    Rng rng(spec.seed, RngKind::Dataset, static_cast<uint64_t>(index), scenes::fnv1a64(canonical) | 1u);
    const json v = draw(r.dist, rng, spec.file + ": /random/" + r.key);
    s.overrides.push_back(r.key + "=" + v.dump());
    s.parameters[r.key] = ojson::parse(v.dump());
  }
  // Realisations 1, 2, ... re-sample the sensor from the light the run saves.
  if (spec.repeats > 1) s.overrides.push_back("outputs.light=true");
  Rng rng(spec.seed, RngKind::Dataset, static_cast<uint64_t>(index), 0);
  s.seed = rng.next_u64() >> 11;  // 53 bits: exact in JSON
  s.overrides.push_back("seed=" + std::to_string(s.seed));
  s.light_seed = spec.light_seed.value_or(s.seed);
  s.chip_seed = spec.chip_seed.value_or(s.seed);
  s.noise_seed = spec.noise_seed.value_or(s.seed);
  if (spec.light_seed) s.overrides.push_back("seeds.light=" + std::to_string(*spec.light_seed));
  if (spec.chip_seed) s.overrides.push_back("seeds.chip=" + std::to_string(*spec.chip_seed));
  if (spec.noise_seed) s.overrides.push_back("seeds.noise=" + std::to_string(*spec.noise_seed));
  return s;
}

std::string Shard::text() const { return std::to_string(index) + "/" + std::to_string(count); }

Shard parse_shard(const std::string& text, const std::string& where) {
  const size_t slash = text.find('/');
  const auto number = [&](const std::string& t, int64_t& out) {
    if (t.empty() || t.size() > 9 || t.find_first_not_of("0123456789") != std::string::npos) return false;
    out = std::stoll(t);
    return true;
  };
  Shard s;
  if (slash == std::string::npos || !number(text.substr(0, slash), s.index) || !number(text.substr(slash + 1), s.count) ||
      s.count < 1 || s.index >= s.count)
    throw Error(where + ": found \"" + scenes::printable(text) + "\", expected I/N with 0 <= I < N <= 999999999 (shard I of N, e.g. 0/4)");
  return s;
}

std::optional<Shard> shard_from_environment() {
  const auto env = [](const char* name) -> std::optional<std::string> {
    const char* v = std::getenv(name);
    return v && *v ? std::optional<std::string>(v) : std::nullopt;
  };
  const auto integer = [](const std::string& name, const std::string& v) {
    if (v.empty() || v.size() > 9 || v.find_first_not_of("0123456789") != std::string::npos)
      throw Error("environment variable " + name + "=\"" + scenes::printable(v) + "\": expected a non-negative integer");
    return std::stoll(v);
  };
  if (const auto id = env("SLURM_ARRAY_TASK_ID")) {
    const auto count = env("SLURM_ARRAY_TASK_COUNT");
    if (!count) throw Error("SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not: run as a Slurm job array (sbatch --array=0-N)");
    const int64_t min = env("SLURM_ARRAY_TASK_MIN") ? integer("SLURM_ARRAY_TASK_MIN", *env("SLURM_ARRAY_TASK_MIN")) : 0;
    const int64_t step = env("SLURM_ARRAY_TASK_STEP") ? integer("SLURM_ARRAY_TASK_STEP", *env("SLURM_ARRAY_TASK_STEP")) : 1;
    const int64_t i = integer("SLURM_ARRAY_TASK_ID", *id), n = integer("SLURM_ARRAY_TASK_COUNT", *count);
    if (n < 1)
      throw Error("Slurm job array: SLURM_ARRAY_TASK_COUNT=" + std::to_string(n) + "; expected a job array of at least one task (sbatch --array=0-N)");
    if (step < 1 || i < min || (i - min) % step != 0 || (i - min) / step >= n)
      throw Error("Slurm job array: SLURM_ARRAY_TASK_ID=" + std::to_string(i) + ", MIN=" + std::to_string(min) + ", STEP=" +
                  std::to_string(step) + ", COUNT=" + std::to_string(n) +
                  " do not make a task index in [0, COUNT): use a contiguous array such as --array=0-" + std::to_string(n - 1));
    // An array of uneven steps (--array=0,2,5) gives STEP 1 or its first step, and a MAX that the others
    // do not make: its tasks would run some shards twice and others never.
    if (const auto max = env("SLURM_ARRAY_TASK_MAX"); max && integer("SLURM_ARRAY_TASK_MAX", *max) != min + step * (n - 1))
      throw Error("Slurm job array: SLURM_ARRAY_TASK_MIN=" + std::to_string(min) + ", MAX=" + *max + ", STEP=" + std::to_string(step) +
                  ", COUNT=" + std::to_string(n) + " are not an evenly spaced array (--array=0,2,5, for example, is uneven), whose tasks would "
                  "run some shards and never others: use --array=0-" + std::to_string(n - 1) + ", or START-END:STEP");
    return Shard{(i - min) / step, n};
  }
  // JOB_COMPLETIONS (which the Job's env sets) without an index: not an Indexed Job, or an empty index; every
  // pod would run the whole dataset (it was taken silently as shard 0 of 1)
  if (env("JOB_COMPLETIONS") && !env("JOB_COMPLETION_INDEX"))
    throw Error("JOB_COMPLETIONS is set but JOB_COMPLETION_INDEX is " + std::string(std::getenv("JOB_COMPLETION_INDEX") ? "empty" : "not") +
                ": run as a Kubernetes Indexed Job (completionMode: Indexed, examples/kubernetes/), or unset JOB_COMPLETIONS");
  if (const auto id = env("JOB_COMPLETION_INDEX")) {
    const auto count = env("JOB_COMPLETIONS");
    if (!count)
      throw Error("JOB_COMPLETION_INDEX is set (a Kubernetes Indexed Job) but JOB_COMPLETIONS is not: set it in the Job's "
                  "container env to the Job's completions (examples/kubernetes/)");
    const int64_t i = integer("JOB_COMPLETION_INDEX", *id), n = integer("JOB_COMPLETIONS", *count);
    if (n < 1 || i >= n)
      throw Error("Kubernetes Indexed Job: JOB_COMPLETION_INDEX=" + std::to_string(i) + " is not below JOB_COMPLETIONS=" + std::to_string(n));
    return Shard{i, n};
  }
  return std::nullopt;
}

std::string ranges_text(const std::vector<int64_t>& indices) {
  std::string out;
  for (size_t i = 0; i < indices.size();) {
    size_t j = i;
    while (j + 1 < indices.size() && indices[j + 1] == indices[j] + 1) ++j;
    if (!out.empty()) out += ", ";
    out += std::to_string(indices[i]);
    if (j > i) out.append("-").append(std::to_string(indices[j]));
    i = j + 1;
  }
  return out;
}

std::string dataset_reference_markdown() {
  std::string o = "| key | type | default | meaning |\n|---|---|---|---|\n";
  for (const DatasetKey& k : dataset_keys())
    o += "| `" + k.key + "` | " + k.type + " | " + (k.def == "required" ? "required" : "`" + k.def + "`") + " | " + k.doc + " |\n";
  o += "\n| distribution | written | draws |\n|---|---|---|\n"
       "| uniform | `{\"uniform\": [a, b]}` | a number in [a, b) |\n"
       "| log-uniform | `{\"log_uniform\": [a, b]}` | a number in [a, b) whose logarithm is uniform (0 < a < b) |\n"
       "| normal | `{\"normal\": [mean, sigma], \"min\": lo, \"max\": hi}` | a normal number; with min and/or max, truncated to [min, max] by rejection (which must keep at least 0.1 % of the mass). A side without min or max reaches any value: on a key with a bound on that side (a power, a count) it is refused, asking for min or max |\n"
       "| uniform integer | `{\"uniform_int\": [a, b]}` | an integer in [a, b], both included |\n"
       "| choice | `{\"choice\": [v1, v2, ...]}` | one of the values (any JSON: numbers, strings, arrays), with equal probability |\n";
  return o;
}

std::string dataset_schema_json() {
  const ojson seed = {{"type", "integer"}, {"minimum", 0}, {"maximum", 9007199254740992.0}};
  const ojson pair = {{"type", "array"}, {"items", {{"type", "number"}}}, {"minItems", 2}, {"maxItems", 2}};
  const auto dist = [&](const char* name, const char* doc, bool bounds) {
    ojson d = {{"type", "object"}, {"description", doc}, {"required", {name}}, {"additionalProperties", false},
               {"properties", {{name, pair}}}};
    if (bounds) d["properties"]["min"] = {{"type", "number"}}, d["properties"]["max"] = {{"type", "number"}};
    return d;
  };
  ojson choice = {{"type", "object"}, {"description", "one of the values, with equal probability"}, {"required", {"choice"}},
                  {"additionalProperties", false}, {"properties", {{"choice", {{"type", "array"}, {"minItems", 1}}}}}};
  ojson root = {
      {"$schema", "https://json-schema.org/draft/2020-12/schema"},
      {"title", "spadgen dataset file"},
      {"description", "A benchmark dataset as variations of scene files (docs/datasets.md). Keys of set, grid and random are "
                      "scene-file keys written as --set writes them (docs/scene-file.md)."},
      {"type", "object"},
      {"additionalProperties", false},
      {"required", {"scenes"}},
      {"properties",
       {{"description", {{"type", "string"}, {"default", ""}}},
        {"seed", seed},
        {"scenes", {{"type", "array"}, {"minItems", 1}, {"items", {{"type", "string"}, {"minLength", 1}}}}},
        {"samples", {{"type", {"integer", "null"}}, {"minimum", 1}, {"maximum", 1e8}, {"default", nullptr}}},
        {"set", {{"type", "object"}}},
        {"grid", {{"type", "object"}, {"additionalProperties", {{"type", "array"}, {"minItems", 1}}}}},
        {"random",
         {{"type", "object"},
          {"additionalProperties",
           {{"oneOf", {dist("uniform", "a number in [a, b)", false), dist("log_uniform", "a number in [a, b) with a uniform logarithm", false),
                       dist("normal", "[mean, sigma], truncated to [min, max] when given", true),
                       dist("uniform_int", "an integer in [a, b], both included", false), choice}}}}}},
        {"seeds",
         {{"type", "object"},
          {"additionalProperties", false},
          {"properties",
           {{"light", {{"oneOf", {seed, {{"const", "per_sample"}}}}}},
            {"chip", {{"oneOf", {seed, {{"const", "per_sample"}}}}}},
            {"noise", {{"oneOf", {seed, {{"const", "per_sample"}}}}}}}}}},
        {"repeats", {{"type", "integer"}, {"minimum", 1}, {"maximum", 1000}, {"default", 1}}}}}};
  root["properties"]["seed"]["default"] = 0;
  // The descriptions of the reference table.
  for (const DatasetKey& k : dataset_keys())
    if (k.key.find('.') == std::string::npos) root["properties"][k.key]["description"] = k.doc;
  return root.dump(2) + "\n";
}

}  // namespace spadgen::datasets
