// The dense Bernoulli kernel behind sample_bits, compiled for several instruction sets (Highway
// foreach_target) and chosen at run time (HWY_DYNAMIC_DISPATCH).
//
// Byte stream: the stream's Philox blocks are taken 16 at a time (a "chunk" of 256 bytes, blocks 16c to
// 16c + 15). Frame f = 256 c + r takes byte (r % 4) of word (r / 64) of block 16 c + (r % 64) / 4, i.e. the
// chunk read word-major, which is the order a vectorised Philox produces. A tie on the top byte is refined
// with the first 56 bits (word 0 high, word 1 low, masked) of block 16 * chunks + f.
#pragma once
#include <cstddef>
#include <cstdint>

#include "core/rng.h"

namespace spadgen::sensor {

// words[0 .. ceil(n / 64)): bit f set when U_f < T, U_f the frame's 64-bit uniform as described above.
void dense_bits(const Rng& stream, uint32_t n, uint64_t T, uint64_t* words);

// dense_bits for many streams of one key in one call (sample_bits_batch's dense pixels of a group): for
// each slot i in slots[0 .. count), the stream with counter (0, c1, c2[i], c3[i]) and threshold T[i] writes
// words[i * ceil(n / 64) ...] (all of them), bitwise inverted when invert[i] (the pixel counts misses).
// Bit-identical to dense_bits followed by the inversion: the top-byte ties are collected without branches
// and settled by one vectorised Philox per 16 (block 16 * ceil(n / 256) + frame of the tie's stream).
void dense_bits_batch(const uint32_t key[2], uint32_t c1, const uint32_t* c2, const uint32_t* c3, const uint64_t* T,
                      const bool* invert, const uint32_t* slots, size_t count, uint32_t n, uint64_t* words);

// dense_bits' bit of one frame, with Rng::block (the reference the tests compare the kernel with).
bool dense_bit_reference(const Rng& stream, uint32_t n, uint64_t T, uint32_t frame);

// The instruction set the dispatcher chose, for the benchmark's report.
const char* dense_bits_target();

}  // namespace spadgen::sensor
