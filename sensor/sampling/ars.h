// ARS-7 (Random123's r123::ARS4x32_R<7>, ars.h): a counter-based generator made of AES rounds with a
// Weyl-sequence key schedule. Scalar reference, in plain software (no AES-NI): the vector version
// (sensor/ars-inl.h, Highway's AESRound) is tested against it on every target.
//
//   v = ctr XOR key;  k = key
//   6 times: k += kweyl (two 64-bit lane additions); v = AESENC(v, k)
//   k += kweyl; v = AESENCLAST(v, k)
//
// with kweyl = (high 64 bits 0xBB67AE8584CAA73B, low 64 bits 0x9E3779B97F4A7C15). Counters, keys and
// outputs are four little-endian u32 words (word 0 = bytes 0..3 of the 128-bit value).
//
// The dense frames (sensor/frames_kernel.h) use it for their random bytes: stream Rng(seed, Frames, a, b)
// has the ARS key ars_key(its Philox key) and block i the counter (i, b, a low, a high), the counter of
// its Philox block i. The counts tables (sensor/batch_kernels.h, counts_block) take block 0 of the same
// construction for Rng(seed, Counts, pixel, k).
#pragma once
#include <array>
#include <atomic>
#include <cstdint>

#include "core/rng.h"

namespace spadgen::sensor {

inline constexpr uint64_t kArsWeylLo = 0x9E3779B97F4A7C15ull, kArsWeylHi = 0xBB67AE8584CAA73Bull;
inline constexpr int kArsRounds = 7;

using Block128 = std::array<uint32_t, 4>;

namespace ars_detail {

inline constexpr uint8_t xtime(uint8_t x) { return static_cast<uint8_t>((x << 1) ^ ((x & 0x80) ? 0x1B : 0)); }

// The AES S-box, computed (multiplicative inverse in GF(2^8), then the affine map) rather than tabulated.
struct SBox {
  uint8_t s[256];
  constexpr SBox() : s{} {
    uint8_t p = 1, q = 1;
    do {  // p runs over the powers of 3, q over those of 3^-1
      p = static_cast<uint8_t>(p ^ xtime(p));
      q = static_cast<uint8_t>(q ^ (q << 1));
      q = static_cast<uint8_t>(q ^ (q << 2));
      q = static_cast<uint8_t>(q ^ (q << 4));
      if (q & 0x80) q = static_cast<uint8_t>(q ^ 0x09);
      const auto rot = [](uint8_t x, int r) { return static_cast<uint8_t>((x << r) | (x >> (8 - r))); };
      s[p] = static_cast<uint8_t>(q ^ rot(q, 1) ^ rot(q, 2) ^ rot(q, 3) ^ rot(q, 4) ^ 0x63);
    } while (p != 1);
    s[0] = 0x63;
  }
};
inline constexpr SBox kSBox{};

}  // namespace ars_detail

// One AES encryption round as AESENC defines it on the 16 state bytes (byte i = row i % 4, column i / 4):
// ShiftRows, SubBytes, MixColumns (unless last: AESENCLAST), then XOR with the round key.
inline void aes_round(uint8_t state[16], const uint8_t round_key[16], bool last = false) {
  using ars_detail::kSBox;
  using ars_detail::xtime;
  uint8_t t[16];
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) t[r + 4 * c] = kSBox.s[state[r + 4 * ((c + r) % 4)]];
  if (!last) {
    for (int c = 0; c < 4; ++c) {
      uint8_t* col = t + 4 * c;
      const uint8_t a0 = col[0], a1 = col[1], a2 = col[2], a3 = col[3];
      const uint8_t all = static_cast<uint8_t>(a0 ^ a1 ^ a2 ^ a3);
      col[0] = static_cast<uint8_t>(a0 ^ all ^ xtime(static_cast<uint8_t>(a0 ^ a1)));
      col[1] = static_cast<uint8_t>(a1 ^ all ^ xtime(static_cast<uint8_t>(a1 ^ a2)));
      col[2] = static_cast<uint8_t>(a2 ^ all ^ xtime(static_cast<uint8_t>(a2 ^ a3)));
      col[3] = static_cast<uint8_t>(a3 ^ all ^ xtime(static_cast<uint8_t>(a3 ^ a0)));
    }
  }
  for (int i = 0; i < 16; ++i) state[i] = static_cast<uint8_t>(t[i] ^ round_key[i]);
}

