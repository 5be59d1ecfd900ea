#include "app/dataset.h"
#include "app/interrupt.h"
#include "app/progress.h"
#include "app/reconstruct.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <functional>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <thread>

#include <tbb/parallel_for.h>

#include "app/pipeline.h"
#include "app/resources.h"
#include "app/run_parts.h"
#include "app/staging.h"
#include "app/warnings.h"
#include "core/buffer_cache.h"
#include "core/error.h"
#include "datasets/dataset.h"
#include "datasets/folder.h"
#include "reconstruct/run_folder.h"
#include "scenes/input.h"
#include "scenes/scene.h"
#include "scenes/scene_file.h"
#include "sensor/sensor.h"

namespace spadgen::app {
namespace fs = std::filesystem;
using json = nlohmann::json;
using ojson = nlohmann::ordered_json;
using datasets::DatasetFolder;
using datasets::DatasetSpec;
using datasets::Sample;
using datasets::SampleRecord;
using datasets::Status;

namespace {

// The cost model of a run's time on this machine kind (2 cores, AVX-512), fitted to runs of the shipped
// scenes (docs/datasets.md, "Estimates"): camera paths, the sensor stage per pixel and gate position, and
// the bytes written. An estimate to plan with, within a factor of about 2; `dataset run` reports the
// measured times.
constexpr double kSecondsPerPathBounce = 0.35e-6;   // per camera path and allowed bounce (paths end early)
constexpr double kSecondsPerPixelGate = 8e-9;       // sensor stage, per pixel and gate position (or exposure)
constexpr double kSecondsPerByte = 2.0 / 1.0e9;     // writing the outputs (and compressing the images)
constexpr double kSecondsPerRun = 0.2;              // loading the scene, building the BVH, publishing


struct Estimate {
  int64_t disk = 0, memory = 0;  // disk: what the sample keeps
  int64_t disk_at_least = 0;  // compressed files (EXR, Zarr) not counted, the saved light without lit bins (ResourcePlan)
  int64_t disk_peak = 0, disk_peak_at_least = 0;  // temporary files while the sample runs (freed at its end)
  double seconds = 0.0;
  bool paths_bound = false;  // a target error: the time counts render.max_samples_per_pixel paths per pixel
  LeastParts least;          // what makes disk_at_least less than disk
  // One further realisation of the noise (sensed from the saved light): its kept disk and time.
  int64_t repeat_disk = 0, repeat_disk_at_least = 0;
  double repeat_seconds = 0.0;
  // What n further realisations of a rendered sample take (repeats grown: the sample is not rendered again).
  Estimate realisations(int n) const {
    Estimate r;
    r.memory = memory;
    r.disk = n * repeat_disk, r.disk_at_least = n * repeat_disk_at_least;
    r.seconds = n * repeat_seconds;
    r.least = least;
    return r;
  }
};

// What a sample not done takes to complete: all of it, or, where its own folder holds it rendered and only
// realisations are missing (repeats grown), their senses from its saved light.
bool only_senses_left(const SampleRecord& rec) { return !rec.held.empty() && rec.held[0]; }
Estimate left_of(const Estimate& e, const SampleRecord& rec) {
  return only_senses_left(rec) ? e.realisations(int(std::count(rec.held.begin() + 1, rec.held.end(), false))) : e;
}

// The estimates of samples generated one at a time (a plan's, a run's): their kept disk, time and largest
// memory, with the largest sample's temporary files on top of the disk (freed after each sample).
struct Totals {
  int64_t kept = 0, kept_at_least = 0, peak = 0, peak_at_least = 0, memory = 0;
  double seconds = 0.0;
  bool paths_bound = false;
  LeastParts least;
  void add(const Estimate& e) {
    kept += e.disk, kept_at_least += e.disk_at_least, seconds += e.seconds;
    peak = std::max(peak, e.disk_peak), peak_at_least = std::max(peak_at_least, e.disk_peak_at_least);
    memory = std::max(memory, e.memory);
    paths_bound = paths_bound || e.paths_bound;
    least.compressed = least.compressed || e.least.compressed, least.light = least.light || e.least.light;
  }
  int64_t disk() const { return kept + peak; }
  int64_t disk_at_least() const { return kept_at_least + peak_at_least; }
  // How disk() is named: "at most" where compressed files are counted uncompressed (a bound), "up to about"
  // where the saved light's estimate is in it (more than most scenes take, not a bound: a sample whose light
  // spans longer wrote 124 MB against "at most 114 MB"; an auditor's find), else "about".
  const char* disk_words() const {
    return least.light ? "up to about " : disk_at_least() != disk() ? "at most " : "about ";
  }
};

// What a sample's scene adds to its plan: its glTF's objects and geometry (-1 objects, no geometry: unknown).
struct SceneSize {
  int objects = -1;
  std::optional<Geometry> geometry;
  std::string error;  // why the glTF does not load ("" when it does)
};

Estimate estimate(const RunConfig& c, int repeats, int threads, const SceneSize& size) {
  // The sensor's shape (gate positions, window, halo), not its counts: with frames the model builds no
  // counts tables (about 3 MB and 15 ms per frame count; a dataset with a random acquisition.frames held
  // one per value it planned). The plan below takes the outputs from c.
  SensorStageConfig shape = sensor_stage(c);
  shape.outputs.frames = true;
  sensor::SensorModel sensor(shape);
  const TimeAxis axis = time_axis(c, sensor);
  const PixelRect img = image_rect(c);
  const ResourcePlan plan = plan_resources(c, sensor, img, axis, threads, "", size.objects, size.geometry ? &*size.geometry : nullptr);
  Estimate e;
  e.memory = plan.memory_needed();
  const int64_t run_disk = plan.disk_needed();
  const double pixels = double(img.count());
  const double bounces = std::min(c.render.max_bounces, 4);
  // With a target error a pixel traces its first round and then as many paths as its spread asks, at most
  // render.max_samples_per_pixel: the estimate takes the most, an upper bound.
  const double paths = c.render.samples_per_pixel + (c.render.target_relative_error ? c.render.max_samples_per_pixel : 0);
  e.paths_bound = c.render.target_relative_error.has_value();
  const double sensor_seconds = pixels * sensor.K() * kSecondsPerPixelGate;
  e.seconds = kSecondsPerRun + pixels * paths * bounces * kSecondsPerPathBounce + sensor_seconds +
              double(run_disk) * kSecondsPerByte;
  // Repeats: the sensor stage again from the saved light, and its noise-dependent files (about the run's
  // files less the ground truth and the light, which are linked).
  // Each further realisation writes the noise's files and links the rest (ResourcePlan::Part::noise_free):
  // the whole sample again for each overcounted a sample of two realisations by 1.9 times.
  int64_t again = 0, again_at_least = 0;
  for (const ResourcePlan::Part& p : plan.disk)
    if (!p.freed_at_end && !p.noise_free) again += p.bytes, again_at_least += p.at_least();
  e.disk = plan.disk_kept() + (repeats - 1) * again;
  e.disk_at_least = plan.disk_kept_at_least() + (repeats - 1) * again_at_least;
  e.disk_peak = run_disk - plan.disk_kept();
  e.disk_peak_at_least = plan.disk_at_least() - plan.disk_kept_at_least();
  e.least = least_parts(plan.disk);
  const double sense_seconds = kSecondsPerRun + sensor_seconds + double(run_disk) * kSecondsPerByte, core_scale = 2.0 / usable_cores(threads);
  e.repeat_disk = again, e.repeat_disk_at_least = again_at_least;
  e.repeat_seconds = sense_seconds * core_scale;
  e.seconds += (repeats - 1) * sense_seconds;
  e.seconds *= core_scale;  // the model is of 2 cores; the work is parallel
  return e;
}

// Estimates of many samples: the sensor's gate response (tens of milliseconds) is built once per distinct
// shape of run. The estimate does not depend on the seeds, the light's strength or the scene's content,
// nor on the laser's emission delay (it shifts the returns, not the time axis's size), the cycles per
// frame (they scale the rates), the camera's optics and pose or the laser's beam: varying them costs
// about 0.25 ms per sample to plan; the durations estimate_shape rounds, about 40 ms per distinct rounded
// value; the gate's other keys or the frames, about 40 ms per distinct value.
class Estimator {
 public:
  Estimator(int repeats, int threads) : repeats_(repeats), threads_(threads) {}

