#include "app/staging.h"
#include "app/reconstruct.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <climits>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <mutex>
#include <sstream>
#include <set>
#include <stdexcept>

#include "core/current_folder.h"
#include "core/error.h"
#include "datasets/folder.h"
#include "reconstruct/run_folder.h"
#include "scenes/input.h"

namespace spadgen::app {
namespace fs = std::filesystem;

namespace {

const std::string kOldStylePrefix = ".spadgen-staging-";  // staging folders inside OUT (spadgen before the swap)

std::string pid_text() { return std::to_string(::getpid()); }

bool starts_with(const std::string& s, const std::string& prefix) { return s.compare(0, prefix.size(), prefix) == 0; }

// Makes renames in `dir` durable; best effort (some file systems refuse to fsync a folder).
void sync_dir(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

// True when `dir` is the root of a mounted file system (a mount point, a bind mount): no folder can be
// renamed into its place.
bool is_mount_point(const fs::path& dir) {
  struct statx sx {};
  if (::statx(AT_FDCWD, dir.c_str(), AT_SYMLINK_NOFOLLOW, STATX_BASIC_STATS, &sx) == 0 &&
      (sx.stx_attributes_mask & STATX_ATTR_MOUNT_ROOT) != 0)
    return (sx.stx_attributes & STATX_ATTR_MOUNT_ROOT) != 0;
  struct stat here {}, up {};  // kernels before 5.8: another device than the parent's
  return ::stat(dir.c_str(), &here) == 0 && ::stat(dir.parent_path().c_str(), &up) == 0 && here.st_dev != up.st_dev;
}

// What metadata.json lists, relative to `out`: itself, the files and folders it names (a Zarr store,
// "counts.zarr", is a folder, the run's with everything in it), and the folders they lie in ("previews",
// "light"). Only a metadata.json of spadgen's (a JSON object with spadgen_version and its list of files) says
// which files are spadgen's. Another one (a user's notes of the same name, listing files of their own) and one
// that cannot be read list nothing, not even themselves: the folder's files are someone else's (a run replaced
// a folder of a user's metadata.json and the files it listed: an adversarial tester's find).
struct Listed {
  std::set<std::string> entries, parents;
  std::string damaged;  // why a metadata.json that is there lists nothing ("" when absent or read)
};
Listed listed_files(const fs::path& out) {
  Listed listed;
  std::string text;
  std::error_code ec;
  try {
    text = scenes::read_file_bounded((out / "metadata.json").string(), uint64_t{64} << 20, "metadata");
  } catch (const Error& e) {
    if (fs::exists(out / "metadata.json", ec)) listed.damaged = e.what();
    return listed;
  }
  const nlohmann::json meta = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (!meta.is_object() || !meta.contains("files") || !meta["files"].is_array() || !meta.contains("spadgen_version") ||
      !meta["spadgen_version"].is_string()) {
    listed.damaged = (out / "metadata.json").string() +
                     (meta.is_discarded() ? " is not JSON (cut short?)"
                                          : " is not a spadgen run's (a JSON object with spadgen_version and its list of files)");
    return listed;
  }
  listed.entries.insert("metadata.json");
  for (const nlohmann::json& f : meta["files"]) {
    if (!f.is_string()) continue;
    const fs::path p = fs::path(f.get<std::string>()).lexically_normal();
    if (p.empty() || p == "." || p == "/" || *p.begin() == "..") continue;
    listed.entries.insert(p.string());
    for (fs::path q = p.parent_path(); !q.empty() && q != "." && q != "/"; q = q.parent_path()) listed.parents.insert(q.string());
  }
  return listed;
}

}  // namespace

fs::path resolved_folder(const fs::path& out) {
  std::error_code ec;
  fs::path abs = fs::absolute(out, ec).lexically_normal();
  if (!abs.has_filename()) abs = abs.parent_path();
  fs::path resolved = fs::weakly_canonical(abs, ec);
  return ec ? abs : resolved;
}

void require_utf8_path(const fs::path& path, const std::string& what, const std::string& why, bool absolute) {
  std::error_code ec;
  const std::string recorded = absolute ? fs::absolute(path, ec).lexically_normal().string() : path.string();
  if (scenes::invalid_utf8_at(ec ? path.string() : recorded) != std::string::npos)
    throw Error(scenes::printable(path.string()) + ": " + what + "'s name (or a folder's above it) is not valid UTF-8 text, " +
                why + "; rename it");
}

bool is_run_folder(const fs::path& folder) {
  std::error_code ec;
  if (!fs::is_regular_file(folder / "metadata.json", ec)) return false;
  nlohmann::json meta;
  try {  // (not a run's when it does not read as one; a run's is kilobytes: another tool's large file is not read)
    const std::string m = (folder / "metadata.json").string();
    meta = scenes::parse_json(scenes::read_file_bounded(m, 16u << 20, "metadata"), m);
  } catch (const Error&) {
  }
  return meta.is_object() && meta.contains("spadgen_version");
}

void refuse_output_inside(const fs::path& out, const std::string& option,
                          const std::function<bool(CheckedFolder, const fs::path&, const fs::path&)>& allowed) {
  std::error_code ec;
  // Where Staging writes it (".." taken before a symbolic link is followed, as the path names it)
  const fs::path where = resolved_folder(out);
  const auto check = [&](CheckedFolder kind, const fs::path& folder, const std::string& what) {
    const fs::path rel = where.lexically_relative(folder);
    if (allowed && allowed(kind, folder, rel)) return;
    throw Error(option + ": " + what + "; expected a folder outside it");
  };
  for (fs::path folder = where.parent_path(); !folder.empty(); folder = folder.parent_path()) {
    if (is_run_folder(folder))
      return check(CheckedFolder::Run, folder, "lies in the run folder " + folder.string() + ", which holds only what spadgen "
                   "writes there (a later run into it, or a dataset's check of it, would refuse the folder for a foreign one)");
    if (fs::is_regular_file(folder / "dataset.json", ec)) {
      const fs::path rel = where.lexically_relative(folder);
      if (!rel.empty() && datasets::own_entries().count(rel.begin()->string()))
        return check(CheckedFolder::Dataset, folder, (std::distance(rel.begin(), rel.end()) == 1 ? "is" : "lies in") +
                     std::string(" the dataset ") + folder.string() + "'s own " + rel.begin()->string() +
                     ", which holds only what spadgen writes there");
    }
    if (reconstruct::is_repeat_set(folder))
      return check(CheckedFolder::RepeatSet, folder, "lies in the folder " + folder.string() + " of sense --repeats' "
                   "realisations, which holds those only");
    if (folder == folder.root_path()) break;
  }
}

void refuse_run_folder_inside(const fs::path& out, bool given, bool dataset_sample) {
  refuse_output_inside(out, given ? "-o " + out.string() : "the default output folder " + out.string() + " (give another with -o)",
                       [&](CheckedFolder kind, const fs::path&, const fs::path& rel) {
                         const auto depth = std::distance(rel.begin(), rel.end());
                         return (kind == CheckedFolder::RepeatSet && depth == 1) ||
                                (dataset_sample && kind == CheckedFolder::Dataset && depth == 2 && *rel.begin() == "samples");
                       });
}

Staging::Staging(const fs::path& out, std::vector<std::string> owned, std::string what)
    : owned_(std::move(owned)), what_(std::move(what)) {
  init(out);
}

Staging::Staging(const fs::path& out, Hook hook) : hook_(std::move(hook)) { init(out); }

Staging::Staging(const fs::path& out, OfRuns) : of_runs_(true), what_("sense --repeats") {
  init(out);
  fs::remove(dir_ / "previews");  // its runs have their own
  fs::remove(dir_ / "light");
}

Staging::Staging(const Staging& parent, const std::string& sub)
    : out_(parent.out_ / sub), parent_(parent.out_), dir_(parent.dir_ / sub), name_(sub), sub_(true), what_(parent.what_) {
  try {
    fs::create_directories(dir_ / "previews");
    fs::create_directories(dir_ / "light");
  } catch (const fs::filesystem_error& e) {  // (a full disk's inodes: it was the library's raw message)
    throw Error("cannot write " + out_.string() + ": " + e.code().message() + " (" + e.path1().string() + ")");
  }
}

void Staging::finish_sub() const { prune_subfolders(); }

void Staging::prune_subfolders() const {
  // rmdir fails, as it should, on the folders with files in them
  for (const auto& e : fs::directory_iterator(dir_))
    if (e.is_directory() && ::rmdir(e.path().c_str()) != 0) sync_dir(e.path());
}

void Staging::remove_leftovers(const fs::path& parent) {
  std::set<std::string> names;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(parent, ec)) {
    const std::string n = e.path().filename().string();
    const size_t at = n.find(".spadgen-staging-");
    if (n.size() > 1 && n[0] == '.' && at != std::string::npos && at > 1) names.insert(n.substr(1, at - 1));
    // a lock file alone: its run was killed after publishing its folder, before removing it (taken and
    // released below as any run does, which removes it; one a live run holds stays)
    static const std::string kLock = ".spadgen-lock";
    if (n.size() > kLock.size() + 1 && n[0] == '.' && n.ends_with(kLock)) names.insert(n.substr(1, n.size() - kLock.size() - 1));
  }
  for (const std::string& name : names) {
    try {
      const Staging cleanup(parent / name);  // recovers under the lock, then removes its own staging folder
    } catch (const Error&) {
      // another run holds it, or the folder is not spadgen's: left as it is
    }
  }
}

namespace {
// The lock file of the resolved folder P/NAME: P/.NAME.spadgen-lock.
fs::path lock_path_of(const fs::path& resolved) {
  return resolved.parent_path() / ("." + resolved.filename().string() + ".spadgen-lock");
}
int take_folder_lock(const fs::path& lock_path, const fs::path& out, bool shared, bool output);
}  // namespace

namespace {
std::mutex g_parent_moved_lock;
std::string g_parent_moved;  // staging_parent_moved(): of the last Staging made
}  // namespace

std::string staging_parent_moved() {
  const std::lock_guard<std::mutex> hold(g_parent_moved_lock);
  return g_parent_moved;
}

void Staging::init(const fs::path& out) {
  const auto cannot = [&](const std::string& why) {
    return Error("cannot use " + out.string() + " as the output folder (-o): " + why);
  };
  std::error_code ec;
  {
    const std::lock_guard<std::mutex> hold(g_parent_moved_lock);
    g_parent_moved.clear();  // (an earlier Staging's parent, moved, is not this one's)
  }
  // A relative path in a current folder that was removed (a shell standing in it): said so, not "Invalid argument"
  if (const std::string problem = relative_path_problem(out); !problem.empty()) throw cannot(problem);
  out_ = resolved_folder(out);
  if (!out_.has_filename() || out_ == out_.root_path()) throw cannot("expected a folder below the root");
  parent_ = out_.parent_path();
  name_ = out_.filename().string();
  // Beside OUT go .OUT.spadgen-staging-<pid>, the longest of spadgen's names (a pid of up to 7 digits): a name
  // the file system takes could not take those ("File name too long" naming the hidden folder).
  {
    constexpr size_t kLongestAddition = std::char_traits<char>::length("..spadgen-staging-") + 7;
    const long name_max = ::pathconf(fs::exists(parent_, ec) ? parent_.c_str() : "/", _PC_NAME_MAX);
    const size_t most = (name_max > 0 ? size_t(name_max) : 255) - kLongestAddition;
    if (name_.size() > most)
      throw cannot("its name is " + std::to_string(name_.size()) + " bytes long; spadgen first writes into a hidden folder " +
                   "beside it whose name adds " + std::to_string(kLongestAddition) + " bytes to it, so expected a name of at most " +
                   std::to_string(most) + " bytes");
    // ... and a path the system takes with the files' names in it (a run of a path near PATH_MAX rendered
    // everything, then failed writing previews/gate_profiles.png): the longest of them, with a temporary
    // file's suffix, fits in kLongestFile bytes
    constexpr size_t kLongestFile = 96;
    const size_t path_most = size_t(PATH_MAX) - 1 - kLongestAddition - 1 - kLongestFile;
    if (out_.string().size() > path_most)
      throw cannot("its path is " + std::to_string(out_.string().size()) + " bytes long (resolved), and the files spadgen writes in " +
                   "it need up to " + std::to_string(kLongestAddition + 1 + kLongestFile) + " more within the system's limit of " +
                   std::to_string(PATH_MAX) + " bytes, so expected a path of at most " + std::to_string(path_most) + " bytes");
  }
  // The swap replaces OUT as a whole: a shell standing in it would be left in a removed folder.
  const fs::path cwd = fs::current_path(ec);
  if (!ec) {
    const fs::path rel = cwd.lexically_relative(out_);
    if (!rel.empty() && *rel.begin() != "..")
      throw cannot("it is the current folder or holds it; " + what_ +
                   " replaces the output folder as a whole, so name a folder below the current one");
  }
  try {
    fs::create_directories(parent_);
  } catch (const fs::filesystem_error& e) {
    throw cannot(e.code().message() + "; expected a folder that exists or can be created");
  }
  if (fs::exists(out_, ec) && !fs::is_directory(out_, ec))
    throw cannot("it exists and is not a folder; expected a folder that exists or can be created");
  if (fs::is_symlink(fs::symlink_status(out_, ec))) {  // a link to a folder was resolved above: this one leads nowhere
    struct stat st{};
    if (::stat(out_.c_str(), &st) != 0 && errno == ELOOP)
      throw cannot("it is a loop of symbolic links (" + out_.string() + " -> " + fs::read_symlink(out_, ec).string() +
                   " -> ...); expected a folder that exists or can be created");
    throw cannot("it is a symbolic link to " + fs::read_symlink(out_, ec).string() +
                 ", which does not exist; expected a folder that exists or can be created");
  }
  if (fs::is_directory(out_, ec) && is_mount_point(out_))
    throw cannot("it is a mount point; " + what_ + " replaces the output folder as a whole, renaming a new folder into its " +
                 "place, which cannot be done to a mount point, so name a folder inside it (" + (out_ / "run").string() + ")");
  if (owned_.empty()) refuse_a_realisation_or_a_folder_being_written();
  lock();
  try {
    recover();
    // A folder of sense --repeats' realisations is replaced with them: each one's lock too, held to the end,
    // so that a reconstruct or evaluate working in one (which holds that realisation's lock, not the set's)
    // is not left writing into a folder replaced under it (its file was lost: "No such file or directory").
    if (reconstruct::is_repeat_set(out_))
      for (const auto& e : fs::directory_iterator(out_, ec))
        if (const std::string n = e.path().filename().string(); n.rfind("repeat_", 0) == 0 && e.is_directory(ec)) {
          realisation_locks_.emplace_back(lock_path_of(e.path()), -1);
          realisation_locks_.back().second = take_folder_lock(realisation_locks_.back().first, e.path(), false, false);
        }
    check_owned();
    // A folder whose entries this user may not remove (mode 555) would be replaced, and its earlier files left
    // in a hidden folder no later run could remove: refused while nothing is written. Its subfolders too
    // (light/, previews/, a Zarr store: `chmod -R a-w`, or a copy from read-only media). After check_owned:
    // a folder of someone else's files is named as such first.
    if (fs::is_directory(out_, ec)) {
      const auto locked = [](const fs::path& d) { return ::access(d.c_str(), W_OK | X_OK) != 0 && errno == EACCES; };
      fs::path found = locked(out_) ? out_ : fs::path();
      if (found.empty()) {
        size_t seen = 0;
        for (auto it = fs::recursive_directory_iterator(out_, fs::directory_options::skip_permission_denied, ec);
             !ec && it != fs::recursive_directory_iterator() && seen < 100000; it.increment(ec), ++seen)
          if (it->is_directory(ec) && !it->is_symlink(ec) && locked(it->path())) {
            found = it->path();
            break;
          }
      }
      if (!found.empty())
        throw cannot((found == out_ ? std::string("it is") : found.string() + " is") +
                     " read-only to this user (its entries could not be removed once the folder is replaced); make it "
                     "writable (chmod -R u+w " + out_.string() + "), or choose another folder");
    }
    dir_ = parent_ / ("." + name_ + ".spadgen-staging-" + pid_text());
    if (struct stat st {}; ::stat(parent_.c_str(), &st) == 0) parent_dev_ = st.st_dev, parent_ino_ = st.st_ino;
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "previews");
    fs::create_directories(dir_ / "light");
  } catch (const fs::filesystem_error& e) {
    // No destructor runs for an object whose constructor throws: the staging folder made before a subfolder
    // failed (a full disk's inodes) is removed here (it was left, hidden, until a later run).
    std::error_code removed;
    if (!dir_.empty()) fs::remove_all(dir_, removed);
    unlock();
    throw cannot(e.code().message() + " (" + e.path1().string() + ")");
  } catch (...) {
    std::error_code removed;
    if (!dir_.empty()) fs::remove_all(dir_, removed);
    unlock();
    throw;
  }
}

