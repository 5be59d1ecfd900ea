#include "sensor.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>

#include "core/atomic_max.h"
#include "core/error.h"
#include "core/rng.h"
#include "core/stage_clock.h"
#include "core/units.h"
#include "sensor/model/gate.h"
#include "sensor/model/pdp.h"
#include "sensor/model/pixel_maps.h"
#include "sensor/sampling/batch_kernels.h"
#include "sensor/sampling/frames_kernel.h"
#include "sensor/sampling/frames_tile.h"
#include "sensor/sampling/sampling.h"
#include "sensor/acquisition/acquisition.h"
#include "sensor/acquisition/intensity.h"
#include "sensor/streams.h"

namespace spadgen::sensor {
namespace {

struct TypeInfo {
  std::string name;
  double pdp_laser = 0, pdp_ambient = 0, fill_factor = 0, crosstalk = 0;
  bool single_avalanche = false;
};

// Neighbour offsets; the index is the direction used to key a crosstalk draw.
constexpr int kNbDx[4] = {-1, 1, 0, 0};
constexpr int kNbDy[4] = {0, 0, -1, 1};

}  // namespace

struct SensorModel::Impl {
  SensorStageConfig cfg;
  std::unique_ptr<Acquisition> acq;
  int K = 0;
  uint32_t frames_per_k = 0;
  std::unique_ptr<PixelMaps> maps;
  std::unique_ptr<BinomialSampler> binom;
  std::shared_ptr<const BinomialTable> table;  // counts by tables (modes that ask for them, without frames)
  TypeInfo types[2];
  int halo = 0;

  explicit Impl(const SensorStageConfig& c);
  std::vector<TypeInfo> used_types() const;

  // The directions (kNbDx, kNbDy) of the neighbours that can fire pixel (x, y) by crosstalk: inside the
  // sensor, in its section; their count.
  int neighbours(int x, int y, int* list) const {
    const int W = cfg.camera.width_px, H = cfg.camera.height_px, sec = maps->section_of_row(y);
    int c = 0;
    for (int d = 0; d < 4; ++d) {
      const int nx = x + kNbDx[d], ny = y + kNbDy[d];
      if (nx < 0 || ny < 0 || nx >= W || ny >= H || maps->section_of_row(ny) != sec) continue;
      list[c++] = d;
    }
    return c;
  }
  // n xt of a pixel of type `type` at (x, y) (SensorModel::crosstalk_share).
  double crosstalk_share(int type, int x, int y) const {
    if (!(types[type].crosstalk > 0.0)) return 0.0;
    int list[4];
    return neighbours(x, y, list) * types[type].crosstalk;
  }

