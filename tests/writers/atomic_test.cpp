#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "core/error.h"
#include "test_util.h"
#include "writers/writers.h"

namespace spadgen::writers {
namespace {

using test::read_bytes;
using test::TempDir;

// Runs f, which must throw spadgen::Error whose message contains every one of `parts`.
template <class F>
void expect_error_naming(F&& f, const std::vector<std::string>& parts) {
  try {
    f();
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    for (const auto& p : parts) EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
  }
}

TEST(Atomic, WriterDestroyedWithoutCommitLeavesNothing) {
  TempDir dir;
  {
    NpyWriter w(dir.file("counts.npy"), NpyWriter::Dtype::U16, {2, 3, 4});
    const uint16_t v = 7;
    w.write(3, &v, 1);
    // While writing, only a hidden temporary named after the file exists.
    const auto entries = dir.entries();
    ASSERT_EQ(entries.size(), 1u);
    EXPECT_EQ(entries[0].rfind(".counts.npy.tmp-" + std::to_string(::getpid()) + "-", 0), 0u) << entries[0];
  }
  EXPECT_TRUE(dir.entries().empty());
}

TEST(Atomic, ExistingFileIsUntouchedUntilCommit) {
  TempDir dir;
  const std::string path = dir.file("expected_counts.npy");
  std::ofstream(path) << "previous run";
  {
    NpyWriter w(path, NpyWriter::Dtype::F32, {4});
    const float v[4] = {1, 2, 3, 4};
    w.write(0, v, 4);
    EXPECT_EQ(read_bytes(path), "previous run");
  }
  EXPECT_EQ(read_bytes(path), "previous run");  // abandoned: the old file stays
  {
    NpyWriter w(path, NpyWriter::Dtype::F32, {4});
    const float v[4] = {1, 2, 3, 4};
    w.write(0, v, 4);
    EXPECT_EQ(read_bytes(path), "previous run");
    w.commit();
    EXPECT_EQ(read_bytes(path).size(), size_t(w.file_bytes()));
  }
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"expected_counts.npy"});
}

TEST(Atomic, MissingFolderThrowsNamingThePath) {
  TempDir dir;
  const std::string path = dir.file("absent/x.npy");
  expect_error_naming([&] { NpyWriter w(path, NpyWriter::Dtype::U8, {1}); }, {path, "No such file or directory"});
  expect_error_naming([&] { write_file_atomic(path, "x"); }, {path, "No such file or directory"});
  expect_error_naming([&] { write_json(path, nlohmann::json::object()); }, {path, "No such file or directory"});
  expect_error_naming([&] { write_png(path, 1, 1, 1, {0}); }, {path, "No such file or directory"});
  EXPECT_TRUE(dir.entries().empty());
}

TEST(Atomic, DestinationThatIsAFolderThrowsAndStays) {
  TempDir dir;
  const std::string path = dir.file("previews");
  std::filesystem::create_directory(path);
  expect_error_naming([&] { write_file_atomic(path, "x"); }, {path, "Is a directory"});
  expect_error_naming([&] { NpyWriter w(path, NpyWriter::Dtype::U8, {1}); }, {path, "Is a directory"});
  EXPECT_TRUE(std::filesystem::is_directory(path));
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"previews"});
}

TEST(Atomic, WriteFileAtomicReplacesContent) {
  TempDir dir;
  const std::string path = dir.file("a.txt");
  write_file_atomic(path, "first");
  write_file_atomic(path, std::string("sec\0nd", 6));
  EXPECT_EQ(read_bytes(path), std::string("sec\0nd", 6));
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"a.txt"});
}

TEST(Atomic, BareFileNameWritesIntoTheWorkingFolder) {
  TempDir dir;
  const auto old = std::filesystem::current_path();
  std::filesystem::current_path(dir.path());
  write_file_atomic("bare.txt", "x");
  std::filesystem::current_path(old);
  EXPECT_EQ(read_bytes(dir.file("bare.txt")), "x");
}

TEST(Atomic, JsonIsPrettyWithTrailingNewlineAndBadUtf8IsAnError) {
  TempDir dir;
  write_json(dir.file("m.json"), nlohmann::json{{"seed", 7}, {"files", {"a.npy"}}});
  EXPECT_EQ(read_bytes(dir.file("m.json")), "{\n  \"files\": [\n    \"a.npy\"\n  ],\n  \"seed\": 7\n}\n");
  const std::string bad = dir.file("bad.json");
  expect_error_naming([&] { write_json(bad, nlohmann::json("\xff\xfe")); }, {bad});
  EXPECT_FALSE(std::filesystem::exists(bad));
}

// The temporary files of a process killed while it wrote (".<name>.tmp-<pid>-<n>" of a pid no longer running)
// go; a running process's (this one's, init's), another name's, and names that only look alike stay.
TEST(Atomic, DeadProcessesTemporariesAreRemovedAndNoOthers) {
  TempDir dir;
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  ASSERT_GT(child, 0);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  const std::string dead = std::to_string(child), me = std::to_string(::getpid());
  const std::vector<std::string> stay = {".x.exr.tmp-" + me + "-3", ".x.exr.tmp-1-0", ".y.exr.tmp-" + dead + "-0",
                                         ".x.exr.tmp-" + dead, ".x.exr.tmp-" + dead + "-a", "x.exr.tmp-" + dead + "-0",
                                         "x.exr"};
  const std::vector<std::string> go = {".x.exr.tmp-" + dead + "-0", ".index.csv.tmp-" + dead + "-12"};
  for (const auto& f : stay) std::ofstream(dir.file(f)) << "s";
  for (const auto& f : go) std::ofstream(dir.file(f)) << "g";
  EXPECT_EQ(remove_dead_temporaries(dir.path().string(), {"x.exr", "index.csv"}), 2);
  for (const auto& f : stay) EXPECT_TRUE(std::filesystem::exists(dir.file(f))) << f;
  for (const auto& f : go) EXPECT_FALSE(std::filesystem::exists(dir.file(f))) << f;
}

}  // namespace
}  // namespace spadgen::writers