Staging::~Staging() {
  if (sub_) return;  // the parent's staging folder holds it
  std::error_code ec;
  // The parent moved or removed while the command wrote (mv of a folder above it): the staging folder and the
  // lock file went with it, out of this path's reach; the message of the error that ends the command says so.
  if (struct stat st {}; parent_ino_ != 0 && !dir_.empty() &&
                         (::stat(parent_.c_str(), &st) != 0 || st.st_dev != parent_dev_ || st.st_ino != parent_ino_)) {
    const std::lock_guard<std::mutex> hold(g_parent_moved_lock);
    g_parent_moved = parent_.string() + " was moved or removed while spadgen wrote into it: the staging folder (" +
                     dir_.filename().string() + ") and the lock file (" + lock_path_.filename().string() +
                     ") went with it, out of spadgen's reach, and nothing was published; remove the two where that folder is now";
  }
  if (!dir_.empty()) fs::remove_all(dir_, ec);  // unpublished files, or the earlier set after an exchange
  unlock();
}

std::string Staging::path(const std::string& rel) const { return (dir_ / rel).string(); }

namespace {
// The processes holding a lock on the open file fd, from /proc/locks ("pid N", "pids N, M"), "" when it lists
// none (another machine's, over a network file system, or no /proc).
std::string lock_holders_listed(int fd) {
  struct stat st {};
  if (::fstat(fd, &st) != 0) return "";
  std::ifstream locks("/proc/locks");
  // "1: FLOCK  ADVISORY  READ  1234 08:01:5678 0 EOF"; a waiter's line has "->" after the number
  const std::string file = [&] {
    char id[64];
    std::snprintf(id, sizeof id, "%02x:%02x:%llu", ::major(st.st_dev), ::minor(st.st_dev), static_cast<unsigned long long>(st.st_ino));
    return std::string(id);
  }();
  std::vector<std::string> pids;
  for (std::string line; std::getline(locks, line) && pids.size() < 4;) {
    std::istringstream in(line);
    std::string number, kind, advisory, mode, pid, id;
    if (!(in >> number >> kind >> advisory >> mode >> pid >> id) || kind != "FLOCK" || id != file) continue;
    if (std::find(pids.begin(), pids.end(), pid) == pids.end()) pids.push_back(pid);
  }
  if (pids.empty()) return "";
  std::string who = pids.size() == 1 ? "pid " : "pids ";
  for (size_t i = 0; i < pids.size() && i < 3; ++i) who += (i ? ", " : "") + pids[i];
  return who + (pids.size() > 3 ? ", ..." : "");
}

// The holder a lock file names ("pid N", written by its exclusive holder), else those /proc/locks lists (a
// reader's shared lock names none), "" when neither does.
std::string lock_holder(int fd) {
  char holder[64] = {0};
  const ssize_t n = ::pread(fd, holder, sizeof holder - 1, 0);
  std::string who = n > 0 ? std::string(holder, static_cast<size_t>(n)) : std::string();
  while (!who.empty() && (who.back() == '\n' || who.back() == ' ')) who.pop_back();
  return who.empty() ? lock_holders_listed(fd) : who;
}

// Locks P/.NAME.spadgen-lock (flock, exclusive, or shared by readers; not waiting) for the folder `out` =
// P/NAME and returns the descriptor; throws spadgen::Error naming the holder when another spadgen process
// has it exclusively (or, exclusive, at all).
// output: the lock of the folder a command writes (-o); else of a run folder it reads (and may write into).
int take_folder_lock(const fs::path& lock_path, const fs::path& out, bool shared, bool output) {
  const std::string folder = (output ? "the output folder " : "the run folder ") + out.string();
  for (int attempt = 0; attempt < 16; ++attempt) {
    const int fd = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (fd < 0)
      throw Error((!output ? "cannot lock " + folder : "cannot use " + out.string() + " as the output folder (-o)") +
                  ": cannot create its lock file " + lock_path.string() + ": " + std::strerror(errno));
    if (::flock(fd, (shared ? LOCK_SH : LOCK_EX) | LOCK_NB) != 0) {
      const int err = errno;
      const std::string who = lock_holder(fd);
      ::close(fd);
      // Held by this very process: the folder is, by another path (a bind mount), one this command already
      // holds (-o over the run it reads was told to wait for its own pid).
      if (err == EWOULDBLOCK && who == "pid " + pid_text())
        throw Error((output ? "cannot use " + out.string() + " as the output folder (-o)" : "cannot read " + folder) +
                    ": its lock file " + lock_path.string() + " is held by this spadgen process itself (pid " + pid_text() +
                    "): by another path (a bind mount), it is a folder this command already reads or writes; " +
                    (output ? "choose another folder (-o)" : "give each folder once"));
      if (err == EWOULDBLOCK && shared)
        // (a run writing it, or a reconstruct or evaluate that may write into it: "another spadgen run" was said of
        // a reconstruct that only read it)
        throw FolderBusy(folder + " is being written, or may be written into, by another spadgen process" +
                    (who.empty() ? std::string() : " (" + who + ")") + ", which holds " + lock_path.string() +
                    "; wait for it to finish");
      if (err == EWOULDBLOCK)
        throw FolderBusy(folder + " is being written or read by another spadgen process" +
                    (who.empty() ? std::string() : " (" + who + ")") + ", which holds " + lock_path.string() +
                    (output ? "; wait for it to finish, or choose another folder (-o)" : "; wait for it to finish"));
      throw Error("cannot lock " + folder + " (" + lock_path.string() + "): " + std::strerror(err));
    }
    // The run that held the lock may have removed the file between our open and our flock.
    struct stat locked {}, now {};
    if (::fstat(fd, &locked) == 0 && ::stat(lock_path.c_str(), &now) == 0 && locked.st_ino == now.st_ino &&
        locked.st_dev == now.st_dev) {
      const std::string me = "pid " + pid_text() + "\n";
      if (!shared && ::ftruncate(fd, 0) == 0 && ::pwrite(fd, me.data(), me.size(), 0) < 0) {
      }  // the pid is only for the message of a second run
      return fd;
    }
    ::close(fd);
  }
  throw Error("cannot lock " + folder + ": its lock file " + lock_path.string() + " keeps being replaced");
}

void release_folder_lock(const fs::path& lock_path, int& fd, bool shared = false) {
  if (fd < 0) return;
  // Unlinked while still locked: a run that opened it meanwhile sees the file gone and locks a new one.
  // A reader unlinks it only when no one else holds it (its lock made exclusive without waiting), and only
  // while the path is still its file.
  bool remove = !shared;
  if (shared && ::flock(fd, LOCK_EX | LOCK_NB) == 0) {
    struct stat locked {}, now {};
    remove = ::fstat(fd, &locked) == 0 && ::stat(lock_path.c_str(), &now) == 0 && locked.st_ino == now.st_ino &&
             locked.st_dev == now.st_dev;
  }
  if (remove) ::unlink(lock_path.c_str());
  ::close(fd);
  fd = -1;
}
}  // namespace

