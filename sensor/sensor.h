// The sensor stage: turns transient tiles (photons per pulse per time bin) into what the time-gated SPAD
// camera streams out. Depends on core/ only, never on the renderer. Pixel coordinates are full-sensor
// coordinates (camera.width_px x camera.height_px), so per-pixel maps and random streams do not change
// with the crop, the tile size or the thread count.
//
// Photon convention (one place, never applied twice): TransientTile holds photons per laser pulse that
// land on the pixel's photosensitive area, i.e. the renderer has already applied the optics transmission,
// the fill factor and cos^4. The sensor multiplies by the PDP only: detections = PDP(lambda) x photons.
// The same holds for TransientTile::ambient_rate. SensorMapsTile::pde (PDP x FF x optics) is informative:
// it relates detections to photons on the whole pixel pitch, and is not used in the computation.
//
// Crosstalk needs the 4 nearest neighbours' detection rates: when halo() is 1, every TransientTile must
// carry data for rect grown by 1 pixel, clipped to the image (data_rect); process() checks this.
//
// Details and measured accuracies: docs/sensor.md.
#pragma once
#include <nlohmann/json.hpp>

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/config.h"
#include "core/tile.h"

namespace spadgen::sensor {

class Acquisition;
struct GateShape;
class PixelLayout;
struct PixelParams;

// The per-pixel maps actually used, for sensor_maps.exr: [rect.index(x, y)].
struct SensorMapsTile {
  PixelRect rect;
  std::vector<float> gate_skew_ps;    // gate position offset of the pixel, ps
  std::vector<float> gate_length_ps;  // gate length of the pixel, ps
  std::vector<float> dcr_cps;         // dark count rate at the set temperature, counts per second
  std::vector<float> pde;             // photon detection efficiency at the laser wavelength (PDP x FF x optics)
  std::vector<float> pde_ambient;     // the same for the ambient light (its band's PDP: pdp_ambient_band)
};

class SensorModel {
 public:
  explicit SensorModel(const SensorStageConfig& config);
  ~SensorModel();
  SensorModel(const SensorModel&) = delete;
  SensorModel& operator=(const SensorModel&) = delete;

  // The acquisition mode (sensor/acquisition/): K, frames, the window, the outputs it declares.
  const Acquisition& acquisition() const;
  // Which pixel design each row has (sensor/pixel_layout.h), and the fill factor of every row, which the
  // renderer applies (RenderStageConfig::row_fill_factor).
  const PixelLayout& layout() const;
  std::vector<double> row_fill_factor() const;
  // Per sensor row, photons per second on the photosensitive area: the ambient rate a gate sweep's counts
  // hardly see, 1 / (N PDP_ambient t) (one expected count over a gate position's N frames, t the gate's open
  // time per frame: its effective length x cycles per frame) plus the median dark count rate / PDP_ambient;
  // +inf where the pixels cannot detect the ambient light, and without a gate (the intensity mode, whose
  // render_stage takes none) (RenderStageConfig::row_ambient_floor).
  std::vector<double> row_ambient_floor() const;

  // K: gate positions (gate sweep) or exposures (2D intensity: 1 single, 2 dual).
  int K() const;
  // Gate positions relative to the laser trigger, seconds (empty in 2D mode).
  const std::vector<double>& gate_positions_s() const;
  // The time window the renderer must cover: the union of every pixel's gate window at every position,
  // widened by the instrument response, on bins of bin_width_s. bins == 0 in 2D intensity mode.
  TimeAxis required_window(double bin_width_s) const;
  // Pixels of halo the sensor needs around a tile (1 when crosstalk is on, else 0).
  int halo() const;

  // Expected and sampled counts (and frames when asked) for the pixels of t.rect.
  SensorTile process(const TransientTile& t) const;
  // The same for several realisations of the temporal noise, one per seed (SensorStageConfig::noise_seed
  // is ignored): the rates are computed once. Element i equals process(t) with noise_seed = noise_seeds[i].
  std::vector<SensorTile> process(const TransientTile& t, const std::vector<uint64_t>& noise_seeds) const;
  SensorMapsTile maps(const PixelRect& rect) const;
  // What metadata.json records about the acquisition: gate positions, cycles per frame, N_sat, PDE, ...
  nlohmann::json describe() const;

