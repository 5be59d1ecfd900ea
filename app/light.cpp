#include "app/light.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>

#include "app/outputs.h"
#include "app/staging.h"
#include "core/error.h"
#include "writers/atomic_file.h"

namespace spadgen::app {
namespace {

std::string number_text(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

// The saved light's arrays, in light_files() order, as stacks: their Zarr chunks and attributes.
// kLaserSe and kSamples came later (a run before them has neither), kAmbientSe after them: a run before them
// is read without them.
enum LightFile : size_t { kRanges, kOffsets, kValues, kLaserTotal, kOutOfWindow, kAmbient, kLaserSe, kSamples, kAmbientSe, kLightFiles };

StackLayout light_layout(LightFile f, Storage storage, int64_t H, int64_t W, int64_t values) {
  using writers::Dtype;
  // Per pixel: 256 x 256 pixel blocks; the values: 2^20 of them (4 MiB) a chunk.
  constexpr int64_t kBlock = 256, kValuesChunk = int64_t(1) << 20;
  const std::vector<std::string> yx{"y_light", "x_light"};
  StackLayout l;
  switch (f) {
    case kRanges:
      l = {"light/ranges", Dtype::I32, {H, W, 2}, true, {kBlock, kBlock, 2},
           "[bin_lo, bin_hi): the pixel's bins on metadata.json light.time_axis_s that may be non-zero", "bins",
           {"y_light", "x_light", "lo_hi"}};
      break;
    case kOffsets:
      l = {"light/offsets", Dtype::I64, {H * W + 1}, true, {kValuesChunk},
           "where each pixel's bins start in values, pixels in row-major order", "elements", {"light_pixel_edge"}};
      break;
    case kValues:
      l = {"light/values", Dtype::F32, {values}, true, {kValuesChunk},
           "photons per laser pulse of bins bin_lo .. bin_hi - 1, pixel after pixel", "photons per pulse", {"light_value"}};
      break;
    case kLaserTotal:
      l = {"light/laser_total", Dtype::F64, {H, W}, true, {kBlock, kBlock},
           "laser photons per pulse, time-integrated (in and out of the window)", "photons per pulse", yx};
      break;
    case kOutOfWindow:
      l = {"light/out_of_window", Dtype::F64, {H, W}, true, {kBlock, kBlock},
           "the part of laser_total that arrived outside the time window", "photons per pulse", yx};
      break;
    case kAmbient:
      l = {"light/ambient_rate", Dtype::F32, {H, W}, true, {kBlock, kBlock}, "ambient photons per second",
           "photons per second", yx};
      break;
    case kLaserSe:
      l = {"light/laser_se", Dtype::F32, {H, W}, true, {kBlock, kBlock},
           "the Monte Carlo standard error of laser_total (laser.exr standard_error)", "photons per pulse", yx};
      break;
    case kSamples:
      l = {"light/samples", Dtype::I32, {H, W}, true, {kBlock, kBlock}, "paths rendered in the pixel", "paths", yx};
      break;
    default:
      l = {"light/ambient_se", Dtype::F32, {H, W}, true, {kBlock, kBlock},
           "the Monte Carlo standard error of ambient_rate (ambient.exr standard_error)", "photons per second", yx};
      break;
  }
  l.file += storage == Storage::Zarr ? ".zarr" : ".npy";
  if (storage != Storage::Zarr) l.chunks.clear();
  return l;
}

template <class T>
void write_stack(const StackLayout& l, const std::string& path, const std::vector<T>& v, nlohmann::json& storage) {
  const std::unique_ptr<writers::StackWriter> w = open_stack(l, path);
  w->write(0, v.data(), int64_t(v.size()));
  w->commit();
  storage[l.file] = storage_json(l);
}

}  // namespace

std::vector<std::string> light_files(Storage storage) {
  std::vector<std::string> f;
  for (size_t i = 0; i < kLightFiles; ++i) f.push_back(light_layout(LightFile(i), storage, 0, 0, 0).file);
  return f;
}

PixelRect light_region(const PixelRect& img, int sensor_width, int sensor_height) {
  return grow_clipped(img, 1, sensor_width, sensor_height);
}

LightWriter::LightWriter(const PixelRect& region, const TimeAxis& axis, const Staging& staging, Storage storage)
    : region_(region), axis_(axis), staging_(staging), storage_(storage), claimed_(size_t(region.count())) {
  const auto n = size_t(region.count());
  spill_at_.assign(n, 0);
  ranges_.assign(2 * n, 0);
  laser_total_.assign(n, 0.0), out_of_window_.assign(n, 0.0), ambient_.assign(n, 0.0f);
  laser_se_.assign(n, 0.0f), samples_.assign(n, 0), ambient_se_.assign(n, 0.0f);
  for (auto& c : claimed_) c.store(0, std::memory_order_relaxed);
  // The transients wait in a file (tiles finish in any order; values.npy is in pixel order), unlinked at
  // once so that nothing is left behind whatever happens to the run.
  spill_path_ = staging.path(".light-spill");
  spill_fd_ = ::open(spill_path_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (spill_fd_ < 0) writers::detail::throw_errno("cannot create", spill_path_, errno);
  ::unlink(spill_path_.c_str());
  // Messages name what it is for (a full disk said only ".../.light-spill").
  spill_path_ = "the transients held for outputs.light (an unlinked temporary file in " + staging.path("") + ")";
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
      laser_se_[ri] = t.laser_se.size() == nd ? t.laser_se[di] : 0.0f;
      ambient_se_[ri] = t.ambient_se.size() == nd ? t.ambient_se[di] : 0.0f;
      samples_[ri] = t.samples.size() == nd ? t.samples[di] : 0;
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
  const int64_t H = region_.height, W = region_.width, total = offsets[n];
  const auto layout = [&](LightFile f) { return light_layout(f, storage_, H, W, total); };
  {
    const StackLayout l = layout(kValues);
    const std::unique_ptr<writers::StackWriter> values = open_stack(l, staging_.path(l.file));
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
            values->write(offsets[i], spill + spill_at_[i], offsets[i + 1] - offsets[i]);
        });
        values->release_rows(0, offsets[y0 * size_t(W)], offsets[y1 * size_t(W)]);
        ::madvise(m, bytes, MADV_DONTNEED);
      }
      ::munmap(m, bytes);
    }
    values->commit();
    storage_json_[l.file] = storage_json(l);
  }
  write_stack(layout(kRanges), staging_.path(layout(kRanges).file), ranges_, storage_json_);
  write_stack(layout(kOffsets), staging_.path(layout(kOffsets).file), offsets, storage_json_);
  write_stack(layout(kLaserTotal), staging_.path(layout(kLaserTotal).file), laser_total_, storage_json_);
  write_stack(layout(kOutOfWindow), staging_.path(layout(kOutOfWindow).file), out_of_window_, storage_json_);
  write_stack(layout(kAmbient), staging_.path(layout(kAmbient).file), ambient_, storage_json_);
  write_stack(layout(kLaserSe), staging_.path(layout(kLaserSe).file), laser_se_, storage_json_);
  write_stack(layout(kSamples), staging_.path(layout(kSamples).file), samples_, storage_json_);
  write_stack(layout(kAmbientSe), staging_.path(layout(kAmbientSe).file), ambient_se_, storage_json_);
  const std::vector<std::string> f = light_files(storage_);
  files.insert(files.end(), f.begin(), f.end());
  if (storage_ == Storage::Zarr) write_zarr_group(staging_, "light", files);
}

