// The publish step under fault injection (app/staging.h): a failure at every file-system step, a crash
// at every step (a child process that dies there), with and without the atomic exchange, a second run,
// files in the way. After each, the output folder holds the complete earlier set or the complete new set.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "app/staging.h"
#include "core/error.h"

namespace {
namespace fs = std::filesystem;
using spadgen::app::FolderLock;
using spadgen::app::Staging;
using ::testing::HasSubstr;

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A set of files as a run writes them: each file's content names the set, and metadata.json (spadgen's: with
// spadgen_version) lists them.
// The two sets differ in their files (the new one has fewer), so that a mix shows.
const std::vector<std::string> kOldFiles = {"counts.npy", "frames.npy", "laser.exr", "previews/depth.png"};
const std::vector<std::string> kNewFiles = {"counts.npy", "laser.exr", "previews/intensity.png"};

std::vector<std::string> write_set(const std::function<std::string(const std::string&)>& path_of, const std::string& tag,
                                   const std::vector<std::string>& files) {
  std::vector<std::string> listed = files;
  listed.push_back("metadata.json");
  for (const std::string& f : files) {
    fs::create_directories(fs::path(path_of(f)).parent_path());
    std::ofstream(path_of(f)) << tag << ":" << f;
  }
  std::ofstream(path_of("metadata.json")) << nlohmann::json({{"spadgen_version", "test"}, {"set", tag}, {"files", listed}}).dump();
  return listed;
}

// "old" or "new" when `out` holds exactly that set, complete; else a description of the mix.
std::string which_set(const fs::path& out) {
  if (!fs::is_directory(out)) return "no folder";
  const auto meta = nlohmann::json::parse(slurp(out / "metadata.json"), nullptr, false);
  if (!meta.is_object()) return "no metadata.json";
  const std::string tag = meta["set"];
  std::set<std::string> listed;
  for (const auto& f : meta["files"]) listed.insert(f.get<std::string>());
  for (const auto& e : fs::recursive_directory_iterator(out)) {
    if (e.is_directory()) continue;
    const std::string rel = fs::relative(e.path(), out).string();
    if (!listed.count(rel)) return "stray " + rel + " beside the " + tag + " set";
    if (rel != "metadata.json" && slurp(e.path()) != tag + ":" + rel) return rel + " is not of the " + tag + " set";
  }
  for (const std::string& f : listed)
    if (!fs::exists(out / f)) return f + " of the " + tag + " set is missing";
  return tag;
}

class StagingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("spadgen_staging_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" +
            std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    out_ = dir_ / "out";
  }
  void TearDown() override { fs::remove_all(dir_); }
  void write_old() {
    fs::create_directories(out_);
    write_set([&](const std::string& f) { return (out_ / f).string(); }, "old", kOldFiles);
  }
  // One run that writes the new set and publishes it; failures are swallowed (the folder is what counts).
  void run(const Staging::Hook& hook, std::string* error = nullptr) {
    try {
      Staging s(out_, hook);
      const auto files = write_set([&](const std::string& f) { return s.path(f); }, "new", kNewFiles);
      s.publish(files);
    } catch (const spadgen::Error& e) {
      if (error) *error = e.what();
    }
  }
  // Nothing of a run is left beside the output folder.
  void expect_no_leftovers() {
    for (const auto& e : fs::directory_iterator(dir_)) EXPECT_EQ(e.path().filename(), "out") << e.path();
  }
  fs::path dir_, out_;
};

// The steps one publish goes through, in order, with the exchange available or not.
std::vector<std::string> steps_of(const fs::path& dir, bool exchange) {
  const fs::path out = dir / "probe";
  fs::create_directories(out);
  write_set([&](const std::string& f) { return (out / f).string(); }, "old", kOldFiles);
  std::vector<std::string> steps;
  {
    Staging s(out, [&](const std::string& step) {
      steps.push_back(step);
      return !exchange && step == "exchange" ? EINVAL : 0;
    });
    s.publish(write_set([&](const std::string& f) { return s.path(f); }, "new", kNewFiles));
  }
  fs::remove_all(out);
  return steps;
}

