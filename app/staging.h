// Atomic output: a run writes every file into a staging folder beside the output folder and, only when
// the whole run has succeeded, swaps that folder in for the output folder as one unit. The folder
// therefore holds either the complete earlier set of files or the complete new one, never a mix, never
// a stale file of an earlier run; a failed or interrupted run leaves the earlier set as it was.
//
// How (docs/outputs.md, "The output folder"), for an output folder OUT in folder P:
// - P/.OUT.spadgen-lock is locked (flock) for the whole run: a second run into OUT refuses at once.
// - The run writes into P/.OUT.spadgen-staging-<pid>.
// - Publishing exchanges the staging folder and OUT in one renameat2(RENAME_EXCHANGE), then removes the
//   earlier set. Where the file system cannot exchange, OUT is renamed to P/.OUT.spadgen-old-<pid> and the
//   staging folder to OUT (the earlier set is renamed back if that fails); between the two renames OUT
//   is briefly absent, never mixed.
// - Under the lock, leftovers of killed runs are removed, and an OUT that a killed run left renamed away
//   is renamed back.
// - OUT must hold only what spadgen wrote there (metadata.json and the files it lists): a folder with
//   other files in it is refused rather than replaced.
#pragma once
#include <sys/types.h>

#include <nlohmann/json_fwd.hpp>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/error.h"

namespace spadgen::app {

// An output folder as Staging and FolderLock name it: absolute, "out/" as "out", ".." taken as the path
// names it (lexically), then through a symbolic link to a folder the folder.
std::filesystem::path resolved_folder(const std::filesystem::path& out);

// A path an output records (metadata.json, metrics.json, an EXR's spadgen_source hold it as JSON text) must
// be valid UTF-8 as it is recorded (made absolute, or as given): else an Error naming it (escaped) as `what`
// ("the run folder"), with `why` ("which the detections file records"), before any work (it failed after the
// work, an internal error).
void require_utf8_path(const std::filesystem::path& path, const std::string& what, const std::string& why, bool absolute = true);

// Whether `folder` holds a spadgen run's metadata.json (one naming spadgen_version; another tool's is not read
// beyond 16 MiB).
bool is_run_folder(const std::filesystem::path& folder);

// The folders whose contents spadgen checks (a later run into the folder, or a dataset's check of its samples,
// refuses one holding a foreign file or folder), which an output folder must not be placed inside.
enum class CheckedFolder { Run, Dataset, RepeatSet };
// Throws spadgen::Error, naming `option` (e.g. "-o out/x") and the folder, when `out` lies inside a run folder,
// a folder of sense --repeats' realisations, or a dataset's own entries (samples/, failed/, evaluation/, ...),
// the nearest such folder above it deciding, unless allowed(kind, folder, out relative to folder) says it is
// that folder's own place (a dataset's sample, a run's evaluation/).
void refuse_output_inside(const std::filesystem::path& out, const std::string& option,
                          const std::function<bool(CheckedFolder, const std::filesystem::path&, const std::filesystem::path&)>& allowed = nullptr);

// refuse_output_inside for the folder of a run or a sense (`given`: named by -o, else the default), which a
// dataset writes into its samples/NAME (`dataset_sample`); a set's direct child is left to Staging, whose
// message says what the set is and how to write it again.
void refuse_run_folder_inside(const std::filesystem::path& out, bool given, bool dataset_sample);

class Staging {
 public:
  // Fault injection for tests: called before each file-system step of publishing and recovery with the
  // step's name ("exchange", "rename out to old", "rename staging to out", "restore old", "remove old",
  // "rename staging"); a non-zero return is taken as the errno of that step's failure.
  using Hook = std::function<int(const std::string& step)>;

  // Creates the output folder's parent if needed, takes the lock, cleans up after killed runs and
  // creates the staging folder. Throws spadgen::Error when the output folder cannot be used, is locked
  // by another run, or holds files spadgen did not write.
  explicit Staging(const std::filesystem::path& out, Hook hook = nullptr);
  // A folder of another command's files (`spadgen evaluate`'s): the folder may hold only the files named in
  // `owned` (a run folder is not replaced by it); `what` names it in messages ("an evaluation").
  Staging(const std::filesystem::path& out, std::vector<std::string> owned, std::string what);
  // A folder of run folders (`spadgen sense --repeats`: repeat_000/, ...), published as one: it may hold
  // only run folders (each with its metadata.json) and empty folders.
  struct OfRuns {};
  Staging(const std::filesystem::path& out, OfRuns);
  // Subfolder `sub` of `parent`'s staging folder, for one run of a folder of runs: path() as for a folder of
  // its own; no lock, no publishing (the parent publishes it with the rest), removed with the parent's.
  Staging(const Staging& parent, const std::string& sub);
  ~Staging();  // removes the staging folder unless published, and releases the lock
  Staging(const Staging&) = delete;
  Staging& operator=(const Staging&) = delete;

