// The dense Bernoulli kernel behind sample_bits, compiled for several instruction sets (Highway
// foreach_target) and chosen at run time (HWY_DYNAMIC_DISPATCH).
//
// Byte stream: the stream's ARS-7 blocks (sensor/ars.h: ars_block, key ars_key(the stream's Philox key),
// block i's counter that of Philox block i) are taken 16 at a time (a "chunk" of 256 bytes, blocks 16c to
// 16c + 15). Frame f = 256 c + r takes byte (r % 4) of word (r / 64) of block 16 c + (r % 64) / 4, i.e. the
// chunk read word-major. A tie on the top byte is refined with the first 56 bits (word 0 high, word 1 low,
// masked) of ARS block 16 * chunks + f. Block 0 of the stream and the sparse path stay Philox (Rng).
#pragma once
#include <cstddef>
#include <cstdint>

#include "core/rng.h"
#include "sensor/sampling/ars.h"
#include "sensor/sampling/sampling.h"

namespace spadgen::sensor {

// words[0 .. ceil(n / 64)): bit f set when U_f < T, U_f the frame's 64-bit uniform as described above.
void dense_bits(const Rng& stream, uint32_t n, uint64_t T, uint64_t* words);

// One group of sample_bits_batch: count <= kFrameGroup pixels, stream i = (0, c1, pixels[i]) under one key
// (the Frames streams of one gate position), probabilities pr[i], n frames, words[i * ceil(n / 64) ...].
// Every pixel's words get their all-equal fill (0, or 1 where the pixel counts misses, p > q); the dense
// pixels (min(p, q) > sparse_below) their bits as dense_bits gives them, inverted where they count misses
// (top-byte ties collected without branches, settled by one vectorised ARS-7 per 16); the sparse pixels
// whose binomial draw's first test says "no rare outcome" are final with the fill. The other sparse pixels
// are returned: slow[0 .. return value) (indices into the group) with block 0 of their streams in
// block0[4 j ...], for the caller's sparse path.
inline constexpr size_t kFrameGroup = 256;
size_t frame_bits_group(const uint32_t key[2], uint32_t c1, const uint64_t* pixels, const Prob* pr, size_t count,
                        uint32_t n, double sparse_below, uint64_t* words, uint32_t* slow, uint32_t* block0);

// dense_bits' bit of one frame, with the scalar ars_block (the reference the tests compare the kernel with).
bool dense_bit_reference(const Rng& stream, uint32_t n, uint64_t T, uint32_t frame);

// ARS-7 of count counters ctr[4 i .. 4 i + 3] into out[4 i ...], with the vector code the kernel uses (the
// tests compare it with the scalar ars7 on every target).
void ars7_blocks(const ArsKeys& keys, const uint32_t* ctr, size_t count, uint32_t* out);

// The instruction set the dispatcher chose, for the benchmark's report ("AVX2+VAES": AVX2 with the
// 256-bit AES rounds below).
const char* dense_bits_target();

// Whether the AVX2 kernel runs its AES rounds with VAES (set when the processor has it; the bits are the
// same either way). set_avx2_vaes(false) makes it split them as Highway's AVX2 target does, for the tests
// and the benchmark's comparison; set_avx2_vaes(true) is ignored without VAES. Returns the previous setting.
bool avx2_vaes();
bool set_avx2_vaes(bool on);

}  // namespace spadgen::sensor
