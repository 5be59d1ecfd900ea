// scenes_gen: writes the scene library of the paper's experiments (glTF + scene files). The shipped
// files under scenes/paper/ are this program's output with its defaults; flags vary the geometry so
// users can make their own variants without a 3D editor. See docs/scenes.md.
#include <nlohmann/json.hpp>

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "gltf_builder.h"
#include "png_write.h"

namespace spadgen::scenes_gen {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kLightSpeed = 299792458.0;  // m/s

// The paper's acquisition (section 4.D): gate positions tau_k = 0.6 ns + k * 36 ps, gate length 3.8 ns.
constexpr double kSweepStart_ns = 0.6;
constexpr double kSweepStop_ns = 13.2;
constexpr double kSweepStep_ns = 0.036;
constexpr double kGateLength_ns = 3.8;
// The camera of the paper: 9.4 um pitch, 12 mm lens (the default of core/config.h).
constexpr double kPixelPitch_m = 9.4e-6;
// Lenses. The 2 mW flood spreads over the field of view, so the photons a pixel receives scale with
// the inverse of that solid angle: the 3D scenes use longer lenses than the test chart (which must
// fill the whole chip) so that their gate profiles rise well above shot noise in 255 frames.
constexpr double kChartFocal_mm = 12;
constexpr double kFlatTargetFocal_mm = 50;
constexpr double kMultiObjectFocal_mm = 25;
// 1600 cycles at 40 MHz are 40 us, most of the 41.7 us frame at 24,000 fps.
constexpr int kCyclesPerFrame = 1600;

struct Options {
  std::string out_dir = SPADGEN_PAPER_SCENES_DIR;
  std::set<std::string> only;
  // flat_target
  double distance = 1.0;  // camera to target, m
  double target_reflectance = 0.6;
  double target_size = 4.0;  // edge of the square target, m
  // multi_object
  double plate_distance = 0.45;  // camera to the plate's front face, m
  double plate_thickness = 0.002;
  double plate_ior = 1.5;
  // A real plastic plate is not optically clean: 5 % of the light that enters it scatters diffusely
  // (glTF: the diffuse lobe weighs 1 - transmission), so the plate returns light across the whole
  // view as in the paper's Fig. 10c and 11a, not only a specular hotspot at the laser's mirror image.
  // Its surfaces are nearly smooth (roughness 0.05): the paper's plate is "almost transparent", the 2D
  // images with and without it show "no significant difference" (Fig. 10b) and its rising-edge detector
  // finds the sphere behind it (Fig. 11b). Measured (docs/paper.md): 2D counts on the covered sphere with
  // and without the plate about equal; roughness 0.3 gave 2.7 times more with it and hid the sphere's edge.
  double plate_roughness = 0.05;
  double plate_transmission = 0.95;
  double plate_right_edge = 0.0;  // x of the plate's right edge, m (the plate covers x < this)
  double sphere_distance = 0.75;  // camera to the sphere's nearest point, m
  double sphere_radius = 0.1;
  double sphere_reflectance = 0.8;
  int icosphere_level = 6;
  double plate_gate_index = 40;  // gate index of the plate's rising edge (sets laser.emission_delay_ns)
  // test_chart
  double chart_distance = 1.0;
  double chart_size = 0.9;
  int chart_texels = 2048;
};

const char* kUsage = R"(usage: scenes_gen [OUTDIR] [options]
Writes flat_target, multi_object and test_chart (.gltf, .bin, .json) into OUTDIR
(default: the source tree's scenes/paper).
  --only NAME               write only this scene (repeatable): flat_target, multi_object, test_chart
 flat_target:
  --distance M              camera to target (1.0); --set camera.position_m=[0,0,D] also moves it
  --target-reflectance R    Lambertian reflectance of the target (0.6)
  --target-size M           edge of the square target (4.0)
 multi_object:
  --plate-distance M        camera to the plate's front face (0.45)
  --plate-thickness M       (0.002)
  --plate-ior N             (1.5)
  --plate-roughness R       (0.05)
  --plate-transmission T    (0.95)
  --plate-right-edge X      the plate covers x < X in metres (0.0: the left half of the view)
  --sphere-distance M       camera to the sphere's nearest point (0.75)
  --sphere-radius M         (0.1)
  --sphere-reflectance R    (0.8)
  --icosphere-level L       subdivisions of the sphere's icosahedron (6)
  --plate-gate-index K      gate index of the plate's rising edge; sets the laser delay (40)
 test_chart:
  --chart-distance M        camera to the chart (1.0)
  --chart-size M            edge of the square chart (0.9)
  --chart-texels N          texture edge in texels (2048)
)";

double parse_number(const std::string& flag, const char* text) {
  char* end = nullptr;
  const double v = std::strtod(text, &end);
  if (end == text || *end != '\0' || !std::isfinite(v))
    throw std::runtime_error(flag + ": expected a number, got '" + std::string(text) + "'");
  return v;
}

Options parse_options(int argc, char** argv) {
  Options o;
  std::map<std::string, double*> numbers = {
      {"--distance", &o.distance},
      {"--target-reflectance", &o.target_reflectance},
      {"--target-size", &o.target_size},
      {"--plate-distance", &o.plate_distance},
      {"--plate-thickness", &o.plate_thickness},
      {"--plate-ior", &o.plate_ior},
      {"--plate-roughness", &o.plate_roughness},
      {"--plate-transmission", &o.plate_transmission},
      {"--plate-right-edge", &o.plate_right_edge},
      {"--sphere-distance", &o.sphere_distance},
      {"--sphere-radius", &o.sphere_radius},
      {"--sphere-reflectance", &o.sphere_reflectance},
      {"--plate-gate-index", &o.plate_gate_index},
      {"--chart-distance", &o.chart_distance},
      {"--chart-size", &o.chart_size},
  };
  bool have_dir = false;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "-h" || arg == "--help") {
      std::cout << kUsage;
      std::exit(0);
    }
    const auto need_value = [&]() -> const char* {
      if (i + 1 >= argc) throw std::runtime_error(arg + ": missing value");
      return argv[++i];
    };
    if (auto it = numbers.find(arg); it != numbers.end()) {
      *it->second = parse_number(arg, need_value());
    } else if (arg == "--icosphere-level") {
      o.icosphere_level = static_cast<int>(parse_number(arg, need_value()));
    } else if (arg == "--chart-texels") {
      o.chart_texels = static_cast<int>(parse_number(arg, need_value()));
    } else if (arg == "--only") {
      const std::string name = need_value();
      if (name != "flat_target" && name != "multi_object" && name != "test_chart")
        throw std::runtime_error("--only: unknown scene '" + name + "'");
      o.only.insert(name);
    } else if (!arg.empty() && arg[0] != '-' && !have_dir) {
      o.out_dir = arg;
      have_dir = true;
    } else {
      throw std::runtime_error("unknown argument '" + arg + "' (see --help)");
    }
  }
  const auto positive = [](const char* name, double v) {
    if (!(v > 0)) throw std::runtime_error(std::string(name) + " must be > 0");
  };
  positive("--distance", o.distance);
  positive("--target-size", o.target_size);
  positive("--plate-distance", o.plate_distance);
  positive("--plate-thickness", o.plate_thickness);
  positive("--plate-ior", o.plate_ior);
  positive("--sphere-radius", o.sphere_radius);
  positive("--chart-distance", o.chart_distance);
  positive("--chart-size", o.chart_size);
  // What spadgen then loads: world coordinates within +-1e6 m (the scene file's camera position), an index
  // of refraction of at least 1 (scenes_gen wrote files spadgen refused, and exited 0)
  for (const auto& [name, v] : {std::pair<const char*, double>{"--distance", o.distance}, {"--target-size", o.target_size},
                                {"--plate-distance", o.plate_distance}, {"--plate-thickness", o.plate_thickness},
                                {"--sphere-distance", o.sphere_distance}, {"--sphere-radius", o.sphere_radius},
                                {"--chart-distance", o.chart_distance}, {"--chart-size", o.chart_size}})
    if (!(v <= 1e6)) throw std::runtime_error(std::string(name) + " must be at most 1e6 m (spadgen's world coordinates)");
  if (!(o.plate_ior >= 1.0)) throw std::runtime_error("--plate-ior must be at least 1 (glTF's KHR_materials_ior)");
  if (o.sphere_distance <= o.plate_distance + o.plate_thickness)
    throw std::runtime_error("--sphere-distance must lie behind the plate's back face");
  for (double r : {o.target_reflectance, o.sphere_reflectance, o.plate_roughness, o.plate_transmission})
    if (r < 0 || r > 1) throw std::runtime_error("reflectance, roughness and transmission must lie in [0, 1]");
  if (o.icosphere_level < 0 || o.icosphere_level > 7)
    throw std::runtime_error("--icosphere-level must lie in [0, 7]");
  if (o.chart_texels < 256 || o.chart_texels > 8192) throw std::runtime_error("--chart-texels must lie in [256, 8192]");
  return o;
}

