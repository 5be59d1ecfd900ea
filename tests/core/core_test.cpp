// Shared value types: the time axis edge rule, tiling, units, and the counter-based RNG.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>
#include <set>
#include <thread>

#include "core/buffer_cache.h"
#include "core/error.h"
#include "core/rng.h"
#include "core/stage_clock.h"
#include "core/tile.h"
#include "core/time_axis.h"
#include "core/units.h"

namespace spadgen {
namespace {

TEST(TimeAxis, ATimeOnABinEdgeBelongsToTheLaterBin) {
  TimeAxis a{1e-9, 9e-12, 1000, 25e-9};
  for (int64_t i = 0; i < a.bins; ++i) {
    EXPECT_EQ(a.bin_of(a.bin_start_s(i)), i) << "edge of bin " << i;
    EXPECT_EQ(a.bin_of(a.bin_centre_s(i)), i);
    EXPECT_EQ(a.bin_of(std::nextafter(a.bin_start_s(i), -1.0)), i - 1) << "just before bin " << i;
  }
  EXPECT_EQ(a.bin_of(a.end_s()), -1);  // the window is half-open
  EXPECT_EQ(a.bin_of(std::nextafter(a.end_s(), 0.0)), a.bins - 1);
  EXPECT_EQ(a.bin_of(std::nan("")), -1);
  EXPECT_EQ(TimeAxis{}.bin_of(0.0), -1);  // no bins: nothing is binned
}

TEST(Tiles, CoverTheImageOnceInRowMajorOrder) {
  const std::vector<PixelRect> tiles = make_tiles(100, 37, 16);
  std::vector<int> covered(100 * 37, 0);
  for (const PixelRect& t : tiles) {
    EXPECT_EQ(t.x0 % 8, 0);
    for (int y = t.y0; y < t.y1(); ++y)
      for (int x = t.x0; x < t.x1(); ++x) ++covered[size_t(y * 100 + x)];
  }
  for (int c : covered) ASSERT_EQ(c, 1);
  EXPECT_EQ(tiles.size(), 7u * 3u);
  EXPECT_EQ(tiles[1].x0, 16);
  EXPECT_THROW(make_tiles(10, 10, 12), Error);
  EXPECT_EQ(grow_clipped({0, 0, 8, 8}, 1, 10, 10), (PixelRect{0, 0, 9, 9}));
  EXPECT_EQ(grow_clipped({8, 8, 2, 2}, 1, 10, 10), (PixelRect{7, 7, 3, 3}));
}

// The kB of transparent huge pages (AnonHugePages) of the mapping that holds address p, from
// /proc/self/smaps; -1 when it cannot be read.
[[maybe_unused]] long huge_kb_of(const void* p) {
  std::ifstream smaps("/proc/self/smaps");
  if (!smaps) return -1;
  const auto a = reinterpret_cast<uintptr_t>(p);
  std::string line;
  bool inside = false;
  while (std::getline(smaps, line)) {
    uintptr_t lo = 0, hi = 0;
    char dash = 0;
    std::istringstream head(line);
    if (head >> std::hex >> lo >> dash >> hi && dash == '-') {
      inside = lo <= a && a < hi;
      continue;
    }
    if (inside && line.rfind("AnonHugePages:", 0) == 0) return std::stol(line.substr(14));
  }
  return -1;
}

TEST(Buffers, LargeBuffersKeepTheirValuesAndSitInHugePages) {
  // Sizes about the rule's edges: below 1 MiB, 1.5 MiB (a fourth to spare: operator new), a 1024 x 500 float
  // image (1.95 MiB: mapped), a 32 x 32 tile's frames of the paper's sweep (350 x 255 x 128 bytes).
  for (const size_t bytes : {size_t{4096}, size_t{3} << 19, size_t{1024 * 500 * 4}, size_t{350 * 255 * 128}}) {
    LargeBuffer<uint32_t> b(bytes / 4);
    for (size_t i = 0; i < b.size(); ++i) EXPECT_EQ(b[i], 0u) << "value-initialised, " << bytes << " bytes";
    for (size_t i = 0; i < b.size(); ++i) b[i] = static_cast<uint32_t>(i * 2654435761u);
    b.resize(b.size() + 1, 7u);  // a reallocation moves every value
    for (size_t i = 0; i + 1 < b.size(); ++i) ASSERT_EQ(b[i], static_cast<uint32_t>(i * 2654435761u));
    EXPECT_EQ(b.back(), 7u);
  }
  FrameBytes frames(size_t{350} * 255 * 128);
  for (size_t i = 0; i < frames.size(); ++i) frames[i] = static_cast<uint8_t>(i);
#if defined(SPADGEN_HUGE_BUFFERS)
  EXPECT_EQ(reinterpret_cast<uintptr_t>(frames.data()) % kHugePageBytes, 0u);
  {  // a freed mapping serves the next buffer of its size (the next band's tiles), with its pages
    const uint8_t* first = nullptr;
    for (int i = 0; i < 2; ++i) {
      FrameBytes tile(size_t{350} * 255 * 128 - 1000);
      if (i == 0) first = tile.data();
      else EXPECT_EQ(tile.data(), first);
      tile[0] = 1;
    }
  }
  std::ifstream thp("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string mode;
  std::getline(thp, mode);
  if (mode.find("[never]") != std::string::npos || mode.empty()) GTEST_SKIP() << "transparent huge pages are off";
  // Touched whole, the buffer's mapping holds huge pages (the kernel may fall back to small ones under
  // memory fragmentation; on this project's machines it has not).
  EXPECT_GT(huge_kb_of(frames.data()), 0) << "THP mode: " << mode;
#endif
}

// The freed mappings kept for reuse are unmapped by release_cached_buffers (a dataset run calls it after each
// sample: a sample of another shape kept the last one's, 850 MB where 413 MB were planned).
TEST(Buffers, ReleasingTheCacheUnmapsTheFreedBuffers) {
#if defined(SPADGEN_HUGE_BUFFERS)
  const auto mapped = [](const void* p) {  // whether /proc/self/maps holds an address
    std::ifstream maps("/proc/self/maps");
    const auto a = reinterpret_cast<uintptr_t>(p);
    for (std::string line; std::getline(maps, line);) {
      const uintptr_t lo = std::stoull(line.substr(0, line.find('-')), nullptr, 16);
      const uintptr_t hi = std::stoull(line.substr(line.find('-') + 1, line.find(' ') - line.find('-') - 1), nullptr, 16);
      if (a >= lo && a < hi) return true;
    }
    return false;
  };
  const void* freed = nullptr;
  {
    FrameBytes b(size_t{6} << 20);
    b[0] = 1;
    freed = b.data();
  }
  EXPECT_TRUE(mapped(freed)) << "kept for the next buffer of its size";
  release_cached_buffers();
  EXPECT_FALSE(mapped(freed)) << "unmapped";
  FrameBytes again(size_t{6} << 20);  // buffers still work after a release
  again[again.size() - 1] = 2;
  EXPECT_EQ(again[0], 0);
#else
  release_cached_buffers();  // nothing is kept under AddressSanitizer (buffers come from operator new)
  GTEST_SKIP() << "large buffers come from operator new in this build";
#endif
}

TEST(Units, PhotonsPerPulseOfThePapersLaser) {
  // 2 mW at 40 MHz and 637 nm: E = hc/lambda = 3.118439e-19 J, N_p = 2e-3 / (4e7 * E) = 1.603366e8.
  EXPECT_NEAR(photons_per_pulse(2e-3, 40e6, 637e-9), 1.603366e8, 1e2);
  EXPECT_NEAR(photon_energy_J(637e-9), 3.118439e-19, 1e-25);
}

TEST(Rng, SameKeySameNumbersAndRandomAccessAgrees) {
  Rng a(42, RngKind::Test, 7, 3), b(42, RngKind::Test, 7, 3);
  std::vector<uint32_t> seq;
  for (int i = 0; i < 64; ++i) {
    const uint32_t v = a.next_u32();
    EXPECT_EQ(v, b.next_u32());
    seq.push_back(v);
  }
  for (uint32_t blk = 0; blk < 16; ++blk)
    for (int j = 0; j < 4; ++j) EXPECT_EQ(a.block(blk)[size_t(j)], seq[blk * 4 + size_t(j)]);
}

TEST(Rng, DistinctKeysGiveDistinctStreams) {
  std::set<uint64_t> firsts;
  for (uint64_t seed : {1ull, 2ull})
    for (RngKind kind : {RngKind::CameraPath, RngKind::Frames})
      for (uint64_t a : {0ull, 1ull, 1ull << 32})
        for (uint64_t b : {0ull, 1ull, 1ull << 33}) firsts.insert(Rng(seed, kind, a, b).next_u64());
  EXPECT_EQ(firsts.size(), 2u * 2u * 3u * 3u);
}

// Chi-square of 64 equal bins of next_double() over 2^20 draws; 63 degrees of freedom, critical value
// 119.0 for a false-alarm rate of 1e-5.
TEST(Rng, UniformDoublesPassChiSquare) {
  Rng r(2026, RngKind::Test, 1, 1);
  std::vector<double> bins(64, 0.0);
  const int n = 1 << 20;
  for (int i = 0; i < n; ++i) {
    const double u = r.next_double();
    ASSERT_GE(u, 0.0);
    ASSERT_LT(u, 1.0);
    bins[size_t(u * 64)] += 1;
  }
  const double e = n / 64.0;
  double chi2 = 0;
  for (double o : bins) chi2 += (o - e) * (o - e) / e;
  EXPECT_LT(chi2, 119.0);
}

// A thread's time goes to its innermost scope only: the outer scope, which only waits for the inner one
// (as a tile's stage waits while its thread runs another tile's stage), is not charged for it; a scope
// without a clock neither times nor interrupts its parent; threads add up.
TEST(StageClock, TimeGoesToTheInnermostScopeAndThreadsAddUp) {
  using namespace std::chrono_literals;
  StageClock clock;
  EXPECT_EQ(StageClock::current(), nullptr);
  {
    const StageClock::Scope outer(&clock, StageClock::kSensorRates);
    EXPECT_EQ(StageClock::current(), &clock);
    {
      const StageClock::Scope inner(&clock, StageClock::kSensorNoise);
      std::this_thread::sleep_for(150ms);  // (against outer's 20 ms: a sleep woken late on a loaded machine)
    }
    {
      const StageClock::Scope none(nullptr, StageClock::kOutputs);  // times nothing: the time stays outer's
      EXPECT_EQ(StageClock::current(), &clock);
      std::this_thread::sleep_for(20ms);
    }
  }
  EXPECT_EQ(StageClock::current(), nullptr);
  EXPECT_GE(clock.seconds(StageClock::kSensorNoise), 0.150);
  EXPECT_GE(clock.seconds(StageClock::kSensorRates), 0.020);
  EXPECT_LT(clock.seconds(StageClock::kSensorRates), clock.seconds(StageClock::kSensorNoise));
  EXPECT_EQ(clock.seconds(StageClock::kOutputs), 0.0);
  std::thread a([&] { const StageClock::Scope s(&clock, StageClock::kOutputs); std::this_thread::sleep_for(30ms); });
  std::thread b([&] { const StageClock::Scope s(&clock, StageClock::kOutputs); std::this_thread::sleep_for(30ms); });
  a.join(), b.join();
  EXPECT_GE(clock.seconds(StageClock::kOutputs), 0.060);
}

}  // namespace
}  // namespace spadgen

// An Error's message is text whatever bytes it was given: a NUL as \0 (what() would end there), a byte of no
// well-formed UTF-8 sequence as \xNN (a damaged EXR's channel name that OpenEXR echoed could not be recorded
// in a dataset's JSON index), well-formed UTF-8 of 2 to 4 bytes as it is.
TEST(ErrorTest, MessagesAreUtf8Text) {
  EXPECT_EQ(std::string(spadgen::Error(std::string("fl\0at", 5)).what()), "fl\\0at");
  EXPECT_EQ(std::string(spadgen::Error("\"count\xc4\x02\" \xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80 \xed\xa0\x80 \xc0\xaf \xe2\x82").what()),
            "\"count\\xC4\x02\" \xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80 \\xED\\xA0\\x80 \\xC0\\xAF \\xE2\\x82");
  const spadgen::KeyError k("/sensor/gate/maps_exr", "channel \"a\xff\"");
  EXPECT_EQ(k.reason, "channel \"a\\xFF\"");
  EXPECT_EQ(spadgen::invalid_utf8_at(k.what()), std::string::npos);
  EXPECT_EQ(spadgen::invalid_utf8_at("ok \xc3\xa9"), std::string::npos);
  EXPECT_EQ(spadgen::invalid_utf8_at("ok \xc3"), 3u);
}
