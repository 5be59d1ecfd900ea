#include "run_folder.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "core/error.h"
#include "writers/writers.h"

namespace spadgen::reconstruct {
namespace fs = std::filesystem;

// A (K, H, W) stack as .npy (memory-mapped) or Zarr (read chunk by chunk), read as float.
struct RunFolder::Stack {
  std::unique_ptr<writers::NpyReader> npy;
  std::unique_ptr<writers::ZarrReader> zarr;
  writers::Dtype dtype() const { return npy ? npy->dtype() : zarr->dtype(); }
  const std::vector<int64_t>& shape() const { return npy ? npy->shape() : zarr->shape(); }
  const std::string& path() const { return npy ? npy->path() : zarr->path(); }
  // count elements from flat index offset, converted to float
  void read(int64_t offset, int64_t count, float* out) const {
    const auto convert = [&](const auto* src) {
      for (int64_t i = 0; i < count; ++i) out[i] = static_cast<float>(src[i]);
    };
    const auto with = [&](auto tag) {
      using T = decltype(tag);
      if (npy) return convert(npy->data<T>() + offset);
      std::vector<T> buffer(static_cast<size_t>(count));
      zarr->read(offset, count, buffer.data());
      convert(buffer.data());
    };
    switch (dtype()) {
      case writers::Dtype::U8: return with(uint8_t{});
      case writers::Dtype::U16: return with(uint16_t{});
      case writers::Dtype::F32: return with(float{});
      default: throw Error(path() + ": expected uint8, uint16 or float32 elements");
    }
  }
};

std::unique_ptr<RunFolder::Stack> open_run_stack(const std::string& dir_name, const std::string& name) {
  const fs::path dir(dir_name);
  auto s = std::make_unique<RunFolder::Stack>();
  if (fs::exists(dir / (name + ".npy")))
    s->npy = std::make_unique<writers::NpyReader>((dir / (name + ".npy")).string());
  else if (fs::exists(dir / (name + ".zarr")))
    s->zarr = std::make_unique<writers::ZarrReader>((dir / (name + ".zarr")).string());
  else
    return nullptr;
  return s;
}

namespace {

std::string format_value(float v) {
  std::ostringstream o;
  o << v;
  return o.str();
}

template <class T>
T get(const nlohmann::json& j, const std::string& pointer, const std::string& file) {
  const nlohmann::json::json_pointer p(pointer);
  if (!j.contains(p)) throw Error(file + ": no " + pointer + " (is this a folder written by spadgen run or sense?)");
  try {
    return j.at(p).get<T>();
  } catch (const nlohmann::json::exception&) {
    // (what it is and what a run writes: it said only "has the wrong type")
    const char* expected = std::is_same_v<T, std::string>                        ? "text"
                           : std::is_same_v<T, std::vector<double>>              ? "a list of numbers"
                           : std::is_same_v<T, std::vector<std::vector<double>>> ? "a list of lists of numbers"
                                                                                 : "another type";
    std::string shown = j.at(p).dump();
    if (shown.size() > 80) shown = shown.substr(0, 77) + "...";
    throw Error(file + ": " + pointer + " is " + shown + "; expected " + expected + ", as a run writes it (is this a folder "
                "written by spadgen run or sense?)");
  }
}

// An integer of metadata.json in [lo, hi] (get<int> of 1e308 or 2^63 overflowed, and a frames_per_k of -1 was
// then blamed on counts.npy: "expected 0 to -1").
int get_int(const nlohmann::json& j, const std::string& pointer, const std::string& file, int64_t lo, int64_t hi) {
  const nlohmann::json::json_pointer p(pointer);
  if (!j.contains(p)) throw Error(file + ": no " + pointer + " (is this a folder written by spadgen run or sense?)");
  const nlohmann::json& v = j.at(p);
  const bool in_range = v.is_number_unsigned()  ? v.get<uint64_t>() >= uint64_t(lo) && v.get<uint64_t>() <= uint64_t(hi)
                        : v.is_number_integer() ? v.get<int64_t>() >= lo && v.get<int64_t>() <= hi
                                                : false;
  if (!in_range)
    throw Error(file + ": " + pointer + " is " + v.dump() + ", not an integer in [" + std::to_string(lo) + ", " +
                std::to_string(hi) + "] (is this a folder written by spadgen run or sense?)");
  return int(v.get<int64_t>());
}

// A number of metadata.json in [lo, hi] (a run writes it from a scene-file key of that range): an emission
// delay of 1e308 ns was taken, and every return's range came out negative.
double get_real(const nlohmann::json& j, const std::string& pointer, const std::string& file, double lo, double hi) {
  const nlohmann::json::json_pointer p(pointer);
  if (!j.contains(p)) throw Error(file + ": no " + pointer + " (is this a folder written by spadgen run or sense?)");
  const nlohmann::json& v = j.at(p);
  if (!v.is_number() || !(v.get<double>() >= lo && v.get<double>() <= hi)) {
    std::ostringstream range;
    range << "[" << lo << ", " << hi << "]";
    throw Error(file + ": " + pointer + " is " + v.dump() + ", not a number in " + range.str() +
                " (is this a folder written by spadgen run or sense?)");
  }
  return v.get<double>();
}

}  // namespace

bool is_repeat_set(const fs::path& dir) {
  std::error_code ec;
  return fs::is_regular_file(dir / "repeat_000" / "metadata.json", ec);
}

nlohmann::json read_run_metadata(const std::string& dir) {
  const std::string path = (fs::path(dir) / "metadata.json").string();
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (!fs::exists(st)) {
    // a dataset's folder holds run folders, one per sample: name one
    const bool dataset = fs::is_regular_file(fs::path(dir) / "dataset.json", ec);
    // sense --repeats' folder holds one run folder per realisation
    const bool repeats = is_repeat_set(dir);
    throw Error(dir + ": not a run folder (no metadata.json); expected the folder of a finished `spadgen run`" +
                (dataset ? std::string(" (this is a dataset's folder: its samples' run folders are in its samples/, e.g. ") +
                               (fs::path(dir) / "samples" / "000000").string() + ")"
                 : repeats ? " (this is the folder of `spadgen sense --repeats`' realisations: each is a run folder, " +
                                 (fs::path(dir) / "repeat_000").string() + ", ...; one command per realisation, e.g. `for r in '" +
                                 dir + "'/repeat_*; do spadgen reconstruct \"$r\"; done`)"
                           : std::string()));
  }
  // Opened only when a regular file: a FIFO would block the open for ever, a device never end.
  if (!fs::is_regular_file(st)) throw Error(path + ": not a regular file; expected the run's metadata.json");
  // A run's metadata.json is kilobytes; read whole, a huge file took gigabytes of memory to be refused.
  if (const uintmax_t size = fs::file_size(path, ec); !ec && size > kMaxMetadataBytes)
    throw Error(path + ": " + std::to_string(size) + " bytes; a run's metadata.json is kilobytes (at most " +
                std::to_string(kMaxMetadataBytes) + " bytes taken): not a run folder's");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path + ": cannot read it: " + std::strerror(errno));
  std::stringstream ss;
  ss << in.rdbuf();
  try {
    return nlohmann::json::parse(ss.str());
  } catch (const nlohmann::json::exception& e) {
    throw Error(path + ": not valid JSON (" + e.what() + ")");
  }
}