// Shortest text that reads back as the same double ("0.45", not "0.45000000000000001").
std::string num(double v) { return nlohmann::json(v).dump(); }

double vertical_fov_rad(int height_px, double focal_mm) {
  return 2.0 * std::atan(0.5 * height_px * kPixelPitch_m / (focal_mm * 1e-3));
}

// ---------------------------------------------------------------------------------------------
// Geometry

// An axis-aligned box [lo, hi] with flat faces (4 vertices per face so each carries its normal).
MeshData box(glm::vec3 lo, glm::vec3 hi) {
  MeshData m;
  const auto face = [&](glm::vec3 n, glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d) {
    const auto base = static_cast<uint32_t>(m.positions.size());
    for (const glm::vec3& p : {a, b, c, d}) {
      m.positions.push_back(p);
      m.normals.push_back(n);
    }
    // a, b, c, d run counter-clockwise seen from outside (along -n).
    m.indices.insert(m.indices.end(), {base, base + 1, base + 2, base, base + 2, base + 3});
  };
  const float x0 = lo.x, y0 = lo.y, z0 = lo.z, x1 = hi.x, y1 = hi.y, z1 = hi.z;
  face({0, 0, 1}, {x0, y0, z1}, {x1, y0, z1}, {x1, y1, z1}, {x0, y1, z1});
  face({0, 0, -1}, {x1, y0, z0}, {x0, y0, z0}, {x0, y1, z0}, {x1, y1, z0});
  face({1, 0, 0}, {x1, y0, z1}, {x1, y0, z0}, {x1, y1, z0}, {x1, y1, z1});
  face({-1, 0, 0}, {x0, y0, z0}, {x0, y0, z1}, {x0, y1, z1}, {x0, y1, z0});
  face({0, 1, 0}, {x0, y1, z1}, {x1, y1, z1}, {x1, y1, z0}, {x0, y1, z0});
  face({0, -1, 0}, {x0, y0, z0}, {x1, y0, z0}, {x1, y0, z1}, {x0, y0, z1});
  return m;
}

