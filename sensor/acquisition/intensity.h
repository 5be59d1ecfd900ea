// The 2D intensity modes (the paper's section 4.C): the gate is held open for a global exposure tau in
// each binary frame, and an image is the sum of N frames. A pixel detects at the rate
// PDP_amb ambient + PDP laser_mean (when the laser is on) + DCR, so lambda = rate * tau. The single and the
// dual exposure differ in their exposures and in how counts are linearised (eqs. (5) and (6)); each is a
// file of its own (intensity_single.cpp, intensity_dual.cpp) over this shared part.
#pragma once
#include "sensor/acquisition/acquisition.h"

namespace spadgen::sensor {

class Intensity : public Acquisition {
 public:
  // exposures: tau of each image; frames_per_k: frames summed into each.
  Intensity(const SensorStageConfig& c, std::vector<double> exposures, uint32_t frames_per_k, bool dual);

  int K() const override { return static_cast<int>(exposures_.size()); }
  uint32_t frames_per_k() const override { return frames_per_k_; }
  bool needs_transient() const override { return false; }
  double nominal_gate_length_s() const override { return nominal_length_s_; }
  const std::vector<double>& exposures_s() const override { return exposures_; }
  bool tabulated_counts() const override { return false; }
  TimeAxis required_window(const PixelMaps& maps, double bin_width_s, double period_s) const override;
  void rates(const PixelDetection& d, const PixelLight& in, const TileSetup* setup, Scratch* scratch,
             double* out) const override;
  // Summed counts of every image and the linearised estimate of the incident photons.
  void finish_tile(SensorTile& tile) const override;
  std::vector<DeclaredOutput> outputs() const override;
  nlohmann::json describe() const override;

 private:
  std::vector<double> exposures_;
  uint32_t frames_per_k_;
  bool dual_;
  double dual_ratio_;
  int frames_;  // N_sat: every frame of the image
  bool laser_on_;
  double repetition_rate_Hz_;
  double nominal_length_s_;
};

// Inverse of eq. (5) / (6): incident (detectable) photons per N-frame image from summed counts. A count at
// saturation is taken as N - 0.5 so the estimate stays finite.
double linearise(double counts, double N, bool dual, double ratio);

}  // namespace spadgen::sensor
