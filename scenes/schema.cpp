#include "schema.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <type_traits>

#include "core/units.h"
#include "scenes/input.h"
#include "scenes/scene_file.h"

namespace spadgen::scenes {
namespace {

using json = nlohmann::json;
using ojson = nlohmann::ordered_json;

// Units as the scene file writes them. A value v in the file is to_si(v) inside; a default is shown as
// from_si of the field's initializer. Both scale the decimal that a double stands for, not the double:
// 13.2 ns is the double nearest 13.2e-9 (as the initializer 13.2e-9 is; 13.2 * 1e-9 or 13.2 / 1e9 can be
// an ulp off), and from_si of it is 13.2. So defaults read 13.2 ns, 10 us and 300 nm (they read
// 10.000000000000002 and 299.99999999999994), a value given as the default is the default, and the
// resolved scene file parses back to the very doubles the run used. (Lambdas, not a template on the
// scale: clang 14, which builds the fuzzing harnesses, has no floating-point template parameters.)
// (times_ten_to: core/units.h)
int decimal_exponent(double scale) { return static_cast<int>(std::lround(-std::log10(scale))); }
#define SCALED_UNIT(name, scale)                                                   \
  Unit {                                                                           \
    name, [](double v) { return times_ten_to(v, -decimal_exponent(scale)); },     \
        [](double v) { return times_ten_to(v, decimal_exponent(scale)); }          \
  }
double deg_to_rad(double v) { return v * kPi / 180.0; }
double rad_to_deg(double v) { return v * 180.0 / kPi; }

constexpr Unit plain(const char* name) { return SCALED_UNIT(name, 1.0); }
constexpr Unit kNone = plain("");
constexpr Unit kMetre = plain("m");
constexpr Unit kPixel = plain("px");
constexpr Unit kUmUnit = SCALED_UNIT("um", kUm);
constexpr Unit kMmUnit = SCALED_UNIT("mm", kMm);
constexpr Unit kNmUnit = SCALED_UNIT("nm", kNm);
constexpr Unit kNsUnit = SCALED_UNIT("ns", kNs);
constexpr Unit kPsUnit = SCALED_UNIT("ps", kPs);
constexpr Unit kUsUnit = SCALED_UNIT("us", kUs);
constexpr Unit kMilliwatt = SCALED_UNIT("mW", kMm);
constexpr Unit kMegahertz = SCALED_UNIT("MHz", 1e6);
constexpr Unit kDegree{"deg", deg_to_rad, rad_to_deg};
#undef SCALED_UNIT

const RunConfig& defaults() {
  static const RunConfig d;
  return d;
}

// A path relative to the scene file, made absolute; "" stays "".
std::string relative_to(const std::string& dir, const std::string& p) {
  if (p.empty()) return p;
  std::filesystem::path q(p);
  if (q.is_relative()) q = std::filesystem::path(dir) / q;
  return normal_path(q.string());
}

struct Range {
  double lo = -std::numeric_limits<double>::infinity();
  double hi = std::numeric_limits<double>::infinity();
  bool lo_open = false;  // lo itself is not allowed
};
constexpr Range closed(double lo, double hi) { return {lo, hi, false}; }
constexpr Range open_closed(double lo, double hi) { return {lo, hi, true}; }  // (lo, hi]
// Coordinates and offsets in the world: 1000 km either way. Embree traces in float and asserts on ray
// origins beyond about 1.8e18; far inside that, float positions past 1e6 m are already coarser than 6 cm.
constexpr Range kWorld = closed(-1e6, 1e6);

Key make(std::string path, Type type, std::string unit, std::string doc) {
  Key k;
  k.path = std::move(path), k.type = type, k.unit = std::move(unit), k.doc = std::move(doc);
  k.pointer = nlohmann::json::json_pointer(k.path);
  return k;
}

// The builders take the field as an accessor, F(RunConfig&) -> T&, usually written with FIELD below.
template <class F>
Key number(std::string path, F field, Unit u, Range r, std::string doc) {
  Key k = make(std::move(path), Type::Number, u.name, std::move(doc));
  k.lo = r.lo, k.hi = r.hi, k.lo_open = r.lo_open;
  using T = std::remove_cvref_t<decltype(field(defaults()))>;
  if constexpr (std::is_same_v<T, std::optional<double>>) {
    const std::optional<double>& d = field(defaults());
    k.nullable = true;
    k.def = d ? json(u.from_si(*d)) : json(nullptr);
    k.set = [field, u](RunConfig& c, const ojson& v, const std::string&) {
      field(c) = v.is_null() ? std::nullopt : std::optional<double>(u.to_si(v.get<double>()));
    };
  } else {
    static_assert(std::is_same_v<T, double>);
    k.def = u.from_si(field(defaults()));
    k.set = [field, u](RunConfig& c, const ojson& v, const std::string&) { field(c) = u.to_si(v.get<double>()); };
  }
  return k;
}

template <class T>
struct is_optional : std::false_type {};
template <class T>
struct is_optional<std::optional<T>> : std::true_type {};

template <class F>
Key integer(std::string path, F field, Unit u, Range r, std::string doc) {
  Key k = make(std::move(path), Type::Integer, u.name, std::move(doc));
  k.lo = r.lo, k.hi = r.hi;
  using T = std::remove_cvref_t<decltype(field(defaults()))>;
  if constexpr (is_optional<T>::value) {
    k.nullable = true;
    const T& d = field(defaults());
    k.def = d ? json(*d) : json(nullptr);
    k.set = [field](RunConfig& c, const ojson& v, const std::string&) {
      field(c) = v.is_null() ? T() : T(v.get<typename T::value_type>());
    };
  } else {
    k.def = field(defaults());
    k.set = [field](RunConfig& c, const ojson& v, const std::string&) { field(c) = v.get<T>(); };
  }
  return k;
}

template <class F>
Key boolean(std::string path, F field, std::string doc) {
  Key k = make(std::move(path), Type::Bool, "", std::move(doc));
  k.def = field(defaults());
  k.set = [field](RunConfig& c, const ojson& v, const std::string&) { field(c) = v.get<bool>(); };
  return k;
}

template <class F>
Key string(std::string path, F field, std::string doc) {
  Key k = make(std::move(path), Type::String, "", std::move(doc));
  k.def = field(defaults());
  k.set = [field](RunConfig& c, const ojson& v, const std::string&) { field(c) = v.get<std::string>(); };
  return k;
}

// A file named relative to the scene file; stored as an absolute path ("" stays "").
template <class F>
Key file(std::string path, F field, std::string doc) {
  Key k = make(std::move(path), Type::Path, "", std::move(doc));
  k.def = field(defaults());
  k.set = [field](RunConfig& c, const ojson& v, const std::string& dir) { field(c) = relative_to(dir, v.get<std::string>()); };
  return k;
}

template <class F>
Key choice(std::string path, F field, std::string doc) {
  using E = std::remove_cvref_t<decltype(field(defaults()))>;
  Key k = make(std::move(path), Type::Enum, "", std::move(doc));
  for (const auto& [name, value] : EnumNames<E>::values) k.choices.emplace_back(name);
  k.def = to_string(field(defaults()));
  k.set = [field](RunConfig& c, const ojson& v, const std::string&) {
    const std::string s = v.get<std::string>();
    for (const auto& [name, value] : EnumNames<E>::values)
      if (name == s) field(c) = value;
  };
  return k;
}

template <class F>
Key vec3(std::string path, F field, Unit u, Range r, std::string doc) {
  Key k = make(std::move(path), Type::Vec3, u.name, std::move(doc));
  k.lo = r.lo, k.hi = r.hi;  // of each component
  const Vec3d& d = field(defaults());
  k.def = json::array({u.from_si(d[0]), u.from_si(d[1]), u.from_si(d[2])});
  k.set = [field, u](RunConfig& c, const ojson& v, const std::string&) {
    field(c) = {u.to_si(v[0].get<double>()), u.to_si(v[1].get<double>()), u.to_si(v[2].get<double>())};
  };
  return k;
}

// [x0, y0, width, height] in pixels, or null.
template <class F>
Key rect(std::string path, F field, std::string doc) {
  Key k = make(std::move(path), Type::Rect, kPixel.name, std::move(doc));
  k.nullable = true;
  k.def = nullptr;
  k.set = [field](RunConfig& c, const ojson& v, const std::string&) {
    if (v.is_null()) field(c) = std::nullopt;
    else field(c) = PixelRect{v[0].get<int>(), v[1].get<int>(), v[2].get<int>(), v[3].get<int>()};
  };
  return k;
}

// Keys of named elements (NamedSection): the field is an accessor of the element, F(E&) -> T&, with E a
// NodeEdit or a MaterialEdit; the element is found by its name in the run's edits (the section's `add`
// created it).
template <class E>
std::vector<E>& elements(RunConfig& c) {
  if constexpr (std::is_same_v<E, NodeEdit>) return c.edits.nodes;
  else return c.edits.materials;
}

template <class E>
E& element(RunConfig& c, const std::string& name) {
  for (E& e : elements<E>(c))
    if (e.name == name) return e;
  throw std::logic_error("schema: no element " + name);  // the section's add() runs first
}

template <class E>
void add_element(RunConfig& c, const std::string& name) {
  std::vector<E>& v = elements<E>(c);
  for (const E& e : v)
    if (e.name == name) return;
  v.push_back(E{});
  v.back().name = name;
}

template <class E, class F>
Key element_number(std::string path, F field, Unit u, Range r, std::string doc) {
  Key k = make(std::move(path), Type::Number, u.name, std::move(doc));
  k.lo = r.lo, k.hi = r.hi, k.lo_open = r.lo_open;
  k.set_element = [field, u](RunConfig& c, const std::string& name, const ojson& v) {
    field(element<E>(c, name)) = u.to_si(v.get<double>());
  };
  return k;
}

// [x, y, z] whose components may each be null: that component keeps the glTF's value.
template <class E, class F>
Key element_vec3(std::string path, F field, Unit u, Range r, std::string doc) {
  Key k = make(std::move(path), Type::Vec3, u.name, std::move(doc));
  k.lo = r.lo, k.hi = r.hi;
  k.null_components = true;
  k.set_element = [field, u](RunConfig& c, const std::string& name, const ojson& v) {
    OptionalVec3& out = field(element<E>(c, name));
    for (size_t i = 0; i < 3; ++i) out[i] = v[i].is_null() ? std::nullopt : std::optional<double>(u.to_si(v[i].get<double>()));
  };
  return k;
}

// The accessor of a RunConfig field, for the builders: FIELD(camera.f_number).
#define FIELD(member) [](auto& c) -> auto& { return c.member; }

template <class P>
void add_pixel_type(std::vector<Key>& s, const std::string& name, P type) {
  const std::string p = "/sensor/" + name + "/";
  // The pixel design's field: its accessor composed with the design's.
#define PIXEL(member) [type](auto& c) -> auto& { return type(c).member; }
  s.push_back(number(p + "fill_factor", PIXEL(fill_factor), kNone, open_closed(0, 1), "fraction of the pixel area that is photosensitive"));
  s.push_back(number(p + "pdp_peak", PIXEL(pdp_peak), kNone, open_closed(0, 1), "peak photon detection probability (times 1 + 5 pdp_nonuniformity, the brightest pixel's, at most 1)"));
  s.push_back(number(p + "pdp_peak_wavelength_nm", PIXEL(pdp_peak_wavelength_m), kNmUnit, closed(200, 2000), "wavelength of the PDP peak; without pdp_csv, strictly between 300 and 1100 nm (the built-in curve is zero at and beyond both ends)"));
  s.push_back(file(p + "pdp_csv", PIXEL(pdp_csv), "table of (wavelength_nm, PDP) replacing the built-in curve, covering the laser's wavelength (0 outside it); relative to the scene file; \"\" = built-in curve scaled to pdp_peak"));
  s.push_back(number(p + "pdp_nonuniformity", PIXEL(pdp_nonuniformity), kNone, closed(0, 0.2), "relative spread (sigma) of PDP across pixels: each pixel's PDP is the curve times 1 + sigma z, z a standard normal truncated at 5, so at most 0.2 keeps it positive (and the curve times 1 + 5 sigma must stay at most 1)"));
  s.push_back(number(p + "dcr_median_cps", PIXEL(dcr_median_cps), plain("counts/s"), closed(0, 1e7), "median dark count rate of the chip's pixels, main and hot together, at room temperature (25 C), as the paper's Fig. 4(a) gives it (docs/sensor.md, \"Dark counts\")"));
  s.push_back(number(p + "dcr_log_sigma", PIXEL(dcr_log_sigma), kNone, closed(0, 5), "spread (sigma of the natural log) of the main DCR population and of the hot pixels' (spadgen's choice: the paper plots the distribution only)"));
  s.push_back(number(p + "hot_pixel_fraction", PIXEL(hot_pixel_fraction), kNone, closed(0, 1), "fraction of hot pixels (the DCR tail; spadgen's choice)"));
  s.push_back(number(p + "hot_pixel_factor", PIXEL(hot_pixel_factor), kNone, closed(1, 1e6), "median hot-pixel DCR divided by the main population's median DCR (spadgen's choice)"));
  s.push_back(number(p + "crosstalk_probability", PIXEL(crosstalk_probability), kNone, closed(0, 0.5), "probability that a detection fires a given neighbour"));
  s.push_back(boolean(p + "single_avalanche_per_frame", PIXEL(single_avalanche_per_frame), "the pixel stops after its first avalanche in a frame (the paper's pixel B feedback)"));
#undef PIXEL
}

// Keys that do nothing under some settings, and why (Key::ignored). Each rule names the keys it covers by
// path or by section prefix ("/acquisition/gate_sweep/").
void add_ignored_when(std::vector<Key>& keys) {
  using Reason = std::function<std::string(const RunConfig&)>;
  const auto when = [&](std::initializer_list<const char*> paths, Reason reason) {
    for (const char* p : paths) {
      const std::string path = p;
      bool found = false;
      for (Key& k : keys) {
        if (path.back() == '/' ? k.path.rfind(path, 0) != 0 : k.path != path) continue;
        found = true;
        // Rules for one key combine: the first that applies is the reason.
        k.ignored = k.ignored ? Reason([first = k.ignored, reason](const RunConfig& c) {
          const std::string r = first(c);
          return r.empty() ? reason(c) : r;
        })
                              : reason;
      }
      if (!found) throw std::logic_error("schema: no key " + path);
    }
  };
  const auto quoted = [](auto value) {
    std::string q(1, '"');  // built up, not "\"" + ...: GCC 12 warns falsely (-Wrestrict) on that
    q += to_string(value);
    q += '"';
    return q;
  };
  when({"/acquisition/gate_sweep/", "/acquisition/cycles_per_frame"}, [=](const RunConfig& c) {
    return c.acquisition.mode != AcquisitionMode::GateSweep ? "acquisition.mode is " + quoted(c.acquisition.mode) : "";
  });
  when({"/acquisition/intensity/"}, [=](const RunConfig& c) {
    return c.acquisition.mode != AcquisitionMode::Intensity ? "acquisition.mode is " + quoted(c.acquisition.mode) : "";
  });
  when({"/acquisition/intensity/dual_ratio"}, [=](const RunConfig& c) {
    return c.acquisition.intensity.exposure != Exposure::Dual
               ? "acquisition.intensity.exposure is " + quoted(c.acquisition.intensity.exposure) : "";
  });
  when({"/render/window_start_ns", "/render/window_stop_ns", "/render/time_bin_ps"}, [](const RunConfig& c) {
    return time_window_used(c)
               ? std::string()
               : std::string("acquisition.mode is \"intensity\" (no time bins) and outputs.transient and outputs.light are false");
  });
  when({"/render/max_samples_per_pixel"}, [](const RunConfig& c) {
    return c.render.target_relative_error ? std::string() : std::string("render.target_relative_error is null");
  });
  when({"/laser/half_angle_deg"}, [=](const RunConfig& c) {
    return c.laser.beam != Beam::Cone ? "laser.beam is " + quoted(c.laser.beam) : "";
  });
  when({"/laser/gltf_light"}, [=](const RunConfig& c) {
    return c.laser.beam != Beam::GltfLight ? "laser.beam is " + quoted(c.laser.beam) : "";
  });
  when({"/camera/position_m", "/camera/look_at_m", "/camera/up", "/camera/focal_length_mm"}, [](const RunConfig& c) {
    return c.camera.gltf_camera.empty() ? std::string()
                                        : "camera.gltf_camera is \"" + c.camera.gltf_camera + "\" (the glTF camera's pose and field of view)";
  });
  when({"/camera/focal_length_mm"}, [](const RunConfig& c) {
    return c.camera.vertical_fov_rad ? "camera.vertical_fov_deg is set" : "";
  });
  when({"/outputs/transient_crop", "/render/split_direct_indirect"}, [](const RunConfig& c) {
    return c.outputs.transient ? "" : "outputs.transient is false";
  });
  when({"/ambient/illuminance_lux"}, [](const RunConfig& c) {
    return c.ambient.spectral_irradiance_W_m2_nm ? "ambient.spectral_irradiance_W_m2_nm is set" : "";
  });
  // sensor/model/pixel_layout.h: full_chip is pixel A above pixel B, and pixel B alone on a 1-row sensor.
  when({"/sensor/pixel_A/"}, [=](const RunConfig& c) {
    if (c.sensor.preset == PixelPreset::PixelB) return "sensor.preset is " + quoted(c.sensor.preset);
    if (c.sensor.preset == PixelPreset::FullChip && c.camera.height_px < 2)
      return std::string("camera.height_px is 1 (full_chip gives a single row pixel B)");
    return std::string();
  });
  when({"/sensor/pixel_B/"}, [=](const RunConfig& c) {
    return c.sensor.preset == PixelPreset::PixelA ? "sensor.preset is " + quoted(c.sensor.preset) : "";
  });
  for (const char* pixel : {"/sensor/pixel_A/", "/sensor/pixel_B/"}) {
    const std::string p = pixel;
    const std::string dcr[] = {p + "dcr_median_cps", p + "dcr_log_sigma", p + "hot_pixel_fraction", p + "hot_pixel_factor"};
    for (const std::string& key : dcr)
      when({key.c_str()}, [](const RunConfig& c) { return c.sensor.dark_counts ? "" : "sensor.dark_counts is false"; });
    when({(p + "crosstalk_probability").c_str()},
         [](const RunConfig& c) { return c.sensor.crosstalk ? "" : "sensor.crosstalk is false"; });
    when({(p + "pdp_nonuniformity").c_str()},
         [](const RunConfig& c) { return c.sensor.pdp_nonuniformity ? "" : "sensor.pdp_nonuniformity is false"; });
    const bool a = p == "/sensor/pixel_A/";
    when({(p + "pdp_peak").c_str(), (p + "pdp_peak_wavelength_nm").c_str()}, [a](const RunConfig& c) {
      const PixelTypeConfig& px = a ? c.sensor.pixel_A : c.sensor.pixel_B;
      return px.pdp_csv.empty() ? std::string() : std::string("sensor.pixel_") + (a ? "A" : "B") + ".pdp_csv is set (its table is the PDP)";
    });
  }
  when({"/laser/pulse_fwhm_ps"}, [](const RunConfig& c) {
    return c.laser.pulse_shape_csv.empty() ? "" : "laser.pulse_shape_csv is set (its table is the pulse)";
  });
  when({"/sensor/gate/rise_ps", "/sensor/gate/fall_ps", "/sensor/gate/edge_shape", "/sensor/gate/length_ns"}, [](const RunConfig& c) {
    return c.sensor.gate.profile_csv.empty() ? "" : "sensor.gate.profile_csv is set (its table is the gate, with its own length)";
  });
  when({"/sensor/temperature_C"}, [](const RunConfig& c) { return c.sensor.dark_counts ? "" : "sensor.dark_counts is false"; });
  when({"/sensor/gate/skew_fwhm_ps", "/sensor/gate/length_fwhm_ps"}, [](const RunConfig& c) {
    if (!c.sensor.skew) return std::string("sensor.gate_skew is false");
    return c.sensor.gate.maps_exr.empty() ? std::string() : std::string("sensor.gate.maps_exr is set (its maps are the skews and lengths)");
  });
}

std::vector<Key> build() {
  std::vector<Key> k;
  Key gltf = file("/gltf", FIELD(gltf_path), "the glTF 2.0 file (.gltf or .glb) of the scene, relative to the scene file");
  gltf.required = true, gltf.def = nullptr;
  k.push_back(gltf);
  k.push_back(string("/gltf_scene", FIELD(gltf_scene), "name of the glTF scene to use; \"\" = the file's default scene"));
  Key description = make("/description", Type::String, "", "free text, copied into metadata.json");
  description.def = "";
  k.push_back(description);
  k.push_back(integer("/seed", FIELD(seed), kNone, closed(0, double(kMaxSeed)), "seed of every random stream that seeds.* does not set (overridden by --seed)"));
  k.push_back(integer("/seeds/light", FIELD(seeds.light), kNone, closed(0, double(kMaxSeed)), "seed of the Monte Carlo light transport (laser.exr, ambient.exr, transients); null = seed"));
  k.push_back(integer("/seeds/chip", FIELD(seeds.chip), kNone, closed(0, double(kMaxSeed)), "seed of the chip's fixed pattern (gate skew and length maps, DCR population, PDP non-uniformity: sensor_maps.exr); null = seed"));
  k.push_back(integer("/seeds/noise", FIELD(seeds.noise), kNone, closed(0, double(kMaxSeed)), "seed of the temporal noise (binary frames, counts, crosstalk draws); null = seed"));

  k.push_back(string("/camera/gltf_camera", FIELD(camera.gltf_camera), "name of a glTF camera node to use instead of position/look_at/up and focal_length_mm (its field of view, unless vertical_fov_deg is set); a node without a name, whose camera has none: node<index>, e.g. node3; \"\" = defined here"));
  k.push_back(vec3("/camera/position_m", FIELD(camera.position_m), kMetre, kWorld, "camera centre (world, glTF frame: +Y up)"));
  k.push_back(vec3("/camera/look_at_m", FIELD(camera.look_at_m), kMetre, kWorld, "point the optical axis passes through"));
  k.push_back(vec3("/camera/up", FIELD(camera.up), kNone, kWorld, "up direction (world); need not be orthogonal to the axis"));
  k.push_back(integer("/camera/width_px", FIELD(camera.width_px), kPixel, closed(1, 16384), "sensor columns"));
  k.push_back(integer("/camera/height_px", FIELD(camera.height_px), kPixel, closed(1, 16384), "sensor rows (500: one half of the paper's chip; 1000: the full chip)"));
  k.push_back(number("/camera/pixel_pitch_um", FIELD(camera.pixel_pitch_m), kUmUnit, closed(0.1, 1000), "pixel pitch"));
  k.push_back(number("/camera/focal_length_mm", FIELD(camera.focal_length_m), kMmUnit, open_closed(0, 10000), "lens focal length (ignored when vertical_fov_deg is set)"));
  k.push_back(number("/camera/vertical_fov_deg", FIELD(camera.vertical_fov_rad), kDegree, closed(1e-3, 179), "vertical field of view (also over a glTF camera's); null = from focal_length_mm, or the glTF camera's"));
  k.push_back(number("/camera/f_number", FIELD(camera.f_number), kNone, closed(0.5, 64), "lens f-number N (aperture diameter = f / N)"));
  k.push_back(number("/camera/optics_transmission", FIELD(camera.optics_transmission), kNone, open_closed(0, 1), "fraction of the light the lens (and any filter) passes"));
  k.push_back(rect("/camera/crop", FIELD(camera.crop), "[x0, y0, width, height] region of interest; null = the whole sensor"));

  k.push_back(number("/laser/average_power_mW", FIELD(laser.average_power_W), kMilliwatt, closed(0, 1e9), "average optical power"));
  k.push_back(number("/laser/repetition_rate_MHz", FIELD(laser.repetition_rate_Hz), kMegahertz, closed(1e-6, 1e5), "pulse repetition rate (1e-6 MHz: one pulse per second)"));
  k.push_back(number("/laser/wavelength_nm", FIELD(laser.wavelength_m), kNmUnit, closed(200, 2000), "vacuum wavelength"));
  k.push_back(number("/laser/pulse_fwhm_ps", FIELD(laser.pulse_fwhm_s), kPsUnit, open_closed(0, 1e6), "Gaussian pulse width (full width at half maximum)"));
  k.push_back(file("/laser/pulse_shape_csv", FIELD(laser.pulse_shape_csv), "table of (time_ps, relative power) replacing the Gaussian; relative to the scene file"));
  k.push_back(number("/laser/emission_delay_ns", FIELD(laser.emission_delay_s), kNsUnit, closed(-1e6, 1e6), "fixed delay from the laser trigger to the pulse's emission (cables, driver)"));
  k.push_back(choice("/laser/beam", FIELD(laser.beam), "flood: uniform over a cone just covering the field of view; cone: uniform over half_angle_deg; gltf_light: a KHR_lights_punctual light of the scene"));
  k.push_back(number("/laser/half_angle_deg", FIELD(laser.half_angle_rad), kDegree, open_closed(0, 180), "half-angle of the beam when beam is \"cone\""));
  k.push_back(vec3("/laser/offset_m", FIELD(laser.offset_m), kMetre, kWorld, "emitter position relative to the camera centre, in camera coordinates (x right, y up, -z forward)"));
  k.push_back(string("/laser/gltf_light", FIELD(laser.gltf_light), "name of the glTF light used as the laser when beam is \"gltf_light\" (its node's; unnamed: the light's, else node<index>)"));

  k.push_back(number("/ambient/illuminance_lux", FIELD(ambient.illuminance_lux), plain("lux"), closed(0, 1e6), "uniform environment illuminance (equal-energy spectrum); see docs/scene-file.md for the conversion"));
  k.push_back(number("/ambient/spectral_irradiance_W_m2_nm", FIELD(ambient.spectral_irradiance_W_m2_nm), plain("W/m^2/nm"), closed(0, 1e3), "the uniform environment in radiometric units (irradiance per nm on a surface facing it, flat over the band); null = from illuminance_lux"));
  k.push_back(number("/ambient/wavelength_nm", FIELD(ambient.wavelength_m), kNmUnit, closed(200, 2000), "centre of the ambient band the camera sees"));
  k.push_back(number("/ambient/bandwidth_nm", FIELD(ambient.bandwidth_m), kNmUnit, open_closed(0, 2000), "width of that band (optical filter or sensor response), less than twice wavelength_nm (the band above 0 nm)"));
  k.push_back(boolean("/ambient/gltf_lights", FIELD(ambient.gltf_lights), "the glTF punctual lights add to the ambient light"));

  k.push_back(choice("/sensor/preset", FIELD(sensor.preset), "pixel design of every row: pixel_A, pixel_B, or full_chip (pixel A in the top half, pixel B in the bottom half)"));
  add_pixel_type(k, "pixel_A", FIELD(sensor.pixel_A));
  add_pixel_type(k, "pixel_B", FIELD(sensor.pixel_B));
  k.push_back(number("/sensor/gate/length_ns", FIELD(sensor.gate.length_s), kNsUnit, open_closed(0, 1e6), "gate length, 50 % to 50 %"));
  k.push_back(number("/sensor/gate/rise_ps", FIELD(sensor.gate.rise_s), kPsUnit, closed(0, 1e6), "rise time, 10 % to 90 % (spadgen's choice within the paper's \"rise/fall time <550ps\")"));
  k.push_back(number("/sensor/gate/fall_ps", FIELD(sensor.gate.fall_s), kPsUnit, closed(0, 1e6), "fall time, 90 % to 10 %"));
  k.push_back(choice("/sensor/gate/edge_shape", FIELD(sensor.gate.edge_shape), "shape of the parametric edges"));
  k.push_back(file("/sensor/gate/profile_csv", FIELD(sensor.gate.profile_csv), "measured gate profile, table of (time_ps, response), replacing the parametric one; relative to the scene file"));
  k.push_back(number("/sensor/gate/delay_ns", FIELD(sensor.gate.delay_s), kNsUnit, closed(-1e6, 1e6), "fixed delay from the laser trigger to the gate opening at position 0"));
  k.push_back(number("/sensor/gate/skew_fwhm_ps", FIELD(sensor.gate.skew_fwhm_s), kPsUnit, closed(0, 1e6), "spread of the gate position across the array (FWHM)"));
  k.push_back(number("/sensor/gate/length_fwhm_ps", FIELD(sensor.gate.length_fwhm_s), kPsUnit, closed(0, 1e6), "spread of the gate length across the array (FWHM)"));
  k.push_back(file("/sensor/gate/maps_exr", FIELD(sensor.gate.maps_exr), "EXR with channels skew_ps and length_ps (full sensor size) replacing the generated maps; relative to the scene file"));
  k.push_back(integer("/sensor/gate/knots_per_edge", FIELD(sensor.gate.knots_per_edge), kNone, closed(2, 4096), "knots of each tabulated gate edge (a smooth edge, or any edge convolved with the pulse and jitter): the gate model's accuracy against its cost (docs/accuracy.md, \"The sensor model's knobs\")"));
  k.push_back(number("/sensor/gate/grid_ps", FIELD(sensor.gate.grid_s), kPsUnit, closed(0.01, 100), "step of the fine grid the pulse, the jitter and the tabulated edges are convolved on (coarser where the edges and the pulse span over 12000 steps; metadata.json gate.grid_ps records the step used)"));
  k.push_back(number("/sensor/jitter_fwhm_ps", FIELD(sensor.gate.jitter_fwhm_s), kPsUnit, closed(0, 1e6), "SPAD timing jitter (Gaussian FWHM; spadgen's choice: the paper gives none)"));
  k.push_back(number("/sensor/temperature_C", FIELD(sensor.temperature_C), plain("C"), closed(-100, 150), "sensor temperature (dark counts rise above about 30 C)"));
  k.push_back(boolean("/sensor/dark_counts", FIELD(sensor.dark_counts), "model dark counts"));
  k.push_back(boolean("/sensor/crosstalk", FIELD(sensor.crosstalk), "model optical/electrical crosstalk between neighbours"));
  k.push_back(boolean("/sensor/gate_skew", FIELD(sensor.skew), "per-pixel gate position and length variation"));
  k.push_back(boolean("/sensor/pdp_nonuniformity", FIELD(sensor.pdp_nonuniformity), "per-pixel PDP variation"));

  k.push_back(choice("/acquisition/mode", FIELD(acquisition.mode), "gate_sweep: 3D time-gated sweep; intensity: 2D intensity imaging"));
  k.push_back(integer("/acquisition/frames", FIELD(acquisition.frames), kNone, closed(1, 65535), "binary frames summed per gate position (gate_sweep) or per image (intensity)"));
  k.push_back(number("/acquisition/frame_rate_fps", FIELD(acquisition.frame_rate_Hz), plain("frames/s"), open_closed(0, 1e7), "binary frame rate: an exposure longer than one frame is warned of; recorded in metadata.json"));
  k.push_back(integer("/acquisition/cycles_per_frame", FIELD(acquisition.cycles_per_frame), kNone, closed(1, 1e12), "laser cycles (gate openings) integrated in one binary frame (gate_sweep)"));
  k.push_back(number("/acquisition/gate_sweep/start_ns", FIELD(acquisition.gate_sweep.start_s), kNsUnit, closed(-1e6, 1e6), "first gate position, relative to the laser trigger"));
  k.push_back(number("/acquisition/gate_sweep/stop_ns", FIELD(acquisition.gate_sweep.stop_s), kNsUnit, closed(-1e6, 1e6), "last gate position (included when on the step grid)"));
  k.push_back(number("/acquisition/gate_sweep/step_ps", FIELD(acquisition.gate_sweep.step_s), kPsUnit, closed(1e-6, 1e9), "gate position step (36 ps: the paper's LSB, 5.4 mm)"));
  k.push_back(choice("/acquisition/intensity/exposure", FIELD(acquisition.intensity.exposure), "single exposure, or dual exposure interleaving tau_S and tau_L"));
  k.push_back(number("/acquisition/intensity/exposure_us", FIELD(acquisition.intensity.exposure_s), kUsUnit, open_closed(0, 1e9), "global exposure per frame (single), or the short exposure tau_S (dual)"));
  k.push_back(number("/acquisition/intensity/dual_ratio", FIELD(acquisition.intensity.dual_ratio), kNone, closed(1, 1e6), "tau_L / tau_S in dual exposure"));
  k.push_back(boolean("/acquisition/intensity/laser_on", FIELD(acquisition.intensity.laser_on), "add the laser's mean photon rate to the ambient light in intensity mode (false: the laser is not traced, unless outputs.transient, or outputs.light with render.window_start_ns, keeps its light)"));

  k.push_back(choice("/render/quality", FIELD(render.quality), "preset of samples_per_pixel, target_relative_error and max_samples_per_pixel (draft, standard, reference; docs/accuracy.md); custom: those keys as given. A key given explicitly wins over the preset"));
  k.push_back(integer("/render/samples_per_pixel", FIELD(render.samples_per_pixel), kNone, closed(1, 1e7), "paths per pixel; with target_relative_error, the paths of the first round (at least 2), which every pixel gets"));
  k.push_back(number("/render/target_relative_error", FIELD(render.target_relative_error), kNone, open_closed(0, 1), "null: samples_per_pixel paths in every pixel; else a first round of samples_per_pixel paths decides each pixel's paths so that the Monte Carlo standard error of its laser return (in a gate sweep, with acquisition.intensity.laser_on, or kept by outputs.transient, or by outputs.light with render.window_start_ns) and of its ambient light (every mode's counts see it; in a gate sweep against its rate plus the rate the counts hardly see, docs/render.md) is this fraction of each (at most max_samples_per_pixel; the estimate leaves the first round out, so it is unbiased); laser.exr records each pixel's paths and standard error, ambient.exr the ambient light's"));
  k.push_back(integer("/render/max_samples_per_pixel", FIELD(render.max_samples_per_pixel), kNone, closed(1, 1e7), "the most paths of a pixel's estimate with target_relative_error: its second round takes from samples_per_pixel to this many paths (the first round's samples_per_pixel decide how many, and are not counted in the estimate), so at least samples_per_pixel; not given, the preset's or default's, raised to a larger samples_per_pixel"));
  k.push_back(integer("/render/max_bounces", FIELD(render.max_bounces), kNone, closed(1, 64), "scattering vertices per path (1 = direct light only); smooth interfaces a path crosses or mirrors off do not count, a rough plate's faces do (an object behind a rough plate needs 3)"));
  k.push_back(integer("/render/russian_roulette_from", FIELD(render.russian_roulette_from), kNone, closed(1, 64), "bounce from which paths may be stopped by Russian roulette"));
  k.push_back(number("/render/time_bin_ps", FIELD(render.time_bin_s), kPsUnit, closed(1e-3, 1e6), "transient bin width"));
  k.push_back(number("/render/window_start_ns", FIELD(render.window_start_s), kNsUnit, closed(-1e6, 1e6), "start of the transient window; null = derived from the acquisition. Set with window_stop_ns (both or neither)"));
  k.push_back(number("/render/window_stop_ns", FIELD(render.window_stop_s), kNsUnit, closed(-1e6, 1e6), "end of the transient window, rounded up to a whole number of bins (metadata.json time_axis end_ns says where it ends); null = derived from the acquisition. Set with window_start_ns (both or neither)"));
  k.push_back(integer("/render/tile_size_px", FIELD(render.tile_size), kPixel, closed(8, 4096), "tile edge (a multiple of 8: bit-packed frames start on a byte); outputs do not depend on it"));
  k.back().multiple_of = 8;
  k.push_back(integer("/render/max_layers", FIELD(render.max_layers), kNone, closed(1, 64), "surfaces recorded per pixel in the ground truth"));
  k.push_back(boolean("/render/split_direct_indirect", FIELD(render.split_direct_indirect), "also keep the indirect part of the transient separately"));
  k.push_back(boolean("/render/guided_connections", FIELD(render.guided_connections), "glossy and Lambertian vertices also draw directions towards the narrow glossy reflections of the laser (GGX alpha <= 0.04) of the surfaces ahead and of plates' edges, weighted by MIS: the same expectation, less variance with glossy plates (docs/render.md); false: BSDF draws only"));

  k.push_back(boolean("/outputs/ground_truth", FIELD(outputs.ground_truth), "write ground_truth.exr"));
  k.push_back(boolean("/outputs/transient", FIELD(outputs.transient), "write transient.npy (H, W, T) float32 photons per pulse per bin"));
  k.push_back(rect("/outputs/transient_crop", FIELD(outputs.transient_crop), "[x0, y0, width, height] (sensor pixels) of transient.npy; null = the whole image"));
  k.push_back(boolean("/outputs/light", FIELD(outputs.light), "write light/: each pixel's transient over its lit bins and its totals, compactly, so that `spadgen sense` can re-sample the sensor without rendering (an intensity run without laser_on keeps the laser's light only with render.window_start_ns and window_stop_ns, for a later sense as a gate sweep; without them its light holds no laser, and its sense images none either)"));
  k.push_back(boolean("/outputs/expected_counts", FIELD(outputs.expected_counts), "write expected_counts.npy: N p = N (1 - exp(-lambda)) as float32 (noise-free; saturates where p rounds to 1, unlike detection_rate.npy)"));
  k.push_back(boolean("/outputs/detection_rate", FIELD(outputs.detection_rate), "write detection_rate.npy: lambda, the mean avalanches per binary frame (noise-free, lossless: expected counts = N (1 - exp(-lambda)))"));
  k.push_back(boolean("/outputs/counts", FIELD(outputs.counts), "write counts.npy (sampled)"));
  k.push_back(boolean("/outputs/frames", FIELD(outputs.frames), "write frames.npy (binary frames, bit-packed); large"));
  k.push_back(boolean("/outputs/previews", FIELD(outputs.previews), "write previews/*.png"));
  k.push_back(choice("/outputs/storage", FIELD(outputs.storage), "container of the stacks: npy (one .npy file each) or zarr (a Zarr v2 folder each, Blosc zstd chunks, lossless; frames.npy stays .npy); docs/outputs.md, Storage"));
  k.push_back(choice("/outputs/exr_compression", FIELD(outputs.exr_compression), "lossless compression of the EXR images: zip (the smallest here), zips (one scanline a block), rle, none"));
  add_ignored_when(k);
  return k;
}
#undef FIELD

}  // namespace

const nlohmann::json& quality_presets() {
  // Measured on the shipped scenes (docs/accuracy.md, bench/accuracy.py).
  static const json p = {
      {"draft", {{"/render/samples_per_pixel", 4}, {"/render/target_relative_error", nullptr}, {"/render/max_samples_per_pixel", 1024}}},
      {"standard", {{"/render/samples_per_pixel", 32}, {"/render/target_relative_error", 0.02}, {"/render/max_samples_per_pixel", 512}}},
      {"reference", {{"/render/samples_per_pixel", 128}, {"/render/target_relative_error", 0.005}, {"/render/max_samples_per_pixel", 4096}}},
  };
  return p;
}

const std::vector<Key>& schema() {
  static const std::vector<Key> s = build();
  return s;
}

namespace {

#define EDIT(member) [](auto& e) -> auto& { return e.member; }
std::vector<NamedSection> build_named() {
  std::vector<NamedSection> out;
  NamedSection nodes;
  nodes.path = "/nodes", nodes.element = "node";
  nodes.doc = "glTF nodes by name: each given value replaces the node's own (its local transform, before world "
              "transforms are composed, so that its children, cameras and lights follow)";
  nodes.add = add_element<NodeEdit>;
  nodes.keys.push_back(element_vec3<NodeEdit>("/translation_m", EDIT(translation_m), kMetre, kWorld,
                                              "the node's translation, in its parent's frame"));
  nodes.keys.push_back(element_vec3<NodeEdit>("/rotation_deg", EDIT(rotation_rad), kDegree, closed(-360, 360),
                                              "the node's rotation as XYZ Euler angles: R = Rz(z) Ry(y) Rx(x) on column vectors "
                                              "(about X, then Y, then Z); a null angle is the glTF rotation's angle in that convention"));
  nodes.keys.push_back(element_vec3<NodeEdit>("/scale", EDIT(scale), kNone, closed(-1e6, 1e6),
                                              "the node's scale along its local axes"));
  out.push_back(std::move(nodes));

  NamedSection materials;
  materials.path = "/materials", materials.element = "material";
  materials.doc = "glTF materials by name: each given value replaces the material's own";
  materials.add = add_element<MaterialEdit>;
  materials.keys.push_back(element_vec3<MaterialEdit>("/base_color", EDIT(base_color), kNone, closed(0, 1),
                                                      "linear RGB base colour (baseColorFactor; its alpha is kept)"));
  materials.keys.push_back(element_number<MaterialEdit>("/roughness", EDIT(roughness), kNone, closed(0, 1), "roughness (roughnessFactor)"));
  materials.keys.push_back(element_number<MaterialEdit>("/metallic", EDIT(metallic), kNone, closed(0, 1), "metalness (metallicFactor)"));
  materials.keys.push_back(element_number<MaterialEdit>("/transmission", EDIT(transmission), kNone, closed(0, 1),
                                                        "transmitted fraction (KHR_materials_transmission transmissionFactor); "
                                                        "> 0 makes the surface transmissive as the extension does"));
  materials.keys.push_back(element_number<MaterialEdit>("/ior", EDIT(ior), kNone, closed(1, 4), "index of refraction (KHR_materials_ior)"));
  materials.keys.push_back(element_number<MaterialEdit>("/thickness_mm", EDIT(thickness_m), kMmUnit, closed(0, 1e6),
                                                        "thickness of the volume behind the surface (KHR_materials_volume "
                                                        "thicknessFactor); 0 = thin-walled"));
  out.push_back(std::move(materials));
  return out;
}
#undef EDIT

}  // namespace

const std::vector<NamedSection>& named_sections() {
  static const std::vector<NamedSection> s = build_named();
  return s;
}

}  // namespace spadgen::scenes
