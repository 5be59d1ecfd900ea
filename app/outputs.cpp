#include "app/outputs.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <mutex>
#include <numeric>
#include <set>
#include <type_traits>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "app/resources.h"
#include "app/staging.h"
#include "core/atomic_max.h"
#include "core/units.h"
#include "writers/previews.h"

namespace spadgen::app {
using writers::NpyWriter;

namespace {

// A few pixels whose gate profiles the preview plots: the centre and points on the diagonals.
std::vector<std::pair<int, int>> profile_pixels(const PixelRect& img) {
  std::vector<std::pair<int, int>> p;
  for (const auto& [fx, fy] : std::vector<std::pair<double, double>>{{0.5, 0.5}, {0.25, 0.5}, {0.75, 0.5}, {0.5, 0.25}, {0.5, 0.75}}) {
    const int x = img.x0 + std::min(img.width - 1, int(fx * img.width));
    const int y = img.y0 + std::min(img.height - 1, int(fy * img.height));
    if (std::find(p.begin(), p.end(), std::pair{x, y}) == p.end()) p.push_back({x, y});
  }
  return p;
}

PixelRect transient_crop(const RunConfig& c, const PixelRect& img) { return c.outputs.transient_crop.value_or(img); }

const sensor::DeclaredOutput* find_declared(const std::vector<sensor::DeclaredOutput>& declared, const std::string& file) {
  for (const sensor::DeclaredOutput& d : declared)
    if (d.file == file) return &d;
  return nullptr;
}

}  // namespace

int64_t StackLayout::bytes() const {
  return std::accumulate(shape.begin(), shape.end(), writers::element_bytes(dtype), std::multiplies<int64_t>());
}

// Zarr chunks (docs/outputs.md, "Storage"): a (K, H, W) stack in blocks of 32 rows x 64 columns holding
// every k, so that a pixel's profile decompresses one chunk, and a chunk is complete (compressed, written,
// freed) once the tiles over its pixels are: the chunks in memory are a band of 32 rows per thread. A
// transient in blocks of 8 x 64 pixels holding every bin (mostly zeros: they compress to little whatever
// their size, and a band of them stays small).
constexpr int64_t kChunkRows = 32, kChunkColumns = 64;
constexpr int64_t kTransientChunkRows = 8;

std::vector<StackLayout> stack_layout(const RunConfig& c, const sensor::SensorModel& sensor, const PixelRect& img,
                                      const TimeAxis& axis) {
  const int64_t K = sensor.K(), frames = sensor.frames_per_k();
  const PixelRect tc = transient_crop(c, img);
  const std::vector<int64_t> khw{K, img.height, img.width}, hwt{tc.height, tc.width, axis.bins};
  const bool zarr = c.outputs.storage == Storage::Zarr;
  const std::vector<int64_t> khw_chunks{K, kChunkRows, kChunkColumns}, hwt_chunks{kTransientChunkRows, kChunkColumns, axis.bins};
  const std::vector<std::string> khw_dims{"k", "y", "x"}, hwt_dims{"y_transient", "x_transient", "t"};
  using writers::Dtype;
  const auto stack = [&](const std::string& name, Dtype dtype, const std::vector<int64_t>& shape, bool written,
                         bool per_k, std::string what, std::string unit) {
    StackLayout l{name + (zarr ? ".zarr" : ".npy"), dtype, shape, written, {}, std::move(what), std::move(unit),
                  per_k ? khw_dims : hwt_dims};
    if (zarr) l.chunks = per_k ? khw_chunks : hwt_chunks;
    return l;
  };
  std::vector<StackLayout> s(kStackCount);
  s[kExpectedCounts] = stack("expected_counts", Dtype::F32, khw, c.outputs.expected_counts, true,
                             "noise-free expected counts N (1 - exp(-lambda_k)), N = acquisition.frames_per_k", "counts");
  s[kDetectionRate] = stack("detection_rate", Dtype::F32, khw, c.outputs.detection_rate, true,
                            "lambda_k: mean avalanches per binary frame at gate position (or exposure) k, noise-free, "
                            "crosstalk, dark counts and ambient light included", "avalanches per frame");
  // Counts never exceed the frames summed into them.
  s[kCounts] = stack("counts", frames <= 255 ? Dtype::U8 : Dtype::U16, khw, c.outputs.counts, true,
                     "sampled counts: the binary frames of gate position (or exposure) k with an avalanche", "counts");
  // One bit per frame and pixel, 8 pixels of a row to a byte: random bits, which no compressor shrinks,
  // so a .npy whatever the storage.
  s[kFrames] = {"frames.npy", Dtype::U8, {K, frames, img.height, (img.width + 7) / 8}, c.outputs.frames, {},
                "binary frames, 8 pixels per byte along x, least significant bit first", "", {"k", "n", "y", "x_byte"}};
  s[kTransient] = stack("transient", Dtype::F32, hwt, c.outputs.transient, false,
                        "photons per laser pulse arriving in time bin t (metadata.json time_axis) on the pixel's "
                        "photosensitive area, before PDP", "photons per pulse");
  s[kTransientIndirect] = stack("transient_indirect", Dtype::F32, hwt, c.outputs.transient && c.render.split_direct_indirect,
                                false, "the part of transient carried by paths with two or more scattering vertices "
                                "(direct = transient - transient_indirect)", "photons per pulse");
  return s;
}

bool write_in_bands(const std::vector<StackLayout>& layout, const PixelRect& img, int tile_size, int threads) {
  const int64_t rows = std::min<int64_t>(tile_size, img.height);
  int64_t band = 0;
  for (const StackLayout& s : layout)
    if (s.written && s.chunks.empty() && (s.khw() || s.frames())) band += s.bytes() / std::max(1, img.height) * rows;
  return band * (worker_threads(threads) + 1) <= kBandMemory;
}

std::unique_ptr<writers::StackWriter> open_stack(const StackLayout& s, const std::string& path) {
  if (s.chunks.empty()) return std::make_unique<NpyWriter>(path, s.dtype, s.shape);
  // _ARRAY_DIMENSIONS names the dimensions for xarray.
  const nlohmann::json attributes = {{"_ARRAY_DIMENSIONS", s.dims}, {"description", s.what}, {"units", s.unit},
                                     {"spadgen_version", SPADGEN_VERSION}};
  return std::make_unique<writers::ZarrWriter>(path, s.dtype, s.shape, s.chunks, attributes);
}

nlohmann::json storage_json(const StackLayout& s) {
  if (s.chunks.empty()) return {{"format", "npy"}};
  const writers::ZarrCodec z = writers::ZarrWriter::codec(s.dtype);
  std::vector<int64_t> chunks = s.chunks;  // as the writer clips them to the shape
  for (size_t d = 0; d < chunks.size(); ++d) chunks[d] = std::max<int64_t>(1, std::min(chunks[d], s.shape[d]));
  return {{"format", "zarr"},
          {"chunks", chunks},
          {"compressor", {{"id", "blosc"}, {"cname", "zstd"}, {"clevel", z.clevel}, {"shuffle", z.shuffle}, {"blocksize", z.blocksize}}}};
}

void write_zarr_group(const Staging& staging, const std::string& folder, std::vector<std::string>& files) {
  const std::string file = folder.empty() ? ".zgroup" : folder + "/.zgroup";
  writers::write_file_atomic(staging.path(file), nlohmann::json{{"zarr_format", 2}}.dump(4) + "\n");
  files.push_back(file);
}

// The per-pixel EXR images, filled tile by tile. Every channel is created here, up front: tiles fill
// them from several threads, and ExrImage::channel creates a channel on first use.
class Outputs::Images {
 public:
  // intensity: the mode's declaration of intensity.exr, null when the mode has none.
  // labels: the mode's declaration of labels.exr when the run's ground truth is at hand, else null.
  Images(const RunConfig& cfg, const PixelRect& img, const sensor::DeclaredOutput* intensity,
         const sensor::DeclaredOutput* labels, int slots, bool laser, const std::set<std::string>& provided)
      : provided_(provided), img_(img), layers_(cfg.render.max_layers), slots_(slots), gt_on_(cfg.outputs.ground_truth),
        laser_traced_(laser), compression_(cfg.outputs.exr_compression), intensity_decl_(intensity),
        labels_decl_(labels),
        gt_(img.width, img.height), laser_(img.width, img.height), ambient_(img.width, img.height),
        maps_(img.width, img.height), intensity_(img.width, img.height), labels_(img.width, img.height) {
    if (gt_on_) {
      for (const char* n : kGroundTruthChannels) gt_ch_.push_back(gt_.channel(n));
      for (int l = 0; l < layers_; ++l) {
        layer_range_.push_back(gt_.channel(layer_name(l, ".range")));
        layer_trans_.push_back(gt_.channel(layer_name(l, ".transmittance")));
      }
      for (const char* n : kObjectChannels) object_ch_.push_back(gt_.channel(n));
      for (int j = 0; j < slots_; ++j)
        for (const char* what : kObjectSlotChannels) object_slot_ch_.push_back(gt_.channel(layer_name(j, what, "object")));
    }
    if (labels_decl_)
      for (int j = 0; j < slots_; ++j)
        for (const char* what : kLabelSlotChannels) label_ch_.push_back(labels_.channel(layer_name(j, what, "object")));
    laser_ch_ = {laser_.channel("photons_per_pulse"), laser_.channel("out_of_window")};
    // Each pixel's standard error, and its paths when a target error decides them (dropped in write() when
    // the light carries none: a sense of light saved before them).
    se_ch_ = laser_.channel("standard_error");
    // (in ambient.exr when the laser is not traced: no laser.exr)
    if (cfg.render.target_relative_error) samples_ch_ = (laser_traced_ ? laser_ : ambient_).channel("samples");
    ambient_ch_ = ambient_.channel("photons_per_second");
    ambient_se_ch_ = ambient_.channel("standard_error");
    maps_ch_ = {maps_.channel("gate_skew_ps"), maps_.channel("gate_length_ps"), maps_.channel("dcr_cps"), maps_.channel("pde"),
                maps_.channel("pde_ambient")};
    if (intensity_decl_) intensity_ch_ = {intensity_.channel("counts"), intensity_.channel("photons")};
    pixel_laser_.assign(size_t(img.count()), 0.0);
    pixel_oow_.assign(size_t(img.count()), 0.0);
    pixel_beyond_.assign(size_t(img.count()), 0.0);
    pixel_samples_.assign(size_t(img.count()), 0);
  }

