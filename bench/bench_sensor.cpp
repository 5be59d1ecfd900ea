// Sensor throughput against the real camera (paper Table 1 / section 3):
//   binary frames: 1024 x 1000 pixels x 24,000 fps = 24.576 Gbit/s;
//   counts for a full sweep: 1024 x 1000 pixels, 350 gate positions, 255 frames each, acquired in 3.7 s.
// Both measured on a sub-image and scaled to the full array (the work is per pixel, so it scales
// linearly); all threads TBB is allowed to use. Results and the command: bench/README.md ("## sensor").
#include <benchmark/benchmark.h>
#include <hwy/targets.h>
#include <malloc.h>
#include <tbb/parallel_for.h>

#include <chrono>
#include <cstdio>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/rng.h"
#include "core/tile.h"
#include "sensor/sampling/batch_kernels.h"
#include "sensor/sampling/binomial_table.h"
#include "sensor/sampling/frames_kernel.h"
#include "sensor/sampling/sampling.h"
#include "sensor/sensor.h"
#include "writers/writers.h"

#include "ars_ceiling.h"

namespace {

using namespace spadgen;

constexpr double kCameraBitRate = 1024.0 * 1000.0 * 24000.0;  // bit/s
constexpr double kCameraSweepSeconds = 3.7;

// A realistic mix of per-frame detection probabilities for one gate position: most pixels see only
// background (p ~ 1e-6 .. 1e-3), some see a return in the gate (p 0.05 .. 0.95).
std::vector<double> realistic_lambdas(size_t n) {
  Rng rng(5, RngKind::Test, 1);
  std::vector<double> lam(n);
  for (double& l : lam) {
    const double u = rng.next_double();
    if (u < 0.7) l = std::pow(10.0, -6.0 + 3.0 * rng.next_double());  // background only
    else if (u < 0.8) l = std::pow(10.0, -3.0 + 2.0 * rng.next_double());  // a weak return
    else l = 0.05 + 3.0 * rng.next_double();  // a return in the gate: p from 0.05 to 0.95
  }
  return lam;
}

// The sampler alone: N = 255 Bernoulli bits per pixel and gate position, keyed streams, all threads.
// Per block of 1024 pixels: Prob {p, q, -lambda} from lambda (vectorised, as process() forms them for a
// tile), then sample_bits_batch (what process() calls for a row of pixels at one gate position).
// BM_FrameBits' mix: 65,536 pixels of realistic rates, N = 255, sampled in blocks of 1024 in parallel; one
// pass per gate position k (Prob of every pixel as process() forms them for a tile, into a buffer that lives
// as long as the run, as process()'s does).
struct FrameBitsMix {
  static constexpr uint32_t N = 255;
  static constexpr size_t pixels = 1 << 16, block = 1024;
  const std::vector<double> lam = realistic_lambdas(pixels);
  std::vector<uint64_t> ids = std::vector<uint64_t>(pixels);
  const sensor::BinomialSampler sampler{N};
  std::vector<uint64_t> words = std::vector<uint64_t>(pixels * 4);
  std::vector<sensor::Prob> prob = std::vector<sensor::Prob>(pixels);
  FrameBitsMix() {
    for (size_t i = 0; i < pixels; ++i) ids[i] = i;
  }
  // Pixels b .. b + count at gate position k: their Prob from lambda, then their bits.
  void sample(size_t b, size_t count, uint64_t k) {
    sensor::probabilities(lam.data() + b, count, prob.data() + b, 1);
    sensor::sample_bits_batch(1, k, ids.data() + b, count, sampler, prob.data() + b, words.data() + 4 * b);
  }
  void pass(uint64_t k) {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, pixels, block),
                      [&](const tbb::blocked_range<size_t>& r) { sample(r.begin(), r.size(), k); });
    benchmark::DoNotOptimize(words.data());
  }
  // FNV-1a of the words, word by word, from h.
  uint64_t words_hash(uint64_t h = 0xcbf29ce484222325ull) const {
    for (uint64_t w : words) h = (h ^ w) * 0x100000001b3ull;
    return h;
  }
};

