// A dataset folder: what `spadgen dataset run` writes and `status` reads.
//
//   DIR/dataset.json         the resolved dataset file (every default explicit); decides whether DIR holds
//                            this dataset (only "samples" may differ: a dataset grows by adding samples)
//   DIR/samples/000042/      sample 42: a complete run folder (metadata.json's "dataset" section holds the
//                            sample's index, parameters and hash), published as one unit
//   DIR/samples/000042_r01/  its realisation 1 of the temporal noise (repeats > 1), a `spadgen sense` folder
//   DIR/failed/000042.json   why sample 42 failed (removed when it succeeds)
//   DIR/index.jsonl, index.csv, dataset.md   the index (one row per sample) and the dataset card
//
// A sample is done when its folders' metadata.json carry the hash of the sample as it resolves now (the
// resolved scene file, the content of the scene's files and the spadgen version): a changed scene, glTF or
// version makes it stale, and it is generated again.
#pragma once
#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "datasets/dataset.h"
#include "scenes/scene.h"
#include "scenes/scene_file.h"

namespace spadgen::datasets {

// Damaged: its folders carry the sample's hash, but a file their metadata.json lists is gone (removed, or a
// copy that left it out) or of another size than the run wrote (cut short); `dataset run` generates the
// sample again.
enum class Status { Done, Failed, Stale, Missing, Damaged };
const char* status_name(Status s);

// What a dataset folder may hold besides its samples' folders: its dataset.json, samples/, failed/, index,
// card, lock files, and evaluation/ (spadgen evaluate's).
const std::set<std::string>& own_entries();

// One row of the index.
struct SampleRecord {
  Sample sample;
  Status status = Status::Missing;
  std::string hash;     // of the sample as it resolves now; "" when it does not resolve
  // the sensor tables' hash that `hash` holds, when inspect resolved the sample ("" when the scene names none, or
  // the hash was given): its run is refused if its sensor reads other tables (RunOptions::tables_hash)
  std::string tables_hash;
  std::string error;    // failed: why; damaged: the files that are gone or changed; stale: what changed (status)
  std::vector<std::string> folders;  // done: the sample's folder and its repeats'
  // inspected: whether each of them (the sample's folder, then its repeats') holds the sample as it resolves now,
  // undamaged (a grown repeats' sample: its own folder, and the earlier realisations)
  std::vector<bool> held;
  // done: every file of its folders but metadata.json (whose size varies with its timing fields), relative to
  // the sample's folder (a repeat's as "_r01/counts.npy"), and its size; a file linked into a repeat counts once
  std::vector<std::pair<std::string, int64_t>> files;
  std::vector<std::string> listed;  // done: every file of the sample and its realisations (hard links too)
  int64_t bytes = 0;                 // done: their sum
  nlohmann::ordered_json summary;    // done: metadata.json's ground_truth_summary and laser totals
  std::vector<std::string> warnings;  // done: metadata.json's warnings (the sample's run's)
  // done: the wall time its run and its realisations' senses took, the sum of their metadata.json's
  // run.wall_seconds; 0 where none records it
  double seconds = 0.0;
  // done: the cores the sample's run could use (its metadata.json's run.cores); 0 where none records it
  int cores = 0;
};

// Warnings of many samples, grouped by kind (warning_kind: the text with its numbers left out): how many samples,
// the first few of them, the first one's text; the kinds most samples share first, at most kKindsShown.
struct WarningTally {
  struct Group {
    int64_t samples = 0;
    std::vector<int64_t> first;  // at most kListed
    std::string example;
  };
  static constexpr size_t kListed = 5, kKindsShown = 20;
  std::map<std::string, Group> groups;
  void add(int64_t sample, const std::vector<std::string>& warnings);
  // One line per kind: "2 samples (3, 7): <the first's text>", then "and N more kinds of warning<more>" past
  // kKindsShown.
  std::vector<std::string> lines(const std::string& more) const;
};
// A warning's kind: its text with each number standing alone as '#' (digits inside names stay).
std::string warning_kind(const std::string& warning);

// What the dataset card says of the samples, gathered one record at a time (in index order).
struct CardTally {
  std::array<int64_t, 5> count{};  // by Status
  int64_t samples = 0, bytes = 0;  // bytes: of the done samples
  struct Observed {
    double lo = std::numeric_limits<double>::infinity(), hi = -std::numeric_limits<double>::infinity();
    std::set<std::string> distinct;  // values that are not numbers
  };
  std::map<std::string, Observed> observed;                    // parameter key: its values over the done samples
  std::map<std::string, std::pair<int64_t, int64_t>> sizes;  // output file: (done samples holding it, bytes)
  WarningTally warnings;                                      // of the done samples
  void add(const SampleRecord& r);
};

// A dataset run's claim on one sample (an open-file-description lock on byte `index` of DIR/.dataset.lock,
// beside the folder lock's flock, which it does not touch): while one run holds it, no other run on the
// folder (another shard, or a second unsharded run) works on that sample. Released when destroyed.
class SampleClaim {
 public:
  explicit SampleClaim(int fd) : fd_(fd) {}
  ~SampleClaim();
  SampleClaim(const SampleClaim&) = delete;
  SampleClaim& operator=(const SampleClaim&) = delete;