  void put_ground_truth(const GroundTruthTile& g) {
    layers_cut_.fetch_add(g.layers_cut, std::memory_order_relaxed);
    for_pixels(g.rect, [&](int, int, size_t i, size_t o) {
      const float v[] = {g.range[i], g.z[i], g.normal[3 * i], g.normal[3 * i + 1], g.normal[3 * i + 2],
                         float(g.mesh_id[i]), float(g.material_id[i]), float(g.layer_count[i])};
      for (size_t c = 0; c < gt_ch_.size(); ++c) gt_ch_[c][o] = v[c];
      for (size_t l = 0; l < size_t(layers_); ++l) {
        layer_range_[l][o] = g.layer_range[i * size_t(g.max_layers) + l];
        layer_trans_[l][o] = g.layer_transmittance[i * size_t(g.max_layers) + l];
      }
      const float ov[] = {float(g.object_id[i]), float(g.object_count[i]), g.direct_other_laser[i], g.indirect_laser[i]};
      for (size_t c = 0; c < object_ch_.size(); ++c) object_ch_[c][o] = ov[c];
      for (size_t j = 0; j < size_t(slots_); ++j) {
        const size_t e = i * size_t(g.max_layers) + j;
        const float sv[] = {float(g.object_slot_id[e]), g.object_range[e], g.object_transmittance[e], g.object_laser[e],
                            g.object_path[e]};
        for (size_t c = 0; c < std::size(kObjectSlotChannels); ++c) object_slot_ch_[j * std::size(kObjectSlotChannels) + c][o] = sv[c];
      }
    });
  }

