#include "datasets/folder.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <set>
#include <sstream>
#include <thread>

#include "core/current_folder.h"
#include "core/error.h"
#include "core/units.h"
#include "scenes/input.h"
#include "scenes/key_path.h"
#include "scenes/scene_file.h"
#include "writers/writers.h"

#ifndef SPADGEN_VERSION
#define SPADGEN_VERSION "dev"
#endif

namespace spadgen::datasets {
namespace fs = std::filesystem;
using json = nlohmann::json;
using ojson = nlohmann::ordered_json;

namespace {
// A file name as a shell word: as it is when it holds only letters, digits and ._/+-, else in single quotes
// (the card's command, pasted into a shell, ran "spadgen dataset run my dataset.json").
std::string shell_word(const std::string& name) {
  if (!name.empty() && name.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789._/+-") == std::string::npos)
    return name;
  std::string out = "'";
  for (const char ch : name) out += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
  return out + "'";
}

// What a dataset folder may hold besides the samples' folders (evaluation/: spadgen evaluate's).
const std::set<std::string> kOwnEntries = {"dataset.json", "samples", "failed", "index.jsonl", "index.csv", "dataset.md",
                                           ".dataset.lock", ".dataset.runs", "evaluation"};

// A JSON file as J (json, or ordered_json to keep its keys' order); nullopt when absent or not JSON.
template <class J = json>
std::optional<J> read_json(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) return std::nullopt;
  std::ostringstream ss;
  ss << in.rdbuf();
  try {
    return J::parse(ss.str());
  } catch (const json::exception&) {
    return std::nullopt;  // a file spadgen wrote whole is never cut short; anything else is not a sample
  }
}

std::string failure_path(const Sample& s) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "failed/%06lld.json", static_cast<long long>(s.index));
  return buf;
}

