// Scene files: one schema declares every key (type, unit, default, range, meaning); parsing checks the
// user's JSON against it, applies `--set` overrides through the same checks, fills the defaults and
// converts to SI. A typo must never become a silently wrong dataset, so unknown keys are errors.
#include "scene_file.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include "core/error.h"
#include "core/units.h"

namespace spadgen::scenes {
namespace {

using json = nlohmann::json;
using ojson = nlohmann::ordered_json;

enum class Type { Number, Integer, Bool, String, Enum, Vec3, Rect };

struct Key {
  std::string path;  // JSON pointer, e.g. "/camera/f_number"
  Type type;
  json def;          // default; null for nullable keys without one; "required" keys have none
  double lo = -std::numeric_limits<double>::infinity();
  double hi = std::numeric_limits<double>::infinity();
  bool lo_open = false;  // lo is exclusive
  std::vector<std::string> choices;
  bool nullable = false;
  bool required = false;
  std::string unit;
  std::string doc;
};

Key make(std::string path, Type type, json def) {
  Key k;
  k.path = std::move(path), k.type = type, k.def = std::move(def);
  return k;
}

Key number(std::string path, double def, double lo, double hi, std::string unit, std::string doc,
           bool lo_open = false) {
  Key k = make(std::move(path), Type::Number, def);
  k.lo = lo, k.hi = hi, k.lo_open = lo_open, k.unit = std::move(unit), k.doc = std::move(doc);
  return k;
}
Key optional_number(std::string path, double lo, double hi, std::string unit, std::string doc, bool lo_open = false) {
  Key k = number(std::move(path), 0, lo, hi, std::move(unit), std::move(doc), lo_open);
  k.def = nullptr, k.nullable = true;
  return k;
}
Key integer(std::string path, int64_t def, double lo, double hi, std::string unit, std::string doc) {
  Key k = make(std::move(path), Type::Integer, def);
  k.lo = lo, k.hi = hi, k.unit = std::move(unit), k.doc = std::move(doc);
  return k;
}
Key boolean(std::string path, bool def, std::string doc) {
  Key k = make(std::move(path), Type::Bool, def);
  k.doc = std::move(doc);
  return k;
}
Key string(std::string path, std::string def, std::string doc) {
  Key k = make(std::move(path), Type::String, def);
  k.doc = std::move(doc);
  return k;
}
Key choice(std::string path, std::string def, std::vector<std::string> choices, std::string doc) {
  Key k = make(std::move(path), Type::Enum, def);
  k.choices = std::move(choices), k.doc = std::move(doc);
  return k;
}
Key vec3(std::string path, std::array<double, 3> def, std::string unit, std::string doc) {
  Key k = make(std::move(path), Type::Vec3, json::array({def[0], def[1], def[2]}));
  k.unit = std::move(unit), k.doc = std::move(doc);
  return k;
}
Key rect(std::string path, std::string doc) {
  Key k = make(std::move(path), Type::Rect, nullptr);
  k.nullable = true, k.unit = "px", k.doc = std::move(doc);
  return k;
}

void add_pixel_type(std::vector<Key>& s, const std::string& name, const PixelTypeConfig& d) {
  const std::string p = "/sensor/" + name + "/";
  s.push_back(number(p + "fill_factor", d.fill_factor, 0, 1, "", "fraction of the pixel area that is photosensitive", true));
  s.push_back(number(p + "pdp_peak", d.pdp_peak, 0, 1, "", "peak photon detection probability", true));
  s.push_back(number(p + "pdp_peak_wavelength_nm", d.pdp_peak_wavelength_m / kNm, 200, 2000, "nm", "wavelength of the PDP peak"));
  s.push_back(string(p + "pdp_csv", d.pdp_csv, "table of (wavelength_nm, PDP) replacing the built-in curve; relative to the scene file; \"\" = built-in curve scaled to pdp_peak"));
  s.push_back(number(p + "pdp_nonuniformity", d.pdp_nonuniformity, 0, 0.5, "", "relative spread (sigma) of PDP across pixels"));
  s.push_back(number(p + "dcr_median_cps", d.dcr_median_cps, 0, 1e7, "counts/s", "median dark count rate at room temperature (25 C)"));
  s.push_back(number(p + "dcr_log_sigma", d.dcr_log_sigma, 0, 5, "", "spread (sigma of the natural log) of the main DCR population"));
  s.push_back(number(p + "hot_pixel_fraction", d.hot_pixel_fraction, 0, 1, "", "fraction of hot pixels (the DCR tail)"));
  s.push_back(number(p + "hot_pixel_factor", d.hot_pixel_factor, 1, 1e6, "", "median hot-pixel DCR divided by the median DCR"));
  s.push_back(number(p + "crosstalk_probability", d.crosstalk_probability, 0, 0.5, "", "probability that a detection fires a given neighbour"));
  s.push_back(boolean(p + "single_avalanche_per_frame", d.single_avalanche_per_frame, "the pixel stops after its first avalanche in a frame (the paper's pixel B feedback)"));
}

// Every key of a scene file. Defaults are the paper's camera and its 3D experiment.
const std::vector<Key>& schema() {
  static const std::vector<Key> s = [] {
    const RunConfig d;
    std::vector<Key> k;
    Key gltf = string("/gltf", "", "the glTF 2.0 file (.gltf or .glb) of the scene, relative to the scene file");
    gltf.required = true, gltf.def = nullptr;
    k.push_back(gltf);
    k.push_back(string("/gltf_scene", "", "name of the glTF scene to use; \"\" = the file's default scene"));
    k.push_back(string("/description", "", "free text, copied into metadata.json"));
    k.push_back(integer("/seed", 1, 0, 9.007199254740992e15, "", "seed of every random stream (overridden by --seed)"));

    const CameraConfig& c = d.camera;
    k.push_back(string("/camera/gltf_camera", "", "name of a glTF camera node to use instead of position/look_at/up and the field of view; \"\" = defined here"));
    k.push_back(vec3("/camera/position_m", c.position_m, "m", "camera centre (world, glTF frame: +Y up)"));
    k.push_back(vec3("/camera/look_at_m", c.look_at_m, "m", "point the optical axis passes through"));
    k.push_back(vec3("/camera/up", c.up, "", "up direction (world); need not be orthogonal to the axis"));
    k.push_back(integer("/camera/width_px", c.width_px, 1, 16384, "px", "sensor columns"));
    k.push_back(integer("/camera/height_px", c.height_px, 1, 16384, "px", "sensor rows (500: one half of the paper's chip; 1000: the full chip)"));
    k.push_back(number("/camera/pixel_pitch_um", c.pixel_pitch_m / kUm, 0, 1000, "um", "pixel pitch", true));
    k.push_back(number("/camera/focal_length_mm", c.focal_length_m / kMm, 0, 10000, "mm", "lens focal length (ignored when vertical_fov_deg is set)", true));
    k.push_back(optional_number("/camera/vertical_fov_deg", 0, 179, "deg", "vertical field of view; null = from focal_length_mm", true));
    k.push_back(number("/camera/f_number", c.f_number, 0.5, 64, "", "lens f-number N (aperture diameter = f / N)"));
    k.push_back(number("/camera/optics_transmission", c.optics_transmission, 0, 1, "", "fraction of the light the lens (and any filter) passes", true));
    k.push_back(rect("/camera/crop", "[x0, y0, width, height] region of interest; null = the whole sensor"));

    const LaserConfig& l = d.laser;
    k.push_back(number("/laser/average_power_mW", l.average_power_W / kMm, 0, 1e9, "mW", "average optical power", false));
    k.push_back(number("/laser/repetition_rate_MHz", l.repetition_rate_Hz / 1e6, 0, 1e5, "MHz", "pulse repetition rate", true));
    k.push_back(number("/laser/wavelength_nm", l.wavelength_m / kNm, 200, 2000, "nm", "vacuum wavelength"));
    k.push_back(number("/laser/pulse_fwhm_ps", l.pulse_fwhm_s / kPs, 0, 1e6, "ps", "Gaussian pulse width (full width at half maximum)", true));
    k.push_back(string("/laser/pulse_shape_csv", l.pulse_shape_csv, "table of (time_ps, relative power) replacing the Gaussian; relative to the scene file"));
    k.push_back(number("/laser/emission_delay_ns", l.emission_delay_s / kNs, -1e6, 1e6, "ns", "fixed delay from the laser trigger to the pulse's emission (cables, driver)"));
    k.push_back(choice("/laser/beam", l.beam, {"flood", "cone", "gltf_light"}, "flood: uniform over a cone just covering the field of view; cone: uniform over half_angle_deg; gltf_light: a KHR_lights_punctual light of the scene"));
    k.push_back(number("/laser/half_angle_deg", 10.0, 0, 180, "deg", "half-angle of the beam when beam is \"cone\"", true));
    k.push_back(vec3("/laser/offset_m", l.offset_m, "m", "emitter position relative to the camera centre, in camera coordinates (x right, y up, -z forward)"));
    k.push_back(string("/laser/gltf_light", l.gltf_light, "name of the glTF light used as the laser when beam is \"gltf_light\""));

    const AmbientConfig& a = d.ambient;
    k.push_back(number("/ambient/illuminance_lux", a.illuminance_lux, 0, 1e6, "lux", "uniform environment illuminance (equal-energy spectrum); see docs/scene-file.md for the conversion"));
    k.push_back(optional_number("/ambient/spectral_irradiance_W_m2_nm", 0, 1e3, "W/m^2/nm", "the uniform environment in radiometric units (irradiance per nm on a surface facing it, flat over the band); null = from illuminance_lux"));
    k.push_back(number("/ambient/wavelength_nm", a.wavelength_m / kNm, 200, 2000, "nm", "centre of the ambient band the camera sees"));
    k.push_back(number("/ambient/bandwidth_nm", a.bandwidth_m / kNm, 0, 2000, "nm", "width of that band (optical filter or sensor response)", true));
    k.push_back(boolean("/ambient/gltf_lights", a.gltf_lights, "the glTF punctual lights add to the ambient light"));

    const SensorConfig& se = d.sensor;
    k.push_back(choice("/sensor/preset", se.preset, {"pixel_A", "pixel_B", "full_chip"}, "pixel design of every row: pixel_A, pixel_B, or full_chip (pixel A in the top half, pixel B in the bottom half)"));
    add_pixel_type(k, "pixel_A", se.pixel_A);
    add_pixel_type(k, "pixel_B", se.pixel_B);
    const GateConfig& g = se.gate;
    k.push_back(number("/sensor/gate/length_ns", g.length_s / kNs, 0, 1e6, "ns", "gate length, 50 % to 50 %", true));
    k.push_back(number("/sensor/gate/rise_ps", g.rise_s / kPs, 0, 1e6, "ps", "rise time, 10 % to 90 %"));
    k.push_back(number("/sensor/gate/fall_ps", g.fall_s / kPs, 0, 1e6, "ps", "fall time, 90 % to 10 %"));
    k.push_back(choice("/sensor/gate/edge_shape", g.edge_shape, {"linear", "smooth"}, "shape of the parametric edges"));
    k.push_back(string("/sensor/gate/profile_csv", g.profile_csv, "measured gate profile, table of (time_ps, response), replacing the parametric one; relative to the scene file"));
    k.push_back(number("/sensor/gate/delay_ns", g.delay_s / kNs, -1e6, 1e6, "ns", "fixed delay from the laser trigger to the gate opening at position 0"));
    k.push_back(number("/sensor/gate/skew_fwhm_ps", g.skew_fwhm_s / kPs, 0, 1e6, "ps", "spread of the gate position across the array (FWHM)"));
    k.push_back(number("/sensor/gate/length_fwhm_ps", g.length_fwhm_s / kPs, 0, 1e6, "ps", "spread of the gate length across the array (FWHM)"));
    k.push_back(string("/sensor/gate/maps_exr", g.maps_exr, "EXR with channels skew_ps and length_ps (full sensor size) replacing the generated maps; relative to the scene file"));
    k.push_back(number("/sensor/jitter_fwhm_ps", g.jitter_fwhm_s / kPs, 0, 1e6, "ps", "SPAD timing jitter (Gaussian FWHM)"));
    k.push_back(number("/sensor/temperature_C", se.temperature_C, -100, 150, "C", "sensor temperature (dark counts rise above about 30 C)"));
    k.push_back(boolean("/sensor/dark_counts", se.dark_counts, "model dark counts"));
    k.push_back(boolean("/sensor/crosstalk", se.crosstalk, "model optical/electrical crosstalk between neighbours"));
    k.push_back(boolean("/sensor/gate_skew", se.skew, "per-pixel gate position and length variation"));
    k.push_back(boolean("/sensor/pdp_nonuniformity", se.pdp_nonuniformity, "per-pixel PDP variation"));

    const AcquisitionConfig& q = d.acquisition;
    k.push_back(choice("/acquisition/mode", q.mode, {"gate_sweep", "intensity"}, "gate_sweep: 3D time-gated sweep; intensity: 2D intensity imaging"));
    k.push_back(integer("/acquisition/frames", q.frames, 1, 65535, "", "binary frames summed per gate position (gate_sweep) or per image (intensity)"));
    k.push_back(number("/acquisition/frame_rate_fps", q.frame_rate_Hz, 0, 1e7, "frames/s", "binary frame rate, for time stamps and exposure checks", true));
    k.push_back(integer("/acquisition/cycles_per_frame", q.cycles_per_frame, 1, 1e12, "", "laser cycles (gate openings) integrated in one binary frame (gate_sweep)"));
    k.push_back(number("/acquisition/gate_sweep/start_ns", q.gate_sweep.start_s / kNs, -1e6, 1e6, "ns", "first gate position, relative to the laser trigger"));
    k.push_back(number("/acquisition/gate_sweep/stop_ns", q.gate_sweep.stop_s / kNs, -1e6, 1e6, "ns", "last gate position (included when on the step grid)"));
    k.push_back(number("/acquisition/gate_sweep/step_ps", q.gate_sweep.step_s / kPs, 0, 1e9, "ps", "gate position step (36 ps: the paper's LSB, 5.4 mm)", true));
    k.push_back(choice("/acquisition/intensity/exposure", q.intensity.exposure, {"single", "dual"}, "single exposure, or dual exposure interleaving tau_S and tau_L"));
    k.push_back(number("/acquisition/intensity/exposure_us", q.intensity.exposure_s / kUs, 0, 1e9, "us", "global exposure per frame (single), or the short exposure tau_S (dual)", true));
    k.push_back(number("/acquisition/intensity/dual_ratio", q.intensity.dual_ratio, 1, 1e6, "", "tau_L / tau_S in dual exposure"));
    k.push_back(boolean("/acquisition/intensity/laser_on", q.intensity.laser_on, "add the laser's mean photon rate to the ambient light in intensity mode"));

    const RenderConfig& r = d.render;
    k.push_back(integer("/render/samples_per_pixel", r.samples_per_pixel, 1, 1e7, "", "paths per pixel"));
    k.push_back(integer("/render/max_bounces", r.max_bounces, 1, 64, "", "surface interactions per path (1 = direct light only)"));
    k.push_back(integer("/render/russian_roulette_from", r.russian_roulette_from, 1, 64, "", "bounce from which paths may be stopped by Russian roulette"));
    k.push_back(number("/render/time_bin_ps", r.time_bin_s / kPs, 0, 1e6, "ps", "transient bin width", true));
    k.push_back(optional_number("/render/window_start_ns", -1e6, 1e6, "ns", "start of the transient window; null = derived from the acquisition"));
    k.push_back(optional_number("/render/window_stop_ns", -1e6, 1e6, "ns", "end of the transient window; null = derived from the acquisition"));
    k.push_back(integer("/render/tile_size_px", r.tile_size, 8, 4096, "px", "tile edge (a multiple of 8); outputs do not depend on it"));
    k.push_back(integer("/render/max_layers", r.max_layers, 1, 64, "", "surfaces recorded per pixel in the ground truth"));
    k.push_back(boolean("/render/split_direct_indirect", r.split_direct_indirect, "also keep the indirect part of the transient separately"));

    const OutputsConfig& o = d.outputs;
    k.push_back(boolean("/outputs/ground_truth", o.ground_truth, "write ground_truth.exr"));
    k.push_back(boolean("/outputs/transient", o.transient, "write transient.npy (H, W, T) float32 photons per pulse per bin"));
    k.push_back(rect("/outputs/transient_crop", "[x0, y0, width, height] (sensor pixels) of transient.npy; null = the whole image"));
    k.push_back(boolean("/outputs/expected_counts", o.expected_counts, "write expected_counts.npy (noise-free)"));
    k.push_back(boolean("/outputs/counts", o.counts, "write counts.npy (sampled)"));
    k.push_back(boolean("/outputs/frames", o.frames, "write frames.npy (binary frames, bit-packed); large"));
    k.push_back(boolean("/outputs/previews", o.previews, "write previews/*.png"));
    return k;
  }();
  return s;
}

const Key* find_key(const std::string& path) {
  for (const Key& k : schema())
    if (k.path == path) return &k;
  return nullptr;
}

// True when some key lies below `path` (it is a section).
bool is_section(const std::string& path) {
  const std::string prefix = path + "/";
  for (const Key& k : schema())
    if (k.path.compare(0, prefix.size(), prefix) == 0) return true;
  return false;
}

size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diag = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

std::string parent_of(const std::string& path) { return path.substr(0, path.rfind('/')); }
std::string leaf_of(const std::string& path) { return path.substr(path.rfind('/') + 1); }

// The children (keys and sections) the schema allows directly under `parent`.
std::vector<std::string> children_of(const std::string& parent) {
  std::vector<std::string> out;
  const std::string prefix = parent + "/";
  for (const Key& k : schema()) {
    if (k.path.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string rest = k.path.substr(prefix.size());
    const std::string child = prefix + rest.substr(0, rest.find('/'));
    if (std::find(out.begin(), out.end(), child) == out.end()) out.push_back(child);
  }
  return out;
}

// "did you mean" for an unknown path: the closest sibling, else a key of the same name elsewhere.
std::string suggestion(const std::string& path) {
  const std::string leaf = leaf_of(path);
  std::string best;
  size_t best_d = std::max<size_t>(2, leaf.size() / 3) + 1;
  for (const std::string& c : children_of(parent_of(path))) {
    const size_t dist = edit_distance(leaf, leaf_of(c));
    if (dist < best_d) best_d = dist, best = c;
  }
  if (best.empty())
    for (const Key& k : schema())
      if (leaf_of(k.path) == leaf) return "; did you mean " + k.path + "?";
  if (best.empty()) {
    std::string list;
    for (const std::string& c : children_of(parent_of(path))) list += (list.empty() ? "" : ", ") + leaf_of(c);
    return list.empty() ? std::string() : "; the keys here are: " + list;
  }
  return "; did you mean " + best + "?";
}

std::string describe_json(const json& v) {
  std::string s = v.dump();
  if (s.size() > 60) s = s.substr(0, 57) + "...";
  switch (v.type()) {
    case json::value_t::string: return s + " (a string)";
    case json::value_t::boolean: return s + " (a boolean)";
    case json::value_t::number_integer:
    case json::value_t::number_unsigned: return s + " (an integer)";
    case json::value_t::number_float: return s + " (a number)";
    case json::value_t::array: return s + " (an array)";
    case json::value_t::object: return s + " (an object)";
    case json::value_t::null: return "null";
    default: return s;
  }
}

std::string format_bound(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}

std::string expected_text(const Key& k) {
  std::string range;
  const bool has_lo = std::isfinite(k.lo), has_hi = std::isfinite(k.hi);
  if (has_lo && has_hi)
    range = std::string(k.lo_open ? " in (" : " in [") + format_bound(k.lo) + ", " + format_bound(k.hi) + "]";
  else if (has_lo)
    range = std::string(k.lo_open ? " > " : " >= ") + format_bound(k.lo);
  std::string unit = k.unit.empty() ? "" : " " + k.unit;
  std::string e;
  switch (k.type) {
    case Type::Number: e = "a number" + range + unit; break;
    case Type::Integer: e = "an integer" + range + unit; break;
    case Type::Bool: e = "true or false"; break;
    case Type::String: e = "a string"; break;
    case Type::Enum: {
      e = "one of";
      for (size_t i = 0; i < k.choices.size(); ++i) e += (i ? ", \"" : " \"") + k.choices[i] + "\"";
      break;
    }
    case Type::Vec3: e = "an array of 3 numbers" + unit; break;
    case Type::Rect: e = "[x0, y0, width, height] (integers >= 0, width and height > 0)"; break;
  }
  if (k.nullable) e += ", or null";
  return e;
}

bool in_range(const Key& k, double v) {
  if (!std::isfinite(v)) return false;
  if (k.lo_open ? !(v > k.lo) : !(v >= k.lo)) return false;
  return v <= k.hi;
}

// Checks one value against its key; returns "" when it fits.
bool value_fits(const Key& k, const json& v) {
  if (v.is_null()) return k.nullable;
  switch (k.type) {
    case Type::Number: return v.is_number() && in_range(k, v.get<double>());
    case Type::Integer: {
      if (!v.is_number()) return false;
      const double d = v.get<double>();
      return std::floor(d) == d && in_range(k, d);
    }
    case Type::Bool: return v.is_boolean();
    case Type::String: return v.is_string();
    case Type::Enum:
      return v.is_string() && std::find(k.choices.begin(), k.choices.end(), v.get<std::string>()) != k.choices.end();
    case Type::Vec3:
      return v.is_array() && v.size() == 3 &&
             std::all_of(v.begin(), v.end(), [](const json& e) { return e.is_number() && std::isfinite(e.get<double>()); });
    case Type::Rect: {
      if (!v.is_array() || v.size() != 4) return false;
      for (size_t i = 0; i < 4; ++i) {
        if (!v[i].is_number_integer() && !v[i].is_number_unsigned()) return false;
        if (v[i].get<int64_t>() < (i < 2 ? 0 : 1) || v[i].get<int64_t>() > 1'000'000) return false;
      }
      return true;
    }
  }
  return false;
}

struct Checker {
  std::string file;
  std::vector<std::string> errors;

  void error(const std::string& where, const std::string& what) { errors.push_back(file + ": " + where + ": " + what); }

  void walk(const json& node, const std::string& path) {
    for (auto it = node.begin(); it != node.end(); ++it) {
      const std::string p = path + "/" + it.key();
      if (const Key* k = find_key(p)) {
        if (!value_fits(*k, it.value()))
          error(p, "found " + describe_json(it.value()) + ", expected " + expected_text(*k) + " (" + k->doc + ")");
      } else if (is_section(p)) {
        if (!it.value().is_object())
          error(p, "found " + describe_json(it.value()) + ", expected an object (a section of keys)");
        else
          walk(it.value(), p);
      } else {
        error(p, "unknown key" + suggestion(p));
      }
    }
  }
};

json parse_json_text(const std::string& text, const std::string& file) {
  try {
    return json::parse(text, nullptr, /*allow_exceptions=*/true, /*ignore_comments=*/true);
  } catch (const json::parse_error& e) {
    // Turn the byte offset into line:column, which is what an editor shows.
    size_t line = 1, col = 1;
    for (size_t i = 0; i + 1 < e.byte && i < text.size(); ++i) {
      if (text[i] == '\n') ++line, col = 1;
      else ++col;
    }
    std::string what = e.what();
    if (const size_t pos = what.find("syntax error"); pos != std::string::npos) what = what.substr(pos);
    throw Error(file + ":" + std::to_string(line) + ":" + std::to_string(col) + ": not valid JSON: " + what);
  }
}

std::string read_text_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error("cannot read scene file " + path + ": " + std::strerror(errno));
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// "camera.f_number=2.8" -> (/camera/f_number, 2.8). A value that is not JSON is taken as a string.
void apply_override(json& doc, const std::string& assignment, Checker& chk) {
  const size_t eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0) {
    chk.errors.push_back(chk.file + ": --set " + assignment + ": expected KEY=VALUE, e.g. laser.average_power_mW=5");
    return;
  }
  std::string key = assignment.substr(0, eq);
  const std::string text = assignment.substr(eq + 1);
  std::string path = "/" + key;
  std::replace(path.begin(), path.end(), '.', '/');
  const Key* k = find_key(path);
  if (!k) {
    chk.errors.push_back(chk.file + ": --set " + key + ": " + path + ": " +
                         (is_section(path) ? "is a section, not a key" : "unknown key" + suggestion(path)));
    return;
  }
  json value;
  try {
    value = json::parse(text, nullptr, true, true);
  } catch (const json::parse_error&) {
    value = text;
  }
  if (k->type == Type::String && !value.is_string() && !value.is_null()) value = text;  // names that look like numbers
  // Create intermediate sections; a non-object in the way is reported by the walk.
  json* node = &doc;
  std::string at;
  size_t start = 1;
  while (true) {
    const size_t slash = path.find('/', start);
    const std::string part = path.substr(start, slash == std::string::npos ? std::string::npos : slash - start);
    at += "/" + part;
    if (slash == std::string::npos) {
      (*node)[part] = value;
      break;
    }
    if (!node->contains(part)) (*node)[part] = json::object();
    if (!(*node)[part].is_object()) {
      chk.errors.push_back(chk.file + ": --set " + key + ": " + at + " is not a section in the scene file");
      return;
    }
    node = &(*node)[part];
    start = slash + 1;
  }
}

// Defaults filled, in schema order.
ojson resolve(const json& doc) {
  ojson out = ojson::object();
  for (const Key& k : schema()) {
    const json::json_pointer ptr(k.path);
    json v = doc.contains(ptr) ? doc.at(ptr) : k.def;
    // Nested sections are created in schema order as their first key appears.
    ojson* node = &out;
    size_t start = 1;
    while (true) {
      const size_t slash = k.path.find('/', start);
      const std::string part = k.path.substr(start, slash == std::string::npos ? std::string::npos : slash - start);
      if (slash == std::string::npos) {
        (*node)[part] = ojson::parse(v.dump());
        break;
      }
      if (!node->contains(part)) (*node)[part] = ojson::object();
      node = &(*node)[part];
      start = slash + 1;
    }
  }
  return out;
}

std::optional<PixelRect> to_rect(const ojson& v) {
  if (v.is_null()) return std::nullopt;
  return PixelRect{v[0].get<int>(), v[1].get<int>(), v[2].get<int>(), v[3].get<int>()};
}
Vec3d to_vec3(const ojson& v) { return {v[0].get<double>(), v[1].get<double>(), v[2].get<double>()}; }

PixelTypeConfig to_pixel_type(const ojson& p) {
  PixelTypeConfig t;
  t.fill_factor = p["fill_factor"];
  t.pdp_peak = p["pdp_peak"];
  t.pdp_peak_wavelength_m = p["pdp_peak_wavelength_nm"].get<double>() * kNm;
  t.pdp_csv = p["pdp_csv"];
  t.pdp_nonuniformity = p["pdp_nonuniformity"];
  t.dcr_median_cps = p["dcr_median_cps"];
  t.dcr_log_sigma = p["dcr_log_sigma"];
  t.hot_pixel_fraction = p["hot_pixel_fraction"];
  t.hot_pixel_factor = p["hot_pixel_factor"];
  t.crosstalk_probability = p["crosstalk_probability"];
  t.single_avalanche_per_frame = p["single_avalanche_per_frame"];
  return t;
}

std::optional<double> opt_scaled(const ojson& v, double scale) {
  if (v.is_null()) return std::nullopt;
  return v.get<double>() * scale;
}

// A path relative to the scene file, made absolute; "" stays "".
std::string relative_to(const std::string& scene_dir, const std::string& p) {
  if (p.empty()) return p;
  std::filesystem::path q(p);
  if (q.is_relative()) q = std::filesystem::path(scene_dir) / q;
  return q.lexically_normal().string();
}

RunConfig to_config(const ojson& r, const std::string& scene_path) {
  RunConfig c;
  const std::string dir = scene_path.empty() ? std::string(".")
                                             : std::filesystem::absolute(scene_path).parent_path().string();
  c.scene_file = scene_path.empty() ? "" : std::filesystem::absolute(scene_path).lexically_normal().string();
  c.gltf_path = relative_to(dir, r["gltf"].get<std::string>());
  c.gltf_scene = r["gltf_scene"];
  c.seed = r["seed"].get<uint64_t>();

  const ojson& cam = r["camera"];
  c.camera.gltf_camera = cam["gltf_camera"];
  c.camera.position_m = to_vec3(cam["position_m"]);
  c.camera.look_at_m = to_vec3(cam["look_at_m"]);
  c.camera.up = to_vec3(cam["up"]);
  c.camera.width_px = cam["width_px"];
  c.camera.height_px = cam["height_px"];
  c.camera.pixel_pitch_m = cam["pixel_pitch_um"].get<double>() * kUm;
  c.camera.focal_length_m = cam["focal_length_mm"].get<double>() * kMm;
  c.camera.vertical_fov_rad = opt_scaled(cam["vertical_fov_deg"], kPi / 180.0);
  c.camera.f_number = cam["f_number"];
  c.camera.optics_transmission = cam["optics_transmission"];
  c.camera.crop = to_rect(cam["crop"]);

  const ojson& la = r["laser"];
  c.laser.average_power_W = la["average_power_mW"].get<double>() * kMm;
  c.laser.repetition_rate_Hz = la["repetition_rate_MHz"].get<double>() * 1e6;
  c.laser.wavelength_m = la["wavelength_nm"].get<double>() * kNm;
  c.laser.pulse_fwhm_s = la["pulse_fwhm_ps"].get<double>() * kPs;
  c.laser.pulse_shape_csv = relative_to(dir, la["pulse_shape_csv"]);
  c.laser.emission_delay_s = la["emission_delay_ns"].get<double>() * kNs;
  c.laser.beam = la["beam"];
  c.laser.half_angle_rad = la["half_angle_deg"].get<double>() * kPi / 180.0;
  c.laser.offset_m = to_vec3(la["offset_m"]);
  c.laser.gltf_light = la["gltf_light"];

  const ojson& am = r["ambient"];
  c.ambient.illuminance_lux = am["illuminance_lux"];
  c.ambient.spectral_irradiance_W_m2_nm = opt_scaled(am["spectral_irradiance_W_m2_nm"], 1.0);
  c.ambient.wavelength_m = am["wavelength_nm"].get<double>() * kNm;
  c.ambient.bandwidth_m = am["bandwidth_nm"].get<double>() * kNm;
  c.ambient.gltf_lights = am["gltf_lights"];

  const ojson& s = r["sensor"];
  c.sensor.preset = s["preset"];
  c.sensor.pixel_A = to_pixel_type(s["pixel_A"]);
  c.sensor.pixel_B = to_pixel_type(s["pixel_B"]);
  c.sensor.pixel_A.pdp_csv = relative_to(dir, c.sensor.pixel_A.pdp_csv);
  c.sensor.pixel_B.pdp_csv = relative_to(dir, c.sensor.pixel_B.pdp_csv);
  const ojson& g = s["gate"];
  c.sensor.gate.length_s = g["length_ns"].get<double>() * kNs;
  c.sensor.gate.rise_s = g["rise_ps"].get<double>() * kPs;
  c.sensor.gate.fall_s = g["fall_ps"].get<double>() * kPs;
  c.sensor.gate.edge_shape = g["edge_shape"];
  c.sensor.gate.profile_csv = relative_to(dir, g["profile_csv"]);
  c.sensor.gate.delay_s = g["delay_ns"].get<double>() * kNs;
  c.sensor.gate.skew_fwhm_s = g["skew_fwhm_ps"].get<double>() * kPs;
  c.sensor.gate.length_fwhm_s = g["length_fwhm_ps"].get<double>() * kPs;
  c.sensor.gate.maps_exr = relative_to(dir, g["maps_exr"]);
  c.sensor.gate.jitter_fwhm_s = s["jitter_fwhm_ps"].get<double>() * kPs;
  c.sensor.temperature_C = s["temperature_C"];
  c.sensor.dark_counts = s["dark_counts"];
  c.sensor.crosstalk = s["crosstalk"];
  c.sensor.skew = s["gate_skew"];
  c.sensor.pdp_nonuniformity = s["pdp_nonuniformity"];

  const ojson& q = r["acquisition"];
  c.acquisition.mode = q["mode"];
  c.acquisition.frames = q["frames"];
  c.acquisition.frame_rate_Hz = q["frame_rate_fps"];
  c.acquisition.cycles_per_frame = q["cycles_per_frame"];
  c.acquisition.gate_sweep.start_s = q["gate_sweep"]["start_ns"].get<double>() * kNs;
  c.acquisition.gate_sweep.stop_s = q["gate_sweep"]["stop_ns"].get<double>() * kNs;
  c.acquisition.gate_sweep.step_s = q["gate_sweep"]["step_ps"].get<double>() * kPs;
  c.acquisition.intensity.exposure = q["intensity"]["exposure"];
  c.acquisition.intensity.exposure_s = q["intensity"]["exposure_us"].get<double>() * kUs;
  c.acquisition.intensity.dual_ratio = q["intensity"]["dual_ratio"];
  c.acquisition.intensity.laser_on = q["intensity"]["laser_on"];

  const ojson& re = r["render"];
  c.render.samples_per_pixel = re["samples_per_pixel"];
  c.render.max_bounces = re["max_bounces"];
  c.render.russian_roulette_from = re["russian_roulette_from"];
  c.render.time_bin_s = re["time_bin_ps"].get<double>() * kPs;
  c.render.window_start_s = opt_scaled(re["window_start_ns"], kNs);
  c.render.window_stop_s = opt_scaled(re["window_stop_ns"], kNs);
  c.render.tile_size = re["tile_size_px"];
  c.render.max_layers = re["max_layers"];
  c.render.split_direct_indirect = re["split_direct_indirect"];

  const ojson& o = r["outputs"];
  c.outputs.ground_truth = o["ground_truth"];
  c.outputs.transient = o["transient"];
  c.outputs.transient_crop = to_rect(o["transient_crop"]);
  c.outputs.expected_counts = o["expected_counts"];
  c.outputs.counts = o["counts"];
  c.outputs.frames = o["frames"];
  c.outputs.previews = o["previews"];
  return c;
}

bool rect_inside(const PixelRect& r, int w, int h) { return r.x0 >= 0 && r.y0 >= 0 && r.x1() <= w && r.y1() <= h; }

// Checks that involve more than one key, in the units the user wrote.
void check_consistency(const RunConfig& c, Checker& chk, std::vector<std::string>& warnings) {
  const auto err = [&](const std::string& key, const std::string& what) { chk.error(key, what); };
  const int w = c.camera.width_px, h = c.camera.height_px;
  const auto rect_text = [](const PixelRect& r) {
    return "[" + std::to_string(r.x0) + ", " + std::to_string(r.y0) + ", " + std::to_string(r.width) + ", " +
           std::to_string(r.height) + "]";
  };
  if (c.camera.crop && !rect_inside(*c.camera.crop, w, h))
    err("/camera/crop", "found " + rect_text(*c.camera.crop) + ", expected a rectangle inside the " +
                            std::to_string(w) + " x " + std::to_string(h) + " sensor");
  if (c.outputs.transient_crop) {
    const PixelRect img = c.camera.crop.value_or(PixelRect{0, 0, w, h});
    const PixelRect& t = *c.outputs.transient_crop;
    if (!(t.x0 >= img.x0 && t.y0 >= img.y0 && t.x1() <= img.x1() && t.y1() <= img.y1()))
      err("/outputs/transient_crop", "found " + rect_text(t) + ", expected a rectangle inside the rendered region " + rect_text(img));
  }
  if (c.render.tile_size % 8 != 0)
    err("/render/tile_size_px", "found " + std::to_string(c.render.tile_size) + ", expected a multiple of 8 (bit-packed frames start on a byte)");
  const Vec3d& p = c.camera.position_m;
  const Vec3d& a = c.camera.look_at_m;
  const Vec3d axis{a[0] - p[0], a[1] - p[1], a[2] - p[2]};
  const double len = std::sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
  const Vec3d& u = c.camera.up;
  const Vec3d cr{axis[1] * u[2] - axis[2] * u[1], axis[2] * u[0] - axis[0] * u[2], axis[0] * u[1] - axis[1] * u[0]};
  if (c.camera.gltf_camera.empty()) {
    if (len <= 0) err("/camera/look_at_m", "equals /camera/position_m; expected a point the camera looks at");
    else if (std::sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]) <= 1e-9 * len)
      err("/camera/up", "is parallel to the viewing direction; expected a direction not along look_at_m - position_m");
  }
  if (c.laser.beam == "gltf_light" && c.laser.gltf_light.empty())
    err("/laser/gltf_light", "is empty, expected the name of a glTF light because /laser/beam is \"gltf_light\"");
  if (c.acquisition.mode == "gate_sweep") {
    if (c.acquisition.gate_sweep.stop_s < c.acquisition.gate_sweep.start_s)
      err("/acquisition/gate_sweep/stop_ns", "is before /acquisition/gate_sweep/start_ns; expected stop >= start");
    const double exposure = static_cast<double>(c.acquisition.cycles_per_frame) / c.laser.repetition_rate_Hz;
    if (exposure > 1.0 / c.acquisition.frame_rate_Hz)
      warnings.push_back("acquisition.cycles_per_frame: " + std::to_string(c.acquisition.cycles_per_frame) +
                         " laser cycles last " + format_bound(exposure / kUs) + " us, longer than one frame at " +
                         format_bound(c.acquisition.frame_rate_Hz) + " fps");
  } else {
    const double longest = c.acquisition.intensity.exposure_s *
                           (c.acquisition.intensity.exposure == "dual" ? c.acquisition.intensity.dual_ratio : 1.0);
    if (longest > 1.0 / c.acquisition.frame_rate_Hz)
      warnings.push_back("acquisition.intensity: an exposure of " + format_bound(longest / kUs) +
                         " us is longer than one frame at " + format_bound(c.acquisition.frame_rate_Hz) + " fps");
  }
  if (c.render.window_start_s.has_value() != c.render.window_stop_s.has_value())
    err("/render/window_stop_ns", "expected render.window_start_ns and render.window_stop_ns both set or both null");
  else if (c.render.window_start_s && *c.render.window_stop_s <= *c.render.window_start_s)
    err("/render/window_stop_ns", "expected a window end after render.window_start_ns");
  if (!std::filesystem::exists(c.gltf_path))
    err("/gltf", "the glTF file " + c.gltf_path + " does not exist; expected a path relative to the scene file");
  for (const auto& [key, file] : {std::pair<std::string, std::string>{"/laser/pulse_shape_csv", c.laser.pulse_shape_csv},
                                  {"/sensor/gate/profile_csv", c.sensor.gate.profile_csv},
                                  {"/sensor/gate/maps_exr", c.sensor.gate.maps_exr},
                                  {"/sensor/pixel_A/pdp_csv", c.sensor.pixel_A.pdp_csv},
                                  {"/sensor/pixel_B/pdp_csv", c.sensor.pixel_B.pdp_csv}})
    if (!file.empty() && !std::filesystem::exists(file))
      err(key, "the file " + file + " does not exist; expected a path relative to the scene file");
}