  bool labels() const { return labels_decl_ != nullptr; }
  void put_labels(const ObjectLabelsTile& t) {
    labels_put_ = true;
    std::array<int64_t, 4> edges{};
    for_pixels(t.rect, [&](int, int, size_t i, size_t o) {
      for (size_t j = 0; j < size_t(slots_); ++j) {
        const size_t e = i * size_t(t.slots) + j;
        const float v[] = {float(t.id[e]), t.edge_counts[e], t.edge_snr[e], float(t.detectable[e])};
        for (size_t c = 0; c < std::size(kLabelSlotChannels); ++c) label_ch_[j * std::size(kLabelSlotChannels) + c][o] = v[c];
      }
      if (!t.edge.empty())
        for (size_t j = 0; j < size_t(t.slots); ++j) ++edges[std::min<size_t>(t.edge[i * size_t(t.slots) + j], 3)];
    });
    for (size_t k = 0; k < edges.size(); ++k) label_edges_[k] += edges[k];
  }
  std::array<int64_t, 4> label_edges() const {
    std::array<int64_t, 4> out{};
    for (size_t k = 0; k < out.size(); ++k) out[k] = label_edges_[k].load();
    return out;
  }

  void put(const TransientTile& t, const sensor::SensorMapsTile& m, const SensorTile& s) {
    for_pixels(t.rect, [&](int x, int y, size_t i, size_t o) {
      const auto d = size_t(t.data_rect.index(x, y));  // the transient tile carries a halo
      laser_ch_[0][o] = float(t.laser_total[d]), laser_ch_[1][o] = float(t.out_of_window[d]);
      ambient_ch_[o] = t.ambient_rate[d];
      if (!t.ambient_se.empty()) ambient_se_ch_[o] = t.ambient_se[d], ambient_se_seen_ = true;
      pixel_laser_[o] = t.laser_total[d], pixel_oow_[o] = t.out_of_window[d];
      if (!t.beyond_period.empty()) pixel_beyond_[o] = t.beyond_period[d];
      if (se_ch_ && !t.laser_se.empty()) se_ch_[o] = t.laser_se[d], se_seen_ = true;
      if (samples_ch_ && !t.samples.empty()) samples_ch_[o] = float(t.samples[d]);
      if (!t.samples.empty()) pixel_samples_[o] = t.samples[d];
      maps_ch_[0][o] = m.gate_skew_ps[i], maps_ch_[1][o] = m.gate_length_ps[i];
      maps_ch_[2][o] = m.dcr_cps[i], maps_ch_[3][o] = m.pde[i], maps_ch_[4][o] = m.pde_ambient[i];
      if (intensity_decl_) intensity_ch_[0][o] = s.intensity_counts[i], intensity_ch_[1][o] = s.intensity_photons[i];
    });
  }

  // Per-pixel sums in image order, so they do not depend on the tile size.
  double laser_total() const { return std::accumulate(pixel_laser_.begin(), pixel_laser_.end(), 0.0); }
  double out_of_window_total() const { return std::accumulate(pixel_oow_.begin(), pixel_oow_.end(), 0.0); }
  double beyond_period_total() const { return std::accumulate(pixel_beyond_.begin(), pixel_beyond_.end(), 0.0); }
  // The deepest layer any pixel has; layer channels beyond it are not written.
  // Pixels whose layers render.max_layers cut before their first opaque surface (GroundTruthTile).
  int64_t layers_cut() const { return layers_cut_.load(); }
  int deepest_layer() const {
    if (!gt_on_) return 0;
    const float* lc = gt_ch_.back();
    return int(*std::max_element(lc, lc + size_t(img_.count())));
  }
  // The most objects along one ray: object<j> channels of ground_truth.exr and labels.exr exist below it.
  // Known once the images are written (write() removes the slots beyond it).
  int object_slots() const { return object_slots_; }