RunFolder::RunFolder(const std::string& dir) : dir_(dir) {
  const fs::path d(dir);
  const std::string meta_path = (d / "metadata.json").string();
  meta_ = read_run_metadata(dir);
  W_ = get_int(meta_, "/image/width", meta_path, 1, 1 << 20);
  H_ = get_int(meta_, "/image/height", meta_path, 1, 1 << 20);
  K_ = get_int(meta_, "/acquisition/K", meta_path, 1, 1 << 24);
  frames_ = get_int(meta_, "/acquisition/frames_per_k", meta_path, 1, 65535);
  image_frames_ = get_int(meta_, "/acquisition/frames", meta_path, 1, 65535);
  if (meta_.contains("/image/crop_in_sensor"_json_pointer)) crop_ = meta_["image"]["crop_in_sensor"];
  const std::string mode = get<std::string>(meta_, "/acquisition/mode", meta_path);
  // (any other mode was read as a 2D run: a gate sweep's planes made an hdr.exr)
  if (mode != "gate_sweep" && mode != "intensity")
    throw Error(meta_path + ": /acquisition/mode is " + nlohmann::json(mode).dump() + ", expected \"gate_sweep\" or \"intensity\" (the metadata.json "
                "spadgen wrote: restore it, or run again)");
  gate_sweep_ = mode == "gate_sweep";
  if (gate_sweep_) {
    const auto gates = get<std::vector<double>>(meta_, "/acquisition/gate_positions_ns", meta_path);
    if (int(gates.size()) != K_ || K_ < 1) throw Error(meta_path + ": /acquisition/gate_positions_ns does not hold K positions");
    // The timing's numbers in the ranges of the scene-file keys they come from (docs/scene-file.md).
    start_s_ = get_real(meta_, "/acquisition/gate_positions_ns/0", meta_path, -1e6, 1e6) * 1e-9;
    step_s_ = get_real(meta_, "/acquisition/gate_step_ps", meta_path, 1e-6, 1e9) * 1e-12;
    gate_delay_s_ = get_real(meta_, "/acquisition/gate/delay_ns", meta_path, -1e6, 1e6) * 1e-9;
    emission_delay_s_ = get_real(meta_, "/resolved_scene/laser/emission_delay_ns", meta_path, -1e6, 1e6) * 1e-9;
    period_s_ = 1e-6 / get_real(meta_, "/resolved_scene/laser/repetition_rate_MHz", meta_path, 1e-6, 1e5);
    // The gate's edge as the run describes it (the edges detector's separation): the slower of rise and fall
    // plus the instrument response (an edited value of another type was an internal error).
    const auto has = [&](const char* key) { return meta_.contains(nlohmann::json::json_pointer(std::string("/acquisition/gate/") + key)); };
    if (has("rise_ps") && has("fall_ps")) {
      edge_s_ = std::max(get_real(meta_, "/acquisition/gate/rise_ps", meta_path, 0.0, 1e9),
                         get_real(meta_, "/acquisition/gate/fall_ps", meta_path, 0.0, 1e9));
      if (has("irf_fwhm_ps")) edge_s_ += get_real(meta_, "/acquisition/gate/irf_fwhm_ps", meta_path, 0.0, 1e9);
      edge_s_ *= 1e-12;
    }
    const std::string maps = (d / "sensor_maps.exr").string();
    if (!fs::is_regular_file(maps))
      throw Error(dir + (fs::exists(maps) ? ": sensor_maps.exr is not a regular file (a folder, a FIFO or a device)"
                                          : ": no sensor_maps.exr") + " (the per-pixel gate skew and length the edges are timed with)");
    writers::ExrData m = writers::read_exr(maps);
    for (const char* c : {"gate_skew_ps", "gate_length_ps"})
      if (!m.channels.count(c)) throw Error(maps + ": no channel " + std::string(c));
    check_image(maps, m, /*of_the_chip=*/true);
    skew_ps_ = std::move(m.channels["gate_skew_ps"]);
    length_ps_ = std::move(m.channels["gate_length_ps"]);
    // The pixel rays and where the laser sits (a return's time holds both legs of its path).
    const auto K = get<std::vector<std::vector<double>>>(meta_, "/camera/intrinsics", meta_path);
    if (K.size() != 3 || K[0].size() != 3 || K[1].size() != 3 || !(K[0][0] > 0.0) || !(K[1][1] > 0.0))
      throw Error(meta_path + ": /camera/intrinsics is not a 3 x 3 pinhole matrix");
    // within what any lens and sensor give (1e300 was taken: every ray's direction lost to rounding)
    fx_ = get_real(meta_, "/camera/intrinsics/0/0", meta_path, 1e-6, 1e12);
    fy_ = get_real(meta_, "/camera/intrinsics/1/1", meta_path, 1e-6, 1e12);
    cx_ = get_real(meta_, "/camera/intrinsics/0/2", meta_path, -1e12, 1e12);
    cy_ = get_real(meta_, "/camera/intrinsics/1/2", meta_path, -1e12, 1e12);
    if (meta_.contains(nlohmann::json::json_pointer("/camera/laser_position_m"))) {
      const auto l = get<std::vector<double>>(meta_, "/camera/laser_position_m", meta_path);
      if (l.size() != 3) throw Error(meta_path + ": /camera/laser_position_m is not 3 numbers");
      for (int k = 0; k < 3; ++k)  // (the glTF's world: within +-1e9 m)
        laser_m_[k] = get_real(meta_, "/camera/laser_position_m/" + std::to_string(k), meta_path, -1e9, 1e9);
    } else if (get<std::string>(meta_, "/resolved_scene/laser/beam", meta_path) != "gltf_light") {
      // a run of a spadgen that did not record it: laser.offset_m, from (x right, y up, -z forward)
      const auto o = get<std::vector<double>>(meta_, "/resolved_scene/laser/offset_m", meta_path);
      if (o.size() != 3) throw Error(meta_path + ": /resolved_scene/laser/offset_m is not 3 numbers");
      for (int k = 0; k < 3; ++k) (void)get_real(meta_, "/resolved_scene/laser/offset_m/" + std::to_string(k), meta_path, -1e9, 1e9);
      laser_m_[0] = o[0], laser_m_[1] = -o[1], laser_m_[2] = -o[2];
    } else {
      throw Error(meta_path + ": no /camera/laser_position_m (where the glTF light that is the laser sits): written by "
                  "an older spadgen; run the scene again");
    }
  } else {
    dual_ = get<std::string>(meta_, "/resolved_scene/acquisition/intensity/exposure", meta_path) == "dual";
    dual_ratio_ = dual_ ? get_real(meta_, "/resolved_scene/acquisition/intensity/dual_ratio", meta_path, 1.0, 1e6) : 1.0;
  }
  counts_ = open_run_stack(dir, "counts");
  rate_ = open_run_stack(dir, "detection_rate");
  for (Stack* s : {counts_.get(), rate_.get()})
    if (s && s->shape() != std::vector<int64_t>{K_, H_, W_})
      throw Error(s->path() + ": shape differs from metadata.json's (K, H, W)");
}