std::string join_errors(const std::vector<std::string>& errors) {
  std::string out = errors.size() == 1 ? "" : std::to_string(errors.size()) + " errors in the scene file:\n";
  for (size_t i = 0; i < errors.size(); ++i) out += (i ? "\n" : "") + errors[i];
  return out;
}

}  // namespace

ResolvedRun parse_scene_text(const std::string& text, const std::string& path, const std::vector<std::string>& overrides) {
  const std::string file = path.empty() ? "<scene>" : path;
  json doc = parse_json_text(text, file);
  if (!doc.is_object()) throw Error(file + ": expected a JSON object at the top, found " + describe_json(doc));
  Checker chk{file, {}};
  for (const std::string& o : overrides) apply_override(doc, o, chk);
  chk.walk(doc, "");
  for (const Key& k : schema())
    if (k.required && !doc.contains(json::json_pointer(k.path)))
      chk.error(k.path, "missing; expected " + expected_text(k) + " (" + k.doc + ")");
  if (!chk.errors.empty()) throw Error(join_errors(chk.errors));

  ResolvedRun run;
  run.resolved = resolve(doc);
  run.config = to_config(run.resolved, path);
  check_consistency(run.config, chk, run.warnings);
  if (!chk.errors.empty()) throw Error(join_errors(chk.errors));
  return run;
}

