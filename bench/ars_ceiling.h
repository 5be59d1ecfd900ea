// The frames sampler's random bytes alone: ARS-7 blocks generated in registers with the vector code the dense
// kernel uses on this processor (sensor/sampling/ars-inl.h, the instruction set Highway's dispatcher chooses,
// VAES on AVX2 where the kernel uses it), nothing stored. The dense sampler draws one random byte per frame,
// so this is the ceiling of its design on the host: bench_sensor's BM_FrameRandomBytes and BM_FramesStage
// report it beside the stage.
#pragma once
#include <cstdint>

#include "core/rng.h"
#include "sensor/sampling/ars.h"

namespace spadgen::bench {

// XOR of ARS-7 blocks first .. first + count - 1 under keys, block i's counter (i, c1, c2, c3); count a
// multiple of 64.
sensor::Block128 ars7_xor(const sensor::ArsKeys& keys, uint32_t c1, uint32_t c2, uint32_t c3, uint32_t first,
                          uint64_t count);

// The same with the scalar ars7, block by block (the check that the vector code computes ARS-7).
sensor::Block128 ars7_xor_reference(const sensor::ArsKeys& keys, uint32_t c1, uint32_t c2, uint32_t c3,
                                    uint32_t first, uint64_t count);

}  // namespace spadgen::bench