SavedLight::SavedLight(const std::string& dir, const PixelRect& region, const TimeAxis& axis, Storage storage)
    : dir_(dir), region_(region), axis_(axis) {
  const int64_t H = region.height, W = region.width, n = H * W;
  const std::vector<std::string> f = light_files(storage);
  const auto path = [&](LightFile i) { return dir + "/" + f[i]; };
  const auto expect_shape = [](const std::string& p, const std::vector<int64_t>& shape, const std::vector<int64_t>& want,
                               const std::string& what) {
    if (shape == want) return;
    const auto text = [](const std::vector<int64_t>& v) {
      std::string t = "(";
      for (size_t i = 0; i < v.size(); ++i) t += (i ? ", " : "") + std::to_string(v[i]);
      return t + ")";
    };
    throw Error("'" + p + "': " + what + ": expected shape " + text(want) + ", found " + text(shape));
  };
  const std::vector<std::pair<std::vector<int64_t>, std::string>> want = {
      {{H, W, 2}, "the light's bin ranges"}, {{n + 1}, "the light's offsets"}, {{}, ""},
      {{H, W}, "the light's laser totals"},  {{H, W}, "the light's out-of-window totals"}, {{H, W}, "the light's ambient rates"},
      {{H, W}, "the light's standard errors"}, {{H, W}, "the light's paths per pixel"},
      {{H, W}, "the light's ambient standard errors"}};
  // The standard errors and paths: both or neither (a run before them); the ambient light's standard errors,
  // or not (a run before them).
  const bool accuracy = std::filesystem::exists(path(kLaserSe)) || std::filesystem::exists(path(kSamples));
  const bool ambient_accuracy = accuracy && std::filesystem::exists(path(kAmbientSe));
  const size_t files = ambient_accuracy ? kLightFiles : accuracy ? kAmbientSe : kLaserSe;
  if (storage == Storage::Zarr) {
    std::vector<writers::ZarrReader> z;
    for (size_t i = 0; i < files; ++i) {
      z.emplace_back(path(LightFile(i)));
      if (i != kValues) expect_shape(z.back().path(), z.back().shape(), want[i].first, want[i].second);
    }
    if (accuracy) {
      laser_se_z_ = z[kLaserSe].read_all<float>(), samples_z_ = z[kSamples].read_all<int32_t>();
      laser_se_ = laser_se_z_.data(), samples_ = samples_z_.data();
    }
    if (ambient_accuracy) ambient_se_z_ = z[kAmbientSe].read_all<float>(), ambient_se_ = ambient_se_z_.data();
    ranges_z_ = z[kRanges].read_all<int32_t>(), offsets_z_ = z[kOffsets].read_all<int64_t>();
    laser_total_z_ = z[kLaserTotal].read_all<double>(), out_of_window_z_ = z[kOutOfWindow].read_all<double>();
    ambient_z_ = z[kAmbient].read_all<float>();
    if (z[kValues].dtype() != writers::Dtype::F32 || z[kValues].shape().size() != 1)
      throw Error("'" + z[kValues].path() + "': the light's values: expected a 1-dimensional float32 array");
    values_elements_ = z[kValues].elements();
    // Tiles in flight each read a few chunks of 4 MiB.
    values_z_ = std::make_unique<writers::ZarrReader>(path(kValues), 32);
    ranges_ = ranges_z_.data(), offsets_ = offsets_z_.data(), laser_total_ = laser_total_z_.data();
    out_of_window_ = out_of_window_z_.data(), ambient_ = ambient_z_.data();
  } else {
    for (size_t i = 0; i < files; ++i) {
      npy_.emplace_back(path(LightFile(i)));
      if (i != kValues) npy_.back().expect_shape(want[i].first, want[i].second);
    }
    if (accuracy) laser_se_ = npy_[kLaserSe].data<float>(), samples_ = npy_[kSamples].data<int32_t>();
    if (ambient_accuracy) ambient_se_ = npy_[kAmbientSe].data<float>();
    ranges_ = npy_[kRanges].data<int32_t>(), offsets_ = npy_[kOffsets].data<int64_t>(), values_ = npy_[kValues].data<float>();
    laser_total_ = npy_[kLaserTotal].data<double>(), out_of_window_ = npy_[kOutOfWindow].data<double>();
    ambient_ = npy_[kAmbient].data<float>();
    values_elements_ = npy_[kValues].elements();
  }
  // Every pixel's range must lie on the axis and match its slice of the values, so tile() reads nothing
  // out of bounds whatever the files hold.
  const int32_t* r = ranges_;
  const int64_t* o = offsets_;
  if (o[0] != 0 || o[n] != values_elements_)
    throw Error("'" + path(kOffsets) + "' and '" + path(kValues) + "' disagree: the offsets run from " + std::to_string(o[0]) +
                " to " + std::to_string(o[n]) + " and the values hold " + std::to_string(values_elements_) +
                " (one of them damaged, or of another run)");
  // (pixels named by their sensor coordinates, as everywhere else; the index into the file was given)
  const auto pixel = [&](int64_t i) {
    return "pixel (" + std::to_string(region_.x0 + int(i % region_.width)) + ", " + std::to_string(region_.y0 + int(i / region_.width)) + ")";
  };
  for (int64_t i = 0; i < n; ++i) {
    if (r[2 * i] < 0 || r[2 * i + 1] < r[2 * i] || r[2 * i + 1] > axis.bins)
      throw Error("'" + path(kRanges) + "': " + pixel(i) + " has the bin range [" + std::to_string(r[2 * i]) +
                  ", " + std::to_string(r[2 * i + 1]) + "), which does not fit the time axis (" + std::to_string(axis.bins) +
                  " bins)");
    if (o[i + 1] - o[i] != r[2 * i + 1] - r[2 * i])
      throw Error("'" + path(kRanges) + "' and '" + path(kOffsets) + "' disagree at " + pixel(i) + ": its range [" +
                  std::to_string(r[2 * i]) + ", " + std::to_string(r[2 * i + 1]) + ") holds " +
                  std::to_string(r[2 * i + 1] - r[2 * i]) + " bins, its offsets " + std::to_string(o[i + 1] - o[i]));
  }
}

