// The gate sweep (3D, the paper's Fig. 1(b)): K gate positions from start to stop in steps, each image
// the sum of N binary frames of C laser cycles. At position k a pixel detects, per cycle, its PDP times
// the gate response h_k = integral g(t) f_eff(t - tau_k - skew) dt of its transient, plus ambient light and
// dark counts over the gate's open time: lambda_k = C (PDP h_k + (PDP_amb ambient + DCR) open_time).
#include <algorithm>
#include <cmath>

#include "core/units.h"
#include "sensor/acquisition/acquisition.h"
#include "sensor/model/gate.h"
#include "sensor/response/gate_response.h"
#include "sensor/model/pixel_maps.h"

namespace spadgen::sensor {
namespace {

class GateSweep final : public Acquisition {
 public:
  GateSweep(const SensorStageConfig& c)
      : cfg_(c.acquisition),
        delay_s_(c.sensor.gate.delay_s),
        gate_cfg_(c.sensor.gate),
        skew_on_(c.sensor.skew),
        gate_(build_gate_shape(c.sensor.gate, c.laser)) {
    const GateSweepConfig& s = cfg_.gate_sweep;
    K_ = static_cast<int>(s.positions());
    for (int k = 0; k < K_; ++k) positions_.push_back(s.start_s + k * s.step_s);
  }

  int K() const override { return K_; }
  uint32_t frames_per_k() const override { return static_cast<uint32_t>(cfg_.frames); }
  std::string name() const override { return to_string(AcquisitionMode::GateSweep); }
  bool needs_transient() const override { return true; }
  const GateShape* gate() const override { return &gate_; }
  double nominal_gate_length_s() const override { return gate_.nominal_length_s; }
  const std::vector<double>& gate_positions_s() const override { return positions_; }
  bool tabulated_counts() const override { return true; }

  // The union of every pixel's gate window at every position. The knots span the whole effective gate
  // including the instrument response (to 1e-15 of Gaussian tails), so no margin is needed beyond rounding
  // outward to whole bins.
  TimeAxis required_window(const PixelMaps& maps, double bin_width_s, double period_s) const override {
    TimeAxis axis;
    axis.bin_width_s = bin_width_s;
    axis.period_s = period_s;
    const double lo = positions_.front() + delay_s_ + maps.min_skew_s() + gate_.support_begin();
    const double hi = positions_.back() + delay_s_ + maps.max_skew_s() + gate_.support_end(maps.max_dL_s());
    axis.start_s = std::floor(lo / bin_width_s) * bin_width_s;
    axis.bins = static_cast<int64_t>(std::ceil((hi - axis.start_s) / bin_width_s));
    return axis;
  }

  struct Edges final : TileSetup {
    EdgeBins rise, fall;
  };
  struct Prefix final : Scratch {
    TransientPrefix prefix;
  };
  std::unique_ptr<TileSetup> setup(const TimeAxis& axis) const override {
    auto e = std::make_unique<Edges>();
    if (axis.bins > 0) {
      e->rise = edge_in_bins(gate_.rise, axis.bin_width_s);
      e->fall = edge_in_bins(gate_.fall, axis.bin_width_s);
    }
    return e;
  }
  std::unique_ptr<Scratch> scratch() const override { return std::make_unique<Prefix>(); }

