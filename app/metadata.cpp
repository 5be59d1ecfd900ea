#include "app/metadata.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <string_view>

#include "app/resources.h"
#include "core/units.h"
#include "render/integrator.h"
#include "scenes/input.h"
#include "render/camera.h"
#include "sensor/model/pixel_layout.h"

#ifndef SPADGEN_VERSION
#define SPADGEN_VERSION "dev"
#endif

namespace spadgen::app {
namespace fs = std::filesystem;
using json = nlohmann::json;
using ojson = nlohmann::ordered_json;

namespace {

json crop_json(const PixelRect& r) { return json::array({r.x0, r.y0, r.width, r.height}); }

}  // namespace

json objects_json(const scenes::Scene& scene) {
  json list = json::array();
  for (const scenes::Object& o : scenes::objects_of(scene).list) {
    std::vector<std::string> meshes, materials;
    for (int m : o.meshes) {
      const scenes::Mesh& mesh = scene.meshes[size_t(m)];
      meshes.push_back(mesh.name);
      // glTF's default material has no name; "(default)" as spadgen info lists it.
      const std::string material = mesh.material >= 0 ? scene.materials[size_t(mesh.material)].name : "(default)";
      if (std::find(materials.begin(), materials.end(), material) == materials.end()) materials.push_back(material);
    }
    list.push_back({{"id", o.id}, {"name", o.name}, {"node", o.node}, {"meshes", meshes}, {"materials", materials}});
  }
  return list;
}

// The images' pinhole camera in the convention of OpenCV and most vision code: camera frame x right,
// y down, z forward (the viewing direction); pixel (u, v) of an image centred at the integer point (u, v).
// render::Camera centres sensor pixel x at x + 0.5 with the optical axis through the sensor's centre
// (width / 2, height / 2), and an image's pixel (0, 0) is the crop's corner (x0, y0): hence c = size / 2
// - 0.5 - crop corner. A camera-frame point (X, Y, Z) lands at u = f X / Z + cx, v = f Y / Z + cy.
json model_components(const RunConfig& c, const scenes::Scene* scene, bool laser, const json& from_run) {
  // The components the scene decides (a sense takes them from its run), in this order.
  static constexpr std::array<std::string_view, 5> kFromScene{"transmissive surfaces", "absorbing volumes", "ambient light",
                                                              "guided connections", "laser mirrors"};
  json out = json::array();
  const auto add = [&](const char* component, bool active, const std::string& why) {
    out.push_back({{"component", component}, {"active", active}, {"why", why}});
  };
  if (scene) {
    bool transmissive = false, volumes = false, emission = false, refractive = false;
    for (size_t i = 0; i < scene->materials.size(); ++i) {
      const scenes::Material& m = scene->materials[i];
      if (!scene->material_used(i)) continue;
      transmissive |= m.transmissive();
      refractive |= m.refracting();
      volumes |= m.transmissive() && m.thickness_m > 0.0f && std::isfinite(m.attenuation_distance_m);
      emission |= m.emissive.x > 0.0f || m.emissive.y > 0.0f || m.emissive.z > 0.0f;
    }
    add(kFromScene[0].data(), transmissive,
        transmissive ? std::string("a mesh has a transmissive material: paths refract through it, and shadow rays walk through it "
                                   "with its Fresnel transmittance") +
                           (refractive ? "; the laser's connections refract through its volumes (a thickness, ior != 1)"
                                       : " in straight lines (no volume of ior != 1)")
                     : "no mesh has a transmissive material: shadow rays are occlusion tests");
    add(kFromScene[1].data(), volumes,
        volumes ? "a transmissive material has a thickness and a finite attenuation distance (KHR_materials_volume)"
                : "no transmissive material with a thickness and a finite attenuation distance");
    const bool lights = c.ambient.gltf_lights && !scene->lights.empty();
    const bool environment = c.ambient.spectral_irradiance_W_m2_nm ? *c.ambient.spectral_irradiance_W_m2_nm > 0.0
                                                                   : c.ambient.illuminance_lux > 0.0;
    add(kFromScene[2].data(), environment || lights || emission,
        std::string(environment ? "ambient.illuminance_lux or spectral_irradiance_W_m2_nm > 0; " : "no ambient environment; ") +
            (lights ? "glTF punctual lights (ambient.gltf_lights); " : "no glTF light used; ") +
            (emission ? "emissive materials" : "no emissive material"));
    const bool guided = render::guided_connections_active(*scene, c.render.guided_connections) && laser;
    add(kFromScene[3].data(), guided,
        guided ? "a material of narrow glossy lobe (roughness 0.032-0.2): glossy and Lambertian vertices also draw towards "
                 "its reflections of the laser, with MIS (render.guided_connections)"
               : !c.render.guided_connections ? "render.guided_connections is false"
               : !laser                       ? "the laser is not traced (laser light)"
                                              : "no material of roughness 0.032-0.2");
    const bool mirrors = render::laser_mirrors_active(*scene) && laser;
    add(kFromScene[4].data(), mirrors,
        mirrors ? "a mesh of a smooth material (roughness below 0.032) has at most 64 triangles or vertex normals: vertices "
                  "are also connected to the laser's image in its planar faces or off its curved surface"
        : !laser ? "the laser is not traced (laser light)"
                 : "no mesh of a smooth material (roughness below 0.032) has at most 64 triangles or vertex normals");
  } else if (from_run.is_array()) {
    for (const json& e : from_run)
      if (std::find(kFromScene.begin(), kFromScene.end(), e.value("component", "")) != kFromScene.end()) out.push_back(e);
  }
  add("laser light", laser,
      c.acquisition.mode == AcquisitionMode::GateSweep ? "a gate sweep images the laser's light"
      : c.acquisition.intensity.laser_on              ? "acquisition.intensity.laser_on is true"
      : c.outputs.transient                           ? "outputs.transient is true: the laser's light is kept"
      : c.outputs.light && c.render.window_start_s    ? "outputs.light with render.window_start_ns keeps the laser's light (for a later sense as a gate sweep)"
      : laser ? "the run's saved light holds the laser's (a sense of a run that traced it)"
              : "the intensity mode without acquisition.intensity.laser_on (and no outputs.transient): the laser is not "
                "traced; no laser.exr, no laser channels in ground_truth.exr" +
                    std::string(c.outputs.light ? "; the saved light holds none (a spadgen sense of it in this mode needs none)" : ""));
  add("indirect light", c.render.max_bounces > 1,
      "render.max_bounces = " + std::to_string(c.render.max_bounces) + (c.render.max_bounces > 1 ? "" : ": direct light only"));
  add("target error", c.render.target_relative_error.has_value(),
      c.render.target_relative_error ? "render.target_relative_error is set: paths per pixel from a first round"
                                     : "render.target_relative_error is null: render.samples_per_pixel paths in every pixel");
  // The sensor's components, as the pixel designs the chip has (sensor.preset) set them: a switch that is on
  // does nothing where those designs' values are 0 (listed active, their rates were bit-identical to the
  // component's off).
  std::vector<const PixelTypeConfig*> designs;
  for (const int t : sensor::PixelLayout(c.sensor.preset, c.camera.height_px).types())
    designs.push_back(t == 0 ? &c.sensor.pixel_A : &c.sensor.pixel_B);
  const auto any = [&](auto value) {
    return std::any_of(designs.begin(), designs.end(), [&](const PixelTypeConfig* d) { return value(*d) > 0.0; });
  };
  const std::string used = designs.size() == 2 ? "sensor.pixel_A or pixel_B's" : designs[0] == &c.sensor.pixel_A ? "sensor.pixel_A's" : "sensor.pixel_B's";
  const bool dark = c.sensor.dark_counts && any([](const PixelTypeConfig& d) { return d.dcr_median_cps; });
  add("dark counts", dark, !c.sensor.dark_counts ? "sensor.dark_counts is false"
                           : dark ? "sensor.dark_counts is true" : "the pixel designs in use have dcr_median_cps 0");
  const bool hot = dark && any([](const PixelTypeConfig& d) { return d.hot_pixel_fraction; });
  add("hot pixels", hot, hot ? used + " hot_pixel_fraction > 0" : "no dark counts, or hot_pixel_fraction 0 in the pixel designs in use");
  const bool crosstalk = c.sensor.crosstalk && any([](const PixelTypeConfig& d) { return d.crosstalk_probability; });
  add("crosstalk", crosstalk, !c.sensor.crosstalk ? "sensor.crosstalk is false"
                              : crosstalk ? "sensor.crosstalk is true" : "the pixel designs in use have crosstalk_probability 0");
  const bool sweep = c.acquisition.mode == AcquisitionMode::GateSweep;
  const bool file_maps = !c.sensor.gate.maps_exr.empty();
  const bool maps = sweep && (file_maps || (c.sensor.skew && (c.sensor.gate.skew_fwhm_s > 0.0 || c.sensor.gate.length_fwhm_s > 0.0)));
  add("per-pixel gate maps", maps, !sweep ? "the intensity mode has no gate"
                                   : file_maps ? "sensor.gate.maps_exr is set"
                                   : !c.sensor.skew ? "sensor.gate_skew is false: every pixel has the nominal gate"
                                   : maps ? "sensor.gate_skew is true"
                                          : "sensor.gate.skew_fwhm_ps and length_fwhm_ps are 0: every pixel has the nominal gate");
  const bool pdp = c.sensor.pdp_nonuniformity && any([](const PixelTypeConfig& d) { return d.pdp_nonuniformity; });
  add("PDP non-uniformity", pdp, !c.sensor.pdp_nonuniformity ? "sensor.pdp_nonuniformity is false"
                                 : pdp ? "sensor.pdp_nonuniformity is true" : "the pixel designs in use have pdp_nonuniformity 0");
  add("binary frames", c.outputs.frames, c.outputs.frames ? "outputs.frames is true" : "outputs.frames is false: counts are sampled without frames");
  return out;
}

json run_json(const RunRecord& r) {
  const RunTimes& t = r.times;
  const double wall = t.setup_seconds + t.tiles_seconds + t.finish_seconds;
  double thread_sum = 0.0;
  for (const double s : t.stage_thread_seconds) thread_sum += s;
  // A tile stage's wall seconds: the tiles' wall time, apportioned by the stages' thread time.
  const auto stage_wall = [&](StageClock::Stage k) {
    return thread_sum > 0.0 ? t.tiles_seconds * t.stage_thread_seconds[size_t(k)] / thread_sum : 0.0;
  };
  const auto share = [&](double seconds) { return wall > 0.0 ? seconds / wall : 0.0; };
  json stages = json::array();
  const auto add = [&](const char* name, double seconds, const json& thread_seconds) {
    stages.push_back({{"stage", name}, {"seconds", seconds}, {"share", share(seconds)}, {"thread_seconds", thread_seconds}});
  };
  add("setup: scene, BVH, sensor maps, outputs opened", t.setup_seconds, nullptr);
  static constexpr std::array<const char*, StageClock::kStageCount> kNames{
      "ground truth", "light transport", "saved light read (spadgen sense)", "sensor: gate response and rates", "sensor: temporal noise (counts, frames, crosstalk)",
      "outputs: labels and stacks"};
  for (int k = 0; k < StageClock::kStageCount; ++k)
    add(kNames[size_t(k)], stage_wall(StageClock::Stage(k)), t.stage_thread_seconds[size_t(k)]);
  add("finish: images and previews", t.finish_seconds, nullptr);

  const render::RayCounts& rays = r.render_stats.rays;
  const double light = share(stage_wall(StageClock::kLightTransport));
  const auto of_rays = [&](uint64_t n) { return rays.total() > 0 ? light * double(n) / double(rays.total()) : 0.0; };
  json components = json::array();
  if (r.model.is_array())
    for (const json& m : r.model) {
      const std::string name = m.value("component", "");
      const bool active = m.value("active", false);
      json value = nullptr;
      std::string measured;
      if (name == "transmissive surfaces") value = of_rays(rays.refracted), measured = "its refracted laser connections' share of the light transport's rays";
      else if (name == "laser light") value = of_rays(rays.laser), measured = "its shadow rays' share of the light transport's rays";
      else if (name == "ambient light") value = of_rays(rays.ambient), measured = "its shadow rays' share of the light transport's rays (the environment costs none)";
      else if (name == "guided connections") value = of_rays(rays.guided), measured = "its rays' share of the light transport's rays";
      else if (name == "laser mirrors") value = of_rays(rays.mirror), measured = "its rays' share of the light transport's rays";
      else if (name == "indirect light") value = of_rays(rays.indirect), measured = "the share of the light transport's rays traced after a path's first vertex";
      else if (name == "binary frames") value = active ? share(stage_wall(StageClock::kSensorNoise)) : 0.0, measured = "the sensor's temporal-noise stage, which samples the frames";
      else if (!active) value = 0.0, measured = "skipped";
      else measured = "no time of its own: part of a stage above";
      components.push_back({{"component", name}, {"share", value}, {"measured", measured}});
    }
  json rays_json = {{"camera", rays.camera},       {"bounce", rays.bounce}, {"laser", rays.laser},
                    {"refracted", rays.refracted}, {"mirror", rays.mirror}, {"guided", rays.guided},
                    {"ambient", rays.ambient},     {"indirect", rays.indirect}, {"total", rays.total()}};
  // The cores its threads could run on (--threads, or all, at most the machine's): what a dataset plan's pace
  // compares the sample's time with (the plan's own --threads made it 2 times off for samples of 1 thread).
  return {{"threads", r.threads}, {"cores", usable_cores(r.threads)}, {"seconds", r.seconds}, {"wall_seconds", wall}, {"stages", stages},
          {"rays", rays_json}, {"components", components}};
}

json camera_json(const render::Camera& cam, const PixelRect& img, const glm::dvec3& laser_world) {
  const double f = cam.focal_length_m() / cam.pitch_m();
  const double cx = 0.5 * cam.width() - 0.5 - img.x0, cy = 0.5 * cam.height() - 0.5 - img.y0;
  // + 0.0 turns the -0.0 of a negated zero into 0.0, which reads better in the JSON.
  const glm::dvec3 x = cam.right() + 0.0, up = cam.up() + 0.0, y = -cam.up() + 0.0, z = cam.forward() + 0.0;
  const glm::dvec3 t = cam.position() + 0.0;
  const glm::dvec3 l = laser_world - t;
  return {{"convention", "OpenCV: camera x right, y down, z forward; pixel (u, v) centred at integers (u, v), "
                         "(0, 0) the image's top-left pixel (the crop's corner); world: the glTF scene's frame"},
          {"intrinsics", {{f, 0.0, cx}, {0.0, f, cy}, {0.0, 0.0, 1.0}}},
          {"camera_to_world", {{x.x, y.x, z.x, t.x}, {x.y, y.y, z.y, t.y}, {x.z, y.z, z.z, t.z}, {0.0, 0.0, 0.0, 1.0}}},
          {"focal_length_m", cam.focal_length_m()},
          {"pixel_pitch_m", cam.pitch_m()},
          {"position_m", {t.x, t.y, t.z}},
          {"forward", {z.x, z.y, z.z}},
          {"up", {up.x, up.y, up.z}},
          {"laser_position_m", {glm::dot(l, x) + 0.0, glm::dot(l, y) + 0.0, glm::dot(l, z) + 0.0}},
          {"laser_world_position_m", {laser_world.x + 0.0, laser_world.y + 0.0, laser_world.z + 0.0}}};
}


Provenance provenance(const RunConfig& c, const PixelRect& img, const std::string& scene_hash, const std::string& tables_hash,
                      const std::vector<scenes::SensorTable>& tables) {
  return {c.scene_file, scene_hash, c.seed, img, c.chip_seed(), tables_hash, tables};
}

void stamp(writers::ExrImage& e, const Provenance& p) {
  e.set_attribute("spadgen_version", SPADGEN_VERSION);
  e.set_attribute("spadgen_seed", std::to_string(p.seed));
  e.set_attribute("spadgen_scene_file", p.scene_file);
  e.set_attribute("spadgen_scene_hash", p.scene_hash);
  e.set_attribute("spadgen_crop", crop_json(p.crop).dump());
}

json axis_json(const TimeAxis& a) {
  return {{"start_ns", a.start_s / kNs}, {"bin_width_ps", a.bin_width_s / kPs}, {"bins", a.bins},
          {"end_ns", a.end_s() / kNs}, {"laser_period_ns", a.period_s / kNs}};
}

std::string settings_hash_of(const nlohmann::json& resolved_scene) {
  nlohmann::json settings = resolved_scene;  // (nlohmann::json: keys sorted, so the text is canonical)
  for (const char* k : {"seed", "seeds", "outputs", "render", "description"}) settings.erase(k);
  return scenes::hex64(scenes::fnv1a64(settings.dump()));
}

json metadata(const scenes::ResolvedRun& resolved, const std::vector<std::string>& scene_warnings,
              const sensor::SensorModel& sensor, const Provenance& p, const TimeAxis& axis, const RunRecord& r) {
  const RunConfig& cfg = resolved.config;
  const PixelRect& img = p.crop;
  ojson meta;
  meta["spadgen_version"] = SPADGEN_VERSION;
  meta["scene_file"] = p.scene_file;
  meta["scene_hash_fnv1a64"] = p.scene_hash;
  meta["seed"] = p.seed;
  meta["sensor_tables_fnv1a64"] = p.tables_hash;
  // Per table in use, so that spadgen sense says which of the tables it reads where the run did have changed
  for (const scenes::SensorTable& t : p.tables)
    if (!t.path.empty()) meta["sensor_table_fnv1a64"][t.key] = t.hash;
  // The seed each random stream used (seeds.* when set, else seed).
  meta["seeds"] = {{"light", cfg.light_seed()}, {"chip", cfg.chip_seed()}, {"noise", cfg.noise_seed()}};
  meta["versions"] = {{"spadgen", SPADGEN_VERSION},
                      {"embree", std::to_string(RTC_VERSION_MAJOR) + "." + std::to_string(RTC_VERSION_MINOR) + "." + std::to_string(RTC_VERSION_PATCH)}};
  meta["units"] = {{"length", "m"}, {"time", "s unless the key says ns or ps"}, {"laser", "photons per laser pulse at the SPAD, before PDP"},
                   {"ambient", "photons per second at the SPAD, before PDP"}, {"counts", "summed binary frames"},
                   {"detection_rate", "mean avalanches per binary frame (lambda; expected counts N (1 - exp(-lambda)))"}};
  meta["image"] = {{"width", img.width}, {"height", img.height}, {"crop_in_sensor", {img.x0, img.y0, img.width, img.height}},
                   {"sensor_width", cfg.camera.width_px}, {"sensor_height", cfg.camera.height_px},
                   {"pixel_order", "row 0 is the top of the image; (K, H, W) stacks index [k, y, x]"}};
  meta["camera"] = r.camera;
  meta["photons_per_pulse_emitted"] = r.photons_per_pulse_emitted;
  meta["time_axis"] = ojson::parse(axis_json(axis).dump());
  if (cfg.outputs.transient) {
    const PixelRect& tc = r.transient_crop;
    meta["transient"] = {{"crop_in_sensor", {tc.x0, tc.y0, tc.width, tc.height}},
                         {"shape", {tc.height, tc.width, axis.bins}},
                         {"indirect", cfg.render.split_direct_indirect
                                          ? "transient_indirect.npy: the part of transient.npy from paths with two or more "
                                            "scattering vertices (docs/render.md); direct = transient - transient_indirect"
                                          : "not split (render.split_direct_indirect is false)"}};
  }
  if (r.light_region) {
    const PixelRect& lr = *r.light_region;
    // The axis in seconds as the sensor used it (time_axis above is in ns, rounded by the conversion).
    meta["light"] = {{"crop_in_sensor", {lr.x0, lr.y0, lr.width, lr.height}},
                     {"time_axis_s", {{"start", axis.start_s}, {"bin_width", axis.bin_width_s}, {"bins", axis.bins},
                                      {"laser_period", axis.period_s}}},
                     {"values_bytes", r.light_values_bytes},
                     {"layout", "docs/outputs.md, section Saved light"}};
    json runs = json::array();
    for (size_t y = 0; y < r.light_fill_factor.size(); ++y)
      if (y == 0 || r.light_fill_factor[y] != r.light_fill_factor[y - 1]) runs.push_back({y, 1, r.light_fill_factor[y]});
      else runs.back()[1] = runs.back()[1].get<size_t>() + 1;
    meta["light"]["fill_factor"] = runs;
  }
  if (r.laser_traced)
    meta["laser_photons_per_pulse"] = {{"total_all_pixels", r.laser_total},
                                       {"outside_time_window", r.out_of_window_total},
                                       {"outside_fraction", r.laser_total > 0 ? r.out_of_window_total / r.laser_total : 0.0}};
  else
    meta["laser_photons_per_pulse"] = nullptr;  // not traced (model: "laser light")
  if (!r.accuracy.is_null()) meta["accuracy"] = ojson::parse(r.accuracy.dump());
  if (!r.model.is_null()) meta["model"] = ojson::parse(r.model.dump());
  meta["acquisition"] = ojson::parse(sensor.describe().dump());
  meta["ground_truth_layers"] = r.ground_truth_layers;
  meta["ground_truth_objects"] = r.ground_truth_objects;
  meta["objects"] = ojson::parse(r.objects.dump());
  if (!r.ground_truth_summary.is_null()) meta["ground_truth_summary"] = ojson::parse(r.ground_truth_summary.dump());
  if (r.dataset) meta["dataset"] = ojson::parse(r.dataset->dump());
  meta["counts_dtype"] = r.counts_u8 ? "uint8" : "uint16";
  meta["storage"] = {{"stacks", to_string(cfg.outputs.storage)},
                     {"exr_compression", to_string(cfg.outputs.exr_compression)},
                     {"files", ojson::parse(r.storage.dump())}};
  meta["preview_profile_pixels"] = r.profile_pixels;
  meta["warnings"] = resolved.warnings;
  for (const std::string& w : scene_warnings) meta["warnings"].push_back(w);
  meta["resolved_scene"] = resolved.resolved;
  // (from the text metadata.json holds, as a reader parses it: reconstruct hashes the run's metadata alike)
  meta["settings_hash_fnv1a64"] = settings_hash_of(nlohmann::json::parse(resolved.resolved.dump()));
  meta["files"] = r.files;
  meta["file_bytes"] = ojson::parse(r.file_bytes.dump());
  if (r.sense) meta["sense"] = ojson::parse(r.sense->dump());
  // Everything above depends only on the scene and the seed; "run" is how this run went.
  meta["run"] = ojson::parse(run_json(r).dump());
  return json::parse(meta.dump());
}

}  // namespace spadgen::app