TEST_F(StagingTest, PublishingReplacesTheWholeSet) {
  write_old();
  run(nullptr);
  EXPECT_EQ(which_set(out_), "new");
  EXPECT_FALSE(fs::exists(out_ / "frames.npy"));  // not in the new set: gone, not stale
  expect_no_leftovers();
  // Into a folder that does not exist yet.
  fs::remove_all(out_);
  run(nullptr);
  EXPECT_EQ(which_set(out_), "new");
  expect_no_leftovers();
}

TEST_F(StagingTest, AFailureAtEveryStepLeavesTheOldOrTheNewSet) {
  for (const bool exchange : {true, false}) {
    const std::vector<std::string> steps = steps_of(dir_, exchange);
    const std::vector<std::string> expected =
        exchange ? std::vector<std::string>{"exchange", "remove old"}
                 : std::vector<std::string>{"exchange", "rename out to old", "rename staging to out", "remove old"};
    ASSERT_EQ(steps, expected);
    for (size_t k = 0; k < steps.size(); ++k) {
      // Fail at step k (EIO), and in the fallback also the renaming back when the new set's rename fails.
      for (const bool restore_fails : {false, true}) {
        fs::remove_all(out_);
        write_old();
        size_t at = 0;
        std::string error;
        run([&](const std::string& step) {
          if (!exchange && step == "exchange") {
            ++at;  // the fallback's first step, as steps_of() counts it
            return EINVAL;
          }
          if (step == "restore old") return restore_fails ? EIO : 0;
          return at++ == k ? EIO : 0;
        }, &error);
        const std::string where = std::string(exchange ? "exchange" : "two renames") + ", failure at " + steps[k] +
                                  (restore_fails ? " and at restore old" : "");
        std::string set = which_set(out_);
        if (restore_fails && set == "no folder") {
          // Both renames failed: the earlier set lies aside, and the next run puts it back.
          EXPECT_THAT(error, HasSubstr("the next run into this folder renames them back")) << where;
          Staging repair(out_);
          set = which_set(out_);
          EXPECT_EQ(set, "old") << where;
        }
        EXPECT_TRUE(set == "old" || set == "new") << where << ": " << set;
        // A failure before the new set is in place keeps the old one, and says so.
        if (set == "old" && !restore_fails) {
          EXPECT_THAT(error, HasSubstr("the output folder holds its earlier files")) << where;
        }
        Staging next(out_);  // leftovers of the failed publish go with the next run
        EXPECT_EQ(which_set(out_), set) << where;
      }
    }
  }
}

// A crash (the process dies) at every step: the folder is the old or the new set, or, between the two
// renames of the fallback, absent with the old set aside; the next run puts the old set back.
TEST_F(StagingTest, ACrashAtEveryStepIsRepairedByTheNextRun) {
  for (const bool exchange : {true, false}) {
    const std::vector<std::string> steps = steps_of(dir_, exchange);
    for (const std::string& crash_at : steps) {
      fs::remove_all(out_);
      write_old();
      const pid_t child = ::fork();
      ASSERT_GE(child, 0);
      if (child == 0) {
        std::string error;
        run([&](const std::string& step) {
          if (step == crash_at) ::_exit(9);  // killed: no destructor, no clean-up, the lock released by the kernel
          return !exchange && step == "exchange" ? EINVAL : 0;
        }, &error);
        std::fprintf(stderr, "the child did not crash: %s\n", error.c_str());
        ::_exit(0);
      }
      int status = 0;
      ASSERT_EQ(::waitpid(child, &status, 0), child);
      ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 9) << crash_at;
      const std::string where = std::string(exchange ? "exchange" : "two renames") + ", crash at " + crash_at;
      const std::string before = which_set(out_);
      EXPECT_TRUE(before == "old" || before == "new" || (!exchange && crash_at == "rename staging to out" && before == "no folder"))
          << where << ": " << before;
      { Staging next(out_); }  // takes the lock, repairs, cleans; publishes nothing
      const std::string after = which_set(out_);
      EXPECT_TRUE(after == "old" || after == "new") << where << ": " << after;
      if (before != "no folder") {
        EXPECT_EQ(after, before) << where;
      }
      expect_no_leftovers();
    }
  }
}