// A square in the z = 0 plane facing +Z, uv (0,0) at the top-left corner as glTF expects.
MeshData square(float size) {
  const float h = 0.5f * size;
  MeshData m;
  m.positions = {{-h, h, 0}, {-h, -h, 0}, {h, -h, 0}, {h, h, 0}};
  m.normals.assign(4, glm::vec3(0, 0, 1));
  m.texcoords = {{0, 0}, {0, 1}, {1, 1}, {1, 0}};
  m.indices = {0, 1, 2, 0, 2, 3};
  return m;
}

// An icosphere with a vertex exactly on +Z (the point nearest the camera), built in double and
// rounded once, so that the sphere's nearest point is exactly where the scene says it is.
MeshData icosphere(double radius, int level, double* max_error_m) {
  std::vector<glm::dvec3> v;
  v.push_back({0, 0, 1});
  const double z = 1.0 / std::sqrt(5.0), r = 2.0 / std::sqrt(5.0);
  for (int k = 0; k < 5; ++k) v.push_back({r * std::cos(2 * kPi * k / 5), r * std::sin(2 * kPi * k / 5), z});
  for (int k = 0; k < 5; ++k)
    v.push_back({r * std::cos(2 * kPi * (k + 0.5) / 5), r * std::sin(2 * kPi * (k + 0.5) / 5), -z});
  v.push_back({0, 0, -1});
  std::vector<glm::uvec3> tris;
  for (uint32_t k = 0; k < 5; ++k) {
    const uint32_t a = 1 + k, b = 1 + (k + 1) % 5, c = 6 + k, d = 6 + (k + 1) % 5;
    tris.push_back({0, a, b});
    tris.push_back({a, c, b});
    tris.push_back({b, c, d});
    tris.push_back({11, d, c});
  }
  for (int l = 0; l < level; ++l) {
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> mid;
    const auto midpoint = [&](uint32_t a, uint32_t b) {
      const auto key = std::minmax(a, b);
      if (auto it = mid.find(key); it != mid.end()) return it->second;
      v.push_back(glm::normalize(v[a] + v[b]));
      const auto i = static_cast<uint32_t>(v.size() - 1);
      mid[key] = i;
      return i;
    };
    std::vector<glm::uvec3> next;
    next.reserve(tris.size() * 4);
    for (const glm::uvec3& t : tris) {
      const uint32_t ab = midpoint(t.x, t.y), bc = midpoint(t.y, t.z), ca = midpoint(t.z, t.x);
      next.push_back({t.x, ab, ca});
      next.push_back({t.y, bc, ab});
      next.push_back({t.z, ca, bc});
      next.push_back({ab, bc, ca});
    }
    tris.swap(next);
  }
  MeshData m;
  double min_plane_distance = 1.0;
  for (const glm::uvec3& t : tris) {
    const glm::dvec3 a = v[t.x], b = v[t.y], c = v[t.z];
    const glm::dvec3 n = glm::cross(b - a, c - a);
    // Outward winding: the triangle's normal points away from the centre.
    if (glm::dot(n, a + b + c) <= 0) throw std::runtime_error("icosphere: inward-facing triangle");
    // The flat triangle's deepest point is the foot of the perpendicular from the centre: these
    // near-equilateral triangles contain it, so the plane distance is the tessellation error.
    min_plane_distance = std::min(min_plane_distance, glm::dot(glm::normalize(n), a));
    m.indices.insert(m.indices.end(), {t.x, t.y, t.z});
  }
  *max_error_m = radius * (1.0 - min_plane_distance);
  for (const glm::dvec3& p : v) {
    m.positions.push_back(glm::vec3(p * radius));
    m.normals.push_back(glm::vec3(p));
  }
  return m;
}

