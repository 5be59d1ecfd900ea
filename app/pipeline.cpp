#include "pipeline.h"

#include <embree3/rtcore.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <cerrno>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <functional>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <mutex>
#include <numeric>
#include <sstream>

#include "app/interrupt.h"
#include "app/metadata.h"
#include "app/progress.h"
#include "app/staging.h"
#include "core/error.h"
#include "core/units.h"
#include "render/renderer.h"
#include "scenes/scene.h"
#include "scenes/scene_file.h"
#include "sensor/acquisition/acquisition.h"
#include "sensor/sensor.h"
#include "writers/previews.h"
#include "writers/writers.h"

#ifndef SPADGEN_VERSION
#define SPADGEN_VERSION "dev"
#endif

namespace spadgen::app {
namespace fs = std::filesystem;
using json = nlohmann::json;
using ojson = nlohmann::ordered_json;

namespace {

// The pixel rectangle the run renders (the crop, or the whole sensor).
PixelRect image_rect(const RunConfig& c) {
  return c.camera.crop.value_or(PixelRect{0, 0, c.camera.width_px, c.camera.height_px});
}

TimeAxis time_axis(const RunConfig& c, const sensor::SensorModel& s) {
  if (c.render.window_start_s) {
    TimeAxis a;
    a.start_s = *c.render.window_start_s;
    a.bin_width_s = c.render.time_bin_s;
    a.bins = static_cast<int64_t>(std::ceil((*c.render.window_stop_s - a.start_s) / a.bin_width_s - 1e-9));
    a.period_s = 1.0 / c.laser.repetition_rate_Hz;
    return a;
  }
  TimeAxis a = s.required_window(c.render.time_bin_s);
  if (a.bins == 0 && c.outputs.transient)
    throw Error(c.scene_file + ": /outputs/transient: intensity mode needs no time bins; set /render/window_start_ns "
                "and /render/window_stop_ns to say which window transient.npy should cover");
  return a;
}

std::string seconds_text(double s) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", s);
  return buf;
}

// A few pixels whose gate profiles the preview plots: the centre and points on the diagonals.
std::vector<std::pair<int, int>> profile_pixels(const PixelRect& img) {
  std::vector<std::pair<int, int>> p;
  for (const auto& [fx, fy] : std::vector<std::pair<double, double>>{{0.5, 0.5}, {0.25, 0.5}, {0.75, 0.5}, {0.5, 0.25}, {0.5, 0.75}}) {
    const int x = img.x0 + std::min(img.width - 1, int(fx * img.width));
    const int y = img.y0 + std::min(img.height - 1, int(fy * img.height));
    if (std::find(p.begin(), p.end(), std::pair{x, y}) == p.end()) p.push_back({x, y});
  }
  return p;
}

// The per-pixel EXR images, filled tile by tile. Every channel is created here, up front: tiles fill
// them from several threads, and ExrImage::channel creates a channel on first use.
class Images {
 public:
  Images(const RunConfig& cfg, const PixelRect& img, bool intensity_image)
      : img_(img), layers_(cfg.render.max_layers), gt_on_(cfg.outputs.ground_truth),
        sweep_(!intensity_image), gt_(img.width, img.height), laser_(img.width, img.height),
        ambient_(img.width, img.height), maps_(img.width, img.height), intensity_(img.width, img.height) {
    if (gt_on_) {
      for (const char* n : kGroundTruthChannels) gt_ch_.push_back(gt_.channel(n));
      for (int l = 0; l < layers_; ++l) {
        layer_range_.push_back(gt_.channel(layer_name(l, ".range")));
        layer_trans_.push_back(gt_.channel(layer_name(l, ".transmittance")));
      }
    }
    laser_ch_ = {laser_.channel("photons_per_pulse"), laser_.channel("out_of_window")};
    ambient_ch_ = ambient_.channel("photons_per_second");
    maps_ch_ = {maps_.channel("gate_skew_ps"), maps_.channel("gate_length_ps"), maps_.channel("dcr_cps"), maps_.channel("pde")};
    if (!sweep_) intensity_ch_ = {intensity_.channel("counts"), intensity_.channel("photons")};
    pixel_laser_.assign(size_t(img.count()), 0.0);
    pixel_oow_.assign(size_t(img.count()), 0.0);
  }

