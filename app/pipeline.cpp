#include "pipeline.h"

#include <embree3/rtcore.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <mutex>
#include <numeric>
#include <sstream>

#include "core/error.h"
#include "core/units.h"
#include "render/renderer.h"
#include "scenes/scene.h"
#include "scenes/scene_file.h"
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

// Set by SIGINT/SIGTERM: the tiles stop, the staging folder is removed, nothing is published.
std::atomic<bool> g_interrupted{false};
extern "C" void on_interrupt(int) { g_interrupted.store(true); }

// Installs the handlers for the duration of a run and restores the previous ones after.
class InterruptGuard {
 public:
  InterruptGuard() {
    g_interrupted.store(false);
    previous_int_ = std::signal(SIGINT, on_interrupt);
    previous_term_ = std::signal(SIGTERM, on_interrupt);
  }
  ~InterruptGuard() {
    std::signal(SIGINT, previous_int_);
    std::signal(SIGTERM, previous_term_);
  }
  static void check() {
    if (g_interrupted.load()) throw Error("interrupted by a signal: the run stopped and wrote nothing");
  }

 private:
  void (*previous_int_)(int) = SIG_DFL;
  void (*previous_term_)(int) = SIG_DFL;
};

// FNV-1a over bytes: a stable content hash for provenance (not for security).
uint64_t fnv1a(const std::string& bytes, uint64_t h = 0xcbf29ce484222325ull) {
  for (unsigned char c : bytes) h = (h ^ c) * 0x100000001b3ull;
  return h;
}
std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}
std::string hex64(uint64_t v) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

// The scene hash covers the scene file, the glTF and every buffer and image beside it, so that the
// provenance changes whenever anything that shapes the data changes.
std::string scene_hash(const RunConfig& c) {
  uint64_t h = fnv1a(read_bytes(c.scene_file));
  h = fnv1a(read_bytes(c.gltf_path), h);
  const fs::path dir = fs::path(c.gltf_path).parent_path();
  std::vector<std::string> side;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file() && e.path() != fs::path(c.gltf_path) &&
        (e.path().extension() == ".bin" || e.path().extension() == ".png" || e.path().extension() == ".jpg"))
      side.push_back(e.path().string());
  std::sort(side.begin(), side.end());
  for (const std::string& f : side) h = fnv1a(read_bytes(f), h);
  return hex64(h);
}