  // The cache key of r's estimate: a hash of its resolved scene without the keys the estimate ignores, and
  // the durations estimate_shape rounds as rounded (a dataset of a million distinct pulse widths keeps 8
  // bytes per value, not the text).
  static uint64_t key(const scenes::ResolvedRun& r) {
    ojson key = r.resolved;
    for (const char* k : {"seed", "seeds", "description", "ambient", "nodes", "materials"}) key.erase(k);
    const auto erase = [&key](const char* section, std::initializer_list<const char*> keys) {
      if (key.contains(section))
        for (const char* k : keys) key[section].erase(k);
    };
    erase("laser", {"average_power_mW", "emission_delay_ns", "beam", "gltf_light", "half_angle_deg", "offset_m", "pulse_fwhm_ps"});
    erase("sensor", {"jitter_fwhm_ps"});
    if (key.contains("sensor") && key["sensor"].contains("gate"))
      for (const char* k : {"rise_ps", "fall_ps", "length_ns", "length_fwhm_ps", "skew_fwhm_ps"}) key["sensor"]["gate"].erase(k);
    const RunConfig shape = estimate_shape(r.config);
    const GateConfig& g = shape.sensor.gate;
    key["rounded_durations_s"] = {shape.laser.pulse_fwhm_s, g.jitter_fwhm_s, g.rise_s, g.fall_s, g.length_s, g.length_fwhm_s, g.skew_fwhm_s};
    erase("acquisition", {"cycles_per_frame"});
    erase("camera", {"f_number", "focal_length_mm", "gltf_camera", "look_at_m", "optics_transmission", "pixel_pitch_um",
                     "position_m", "up", "vertical_fov_deg"});
    return scenes::fnv1a64(key.dump());
  }

  // An estimate, or why there is none (the sensor's tables or time axis refuse the run: the sample is invalid).
  struct Entry {
    Estimate estimate;
    std::string error;
    std::string pointer, reason;  // of a KeyError: named as each sample gives the key (error_of)
    // The error as the sample `r` gives its key: the --set form of a key the dataset gives (which the caller
    // names at its place in the dataset file), else the scene file's pointer.
    std::string error_of(const scenes::ResolvedRun& r) const {
      if (pointer.empty()) return error;
      const auto set = r.set_keys.find(pointer);
      return (set != r.set_keys.end() ? "--set " + set->second : r.config.scene_file + ": " + pointer) + ": " + reason;
    }
  };

  // The estimates of the keys not known yet, computed in parallel from the first run of each (by key); none
  // while a signal is pending (interruptible: the caller stops).
  void add(const std::vector<std::pair<uint64_t, const RunConfig*>>& runs, bool interruptible) {
    std::vector<std::pair<uint64_t, const RunConfig*>> todo;
    for (const auto& [k, c] : runs)
      if (!cache_.count(k) && std::none_of(todo.begin(), todo.end(), [k = k](const auto& t) { return t.first == k; }))
        todo.emplace_back(k, c);
    // Each glTF (and scene of it) loaded once, for its objects and geometry: the node and material edits
    // change neither. A glTF that does not load makes its samples invalid, with the loader's message (plan
    // called such a dataset valid, and run failed every sample of it: a verifier's out-of-range index).
    for (const auto& [k, c] : todo) {
      const auto [at, fresh] = scenes_.try_emplace(scene_of(*c));
      if (!fresh) continue;
      SceneSize& size = at->second;
      try {
        const scenes::Scene scene = scenes::load_gltf(c->gltf_path, c->gltf_scene);
        size.objects = int(scenes::objects_of(scene).list.size());
        size.geometry = geometry_of(scene);
      } catch (const Interrupted&) {
        throw;
      } catch (const Error& e) {
        size.error = e.what();
      }
    }
    std::vector<Entry> done(todo.size());
    tbb::parallel_for(size_t{0}, todo.size(), [&](size_t j) {
      if (interruptible && interrupt_flag().load()) return;
      if (const std::string& error = scenes_.at(scene_of(*todo[j].second)).error; !error.empty()) {
        done[j].error = error;
        return;
      }
      try {
        const RunConfig c = estimate_shape(*todo[j].second);
        done[j].estimate = estimate(c, repeats_, threads_, scenes_.at(scene_of(c)));
      } catch (const KeyError& e) {
        done[j].error = e.what(), done[j].pointer = e.pointer, done[j].reason = e.reason;
      } catch (const Error& e) {
        done[j].error = e.what();
      }
    });
    if (interruptible) InterruptGuard::check();
    for (size_t j = 0; j < todo.size(); ++j) cache_.emplace(todo[j].first, std::move(done[j]));
  }
  const Entry& at(uint64_t key) const { return cache_.at(key); }
  size_t shapes() const { return cache_.size(); }  // the estimates computed (the probes' included)