TEST_F(StagingTest, OneRunAtATimePerFolder) {
  write_old();
  std::string error;
  {
    Staging first(out_);
    run(nullptr, &error);
    // (both in this process: the lock is said to be its own, as a folder reached twice by a bind mount is; two
    // processes are Hardening's and Sense's tests)
    EXPECT_THAT(error, HasSubstr("cannot use " + out_.string() + " as the output folder (-o): its lock file " +
                                 (dir_ / ".out.spadgen-lock").string() + " is held by this spadgen process itself (pid " +
                                 std::to_string(::getpid()) + ")"));
    EXPECT_EQ(which_set(out_), "old");
    // Another folder in the same parent is not affected.
    Staging other(dir_ / "other");
  }
  run(nullptr);
  EXPECT_EQ(which_set(out_), "new");
  expect_no_leftovers();  // the lock file went with the run that held it
  // a reader's shared lock (a sense of the run) writes no pid into the file: the holder is found in /proc/locks
  {
    const FolderLock reader(out_, true);
    run(nullptr, &error);
    EXPECT_THAT(error, HasSubstr("is held by this spadgen process itself (pid " + std::to_string(::getpid()) + ")"));
  }
}

TEST_F(StagingTest, AFolderWithFilesSpadgenDidNotWriteIsNotReplaced) {
  write_old();
  std::ofstream(out_ / "notes.txt") << "mine";
  fs::create_directories(out_ / "analysis");
  std::ofstream(out_ / "analysis/fit.csv") << "1,2";
  std::string error;
  run(nullptr, &error);
  EXPECT_THAT(error, HasSubstr("holds files that spadgen did not write there ("));
  EXPECT_THAT(error, HasSubstr("notes.txt"));
  EXPECT_THAT(error, HasSubstr("analysis/"));
  EXPECT_EQ(slurp(out_ / "notes.txt"), "mine");
  EXPECT_EQ(slurp(out_ / "counts.npy"), "old:counts.npy");
  // An empty folder is nobody's data: it is replaced; so is one holding only empty folders (a/b/ was
  // refused as "a/" while a/ alone was taken), not one with a file deep inside.
  fs::remove_all(out_);
  fs::create_directories(out_ / "a" / "b");
  error.clear();
  run(nullptr, &error);
  EXPECT_EQ(error, "");
  EXPECT_EQ(which_set(out_), "new");
  fs::remove_all(out_);
  fs::create_directories(out_ / "a" / "b");
  std::ofstream(out_ / "a" / "b" / "data.bin") << "x";
  run(nullptr, &error);
  EXPECT_THAT(error, HasSubstr("(a/;"));
  EXPECT_EQ(slurp(out_ / "a" / "b" / "data.bin"), "x");
}