  void rates(const PixelDetection& d, const PixelLight& in, const TileSetup* setup, Scratch* scratch,
             double* out) const override {
    const PixelParams& px = *d.params;
    const auto& edges = static_cast<const Edges&>(*setup);
    TransientPrefix& prefix = static_cast<Prefix*>(scratch)->prefix;
    const double C = static_cast<double>(cfg_.cycles_per_frame);
    const double B = (d.pdp_ambient * in.ambient_rate + px.dcr_cps) * gate_.open_time(px.dL_s);
    std::fill(out, out + K_, 0.0);
    const TimeAxis& axis = *in.axis;
    if (in.transient != nullptr && axis.bins > 0) {
      const double dt = axis.bin_width_s;
      const double b0 = (positions_[0] + delay_s_ + px.skew_s - axis.start_s) / dt;
      const double step = cfg_.gate_sweep.step_s / dt;
      if (const int64_t s = integer_step(step); s > 0) {  // the step is a whole number of bins
        if (prefix.build_bins(in.transient, in.bin_lo, in.bin_hi)) {
          accumulate_edge_response_int(prefix, edges.rise, b0, s, K_, 1.0, out);
          accumulate_edge_response_int(prefix, edges.fall, b0 + px.dL_s / dt, s, K_, -1.0, out);
        }
      } else if (prefix.build(in.transient, axis.bins)) {
        accumulate_edge_response(prefix, edges.rise, b0, step, K_, 1.0, out);
        accumulate_edge_response(prefix, edges.fall, b0 + px.dL_s / dt, step, K_, -1.0, out);
      }
    }
    for (int k = 0; k < K_; ++k) out[k] = C * (d.pdp_laser * std::max(out[k], 0.0) + B);
  }

  std::vector<DeclaredOutput> outputs() const override {
    // Labels need gates to say whether an object's rising edge stands out of the noise: a sweep's only.
    return {{"previews/gate_profiles.png", "sampled gate profiles of a few pixels"},
            {"labels.exr", "per object of the ground truth: object<j>.id, edge_counts (counts), edge_snr, detectable (0/1)"}};
  }

  nlohmann::json describe() const override {
    nlohmann::json j;
    j["cycles_per_frame"] = cfg_.cycles_per_frame;
    std::vector<double> ns;
    for (double p : positions_) ns.push_back(p / kNs);
    j["gate_positions_ns"] = ns;
    j["gate_step_ps"] = cfg_.gate_sweep.step_s / kPs;
    const GateConfig& g = gate_cfg_;
    nlohmann::json gj;
    gj["profile"] = g.profile_csv.empty() ? to_string(g.edge_shape) : "table:" + g.profile_csv;
    gj["nominal_length_ns"] = gate_.nominal_length_s / kNs;
    gj["effective_length_ns"] = gate_.open_time_s / kNs;
    gj["plateau"] = gate_.plateau;
    gj["rise_ps"] = gate_.rise_s / kPs;  // (a table's own: the ignored sensor.gate.rise_ps had been given)
    gj["fall_ps"] = gate_.fall_s / kPs;
    gj["delay_ns"] = g.delay_s / kNs;
    gj["irf_fwhm_ps"] = gate_.irf_fwhm_s / kPs;
    gj["knots_per_edge"] = gate_.knots_per_edge;
    gj["knots_exact"] = gate_.exact;
    gj["knot_max_error"] = gate_.max_knot_error;
    gj["grid_ps"] = gate_.grid_s / kPs;
    gj["grid_max_error"] = gate_.max_grid_error;
    // The spreads the maps were drawn with: none when they are the user's (sensor.gate.maps_exr).
    const nlohmann::json none(nullptr);
    gj["skew_spread_fwhm_ps"] = !g.maps_exr.empty() ? none : nlohmann::json(skew_on_ ? g.skew_fwhm_s / kPs : 0.0);
    gj["length_spread_fwhm_ps"] = !g.maps_exr.empty() ? none : nlohmann::json(skew_on_ ? g.length_fwhm_s / kPs : 0.0);
    j["gate"] = gj;
    return j;
  }

 private:
  AcquisitionConfig cfg_;
  double delay_s_;
  GateConfig gate_cfg_;
  bool skew_on_;
  GateShape gate_;
  int K_ = 0;
  std::vector<double> positions_;
};

}  // namespace

std::unique_ptr<Acquisition> make_gate_sweep(const SensorStageConfig& c) {
  return std::make_unique<GateSweep>(c);
}

}  // namespace spadgen::sensor