  // A summary of the ground truth for dataset indices: the share of pixels whose ray hits something, the
  // span of their first-surface ranges, the meshes seen first and the most surfaces along one ray.
  // metadata.json "accuracy": the Monte Carlo standard error of the laser return relative to it, over the
  // pixels with a return, and the paths per pixel (null when the light carries no standard errors).
  nlohmann::json accuracy(const RunConfig& cfg) const {
    if (!se_ch_ || !se_seen_) return nullptr;
    const size_t n = size_t(img_.count());
    std::vector<double> rel;
    rel.reserve(n);
    double paths = 0.0;
    int32_t lo = INT32_MAX, hi = 0;
    for (size_t i = 0; i < n; ++i) {
      paths += pixel_samples_[i];
      lo = std::min(lo, pixel_samples_[i]), hi = std::max(hi, pixel_samples_[i]);
      if (pixel_laser_[i] > 0.0) rel.push_back(double(se_ch_[i]) / pixel_laser_[i]);
    }
    const auto summary = [](std::vector<double>& v, const char* pixels) {
      std::sort(v.begin(), v.end());
      const auto q = [&](double f) { return v.empty() ? 0.0 : v[std::min(v.size() - 1, size_t(f * double(v.size())))]; };
      return nlohmann::json{{pixels, v.size()}, {"median", q(0.5)}, {"p90", q(0.9)}, {"p99", q(0.99)}, {"max", v.empty() ? 0.0 : v.back()}};
    };
    nlohmann::json a;
    // One path per pixel has no spread to estimate an error from: every standard_error is 0, which a summary
    // of zeros would read as exact (it is null, and `meaning` says why).
    const bool estimable = hi >= 2;
    a["laser_relative_standard_error"] = laser_traced_ && estimable ? summary(rel, "pixels_with_laser") : nlohmann::json(nullptr);
    if (ambient_se_ch_ && !estimable) a["ambient_relative_standard_error"] = nullptr;
    if (ambient_se_ch_ && estimable) {
      std::vector<double> amb;
      amb.reserve(n);
      for (size_t i = 0; i < n; ++i)
        if (ambient_ch_[i] > 0.0f) amb.push_back(double(ambient_se_ch_[i]) / double(ambient_ch_[i]));
      a["ambient_relative_standard_error"] = summary(amb, "pixels_with_ambient");
    }
    a["samples_per_pixel"] = {{"mean", n ? paths / double(n) : 0.0}, {"min", n ? lo : 0}, {"max", hi}};
    a["target_relative_error"] = cfg.render.target_relative_error ? nlohmann::json(*cfg.render.target_relative_error) : nlohmann::json(nullptr);
    a["meaning"] = std::string(estimable ? "" : "one path per pixel: no spread to estimate the error from, so every "
                                                "standard_error is 0 and the summaries are null (2 paths or more estimate it); ") +
                   std::string(laser_traced_ ? "laser.exr standard_error: the Monte Carlo standard error of photons_per_pulse; "
                                               "ambient.exr standard_error: of photons_per_second"
                                             : "ambient.exr standard_error: the Monte Carlo standard error of photons_per_second "
                                               "(the laser is not traced)") +
                   (cfg.render.target_relative_error ? std::string("; ") + (laser_traced_ ? "laser.exr" : "ambient.exr") +
                                                           " samples: each pixel's paths"
                                                     : "") +
                   " (docs/render.md, Accuracy)";
    return a;
  }

  nlohmann::json ground_truth_summary() const {
    if (!gt_on_) return label_summary();
    const size_t n = size_t(img_.count());
    const float* range = gt_ch_[0];
    const float* mesh = gt_ch_[5];
    size_t hits = 0;
    float lo = std::numeric_limits<float>::infinity(), hi = -lo;
    std::set<int> meshes;
    for (size_t i = 0; i < n; ++i) {
      if (!std::isfinite(range[i])) continue;
      ++hits;
      lo = std::min(lo, range[i]), hi = std::max(hi, range[i]);
      meshes.insert(int(mesh[i]));
    }
    // Objects: those any pixel's ray meets, the most along one ray, and the pixels whose ray meets two or
    // more (where a multi-object detector is tested).
    std::set<int> objects;
    const float* count = object_ch_[1];
    size_t several = 0;
    int most = 0;
    for (size_t i = 0; i < n; ++i) {
      most = std::max(most, int(count[i]));
      several += count[i] >= 2.0f;
    }
    // only the slots written (write() removed the channels of the others: their pointers are gone)
    for (size_t j = 0; j < size_t(object_slots()) * std::size(kObjectSlotChannels); j += std::size(kObjectSlotChannels))
      for (size_t i = 0; i < n; ++i)
        if (object_slot_ch_[j][i] >= 0.0f) objects.insert(int(object_slot_ch_[j][i]));
    const nlohmann::json none = nullptr;
    nlohmann::json summary = {{"hit_fraction", double(hits) / double(n)},
            {"range_min_m", hits ? nlohmann::json(double(lo)) : none},
            {"range_max_m", hits ? nlohmann::json(double(hi)) : none},
            {"meshes_in_view", meshes.size()},
            {"max_layer_count", deepest_layer()},
            {"objects_in_view", objects.size()},
            {"max_object_count", most},
            {"multi_object_fraction", double(several) / double(n)}};
    if (const nlohmann::json l = label_summary(); !l.is_null()) summary.update(l);
    return summary;
  }

  // What this run's labels.exr says (null without labels computed here): the objects whose edge (labels.exr's)
  // stands out of the noise in at least one pixel, and the share of the (pixel, object) pairs along the
  // rays that do. Read after write(), which removed the label slots beyond the objects'.
  nlohmann::json label_summary() const {
    if (!labels_decl_ || !labels_put_) return nullptr;
    const size_t n = size_t(img_.count()), per_slot = std::size(kLabelSlotChannels);
    std::set<int> objects;
    size_t pairs = 0, detectable = 0;
    for (size_t j = 0; j < size_t(std::max(1, object_slots())); ++j) {
      const float* id = label_ch_[j * per_slot];
      const float* det = label_ch_[j * per_slot + 3];
      for (size_t i = 0; i < n; ++i) {
        if (id[i] < 0.0f) continue;
        ++pairs;
        if (det[i] > 0.5f) ++detectable, objects.insert(int(id[i]));
      }
    }
    return {{"objects_detectable", objects.size()}, {"detectable_fraction", pairs ? double(detectable) / double(pairs) : 0.0}};
  }

