// Tile buffers that stream from the renderer through the sensor to the writers. Memory is bounded by
// tiles, never by image size times time bins. Each pixel is owned by exactly one tile, so buffers are
// filled without atomics and results do not depend on which thread ran which tile.
#pragma once
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

#include "time_axis.h"

namespace spadgen {

// Large buffers in transparent huge pages. A run's big buffers (a tile's frames, 11 MB per 32 x 32 tile of a
// sweep, kept by band; a band's (K, H, W) stacks; the EXR images' channels; the sensor's per-tile rates)
// are new memory, which the kernel maps on first touch: in 4 kB pages, one fault per page,
// about 10 us each on this machine kind (a virtual machine), a fifth of a frames run's CPU time
// (bench/README.md, "End to end"). A buffer that whole 2 MB pages hold with at most an eighth to spare
// (from 1 MiB on) gets a mapping of its own, aligned to 2 MB, advised MADV_HUGEPAGE (the THP mode of
// Debian's kernel is "madvise"; without THP the advice does nothing), never shared with the heap. A freed
// mapping is kept (up to 512 MB, the oldest unmapped first) for the next buffer of its size, e.g. the next
// band's tiles, which then pay no faults and no zeroing. Smaller buffers, and every buffer under
// AddressSanitizer, come from operator new.
inline constexpr size_t kHugePageBytes = size_t{2} << 20;
// AddressSanitizer, as GCC (__SANITIZE_ADDRESS__) and clang 14 (__has_feature only) announce it; the huge-page
// mappings where the machine has them and ASan is off.
#if defined(__SANITIZE_ADDRESS__)
#define SPADGEN_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SPADGEN_ASAN 1
#endif
#endif
#if defined(__linux__) && !defined(SPADGEN_ASAN)
#define SPADGEN_HUGE_BUFFERS 1
#endif
void* allocate_buffer(size_t bytes);  // core/tile.cpp
void deallocate_buffer(void* p, size_t bytes) noexcept;

// std::allocator with allocate_buffer's huge pages for large buffers.
template <class T>
struct BufferAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = BufferAllocator<U>;
  };
  using std::allocator<T>::allocator;
  T* allocate(size_t n) { return static_cast<T*>(allocate_buffer(n * sizeof(T))); }
  void deallocate(T* p, size_t n) noexcept { deallocate_buffer(p, n * sizeof(T)); }
};
template <class T>
using LargeBuffer = std::vector<T, BufferAllocator<T>>;

// A BufferAllocator whose resize() leaves the new elements uninitialised (default-initialised), for
// buffers whose every element is written before it is read: a tile's binary frames, which the packing
// writes whole. In a build with AddressSanitizer the new bytes are set to 0xA5 instead, so that a byte the
// packing missed shows in the tests that check frames against their reference bits and their counts
// (tests/sensor/frames_test.cpp, sensor_test.cpp).
template <class T>
struct DefaultInitAllocator : BufferAllocator<T> {
  template <class U>
  struct rebind {
    using other = DefaultInitAllocator<U>;
  };
  using BufferAllocator<T>::BufferAllocator;
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
#if defined(SPADGEN_ASAN)
    if constexpr (std::is_same_v<U, uint8_t>) {
      ::new (static_cast<void*>(p)) U(0xA5);
      return;
    }
#endif
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};
// A tile's binary frames (SensorTile::frames).
using FrameBytes = std::vector<uint8_t, DefaultInitAllocator<uint8_t>>;

// A rectangle of pixels in image coordinates (x to the right, y down, row 0 at the top of the image).
struct PixelRect {
  int x0 = 0, y0 = 0, width = 0, height = 0;
  int x1() const { return x0 + width; }
  int y1() const { return y0 + height; }
  int64_t count() const { return int64_t(width) * height; }
  bool contains(int x, int y) const { return x >= x0 && x < x1() && y >= y0 && y < y1(); }
  // Index of pixel (x, y) inside this rectangle, row-major.
  int64_t index(int x, int y) const { return int64_t(y - y0) * width + (x - x0); }
  bool operator==(const PixelRect&) const = default;
};

// The rectangle grown by `margin` pixels on every side and clipped to the image.
inline PixelRect grow_clipped(const PixelRect& r, int margin, int image_width, int image_height) {
  const int x0 = std::max(0, r.x0 - margin), y0 = std::max(0, r.y0 - margin);
  const int x1 = std::min(image_width, r.x1() + margin), y1 = std::min(image_height, r.y1() + margin);
  return {x0, y0, x1 - x0, y1 - y0};
}