// The round keys k_r = key + r kweyl (64-bit lane additions), r = 0 .. 7, as u32 words.
struct ArsKeys {
  alignas(16) uint32_t rk[kArsRounds + 1][4];
};

inline ArsKeys ars_round_keys(const Block128& key) {
  ArsKeys k{};
  uint64_t lo = key[0] | (uint64_t{key[1]} << 32), hi = key[2] | (uint64_t{key[3]} << 32);
  for (int r = 0; r <= kArsRounds; ++r) {
    k.rk[r][0] = static_cast<uint32_t>(lo);
    k.rk[r][1] = static_cast<uint32_t>(lo >> 32);
    k.rk[r][2] = static_cast<uint32_t>(hi);
    k.rk[r][3] = static_cast<uint32_t>(hi >> 32);
    lo += kArsWeylLo;
    hi += kArsWeylHi;
  }
  return k;
}

inline void words_to_bytes(const uint32_t w[4], uint8_t b[16]) {
  for (int i = 0; i < 16; ++i) b[i] = static_cast<uint8_t>(w[i / 4] >> (8 * (i % 4)));
}

// Whether the AVX2 kernels run ARS-7's rounds with VAES (256-bit AES rounds: AMD Zen 3, Intel Alder Lake
// and later), where the AVX2 target otherwise runs each block's rounds as 128-bit AESENC: on when the processor has
// VAES; frames_kernel.h's set_avx2_vaes turns it off for tests and the benchmark. The bits are the same.
inline bool cpu_has_vaes() {
#if defined(__x86_64__) || defined(__i386__)
  return __builtin_cpu_supports("vaes") != 0;
#else
  return false;
#endif
}
inline std::atomic<bool>& avx2_vaes_flag() {
  static std::atomic<bool> on{cpu_has_vaes()};
  return on;
}

// ARS-7 of one counter, in software.
inline Block128 ars7(const Block128& ctr, const ArsKeys& k) {
  uint8_t v[16], rk[16];
  words_to_bytes(ctr.data(), v);
  words_to_bytes(k.rk[0], rk);
  for (int i = 0; i < 16; ++i) v[i] = static_cast<uint8_t>(v[i] ^ rk[i]);
  for (int r = 1; r <= kArsRounds; ++r) {
    words_to_bytes(k.rk[r], rk);
    aes_round(v, rk, r == kArsRounds);
  }
  Block128 out{};
  for (int i = 0; i < 16; ++i) out[i / 4] |= uint32_t{v[i]} << (8 * (i % 4));
  return out;
}

// The ARS key of a stream, from its Philox key (k0, k1): (k0, k1, low and high half of mix64(k1:k0)).
// Deterministic in (seed, kind, b) like the Philox key; the mix64 half keeps the key's upper 64 bits as
// varied as its lower.
inline Block128 ars_key(const uint32_t philox_key[2]) {
  const uint64_t m = mix64(philox_key[0] | (uint64_t{philox_key[1]} << 32));
  return {philox_key[0], philox_key[1], static_cast<uint32_t>(m), static_cast<uint32_t>(m >> 32)};
}

inline ArsKeys ars_keys_of(const Rng& stream) {
  const uint32_t pk[2] = {stream.key().v[0], stream.key().v[1]};
  return ars_round_keys(ars_key(pk));
}

// Block i of the stream's ARS sequence: counter (i, b, a low, a high) as the stream's Philox counter.
inline Block128 ars_block(const Rng& stream, const ArsKeys& k, uint32_t i) {
  const auto& c = stream.counter();
  return ars7({i, c.v[1], c.v[2], c.v[3]}, k);
}

}  // namespace spadgen::sensor
