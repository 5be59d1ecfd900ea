// The frames of one tile at one gate position once its region's own avalanches are sampled (sample_bits_batch
// over the tile and its halo): crosstalk between the sampled frames, the counts (popcounts) and the frames
// packed as the tile's part of the (K, N, H, ceil(W / 8)) stack. Compiled for several instruction sets
// (Highway foreach_target), chosen at run time.
//
// Crosstalk follows crosstalk_reference (sampling.h) bit for bit, pixel by pixel: the kernel only decides
// faster which pixels can receive any. Per gate position: each region pixel's avalanche count n_i and the
// limit crosstalk_limit(n_i, rho_i) (vectorised); block 0 of every tile pixel's crosstalk stream (Philox on
// 16 lanes) compared with its 4 neighbours' limits; the few pixels where some draw falls below its limit get
// block 1 (vectorised, compacted) and the scalar draws of crosstalk_reference. Packing: 64 x 64 bit-matrix
// transposes, one per lane (lanes = 64-pixel groups of the tile's padded rows), so that each output row of a
// frame is stored whole.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

#include "sensor/sampling/sampling.h"

namespace spadgen::sensor {

// What stays the same for every gate position of a tile. The region is the tile grown by the halo (clipped
// to the image): region pixels are row-major, region_width per row; the tile starts at (tile_x, tile_y).
struct FramesTileShape {
  int width = 0, height = 0;                // the tile
  int region_width = 0, region_height = 0;  // the region
  int tile_x = 0, tile_y = 0;               // the tile's first pixel in the region
  uint32_t frames = 0;                      // N
  // The crosstalk law of each region row's pixels (xt = 0: its pixels receive none).
  std::vector<CrosstalkLaw> region_row_law;
  // Per tile row: which of the directions 0 left, 1 right, 2 up, 3 down have a neighbour for its pixels
  // (bit d; up and down: inside the image and in the same array section; left and right: for the row's
  // inner pixels, 0 when the row receives no crosstalk); at the tile's first / last column left / right
  // also needs !left_edge / !right_edge (the image's edge).
  std::vector<uint8_t> row_dirs;
  bool left_edge = false, right_edge = false;
  // Stream index (y * sensor width + x) of every tile pixel, row-major, split into low and high words.
  std::vector<uint32_t> pixel_lo, pixel_hi;

  // Set by finish() from the fields above: the packing's source word offset (into own, per word of a
  // pixel) of every slot of the padded rows (ceil(width / 8) * 8 slots per row, groups of 64 slots), as
  // [slot % 64][group] with the groups padded to a multiple of 8; padding slots point at the zero word.
  std::vector<int64_t> slot_word;
  size_t groups = 0, groups_padded = 0;
  // Also set by finish(): every tile pixel's region index and grid index (the tile grown by one pixel,
  // row-major), every region row's law as xt and single_avalanche (0 / 1).
  std::vector<uint32_t> tile_region, tile_grid;
  std::vector<double> row_xt;
  std::vector<uint64_t> row_single;
  void finish();
};

// Working memory of one thread, reused across gate positions and tiles.
struct FramesTileScratch {
  // per region pixel: avalanche frames (all, and per word as bytes), limit, rho; the limits on the grid
  std::vector<uint32_t> n, pop, lim_r, lim, n_row, pop_row;
  std::vector<double> rho;
  // The (pixel, direction) pairs that draw: tile index, direction, top word, stream index (low, high), region
  // row; the first block of the direction's words.
  std::vector<uint32_t> p_t, p_d, p_w, p_lo, p_hi, p_row, p_b[4];
  // Decided in vectors: one hit each (tile index, frame); the rest, one by one, hits as (tile index, word, bits).
  std::vector<uint64_t> hit_t, hit_frame, fallback;
  size_t nhits = 0, nfallback = 0;
  struct Bits {
    uint32_t t, word;
    uint64_t bits;
  };
  std::vector<Bits> fb_bits;
  std::vector<uint64_t> work;
  // Pixel B's S and P0 (crosstalk_no_hit) and crosstalk_hits_exact's thresholds of H > 0, 1, 2 for c = 0 ..
  // N, for b_xt and b_frames.
  double b_xt = -1.0;
  uint32_t b_frames = 0;
  std::vector<double> b_S, b_P0;
  std::vector<uint64_t> b_T0, b_T1, b_T2;
};

// Region bits own[region index * ceil(N / 64) ...] (the region's own avalanches at gate position k, one zero
// word after them), their probabilities prob[region index]; key: Rng(seed, Crosstalk, 0, 0).key(). Adds the
// crosstalk hits to the tile pixels' words of own, writes counts[tile index] (popcounts) and frames[(f *
// height + row) * ceil(width / 8) + byte] (bits along x, LSB first; bits past the width are 0).
void frames_tile(const FramesTileShape& shape, const uint32_t key[2], uint32_t k, const Prob* prob, uint64_t* own,
                 uint16_t* counts, uint8_t* frames, FramesTileScratch& scratch);

// The packing alone (for tests): rows[y] points at the first of the width pixels of row y (each
// words_per_pixel words, frame f = bit f % 64 of word f / 64); frames as above.
void pack_frames_tile(const uint64_t* const* rows, int width, int height, uint32_t n, size_t words_per_pixel,
                      uint8_t* frames);

}  // namespace spadgen::sensor
