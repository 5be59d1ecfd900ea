// Renderer benchmark on the paper's multi-object scene (plate + sphere) at 1024 x 1000:
//  - the integrator's rays per second (camera + shadow rays, counted by RenderStats) against raw Embree
//    rtcIntersect1 / rtcOccluded1 replaying exactly the rays the integrator traced, on the same scene;
//  - cost against error for samples per pixel, for the time-bin width and for max_bounces.
// Usage: bench_render [--benchmark_filter=...]; the summary (ratio, error tables) is printed at the end.
#include <benchmark/benchmark.h>
#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <vector>

#include "core/units.h"
#include "render/embree_scene.h"
#include "render/renderer.h"
#include "sensor/model/pixel_layout.h"
#include "scenes/scene.h"
#include "scenes/scene_file.h"

namespace {

using namespace spadgen;

struct Setup {
  scenes::Scene scene;
  RunConfig config;
  std::string source;
};

// The renderer's part of the run, with the fill factor of every row as the sensor lays them out.
RenderStageConfig stage(const RunConfig& c) {
  return render_stage(c, sensor::PixelLayout(c.sensor.preset, c.camera.height_px).row_fill_factor(c.sensor));
}

// The equivalent of scenes/paper/multi_object.json when the shipped file is not there: a 2 mm plate of
// ior 1.5, front face at 0.45 m, covering the left half, in front of a sphere whose nearest point is 0.75 m.
Setup build_in_code() {
  Setup s;
  s.source = "built in code";
  scenes::Material plate;
  plate.name = "plastic_plate";
  plate.metallic = 0;
  plate.roughness = 0.1f;
  plate.transmission = 1;
  plate.ior = 1.5f;
  plate.thickness_m = 0.002f;
  s.scene.materials.push_back(plate);
  scenes::Material white;
  white.base_color = {0.8f, 0.8f, 0.8f, 1};
  white.metallic = 0;
  s.scene.materials.push_back(white);
  scenes::Mesh box;
  const glm::vec3 lo(-0.35f, -0.2f, -0.452f), hi(0.0f, 0.2f, -0.45f);
  for (int i = 0; i < 8; ++i) box.positions.push_back({(i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z});
  const uint32_t f[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (const auto& q : f) box.indices.insert(box.indices.end(), {q[0], q[1], q[2], q[0], q[2], q[3]});
  box.material = 0;
  s.scene.meshes.push_back(box);
  scenes::Mesh sphere;
  const int rings = 128, segs = 256;
  for (int i = 0; i <= rings; ++i)
    for (int j = 0; j <= segs; ++j) {
      const double th = kPi * i / rings, ph = 2 * kPi * j / segs;
      const glm::vec3 n(float(std::sin(th) * std::cos(ph)), float(std::cos(th)), float(-std::sin(th) * std::sin(ph)));
      sphere.positions.push_back(glm::vec3(0, 0, -0.85f) + 0.1f * n);
      sphere.normals.push_back(n);
    }
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segs; ++j) {
      const auto a = uint32_t(i * (segs + 1) + j), b = a + uint32_t(segs + 1);
      sphere.indices.insert(sphere.indices.end(), {a, b, b + 1, a, b + 1, a + 1});
    }
  sphere.material = 1;
  s.scene.meshes.push_back(sphere);
  s.config.camera.height_px = 1000;
  s.config.laser.wavelength_m = 510e-9;
  s.config.render.max_bounces = 8;
  return s;
}

Setup& setup() {
  static Setup s = [] {
    const std::string json = std::string(SPADGEN_SOURCE_DIR) + "/scenes/paper/multi_object.json";
    if (std::filesystem::exists(json)) {
      try {
        Setup r;
        r.config = scenes::load_scene_file(json, {"camera.height_px=1000"}).config;
        r.scene = scenes::load_gltf(r.config.gltf_path, r.config.gltf_scene);
        r.source = json;
        return r;
      } catch (const std::exception& e) {
        std::fprintf(stderr, "could not load %s (%s); building the scene in code\n", json.c_str(), e.what());
      }
    }
    return build_in_code();
  }();
  return s;
}

// The window of the paper's gate sweep (0.6 to 13.2 ns plus the 3.8 ns gate) in bins of bin_s.
TimeAxis sweep_axis(double bin_s) {
  TimeAxis a;
  a.start_s = 0.0;
  a.bin_width_s = bin_s;
  a.bins = static_cast<int64_t>(std::ceil(17.5e-9 / bin_s));
  a.period_s = 25e-9;
  return a;
}

struct Result {
  double integrator_rays_per_s = 0, raw_rays_per_s = 0;
} g_result;

// Renders the whole image tile by tile, as the app does (TBB over tiles).
render::RenderStats render_image(const render::Renderer& r, const RunConfig& c, const TimeAxis& axis,
                                 const PixelRect& region) {
  std::vector<PixelRect> tiles;
  for (int y = region.y0; y < region.y1(); y += 32)
    for (int x = region.x0; x < region.x1(); x += 32)
      tiles.push_back({x, y, std::min(32, region.x1() - x), std::min(32, region.y1() - y)});
  std::vector<render::RenderStats> stats(tiles.size());
  tbb::parallel_for(size_t(0), tiles.size(), [&](size_t i) {
    const TransientTile t = r.transient(tiles[i], tiles[i], axis, &stats[i]);
    benchmark::DoNotOptimize(t.laser_total.data());
  });
  (void)c;
  render::RenderStats total;
  for (const auto& s : stats) {
    total.camera_rays += s.camera_rays;
    total.shadow_rays += s.shadow_rays;
  }
  return total;
}

// state.range(0): time-bin width in ps, 0 for no transient (the time-integrated render only).
void BM_Integrator(benchmark::State& state) {
  Setup& s = setup();
  RunConfig c = s.config;
  c.render.samples_per_pixel = 1;
  const render::Renderer r(s.scene, stage(c));
  const TimeAxis axis = state.range(0) > 0 ? sweep_axis(double(state.range(0)) * 1e-12) : TimeAxis{};
  const PixelRect all{0, 0, c.camera.width_px, c.camera.height_px};
  uint64_t rays = 0;
  for (auto _ : state) {
    const render::RenderStats st = render_image(r, c, axis, all);
    rays += st.camera_rays + st.shadow_rays;
  }
  state.counters["rays_per_s"] = benchmark::Counter(double(rays), benchmark::Counter::kIsRate);
  state.counters["rays_per_image"] = double(rays) / double(state.iterations());
}

// The integrator's rays for the whole image at 1 sample per pixel, recorded on one thread.
const std::vector<render::RayRecord>& recorded_rays() {
  static std::vector<render::RayRecord> rays = [] {
    Setup& s = setup();
    RunConfig c = s.config;
    c.render.samples_per_pixel = 1;
    const render::Renderer r(s.scene, stage(c));
    std::vector<render::RayRecord> out;
    out.reserve(8u << 20);
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    render::EmbreeScene::record_rays_on_this_thread(&out);
    // The rays do not depend on the time axis, so none is kept while recording.
    render_image(r, c, TimeAxis{}, {0, 0, c.camera.width_px, c.camera.height_px});
    render::EmbreeScene::record_rays_on_this_thread(nullptr);
    return out;
  }();
  return rays;
}

// One pass of raw Embree over the recorded rays, on all threads.
void replay(RTCScene scene, const std::vector<render::RayRecord>& rays) {
  tbb::parallel_for(tbb::blocked_range<size_t>(0, rays.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    unsigned hits = 0;
    for (size_t i = r.begin(); i < r.end(); ++i) {
      const render::RayRecord& q = rays[i];
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      if (q.occlusion) {
        RTCRay ray{q.origin.x, q.origin.y, q.origin.z, q.tnear, q.dir.x, q.dir.y, q.dir.z, 0.0f, q.tfar, ~0u, 0, 0};
        rtcOccluded1(scene, &ctx, &ray);
        hits += ray.tfar < 0.0f;
      } else {
        RTCRayHit rh{};
        rh.ray = {q.origin.x, q.origin.y, q.origin.z, q.tnear, q.dir.x, q.dir.y, q.dir.z, 0.0f, q.tfar, ~0u, 0, 0};
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(scene, &ctx, &rh);
        hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
      }
    }
    benchmark::DoNotOptimize(hits);
  });
}

void BM_RawEmbreeReplay(benchmark::State& state) {
  const std::vector<render::RayRecord>& rays = recorded_rays();
  const render::EmbreeScene embree(setup().scene);  // the same geometry, built the same way
  for (auto _ : state) replay(embree.handle(), rays);
  state.counters["rays_per_s"] =
      benchmark::Counter(double(rays.size()) * double(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["rays_per_image"] = double(rays.size());
}

// The ratio under a changing machine load: integrator images (no transient) and raw replays alternate,
// and each adjacent pair gives one ratio of rays per second; the median of the pairs is printed.
void paired_ratio(int pairs) {
  Setup& s = setup();
  RunConfig c = s.config;
  c.render.samples_per_pixel = 1;
  const render::Renderer r(s.scene, stage(c));
  const render::EmbreeScene embree(s.scene);
  const std::vector<render::RayRecord>& rays = recorded_rays();
  const PixelRect all{0, 0, c.camera.width_px, c.camera.height_px};
  std::vector<double> ratios;
  double t_int_min = 1e30, t_raw_min = 1e30;
  uint64_t int_rays = 0;
  for (int i = 0; i < pairs; ++i) {
    auto t0 = std::chrono::steady_clock::now();
    const render::RenderStats st = render_image(r, c, TimeAxis{}, all);
    auto t1 = std::chrono::steady_clock::now();
    replay(embree.handle(), rays);
    auto t2 = std::chrono::steady_clock::now();
    int_rays = st.camera_rays + st.shadow_rays;
    const double ti = std::chrono::duration<double>(t1 - t0).count(), tr = std::chrono::duration<double>(t2 - t1).count();
    t_int_min = std::min(t_int_min, ti);
    t_raw_min = std::min(t_raw_min, tr);
    ratios.push_back((double(int_rays) / ti) / (double(rays.size()) / tr));
  }
  std::sort(ratios.begin(), ratios.end());
  std::printf("\npaired integrator/raw ratio over %d alternating pairs: median %.3f (min %.3f, max %.3f); "
              "fastest integrator %.0f ms (%.2f Mrays/s), fastest raw replay %.0f ms (%.2f Mrays/s)\n",
              pairs, ratios[ratios.size() / 2], ratios.front(), ratios.back(), t_int_min * 1e3,
              double(int_rays) / t_int_min * 1e-6, t_raw_min * 1e3, double(rays.size()) / t_raw_min * 1e-6);
}

// Cost against error on a 128 x 128 crop where the plate covers the sphere: render time and the RMS
// relative error of the per-pixel laser total against a 1024-sample reference.
void samples_vs_error() {
  Setup& s = setup();
  const PixelRect crop{s.config.camera.width_px / 2 - 192, s.config.camera.height_px / 2 - 64, 128, 128};
  const TimeAxis none{};
  auto totals = [&](int spp, double* seconds) {
    RunConfig c = s.config;
    c.render.samples_per_pixel = spp;
    const render::Renderer r(s.scene, stage(c));
    const auto t0 = std::chrono::steady_clock::now();
    const TransientTile t = r.transient(crop, crop, none);
    *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return t.laser_total;
  };
  double ref_s = 0;
  const std::vector<double> ref = totals(1024, &ref_s);
  std::printf("\nsamples per pixel vs error (128 x 128 crop over plate and sphere, reference 1024 spp in %.1f s)\n",
              ref_s);
  std::printf("%6s %10s %12s\n", "spp", "time_s", "rms_rel_err");
  for (int spp : {1, 4, 16, 64, 256}) {
    double sec = 0;
    const std::vector<double> v = totals(spp, &sec);
    double e = 0;
    size_t n = 0;
    for (size_t i = 0; i < v.size(); ++i)
      if (ref[i] > 0) {
        e += std::pow(v[i] / ref[i] - 1, 2);
        ++n;
      }
    std::printf("%6d %10.3f %12.4f\n", spp, sec, std::sqrt(e / double(n)));
  }
}

// Cost against error for the bin width: render time of the same crop (16 spp) and the RMS error of each
// pixel's mean arrival time against 0.5 ps bins, in mm of depth (c t / 2).
void bin_width_vs_error() {
  Setup& s = setup();
  RunConfig c = s.config;
  c.render.samples_per_pixel = 16;
  const render::Renderer r(s.scene, stage(c));
  const PixelRect crop{c.camera.width_px / 2 - 192, c.camera.height_px / 2 - 64, 128, 128};
  auto mean_times = [&](double bin, double* seconds, int64_t* bins) {
    const TimeAxis axis = sweep_axis(bin);
    *bins = axis.bins;
    const auto t0 = std::chrono::steady_clock::now();
    const TransientTile t = r.transient(crop, crop, axis);
    *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::vector<double> m(size_t(crop.count()), 0.0);
    for (int64_t i = 0; i < crop.count(); ++i) {
      double m0 = 0, m1 = 0;
      for (int64_t b = 0; b < axis.bins; ++b) {
        const double g = t.transient[size_t(i * axis.bins + b)];
        m0 += g;
        m1 += g * axis.bin_centre_s(b);
      }
      m[size_t(i)] = m0 > 0 ? m1 / m0 : 0.0;
    }
    return m;
  };
  double sec = 0;
  int64_t bins = 0;
  const std::vector<double> ref = mean_times(0.5e-12, &sec, &bins);
  std::printf("\ntime-bin width vs error (same crop, 16 spp; reference 0.5 ps bins: %lld bins, %.2f s)\n",
              static_cast<long long>(bins), sec);
  std::printf("%8s %8s %10s %14s\n", "bin_ps", "bins", "time_s", "rms_depth_mm");
  for (double bin_ps : {1.0, 4.5, 9.0, 18.0, 36.0}) {
    const std::vector<double> m = mean_times(bin_ps * 1e-12, &sec, &bins);
    double e = 0;
    for (size_t i = 0; i < m.size(); ++i) e += std::pow((m[i] - ref[i]) * kSpeedOfLight / 2 * 1e3, 2);
    std::printf("%8.1f %8lld %10.3f %14.4f\n", bin_ps, static_cast<long long>(bins), sec,
                std::sqrt(e / double(m.size())));
  }
}

// Cost against truncation error for render.max_bounces: render time of the same crop (16 spp) and the
// change of its laser total (summed over the crop, and RMS over pixels) against max_bounces 16. The
// random draws of a path do not depend on max_bounces, so the differences are the truncated light itself.
void bounces_vs_error() {
  Setup& s = setup();
  const PixelRect crop{s.config.camera.width_px / 2 - 192, s.config.camera.height_px / 2 - 64, 128, 128};
  auto totals = [&](int bounces, double* seconds) {
    RunConfig c = s.config;
    c.render.samples_per_pixel = 16;
    c.render.max_bounces = bounces;
    const render::Renderer r(s.scene, stage(c));
    const auto t0 = std::chrono::steady_clock::now();
    const TransientTile t = r.transient(crop, crop, TimeAxis{});
    *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return t.laser_total;
  };
  double ref_s = 0;
  const std::vector<double> ref = totals(16, &ref_s);
  double ref_sum = 0;
  for (double v : ref) ref_sum += v;
  std::printf("\nmax_bounces vs error (same crop, 16 spp; reference max_bounces 16 in %.3f s)\n", ref_s);
  std::printf("%8s %10s %16s %16s\n", "bounces", "time_s", "total_change", "rms_pixel_change");
  for (int b : {1, 2, 3, 4, 6, 8, 12}) {
    double sec = 0;
    const std::vector<double> v = totals(b, &sec);
    double sum = 0, e = 0;
    size_t n = 0;
    for (size_t i = 0; i < v.size(); ++i) {
      sum += v[i];
      if (ref[i] > 0) {
        e += std::pow(v[i] / ref[i] - 1, 2);
        ++n;
      }
    }
    std::printf("%8d %10.3f %16.3e %16.3e\n", b, sec, sum / ref_sum - 1, std::sqrt(e / double(n)));
  }
}

}  // namespace

BENCHMARK(BM_Integrator)->Arg(0)->Arg(9)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);
BENCHMARK(BM_RawEmbreeReplay)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

int main(int argc, char** argv) {
  bool studies = true;  // --no_studies: only the throughput benchmarks (for profiling)
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]) == "--no_studies") {
      studies = false;
      for (int j = i; j + 1 < argc; ++j) argv[j] = argv[j + 1];
      --argc;
      break;
    }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  std::printf("scene: %s (%zu triangles), %d x %d\n", setup().source.c_str(), setup().scene.triangle_count(),
              setup().config.camera.width_px, setup().config.camera.height_px);
  // Record the replayed rays before timing anything.
  std::printf("integrator rays recorded for the replay: %zu\n", recorded_rays().size());
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  paired_ratio(9);
  if (studies) {
    samples_vs_error();
    bin_width_vs_error();
    bounces_vs_error();
  }
  return 0;
}