// Splits a width x height image into tiles of tile_size x tile_size (the last row and column smaller),
// in row-major order. tile_size must be a positive multiple of 8 so that bit-packed frames of a tile
// start on a byte boundary.
std::vector<PixelRect> make_tiles(int width, int height, int tile_size);

// Light transport output for one tile: photons per laser pulse arriving at each pixel's SPAD (after the
// optics and fill factor, before PDP), binned in time, plus time-integrated totals.
struct TransientTile {
  PixelRect rect;       // pixels this tile owns
  PixelRect data_rect;  // pixels with data: rect grown by the sensor's halo (crosstalk), clipped to the image
  TimeAxis axis;        // axis.bins == 0: no transient was rendered (time-integrated quantities only)

  // photons per pulse in bin t of pixel (x, y): transient[data_rect.index(x, y) * axis.bins + t]
  std::vector<float> transient;
  // render.split_direct_indirect only (else empty): the part of `transient` carried by indirect paths,
  // same layout. Direct: camera -> smooth interfaces -> ONE non-delta surface vertex -> laser (the shadow
  // ray may cross transmissive surfaces in a straight line); indirect: two or more non-delta vertices.
  // The direct transient is transient - transient_indirect (docs/render.md).
  std::vector<float> transient_indirect;
  // per data pixel, photons per pulse integrated over all time (in and out of the window)
  std::vector<double> laser_total;
  // per data pixel, photons per pulse whose arrival (after folding by the laser period) fell outside the window
  std::vector<double> out_of_window;
  // per data pixel, steady ambient photon rate arriving at the SPAD, photons per second
  std::vector<float> ambient_rate;
  // Optional (the renderer fills it; empty for light read back by `spadgen sense`), per data pixel: photons
  // per pulse whose time of flight is one laser period or more (from beyond the unambiguous range, folded
  // onto the next pulse's returns), part of laser_total.
  std::vector<double> beyond_period;
  // Optional (the renderer fills them; empty for light read back by `spadgen sense`), per data pixel: the
  // Monte Carlo standard error of laser_total, photons per pulse (the paths' sample standard deviation over
  // sqrt(paths); 0 with one path, where it cannot be estimated), and the paths rendered.
  std::vector<float> laser_se;
  std::vector<int32_t> samples;
  // Optional, as laser_se: the Monte Carlo standard error of ambient_rate, photons per second.
  std::vector<float> ambient_se;
  // Optional, per data pixel: every non-zero bin of the pixel (in transient and transient_indirect) lies in
  // [bin_lo, bin_hi). The renderer fills them with the bins it wrote; empty means unknown (the sensor then
  // scans every bin). bin_lo >= bin_hi: no light in the window.
  std::vector<int32_t> bin_lo, bin_hi;

  const float* pixel_transient(int x, int y) const {
    return transient.data() + data_rect.index(x, y) * axis.bins;
  }

  // bin_lo / bin_hi from the data: the first and one past the last non-zero bin of each pixel (0, 0 for a
  // pixel without light), for tiles not made by the renderer. Reads transient only.
  void set_bin_ranges_from_data() {
    const auto T = static_cast<size_t>(axis.bins);
    const size_t n = T > 0 ? transient.size() / T : 0;
    bin_lo.assign(n, 0);
    bin_hi.assign(n, 0);
    for (size_t i = 0; i < n; ++i)
      for (size_t b = 0; b < T; ++b)
        if (transient[i * T + b] != 0.0f) {
          if (bin_hi[i] == 0) bin_lo[i] = static_cast<int32_t>(b);
          bin_hi[i] = static_cast<int32_t>(b + 1);
        }
  }
};

// Exact ground truth along each pixel's primary ray (through the pixel centre).
struct GroundTruthTile {
  PixelRect rect;
  int max_layers = 0;
  std::vector<float> range;   // m, camera centre to first hit along the ray; +inf on a miss
  std::vector<float> z;       // m, along the optical axis; +inf on a miss
  std::vector<float> normal;  // 3 per pixel, world space, facing the camera; 0 on a miss
  std::vector<int32_t> mesh_id;      // -1 on a miss
  std::vector<int32_t> material_id;  // -1 on a miss or a mesh without material
  std::vector<int32_t> layer_count;  // surfaces along the ray up to and including the first opaque one
  // Pixels whose ray met max_layers transmissive surfaces and more surfaces beyond them: their layers and
  // objects stop there (render.max_layers), before the first opaque surface.
  int64_t layers_cut = 0;
  // per pixel, max_layers entries each: [index(x, y) * max_layers + i]; +inf / 0 beyond layer_count
  std::vector<float> layer_range;
  std::vector<float> layer_transmittance;  // fraction of light reaching that surface along the ray