 private:
  int repeats_, threads_;
  std::map<uint64_t, Entry> cache_;
  std::map<std::string, SceneSize> scenes_;  // by scene_of
  static std::string scene_of(const RunConfig& c) { return c.gltf_path + "\n" + c.gltf_scene; }
};

// One sample as the plan and a run's check see it: resolved, its estimate, and with a folder its state there.
struct Checked {
  Sample sample;
  bool resolved = false;  // else error says why
  std::string error;
  Estimate estimate;
  std::vector<std::string> warnings;  // the scene file's, as the sample resolves (a run prints and records them)
  SampleRecord record;  // with a folder
};

// The samples the shard owns, resolved and inspected in parallel (the scenes resolve and the
// folders are read on every core; a distinct sensor shape's estimate too), handed to `each` in index order.
// estimate_done: also the samples the folder holds done (a plan lists their estimates; a run skips them).
// interruptible: a signal stops the work within a sample per thread (InterruptGuard::check).
void check_samples(const DatasetSpec& spec, const datasets::Shard& shard, const DatasetFolder* folder, Estimator& estimator,
                   bool estimate_done, bool interruptible, const std::function<void(Checked&)>& each) {
  constexpr int64_t kBlock = 2048;
  const int64_t end = spec.count();
  for (int64_t b = 0; b < end; b += kBlock) {
    std::vector<int64_t> mine;
    for (int64_t i = b; i < std::min(end, b + kBlock); ++i)
      if (shard.owns(i)) mine.push_back(i);
    std::vector<Checked> rows(mine.size());
    std::vector<scenes::ResolvedRun> runs(mine.size());
    std::vector<uint64_t> keys(mine.size());
    tbb::parallel_for(size_t{0}, mine.size(), [&](size_t j) {
      if (interruptible && interrupt_flag().load()) return;
      Checked& c = rows[j];
      c.sample = datasets::make_sample(spec, mine[j]);
      std::string hash;
      try {
        runs[j] = scenes::load_scene_file(spec.scenes[size_t(c.sample.scene)], c.sample.overrides);
        keys[j] = Estimator::key(runs[j]);
        c.warnings = runs[j].warnings;
        c.resolved = true;
      } catch (const Error& err) {
        c.error = err.what();
      }
      try {  // the folder's inspection need not resolve it again (without the hash it does, and says why it fails)
        if (folder && c.resolved) hash = folder->sample_hash(c.sample, runs[j]);
      } catch (const Error&) {
      }
      if (folder) c.record = folder->inspect(c.sample, &hash);
    });
    if (interruptible) InterruptGuard::check();
    const auto wanted = [&](size_t j) {
      return rows[j].resolved && (estimate_done || !folder || rows[j].record.status != Status::Done);
    };
    std::vector<std::pair<uint64_t, const RunConfig*>> estimates;
    for (size_t j = 0; j < rows.size(); ++j)
      if (wanted(j)) estimates.emplace_back(keys[j], &runs[j].config);
    estimator.add(estimates, interruptible);
    for (size_t j = 0; j < rows.size(); ++j) {
      if (wanted(j)) {
        const Estimator::Entry& e = estimator.at(keys[j]);
        if (e.error.empty()) rows[j].estimate = e.estimate;
        else rows[j].resolved = false, rows[j].error = e.error_of(runs[j]);
      }
      each(rows[j]);
    }
  }
}

// datasets' rule of the first samples (probe_samples), with the sensor's refusals too: when every probed
// sample of a scene file makes an invalid scene or a run the sensor refuses (its time axis, its tables:
// transients in the intensity mode), the mistake is the dataset file's, refused before any work (it was
// recorded as 5000 failed samples). The estimates made here stay in the estimator's cache.
void refuse_a_dataset_of_invalid_samples(const DatasetSpec& spec, Estimator& estimator, bool interruptible) {
  for (size_t k = 0; k < spec.scenes.size(); ++k) {
    const std::vector<int64_t> probes = datasets::probe_samples(spec, k);
    std::string why;
    bool valid = false;
    for (size_t j = 0; !valid && j < probes.size(); ++j) {
      std::string error;
      try {
        const scenes::ResolvedRun r = scenes::load_scene_file(spec.scenes[k], datasets::make_sample(spec, probes[j]).overrides);
        const uint64_t key = Estimator::key(r);
        estimator.add({{key, &r.config}}, interruptible);
        error = estimator.at(key).error_of(r);
      } catch (const Interrupted&) {
        throw;
      } catch (const Error& e) {
        error = e.what();
      }
      valid = error.empty();
      if (why.empty()) why = error;
    }
    if (!valid && !probes.empty()) throw Error(spec.file + ": " + datasets::invalid_probes_message(spec, k, probes, why));
  }
}

std::string duration_text(double s) {
  char buf[64];
  if (s < 0.005) std::snprintf(buf, sizeof buf, "0 s");
  else if (s < 9.95) std::snprintf(buf, sizeof buf, "%.2g s", s);  // small samples: "0.15 s", not "0 s"
  else if (s < 90) std::snprintf(buf, sizeof buf, "%.0f s", s);
  else if (s < 5400) std::snprintf(buf, sizeof buf, "%.0f min", s / 60);
  else if (s < 3 * 86400) std::snprintf(buf, sizeof buf, "%.1f h", s / 3600);
  else std::snprintf(buf, sizeof buf, "%.1f days", s / 86400);
  return buf;
}

// A ratio of measured to estimated: "0.14", "2.8", "37".
std::string ratio_text(double r) {
  char buf[32];
  std::snprintf(buf, sizeof buf, r >= 10.0 ? "%.0f" : "%.2g", r);
  return buf;
}

datasets::Shard choose_shard(const DatasetOptions& o) {
  if (o.shard) return datasets::parse_shard(*o.shard);
  if (const auto s = datasets::shard_from_environment()) return *s;
  return {};
}

// The dataset file a dataset folder was generated from (dataset.json records it and its resolved form).
DatasetSpec spec_of_folder(const fs::path& dir) {
  const fs::path own = dir / "dataset.json";
  const std::string problem = scenes::file_problem(own.string(), scenes::kMaxSceneFileBytes);
  if (!problem.empty()) throw Error(own.string() + " " + problem + "; expected a dataset folder written by spadgen dataset run");
  const std::string text = scenes::read_file_bounded(own.string(), scenes::kMaxSceneFileBytes, "dataset.json");
  (void)scenes::parse_json(text, own.string());  // checked
  const ojson j = ojson::parse(text);             // in its order, which orders the axes
  if (!j.contains("dataset_file") || !j["dataset_file"].is_string())
    throw Error(own.string() + ": no \"dataset_file\"; expected a dataset folder written by spadgen dataset run");
  const std::string file = j["dataset_file"].get<std::string>();
  ojson body = j;
  body.erase("dataset_file");
  // The scene files are relative to the dataset file: parsed as if from there. A mistake is this folder's
  // record's, not the dataset file's (which may hold a good value): named here.
  try {
    return datasets::parse_dataset_text(body.dump(), file);
  } catch (const Error& e) {
    std::string m = e.what();
    if (m.rfind(file + ": ", 0) == 0) m.erase(0, file.size() + 2);
    throw Error(own.string() + " (the dataset file " + file + " as this folder recorded it): " + m);
  }
}

// Every sample's record (about 0.15 ms each: its scene resolved, its folders' metadata read); past 10,000
// samples with progress on stderr.
// The hashes of the samples a run inspected as it began (SampleHashes), by index, 0 where not known: resolving a
// sample's scene is most of its inspection (0.3 ms; a run of 100,000 samples stopped by a signal took 29 s to
// list them in the index). Kept for datasets of up to kMaxKeptHashes samples (8 bytes each).
constexpr int64_t kMaxKeptHashes = 10'000'000;
using SampleHashes = std::vector<uint64_t>;

// Every sample's record, handed to `sink` in index order and not kept (a million samples' records took 1.7 GB).
void inspect_each(const DatasetFolder& folder, bool progress, const SampleHashes* hashes,
                  const DatasetFolder::RecordSink& sink) {
  const int64_t n = folder.spec().count();
  Progress bar(size_t(n), progress && n > 10000, "samples inspected");
  for (int64_t i = 0; i < n; ++i) {
    const uint64_t h = hashes != nullptr && size_t(i) < hashes->size() ? (*hashes)[size_t(i)] : 0;
    const std::string known = h != 0 ? scenes::hex64(h) : std::string();
    sink(folder.inspect(datasets::make_sample(folder.spec(), i), &known));
    bar.tick();
  }
}

// The names of the done sample folders (realisations included) index.jsonl lists, as evaluate scores them;
// rows that do not read are left out (evaluate names them).
std::set<std::string> indexed_done_folders(const fs::path& dir) {
  std::set<std::string> out;
  std::ifstream in(dir / "index.jsonl");
  for (std::string line; std::getline(in, line);) {
    const nlohmann::json r = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (!r.is_object() || r.value("status", nlohmann::json()) != "done") continue;
    std::vector<nlohmann::json> folders{r.value("folder", nlohmann::json())};
    if (r.contains("repeats") && r["repeats"].is_array()) folders.insert(folders.end(), r["repeats"].begin(), r["repeats"].end());
    for (const nlohmann::json& f : folders)
      if (f.is_string()) out.insert(fs::path(f.get<std::string>()).filename().string());
  }
  return out;
}

// A line naming an evaluation/ that scored other versions of the samples than the folder holds now (generated
// again with another sample_hash since, no longer done, or done and not scored): its metrics are of data no
// longer there. Empty when it is current (but see say_current), or absent.
// say_current: also a line for a current evaluation of some samples only (dataset status; a run says only
// what is out of date).
std::string evaluation_status(const std::string& dir, const std::set<std::string>* done_now = nullptr, bool say_current = false) {
  const fs::path metrics = fs::path(dir) / "evaluation" / "metrics.json";
  std::error_code ec;
  // (one that is there but no file, a folder or a link to a device, was passed over in silence)
  if (!fs::is_regular_file(metrics, ec))
    return fs::symlink_status(metrics, ec).type() == fs::file_type::not_found || ec
               ? ""
               : "evaluation/: " + metrics.string() + " is not a regular file (" + scenes::file_problem(metrics.string(), 1) +
                     "): run `spadgen evaluate " + dir + "` again\n";
  constexpr uint64_t kMost = uint64_t{1} << 30;  // about 3 kB per sample folder: 300,000 folders
  if (const uintmax_t size = fs::file_size(metrics, ec); !ec && size > kMost)
    return "evaluation/: " + metrics.string() + " is larger than 1 GB: not checked against the samples\n";
  nlohmann::json m;
  try {
    m = scenes::parse_json(scenes::read_file_bounded(metrics.string(), kMost, "metrics"), metrics.string());
  } catch (const Error&) {
    return "evaluation/: " + metrics.string() + " does not read as spadgen evaluate's: run `spadgen evaluate " + dir + "` again\n";
  }
  // (evaluate writes samples for a dataset: a metrics.json without them is not its)
  if (!m.is_object() || !m.contains("samples") || !m["samples"].is_array())
    return "evaluation/: " + metrics.string() + " does not read as spadgen evaluate's of a dataset: run `spadgen evaluate " + dir +
           "` again\n";
  // done: as the folders are now (dataset status inspects them: a damaged sample is no longer done), or as
  // index.jsonl lists them
  std::set<std::string> done = done_now ? *done_now : indexed_done_folders(dir);
  // (an evaluation of some samples, --samples, is of those: the others' folders are not expected in it)
  const auto chosen = SampleSelection::from_json(m.value("selection", nlohmann::json()));
  std::string selection;  // "0-3,7" when the evaluation is of some samples, as --samples takes it
  if (chosen) {
    for (auto it = done.begin(); it != done.end();) {
      const std::string& f = *it;  // 000042, 000042_r01, 1234567 (a sample's index: the digits before _)
      const size_t digits = std::min(f.find('_'), f.size());
      const bool numbered = digits > 0 && digits <= 15 &&
                            std::all_of(f.begin(), f.begin() + std::ptrdiff_t(digits), [](char ch) { return ch >= '0' && ch <= '9'; });
      it = numbered && !chosen->contains(std::stoll(f.substr(0, digits))) ? done.erase(it) : std::next(it);
    }
    selection = chosen->text(200);
  }
  std::set<std::string> scored;
  int64_t changed = 0, gone = 0;
  // The folders scored, and the 2D ones evaluate left out (without detections for them) with their hashes:
  // each is accounted for while it holds the version evaluate saw.
  std::vector<const nlohmann::json*> rows;
  for (const nlohmann::json& row : m["samples"]) rows.push_back(&row);
  if (const auto n = m.find("not_scored_intensity"); n != m.end() && n->is_object() && n->contains("sample_folders") &&
                                                     (*n)["sample_folders"].is_array())
    for (const nlohmann::json& row : (*n)["sample_folders"]) rows.push_back(&row);
  for (const nlohmann::json* r : rows) {
    const nlohmann::json& row = *r;
    if (!row.is_object() || !row.contains("sample") || !row["sample"].is_string()) continue;
    const std::string name = row["sample"].get<std::string>();
    scored.insert(name);
    if (!done.count(name)) {  // removed, no longer done, or past the dataset's samples
      ++gone;
      continue;
    }
    std::optional<nlohmann::json> now;
    try {
      now = reconstruct::read_run_metadata((fs::path(dir) / "samples" / name).string());
    } catch (const Error&) {
    }
    // (a metadata.json that is JSON but no object is a damaged sample: not the one scored)
    const bool readable = now && now->is_object();
    const nlohmann::json hash = readable ? now->value("/dataset/sample_hash"_json_pointer, nlohmann::json(nullptr)) : nlohmann::json();
    if (!readable || (row.contains("sample_hash") && row["sample_hash"] != hash)) ++changed;
  }
  int64_t unscored = 0;
  for (const std::string& f : done) unscored += !scored.count(f);
  if (changed == 0 && gone == 0 && unscored == 0)
    return selection.empty() || !say_current ? "" : "evaluation/ is current, of some samples only: " + selection + " (evaluate --samples)\n";
  return "evaluation/ is out of date: of the " + std::to_string(scored.size()) + " sample folders it scored" +
         (rows.size() > m["samples"].size() ? " (or left out: 2D)" : "") + ", " +
         std::to_string(changed) + " changed since (generated again with another sample_hash) and " + std::to_string(gone) +
         " are no longer done samples (damaged, failed, stale or missing now, or past the dataset's samples), and " + std::to_string(unscored) + " done ones are not in it: run `spadgen evaluate " +
         dir + (selection.empty() ? std::string() : selection.back() == '.' ? " --samples @FILE" : " --samples " + selection) +
         "` again\n";
}

std::string status_counts(const std::array<int64_t, 5>& c) {
  return std::to_string(c[0]) + " done, " + std::to_string(c[1]) + " failed, " + std::to_string(c[2]) + " stale, " +
         std::to_string(c[3]) + " missing" + (c[4] ? ", " + std::to_string(c[4]) + " damaged" : std::string());
}

}  // namespace

RunConfig estimate_shape(RunConfig c) {
  const auto round_up_2 = [](double v) {
    if (!(v > 0.0) || !std::isfinite(v)) return v;
    const double step = std::pow(10.0, std::floor(std::log10(v)) - 1.0);
    return std::ceil(v / step - 1e-9) * step;
  };
  GateConfig& g = c.sensor.gate;
  for (double* v : {&c.laser.pulse_fwhm_s, &g.jitter_fwhm_s, &g.rise_s, &g.fall_s, &g.length_s, &g.length_fwhm_s, &g.skew_fwhm_s})
    *v = round_up_2(*v);
  return c;
}

std::string dataset_schema() { return datasets::dataset_reference_markdown(); }

std::string index_rows_text(const std::string& index_path, int64_t rows, int64_t samples) {
  return index_path + " has " + std::to_string(rows) + (rows == 1 ? " row" : " rows") + " for the dataset's " + std::to_string(samples) +
         " samples (dataset.json)";
}

std::string index_rows_cause() {
  return "the index was cut short or added to after `spadgen dataset run` wrote it, or a run that changed the dataset's samples "
         "was killed before it wrote the index; `spadgen dataset run` writes it again (with nothing left to generate, only the "
         "index and the card)";
}

DatasetFolderState dataset_folder_state(const std::string& dir) {
  const DatasetSpec spec = spec_of_folder(dir);
  return {spec.count(), datasets::DatasetFolder(spec, dir).runs_on()};
}


DatasetPlan dataset_plan(const DatasetOptions& options) {
  const DatasetSpec spec = datasets::load_dataset_file(options.file);
  const datasets::Shard shard = choose_shard(options);
  const ThreadLimit thread_limit(options.threads);
  Estimator estimator(spec.repeats, options.threads);
  refuse_a_dataset_of_invalid_samples(spec, estimator, false);
  std::optional<DatasetFolder> folder;
  if (!options.out_dir.empty()) {
    folder.emplace(spec, options.out_dir);
    folder->check();  // what run would refuse (another dataset's folder, foreign files)
  }
  std::ostringstream o;
  const int64_t n = spec.count();
  o << "# dataset " << spec.file << ": " << n << " samples (" << spec.grid_cells() << " grid cells";
  if (!spec.random.empty()) o << ", " << spec.random.size() << " random keys";
  o << "), dataset seed " << spec.seed << ", " << spec.repeats << (spec.repeats == 1 ? " realisation" : " realisations")
    << " of the noise per sample\n";
  if (shard.count > 1) o << "# shard " << shard.text() << "\n";

  std::vector<std::string> columns = {"scene"};
  for (const datasets::GridAxis& g : spec.grid) columns.push_back(g.key);
  for (const datasets::RandomAxis& r : spec.random) columns.push_back(r.key);
  o << "index";
  for (const std::string& c : columns) o << "\t" << c;
  o << "\tseed\tdisk\tmemory\ttime";
  if (folder) o << "\tstatus";
  o << "\n";

  Totals total, left_total;
  int64_t samples = 0, left = 0, sensed_only = 0;
  // The done samples' measured wall times against their estimates: the pace of this machine and dataset.
  double done_seconds = 0.0, done_estimated = 0.0;
  int64_t done_timed = 0;
  // The done samples' bytes on disk against their disk estimates: where compressed files make the estimate a
  // bound (the shipped example's up to about 22.1 GB for about 3 GB written), the share done samples
  // took tells the rest.
  int64_t done_bytes = 0, done_disk_estimated = 0, done_sized = 0;
  std::vector<std::string> errors;
  std::vector<int64_t> invalid;  // the samples of the errors
  const int64_t memory_here = available_memory();
  std::vector<int64_t> too_large;  // the samples that need more memory than this machine has (run refuses each)
  datasets::WarningTally warnings;  // the scene file's, as each sample resolves
  // Each sample's scene is resolved (about 0.2 ms of one core): a plan of millions of samples takes minutes,
  // so it shows its progress.
  const int64_t owned = shard.owned(n);
  Progress bar(size_t(owned), options.progress && owned > 10000, "samples");
  check_samples(spec, shard, folder ? &*folder : nullptr, estimator, true, false, [&](Checked& checked) {
    const Sample& s = checked.sample;
    const int64_t i = s.index;
    ++samples;
    bar.tick();
    const Estimate& e = checked.estimate;
    warnings.add(i, checked.warnings);
    std::string status;
    if (!checked.resolved) {
      // with the parameters the dataset gave it (the key the error names may be set for every sample, and
      // invalid only with the drawn ones: a crop outside a width drawn smaller)
      errors.push_back(datasets::sample_text(s) + ": " + datasets::named_in_dataset_file(spec, checked.error));
      invalid.push_back(i);
      status = "invalid";
    }
    if (folder) {
      const SampleRecord& rec = checked.record;
      if (status.empty()) status = datasets::status_name(rec.status);
      if (rec.status == Status::Done && checked.resolved && rec.bytes > 0)
        done_bytes += rec.bytes, done_disk_estimated += e.disk, ++done_sized;
      // (a rendered sample of a grown repeats: its missing realisations are sensed, as `dataset run` does)
      if (rec.status != Status::Done) ++left, left_total.add(left_of(e, rec)), sensed_only += only_senses_left(rec);
      // (its estimate on the cores it ran with: the estimates scale as 1 / cores; a sample that records none, on
      // this plan's)
      else if (checked.resolved && rec.seconds > 0.0)
        done_seconds += rec.seconds, ++done_timed,
        done_estimated += e.seconds * (rec.cores > 0 ? double(usable_cores(options.threads)) / rec.cores : 1.0);
    }
    total.add(e);
    if (checked.resolved && memory_here >= 0 && e.memory > memory_here && !(folder && checked.record.status == Status::Done))
      too_large.push_back(i);
    const bool show = options.all || samples <= 10 || i >= n - 10 * shard.count;
    if (!show) {
      if (samples == 11) o << "...\t(" << "--all lists every sample)\n";
      return;
    }
    o << i;
    for (const std::string& c : columns) {
      const ojson& v = s.parameters.value(c, ojson());
      o << "\t";
      if (v.is_number_float()) {
        char buf[32];
        std::snprintf(buf, sizeof buf, "%.6g", v.get<double>());  // the index holds every digit
        o << buf;
      } else {
        o << (v.is_string() ? v.get<std::string>() : v.dump());
      }
    }
    if (checked.resolved) o << "\t" << s.seed << "\t" << bytes_text(e.disk) << "\t" << bytes_text(e.memory) << "\t" << duration_text(e.seconds);
    else o << "\t" << s.seed << "\t-\t-\t-";  // its error below
    if (folder) o << "\t" << status;
    o << "\n";
  });
  // per sample what it keeps; the totals with one sample's temporary files, as dataset run's disk check counts them
  const int64_t valid = samples - int64_t(errors.size());  // the invalid ones have no estimate
  // Where compressed files or the saved light are counted at their most (the note below gives the least), the
  // figures are bounds, so named (the shipped example's "disk about 22.1 GB" was 7 times what it wrote).
  // (the saved light at 2.5 ns of bins per pixel is more than most scenes take, not a bound: the footer says so)
  const std::string disk = std::string("disk ") + total.disk_words();
  o << "# per sample: " << disk << bytes_text(valid ? total.kept / valid : 0) << ", memory up to "
    << bytes_text(total.memory) << ", time about " << duration_text(valid ? total.seconds / double(valid) : 0.0) << "\n";
  o << "# " << (shard.count > 1 ? "this shard" : "total") << ": " << samples << " samples"
    << (valid < samples ? " (the " + std::to_string(valid) + " valid ones estimated)" : std::string()) << ", " << disk << bytes_text(total.disk())
    << ", time about " << duration_text(total.seconds) << " (estimates for " << usable_cores(options.threads)
    << (usable_cores(options.threads) == 1 ? " core" : " cores") << ": docs/datasets.md, \"Estimates\")\n";
  o << "# " << estimator.shapes() << (estimator.shapes() == 1 ? " estimate" : " estimates")
    << " computed, one per distinct shape of run (about 40 ms of one core each where the sensor's gate response "
       "differs; docs/datasets.md, \"Estimates\")\n";
  if (total.paths_bound)
    o << "# with render.target_relative_error a pixel's paths depend on its light: the times count "
         "render.max_samples_per_pixel for every pixel, an upper bound\n";
  if (total.disk_at_least() != total.disk())
    o << "# the disk counts the compressed files (EXR images, Zarr stores) uncompressed"
      << (total.least.light ? " and the saved light at 2.5 ns of bins per pixel (more than most scenes take, not a bound: "
                              "the scene decides the span, up to the time window)" : "") << ": "
      << (total.disk_at_least() > 0 ? "the samples take at least " + bytes_text(total.disk_at_least()) + " (" + least_text(total.least) + "); "
                                    : std::string("the samples may take far less (zeros compress to almost nothing"
                                                  ") and no least is counted; "))
      << "examples/datasets/multi_object_variations.json writes about an eighth of the most, and `dataset plan -o DIR` "
         "scales the samples left by what the done ones keep\n";
  if (folder) {
    const int64_t free = free_disk(options.out_dir);
    o << "# left to generate in " << options.out_dir << ": " << left << (left == 1 ? " sample" : " samples")
      << (sensed_only > 0 ? " (" + std::to_string(sensed_only) + " of them rendered, with realisations missing: only those are sensed, from the saved light)"
                          : std::string())
      << ", "
      << "disk " << left_total.disk_words() << bytes_text(left_total.disk())
      << " (free: " << (free >= 0 ? bytes_text(free) : std::string("unknown")) << "), time about "
      << duration_text(left_total.seconds) << "\n";
    // The model is of one machine kind; the samples done here tell this machine's pace (the model's fixed cost
    // per run was 3-6 times what small samples took on another).
    if (done_timed > 0 && done_estimated > 0.0) {
      const double pace = done_seconds / done_estimated;
      const bool one = done_timed == 1;
      o << "# the " << done_timed << " done " << (one ? "sample" : "samples") << " took " << duration_text(done_seconds)
        << ", " << ratio_text(pace) << (one ? " times its estimate (its" : " times their estimates (their")
        << " metadata.json's run.wall_seconds, against estimates for the cores they ran on, run.cores)"
        << (left > 0 ? ": at that pace the samples left take about " + duration_text(left_total.seconds * pace) : std::string())
        << "\n";
    }
    if (done_sized > 0 && done_disk_estimated > 0) {
      const double share = double(done_bytes) / double(done_disk_estimated);
      const bool one = done_sized == 1;
      o << "# the " << done_sized << " done " << (one ? "sample keeps " : "samples keep ") << bytes_text(done_bytes)
        << " on disk, " << ratio_text(share) << (one ? " of its disk estimate (its" : " of their disk estimates (their")
        << " files but metadata.json, as index.jsonl's bytes)"
        << (left > 0 ? ": at that share the samples left keep about " +
                           bytes_text(int64_t(std::llround(double(left_total.kept) * share)))
                     : std::string())
        << "\n";
    }
  }
  if (const std::string w = spec.coverage_warning(); !w.empty()) o << "warning: " << w << "\n";
  // (the run refuses each such sample, recorded in failed/: said here, before any work)
  if (!too_large.empty())
    o << "warning: " << too_large.size() << (too_large.size() == 1 ? " sample (" : " samples (") << datasets::ranges_text(too_large)
      << ") need more memory than this machine has (up to " << bytes_text(total.memory) << ", " << bytes_text(memory_here)
      << " available): `dataset run` refuses " << (too_large.size() == 1 ? "it" : "each") << ", recorded in failed/; "
         "lower the keys of the largest parts (spadgen info SCENE --set ... lists them) or run on a larger machine\n";
  for (const std::string& w : warnings.lines(" (spadgen info SCENE --set ... shows a sample's)")) o << "warning: " << w << "\n";
  for (const std::string& e : errors) o << "error: " << e << "\n";
  return {o.str(), int64_t(errors.size()),
          errors.empty() ? std::string()
                         : spec.file + ": " + std::to_string(errors.size()) + (errors.size() == 1 ? " sample (" : " samples (") +
                               datasets::ranges_text(invalid) + (errors.size() == 1 ? ") makes" : ") make") +
                               " an invalid run (the errors end the plan); `dataset run` records them in failed/"};
}

namespace {
// The index as a run leaves early (a signal, an error), best effort: the way it leaves is reported first.
// Where the completed samples (`completed` of them) are listed: "index.jsonl lists them" ("it") when written here.
std::string leave_index(const DatasetFolder& folder, datasets::RunPresence& presence, const SampleHashes& hashes, int64_t completed) {
  const std::string them = completed == 1 ? "it" : "them";
  try {
    return folder.write_index([&](const DatasetFolder::RecordSink& sink) { inspect_each(folder, false, &hashes, sink); }, &presence)
               ? "index.jsonl lists " + them
               : "the last run on the folder to end lists " + them + " in index.jsonl";
  } catch (const std::exception& e) {
    std::fprintf(stderr, "spadgen: dataset: the index was not updated: %s\n", e.what());
    return "the next run lists " + them + " in index.jsonl";
  }
}

// A signal while the samples are checked: no sample generated, so the index stays as it was (rewriting it
// resolves every sample the check had not reached: about a minute per 200,000, past Slurm's 30 s to SIGKILL).
struct StoppedWhileChecking : Interrupted {
  using Interrupted::Interrupted;
};

// dataset_run's work once it is on the folder: the shard's samples, then the index when no other run is on it.
void run_owned_samples(const DatasetOptions& options, const DatasetSpec& spec, const datasets::Shard& shard,
                       const DatasetFolder& folder, datasets::RunPresence& presence, SampleHashes& hashes,
                       Estimator& estimator) {
  const fs::path dir = folder.dir();

  // What this shard has to do: every sample it owns that is not done, checked before any work, by index
  // (inspected again when its turn comes: a record per sample took 1.7 kB, 1.7 GB for a million samples).
  std::vector<int64_t> todo;
  int64_t owned = 0, skipped = 0;
  Totals totals;
  const int64_t mine = shard.owned(spec.count());
  Progress bar(size_t(mine), options.progress && mine > 10000, "samples inspected");
  try {
    check_samples(spec, shard, &folder, estimator, false, true, [&](Checked& c) {
      InterruptGuard::check();  // a signal while the samples are checked (100,000 took 50 s before it stopped)
      ++owned;
      bar.tick();
      const SampleRecord& rec = c.record;
      const int64_t i = c.sample.index;
      if (size_t(i) < hashes.size() && !rec.hash.empty()) std::from_chars(rec.hash.data(), rec.hash.data() + rec.hash.size(), hashes[size_t(i)], 16);
      if (rec.status == Status::Done) {
        ++skipped;
        return;
      }
      if (!rec.hash.empty()) {
        // (a rendered sample whose realisations are missing, repeats grown: only those are sensed)
        totals.add(left_of(c.estimate, rec));
      }
      todo.push_back(i);
    });
  } catch (const Interrupted&) {
    throw StoppedWhileChecking("interrupted by a signal: the dataset run stopped while it checked the samples, before it "
                               "generated any; the index is as it was, and running it again goes on");
  }
  // What killed runs left in samples/ is removed first (a sample another run is writing keeps its own), so
  // that the disk check does not count it.
  Staging::remove_leftovers(dir / "samples");
  const int64_t disk = totals.disk(), disk_at_least = totals.disk_at_least();
  const double seconds = totals.seconds;
  // Refused when even the least they can take does not fit (compressed stores not counted,
  // the saved light without lit bins: the scene decides them).
  if (const int64_t free = free_disk(dir); free >= 0 && free < disk_at_least) {
    const bool compressed = disk_at_least != disk;
    const auto [need, have] = bytes_texts(compressed ? disk_at_least : disk, free);
    throw Error("dataset run: the " + std::to_string(todo.size()) + " samples left to generate in " + dir.string() +
                (shard.count > 1 ? " (shard " + shard.text() + ")" : std::string()) + " need " +
                (compressed ? "at least " + need + " (" + least_text(totals.least) + "; at most " + bytes_text(disk) + ")"
                            : "about " + need) +
                ", and " + have + " is free there (about " +
                bytes_text(todo.empty() ? 0 : disk_at_least / int64_t(todo.size())) +
                " per sample: `spadgen dataset plan` lists them); free some space, write fewer outputs (outputs.*), or "
                "use another folder (-o)");
  }
  if (options.progress)
    std::fprintf(stderr, "spadgen: dataset %s: %lld of %lld samples%s to generate (%lld done already), about %s, %s%s on disk\n",
                 dir.string().c_str(), static_cast<long long>(todo.size()), static_cast<long long>(owned),
                 shard.count > 1 ? (" of shard " + shard.text()).c_str() : "", static_cast<long long>(skipped),
                 duration_text(seconds).c_str(), totals.disk_words(), bytes_text(disk).c_str());

  const auto start = std::chrono::steady_clock::now();
  std::vector<int64_t> failed;
  int64_t generated = 0, by_others = 0;
  // Samples another run on this folder is working on (a second run without shards, or overlapping shards)
  // are left for later: each sample is claimed first, and checked again once claimed (the other run may
  // have completed it). When only claimed samples are left, they are tried again after 0.2 s, the pause doubling
  // to at most 1 s while they stay held: each try checks every held sample (its scene resolved and hashed), which
  // at 5 tries a second took a third of a core under the sanitizers.
  // SIGINT or SIGTERM (Slurm's time limit, scancel) stop the run; the samples published before stay (the
  // next run skips them), and the index lists them: best effort, the signal's message comes first.
  const auto stopped = [&](const std::string& where) {
    const std::string listed = leave_index(folder, presence, hashes, int64_t(generated));
    const std::string kept = generated == 0 ? "it completed no sample" :
                             generated == 1 ? "the sample it completed is kept (" + listed + ")" :
                             "the " + std::to_string(generated) + " samples it completed are kept (" + listed + ")";
    return Interrupted("interrupted by a signal: the dataset run stopped " + where + "; " + kept + ", and running it again goes on");
  };
  std::deque<size_t> pending;
  for (size_t t = 0; t < todo.size(); ++t) pending.push_back(t);
  size_t handled = 0, busy_in_a_row = 0;
  std::set<int64_t> rendered_here;  // samples this run rendered (a retried one's realisations follow its render)
  bool waiting = false;  // since waiting_since, every sample left was another run's
  std::chrono::milliseconds pause{200};  // before the next try of samples that are all held
  std::chrono::steady_clock::time_point waiting_since{};
  std::chrono::steady_clock::time_point last_said;
  int said = 0;
  while (!pending.empty()) {
    const size_t t = pending.front();
    pending.pop_front();
    const Sample s = datasets::make_sample(spec, todo[t]);
    // A sample another spadgen process holds (its claim: another dataset run generates it; or its folder's lock:
    // a reader such as reconstruct or sense, or a run into it) is tried again after the others, with a wait
    // when every sample left is held (a reader's lock failed the sample, as if it could not be generated).
    const auto wait_turn = [&] {
      pending.push_back(t);
      if (++busy_in_a_row >= pending.size()) {  // every sample left is held for now
        if (interrupt_flag().load()) throw stopped("waiting for samples another spadgen process holds");
        // Said after 10 s and every minute: a run that was stopped (SIGSTOP, a suspended job) or hangs holds
        // its samples until it ends, and this one waits for it.
        const auto now = std::chrono::steady_clock::now();
        if (!waiting) waiting = true, waiting_since = now, last_said = now, pause = std::chrono::milliseconds(200);
        const double waited = std::chrono::duration<double>(now - waiting_since).count();
        if (waited >= 10.0 && (said == 0 || std::chrono::duration<double>(now - last_said).count() >= 60.0)) {
          std::vector<int64_t> held;
          for (size_t p : pending) held.push_back(todo[p]);
          std::sort(held.begin(), held.end());
          std::fprintf(stderr, "spadgen: dataset: waiting %.0f s for sample(s) %s, which another spadgen process holds "
                               "(another run on %s, or a reader of the sample's folder: reconstruct, sense, evaluate; a "
                               "process that was stopped or hangs holds them until it ends)\n",
                       waited, datasets::ranges_text(held).c_str(), dir.string().c_str());
          last_said = now, ++said;
        }
        std::this_thread::sleep_for(pause);
        pause = std::min(2 * pause, std::chrono::milliseconds(1000));
        busy_in_a_row = 0;
      }
    };
    const std::unique_ptr<datasets::SampleClaim> claim = folder.try_claim(s);
    if (!claim) {
      wait_turn();
      continue;
    }
    // (the counts of held samples restart only once a sample is handled: one whose folder turns out held, below,
    // spun without a pause or a word when they restarted here)
    const auto handled_one = [&] { busy_in_a_row = 0, waiting = false, said = 0; };
    ++handled;
    const SampleRecord rec = folder.inspect(s);  // as it is now, under the claim
    if (rec.status == Status::Done) {
      ++by_others;  // completed by another run meanwhile
      handled_one();
      continue;
    }
    const auto sample_start = std::chrono::steady_clock::now();
    // The buffers this sample's runs freed and kept for reuse go with it: the next sample may have another
    // shape, and the plan's memory is per sample (a random acquisition.frames over 10 samples peaked at 850 MB
    // against 413 MB planned).
    struct ReleaseBuffers {
      ~ReleaseBuffers() { release_cached_buffers(); }
    } release_buffers;
    try {
      InterruptGuard::check();  // a signal between two samples
      if (rec.hash.empty()) throw Error(rec.error);  // the sample's parameters make an invalid scene
      // A sample rendered again (damaged, stale) has its realisations sensed again too: they hard-link its
      // files, which are new ones now.
      // (rendered in an earlier attempt of this run, which a realisation's held folder stopped: its realisations
      // are sensed again all the same)
      bool rendered = rendered_here.count(s.index) > 0;
      // A sample or realisation folder without a readable metadata.json (lost, or cut short by a copy)
      // says nothing of what it holds, and its run would refuse the files as another's: it is this sample's
      // (in samples/, under its claim), so it goes, and the sample is generated again.
      const auto clear_unrecorded = [&](const std::string& f) {
        std::error_code ec;
        if (fs::exists(dir / f, ec) && !folder.sample_metadata(f)) {
          fs::remove_all(dir / f, ec);
          if (ec) throw Error("cannot remove " + (dir / f).string() + ", a sample folder without its metadata.json: " + ec.message());
        }
      };
      clear_unrecorded(s.folder());
      for (int k = 1; k < spec.repeats; ++k) clear_unrecorded(s.repeat_folder(k));
      // Another process's hold on the sample's folder, found before the scene is loaded (the run takes the same
      // lock later: this is a quick look, so that a held sample costs little each time it is tried)
      { const FolderLock probe(dir / s.folder()); }
      if (!folder.holds(s.folder(), rec.hash, s.scene)) {
        rendered = true;
        rendered_here.insert(s.index);
        RunOptions r;
        r.scene_file = spec.scenes[size_t(s.scene)];
        r.out_dir = (dir / s.folder()).string();
        r.overrides = s.overrides;
        r.threads = options.threads;
        r.progress = false;
        r.dataset = datasets::dataset_section(folder, s, rec.hash, 0);
        if (!rec.tables_hash.empty()) r.tables_hash = rec.tables_hash;
        const WarningContext context("sample " + std::to_string(s.index) + ": ");
        run(r);
      }
      bool warned = rendered;  // the sample's warnings said on stderr (by its run, or a realisation's sense)
      for (int k = 1; k < spec.repeats; ++k) {
        if (!rendered && folder.holds(s.repeat_folder(k), rec.hash, s.scene)) continue;
        const fs::path rf = dir / s.repeat_folder(k);
        SenseOptions so;
        so.run_dir = (dir / s.folder()).string();
        so.out_dir = rf.string();
        so.noise_seed = s.noise_seed + uint64_t(k);
        so.threads = options.threads;
        so.progress = false;
        so.dataset = datasets::dataset_section(folder, s, rec.hash, k);
        if (!rec.tables_hash.empty()) so.tables_hash = rec.tables_hash;
        // (silent once said: the same scene, sensor and light)
        const WarningContext context("sample " + std::to_string(s.index) + ", realisation " + std::to_string(k) + ": ", warned);
        sense(so);
        warned = true;
      }
      folder.clear_failure(s);
      ++generated;
    } catch (const Interrupted&) {
      throw stopped("in sample " + std::to_string(s.index));  // this one's folder was not published
    } catch (const FolderBusy&) {  // before anything of it was written: tried again later
      --handled;
      wait_turn();
      continue;
    } catch (const std::exception& e) {
      // said first: recording it in failed/ may fail too (the disk that made the sample fail is full)
      std::fprintf(stderr, "spadgen: dataset: sample %lld failed: %s\n", static_cast<long long>(s.index), scenes::one_line(e.what()).c_str());
      failed.push_back(s.index);
      try {
        folder.record_failure(s, rec.hash, e.what());
      } catch (const std::exception& r) {  // the other samples go on (a full disk failed the whole run)
        std::fprintf(stderr, "spadgen: dataset: the failure of sample %lld is not recorded in failed/: %s\n",
                     static_cast<long long>(s.index), scenes::one_line(r.what()).c_str());
      }
    }
    handled_one();
    if (options.progress) {
      const auto now = std::chrono::steady_clock::now();
      const double took = std::chrono::duration<double>(now - sample_start).count();
      const double mean = std::chrono::duration<double>(now - start).count() / double(handled);
      std::fprintf(stderr, "spadgen: dataset: sample %lld %s in %.1f s; %zu/%zu of this run, %lld failed; about %s left\n",
                   static_cast<long long>(s.index), failed.empty() || failed.back() != s.index ? "done" : "failed", took, handled,
                   todo.size(), static_cast<long long>(failed.size()), duration_text(mean * double(todo.size() - handled)).c_str());
    }
  }

  const std::optional<datasets::CardTally> records = folder.write_index(
      [&](const DatasetFolder::RecordSink& sink) { inspect_each(folder, options.progress, &hashes, sink); }, &presence);
  if (options.progress)
    std::fprintf(stderr, "spadgen: dataset %s: %s (this run: %lld generated, %lld skipped, %lld completed by another run, %zu failed)\n",
                 dir.string().c_str(),
                 records ? status_counts(records->count).c_str()
                         : "another run is still on the folder: the last to end writes the index",
                 static_cast<long long>(generated), static_cast<long long>(skipped), static_cast<long long>(by_others),
                 failed.size());
  // An evaluation/ of the samples this run generated again is of data no longer there: said (even with -q).
  if (records && generated > 0)
    if (const std::string note = evaluation_status(dir.string()); !note.empty())
      std::fprintf(stderr, "spadgen: dataset: %s", note.c_str());
  if (!failed.empty())
    throw Error("dataset run: " + std::to_string(failed.size()) + (failed.size() == 1 ? " sample failed (" : " samples failed (") + datasets::ranges_text(failed) +
                "); their errors are in " + (dir / "failed").string() + " and `spadgen dataset status " + dir.string() + "`");
}
}  // namespace

void dataset_run(const DatasetOptions& options) {
  const DatasetSpec spec = datasets::load_dataset_file(options.file);
  const datasets::Shard shard = choose_shard(options);
  if (options.out_dir.empty()) throw Error("dataset run: expected the dataset folder (-o DIR)");
  InterruptGuard interrupt_guard;  // for the whole run: the runs and senses of its samples hold theirs inside it
  const ThreadLimit thread_limit(options.threads);  // the samples' checks too (each run and sense sets its own as well)
  Estimator estimator(spec.repeats, options.threads);
  refuse_a_dataset_of_invalid_samples(spec, estimator, true);  // before the folder is made
  refuse_output_inside(options.out_dir, "-o " + options.out_dir);  // (in a run folder, a dataset's entries, a set)
  if (const std::string w = spec.coverage_warning(); !w.empty()) std::fprintf(stderr, "spadgen: warning: %s\n", w.c_str());
  // A realisation's metadata.json names the sample it re-samples (sense.from): every sample failed with it
  if (spec.repeats > 1)
    require_utf8_path(resolved_folder(options.out_dir), "the dataset folder",
                      "which each realisation's metadata.json records (repeats: sense.from names its sample)");
  // The folder as the samples' staging names it (-o LINK/../D: the dataset's own files and its samples went
  // to two folders, the kernel's and the lexical one)
  const DatasetFolder folder(spec, resolved_folder(options.out_dir).string());
  folder.claim();
  // The index is written by the last run on the folder to end (datasets::RunPresence).
  const std::unique_ptr<datasets::RunPresence> presence = folder.enter();
  SampleHashes hashes(spec.count() <= kMaxKeptHashes ? size_t(spec.count()) : 0);
  try {
    run_owned_samples(options, spec, shard, folder, *presence, hashes, estimator);
  } catch (const StoppedWhileChecking&) {
    throw;
  } catch (...) {
    // Any other way out (a signal while samples are generated, the disk check's refusal, an error): the
    // index is written as at the end when no other run is on the folder (another may have left it to this
    // one, which would leave it to no one).
    if (presence->held()) (void)leave_index(folder, *presence, hashes, 0);
    throw;
  }
}

namespace {
// What is wrong with index.jsonl against the samples as they are now, row by row as the samples are inspected
// (in index order): "" when every row is there, in order, and is the row the index writer would write now
// (index_jsonl_row), but for its bytes (of the files' sizes less hard links: a copy of the folder without its
// links holds more). The rows are not kept: a million samples' are gigabytes.
class IndexCheck {
 public:
  explicit IndexCheck(const fs::path& dir) : path_(dir / "index.jsonl") {
    std::error_code ec;
    if (!fs::is_regular_file(path_, ec))
      problem_ = "index: " + path_.string() + (fs::exists(path_, ec) ? " is not a regular file" : " is missing") + kFix;
    else
      in_.open(path_);
  }