// An instruction set this processor runs, as Highway's dispatcher would run it (AVX2 twice where the processor
// has VAES: with and without it), named as the benchmarks' labels name them ("AVX3", "AVX2+VAES").
struct InstructionSet {
  int64_t target;
  bool vaes;
  std::string name;
};
std::vector<InstructionSet> instruction_sets() {
  std::vector<InstructionSet> sets;
  for (const int64_t t : hwy::SupportedAndGeneratedTargets())
    for (const bool vaes : {false, true})
      if (!vaes || (t == HWY_AVX2 && sensor::cpu_has_vaes()))
        sets.push_back({t, vaes, std::string(hwy::TargetName(t)) + (vaes ? "+VAES" : "")});
  return sets;
}
// Every kernel runs on `set` from now on (0 for the target: the dispatcher's own choice again).
void use(const InstructionSet& set) {
  hwy::SetSupportedTargetsForTest(set.target);
  sensor::set_avx2_vaes(set.vaes);
}

void BM_FrameBits(benchmark::State& state) {
  FrameBitsMix m;
  const size_t pixels = m.pixels, block = m.block;
  uint64_t k = 0;
  for (auto _ : state) m.pass(k++);
  const double bits = static_cast<double>(state.iterations()) * pixels * m.N;
  // Bit-identity check across builds: FNV-1a of the words of gate positions 0..3 (one pass each, outside
  // the timing), modulo 10^6.
  uint64_t hash = 0xcbf29ce484222325ull;
  for (uint64_t kk = 0; kk < 4; ++kk) {
    for (size_t b0 = 0; b0 < pixels; b0 += block) {
      std::vector<double> p(block), q(block);
      std::vector<sensor::Prob> pr(block);
      sensor::probabilities(m.lam.data() + b0, block, p.data(), q.data());
      for (size_t i = 0; i < block; ++i) pr[i] = {p[i], q[i], -m.lam[b0 + i]};
      sensor::sample_bits_batch(1, kk, m.ids.data() + b0, block, m.sampler, pr.data(), m.words.data() + 4 * b0);
    }
    hash = m.words_hash(hash);
  }
  state.counters["outputs_hash"] = static_cast<double>(hash % 1000000);
  state.counters["Gbit_per_s"] = benchmark::Counter(bits * 1e-9, benchmark::Counter::kIsRate);
  state.counters["x_camera"] = benchmark::Counter(bits / kCameraBitRate, benchmark::Counter::kIsRate);
  state.SetLabel(sensor::dense_bits_target());
}
BENCHMARK(BM_FrameBits)->UseRealTime()->Unit(benchmark::kMillisecond);