  void put_ground_truth(const GroundTruthTile& g) {
    for_pixels(g.rect, [&](int, int, size_t i, size_t o) {
      const float v[] = {g.range[i], g.z[i], g.normal[3 * i], g.normal[3 * i + 1], g.normal[3 * i + 2],
                         float(g.mesh_id[i]), float(g.material_id[i]), float(g.layer_count[i])};
      for (size_t c = 0; c < gt_ch_.size(); ++c) gt_ch_[c][o] = v[c];
      for (size_t l = 0; l < size_t(layers_); ++l) {
        layer_range_[l][o] = g.layer_range[i * size_t(g.max_layers) + l];
        layer_trans_[l][o] = g.layer_transmittance[i * size_t(g.max_layers) + l];
      }
    });
  }

  void put(const TransientTile& t, const sensor::SensorMapsTile& m, const SensorTile& s) {
    for_pixels(t.rect, [&](int x, int y, size_t i, size_t o) {
      const auto d = size_t(t.data_rect.index(x, y));  // the transient tile carries a halo
      laser_ch_[0][o] = float(t.laser_total[d]), laser_ch_[1][o] = float(t.out_of_window[d]);
      ambient_ch_[o] = t.ambient_rate[d];
      pixel_laser_[o] = t.laser_total[d], pixel_oow_[o] = t.out_of_window[d];
      maps_ch_[0][o] = m.gate_skew_ps[i], maps_ch_[1][o] = m.gate_length_ps[i];
      maps_ch_[2][o] = m.dcr_cps[i], maps_ch_[3][o] = m.pde[i];
      if (!sweep_) intensity_ch_[0][o] = s.intensity_counts[i], intensity_ch_[1][o] = s.intensity_photons[i];
    });
  }

  // Per-pixel sums in image order, so they do not depend on the tile size.
  double laser_total() const { return std::accumulate(pixel_laser_.begin(), pixel_laser_.end(), 0.0); }
  double out_of_window_total() const { return std::accumulate(pixel_oow_.begin(), pixel_oow_.end(), 0.0); }
  // The deepest layer any pixel has; layer channels beyond it are not written.
  int deepest_layer() const {
    if (!gt_on_) return 0;
    const float* lc = gt_ch_.back();
    return int(*std::max_element(lc, lc + size_t(img_.count())));
  }

  // Writes the EXRs with their provenance and the previews into the staging folder.
  void write(const Staging& staging, const std::function<void(writers::ExrImage&)>& provenance, const TimeAxis& axis,
             bool previews, std::vector<std::string>& files) {
    const auto put_file = [&](writers::ExrImage& e, const std::string& name, const std::string& units) {
      provenance(e);
      e.set_attribute("spadgen_units", units);
      e.write(staging.path(name));
      files.push_back(name);
    };
    if (gt_on_) {
      for (int l = deepest_layer(); l < layers_; ++l) {
        gt_.remove_channel(layer_name(l, ".range"));
        gt_.remove_channel(layer_name(l, ".transmittance"));
      }
      put_file(gt_, "ground_truth.exr", "range, z, layer<i>.range: metres (+inf where the ray hits nothing); transmittance: fraction");
    }
    laser_.set_attribute("spadgen_time_axis", axis_json(axis).dump());
    put_file(laser_, "laser.exr", "photons per laser pulse reaching the pixel's SPAD (before PDP)");
    put_file(ambient_, "ambient.exr", "ambient photons per second reaching the pixel's SPAD (before PDP)");
    put_file(maps_, "sensor_maps.exr", "gate_skew_ps, gate_length_ps: ps; dcr_cps: counts/s; pde: fraction");
    if (!sweep_)
      put_file(intensity_, "intensity.exr", "counts: summed binary frames; photons: linearised incident photons per image");
    if (!previews) return;
    if (gt_on_) {
      writers::write_png(staging.path("previews/depth.png"), writers::depth_preview(gt_ch_[0], img_.width, img_.height, 0.0f, 0.0f));
      files.push_back("previews/depth.png");
    }
    const float* bright = sweep_ ? laser_ch_[0] : intensity_ch_[1];
    writers::write_png(staging.path("previews/intensity.png"), writers::gray_preview(bright, img_.width, img_.height));
    files.push_back("previews/intensity.png");
  }