  // Objects (scenes::Object: a glTF node with a mesh) along the same ray, as the layers are counted.
  std::vector<int32_t> object_id;     // the first hit's object, -1 on a miss
  std::vector<int32_t> object_count;  // distinct objects up to and including the first opaque surface
  // per pixel, max_layers slots each, [index(x, y) * max_layers + j], the objects in the order the ray meets
  // them; slots from object_count on: id -1, range +inf, transmittance and laser 0
  std::vector<int32_t> object_slot_id;
  std::vector<float> object_range;          // m, range of the object's first surface along the ray
  std::vector<float> object_transmittance;  // fraction of light reaching that first surface
  // m, the optical path of the object's direct return: laser to that first surface, and it to the camera
  // centre, each a straight line with (n - 1) x its length inside each medium added; the return arrives
  // at laser.emission_delay + path / c
  std::vector<float> object_path;
  // Filled by Renderer::transient (given this tile), photons per pulse as in TransientTile::laser_total:
  // the direct light of slot j's object (its vertex meets the laser and the camera sees it through
  // transmissions only); per pixel, the direct light of objects in no slot (a neighbour seen by jittered
  // samples at a silhouette) and the light of indirect paths (a reflection before the vertex). Their sum is
  // laser_total (docs/render.md).
  std::vector<float> object_laser;
  std::vector<float> direct_other_laser;
  std::vector<float> indirect_laser;
};

// Detectability of each object of GroundTruthTile's slots under one acquisition (sensor::object_labels).
struct ObjectLabelsTile {
  PixelRect rect;
  int slots = 0;  // per pixel, [index(x, y) * slots + j], the ground truth's object slots
  std::vector<int32_t> id;         // the slot's object, -1 unused
  std::vector<float> edge_counts;  // expected-count step of the object's rising edge, counts
  std::vector<float> edge_snr;     // that step over the standard deviation of the difference of the two counts
  std::vector<uint8_t> detectable; // edge_snr >= sensor::kDetectableSnr
  // Which edge of the object's return the sweep holds (EdgeInSweep; not written: the run's warnings count them).
  std::vector<uint8_t> edge;
};
// The edge sensor::object_labels labels: none (no light of the object in the sweep), its rising edge, its
// falling edge only (the sweep begins on the return's plateau: the rise lies before the first gate position),
// or none (the plateau spans the whole sweep).
enum EdgeInSweep : uint8_t { kNoReturn = 0, kRisingEdge = 1, kFallingEdgeOnly = 2, kNoEdgeInSweep = 3 };

// What the sensor makes of a tile. K is the number of gate positions (gate sweep) or exposures (2D).
struct SensorTile {
  PixelRect rect;
  int K = 0;
  // [k * rect.count() + rect.index(x, y)]
  std::vector<float> expected;     // noise-free expected counts N * p
  // noise-free detection rate lambda: mean avalanches per binary frame, crosstalk included, so that
  // p = 1 - exp(-lambda) and expected = N p; empty unless the sensor was asked for it
  std::vector<float> rate;
  // The largest of its pixels' laser rates with the gate open (cycles per frame x PDP x laser photons per
  // pulse, and n xt more for crosstalk; avalanches per frame): what the gate's tabulation error is a fraction of, at any gate position
  // (ambient light and dark counts see the gate's integral, which that error barely moves); for its warning.
  float laser_open_rate = 0.0f;
  std::vector<uint16_t> counts;    // sampled counts
  // optional binary frames, [((k * N + n) * rect.height + row) * bytes_per_row + byte], bits packed
  // along x least significant bit first, bytes_per_row = ceil(rect.width / 8)
  int frames_per_k = 0;
  FrameBytes frames;  // written whole by the sensor (resize leaves it uninitialised: DefaultInitAllocator)
  // 2D intensity mode only, per pixel: summed counts and the linearised photon estimate
  std::vector<float> intensity_counts;
  std::vector<float> intensity_photons;
};

}  // namespace spadgen
