#include "app/pipeline.h"

#include <tbb/parallel_for.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>

#include "app/interrupt.h"
#include "app/metadata.h"
#include "app/outputs.h"
#include "app/light.h"
#include "app/preflight.h"
#include "app/progress.h"
#include "app/resources.h"
#include "app/run_parts.h"
#include "app/staging.h"
#include "app/warnings.h"
#include "core/error.h"
#include "core/stage_clock.h"
#include "core/units.h"
#include "render/camera.h"
#include "render/lights.h"
#include "render/renderer.h"
#include "scenes/key_path.h"
#include "scenes/scene.h"
#include "scenes/input.h"
#include "scenes/scene_file.h"
#include "sensor/labels.h"
#include "sensor/sensor.h"
#include "writers/writers.h"

namespace spadgen::app {
namespace fs = std::filesystem;

namespace {

std::string seconds_text(double s) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", s);
  return buf;
}

// The glTF with the scene file's node and material edits. An edit of a node or material the glTF does not
// have is named as the user gave it: the --set key (--set nodes.a.scale), else the scene file's pointer
// after the file's name (it was "/nodes/a" alone).
scenes::Scene load_edited_gltf(const scenes::ResolvedRun& r, const std::string& scene_file) {
  const RunConfig& c = r.config;
  try {
    return scenes::load_gltf(c.gltf_path, c.gltf_scene, c.edits);
  } catch (const scenes::EditError& e) {
    // the --set key of that node or material (nodes.a.scale), else the scene file
    // (gltf_scene: the key itself; nodes and materials: the element's pointer, a prefix of its keys')
    const bool top = e.section == "gltf_scene";
    const std::string what = e.what(), element = top ? "/gltf_scene" : "/" + e.section + "/" + scenes::pointer_token(e.name);
    for (const auto& [pointer, key] : r.set_keys)
      if (top ? pointer == element : pointer.rfind(element + "/", 0) == 0)  // (the message holds the element on one line: a newline escaped)
        throw Error("--set " + scenes::one_line(key) + what.substr(std::min(what.size(), scenes::one_line(element).size())));
    throw Error(scene_file + ": " + what);
  }
}

// What `make` builds, with an error of a key the render stage checks against the glTF (a KeyError:
// "camera.gltf_camera: no perspective camera named ...") named as the user gave the key: the --set key, else
// the scene file and the key's pointer (it named neither the scene file nor the pointer).
template <class Make>
auto naming_keys(const scenes::ResolvedRun& r, const std::string& scene_file, Make&& make) {
  try {
    return make();
  } catch (const KeyError& e) {
    const auto set = r.set_keys.find(e.pointer);
    throw Error((set != r.set_keys.end() ? "--set " + scenes::one_line(set->second) : scene_file + ": " + e.pointer) + ": " +
                e.reason);
  }
}

}  // namespace

