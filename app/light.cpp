#include "app/light.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "app/staging.h"
#include "core/error.h"
#include "writers/atomic_file.h"

namespace spadgen::app {
using writers::NpyReader;
using writers::NpyWriter;

const std::vector<std::string>& light_files() {
  static const std::vector<std::string> f = {"light/ranges.npy",      "light/offsets.npy",       "light/values.npy",
                                             "light/laser_total.npy", "light/out_of_window.npy", "light/ambient_rate.npy"};
  return f;
}

PixelRect light_region(const PixelRect& img, int sensor_width, int sensor_height) {
  return grow_clipped(img, 1, sensor_width, sensor_height);
}

namespace {

template <class T>
void write_npy(const std::string& path, NpyWriter::Dtype dtype, const std::vector<int64_t>& shape, const std::vector<T>& v) {
  NpyWriter w(path, dtype, shape);
  w.write(0, v.data(), int64_t(v.size()));
  w.commit();
}

}  // namespace

LightWriter::LightWriter(const PixelRect& region, const TimeAxis& axis, const Staging& staging)
    : region_(region), axis_(axis), staging_(staging), claimed_(size_t(region.count())) {
  const auto n = size_t(region.count());
  spill_at_.assign(n, 0);
  ranges_.assign(2 * n, 0);
  laser_total_.assign(n, 0.0), out_of_window_.assign(n, 0.0), ambient_.assign(n, 0.0f);
  for (auto& c : claimed_) c.store(0, std::memory_order_relaxed);
  // The transients wait in a file (tiles finish in any order; values.npy is in pixel order), unlinked at
  // once so that nothing is left behind whatever happens to the run.
  spill_path_ = staging.path(".light-spill");
  spill_fd_ = ::open(spill_path_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (spill_fd_ < 0) writers::detail::throw_errno("cannot create", spill_path_, errno);
  ::unlink(spill_path_.c_str());
}

LightWriter::~LightWriter() {
  if (spill_fd_ >= 0) ::close(spill_fd_);
}

void LightWriter::put(const TransientTile& t) {
  const PixelRect& dr = t.data_rect;
  const int x0 = std::max(dr.x0, region_.x0), x1 = std::min(dr.x1(), region_.x1());
  const int y0 = std::max(dr.y0, region_.y0), y1 = std::min(dr.y1(), region_.y1());
  const int64_t T = axis_.bins;
  const size_t nd = size_t(dr.count());
  const bool ranges = t.bin_lo.size() == nd && t.bin_hi.size() == nd;
  std::vector<float> buf;
  std::vector<std::pair<size_t, int64_t>> mine;  // region index, offset in buf
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) {
      const auto ri = size_t(region_.index(x, y));
      if (claimed_[ri].exchange(1, std::memory_order_relaxed)) continue;
      const auto di = size_t(dr.index(x, y));
      int64_t lo = 0, hi = 0;
      if (T > 0) {
        const float* g = t.transient.data() + di * size_t(T);
        if (ranges) {
          lo = std::clamp<int64_t>(t.bin_lo[di], 0, T), hi = std::clamp<int64_t>(t.bin_hi[di], lo, T);
        } else {
          lo = T, hi = 0;
          for (int64_t b = 0; b < T; ++b)
            if (g[b] != 0.0f) lo = std::min(lo, b), hi = b + 1;
          if (hi == 0) lo = 0;
        }
        mine.push_back({ri, int64_t(buf.size())});
        buf.insert(buf.end(), g + lo, g + hi);
      }
      ranges_[2 * ri] = int32_t(lo), ranges_[2 * ri + 1] = int32_t(hi);
      laser_total_[ri] = t.laser_total.size() == nd ? t.laser_total[di] : 0.0;
      out_of_window_[ri] = t.out_of_window.size() == nd ? t.out_of_window[di] : 0.0;
      ambient_[ri] = t.ambient_rate.size() == nd ? t.ambient_rate[di] : 0.0f;
    }
  if (buf.empty()) {
    for (const auto& [ri, off] : mine) spill_at_[ri] = 0;
    return;
  }
  const int64_t base = spill_elements_.fetch_add(int64_t(buf.size()));
  writers::detail::pwrite_all(spill_fd_, reinterpret_cast<const char*>(buf.data()), buf.size() * sizeof(float), uint64_t(base) * 4, spill_path_);
  for (const auto& [ri, off] : mine) spill_at_[ri] = base + off;
}

void LightWriter::write(std::vector<std::string>& files) {
  const auto n = size_t(region_.count());
  for (size_t i = 0; i < n; ++i)
    if (!claimed_[i].load()) throw Error("internal: the saved light misses a pixel of its region");
  std::vector<int64_t> offsets(n + 1, 0);
  for (size_t i = 0; i < n; ++i) offsets[i + 1] = offsets[i] + (ranges_[2 * i + 1] - ranges_[2 * i]);
  const std::vector<std::string>& f = light_files();
  const int64_t H = region_.height, W = region_.width, total = offsets[n];
  {
    NpyWriter values(staging_.path(f[2]), NpyWriter::Dtype::F32, {total});
    if (total > 0) {
      const size_t bytes = size_t(spill_elements_.load()) * sizeof(float);
      void* m = ::mmap(nullptr, bytes, PROT_READ, MAP_PRIVATE, spill_fd_, 0);
      if (m == MAP_FAILED) writers::detail::throw_errno("cannot map", spill_path_, errno);
      const auto* spill = static_cast<const float*>(m);
      // In bands of rows, each band's pages then leaving the resident set (both files stay in the page
      // cache), so the gather costs no more memory than a band.
      constexpr size_t kBand = 32;
      for (size_t y0 = 0; y0 < size_t(H); y0 += kBand) {
        const size_t y1 = std::min(size_t(H), y0 + kBand);
        tbb::parallel_for(y0, y1, [&](size_t y) {
          for (size_t i = y * size_t(W); i < (y + 1) * size_t(W); ++i)
            values.write(offsets[i], spill + spill_at_[i], offsets[i + 1] - offsets[i]);
        });
        values.release_rows(0, offsets[y0 * size_t(W)], offsets[y1 * size_t(W)]);
        ::madvise(m, bytes, MADV_DONTNEED);
      }
      ::munmap(m, bytes);
    }
    values.commit();
  }
  write_npy(staging_.path(f[0]), NpyWriter::Dtype::I32, {H, W, 2}, ranges_);
  write_npy(staging_.path(f[1]), NpyWriter::Dtype::I64, {int64_t(n) + 1}, offsets);
  write_npy(staging_.path(f[3]), NpyWriter::Dtype::F64, {H, W}, laser_total_);
  write_npy(staging_.path(f[4]), NpyWriter::Dtype::F64, {H, W}, out_of_window_);
  write_npy(staging_.path(f[5]), NpyWriter::Dtype::F32, {H, W}, ambient_);
  files.insert(files.end(), f.begin(), f.end());
}

SavedLight::SavedLight(const std::string& dir, const PixelRect& region, const TimeAxis& axis)
    : region_(region), axis_(axis), ranges_(dir + "/" + light_files()[0]), offsets_(dir + "/" + light_files()[1]),
      values_(dir + "/" + light_files()[2]), laser_total_(dir + "/" + light_files()[3]),
      out_of_window_(dir + "/" + light_files()[4]), ambient_(dir + "/" + light_files()[5]) {
  const int64_t H = region.height, W = region.width, n = H * W;
  ranges_.expect_shape({H, W, 2}, "the light's bin ranges");
  offsets_.expect_shape({n + 1}, "the light's offsets");
  laser_total_.expect_shape({H, W}, "the light's laser totals");
  out_of_window_.expect_shape({H, W}, "the light's out-of-window totals");
  ambient_.expect_shape({H, W}, "the light's ambient rates");
  // Every pixel's range must lie on the axis and match its slice of values.npy, so tile() reads nothing
  // out of bounds whatever the files hold.
  const int32_t* r = ranges_.data<int32_t>();
  const int64_t* o = offsets_.data<int64_t>();
  values_.data<float>();
  laser_total_.data<double>(), out_of_window_.data<double>(), ambient_.data<float>();
  if (o[0] != 0 || o[n] != values_.elements())
    throw Error("'" + offsets_.path() + "': the offsets do not span values.npy");
  for (int64_t i = 0; i < n; ++i)
    if (r[2 * i] < 0 || r[2 * i + 1] < r[2 * i] || r[2 * i + 1] > axis.bins || o[i + 1] - o[i] != r[2 * i + 1] - r[2 * i])
      throw Error("'" + ranges_.path() + "': pixel " + std::to_string(i) + " has a bin range that does not fit the time axis (" +
                  std::to_string(axis.bins) + " bins) or its offsets");
}

TransientTile SavedLight::tile(const PixelRect& rect, const PixelRect& data_rect) const {
  const PixelRect& dr = data_rect;
  if (dr.x0 < region_.x0 || dr.y0 < region_.y0 || dr.x1() > region_.x1() || dr.y1() > region_.y1())
    throw Error("internal: a tile's data lies outside the saved light");
  TransientTile t;
  t.rect = rect, t.data_rect = dr, t.axis = axis_;
  const auto nd = size_t(dr.count());
  const auto T = size_t(axis_.bins);
  t.transient.assign(nd * T, 0.0f);
  t.laser_total.resize(nd), t.out_of_window.resize(nd), t.ambient_rate.resize(nd);
  if (T > 0) t.bin_lo.resize(nd), t.bin_hi.resize(nd);
  const int32_t* r = ranges_.data<int32_t>();
  const int64_t* o = offsets_.data<int64_t>();
  const float* v = values_.data<float>();
  for (int y = dr.y0; y < dr.y1(); ++y)
    for (int x = dr.x0; x < dr.x1(); ++x) {
      const auto di = size_t(dr.index(x, y)), ri = size_t(region_.index(x, y));
      t.laser_total[di] = laser_total_.data<double>()[ri];
      t.out_of_window[di] = out_of_window_.data<double>()[ri];
      t.ambient_rate[di] = ambient_.data<float>()[ri];
      if (T == 0) continue;
      t.bin_lo[di] = r[2 * ri], t.bin_hi[di] = r[2 * ri + 1];
      std::copy(v + o[ri], v + o[ri + 1], t.transient.data() + di * T + size_t(r[2 * ri]));
    }
  if (row_scale_.empty()) return t;
  for (int y = dr.y0; y < dr.y1(); ++y) {
    const double s = row_scale_.at(size_t(y));
    if (s == 1.0) continue;
    for (int x = dr.x0; x < dr.x1(); ++x) {
      const auto di = size_t(dr.index(x, y));
      t.laser_total[di] *= s, t.out_of_window[di] *= s;
      t.ambient_rate[di] = float(t.ambient_rate[di] * s);
      for (size_t b = di * T; b < (di + 1) * T; ++b) t.transient[b] = float(t.transient[b] * s);
    }
  }
  return t;
}

}  // namespace spadgen::app
