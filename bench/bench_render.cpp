// Renderer benchmark on the paper's multi-object scene (plate + sphere) at 1024 x 1000:
//  - the integrator's rays per second (camera + shadow rays, counted by RenderStats) against raw Embree
//    rtcIntersect1 / rtcOccluded1 replaying exactly the rays the integrator traced, on the same scene
//    (recorded by bench_render_rays, which this program runs);
//  - cost against error for samples per pixel, for the time-bin width and for max_bounces.
// Usage: bench_render [--benchmark_filter=...]; the summary (ratio, error tables) is printed at the end.
#include <benchmark/benchmark.h>
#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "core/units.h"
#include "ray_record.h"
#include "render/embree_scene.h"
#include "render/renderer.h"
#include "render_setup.h"
#include "scenes/scene.h"

namespace {

using namespace spadgen;
using bench::render_image;
using bench::Setup;
using bench::setup;

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

// state.range(0): time-bin width in ps, 0 for no transient (the time-integrated render only).
void BM_Integrator(benchmark::State& state) {
  Setup& s = setup();
  RunConfig c = s.config;
  c.render.samples_per_pixel = 1;
  const render::Renderer r(s.scene, bench::stage(c));
  const TimeAxis axis = state.range(0) > 0 ? sweep_axis(double(state.range(0)) * 1e-12) : TimeAxis{};
  const PixelRect all{0, 0, c.camera.width_px, c.camera.height_px};
  uint64_t rays = 0;
  for (auto _ : state) {
    const render::RenderStats st = render_image(r, c, axis, all);
    rays += st.rays.total();
  }
  state.counters["rays_per_s"] = benchmark::Counter(double(rays), benchmark::Counter::kIsRate);
  state.counters["rays_per_image"] = double(rays) / double(state.iterations());
}

// The integrator's rays for the whole image at 1 sample per pixel, as bench_render_rays records them (in
// another process, so that no recording hook lies on the path this program times).
// The recorder is the bench_render_rays beside this program (so that a copy of an older build's two
// programs, measured against the new build's, records its own renderer's rays), else the one it was built
// with.
std::string rays_program() {
  std::error_code ec;
  const std::filesystem::path beside = std::filesystem::read_symlink("/proc/self/exe", ec).parent_path() / "bench_render_rays";
  return !ec && std::filesystem::is_regular_file(beside, ec) ? beside.string() : std::string(SPADGEN_BENCH_RENDER_RAYS);
}

const std::vector<bench::RayRecord>& recorded_rays() {
  static std::vector<bench::RayRecord> rays = [] {
    std::vector<bench::RayRecord> out;
    const std::string program = rays_program();
    std::fprintf(stderr, "recording the integrator's rays with %s\n", program.c_str());
    FILE* pipe = popen(("'" + program + "'").c_str(), "r");
    uint64_t n = 0;
    bool ok = pipe && std::fread(&n, sizeof n, 1, pipe) == 1;
    if (ok) {
      out.resize(n);
      ok = std::fread(out.data(), sizeof(bench::RayRecord), n, pipe) == n;
    }
    if (!pipe || pclose(pipe) != 0 || !ok) {
      std::fprintf(stderr, "could not record the integrator's rays with %s\n", program.c_str());
      std::exit(1);
    }
    return out;
  }();
  return rays;
}

// One pass of raw Embree over the recorded rays, on all threads.
void replay(RTCScene scene, const std::vector<bench::RayRecord>& rays) {
  tbb::parallel_for(tbb::blocked_range<size_t>(0, rays.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    unsigned hits = 0;
    for (size_t i = r.begin(); i < r.end(); ++i) {
      const bench::RayRecord& q = rays[i];
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      if (q.occlusion) {
        RTCRay ray{q.origin[0], q.origin[1], q.origin[2], q.tnear, q.dir[0], q.dir[1], q.dir[2], 0.0f, q.tfar, ~0u, q.id, 0};
        rtcOccluded1(scene, &ctx, &ray);
        hits += ray.tfar < 0.0f;
      } else {
        RTCRayHit rh{};
        rh.ray = {q.origin[0], q.origin[1], q.origin[2], q.tnear, q.dir[0], q.dir[1], q.dir[2], 0.0f, q.tfar, ~0u, q.id, 0};
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(scene, &ctx, &rh);
        hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
      }
    }
    benchmark::DoNotOptimize(hits);
  });
}

void BM_RawEmbreeReplay(benchmark::State& state) {
  const std::vector<bench::RayRecord>& rays = recorded_rays();
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
  const render::Renderer r(s.scene, bench::stage(c));
  const render::EmbreeScene embree(s.scene);
  const std::vector<bench::RayRecord>& rays = recorded_rays();
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
    int_rays = st.rays.total();
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
    const render::Renderer r(s.scene, bench::stage(c));
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
  const render::Renderer r(s.scene, bench::stage(c));
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
    const render::Renderer r(s.scene, bench::stage(c));
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