RunResult run(const RunOptions& options) {
  const auto started = std::chrono::steady_clock::now();
  std::vector<std::string> overrides = options.overrides;
  if (options.seed) overrides.push_back("seed=" + std::to_string(*options.seed));
  scenes::ResolvedRun resolved = scenes::load_scene_file(options.scene_file, overrides);
  const RunConfig& cfg = resolved.config;
  for (const std::string& w : resolved.warnings) print_warning(w);

  InterruptGuard interrupt_guard;
  const ThreadLimit threads(options.threads);

  // The hash of the files as they were read (metadata.json's scene_hash_fnv1a64): taken when the glTF loads,
  // and refused if they changed meanwhile. (Taken when the outputs were written, it was of the files then: a
  // dataset sample rendered from a glTF edited and restored meanwhile stayed done under the restored one's.)
  std::string scene_hash;
  const scenes::Scene scene = [&] {
    const StopAtOnce loading;  // (nothing written yet)
    scene_hash = scenes::content_hash(cfg.scene_file, cfg.gltf_path);
    scenes::Scene s = load_edited_gltf(resolved, options.scene_file);
    if (scenes::content_hash(cfg.scene_file, cfg.gltf_path) != scene_hash)
      throw Error(options.scene_file + ": the scene file, its glTF or a file the glTF reads changed while they were read; "
                  "run again once they are written");
    return s;
  }();
  for (const std::string& w : scene.warnings) print_warning(w);
  std::vector<std::string> warnings = scene.warnings;  // for metadata.json, with those of the run (app/warnings.h)
  const auto warn = [&](const std::vector<std::string>& ws) {
    for (const std::string& w : ws) print_warning(w), warnings.push_back(w);
  };
  warn(camera_warnings(cfg, scene));
  const render::Camera camera = naming_keys(resolved, options.scene_file, [&] { return render::Camera(cfg.camera, scene); });
  warn(laser_warnings(cfg, camera, &scene));
  const SensorTables tables = SensorTables::hashed(cfg);
  // (its keys checked against its curves: a PDP above 1, a table that misses the laser, named as given)
  sensor::SensorModel sensor = naming_keys(resolved, options.scene_file, [&] { return sensor::SensorModel(sensor_stage(cfg)); });
  apply_user_maps(sensor, cfg);
  tables.check_unchanged(cfg);
  tables.check_expected(cfg, options.tables_hash);
  warn(sensor_warnings(sensor, cfg.sensor.gate.grid_s));
  const render::Renderer renderer = naming_keys(resolved, options.scene_file, [&] {
    return render::Renderer(scene, render_stage(cfg, sensor.row_fill_factor(), sensor.row_ambient_floor()));
  });
  const int objects = int(scenes::objects_of(scene).list.size());

  const TimeAxis axis = naming_keys(resolved, options.scene_file, [&] { return time_axis(cfg, sensor); });
  const PixelRect img = image_rect(cfg);
  check_derived(cfg, sensor, img, axis, resolved.set_keys);

  const fs::path out = options.out_dir.empty() ? fs::path("out") / fs::path(options.scene_file).stem() : fs::path(options.out_dir);
  // Not inside a run folder, a set of realisations or a dataset's own entries (-o RUN/x made the next run
  // into RUN refuse it for a foreign folder), but a dataset's sample when the dataset writes it.
  refuse_run_folder_inside(out, !options.out_dir.empty(), options.dataset.has_value());
  // The staging first: it removes what a killed run left beside the folder, which the disk check would
  // otherwise count as taken.
  Staging staging(out);
  // (the scene's geometry and BVH are in memory already: what is available counts them)
  check_resources(cfg, sensor, img, axis, options.threads, out, objects);
  Outputs outputs(cfg, sensor, img, axis, staging, objects, options.threads, laser_traced(cfg));
  const PixelRect light_rect = light_region(img, cfg.camera.width_px, cfg.camera.height_px);
  std::unique_ptr<LightWriter> light;
  if (cfg.outputs.light) light = std::make_unique<LightWriter>(light_rect, axis, staging, cfg.outputs.storage);

  // Tiles are laid over the output image; the renderer and the sensor see full-sensor coordinates.
  std::vector<PixelRect> tiles = make_tiles(img.width, img.height, cfg.render.tile_size);
  for (PixelRect& t : tiles) t.x0 += img.x0, t.y0 += img.y0;
  std::vector<render::RenderStats> tile_stats(tiles.size());
  if (options.progress)
    std::fprintf(stderr, "spadgen: %s: %d x %d pixels, %zu tiles, %lld time bins of %s ps, K = %d\n",
                 options.scene_file.c_str(), img.width, img.height, tiles.size(), static_cast<long long>(axis.bins),
                 seconds_text(axis.bin_width_s / kPs).c_str(), sensor.K());
  const double setup_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  Progress progress(tiles.size(), options.progress);
  StageClock clock;  // where the tiles' time goes (metadata.json "run")

  tbb::parallel_for(size_t(0), tiles.size(), [&](size_t ti) {
    InterruptGuard::check();
    const PixelRect& rect = tiles[ti];
    // The ground truth first: the renderer splits each pixel's laser light by the objects of its slots.
    GroundTruthTile gt;
    if (cfg.outputs.ground_truth) {
      const StageClock::Scope time(&clock, StageClock::kGroundTruth);
      gt = renderer.ground_truth(rect);
    }
    const PixelRect data_rect = grow_clipped(rect, sensor.halo(), cfg.camera.width_px, cfg.camera.height_px);
    TransientTile t;
    {
      const StageClock::Scope time(&clock, StageClock::kLightTransport);
      t = renderer.transient(rect, data_rect, axis, &tile_stats[ti], cfg.outputs.ground_truth ? &gt : nullptr);
    }
    SensorTile s;
    {
      const StageClock::Scope time(&clock, StageClock::kSensorRates);  // the noise inside it times itself
      s = sensor.process(t);
    }
    const StageClock::Scope time(&clock, StageClock::kOutputs);
    if (cfg.outputs.ground_truth) outputs.put_ground_truth(gt);
    if (outputs.labels()) outputs.put_labels(sensor::object_labels(sensor, gt, s, axis, cfg.laser.emission_delay_s));
    outputs.put(t, sensor.maps(rect), std::move(s));
    if (light) light->put(t);
    progress.tick();
  });
  // The saved light also covers the ring of pixels around a crop, which crosstalk reads: rendered here
  // when the tiles' halo did not already cover it (a pixel's light does not depend on its tile).
  if (light && sensor.halo() == 0) {
    const std::vector<PixelRect> ring = {
        {light_rect.x0, light_rect.y0, light_rect.width, img.y0 - light_rect.y0},
        {light_rect.x0, img.y1(), light_rect.width, light_rect.y1() - img.y1()},
        {light_rect.x0, img.y0, img.x0 - light_rect.x0, img.height},
        {img.x1(), img.y0, light_rect.x1() - img.x1(), img.height}};
    tbb::parallel_for(size_t(0), ring.size(), [&](size_t i) {
      if (ring[i].count() > 0) light->put(renderer.transient(ring[i], ring[i], axis, nullptr));
    });
  }
  const double render_seconds = progress.seconds();
  const auto tiles_done = std::chrono::steady_clock::now();

  const Provenance prov = provenance(cfg, img, scene_hash, tables.hash, tables.tables);
  outputs.write(prov);
  std::vector<std::string> files = outputs.files();
  RunRecord record;
  if (light) {
    light->write(files);
    record.light_region = light_rect;
    record.light_values_bytes = light->values_bytes();
    record.light_fill_factor = sensor.row_fill_factor();
  }
  files.push_back("metadata.json");
  order_files(files);

  outputs.report(record);
  warn(bright_gate_warnings(sensor, record.laser_open_rate));
  warn(sweep_edge_warnings(cfg, record));
  if (light) record.storage.update(light->storage());
  record.files = files;
  record.photons_per_pulse_emitted = renderer.photons_per_pulse();
  record.objects = objects_json(scene);
  record.laser_traced = laser_traced(cfg);
  record.model = model_components(cfg, &scene, record.laser_traced);
  record.camera = camera_json(camera, img, renderer.laser_position());
  record.threads = options.threads;
  record.dataset = options.dataset;
  record.seconds = render_seconds;
  for (const auto& st : tile_stats) record.render_stats.rays += st.rays, record.render_stats.camera_hits += st.camera_hits;
  record.times.setup_seconds = setup_seconds;
  record.times.tiles_seconds = render_seconds;
  record.times.take_stages(clock);
  warn(light_warnings(cfg, img, record, camera));
  InterruptGuard::check();
  outputs.commit();
  record.file_bytes = file_bytes(staging.path(""), files);  // every file complete: metadata.json goes last
  record.times.finish_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - tiles_done).count();
  writers::write_json(staging.path("metadata.json"), metadata(resolved, warnings, sensor, prov, axis, record));
  staging.publish(files);
  if (options.progress)
    std::fprintf(stderr, "spadgen: wrote %zu files to %s in %.1f s\n", files.size(), out.string().c_str(), progress.seconds());
  return {out.string(), files};
}

