// What reconstruction and evaluation read from a run folder (docs/outputs.md): metadata.json, the counts
// (counts.npy or counts.zarr) or the noise-free detection rate, and the per-pixel gate maps.
#pragma once
#include <cstdint>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "reconstruct/detect.h"

namespace spadgen::writers {
struct ExrData;
}

namespace spadgen::reconstruct {

// A run folder's metadata.json, parsed. Throws spadgen::Error naming the file when it is absent, not a
// regular file (a FIFO is not opened), larger than kMaxMetadataBytes, or not JSON.
inline constexpr uintmax_t kMaxMetadataBytes = 256u << 20;
nlohmann::json read_run_metadata(const std::string& dir);

// Whether dir is the folder of `spadgen sense --repeats`' realisations (it holds repeat_000/metadata.json):
// each realisation is a run folder, the set is none.
bool is_repeat_set(const std::filesystem::path& dir);

class RunFolder {
 public:
  // Throws spadgen::Error naming the folder and the file when something needed is missing or malformed.
  explicit RunFolder(const std::string& dir);
  ~RunFolder();
  RunFolder(RunFolder&&) noexcept;

  const std::string& dir() const { return dir_; }
  const nlohmann::json& metadata() const { return meta_; }
  bool gate_sweep() const { return gate_sweep_; }
  int K() const { return K_; }
  int width() const { return W_; }
  int height() const { return H_; }
  int frames() const { return frames_; }  // N per gate position or exposure
  // 2D mode: dual exposure and its ratio tau_L / tau_S; the frames of the whole image (N_sat).
  bool dual() const { return dual_; }
  double dual_ratio() const { return dual_ratio_; }
  int image_frames() const { return image_frames_; }

  // The timing of pixel (x, y) of the image (gate-sweep mode).
  PixelTiming timing(int x, int y) const;
  // Where the laser sits against the pixel-centre ray of pixel (x, y) (gate-sweep mode): metadata.json's
  // camera.intrinsics and camera.laser_position_m.
  Bistatic bistatic(int x, int y) const;
  // A gate sweep's step between gate positions, and its gate's edge (the slower of rise and fall plus the
  // instrument response's FWHM; 0 when metadata.json does not say): 0 for a 2D run.
  double gate_step_s() const { return step_s_; }
  double gate_edge_s() const { return edge_s_; }
  // c T / 2 for the laser period T: the half paths a gate sweep tells apart (0 for a 2D run).
  double ambiguity_m() const { return ambiguity_range_m(period_s_); }
  // Rows [y0, y1) of the counts as [((y - y0) * W + x) * K + k] (one profile per pixel). noise_free: the
  // expected counts N (1 - exp(-lambda)) from detection_rate instead of the sampled counts.
  void profiles(int y0, int y1, bool noise_free, float* out) const;
  // The same rows of detection_rate: lambda, the mean avalanches per frame (no counts: no saturation).
  void rates(int y0, int y1, float* out) const;
  // Refuses an image (an EXR of the run folder, read as e) of another size or, where its header says so
  // (spadgen_crop), of another crop than metadata.json's, naming the file; with `of_the_chip` (sensor maps,
  // labels), also one of another chip than metadata.json's seeds.chip (its spadgen_chip_seed).
  void check_image(const std::string& path, const writers::ExrData& e, bool of_the_chip = false) const;
  // The image's file named `name` (e.g. "ground_truth.exr"): its path, or "" when the run has none; throws
  // spadgen::Error when metadata.json lists it (files) and it is gone.
  std::string file(const std::string& name) const;

 private:
  // Rows [y0, y1) of detection_rate (rate) or counts, as profiles; to_counts: the rates as N (1 - exp(-lambda)).
  void read_rows(int y0, int y1, bool rate, bool to_counts, float* out) const;
  struct Stack;
  friend std::unique_ptr<Stack> open_run_stack(const std::string& dir, const std::string& name);
  std::string dir_;
  nlohmann::json meta_;
  nlohmann::json crop_;  // metadata.json's image.crop_in_sensor (null when absent)
  bool gate_sweep_ = true, dual_ = false;
  int K_ = 0, W_ = 0, H_ = 0, frames_ = 0, image_frames_ = 0;
  double dual_ratio_ = 1.0;
  double start_s_ = 0, step_s_ = 0, gate_delay_s_ = 0, emission_delay_s_ = 0, period_s_ = 0, edge_s_ = 0;
  double fx_ = 1, fy_ = 1, cx_ = 0, cy_ = 0, laser_m_[3] = {0, 0, 0};  // OpenCV camera frame
  std::vector<float> skew_ps_, length_ps_;
  std::unique_ptr<Stack> counts_, rate_;
};

}  // namespace spadgen::reconstruct
