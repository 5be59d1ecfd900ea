#include "reconstruct.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <optional>
#include <limits>
#include <map>
#include <set>
#include <memory>
#include <sstream>
#include <string_view>

#include "app/dataset.h"
#include "app/interrupt.h"
#include "app/metadata.h"
#include "app/progress.h"
#include "app/run_parts.h"
#include "app/staging.h"
#include "core/error.h"
#include "datasets/folder.h"
#include "reconstruct/detect.h"
#include "reconstruct/evaluate.h"
#include "reconstruct/run_folder.h"
#include "scenes/input.h"
#include "writers/writers.h"

namespace spadgen::app {
namespace fs = std::filesystem;
using reconstruct::Detection;
using reconstruct::RunFolder;

namespace {

constexpr int kBandRows = 8;

// Detections of every pixel of an image: `slots` per pixel, [slot * W * H + y * W + x]; NaN range in unused slots.
struct DetectionImage {
  int width = 0, height = 0, slots = 0;
  std::vector<float> count, range, gate, amplitude, score;
  DetectionImage(int w, int h, int m)
      : width(w), height(h), slots(m), count(size_t(w) * size_t(h), 0.0f),
        range(size_t(m) * count.size(), std::numeric_limits<float>::quiet_NaN()), gate(range), amplitude(range), score(range) {}
  size_t at(int slot, size_t pixel) const { return size_t(slot) * count.size() + pixel; }
  // (range, score) pairs of a pixel
  std::vector<std::pair<double, double>> of(size_t pixel) const {
    std::vector<std::pair<double, double>> d;
    for (int s = 0; s < slots; ++s)
      if (std::isfinite(range[at(s, pixel)])) d.emplace_back(range[at(s, pixel)], std::isnan(score[at(s, pixel)]) ? 0.0 : score[at(s, pixel)]);
    return d;
  }
};

// A detector with its parameters for one run: the edge detector's separation is the run's gate edge
// (the slower of rise and fall, plus the instrument response's FWHM) in gate steps, and a rise and a fall
// are one return within half of it.
struct Detector {
  std::string name;
  reconstruct::EdgeDetector edges;
  reconstruct::PaperDetector paper;