  // The next sample's row as the index writer would write it now.
  void expect(const std::string& wanted) {
    if (problem_.empty() && !short_) problem_ = check(&wanted);
    if (problem_.empty() && !short_) ++row_;
  }

  // What is wrong, once `samples` rows were expected.
  std::string finish(size_t samples) {
    if (problem_.empty() && short_)
      problem_ = "index: " + index_rows_text(path_.string(), int64_t(row_), int64_t(samples)) + ": " + index_rows_cause();
    if (problem_.empty()) {
      samples_ = samples;
      problem_ = check(nullptr);  // a row past the samples
    }
    return problem_;
  }

 private:
  static constexpr const char* kFix =
      ": `spadgen dataset run` writes it again (with nothing left to generate, it writes only the index and the card)";

  // Row row_ against `wanted` (null: there should be none).
  std::string check(const std::string* wanted) {
    std::string line;
    if (!std::getline(in_, line)) {
      short_ = wanted != nullptr;
      return "";
    }
    const std::string where = "index: " + path_.string() + " row " + std::to_string(row_ + 1);
    json r;
    try {
      r = json::parse(line);
    } catch (const json::exception&) {
      return where + " is not JSON (damaged since it was written)" + kFix;
    }
    const auto text = [](const json& j, const char* key) {
      return j.is_object() && j.contains(key) && j[key].is_string() ? j[key].get<std::string>() : std::string();
    };
    if (!r.is_object() || !r.contains("index") || !r["index"].is_number_unsigned() || text(r, "status").empty())
      return where + " is not a row spadgen writes (index, status, ...)" + kFix;
    if (r["index"].get<uint64_t>() != row_)
      return where + " lists sample " + r["index"].dump() + " where sample " + std::to_string(row_) + " belongs (damaged since it was written)" + kFix;
    if (!wanted) return where + ": the dataset has " + std::to_string(samples_) + " samples" + kFix;
    json want = json::parse(*wanted);
    const bool done = text(r, "status") == "done", done_now = text(want, "status") == "done";
    if (done != done_now || (done && text(r, "sample_hash") != text(want, "sample_hash")))
      return where + " lists sample " + std::to_string(row_) + " as " + text(r, "status") +
             (done && done_now ? " with another hash (" + text(r, "sample_hash") + ")" : "") + ", and it is " +
             (done_now ? "done (" + text(want, "sample_hash") + ")" : text(want, "status")) + " now: the index is out of date" + kFix;
    // The rest of the row as the sample's folder and the dataset file give it: its parameters, seeds, folders,
    // files and ground truth (a row edited to other parameters was taken, and the Python package selected the
    // sample by them; an adversarial tester's find).
    for (json* j : {&r, &want}) j->erase("bytes");
    if (r == want) return "";
    for (const auto& [key, value] : want.items())
      if (!r.contains(key) || r[key] != value)
        return where + " gives sample " + std::to_string(row_) + " another " + key + " than its folder and the dataset file (" +
               scenes::one_line(r.contains(key) ? r[key].dump().substr(0, 80) : std::string("none")) + ", expected " +
               scenes::one_line(value.dump().substr(0, 80)) + "): damaged or edited since it was written" + kFix;
    for (const auto& [key, value] : r.items())
      if (!want.contains(key))
        return where + " holds " + key + ", which spadgen does not write for a " + text(r, "status") + " sample: damaged or "
               "edited since it was written" + kFix;
    return "";
  }

