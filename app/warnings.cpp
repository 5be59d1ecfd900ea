#include "app/warnings.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <utility>

#include <glm/glm.hpp>

#include "core/units.h"
#include "scenes/input.h"
#include "render/embree_scene.h"

namespace spadgen::app {
namespace {

std::string g(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

std::string percent(double fraction) { return g(100.0 * fraction) + " %"; }

double degrees(double rad) { return rad * 180.0 / kPi; }

}  // namespace

namespace {
std::string warning_context;  // WarningContext's
bool warnings_silent = false;
}  // namespace

void print_warning(const std::string& warning) {
  // (one line, as the errors: a path holding a newline split it)
  if (!warnings_silent)
    std::fprintf(stderr, "spadgen: warning: %s%s\n", warning_context.c_str(), scenes::one_line(warning).c_str());
}

WarningContext::WarningContext(std::string context, bool silent)
    : previous_(std::exchange(warning_context, std::move(context))), previous_silent_(std::exchange(warnings_silent, silent)) {}
WarningContext::~WarningContext() {
  warning_context = std::move(previous_);
  warnings_silent = previous_silent_;
}

std::vector<std::string> camera_warnings(const RunConfig& c, const scenes::Scene& scene) {
  std::vector<std::string> w;
  if (c.camera.gltf_camera.empty()) return w;
  const scenes::Camera* gc = scene.find_camera(c.camera.gltf_camera);
  if (!gc || !(gc->aspect_ratio > 0.0)) return w;  // no camera: the renderer's error; no aspect ratio: nothing to differ
  const double sensor = static_cast<double>(c.camera.width_px) / c.camera.height_px;
  if (std::fabs(gc->aspect_ratio / sensor - 1.0) <= kWarnAspectMismatch) return w;
  // The renderer keeps the vertical field of view (the glTF camera's, or camera.vertical_fov_deg).
  const double yfov = c.camera.vertical_fov_rad.value_or(gc->yfov_rad);
  const double meant = 2.0 * std::atan(gc->aspect_ratio * std::tan(0.5 * yfov));
  const double got = 2.0 * std::atan(sensor * std::tan(0.5 * yfov));
  w.push_back("camera.gltf_camera: the glTF camera '" + c.camera.gltf_camera + "' has the aspect ratio " +
              g(gc->aspect_ratio) + ", the " + std::to_string(c.camera.width_px) + " x " +
              std::to_string(c.camera.height_px) + " sensor " + g(sensor) + ": the vertical field of view (" +
              g(degrees(yfov)) + " deg) is kept and the horizontal one is " + g(degrees(got)) + " deg instead of " +
              g(degrees(meant)) + " (camera.width_px, camera.height_px)");
  return w;
}

std::vector<std::string> laser_warnings(const RunConfig& c, const render::Camera& camera, const scenes::Scene* scene) {
  std::vector<std::string> w;
  const auto spacing = [](double at) { return at > 0.0 ? std::ldexp(1.0, std::ilogb(at) - 23) : 0.0; };
  if (scene) {
    // The renderer works in a frame centred on the camera: a path's next ray steps off a transmissive
    // surface by kOffsetUlps ulps of the surface's distance from the camera.
    double farthest = 0.0, coarsest = 0.0;
    std::string far_mesh, coarse_mesh;
    for (const scenes::Mesh& m : scene->meshes) {
      const bool transmissive = m.material >= 0 && scene->materials[size_t(m.material)].transmissive();
      for (const glm::vec3& p : m.positions) {
        // Floats measured from the mesh's offset (the centre of its vertices): their spacing is that of their size.
        const double size = std::max({std::fabs(double(p.x)), std::fabs(double(p.y)), std::fabs(double(p.z))});
        if (size > coarsest) coarsest = size, coarse_mesh = m.name;
        if (!transmissive) continue;
        const double d = glm::length(glm::dvec3(p) + m.offset - camera.position());
        if (d > farthest) farthest = d, far_mesh = m.name;
      }
    }
    if (farthest >= kWarnTransmissiveFromCameraM) {
      const double step = double(render::kOffsetUlps) * spacing(farthest);
      w.push_back("the transmissive mesh '" + far_mesh + "' reaches " + g(farthest) + " m from the camera, where the renderer "
                  "moves each path's next ray up to " + g(step * 1e3) + " mm off the surface it leaves (" +
                  g(render::kOffsetUlps) + " float ulps of its distance from the camera): a plate about that thin or "
                  "thinner that far loses the light behind its back face (the ground truth is exact)");
    }
    // The laser's connections cross a curved refracting volume's faces (vertex normals) as smooth ones
    // (docs/render.md): behind a rough one the laser's light is too bright where the rough transmission would
    // spread it. (A flat one's rough faces are crossed by their own estimate.)
    const auto curved = [](const scenes::Mesh& mesh) {
      if (mesh.normals.size() != mesh.positions.size()) return false;
      for (size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
        const uint32_t* i = &mesh.indices[t];
        if (i[0] >= mesh.positions.size() || i[1] >= mesh.positions.size() || i[2] >= mesh.positions.size()) continue;
        const glm::vec3 n = glm::cross(mesh.positions[i[1]] - mesh.positions[i[0]], mesh.positions[i[2]] - mesh.positions[i[0]]);
        const float l = glm::length(n);
        if (!(l > 0.0f)) continue;
        for (int k = 0; k < 3; ++k)
          if (std::fabs(glm::dot(n / l, mesh.normals[i[k]])) < 1.0f - 1e-6f) return true;
      }
      return false;
    };
    for (size_t i = 0; i < scene->materials.size(); ++i) {
      const scenes::Material& m = scene->materials[i];
      if (!m.refracting() || !scene->material_used(i) || !(std::clamp(m.roughness, 0.0f, 1.0f) >= kWarnRoughRefractor)) continue;
      if (std::none_of(scene->meshes.begin(), scene->meshes.end(), [&](const scenes::Mesh& mesh) {
            return mesh.material == int(i) && curved(mesh);
          }))
        continue;
      w.push_back("the material '" + m.name + "' (roughness " + g(m.roughness) + ") bounds a curved refracting volume (vertex "
                  "normals) whose faces the laser's connections cross as smooth ones: the laser's light behind it is too "
                  "bright where its rough transmission would spread the light (crossed so, a 3 mm flat plate of ior 1.5 "
                  "measured +0.6 % to +3 % at roughness 0.2, +6 % to +34 % at 0.4, +42 % to +139 % at 0.7, the most at "
                  "30 degrees; flat faces are crossed rough)");
    }
    if (coarsest >= kWarnCoarseVerticesM)
      w.push_back("the mesh '" + coarse_mesh + "' has vertices " + g(coarsest) + " m from its centre, where floats are " +
                  g(spacing(coarsest) * 1e3) +
                  " mm apart: its depths and times of flight (" + g(2.0 * spacing(coarsest) / kSpeedOfLight * 1e12) +
                  " ps) are that coarse; split it into smaller meshes");
  }
  const double pixel_angle_rad = camera.pitch_m() / camera.focal_length_m();
  if (c.laser.beam != Beam::Cone || !(pixel_angle_rad > 0.0)) return w;
  // The spot against one pixel's footprint, as solid angles seen from the camera (the laser beside it).
  const double half = c.laser.half_angle_rad;
  const double spot_pixels = kPi * half * half / (pixel_angle_rad * pixel_angle_rad);
  const double paths = c.render.samples_per_pixel * spot_pixels;
  if (!(spot_pixels < 1.0 && paths < kWarnSpotPaths)) return w;
  w.push_back("laser.half_angle_deg: a cone of " + g(degrees(half)) + " deg lights a spot of about " + g(spot_pixels) +
              " pixels (a pixel spans " + g(degrees(pixel_angle_rad)) + " deg): a pixel's camera paths find the laser's light only "
              "where they land on the spot, about " + g(paths) + " of its " + std::to_string(c.render.samples_per_pixel) +
              " paths, so its light is noisy or missed (unbiased, but zero where no path lands); widen the cone or raise "
              "render.samples_per_pixel");
  return w;
}

bool is_sensor_warning(const std::string& warning) {
  return warning.rfind(kGateWarning, 0) == 0 || warning.rfind(kTablesChangedWarning, 0) == 0 || warning.rfind(kGridWarning, 0) == 0 ||
         warning.find(kPdpWarning) != std::string::npos || warning.find(kSweepEdgeWarning) != std::string::npos;
}

std::vector<std::string> sensor_warnings(const sensor::SensorModel& sensor, double asked_grid_s) {
  const nlohmann::json d = sensor.describe();
  std::vector<std::string> w;
  for (const nlohmann::json& t : d.at("pixel_types"))
    if (!(t.at("pdp_laser").get<double>() > 0.0)) {
      const std::string key = "sensor." + t.at("name").get<std::string>();
      w.push_back(key + kPdpWarning + " (laser.wavelength_nm) is 0 (the built-in curve spans 300 to 1100 nm; or " + key +
                  ".pdp_csv): its pixels see no laser light, only dark counts and ambient light");
    }
  if (!d.contains("gate")) return w;
  const nlohmann::json& gate = d.at("gate");
  // (the default, 0.25 ps, is "0.25 ps or coarser where needed": the shipped scenes' 0.26-0.29 ps is not warned about)
  const double grid_ps = gate.at("grid_ps").get<double>();
  if (asked_grid_s != GateConfig{}.grid_s && grid_ps > asked_grid_s / kPs * (1.0 + 1e-9))
    w.push_back(std::string(kGridWarning) + g(asked_grid_s / kPs) + " is finer than the fine grid goes: its step is " + g(grid_ps) +
                " ps, the gate's edges and the instrument response (pulse and jitter) over at most 12000 steps (metadata.json "
                "gate.grid_ps)");
  const double knots = gate.at("knot_max_error").get<double>(), grid = gate.at("grid_max_error").get<double>();
  const double error = knots + grid;
  if (!(error > kWarnGateError)) return w;
  w.push_back(std::string(kGateWarning) + " to within about " + percent(error) + " of its open value (knots_per_edge " +
          std::to_string(gate.at("knots_per_edge").get<int>()) + ": the knots within " + percent(knots) +
          " of the fine grid; grid_ps " + g(gate.at("grid_ps").get<double>()) + ": the grid within about " + percent(grid) +
          " of the exact gate), above " + percent(kWarnGateError) + ": the expected counts of " +
          std::to_string(sensor.frames_per_k()) + " frames may move by up to about " + g(error * sensor.frames_per_k()) +
          " counts per avalanche per frame of a pixel's rate with the gate open; more knots or a finer grid "
          "(docs/accuracy.md, \"The sensor model's knobs\")");
  return w;
}

std::vector<std::string> bright_gate_warnings(const sensor::SensorModel& sensor, double laser_open_rate) {
  const nlohmann::json d = sensor.describe();
  if (!d.contains("gate") || !(laser_open_rate > 1.0)) return {};
  const nlohmann::json& gate = d.at("gate");
  const double error = gate.at("knot_max_error").get<double>() + gate.at("grid_max_error").get<double>();
  if (!(error * laser_open_rate > kWarnGateError)) return {};
  const double N = sensor.frames_per_k();
  return {std::string(kGateWarning) + " to within about " + percent(error) + " of its open value (knots_per_edge " +
          std::to_string(gate.at("knots_per_edge").get<int>()) + ", grid_ps " + g(gate.at("grid_ps").get<double>()) +
          "), and that error is of the open gate's rate: the brightest return's, " + g(laser_open_rate) +
          " avalanches per frame with the gate open (cycles x PDP x laser photons per pulse), makes it up to about " +
          g(error * laser_open_rate) + " per frame where the gate's edges let "
          "little through, so expected counts of " + std::to_string(sensor.frames_per_k()) + " frames there may be off by up "
          "to about " + g(N * -std::expm1(-error * laser_open_rate)) + " counts (the returns' edges widen); more knots "
          "(sensor.gate.knots_per_edge) or a finer grid (docs/accuracy.md, \"The sensor model's knobs\")"};
}

std::vector<std::string> sweep_edge_warnings(const RunConfig& c, const RunRecord& r) {
  if (c.acquisition.mode != AcquisitionMode::GateSweep) return {};
  const auto& e = r.label_edges;
  const int64_t lit = e[kRisingEdge] + e[kFallingEdgeOnly] + e[kNoEdgeInSweep];
  const int64_t without = e[kFallingEdgeOnly] + e[kNoEdgeInSweep];
  if (lit == 0 || !(double(without) > kWarnLightFraction * double(lit))) return {};
  const auto pairs = [](int64_t n) { return std::to_string(n) + (n == 1 ? " pair" : " pairs"); };
  std::string w = percent(double(without) / double(lit)) + kSweepEdgeWarning + std::to_string(without) +
                  " of the " + pairs(lit) + " (pixel, object) with laser light in labels.exr) rise before the gate sweep's first "
                  "position (acquisition.gate_sweep.start_ns " + g(c.acquisition.gate_sweep.start_s * 1e9) +
                  " ns; a pixel's gate opens at the position plus sensor.gate.delay_ns " + g(c.sensor.gate.delay_s * 1e9) +
                  " ns and its skew): the counts hold no rising edge of them, only a fall (" + pairs(e[kFallingEdgeOnly]) +
                  ", which labels.exr labels) or no edge at all (" + pairs(e[kNoEdgeInSweep]) +
                  ": flat over the sweep); start the sweep earlier or lower sensor.gate.delay_ns";
  return {w};
}

std::vector<std::string> light_warnings(const RunConfig& c, const PixelRect& img, const RunRecord& r, const render::Camera& camera) {
  const double laser_total = r.laser_total;
  std::vector<std::string> w;
  const std::string image = std::to_string(img.width) + " x " + std::to_string(img.height) + " image";
  if (r.render_stats.camera_hits == 0) {
    w.push_back("nothing in view: no camera ray of the " + image +
                " hits a surface of the scene (camera.position_m, look_at_m, gltf_camera, crop): the outputs hold "
                "ambient light and dark counts only");
    return w;
  }
  // A surface through the camera's centre is met at range 0 (a ground plane at the camera's height, a mesh on
  // the camera's node): its pixels see nothing else.
  if (const nlohmann::json& lo = r.ground_truth_summary.is_object() ? r.ground_truth_summary.value("range_min_m", nlohmann::json())
                                                                     : nlohmann::json();
      lo.is_number() && lo.get<double>() <= kWarnRangeAtCameraM)
    w.push_back("a surface passes through the camera's centre: pixels of the " + image + " meet it at range " + g(std::max(0.0, lo.get<double>())) +
                " m (ground_truth.exr range; camera.position_m lies on a surface of the glTF, such as a ground plane at the "
                "camera's height or a mesh on the camera's node): move the camera off it");
  if (r.ground_truth_layers_cut > 0)
    w.push_back("render.max_layers (" + std::to_string(c.render.max_layers) + ") cuts the ground truth of " +
                std::to_string(r.ground_truth_layers_cut) + " pixels of the " + image + ": their rays pass " +
                std::to_string(c.render.max_layers) + " transmissive surfaces and meet beyond them an object that gets no "
                "slot in ground_truth.exr and labels.exr (their direct light counts in direct_other_laser, and spadgen "
                "evaluate scores a detection of them as false): raise render.max_layers");
  // The laser matters to a gate sweep, to transients, and to the intensity mode with laser_on; its timing
  // only to the first two.
  const bool timed = c.acquisition.mode == AcquisitionMode::GateSweep || c.outputs.transient;
  if (!timed && !c.acquisition.intensity.laser_on) return w;
  if (!(laser_total > 0.0)) {
    if (c.laser.average_power_W > 0.0)
      w.push_back("no laser light reaches the " + image + " (laser.beam, half_angle_deg, offset_m, gltf_light" +
                  (laser_warnings(c, camera).empty() ? std::string() : "; or no camera path landed on the cone's small spot") +
                  "; or what it lights reflects none of it: a black base colour, or a smooth mirror (roughness below "
                  "0.032, a Dirac lobe) that sends it where nothing in view is lit (the laser's image is rendered in planar "
                  "faces of small meshes only: docs/render.md, \"The laser's image in smooth planar faces\")): the outputs hold "
                  "ambient light and dark counts only");
    return w;
  }
  if (!timed) return w;
  const double beyond = r.beyond_period_total / laser_total;
  if (beyond > kWarnLightFraction)
    w.push_back(percent(beyond) + " of the laser light comes from beyond the unambiguous range of " +
                g(kSpeedOfLight / (2.0 * c.laser.repetition_rate_Hz)) + " m (c / 2 / laser.repetition_rate_MHz): its time of "
                "flight exceeds the laser period of " + g(1e9 / c.laser.repetition_rate_Hz) +
                " ns, so it folds onto the next pulse and looks nearer than it is");
  const double outside = r.out_of_window_total / laser_total;
  if (outside > kWarnLightFraction)
    w.push_back(percent(outside) + " of the laser light arrives outside the time window (metadata.json "
                "laser_photons_per_pulse.outside_fraction; acquisition.gate_sweep.start_ns, stop_ns, "
                "laser.emission_delay_ns, sensor.gate.delay_ns, or render.window_start_ns, window_stop_ns): "
                "the counts miss it");
  return w;
}

}  // namespace spadgen::app