// ---------------------------------------------------------------------------------------------
// Materials

tinygltf::Material lambertian(const std::string& name, double reflectance) {
  tinygltf::Material m;
  m.name = name;
  // A dielectric at roughness 1 is glTF's nearest to a Lambertian surface; the renderer treats
  // baseColor of such a material as the diffuse reflectance.
  m.pbrMetallicRoughness.baseColorFactor = {reflectance, reflectance, reflectance, 1.0};
  m.pbrMetallicRoughness.metallicFactor = 0.0;
  m.pbrMetallicRoughness.roughnessFactor = 1.0;
  return m;
}

uint8_t srgb_byte(double linear) {
  const double c = std::clamp(linear, 0.0, 1.0);
  const double s = c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
  return static_cast<uint8_t>(std::lround(s * 255.0));
}

// ---------------------------------------------------------------------------------------------
// Scene-file text (JSON with // comments, which the scene-file parser accepts)

void write_text(const std::filesystem::path& path, const std::string& text) {
  // Catch a malformed template here rather than in the user's first run.
  const nlohmann::json parsed = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/true,
                                                      /*ignore_comments=*/true);
  if (!parsed.is_object()) throw std::runtime_error(path.string() + ": not a JSON object");
  std::ofstream f(path, std::ios::binary);
  f << text;
  if (!f) throw std::runtime_error("could not write " + path.string());
}

std::string sweep_json() {
  std::ostringstream s;
  s << R"({"start_ns": )" << num(kSweepStart_ns) << R"(, "stop_ns": )" << num(kSweepStop_ns)
    << R"(, "step_ps": )" << num(kSweepStep_ns * 1000) << "}";
  return s.str();
}

// Gate index k whose position tau_k = start + k * step puts the gate's end on a return arriving at
// t (tau = t - L): the rising edge of the count profile.
double rising_edge_index(double delay_ns, double distance_m) {
  const double t_ns = delay_ns + 2.0 * distance_m / kLightSpeed * 1e9;
  return (t_ns - kGateLength_ns - kSweepStart_ns) / kSweepStep_ns;
}

void node_translation(tinygltf::Node& n, double x, double y, double z) { n.translation = {x, y, z}; }

void add_spad_camera(GltfBuilder& b, int width_px, int height_px, double focal_mm, glm::dvec3 position) {
  // Not used by the scene files (they define the camera themselves so --set can move it); it is
  // here so the view can be checked in Blender or any glTF viewer.
  const int cam = b.add_perspective_camera("spad_camera", vertical_fov_rad(height_px, focal_mm),
                                           static_cast<double>(width_px) / height_px);
  tinygltf::Node node;
  node.name = "spad_camera";
  node.camera = cam;
  node_translation(node, position.x, position.y, position.z);
  b.add_node(node);
}

// ---------------------------------------------------------------------------------------------
// flat_target