  // Writes the EXRs with their provenance and the previews into the staging folder.
  void write(const Staging& staging, const Provenance& p, const TimeAxis& axis, bool previews, std::vector<std::string>& files) {
    const auto put_file = [&](writers::ExrImage& e, const std::string& name, const std::string& units) {
      if (provided_.count(name)) return;
      stamp(e, p);
      // (of the chip: another seeds.chip's is refused by reconstruct and evaluate; the others, linked by a
      // sense of another chip, are the same for any)
      if (&e == &maps_ || (labels_decl_ && &e == &labels_)) e.set_attribute("spadgen_chip_seed", std::to_string(p.chip_seed));
      e.set_attribute("spadgen_units", units);
      e.write(staging.path(name), compression_);
      files.push_back(name);
    };
    object_slots_ = count_object_slots();
    if (!se_seen_) laser_.remove_channel("standard_error"), laser_.remove_channel("samples");
    if (!ambient_se_seen_) ambient_.remove_channel("standard_error"), ambient_se_ch_ = nullptr;
    if (gt_on_) {
      for (int l = deepest_layer(); l < layers_; ++l) {
        gt_.remove_channel(layer_name(l, ".range"));
        gt_.remove_channel(layer_name(l, ".transmittance"));
      }
      for (int j = object_slots(); j < slots_; ++j)
        for (const char* what : kObjectSlotChannels) gt_.remove_channel(layer_name(j, what, "object"));
      if (!laser_traced_) {  // the laser's light by object: none traced
        gt_.remove_channel("direct_other_laser"), gt_.remove_channel("indirect_laser");
        for (int j = 0; j < object_slots(); ++j) gt_.remove_channel(layer_name(j, ".laser", "object"));
      }
      put_file(gt_, "ground_truth.exr", std::string("range, z, layer<i>.range, object<j>.range, object<j>.path: metres (+inf where the ray hits nothing); "
               "transmittance: fraction") + (laser_traced_ ? "; object<j>.laser, direct_other_laser, indirect_laser: photons per laser "
                                                             "pulse reaching the pixel's SPAD (before PDP)" : ""));
    }
    if (labels_decl_) {
      // Slot 0 stays when nothing is in view (ids -1): an EXR needs a channel.
      for (int j = std::max(1, object_slots()); j < slots_; ++j)
        for (const char* what : kLabelSlotChannels) labels_.remove_channel(layer_name(j, what, "object"));
      put_file(labels_, labels_decl_->file, "object<j>.edge_counts: counts; edge_snr: ratio; detectable: 0 or 1");
    }
    laser_.set_attribute("spadgen_time_axis", axis_json(axis).dump());
    if (laser_traced_) put_file(laser_, "laser.exr", "photons per laser pulse reaching the pixel's SPAD (before PDP)");
    put_file(ambient_, "ambient.exr", std::string(ambient_se_ch_ ? "photons_per_second, standard_error: " : "") +
             "ambient photons per second reaching the pixel's SPAD (before PDP)");
    put_file(maps_, "sensor_maps.exr", "gate_skew_ps, gate_length_ps: ps; dcr_cps: counts/s; pde, pde_ambient: fraction");
    // The mode that declares the image knows what its channels mean.
    if (intensity_decl_) put_file(intensity_, intensity_decl_->file, intensity_decl_->what);
    if (!previews) return;
    if (gt_on_) {
      writers::write_png(staging.path("previews/depth.png"), writers::depth_preview(gt_ch_[0], img_.width, img_.height, 0.0f, 0.0f));
      files.push_back("previews/depth.png");
    }
    // What the camera saw when it takes an intensity image; a gate sweep has no single image, so the
    // laser light reaching each pixel stands in.
    const float* bright = intensity_decl_ ? intensity_ch_[1] : laser_ch_[0];
    if (provided_.count("previews/intensity.png")) return;
    writers::write_png(staging.path("previews/intensity.png"), writers::gray_preview(bright, img_.width, img_.height));
    files.push_back("previews/intensity.png");
  }

 private:
  static constexpr const char* kGroundTruthChannels[] = {"range", "z", "normal.X", "normal.Y", "normal.Z",
                                                         "mesh_id", "material_id", "layer_count"};
  static constexpr const char* kObjectChannels[] = {"object_id", "object_count", "direct_other_laser", "indirect_laser"};
  static constexpr const char* kObjectSlotChannels[] = {".id", ".range", ".transmittance", ".laser", ".path"};
  static constexpr const char* kLabelSlotChannels[] = {".id", ".edge_counts", ".edge_snr", ".detectable"};
  static std::string layer_name(int l, const char* what, const char* prefix = "layer") {
    return prefix + std::to_string(l) + what;
  }
  // From the slots' ids, which both images hold (spadgen sense has labels.exr only).
  int count_object_slots() const {
    const std::vector<float*>& ch = gt_on_ ? object_slot_ch_ : label_ch_;
    const size_t per_slot = gt_on_ ? std::size(kObjectSlotChannels) : std::size(kLabelSlotChannels);
    int deepest = 0;
    for (int j = 0; j < slots_ && size_t(j) * per_slot < ch.size(); ++j) {
      const float* id = ch[size_t(j) * per_slot];
      if (std::any_of(id, id + size_t(img_.count()), [](float v) { return v >= 0.0f; })) deepest = j + 1;
    }
    return deepest;
  }
  // Calls f(x, y, index in rect, index in the image) for every pixel (x, y) of rect.
  template <class F>
  void for_pixels(const PixelRect& r, F&& f) const {
    for (int y = r.y0; y < r.y1(); ++y)
      for (int x = r.x0; x < r.x1(); ++x)
        f(x, y, size_t(r.index(x, y)), size_t(y - img_.y0) * size_t(img_.width) + size_t(x - img_.x0));
  }

