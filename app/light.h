// The saved light (`light/` in a run folder, outputs.light): everything the sensor stage reads from the
// renderer, kept so that `spadgen sense` can re-sample the sensor without rendering again. Each pixel's
// transient is kept over its written bin range only (TransientTile::bin_lo / bin_hi), in pixel order
// (.npy files as below, or Zarr stores light/ranges.zarr ... with outputs.storage = zarr):
//
//   light/ranges.npy         (H, W, 2) int32    [bin_lo, bin_hi) of each pixel on metadata.json's time axis
//   light/offsets.npy        (H * W + 1,) int64 where each pixel's bins start in values.npy (row-major pixels)
//   light/values.npy         (n,) float32       photons per pulse of bins bin_lo .. bin_hi - 1, pixel after pixel
//   light/laser_total.npy    (H, W) float64     laser photons per pulse, time-integrated (in and out of the window)
//   light/out_of_window.npy  (H, W) float64     the part of it outside the time window
//   light/ambient_rate.npy   (H, W) float32     ambient photons per second
//
// H x W is the rendered image grown by one pixel on every side, clipped to the sensor (the ring the
// sensor's crosstalk reads around a crop), metadata.json's light.crop_in_sensor. Pixel (x, y) of the
// sensor has bins values[offsets[i] : offsets[i + 1]] for bins ranges[i][0] .. ranges[i][1] - 1,
// i = (y - y0) * W + (x - x0). As .npy files the whole set is memory-mappable; as Zarr stores it is a
// small part of that size (values.npy is mostly zeros: the bins between a pixel's returns).
#pragma once
#include <atomic>
#include <memory>
#include <mutex>
#include <mutex>
#include <string>
#include <vector>

#include "core/config.h"
#include "core/tile.h"
#include "core/time_axis.h"
#include "writers/writers.h"

namespace spadgen::app {

class Staging;

// The saved light's files (Zarr: folders), relative to the output folder, in the order metadata.json lists them.
std::vector<std::string> light_files(Storage storage);

// The pixels whose light a run keeps: the image grown by one pixel, clipped to the sensor.
PixelRect light_region(const PixelRect& img, int sensor_width, int sensor_height);

// Collects the light of a run's tiles (from several threads at once) and writes the files at the end.
class LightWriter {
 public:
  LightWriter(const PixelRect& region, const TimeAxis& axis, const Staging& staging, Storage storage);
  ~LightWriter();
  LightWriter(const LightWriter&) = delete;
  LightWriter& operator=(const LightWriter&) = delete;

  // Keeps every pixel of t.data_rect inside the region that no tile has delivered yet (a pixel's light
  // does not depend on the tile that rendered it, so any copy will do).
  void put(const TransientTile& t);
  // Writes the files into the staging folder and adds them to `files`. Every pixel must have been put.
  void write(std::vector<std::string>& files);
  // Bytes of the values so far, uncompressed (for the report).
  int64_t values_bytes() const { return int64_t(spill_elements_.load()) * 4; }
  // metadata.json's storage record of each file written.
  const nlohmann::json& storage() const { return storage_json_; }

 private:
  PixelRect region_;
  TimeAxis axis_;
  const Staging& staging_;
  Storage storage_;
  nlohmann::json storage_json_ = nlohmann::json::object();
  std::string spill_path_;  // once unlinked: what it is, for messages
  int spill_fd_ = -1;
  std::atomic<int64_t> spill_elements_{0};
  std::vector<std::atomic<char>> claimed_;
  std::vector<int64_t> spill_at_;  // per region pixel: where its bins start in the spill file
  std::vector<int32_t> ranges_;    // per region pixel: bin_lo, bin_hi
  std::vector<double> laser_total_, out_of_window_;
  std::vector<float> ambient_;
  std::vector<float> laser_se_;
  std::vector<int32_t> samples_;
  std::vector<float> ambient_se_;
};

// A run folder's saved light, read-only: .npy files mapped, or Zarr stores (the per-pixel arrays
// decompressed whole, the values chunk by chunk as tiles ask for them).
class SavedLight {
 public:
  // Opens `dir`/light/ (as the run stored it) and checks it against the region and the axis metadata.json records.
  SavedLight(const std::string& dir, const PixelRect& region, const TimeAxis& axis, Storage storage);
  const PixelRect& region() const { return region_; }
  const TimeAxis& axis() const { return axis_; }
  // The renderer's tile for `rect` with data over `data_rect` (which must lie inside the region), as
  // the renderer delivered it: the dense transient, the ranges, the totals and the ambient rates.
  TransientTile tile(const PixelRect& rect, const PixelRect& data_rect) const;
  // Hands a tile's dense transient back for the next tile() (on any thread): its bins that tile() filled
  // are cleared, so a tile starts from zeros without zeroing (or faulting in) the whole dense stack, which
  // is twenty times the lit bins. Optional: a tile not handed back is simply freed.
  void recycle(TransientTile&& t) const;
  // Light per sensor row times row_scale[y] (photons on the photosensitive area scale with the fill
  // factor: a new pixel design rescales the light the run saved). Empty or 1: as saved, bit for bit.
  void set_row_scale(std::vector<double> row_scale) { row_scale_ = std::move(row_scale); }

 private:
  // values[offset, offset + count) into dest.
  void values(int64_t offset, int64_t count, float* dest) const;

  std::string dir_;  // the run's light/ folder, for messages
  PixelRect region_;
  TimeAxis axis_;
  std::vector<writers::NpyReader> npy_;           // .npy: the files, mapped
  std::unique_ptr<writers::ZarrReader> values_z_;  // Zarr: the values
  std::vector<int32_t> ranges_z_;                  // Zarr: the per-pixel arrays, decompressed
  std::vector<int64_t> offsets_z_;
  std::vector<double> laser_total_z_, out_of_window_z_;
  std::vector<float> ambient_z_, laser_se_z_, ambient_se_z_;
  std::vector<int32_t> samples_z_;
  const int32_t* ranges_ = nullptr;
  const int64_t* offsets_ = nullptr;
  const float* values_ = nullptr;  // .npy only
  const double* laser_total_ = nullptr;
  const double* out_of_window_ = nullptr;
  const float* ambient_ = nullptr;
  const float* laser_se_ = nullptr;   // null: a run before the standard errors
  const int32_t* samples_ = nullptr;
  const float* ambient_se_ = nullptr;  // null: a run before the ambient light's standard errors
  int64_t values_elements_ = 0;
  std::vector<double> row_scale_;
  mutable std::mutex pool_mutex_;
  mutable std::vector<std::vector<float>> pool_;  // dense transients, all zero, for tile() to reuse
};

}  // namespace spadgen::app