RunFolder::~RunFolder() = default;
RunFolder::RunFolder(RunFolder&&) noexcept = default;

PixelTiming RunFolder::timing(int x, int y) const {
  const size_t i = size_t(y) * size_t(W_) + size_t(x);
  PixelTiming t;
  t.start_s = start_s_;
  t.step_s = step_s_;
  t.fall_offset_s = gate_delay_s_ + skew_ps_[i] * 1e-12;
  t.rise_offset_s = t.fall_offset_s + length_ps_[i] * 1e-12;
  t.emission_delay_s = emission_delay_s_;
  t.period_s = period_s_;
  t.bistatic = bistatic(x, y);
  return t;
}

Bistatic RunFolder::bistatic(int x, int y) const {
  const double u = (x - cx_) / fx_, v = (y - cy_) / fy_, n = std::sqrt(u * u + v * v + 1.0);
  const double ray[3] = {u / n, v / n, 1.0 / n};
  return Bistatic::of(ray, laser_m_);
}

void RunFolder::rates(int y0, int y1, float* out) const { read_rows(y0, y1, true, false, out); }
void RunFolder::profiles(int y0, int y1, bool noise_free, float* out) const { read_rows(y0, y1, noise_free, noise_free, out); }

void RunFolder::read_rows(int y0, int y1, bool rate, bool to_counts, float* out) const {
  const Stack* s = rate ? rate_.get() : counts_.get();
  if (!s) {
    std::error_code ec;
    const bool light = std::filesystem::is_directory(std::filesystem::path(dir_) / "light", ec);
    throw Error(dir_ + (rate ? ": no detection_rate.npy or .zarr (outputs.detection_rate)" +
                                   (light ? "; it saved the light, from which `spadgen sense " + dir_ +
                                                " --set outputs.detection_rate=true -o DIR` writes it without rendering"
                                          : std::string())
                             : ": no counts.npy or counts.zarr (outputs.counts)"));
  }
  const int64_t rows = y1 - y0, n = rows * W_;
  std::vector<float> plane(static_cast<size_t>(n));
  for (int k = 0; k < K_; ++k) {
    s->read((int64_t(k) * H_ + y0) * W_, n, plane.data());
    for (int64_t i = 0; i < n; ++i) {
      float v = plane[size_t(i)];
      // A count above the frames, or a rate that is no rate, is not what a run writes (a hand-edited or
      // damaged file): its detections and scores would be of data no camera gives.
      if (!(v >= 0.0f) || (!rate && v > float(frames_)))
        throw Error(s->path() + ": " + (rate ? "detection rate " : "count ") + format_value(v) + " at (k " +
                    std::to_string(k) + ", y " + std::to_string(y0 + i / W_) + ", x " + std::to_string(i % W_) +
                    "); expected " +
                    (rate ? std::string("a rate >= 0 (expected detections per frame)")
                          : "0 to " + std::to_string(frames_) + " (/acquisition/frames_per_k of metadata.json)"));
      if (to_counts) v = static_cast<float>(frames_ * -std::expm1(-double(v)));
      out[size_t(i) * size_t(K_) + size_t(k)] = v;
    }
  }
}