// The AVX2 kernel's AES rounds with VAES against Highway's split 128-bit rounds, on BM_FrameBits' mix,
// alternated pass by pass in one run (manual time: the VAES passes). Skipped unless the dispatcher chose
// AVX2 on a processor with VAES.
void BM_FrameBitsVaes(benchmark::State& state) {
  if (std::string(sensor::dense_bits_target()) != "AVX2+VAES") {
    state.SkipWithError("the dispatcher did not choose AVX2 with VAES on this processor");
    return;
  }
  FrameBitsMix m;
  uint64_t k = 0;
  const auto timed = [&] {
    const auto t0 = std::chrono::steady_clock::now();
    m.pass(k++);
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  double on = 0.0, off = 0.0;
  for (auto _ : state) {
    sensor::set_avx2_vaes(false);
    off += timed();
    sensor::set_avx2_vaes(true);
    const double t = timed();
    on += t;
    state.SetIterationTime(t);
  }
  const double bits = static_cast<double>(state.iterations()) * m.pixels * m.N;
  state.counters["Gbit_per_s"] = bits * 1e-9 / on;
  state.counters["split_Gbit_per_s"] = bits * 1e-9 / off;
  state.counters["x_split"] = off / on;
}
BENCHMARK(BM_FrameBitsVaes)->UseManualTime()->Unit(benchmark::kMillisecond);

// The frame-bit sampler on every instruction set this processor runs, forced in turn
// (hwy::SetSupportedTargetsForTest; AVX2 with and without VAES where it has VAES): BM_FrameBits' mix on one
// thread, one pass per target per iteration, alternated; counters: each target's fastest pass in Gbit/s (frames
// per second), e.g. AVX3 for AVX-512 machines without VAES (Skylake-SP, Cascade Lake). Each pass's words are
// checked against the dispatcher's choice (the bits are the same on every target; a difference skips the
// benchmark with an error). SSSE3 (no AES instructions) and the scalar target are left out.
void BM_FrameBitsByTarget(benchmark::State& state) {
  FrameBitsMix m;
  const auto pass = [&m] {  // one thread
    for (size_t b = 0; b < m.pixels; b += m.block) m.sample(b, m.block, 0);
  };
  pass();
  const uint64_t reference = m.words_hash();
  std::vector<InstructionSet> sets;
  for (InstructionSet& set : instruction_sets())
    if (set.target != HWY_SCALAR && set.target != HWY_SSSE3) sets.push_back(std::move(set));
  std::vector<double> best(sets.size(), 1e300);
  const InstructionSet dispatched{0, sensor::avx2_vaes(), ""};
  for (auto _ : state) {
    for (size_t i = 0; i < sets.size(); ++i) {
      use(sets[i]);
      const auto t0 = std::chrono::steady_clock::now();
      pass();
      best[i] = std::min(best[i], std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      if (m.words_hash() != reference) {
        use(dispatched);
        state.SkipWithError((sets[i].name + " sampled other bits than the dispatcher's choice").c_str());
        return;
      }
    }
  }
  use(dispatched);
  for (size_t i = 0; i < sets.size(); ++i) state.counters[sets[i].name] = static_cast<double>(m.pixels) * m.N / best[i] * 1e-9;
  state.SetLabel(std::string("Gbit/s per thread; dispatched: ") + sensor::dense_bits_target());
}
BENCHMARK(BM_FrameBitsByTarget)->Iterations(20)->Unit(benchmark::kMillisecond);

// A synthetic transient: one return per pixel, a second one for 30 % of them (a semi-transparent
// layer), photons per pulse log-uniform in [1e-4, 1e-2] (the paper's flat target at 0.2-1.6 m sees
// about 1e-3), ambient 1e5 to 1e6 photons/s, or none (`dark`: the paper's dark lab, as in
// scenes/paper/multi_object.json; the same returns).
struct Scene {
  SensorStageConfig cfg;
  int width = 64, height = 64;
  TimeAxis axis;
  std::vector<float> transient, ambient;
};

Scene make_scene(bool frames, int width, int height, bool dark = false) {
  Scene s;
  s.width = width;
  s.height = height;
  s.cfg.camera.width_px = 1024;
  s.cfg.camera.height_px = 1000;
  s.cfg.sensor.preset = PixelPreset::FullChip;
  s.cfg.sensor.pixel_B.fill_factor = 0.134;
  s.cfg.sensor.pixel_B.pdp_peak = 0.267;
  s.cfg.sensor.pixel_B.dcr_median_cps = 2.0;
  s.cfg.sensor.pixel_B.crosstalk_probability = 0.0039;
  s.cfg.sensor.pixel_B.single_avalanche_per_frame = true;
  s.cfg.acquisition.gate_sweep = {0.6e-9, 0.6e-9 + 349 * 36e-12, 36e-12};  // 350 positions
  s.cfg.outputs.frames = frames;
  sensor::SensorModel model(s.cfg);
  s.axis = model.required_window(9e-12);
  const auto bins = static_cast<size_t>(s.axis.bins);
  s.transient.assign(static_cast<size_t>(width * height) * bins, 0.0f);
  s.ambient.resize(static_cast<size_t>(width * height));
  Rng rng(8, RngKind::Test, 2);
  for (size_t i = 0; i < s.ambient.size(); ++i) {
    float* g = s.transient.data() + i * bins;
    const int returns = rng.next_double() < 0.3 ? 2 : 1;
    for (int r = 0; r < returns; ++r) {
      const double t = 1.5e-9 + 10e-9 * rng.next_double();  // 0.2 to 1.7 m
      const auto b = static_cast<size_t>(s.axis.bin_of(t));
      const double photons = std::pow(10.0, -4.0 + 2.0 * rng.next_double());
      const double f = rng.next_double();  // the return straddles two bins
      g[b] += static_cast<float>(photons * f);
      g[b + 1] += static_cast<float>(photons * (1 - f));
    }
    const double ambient = std::pow(10.0, 5.0 + rng.next_double());  // drawn either way: the same returns
    s.ambient[i] = dark ? 0.0f : static_cast<float>(ambient);
  }
  return s;
}

TransientTile cut(const Scene& s, const PixelRect& r, int halo) {
  TransientTile t;
  t.rect = r;
  t.data_rect = grow_clipped(r, halo, s.width, s.height);
  t.axis = s.axis;
  const auto bins = static_cast<size_t>(s.axis.bins);
  for (int y = t.data_rect.y0; y < t.data_rect.y1(); ++y)
    for (int x = t.data_rect.x0; x < t.data_rect.x1(); ++x) {
      const auto i = static_cast<size_t>(y * s.width + x);
      t.transient.insert(t.transient.end(), s.transient.begin() + static_cast<std::ptrdiff_t>(i * bins),
                         s.transient.begin() + static_cast<std::ptrdiff_t>((i + 1) * bins));
      t.ambient_rate.push_back(s.ambient[i]);
      t.laser_total.push_back(0.0);
      t.out_of_window.push_back(0.0);
    }
  t.set_bin_ranges_from_data();  // the ranges of non-zero bins, as the renderer reports the bins it wrote
  return t;
}

// FNV-1a of every output of one more pass (counts, expected values, frames), to check that two versions give
// bit-identical results: shown modulo 10^6.
uint64_t outputs_hash(const sensor::SensorModel& model, const std::vector<TransientTile>& tiles) {
  uint64_t hash = 1469598103934665603ull;
  auto mix = [&hash](const void* data, size_t bytes) {
    const auto* b = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; ++i) hash = (hash ^ b[i]) * 1099511628211ull;
  };
  for (const TransientTile& t : tiles) {
    const SensorTile out = model.process(t);
    mix(out.counts.data(), out.counts.size() * sizeof(out.counts[0]));
    mix(out.expected.data(), out.expected.size() * sizeof(out.expected[0]));
    mix(out.frames.data(), out.frames.size() * sizeof(out.frames[0]));
  }
  return hash % 1000000;
}

// The sweeps' sub-image (the top-left corner of the full_chip sensor: pixel A in its top half, pixel B in its
// bottom half) with its model and tiles of 32 with their halo, as the program cuts them.
struct Sweep {
  Scene scene;
  std::unique_ptr<sensor::SensorModel> model;
  std::vector<TransientTile> tiles;
  Sweep(bool frames, bool dark, int w, int h) : scene(make_scene(frames, w, h, dark)) {
    SensorStageConfig cfg = scene.cfg;
    cfg.camera.width_px = w;  // the sub-image is the sensor here; per-pixel work is the same
    cfg.camera.height_px = h;
    model = std::make_unique<sensor::SensorModel>(cfg);
    for (const PixelRect& r : make_tiles(w, h, 32)) tiles.push_back(cut(scene, r, model->halo()));
  }
};

// The whole sensor stage (gate response of 350 positions + crosstalk + sampling, and with frames the
// frames' crosstalk, counts and packing) on a 64 x 64 sub-image, tiles of 32 with their halo processed in
// parallel, as the program streams them.
void run_sweep(benchmark::State& state, bool frames, bool dark) {
  const int w = 64, h = 64;
  const Sweep sw(frames, dark, w, h);
  std::vector<double> checksum(sw.tiles.size(), 0.0);
  for (auto _ : state) {
    // tiles in parallel, as app/pipeline.cpp runs them (process() itself nests parallel loops)
    tbb::parallel_for(size_t{0}, sw.tiles.size(), [&](size_t i) {
      const SensorTile out = sw.model->process(sw.tiles[i]);
      checksum[i] += out.counts[out.counts.size() / 2];
    });
  }
  benchmark::DoNotOptimize(checksum);
  state.counters["outputs_hash"] = static_cast<double>(outputs_hash(*sw.model, sw.tiles));
  const double pixels = static_cast<double>(w * h) * static_cast<double>(state.iterations());
  const double scale = 1024.0 * 1000.0 / pixels;  // per second of benchmark: full arrays processed = 1/scale
  if (frames) {
    const double bits = pixels * sw.model->K() * 255.0;
    state.counters["Gbit_per_s"] = benchmark::Counter(bits * 1e-9, benchmark::Counter::kIsRate);
    state.counters["x_camera"] = benchmark::Counter(bits / kCameraBitRate, benchmark::Counter::kIsRate);
    state.SetLabel(dark ? "dark" : "ambient");
  } else {
    // seconds for a full 1024 x 1000 sweep = elapsed * scale; ratio = 3.7 s / that
    state.counters["full_sweep_s"] = benchmark::Counter(1.0 / scale, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
    state.counters["x_camera"] = benchmark::Counter(kCameraSweepSeconds / scale, benchmark::Counter::kIsRate);
  }
}

// The dense sampler's random bytes alone, frames * 1 byte as ARS-7 blocks (bench/ars_ceiling.h) from streams of
// blocks blocks each, streams in parallel on every thread; seconds. The ARS-7 streams are not the sampler's
// (a fixed key, counters (i, stream, 0, 0)): the work is the same.
double random_bytes_seconds(double frames, uint64_t blocks) {
  static const sensor::ArsKeys keys = sensor::ars_round_keys({0x5eed, 1, 2, 3});
  const auto streams = static_cast<size_t>(std::ceil(frames / 16.0 / static_cast<double>(blocks)));
  std::vector<sensor::Block128> sink(streams);
  const auto t0 = std::chrono::steady_clock::now();
  tbb::parallel_for(size_t{0}, streams, [&](size_t s) {
    sink[s] = bench::ars7_xor(keys, static_cast<uint32_t>(s), 0, 0, 0, blocks);
  });
  const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  benchmark::DoNotOptimize(sink.data());
  return t;
}

// The ceiling of the frames sampler's design on this host: the dense sampler draws one random byte per frame
// (ARS-7, 16 frames per block; ties, 1 frame in 256, draw a block more), so its frames cannot come faster than
// the processor generates those bytes. ARS-7 in registers with the kernel's vector code (checked against the
// scalar ars7 first), 64 streams of 2^16 blocks per iteration on every thread, nothing stored; reported as
// frames at one byte each, against the camera. Label: the instruction set.
void BM_FrameRandomBytes(benchmark::State& state) {
  const sensor::ArsKeys keys = sensor::ars_round_keys({1, 2, 3, 4});
  for (const uint32_t first : {0u, 64u, 0xffffffc0u})
    if (bench::ars7_xor(keys, 5, 6, 7, first, 4096) != bench::ars7_xor_reference(keys, 5, 6, 7, first, 4096)) {
      state.SkipWithError("the vector ARS-7 differs from the scalar ars7");
      return;
    }
  constexpr uint64_t blocks = uint64_t{1} << 16;
  constexpr double frames = 64.0 * blocks * 16.0;
  double seconds = 0.0;
  for (auto _ : state) {
    const double t = random_bytes_seconds(frames, blocks);
    seconds += t;
    state.SetIterationTime(t);
  }
  const double bits = frames * static_cast<double>(state.iterations());
  state.counters["Gbit_per_s"] = bits * 1e-9 / seconds;
  state.counters["x_camera"] = bits / kCameraBitRate / seconds;
  state.SetLabel(sensor::dense_bits_target());
}
BENCHMARK(BM_FrameRandomBytes)->UseManualTime()->Unit(benchmark::kMillisecond);

// The frames stage alone: what one more realisation of the temporal noise costs in process() (own
// avalanches of the tile and its halo, crosstalk between the sampled frames, counts, packing, the tile's
// output buffers), i.e. everything after the rates. Each iteration times process(tile, 1 seed) and
// process(tile, 1 + R seeds) on every tile, alternately; the frames stage is the difference, R realisations
// (manual time). Also reported: the whole stage of the same run (rates + one realisation) as
// whole_Gbit_per_s, and, alternated with them, the random bytes of the R realisations' frames alone
// (random_bytes_seconds, one byte per frame): random_Gbit_per_s, and x_random = the stage's speed over theirs.
void BM_FramesStage(benchmark::State& state) {
  const bool dark = state.range(0) == 1;
  const int w = 64, h = 64;
  constexpr size_t R = 4;
  const Sweep sw(true, dark, w, h);
  std::vector<uint64_t> one = {1}, many;
  for (uint64_t i = 0; i <= R; ++i) many.push_back(1 + i);
  std::vector<double> checksum(sw.tiles.size(), 0.0);
  auto run = [&](const std::vector<uint64_t>& seeds) {
    const auto t0 = std::chrono::steady_clock::now();
    tbb::parallel_for(size_t{0}, sw.tiles.size(), [&](size_t i) {
      const std::vector<SensorTile> out = sw.model->process(sw.tiles[i], seeds);
      checksum[i] += out.back().counts[out.back().counts.size() / 2];
    });
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  const double bits = static_cast<double>(w * h) * sw.model->K() * 255.0;  // one realisation
  double whole = 0.0, stage = 0.0, random = 0.0;
  for (auto _ : state) {
    const double t1 = run(one), tm = run(many), tr = random_bytes_seconds(bits * R, 4096);
    const double ts = std::max(tm - t1, 1e-9);  // the R realisations
    whole += t1;
    stage += ts;
    random += tr;
    state.SetIterationTime(ts);
  }
  benchmark::DoNotOptimize(checksum);
  const double stage_bits = bits * R * static_cast<double>(state.iterations());
  state.counters["random_Gbit_per_s"] = stage_bits * 1e-9 / random;
  state.counters["x_random"] = random / stage;
  state.counters["Gbit_per_s"] = benchmark::Counter(stage_bits * 1e-9, benchmark::Counter::kIsRate);
  state.counters["x_camera"] = benchmark::Counter(stage_bits / kCameraBitRate, benchmark::Counter::kIsRate);
  state.counters["whole_Gbit_per_s"] = bits * static_cast<double>(state.iterations()) / whole * 1e-9;
  state.SetLabel(dark ? "dark" : "ambient");
}

// The counts sampler alone, for comparison with BM_CountsSweep: the rates of the same 64 x 64 sub-image
// (gate response, no crosstalk) computed once, then per iteration Binomial(255, p) counts of every pixel's
// 350 gates, pixels in parallel; scaled to 1024 x 1000. Argument 0: the table kernel (what process() calls
// per pixel); 1: the walk from the mode (BinomialSampler's kernel, used before round 5 and for 2D modes).
void BM_CountsSampling(benchmark::State& state) {
  const int w = 64, h = 64;
  const Scene s = make_scene(false, w, h);
  SensorStageConfig cfg = s.cfg;
  cfg.camera.width_px = w;
  cfg.camera.height_px = h;
  const sensor::SensorModel model(cfg);
  const auto K = static_cast<size_t>(model.K());
  const auto bins = static_cast<size_t>(s.axis.bins);
  std::vector<double> lam(static_cast<size_t>(w * h) * K);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const auto i = static_cast<size_t>(y * w + x);
      const std::vector<double> l = model.pixel_lambda(x, y, s.transient.data() + i * bins, s.axis, s.ambient[i], 0.0);
      std::copy(l.begin(), l.end(), lam.begin() + static_cast<std::ptrdiff_t>(i * K));
    }
  const std::shared_ptr<const sensor::BinomialTable> table = sensor::BinomialTable::get(255);
  const sensor::BinomialSampler sampler(255);
  const bool walk = state.range(0) == 1;
  const Rng base(cfg.noise_seed, RngKind::Counts, 0, 0);
  const uint32_t key[2] = {base.key().v[0], base.key().v[1]};
  std::vector<uint16_t> counts(lam.size());
  for (auto _ : state) {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, static_cast<size_t>(w * h), 32), [&](const tbb::blocked_range<size_t>& r) {
      sensor::KernelScratch scratch;
      for (size_t i = r.begin(); i < r.end(); ++i) {
        if (walk) sensor::binomial_counts(lam.data() + i * K, K, key, i, sampler, scratch);
        else sensor::binomial_counts(lam.data() + i * K, K, key, i, *table, scratch);
        for (size_t k = 0; k < K; ++k) counts[i * K + k] = static_cast<uint16_t>(scratch.x[k]);
      }
    });
    benchmark::DoNotOptimize(counts.data());
  }
  const double scale = 1024.0 * 1000.0 / (static_cast<double>(w * h) * static_cast<double>(state.iterations()));
  state.counters["full_sweep_s"] = benchmark::Counter(1.0 / scale, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["x_camera"] = benchmark::Counter(kCameraSweepSeconds / scale, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_CountsSampling)->Arg(0)->Arg(1)->UseRealTime()->Unit(benchmark::kMillisecond);

// Frames to disk: the frames of a 1024 x 32 strip (issue 9's crop: 32 tiles of 32 x 32, 350 gate positions x
// 255 frames, 367 MB; BM_CountsSweep's scene, computed once outside the timing) written as the program
// writes them (writers::NpyWriter: the file allocated and mapped, write_frames per tile from parallel tasks,
// the band's rows released, commit: unmap, fsync, rename), alternated with `dd if=/dev/zero bs=1M
// conv=fsync` of the same size into the same folder, $SPADGEN_BENCH_DIR (unset: an error and no figure, so that a run of
// every benchmark does not write gigabytes). Manual time: the writer's; counters: both bandwidths and
// writer / dd over the whole run.
void BM_FramesToDisk(benchmark::State& state) {
  const char* dir_env = std::getenv("SPADGEN_BENCH_DIR");
  if (dir_env == nullptr) {
    state.SkipWithError("set SPADGEN_BENCH_DIR to a folder on the disk to measure (writes 2 x 366 MB per iteration)");
    for (auto _ : state) {
    }
    return;
  }
  const int w = 1024, h = 32;
  const Sweep sw(true, false, w, h);
  std::vector<SensorTile> out(sw.tiles.size());
  tbb::parallel_for(size_t{0}, sw.tiles.size(), [&](size_t i) { out[i] = sw.model->process(sw.tiles[i]); });
  const int64_t K = sw.model->K(), N = sw.model->frames_per_k();
  // 0: the band assembled and written whole rows at a time (app/outputs.cpp while bands fit in memory);
  // 1: each tile written through the mapping as it completes.
  const bool in_bands = state.range(0) == 0;
  std::vector<writers::NpyWriter::FramesTile> band;
  for (const SensorTile& t : out) band.push_back({t.rect, t.frames.data()});
  const std::filesystem::path dir(dir_env);
  const std::string npy = (dir / "bench_frames_to_disk.npy").string(), raw = (dir / "bench_frames_to_disk.dd").string();
  int64_t bytes = 0;
  double t_writer = 0.0, t_dd = 0.0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    {
      writers::NpyWriter wr(npy, writers::NpyWriter::Dtype::U8, {K, N, h, w / 8}, /*mapped=*/!in_bands);
      bytes = wr.file_bytes();
      if (in_bands)
        tbb::parallel_for(tbb::blocked_range<int64_t>(0, K, 8),
                          [&](const tbb::blocked_range<int64_t>& r) { wr.write_frames_band(band, 0, 0, r.begin(), r.end()); });
      else
        tbb::parallel_for(size_t{0}, sw.tiles.size(), [&](size_t i) { wr.write_frames(out[i].rect, 0, 0, out[i].frames.data()); });
      wr.release_rows(2, 0, h);  // the strip is one band of tiles
      wr.commit();
    }
    const auto t1 = std::chrono::steady_clock::now();
    const double tw = std::chrono::duration<double>(t1 - t0).count();
    std::filesystem::remove(npy);
    const int64_t mb = (bytes + (1 << 20) - 1) >> 20;
    const std::string cmd = "dd if=/dev/zero of='" + raw + "' bs=1M count=" + std::to_string(mb) + " conv=fsync status=none";
    const auto t2 = std::chrono::steady_clock::now();
    if (std::system(cmd.c_str()) != 0) {
      state.SkipWithError("dd failed");
      break;
    }
    const double td = std::chrono::duration<double>(std::chrono::steady_clock::now() - t2).count() * static_cast<double>(bytes) /
                      static_cast<double>(mb << 20);  // dd's time for the npy's size
    std::filesystem::remove(raw);
    t_writer += tw;
    t_dd += td;
    state.SetIterationTime(tw);
  }
  const double total = static_cast<double>(bytes) * static_cast<double>(state.iterations());
  state.counters["writer_MB_per_s"] = total / t_writer * 1e-6;
  state.counters["dd_MB_per_s"] = total / t_dd * 1e-6;
  state.counters["writer_over_dd"] = t_dd / t_writer;
  state.counters["MB"] = static_cast<double>(bytes) * 1e-6;
}
BENCHMARK(BM_FramesToDisk)->Arg(0)->Arg(1)->UseManualTime()->Iterations(4)->Unit(benchmark::kMillisecond);

void BM_CountsSweep(benchmark::State& state) { run_sweep(state, false, false); }
// Argument 0: ambient light (BM_CountsSweep's scene); 1: dark (the same returns, no ambient light).
void BM_FramesSweep(benchmark::State& state) { run_sweep(state, true, state.range(0) == 1); }
BENCHMARK(BM_CountsSweep)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FramesSweep)->Arg(0)->Arg(1)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FramesStage)->Arg(0)->Arg(1)->UseManualTime()->Unit(benchmark::kMillisecond);