ResolvedRun load_scene_file(const std::string& path, const std::vector<std::string>& overrides) {
  return parse_scene_text(read_text_file(path), path, overrides);
}

std::string schema_reference_markdown() {
  std::ostringstream o;
  o << "| key | type | unit | default | valid | meaning |\n|---|---|---|---|---|---|\n";
  for (const Key& k : schema()) {
    std::string type;
    switch (k.type) {
      case Type::Number: type = "number"; break;
      case Type::Integer: type = "integer"; break;
      case Type::Bool: type = "bool"; break;
      case Type::String: type = "string"; break;
      case Type::Enum: type = "choice"; break;
      case Type::Vec3: type = "[x, y, z]"; break;
      case Type::Rect: type = "[x0, y0, w, h]"; break;
    }
    if (k.nullable) type += " or null";
    std::string valid = k.type == Type::Number || k.type == Type::Integer || k.type == Type::Enum ? expected_text(k) : "";
    if (const size_t u = valid.rfind(" " + k.unit); !k.unit.empty() && u != std::string::npos && u + k.unit.size() + 1 == valid.size())
      valid = valid.substr(0, u);
    std::string dotted = k.path.substr(1);
    std::replace(dotted.begin(), dotted.end(), '/', '.');
    o << "| `" << dotted << "` | " << type << " | " << k.unit << " | "
      << (k.required ? std::string("required") : "`" + k.def.dump() + "`") << " | " << valid << " | " << k.doc << " |\n";
  }
  return o.str();
}

}  // namespace spadgen::scenes
