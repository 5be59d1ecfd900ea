// An acquisition mode: what the camera does with its gate and its binary frames. The gate sweep (3D), the
// single-exposure and the dual-exposure intensity images (2D) implement this interface, one file each;
// registry.cpp maps the scene file's acquisition settings to one of them.
//
// The SensorModel owns everything a mode shares (pixel maps, PDP, crosstalk, sampling); a mode says how
// many images it takes (K) of how many frames each, which arrival times it needs rendered, the detection
// rate lambda of each image for one pixel, what it adds to a finished tile, which output files it
// declares, and how metadata.json describes it.
//
// Adding a mode: an enum value in core/config.h (its scene-file spelling comes with it), one file here
// implementing Acquisition, one line in registry.cpp.
#pragma once
#include <nlohmann/json.hpp>

#include <memory>
#include <string>
#include <vector>

#include "core/config.h"
#include "core/tile.h"
#include "core/time_axis.h"

namespace spadgen::sensor {

struct GateShape;
struct PixelParams;
class PixelMaps;

// What reached one pixel, as the renderer delivered it.
struct PixelLight {
  const float* transient = nullptr;  // photons per pulse per bin on axis (null when the mode needs none)
  const TimeAxis* axis = nullptr;
  int64_t bin_lo = 0, bin_hi = 0;    // its non-zero bins lie in [bin_lo, bin_hi)
  double ambient_rate = 0.0;         // ambient photons per second
  double laser_total = 0.0;          // laser photons per pulse, time-integrated
};

// The pixel's detection: PDP at the laser and in the ambient band (with its non-uniformity), and its
// gate skew, gate length deviation and dark count rate (PixelParams).
struct PixelDetection {
  const PixelParams* params = nullptr;
  double pdp_laser = 0.0, pdp_ambient = 0.0;
};

// A file a mode adds to a run's outputs, beyond the files every run writes.
struct DeclaredOutput {
  std::string file;  // e.g. "intensity.exr"
  std::string what;
};

class Acquisition {
 public:
  virtual ~Acquisition() = default;

  // Images taken (gate positions, exposures) and binary frames summed into each.
  virtual int K() const = 0;
  virtual uint32_t frames_per_k() const = 0;
  // The scene-file spelling of the mode, for messages and metadata.
  virtual std::string name() const = 0;

  // Whether the mode reads the transient (gate sweep) or only time-integrated light (2D).
  virtual bool needs_transient() const = 0;
  // The effective gate when the mode uses its time profile (null for 2D modes, which only open it).
  virtual const GateShape* gate() const { return nullptr; }
  // The nominal (50 %-50 %) gate length the pixel maps vary around.
  virtual double nominal_gate_length_s() const = 0;
  // The window of arrival times the renderer must cover, on bins of bin_width_s (bins == 0: none).
  virtual TimeAxis required_window(const PixelMaps& maps, double bin_width_s, double period_s) const = 0;
  // Gate positions relative to the laser trigger (empty for 2D modes), and exposure times (empty for 3D).
  virtual const std::vector<double>& gate_positions_s() const;
  virtual const std::vector<double>& exposures_s() const;

  // State rates() needs for one tile's time axis, made once per tile and shared by its workers, and
  // scratch one worker reuses from pixel to pixel. Both may be null.
  struct TileSetup {
    virtual ~TileSetup() = default;
  };
  struct Scratch {
    virtual ~Scratch() = default;
  };
  virtual std::unique_ptr<TileSetup> setup(const TimeAxis& axis) const;
  virtual std::unique_ptr<Scratch> scratch() const;
  // lambda (mean avalanches per binary frame, before crosstalk) of each of the K images for one pixel.
  virtual void rates(const PixelDetection& d, const PixelLight& in, const TileSetup* setup, Scratch* scratch,
                     double* out) const = 0;

  // Counts by 64-bit CDF tables (many images of a few hundred frames each) rather than by inversion.
  virtual bool tabulated_counts() const = 0;
  // Fills what the mode adds to a finished tile (2D: summed counts and the linearised photon estimate).
  virtual void finish_tile(SensorTile& tile) const;
  // Files the mode adds to a run's outputs.
  virtual std::vector<DeclaredOutput> outputs() const = 0;
  // The mode's part of metadata.json's "acquisition".
  virtual nlohmann::json describe() const = 0;
};

// The mode the settings select.
std::unique_ptr<Acquisition> make_acquisition(const SensorStageConfig& config);

}  // namespace spadgen::sensor