std::string info(const std::string& scene_file, const std::vector<std::string>& overrides) {
  const scenes::ResolvedRun r = scenes::load_scene_file(scene_file, overrides);
  const RunConfig& c = r.config;
  const scenes::Scene scene = load_edited_gltf(r, scene_file);
  // camera.gltf_camera names a camera of the glTF, as the run needs
  const render::Camera camera = naming_keys(r, scene_file, [&] { return render::Camera(c.camera, scene); });
  sensor::SensorModel sensor = naming_keys(r, scene_file, [&] { return sensor::SensorModel(sensor_stage(c)); });
  apply_user_maps(sensor, c);  // maps that do not fit the sensor are refused here as by the run
  naming_keys(r, scene_file, [&] {
    int laser_light = -1;  // laser.gltf_light names a light of the glTF, as the run needs
    (void)render::make_laser(render_stage(c, sensor.row_fill_factor()), camera, scene, &laser_light);
  });
  std::ostringstream o;
  o << "# resolved scene file " << c.scene_file << "\n" << r.resolved.dump(2) << "\n\n";
  o << "# glTF\n" << scenes::summarize(scene) << "\n";
  std::vector<std::string> before = camera_warnings(c, scene);  // the warnings known before rendering
  for (std::string& w : laser_warnings(c, camera, &scene)) before.push_back(std::move(w));
  for (std::string& w : sensor_warnings(sensor, c.sensor.gate.grid_s)) before.push_back(std::move(w));
  const TimeAxis axis = naming_keys(r, scene_file, [&] { return time_axis(c, sensor); });
  const PixelRect img = image_rect(c);
  check_derived(c, sensor, img, axis, r.set_keys);
  o << "# run\n";
  o << "photons per pulse emitted: " << photons_per_pulse(c.laser.average_power_W, c.laser.repetition_rate_Hz, c.laser.wavelength_m) << "\n";
  o << "image: " << img.width << " x " << img.height << " pixels; K = " << sensor.K() << "\n";
  o << "time axis: " << axis.bins << " bins of " << axis.bin_width_s / kPs << " ps from " << axis.start_s / kNs << " ns to "
    << axis.end_s() / kNs << " ns\n";
  // Every stack the run will write, from the same layout the run uses (a Zarr store: uncompressed, at most).
  o << "output sizes:";
  const char* sep = " ";
  for (const StackLayout& st : stack_layout(c, sensor, img, axis)) {
    if (!st.written) continue;
    o << sep << st.file << (st.chunks.empty() ? " " : " at most ") << bytes_text(st.bytes());
    sep = ", ";
  }
  o << "\n";
  const Geometry geometry = geometry_of(scene);
  o << "resources: " << resource_summary(plan_resources(c, sensor, img, axis, 0, "", int(scenes::objects_of(scene).list.size()), &geometry));
  for (const std::string& w : r.warnings) o << "warning: " << w << "\n";
  for (const std::string& w : before) o << "warning: " << w << "\n";
  return o.str();
}

}  // namespace spadgen::app