  std::set<std::string> provided_;
  bool labels_put_ = false;  // put_labels was called: labels.exr is this run's, not linked
  PixelRect img_;
  int layers_;
  int slots_;  // object slots held: render.max_layers, or the scene's objects when fewer
  std::atomic<int64_t> layers_cut_{0};
  std::array<std::atomic<int64_t>, 4> label_edges_{};  // (pixel, object) pairs by EdgeInSweep (put_labels)
  bool gt_on_;
  bool laser_traced_;  // the light holds the laser's: else no laser.exr and no laser channels in ground_truth.exr
  ExrCompression compression_;
  const sensor::DeclaredOutput* intensity_decl_;
  const sensor::DeclaredOutput* labels_decl_;
  writers::ExrImage gt_, laser_, ambient_, maps_, intensity_, labels_;
  // object_slot_ch_ and label_ch_: slot j's channels at [j * channels per slot + c]
  std::vector<float*> gt_ch_, layer_range_, layer_trans_, object_ch_, object_slot_ch_, laser_ch_, maps_ch_, intensity_ch_,
      label_ch_;
  float* ambient_ch_ = nullptr;
  float* ambient_se_ch_ = nullptr;
  std::atomic<bool> ambient_se_seen_{false};
  std::vector<double> pixel_laser_, pixel_oow_, pixel_beyond_;
  std::vector<int32_t> pixel_samples_;
  float* se_ch_ = nullptr;       // laser.exr standard_error (null: not written)
  std::atomic<bool> se_seen_{false};  // a tile carried standard errors (not light saved before them)
  float* samples_ch_ = nullptr;  // laser.exr samples, ambient.exr's without the laser (null: not written)
  int object_slots_ = 0;
};

// The stacks, streamed to disk tile by tile (.npy files or Zarr stores).
class Outputs::Stacks {
 public:
  // in_bands: write_in_bands.
  Stacks(const std::vector<StackLayout>& layout, const PixelRect& img, const PixelRect& transient_crop,
         const Staging& staging, std::vector<std::string>& files, bool in_bands)
      : layout_(layout), img_(img), tcrop_(transient_crop), counts_u8_(layout[kCounts].dtype == writers::Dtype::U8),
        band_width_(size_t(img.height)), complete_(size_t(img.height), 0) {
    for (size_t k = 0; k < kStackCount; ++k) {
      if (!layout[k].written) continue;
      if (in_bands && layout[k].khw() && layout[k].chunks.empty()) {  // a (K, H, W) .npy: written band by band
        w_[k] = std::make_unique<NpyWriter>(staging.path(layout[k].file), layout[k].dtype, layout[k].shape, /*mapped=*/false);
        band_stack_[k] = true;
      } else if (k == kFrames && in_bands) {  // the frames: kept by band, written whole rows at a time
        auto frames = std::make_unique<NpyWriter>(staging.path(layout[k].file), layout[k].dtype, layout[k].shape, /*mapped=*/false);
        frames_ = frames.get();
        frames_in_bands_ = true;
        w_[k] = std::move(frames);
      } else if (k == kFrames) {
        auto frames = std::make_unique<NpyWriter>(staging.path(layout[k].file), layout[k].dtype, layout[k].shape);
        frames_ = frames.get();
        w_[k] = std::move(frames);
      } else {
        w_[k] = open_stack(layout[k], staging.path(layout[k].file));
      }
      files.push_back(layout[k].file);
    }
    for (size_t k = 0; k < kStackCount; ++k)
      if (layout[k].written && !layout[k].chunks.empty()) {
        write_zarr_group(staging, "", files);
        break;
      }
  }

  void put(const TransientTile& t, SensorTile&& s) {
    const PixelRect& r = t.rect;
    // A .npy stack: into the tile's band, written whole once complete; a Zarr store: chunk by chunk.
    Band* band = band_stack_[kExpectedCounts] || band_stack_[kDetectionRate] || band_stack_[kCounts] || frames_in_bands_
                     ? &band_of(r)
                     : nullptr;
    const auto to_u8 = [](uint16_t v) { return uint8_t(v); };  // counts never exceed the frames, <= 255 here
    if (band_stack_[kExpectedCounts]) band->put(kExpectedCounts, r, img_, s.expected.data());
    else if (w_[kExpectedCounts]) w_[kExpectedCounts]->write_khw(r, img_.x0, img_.y0, s.expected.data());
    if (band_stack_[kDetectionRate]) band->put(kDetectionRate, r, img_, s.rate.data());
    else if (w_[kDetectionRate]) w_[kDetectionRate]->write_khw(r, img_.x0, img_.y0, s.rate.data());
    if (band_stack_[kCounts] && counts_u8_) {
      band->put(kCounts, r, img_, s.counts.data(), to_u8);
    } else if (band_stack_[kCounts]) {
      band->put(kCounts, r, img_, s.counts.data());
    } else if (w_[kCounts] && counts_u8_) {
      std::vector<uint8_t> c8(s.counts.size());
      std::transform(s.counts.begin(), s.counts.end(), c8.begin(), to_u8);
      w_[kCounts]->write_khw(r, img_.x0, img_.y0, c8.data());
    } else if (w_[kCounts]) {
      w_[kCounts]->write_khw(r, img_.x0, img_.y0, s.counts.data());
    }
    if (frames_in_bands_) {
      std::lock_guard<std::mutex> lock(band_mutex_);
      band->frames.emplace_back(r, std::move(s.frames));
    } else if (frames_) {
      frames_->write_frames(r, img_.x0, img_.y0, s.frames.data());
    }
    const int x0 = std::max(r.x0, tcrop_.x0), x1 = std::min(r.x1(), tcrop_.x1());
    const int y0 = std::max(r.y0, tcrop_.y0), y1 = std::min(r.y1(), tcrop_.y1());
    if (t.axis.bins != 0 && x1 > x0 && y1 > y0) {
      const PixelRect part{x0, y0, x1 - x0, y1 - y0};
      if (w_[kTransient]) w_[kTransient]->write_hwt(part, t.data_rect, tcrop_.x0, tcrop_.y0, t.transient.data());
      if (w_[kTransientIndirect])
        w_[kTransientIndirect]->write_hwt(part, t.data_rect, tcrop_.x0, tcrop_.y0, t.transient_indirect.data());
    }
    tile_done(r);
  }

