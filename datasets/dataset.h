// Dataset files: JSON (comments allowed) describing a benchmark dataset as variations of scene files.
//
//   {
//     "description": "plate and sphere at varied distances",
//     "seed": 7,                                   // the dataset seed: every sample's draws and seeds derive from it
//     "scenes": ["../scenes/paper/multi_object.json"],
//     "samples": 100,                              // null: one sample per grid cell
//     "set":    {"render.samples_per_pixel": 4},   // every sample
//     "grid":   {"laser.average_power_mW": [1, 2]},  // sample i takes grid cell i mod (cells)
//     "random": {"ambient.illuminance_lux": {"log_uniform": [1, 1000]}},
//     "seeds":  {"chip": 1},                       // a stream's seed fixed for every sample ("per_sample": derived)
//     "repeats": 1                                 // sensor realisations of the temporal noise per rendered sample
//   }
//
// A sample's parameters and seeds depend only on the dataset seed, the file's axes and the sample's index:
// adding samples (a larger "samples") never changes the existing ones. Every key of set, grid and random is
// a scene-file key, written as `--set` writes it, and is checked exactly as `--set` checks it.
// The keys, their types and defaults are declared once (dataset_keys()); docs/datasets.md is generated
// from them by `spadgen dataset schema`.
#pragma once
#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace spadgen::datasets {

struct DatasetKey {
  std::string key;      // top-level key of the dataset file
  std::string type;     // as the reference shows it
  std::string def;      // default as JSON text; "required" when there is none
  std::string doc;
};
// Every key a dataset file may hold, in the order the resolved file lists them.
const std::vector<DatasetKey>& dataset_keys();

// A random draw for one scene-file key.
struct Distribution {
  enum class Kind { Uniform, LogUniform, Normal, UniformInt, Choice };
  Kind kind = Kind::Uniform;
  double a = 0.0, b = 0.0;  // uniform, log_uniform: [a, b); uniform_int: [a, b] inclusive; normal: mean, sigma
  std::optional<double> min, max;  // normal: truncated to [min, max] (by rejection)
  nlohmann::json choices;          // choice: the values, drawn with equal probability
};

struct GridAxis {
  std::string key;  // scene-file key, dotted as --set writes it
  nlohmann::json values;
};
struct RandomAxis {
  std::string key;
  Distribution dist;
  nlohmann::json spec;  // as the file wrote it, for the card
};

struct DatasetSpec {
  std::string file;                      // the dataset file, absolute
  std::string description;
  uint64_t seed = 0;
  std::vector<std::string> scenes;       // scene files, absolute
  std::vector<std::string> scene_names;  // as the dataset file wrote them
  std::optional<int64_t> samples;        // null: one per grid cell
  std::vector<std::pair<std::string, nlohmann::json>> set;
  std::vector<GridAxis> grid;
  std::vector<RandomAxis> random;
  // A stream's seed fixed for every sample, or nullopt: derived per sample from the dataset seed.
  std::optional<uint64_t> light_seed, chip_seed, noise_seed;
  int repeats = 1;
  // The file with every default explicit and the scene paths as written: what `dataset.json` in the
  // dataset folder records, and what decides whether a folder holds this dataset.
  nlohmann::ordered_json resolved;

  // Scenes times the product of the grid axes' sizes.
  int64_t grid_cells() const;
  // The number of samples: "samples", or grid_cells() when it is null.
  int64_t count() const;
  // "" or, when "samples" is fewer than the grid cells, what that leaves out: the cells past the samples make
  // none, and with the scenes outermost, whole scene files may make none (a plan and a run say it).
  std::string coverage_warning() const;
  // The samples scene file i makes: its cells once per pass over the grid, and of the last, partial pass
  // those before count() (the scenes are outermost).
  int64_t samples_of_scene(size_t i) const;
};

// The largest dataset (samples) a file may describe, and the largest grid.
inline constexpr int64_t kMaxSamples = 100'000'000;