 private:
  int fd_;
};

// A dataset run on the folder, for as long as it lives (a shared open-file-description lock on
// DIR/.dataset.runs): the index is written by the last run on the folder to end,
// so that a shard's end does not read and rewrite the whole index while other shards are still running
// (100,000 samples took about 29 s and 183 MB per shard under the folder's lock).
class RunPresence {
 public:
  explicit RunPresence(int fd) : fd_(fd) {}
  ~RunPresence();
  RunPresence(const RunPresence&) = delete;
  RunPresence& operator=(const RunPresence&) = delete;
  void release();  // this run is ending
  bool held() const { return fd_ >= 0; }

 private:
  int fd_;
};

// Whether a dataset run is on the folder DIR now (a process holds its presence, RunPresence). Creates nothing.
bool dataset_runs_on(const std::filesystem::path& dir);

class DatasetFolder {
 public:
  DatasetFolder(const DatasetSpec& spec, std::filesystem::path dir);

  const std::filesystem::path& dir() const { return dir_; }
  const DatasetSpec& spec() const { return spec_; }

  // Takes DIR for this dataset: creates it, refuses a folder that holds another dataset (naming the key
  // that differs) or files spadgen did not write, and writes dataset.json. Safe to call from every shard
  // at once (the same bytes are written atomically).
  void claim() const;
  // The same refusals without writing anything (dataset plan -o): nothing to refuse when DIR does not exist.
  void check() const;

  // The sample's scene file with its overrides, resolved and checked; throws spadgen::Error naming the
  // sample and its parameters when they make an invalid scene.
  struct Resolved {
    nlohmann::ordered_json scene;  // the resolved scene file
    std::string hash;
    std::string hash_before_revisions;  // the hash without sample_hash's revisions of the renderer's rules
    std::string revisions;              // those revisions in words ("" when none applies)
    // the sensor tables' hash (scenes::sensor_tables_hash) the hash holds; "" when the scene names none
    std::string tables_hash;
  };
  Resolved resolve(const Sample& s) const;
  // The hash of sample s whose scene resolved to r (as resolve computes it); tables: the sensor tables' hash
  // when already read (null: read here).
  std::string sample_hash(const Sample& s, const scenes::ResolvedRun& r, bool revisions = true,
                          const std::string* tables = nullptr) const;

  // The metadata.json of a sample folder ("samples/000042", a repeat's) when it is one spadgen published
  // (it lists its files and has a dataset section), else nullopt.
  std::optional<nlohmann::json> sample_metadata(const std::string& folder) const;
  // True when that folder holds the sample whose hash is `hash` (not a stale one), rendered from the contents of
  // scene file `scene` (of the dataset's) as they are.
  bool holds(const std::string& folder, const std::string& hash, int scene) const;

  // Sample s's claim, or null when another run holds it (no waiting).
  std::unique_ptr<SampleClaim> try_claim(const Sample& s) const;

  // The sample's state on disk (reads its metadata.json files and the failure record). hash: the sample's
  // hash when known (sample_hash of its resolved scene: resolving is most of an inspection), else it is
  // computed (its scene resolved). Safe to call from several threads at once.
  SampleRecord inspect(const Sample& s, const std::string* hash = nullptr) const;

  // Failure records (DIR/failed/000042.json), written atomically.
  void record_failure(const Sample& s, const std::string& hash, const std::string& error) const;
  void clear_failure(const Sample& s) const;

  // This run's presence on the folder (see RunPresence), taken as it begins.
  std::unique_ptr<RunPresence> enter() const;
  // Whether a dataset run is on the folder now (another process holds its presence): for `dataset status`,
  // whose missing samples and index are then the running ones' work in progress. Creates nothing.
  bool runs_on() const;

  // Rewrites index.jsonl, index.csv and dataset.md from the records of every sample that `inspect_each`
  // reads from the folder and hands, in index order, to its argument, under the folder's lock: the read and
  // the write are one step, so that the last shard to finish writes the complete index (a shard that read
  // the folder before another's last sample and wrote after it listed that sample missing). Returns the
  // records' tally. With `leaving` (the ending run's presence, released under the lock): nothing is read or
  // written, and nullopt returned, while another run is on the folder; that run, or the last of them, writes
  // the index as it ends.
  using RecordSink = std::function<void(const SampleRecord&)>;
  std::optional<CardTally> write_index(const std::function<void(const RecordSink&)>& inspect_each,
                                       RunPresence* leaving = nullptr) const;