void write_flat_target(const Options& o) {
  GltfBuilder b("spadgen scene library: flat target of the paper's section 4.D (CC0)");
  const int mat = b.add_material(lambertian("white_paper", o.target_reflectance));
  const int mesh = b.add_mesh("target", square(static_cast<float>(o.target_size)), mat);
  tinygltf::Node node;
  node.name = "target";
  node.mesh = mesh;
  b.add_node(node);
  add_spad_camera(b, 1024, 500, kFlatTargetFocal_mm, {0, 0, o.distance});
  const auto dir = std::filesystem::path(o.out_dir);
  b.write((dir / "flat_target.gltf").string(), "flat_target", "");

  const double delay_ns = 4.0;
  std::ostringstream s;
  s << R"({
  // The paper's ranging experiment (section 4.D, Fig. 9c-e): a flat white target (paper, reflectance
  // about 0.6) facing the camera, measured from 0.2 to 1.6 m. Generated by scenes_gen.
  "description": "Flat white Lambertian target (reflectance )" << num(o.target_reflectance)
    << R"() facing the camera at )" << num(o.distance) << R"( m; paper section 4.D",
  "gltf": "flat_target.gltf",
  "seed": 1,
  "camera": {
    // The target lies in the plane z = 0 facing +Z; the camera stands on the +Z axis looking at it,
    // so the distance is camera.position_m[2]: `--set camera.position_m=[0,0,0.2]` ... [0,0,1.6]
    // reproduces the paper's range sweep without regenerating the glTF.
    "position_m": [0, 0, )" << num(o.distance) << R"(],
    "look_at_m": [0, 0, 0],
    "up": [0, 1, 0],
    // Pixel A half of the chip, as in the paper's Fig. 9.
    "width_px": 1024,
    "height_px": 500,
    "focal_length_mm": )" << num(kFlatTargetFocal_mm) << R"(,
    "f_number": 1.4
  },
  "laser": {
    // ALS 637 nm picosecond laser of the paper, spread over the field of view.
    "wavelength_nm": 637,
    "repetition_rate_MHz": 40,
    "average_power_mW": 2,
    "pulse_fwhm_ps": 80,
    // The setup's fixed delay from trigger to emission. A return arrives at t = delay + 2 d / c and
    // the count profile rises at gate position tau = t - 3.8 ns: with 4.0 ns the rising edge of a
    // target at 0.2 m lies at gate index )"
    << std::lround(rising_edge_index(delay_ns, 0.2)) << R"( and at 1.6 m at index )"
    << std::lround(rising_edge_index(delay_ns, 1.6)) << R"( of the 351 positions
    // (0.6 to 13.2 ns), clear of the ends even with the 410 ps gate skew.
    "emission_delay_ns": )" << num(delay_ns) << R"(,
    "beam": "flood"
  },
  "ambient": {
    // A dark lab: the paper's ranging relies on the laser alone.
    "illuminance_lux": 0
  },
  "sensor": {
    "preset": "pixel_A"
  },
  "acquisition": {
    // Gate shifted from 0.6 to 13.2 ns in 36 ps steps (5.4 mm LSB), 255 binary frames (an 8-bit
    // image) per position.
    "mode": "gate_sweep",
    "frames": 255,
    // Laser cycles per binary frame: 40 us at 40 MHz, most of a 24 kfps frame.
    "cycles_per_frame": )" << kCyclesPerFrame << R"(,
    "gate_sweep": )" << sweep_json() << R"(
  },
  "render": {
    // A plane needs few samples; one bounce more than direct light is enough for a lone target.
    "samples_per_pixel": 16,
    "max_bounces": 2
  }
}
)";
  write_text(dir / "flat_target.json", s.str());
}

// ---------------------------------------------------------------------------------------------
// multi_object