void SavedLight::values(int64_t offset, int64_t count, float* dest) const {
  if (values_) std::copy(values_ + offset, values_ + offset + count, dest);
  else values_z_->read(offset, count, dest);
}

TransientTile SavedLight::tile(const PixelRect& rect, const PixelRect& data_rect) const {
  const PixelRect& dr = data_rect;
  if (dr.x0 < region_.x0 || dr.y0 < region_.y0 || dr.x1() > region_.x1() || dr.y1() > region_.y1())
    throw Error("internal: a tile's data lies outside the saved light");
  TransientTile t;
  t.rect = rect, t.data_rect = dr, t.axis = axis_;
  const auto nd = size_t(dr.count());
  const auto T = size_t(axis_.bins);
  {
    std::lock_guard<std::mutex> lock(pool_mutex_);
    if (!pool_.empty()) t.transient = std::move(pool_.back()), pool_.pop_back();
  }
  t.transient.resize(nd * T);  // all zero: a recycled buffer's extra elements go, missing ones come as 0
  t.laser_total.resize(nd), t.out_of_window.resize(nd), t.ambient_rate.resize(nd);
  if (laser_se_) t.laser_se.resize(nd), t.samples.resize(nd);
  if (ambient_se_) t.ambient_se.resize(nd);
  if (T > 0) t.bin_lo.resize(nd), t.bin_hi.resize(nd);
  const int32_t* r = ranges_;
  const int64_t* o = offsets_;
  std::vector<float> row;  // a row's values (its pixels are contiguous in the values), from a Zarr store
  for (int y = dr.y0; y < dr.y1(); ++y) {
    const auto first = size_t(region_.index(dr.x0, y)), last = size_t(region_.index(dr.x1() - 1, y));
    const float* vals = values_ ? values_ + o[first] : nullptr;  // mapped: read in place
    if (T > 0 && !values_) {
      row.resize(size_t(o[last + 1] - o[first]));
      values(o[first], int64_t(row.size()), row.data());
      vals = row.data();
    }
    for (int x = dr.x0; x < dr.x1(); ++x) {
      const auto di = size_t(dr.index(x, y)), ri = size_t(region_.index(x, y));
      t.laser_total[di] = laser_total_[ri];
      t.out_of_window[di] = out_of_window_[ri];
      t.ambient_rate[di] = ambient_[ri];
      if (laser_se_) t.laser_se[di] = laser_se_[ri], t.samples[di] = samples_[ri];
      if (ambient_se_) t.ambient_se[di] = ambient_se_[ri];
      // Photons, their standard errors and sample counts are finite and not negative: a damaged file (a NaN)
      // would make every output NaN silently (out_of_window, laser_se and samples were not checked: a NaN
      // reached metadata.json as null, -4 samples its minimum).
      const auto photons_in = [](double v) { return v >= 0.0 && v <= std::numeric_limits<double>::max(); };
      const char* bad = !photons_in(t.laser_total[di])                      ? "laser_total"
                        : !photons_in(t.ambient_rate[di])                   ? "ambient_rate"
                        : !photons_in(t.out_of_window[di])                  ? "out_of_window"
                        : laser_se_ && !photons_in(t.laser_se[di])          ? "laser_se"
                        : laser_se_ && t.samples[di] < 0                    ? "samples"
                        : ambient_se_ && !photons_in(t.ambient_se[di])      ? "ambient_se"
                                                                            : nullptr;
      bool ok = bad == nullptr;
      if (T > 0) {
        t.bin_lo[di] = r[2 * ri], t.bin_hi[di] = r[2 * ri + 1];
        const float* from = vals + (o[ri] - o[first]);
        const float* to = vals + (o[ri + 1] - o[first]);
        float* dest = t.transient.data() + di * T + size_t(r[2 * ri]);
        bool photons = true;  // copied and checked in one pass; NaN fails both comparisons
        double sum = 0.0;
        for (const float* v = from; v < to; ++v, ++dest) {
          photons &= *v >= 0.0f && *v <= std::numeric_limits<float>::max();
          sum += double(*v);
          *dest = *v;
        }
        if (ok && !photons) ok = false, bad = "values";
        // The bins hold the laser light inside the window: laser_total less out_of_window, to float32 rounding
        // (5e-8 measured; 1e-4 of the total allowed). Values far from it, finite, are damage too (3e38 in every
        // bin wrote +inf rates, exit 0).
        if (ok && std::abs(sum - (t.laser_total[di] - t.out_of_window[di])) > 1e-4 * t.laser_total[di] + 1e-30)
          throw Error((std::filesystem::path(dir_) / "light").string() + ": pixel (" + std::to_string(x) + ", " + std::to_string(y) +
                      ")'s values sum to " + number_text(sum) + " photons per pulse, and its laser_total less out_of_window is " +
                      number_text(t.laser_total[di] - t.out_of_window[di]) +
                      " (the light inside the window, which the values hold); the saved light is damaged: run the scene again");
      }
      if (!ok)
        throw Error((std::filesystem::path(dir_) / "light").string() + ": pixel (" + std::to_string(x) + ", " + std::to_string(y) +
                    ") holds a value that is not " + (std::string(bad) == "samples" ? "a count >= 0" : "a finite number >= 0") +
                    " (in " + bad + "); the saved light is damaged: run the scene again");
    }
  }
  if (row_scale_.empty()) return t;
  for (int y = dr.y0; y < dr.y1(); ++y) {
    const double s = row_scale_.at(size_t(y));
    if (s == 1.0) continue;
    for (int x = dr.x0; x < dr.x1(); ++x) {
      const auto di = size_t(dr.index(x, y));
      t.laser_total[di] *= s, t.out_of_window[di] *= s;
      t.ambient_rate[di] = float(t.ambient_rate[di] * s);
      if (laser_se_) t.laser_se[di] = float(t.laser_se[di] * s);
      if (ambient_se_) t.ambient_se[di] = float(t.ambient_se[di] * s);
      for (size_t b = di * T; b < (di + 1) * T; ++b) t.transient[b] = float(t.transient[b] * s);
    }
  }
  return t;
}

void SavedLight::recycle(TransientTile&& t) const {
  const auto T = size_t(axis_.bins);
  if (T == 0 || t.transient.size() != size_t(t.data_rect.count()) * T || t.bin_lo.size() != size_t(t.data_rect.count())) return;
  // tile() wrote bins [bin_lo, bin_hi) of each pixel and nothing else.
  for (size_t i = 0; i < t.bin_lo.size(); ++i)
    if (t.bin_hi[i] > t.bin_lo[i]) std::fill(t.transient.data() + i * T + t.bin_lo[i], t.transient.data() + i * T + t.bin_hi[i], 0.0f);
  std::lock_guard<std::mutex> lock(pool_mutex_);
  pool_.push_back(std::move(t.transient));
}

}  // namespace spadgen::app