  Detector(const std::string& n, const RunFolder& run) : name(n) {
    if (name != "edges" && name != "paper") throw Error("--detector " + name + ": expected edges or paper");
    const double step_ps = run.gate_step_s() * 1e12, edge_ps = run.gate_edge_s() * 1e12;
    if (edge_ps > 0.0 && step_ps > 0.0) {
      // (at most K gate positions apart: an edge slower than the sweep is no edge the detector can pair)
      edges.separation = std::max(3, int(std::min(std::ceil(edge_ps / step_ps), double(std::max(run.K(), 3)))));
      // a rise and a fall of one return agree within their noise; two returns closer than half the
      // separation are not resolved anyway
      edges.match_s = 0.5 * edges.separation * step_ps * 1e-12;
    }
  }
  std::vector<Detection> operator()(const float* profile, int K, int frames, const reconstruct::PixelTiming& t, bool rates) const {
    return name == "edges" ? reconstruct::detect(edges, profile, K, frames, t, rates)
                           : reconstruct::detect(paper, profile, K, frames, t, rates);
  }
  nlohmann::json parameters() const {
    if (name == "paper")
      return {{"window", paper.window}, {"half_width", paper.half_width}, {"plateau", paper.plateau}, {"min_score", paper.min_score}};
    return {{"scales", edges.scales}, {"min_score", edges.min_score}, {"separation", edges.separation}, {"match_ps", edges.match_s * 1e12}};
  }
};

DetectionImage detect_image(const RunFolder& run, const Detector& detector, bool noise_free, int slots, bool progress) {
  if (!run.gate_sweep()) throw Error(run.dir() + ": a 2D intensity run has no gate profiles to detect returns in");
  DetectionImage img(run.width(), run.height(), slots);
  const int bands = (run.height() + kBandRows - 1) / kBandRows;
  Progress bar(size_t(bands), progress, "bands of rows");
  tbb::parallel_for(tbb::blocked_range<int>(0, bands, 1), [&](const tbb::blocked_range<int>& r) {
    std::vector<float> profiles;
    for (int b = r.begin(); b < r.end(); ++b) {
      InterruptGuard::check();
      const int y0 = b * kBandRows, y1 = std::min(run.height(), y0 + kBandRows);
      profiles.resize(size_t(y1 - y0) * size_t(run.width()) * size_t(run.K()));
      if (noise_free) run.rates(y0, y1, profiles.data());
      else run.profiles(y0, y1, false, profiles.data());
      for (int y = y0; y < y1; ++y)
        for (int x = 0; x < run.width(); ++x) {
          const float* p = profiles.data() + (size_t(y - y0) * size_t(run.width()) + size_t(x)) * size_t(run.K());
          std::vector<Detection> d = detector(p, run.K(), run.frames(), run.timing(x, y), noise_free);
          if (int(d.size()) > slots) {  // keep the strongest, in range order
            std::partial_sort(d.begin(), d.begin() + slots, d.end(),
                              [](const Detection& a, const Detection& c) { return std::abs(a.score) > std::abs(c.score); });
            d.resize(size_t(slots));
            std::sort(d.begin(), d.end(), [](const Detection& a, const Detection& c) { return a.range_m < c.range_m; });
          }
          const size_t i = size_t(y) * size_t(run.width()) + size_t(x);
          img.count[i] = float(d.size());
          for (size_t s = 0; s < d.size(); ++s) {
            img.range[img.at(int(s), i)] = float(d[s].range_m);
            img.gate[img.at(int(s), i)] = float(d[s].gate);
            img.amplitude[img.at(int(s), i)] = float(d[s].amplitude);
            img.score[img.at(int(s), i)] = float(d[s].score);
          }
        }
      bar.tick();
    }
  });
  return img;
}

// The folder of an output file takes new files, checked before the work rather than after it (a read-only
// file system was found once the detector had run over the whole image).
// Whether `target` is a file a listing owns: metadata.json, what its "files" list, or a file inside a listed
// folder (a Zarr store, light/); the entry it falls under, or "".
std::string listed_entry(const fs::path& target, const fs::path& folder, const nlohmann::json& metadata) {
  std::error_code ec;
  std::vector<std::string> own = {"metadata.json"};
  if (metadata.is_object() && metadata.contains("files") && metadata["files"].is_array())
    for (const nlohmann::json& f : metadata["files"])
      if (f.is_string()) own.push_back(f.get<std::string>());
  for (const std::string& f : own) {
    const fs::path listed = fs::weakly_canonical(fs::absolute(folder / f), ec);
    if (ec || listed.empty() || f.empty()) continue;  // (an empty path would be the prefix of every output)
    const auto [end, it] = std::mismatch(listed.begin(), listed.end(), target.begin(), target.end());
    if (end == listed.end()) return f;
  }
  return "";
}

// own_name: the name this output has by default at the run's top (detections_edges.exr, hdr_noise_free.exr):
// at a run's top no other of reconstruct's names is taken (-o RUN/detections_edges.exr of the paper detector was
// then scored as the edges detector's).
void check_writable(const std::string& file, const RunFolder& run, const std::string& run_dir, const std::string& own_name) {
  // The file is replaced by rename: whatever is at the path goes. A regular file (an earlier output) may;
  // a device, a FIFO, a folder or a symbolic link is not an output to replace (-o /dev/full replaced the
  // device node with an EXR, as root).
  struct stat st {};
  const bool exists = ::lstat(file.c_str(), &st) == 0;
  if (exists && !S_ISREG(st.st_mode))
    throw Error(file + ": exists and is " + (S_ISLNK(st.st_mode) ? "a symbolic link" : S_ISDIR(st.st_mode) ? "a folder" :
                                            S_ISFIFO(st.st_mode) ? "a FIFO" : S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) ? "a device" : "not a regular file") +
                ", which writing the output would replace; expected a new file or an earlier output (-o)");
  const fs::path dir = fs::absolute(fs::path(file)).parent_path();
  if (!fs::is_directory(dir)) throw Error(file + ": its folder " + dir.string() + " does not exist");
  // The file is written as .NAME.tmp-<pid>-<n> beside it first (a pid of up to 7 digits, a counter of up to 4):
  // a name the file system takes could not take those ("File name too long", after the detector had run).
  {
    constexpr size_t kAddition = std::char_traits<char>::length("..tmp--") + 7 + 4;
    const long name_max = ::pathconf(dir.c_str(), _PC_NAME_MAX);
    const size_t most = (name_max > 0 ? size_t(name_max) : 255) - kAddition;
    if (const size_t n = fs::path(file).filename().string().size(); n > most)
      throw Error(file + ": its name is " + std::to_string(n) + " bytes long; it is written into a hidden file beside it " +
                  "whose name adds " + std::to_string(kAddition) + " bytes to it first, so expected a name of at most " +
                  std::to_string(most) + " bytes (-o)");
  }
  // Nor is a file of the run itself (-o RUN/counts.npy replaced the counts with an EXR, and every later
  // reconstruct or evaluate of the run failed): metadata.json and what it lists, or a file inside a listed
  // folder (a Zarr store, light/); nor a file of another run, or of a dataset (-o OTHER/counts.npy,
  // -o DATASET/index.jsonl replaced them, exit 0), nor any other file in a run folder (it holds what spadgen writes there only: a later run into
  // it, or a dataset's check of its sample, refused it for a foreign file): the nearest folder above the
  // target holding a spadgen run's metadata.json takes reconstruct's own outputs at its top only
  // (is_derived_output; its evaluation/ is evaluate's); else one holding a dataset's dataset.json refuses
  // its own entries (samples, index, card, evaluation/ ...); a folder holding sense --repeats'
  // realisations (repeat_000/) holds those only.
  // The run being read is known by its metadata already (and, in the messages, as "the run").
  std::error_code ec;
  const fs::path target = fs::weakly_canonical(fs::absolute(fs::path(file)), ec);
  const fs::path own_run = fs::weakly_canonical(fs::absolute(fs::path(run_dir)), ec);
  for (fs::path folder = target.parent_path(); !folder.empty(); folder = folder.parent_path()) {
    const bool the_run = folder == own_run;
    if (the_run || fs::is_regular_file(folder / "metadata.json", ec)) {
      nlohmann::json meta;
      if (the_run) {
        meta = run.metadata();
      } else {
        try {  // (not a run's when it does not read as one)
          const std::string m = (folder / "metadata.json").string();
          meta = scenes::parse_json(scenes::read_file_bounded(m, 256u << 20, "metadata"), m);
        } catch (const Error&) {
        }
      }
      if (the_run || (meta.is_object() && meta.contains("spadgen_version"))) {
        if (const std::string f = listed_entry(target, folder, meta); !f.empty())
          throw Error(file + (the_run ? ": is the run's own " + f + " (" + run_dir + "/metadata.json lists it)"
                                      : ": is the run " + folder.string() + "'s own " + f + " (its metadata.json lists it)") +
                      ", which writing the output would replace; expected a new file or an earlier output (-o)");
        const fs::path rel = target.lexically_relative(folder);
        // (only the run reconstructed: its outputs at another run's top were scored as that run's)
        if (the_run && std::distance(rel.begin(), rel.end()) == 1 && rel != "evaluation" && is_derived_output(rel.string())) {
          if (rel.string() == own_name) break;
          throw Error(file + ": is the name of another of reconstruct's outputs at the top of the run folder " + folder.string() +
                      ", which evaluate and Python read as that output; this one's is " + own_name +
                      " (-o: that name, or a file outside run folders)");
        }
        throw Error(file + ": lies in the run folder " + folder.string() + ", which holds only what spadgen writes there (a "
                    "later run into it, or a dataset's check of it, would refuse the folder for a foreign file); expected a "
                    "file outside run folders, or one of reconstruct's own names at the top of the run it reads "
                    "(detections_edges.exr, detections_paper.exr, hdr.exr, or their _noise_free.exr) (-o)");
      }
    }
    if (fs::is_regular_file(folder / "dataset.json", ec)) {
      const fs::path rel = target.lexically_relative(folder);
      if (!rel.empty() && datasets::own_entries().count(rel.begin()->string()))
        throw Error(file + ": is the dataset " + folder.string() + "'s own " + rel.string() + ", which writing the output "
                    "would replace or add to; expected a new file or an earlier output (-o)");
    }
    if (reconstruct::is_repeat_set(folder))
      throw Error(file + ": lies in the folder " + folder.string() + " of sense --repeats' realisations, which holds those only; "
                  "expected a file outside it (-o)");
    if (folder == folder.root_path()) break;
  }
  // (After the walk, whose messages name whose file it is.) A regular file there is replaced only when it is
  // an earlier output of reconstruct, an OpenEXR file whose header names its spadgen_reconstruct attribute
  // (-o my.json replaced a scene file with an EXR, exit 0), or empty (a placeholder such as mktemp's).
  if (exists && st.st_size > 0) {
    std::string head(size_t(64) << 10, '\0');
    std::ifstream in(file, std::ios::binary);
    if (!in)
      throw Error(file + ": exists and cannot be read (" + std::strerror(errno) + "), so it cannot be told an earlier output "
                  "of spadgen reconstruct, which writing the output would replace; expected a new file or an earlier output (-o)");
    in.read(head.data(), std::streamsize(head.size()));
    head.resize(size_t(in.gcount()));
    static const std::string kMagic("\x76\x2f\x31\x01", 4), kMark("spadgen_reconstruct\0", 20);
    if (head.compare(0, 4, kMagic) != 0 || head.find(kMark) == std::string::npos)
      throw Error(file + ": exists and is not an output of spadgen reconstruct (" +
                  (head.compare(0, 4, kMagic) != 0 ? std::string("not an OpenEXR file") : "an OpenEXR file without its spadgen_reconstruct attribute") +
                  "), which writing the output would replace; expected a new file or an earlier output (-o)");
  }
  // An OpenEXR image under another name: evaluate --detections reads a .npy name as a NumPy array of detections
  // (-o det.npy wrote an EXR, exit 0, which evaluate then refused).
  if (fs::path(file).extension() != ".exr")
    throw Error(file + ": reconstruct writes an OpenEXR image, which evaluate --detections tells by its name (a .npy name "
                "is read as a NumPy array of detections); expected a name ending in .exr (-o)");
  if (::access(dir.c_str(), W_OK) != 0)
    throw Error(file + ": cannot write into " + dir.string() + ": " + std::strerror(errno));
  // the temporary file a reconstruct killed while it wrote this one left (stayed for ever beside the run's files):
  // in the run folder, whose lock this process holds (a writer of another pid namespace or host, elsewhere, may
  // live without a pid here)
  if (std::error_code same; fs::equivalent(dir, fs::path(run_dir), same)) writers::remove_dead_temporaries(dir.string(), {fs::path(file).filename().string()});
}

std::string slot_name(int s, const char* what) { return "det" + std::to_string(s) + "." + what; }

// A range is metres from the camera centre, or NaN for no detection: an infinite one is neither (it was
// skipped silently, as if the detector had found nothing there), and a negative one is not a distance (a
// sentinel such as -1 for "none" was counted as a false detection).
void check_ranges(const std::string& path, const DetectionImage& img) {
  for (int s = 0; s < img.slots; ++s)
    for (size_t i = 0; i < img.count.size(); ++i)
      if (const float r = img.range[img.at(s, i)]; std::isinf(r) || r < 0.0f) {
        std::ostringstream v;
        v << r;
        throw Error(path + ": pixel (x " + std::to_string(i % size_t(img.width)) + ", y " + std::to_string(i / size_t(img.width)) +
                    ") slot " + std::to_string(s) + " holds " + (std::isinf(r) ? "an infinite" : "a negative") + " range (" +
                    v.str() + "); expected metres >= 0 from the camera centre, or NaN for no detection");
      }
}

// The detections file (docs/detection.md): an EXR with `count` and det<i>.range (metres; NaN: none), and
// optionally det<i>.score; or a float .npy (H, W, M) of ranges, NaN where there is none.
// What the scene was set to, which the scene hash does not see (settings_hash_of, metadata.h); null for a run
// that records no resolved scene.
nlohmann::json settings_hash(const nlohmann::json& meta) {
  const auto it = meta.find("resolved_scene");
  if (it == meta.end() || !it->is_object()) return nullptr;
  return settings_hash_of(*it);
}

// What a derived file records of the run it was made from (its spadgen_source, with the run's path) and
// check_source compares: the seed, the scene's hash, the crop of the sensor, the settings hash (null where
// metadata lacks them).
nlohmann::json source_fields(const RunFolder& run) {
  const auto& m = run.metadata();
  return {{"seed", m.value("seed", nlohmann::json(nullptr))},
          {"scene_hash_fnv1a64", m.value("scene_hash_fnv1a64", nlohmann::json(nullptr))},
          {"crop_in_sensor", m.value("/image/crop_in_sensor"_json_pointer, nlohmann::json(nullptr))},
          {"settings_hash", settings_hash(m)}};
}

// What the detections file says it was made from (reconstruct's spadgen_source), against the run it is
// scored on: another scene file or glTF (scene_hash_fnv1a64), or another crop of the sensor, is refused;
// another run of the same scene and crop (another seed, a sense realisation) is scored. `source` records
// whether the check could be made (a .npy, or an EXR written elsewhere, names no source).
void check_source(const std::string& path, const std::map<std::string, std::string>& attributes, const RunFolder& run,
                  nlohmann::json* source) {
  const auto it = attributes.find("spadgen_source");
  if (it == attributes.end()) {
    if (source) (*source)["source_checked"] = "no: the file names no run (spadgen_source); its scene and crop are taken on trust";
    return;
  }
  const nlohmann::json made = nlohmann::json::parse(it->second, nullptr, false);
  if (!made.is_object()) {
    if (source) (*source)["source_checked"] = "no: its spadgen_source is not a JSON object (unreadable); its scene and crop are taken on trust";
    return;
  }
  const nlohmann::json ours_all = source_fields(run);
  const std::string made_from = made.contains("run") && made["run"].is_string() ? made["run"].get<std::string>() : "?";
  std::string unchecked;  // what the file does not say, so was not compared
  for (const auto& [key, what] : {std::pair<std::string, std::string>{"scene_hash_fnv1a64", "scene (scene file and glTF hash)"},
                                  {"crop_in_sensor", "crop of the sensor"}}) {
    const nlohmann::json& ours = ours_all[key];
    if (!made.contains(key) || made[key].is_null() || ours.is_null()) {
      unchecked += (unchecked.empty() ? "" : " and its ") + what;
      continue;
    }
    if (made[key] != ours)
      throw Error(path + ": detections of another " + what + " than " + run.dir() + "'s (made from " + made_from + ": " +
                  made[key].dump() + ", this run: " + ours.dump() + "); run spadgen reconstruct on " + run.dir() +
                  ", or give --detections of this scene and crop");
  }
  // Made with other settings (--set values, a dataset sample's parameters and set: the scene hash does not
  // see them): refused as another scene's are; another seed's or path count's are scored. A file of an
  // earlier spadgen names none: said unchecked.
  const nlohmann::json& ours_s = ours_all["settings_hash"];
  const nlohmann::json theirs_s = made.value("settings_hash", nlohmann::json(nullptr));
  if (ours_s.is_string() && theirs_s.is_string() && theirs_s != ours_s)
    throw Error(path + ": detections of a run of other settings than " + run.dir() + " (made from " + made_from +
                ": its resolved scene differs in a --set value, a dataset sample's parameters or the dataset's set, not "
                "only in seeds, outputs or render settings); run spadgen reconstruct on " + run.dir() +
                ", or give --detections of this run");
  if (!ours_s.is_string() || !theirs_s.is_string()) {
    if (!unchecked.empty()) unchecked += " and its ";
    unchecked += "settings (--set values, dataset parameters; an earlier spadgen's file names none)";
  }
  if (source)
    (*source)["source_checked"] = unchecked.empty() ? "yes: made from " + made_from + ", the same scene, settings and crop"
                                                    : "no: its spadgen_source names no " + unchecked +
                                                          " (made from " + made_from + "); taken on trust";
}

DetectionImage read_detections(const std::string& path, const RunFolder& run, bool need_scores, nlohmann::json* source) {
  const int width = run.width(), height = run.height();
  if (std::error_code ec; !fs::exists(path, ec))
    throw Error(path + ": no such file; expected the detections file --detections names (of a dataset: a file of that "
                "name in every sample's folder)");
  if (!fs::is_regular_file(path)) throw Error(path + ": not a regular file (a FIFO, a device or a folder); expected a detections EXR or .npy");
  if (fs::path(path).extension() == ".npy") {
    const writers::NpyReader npy = [&] {
      try {
        return writers::NpyReader(path);
      } catch (const Error& e) {
        throw Error(std::string(e.what()) + " (detections: a C-order float32 or float64 array (H, W, M) of ranges; "
                    "np.save(f, np.ascontiguousarray(a, np.float32)) writes one)");
      }
    }();
    // A stack of the run itself (counts.npy, expected_counts.npy: (K, H, W)) is no detections file (its shape
    // was read as a transposed detections array, and the advice led to a dtype error).
    {
      std::error_code ec_target, ec_folder;
      const fs::path target = fs::weakly_canonical(fs::absolute(fs::path(path)), ec_target);
      const fs::path folder = fs::weakly_canonical(fs::absolute(fs::path(run.dir())), ec_folder);
      if (const std::string f = ec_target || ec_folder ? std::string() : listed_entry(target, folder, run.metadata()); !f.empty())
        throw Error(path + ": is the run's own " + f + " (" + run.dir() + "/metadata.json lists it), not detections; expected "
                    "a detector's output: spadgen reconstruct's detections_<detector>.exr, or a float32 or float64 .npy (H, W, M) "
                    "of ranges in metres");
    }
    // the dtype first (a uint8 (K, H, W) stack was said to be a transposed detections array)
    if (npy.dtype() != writers::Dtype::F64 && npy.dtype() != writers::Dtype::F32)
      throw Error(path + ": its dtype is " + writers::numpy_descr(npy.dtype()) + "; expected <f4 or <f8 ranges in metres");
    if (npy.shape().size() != 3 || npy.shape()[0] != height || npy.shape()[1] != width) {
      std::string found;
      for (int64_t d : npy.shape()) found += (found.empty() ? "" : ", ") + std::to_string(d);
      if (npy.shape().size() == 1) found += ",";
      const bool mhw = npy.shape().size() == 3 && npy.shape()[1] == height && npy.shape()[2] == width;
      throw Error(path + ": expected a float32 or float64 array (H, W, M) = (" + std::to_string(height) + ", " + std::to_string(width) +
                  ", M) of ranges, found shape (" + found + ")" +
                  (mhw ? std::string(": (M, H, W), as Python's Run.detections().range gives it; np.moveaxis(a, 0, -1) is (H, W, M)") : ""));
    }
    if (need_scores)
      throw Error(path + ": --min-score: a .npy of ranges holds no scores (an EXR's det<i>.score does); leave --min-score out");
    check_source(path, {}, run, source);
    const int m = int(npy.shape()[2]);
    DetectionImage img(width, height, m);
    // float64 (NumPy's default) is taken too, to float32: 1 um at 10 m, far below any tolerance
    const bool f64 = npy.dtype() == writers::Dtype::F64;
    const float* v = f64 ? nullptr : npy.data<float>();
    const double* v64 = f64 ? npy.data<double>() : nullptr;
    for (size_t i = 0; i < img.count.size(); ++i)
      for (int s = 0; s < m; ++s) {
        const size_t at = i * size_t(m) + size_t(s);
        // a double beyond float's range (its conversion would be undefined)
        if (f64 && std::isfinite(v64[at]) && std::abs(v64[at]) > double(std::numeric_limits<float>::max()))
          throw Error(path + ": the range " + nlohmann::json(v64[at]).dump() + " m at pixel (x " + std::to_string(i % size_t(width)) + ", y " +
                      std::to_string(i / size_t(width)) + "), detection " + std::to_string(s) + ", is beyond float32's range; expected metres");
        const float r = f64 ? static_cast<float>(v64[at]) : v[at];
        img.range[img.at(s, i)] = r;
        img.count[i] += std::isfinite(r);
      }
    check_ranges(path, img);
    return img;
  }
  writers::ExrData e;
  try {
    e = writers::read_exr(path);
  } catch (const Error& err) {
    throw Error(std::string(err.what()) + " (a detections file is an OpenEXR image, or a NumPy array named *.npy: the "
                "extension .npy selects the NumPy reader)");
  }
  // pixels at other positions than the image's (a shifted data window was scored one row off)
  if (!e.partial_window.empty())
    throw Error(path + ": its " + e.partial_window + "; expected the whole image's pixels (a data window equal to the display window)");
  if (e.width != width || e.height != height)
    throw Error(path + ": " + std::to_string(e.width) + " x " + std::to_string(e.height) + " pixels, the run has " +
                std::to_string(width) + " x " + std::to_string(height));
  int m = 0;
  while (e.channels.count(slot_name(m, "range"))) ++m;
  if (m == 0) throw Error(path + ": no channel det0.range (a detections file holds det<i>.range in metres, NaN where there is none)");
  for (const auto& [name, v] : e.channels)
    if (name.rfind("det", 0) == 0 && name.size() > 9 && name.compare(name.size() - 6, 6, ".range") == 0 &&
        name.find_first_not_of("0123456789", 3) == name.size() - 6 && std::stoll(name.substr(3, std::min<size_t>(name.size() - 9, 9))) >= m)
      throw Error(path + ": channel " + name + " after " + slot_name(m - 1, "range") + " without " + slot_name(m, "range") +
                  " (slots are numbered det0, det1, ... without gaps; the slots after a gap would not be scored)");
  if (need_scores)
    for (int s = 0; s < m; ++s)
      if (!e.channels.count(slot_name(s, "score")))
        throw Error(path + ": --min-score: slot " + std::to_string(s) + " has no " + slot_name(s, "score") +
                    " channel (every slot's detections would be dropped); leave --min-score out, or give the scores");
  check_source(path, e.attributes, run, source);
  if (const auto made = e.attributes.find("spadgen_reconstruct"); source && made != e.attributes.end()) {
    const nlohmann::json by = nlohmann::json::parse(made->second, nullptr, false);
    if (by.is_object() && by.contains("detector"))  // which of reconstruct's detectors wrote it, and from what
      (*source)["made_by"] = {{"detector", by["detector"]},
                              {"noise_free", by.contains("noise_free") && by["noise_free"].is_boolean() && by["noise_free"].get<bool>()}};
  }
  DetectionImage img(width, height, m);
  for (int s = 0; s < m; ++s) {
    const auto& r = e.channels[slot_name(s, "range")];
    std::copy(r.begin(), r.end(), img.range.begin() + std::ptrdiff_t(img.at(s, 0)));
    if (e.channels.count(slot_name(s, "score"))) {
      const auto& sc = e.channels[slot_name(s, "score")];
      std::copy(sc.begin(), sc.end(), img.score.begin() + std::ptrdiff_t(img.at(s, 0)));
    }
  }
  for (size_t i = 0; i < img.count.size(); ++i)
    for (int s = 0; s < m; ++s) {
      const bool found = std::isfinite(img.range[img.at(s, i)]);
      img.count[i] += found;
      // --min-score compares the score: a NaN one would drop the detection without a word
      if (need_scores && found && std::isnan(img.score[img.at(s, i)]))
        throw Error(path + ": --min-score: " + slot_name(s, "score") + " is NaN at pixel (x " + std::to_string(i % size_t(width)) +
                    ", y " + std::to_string(i / size_t(width)) + "), where " + slot_name(s, "range") +
                    " holds a detection; expected a number (or leave --min-score out)");
    }
  check_ranges(path, img);
  return img;
}

std::string provenance(const RunFolder& run) {
  nlohmann::json p = source_fields(run);
  p["run"] = fs::absolute(run.dir()).lexically_normal().string();
  return p.dump();
}

// The object labels of a run: per pixel, its objects (ground_truth.exr, labels.exr).
struct Labels {
  std::vector<std::vector<reconstruct::TruthObject>> pixels;
  std::map<int, std::string> names;
  bool detectability = false;
};

Labels read_labels(const RunFolder& run) {
  const std::string gt_path = run.file("ground_truth.exr");
  if (gt_path.empty()) throw Error(run.dir() + ": no ground_truth.exr (outputs.ground_truth) to score against");
  const writers::ExrData gt = writers::read_exr(gt_path);
  if (!gt.channels.count("object_count"))
    throw Error(gt_path + ": no object channels (object_count, object<j>.range): written by an older spadgen; run the scene again");
  writers::ExrData labels;
  const std::string labels_path = run.file("labels.exr");
  if (!labels_path.empty()) labels = writers::read_exr(labels_path);
  // Both images are the run's (a file replaced since, of another crop, was read past its end).
  // (of the run's size and crop: another run's ground truth of the same size was scored, recall 75 % for 99.97 %)
  run.check_image(gt_path, gt);
  Labels l;
  l.detectability = labels.channels.count("object0.detectable") > 0;
  // A labels.exr always holds slot 0 (object0.id -1 where no object is in view): one without it is another
  // image in its place (a ground_truth.exr copied there was scored as a run without labels, exit 0).
  if (!labels_path.empty() && !l.detectability)
    throw Error(labels_path + ": no channel object0.detectable; expected the labels a gate sweep writes (object<j>.id, "
                ".edge_counts, .edge_snr, .detectable, slot 0 at least): another image in its place; restore the run's, or "
                "run the scene again");
  if (!labels_path.empty()) run.check_image(labels_path, labels, /*of_the_chip=*/true);
  const size_t n = size_t(run.width()) * size_t(run.height());
  l.pixels.resize(n);
  for (int j = 0; gt.channels.count("object" + std::to_string(j) + ".range"); ++j) {
    const std::string p = "object" + std::to_string(j) + ".";
    if (!gt.channels.count(p + "id"))
      throw Error(gt_path + ": channel " + p + "range without " + p + "id: not a ground truth spadgen wrote; run the scene again");
    if (l.detectability && !labels.channels.count(p + "detectable"))
      throw Error(labels_path + ": no channel " + p + "detectable, while " + gt_path + " has object slot " +
                  std::to_string(j) + ": the two files are not of one run; run the scene again");
    const auto& range = gt.channels.at(p + "range");
    const auto& id = gt.channels.at(p + "id");
    const std::vector<float>* det = l.detectability ? &labels.channels.at(p + "detectable") : nullptr;
    // The labels' slots are the ground truth's: the same object in each pixel's slot j (a labels.exr of
    // another scene, or with its slots in another order, would score one object by another's edge).
    if (det && labels.channels.count(p + "id")) {
      const auto& label_id = labels.channels.at(p + "id");
      for (size_t i = 0; i < n; ++i)
        if (label_id[i] != id[i] && !(std::isnan(label_id[i]) && std::isnan(id[i]))) {
          std::ostringstream m;
          m << labels_path << ": pixel (x " << i % size_t(run.width()) << ", y " << i / size_t(run.width())
            << ") holds object id " << label_id[i] << " in slot " << j << ", " << gt_path << " object id " << id[i]
            << ": the two files are not of one run; run the scene again";
          throw Error(m.str());
        }
    }
    for (size_t i = 0; i < n; ++i)
      if (std::isfinite(range[i]) && id[i] >= 0.0f) l.pixels[i].push_back({int(id[i]), range[i], det ? (*det)[i] > 0.5f : true});
  }
  // The objects' names, for the metrics: a list of {"id": integer, "name": string}, as a run writes it (a
  // damaged one was an internal error: value() of a number).
  if (const auto& meta = run.metadata(); meta.contains("objects")) {
    const nlohmann::json& objects = meta["objects"];
    const auto damaged = [&](const std::string& what) {
      return Error((fs::path(run.dir()) / "metadata.json").string() + ": objects " + what +
                   "; expected a list of {\"id\": integer, \"name\": text, ...} as a run writes it (run the scene again)");
    };
    if (!objects.is_array()) throw damaged("is not a list");
    for (size_t k = 0; k < objects.size(); ++k) {
      const nlohmann::json& o = objects[k];
      if (!o.is_object() || !o.contains("id") || !o["id"].is_number_integer() || !(o["id"].get<double>() >= 0.0) ||
          !(o["id"].get<double>() < 2147483647.0) || (o.contains("name") && !o["name"].is_string()))
        throw damaged("entry " + std::to_string(k) + " is " + scenes::printable(o.dump()).substr(0, 60));
      l.names[o["id"].get<int>()] = o.value("name", "");
    }
  }
  return l;
}

// Blue (detection too near) through white to red (too far), over +-tolerance; grey: no object; black: missed.
void write_maps(const std::string& dir, int w, int h, const std::vector<reconstruct::PixelOutcome>& o, double tolerance) {
  std::vector<uint8_t> err(size_t(w) * size_t(h) * 3), outcome(err.size());
  for (size_t i = 0; i < o.size(); ++i) {
    uint8_t* e = &err[3 * i];
    uint8_t* c = &outcome[3 * i];
    if (o[i].objects == 0) {
      e[0] = e[1] = e[2] = 64;
    } else if (std::isnan(o[i].first_error_m)) {
      e[0] = e[1] = e[2] = 0;
    } else {
      const double t = std::clamp(double(o[i].first_error_m) / tolerance, -1.0, 1.0);
      const auto fade = [](double a) { return uint8_t(std::lround(255.0 * (1.0 - a))); };
      e[0] = t < 0 ? fade(-t) : 255, e[1] = fade(std::abs(t)), e[2] = t > 0 ? fade(t) : 255;
    }
    // green: every object found, no false detection; yellow: objects missed; red: false detections; grey: nothing there
    if (o[i].false_detections > 0) c[0] = 230, c[1] = 30, c[2] = 30;
    else if (o[i].found < o[i].objects) c[0] = 240, c[1] = 200, c[2] = 20;
    else if (o[i].objects > 0) c[0] = 30, c[1] = 180, c[2] = 60;
    else c[0] = c[1] = c[2] = 64;
  }
  writers::write_png((fs::path(dir) / "range_error.png").string(), w, h, 3, err);
  writers::write_png((fs::path(dir) / "outcome.png").string(), w, h, 3, outcome);
}

reconstruct::EvaluateOptions scorer_options(const EvaluateCommand& c) {
  reconstruct::EvaluateOptions o;
  o.tolerance_m = c.tolerance_m;
  if (c.min_score) o.min_score = *c.min_score;
  o.region = c.region;
  return o;
}

// The default file of a reconstruction: from the expected counts it is another file than from the sampled
// ones, so that neither replaces the other.
std::string derived_name(const std::string& stem, bool noise_free) { return stem + (noise_free ? "_noise_free" : "") + ".exr"; }

// Scores one run; with maps_dir, writes its error maps there.
reconstruct::Scores evaluate_run(const EvaluateCommand& c, const std::string& run_dir, const std::string& detections,
                                 const std::string& maps_dir, std::map<int, std::string>* names, nlohmann::json* source,
                                 std::map<std::string, int>* ids_by_name = nullptr) {
  const RunFolder run(run_dir);
  // (in 64 bits: x0 + width of int overflowed, and a rectangle of 2147483647 pixels passed)
  if (const auto& r = c.region; r && (r->x0 < 0 || r->y0 < 0 || int64_t{r->x0} + r->width > run.width() ||
                                      int64_t{r->y0} + r->height > run.height()))
    throw Error("--region " + std::to_string(r->x0) + "," + std::to_string(r->y0) + "," + std::to_string(r->width) + "," +
                std::to_string(r->height) + ": expected a rectangle inside " + run_dir + "'s " + std::to_string(run.width()) +
                " x " + std::to_string(run.height()) + " pixels (x, y from its top left)");
  if (run.ambiguity_m() > 0.0 && c.tolerance_m >= run.ambiguity_m() / 2.0) {
    std::ostringstream t;
    t << "--tolerance-m " << c.tolerance_m << ": expected less than half the range one laser period spans, c T / 4 = "
      << run.ambiguity_m() / 2.0 << " m for " << run_dir << " (errors are taken modulo c T / 2 = " << run.ambiguity_m()
      << " m, into [-c T / 4, c T / 4): a wider tolerance would match a detection to an object's other fold)";
    throw Error(t.str());
  }
  Labels labels = read_labels(run);
  if (ids_by_name) {
    // A dataset's objects are counted by name across its samples (a sample's ids are its own scene's): each
    // name gets one id, in the order the samples name them; an object without a name keeps its own.
    std::map<int, int> to;
    std::map<int, std::string> renamed;
    for (const auto& [id, name] : labels.names) {
      const std::string key = name.empty() ? "object " + std::to_string(id) : name;
      const auto [it, added] = ids_by_name->emplace(key, int(ids_by_name->size()));
      to[id] = it->second;
      renamed[it->second] = key;
    }
    for (auto& px : labels.pixels)
      for (reconstruct::TruthObject& o : px)
        if (const auto t = to.find(o.id); t != to.end()) o.id = t->second;
    labels.names = std::move(renamed);
  }
  if (names) names->insert(labels.names.begin(), labels.names.end());
  const std::string file =
      detections.empty() ? (fs::path(run_dir) / derived_name("detections_" + c.detector, c.noise_free)).string() : detections;
  const bool compute = detections.empty() && !fs::exists(file);  // the default file is absent: run the detector
  if (source)
    *source = compute ? nlohmann::json{{"detector", c.detector}, {"computed", true}, {"noise_free", c.noise_free}}
                      : nlohmann::json{{"file", file}};
  // As reconstruct writes it by default (its slots too), so that the scores are those of its file.
  nlohmann::json read_source;  // (what the file says of itself, also when the caller keeps none)
  DetectionImage img = compute ? detect_image(run, Detector(c.detector, run), c.noise_free, ReconstructOptions{}.max_detections, false)
                               : read_detections(file, run, c.min_score.has_value(), source ? source : &read_source);
  // The default file stands for --detector (and --noise-free): one another detector wrote is refused.
  if (const nlohmann::json& s = source ? *source : read_source; detections.empty() && !compute && s.contains("made_by")) {
    const nlohmann::json want = {{"detector", c.detector}, {"noise_free", c.noise_free}};
    if (s["made_by"] != want)
      throw Error(file + ": written by reconstruct's " +
                  (s["made_by"]["detector"].is_string() ? s["made_by"]["detector"].get<std::string>() : s["made_by"]["detector"].dump()) +
                  (s["made_by"]["noise_free"] == true ? " detector on the noise-free rates" : " detector") + ", not the " +
                  c.detector + " detector" + (c.noise_free ? " on the noise-free rates" : "") +
                  " its name stands for; run `spadgen reconstruct " + run_dir + (c.detector == "edges" ? "" : " --detector " + c.detector) +
                  (c.noise_free ? " --noise-free" : "") + "` again, or give it with --detections");
  }
  if (source && !labels.detectability) (*source)["labels"] = "labels.exr absent: every object counted as detectable";
  reconstruct::EvaluateOptions options = scorer_options(c);
  options.ambiguity_m = run.ambiguity_m();
  reconstruct::Scores scores(options);
  std::vector<reconstruct::PixelOutcome> outcome(labels.pixels.size());
  for (int y = 0; y < run.height(); ++y)
    for (int x = 0; x < run.width(); ++x) {
      const size_t i = size_t(y) * size_t(run.width()) + size_t(x);
      outcome[i] = scores.add(x, y, labels.pixels[i], img.of(i), run.bistatic(x, y));
    }
  if (!maps_dir.empty()) write_maps(maps_dir, run.width(), run.height(), outcome, c.tolerance_m);
  return scores;
}

std::string percent(const nlohmann::json& v) {
  if (!v.is_number()) return "-";
  std::ostringstream s;
  s << std::fixed << std::setprecision(1) << 100.0 * v.get<double>() << " %";
  return s.str();
}

// metrics.json's "scored" in words: "--detector edges", "--detector paper --noise-free", "--detections FILE".
// An earlier metrics.json edited by hand may hold anything there: "?" for what it does not say.
std::string scored_text(const nlohmann::json& scored) {
  if (!scored.is_object()) return "?";
  if (scored.contains("detections") && scored["detections"].is_string()) return "--detections " + scored["detections"].get<std::string>();
  const std::string detector = scored.contains("detector") && scored["detector"].is_string() ? scored["detector"].get<std::string>() : "?";
  return "--detector " + detector + (scored.contains("noise_free") && scored["noise_free"] == true ? " --noise-free" : "");
}

// An earlier evaluation's metrics.json, or none when it is absent, no regular file, larger than 1 GB or not
// JSON (read as the program reads its files: bounded, and never a FIFO's blocking open).
std::optional<nlohmann::json> read_json_if_valid(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return std::nullopt;
  try {
    return scenes::parse_json(scenes::read_file_bounded(path.string(), uint64_t{1} << 30, "metrics"), path.string());
  } catch (const Error&) {
    return std::nullopt;
  }
}

std::string summary(const nlohmann::json& m) {
  std::ostringstream s;
  s << "objects found: " << percent(m["objects"]["recall"]) << " of " << m["objects"]["objects"] << " (detectable: "
    << percent(m["objects_detectable"]["recall"]) << " of " << m["objects_detectable"]["objects"] << ")\n";
  s << "detections: " << m["detections"]["total"] << ", precision " << percent(m["detections"]["precision"]) << ", false "
    << m["detections"]["false"] << "\n";
  // Matches a whole laser period's range off their object: real for a return folded by the period, but the
  // sign of ranges not in metres when they are most matches (millimetres scored recall 11 % and a bias of 0.6 mm,
  // saying nothing)
  if (const int64_t across = m["detections"].value("matched_across_period", int64_t{0}); across > 0) {
    const int64_t matched = m["detections"].value("matched", int64_t{0});
    s << "matched across the laser period: " << across << " of the " << matched
      << " matched detections lie a whole c T / 2 (the laser period's range) or more off their object";
    if (2 * across > matched)
      s << ": most matches; are the detections' ranges in metres from the camera centre, as evaluate reads them?";
    s << "\n";
  }
  if (m["range_error"].value("bias_mm", nlohmann::json()).is_number())
    s << "range error: bias " << std::setprecision(3) << m["range_error"]["bias_mm"].get<double>() << " mm, rms "
      << m["range_error"]["rms_mm"].get<double>() << " mm, |error| p90 " << m["range_error"]["abs_p90_mm"].get<double>() << " mm\n";
  return s.str();
}

// The folders of a dataset's done samples as its index.jsonl lists them (the samples a run has published;
// not every folder under samples/: stale ones, those past the dataset's samples and those a run has not
// finished are not done), in index order, each sample's realisations after it; `not_done` counts the rows
// not done by status (empty when every row is done). A folder whose metadata.json carries another hash than its
// row was generated again since the index was written: refused; each folder comes with the hash it carries.
struct DoneFolder {
  fs::path path;
  std::string sample_hash;
  bool intensity = false;  // a 2D intensity run (its metadata.json's acquisition.mode)
  // the index row's: the sample's index, the realisation (0: the sample's own folder), its parameters
  int64_t index = -1;
  int repeat = 0;
  nlohmann::ordered_json parameters = nlohmann::ordered_json::object();
};
// only: the dataset indices to take (nullptr: every row); samples: set to the samples the index knows (its
// largest index + 1).
std::vector<DoneFolder> done_sample_folders(const fs::path& dir, std::map<std::string, int>& not_done,
                                            const SampleSelection* only = nullptr, int64_t* samples = nullptr) {
  const fs::path index = dir / "index.jsonl";
  if (!fs::is_regular_file(index))
    throw Error(dir.string() + ": a dataset folder without index.jsonl: " +
                (datasets::dataset_runs_on(dir)
                     ? "the first `spadgen dataset run` into it is still running (the last run on the folder to end writes "
                       "the index); wait for it to finish"
                     : "the first `spadgen dataset run` into it was killed (the last run on the folder to end writes the "
                       "index, also when stopped by SIGINT or SIGTERM); run it again to finish"));
  std::istringstream lines(scenes::read_file_bounded(index.string(), int64_t{1} << 36, "index.jsonl"));
  std::vector<DoneFolder> out;
  std::set<std::string> seen;
  not_done.clear();
  int row = 0;
  for (std::string line; std::getline(lines, line);) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    ++row;
    const std::string where = index.string() + " row " + std::to_string(row);
    nlohmann::json r;
    try {
      r = nlohmann::json::parse(line);
    } catch (const nlohmann::json::exception&) {
      throw Error(where + ": not JSON; `spadgen dataset run` writes the index whole, so it was damaged afterwards: run the "
                  "dataset again to write it");
    }
    const auto text = [&](const nlohmann::json& j, const char* key) {
      if (!j.is_object() || !j.contains(key) || !j[key].is_string())
        throw Error(where + ": expected a string \"" + key + "\" (an index row spadgen wrote); run the dataset again to write it");
      return j[key].get<std::string>();
    };
    // Row N lists sample N - 1, as `spadgen dataset run` writes it (`dataset status` checks it): a row removed
    // was scored as the rows left, without a word.
    if (!r.is_object() || !r.contains("index") || !r["index"].is_number_integer() || r["index"].get<int64_t>() != row - 1)
      throw Error(where + ": lists sample " + (r.is_object() && r.contains("index") ? r["index"].dump().substr(0, 40) : std::string("none")) +
                  " where sample " + std::to_string(row - 1) + " belongs (the index lists every sample in index order); the "
                  "index was damaged after `spadgen dataset run` wrote it: run the dataset again to write it");
    const int64_t sample_index = row - 1;
    if (samples) *samples = std::max(*samples, sample_index + 1);
    if (only && !only->contains(sample_index)) continue;
    const std::string status = text(r, "status");
    if (status != "done") {
      ++not_done[status];
      continue;
    }
    std::vector<std::string> folders{text(r, "folder")};
    if (r.contains("repeats") && r["repeats"].is_array())
      for (const nlohmann::json& f : r["repeats"])
        if (f.is_string()) folders.push_back(f.get<std::string>());
    const std::string hash = text(r, "sample_hash");
    // (in the row's order of keys: the dataset file's)
    nlohmann::ordered_json parameters = nlohmann::ordered_json::parse(line).value("parameters", nlohmann::ordered_json::object());
    if (!parameters.is_object()) parameters = nlohmann::ordered_json::object();
    for (size_t repeat = 0; repeat < folders.size(); ++repeat) {
      const std::string& f = folders[repeat];
      // A sample folder, once: a row copied by hand scored its sample twice; a folder outside samples/ was scored too.
      const fs::path rel(f);
      if (rel.is_absolute() || rel.empty() || *rel.begin() != "samples" ||
          std::any_of(rel.begin(), rel.end(), [](const fs::path& part) { return part == ".." || part == "."; }))
        throw Error(where + ": lists the folder " + f + ", not a sample folder of the dataset (samples/NAME); the index was "
                    "damaged after `spadgen dataset run` wrote it: run the dataset again to write it");
      if (!seen.insert(rel.lexically_normal().string()).second)
        throw Error(where + ": lists the folder " + f + " again (an earlier row lists it); the index was damaged after "
                    "`spadgen dataset run` wrote it: run the dataset again to write it");
      const fs::path meta = dir / f / "metadata.json";
      std::string found = fs::exists(dir / f) ? "its folder has no readable metadata.json" : "its folder does not exist";
      bool intensity = false;
      try {
        const nlohmann::json m = nlohmann::json::parse(scenes::read_file_bounded(meta.string(), int64_t{1} << 28, "metadata.json"));
        const auto at = "/dataset/sample_hash"_json_pointer;
        found = m.contains(at) && m.at(at).is_string() ? "its folder has hash " + m.at(at).get<std::string>()
                                                       : "its folder has no dataset section";
        const auto mode = "/acquisition/mode"_json_pointer;
        intensity = m.contains(mode) && m.at(mode) == "intensity";
      } catch (const std::exception&) {
      }
      if (found != "its folder has hash " + hash)
        throw Error((dir / f).string() + ": index.jsonl lists it done with hash " + hash + ", and " + found +
                    ": the sample was removed or changed since the index was written; `spadgen dataset run` brings the index up to date "
                    "(and generates what is not done)");
      out.push_back({dir / f, hash, intensity, sample_index, int(repeat), parameters});
    }
  }
  return out;
}

}  // namespace