 private:
  static constexpr const char* kGroundTruthChannels[] = {"range", "z", "normal.X", "normal.Y", "normal.Z",
                                                         "mesh_id", "material_id", "layer_count"};
  static std::string layer_name(int l, const char* what) { return "layer" + std::to_string(l) + what; }
  // Calls f(x, y, index in rect, index in the image) for every pixel (x, y) of rect.
  template <class F>
  void for_pixels(const PixelRect& r, F&& f) const {
    for (int y = r.y0; y < r.y1(); ++y)
      for (int x = r.x0; x < r.x1(); ++x)
        f(x, y, size_t(r.index(x, y)), size_t(y - img_.y0) * size_t(img_.width) + size_t(x - img_.x0));
  }

  PixelRect img_;
  int layers_;
  bool gt_on_, sweep_;
  writers::ExrImage gt_, laser_, ambient_, maps_, intensity_;
  std::vector<float*> gt_ch_, layer_range_, layer_trans_, laser_ch_, maps_ch_, intensity_ch_;
  float* ambient_ch_ = nullptr;
  std::vector<double> pixel_laser_, pixel_oow_;
};

// The NumPy stacks, streamed to disk tile by tile.
class Stacks {
 public:
  Stacks(const RunConfig& cfg, const PixelRect& img, int K, int frames_per_k, const TimeAxis& axis,
         const Staging& staging, std::vector<std::string>& files)
      : img_(img), tcrop_(cfg.outputs.transient_crop.value_or(img)), counts_u8_(frames_per_k <= 255) {
    using writers::NpyWriter;
    const auto open = [&](std::unique_ptr<NpyWriter>& w, const std::string& name, NpyWriter::Dtype type, std::vector<int64_t> shape) {
      w = std::make_unique<NpyWriter>(staging.path(name), type, std::move(shape));
      files.push_back(name);
    };
    const std::vector<int64_t> khw{K, img.height, img.width};
    if (cfg.outputs.expected_counts) open(expected_, "expected_counts.npy", NpyWriter::Dtype::F32, khw);
    if (cfg.outputs.counts) open(counts_, "counts.npy", counts_u8_ ? NpyWriter::Dtype::U8 : NpyWriter::Dtype::U16, khw);
    if (cfg.outputs.frames)
      open(frames_, "frames.npy", NpyWriter::Dtype::U8, {K, frames_per_k, img.height, (img.width + 7) / 8});
    const std::vector<int64_t> hwt{tcrop_.height, tcrop_.width, axis.bins};
    if (cfg.outputs.transient) open(transient_, "transient.npy", NpyWriter::Dtype::F32, hwt);
    if (cfg.outputs.transient && cfg.render.split_direct_indirect)
      open(indirect_, "transient_indirect.npy", NpyWriter::Dtype::F32, hwt);
  }

  void put(const TransientTile& t, const SensorTile& s) {
    const PixelRect& r = t.rect;
    if (expected_) expected_->write_khw(r, img_.x0, img_.y0, s.expected.data());
    if (counts_ && counts_u8_) {
      std::vector<uint8_t> c8(s.counts.size());
      std::transform(s.counts.begin(), s.counts.end(), c8.begin(), [](uint16_t v) { return uint8_t(v); });
      counts_->write_khw(r, img_.x0, img_.y0, c8.data());
    } else if (counts_) {
      counts_->write_khw(r, img_.x0, img_.y0, s.counts.data());
    }
    if (frames_) frames_->write_frames(r, img_.x0, img_.y0, s.frames.data());
    const int x0 = std::max(r.x0, tcrop_.x0), x1 = std::min(r.x1(), tcrop_.x1());
    const int y0 = std::max(r.y0, tcrop_.y0), y1 = std::min(r.y1(), tcrop_.y1());
    if (t.axis.bins == 0 || x1 <= x0 || y1 <= y0) return;
    const PixelRect part{x0, y0, x1 - x0, y1 - y0};
    if (transient_) transient_->write_hwt(part, t.data_rect, tcrop_.x0, tcrop_.y0, t.transient.data());
    if (indirect_) indirect_->write_hwt(part, t.data_rect, tcrop_.x0, tcrop_.y0, t.transient_indirect.data());
  }

  void commit() {
    for (auto* w : {&expected_, &counts_, &frames_, &transient_, &indirect_})
      if (*w) (*w)->commit();
  }
  bool counts_u8() const { return counts_u8_; }
  const PixelRect& transient_crop() const { return tcrop_; }