void RunFolder::check_image(const std::string& path, const writers::ExrData& e, bool of_the_chip) const {
  if (e.width != W_ || e.height != H_)
    throw Error(path + ": " + std::to_string(e.width) + " x " + std::to_string(e.height) + " pixels, and the run's image is " +
                std::to_string(W_) + " x " + std::to_string(H_) + " (metadata.json): a file of another run");
  // (the sensor maps or labels of another chip: another seed's maps timed the edges 3 times worse, 17.5 mm rms
  // for 6.0, and were scored as the run's)
  const nlohmann::json::json_pointer chip_at("/seeds/chip");
  if (const auto chip = e.attributes.find("spadgen_chip_seed");
      of_the_chip && chip != e.attributes.end() && meta_.contains(chip_at) && meta_.at(chip_at).is_number_unsigned() &&
      chip->second != std::to_string(meta_.at(chip_at).get<uint64_t>())) {
    std::string shown = chip->second.substr(0, 24);
    for (char& ch : shown)
      if (static_cast<unsigned char>(ch) < 0x20) ch = '?';
    throw Error(path + ": made for the chip of seed " + shown + " (its spadgen_chip_seed), and the run's is " +
                meta_.at(chip_at).dump() + " (metadata.json seeds.chip): a file of another run");
  }
  // (an image of another run of the same size: a crop elsewhere on the sensor)
  const auto at = e.attributes.find("spadgen_crop");
  if (at == e.attributes.end() || crop_.is_null()) return;
  nlohmann::json crop;
  try {
    crop = nlohmann::json::parse(at->second);
  } catch (const nlohmann::json::exception&) {
  }
  if (crop != crop_) {
    std::string shown = at->second.substr(0, 80);  // (one line, whatever the header holds)
    for (char& ch : shown)
      if (static_cast<unsigned char>(ch) < 0x20) ch = '?';
    throw Error(path + ": an image of the crop " + shown + " (its spadgen_crop), and the run's is " +
                crop_.dump() + " (metadata.json image.crop_in_sensor): a file of another run");
  }
}

std::string RunFolder::file(const std::string& name) const {
  const fs::path p = fs::path(dir_) / name;
  if (fs::exists(p)) return p.string();
  // A file the run wrote and lists, gone since: the run is damaged, not a run without it (an evaluation took a
  // sample whose labels.exr was removed for one without labels, every object counted as detectable, exit 0).
  if (const auto files = meta_.find("files"); files != meta_.end() && files->is_array())
    for (const auto& f : *files)
      if (f.is_string() && f.get<std::string>() == name)
        throw Error(p.string() + ": listed in " + (fs::path(dir_) / "metadata.json").string() +
                    " (files) but missing: the run folder is damaged; restore the file, or run the scene again" +
                    " (a dataset's sample: `spadgen dataset run` generates it again, `spadgen dataset status` lists it)");
  return std::string();
}

}  // namespace spadgen::reconstruct