// A CSV field (RFC 4180): quoted when it holds a comma, a quote or a line break.
std::string csv_field(const std::string& v) {
  if (v.find_first_of(",\"\n\r") == std::string::npos) return v;
  std::string q = "\"";
  for (char c : v) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

// The runs' presence (RunPresence): a file of its own, not .dataset.lock, whose flock (FolderLock) NFS emulates
// as a whole-file fcntl lock, which a presence lock on the same file would block for ever.
constexpr const char* kPresenceFile = ".dataset.runs";

// Holds DIR/.dataset.lock for the scope. Another process holds it while it writes the index (about 0.2 ms a
// sample: minutes for millions): a wait of over 2 s is said on stderr, again each minute (a run starting
// meanwhile sat silent), and with `interruptible` a signal ends it (spadgen::Interrupted).
class FolderLock {
 public:
  explicit FolderLock(const fs::path& dir, bool interruptible = true) {
    const std::string p = (dir / ".dataset.lock").string();
    fd_ = ::open(p.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (fd_ < 0) throw Error("cannot open the dataset folder's lock " + p + ": " + std::strerror(errno));
    const auto start = std::chrono::steady_clock::now();
    double said = 0.0;  // the wait last said, s
    while (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      if (errno != EWOULDBLOCK && errno != EINTR) {
        const int err = errno;
        ::close(fd_);
        throw Error("cannot lock " + p + ": " + std::strerror(err));
      }
      if (interruptible && interrupt_flag().load()) {
        ::close(fd_);
        throw Interrupted("interrupted by a signal while waiting for " + p + "; nothing was written");
      }
      const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (waited >= 2.0 && (said == 0.0 || waited - said >= 60.0)) {
        std::fprintf(stderr, "spadgen: dataset: waiting %.0f s for %s, which another spadgen process holds (a run on the "
                             "folder writing its index, about 0.2 ms a sample)\n", waited, p.c_str());
        said = waited;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
  ~FolderLock() { ::close(fd_); }
  FolderLock(const FolderLock&) = delete;
  FolderLock& operator=(const FolderLock&) = delete;

 private:
  int fd_ = -1;
};

}  // namespace

const std::set<std::string>& own_entries() { return kOwnEntries; }

const char* status_name(Status s) {
  switch (s) {
    case Status::Done: return "done";
    case Status::Failed: return "failed";
    case Status::Stale: return "stale";
    case Status::Missing: return "missing";
    case Status::Damaged: return "damaged";
  }
  return "?";
}

DatasetFolder::DatasetFolder(const DatasetSpec& spec, fs::path dir) : spec_(spec), dir_(std::move(dir)) {}

SampleClaim::~SampleClaim() { ::close(fd_); }  // closing the description releases its locks

namespace {
// An open-file-description lock of `type` on byte `at` of DIR/`file`, on a description of its own: its fd
// (closing it releases the lock), or -1 when another run's lock conflicts and `wait` is false.
int lock_byte(const fs::path& dir, const char* file, short type, off_t at, const std::string& what, bool wait) {
  const std::string p = (dir / file).string();
  const int fd = ::open(p.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
  if (fd < 0) throw Error("cannot open the dataset folder's lock " + p + ": " + std::strerror(errno));
  struct flock l {};
  l.l_type = type;
  l.l_whence = SEEK_SET;
  l.l_start = at;
  l.l_len = 1;
  while (::fcntl(fd, wait ? F_OFD_SETLKW : F_OFD_SETLK, &l) != 0) {
    const int err = errno;
    if (err == EINTR) continue;
    ::close(fd);
    if (!wait && (err == EAGAIN || err == EACCES)) return -1;
    throw Error("cannot lock " + what + " in " + p + ": " + std::strerror(err));
  }
  return fd;
}
}  // namespace

RunPresence::~RunPresence() { release(); }
void RunPresence::release() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

std::unique_ptr<RunPresence> DatasetFolder::enter() const {
  // Shared; a run ending takes it exclusively for a moment, to test for others.
  return std::make_unique<RunPresence>(lock_byte(dir_, kPresenceFile, F_RDLCK, 0, "this run's presence", true));
}

bool DatasetFolder::runs_on() const { return dataset_runs_on(dir_); }

bool dataset_runs_on(const fs::path& dir) {
  const int fd = ::open((dir / kPresenceFile).c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;  // no run ever entered
  struct flock l {};
  l.l_type = F_WRLCK;  // would an exclusive lock conflict: a run holds its shared one
  l.l_whence = SEEK_SET;
  l.l_start = 0;
  l.l_len = 1;
  const bool held = ::fcntl(fd, F_OFD_GETLK, &l) == 0 && l.l_type != F_UNLCK;
  ::close(fd);
  return held;
}

std::unique_ptr<SampleClaim> DatasetFolder::try_claim(const Sample& s) const {
  const int fd = lock_byte(dir_, ".dataset.lock", F_WRLCK, static_cast<off_t>(s.index), "sample " + std::to_string(s.index), false);
  return fd < 0 ? nullptr : std::make_unique<SampleClaim>(fd);
}

void DatasetFolder::claim() const {
  std::error_code ec;
  // (a relative folder in a current folder that was removed: "No such file or directory" said nothing of it)
  if (const std::string problem = relative_path_problem(dir_); !problem.empty())
    throw Error("cannot create the dataset folder " + dir_.string() + ": " + problem);
  fs::create_directories(dir_, ec);
  if (ec)
    throw Error("cannot create the dataset folder " + dir_.string() + ": " +
                (ec == std::errc::not_a_directory || (ec == std::errc::file_exists && !fs::is_directory(dir_))
                     ? std::string("a file of that name (or of a folder above it) exists; expected a folder or a new name (-o)")
                     : ec.message()));
  const ojson wanted = record();
  // A folder refused (a run's, a user's) is left as it was: the lock file this run made there goes (it made the
  // next run into the folder refuse it as a file spadgen did not write there: a verifier's find).
  const bool had_lock = fs::exists(dir_ / ".dataset.lock", ec);
  try {
    // Checked and written as one step: two datasets started at once on a new folder both found it empty
    // and both wrote dataset.json, mixing their samples.
    const FolderLock lock(dir_);
    // what a run killed while it wrote them left (the index's files are written by the last run to end)
    writers::remove_dead_temporaries(dir_.string(), {"dataset.json", "index.jsonl", "index.csv", "dataset.md"});
    if (checked(wanted) != wanted) writers::write_file_atomic((dir_ / "dataset.json").string(), wanted.dump(2) + "\n");
  } catch (const Error&) {
    if (!had_lock && !fs::exists(dir_ / "dataset.json", ec)) fs::remove(dir_ / ".dataset.lock", ec);
    throw;
  }
  fs::create_directories(dir_ / "samples", ec);
  if (ec) throw Error("cannot create " + (dir_ / "samples").string() + ": " + ec.message());
}

// dataset.json: where the dataset file is (for `dataset status`) and its resolved form.
ojson DatasetFolder::record() const {
  ojson record = {{"dataset_file", spec_.file}};
  for (auto it = spec_.resolved.begin(); it != spec_.resolved.end(); ++it) record[it.key()] = it.value();
  return record;
}

void DatasetFolder::check() const {
  std::error_code ec;
  if (fs::exists(dir_, ec)) (void)checked(record());
}

namespace {
// Where a sample's resolved scene as its metadata.json recorded it (`was`) first differs from the scene as it
// resolves now: the dotted key and both values ("sensor.gate.knots_per_edge (64 in the sample, 256 now)"),
// "" when they are equal.
std::string resolved_difference(const json& was, const json& now, const std::string& path) {
  const auto text = [](const json& v) {
    const std::string t = v.dump();
    return t.size() <= 40 ? t : t.substr(0, 37) + "...";
  };
  if (was == now) return "";
  if (was.is_object() && now.is_object()) {
    for (auto it = now.begin(); it != now.end(); ++it) {
      const std::string here = path + (path.empty() ? "" : ".") + it.key();
      if (!was.contains(it.key())) return here + " (not in the sample's, " + text(it.value()) + " now)";
      if (const std::string d = resolved_difference(was[it.key()], it.value(), here); !d.empty()) return d;
    }
    for (auto it = was.begin(); it != was.end(); ++it)
      if (!now.contains(it.key())) return path + (path.empty() ? "" : ".") + it.key() + " (" + text(it.value()) + " in the sample's, gone now)";
    return "";
  }
  return (path.empty() ? std::string("the top level") : path) + " (" + text(was) + " in the sample, " + text(now) + " now)";
}

// Where the dataset file's resolved form `file` first differs from the folder's dataset.json `folder`: the
// keys down to the value that differs ("set"."render.samples_per_pixel"), with both values (it named the
// top-level key alone: "set").
std::string first_difference(const ojson& folder, const ojson& file, const std::string& path) {
  const auto text = [](const ojson& v) {
    const std::string t = v.dump();
    return t.size() <= 60 ? t : t.substr(0, 57) + "...";
  };
  if (folder.is_object() && file.is_object()) {
    for (auto it = file.begin(); it != file.end(); ++it) {
      const std::string here = path + (path.empty() ? "" : ".") + "\"" + it.key() + "\"";
      if (!folder.contains(it.key())) return here + " (the dataset file has it, the folder's dataset.json has not)";
      if (folder[it.key()] != it.value()) return first_difference(folder[it.key()], it.value(), here);
    }
    for (auto it = folder.begin(); it != folder.end(); ++it)
      if (!file.contains(it.key()))
        return path + (path.empty() ? "" : ".") + "\"" + it.key() + "\" (the folder's dataset.json has it, the dataset file has not)";
    return (path.empty() ? std::string("the top level") : path) +
           " (the order of its keys" + (path == "\"grid\"" ? ", which decides the grid cell each sample takes)" : ")");
  }
  return path + " (the folder's dataset.json: " + text(folder) + ", the dataset file: " + text(file) + ")";
}
}  // namespace

std::optional<ojson> DatasetFolder::checked(const ojson& wanted) const {
  std::error_code ec;
  if (!fs::is_directory(dir_)) throw Error(dir_.string() + " is not a folder; expected the dataset folder (-o)");
  // Compared in order: the order of the grid's keys decides which cell a sample takes.
  const std::optional<ojson> prev = read_json<ojson>(dir_ / "dataset.json");
  if (prev && !prev->is_object())  // JSON, not a dataset's (it was an internal error: erase() of a string)
    throw Error((dir_ / "dataset.json").string() + " is damaged (JSON, but not an object): it says which dataset file " +
                dir_.string() + " holds; restore it, or remove " + dir_.string() + " or use another folder (-o)");
  if (prev) {
    ojson a = *prev, b = wanted;
    // repeats may grow: realisations added to the samples (each sensed from its sample's saved light, the others
    // kept); not shrink, which would leave the last realisations' folders behind. Checked after the rest, so that
    // another dataset is told as such (it was told only that repeats may not shrink).
    const auto repeats = [](const ojson& d) {
      const auto r = d.find("repeats");
      return r != d.end() && r->is_number_integer() ? r->get<int64_t>() : int64_t(1);
    };
    const int64_t held = repeats(a), asked = repeats(b);
    for (const char* free_key : {"samples", "dataset_file", "repeats"}) a.erase(free_key), b.erase(free_key);
    // set's and random's keys in any order make the same samples (only the grid's order decides the cells)
    for (const char* unordered : {"set", "random"})
      if (a.contains(unordered) && b.contains(unordered) && json(a[unordered]) == json(b[unordered])) b[unordered] = a[unordered];
    if (a != b)
      throw Error(dir_.string() + " holds another dataset: its dataset.json differs from " + spec_.file + " at " +
                  first_difference(a, b, "") + " (only \"samples\" and \"repeats\" may grow, to add samples and realisations); use "
                  "another folder (-o) or remove " +
                  dir_.string());
    if (const std::string other = other_scenes(*prev); !other.empty())
      throw Error(dir_.string() + " holds another dataset: " + other + "; the two datasets' samples would mix in one folder: use "
                  "another folder (-o), or, where " + spec_.file + " replaces it, remove the other dataset file");
    if (asked < held)
      throw Error(dir_.string() + " holds " + std::to_string(held) + " realisations of each sample's noise (repeats), and " +
                  spec_.file + " asks for " + std::to_string(asked) +
                  ": repeats may grow, to add realisations, not shrink; use another folder (-o), or remove " + dir_.string());
  } else {
    // dataset.json decides whose the folder is: without it (damaged, or lost), samples and an index there
    // may be another dataset's, which this one would replace.
    if (fs::exists(dir_ / "dataset.json", ec))
      throw Error((dir_ / "dataset.json").string() + " is damaged (not JSON): it says which dataset file " + dir_.string() +
                  " holds; restore it, or remove " + dir_.string() + " or use another folder (-o)");
    for (const char* own : {"samples", "index.jsonl", "index.csv", "dataset.md", "failed"})
      if (fs::exists(dir_ / own, ec) && !(fs::is_directory(dir_ / own, ec) && fs::is_empty(dir_ / own, ec)))
        throw Error(dir_.string() + " holds a dataset's " + own + " but no dataset.json, which says which dataset file "
                    "they are of (another dataset's would be replaced); restore its dataset.json, or remove " +
                    dir_.string() + " or use another folder (-o)");
    if (fs::exists(dir_ / "metadata.json", ec))
      throw Error(dir_.string() + " is a run folder (it holds metadata.json), not a dataset folder; expected an empty "
                  "folder or a dataset folder (with its dataset.json): use another folder (-o)");
    for (const auto& e : fs::directory_iterator(dir_)) {
      const std::string name = e.path().filename().string();
      if (kOwnEntries.count(name) || name.rfind(".dataset.json.tmp", 0) == 0) continue;
      throw Error(dir_.string() + " holds " + name + ", which spadgen did not write there; expected an empty folder or a "
                  "dataset folder (with its dataset.json): use another folder (-o)");
    }
  }
  // The dataset's own folders are its own: a symbolic link there (samples/, failed/, a sample's folder) led
  // the samples into another dataset's folders, which they replaced (exit 0), or made two samples one folder.
  for (const char* own : {"samples", "failed"})
    if (fs::is_symlink(dir_ / own, ec))
      throw Error((dir_ / own).string() + " is a symbolic link; a dataset's " + own + " is a folder of its own (the samples "
                  "would be written into the link's target): replace the link with the folder it should be");
  if (fs::is_directory(dir_ / "samples", ec))
    for (const auto& e : fs::directory_iterator(dir_ / "samples", ec))
      if (e.is_symlink(ec))
        throw Error(e.path().string() + " is a symbolic link; a dataset's samples are folders of their own (the sample "
                    "would be written into the link's target): replace the link with the folder, or remove it");
  return prev;
}

std::string DatasetFolder::other_scenes(const ojson& prev) const {
  const auto f = prev.find("dataset_file");
  if (f == prev.end() || !f->is_string() || f->get<std::string>() == spec_.file) return "";
  const std::string other = f->get<std::string>();
  std::error_code ec;
  // moved or renamed (the folder's record names a file no longer there), or the same file by another path
  if (!fs::exists(other, ec) || fs::equivalent(other, spec_.file, ec)) return "";
  ojson body = prev;
  body.erase("dataset_file");
  const std::string whose = "its dataset.json was written by " + other + ", which is still there";
  DatasetSpec was;
  try {
    was = parse_dataset_text(body.dump(), other);  // its scene files, relative to it
  } catch (const Error& e) {
    return whose + ", and its scene files are not this run's (" + e.what() + ")";
  }
  for (size_t i = 0; i < spec_.scenes.size() && i < was.scenes.size(); ++i) {
    if (fs::equivalent(was.scenes[i], spec_.scenes[i], ec)) continue;
    if (!fs::exists(was.scenes[i], ec)) return whose + ", and its scene file " + was.scenes[i] + " is missing";
    std::string hash;
    try {
      const scenes::ResolvedRun base = scenes::load_scene_file(was.scenes[i]);
      hash = scenes::content_hash(base.config.scene_file, base.config.gltf_path);
    } catch (const Error& e) {
      return whose + ", and its scene file " + was.scenes[i] + " does not load (" + e.what() + ")";
    }
    if (hash != scene_content_hash(int(i)))
      return whose + ": its scene file " + was.scenes[i] + " differs from this run's " + spec_.scenes[i] +
             " (the same dataset text beside other scenes: their contents, glTF or buffers differ)";
  }
  return "";
}

const std::string& DatasetFolder::scene_content_hash(int scene) const {
  const std::lock_guard<std::mutex> lock(content_mutex_);  // map nodes stay where they are: the reference outlives it
  auto it = content_hashes_.find(scene);
  if (it == content_hashes_.end()) {
    const scenes::ResolvedRun base = scenes::load_scene_file(spec_.scenes[size_t(scene)]);
    it = content_hashes_.emplace(scene, scenes::content_hash(base.config.scene_file, base.config.gltf_path)).first;
  }
  return it->second;
}

namespace {
// A colour the renderer keeps grey (its channels equal): the same light at every wavelength.
bool grey(const glm::vec3& v) { return v.r == v.g && v.g == v.b; }
}  // namespace

DatasetFolder::MaterialTraits DatasetFolder::material_traits(const scenes::ResolvedRun& r) const {
  const std::lock_guard<std::mutex> lock(content_mutex_);
  const std::pair<std::string, std::string> key{r.config.gltf_path, r.config.gltf_scene};
  auto it = scene_materials_.find(key);
  if (it == scene_materials_.end()) {
    SceneMaterials m;
    try {
      const scenes::Scene scene = scenes::load_gltf(r.config.gltf_path, r.config.gltf_scene);
      for (const scenes::Mesh& mesh : scene.meshes)
        if (mesh.material < 0 || size_t(mesh.material) >= scene.materials.size()) m.default_material = true;
      for (size_t i = 0; i < scene.materials.size(); ++i)
        if (scene.material_used(i)) m.used.push_back(scene.materials[i]);
      for (const scenes::Mesh& mesh : scene.meshes) m.painted |= !mesh.colors0.empty();
      std::vector<bool> shaded(scene.materials.size()), curved(scene.materials.size());
      for (const scenes::Mesh& mesh : scene.meshes) {
        if (mesh.material < 0 || size_t(mesh.material) >= scene.materials.size()) continue;
        const auto i = size_t(mesh.material);
        if (!shaded[i] && mesh.smooth_shaded()) shaded[i] = true, m.smooth_shaded.push_back(scene.materials[i]);
        if (!curved[i] && mesh.curved()) curved[i] = true, m.curved.push_back(scene.materials[i]);
      }
      for (const scenes::Light& l : scene.lights)
        m.lights = true, m.coloured_lights |= !grey(l.color), m.point_lights |= l.type != scenes::Light::Type::Directional;
      m.loaded = true;
    } catch (const Error&) {
      // (the sample's run says what is wrong with its glTF)
    }
    it = scene_materials_.emplace(key, std::move(m)).first;
  }
  const SceneMaterials& m = it->second;
  MaterialTraits t;
  if (!m.loaded) return t;
  t.ggx = m.default_material;
  bool refracting = false, smooth_clear = false, colour = m.painted || m.coloured_lights, emission = false;
  t.smooth_mirror = false;
  t.texture_transform = false;
  t.rough_refracting = false;
  // a material as the loader applies the scene's edits to it (an ior or thickness makes a volume refract)
  const auto edited = [&](scenes::Material mat) {
    for (const MaterialEdit& e : r.config.edits.materials)
      if (e.name == mat.name) mat.apply(e);
    return mat;
  };
  for (const scenes::Material& used : m.used) {
    const scenes::Material mat = edited(used);
    // a smooth surface reflects and refracts by Dirac lobes only
    t.ggx |= !mat.lambertian() && !mat.smooth();
    refracting |= mat.refracting();
    smooth_clear |= mat.transmissive() && mat.smooth();
    t.smooth_mirror |= !mat.lambertian() && mat.smooth();
    colour |= !grey(glm::vec3(mat.base_color)) || mat.base_color_texture >= 0 || !grey(mat.attenuation_color) || !grey(mat.emissive);
    emission |= mat.emissive != glm::vec3(0.0f);
    t.texture_transform |= mat.base_color_texture >= 0 && mat.base_color_transformed;
    t.rough_refracting |= mat.refracting() && mat.crossed_as_rough();
  }
  t.echo = refracting && smooth_clear;
  t.shaded_connections = false;
  for (const scenes::Material& mat : m.smooth_shaded) t.shaded_connections |= refracting && edited(mat).transmissive();
  for (const scenes::Material& used : m.curved) {
    const scenes::Material mat = edited(used);
    t.shaded_connections |= !mat.lambertian() && mat.smooth();
  }
  const AmbientConfig& a = r.config.ambient;
  t.coloured_ambient = colour && (a.illuminance_lux > 0.0 || a.spectral_irradiance_W_m2_nm || (a.gltf_lights && m.lights) || emission);
  t.lamps = a.gltf_lights && m.point_lights;
  return t;
}

// Revisions of what a resolved scene renders to, within one version: sample_hash holds the marker of each
// that applies, so that its samples rendered before are stale, not mixed with the new rule; `change` says why
// in dataset status.
struct DatasetFolder::Revision {
  const char* marker;
  const char* change;
};

std::vector<DatasetFolder::Revision> DatasetFolder::revisions_of(const scenes::ResolvedRun& r) const {
  const RunConfig& c = r.config;
  const MaterialTraits m = material_traits(r);
  std::vector<Revision> out;
  // glTF point and spot lights in view, points no camera ray meets, rendered in their pixels (they were missing)
  if (m.lamps)
    out.push_back({"the camera sees glTF point and spot lights in view",
                   "glTF point and spot lights render otherwise: a lamp in view is rendered in the pixel it lands in (it was missing)"});
  // and their images in smooth planar faces, points too (a lamp in a mirror, a plate's echoes of it)
  if (m.lamps && m.smooth_mirror)
    out.push_back({"the camera sees glTF point and spot lights' images in smooth planar faces",
                   "glTF point and spot lights beside smooth (roughness below 0.032) mirrors and plates render otherwise: a "
                   "lamp's image in their faces is rendered in the pixel it lands in (it was missing)"});
  // the camera's view of the laser's image in smooth planar faces (laser -> face -> lens), a glint that was not
  // rendered: a scene with a smooth material (its faces may be the laser's mirrors) whose laser is traced
  if (m.smooth_mirror && laser_traced(c))
    out.push_back({"the camera sees the laser's image in smooth planar faces",
                   "smooth (roughness below 0.032) mirrors and plates render otherwise: the laser's image in their faces, a "
                   "glint where it lands in view, is rendered as the camera sees it (it was missing)"});
  // the ambient band's colours weighted by its photons (lambda), not averaged plainly over wavelength: a colour's
  // ambient light moved by up to about 15 % (grey ones kept their bits)
  if (m.coloured_ambient)
    out.push_back({"the ambient band's colours weighted by its photons",
                   "coloured surfaces and lights render the ambient light otherwise: the band's colours are averaged over "
                   "its photons (an equal-energy spectrum's, by lambda), not plainly over wavelength (up to about 15 %)"});
  // the laser's connections through clear plates carry the echo inside each (the camera side's half of a plate's
  // delayed echo was all a transient held)
  if (m.echo && laser_traced(c))  // (a run that traces no laser draws no echo: the same bits)
    out.push_back({"laser connections through clear plates carry their echo",
                   "clear (smooth) refracting plates render otherwise: the laser's light reflected inside a plate on its way "
                   "in (half of the plate's delayed echo) was left out"});
  // and its higher orders (round trips between the same two faces while their share of the light is at least
  // 1e-6): the laser side's part of a plate's second echo was left out (0.69-0.71 of it rendered), 0.4 % of a
  // plate's light at ior 3
  if (m.echo && laser_traced(c))
    out.push_back({"laser connections through clear plates carry their echoes' higher orders",
                   "clear (smooth) refracting plates render otherwise: the laser's light reflected round inside a plate twice "
                   "or more on its way in (part of the plate's later echoes) was left out"});
  // the Fresnel factors of the laser's connections solved on a mesh's interpolated normals (through glass
  // meshes, off curved mirrors), at the solved path's normals: they were taken where the traced segments met the
  // mesh, some 1e-5 m away (the trace's origin offsets), 2.9e-4 of the light high through a glass sphere at 60
  // degrees' incidence (2e-3 at ior 1.3)
  if (m.shaded_connections && laser_traced(c))
    out.push_back({"laser connections solved on shaded meshes take Fresnel at the solved normals",
                   "glass meshes shaded by vertex normals and smooth curved mirrors render otherwise: the Fresnel factors of "
                   "the laser's connections through and off them are taken at the solved path's normals (they were taken some "
                   "1e-5 m away: 3e-4 of the light through glass at 60 degrees' incidence)"});
  // GGX's D evaluated without cancellation, and its draws' sines too: a narrow lobe's peak was up to 7 % bright
  // (1.4 % at roughness 0.05), and every GGX draw moved
  if (m.ggx)
    out.push_back({"GGX lobes without float cancellation",
                   "glossy and metallic materials (GGX) render otherwise: a narrow lobe's peak was up to 7 % bright"});
  // the laser's connections through rough flat refracting faces: crossed by drawn microfacet normals, also
  // beside the plate's shadow, a plate frosted on one side, two panes of one node as two plates (they were
  // crossed as smooth)
  if (m.rough_refracting && laser_traced(c))
    out.push_back({"laser connections through rough refracting faces",
                   "rough refracting plates (roughness above 0.158) render otherwise: the laser's connections cross their "
                   "rough faces by drawn microfacet normals, also beside their shadow (they were crossed as smooth)"});
  // a sweep's positions: its last counts where it lies on the step grid within the rounding of start, stop and
  // step (an absolute 1e-9 of a step left some out)
  if (c.acquisition.mode == AcquisitionMode::GateSweep) {
    const GateSweepConfig& g = c.acquisition.gate_sweep;
    if (g.positions() != std::floor((g.stop_s - g.start_s) / g.step_s + 1e-9) + 1.0)
      out.push_back({"the sweep's last position on the grid counts",
                     "this gate sweep has another number of positions: its last, on the step grid within the rounding of "
                     "start, stop and step, counts (it was left out)"});
  }
  // a measured gate table's own rise and fall times in metadata.json (the ignored sensor.gate.rise_ps and
  // fall_ps were written, and set the edges detector's separation), its fit errors of the open gate's peak
  if (!c.sensor.gate.profile_csv.empty())
    out.push_back({"a gate table's own rise and fall times",
                   "a measured gate table (sensor.gate.profile_csv) is described otherwise: metadata.json's gate rise_ps "
                   "and fall_ps are the table's own 10-90 % times (they were sensor.gate.rise_ps and fall_ps, unused)"});
  // a base colour texture's KHR_texture_transform maps the coordinates it reads (offset, rotation, scale,
  // texCoord): it was left out, with a warning, the texture read untransformed
  if (m.texture_transform)
    out.push_back({"base colour textures through KHR_texture_transform",
                   "base colour textures with KHR_texture_transform render otherwise: the transform (offset, rotation, scale, "
                   "texCoord) maps the coordinates they read (it was left out, with a warning)"});
  // an intensity run's saved light (outputs.light: a dataset's repeats) without laser_on, outputs.transient or a time window: the
  // laser was traced for it, which the counts do not see; the light holds none now, and the run writes no laser
  // images (the counts are the same bits unless a target error held the laser too: below; the laser-side echoes'
  // draws are hashes, not the path's stream)
  if (c.acquisition.mode == AcquisitionMode::Intensity && !c.acquisition.intensity.laser_on && c.outputs.light && !c.outputs.transient &&
      !c.render.window_start_s)
    out.push_back({"an intensity run's saved light holds no laser",
                   "an intensity run's saved light (outputs.light, the dataset's repeats) no longer traces the laser, which its "
                   "counts do not see: no laser.exr, no laser channels in ground_truth.exr"});
  // the sensor's dark counts: sensor.pixel_*.dcr_median_cps is the chip's median, hot pixels included (it was the
  // main population's, and the chip's median 1.07 times it): every pixel's dark count rate moved (0.936 times it
  // at the defaults). Where a pixel type the chip uses has hot pixels (without them the two medians are one; with
  // them but no spread in log DCR too, below half of the pixels hot, which this does not tell apart)
  const auto hot = [&](const PixelTypeConfig& t) { return t.dcr_median_cps > 0.0 && t.hot_pixel_fraction > 0.0; };
  const PixelPreset preset = c.sensor.preset;
  if (c.sensor.dark_counts && ((preset != PixelPreset::PixelB && hot(c.sensor.pixel_A)) || (preset != PixelPreset::PixelA && hot(c.sensor.pixel_B))))
    out.push_back({"dcr_median_cps is the chip's median",
                   "the sensor's dark counts are drawn otherwise: sensor.pixel_A/B.dcr_median_cps is the chip's median, hot "
                   "pixels included (it was the main population's, and the chip's median 1.07 times it)"});
  if (!c.render.target_relative_error) return out;
  // a gate sweep's background, where the counts see it (dark scenes' bits did not change, but are not told apart)
  if (c.acquisition.mode == AcquisitionMode::GateSweep)
    out.push_back({"the target holds the ambient light where the counts see it",
                   "a gate sweep to render.target_relative_error holds the ambient light too"});
  // an intensity run's laser return where it is kept (outputs.transient; outputs.light with a time window) without laser_on
  if (c.acquisition.mode == AcquisitionMode::Intensity && !c.acquisition.intensity.laser_on &&
      (c.outputs.transient || (c.outputs.light && c.render.window_start_s)))
    out.push_back({"the target holds a kept laser return",
                   "render.target_relative_error holds the laser return an intensity run keeps (outputs.transient, outputs.light with a time window)"});
  return out;
}

DatasetFolder::Resolved DatasetFolder::resolve(const Sample& s) const {
  scenes::ResolvedRun r;
  try {
    r = scenes::load_scene_file(spec_.scenes[size_t(s.scene)], s.overrides);
  } catch (const Error& e) {
    throw Error(sample_text(s) + " makes an invalid scene: " + named_in_dataset_file(spec_, e.what()));
  }
  const std::vector<Revision> applied = revisions_of(r);
  std::string revisions;
  for (const Revision& v : applied) {
    if (!revisions.empty()) revisions += "; ";
    revisions += v.change;
  }
  // (the tables read once for both hashes: read twice, an edit between the readings gave them other tables)
  const std::string tables = scenes::uses_sensor_tables(r.config) ? scenes::sensor_tables_hash(r.config) : std::string();
  return {r.resolved, hash_with(s, r, &applied, &tables), hash_with(s, r, nullptr, &tables), revisions, tables};
}

std::string DatasetFolder::sample_hash(const Sample& s, const scenes::ResolvedRun& r, bool revisions,
                                       const std::string* tables) const {
  if (!revisions) return hash_with(s, r, nullptr, tables);
  const std::vector<Revision> applied = revisions_of(r);
  return hash_with(s, r, &applied, tables);
}

std::string DatasetFolder::hash_with(const Sample& s, const scenes::ResolvedRun& r, const std::vector<Revision>* revisions,
                                     const std::string* tables) const {
  // The hash covers what shapes the sample's data: its resolved scene, the content of its files and the
  // program's version; the same function of the sample on every machine and shard.
  // The sensor's tables (CSV and EXR files the scene file names) by content, when it names any (a pulse
  // shape replaced under a done dataset left its samples done, mixing two pulses).
  std::string text = r.resolved.dump() + "\n" + scene_content_hash(s.scene) + "\n" + SPADGEN_VERSION;
  if (revisions)
    for (const Revision& v : *revisions) text += std::string("\n") + v.marker;
  if (scenes::uses_sensor_tables(r.config)) text += "\n" + (tables ? *tables : scenes::sensor_tables_hash(r.config));
  return scenes::hex64(scenes::fnv1a64(text));
}

std::optional<json> DatasetFolder::sample_metadata(const std::string& folder) const {
  std::optional<json> meta = read_json(dir_ / folder / "metadata.json");
  // What the dataset reads of it, of the types a run writes: a damaged one (a number among the files, a
  // dataset section that is no object) is a sample not written, generated again as an unreadable one is
  // (it stopped every dataset status and run: an internal error).
  const auto well_formed = [](const json& m) {
    if (!m.is_object() || !m.contains("dataset") || !m["dataset"].is_object() || !m.contains("files") || !m["files"].is_array())
      return false;
    if (const auto h = m["dataset"].find("sample_hash"); h != m["dataset"].end() && !h->is_string()) return false;
    for (const char* text : {"spadgen_version", "scene_hash_fnv1a64"})  // (read to say why a sample is stale)
      if (const auto t = m.find(text); t != m.end() && !t->is_string()) return false;
    for (const json& f : m["files"])
      if (!f.is_string()) return false;
    if (m.contains("ground_truth_summary") && !m["ground_truth_summary"].is_object()) return false;
    // (a size of another type was skipped: a counts.npy cut short passed as done)
    if (const auto b = m.find("file_bytes"); b != m.end()) {
      if (!b->is_object()) return false;
      for (const json& size : *b)
        if (!size.is_number_unsigned()) return false;
    }
    if (const auto l = m.find("laser_photons_per_pulse"); l != m.end() && !l->is_null()) {  // null: no laser traced
      if (!l->is_object()) return false;
      if (const auto t = l->find("total_all_pixels"); t != l->end() && !t->is_number()) return false;
    }
    return true;
  };
  if (meta && !well_formed(*meta)) meta.reset();
  return meta;
}

namespace {
// metadata.json's file_bytes (a run before it recorded them: none).
const json& recorded_sizes(const json& meta) {
  static const json none = json::object();
  return meta.contains("file_bytes") && meta["file_bytes"].is_object() ? meta["file_bytes"] : none;
}

// Listed file f as found, with `have` bytes (-1: absent), against what the run wrote: "" when it is as
// written, else f and how it differs (gone, or, where the run recorded its size, cut short or changed).
std::string damage_of(const std::string& f, int64_t have, const json& sizes) {
  if (have < 0) return f;
  if (const auto it = sizes.find(f); it != sizes.end() && it->is_number_integer() && it->get<int64_t>() != have)
    return f + " (" + std::to_string(have) + " of its " + std::to_string(it->get<int64_t>()) + " bytes)";
  return "";
}

// damage_of for listed file f at `path` with `have` bytes, where also a folder stands for a file the run wrote
// (a Zarr store is a folder; a name damaged to "" lists the sample's folder itself). The one rule of what
// `dataset status` calls damaged and of what `dataset run` generates again (status said a sample listing ""
// was damaged and run would generate it again, and run kept it as done).
std::string listed_damage(const fs::path& path, const std::string& f, int64_t have, const json& sizes) {
  std::error_code ec;
  // (a folder where the run wrote a file: it was "0 of its 89984 bytes")
  if (fs::is_directory(path, ec) && !f.ends_with(".zarr")) return f + " (a folder, where the run wrote a file)";
  return damage_of(f, have, sizes);
}

// The files a published folder's metadata.json lists that are not as the run wrote them.
std::vector<std::string> gone_files(const fs::path& folder, const json& meta) {
  std::vector<std::string> gone;
  for (const json& name : meta["files"]) {
    if (!name.is_string() || name == "metadata.json") continue;
    const std::string f = name.get<std::string>();
    const fs::path path = folder / f;
    if (std::string d = listed_damage(path, f, writers::bytes_on_disk(path.string()), recorded_sizes(meta)); !d.empty())
      gone.push_back(std::move(d));
  }
  return gone;
}
}  // namespace

bool DatasetFolder::holds(const std::string& folder, const std::string& hash, int scene) const {
  const std::optional<json> meta = sample_metadata(folder);
  return meta && (*meta)["dataset"].value("sample_hash", "") == hash && meta->value("scene_hash_fnv1a64", "") == scene_content_hash(scene) &&
         gone_files(dir_ / folder, *meta).empty();
}

SampleRecord DatasetFolder::inspect(const Sample& s, const std::string* hash) const {
  SampleRecord rec;
  rec.sample = s;
  try {
    if (hash != nullptr && !hash->empty()) {
      rec.hash = *hash;
    } else {
      Resolved now = resolve(s);
      rec.hash = std::move(now.hash), rec.tables_hash = std::move(now.tables_hash);
    }
  } catch (const Error& e) {
    rec.status = Status::Failed;
    rec.error = e.what();
    return rec;
  }
  bool done = true, stale = false;
  std::vector<std::string> gone;  // listed files that are not there, relative to the sample's folder
  std::set<std::pair<dev_t, ino_t>> inodes;
  std::vector<std::string> folders = {s.folder()};
  for (int r = 1; r < spec_.repeats; ++r) folders.push_back(s.repeat_folder(r));
  rec.held.assign(folders.size(), false);
  for (size_t f = 0; f < folders.size(); ++f) {
    const std::optional<json> meta = sample_metadata(folders[f]);
    if (!meta) {
      done = false;
      continue;
    }
    if ((*meta)["dataset"].value("sample_hash", "") != rec.hash) {
      // what changed since it was generated, as far as its metadata.json tells
      if (!stale) {
        const std::string version = meta->value("spadgen_version", "");
        const json& ds = (*meta)["dataset"];
        const auto other = [&](const char* key, int64_t own) {  // its dataset section names another sample or realisation
          return ds.contains(key) && ds[key].is_number_integer() && ds[key].get<int64_t>() != own;
        };
        if (other("index", s.index) || other("repeat", int64_t(f))) {
          // (read with value(): a const json's [] on a missing key is undefined)
          const json index = ds.value("index", json(s.index)), repeat = ds.value("repeat", json(0));
          rec.error = folders[f] + " holds the run of sample " + index.dump() +
                      (repeat.is_number_integer() && repeat.get<int64_t>() > 0 ? " (realisation " + repeat.dump() + ")" : std::string()) +
                      ", as its metadata.json's dataset section says: a copy or a link of another sample's folder";
        }
        else if (version != SPADGEN_VERSION)
          rec.error = "generated by spadgen " + (version.empty() ? std::string("?") : version) + ", this is " SPADGEN_VERSION;
        else if (meta->value("scene_hash_fnv1a64", "") != scene_content_hash(s.scene))
          rec.error = "the scene file, its glTF or a file the glTF reads changed since it was generated";
        else if (const Resolved now = resolve(s); (*meta)["dataset"].value("sample_hash", "") == now.hash_before_revisions)
          rec.error = "spadgen renders this scene otherwise now (" + now.revisions + ")";
        else if (const std::string at = resolved_difference(meta->value("resolved_scene", json()), json(now.scene), ""); !at.empty())
          // (a default of this spadgen: the knots of the gate, 64 then 256, made every sample stale with the
          // reason below, which named no default)
          rec.error = "the scene as it resolves now differs at " + at + ": a parameter, or a default of this spadgen";
        else if (const auto t = meta->find("sensor_tables_fnv1a64");
                 t != meta->end() && t->is_string() && !now.tables_hash.empty() && *t != now.tables_hash)
          rec.error = "a sensor table the scene file names (a CSV or EXR file) changed since it was generated";
        else
          // the same resolved scene, contents and tables as it rendered, under the hash of other contents: the
          // contents it was planned from, edited before it rendered (it said "a sensor table ..., or the parameters")
          rec.error = "the scene file, its glTF or a file the glTF reads changed while it was generated (it was planned from "
                      "other contents than it rendered)";
      }
      stale = true;
      continue;
    }
    // The bytes it rendered: the scene file and glTF as its run read them (an edit while the dataset ran, undone
    // after, left samples of the edited glTF under the hash of the other, done: a verifier's find)
    if (const auto h = meta->find("scene_hash_fnv1a64"); h != meta->end() && h->is_string() && *h != scene_content_hash(s.scene)) {
      if (!stale)
        rec.error = "rendered from other contents of the scene file or its glTF (scene_hash_fnv1a64 " + h->get<std::string>() +
                    ", now " + scene_content_hash(s.scene) + "): they changed while it was generated";
      stale = true;
      continue;
    }
    if (const json::json_pointer wall("/run/wall_seconds"); meta->contains(wall) && (*meta)[wall].is_number())
      rec.seconds += std::max(0.0, (*meta)[wall].get<double>());
    if (const json::json_pointer cores("/run/cores"); f == 0 && meta->contains(cores) && (*meta)[cores].is_number_integer())
      rec.cores = std::max(0, (*meta)[cores].get<int>());
    const std::string prefix = f == 0 ? "" : folders[f].substr(s.folder().size()) + "/";
    const size_t gone_before = gone.size();
    const json& sizes = recorded_sizes(*meta);
    for (const json& name : (*meta)["files"]) {
      // metadata.json's size varies with its timing fields; the index and the card must not.
      if (name == "metadata.json") continue;
      // A repeat links the files that do not depend on the noise (ground truth, light): counted once.
      // A listed folder (a Zarr store) counts with every file in it.
      // Its bytes as they are (writers::bytes_on_disk, from the same stats) tell whether it is as written.
      const fs::path path = dir_ / folders[f] / name.get<std::string>();
      std::vector<fs::path> parts = {path};
      std::error_code ec;
      const bool present = fs::exists(path, ec);
      if (fs::is_directory(path, ec))
        for (const auto& e : fs::recursive_directory_iterator(path, ec))
          if (e.is_regular_file(ec)) parts.push_back(e.path());
      int64_t size = 0, whole = 0;
      bool any = false;
      for (const fs::path& q : parts) {
        struct stat st {};
        if (::stat(q.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) continue;
        whole += int64_t(st.st_size);
        if (!inodes.insert({st.st_dev, st.st_ino}).second) continue;
        size += int64_t(st.st_size), any = true;
      }
      if (std::string d = listed_damage(path, name.get_ref<const std::string&>(), present ? whole : -1, sizes); !d.empty())
        gone.push_back(prefix + d);
      if (present) rec.listed.push_back(prefix + name.get<std::string>());
      if (!any) continue;
      rec.files.emplace_back(prefix + name.get<std::string>(), size);
      rec.bytes += size;
    }
    rec.held[f] = gone.size() == gone_before;
    if (f == 0) {
      if (const auto w = meta->find("warnings"); w != meta->end() && w->is_array())
        for (const json& t : *w)
          if (t.is_string()) rec.warnings.push_back(t.get<std::string>());
      if (meta->contains("ground_truth_summary")) rec.summary = ojson::parse((*meta)["ground_truth_summary"].dump());
      if (meta->contains("/laser_photons_per_pulse/total_all_pixels"_json_pointer))
        rec.summary["laser_photons_per_pulse"] = (*meta)["laser_photons_per_pulse"]["total_all_pixels"].get<double>();
    }
  }
  // The sample as it resolves now failed: failed, with why (also when its folder is damaged or stale: a run
  // that could not generate the damaged sample again left it damaged, and said it would generate it).
  // (what a done sample's record holds of its files, dropped when it is not done after all)
  const auto forget_files = [&rec] {
    rec.files.clear(), rec.listed.clear(), rec.bytes = 0, rec.summary = nullptr, rec.warnings.clear(), rec.seconds = 0.0;
  };
  const auto failed = [&]() {
    const std::optional<json> f = read_json(dir_ / failure_path(s));
    // (a damaged record, of other types than record_failure writes, is none)
    if (!f || !f->is_object() || !f->contains("sample_hash") || (*f)["sample_hash"] != rec.hash ||
        (f->contains("error") && !(*f)["error"].is_string()))
      return false;
    forget_files();
    rec.status = Status::Failed;
    rec.error = f->value("error", "");
    return true;
  };
  if (done && !stale && !gone.empty()) {
    if (failed()) return rec;
    forget_files();
    rec.status = Status::Damaged;
    rec.error = "listed in metadata.json but gone or changed: ";
    for (size_t i = 0; i < gone.size() && i < 4; ++i) rec.error += (i ? ", " : "") + gone[i];
    if (gone.size() > 4) rec.error += ", ... (" + std::to_string(gone.size()) + " files)";
    return rec;
  }
  if (done && !stale) {
    rec.status = Status::Done;
    rec.folders = folders;
    return rec;
  }
  if (failed()) return rec;
  forget_files();
  if (stale) rec.status = Status::Stale;
  return rec;
}

void DatasetFolder::record_failure(const Sample& s, const std::string& hash, const std::string& error) const {
  fs::create_directories(dir_ / "failed");
  const ojson j = {{"index", s.index}, {"sample_hash", hash}, {"parameters", s.parameters}, {"error", error}};
  writers::write_file_atomic((dir_ / failure_path(s)).string(), j.dump(2) + "\n");
}

void DatasetFolder::clear_failure(const Sample& s) const {
  std::error_code ec;
  fs::remove(dir_ / failure_path(s), ec);
  fs::remove(dir_ / "failed", ec);  // when it is empty now (a resumed run leaves none, as a run never failed)
}

std::optional<CardTally> DatasetFolder::write_index(const std::function<void(const RecordSink&)>& inspect_each,
                                                    RunPresence* leaving) const {
  const FolderLock lock(dir_, leaving == nullptr);  // (a run leaving after a signal still lists its samples)
  if (leaving) {
    // Under the folder's lock, so that of two runs ending at once the second sees the first gone.
    leaving->release();
    const int others = lock_byte(dir_, kPresenceFile, F_WRLCK, 0, "the runs' presence", false);
    if (others < 0) return std::nullopt;
    ::close(others);
  }
  // The temporary files of index writes that never ended (a run killed while it wrote the index, which takes
  // minutes for millions of samples): every such write holds this lock, so those left are of dead processes.
  {
    std::error_code ec;
    std::vector<fs::path> stale;
    for (const auto& e : fs::directory_iterator(dir_, ec))
      for (const char* prefix : {".index.jsonl.tmp-", ".index.csv.tmp-", ".dataset.md.tmp-"})
        if (e.path().filename().string().rfind(prefix, 0) == 0) stale.push_back(e.path());
    for (const fs::path& p : stale) fs::remove(p, ec);
  }
  // Streamed: the rows are written as the records come (a million samples' records took 1.7 GB).
  writers::AtomicWriter jsonl((dir_ / "index.jsonl").string()), csv((dir_ / "index.csv").string());
  csv.append(index_csv_header(spec_));
  CardTally tally;
  inspect_each([&](const SampleRecord& r) {
    jsonl.append(index_jsonl_row(spec_, r));
    csv.append(index_csv_row(spec_, r));
    tally.add(r);
  });
  // dataset.json with the index, as one step: two runs of different sample counts at once left the one's
  // dataset.json (written as it began) beside the other's index.
  const ojson wanted = record();
  if (read_json<ojson>(dir_ / "dataset.json") != wanted)
    writers::write_file_atomic((dir_ / "dataset.json").string(), wanted.dump(2) + "\n");
  jsonl.commit();
  csv.commit();
  writers::write_file_atomic((dir_ / "dataset.md").string(), dataset_card(*this, tally));
  return tally;
}

json dataset_section(const DatasetFolder& folder, const Sample& s, const std::string& hash, int repeat) {
  const DatasetSpec& spec = folder.spec();
  return {{"dataset_file", spec.file},
          {"index", s.index},
          {"repeat", repeat},
          {"parameters", json::parse(s.parameters.dump())},
          {"seeds", {{"seed", s.seed}, {"light", s.light_seed}, {"chip", s.chip_seed}, {"noise", s.noise_seed + uint64_t(repeat)}}},
          {"sample_hash", hash}};
}

namespace {
// The error the index lists: a failed sample's cause, a damaged one's files (a stale one's change is status's).
std::string listed_error(const SampleRecord& r) {
  return r.status == Status::Failed || r.status == Status::Damaged ? r.error : std::string();
}
}  // namespace

std::string index_jsonl_row(const DatasetSpec& spec, const SampleRecord& r) {
  ojson row;
  row["index"] = r.sample.index;
  row["status"] = status_name(r.status);
  row["folder"] = r.sample.folder();
  row["parameters"] = r.sample.parameters;
  row["seeds"] = {{"seed", r.sample.seed}, {"light", r.sample.light_seed}, {"chip", r.sample.chip_seed}, {"noise", r.sample.noise_seed}};
  row["repeats"] = ojson::array();
  for (int k = 1; k < spec.repeats; ++k) row["repeats"].push_back(r.sample.repeat_folder(k));
  row["sample_hash"] = r.hash;
  if (r.status == Status::Done) {
    row["bytes"] = r.bytes;
    row["files"] = ojson::array();
    for (const std::string& name : r.listed) row["files"].push_back(name);
    row["ground_truth"] = r.summary;
    row["warnings"] = r.warnings;
  }
  if (const std::string error = listed_error(r); !error.empty()) row["error"] = error;
  return row.dump() + "\n";
}

namespace {
std::vector<std::string> csv_parameters(const DatasetSpec& spec) {
  std::vector<std::string> params = {"scene"};
  for (const GridAxis& g : spec.grid) params.push_back(g.key);
  for (const RandomAxis& r : spec.random) params.push_back(r.key);
  return params;
}
const std::vector<std::string> kCsvSummary = {"hit_fraction", "range_min_m", "range_max_m", "meshes_in_view", "max_layer_count",
                                              "objects_in_view", "max_object_count", "multi_object_fraction",
                                              "objects_detectable", "detectable_fraction", "laser_photons_per_pulse"};
}  // namespace

std::string index_csv_header(const DatasetSpec& spec) {
  std::string out = "index,status,folder";
  for (const std::string& p : csv_parameters(spec)) out.append(",").append(csv_field(p));
  out += ",seed,seed_light,seed_chip,seed_noise,sample_hash,bytes";
  for (const std::string& k : kCsvSummary) out.append(",").append(k);
  out += ",error,warnings\n";
  return out;
}

std::string csv_value(const ojson& v) {
  if (v.is_null()) return "";
  if (v.is_string()) return csv_field(v.get<std::string>());
  return csv_field(v.dump());
}

std::string index_csv_row(const DatasetSpec& spec, const SampleRecord& r) {
  std::string out = std::to_string(r.sample.index) + "," + status_name(r.status) + "," + r.sample.folder();
  for (const std::string& p : csv_parameters(spec)) out.append(",").append(csv_value(r.sample.parameters.value(p, ojson())));
  out += "," + std::to_string(r.sample.seed) + "," + std::to_string(r.sample.light_seed) + "," + std::to_string(r.sample.chip_seed) +
         "," + std::to_string(r.sample.noise_seed) + "," + r.hash + ",";
  if (r.status == Status::Done) out += std::to_string(r.bytes);
  for (const std::string& k : kCsvSummary)
    out.append(",").append(r.summary.is_object() ? csv_value(r.summary.value(k, ojson())) : std::string());
  out.append(",").append(csv_field(listed_error(r)));
  out.append(",").append(r.status == Status::Done ? std::to_string(r.warnings.size()) : std::string()).append("\n");
  return out;
}

namespace {
// Text in a Markdown table cell: a '|' escaped (GFM reads it as a cell's end, in code spans too), lines joined.
// The names of a dataset's key (materials."Glass.001".roughness: materials, Glass.001, roughness).
std::vector<std::string> varied_names(const std::string& key) {
  try {
    return scenes::parse_key_path(key).names;
  } catch (const Error&) {
    return {};
  }
}

std::string cell(const std::string& t) {
  std::string out;
  for (char c : t) {
    if (c == '|') out += "\\|";
    else out += c == '\n' || c == '\r' ? ' ' : c;
  }
  return out;
}
}  // namespace

void CardTally::add(const SampleRecord& r) {
  ++samples, ++count[size_t(r.status)];
  if (r.status != Status::Done) return;
  for (const auto& [key, v] : r.sample.parameters.items()) {
    Observed& o = observed[key];
    if (v.is_number()) o.lo = std::min(o.lo, v.get<double>()), o.hi = std::max(o.hi, v.get<double>());
    else o.distinct.insert(v.dump());
  }
  for (const auto& [name, size] : r.files) {
    std::string key = name;
    if (key.rfind("_r", 0) == 0) key = "_rNN" + key.substr(key.find('/'));  // repeats together
    auto& e = sizes[key];
    ++e.first, e.second += size;
  }
  bytes += r.bytes;
  warnings.add(r.sample.index, r.warnings);
}

std::string warning_kind(const std::string& w) {
  // Each number standing alone ("-1.5e+06", "47.875") becomes '#'; digits that are part of a name (layer0,
  // offset_m[2], pde_905nm.csv, x86) stay, so that warnings of different keys or files are not one kind.
  // (a '[' is part of a name after one: offset_m[2]; not in a list: [0, 1])
  const auto name_char_at = [&](size_t k) {
    const char c = w[k];
    if (c == '[') return k > 0 && (std::isalnum(static_cast<unsigned char>(w[k - 1])) || w[k - 1] == '_' || w[k - 1] == ']');
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.';
  };
  const auto digit = [&](size_t i) { return i < w.size() && std::isdigit(static_cast<unsigned char>(w[i])); };
  std::string key;
  for (size_t i = 0; i < w.size();) {
    size_t j = i;
    if ((w[j] == '-' || w[j] == '+') && (digit(j + 1) || (w[j + 1 < w.size() ? j + 1 : j] == '.' && digit(j + 2)))) ++j;
    const bool starts = digit(j) || (j + 1 < w.size() && w[j] == '.' && digit(j + 1));
    if (starts && (i == 0 || !name_char_at(i - 1))) {
      while (digit(j)) ++j;
      if (j < w.size() && w[j] == '.' && digit(j + 1))
        for (++j; digit(j);) ++j;
      if (j < w.size() && (w[j] == 'e' || w[j] == 'E')) {  // an exponent: e+06, e-9
        size_t e = j + 1;
        if (e < w.size() && (w[e] == '+' || w[e] == '-')) ++e;
        if (digit(e)) {
          for (j = e; digit(j);) ++j;
        }
      }
      if (j >= w.size() || !(std::isalpha(static_cast<unsigned char>(w[j])) || w[j] == '_')) {  // (not 400nm: a name)
        key += '#';
        i = j;
        continue;
      }
    }
    key += w[i++];
  }
  return key;
}

void WarningTally::add(int64_t sample, const std::vector<std::string>& ws) {
  std::set<std::string> keys;
  for (const std::string& w : ws) {
    const std::string key = warning_kind(w);
    if (!keys.insert(key).second) continue;  // a sample counts once per kind
    Group& g = groups[key];
    if (g.samples++ == 0) g.example = w;
    if (g.first.size() < kListed) g.first.push_back(sample);
  }
}

std::vector<std::string> WarningTally::lines(const std::string& more) const {
  std::vector<std::pair<const std::string*, const Group*>> order;
  for (const auto& [key, g] : groups) order.emplace_back(&key, &g);
  // the most frequent first; ties in the order of their first sample
  std::sort(order.begin(), order.end(), [](const auto& a, const auto& b) {
    return a.second->samples != b.second->samples ? a.second->samples > b.second->samples : a.second->first < b.second->first;
  });
  std::vector<std::string> out;
  for (const auto& [key, g] : order) {
    if (out.size() == kKindsShown) {
      out.push_back("and " + std::to_string(order.size() - kKindsShown) + " more kinds of warning" + more);
      break;
    }
    std::string line = std::to_string(g->samples) + (g->samples == 1 ? " sample (" : " samples (");
    for (size_t i = 0; i < g->first.size(); ++i) {
      if (i > 0) line += ", ";
      line += std::to_string(g->first[i]);
    }
    if (g->samples > int64_t(g->first.size())) line += ", ...";
    line += "): " + g->example;
    out.push_back(std::move(line));
  }
  return out;
}

std::string dataset_card(const DatasetFolder& folder, const CardTally& tally) {
  const DatasetSpec& spec = folder.spec();
  const auto count = [&tally](Status st) { return tally.count[size_t(st)]; };
  std::ostringstream o;
  // The description's first line is the title, the rest a paragraph under it (a newline in the title broke
  // the heading).
  const size_t start = spec.description.find_first_not_of(" \t\r\n");
  const std::string d = start == std::string::npos ? std::string() : spec.description.substr(start);
  const size_t eol = d.find_first_of("\r\n");
  const std::string title = d.empty() ? fs::path(spec.file).filename().string() : d.substr(0, eol);
  o << "# " << title << "\n\n";
  if (eol != std::string::npos && d.find_first_not_of(" \t\r\n", eol) != std::string::npos)
    o << d.substr(d.find_first_not_of("\r\n", eol)) << "\n\n";
  o << "A synthetic time-gated SPAD dataset generated by spadgen " << SPADGEN_VERSION << " from the dataset file `"
    << fs::path(spec.file).filename().string() << "` (its resolved form: `dataset.json`):\n\n"
    << "```sh\nspadgen dataset run " << shell_word(fs::path(spec.file).filename().string()) << " -o DIR   # DIR: this folder\n```\n\n";
  o << "## Samples\n\n"
    << "| samples | done | failed | stale | missing | damaged |\n|---|---|---|---|---|---|\n"
    << "| " << tally.samples << " | " << count(Status::Done) << " | " << count(Status::Failed) << " | " << count(Status::Stale)
    << " | " << count(Status::Missing) << " | " << count(Status::Damaged) << " |\n\n";
  o << "Sample i is the folder `samples/<i, 6 digits>/` (a complete spadgen run folder: `metadata.json` lists its files, "
       "units and settings, and its `dataset` section the sample's parameters and seeds)";
  if (spec.repeats > 1)
    o << (spec.repeats == 2 ? std::string("; its realisation 1 of the temporal noise is `samples/<i>_r01/` (the same light, noise seed S + 1)")
                            : "; its realisations 1 to " + std::to_string(spec.repeats - 1) +
                                  " of the temporal noise are `samples/<i>_r01/`, ... (the same light, noise seeds S + 1, ...)");
  o << ". `index.jsonl` and `index.csv` have one row per sample: parameters, seeds, status, files, bytes, a summary of "
       "its ground truth and its run's warnings.\n\n";
  if (!tally.warnings.groups.empty()) {
    o << "## Warnings\n\nWhat the done samples' runs warned about (each sample's `metadata.json` `warnings`, its row's "
         "`warnings`): settings that are consistent but likely not what was meant.\n\n";
    for (const std::string& line : tally.warnings.lines(" (each sample's metadata.json lists its own)")) o << "- " << cell(line) << "\n";
    o << "\n";
  }
  // with how many samples each scene file makes ("samples" fewer than the cells leaves the last scene files
  // out, which the table said nothing of)
  o << "## Scenes\n\n| scene file | samples | description |\n|---|---|---|\n";
  for (size_t i = 0; i < spec.scenes.size(); ++i) {
    std::string description;
    try {
      description = scenes::load_scene_file(spec.scenes[i]).resolved.value("description", "");
    } catch (const Error&) {
    }
    o << "| `" << cell(spec.scene_names[i]) << "` | " << spec.samples_of_scene(i) << " | " << cell(description) << " |\n";
  }
  if (const std::string w = spec.coverage_warning(); !w.empty()) o << "\n" << cell(w.substr(spec.file.size() + 2)) << ".\n";
  // The camera each scene's first sample resolves to; a value a grid or random key varies reads "varies" (a new
  // user read sample 0's sensor preset and laser power as the dataset's).
  std::vector<std::vector<std::string>> varied_keys;
  for (const GridAxis& g : spec.grid) varied_keys.push_back(varied_names(g.key));
  for (const RandomAxis& ra : spec.random) varied_keys.push_back(varied_names(ra.key));
  // dotted: a key of the resolved scene (camera.width_px); varied when a varied key sets it, a part of it or all of it
  // (below: or its value differs among the scene's first samples: a preset that sets it, render.quality)
  const auto varies = [&](const std::string& dotted) {
    const std::vector<std::string> names = varied_names(dotted);
    for (const std::vector<std::string>& k : varied_keys) {
      const size_t n = std::min(k.size(), names.size());
      if (!k.empty() && std::equal(k.begin(), k.begin() + std::ptrdiff_t(n), names.begin())) return true;
    }
    return false;
  };
  o << "\n## Sensor and acquisition\n\n| scene file | image | sensor | acquisition | laser | render |\n|---|---|---|---|---|---|\n";
  for (size_t i = 0; i < spec.scenes.size(); ++i) {
    const int64_t first = static_cast<int64_t>(i) * (spec.grid_cells() / static_cast<int64_t>(spec.scenes.size()));
    if (first >= spec.count()) break;
    ojson r;
    try {
      r = folder.resolve(make_sample(spec, first)).scene;
    } catch (const Error&) {
      continue;
    }
    std::vector<ojson> others;  // the scene's next samples, as they resolve (the valid ones)
    for (const int64_t p : probe_samples(spec, i))
      if (p != first) try {
          others.push_back(folder.resolve(make_sample(spec, p)).scene);
        } catch (const Error&) {
        }
    const auto at = [](ojson& scene, const std::string& k) {
      ojson* v = &scene;
      for (const std::string& name : varied_names(k)) v = &(*v)[name];
      return v;
    };
    // the value of dotted key k in the resolved scene, or "varies"
    const auto num = [&](const std::string& k) {
      if (varies(k)) return std::string("varies");
      const ojson* v = at(r, k);
      for (ojson& other : others)
        if (*at(other, k) != *v) return std::string("varies");
      std::ostringstream t;
      if (v->is_number()) t << v->get<double>();
      else if (v->is_string()) t << v->get<std::string>();
      else t << v->dump();
      return t.str();
    };
    const ojson& acq = r["acquisition"];
    std::string acquisition = num("acquisition.mode") + ", " + num("acquisition.frames") + " frames";
    if (!varies("acquisition.mode")) {
      if (acq["mode"] == "gate_sweep")
        acquisition += ", gates " + num("acquisition.gate_sweep.start_ns") + " to " + num("acquisition.gate_sweep.stop_ns") +
                       " ns in " + num("acquisition.gate_sweep.step_ps") + " ps steps";
      else {
        // ("varies exposure of varies us" read as a typo: the varying parts said as such)
        const std::string exposure = num("acquisition.intensity.exposure"), us = num("acquisition.intensity.exposure_us");
        acquisition += exposure == "varies" ? std::string(", exposure (single or dual) varies") : ", " + exposure + " exposure";
        acquisition += us == "varies" ? std::string(", its length varies") : " of " + us + " us";
      }
    }
    const std::string crop = num("camera.crop");
    // (a 2D scene whose counts see no laser: its laser's settings say nothing of its data)
    const std::string laser_on = num("acquisition.intensity.laser_on");
    // (with outputs.transient, or outputs.light with a time window, its files hold the laser's light all the same)
    const bool laser_off = num("acquisition.mode") == "intensity" && laser_on == "false" && num("outputs.transient") == "false" &&
                           (num("outputs.light") == "false" || num("render.window_start_ns") == "null");
    o << "| `" << cell(spec.scene_names[i]) << "` | " << num("camera.width_px") << " x " << num("camera.height_px")
      << (crop == "null" ? std::string() : ", crop " + crop) << " | " << num("sensor.preset") << " | " << acquisition << " | "
      << (laser_off ? std::string("off (intensity mode without laser_on)")
                    : num("laser.wavelength_nm") + " nm, " + num("laser.repetition_rate_MHz") + " MHz, " + num("laser.average_power_mW") +
                          " mW" + (num("acquisition.mode") == "intensity" && laser_on == "varies" ? " (laser_on varies)" : ""))
      << " | " << num("render.samples_per_pixel") << (num("render.samples_per_pixel") == "1" ? " path" : " paths") << " per pixel |\n";
  }
  o << "\nAs each scene's first sample resolves; \"varies\": a key under Parameters sets it per sample (or a preset it sets). Every sample's full settings "
       "are its `metadata.json`'s `resolved_scene`.\n";
  o << "\n## Parameters\n\n";
  o << "Sample i takes grid cell i mod " << spec.grid_cells() << " (the scene outermost, the last grid key fastest) and its "
    << "own random draws, from the dataset seed " << spec.seed << " and i only: adding samples leaves the existing ones "
    << "unchanged.\n\n";
  o << "| key | varied by | values | range over the done samples |\n|---|---|---|---|\n";
  const auto observed = [&](const std::string& key) {
    std::ostringstream t;
    const auto it = tally.observed.find(key);
    if (it == tally.observed.end()) return t.str();
    if (it->second.lo <= it->second.hi) t << it->second.lo << " to " << it->second.hi;
    else if (!it->second.distinct.empty()) t << it->second.distinct.size() << " distinct values";
    return t.str();
  };
  if (spec.scenes.size() > 1) o << "| `scene` | grid | " << cell(ojson(spec.scene_names).dump()) << " | " << observed("scene") << " |\n";
  for (const GridAxis& g : spec.grid) o << "| `" << cell(g.key) << "` | grid | `" << cell(g.values.dump()) << "` | " << observed(g.key) << " |\n";
  for (const RandomAxis& r : spec.random) o << "| `" << cell(r.key) << "` | random | `" << cell(r.spec.dump()) << "` | " << observed(r.key) << " |\n";
  if (!spec.set.empty()) {
    o << "\nSet for every sample:";
    for (const auto& [k, v] : spec.set) o << " `" << k << "=" << v.dump() << "`";
    o << "\n";
  }
  const auto seed_text = [](const std::optional<uint64_t>& v) { return v ? std::to_string(*v) + " for every sample" : std::string("per sample"); };
  o << "\nSeeds: light " << seed_text(spec.light_seed) << ", chip " << seed_text(spec.chip_seed) << ", noise "
    << seed_text(spec.noise_seed) << " (per sample: derived from the dataset seed and the index; each row of the index "
    << "lists them).\n";
  // Sizes per output file, over the done samples.
  const auto& sizes = tally.sizes;
  const int64_t total = tally.bytes;
  o << "\n## Files and sizes\n\n";
  if (count(Status::Done) == 0) {
    o << "No sample is done yet.\n";
  } else {
    o << "| file | mean bytes per sample | total |\n|---|---|---|\n";
    for (const auto& [name, e] : sizes)
      o << "| `" << cell(name) << "` | " << bytes_text(std::llround(double(e.second) / double(e.first))) << " | " << bytes_text(e.second) << " |\n";
    o << "| all | " << bytes_text(std::llround(double(total) / double(count(Status::Done)))) << " | " << bytes_text(total) << " |\n";
  }
  o << "\n## Reading it\n\nFrom this folder:\n\n```python\nimport json\nrows = [json.loads(l) for l in open(\"index.jsonl\")]\n"
       "import spadgen                                   # python/ in the spadgen repository (docs/python.md, Datasets)\n"
       "ds = spadgen.open_dataset(\".\")                   # the index: ds.table(), ds.select(status=\"done\", ...)\n"
       "run = ds.select(status=\"done\")[0].run            # one sample: metadata, ground truth, counts, ...\n```\n\n"
       "docs/datasets.md in the spadgen repository documents the folder, the index and the card.\n";
  return o.str();
}

}  // namespace spadgen::datasets