void write_multi_object(const Options& o) {
  GltfBuilder b("spadgen scene library: plate and sphere of the paper's section 4.E (CC0)");

  tinygltf::Material plate = lambertian("plastic_plate", 1.0);
  plate.pbrMetallicRoughness.roughnessFactor = o.plate_roughness;
  plate.extensions["KHR_materials_transmission"] = object({{"transmissionFactor", tinygltf::Value(o.plate_transmission)}});
  plate.extensions["KHR_materials_ior"] = object({{"ior", tinygltf::Value(o.plate_ior)}});
  plate.extensions["KHR_materials_volume"] = object({{"thicknessFactor", tinygltf::Value(o.plate_thickness)}});
  const int plate_mat = b.add_material(plate);
  const int sphere_mat = b.add_material(lambertian("sphere_white", o.sphere_reflectance));

  // The plate: a closed box (KHR_materials_volume needs a closed surface) whose front face is the
  // node's origin plane, so the node's z is exactly the front face. It spans 0.4 m vertically (the
  // full chip's view is 0.35 m tall at 0.45 m) and leaves the right part of the view open, so that
  // pixels see plate and sphere, the plate alone, the sphere alone, and nothing.
  const double left = -0.35, height = 0.4;
  if (o.plate_right_edge <= left) throw std::runtime_error("--plate-right-edge must be > -0.35");
  const float t = static_cast<float>(o.plate_thickness);
  const float w = static_cast<float>(o.plate_right_edge - left);
  const float h = static_cast<float>(height);
  const int plate_mesh = b.add_mesh("plate", box({-0.5f * w, -0.5f * h, -t}, {0.5f * w, 0.5f * h, 0.0f}), plate_mat);
  tinygltf::Node plate_node;
  plate_node.name = "plate";
  plate_node.mesh = plate_mesh;
  node_translation(plate_node, 0.5 * (left + o.plate_right_edge), 0.0, -o.plate_distance);
  b.add_node(plate_node);

  double tess_error = 0;
  const int sphere_mesh = b.add_mesh("sphere", icosphere(o.sphere_radius, o.icosphere_level, &tess_error), sphere_mat);
  tinygltf::Node sphere_node;
  sphere_node.name = "sphere";
  sphere_node.mesh = sphere_mesh;
  node_translation(sphere_node, 0.0, 0.0, -(o.sphere_distance + o.sphere_radius));
  b.add_node(sphere_node);
  add_spad_camera(b, 1024, 500, kMultiObjectFocal_mm, {0, 0, 0});

  const auto dir = std::filesystem::path(o.out_dir);
  b.write((dir / "multi_object.gltf").string(), "multi_object", "multi_object.bin");
  const size_t triangles = b.model().accessors[static_cast<size_t>(b.model().meshes[1].primitives[0].indices)].count / 3;
  std::cout << "multi_object: icosphere level " << o.icosphere_level << ", " << triangles
            << " triangles, max tessellation error " << tess_error * 1e6 << " um (radius "
            << o.sphere_radius << " m)\n";

  // Put the plate's rising edge at the requested gate index (the paper's Fig. 10c: about 40).
  const double delay_ns =
      std::round(100.0 * (kSweepStart_ns + o.plate_gate_index * kSweepStep_ns + kGateLength_ns -
                          2.0 * o.plate_distance / kLightSpeed * 1e9)) / 100.0;
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s << R"({
  // The paper's multi-object experiment (section 4.E, Fig. 10 and 11): a transparent plastic plate
  // between the camera and a white sphere. Generated by scenes_gen.
  "description": "Transmissive plate ()" << num(o.plate_thickness * 1000) << " mm, ior " << num(o.plate_ior)
    << ") at " << num(o.plate_distance) << " m in front of a Lambertian sphere (nearest point "
    << num(o.sphere_distance) << R"( m); paper section 4.E",
  "gltf": "multi_object.gltf",
  "seed": 1,
  "camera": {
    // At the origin looking down -Z. The plate covers the left part of the view (x < )"
    << num(o.plate_right_edge) << R"( m): pixels
    // there see the plate and, through it, the sphere (the paper's points A and B) or the plate alone
    // (point C); pixels on the right see the sphere without the plate.
    "position_m": [0, 0, 0],
    "look_at_m": [0, 0, -1],
    "up": [0, 1, 0],
    "width_px": 1024,
    "height_px": 500,
    "focal_length_mm": )" << num(kMultiObjectFocal_mm) << R"(,
    "f_number": 1.4
  },
  "laser": {
    // PicoQuant 510 nm laser of the paper, spread by a diffuser.
    "wavelength_nm": 510,
    "repetition_rate_MHz": 40,
    "average_power_mW": 2,
    "pulse_fwhm_ps": 130,
    // Chosen so the profiles rise where the paper's Fig. 10c shows them: with tau_k = 0.6 ns + k * 36 ps
    // and a rising edge at tau = delay + 2 d / c - 3.8 ns, the plate's front face rises at gate
    // index )"
    << std::setprecision(1) << rising_edge_index(delay_ns, o.plate_distance)
    << R"( and the sphere's nearest point at index )" << rising_edge_index(delay_ns, o.sphere_distance)
    << R"( (the paper: "around gate
    // positions 40 and 100").
    "emission_delay_ns": )" << num(delay_ns) << R"(,
    // The diffused beam leaves 3 cm to the right of the lens, as a laser beside a camera does: a laser
    // exactly at the camera would see its own mirror image in the plate as a saturated spot; from here
    // that image falls just right of the plate's edge. A 16 degree cone covers the whole view from
    // this offset down to the plate (a flood cone is sized for directions from the camera centre).
    "beam": "cone",
    "half_angle_deg": 16,
    "offset_m": [0.03, 0, 0]
  },
  "ambient": {
    // The lab is dark and has no background: rays that miss both objects return nothing.
    "illuminance_lux": 0
  },
  "sensor": {
    "preset": "pixel_A"
  },
  "acquisition": {
    "mode": "gate_sweep",
    "frames": 255,
    // Laser cycles per binary frame: 40 us at 40 MHz, most of a 24 kfps frame.
    "cycles_per_frame": )" << kCyclesPerFrame << R"(,
    "gate_sweep": )" << sweep_json() << R"(
  },
  "render": {
    "samples_per_pixel": 16,
    // Light reaching the sphere crosses the plate's two faces each way: allow those bounces.
    "max_bounces": 8,
    "max_layers": 8
  }
}
)";
  write_text(dir / "multi_object.json", s.str());
}