  // lambda of every k for one pixel (no crosstalk).
  void lambda(const PixelParams& px, const PixelLight& in, const Acquisition::TileSetup* setup,
              Acquisition::Scratch* scratch, double* out) const {
    const TypeInfo& t = types[px.type];
    acq->rates({&px, t.pdp_laser * px.pdp_scale, t.pdp_ambient * px.pdp_scale}, in, setup, scratch, out);
  }
};

SensorModel::Impl::Impl(const SensorStageConfig& c) : cfg(c) {
  acq = make_acquisition(cfg);
  K = acq->K();
  frames_per_k = acq->frames_per_k();
  maps = std::make_unique<PixelMaps>(cfg, acq->nominal_gate_length_s());
  binom = std::make_unique<BinomialSampler>(frames_per_k);
  if (!cfg.outputs.frames && acq->tabulated_counts())
    table = BinomialTable::get(frames_per_k);
  const PixelTypeConfig* tc[2] = {&cfg.sensor.pixel_A, &cfg.sensor.pixel_B};
  const std::vector<int> used = maps->layout().types();
  for (int t = 0; t < 2; ++t) {
    types[t].name = to_string(t == 0 ? PixelPreset::PixelA : PixelPreset::PixelB);
    // A design the preset does not use is not built: its keys do nothing (a warning says so), and one
    // its PDP curve would refuse (a wavelength where the built-in curve is zero) refused the whole run.
    if (std::find(used.begin(), used.end(), t) == used.end()) continue;
    const PdpCurve curve = PdpCurve::from_config(*tc[t], "sensor." + types[t].name);
    // A measured table that stops short of the laser's wavelength makes its pixels blind to the laser (PDP 0
    // outside the table): a mistake, not a sensor.
    const double nm = cfg.laser.wavelength_m / kNm;
    if (!tc[t]->pdp_csv.empty() && std::find(used.begin(), used.end(), t) != used.end() &&
        !(nm >= curve.first_nm() && nm <= curve.last_nm())) {
      std::ostringstream m;
      m << "'" << tc[t]->pdp_csv << "' covers " << curve.first_nm() << " to " << curve.last_nm() << " nm, not the laser's " << nm
        << " nm (laser.wavelength_nm): its pixels would not see the laser; expected a table that covers it";
      throw KeyError("/sensor/" + types[t].name + "/pdp_csv", m.str());
    }
    // Each pixel's PDP is the curve times 1 + pdp_nonuniformity z (z truncated at 5): a probability at most 1
    // (a pdp_peak of 1 gave half the pixels a PDP above 1; a peak wavelength off the built-in curve's own
    // peak scaled it past 1 at 520 nm).
    const double spread = cfg.sensor.pdp_nonuniformity ? tc[t]->pdp_nonuniformity : 0.0;
    if (const double most = curve.max() * (1.0 + 5.0 * spread); most > 1.0) {
      // Named by the key that sets the curve's most: the table, else the peak, else (a peak of at most 1 the
      // built-in curve exceeds elsewhere) the peak's wavelength.
      const std::string key = "sensor." + types[t].name;
      const bool by_wavelength = tc[t]->pdp_csv.empty() && curve.max() > tc[t]->pdp_peak * (1.0 + 1e-12);
      const std::string pointer = "/sensor/" + types[t].name + (!tc[t]->pdp_csv.empty() ? "/pdp_csv" : by_wavelength ? "/pdp_peak_wavelength_nm" : "/pdp_peak");
      std::ostringstream m;
      if (!tc[t]->pdp_csv.empty()) m << "'" << tc[t]->pdp_csv << "': the PDP curve reaches " << curve.max();
      else if (by_wavelength)
        m << "found " << tc[t]->pdp_peak_wavelength_m / kNm << " nm, off the built-in curve's own peak (520 nm): scaled so that PDP there is "
          << key << ".pdp_peak " << tc[t]->pdp_peak << ", the curve reaches " << curve.max();
      else m << "found " << tc[t]->pdp_peak << ": the PDP curve reaches " << curve.max();
      if (spread > 0.0) m << ", and " << key << ".pdp_nonuniformity " << spread << " spreads it to " << most << " (times 1 + 5 sigma)";
      m << "; expected a photon detection probability of at most 1: lower the curve"
        << (spread > 0.0 ? ", or the spread (sensor.pdp_nonuniformity = false for none)" : "");
      throw KeyError(pointer, m.str());
    }
    types[t].pdp_laser = curve.at(cfg.laser.wavelength_m);
    types[t].pdp_ambient = curve.band_average(cfg.ambient.wavelength_m, cfg.ambient.bandwidth_m);
    types[t].fill_factor = tc[t]->fill_factor;
    types[t].crosstalk = cfg.sensor.crosstalk ? tc[t]->crosstalk_probability : 0.0;
    types[t].single_avalanche = tc[t]->single_avalanche_per_frame;
  }
  for (const TypeInfo& t : used_types())
    if (t.crosstalk > 0.0) halo = 1;
}

std::vector<TypeInfo> SensorModel::Impl::used_types() const {
  std::vector<TypeInfo> out;
  for (int t : maps->layout().types()) out.push_back(types[t]);
  return out;
}

SensorModel::SensorModel(const SensorStageConfig& config) : impl_(std::make_unique<Impl>(config)) {}
SensorModel::~SensorModel() = default;

int SensorModel::K() const { return impl_->K; }
const std::vector<double>& SensorModel::gate_positions_s() const { return impl_->acq->gate_positions_s(); }
const std::vector<double>& SensorModel::exposures_s() const { return impl_->acq->exposures_s(); }
const Acquisition& SensorModel::acquisition() const { return *impl_->acq; }
const PixelLayout& SensorModel::layout() const { return impl_->maps->layout(); }
std::vector<double> SensorModel::row_fill_factor() const { return layout().row_fill_factor(impl_->cfg.sensor); }
std::vector<double> SensorModel::row_ambient_floor() const {
  const SensorStageConfig& c = impl_->cfg;
  // the gate's effective open time (its integral: a tabulated gate's too), as the counts' background sees it
  const GateShape* gate = impl_->acq->gate();
  const double open_s = gate ? gate->open_time_s * double(c.acquisition.cycles_per_frame) : 0.0;
  const double tf = PixelMaps::temperature_factor(c.sensor.temperature_C);
  // a main pixel's dark count rate, per pixel type (the median is a bisection: once per type, not per row)
  double dcr_of_type[2] = {0.0, 0.0};
  if (c.sensor.dark_counts) {
    dcr_of_type[0] = PixelMaps::dcr_main_median(c.sensor.pixel_A) * tf;
    dcr_of_type[1] = PixelMaps::dcr_main_median(c.sensor.pixel_B) * tf;
  }
  std::vector<double> floor(size_t(c.camera.height_px));
  for (size_t y = 0; y < floor.size(); ++y) {
    const int type = layout().type_of_row(int(y));
    const double pdp = impl_->types[type].pdp_ambient;
    const double dcr = dcr_of_type[type];
    floor[y] = pdp > 0.0 && open_s > 0.0 ? (1.0 / (double(impl_->frames_per_k) * pdp * open_s) + dcr / pdp)
                                         : std::numeric_limits<double>::infinity();
  }
  return floor;
}
int SensorModel::halo() const { return impl_->halo; }
int SensorModel::frames_per_k() const { return static_cast<int>(impl_->frames_per_k); }
const GateShape& SensorModel::gate() const {
  if (const GateShape* g = impl_->acq->gate()) return *g;
  throw Error("sensor: the " + impl_->acq->name() + " acquisition has no gate profile");
}
PixelParams SensorModel::pixel(int x, int y) const { return impl_->maps->at(x, y); }
double SensorModel::pdp_laser(int type) const { return impl_->types[type].pdp_laser; }
double SensorModel::pdp_ambient(int type) const { return impl_->types[type].pdp_ambient; }

void SensorModel::set_gate_maps(std::vector<float> skew_ps, std::vector<float> length_ps) {
  impl_->maps->set_gate_maps(std::move(skew_ps), std::move(length_ps));
}

void SensorModel::set_maps(int width, int height, const std::map<std::string, std::vector<float>>& channels,
                           const std::string& source) {
  const auto& cam = impl_->cfg.camera;
  const std::string key = "sensor.gate.maps_exr ('" + source + "')";
  if (width != cam.width_px || height != cam.height_px)
    throw Error(key + ": expected the full sensor, " + std::to_string(cam.width_px) + " x " +
                std::to_string(cam.height_px) + " pixels, found " + std::to_string(width) + " x " + std::to_string(height));
  auto find = [&](const char* a, const char* b) -> const std::vector<float>& {
    for (const char* name : {a, b})
      if (auto it = channels.find(name); it != channels.end()) return it->second;
    throw Error(key + ": expected a channel named " + a + " (or " + b + ")");
  };
  set_gate_maps(find("skew_ps", "gate_skew_ps"), find("length_ps", "gate_length_ps"));
}

TimeAxis SensorModel::required_window(double bin_width_s) const {
  const Impl& m = *impl_;
  return m.acq->required_window(*m.maps, bin_width_s, 1.0 / m.cfg.laser.repetition_rate_Hz);
}

std::vector<double> SensorModel::pixel_lambda(int x, int y, const float* g, const TimeAxis& axis,
                                              double ambient_rate, double laser_total) const {
  const Impl& m = *impl_;
  std::vector<double> out(static_cast<size_t>(m.K));
  const auto setup = m.acq->setup(axis);
  const auto scratch = m.acq->scratch();
  const PixelLight in{m.acq->needs_transient() ? g : nullptr, &axis, 0, axis.bins, ambient_rate, laser_total};
  m.lambda(m.maps->at(x, y), in, setup.get(), scratch.get(), out.data());
  return out;
}

double SensorModel::crosstalk_share(int x, int y) const { return impl_->crosstalk_share(impl_->maps->at(x, y).type, x, y); }

std::vector<double> SensorModel::return_lambda(const std::vector<Return>& returns, const TimeAxis& axis) const {
  const Impl& m = *impl_;
  const auto K = static_cast<size_t>(m.K);
  std::vector<double> out(returns.size() * K, 0.0);
  if (axis.bins <= 0 || !m.acq->needs_transient()) return out;
  const auto setup = m.acq->setup(axis);
  const auto scratch = m.acq->scratch();
  // One transient for all returns: each sets its bins and clears them again.
  std::vector<float> g(static_cast<size_t>(axis.bins), 0.0f);
  std::vector<int64_t> lit;
  std::vector<double> dark(K);
  for (size_t r = 0; r < returns.size(); ++r) {
    const Return& ret = returns[r];
    if (!std::isfinite(ret.t_s)) continue;
    const auto put = [&](double t) {
      const int64_t b = axis.bin_of(t);
      if (b < 0) return;
      g[size_t(b)] += ret.photons;
      lit.push_back(b);
    };
    if (axis.period_s > 0.0) {
      // The first image at or after the window's start, then one per period up to its end.
      for (double ti = ret.t_s + (std::ceil((axis.start_s - ret.t_s) / axis.period_s) - 1.0) * axis.period_s;
           ti < axis.end_s(); ti += axis.period_s)
        put(ti);
    } else {
      put(ret.t_s);
    }
    if (lit.empty()) continue;
    const auto [lo, hi] = std::minmax_element(lit.begin(), lit.end());
    const PixelParams px = m.maps->at(ret.x, ret.y);
    double* o = out.data() + r * K;
    m.lambda(px, {g.data(), &axis, *lo, *hi + 1, 0.0, ret.photons}, setup.get(), scratch.get(), o);
    m.lambda(px, {nullptr, &axis, 0, 0, 0.0, 0.0}, setup.get(), scratch.get(), dark.data());
    for (size_t k = 0; k < K; ++k) o[k] -= dark[k];
    // Crosstalk its light fires through the neighbours that can fire this pixel, each taken to receive the
    // same return.
    if (const double share = m.crosstalk_share(px.type, ret.x, ret.y); share > 0.0)
      for (size_t k = 0; k < K; ++k) o[k] += share * (m.types[px.type].single_avalanche ? -std::expm1(-o[k]) : o[k]);
    for (int64_t b : lit) g[size_t(b)] = 0.0f;
    lit.clear();
  }
  return out;
}

SensorTile SensorModel::process(const TransientTile& t) const {
  return std::move(process(t, {impl_->cfg.noise_seed}).front());
}

std::vector<SensorTile> SensorModel::process(const TransientTile& t, const std::vector<uint64_t>& noise_seeds) const {
  const Impl& m = *impl_;
  const int W = m.cfg.camera.width_px, H = m.cfg.camera.height_px;
  const PixelRect& rect = t.rect;
  if (rect.x0 < 0 || rect.y0 < 0 || rect.x1() > W || rect.y1() > H)
    throw Error("sensor: tile outside the sensor's " + std::to_string(W) + " x " + std::to_string(H) + " pixels");
  // With crosstalk the 4 neighbours' rates are needed; without, only the tile's own pixels.
  const PixelRect region = grow_clipped(rect, m.halo, W, H);
  const PixelRect& dr = t.data_rect;
  if (region.x0 < dr.x0 || region.y0 < dr.y0 || region.x1() > dr.x1() || region.y1() > dr.y1())
    throw Error("sensor: a tile's data must cover its pixels grown by the sensor's halo of " +
                std::to_string(m.halo) + " pixel(s)");
  const size_t ndata = static_cast<size_t>(dr.count());
  if (t.ambient_rate.size() != ndata) throw Error("sensor: TransientTile::ambient_rate must hold one value per data pixel");
  const bool transient = m.acq->needs_transient();
  if (transient) {
    if (t.axis.bins <= 0) throw Error("sensor: the " + m.acq->name() + " acquisition needs a rendered transient (time axis with bins)");
    if (t.transient.size() != ndata * static_cast<size_t>(t.axis.bins))
      throw Error("sensor: TransientTile::transient must hold data_rect pixels x axis.bins values");
    if ((!t.bin_lo.empty() || !t.bin_hi.empty()) && (t.bin_lo.size() != ndata || t.bin_hi.size() != ndata))
      throw Error("sensor: TransientTile::bin_lo / bin_hi must be empty or hold one value per data pixel");
  } else if (m.cfg.acquisition.intensity.laser_on && t.laser_total.size() != ndata) {
    throw Error("sensor: TransientTile::laser_total must hold one value per data pixel");
  }

  const int K = m.K;
  const size_t Ks = static_cast<size_t>(K);
  const auto setup = m.acq->setup(t.axis);
  const bool frames = m.cfg.outputs.frames;
  auto pixel_index = [W](int x, int y) { return streams::pixel_index(x, y, W); };
  // lambda of every k for the region's pixels (the tile and its halo), [region.index(x, y) * K + k]; and
  // p, q of each pixel's own avalanches where its neighbours (crosstalk of pixel B) or its frames need them.
  const size_t nreg = static_cast<size_t>(region.count());
  // Not value-initialised (every entry read is written first): zeroing megabytes per tile cost page faults
  // and memset time. q is kept only for frames; without frames only pixel B's neighbours read p.
  // Large ones (own_prob is 9.7 MB for a 34 x 34 region of the paper's sweep) in huge pages, whose mappings
  // the next tile's arrays of the same size reuse (core/tile.h, allocate_buffer).
  const auto uninit = [](size_t count) { return std::vector<double, DefaultInitAllocator<double>>(count); };
  auto lam = uninit(nreg * Ks);
  const bool ranges = transient && t.bin_lo.size() == ndata;
  const bool own_probs = frames || m.halo > 0;
  auto own_p = uninit(own_probs ? nreg * Ks : 0);
  // With frames: every region pixel's Prob {p, q, -lambda} gate-major ([k * nreg + region index]), so a
  // row at one gate position is the contiguous input of sample_bits_batch.
  auto own_prob = std::vector<Prob, DefaultInitAllocator<Prob>>(frames ? nreg * Ks : 0);
  std::vector<PixelParams> params(nreg);
  std::atomic<float> laser_open_rate{0.0f};  // SensorTile::laser_open_rate
  const double cycles = static_cast<double>(m.cfg.acquisition.cycles_per_frame);
  tbb::parallel_for(tbb::blocked_range<int>(region.y0, region.y1()), [&](const tbb::blocked_range<int>& rows) {
    const auto scratch = m.acq->scratch();
    double open_max = 0.0;
    for (int y = rows.begin(); y < rows.end(); ++y) {
      throw_if_interrupted();  // a row of K gate responses; with long sweeps a tile takes seconds
      for (int x = region.x0; x < region.x1(); ++x) {
        const size_t ri = static_cast<size_t>(region.index(x, y));
        const auto di = static_cast<size_t>(dr.index(x, y));
        params[ri] = m.maps->at(x, y);
        const float* g = transient ? t.transient.data() + di * static_cast<size_t>(t.axis.bins) : nullptr;
        const double laser_total = t.laser_total.size() == ndata ? t.laser_total[di] : 0.0;
        int64_t lo = 0, hi = t.axis.bins;  // the renderer's range of non-zero bins, when it gave one
        if (ranges) {
          lo = std::clamp<int64_t>(t.bin_lo[di], 0, t.axis.bins);
          hi = std::clamp<int64_t>(t.bin_hi[di], lo, t.axis.bins);
        }
        m.lambda(params[ri], {g, &t.axis, lo, hi, t.ambient_rate[di], laser_total}, setup.get(), scratch.get(), lam.data() + ri * Ks);
        if (rect.contains(x, y))  // (with the share its neighbours' avalanches fire in it, at most n xt of its own)
          open_max = std::max(open_max, cycles * m.types[params[ri].type].pdp_laser * params[ri].pdp_scale * laser_total *
                                            (1.0 + m.crosstalk_share(params[ri].type, x, y)));
        // without frames only pixel B's neighbours read p (pixel A's read lambda); sections keep one type
        if (frames)
          probabilities(lam.data() + ri * Ks, Ks, own_prob.data() + ri, nreg, own_p.data() + ri * Ks);
        else if (own_probs && m.types[params[ri].type].single_avalanche)
          probabilities(lam.data() + ri * Ks, Ks, own_p.data() + ri * Ks, nullptr);
      }
    }
    store_max(laser_open_rate, float(open_max));
  });

  // From here the temporal noise: its own stage of a run's time (app/pipeline.cpp), the rates above being
  // the enclosing one.
  const StageClock::Scope noise_time(StageClock::current(), StageClock::kSensorNoise);

  // The frames' layout of this tile (frames_tile), the same for every gate position and noise seed: the
  // crosstalk law of every region row, each tile row's neighbour directions (not across sections or the
  // image's edges), the streams' pixel indices.
  FramesTileShape shape;
  std::vector<uint64_t> region_ids;
  if (frames) {
    shape.width = rect.width;
    shape.height = rect.height;
    shape.region_width = region.width;
    shape.region_height = region.height;
    shape.tile_x = rect.x0 - region.x0;
    shape.tile_y = rect.y0 - region.y0;
    shape.frames = m.frames_per_k;
    const PixelLayout& lay = m.maps->layout();
    for (int y = region.y0; y < region.y1(); ++y) {
      const TypeInfo& ty = m.types[lay.type_of_row(y)];
      shape.region_row_law.push_back({ty.crosstalk, ty.single_avalanche});
      for (int x = region.x0; x < region.x1(); ++x) region_ids.push_back(pixel_index(x, y));
    }
    for (int y = rect.y0; y < rect.y1(); ++y) {
      unsigned dirs = 0;
      if (m.types[lay.type_of_row(y)].crosstalk > 0.0) {
        const int sec = lay.section_of_row(y);
        dirs = 1u | 2u;
        if (y > 0 && lay.section_of_row(y - 1) == sec) dirs |= 4u;
        if (y + 1 < H && lay.section_of_row(y + 1) == sec) dirs |= 8u;
      }
      shape.row_dirs.push_back(static_cast<uint8_t>(dirs));
      for (int x = rect.x0; x < rect.x1(); ++x) {
        shape.pixel_lo.push_back(static_cast<uint32_t>(pixel_index(x, y)));
        shape.pixel_hi.push_back(static_cast<uint32_t>(pixel_index(x, y) >> 32));
      }
    }
    shape.left_edge = rect.x0 == 0;
    shape.right_edge = rect.x1() == W;
    shape.finish();
  }

  // Everything above is the same for every realisation of the temporal noise; what follows draws it.
  // So are the rates with crosstalk and the expectations: the first realisation computes them, the others
  // reuse them (without frames, the counts' rates are kept per pixel for that).
  std::vector<SensorTile> outs;
  outs.reserve(noise_seeds.size());
  // The frames' working memory of each thread, for every gate position and realisation it takes: a region's
  // words (own; + wpp: the zero words frames_tile packs padding from) and frames_tile's scratch. (Made per
  // task, each task zeroed its words and grew its scratch again.)
  struct FramesWork {
    std::vector<uint64_t> own;
    FramesTileScratch scratch;
  };
  tbb::enumerable_thread_specific<FramesWork> frames_work;
  const bool keep_eff = noise_seeds.size() > 1 && !frames;
  std::vector<double> eff_tile(keep_eff ? static_cast<size_t>(rect.count()) * Ks : 0);
  for (const uint64_t seed : noise_seeds) {
    const bool first = outs.empty();
    SensorTile out;
    out.rect = rect;
    out.K = K;
    const size_t n = static_cast<size_t>(rect.count());
    const uint32_t N = m.frames_per_k;
    const bool keep_rate = m.cfg.outputs.detection_rate;
    const double rate_limit = double(std::numeric_limits<float>::max()) / (2.0 * double(N));
    const auto too_bright = [&](double most) {
      std::ostringstream text;
      text << "the light is too bright for the outputs: a pixel's detection rate reaches " << most
        << " per frame, beyond the " << rate_limit << " (float32's 3.4e38 over 2 N, N = " << N
        << " frames per gate position or exposure) that detection_rate.npy and the HDR inversion's photons can hold: lower laser.average_power_mW, "
           "ambient.illuminance_lux or the light of a frame (acquisition.cycles_per_frame, acquisition.intensity.exposure_us), "
           "or switch outputs.detection_rate off (in a gate sweep outputs.ground_truth too: labels.exr reads the rates)";
      return text.str();
    };
    if (first) {
      out.expected.assign(n * Ks, 0.0f);
      if (keep_rate) out.rate.assign(n * Ks, 0.0f);
    } else {
      out.expected = outs.front().expected;
      out.rate = outs.front().rate;
    }
    out.laser_open_rate = laser_open_rate.load();
    out.counts.assign(n * Ks, 0);
    const size_t bpr = static_cast<size_t>((rect.width + 7) / 8);
    if (frames) {
      out.frames_per_k = static_cast<int>(N);
      out.frames.resize(Ks * N * static_cast<size_t>(rect.height) * bpr);  // every byte packed below
    }
    const size_t wpp = (N + 63) / 64;

    auto nb_index = [&](int x, int y, int d) {
      return static_cast<size_t>(region.index(x + kNbDx[d], y + kNbDy[d]));
    };

    // Per pixel of the tile, all K at once: the rate with crosstalk (pixel A: every neighbour avalanche may
    // fire this pixel, a thinned Poisson process; pixel B: a neighbour avalanches at most once per frame,
    // firing this pixel with probability xt), its expected counts N p and, without frames, the counts.
    const Rng counts_base = streams::counts(seed, 0, 0);
    const uint32_t counts_key[2] = {counts_base.key().v[0], counts_base.key().v[1]};
    if (first || !frames) tbb::parallel_for(tbb::blocked_range<int>(rect.y0, rect.y1()), [&](const tbb::blocked_range<int>& rows) {
      KernelScratch s;
      s.reserve(Ks);
      std::vector<double> eff(Ks), pe(Ks), qe(Ks);
      // One row's results pixel-major ([x K + k]), written to the k-major outputs after the row by
      // transpose_rows (a gather of a vector of pixels per k) instead of K strided stores per pixel.
      const size_t rw = static_cast<size_t>(rect.width);
      std::vector<float> row_exp(rw * Ks), row_rate(keep_rate ? rw * Ks : 0);
      std::vector<uint16_t> row_cnt(frames ? 0 : rw * Ks + 1);  // + 1: transpose_rows reads one beyond
      for (int y = rows.begin(); y < rows.end(); ++y) {
        throw_if_interrupted();
        for (int x = rect.x0; x < rect.x1(); ++x) {
          const auto ri = static_cast<size_t>(region.index(x, y));
          const auto xi = static_cast<size_t>(x - rect.x0);
          double* cached = keep_eff ? eff_tile.data() + static_cast<size_t>(rect.index(x, y)) * Ks : nullptr;
          if (!first) {  // another realisation of the counts: only the draws are new
            if (m.table) binomial_counts(cached, Ks, counts_key, pixel_index(x, y), *m.table, s);
            else binomial_counts(cached, Ks, counts_key, pixel_index(x, y), *m.binom, s);
            std::transform(s.x.begin(), s.x.begin() + static_cast<ptrdiff_t>(Ks), row_cnt.data() + xi * Ks,
                           [](auto v) { return static_cast<uint16_t>(v); });
            continue;
          }
          float* ex = row_exp.data() + xi * Ks;
          const TypeInfo& ty = m.types[params[ri].type];
          int nb[4];
          const int nnb = ty.crosstalk > 0.0 ? m.neighbours(x, y, nb) : 0;
          const double* l = lam.data() + ri * Ks;
          if (nnb > 0) {
            const double* nbv[4];
            for (int i = 0; i < nnb; ++i)
              nbv[i] = (ty.single_avalanche ? own_p.data() : lam.data()) + nb_index(x, y, nb[i]) * Ks;
            crosstalk_rates(l, Ks, nbv, nnb, ty.crosstalk, ty.single_avalanche, eff.data());
            l = eff.data();
          }
          if (keep_rate) {
            std::transform(l, l + Ks, row_rate.data() + xi * Ks, [](double v) { return static_cast<float>(v); });
            // detection_rate.npy holds float32, and the 2D HDR inversion's photons are N times a rate (two
            // exposures: 2N): a rate beyond them would be written as inf (a 20 m aperture 1 mm from a target,
            // 1e12 cycles per frame).
            // (an OR of comparisons, no dependence between them; the maximum only for the message: max_element's
            // chain of comparisons through memory took a tenth of the counts sweep)
            bool over = false;
            for (size_t k = 0; k < Ks; ++k) over |= l[k] > rate_limit;
            if (over) throw Error(too_bright(*std::max_element(l, l + Ks)));
          }
          if (cached) std::copy(l, l + Ks, cached);
          if (!frames) {
            if (m.table) binomial_counts(l, Ks, counts_key, pixel_index(x, y), *m.table, s);
            else binomial_counts(l, Ks, counts_key, pixel_index(x, y), *m.binom, s);
            uint16_t* cn = row_cnt.data() + xi * Ks;
            for (size_t k = 0; k < Ks; ++k) {
              ex[k] = static_cast<float>(static_cast<double>(N) * s.p[k] + 0.0);  // + 0.0: p = -expm1(-0) is -0
              cn[k] = static_cast<uint16_t>(s.x[k]);
            }
          } else {
            const double* p = own_p.data() + ri * Ks;
            if (nnb > 0) {
              probabilities(l, Ks, pe.data(), qe.data());
              p = pe.data();
            }
            for (size_t k = 0; k < Ks; ++k) ex[k] = static_cast<float>(static_cast<double>(N) * p[k] + 0.0);
          }
        }
        const size_t o0 = static_cast<size_t>(rect.index(rect.x0, y));
        if (first) transpose_rows(row_exp.data(), rw, Ks, out.expected.data() + o0, n);
        if (first && keep_rate) transpose_rows(row_rate.data(), rw, Ks, out.rate.data() + o0, n);
        if (!frames) transpose_rows(row_cnt.data(), rw, Ks, out.counts.data() + o0, n);
      }
    });

    if (frames) {
      // Per gate position: every region pixel's own avalanches (its keyed stream, identical in whichever tile
      // owns it), then crosstalk simulated from the neighbours' bits, counts as popcounts, packed frames
      // (frames_tile). The same buffers serve every gate position a task takes.
      const Rng xt_base = streams::crosstalk(seed, 0, 0);
      const uint32_t xt_key[2] = {xt_base.key().v[0], xt_base.key().v[1]};
      const size_t frame_bytes = static_cast<size_t>(N) * static_cast<size_t>(rect.height) * bpr;
      tbb::parallel_for(tbb::blocked_range<int>(0, K, 1), [&](const tbb::blocked_range<int>& ks) {
        FramesWork& work = frames_work.local();
        // every region pixel's words are written at each gate position (sample_bits_batch) before they are read
        if (work.own.size() != nreg * wpp + wpp) work.own.assign(nreg * wpp + wpp, 0);
        std::vector<uint64_t>& own = work.own;
        FramesTileScratch& scratch = work.scratch;
        for (int k = ks.begin(); k < ks.end(); ++k) {
          throw_if_interrupted();  // one gate position's frames of the tile: N x pixels bits
          const auto kk = static_cast<size_t>(k);
          sample_bits_batch(seed, kk, region_ids.data(), nreg, *m.binom, own_prob.data() + kk * nreg, own.data());
          frames_tile(shape, xt_key, static_cast<uint32_t>(k), own_prob.data() + kk * nreg, own.data(),
                      out.counts.data() + kk * n, out.frames.data() + kk * frame_bytes, scratch);
        }
      });
    }

    m.acq->finish_tile(out);
    outs.push_back(std::move(out));
  }
  return outs;
}

SensorMapsTile SensorModel::maps(const PixelRect& rect) const {
  const Impl& m = *impl_;
  SensorMapsTile t;
  t.rect = rect;
  const auto n = static_cast<size_t>(rect.count());
  t.gate_skew_ps.resize(n);
  t.gate_length_ps.resize(n);
  t.dcr_cps.resize(n);
  t.pde.resize(n);
  t.pde_ambient.resize(n);
  for (int y = rect.y0; y < rect.y1(); ++y)
    for (int x = rect.x0; x < rect.x1(); ++x) {
      const auto i = static_cast<size_t>(rect.index(x, y));
      const PixelParams p = m.maps->at(x, y);
      const TypeInfo& ty = m.types[p.type];
      t.gate_skew_ps[i] = static_cast<float>(p.skew_s / kPs);
      t.gate_length_ps[i] = static_cast<float>((m.acq->nominal_gate_length_s() + p.dL_s) / kPs);
      t.dcr_cps[i] = static_cast<float>(p.dcr_cps);
      const double collected = p.pdp_scale * ty.fill_factor * m.cfg.camera.optics_transmission;
      t.pde[i] = static_cast<float>(ty.pdp_laser * collected);
      t.pde_ambient[i] = static_cast<float>(ty.pdp_ambient * collected);
    }
  return t;
}

double linearise_counts(double counts, int frames, bool dual, double ratio) {
  return linearise(counts, static_cast<double>(frames), dual, ratio);
}

nlohmann::json SensorModel::describe() const {
  const Impl& m = *impl_;
  const AcquisitionConfig& a = m.cfg.acquisition;
  nlohmann::json j = m.acq->describe();
  j["mode"] = to_string(a.mode);
  j["K"] = m.K;
  j["frames"] = a.frames;
  j["frames_per_k"] = m.frames_per_k;
  j["N_sat"] = a.frames;
  j["frame_rate_fps"] = a.frame_rate_Hz;
  j["photon_convention"] =
      "transient and ambient inputs are photons on the photosensitive area (fill factor and optics already "
      "applied); detections = PDP x photons";
  if (j.contains("gate")) j["gate"]["user_maps"] = m.maps->has_user_maps();
  nlohmann::json types = nlohmann::json::array();
  const double tf = PixelMaps::temperature_factor(m.cfg.sensor.temperature_C);
  for (const TypeInfo& t : m.used_types()) {
    const PixelTypeConfig& c = t.name == to_string(PixelPreset::PixelA) ? m.cfg.sensor.pixel_A : m.cfg.sensor.pixel_B;
    types.push_back({{"name", t.name},
                     {"pdp_laser", t.pdp_laser},
                     {"pdp_ambient_band", t.pdp_ambient},
                     {"fill_factor", t.fill_factor},
                     {"pde_laser", t.pdp_laser * t.fill_factor * m.cfg.camera.optics_transmission},
                     {"crosstalk_probability", t.crosstalk},
                     {"single_avalanche_per_frame", t.single_avalanche},
                     {"dcr_median_cps", m.cfg.sensor.dark_counts ? c.dcr_median_cps * tf : 0.0},
                     {"dcr_main_median_cps", m.cfg.sensor.dark_counts ? PixelMaps::dcr_main_median(c) * tf : 0.0}});
  }
  j["pixel_types"] = types;
  j["temperature_C"] = m.cfg.sensor.temperature_C;
  j["dcr_temperature_factor"] = tf;
  j["crosstalk"] = {{"enabled", m.halo > 0}, {"neighbours", "4 nearest, not across array sections"}};
  j["sampling"] = {{"counts", m.cfg.outputs.frames ? "popcount of the sampled frames"
                              : m.table ? "Binomial(N, p) exactly: thinning at a 1/4096 grid, 64-bit CDF tables, then a second round"
                                        : "Binomial(N, p) by exact inversion"},
                   {"bernoulli", "64-bit threshold, top byte first (dense) or binomial + uniform subset (p or 1-p <= 1/512)"},
                   {"simd_target", dense_bits_target()}};
  return j;
}

}  // namespace spadgen::sensor