 private:
  const std::string& scene_content_hash(int scene) const;
  // Why the folder's dataset.json `prev`, written from another dataset file of the same text, is another dataset:
  // that file is still there and a scene file of its differs from this run's in content (a copy of the dataset
  // file beside other scenes; concurrent shards of the two copies mixed their samples); "" when it is the same
  // dataset (the same file by another path, one moved away, the same scenes' contents).
  std::string other_scenes(const nlohmann::ordered_json& prev) const;
  // What of a sample's resolved scene r the render revisions depend on, from the materials its meshes use as
  // the sample's edits leave them (both true where the glTF does not load). The glTF's materials are loaded
  // once per glTF (and glTF scene).
  struct MaterialTraits {
    bool ggx = true;   // GGX lobes: a material is not Lambertian, or a mesh has the glTF's default material
    bool echo = true;  // laser echoes through plates: a material refracts (a volume of ior != 1), a transmissive one is smooth
    // a colour meets ambient light: a material, vertex paint or glTF light not grey, under an ambient
    // environment, glTF lights or emission
    bool coloured_ambient = true;
    // a smooth material (Dirac lobes) other than a Lambertian one: its planar faces may mirror the laser into the lens
    bool smooth_mirror = true;
    // glTF point or spot lights light the scene (ambient.gltf_lights): the camera sees one in view
    bool lamps = true;
    // a base colour texture through KHR_texture_transform
    bool texture_transform = true;
    // a refracting volume with a face the laser's connections cross as rough (roughness 0.158 and above)
    bool rough_refracting = true;
    // the laser's connections solved on a mesh's interpolated normals: a transmissive smooth-shaded mesh where a
    // material refracts (a glass sphere or bottle), or a curved mesh of a smooth material other than a Lambertian
    // one (a mirror sphere)
    bool shaded_connections = true;
  };
  MaterialTraits material_traits(const scenes::ResolvedRun& r) const;
  // The revisions of the renderer's rules that apply to r (a marker sample_hash holds, and the change in words),
  // from its settings and material_traits.
  struct Revision;
  std::vector<Revision> revisions_of(const scenes::ResolvedRun& r) const;
  // sample_hash with the revisions that apply (null: none) and the sensor tables' hash (null: read here).
  std::string hash_with(const Sample& s, const scenes::ResolvedRun& r, const std::vector<Revision>* revisions,
                        const std::string* tables) const;
  nlohmann::ordered_json record() const;  // what dataset.json holds for this dataset
  // check()'s refusals of the existing folder DIR against `wanted` (record()); its dataset.json as it is.
  std::optional<nlohmann::ordered_json> checked(const nlohmann::ordered_json& wanted) const;

  DatasetSpec spec_;
  std::filesystem::path dir_;
  mutable std::map<int, std::string> content_hashes_;  // under content_mutex_
  struct SceneMaterials {
    bool loaded = false;                      // else unknown (the glTF did not load): GGX taken to be rendered
    bool default_material = false;            // a mesh has none (the glTF's default: metallic 1)
    std::vector<scenes::Material> used;       // the materials the meshes use, unedited
    bool painted = false;                     // a mesh has vertex colours (COLOR_0)
    bool lights = false, coloured_lights = false;  // the glTF has punctual lights; one of them is not grey
    bool point_lights = false;                     // one of them is a point or spot light
    // the materials (unedited, each once) of smooth-shaded meshes (scenes::Mesh::smooth_shaded) and of curved
    // ones (scenes::Mesh::curved): the laser's connections through or off them are solved on their normals
    std::vector<scenes::Material> smooth_shaded, curved;
  };
  mutable std::map<std::pair<std::string, std::string>, SceneMaterials> scene_materials_;  // by glTF and glTF scene; under content_mutex_
  mutable std::mutex content_mutex_;
};

// The metadata.json "dataset" section of sample s.
nlohmann::json dataset_section(const DatasetFolder& folder, const Sample& s, const std::string& hash, int repeat);

// The index rows as JSON Lines and CSV, and the dataset card (Markdown): pure functions of the records,
// so that any set of shards writes the same bytes as one serial run. One record at a time: an index of
// millions of samples is written without holding their records.
std::string index_jsonl_row(const DatasetSpec& spec, const SampleRecord& r);
std::string index_csv_header(const DatasetSpec& spec);
// A CSV field (RFC 4180) of a JSON value as index.csv writes it: a string's text, any other value as JSON,
// quoted when it holds a comma, a quote or a line break; null as an empty field.
std::string csv_value(const nlohmann::ordered_json& v);
std::string index_csv_row(const DatasetSpec& spec, const SampleRecord& r);

std::string dataset_card(const DatasetFolder& folder, const CardTally& tally);

}  // namespace spadgen::datasets