// ---------------------------------------------------------------------------------------------
// test_chart

// Reflectances of the chart (linear): white paper and black ink.
constexpr double kChartWhite = 0.8;
constexpr double kChartBlack = 0.04;

// A resolution chart: groups of five bars of decreasing width, vertical bars (horizontal
// resolution) on the upper band and horizontal bars (vertical resolution) on the middle band, and a
// grey step wedge at the bottom. Widths are whole texels so every edge is sharp.
std::vector<uint8_t> chart_texture(int n) {
  std::vector<double> refl(static_cast<size_t>(n) * static_cast<size_t>(n), kChartWhite);
  const auto set = [&](int x, int y, double r) {
    if (x >= 0 && y >= 0 && x < n && y < n) refl[static_cast<size_t>(y) * static_cast<size_t>(n) + static_cast<size_t>(x)] = r;
  };
  const auto fill = [&](int x0, int y0, int x1, int y1, double r) {
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) set(x, y, r);
  };
  const double s = n / 2048.0;  // layout designed on a 2048-texel chart
  const auto px = [&](double v) { return static_cast<int>(std::lround(v * s)); };
  // Bar widths in texels of the 2048 layout: 0.44 mm per texel on the 0.9 m chart, i.e. about 0.56
  // sensor pixels at 1 m, so the finest groups go past the sensor's Nyquist limit on purpose.
  const std::vector<int> widths = {32, 24, 16, 12, 8, 6, 4, 3, 2, 1};
  const int margin = px(96);

  // Upper band: vertical bars.
  {
    int x = margin, used = 0;
    for (int wd : widths) used += 9 * std::max(1, px(wd));
    const int gap = (n - 2 * margin - used) / static_cast<int>(widths.size() - 1);
    const int y0 = px(128), y1 = px(768);
    for (int wd : widths) {
      const int bw = std::max(1, px(wd));
      for (int k = 0; k < 5; ++k) fill(x + 2 * k * bw, y0, x + (2 * k + 1) * bw, y1, kChartBlack);
      x += 9 * bw + gap;
    }
  }
  // Middle band: horizontal bars, one group per column.
  {
    const int column = (n - 2 * margin) / static_cast<int>(widths.size());
    for (size_t g = 0; g < widths.size(); ++g) {
      const int bw = std::max(1, px(widths[g]));
      const int x0 = margin + static_cast<int>(g) * column, x1 = x0 + column - px(32);
      const int yc = px(1216), y0 = yc - 9 * bw / 2;
      for (int k = 0; k < 5; ++k) fill(x0, y0 + 2 * k * bw, x1, y0 + (2 * k + 1) * bw, kChartBlack);
    }
  }
  // Bottom band: 16 grey steps, each 2^-0.4 of the one before (0.8 down to 0.0126), spanning
  // 36 dB of reflectance for the HDR (dual exposure) comparison.
  {
    const int steps = 16, x0 = margin, width = n - 2 * margin;
    // A black outline, so the first step (as bright as the paper) has visible edges.
    fill(x0 - px(8), px(1592), x0 + width + px(8), px(1928), kChartBlack);
    for (int k = 0; k < steps; ++k)
      fill(x0 + k * width / steps, px(1600), x0 + (k + 1) * width / steps, px(1920),
           kChartWhite * std::pow(2.0, -0.4 * k));
  }
  // A black frame marks the chart's edge in the image.
  fill(0, 0, n, px(16), kChartBlack);
  fill(0, n - px(16), n, n, kChartBlack);
  fill(0, 0, px(16), n, kChartBlack);
  fill(n - px(16), 0, n, n, kChartBlack);

  std::vector<uint8_t> grey(refl.size());
  std::transform(refl.begin(), refl.end(), grey.begin(), srgb_byte);
  return grey;
}