// The folder is checked again as the run publishes: a file put there while the run ran (into the earlier
// set, or into a folder that did not exist when the run began) stops the publish, the file as it was (the
// swap removed it with the earlier set); one put there after that check, as the swap happens, is kept with
// the earlier set in a visible folder beside it. A signal that arrives once the files are written stops the
// publish too (it was published, exit 0).
TEST_F(StagingTest, FilesPutIntoTheFolderWhileTheRunRanAreNotRemoved) {
  write_old();
  const auto publish_after = [&](const std::function<void()>& meanwhile, const Staging::Hook& hook = nullptr) {
    std::string error;
    try {
      Staging s(out_, hook);
      const auto files = write_set([&](const std::string& f) { return s.path(f); }, "new", kNewFiles);
      meanwhile();
      s.publish(files);
    } catch (const spadgen::Error& e) {
      error = e.what();
    }
    return error;
  };
  std::string error = publish_after([&] { std::ofstream(out_ / "analysis.txt") << "mine"; });
  EXPECT_THAT(error, HasSubstr("now holds files that spadgen did not write there, put there while a run ran (analysis.txt;"));
  EXPECT_THAT(error, HasSubstr("nothing was published"));
  EXPECT_EQ(slurp(out_ / "analysis.txt"), "mine");
  EXPECT_EQ(slurp(out_ / "counts.npy"), "old:counts.npy");
  expect_no_leftovers();
  fs::remove_all(out_);
  error = publish_after([&] {
    fs::create_directories(out_);
    std::ofstream(out_ / "thesis.tex") << "draft";
  });
  EXPECT_THAT(error, HasSubstr("(thesis.tex;"));
  EXPECT_EQ(slurp(out_ / "thesis.tex"), "draft");
  expect_no_leftovers();
  // Between the check and the swap.
  fs::remove_all(out_);
  write_old();
  error = publish_after([] {}, [&](const std::string& step) {
    if (step == "exchange") std::ofstream(out_ / "late.txt") << "late";
    return 0;
  });
  EXPECT_EQ(error, "");
  EXPECT_EQ(which_set(out_), "new");
  const fs::path kept = dir_ / ("out.spadgen-earlier-" + std::to_string(::getpid()));
  EXPECT_EQ(slurp(kept / "late.txt"), "late");
  EXPECT_EQ(slurp(kept / "counts.npy"), "old:counts.npy");
  // again, that folder still there (a container's runs have the same pid): a name of its own, neither
  // replacing it nor lost (the rename failed and the earlier set was removed with the staging folder)
  fs::remove_all(out_);
  write_old();
  error = publish_after([] {}, [&](const std::string& step) {
    if (step == "exchange") std::ofstream(out_ / "later.txt") << "later";
    return 0;
  });
  EXPECT_EQ(error, "");
  EXPECT_EQ(slurp(kept / "late.txt"), "late");
  EXPECT_EQ(slurp(fs::path(kept.string() + "-1") / "later.txt"), "later");
  fs::remove_all(kept.string() + "-1");
  // A signal once every file is written.
  fs::remove_all(kept);
  fs::remove_all(out_);
  write_old();
  try {
    Staging s(out_);
    const auto files = write_set([&](const std::string& f) { return s.path(f); }, "new", kNewFiles);
    spadgen::interrupt_flag().store(true);
    EXPECT_THROW(s.publish(files), spadgen::Interrupted);
  } catch (...) {
  }
  spadgen::interrupt_flag().store(false);
  EXPECT_EQ(which_set(out_), "old");
  expect_no_leftovers();
}

// A Zarr store (a folder ending .zarr that metadata.json lists) is the run's with everything in it, so a
// new run replaces it; a listed folder of another name is looked into, and files beside a store are not
// the run's.
TEST_F(StagingTest, AListedZarrStoreIsTheRunsWhole) {
  write_old();
  fs::create_directories(out_ / "counts.zarr");
  std::ofstream(out_ / "counts.zarr/0.0.0") << "chunk";
  std::ofstream(out_ / "counts.zarr/.zarray") << "{}";
  fs::create_directories(out_ / "previews/notes");
  std::ofstream(out_ / "previews/notes/mine.txt") << "mine";
  auto meta = nlohmann::json::parse(slurp(out_ / "metadata.json"));
  meta["files"].push_back("counts.zarr");
  meta["files"].push_back("previews/notes");
  std::ofstream(out_ / "metadata.json") << meta.dump();
  std::string error;
  run(nullptr, &error);
  EXPECT_THAT(error, HasSubstr("previews/notes/mine.txt"));
  EXPECT_THAT(error, ::testing::Not(HasSubstr("counts.zarr")));
  fs::remove_all(out_ / "previews/notes");
  std::ofstream(out_ / "counts.zarr.txt") << "mine";
  error.clear();
  run(nullptr, &error);
  EXPECT_THAT(error, HasSubstr("counts.zarr.txt"));
  fs::remove(out_ / "counts.zarr.txt");
  error.clear();
  run(nullptr, &error);
  EXPECT_EQ(error, "");
  EXPECT_EQ(which_set(out_), "new");
}

