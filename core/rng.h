// Counter-based random numbers (Philox4x32-10 from Random123), keyed by what is being sampled and never
// by thread or tile: the same seed gives bit-identical outputs for any thread count or tile size.
//
// A stream is named by (seed, kind, a, b): for example (seed, CameraPath, pixel index, sample index) or
// (seed, Frames, pixel index, gate index). Inside a stream, draws are taken in order; block(i) gives
// random access to the i-th 128-bit block.
#pragma once
#include <Random123/philox.h>

#include <array>
#include <cstdint>

namespace spadgen {

enum class RngKind : uint32_t {
  CameraPath = 1,    // a = pixel index (y * image width + x), b = sample index
  SensorMaps = 2,    // a = pixel index, b = which map
  Frames = 3,        // a = pixel index, b = gate / exposure index; draws along frames
  Counts = 4,        // a = pixel index, b = gate / exposure index
  Crosstalk = 5,     // a = pixel index, b = gate / exposure index
  GroundTruth = 6,
  Dataset = 7,       // a = sample index, b = 0 for the sample's seed, else the FNV-1a 64 hash of an axis key
  PixelJitter = 8,   // a = pixel index, b = round (a target-error render's second round: 1): the jitter's shift
  Test = 1000,       // tests and benchmarks
};

// SplitMix64 finaliser: a bijective 64-bit mix used to derive keys.
inline constexpr uint64_t mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

class Rng {
 public:
  using Philox = r123::Philox4x32;

  Rng(uint64_t seed, RngKind kind, uint64_t a, uint64_t b = 0) {
    const uint64_t k = mix64(seed ^ mix64(0x9e3779b97f4a7c15ull * (static_cast<uint64_t>(kind) + 1)));
    key_ = {{static_cast<uint32_t>(k), static_cast<uint32_t>(k >> 32)}};
    ctr_ = {{0u, static_cast<uint32_t>(b), static_cast<uint32_t>(a), static_cast<uint32_t>(a >> 32)}};
    // b above 32 bits is folded into the key so that distinct (a, b) never share a counter.
    key_.v[1] ^= static_cast<uint32_t>(mix64(b >> 32));
  }

  // The i-th 128-bit block of this stream (random access; does not move the sequential position).
  std::array<uint32_t, 4> block(uint32_t i) const {
    Philox::ctr_type c = ctr_;
    c.v[0] = i;
    const Philox::ctr_type r = Philox()(c, key_);
    return {r.v[0], r.v[1], r.v[2], r.v[3]};
  }

  uint32_t next_u32() {
    if (used_ == 4) refill();
    return buf_[used_++];
  }
  uint64_t next_u64() {
    const uint64_t hi = next_u32();
    return (hi << 32) | next_u32();
  }
  // The Philox key and the counter of block 0 (block(i) sets its word 0 to i), for vectorised generators
  // that must reproduce block(i) exactly.
  const Philox::key_type& key() const { return key_; }
  const Philox::ctr_type& counter() const { return ctr_; }

  // Uniform in [0, 1) with 53 random bits.
  double next_double() { return static_cast<double>(next_u64() >> 11) * 0x1.0p-53; }
  // Uniform in [0, 1) with 24 random bits.
  float next_float() { return static_cast<float>(next_u32() >> 8) * 0x1.0p-24f; }

 private:
  void refill() {
    buf_ = block(next_block_++);
    used_ = 0;
  }
  Philox::ctr_type ctr_;
  Philox::key_type key_;
  std::array<uint32_t, 4> buf_{};
  uint32_t next_block_ = 0;
  unsigned used_ = 4;
};

}  // namespace spadgen