std::string chart_scene_text(const Options& o, bool dual) {
  std::ostringstream s;
  s << R"({
  // The paper's 2D imaging (section 4.C, Fig. 6 and 7): a resolution test chart under 50 lux of
  // ambient light, summed over 4080 binary frames (Fig. 7's 12-bit image, N_sat = 4080 in eq. (5)/(6));
  // Fig. 6's 14-bit image sums 16,320: `--set acquisition.frames=16320`.)";
  if (dual)
    s << R"(
  // Dual exposure: short and long global exposures interleaved, tau_L = 8 tau_S. The paper compares
  // it with single exposure at equal total time, 2 tau_M = tau_S + tau_L with tau_M = 4.5 tau_S:
  // with test_chart.json's tau_M = 10 us, tau_S = 10 / 4.5 = 2.2222 us and tau_L = 17.778 us.)";
  s << R"(
  // Generated by scenes_gen.
  "description": "Resolution test chart (bars, grey wedge) under 50 lux, )"
    << (dual ? "dual exposure 1:8" : "single exposure") << R"(; paper section 4.C",
  "gltf": "test_chart.gltf",
  "seed": 1,
  "camera": {
    // The whole 1 Mpixel chip (both halves), as in the paper's Fig. 6; the )" << num(o.chart_size)
    << R"( m chart at )" << num(o.chart_distance) << R"( m
    // fills the view. `--set camera.height_px=500 --set sensor.preset=pixel_A` images one half.
    "position_m": [0, 0, 0],
    "look_at_m": [0, 0, -1],
    "up": [0, 1, 0],
    "width_px": 1024,
    "height_px": 1000,
    "focal_length_mm": )" << num(kChartFocal_mm) << R"(,
    "f_number": 1.4
  },
  "ambient": {
    // Uniform indoor light; the laser stays off in 2D mode (acquisition.intensity.laser_on false).
    "illuminance_lux": 50
  },
  "sensor": {
    "preset": "full_chip"
  },
  "acquisition": {
    "mode": "intensity",
    "frames": 4080,
    "intensity": {)";
  if (dual)
    s << R"("exposure": "dual", "exposure_us": 2.2222, "dual_ratio": 8})";
  else
    s << R"("exposure": "single", "exposure_us": 10})";
  s << R"(
  },
  "render": {
    // Ambient light only, so a few samples per pixel suffice; they also average the finest bar
    // groups (narrower than a pixel) over each pixel's footprint.
    "samples_per_pixel": 16,
    "max_bounces": 2
  }
}
)";
  return s.str();
}

void write_test_chart(const Options& o) {
  GltfBuilder b("spadgen scene library: resolution test chart for the paper's section 4.C (CC0)");
  const int n = o.chart_texels;
  const int tex = b.add_png_texture("test_chart", encode_png(chart_texture(n), n, n, 1),
                                    TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE, TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE);
  tinygltf::Material m = lambertian("test_chart_print", 1.0);
  m.pbrMetallicRoughness.baseColorTexture.index = tex;
  const int mat = b.add_material(m);
  const int mesh = b.add_mesh("chart", square(static_cast<float>(o.chart_size)), mat);
  tinygltf::Node node;
  node.name = "chart";
  node.mesh = mesh;
  node_translation(node, 0, 0, -o.chart_distance);
  b.add_node(node);
  add_spad_camera(b, 1024, 1000, kChartFocal_mm, {0, 0, 0});
  const auto dir = std::filesystem::path(o.out_dir);
  b.write((dir / "test_chart.gltf").string(), "test_chart", "");
  write_text(dir / "test_chart.json", chart_scene_text(o, false));
  write_text(dir / "test_chart_dual.json", chart_scene_text(o, true));
}

}  // namespace
}  // namespace spadgen::scenes_gen

int main(int argc, char** argv) {
  using namespace spadgen::scenes_gen;
  try {
    const Options o = parse_options(argc, argv);
    std::filesystem::create_directories(o.out_dir);
    const auto wanted = [&](const char* name) { return o.only.empty() || o.only.count(name) > 0; };
    if (wanted("flat_target")) write_flat_target(o);
    if (wanted("multi_object")) write_multi_object(o);
    if (wanted("test_chart")) write_test_chart(o);
    std::cout << "scenes written to " << o.out_dir << "\n";
  } catch (const std::exception& e) {
    std::cerr << "scenes_gen: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