SampleSelection::SampleSelection(const std::string& given) {
  std::string text = given;
  const bool file = !given.empty() && given[0] == '@';  // (whose lines and spaces may leave empty elements)
  if (file) {
    text = scenes::read_file_bounded(given.substr(1), int64_t{1} << 30, "--samples file");
    for (char& ch : text)
      if (ch == '\n' || ch == '\r' || ch == ' ' || ch == '\t') ch = ',';
  }
  const auto shown = [](const std::string& t) {  // (a token quoted as it is, shortened and printable)
    std::string out = scenes::printable(t.substr(0, 40));
    return t.size() > 40 ? out + "..." : out;
  };
  const auto number = [&](const std::string& t) {
    if (t.empty() || t.size() > 15 || t.find_first_not_of("0123456789") != std::string::npos)
      throw Error("--samples " + shown(given) + ": found '" + shown(t) + "', expected dataset indices and ranges such as 0,3,5-8");
    return std::stoll(t);
  };
  if (!file && !text.empty() && (text.front() == ',' || text.back() == ',' || text.find(",,") != std::string::npos))
    throw Error("--samples " + shown(given) + ": an empty element between commas; expected dataset indices and ranges such as 0,3,5-8");
  std::vector<std::pair<int64_t, int64_t>> parts;
  for (size_t i = 0; i < text.size();) {
    const size_t end = std::min(text.find(',', i), text.size());
    if (const std::string part = text.substr(i, end - i); !part.empty()) {
      const size_t dash = part.find('-');
      const int64_t a = number(part.substr(0, dash));
      const int64_t b = dash == std::string::npos ? a : number(part.substr(dash + 1));
      if (b < a) throw Error("--samples " + shown(given) + ": the range " + shown(part) + " is empty");
      parts.emplace_back(a, b);
    }
    i = end + 1;
  }
  if (parts.empty()) throw Error("--samples " + shown(given) + ": selects no samples; expected dataset indices such as 0,3,5-8");
  add_sorted_merged(std::move(parts));
}