int64_t realisations_of(const nlohmann::json& metadata) {
  if (!metadata.is_object() || !metadata.contains("sense") || !metadata["sense"].is_object()) return 0;
  const nlohmann::json repeats = metadata["sense"].value("repeats", nlohmann::json());
  return repeats.is_number_integer() && repeats.get<int64_t>() > 1 ? repeats.get<int64_t>() : 0;
}

// A run folder (or a folder of runs) OUT inside a `sense --repeats` set (beside the set's realisation 0, whose
// metadata.json says sense.repeats > 1), or inside a folder another spadgen process writes as a whole (a set
// being made): the set would mix calls, or hold a folder that keeps it from being written again, or the
// other process's swap would replace this one's files (each exited 0).
void Staging::refuse_a_realisation_or_a_folder_being_written() const {
  const auto cannot = [&](const std::string& why) {
    return Error("cannot use " + out_.string() + " as the output folder (-o): " + why);
  };
  // The set's size from its realisation 0's metadata.json (0: not a set).
  const auto set_size = [&]() -> int64_t {
    std::error_code ec;
    const fs::path m = parent_ / "repeat_000" / "metadata.json";
    if (!fs::is_regular_file(m, ec)) return 0;
    try {
      return realisations_of(nlohmann::json::parse(scenes::read_file_bounded(m.string(), uint64_t{64} << 20, "metadata"),
                                                   nullptr, /*allow_exceptions=*/false));
    } catch (const Error&) {
      return 0;
    }
  };
  if (const int64_t repeats = set_size(); repeats > 0)
    throw cannot("it lies in " + parent_.string() + ", the " + std::to_string(repeats) +
                 " realisations that one `spadgen sense --repeats` wrote together, a set no other call writes into; " +
                 "write the whole set again (-o " + parent_.string() + " --repeats " + std::to_string(repeats) +
                 "), or choose a folder outside it");
  const fs::path parent_lock = lock_path_of(parent_);
  const int fd = ::open(parent_lock.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return;
  const bool written = ::flock(fd, LOCK_SH | LOCK_NB) != 0 && errno == EWOULDBLOCK;
  const std::string who = written ? lock_holder(fd) : std::string();
  ::close(fd);  // (and the shared lock with it)
  if (written)
    throw cannot("the folder holding it, " + parent_.string() + ", is held by another spadgen process" +
                 (who.empty() ? std::string() : " (" + who + ")") + " that writes it (a run or a sense --repeats, which " +
                 "replaces it as a whole when it ends, or a reconstruct); wait for it to finish, or choose another folder");
}

void Staging::lock() {
  lock_path_ = lock_path_of(out_);
  lock_fd_ = take_folder_lock(lock_path_, out_, false, true);
}

void Staging::unlock() {
  // (a realisation's lock file is removed only while its path is still that file: once the set is replaced
  // the path is the new set's, whose readers may hold a lock file of their own there)
  for (auto& [path, fd] : realisation_locks_) {
    struct stat locked {}, now {};
    if (::fstat(fd, &locked) == 0 && ::stat(path.c_str(), &now) == 0 && locked.st_ino == now.st_ino && locked.st_dev == now.st_dev)
      ::unlink(path.c_str());
    ::close(fd);
  }
  realisation_locks_.clear();
  release_folder_lock(lock_path_, lock_fd_);
}

FolderLock::FolderLock(const fs::path& folder, bool shared) : shared_(shared) {
  const fs::path out = resolved_folder(folder);
  path_ = lock_path_of(out);
  // A folder no one may write beside (a read-only copy, another user's): nothing can replace it through
  // this lock, and reading it needs none.
  if (::access(out.parent_path().c_str(), W_OK) != 0 && (errno == EROFS || errno == EACCES || errno == EPERM)) return;
  fd_ = take_folder_lock(path_, out, shared, false);
}

FolderLock::~FolderLock() { release_folder_lock(path_, fd_, shared_); }

// Under the lock every staging or old folder of OUT belongs to a run that is gone.
void Staging::recover() {
  const std::string staging_prefix = "." + name_ + ".spadgen-staging-", old_prefix = "." + name_ + ".spadgen-old-";
  std::vector<fs::path> leftovers, olds;
  for (const auto& e : fs::directory_iterator(parent_)) {
    const std::string n = e.path().filename().string();
    if (starts_with(n, staging_prefix)) leftovers.push_back(e.path());
    if (starts_with(n, old_prefix)) olds.push_back(e.path());
  }
  std::error_code ec;
  if (!olds.empty() && !fs::exists(out_, ec)) {
    // A run was killed between renaming the earlier set aside and renaming its own in: the earlier set
    // is complete, so it goes back.
    fs::path latest = olds.front();
    for (const fs::path& o : olds)
      if (fs::last_write_time(o, ec) > fs::last_write_time(latest, ec)) latest = o;
    int err = step("restore old");
    if (!err && ::rename(latest.c_str(), out_.c_str()) != 0) err = errno;
    if (err)
      throw Error("cannot use " + out_.string() + " as the output folder (-o): a killed run left its earlier files in " +
                  latest.string() + ", and renaming them back failed: " + std::strerror(err));
    sync_dir(parent_);
    olds.erase(std::find(olds.begin(), olds.end(), latest));
  }
  for (const std::vector<fs::path>* list : {&leftovers, &olds})
    for (const fs::path& p : *list) fs::remove_all(p, ec);
  // Staging folders inside OUT, left by spadgen versions before this scheme, of processes that are gone.
  if (fs::is_directory(out_, ec))
    for (const auto& e : fs::directory_iterator(out_)) {
      const std::string n = e.path().filename().string();
      if (!starts_with(n, kOldStylePrefix)) continue;
      const long pid = std::strtol(n.c_str() + kOldStylePrefix.size(), nullptr, 10);
      if (pid > 0 && ::kill(pid_t(pid), 0) != 0 && errno == ESRCH) fs::remove_all(e.path(), ec);
    }
}

namespace {
// True when a folder holds no file, however deep: only folders (a/b/ as an empty a/).
bool holds_no_file(const fs::path& dir) {
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (it->is_symlink(ec) || !it->is_directory(ec)) return false;
  return !ec;
}
}  // namespace

// A run replaces OUT as a whole, so OUT may hold only what an earlier run wrote there, and what
// reconstruct and evaluate derived from it there.
std::vector<std::string> Staging::foreign_entries(const fs::path& folder_out, bool of_runs,
                                                  const std::vector<std::string>& owned) {
  std::error_code ec;
  if (!fs::is_directory(folder_out, ec)) return {};
  Listed listed;  // another command's folder holds its own files only (a run folder given to it is not its own)
  // The run folders a sense --repeats writes (repeat_NNN, with their metadata.json): each holds the files
  // its own metadata.json lists. Any other folder inside, a run's or not, is someone else's.
  std::set<std::string> repeats;
  if (of_runs || owned.empty()) {
    // A run and a folder of runs (sense --repeats) replace each other: a run folder's listed files, or a
    // folder of runs' run folders, are spadgen's either way (each refused the other as foreign files).
    if (fs::is_regular_file(folder_out / "metadata.json", ec)) listed = listed_files(folder_out);
    else
      for (const auto& e : fs::directory_iterator(folder_out)) {
        const std::string n = e.path().filename().string();
        if (n.size() > 7 && starts_with(n, "repeat_") && std::all_of(n.begin() + 7, n.end(), [](char c) { return c >= '0' && c <= '9'; }) &&
            e.is_directory(ec) && !e.is_symlink(ec) && fs::is_regular_file(e.path() / "metadata.json", ec))
          repeats.insert(n);
      }
  } else {
    listed.entries = {owned.begin(), owned.end()};
  }
  std::vector<std::string> foreign;
  // The entries of a run folder `root` (OUT, or one of its repeat_NNN) that `of_root` does not list.
  const auto walk = [&](const fs::path& root, const Listed& of_root, const auto& self) -> void {
    std::vector<fs::path> folders{root};
    while (!folders.empty() && foreign.size() < 6) {
      const fs::path folder = folders.back();
      folders.pop_back();
      for (const auto& e : fs::directory_iterator(folder)) {
        const std::string rel = e.path().lexically_relative(root).string();
        const bool top = folder == root, out = root == folder_out;
        // (derived outputs of a run folder: reconstruct's and evaluate's, by their content, and an interrupted
        // evaluate's staging folder and lock; not a user's file of such a name, nor beside no run's metadata.json)
        const bool run_root = of_root.entries.count("metadata.json") > 0;
        if (top && ((run_root && (is_spadgen_derived_output(e.path(), rel) || starts_with(rel, ".evaluation.spadgen-"))) ||
                    (out && starts_with(rel, kOldStylePrefix))))
          continue;
        // a run folder's lock file inside (a sense of a run in OUT leaves its reader's lock): spadgen's, no data
        if (top && rel.size() > 1 && rel[0] == '.' && rel.ends_with(".spadgen-lock") && e.is_regular_file(ec) && e.file_size(ec) < 64)
          continue;
        // a derived output's temporary file (writers' ".NAME.tmp-PID-N"), left by a reconstruct killed while it
        // wrote: the swap removes it with the folder (it made every later run refuse the folder)
        if (const size_t t = rel.find(".tmp-"); top && run_root && rel.size() > 1 && rel[0] == '.' && t != std::string::npos &&
                                                  is_derived_output(rel.substr(1, t - 1)))
          continue;
        const bool dir = e.is_directory(ec) && !e.is_symlink(ec);
        if (dir && holds_no_file(e.path())) continue;  // nothing to lose (folders only, empty at their ends)
        if (dir && top && out && repeats.count(rel)) {  // a realisation's run folder: its own files only
          self(e.path(), listed_files(e.path()), self);
          continue;
        }
        if (of_runs && top && out && starts_with(rel, ".repeat_")) continue;  // an earlier version's per-run leftovers
        const bool entry = of_root.entries.count(rel) > 0;
        if (entry && (!dir || rel.ends_with(".zarr"))) continue;  // a listed file, or a Zarr store with all in it
        if (dir && (entry || of_root.parents.count(rel))) folders.push_back(e.path());
        else foreign.push_back(e.path().lexically_relative(folder_out).string() + (dir ? "/" : ""));
      }
    }
  };
  walk(folder_out, listed, walk);
  return foreign;
}

// A list of at most five of them, for a message.
std::string Staging::foreign_list(const std::vector<std::string>& foreign) {
  std::string list;
  for (size_t i = 0; i < foreign.size() && i < 5; ++i) list += (i ? ", " : "") + foreign[i];
  if (foreign.size() > 5) list += ", ...";
  return list;
}

void Staging::check_owned(bool publishing) const {
  const std::vector<std::string> foreign = foreign_entries(out_);
  if (foreign.empty()) return;
  const std::string list = foreign_list(foreign);
  std::string known = of_runs_ ? "expected only the realisations' folders, repeat_NNN, each with the files its metadata.json lists"
                               : "not listed in its metadata.json";
  // A run folder whose metadata.json cannot be read lists nothing: that is what to say (its own files were
  // called foreign, a damaged or unreadable metadata.json not named)
  if (const Listed l = listed_files(out_); owned_.empty() && !of_runs_ && !l.damaged.empty())
    known = "no metadata.json of spadgen's lists them: " + l.damaged + "; a run folder's metadata.json says which files are spadgen's";
  if (!owned_.empty()) {
    known = "expected only ";
    for (size_t i = 0; i < owned_.size(); ++i) known += (i == 0 ? "" : i + 1 == owned_.size() ? " and " : ", ") + owned_[i];
  }
  if (publishing)
    throw Error("the output folder " + out_.string() + " now holds files that spadgen did not write there, put there " +
                "while " + what_ + " ran (" + list + "; " + known + "); " + what_ + " replaces the whole folder, so " +
                "nothing was published and they are as they were: move them and run again, or choose another folder (-o)");
  throw Error("the output folder " + out_.string() + " holds files that spadgen did not write there (" + list + "; " +
              known + "); " + what_ + " replaces the whole folder, so it does not write into one with other files: "
              "move them, or choose another folder (-o)");
}

void Staging::publish(const std::vector<std::string>& files) {
  if (sub_) throw std::logic_error("publish: a subfolder is published by its parent");
  for (const std::string& f : files)  // files, and the folders of Zarr stores
    if (!fs::is_regular_file(dir_ / f) && !fs::is_directory(dir_ / f))
      throw std::logic_error("publish: " + f + " was not written to the staging folder");
  // A signal that arrived after the last long loop (the stacks' fsyncs take seconds) still stops the run.
  throw_if_interrupted();
  // Files put into the output folder while the run ran would go with the earlier set.
  check_owned(true);
  // Subfolders nothing was written into (no previews, no light/) do not go out.
  prune_subfolders();
  sync_dir(dir_);
  const auto fail = [&](const std::string& what, int err) {
    return Error("cannot publish into " + out_.string() + ": " + what + ": " + std::strerror(err) +
                 "; the output folder holds its earlier files");
  };
  std::error_code ec;
  fs::path earlier;  // where the earlier set is once the new one is in place
  if (!fs::exists(out_, ec)) {
    int err = step("rename staging");
    if (!err && ::rename(dir_.c_str(), out_.c_str()) != 0) err = errno;
    if (err) throw fail("renaming " + dir_.string() + " to " + out_.string(), err);
  } else {
    int err = step("exchange");
    if (!err && ::renameat2(AT_FDCWD, dir_.c_str(), AT_FDCWD, out_.c_str(), RENAME_EXCHANGE) != 0) err = errno;
    if (err == 0) {
      earlier = dir_;
    } else if (err == EINVAL || err == ENOSYS || err == EOPNOTSUPP) {
      // No atomic exchange on this file system: two renames, the earlier set kept aside until the second
      // one has succeeded.
      const fs::path old = parent_ / ("." + name_ + ".spadgen-old-" + pid_text());
      err = step("rename out to old");
      if (!err && ::rename(out_.c_str(), old.c_str()) != 0) err = errno;
      if (err) throw fail("renaming " + out_.string() + " aside to " + old.string(), err);
      err = step("rename staging to out");
      if (!err && ::rename(dir_.c_str(), out_.c_str()) != 0) err = errno;
      if (err) {
        int back = step("restore old");
        if (!back && ::rename(old.c_str(), out_.c_str()) != 0) back = errno;
        if (back)
          throw Error("cannot publish into " + out_.string() + ": renaming " + dir_.string() + " to it: " +
                      std::strerror(err) + "; and renaming its earlier files back from " + old.string() +
                      " failed too (" + std::strerror(back) + "): the next run into this folder renames them back");
        throw fail("renaming " + dir_.string() + " to " + out_.string(), err);
      }
      earlier = old;
    } else {
      throw fail("exchanging " + dir_.string() + " with " + out_.string(), err);
    }
  }
  sync_dir(parent_);
  if (earlier.empty()) return;
  // The new set is in place; the earlier one goes, unless a file was put into the output folder between
  // the check above and the swap: then it is kept, in a visible folder beside it that no run removes.
  if (const std::vector<std::string> foreign = foreign_entries(earlier); !foreign.empty()) {
    // A name no other folder has (a container's runs often have the same pid), never replacing one.
    fs::path keep;
    for (int i = 0; i < 1000 && keep.empty(); ++i) {
      const fs::path k = parent_ / (name_ + ".spadgen-earlier-" + pid_text() + (i ? "-" + std::to_string(i) : std::string()));
      if (::renameat2(AT_FDCWD, earlier.c_str(), AT_FDCWD, k.c_str(), RENAME_NOREPLACE) == 0) keep = k;
      else if (errno != EEXIST && errno != ENOTEMPTY) break;
    }
    if (keep.empty()) {
      // Left where it is: not removed by this run (the staging folder's name after the exchange), but a later
      // run into the folder removes what lies under spadgen's hidden names.
      if (earlier == dir_) dir_.clear();
      std::fprintf(stderr, "spadgen: warning: files not spadgen's were put into %s as %s published its outputs there (%s): "
                   "the folder's earlier contents, with them, are in %s, which could not be renamed to a visible name: "
                   "move them out of it before the next run into %s, which removes it\n", out_.c_str(), what_.c_str(),
                   foreign_list(foreign).c_str(), earlier.c_str(), out_.c_str());
      return;
    }
    sync_dir(parent_);
    std::fprintf(stderr, "spadgen: warning: files not spadgen's were put into %s as %s published its outputs there (%s): "
                 "the folder's earlier contents, with them, are in %s\n", out_.c_str(), what_.c_str(),
                 foreign_list(foreign).c_str(), keep.c_str());
    return;
  }
  // If that fails, the next run into the folder removes it again.
  if (step("remove old") == 0 && (fs::remove_all(earlier, ec), ec))
    std::fprintf(stderr, "spadgen: warning: the earlier contents of %s, kept in %s, could not be removed (%s); the next run "
                 "into the folder tries again\n", out_.c_str(), earlier.c_str(), ec.message().c_str());
}

}  // namespace spadgen::app