TEST_F(StagingTest, PathsThatCannotBeTheOutputFolder) {
  std::ofstream(dir_ / "a_file") << "x";
  for (const fs::path& p : {dir_ / "a_file", dir_ / "a_file" / "sub", fs::path("/")}) {
    try {
      Staging s(p);
      ADD_FAILURE() << p;
    } catch (const spadgen::Error& e) {
      EXPECT_THAT(std::string(e.what()), HasSubstr("cannot use " + p.string() + " as the output folder (-o)"));
    }
  }
  EXPECT_EQ(slurp(dir_ / "a_file"), "x");
  // The current folder: replacing it would leave the shell in a removed folder.
  fs::create_directories(out_);
  const fs::path cwd = fs::current_path();
  fs::current_path(out_);
  try {
    Staging s(".");
    ADD_FAILURE() << "the current folder was accepted";
  } catch (const spadgen::Error& e) {
    EXPECT_THAT(std::string(e.what()), HasSubstr("it is the current folder or holds it"));
  }
  fs::current_path(cwd);
  // a name the file system takes, but not with the staging folder's 25 more bytes
  try {
    Staging s(dir_ / std::string(240, 'a'));
    ADD_FAILURE() << "a name of 240 bytes was accepted";
  } catch (const spadgen::Error& e) {
    EXPECT_THAT(std::string(e.what()), HasSubstr("its name is 240 bytes long; spadgen first writes into a hidden folder beside "
                                                 "it whose name adds 25 bytes to it, so expected a name of at most 230 bytes"));
  }
  EXPECT_NO_THROW(Staging(dir_ / std::string(230, 'a')));
  // a path whose files' paths would pass the system's limit (PATH_MAX), in folders of 200-byte names
  fs::path deep = dir_;
  while (deep.string().size() + 201 < 3990) deep /= std::string(200, 'd');
  deep /= std::string(3990 - deep.string().size() - 1, 'e');  // 3990 bytes: with /out, 21 past the most
  try {
    Staging s(deep / "out");
    ADD_FAILURE() << "a path of " << (deep / "out").string().size() << " bytes was accepted";
  } catch (const spadgen::Error& e) {
    EXPECT_THAT(std::string(e.what()), HasSubstr("bytes long (resolved), and the files spadgen writes in it need up to 122 more "
                                                 "within the system's limit of 4096 bytes"));
  }
  EXPECT_FALSE(fs::exists(deep / "out"));
}

TEST_F(StagingTest, ALinkToAFolderPublishesIntoTheFolder) {
  write_old();
  fs::create_symlink(out_, dir_ / "link");
  {
    Staging s(dir_ / "link");
    EXPECT_EQ(s.out(), fs::canonical(out_));
    s.publish(write_set([&](const std::string& f) { return s.path(f); }, "new", kNewFiles));
  }
  EXPECT_TRUE(fs::is_symlink(dir_ / "link"));
  EXPECT_EQ(which_set(dir_ / "link"), "new");
}

// A link that leads nowhere is refused when the staging is made, before any work (its publishing would
// fail: a folder cannot be renamed onto a link), and stays as it was.
TEST_F(StagingTest, ALinkThatLeadsNowhereIsRefusedUpFront) {
  fs::create_symlink(dir_ / "nowhere", dir_ / "dangling");
  try {
    Staging s(dir_ / "dangling");
    ADD_FAILURE() << "a dangling link was accepted";
  } catch (const spadgen::Error& e) {
    EXPECT_THAT(std::string(e.what()), HasSubstr("it is a symbolic link to " + (dir_ / "nowhere").string() + ", which does not exist"));
  }
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(dir_ / "dangling")));
  EXPECT_FALSE(fs::exists(dir_ / "nowhere"));
  // two links naming each other: a loop, not a link to a folder that "does not exist"
  fs::create_symlink("loopb", dir_ / "loopa");
  fs::create_symlink("loopa", dir_ / "loopb");
  try {
    Staging s(dir_ / "loopa");
    ADD_FAILURE() << "a loop of links was accepted";
  } catch (const spadgen::Error& e) {
    EXPECT_THAT(std::string(e.what()), HasSubstr("it is a loop of symbolic links (" + (dir_ / "loopa").string() + " -> loopb -> ...)"));
  }
}

}  // namespace