std::optional<SampleSelection> SampleSelection::from_json(const nlohmann::json& ranges) {
  std::vector<std::pair<int64_t, int64_t>> parts;
  if (ranges.is_array())
    for (const nlohmann::json& r : ranges)
      if (r.is_array() && r.size() == 2 && r[0].is_number_integer() && r[1].is_number_integer() && r[0] <= r[1])
        parts.emplace_back(r[0].get<int64_t>(), r[1].get<int64_t>());
  if (parts.empty()) return std::nullopt;
  SampleSelection s;
  s.add_sorted_merged(std::move(parts));
  return s;
}

void SampleSelection::add_sorted_merged(std::vector<std::pair<int64_t, int64_t>> parts) {
  std::sort(parts.begin(), parts.end());
  for (const auto& [a, b] : parts)  // (overlapping and adjacent ranges merged)
    if (!ranges_.empty() && a <= ranges_.back().second + 1) ranges_.back().second = std::max(ranges_.back().second, b);
    else ranges_.emplace_back(a, b);
}

bool SampleSelection::contains(int64_t i) const {  // (by bisection: a random split is about one range per sample)
  const auto it = std::upper_bound(ranges_.begin(), ranges_.end(), std::pair{i, std::numeric_limits<int64_t>::max()});
  return it != ranges_.begin() && std::prev(it)->second >= i;
}