  void commit() {
    for (auto& w : w_)
      if (w) w->commit();
  }
  bool counts_u8() const { return counts_u8_; }
  const PixelRect& transient_crop() const { return tcrop_; }
  // metadata.json's storage record of every stack written.
  nlohmann::json storage() const {
    nlohmann::json j = nlohmann::json::object();
    for (size_t k = 0; k < kStackCount; ++k)
      if (w_[k]) j[layout_[k].file] = storage_json(layout_[k]);
    return j;
  }

 private:
  // The (K, H, W) .npy stacks of one band of tiles (the rows from y0, of the tiles' height), assembled in
  // memory: a tile's share of gate position k is a short run per row (128 bytes for 32 pixels), the
  // band's is rows x W contiguous values, which one pwrite puts in the page cache without the page faults,
  // zero-filling and TLB shootdowns of writing through a mapping. (Frames stay mapped: assembled the same
  // way, a 1024 x 32 band of the paper's sweep wrote at 0.55 of the mapping's speed, bench_sensor
  // BM_FramesToDisk, its 4-byte rows scattered over 89,505 pages either way.)
  struct Band {
    int rows = 0;
    int64_t K = 0, W = 0;
    // [k][row][x], every byte written by its tiles (uninitialised; large ones in huge pages, core/tile.h)
    std::array<std::vector<char, DefaultInitAllocator<char>>, kStackCount> data;
    std::array<int64_t, kStackCount> element_bytes{};
    std::vector<std::pair<PixelRect, FrameBytes>> frames;  // the tiles' frames, as SensorTile holds them
    template <class T, class Convert = std::identity>
    void put(Stack k, const PixelRect& r, const PixelRect& img, const T* src, Convert convert = {}) {
      using Out = std::decay_t<decltype(convert(*src))>;
      auto* dst = reinterpret_cast<Out*>(data[k].data());
      const auto n = size_t(r.count());
      for (int64_t g = 0; g < K; ++g)
        for (int y = 0; y < r.height; ++y) {
          Out* d = dst + (size_t(g) * size_t(rows) + size_t(y)) * size_t(W) + size_t(r.x0 - img.x0);
          const T* from = src + size_t(g) * n + size_t(y) * size_t(r.width);
          if constexpr (std::is_same_v<T, Out>) std::memcpy(d, from, size_t(r.width) * sizeof(T));
          else std::transform(from, from + r.width, d, convert);
        }
    }
  };

  Band& band_of(const PixelRect& r) {
    std::lock_guard<std::mutex> lock(band_mutex_);
    std::unique_ptr<Band>& b = bands_[r.y0 - img_.y0];
    if (!b) {
      b = std::make_unique<Band>();
      b->rows = r.height, b->W = img_.width;
      for (size_t k = 0; k < kStackCount; ++k)
        if (band_stack_[k]) {
          b->K = layout_[k].shape[0];
          b->element_bytes[k] = writers::element_bytes(layout_[k].dtype);
          b->data[k].resize(size_t(b->K * b->rows * b->W * b->element_bytes[k]));
        }
    }
    return *b;
  }

  // The band at `row` is complete: each gate position's rows go to the file in one write, and the band is freed.
  void write_band(size_t row) {
    std::unique_ptr<Band> b;
    {
      std::lock_guard<std::mutex> lock(band_mutex_);
      const auto it = bands_.find(int(row));
      if (it == bands_.end()) return;
      b = std::move(it->second);
      bands_.erase(it);
    }
    const int64_t H = img_.height, plane = int64_t(b->rows) * b->W;
    for (size_t k = 0; k < kStackCount; ++k)
      if (band_stack_[k])
        for (int64_t g = 0; g < b->K; ++g)
          w_[k]->write((g * H + int64_t(row)) * b->W, b->data[k].data() + g * plane * b->element_bytes[k], plane);
    if (!b->frames.empty()) {
      std::vector<NpyWriter::FramesTile> tiles;
      for (const auto& [rect, bytes] : b->frames) tiles.push_back({rect, bytes.data()});
      // Gate positions in parallel: this band may be the run's last, with the other threads idle.
      const int64_t K = layout_[kFrames].shape[0];
      tbb::parallel_for(tbb::blocked_range<int64_t>(0, K, 8), [&](const tbb::blocked_range<int64_t>& ks) {
        frames_->write_frames_band(tiles, img_.x0, img_.y0, ks.begin(), ks.end());
      });
    }
  }

  // A band of tiles is complete: its (K, H, W) .npy stacks are written; the frames and transients are
  // mapped for writing (NpyWriter), so every page a tile touched stays in the run's resident set until
  // released. Tiles come in bands (rows of tiles sharing y0 and height): when a band
  // is complete, the rows of the complete bands around it leave the resident set. Only whole pages
  // inside complete rows are released, so no page another tile still writes is touched; a page at a band
  // boundary goes when the band beyond it completes. (A Zarr store frees each chunk once it is complete.)
  void tile_done(const PixelRect& r) {
    const auto row = size_t(r.y0 - img_.y0);
    if (band_width_[row].fetch_add(r.width) + r.width != img_.width) return;
    write_band(row);
    std::lock_guard<std::mutex> lock(release_mutex_);
    std::fill(complete_.begin() + ptrdiff_t(row), complete_.begin() + ptrdiff_t(row) + r.height, 1);
    size_t lo = row, hi = row + size_t(r.height);
    while (lo > 0 && complete_[lo - 1]) --lo;
    while (hi < complete_.size() && complete_[hi]) ++hi;
    const int64_t a = int64_t(lo), b = int64_t(hi);
    for (Stack k : {kExpectedCounts, kDetectionRate, kCounts})
      if (w_[k]) w_[k]->release_rows(1, a, b);
    if (w_[kFrames]) w_[kFrames]->release_rows(2, a, b);
    // The transient stacks cover the transient crop: its rows inside the complete run.
    const int64_t ta = std::max<int64_t>(a + img_.y0, tcrop_.y0) - tcrop_.y0;
    const int64_t tb = std::min<int64_t>(b + img_.y0, tcrop_.y1()) - tcrop_.y0;
    for (Stack k : {kTransient, kTransientIndirect})
      if (w_[k] && tb > ta) w_[k]->release_rows(0, ta, tb);
  }