// Progress on stderr: a bar on a terminal, a line every 10 % otherwise, with an estimate of the time left.
class Progress {
 public:
  Progress(size_t total, bool enabled) : total_(total), enabled_(enabled), tty_(isatty(2) != 0) {}
  void tick() {
    const size_t done = ++done_;
    if (!enabled_) return;
    std::lock_guard<std::mutex> lock(mutex_);
    const double elapsed = seconds();
    const double left = done ? elapsed * double(total_ - done) / double(done) : 0.0;
    if (tty_) {
      if (elapsed - last_print_ < 0.1 && done != total_) return;
      last_print_ = elapsed;
      const int width = 30, filled = int(double(width) * double(done) / double(total_));
      std::fprintf(stderr, "\r[%s%s] %3d%%  %zu/%zu tiles  %.1f s, ~%.0f s left ", std::string(size_t(filled), '#').c_str(),
                   std::string(size_t(width - filled), '.').c_str(), int(100.0 * double(done) / double(total_)), done,
                   total_, elapsed, left);
      if (done == total_) std::fprintf(stderr, "\n");
    } else {
      const size_t decile = 10 * done / total_;
      if (decile > last_decile_ || done == total_) {
        last_decile_ = decile;
        std::fprintf(stderr, "spadgen: %3d%% (%zu/%zu tiles) %.1f s elapsed, ~%.0f s left\n",
                     int(100.0 * double(done) / double(total_)), done, total_, elapsed, left);
      }
    }
  }
  double seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  size_t total_;
  bool enabled_, tty_;
  std::atomic<size_t> done_{0};
  std::mutex mutex_;
  double last_print_ = -1.0;
  size_t last_decile_ = 0;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

// A folder inside the output folder that holds this run's files until they are all complete; removed
// (with whatever is in it) unless released.
class Staging {
 public:
  explicit Staging(const fs::path& out) : out_(out) {
    fs::create_directories(out_);
    remove_abandoned();
    dir_ = out_ / (".spadgen-staging-" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "previews");
  }
  ~Staging() {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string path(const std::string& rel) const { return (dir_ / rel).string(); }
  // Staging folders of runs that were killed outright (SIGKILL, power loss) hold only temporary files.
  void remove_abandoned() const {
    const std::string prefix = ".spadgen-staging-";
    for (const auto& e : fs::directory_iterator(out_)) {
      const std::string name = e.path().filename().string();
      if (name.rfind(prefix, 0) != 0) continue;
      const long pid = std::strtol(name.c_str() + prefix.size(), nullptr, 10);
      if (pid > 0 && pid != ::getpid() && ::kill(pid_t(pid), 0) != 0 && errno == ESRCH) {
        std::error_code ec;
        fs::remove_all(e.path(), ec);
      }
    }
  }
  // Moves every listed file into the output folder; metadata.json comes last so that it never lists a
  // file that is not there yet.
  void publish(const std::vector<std::string>& files) {
    fs::create_directories(out_ / "previews");
    for (const std::string& f : files)
      if (f != "metadata.json") fs::rename(dir_ / f, out_ / f);
    fs::rename(dir_ / "metadata.json", out_ / "metadata.json");
  }

 private:
  fs::path out_, dir_;
};

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

json axis_json(const TimeAxis& a) {
  return {{"start_ns", a.start_s / kNs}, {"bin_width_ps", a.bin_width_s / kPs}, {"bins", a.bins},
          {"end_ns", a.end_s() / kNs}, {"laser_period_ns", a.period_s / kNs}};
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
  sensor::SensorModel sensor(cfg);
  if (!cfg.sensor.gate.maps_exr.empty()) {
    const writers::ExrData maps = writers::read_exr(cfg.sensor.gate.maps_exr);
    sensor.set_maps(maps.width, maps.height, maps.channels, cfg.sensor.gate.maps_exr);
  }
  const render::Renderer renderer(scene, cfg);

  const TimeAxis axis = time_axis(cfg, sensor);
  const PixelRect img = image_rect(cfg);
  const int W = img.width, H = img.height, K = sensor.K();
  const int halo = sensor.halo();
  const bool sweep = cfg.acquisition.mode == "gate_sweep";
  const int frames = cfg.acquisition.frames;

  fs::path out = options.out_dir.empty() ? fs::path("out") / fs::path(options.scene_file).stem() : fs::path(options.out_dir);
  Staging staging(out);
  std::vector<std::string> files;

  // Full-image float images are small (tens of MB); the large stacks stream to disk tile by tile.
  writers::ExrImage gt(W, H), laser(W, H), ambient(W, H), maps(W, H), intensity(W, H);
  const int L = cfg.render.max_layers;
  std::vector<float*> layer_range(static_cast<size_t>(L)), layer_trans(static_cast<size_t>(L));
  if (cfg.outputs.ground_truth)
    for (int i = 0; i < L; ++i) {
      layer_range[size_t(i)] = gt.channel("layer" + std::to_string(i) + ".range");
      layer_trans[size_t(i)] = gt.channel("layer" + std::to_string(i) + ".transmittance");
    }

  // ExrImage::channel creates on first use, so every channel is created here, before the tiles run.
  float *range = gt.channel("range"), *zc = gt.channel("z"), *nx = gt.channel("normal.X"), *ny = gt.channel("normal.Y"),
        *nz = gt.channel("normal.Z"), *mesh = gt.channel("mesh_id"), *mat = gt.channel("material_id"),
        *lc = gt.channel("layer_count");
  float *lz = laser.channel("photons_per_pulse"), *oow = laser.channel("out_of_window"),
        *amb = ambient.channel("photons_per_second");
  float *skew = maps.channel("gate_skew_ps"), *glen = maps.channel("gate_length_ps"), *dcr = maps.channel("dcr_cps"),
        *pde = maps.channel("pde");
  float *ic = intensity.channel("counts"), *ip = intensity.channel("photons");

  using writers::NpyWriter;
  const auto K64 = int64_t(K), H64 = int64_t(H), W64 = int64_t(W);
  // Dual exposure splits the frames between its two exposures.
  const int frames_per_k = sweep ? frames : (cfg.acquisition.intensity.exposure == "dual" ? frames / 2 : frames);
  const bool counts_u8 = frames_per_k <= 255;
  std::unique_ptr<NpyWriter> expected_npy, counts_npy, frames_npy, transient_npy, indirect_npy;
  if (cfg.outputs.expected_counts) {
    expected_npy = std::make_unique<NpyWriter>(staging.path("expected_counts.npy"), NpyWriter::Dtype::F32, std::vector<int64_t>{K64, H64, W64});
    files.push_back("expected_counts.npy");
  }
  if (cfg.outputs.counts) {
    counts_npy = std::make_unique<NpyWriter>(staging.path("counts.npy"), counts_u8 ? NpyWriter::Dtype::U8 : NpyWriter::Dtype::U16,
                                             std::vector<int64_t>{K64, H64, W64});
    files.push_back("counts.npy");
  }
  if (cfg.outputs.frames) {
    frames_npy = std::make_unique<NpyWriter>(staging.path("frames.npy"), NpyWriter::Dtype::U8,
                                             std::vector<int64_t>{K64, int64_t(frames_per_k), H64, (W64 + 7) / 8});
    files.push_back("frames.npy");
  }
  const PixelRect tcrop = cfg.outputs.transient_crop.value_or(img);
  if (cfg.outputs.transient) {
    transient_npy = std::make_unique<NpyWriter>(staging.path("transient.npy"), NpyWriter::Dtype::F32,
                                                std::vector<int64_t>{int64_t(tcrop.height), int64_t(tcrop.width), axis.bins});
    files.push_back("transient.npy");
    if (cfg.render.split_direct_indirect) {
      indirect_npy = std::make_unique<NpyWriter>(staging.path("transient_indirect.npy"), NpyWriter::Dtype::F32,
                                                 std::vector<int64_t>{int64_t(tcrop.height), int64_t(tcrop.width), axis.bins});
      files.push_back("transient_indirect.npy");
    }
  }

  const std::vector<PixelRect> local_tiles = make_tiles(W, H, cfg.render.tile_size);
  // Per-pixel totals in double, summed in image order at the end, so the totals in metadata.json do
  // not depend on the tile size (a per-tile sum would change the order of the additions).
  std::vector<double> pixel_laser(size_t(W) * size_t(H), 0.0), pixel_oow(size_t(W) * size_t(H), 0.0);
  std::vector<render::RenderStats> tile_stats(local_tiles.size());
  const auto plot_pixels = profile_pixels(img);
  std::vector<std::vector<float>> profiles(plot_pixels.size(), std::vector<float>(size_t(K), 0.0f));
  std::vector<std::vector<float>> profiles_expected = profiles;

  std::fprintf(stderr, "spadgen: %s: %d x %d pixels, %zu tiles, %lld time bins of %s ps, K = %d\n",
               options.scene_file.c_str(), W, H, local_tiles.size(), static_cast<long long>(axis.bins),
               seconds_text(axis.bin_width_s / kPs).c_str(), K);
  Progress progress(local_tiles.size(), options.progress);

  tbb::parallel_for(size_t(0), local_tiles.size(), [&](size_t ti) {
    InterruptGuard::check();
    // Tiles are laid over the output image; the renderer and sensor see full-sensor coordinates.
    const PixelRect& lt = local_tiles[ti];
    const PixelRect rect{lt.x0 + img.x0, lt.y0 + img.y0, lt.width, lt.height};
    const auto out_index = [&](int x, int y) { return size_t(y - img.y0) * size_t(W) + size_t(x - img.x0); };

    if (cfg.outputs.ground_truth) {
      const GroundTruthTile g = renderer.ground_truth(rect);
      for (int y = rect.y0; y < rect.y1(); ++y)
        for (int x = rect.x0; x < rect.x1(); ++x) {
          const auto i = size_t(rect.index(x, y));
          const size_t o = out_index(x, y);
          range[o] = g.range[i], zc[o] = g.z[i];
          nx[o] = g.normal[3 * i], ny[o] = g.normal[3 * i + 1], nz[o] = g.normal[3 * i + 2];
          mesh[o] = float(g.mesh_id[i]), mat[o] = float(g.material_id[i]), lc[o] = float(g.layer_count[i]);
          for (int l = 0; l < L; ++l) {
            layer_range[size_t(l)][o] = g.layer_range[i * size_t(g.max_layers) + size_t(l)];
            layer_trans[size_t(l)][o] = g.layer_transmittance[i * size_t(g.max_layers) + size_t(l)];
          }
        }
    }

    const PixelRect data_rect = grow_clipped(rect, halo, cfg.camera.width_px, cfg.camera.height_px);
    const TransientTile t = renderer.transient(rect, data_rect, axis, &tile_stats[ti]);
    const SensorTile s = sensor.process(t);

    for (int y = rect.y0; y < rect.y1(); ++y)
      for (int x = rect.x0; x < rect.x1(); ++x) {
        const auto d = size_t(t.data_rect.index(x, y));
        const size_t o = out_index(x, y);
        lz[o] = float(t.laser_total[d]), oow[o] = float(t.out_of_window[d]), amb[o] = t.ambient_rate[d];
        pixel_laser[o] = t.laser_total[d], pixel_oow[o] = t.out_of_window[d];
      }

    const sensor::SensorMapsTile m = sensor.maps(rect);
    for (int y = rect.y0; y < rect.y1(); ++y)
      for (int x = rect.x0; x < rect.x1(); ++x) {
        const auto i = size_t(rect.index(x, y));
        const size_t o = out_index(x, y);
        skew[o] = m.gate_skew_ps[i], glen[o] = m.gate_length_ps[i], dcr[o] = m.dcr_cps[i], pde[o] = m.pde[i];
      }

    if (expected_npy) expected_npy->write_khw(rect, img.x0, img.y0, s.expected.data());
    if (counts_npy) {
      if (counts_u8) {
        std::vector<uint8_t> c8(s.counts.size());
        std::transform(s.counts.begin(), s.counts.end(), c8.begin(), [](uint16_t v) { return uint8_t(v); });
        counts_npy->write_khw(rect, img.x0, img.y0, c8.data());
      } else {
        counts_npy->write_khw(rect, img.x0, img.y0, s.counts.data());
      }
    }
    if (frames_npy) frames_npy->write_frames(rect, img.x0, img.y0, s.frames.data());
    if (transient_npy && axis.bins > 0) {
      const int x0 = std::max(rect.x0, tcrop.x0), x1 = std::min(rect.x1(), tcrop.x1());
      const int y0 = std::max(rect.y0, tcrop.y0), y1 = std::min(rect.y1(), tcrop.y1());
      if (x1 > x0 && y1 > y0)
        transient_npy->write_hwt({x0, y0, x1 - x0, y1 - y0}, t.data_rect, tcrop.x0, tcrop.y0, t.transient.data());
      if (indirect_npy && x1 > x0 && y1 > y0)
        indirect_npy->write_hwt({x0, y0, x1 - x0, y1 - y0}, t.data_rect, tcrop.x0, tcrop.y0, t.transient_indirect.data());
    }
    if (!sweep) {
      for (int y = rect.y0; y < rect.y1(); ++y)
        for (int x = rect.x0; x < rect.x1(); ++x) {
          const auto i = size_t(rect.index(x, y));
          ic[out_index(x, y)] = s.intensity_counts[i], ip[out_index(x, y)] = s.intensity_photons[i];
        }
    }
    for (size_t p = 0; p < plot_pixels.size(); ++p)
      if (rect.contains(plot_pixels[p].first, plot_pixels[p].second))
        for (int k = 0; k < K; ++k) {
          const size_t i = size_t(k) * size_t(rect.count()) + size_t(rect.index(plot_pixels[p].first, plot_pixels[p].second));
          profiles[p][size_t(k)] = float(s.counts[i]);
          profiles_expected[p][size_t(k)] = s.expected[i];
        }
    progress.tick();
  });
  const double render_seconds = progress.seconds();

  // Provenance travels with every image.
  const std::string hash = scene_hash(cfg);
  const std::string crop_text = json::array({img.x0, img.y0, img.width, img.height}).dump();
  const auto provenance = [&](writers::ExrImage& e) {
    e.set_attribute("spadgen_version", SPADGEN_VERSION);
    e.set_attribute("spadgen_seed", std::to_string(cfg.seed));
    e.set_attribute("spadgen_scene_file", cfg.scene_file);
    e.set_attribute("spadgen_scene_hash", hash);
    e.set_attribute("spadgen_crop", crop_text);
  };
  // Layers beyond the deepest one any pixel has are not written.
  int deepest = 0;
  if (cfg.outputs.ground_truth) {
    deepest = int(*std::max_element(lc, lc + size_t(W) * size_t(H)));
    writers::ExrImage g2(W, H);
    for (const char* name : {"range", "z", "normal.X", "normal.Y", "normal.Z", "mesh_id", "material_id", "layer_count"})
      std::copy_n(gt.channel(name), size_t(W) * size_t(H), g2.channel(name));
    for (int l = 0; l < deepest; ++l)
      for (const char* what : {".range", ".transmittance"}) {
        const std::string n = "layer" + std::to_string(l) + what;
        std::copy_n(gt.channel(n), size_t(W) * size_t(H), g2.channel(n));
      }
    provenance(g2);
    g2.set_attribute("spadgen_units", "range, z, layer<i>.range: metres (+inf where the ray hits nothing); transmittance: fraction");
    g2.write(staging.path("ground_truth.exr"));
    files.push_back("ground_truth.exr");
  }
  provenance(laser);
  laser.set_attribute("spadgen_units", "photons per laser pulse reaching the pixel's SPAD (before PDP)");
  laser.set_attribute("spadgen_time_axis", axis_json(axis).dump());
  laser.write(staging.path("laser.exr"));
  files.push_back("laser.exr");
  provenance(ambient);
  ambient.set_attribute("spadgen_units", "ambient photons per second reaching the pixel's SPAD (before PDP)");
  ambient.write(staging.path("ambient.exr"));
  files.push_back("ambient.exr");
  provenance(maps);
  maps.write(staging.path("sensor_maps.exr"));
  files.push_back("sensor_maps.exr");
  if (!sweep) {
    provenance(intensity);
    intensity.set_attribute("spadgen_units", "counts: summed binary frames; photons: linearised incident photons per image");
    intensity.write(staging.path("intensity.exr"));
    files.push_back("intensity.exr");
  }

  if (cfg.outputs.previews) {
    if (cfg.outputs.ground_truth) {
      writers::write_png(staging.path("previews/depth.png"), writers::depth_preview(gt.channel("range"), W, H, 0.0f, 0.0f));
      files.push_back("previews/depth.png");
    }
    const float* bright = sweep ? laser.channel("photons_per_pulse") : intensity.channel("photons");
    writers::write_png(staging.path("previews/intensity.png"), writers::gray_preview(bright, W, H));
    files.push_back("previews/intensity.png");
    if (sweep && K > 1) {
      std::vector<double> x(sensor.gate_positions_s().size());
      std::transform(sensor.gate_positions_s().begin(), sensor.gate_positions_s().end(), x.begin(), [](double t) { return t / kNs; });
      writers::write_png(staging.path("previews/gate_profiles.png"),
                         writers::profile_plot(profiles, x, 800, 450, "gate position (ns)", "counts"));
      files.push_back("previews/gate_profiles.png");
    }
  }

  const double laser_total = std::accumulate(pixel_laser.begin(), pixel_laser.end(), 0.0);
  const double oow_total = std::accumulate(pixel_oow.begin(), pixel_oow.end(), 0.0);
  render::RenderStats rays;
  for (const auto& st : tile_stats) rays.camera_rays += st.camera_rays, rays.shadow_rays += st.shadow_rays;
  files.push_back("metadata.json");

  ojson meta;
  meta["spadgen_version"] = SPADGEN_VERSION;
  meta["scene_file"] = cfg.scene_file;
  meta["scene_hash_fnv1a64"] = hash;
  meta["seed"] = cfg.seed;
  meta["versions"] = {{"spadgen", SPADGEN_VERSION},
                      {"embree", std::to_string(RTC_VERSION_MAJOR) + "." + std::to_string(RTC_VERSION_MINOR) + "." + std::to_string(RTC_VERSION_PATCH)}};
  meta["units"] = {{"length", "m"}, {"time", "s unless the key says ns or ps"}, {"laser", "photons per laser pulse at the SPAD, before PDP"},
                   {"ambient", "photons per second at the SPAD, before PDP"}, {"counts", "summed binary frames"}};
  meta["image"] = {{"width", W}, {"height", H}, {"crop_in_sensor", {img.x0, img.y0, img.width, img.height}},
                   {"sensor_width", cfg.camera.width_px}, {"sensor_height", cfg.camera.height_px},
                   {"pixel_order", "row 0 is the top of the image; (K, H, W) stacks index [k, y, x]"}};
  meta["photons_per_pulse_emitted"] = renderer.photons_per_pulse();
  meta["time_axis"] = ojson::parse(axis_json(axis).dump());
  if (cfg.outputs.transient)
    meta["transient"] = {{"crop_in_sensor", {tcrop.x0, tcrop.y0, tcrop.width, tcrop.height}},
                         {"shape", {tcrop.height, tcrop.width, axis.bins}},
                         {"indirect", cfg.render.split_direct_indirect
                                          ? "transient_indirect.npy: the part of transient.npy from paths with two or more "
                                            "scattering vertices (docs/render.md); direct = transient - transient_indirect"
                                          : "not split (render.split_direct_indirect is false)"}};
  meta["laser_photons_per_pulse"] = {{"total_all_pixels", laser_total},
                                     {"outside_time_window", oow_total},
                                     {"outside_fraction", laser_total > 0 ? oow_total / laser_total : 0.0}};
  meta["acquisition"] = ojson::parse(sensor.describe().dump());
  meta["ground_truth_layers"] = deepest;
  meta["counts_dtype"] = counts_u8 ? "uint8" : "uint16";
  meta["preview_profile_pixels"] = plot_pixels;
  meta["warnings"] = resolved.warnings;
  for (const std::string& w : scene.warnings) meta["warnings"].push_back(w);
  meta["resolved_scene"] = resolved.resolved;
  meta["files"] = files;
  // Everything above depends only on the scene and the seed; "run" is how this run went.
  meta["run"] = {{"threads", options.threads}, {"seconds", render_seconds}, {"camera_rays", rays.camera_rays},
                 {"shadow_rays", rays.shadow_rays}};
  writers::write_json(staging.path("metadata.json"), json::parse(meta.dump()));

  InterruptGuard::check();
  if (expected_npy) expected_npy->commit();
  if (counts_npy) counts_npy->commit();
  if (frames_npy) frames_npy->commit();
  if (transient_npy) transient_npy->commit();
  if (indirect_npy) indirect_npy->commit();
  staging.publish(files);
  std::fprintf(stderr, "spadgen: wrote %zu files to %s in %.1f s\n", files.size(), out.string().c_str(), progress.seconds());
  return {out.string(), files};
}

std::string info(const std::string& scene_file, const std::vector<std::string>& overrides) {
  const scenes::ResolvedRun r = scenes::load_scene_file(scene_file, overrides);
  const RunConfig& c = r.config;
  const scenes::Scene scene = scenes::load_gltf(c.gltf_path, c.gltf_scene);
  sensor::SensorModel sensor(c);
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
    << mb((c.acquisition.frames <= 255 ? 1.0 : 2.0) * px * sensor.K());
  if (c.outputs.frames) o << ", frames.npy " << mb(double(sensor.K()) * c.acquisition.frames * img.height * ((img.width + 7) / 8));
  if (c.outputs.transient) {
    const PixelRect t = c.outputs.transient_crop.value_or(img);
    o << ", transient.npy " << mb(4.0 * double(t.width) * t.height * double(axis.bins));
  }
  o << "\n";
  for (const std::string& w : r.warnings) o << "warning: " << w << "\n";
  return o.str();
}

}  // namespace spadgen::app
