// ARS-7 (sensor/ars.h, sensor/ars-inl.h): the software AES round against FIPS-197, the scalar ARS-7 against
// Random123's, and the vector ARS-7 and the dense frame kernels against the scalar reference on every
// compiled instruction set (AVX3_DL, VAES, included: HWY_WANT_AVX3_DL comes with the sensor library).
#include <gtest/gtest.h>
#include <hwy/targets.h>

#include <array>
#include <cstdio>
#include <vector>

#include "core/rng.h"
#include "sensor/sampling/ars.h"
#include "sensor/sampling/frames_kernel.h"
#include "sensor/sampling/sampling.h"

namespace spadgen::sensor {
namespace {

std::array<uint8_t, 16> hex16(const char* s) {
  std::array<uint8_t, 16> b{};
  for (int i = 0; i < 16; ++i) {
    const auto nib = [](char c) { return static_cast<uint8_t>(c <= '9' ? c - '0' : c - 'a' + 10); };
    b[static_cast<size_t>(i)] = static_cast<uint8_t>(nib(s[2 * i]) << 4 | nib(s[2 * i + 1]));
  }
  return b;
}

// Restores the dispatcher's choice and the AVX2 kernels' VAES setting when a test that forces them ends,
// also when an assertion returns early.
struct RestoreTargets {
  bool vaes = avx2_vaes();
  ~RestoreTargets() {
    set_avx2_vaes(vaes);
    hwy::SetSupportedTargetsForTest(0);
  }
};

// AES-128 with the standard key expansion, built on aes_round: FIPS-197 Appendix B.
TEST(Ars, AesRoundGivesFips197AppendixB) {
  const auto pt = hex16("3243f6a8885a308d313198a2e0370734");
  const auto key = hex16("2b7e151628aed2a6abf7158809cf4f3c");
  const auto expected = hex16("3925841d02dc09fbdc118597196a0b32");
  uint8_t w[11][16];
  for (int i = 0; i < 16; ++i) w[0][i] = key[static_cast<size_t>(i)];
  uint8_t rcon = 1;
  for (int r = 1; r <= 10; ++r) {
    const uint8_t* p = w[r - 1];
    uint8_t t[4] = {ars_detail::kSBox.s[p[13]], ars_detail::kSBox.s[p[14]], ars_detail::kSBox.s[p[15]],
                    ars_detail::kSBox.s[p[12]]};  // SubWord(RotWord(last word))
    t[0] = static_cast<uint8_t>(t[0] ^ rcon);
    rcon = ars_detail::xtime(rcon);
    for (int i = 0; i < 4; ++i) w[r][i] = static_cast<uint8_t>(p[i] ^ t[i]);
    for (int i = 4; i < 16; ++i) w[r][i] = static_cast<uint8_t>(p[i] ^ w[r][i - 4]);
  }
  EXPECT_EQ(w[10][0], 0xd0);  // last round key d014f9a8 c9ee2589 e13f0cc8 b6630ca6
  EXPECT_EQ(w[10][15], 0xa6);
  uint8_t s[16];
  for (int i = 0; i < 16; ++i) s[i] = static_cast<uint8_t>(pt[static_cast<size_t>(i)] ^ w[0][i]);
  for (int r = 1; r <= 10; ++r) aes_round(s, w[r], r == 10);
  for (int i = 0; i < 16; ++i) EXPECT_EQ(s[i], expected[static_cast<size_t>(i)]) << "byte " << i;
}

// The scalar ARS-7 against r123::ARS4x32_R<7> (Random123's ars.h with AES-NI; values computed once with it).
TEST(Ars, ScalarMatchesRandom123) {
  struct Case {
    Block128 ctr, key, out;
  };
  const Case cases[] = {
      {{0, 0, 0, 0}, {0, 0, 0, 0}, {0xdacf61ff, 0xc45798f3, 0x113c7eeb, 0x101e27f3}},
      {{1, 2, 3, 4}, {5, 6, 7, 8}, {0x55f62793, 0x798d5696, 0x032e8f5b, 0x74b29c4d}},
      {{0xdeadbeef, 0x12345678, 0xffffffff, 0x80000000},
       {0xfedcba98, 0x01234567, 0x9abcdef0, 0xffffffff},
       {0x00c6642e, 0x00bc7f2c, 0xdd8633f0, 0x43ff9227}},
  };
  for (const Case& c : cases) EXPECT_EQ(ars7(c.ctr, ars_round_keys(c.key)), c.out);
}

// The vector ARS-7 equals the scalar one on random keys and counters, on every compiled target, for block
// counts that do not fill the last vector.
TEST(Ars, VectorMatchesScalarOnEveryTarget) {
  Rng rng(5, RngKind::Test, 1);
  int targets = 0;
  const RestoreTargets restore;
  const bool vaes = restore.vaes;
  for (const int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    for (const bool use_vaes : {false, true}) {  // AVX2 twice where the processor has VAES
      if (use_vaes && (!vaes || target != HWY_AVX2)) continue;
      set_avx2_vaes(use_vaes);
      ++targets;
      for (int trial = 0; trial < 20; ++trial) {
        const Block128 key = {rng.next_u32(), rng.next_u32(), rng.next_u32(), rng.next_u32()};
        const ArsKeys k = ars_round_keys(key);
        const size_t count = 1 + static_cast<size_t>(trial) * 3;
        std::vector<uint32_t> ctr(4 * count), out(4 * count + 4, 0xABABABABu);
        for (auto& c : ctr) c = rng.next_u32();
        ars7_blocks(k, ctr.data(), count, out.data());
        for (size_t i = 0; i < count; ++i) {
          const Block128 e = ars7({ctr[4 * i], ctr[4 * i + 1], ctr[4 * i + 2], ctr[4 * i + 3]}, k);
          for (size_t w = 0; w < 4; ++w)
            ASSERT_EQ(out[4 * i + w], e[w]) << hwy::TargetName(target) << (use_vaes ? "+VAES" : "") << " block " << i;
        }
        for (size_t w = 0; w < 4; ++w) ASSERT_EQ(out[4 * count + w], 0xABABABABu);
      }
    }
  }
  std::printf("vector ARS-7 checked on %d targets%s\n", targets, vaes ? " (AVX2 twice: with and without VAES)" : "");
  EXPECT_GE(targets, 1);
}

// dense_bits (one stream) equals dense_bit_reference on every compiled target, ties included.
TEST(Ars, DenseBitsEqualReferenceOnEveryTarget) {
  const RestoreTargets restore;
  for (const int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    for (const bool use_vaes : {false, true}) {  // AVX2 twice where the processor has VAES
      if (use_vaes && (!restore.vaes || target != HWY_AVX2)) continue;
      set_avx2_vaes(use_vaes);
      for (const uint32_t n : {70u, 300u, 1000u}) {
        for (const double p : {0.5, 0.0039, 0.2}) {
          const uint64_t T = probability_threshold(p);
          for (uint64_t s = 0; s < 8; ++s) {
            const Rng stream(31, RngKind::Frames, s << 31, 3);
            std::vector<uint64_t> w((n + 63) / 64);
            dense_bits(stream, n, T, w.data());
            for (uint32_t f = 0; f < n; ++f)
              ASSERT_EQ(((w[f / 64] >> (f % 64)) & 1u) != 0, dense_bit_reference(stream, n, T, f))
                  << hwy::TargetName(target) << (use_vaes ? "+VAES" : "") << " n " << n << " frame " << f;
          }
        }
      }
    }
  }
}

// The ARS key follows the stream's Philox key: it depends on the seed (and on b above 32 bits), not on the
// pixel or on b's low word, which are in the counter (i, b, pixel low, pixel high) like Philox's.
TEST(Ars, KeyDependsOnSeedCounterOnPixelAndGate) {
  const auto key = [](uint64_t seed, uint64_t a, uint64_t b) {
    const Rng r(seed, RngKind::Frames, a, b);
    const uint32_t pk[2] = {r.key().v[0], r.key().v[1]};
    return ars_key(pk);
  };
  EXPECT_EQ(key(1, 5, 7), key(1, 900, 7));
  EXPECT_EQ(key(1, 5, 7), key(1, 5, 8));
  EXPECT_NE(key(1, 5, 7), key(2, 5, 7));
  EXPECT_NE(key(1, 5, 7), key(1, 5, 7 + (uint64_t{1} << 32)));
  const Rng r(1, RngKind::Frames, 0x123456789ull, 8);
  const ArsKeys k = ars_keys_of(r);
  EXPECT_EQ(ars_block(r, k, 3), ars7({3, 8, 0x23456789u, 0x1u}, k));
}

}  // namespace
}  // namespace spadgen::sensor