 private:
  PixelRect img_, tcrop_;
  bool counts_u8_;
  std::unique_ptr<writers::NpyWriter> expected_, counts_, frames_, transient_, indirect_;
};

// The sampled gate profiles of a few pixels, for previews/gate_profiles.png.
class ProfileProbe {
 public:
  ProfileProbe(const PixelRect& img, int K) : pixels_(profile_pixels(img)), curves_(pixels_.size(), std::vector<float>(size_t(K))) {}
  void put(const SensorTile& s) {
    for (size_t p = 0; p < pixels_.size(); ++p)
      if (s.rect.contains(pixels_[p].first, pixels_[p].second))
        for (int k = 0; k < s.K; ++k)
          curves_[p][size_t(k)] = float(s.counts[size_t(k) * size_t(s.rect.count()) + size_t(s.rect.index(pixels_[p].first, pixels_[p].second))]);
  }
  void write(const Staging& staging, const std::vector<double>& gate_positions_s, std::vector<std::string>& files) const {
    std::vector<double> x(gate_positions_s.size());
    std::transform(gate_positions_s.begin(), gate_positions_s.end(), x.begin(), [](double t) { return t / kNs; });
    writers::write_png(staging.path("previews/gate_profiles.png"),
                       writers::profile_plot(curves_, x, 800, 450, "gate position (ns)", "counts"));
    files.push_back("previews/gate_profiles.png");
  }
  const std::vector<std::pair<int, int>>& pixels() const { return pixels_; }

 private:
  std::vector<std::pair<int, int>> pixels_;
  std::vector<std::vector<float>> curves_;
};

}  // namespace

RunResult run(const RunOptions& options) {
  std::vector<std::string> overrides = options.overrides;
  if (options.seed) overrides.push_back("seed=" + std::to_string(*options.seed));
  scenes::ResolvedRun resolved = scenes::load_scene_file(options.scene_file, overrides);
  const RunConfig& cfg = resolved.config;
  for (const std::string& w : resolved.warnings) std::fprintf(stderr, "spadgen: warning: %s\n", w.c_str());

  InterruptGuard interrupt_guard;
  std::unique_ptr<tbb::global_control> threads;
  if (options.threads > 0)
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, size_t(options.threads));

  const scenes::Scene scene = scenes::load_gltf(cfg.gltf_path, cfg.gltf_scene);
  for (const std::string& w : scene.warnings) std::fprintf(stderr, "spadgen: warning: %s\n", w.c_str());
  sensor::SensorModel sensor(sensor_stage(cfg));
  if (!cfg.sensor.gate.maps_exr.empty()) {
    const writers::ExrData maps = writers::read_exr(cfg.sensor.gate.maps_exr);
    sensor.set_maps(maps.width, maps.height, maps.channels, cfg.sensor.gate.maps_exr);
  }
  const render::Renderer renderer(scene, render_stage(cfg, sensor.row_fill_factor()));

  const TimeAxis axis = time_axis(cfg, sensor);
  const PixelRect img = image_rect(cfg);
  const int K = sensor.K();
  const auto declared = [&](const std::string& file) {
    for (const sensor::DeclaredOutput& d : sensor.acquisition().outputs())
      if (d.file == file) return true;
    return false;
  };

  const fs::path out = options.out_dir.empty() ? fs::path("out") / fs::path(options.scene_file).stem() : fs::path(options.out_dir);
  Staging staging(out);
  std::vector<std::string> files;
  Images images(cfg, img, declared("intensity.exr"));
  Stacks stacks(cfg, img, K, sensor.frames_per_k(), axis, staging, files);
  ProfileProbe probe(img, K);

  // Tiles are laid over the output image; the renderer and the sensor see full-sensor coordinates.
  std::vector<PixelRect> tiles = make_tiles(img.width, img.height, cfg.render.tile_size);
  for (PixelRect& t : tiles) t.x0 += img.x0, t.y0 += img.y0;
  std::vector<render::RenderStats> tile_stats(tiles.size());
  std::fprintf(stderr, "spadgen: %s: %d x %d pixels, %zu tiles, %lld time bins of %s ps, K = %d\n",
               options.scene_file.c_str(), img.width, img.height, tiles.size(), static_cast<long long>(axis.bins),
               seconds_text(axis.bin_width_s / kPs).c_str(), K);
  Progress progress(tiles.size(), options.progress);

  tbb::parallel_for(size_t(0), tiles.size(), [&](size_t ti) {
    InterruptGuard::check();
    const PixelRect& rect = tiles[ti];
    if (cfg.outputs.ground_truth) images.put_ground_truth(renderer.ground_truth(rect));
    const PixelRect data_rect = grow_clipped(rect, sensor.halo(), cfg.camera.width_px, cfg.camera.height_px);
    const TransientTile t = renderer.transient(rect, data_rect, axis, &tile_stats[ti]);
    const SensorTile s = sensor.process(t);
    images.put(t, sensor.maps(rect), s);
    stacks.put(t, s);
    probe.put(s);
    progress.tick();
  });
  const double render_seconds = progress.seconds();

  const Provenance prov = provenance(cfg, img);
  images.write(staging, [&](writers::ExrImage& e) { stamp(e, prov); }, axis, cfg.outputs.previews, files);
  if (cfg.outputs.previews && declared("previews/gate_profiles.png") && K > 1) probe.write(staging, sensor.gate_positions_s(), files);

  RunRecord record;
  record.photons_per_pulse_emitted = renderer.photons_per_pulse();
  record.laser_total = images.laser_total(), record.out_of_window_total = images.out_of_window_total();
  record.ground_truth_layers = images.deepest_layer();
  record.counts_u8 = stacks.counts_u8();
  record.transient_crop = stacks.transient_crop();
  record.profile_pixels = probe.pixels();
  record.threads = options.threads;
  record.seconds = render_seconds;
  for (const auto& st : tile_stats) record.rays.camera_rays += st.camera_rays, record.rays.shadow_rays += st.shadow_rays;
  files.push_back("metadata.json");
  record.files = files;
  writers::write_json(staging.path("metadata.json"), metadata(resolved, scene, sensor, prov, axis, record));

  InterruptGuard::check();
  stacks.commit();
  staging.publish(files);
  std::fprintf(stderr, "spadgen: wrote %zu files to %s in %.1f s\n", files.size(), out.string().c_str(), progress.seconds());
  return {out.string(), files};
}