  // Where the file `rel` (relative to the output folder) is written until it is published.
  std::string path(const std::string& rel) const;
  // Replaces the output folder with the staging folder, which must hold every listed file. Throws
  // spadgen::Error when the swap fails; the output folder then holds the earlier set.
  void publish(const std::vector<std::string>& files);
  // A subfolder's: removes the folders nothing was written into (previews/, light/), as publish() does.
  void finish_sub() const;
  // Removes what killed runs left in `parent` (the staging folders of its output folders, and lock files no
  // process holds), each under its output folder's lock: one that another run is writing is left to it.
  static void remove_leftovers(const std::filesystem::path& parent);
  // The output folder, absolute, with symbolic links resolved.
  const std::filesystem::path& out() const { return out_; }
  // What a run (Staging(folder)) would refuse in the run folder `folder`: the entries it did not write there
  // (at most six, relative to it), and them as a message's list. Reads only.
  static std::vector<std::string> foreign_in_run_folder(const std::filesystem::path& folder) {
    return foreign_entries(folder, false, {});
  }
  static std::string foreign_list(const std::vector<std::string>& foreign);

 private:
  int step(const std::string& name) const { return hook_ ? hook_(name) : 0; }
  void refuse_a_realisation_or_a_folder_being_written() const;
  void lock();
  void unlock();
  void recover();
  void init(const std::filesystem::path& out);
  // Throws spadgen::Error naming foreign_entries(out_), if any (publishing: put there during the run).
  void check_owned(bool publishing = false) const;
  // The entries of `folder` (the output folder, or its earlier set once exchanged) spadgen did not write.
  std::vector<std::string> foreign_entries(const std::filesystem::path& folder) const {
    return foreign_entries(folder, of_runs_, owned_);
  }
  // The same for a folder of run folders (of_runs) or of the files `owned` (none: a run folder).
  static std::vector<std::string> foreign_entries(const std::filesystem::path& folder, bool of_runs,
                                                  const std::vector<std::string>& owned);
  void prune_subfolders() const;  // the subfolders nothing was written into go; the others are made durable

  std::filesystem::path out_, parent_, dir_, lock_path_;
  std::string name_;
  Hook hook_;
  std::vector<std::string> owned_;
  bool of_runs_ = false;  // a folder of run folders
  bool sub_ = false;      // a parent's subfolder: nothing of its own to lock, remove or publish
  std::string what_ = "a run";  // in messages: "... replaces the output folder as a whole"
  int lock_fd_ = -1;
  // The parent folder as init found it (st_dev, st_ino): the destructor tells one moved or removed meanwhile
  dev_t parent_dev_ = 0;
  ino_t parent_ino_ = 0;
  // the locks of the realisations of a sense --repeats set being replaced (lock file, fd)
  std::vector<std::pair<std::filesystem::path, int>> realisation_locks_;
};

// What became of the last staging folder a Staging could not remove because its parent folder was moved or
// removed while it was written, in words ("" when none): it and the lock file went with the parent (the
// message of the error that ends the command says so).
std::string staging_parent_moved();

// R when a run folder's metadata.json says it is one of the R > 1 realisations of a `sense --repeats` set
// (sense.repeats), else 0.
int64_t realisations_of(const nlohmann::json& metadata);

// The error of a folder whose lock another spadgen process holds (a run writing it, a reader of it): a dataset
// run waits for such a sample and tries it again, as for one another dataset run generates.
class FolderBusy : public spadgen::Error {
 public:
  using Error::Error;
};

// The output folder's lock alone (the one a run holds while it writes and replaces the folder), for a
// command that reads a run folder and writes a file into it (reconstruct): while it is held no run replaces
// the folder (a reconstruct while a run replaced it wrote the earlier run's detections beside the new run's
// counts), and a run or another such command refuses, naming the holder.
class FolderLock {
 public:
  // shared: a reader's (sense of a run), which other readers may hold too, but not a run replacing the folder.
  explicit FolderLock(const std::filesystem::path& folder, bool shared = false);
  ~FolderLock();
  FolderLock(const FolderLock&) = delete;
  FolderLock& operator=(const FolderLock&) = delete;

 private:
  std::filesystem::path path_;
  int fd_ = -1;
  bool shared_ = false;
};

}  // namespace spadgen::app