nlohmann::json SampleSelection::json() const {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& [a, b] : ranges_) out.push_back({a, b});
  return out;
}

std::string SampleSelection::text(size_t most) const {
  std::string out;
  for (const auto& [a, b] : ranges_) {
    if (out.size() > most) {
      out += ",...";
      break;
    }
    if (!out.empty()) out += ',';
    out += std::to_string(a);
    if (b > a) {
      out += '-';
      out += std::to_string(b);
    }
  }
  return out;
}

bool is_derived_output(const std::string& rel) {
  for (const char* d : {"detections_edges", "detections_paper", "hdr"})
    if (rel == std::string(d) + ".exr" || rel == std::string(d) + "_noise_free.exr") return true;
  return rel == "evaluation";
}

bool is_evaluation_metrics(const fs::path& metrics) {
  const std::optional<nlohmann::json> m = read_json_if_valid(metrics);
  return m && m->is_object() && m->contains("scored") && (m->contains("spadgen_version") || m->contains("run") || m->contains("dataset"));
}

bool is_spadgen_derived_output(const fs::path& path, const std::string& rel) {
  if (!is_derived_output(rel)) return false;
  std::error_code ec;
  if (fs::is_symlink(path, ec)) return false;
  if (rel == "evaluation") {
    if (!fs::is_directory(path, ec) || !is_evaluation_metrics(path / "metrics.json")) return false;
    static const std::set<std::string> kOwn = {"metrics.json", "samples.csv", "range_error.png", "outcome.png"};
    for (const auto& e : fs::directory_iterator(path, ec))
      if (!kOwn.count(e.path().filename().string()) || !e.is_regular_file(ec) || e.is_symlink(ec)) return false;
    return !ec;
  }
  // An OpenEXR file (its magic number) whose header records spadgen_source (reconstruct's provenance).
  if (!fs::is_regular_file(path, ec)) return false;
  std::ifstream in(path, std::ios::binary);
  std::string head(64 * 1024, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(std::max<std::streamsize>(0, in.gcount())));
  return head.compare(0, 4, "\x76\x2f\x31\x01") == 0 && head.find("spadgen_source") != std::string::npos;
}

