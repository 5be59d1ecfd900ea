// The C++ side of the Zarr writer's round trip through zarr-python (test_zarr.py):
//   zarr_tool write OUT_DIR
//       for each case below, the same array as OUT_DIR/<case>.npy (writers::NpyWriter) and
//       OUT_DIR/<case>.zarr (writers::ZarrWriter), written the way the app writes: (K, H, W) stacks tile by
//       tile (write_khw) from several threads in a shuffled order, (H, W, T) stacks with write_hwt from tiles
//       with a halo, 1-dimensional and 2-dimensional arrays in runs that cross chunk boundaries. Shapes are not
//       multiples of the chunks. Values: a formula per element (distinct, with zeros and, for floats, the
//       smallest subnormal, -0.0, infinities and NaN payloads).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "writers/writers.h"

namespace {
using spadgen::PixelRect;
using namespace spadgen::writers;

// Element i of a case, as the raw bytes of its dtype.
template <class T>
T value(int64_t i) {
  if constexpr (std::is_floating_point_v<T>) {
    switch (i % 97) {
      case 0: return T(0);
      case 1: return -T(0);
      case 2: return std::numeric_limits<T>::denorm_min();
      case 3: return std::numeric_limits<T>::infinity();
      case 4: return -std::numeric_limits<T>::infinity();
      case 5: return std::numeric_limits<T>::quiet_NaN();
      default: return i % 3 == 0 ? T(0) : T(std::sin(double(i)) * 1e-3 + double(i) * 1e-7);
    }
  } else {
    const uint64_t h = (uint64_t(i) * 2654435761u) >> 7;
    return i % 5 == 0 ? T(0) : T(h % uint64_t(std::numeric_limits<T>::max()));
  }
}

template <class T>
std::vector<T> values(int64_t n) {
  std::vector<T> v(static_cast<size_t>(n));
  for (int64_t i = 0; i < n; ++i) v[size_t(i)] = value<T>(i);
  return v;
}

// A (K, H, W) case: the tile values of the app's layout, tiles written in a shuffled order by 3 threads.
template <class T>
void khw(const std::string& dir, const std::string& name, Dtype dtype, int64_t K, int H, int W, int tile,
         std::vector<int64_t> chunks) {
  const std::vector<T> all = values<T>(K * H * W);
  NpyWriter npy(dir + "/" + name + ".npy", dtype, {K, H, W});
  ZarrWriter zarr(dir + "/" + name + ".zarr", dtype, {K, H, W}, chunks, {{"case", name}});
  std::vector<PixelRect> tiles = spadgen::make_tiles(W, H, tile);
  std::shuffle(tiles.begin(), tiles.end(), std::mt19937(7));
  const auto put = [&](size_t from) {
    for (size_t t = from; t < tiles.size(); t += 3) {
      const PixelRect& r = tiles[t];
      std::vector<T> data(size_t(K * r.count()));
      for (int64_t k = 0; k < K; ++k)
        for (int y = r.y0; y < r.y1(); ++y)
          for (int x = r.x0; x < r.x1(); ++x) data[size_t(k * r.count() + r.index(x, y))] = all[size_t((k * H + y) * W + x)];
      npy.write_khw(r, 0, 0, data.data());
      zarr.write_khw(r, 0, 0, data.data());
    }
  };
  std::vector<std::thread> threads;
  for (size_t i = 0; i < 3; ++i) threads.emplace_back(put, i);
  for (auto& t : threads) t.join();
  npy.commit();
  zarr.commit();
}

// An (H, W, T) case written from tiles carrying a halo of 1 pixel, as transients are.
void hwt(const std::string& dir, const std::string& name, int H, int W, int64_t T, int tile, std::vector<int64_t> chunks) {
  const std::vector<float> all = values<float>(H * W * T);
  NpyWriter npy(dir + "/" + name + ".npy", Dtype::F32, {H, W, T});
  ZarrWriter zarr(dir + "/" + name + ".zarr", Dtype::F32, {H, W, T}, chunks, {{"case", name}});
  for (const PixelRect& r : spadgen::make_tiles(W, H, tile)) {
    const PixelRect d = spadgen::grow_clipped(r, 1, W, H);
    std::vector<float> data(size_t(d.count() * T));
    for (int y = d.y0; y < d.y1(); ++y)
      for (int x = d.x0; x < d.x1(); ++x)
        std::copy_n(all.begin() + (int64_t(y) * W + x) * T, T, data.begin() + d.index(x, y) * T);
    npy.write_hwt(r, d, 0, 0, data.data());
    zarr.write_hwt(r, d, 0, 0, data.data());
  }
  npy.commit();
  zarr.commit();
}

// Any shape, written in runs of `run` elements.
template <class T>
void flat(const std::string& dir, const std::string& name, Dtype dtype, std::vector<int64_t> shape, std::vector<int64_t> chunks,
          int64_t run) {
  const int64_t n = std::accumulate(shape.begin(), shape.end(), int64_t(1), std::multiplies<int64_t>());
  const std::vector<T> all = values<T>(n);
  NpyWriter npy(dir + "/" + name + ".npy", dtype, shape);
  ZarrWriter zarr(dir + "/" + name + ".zarr", dtype, shape, chunks, {{"case", name}});
  for (int64_t at = 0; at < n; at += run) {
    const int64_t count = std::min(run, n - at);
    npy.write(at, all.data() + at, count);
    zarr.write(at, all.data() + at, count);
  }
  npy.commit();
  zarr.commit();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3 || std::string(argv[1]) != "write") {
    std::fprintf(stderr, "usage: %s write OUT_DIR\n", argv[0]);
    return 2;
  }
  const std::string dir = argv[2];
  try {
    khw<uint8_t>(dir, "khw_u8", Dtype::U8, 37, 45, 70, 16, {37, 32, 64});
    khw<uint16_t>(dir, "khw_u16", Dtype::U16, 2, 45, 70, 8, {2, 32, 64});
    khw<float>(dir, "khw_f32", Dtype::F32, 11, 45, 70, 24, {4, 16, 32});  // K split into chunks too
    khw<float>(dir, "khw_f32_one_chunk", Dtype::F32, 3, 5, 6, 8, {3, 32, 64});  // chunks larger than the array
    hwt(dir, "hwt_f32", 19, 21, 50, 8, {8, 64, 50});
    flat<float>(dir, "values_f32", Dtype::F32, {100003}, {4096}, 999);
    flat<int64_t>(dir, "offsets_i64", Dtype::I64, {5001}, {1024}, 77);
    flat<double>(dir, "image_f64", Dtype::F64, {300, 260}, {256, 256}, 1000);
    flat<int32_t>(dir, "ranges_i32", Dtype::I32, {33, 17, 2}, {16, 16, 2}, 5);
    flat<uint8_t>(dir, "empty_u8", Dtype::U8, {0, 7}, {4, 4}, 1);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "zarr_tool: %s\n", e.what());
    return 1;
  }
  return 0;
}
