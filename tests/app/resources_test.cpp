// app/resources.h: what the process's memory cgroups allow, read from a cgroup tree made here.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>

#include "app/resources.h"

namespace {
namespace fs = std::filesystem;
using spadgen::app::cgroup_memory_left;

class CgroupTree : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() / ("spadgen_cgroup_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) +
                                         "_" + std::to_string(::getpid()));
    fs::remove_all(root_);
  }
  void TearDown() override { fs::remove_all(root_); }
  void put(const fs::path& rel, const std::string& text) {
    fs::create_directories((root_ / rel).parent_path());
    std::ofstream(root_ / rel) << text << "\n";
  }
  fs::path root_;
};

constexpr int64_t kMiB = 1 << 20;

// cgroup v2: a Slurm job's group two levels down sets 200 MiB; the slice above 1 GiB; the root none. What is
// left is the least of the limits less the usage that cannot be reclaimed (the inactive file cache can).
TEST_F(CgroupTree, AV2GroupBelowTheRootIsRead) {
  put("cgroup.controllers", "cpu memory");
  put("memory.current", std::to_string(5000 * kMiB));  // (the root has no memory.max)
  put("system.slice/memory.max", std::to_string(1024 * kMiB));
  put("system.slice/memory.current", std::to_string(100 * kMiB));
  put("system.slice/slurm/job_7/memory.max", std::to_string(200 * kMiB));
  put("system.slice/slurm/job_7/memory.current", std::to_string(80 * kMiB));
  put("system.slice/slurm/job_7/memory.stat", "anon 123\ninactive_file " + std::to_string(30 * kMiB) + "\nactive_file 9");
  put("system.slice/slurm/memory.max", "max");
  put("system.slice/slurm/memory.current", std::to_string(90 * kMiB));
  EXPECT_EQ(cgroup_memory_left("0::/system.slice/slurm/job_7\n", root_), 150 * kMiB);
  // the slice's limit when it is the tighter: 1024 - 900
  put("system.slice/memory.current", std::to_string(900 * kMiB));
  EXPECT_EQ(cgroup_memory_left("0::/system.slice/slurm/job_7\n", root_), 124 * kMiB);
  // no limit anywhere: none found
  EXPECT_EQ(cgroup_memory_left("0::/\n", root_), -1);
  // a container's namespace: its group is the root, with its own memory.max
  put("memory.max", std::to_string(300 * kMiB));
  EXPECT_EQ(cgroup_memory_left("0::/\n", root_), 0);  // (5000 MiB used of 300: nothing left)
}

// cgroup v1 (this machine kind, many clusters): the memory controller's hierarchy, memory.limit_in_bytes less
// memory.usage_in_bytes less total_inactive_file; v1's "no limit" (2^63 rounded to pages) is no limit. A
// hybrid machine's v2 line reads unified/.
TEST_F(CgroupTree, AV1MemoryGroupIsRead) {
  const std::string unlimited = "9223372036854771712";
  put("memory/memory.limit_in_bytes", unlimited);
  put("memory/memory.usage_in_bytes", std::to_string(8000 * kMiB));
  put("memory/jobs/memory.limit_in_bytes", unlimited);
  put("memory/jobs/memory.usage_in_bytes", std::to_string(500 * kMiB));
  put("memory/jobs/a1/memory.limit_in_bytes", std::to_string(200 * kMiB));
  put("memory/jobs/a1/memory.usage_in_bytes", std::to_string(60 * kMiB));
  put("memory/jobs/a1/memory.stat", "cache 1\ninactive_file 5\ntotal_inactive_file " + std::to_string(10 * kMiB));
  const std::string groups = "12:pids:/jobs\n4:memory:/jobs/a1\n3:cpu,cpuacct:/jobs\n1:name=systemd:/\n0::/\n";
  EXPECT_EQ(cgroup_memory_left(groups, root_), 150 * kMiB);
  EXPECT_EQ(cgroup_memory_left("4:cpuset,memory:/jobs/a1\n", root_), 150 * kMiB);  // (controllers mounted together)
  put("unified/x/memory.max", std::to_string(100 * kMiB));
  put("unified/x/memory.current", std::to_string(40 * kMiB));
  EXPECT_EQ(cgroup_memory_left(groups + "0::/x\n", root_), 60 * kMiB);
  // without the limit: v1's unlimited less the usage, a huge number, not a limit that refuses anything
  EXPECT_GT(cgroup_memory_left("4:memory:/jobs\n", root_), int64_t{1} << 60);
  EXPECT_EQ(cgroup_memory_left("4:memory:/../etc\n7:garbage\n", root_), -1);
}

// The sizes a refusal compares read apart: "need at least 2 MB ... and 2 MB is free there" did not say why.
TEST(BytesTexts, TwoSizesThatWouldReadTheSameGetTheDigitsToTellThemApart) {
  using spadgen::bytes_texts;
  EXPECT_EQ(bytes_texts(2'000'000, 1'700'000), std::make_pair(std::string("2.0 MB"), std::string("1.7 MB")));
  EXPECT_EQ(bytes_texts(2'000, 1'700), std::make_pair(std::string("2.0 kB"), std::string("1.7 kB")));
  EXPECT_EQ(bytes_texts(1'234'000'000, 1'230'000'000), std::make_pair(std::string("1.234 GB"), std::string("1.230 GB")));
  EXPECT_EQ(bytes_texts(2'000'001, 2'000'000), std::make_pair(std::string("2000001 bytes"), std::string("2000000 bytes")));
  EXPECT_EQ(bytes_texts(1'500'000'000, 1'400'000'000), std::make_pair(std::string("1.5 GB"), std::string("1.4 GB")));  // as bytes_text
  EXPECT_EQ(bytes_texts(5'000'000, 5'000'000), std::make_pair(std::string("5.0 MB"), std::string("5.0 MB")));
  // below 10 of a unit, a digit more (1.44 MB read as "1 MB"); from 9.95 on, whole units
  EXPECT_EQ(spadgen::bytes_text(1'440'000), "1.4 MB");
  EXPECT_EQ(spadgen::bytes_text(9'960'000), "10 MB");
  EXPECT_EQ(spadgen::bytes_text(12'400'000), "12 MB");
  EXPECT_EQ(spadgen::bytes_text(2'500), "2.5 kB");
  EXPECT_EQ(spadgen::bytes_text(500), "0.5 kB");
}

}  // namespace