namespace {
// The image written whole in place of `out` (a temporary file renamed over it): a failure (a full disk) says
// what became of an earlier file there, which is kept.
void write_output(const writers::ExrImage& img, const std::string& out) {
  const bool earlier = fs::exists(out);
  try {
    img.write(out);
  } catch (const Error& e) {
    throw Error(std::string(e.what()) + (earlier ? " (nothing was replaced: the earlier " + out + " is as it was)" : " (nothing was written)"));
  }
}
}  // namespace

std::string reconstruct(const ReconstructOptions& o) {
  InterruptGuard interrupt_guard;
  const ThreadLimit threads(o.threads);
  if (o.max_detections < 1 || o.max_detections > 64) throw Error("--max-detections: expected 1 to 64");
  require_utf8_path(o.run_dir, "the run folder", "which the output records (spadgen_source)");
  // The run folder's lock, held from reading the run to writing the detections (into it, by default): a run
  // replacing the folder meanwhile would leave the earlier run's detections beside its own counts.
  std::optional<FolderLock> run_lock;
  if (fs::is_regular_file(fs::path(o.run_dir) / "metadata.json")) run_lock.emplace(o.run_dir);
  const RunFolder run(o.run_dir);
  if (!run.gate_sweep()) {
    if (o.detector_given || o.max_detections_given)
      throw Error(std::string(o.detector_given ? "--detector" : "--max-detections") + ": " + o.run_dir +
                  " is a 2D run (an intensity image, no gate profiles to detect returns in); reconstruct writes its HDR "
                  "inversion, hdr.exr, and takes only -o, --noise-free and --threads for it");
    // The 2D HDR inversion: eq. (5) or (6) on the image's summed counts.
    const std::string out = o.out.empty() ? (fs::path(o.run_dir) / derived_name("hdr", o.noise_free)).string() : o.out;
    check_writable(out, run, o.run_dir, derived_name("hdr", o.noise_free));
    writers::ExrImage img(run.width(), run.height());
    std::vector<float> c(size_t(run.width()) * size_t(run.height()) * size_t(run.K()));
    // noise-free: the rates themselves (the expected counts, inverted, were clamped at N - 0.5: N = 1 gave
    // 0.693 for any brighter pixel)
    if (o.noise_free) run.rates(0, run.height(), c.data());
    else run.profiles(0, run.height(), false, c.data());
    float* photons = img.channel("photons");
    float* se = img.channel("photons_se");
    float* sat = img.channel("saturated");
    for (size_t i = 0; i < size_t(run.width()) * size_t(run.height()); ++i) {
      double counts = 0.0;
      for (int k = 0; k < run.K(); ++k) counts += c[i * size_t(run.K()) + size_t(k)];
      const reconstruct::HdrEstimate e =
          o.noise_free ? reconstruct::hdr_of_rates(&c[i * size_t(run.K())], run.image_frames(), run.dual(), run.dual_ratio())
                       : reconstruct::invert_hdr(counts, run.image_frames(), run.dual(), run.dual_ratio());
      photons[i] = float(e.photons), se[i] = float(e.standard_error), sat[i] = e.saturated ? 1.0f : 0.0f;
    }
    img.set_attribute("spadgen_reconstruct", nlohmann::json{{"what", run.dual() ? "eq. (6) inversion" : "eq. (5) inversion"},
                                                            {"noise_free", o.noise_free}}.dump());
    img.set_attribute("spadgen_source", provenance(run));
    write_output(img, out);
    return out;
  }
  const std::string out =
      o.out.empty() ? (fs::path(o.run_dir) / derived_name("detections_" + o.detector, o.noise_free)).string() : o.out;
  check_writable(out, run, o.run_dir, derived_name("detections_" + o.detector, o.noise_free));
  const Detector detector(o.detector, run);
  const DetectionImage d = detect_image(run, detector, o.noise_free, o.max_detections, o.progress);
  writers::ExrImage img(d.width, d.height);
  std::copy(d.count.begin(), d.count.end(), img.channel("count"));
  const size_t n = d.count.size();
  for (int s = 0; s < d.slots; ++s)
    for (const auto& [name, v] : {std::pair{"range", &d.range}, {"gate", &d.gate}, {"amplitude", &d.amplitude}, {"score", &d.score}})
      std::copy_n(v->begin() + std::ptrdiff_t(d.at(s, 0)), n, img.channel(slot_name(s, name)));
  img.set_attribute("spadgen_reconstruct", nlohmann::json{{"detector", o.detector},
                                                          {"parameters", detector.parameters()},
                                                          {"noise_free", o.noise_free},
                                                          {"units", "range m; gate: fractional gate index; amplitude: detections per frame; score: z"}}
                                               .dump());
  img.set_attribute("spadgen_source", provenance(run));
  write_output(img, out);
  return out;
}