// --target=NAME (AVX3_DL, AVX3, AVX2+VAES, AVX2, SSE4, ...: an instruction set this processor runs, as
// BM_FrameBitsByTarget names them): every kernel runs on it for the whole run, as on a machine without the
// others. Returns false (and says why) for a name it does not run.
bool force_target(const std::string& name) {
  std::string names;
  for (const InstructionSet& set : instruction_sets()) {
    if (set.name == name) {
      use(set);
      return true;
    }
    names += (names.empty() ? "" : ", ") + set.name;
  }
  std::fprintf(stderr, "bench_sensor: --target=%s: expected one of this processor's instruction sets: %s\n", name.c_str(),
               names.c_str());
  return false;
}

}  // namespace

// As the program does (app/main.cpp): large buffers (a tile's frames are megabytes) stay in the heap, so
// that each tile does not pay page faults and the kernel's zeroing for fresh mappings.
int main(int argc, char** argv) {
  mallopt(M_MMAP_THRESHOLD, 64 << 20);
  mallopt(M_TRIM_THRESHOLD, 256 << 20);
  const std::string option = "--target=";
  for (int i = 1; i < argc; ++i) {
    if (std::string(argv[i]).rfind(option, 0) != 0) continue;
    if (!force_target(argv[i] + option.size())) return 1;
    for (int j = i; j + 1 < argc; ++j) argv[j] = argv[j + 1];
    --argc, --i;
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