  std::vector<StackLayout> layout_;
  PixelRect img_, tcrop_;
  bool counts_u8_;
  std::array<std::unique_ptr<writers::StackWriter>, kStackCount> w_;  // null: not written
  std::array<bool, kStackCount> band_stack_{};                        // w_[k] is written by bands
  std::map<int, std::unique_ptr<Band>> bands_;                        // by first row - img.y0: the bands being filled
  std::mutex band_mutex_;
  NpyWriter* frames_ = nullptr;                                       // w_[kFrames], always a .npy
  bool frames_in_bands_ = false;                                      // kept by band (Band::frames)
  std::vector<std::atomic<int>> band_width_;  // [row - img.y0]: pixels written in the band starting there
  std::vector<char> complete_;                // [row - img.y0]: the row is complete
  std::mutex release_mutex_;
};

// The sampled gate profiles of a few pixels, for previews/gate_profiles.png.
class Outputs::ProfileProbe {
 public:
  ProfileProbe(const PixelRect& img, int K) : pixels_(profile_pixels(img)), curves_(pixels_.size(), std::vector<float>(size_t(K))) {}
  void put(const SensorTile& s) {
    for (size_t p = 0; p < pixels_.size(); ++p)
      if (s.rect.contains(pixels_[p].first, pixels_[p].second))
        for (int k = 0; k < s.K; ++k)
          curves_[p][size_t(k)] = float(s.counts[size_t(k) * size_t(s.rect.count()) + size_t(s.rect.index(pixels_[p].first, pixels_[p].second))]);
  }
  void write(const Staging& staging, const std::string& file, const std::vector<double>& gate_positions_s,
             std::vector<std::string>& files) const {
    std::vector<double> x(gate_positions_s.size());
    std::transform(gate_positions_s.begin(), gate_positions_s.end(), x.begin(), [](double t) { return t / kNs; });
    writers::write_png(staging.path(file), writers::profile_plot(curves_, x, 800, 450, "gate position (ns)", "counts"));
    files.push_back(file);
  }
  const std::vector<std::pair<int, int>>& pixels() const { return pixels_; }

 private:
  std::vector<std::pair<int, int>> pixels_;
  std::vector<std::vector<float>> curves_;
};

Outputs::Outputs(const RunConfig& c, const sensor::SensorModel& sensor, const PixelRect& img, const TimeAxis& axis,
                 const Staging& staging, int objects, int threads, bool laser, const std::set<std::string>& provided)
    : cfg_(c), axis_(axis), gate_positions_s_(sensor.gate_positions_s()), declared_(sensor.acquisition().outputs()),
      staging_(staging) {
  // Labels come from the ground truth: this run's, or the one spadgen sense was given (provided).
  const bool ground_truth = c.outputs.ground_truth || provided.count("ground_truth.exr");
  images_ = std::make_unique<Images>(c, img, find_declared(declared_, "intensity.exr"),
                                     ground_truth ? find_declared(declared_, "labels.exr") : nullptr,
                                     image_object_slots(c.render.max_layers, objects), laser, provided);
  std::vector<StackLayout> layout = stack_layout(c, sensor, img, axis);
  for (StackLayout& s : layout)
    if (provided.count(s.file)) s.written = false;
  stacks_ = std::make_unique<Stacks>(layout, img, transient_crop(c, img), staging, files_,
                                     write_in_bands(layout, img, c.render.tile_size, threads));
  probe_ = std::make_unique<ProfileProbe>(img, sensor.K());
}

Outputs::~Outputs() = default;

void Outputs::put_ground_truth(const GroundTruthTile& g) { images_->put_ground_truth(g); }
void Outputs::put_labels(const ObjectLabelsTile& l) { images_->put_labels(l); }
bool Outputs::labels() const { return images_->labels(); }

void Outputs::put(const TransientTile& t, const sensor::SensorMapsTile& m, SensorTile&& s) {
  store_max(laser_open_rate_, s.laser_open_rate);
  images_->put(t, m, s);
  probe_->put(s);
  stacks_->put(t, std::move(s));
}

void Outputs::write(const Provenance& p) {
  images_->write(staging_, p, axis_, cfg_.outputs.previews, files_);
  // One gate position makes no curve.
  if (const sensor::DeclaredOutput* d = find_declared(declared_, "previews/gate_profiles.png");
      d && cfg_.outputs.previews && gate_positions_s_.size() > 1)
    probe_->write(staging_, d->file, gate_positions_s_, files_);
}

void Outputs::commit() { stacks_->commit(); }

void Outputs::report(RunRecord& r) const {
  r.laser_total = images_->laser_total(), r.out_of_window_total = images_->out_of_window_total();
  r.beyond_period_total = images_->beyond_period_total();
  r.ground_truth_layers = images_->deepest_layer();
  r.ground_truth_layers_cut = images_->layers_cut();
  r.ground_truth_objects = images_->object_slots();
  r.ground_truth_summary = images_->ground_truth_summary();
  r.label_edges = images_->label_edges();
  r.accuracy = images_->accuracy(cfg_);
  r.counts_u8 = stacks_->counts_u8();
  r.transient_crop = stacks_->transient_crop();
  r.profile_pixels = probe_->pixels();
  r.storage = stacks_->storage();
  r.laser_open_rate = laser_open_rate_.load();
}

}  // namespace spadgen::app
