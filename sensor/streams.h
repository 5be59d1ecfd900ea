// Every random stream the sensor draws from, and how each is keyed: the one place that says which
// randomness drives what. Streams are counter-based (core/rng.h): named by (seed, kind, a, b), never by
// thread, tile or crop, so the same seed gives the same bits for any split of the image, and a crop of one
// pixel replays that pixel of a full run.
//
// | stream    | drives                                                        | keyed by                      |
// |-----------|---------------------------------------------------------------|-------------------------------|
// | chip_map  | the chip's fixed pattern: a pixel's gate skew, gate length,   | (seed, SensorMaps, pixel, map)|
// |           | dark count rate and PDP non-uniformity                        |                               |
// | frames    | the binary frames of a pixel at image k (gate position or     | (seed, Frames, pixel, k)      |
// |           | exposure): block 0 by Philox4x32-10, the dense bytes by ARS-7 |                               |
// |           | with key ars_key(the stream's key) (sampling/ars.h)           |                               |
// | counts    | counts drawn without frames, pixel at image k: the tables     | key of (seed, Counts); tables |
// |           | (sweeps) by ARS-7 with counter (0, k, pixel), the walk (2D)   | ARS-7 (0, k, pixel), walk     |
// |           | by Philox block 0 of (seed, Counts, pixel, k)                 | (seed, Counts, pixel, k)      |
// | crosstalk | which of a neighbour's avalanches fire the pixel, image k     | (seed, Crosstalk, pixel, k)   |
// |           | (frames): block 0 one word per direction, then direction d's  |                               |
// |           | own blocks 1 + d, 5 + d, ... (sampling.h crosstalk_reference) |                               |
//
// pixel = y * camera.width_px + x in full-sensor coordinates. chip_map takes the chip's seed
// (SensorStageConfig::chip_seed, scene-file seeds.chip), the others the temporal noise's
// (SensorStageConfig::noise_seed, seeds.noise); both default to the run's seed. The renderer's paths take
// the light-transport seed (seeds.light).
#pragma once
#include <cstdint>

#include "core/rng.h"

namespace spadgen::sensor::streams {

// The per-pixel maps of the chip's fixed pattern.
enum class Map : uint64_t { Skew = 0, Length = 1, Dcr = 2, Pdp = 3 };

inline uint64_t pixel_index(int x, int y, int width) {
  return static_cast<uint64_t>(y) * static_cast<uint64_t>(width) + static_cast<uint64_t>(x);
}
inline Rng chip_map(uint64_t seed, uint64_t pixel, Map map) {
  return Rng(seed, RngKind::SensorMaps, pixel, static_cast<uint64_t>(map));
}
inline Rng frames(uint64_t seed, uint64_t pixel, uint64_t k) { return Rng(seed, RngKind::Frames, pixel, k); }
inline Rng counts(uint64_t seed, uint64_t pixel, uint64_t k) { return Rng(seed, RngKind::Counts, pixel, k); }
inline Rng crosstalk(uint64_t seed, uint64_t pixel, uint64_t k) { return Rng(seed, RngKind::Crosstalk, pixel, k); }

}  // namespace spadgen::sensor::streams