std::string info(const std::string& scene_file, const std::vector<std::string>& overrides) {
  const scenes::ResolvedRun r = scenes::load_scene_file(scene_file, overrides);
  const RunConfig& c = r.config;
  const scenes::Scene scene = scenes::load_gltf(c.gltf_path, c.gltf_scene);
  sensor::SensorModel sensor(sensor_stage(c));
  std::ostringstream o;
  o << "# resolved scene file " << c.scene_file << "\n" << r.resolved.dump(2) << "\n\n";
  o << "# glTF\n" << scenes::summarize(scene) << "\n";
  const TimeAxis axis = time_axis(c, sensor);
  const PixelRect img = image_rect(c);
  const double px = double(img.width) * img.height;
  o << "# run\n";
  o << "photons per pulse emitted: " << photons_per_pulse(c.laser.average_power_W, c.laser.repetition_rate_Hz, c.laser.wavelength_m) << "\n";
  o << "image: " << img.width << " x " << img.height << " pixels; K = " << sensor.K() << "\n";
  o << "time axis: " << axis.bins << " bins of " << axis.bin_width_s / kPs << " ps from " << axis.start_s / kNs << " ns to "
    << axis.end_s() / kNs << " ns\n";
  const auto mb = [](double bytes) { return std::to_string(int64_t(std::ceil(bytes / 1e6))) + " MB"; };
  o << "output sizes: expected_counts.npy " << mb(4.0 * px * sensor.K()) << ", counts.npy "
    << mb((sensor.frames_per_k() <= 255 ? 1.0 : 2.0) * px * sensor.K());
  if (c.outputs.frames) o << ", frames.npy " << mb(double(sensor.K()) * sensor.frames_per_k() * img.height * ((img.width + 7) / 8));
  if (c.outputs.transient) {
    const PixelRect t = c.outputs.transient_crop.value_or(img);
    o << ", transient.npy " << mb(4.0 * double(t.width) * t.height * double(axis.bins));
  }
  o << "\n";
  for (const std::string& w : r.warnings) o << "warning: " << w << "\n";
  return o.str();
}

}  // namespace spadgen::app
