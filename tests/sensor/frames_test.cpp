// Binary frames with crosstalk: the tile kernel (frames_tile) against its scalar reference on every compiled
// instruction set, the packing against the row packing, and the frames' statistics end to end
// (SensorModel::process): crosstalk only in frames where a neighbour avalanched, at the rate the model
// states, its hits uniformly spread over those frames, and each pixel's mean count equal to the counts
// path's expectation. Statistical checks use fixed seeds and a false-alarm rate of 1e-6 each (z bound 4.89,
// chi-square p-value).
#include <gtest/gtest.h>
#include <hwy/targets.h>

#include <bit>
#include <cmath>
#include <cstdio>

#include "core/error.h"
#include "core/rng.h"
#include "sensor/sampling/frames_tile.h"
#include "sensor/sampling/sampling.h"
#include "sensor/sensor.h"
#include "sensor/streams.h"
#include "test_util.h"

namespace spadgen::sensor {
namespace {

using testing::binomial_pmf;
using testing::chi_square_p;
using testing::Image;
using testing::kZ;
constexpr double kAlpha = 1e-6;

uint32_t popcount_words(const uint64_t* w, size_t nw) {
  uint32_t c = 0;
  for (size_t i = 0; i < nw; ++i) c += static_cast<uint32_t>(std::popcount(w[i]));
  return c;
}

// An image of W x H pixels in two array sections (rows [0, split): law A, the rest: law B), random per-pixel
// probabilities (none, faint, bright, saturated, and for pixel A rates high enough for per-candidate draws)
// and own avalanche frames drawn from them.
struct Scene {
  int W = 0, H = 0, split = 0;
  uint32_t N = 0;
  size_t nw = 0;
  CrosstalkLaw law[2];
  std::vector<Prob> prob;
  std::vector<uint64_t> bits;  // [(y * W + x) * nw + q]
  const CrosstalkLaw& row_law(int y) const { return law[y < split ? 0 : 1]; }
  int section(int y) const { return y < split ? 0 : 1; }
};

Scene make_scene(int W, int H, int split, uint32_t N, const CrosstalkLaw& a, const CrosstalkLaw& b, uint64_t seed) {
  Scene s;
  s.W = W;
  s.H = H;
  s.split = split;
  s.N = N;
  s.nw = (N + 63) / 64;
  s.law[0] = a;
  s.law[1] = b;
  Rng rng(seed, RngKind::Test, 7);
  s.prob.resize(static_cast<size_t>(W * H));
  s.bits.assign(static_cast<size_t>(W * H) * s.nw, 0);
  for (size_t i = 0; i < s.prob.size(); ++i) {
    const double u = rng.next_double();
    double lam = 0.0;
    if (u < 0.15) lam = 0.0;
    else if (u < 0.35) lam = std::pow(10.0, -6.0 + 4.0 * rng.next_double());
    else if (u < 0.85) lam = 0.02 + 3.0 * rng.next_double();
    else if (u < 0.95) lam = 5.0 + 30.0 * rng.next_double();
    else lam = u < 0.98 ? 300.0 + 500.0 * rng.next_double() : INFINITY;
    s.prob[i] = prob_from_lambda(lam);
    for (uint32_t f = 0; f < N; ++f)
      if (rng.next_double() < s.prob[i].p) s.bits[i * s.nw + f / 64] |= uint64_t{1} << (f % 64);
  }
  return s;
}

// The kernel's view of tile `rect` (as SensorModel::process builds it) and the region's bits and probabilities.
struct TileInput {
  FramesTileShape shape;
  std::vector<Prob> prob;
  std::vector<uint64_t> own;
};

TileInput tile_input(const Scene& s, const PixelRect& rect) {
  const PixelRect region = grow_clipped(rect, 1, s.W, s.H);
  TileInput t;
  FramesTileShape& sh = t.shape;
  sh.width = rect.width;
  sh.height = rect.height;
  sh.region_width = region.width;
  sh.region_height = region.height;
  sh.tile_x = rect.x0 - region.x0;
  sh.tile_y = rect.y0 - region.y0;
  sh.frames = s.N;
  for (int y = region.y0; y < region.y1(); ++y) {
    sh.region_row_law.push_back(s.row_law(y));
    for (int x = region.x0; x < region.x1(); ++x) {
      const size_t i = static_cast<size_t>(y * s.W + x);
      t.prob.push_back(s.prob[i]);
      t.own.insert(t.own.end(), s.bits.begin() + static_cast<std::ptrdiff_t>(i * s.nw),
                   s.bits.begin() + static_cast<std::ptrdiff_t>((i + 1) * s.nw));
    }
  }
  t.own.resize(t.own.size() + s.nw, 0);  // the zero words
  for (int y = rect.y0; y < rect.y1(); ++y) {
    unsigned dirs = 0;
    if (s.row_law(y).xt > 0.0) {
      dirs = 3;
      if (y > 0 && s.section(y - 1) == s.section(y)) dirs |= 4;
      if (y + 1 < s.H && s.section(y + 1) == s.section(y)) dirs |= 8;
    }
    sh.row_dirs.push_back(static_cast<uint8_t>(dirs));
    for (int x = rect.x0; x < rect.x1(); ++x) {
      sh.pixel_lo.push_back(static_cast<uint32_t>(y * s.W + x));
      sh.pixel_hi.push_back(0);
    }
  }
  sh.left_edge = rect.x0 == 0;
  sh.right_edge = rect.x1() == s.W;
  sh.finish();
  return t;
}

// What frames_tile must give for tile `rect`: crosstalk_reference per pixel, popcounts, pack_frames_row.
void reference_tile(const Scene& s, const PixelRect& rect, uint64_t seed, uint32_t k, std::vector<uint64_t>& bits,
                    std::vector<uint16_t>& counts, std::vector<uint8_t>& frames) {
  const size_t nw = s.nw, bpr = static_cast<size_t>((rect.width + 7) / 8);
  bits.assign(static_cast<size_t>(rect.count()) * nw, 0);
  counts.assign(static_cast<size_t>(rect.count()), 0);
  frames.assign(static_cast<size_t>(s.N) * static_cast<size_t>(rect.height) * bpr, 0xAB);
  constexpr int dx[4] = {-1, 1, 0, 0}, dy[4] = {0, 0, -1, 1};
  for (int y = rect.y0; y < rect.y1(); ++y)
    for (int x = rect.x0; x < rect.x1(); ++x) {
      const size_t i = static_cast<size_t>(y * s.W + x), o = static_cast<size_t>(rect.index(x, y));
      CrosstalkNeighbour nb[4];
      for (int d = 0; d < 4; ++d) {
        const int nx = x + dx[d], ny = y + dy[d];
        if (!(s.row_law(y).xt > 0.0) || nx < 0 || ny < 0 || nx >= s.W || ny >= s.H || s.section(ny) != s.section(y)) continue;
        const size_t j = static_cast<size_t>(ny * s.W + nx);
        nb[d] = {s.bits.data() + j * nw, s.prob[j]};
      }
      std::vector<uint64_t> extra(nw, 0);
      const uint32_t added = crosstalk_reference(streams::crosstalk(seed, i, k), s.N, s.bits.data() + i * nw, nb,
                                                 s.row_law(y), extra.data());
      for (size_t q = 0; q < nw; ++q) bits[o * nw + q] = s.bits[i * nw + q] | extra[q];
      counts[o] = static_cast<uint16_t>(popcount_words(bits.data() + o * nw, nw));
      EXPECT_EQ(counts[o], popcount_words(s.bits.data() + i * nw, nw) + added);
    }
  for (int r = 0; r < rect.height; ++r)
    pack_frames_row(bits.data() + static_cast<size_t>(r * rect.width) * nw, rect.width, s.N, nw,
                    frames.data() + static_cast<size_t>(r) * bpr, static_cast<size_t>(rect.height) * bpr);
}

// frames_tile equals the reference (per-pixel draws, popcounts, row packing) on tiles at the image's corners,
// edges and inside, across a section boundary, for several frame counts, on every compiled target.
TEST(Frames, TileKernelEqualsReference) {
  // the paper's crosstalk probabilities, and large ones (more draws with several hits)
  const CrosstalkLaw laws[2][2] = {{{0.0017, false}, {0.0039, true}}, {{0.01, false}, {0.03, true}}};
  int targets = 0;
  size_t hit_pixels = 0, per_candidate = 0, vector_hits = 0, one_by_one = 0;
  for (const int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    ++targets;
    for (const uint32_t N : {255u, 64u, 70u, 300u, 1000u}) {
      for (const auto& law : laws) {
        const Scene s = make_scene(37, 21, 9, N, law[0], law[1], 100 + N);
        const std::vector<PixelRect> rects = {{0, 0, 16, 8}, {16, 5, 21, 11}, {8, 8, 13, 13}, {0, 0, 37, 21},
                                              {36, 20, 1, 1}, {3, 9, 1, 7}, {5, 2, 32, 10}};
        for (const PixelRect& rect : rects)
          for (const uint32_t k : {0u, 7u}) {
            const uint64_t seed = 5 + k;
            TileInput in = tile_input(s, rect);
            const size_t nw = s.nw, bpr = static_cast<size_t>((rect.width + 7) / 8);
            std::vector<uint16_t> counts(static_cast<size_t>(rect.count()), 0xFFFF);
            std::vector<uint8_t> frames(static_cast<size_t>(N) * static_cast<size_t>(rect.height) * bpr, 0xCD);
            FramesTileScratch scratch;
            const Rng base = streams::crosstalk(seed, 0, 0);
            const uint32_t key[2] = {base.key().v[0], base.key().v[1]};
            frames_tile(in.shape, key, k, in.prob.data(), in.own.data(), counts.data(), frames.data(), scratch);
            vector_hits += scratch.nhits;
            one_by_one += scratch.nfallback;
            std::vector<uint64_t> want_bits;
            std::vector<uint16_t> want_counts;
            std::vector<uint8_t> want_frames;
            reference_tile(s, rect, seed, k, want_bits, want_counts, want_frames);
            const std::string where = std::string(hwy::TargetName(target)) + " N=" + std::to_string(N) + " xt=" +
                                      std::to_string(law[1].xt) + " tile " +
                                      std::to_string(rect.x0) + "," + std::to_string(rect.y0) + " " +
                                      std::to_string(rect.width) + "x" + std::to_string(rect.height) + " k=" + std::to_string(k);
            ASSERT_EQ(counts, want_counts) << where;
            ASSERT_EQ(frames, want_frames) << where;
            const PixelRect region = grow_clipped(rect, 1, s.W, s.H);
            for (int y = rect.y0; y < rect.y1(); ++y)
              for (int x = rect.x0; x < rect.x1(); ++x) {
                const size_t ri = static_cast<size_t>(region.index(x, y)), o = static_cast<size_t>(rect.index(x, y));
                for (size_t q = 0; q < nw; ++q) ASSERT_EQ(in.own[ri * nw + q], want_bits[o * nw + q]) << where;
                const size_t i = static_cast<size_t>(y * s.W + x);
                hit_pixels += want_counts[o] != popcount_words(s.bits.data() + i * nw, nw);
                per_candidate += s.prob[i].p > 0.999 && y < s.split;
              }
          }
      }
    }
  }
  hwy::SetSupportedTargetsForTest(0);
  std::printf("frames_tile checked on %d targets; %zu pixel-tiles received crosstalk; %zu hits decided in vectors, "
              "%zu draws one by one\n", targets, hit_pixels, vector_hits, one_by_one);
  EXPECT_GE(targets, 1);
  EXPECT_GT(hit_pixels, 1000u);
  EXPECT_GT(per_candidate, 10u);  // saturated pixel-A neighbours: the per-candidate draws are exercised
  EXPECT_GT(vector_hits, 1000u);  // both ways of deciding are exercised
  EXPECT_GT(one_by_one, 1000u);
}

// pack_frames_tile equals pack_frames_row row by row, for widths that are and are not multiples of 8 and
// frame counts around word boundaries, on every compiled target.
TEST(Frames, TilePackingEqualsRowPacking) {
  Rng rng(3, RngKind::Test, 0);
  for (const int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    for (const uint32_t n : {1u, 8u, 63u, 64u, 65u, 255u, 300u})
      for (const int width : {1, 7, 8, 9, 16, 31, 32, 40, 64, 70})
        for (const int height : {1, 2, 3, 5, 32}) {
          const size_t nw = (n + 63) / 64, bpr = static_cast<size_t>((width + 7) / 8);
          std::vector<uint64_t> masks(static_cast<size_t>(width * height) * nw);
          for (uint64_t& m : masks) m = rng.next_u64();
          std::vector<const uint64_t*> rows;
          for (int y = 0; y < height; ++y) rows.push_back(masks.data() + static_cast<size_t>(y * width) * nw);
          std::vector<uint8_t> got(n * static_cast<size_t>(height) * bpr, 0x5A), want(got.size(), 0xA5);
          pack_frames_tile(rows.data(), width, height, n, nw, got.data());
          for (int y = 0; y < height; ++y)
            pack_frames_row(rows[static_cast<size_t>(y)], width, n, nw, want.data() + static_cast<size_t>(y) * bpr,
                            static_cast<size_t>(height) * bpr);
          ASSERT_EQ(got, want) << hwy::TargetName(target) << " n=" << n << " " << width << "x" << height;
        }
  }
  hwy::SetSupportedTargetsForTest(0);
}

// The 2D single-exposure sensor of `type` (0: pixel A, 1: pixel B, crosstalk xt), no dark counts or other
// noise, N frames, frames on.
SensorStageConfig lattice_config(int type, double xt, int w, int h, int frames) {
  SensorStageConfig c = testing::sweep_config(w, h);
  c.sensor.dark_counts = false;
  c.sensor.pdp_nonuniformity = false;
  c.sensor.skew = false;
  c.sensor.crosstalk = true;
  c.sensor.preset = type == 0 ? PixelPreset::PixelA : PixelPreset::PixelB;
  (type == 0 ? c.sensor.pixel_A : c.sensor.pixel_B).crosstalk_probability = xt;
  c.acquisition.mode = AcquisitionMode::Intensity;
  c.acquisition.intensity.exposure = Exposure::Single;
  c.acquisition.frames = frames;
  c.outputs.frames = true;
  return c;
}

bool frame_bit(const SensorTile& t, int f, int x, int y) {
  const size_t bpr = static_cast<size_t>((t.rect.width + 7) / 8);
  return (t.frames[(static_cast<size_t>(f) * static_cast<size_t>(t.rect.height) + static_cast<size_t>(y)) * bpr +
                   static_cast<size_t>(x / 8)] >> (x % 8)) & 1u;
}

// Bright pixels on a lattice of spacing 4 in a dark image (no dark counts): each of their 4 neighbours sees
// exactly one bright pixel, and the bright pixels receive nothing (their neighbours never avalanche). So
// every frame of a neighbour is crosstalk, and:
//  - it lies in a frame where its bright pixel avalanched (checked exactly, every frame);
//  - the hits of a neighbour over its bright pixel's m avalanche frames are Binomial(m, r), r = xt (pixel B)
//    or (1 - exp(-xt lambda)) / p (pixel A): the total against its mean (z-test) and the distribution of
//    the hits per neighbour and realisation (chi-square against the pooled binomial pmfs);
//  - the hits are spread over the avalanche frames uniformly: hits per eighth of the frames against r times
//    the avalanche frames there (chi-square).
// For both pixel types at the paper's crosstalk and at 0.05 (more frames with two hits), and for pixel A
// at lambda = 500 (r = 0.57: the draws per avalanche frame). N = 255 frames, 12 noise realisations.
TEST(Frames, CrosstalkFiresInNeighbourAvalanchesAtItsRate) {
  struct Case {
    int type;
    double xt, lambda;
  };
  const Case cases[] = {{0, 0.0017, 1.5}, {1, 0.0039, 1.5}, {0, 0.05, 1.0}, {1, 0.05, 1.0}, {0, 0.0017, 500.0}};
  const int W = 64, H = 64, N = 255;
  std::vector<uint64_t> seeds;
  for (uint64_t s = 0; s < 12; ++s) seeds.push_back(100 + s);
  for (const Case& cs : cases) {
    SensorModel model(lattice_config(cs.type, cs.xt, W, H, N));
    ASSERT_EQ(model.halo(), 1);
    const SensorStageConfig c = lattice_config(cs.type, cs.xt, W, H, N);
    Image img(W, H, TimeAxis{});
    const double rate = cs.lambda / (model.pdp_ambient(cs.type) * c.acquisition.intensity.exposure_s);
    for (int y = 1; y < H; y += 4)
      for (int x = 1; x < W; x += 4) img.ambient[static_cast<size_t>(y * W + x)] = static_cast<float>(rate);
    const std::vector<SensorTile> outs = model.process(img.tile({0, 0, W, H}, 1), seeds);
    const double p = -std::expm1(-cs.lambda);
    const double r = cs.type == 1 ? cs.xt : -std::expm1(-cs.xt * cs.lambda) / p;
    constexpr int kBins = 8;
    double trials = 0.0, hits = 0.0, outside = 0.0;
    std::vector<double> per_bin_trials(kBins, 0.0), per_bin_hits(kBins, 0.0);
    std::vector<double> hist(N + 1, 0.0), expect(N + 1, 0.0);
    double pairs = 0.0;
    constexpr int dx[4] = {-1, 1, 0, 0}, dy[4] = {0, 0, -1, 1};
    for (const SensorTile& t : outs)
      for (int by = 1; by < H; by += 4)
        for (int bx = 1; bx < W; bx += 4) {
          std::vector<int> fired;
          for (int f = 0; f < N; ++f)
            if (frame_bit(t, f, bx, by)) fired.push_back(f);
          for (int d = 0; d < 4; ++d) {
            const int x = bx + dx[d], y = by + dy[d];
            int h = 0;
            for (int f = 0; f < N; ++f) {
              if (!frame_bit(t, f, x, y)) continue;
              if (!frame_bit(t, f, bx, by)) ++outside;
              ++h;
              ++per_bin_hits[static_cast<size_t>(f * kBins / N)];
            }
            for (int f : fired) per_bin_trials[static_cast<size_t>(f * kBins / N)] += 1.0;
            trials += static_cast<double>(fired.size());
            hits += h;
            hist[static_cast<size_t>(h)] += 1.0;
            const std::vector<double> pmf = binomial_pmf(static_cast<int>(fired.size()), r);
            for (size_t k = 0; k < pmf.size(); ++k) expect[k] += pmf[k];
            pairs += 1.0;
          }
        }
    const std::string what = std::string(cs.type == 0 ? "pixel A" : "pixel B") + " xt " + std::to_string(cs.xt) +
                             " lambda " + std::to_string(cs.lambda);
    EXPECT_EQ(outside, 0.0) << what;  // crosstalk only in frames where the neighbour avalanched
    const double mean = trials * r, sd = std::sqrt(trials * r * (1.0 - r));
    EXPECT_LT(std::abs(hits - mean), kZ * sd) << what << ": " << hits << " hits, expected " << mean;
    for (double& e : expect) e /= pairs;
    const double p_count = chi_square_p(hist, expect, pairs);
    EXPECT_GT(p_count, kAlpha) << what << ": hits per neighbour and realisation";
    std::vector<double> bin_prob(kBins);
    double bin_total = 0.0;
    for (size_t b = 0; b < kBins; ++b) bin_total += per_bin_trials[b];
    for (size_t b = 0; b < kBins; ++b) bin_prob[b] = per_bin_trials[b] / bin_total;
    const double p_pos = chi_square_p(per_bin_hits, bin_prob, hits);
    EXPECT_GT(p_pos, kAlpha) << what << ": hits over the frames";
    std::printf("%s: %.0f hits / %.0f avalanche frames (r = %.5f, expected %.0f), chi-square p %.3g (counts), %.3g (frames)\n",
                what.c_str(), hits, trials, r, mean, p_count, p_pos);
  }
}

// Pixel B between two bright neighbours (pairs of bright pixels two apart): a frame where both avalanched
// fires it with 1 - (1 - xt)^2, a frame where one did with xt, else never (z-tests, exact zero).
TEST(Frames, CrosstalkFromTwoNeighbours) {
  const int W = 64, H = 16, N = 255;
  const double xt = 0.05, lambda = 1.0;
  const SensorStageConfig c = lattice_config(1, xt, W, H, N);
  SensorModel model(c);
  Image img(W, H, TimeAxis{});
  const double rate = lambda / (model.pdp_ambient(1) * c.acquisition.intensity.exposure_s);
  for (int y = 1; y < H; y += 3)
    for (int x = 1; x + 2 < W; x += 5) {  // bright at x and x + 2, the receiver at x + 1
      img.ambient[static_cast<size_t>(y * W + x)] = static_cast<float>(rate);
      img.ambient[static_cast<size_t>(y * W + x + 2)] = static_cast<float>(rate);
    }
  std::vector<uint64_t> seeds;
  for (uint64_t s = 0; s < 10; ++s) seeds.push_back(7 + s);
  const std::vector<SensorTile> outs = model.process(img.tile({0, 0, W, H}, 1), seeds);
  double both = 0, both_hits = 0, one = 0, one_hits = 0, none_hits = 0;
  for (const SensorTile& t : outs)
    for (int y = 1; y < H; y += 3)
      for (int x = 1; x + 2 < W; x += 5)
        for (int f = 0; f < N; ++f) {
          const int fired = frame_bit(t, f, x, y) + frame_bit(t, f, x + 2, y);
          const bool hit = frame_bit(t, f, x + 1, y);
          if (fired == 2) {
            ++both;
            both_hits += hit;
          } else if (fired == 1) {
            ++one;
            one_hits += hit;
          } else {
            none_hits += hit;
          }
        }
  const double r2 = 1.0 - (1.0 - xt) * (1.0 - xt);
  EXPECT_LT(std::abs(both_hits - both * r2), kZ * std::sqrt(both * r2 * (1 - r2))) << both_hits << " of " << both;
  EXPECT_LT(std::abs(one_hits - one * xt), kZ * std::sqrt(one * xt * (1 - xt))) << one_hits << " of " << one;
  EXPECT_EQ(none_hits, 0.0);
}

// The frames' per-frame marginal with crosstalk is the counts path's: in a gate sweep of random transients
// (full chip: pixel A and B halves, crosstalk 0.02), every pixel's summed counts over the gate positions
// against the sum of its expected counts N p (the rate with crosstalk, as the counts path computes it; a
// z-test per pixel, frames independent across gate positions), and the expectations are the counts path's.
TEST(Frames, MarginalIsTheCountsPathsExpectation) {
  const int W = 40, H = 24;
  SensorStageConfig c = testing::sweep_config(W, H);
  c.sensor.preset = PixelPreset::FullChip;
  c.sensor.pixel_A.crosstalk_probability = 0.02;
  c.sensor.pixel_B.crosstalk_probability = 0.02;
  c.acquisition.gate_sweep = {0.6e-9, 9e-9, 36e-12};
  c.outputs.frames = true;
  SensorModel model(c);
  const TimeAxis ax = model.required_window(9e-12);
  Image img(W, H, ax);
  Rng rng(31, RngKind::Test, 0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      float* g = img.pixel(x, y);
      const auto b = static_cast<int64_t>(rng.next_double() * static_cast<double>(ax.bins - 20));
      g[b] = 0.02f * rng.next_float();
      img.ambient[static_cast<size_t>(y * W + x)] = 2e5f * rng.next_float();
    }
  const SensorTile fr = model.process(img.tile({0, 0, W, H}, 1));
  c.outputs.frames = false;
  const SensorTile co = SensorModel(c).process(img.tile({0, 0, W, H}, 1));
  ASSERT_EQ(fr.expected, co.expected);
  const auto K = static_cast<size_t>(model.K());
  const double N = model.frames_per_k();
  int tested = 0;
  for (size_t i = 0; i < static_cast<size_t>(W * H); ++i) {
    double sum = 0.0, mean = 0.0, var = 0.0;
    for (size_t k = 0; k < K; ++k) {
      sum += fr.counts[k * W * H + i];
      const double e = fr.expected[k * W * H + i], p = e / N;
      mean += e;
      var += N * p * (1.0 - p);
    }
    if (var > 0.0) {
      EXPECT_LT(std::abs(sum - mean), kZ * std::sqrt(var)) << "pixel " << i;
      ++tested;
    }
  }
  EXPECT_EQ(tested, W * H);
}

}  // namespace
}  // namespace spadgen::sensor

namespace spadgen::sensor {
namespace {

// A signal stops the sensor inside a tile (per row of gate responses, per row of counts, per gate position of
// frames), not only between tiles: with the interrupt flag raised, process() throws before finishing.
TEST(SensorInterrupt, ARaisedFlagStopsProcessInsideTheTile) {
  const int W = 16, H = 8;
  for (const bool with_frames : {false, true}) {
    SensorStageConfig c = testing::sweep_config(W, H);
    c.acquisition.gate_sweep = {0.6e-9, 4e-9, 36e-12};
    c.outputs.frames = with_frames;
    SensorModel model(c);
    testing::Image img(W, H, model.required_window(9e-12));
    interrupt_flag().store(true);
    EXPECT_THROW(model.process(img.tile({0, 0, W, H}, 1)), Interrupted) << (with_frames ? "frames" : "counts");
    interrupt_flag().store(false);
    EXPECT_NO_THROW(model.process(img.tile({0, 0, W, H}, 1)));
  }
}

}  // namespace
}  // namespace spadgen::sensor