// Reads and checks a dataset file. Errors name the file and the key (/random/ambient.illuminance_lux),
// what was found and what was expected; keys of set, grid and random are checked against the first scene
// file with the scene file's own checks (unknown key, did-you-mean, type, range).
DatasetSpec load_dataset_file(const std::string& path);
DatasetSpec parse_dataset_text(const std::string& text, const std::string& path);

// One sample of a dataset.
struct Sample {
  int64_t index = 0;
  int scene = 0;                         // into DatasetSpec::scenes
  // Overrides of the scene file, as `--set` takes them, in order: set, grid, random, seeds.
  std::vector<std::string> overrides;
  // What varies: {"scene": name, grid and random keys: value}, in the file's order.
  nlohmann::ordered_json parameters;
  uint64_t seed = 0;                     // the sample's `seed` key
  uint64_t light_seed = 0, chip_seed = 0, noise_seed = 0;  // the seeds its streams use
  // The sample's folder relative to the dataset folder ("samples/000042"), and realisation r's
  // (r >= 1: "samples/000042_r01"; realisation 0 is the sample's own folder).
  std::string folder() const;
  std::string repeat_folder(int r) const;
};

// Sample `index` (0 <= index < spec.count()): a function of the dataset seed, the axes and the index only.
Sample make_sample(const DatasetSpec& spec, int64_t index);

// "sample 2 (camera.width_px 16, sensor.preset pixel_A)": the sample and the values the dataset gave it (the
// scene file left out: an error about the sample names it).
std::string sample_text(const Sample& s);
// A sample's error that names a key as the run's --set ("--set camera.crop: found ..."), with the key's place in
// the dataset file instead ("d.json: /set/camera.crop: found ..."): the sample's keys are the dataset's. Other
// errors are returned as they are.
std::string named_in_dataset_file(const DatasetSpec& spec, const std::string& error);

// The samples of scene file `scene` that tell whether the dataset file is wrong: its first kProbeSamples
// samples (index order, over the grid's cells of that scene). When all of them make invalid scenes (or
// runs the sensor refuses), the mistake is the dataset file's: load_dataset_file and `dataset plan|run`
// refuse it naming the first.
inline constexpr int kProbeSamples = 16;
std::vector<int64_t> probe_samples(const DatasetSpec& spec, size_t scene);
// Their refusal, after "FILE: ": the first probe, the scene file and `why` (the first probe's error).
std::string invalid_probes_message(const DatasetSpec& spec, size_t scene, const std::vector<int64_t>& probes,
                                   const std::string& why);

// Which samples a shard runs: index i belongs to shard i mod count.
struct Shard {
  int64_t index = 0, count = 1;
  bool owns(int64_t sample) const { return sample % count == index; }
  int64_t owned(int64_t samples) const { return samples / count + (index < samples % count ? 1 : 0); }  // of 0..samples-1
  std::string text() const;  // "2/4"
};
// "I/N" (0 <= I < N); throws spadgen::Error naming `where` otherwise.
Shard parse_shard(const std::string& text, const std::string& where = "--shard");
// The shard the environment assigns, or nullopt: a Slurm job array (SLURM_ARRAY_TASK_ID minus
// SLURM_ARRAY_TASK_MIN, of SLURM_ARRAY_TASK_COUNT) or a Kubernetes Indexed Job (JOB_COMPLETION_INDEX,
// of JOB_COMPLETIONS, which the Job's manifest sets to its completions). Throws spadgen::Error on
// inconsistent values, naming the variables.
std::optional<Shard> shard_from_environment();

// "12-15, 20, 31-40": indices for messages.
std::string ranges_text(const std::vector<int64_t>& indices);

// The reference of the dataset file's keys and distributions, as Markdown (docs/datasets.md).
std::string dataset_reference_markdown();

// The same as a JSON Schema (draft 2020-12), for editors (docs/dataset-file.schema.json).
std::string dataset_schema_json();

}  // namespace spadgen::datasets