namespace {

// --detections' placeholder for a dataset's sample folder name.
constexpr std::string_view kSampleField = "{sample}";

std::string expand_sample_field(const std::string& pattern, const std::string& sample) {
  std::string out;
  for (size_t i = 0; i < pattern.size();) {
    if (pattern.compare(i, kSampleField.size(), kSampleField) == 0) {
      out += sample;
      i += kSampleField.size();
    } else {
      out += pattern[i++];
    }
  }
  return out;
}

}  // namespace

std::string evaluate(const EvaluateCommand& c) {
  InterruptGuard interrupt_guard;
  const ThreadLimit threads(c.threads);
  if (!(c.tolerance_m > 0.0) || !std::isfinite(c.tolerance_m)) throw Error("--tolerance-m: expected a positive, finite number of metres");
  if (c.min_score && !std::isfinite(*c.min_score)) throw Error("--min-score: expected a finite number (a detection's z score)");
  // (as given: metrics.json records them so)
  require_utf8_path(c.target, "the evaluated folder", "which metrics.json records", false);
  if (!c.detections.empty()) require_utf8_path(c.detections, "the detections file", "which metrics.json records", false);
  const fs::path target(c.target);
  // Written into a staging folder beside the output folder and swapped in whole (app/staging.h): a failed
  // or interrupted evaluation leaves the earlier one as it was, never a mix of the two.
  const fs::path out_given = c.out_dir.empty() ? target / "evaluation" : fs::path(c.out_dir);
  if (!fs::exists(target / "metadata.json") && !fs::exists(target / "dataset.json"))
    throw Error(c.target + ": neither a run folder (metadata.json) nor a dataset folder (dataset.json)" +
                (reconstruct::is_repeat_set(target)
                     ? " but the folder of `spadgen sense --repeats`' realisations: evaluate each, " + (target / "repeat_000").string() + ", ..."
                     : std::string()));
  // Not inside a run folder, a dataset's own entries or a folder of sense --repeats' realisations (-o RUN/scores
  // made the next run into RUN refuse it for a foreign folder), but the evaluated run's or dataset's own
  // evaluation/, the default.
  const fs::path own = resolved_folder(target);
  refuse_output_inside(out_given, "-o " + out_given.string(), [&](CheckedFolder kind, const fs::path& folder, const fs::path& rel) {
    return kind != CheckedFolder::RepeatSet && folder == own && rel == "evaluation";
  });
  // Nor a run or dataset folder itself (-o RUN was refused for files "spadgen did not write there": it wrote them)
  {
    std::error_code ec;
    const fs::path where = resolved_folder(out_given);
    const bool is_run = is_run_folder(where);
    if (is_run || fs::is_regular_file(where / "dataset.json", ec))
      throw Error("-o " + out_given.string() + ": is a " + (is_run ? "run folder (its metadata.json)" : "dataset folder (its dataset.json)") +
                  "; an evaluation replaces the whole folder it writes, so it needs a folder of its own: leave -o out for " +
                  (target / "evaluation").string() + ", or choose a new folder");
  }
  // Its own names are an earlier evaluation's only beside its metrics.json (a user's samples.csv or notes called
  // metrics.json were replaced: a verifier's find)
  {
    std::error_code ec;
    std::vector<std::string> theirs;
    if (!is_evaluation_metrics(out_given / "metrics.json"))
      for (const char* f : {"metrics.json", "samples.csv", "range_error.png", "outcome.png"})
        if (fs::exists(out_given / f, ec)) theirs.push_back(f);
    if (!theirs.empty()) {
      std::string list;
      for (const std::string& f : theirs) list += (list.empty() ? "" : ", ") + f;
      throw Error("the output folder " + out_given.string() + " holds files that spadgen did not write there (" + list +
                  ": no metrics.json of an evaluation's beside them); an evaluation replaces the whole folder, so it "
                  "does not write into one with other files: move them, or choose another folder (-o)");
    }
  }
  Staging staging(out_given,
                  {"metrics.json", "samples.csv", "range_error.png", "outcome.png"}, "an evaluation");
  const std::string out = staging.path("");
  std::vector<std::string> files{"metrics.json"};
  std::map<int, std::string> names;
  std::map<std::string, int> ids_by_name;  // a dataset's: objects by name across samples
  nlohmann::json report;
  std::ostringstream text;
  // A run folder's lock, shared with other readers: the run is not replaced while it is scored (labels and counts
  // of one run) nor before its evaluation/ is published into it (released before, a run replacing the folder
  // meanwhile failed the publication: "No such file or directory").
  std::optional<FolderLock> run_lock;
  if (fs::exists(target / "metadata.json")) {
    run_lock.emplace(target, true);
    if (c.detections.find(kSampleField) != std::string::npos)
      throw Error("--detections " + c.detections + ": {sample} names each sample folder of a dataset; " + c.target +
                  " is a run folder (give its detections file)");
    if (c.samples) throw Error("--samples: chooses samples of a dataset; " + c.target + " is a run folder");
    nlohmann::json source;
    const reconstruct::Scores s = evaluate_run(c, c.target, c.detections, out, &names, &source);
    report = s.to_json(names);
    report["detections_source"] = source;
    report["run"] = c.target;
    text << summary(report);
    files.insert(files.end(), {"range_error.png", "outcome.png"});
  } else if (fs::exists(target / "dataset.json")) {
    std::map<std::string, int> not_done;
    std::optional<SampleSelection> selected;
    if (c.samples) selected.emplace(*c.samples);
    int64_t indexed = 0;
    const std::vector<DoneFolder> samples = done_sample_folders(target, not_done, selected ? &*selected : nullptr, &indexed);
    // The index's rows against the dataset's samples (its dataset.json, as `dataset status` checks them): an index
    // cut short was scored as the rows left, without a word. While a dataset run is on the folder, the index is
    // an earlier run's until the last run on it ends: scored as it is, and said.
    std::string index_note;
    if (const DatasetFolderState folder = dataset_folder_state(c.target); indexed != folder.samples) {
      const std::string rows = index_rows_text((target / "index.jsonl").string(), indexed, folder.samples);
      if (!folder.run_on) throw Error(rows + ": " + index_rows_cause());
      index_note = rows + ": a dataset run is on the folder, and the last run on it to end writes the index; scored as the index is now";
    }
    if (selected && selected->last() >= indexed)
      throw Error("--samples: sample " + std::to_string(selected->last()) + " is not one of the dataset's " +
                  std::to_string(indexed) + " (index.jsonl: 0 to " + std::to_string(indexed - 1) + ")");
    std::string left_out;  // "1 failed, 2 stale"
    for (const auto& [status, n] : not_done) left_out += (left_out.empty() ? "" : ", ") + std::to_string(n) + " " + status;
    if (samples.empty())
      throw Error(c.target + ": no done samples to evaluate (index.jsonl: " + (left_out.empty() ? "no rows" : left_out) + ")");
    reconstruct::Scores total(scorer_options(c));
    // After the metrics, each sample's index, realisation and parameters (index.jsonl's: the scene and every
    // grid and random key), so that a detector's scores can be read against what the dataset varies.
    std::vector<std::string> parameter_keys;
    for (const DoneFolder& d : samples)
      for (const auto& [key, value] : d.parameters.items())
        if (std::find(parameter_keys.begin(), parameter_keys.end(), key) == parameter_keys.end()) parameter_keys.push_back(key);
    std::ostringstream csv;
    csv << "sample,objects,found,recall,detectable,detectable_found,detections,false,bias_mm,rms_mm,index,repeat";
    for (const std::string& k : parameter_keys) csv << ',' << datasets::csv_value(k);
    csv << '\n';
    nlohmann::json rows = nlohmann::json::array();
    // --detections: a name inside each sample folder, or a path with {sample} (the sample folder's name)
    const bool templated = c.detections.find(kSampleField) != std::string::npos;
    const fs::path named(c.detections);
    if (!templated &&
        (named.is_absolute() || std::any_of(named.begin(), named.end(), [](const fs::path& part) { return part == ".."; })))
      throw Error("--detections " + c.detections + ": for a dataset, expected a file name relative to each sample's folder, "
                  "inside it (one file would be scored against every sample), or a path with {sample}, the sample folder's "
                  "name (preds/{sample}.npy)");
    const auto file_of = [&](const fs::path& sample) {
      if (c.detections.empty()) return std::string();
      return templated ? expand_sample_field(c.detections, sample.filename().string()) : (sample / c.detections).string();
    };
    // Every sample's file first: a missing one is named before any is scored, as is one that is no regular
    // file, or one file named for two samples ({sample}/../x.npy, a link: one file scored against several).
    std::set<fs::path> without_file;  // the 2D sample folders --detections names no file for: left out
    if (!c.detections.empty()) {
      std::vector<std::string> missing;
      std::map<std::pair<dev_t, ino_t>, std::pair<std::string, std::string>> sample_of;  // by file: (its path, sample)
      for (const auto& sample : samples) {
        const std::string f = file_of(sample.path);
        struct stat st {};
        if (::stat(f.c_str(), &st) != 0) {
          if (errno != ENOENT && errno != ENOTDIR)
            throw Error("--detections " + c.detections + ": " + f + ": " + std::strerror(errno));
          // a 2D sample without detections is left out as without --detections (the detectors' own have none)
          if (sample.intensity) without_file.insert(sample.path);
          else missing.push_back(f);
          continue;
        }
        if (!S_ISREG(st.st_mode))
          throw Error("--detections " + c.detections + ": " + f + " is not a regular file (a folder, a FIFO or a device); "
                      "expected the detections of " + sample.path.filename().string());
        // (one file under two names, by .., a symbolic or a hard link, is told by its device and inode)
        const auto [at, fresh] = sample_of.try_emplace({st.st_dev, st.st_ino}, f, sample.path.filename().string());
        if (!fresh)
          throw Error("--detections " + c.detections + ": names one file, " + at->second.first + " and " + f + ", for the samples " +
                      at->second.second + " and " + sample.path.filename().string() + "; expected each sample's own detections");
      }
      if (!missing.empty())
        throw Error("--detections " + c.detections + ": " + std::to_string(missing.size()) + " of " + std::to_string(samples.size()) +
                    " done sample folders have no detections file, first " + missing.front() +
                    (templated ? " ({sample} is the sample folder's name, realisations' too: 000042, 000042_r01)"
                               : " (a name inside each sample's folder; a path with {sample} names files elsewhere)"));
    }
    int unlabelled = 0;
    // Without --detections the detector reads each sample's gate profiles: a 2D sample (a dataset mixing
    // scenes of both modes) has none, so it is left out and counted (it stopped the whole evaluation).
    nlohmann::json intensity_folders = nlohmann::json::array();
    size_t scored = 0;
    for (const auto& [p, sample_hash, is_2d, sample_index, repeat, parameters] : samples) {
      InterruptGuard::check();
      if (is_2d && (c.detections.empty() || without_file.count(p))) {  // (with its hash: status names it when generated again)
        intensity_folders.push_back({{"sample", p.filename().string()}, {"sample_hash", sample_hash}});
        continue;
      }
      ++scored;
      const std::string file = file_of(p);
      std::map<int, std::string> sample_names;
      nlohmann::json sample_source;
      const reconstruct::Scores s = evaluate_run(c, p.string(), file, "", &sample_names, &sample_source, &ids_by_name);
      unlabelled += sample_source.contains("labels");
      names.insert(sample_names.begin(), sample_names.end());
      total.merge(s);
      const nlohmann::json m = s.to_json(sample_names);
      const auto num = [](const nlohmann::json& v) { return v.is_number() ? v.dump() : std::string(); };
      csv << p.filename().string() << ',' << m["objects"]["objects"] << ',' << m["objects"]["found"] << ','
          << num(m["objects"]["recall"]) << ',' << m["objects_detectable"]["objects"] << ',' << m["objects_detectable"]["found"]
          << ',' << m["detections"]["total"] << ',' << m["detections"]["false"] << ',' << num(m["range_error"].value("bias_mm", nlohmann::json()))
          << ',' << num(m["range_error"].value("rms_mm", nlohmann::json())) << ',' << (sample_index >= 0 ? std::to_string(sample_index) : "")
          << ',' << repeat;
      for (const std::string& k : parameter_keys) csv << ',' << datasets::csv_value(parameters.value(k, nlohmann::ordered_json()));
      csv << '\n';
      // the version of the sample scored (done_sample_folders checked it in its metadata.json): dataset status
      // names an evaluation of samples generated again since
      rows.push_back({{"sample", p.filename().string()},
                      {"index", sample_index >= 0 ? nlohmann::json(sample_index) : nlohmann::json()},
                      {"repeat", repeat},
                      {"parameters", nlohmann::json::parse(parameters.dump())},
                      {"sample_hash", sample_hash},
                      {"detections_source", sample_source},
                      {"metrics", m}});
    }
    report = total.to_json(names);
    report["dataset"] = c.target;
    if (!index_note.empty()) report["index"] = index_note;
    if (unlabelled > 0)
      report["labels"] = std::to_string(unlabelled) + " of " + std::to_string(scored) +
                         " samples without labels.exr: their objects are counted as detectable (samples[].detections_source.labels)";
    const size_t intensity = intensity_folders.size();
    if (scored == 0)
      throw Error(c.target + ": its " + std::to_string(intensity) + " done sample folders are 2D intensity runs, without gate "
                  "profiles for the detector to read: " +
                  (c.detections.empty() ? std::string("give their detections with --detections")
                                        : "--detections " + c.detections + " names no file for any of them (first " +
                                              file_of(samples.front().path) + ")"));
    report["samples"] = rows;
    if (selected) report["selection"] = selected->json();  // the dataset indices asked for (--samples), as ranges
    if (!not_done.empty()) report["not_scored"] = not_done;  // {"failed": 1}: index.jsonl's rows not done, by status
    if (intensity > 0)
      report["not_scored_intensity"] = {{"sample_folders", intensity_folders},
                                        {"why", c.detections.empty()
                                                    ? "2D intensity runs have no gate profiles for the detector; --detections "
                                                      "scores them with detections given"
                                                    : "2D intensity runs for which --detections names no file (the detectors "
                                                      "have no gate profiles to read in them)"}};
    writers::write_file_atomic((fs::path(out) / "samples.csv").string(), csv.str());
    files.push_back("samples.csv");
    text << scored << (scored == 1 ? " sample folder" : " sample folders") << " (realisations included)"
         << (left_out.empty() ? std::string() : "; not scored, not done: " + left_out)
         << (intensity == 0             ? std::string()
             : c.detections.empty() ? "; not scored, 2D intensity runs (no gate profiles for the detector): " + std::to_string(intensity)
                                    : "; not scored, 2D intensity runs without a file of --detections: " + std::to_string(intensity))
         << "\n" << (index_note.empty() ? std::string() : "note: " + index_note + "\n") << summary(report);
  } else {
    throw Error(c.target + ": neither a run folder (metadata.json) nor a dataset folder (dataset.json)");
  }
  // What was scored, at the top (a dataset's evaluation named its detector only per sample, and one of another
  // detector replaced it unsaid: a new user's find).
  const nlohmann::json scored = c.detections.empty() ? nlohmann::json{{"detector", c.detector}, {"noise_free", c.noise_free}}
                                                     : nlohmann::json{{"detections", c.detections}};
  report["scored"] = scored;
  report["spadgen_version"] = SPADGEN_VERSION;  // (what says the file is evaluate's: is_evaluation_metrics)
  std::string replaced;  // the evaluation this one replaces, when it scored other detections
  if (const auto earlier = read_json_if_valid(out_given / "metrics.json"); earlier && earlier->is_object() &&
                                                                           earlier->contains("scored") && (*earlier)["scored"] != scored)
    replaced = scored_text((*earlier)["scored"]);
  writers::write_json((fs::path(out) / "metrics.json").string(), report);
  staging.publish(files);
  std::string head = "scored: " + scored_text(scored) + "\n";
  if (!replaced.empty()) head += "replaced the evaluation in " + out_given.string() + " of " + replaced + " (-o keeps each in its own folder)\n";
  text << "wrote " << (out_given / "metrics.json").string()
       << (std::find(files.begin(), files.end(), "samples.csv") != files.end() ? " and samples.csv" : "") << "\n";
  return head + text.str();
}

}  // namespace spadgen::app