  fs::path path_;
  std::ifstream in_;
  size_t row_ = 0, samples_ = 0;
  bool short_ = false;  // the file ended before the samples
  std::string problem_;
};
}  // namespace

namespace {
// What `dataset run` does with a damaged sample: it generates it again, unless one of its folders holds files
// that folder's metadata.json does not list (its list damaged): a run never replaces files it cannot tell are
// its own, so it records the sample failed, naming them (status said it would generate it again).
std::string damaged_remedy(const DatasetSpec& spec, const std::string& dir, const datasets::Sample& s) {
  std::vector<std::string> folders = {s.folder()};
  for (int r = 1; r < spec.repeats; ++r) folders.push_back(s.repeat_folder(r));
  for (const std::string& f : folders) {
    std::vector<std::string> foreign;
    try {
      foreign = Staging::foreign_in_run_folder(fs::path(dir) / f);
    } catch (const fs::filesystem_error&) {
      continue;  // (a folder it cannot read: the run's own attempt says why)
    }
    if (!foreign.empty())
      return "`spadgen dataset run` cannot generate it again: " + f + " holds " + Staging::foreign_list(foreign) +
             ", which its metadata.json does not list, and a run replaces only files it can tell are its own; move or "
             "remove " + f + " and run again";
  }
  return "`spadgen dataset run` generates it again";
}

// The dataset file as it is now against this folder's record of it (dataset.json): where `dataset run` with the
// file would refuse the folder (the file edited since, or the record damaged), what it would say; "" otherwise, or
// when the file is not there to read (a folder copied from another machine). Status reported "2 done" of a
// folder whose next run was refused.
std::string dataset_file_refusal(const DatasetSpec& recorded, const std::string& dir) {
  std::error_code ec;
  if (!fs::is_regular_file(recorded.file, ec)) return "";
  try {
    DatasetFolder(datasets::load_dataset_file(recorded.file), dir).check();
  } catch (const Error& e) {
    return "`spadgen dataset run " + recorded.file + "` on this folder would stop now: " + scenes::one_line(e.what()) + "\n";
  }
  return "";
}
}  // namespace

DatasetStatus dataset_status(const std::string& dir) {
  const DatasetSpec spec = spec_of_folder(dir);
  const DatasetFolder folder(spec, dir);
  // The samples by status and the errors of the failed and damaged ones; no record kept.
  std::array<int64_t, 5> count{};
  std::array<std::vector<int64_t>, 5> which;
  std::string failed, damaged;
  std::map<std::string, std::vector<int64_t>> stale_why;  // what changed, and the samples it made stale
  std::set<std::string> done_folders;                      // (their names, as evaluate's metrics.json names them)
  // index.jsonl's rows against the samples as they are now
  IndexCheck index_check{fs::path(dir)};
  inspect_each(folder, true, nullptr, [&](const SampleRecord& r) {
    index_check.expect(datasets::index_jsonl_row(spec, r));
    ++count[size_t(r.status)];
    if (r.status == Status::Done)
      for (const std::string& f : r.folders) done_folders.insert(fs::path(f).filename().string());
    if (r.status != Status::Done) which[size_t(r.status)].push_back(r.sample.index);
    if (r.status == Status::Stale) stale_why[r.error].push_back(r.sample.index);
    // (on one line each: a recorded error may hold a list of mistakes, or a control byte a library echoed)
    if (r.status == Status::Failed) failed += "sample " + std::to_string(r.sample.index) + " failed: " + scenes::one_line(r.error) + "\n";
    if (r.status == Status::Damaged)
      damaged += "sample " + std::to_string(r.sample.index) + " damaged: " + scenes::one_line(r.error) + " (" +
                 damaged_remedy(spec, dir, r.sample) + ")\n";
  });
  std::ostringstream o;
  o << dir << ": dataset " << spec.file << ", " << spec.count() << " samples: " << status_counts(count) << "\n";
  // (a status while shards ran said "missing" and "index.jsonl is missing" and nothing of the runs: a user ran
  // the dataset again, needlessly)
  if (folder.runs_on())
    o << "a dataset run is on the folder now: its samples in progress count as missing until it publishes them, "
         "and the last run to end writes the index\n";
  o << dataset_file_refusal(spec, dir);
  for (Status st : {Status::Failed, Status::Stale, Status::Missing, Status::Damaged})
    if (!which[size_t(st)].empty()) o << datasets::status_name(st) << ": " << datasets::ranges_text(which[size_t(st)]) << "\n";
  for (const auto& [why, samples] : stale_why)
    o << "stale " << datasets::ranges_text(samples) << ": " << why << " (`spadgen dataset run` generates them again)\n";
  o << failed << damaged;
  // Folders of samples past "samples" (the file asked for fewer since): kept, outside the index.
  std::vector<int64_t> beyond;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(fs::path(dir) / "samples", ec)) {
    const std::string n = e.path().filename().string();
    if (n.size() == 6 && std::all_of(n.begin(), n.end(), [](char ch) { return ch >= '0' && ch <= '9'; }) &&
        std::stoll(n) >= spec.count())
      beyond.push_back(std::stoll(n));
  }
  std::sort(beyond.begin(), beyond.end());
  if (!beyond.empty())
    o << "beyond the " << spec.count() << " samples: the folders of samples " << datasets::ranges_text(beyond)
      << " (kept, not in the index; a larger \"samples\" takes them again)\n";
  o << evaluation_status(dir, &done_folders, /*say_current=*/true);
  // The index as the folders are now: a missing, damaged or out-of-date index.jsonl is said, and the dataset is
  // not complete (status said "all done", exit 0, and evaluate and the Python package then refused the folder)
  const std::string index = index_check.finish(size_t(spec.count()));
  if (!index.empty()) o << index << "\n";
  const bool complete = count[size_t(Status::Done)] == spec.count() && index.empty();
  return {o.str(), complete};
}

}  // namespace spadgen::app