  // Measured gate maps (the app reads sensor.gate.maps_exr and passes its channels here): full-sensor
  // row-major arrays of width_px * height_px, gate skew in ps and absolute gate length (50 %-50 %) in ps.
  // Replaces the generated skew and length maps (still switched off by sensor.gate_skew = false). Call
  // before required_window() and process(). Throws spadgen::Error on a size mismatch or bad values.
  void set_gate_maps(std::vector<float> skew_ps, std::vector<float> length_ps);
  // The same from the channels of an EXR (sensor.gate.maps_exr, named `source` in errors): "skew_ps" and
  // "length_ps", or "gate_skew_ps" and "gate_length_ps" as written to sensor_maps.exr, full-sensor size.
  void set_maps(int width, int height, const std::map<std::string, std::vector<float>>& channels,
                const std::string& source);

  // Frames per gate position or exposure (N; N / 2 per exposure in dual mode).
  int frames_per_k() const;
  // Exposure time of each k in 2D intensity mode, seconds (empty in gate-sweep mode).
  const std::vector<double>& exposures_s() const;
  // The effective gate (profile convolved with the instrument response); gate-sweep mode (throws otherwise).
  const GateShape& gate() const;
  // The parameters of pixel (x, y): type, skew, length deviation, DCR, PDP scale.
  PixelParams pixel(int x, int y) const;
  // Mean detections per laser cycle per photon at the laser (or ambient) wavelength for a pixel type
  // (0: pixel A settings, 1: pixel B), before the per-pixel non-uniformity.
  double pdp_laser(int type) const;
  double pdp_ambient(int type) const;
  // The binary-frame detection rate lambda (mean avalanches per frame) of every k for one pixel, without
  // crosstalk: g = its transient on `axis` (ignored in 2D mode), ambient in photons per second,
  // laser_total in photons per pulse. Used by process() and by tests as the reference.
  std::vector<double> pixel_lambda(int x, int y, const float* g, const TimeAxis& axis, double ambient_rate,
                                   double laser_total) const;
  // One return of light at a pixel: `photons` per pulse arriving at t_s as a delta.
  struct Return {
    int x = 0, y = 0;
    double t_s = 0.0;
    float photons = 0.0f;
  };
  // The detection rate per frame of every k that each return adds to its pixel, out[r * K + k]: the
  // photons in the bin of each periodic image t_s + m period inside `axis` (as the renderer bins light),
  // through the pixel's PDP, gate shape, skew and length and the cycles per frame; without dark counts or
  // ambient light. pixel_lambda of that one-bin transient less pixel_lambda with no light; zero when no
  // image of t_s lies inside the axis. With crosstalk, plus what the same return at its crosstalk
  // neighbours would fire in it (pixel A: xt per neighbour avalanche, xt n lambda; pixel B: xt per
  // neighbour avalanche frame, at most xt n p): an object's light reaches its neighbours too, and their
  // avalanches fire this pixel. Many returns at once share the gate's set-up.
  std::vector<double> return_lambda(const std::vector<Return>& returns, const TimeAxis& axis) const;
  // n xt of pixel (x, y): its crosstalk neighbours (same section, inside the sensor) times its crosstalk
  // probability; 0 without crosstalk.
  double crosstalk_share(int x, int y) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Inverse of the paper's eq. (5) (single exposure) or eq. (6) (dual, ratio = tau_L / tau_S) with
// N_sat = frames: the incident (detectable) photons per N-frame image that give `counts` on average.
// Counts at or above frames - 0.5 are taken as frames - 0.5, so saturation gives a large finite value.
double linearise_counts(double counts, int frames, bool dual, double ratio);

}  // namespace spadgen::sensor
