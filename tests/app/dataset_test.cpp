// `spadgen dataset`: shards equal the serial run, a run killed with SIGKILL resumes to the same bytes, done
// samples are skipped, stale ones replaced whole, samples added without touching the existing ones, a full
// disk and a folder of another dataset refused, a failing sample recorded while the others go on (the first
// one too), a dataset whose samples all fail refused.
#include <gmock/gmock.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <set>
#include <sstream>
#include <thread>

#include "app/dataset.h"
#include "app/pipeline.h"
#include "core/error.h"
#include "core/units.h"
#include "app/run_parts.h"
#include "app_fixture.h"
#include "scenes/scene_file.h"
#include "writers/writers.h"

namespace spadgen::testing {
namespace {

using ::testing::ContainsRegex;
using ::testing::HasSubstr;
using ::testing::Not;
using json = nlohmann::json;

// Six samples of a 24 x 20 crop of the multi-object scene: a grid over the laser power, random ambient
// light and pixel design, two realisations of the noise each, one chip for all.
std::string small_dataset(int samples, uint64_t seed = 3, const std::string& scene = kScenes + "multi_object.json",
                          const std::string& extra_grid = "") {
  return "{\n  \"description\": \"test dataset\", \"seed\": " + std::to_string(seed) + ",\n  \"scenes\": [\"" + scene +
         "\"],\n  \"samples\": " + std::to_string(samples) +
         ",\n  \"set\": {\"render.samples_per_pixel\": 2, \"acquisition.gate_sweep.stop_ns\": 4.2, \"camera.crop\": [496, 232, 24, 20]},"
         "\n  \"grid\": {\"laser.average_power_mW\": [1, 2]" + extra_grid + "},"
         "\n  \"random\": {\"ambient.illuminance_lux\": {\"log_uniform\": [1, 1000]}, \"sensor.preset\": {\"choice\": [\"pixel_A\", \"pixel_B\"]}},"
         "\n  \"seeds\": {\"chip\": 1}, \"repeats\": 2\n}\n";
}

void write(const fs::path& p, const std::string& text) {
  std::ofstream(p) << text;
}

// `dataset run FILE -o OUT -q` sent `sig` while sample 2 is being written (its staging folder exists), or as
// near to it as the polling sees; its stderr into `log` when given. seen: sample 2's staging was seen.
struct Stopped {
  bool seen = false;
  int status = 0;  // waitpid's
};
// Starts `dataset run FILE -o OUT -q` (its stderr into `log` when given) and waits up to 15 s for sample 2's
// staging folder; its pid, and whether the folder was seen.
std::pair<pid_t, bool> run_until_sample_2(const fs::path& file, const fs::path& out, const fs::path& log = {}) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (!log.empty()) ::dup2(::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644), 2);
    ::execl(kBin.c_str(), kBin.c_str(), "dataset", "run", file.c_str(), "-o", out.c_str(), "-q", nullptr);
    ::_exit(127);
  }
  bool seen = false;
  for (int i = 0; i < 3000 && !seen; ++i) {
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(out / "samples", ec))
      if (e.path().filename().string().find(".000002.spadgen-staging") == 0) seen = true;
    if (!seen) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return {pid, seen};
}

Stopped stop_inside_sample_2(const fs::path& file, const fs::path& out, int sig, const fs::path& log = {}) {
  Stopped s;
  const auto [pid, seen] = run_until_sample_2(file, out, log);
  s.seen = seen;
  ::kill(pid, sig);
  ::waitpid(pid, &s.status, 0);
  return s;
}

// Every file of two dataset folders byte for byte, except the "run" (timing) and "sense" (the folder read)
// sections of the samples' metadata.json.
void expect_same_dataset(const fs::path& a, const fs::path& b) {
  std::set<std::string> in_a, in_b;
  for (const auto& e : fs::recursive_directory_iterator(a))
    if (e.is_regular_file() && e.path().filename().string()[0] != '.') in_a.insert(fs::relative(e.path(), a).string());
  for (const auto& e : fs::recursive_directory_iterator(b))
    if (e.is_regular_file() && e.path().filename().string()[0] != '.') in_b.insert(fs::relative(e.path(), b).string());
  EXPECT_EQ(in_a, in_b);
  EXPECT_GE(in_a.size(), 50u);
  for (const std::string& rel : in_a) {
    if (!in_b.count(rel)) continue;
    if (fs::path(rel).filename() == "metadata.json") {
      json ma = json::parse(slurp(a / rel)), mb = json::parse(slurp(b / rel));
      for (const char* k : {"run", "sense"}) ma.erase(k), mb.erase(k);
      EXPECT_EQ(ma, mb) << rel;
    } else {
      EXPECT_TRUE(slurp(a / rel) == slurp(b / rel)) << rel << " differs";
    }
  }
}

// Files and folders a run leaves behind when it is killed (staging folders, temporary files).
std::vector<std::string> leftovers(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    const std::string n = e.path().filename().string();
    if (n.find("spadgen-staging") != std::string::npos || n.find("spadgen-old") != std::string::npos || n.find(".tmp-") != std::string::npos)
      out.push_back(n);
  }
  return out;
}

ino_t inode(const fs::path& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0 ? st.st_ino : 0;
}

using Dataset = App;

// Two runs without shards into one folder at once (a user starting the same command twice, or two nodes
// given the same job): they share the samples, each rendered once, both exit 0, and the folder equals a
// serial run's, a realisation's files hard links to its sample's.
TEST_F(Dataset, TwoRunsIntoOneFolderShareTheSamples) {
  write(dir_ / "d.json", small_dataset(6));
  const Result serial = sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "serial").string() + " -q");
  ASSERT_EQ(serial.code, 0) << serial.output;
  const std::string run = kBin + " dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "both").string();
  const Result r = shell("(" + run + " 2> " + (dir_ / "a.log").string() + "; echo a=$?) & " + run + " 2> " +
                         (dir_ / "b.log").string() + "; echo b=$?; wait");
  EXPECT_THAT(r.output, HasSubstr("a=0"));
  EXPECT_THAT(r.output, HasSubstr("b=0"));
  // each sample generated by one of the two: "this run: G generated, S skipped, C completed by another run"
  int generated = 0;
  for (const char* log : {"a.log", "b.log"}) {
    const std::string text = slurp(dir_ / log);
    const size_t at = text.find("(this run: ");
    ASSERT_NE(at, std::string::npos) << text;
    generated += std::stoi(text.substr(at + 11));
  }
  EXPECT_EQ(generated, 6);
  expect_same_dataset(dir_ / "serial", dir_ / "both");
  for (int i = 0; i < 6; ++i) {
    const fs::path sample = dir_ / "both/samples" / ("00000" + std::to_string(i));
    EXPECT_EQ(inode(sample / "ground_truth.exr"), inode(fs::path(sample.string() + "_r01") / "ground_truth.exr")) << sample;
  }
  EXPECT_FALSE(fs::exists(dir_ / "both/failed"));
}

// A dataset shared by a group (umask 002) is continued by another member: every file spadgen creates takes
// the umask, its locks too (.dataset.lock, .dataset.runs and the samples' locks were 0644 whatever the umask:
// "cannot open the dataset folder's lock ...: Permission denied" for a teammate; a helper's find).
TEST_F(Dataset, EveryFileTakesTheUmaskItsLocksToo) {
  write(dir_ / "d.json", small_dataset(1));
  const Result r = shell("umask 002 && " + kBin + " dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "shared").string() + " -q");
  ASSERT_EQ(r.code, 0) << r.output;
  int locks = 0, files = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir_ / "shared")) {
    if (!e.is_regular_file()) continue;
    const std::string name = e.path().filename().string();
    ++files;
    locks += name.ends_with("lock") || name == ".dataset.runs";
    EXPECT_EQ(e.status().permissions() & fs::perms::all, fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read |
                                                           fs::perms::group_write | fs::perms::others_read) << e.path();
  }
  EXPECT_EQ(locks, 2) << ".dataset.lock and .dataset.runs";
  EXPECT_GE(files, 10);
}

// A dataset's own folders are its own: samples/ linked to another dataset's, or one sample's folder linked to
// another folder, is refused, naming the link, and the link's target is left as it was (the samples were
// written through the link into the other dataset, exit 0).
TEST_F(Dataset, SymbolicLinksAmongTheSamplesAreRefused) {
  write(dir_ / "d.json", small_dataset(3));
  Result r = sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "a").string() + " -q");
  ASSERT_EQ(r.code, 0) << r.output;
  // A sense of a sample writes beside the dataset by default (DATASET-000000-sense), not into its samples/
  r = sh("sense " + (dir_ / "a/samples/000000").string() + " -q --noise-seed 9");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::exists(dir_ / "a-000000-sense/metadata.json"));
  EXPECT_EQ(sh("dataset status " + (dir_ / "a").string()).code, 0);
  fs::create_directories(dir_ / "other/000001");
  write(dir_ / "other/000001/mine.txt", "mine");
  fs::rename(dir_ / "a/samples/000001", dir_ / "a_000001");
  fs::create_symlink(dir_ / "other/000001", dir_ / "a/samples/000001");
  r = sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "a").string() + " -q");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr((dir_ / "a/samples/000001").string() + " is a symbolic link"));
  fs::remove(dir_ / "a/samples/000001");
  fs::rename(dir_ / "a/samples", dir_ / "a_samples");
  fs::create_symlink(dir_ / "other", dir_ / "a/samples");
  r = sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "a").string() + " -q");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr((dir_ / "a/samples").string() + " is a symbolic link"));
  EXPECT_EQ(slurp(dir_ / "other/000001/mine.txt"), "mine");
  std::vector<std::string> in_other;
  for (const auto& e : fs::directory_iterator(dir_ / "other")) in_other.push_back(e.path().filename().string());
  EXPECT_EQ(in_other, std::vector<std::string>{"000001"});
}

// A done sample that lost a listed file (removed to save space, or a copy that left it out) is damaged, not
// done: status names the file, the index says so, and the next run generates it again, whole.
TEST_F(Dataset, ASampleThatLostAFileIsDamagedAndGeneratedAgain) {
  write(dir_ / "d.json", small_dataset(3));
  const std::string run = "dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q";
  ASSERT_EQ(sh(run).code, 0);
  fs::copy(dir_ / "out", dir_ / "reference", fs::copy_options::recursive);
  fs::remove(dir_ / "out/samples/000001/counts.npy");
  fs::remove(dir_ / "out/samples/000002_r01/counts.npy");
  fs::resize_file(dir_ / "out/samples/000000/ground_truth.exr", 1000);  // a copy cut short
  const Result st = sh("dataset status " + (dir_ / "out").string());
  EXPECT_EQ(st.code, 4);  // not all done
  EXPECT_THAT(st.output, HasSubstr("3 samples: 0 done, 0 failed, 0 stale, 0 missing, 3 damaged"));
  EXPECT_THAT(st.output, HasSubstr("sample 0 damaged: listed in metadata.json but gone or changed: ground_truth.exr (1000 of its "));
  EXPECT_THAT(st.output, HasSubstr("sample 1 damaged: listed in metadata.json but gone or changed: counts.npy "
                                   "(`spadgen dataset run` generates it again)"));
  EXPECT_THAT(st.output, HasSubstr("sample 2 damaged: listed in metadata.json but gone or changed: _r01/counts.npy "
                                   "(`spadgen dataset run` generates it again)"));
  // sense refuses to link the run's cut file
  const Result sense = sh("sense " + (dir_ / "out/samples/000000").string() + " -o " + (dir_ / "sensed").string() + " -q");
  EXPECT_EQ(sense.code, 1);
  EXPECT_THAT(sense.output, HasSubstr("ground_truth.exr: holds 1000 bytes, and the run wrote "));
  const Result again = sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string());
  ASSERT_EQ(again.code, 0) << again.output;
  EXPECT_THAT(again.output, HasSubstr("(this run: 3 generated, 0 skipped"));
  const Result done = sh("dataset status " + (dir_ / "out").string());
  EXPECT_EQ(done.code, 0);
  EXPECT_THAT(done.output, HasSubstr("3 samples: 3 done, 0 failed, 0 stale, 0 missing\n"));
  expect_same_dataset(dir_ / "reference", dir_ / "out");
  // a size in metadata.json's file_bytes of another type hid a counts.npy cut short (the sample was done; an
  // adversarial tester's find): the metadata is damaged, and the sample not done
  {
    const fs::path meta = dir_ / "out/samples/000001/metadata.json";
    const std::string kept = slurp(meta);
    nlohmann::ordered_json m = nlohmann::ordered_json::parse(kept);
    m["file_bytes"]["counts.npy"] = "x";
    write(meta, m.dump(2));
    fs::resize_file(dir_ / "out/samples/000001/counts.npy", 100);
    const Result cut = sh("dataset status " + (dir_ / "out").string());
    EXPECT_EQ(cut.code, 4) << cut.output;
    EXPECT_THAT(cut.output, HasSubstr("3 samples: 2 done")) << cut.output;
    ASSERT_EQ(sh(run).code, 0);  // generated again
    EXPECT_EQ(sh("dataset status " + (dir_ / "out").string()).code, 0);
    // a folder in place of a file is named as one (it was "0 of its N bytes")
    fs::remove(dir_ / "out/samples/000002/counts.npy");
    fs::create_directories(dir_ / "out/samples/000002/counts.npy");
    const Result folder = sh("dataset status " + (dir_ / "out").string());
    EXPECT_EQ(folder.code, 4) << folder.output;
    EXPECT_THAT(folder.output, HasSubstr("sample 2 damaged: listed in metadata.json but gone or changed: counts.npy (a folder, where the "
                                         "run wrote a file)"));
    ASSERT_EQ(sh(run).code, 0);
  }
  // what a killed run left beside a sample is removed at the start (before the disk check counts it), even
  // when the sample is done and skipped
  fs::create_directories(dir_ / "out/samples/.000000.spadgen-staging-999999");
  std::ofstream(dir_ / "out/samples/.000000.spadgen-staging-999999/counts.npy") << "partial";
  ASSERT_EQ(sh(run).code, 0);
  EXPECT_FALSE(fs::exists(dir_ / "out/samples/.000000.spadgen-staging-999999"));
  // every file of a realisation is in the index, its hard links to the sample's files too (a copy made from
  // the index's list was damaged: only _r01/counts.npy and its preview were listed)
  {
    std::ifstream in(dir_ / "out/index.jsonl");
    std::string line;
    std::getline(in, line);
    const json row = json::parse(line);
    std::set<std::string> listed;
    for (const auto& f : row["files"]) listed.insert(f.get<std::string>());
    const json meta = json::parse(slurp(dir_ / "out/samples/000000_r01/metadata.json"));
    for (const auto& f : meta["files"])
      if (f != "metadata.json") {
        EXPECT_TRUE(listed.count("_r01/" + f.get<std::string>())) << f;
      }
    EXPECT_TRUE(listed.count("_r01/ground_truth.exr"));
    EXPECT_EQ(row["repeats"], json::array({"samples/000000_r01"}));
  }
  // a sample whose metadata.json is lost, or cut short, and a realisation's: missing, and generated again
  // (the run refused their folders as holding files spadgen did not write there, every time)
  fs::remove(dir_ / "out/samples/000000/metadata.json");
  std::ofstream(dir_ / "out/samples/000001/metadata.json") << "{";
  fs::remove(dir_ / "out/samples/000002_r01/metadata.json");
  EXPECT_THAT(sh("dataset status " + (dir_ / "out").string()).output, HasSubstr("3 samples: 0 done, 0 failed, 0 stale, 3 missing"));
  const Result regenerated = sh(run);
  ASSERT_EQ(regenerated.code, 0) << regenerated.output;
  EXPECT_THAT(sh("dataset status " + (dir_ / "out").string()).output, HasSubstr("3 samples: 3 done, 0 failed, 0 stale, 0 missing\n"));
  expect_same_dataset(dir_ / "reference", dir_ / "out");
  // a metadata.json of other types than a run writes (a number among the files, a dataset section that is no
  // object, a summary that is no object): missing, and generated again (each stopped every dataset status
  // and run with an internal error, exit 3)
  const auto edit = [&](const fs::path& meta, const std::function<void(json&)>& change) {
    json m = json::parse(slurp(meta));
    change(m);
    write(meta, m.dump());
  };
  edit(dir_ / "out/samples/000000/metadata.json", [](json& m) { m["files"].push_back(7); });
  edit(dir_ / "out/samples/000001/metadata.json", [](json& m) { m["dataset"] = "x"; });
  edit(dir_ / "out/samples/000002/metadata.json", [](json& m) { m["ground_truth_summary"] = "x"; });
  edit(dir_ / "out/samples/000002_r01/metadata.json", [](json& m) { m["dataset"]["sample_hash"] = 12, m["spadgen_version"] = 5; });
  const Result typed = sh("dataset status " + (dir_ / "out").string());
  EXPECT_EQ(typed.code, 4) << typed.output;
  EXPECT_THAT(typed.output, HasSubstr("3 samples: 0 done, 0 failed, 0 stale, 3 missing"));
  const Result retyped = sh(run);
  ASSERT_EQ(retyped.code, 0) << retyped.output;
  expect_same_dataset(dir_ / "reference", dir_ / "out");
  // the folder's dataset.json: JSON but no object (an internal error: erase() of a string), and a bad value
  // in it (blamed on the dataset file, which held a good one)
  const std::string own = slurp(dir_ / "out/dataset.json");
  write(dir_ / "out/dataset.json", "\"hello\"");
  Result damaged = sh(run);
  EXPECT_EQ(damaged.code, 1) << damaged.output;
  EXPECT_THAT(damaged.output, HasSubstr((dir_ / "out/dataset.json").string() + " is damaged (JSON, but not an object)"));
  edit(dir_ / "out/dataset.json", [&](json& m) { m = json::parse(own), m["seed"] = "7"; });
  damaged = sh("dataset status " + (dir_ / "out").string());
  EXPECT_EQ(damaged.code, 1) << damaged.output;
  EXPECT_THAT(damaged.output, HasSubstr((dir_ / "out/dataset.json").string() + " (the dataset file " + (dir_ / "d.json").string() +
                                        " as this folder recorded it): /seed"));
  write(dir_ / "out/dataset.json", own);
  // fewer samples: the folders past them stay, outside the index, and status says so
  write(dir_ / "d2.json", small_dataset(2));
  ASSERT_EQ(sh("dataset run " + (dir_ / "d2.json").string() + " -o " + (dir_ / "out").string() + " -q").code, 0);
  EXPECT_THAT(sh("dataset status " + (dir_ / "out").string()).output,
              HasSubstr("beyond the 2 samples: the folders of samples 2 (kept, not in the index"));
}

TEST_F(Dataset, ShardsOnTheCommandLineSlurmAndKubernetesEqualTheSerialRun) {
  write(dir_ / "d.json", small_dataset(6));
  const Result serial = sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "serial").string() + " -q");
  ASSERT_EQ(serial.code, 0) << serial.output;
  const std::string out = (dir_ / "sharded").string();
  // Shard 2 first: the order the shards finish in must not matter.
  const Result s2 = sh("dataset run " + (dir_ / "d.json").string() + " -o " + out + " -q --shard 2/3");
  const Result s1 = shell("SLURM_ARRAY_TASK_ID=11 SLURM_ARRAY_TASK_MIN=10 SLURM_ARRAY_TASK_COUNT=3 " + kBin + " dataset run " +
                          (dir_ / "d.json").string() + " -o " + out + " -q");
  ASSERT_EQ(s2.code, 0) << s2.output;
  ASSERT_EQ(s1.code, 0) << s1.output;
  EXPECT_THAT(slurp(dir_ / "sharded" / "index.csv"), HasSubstr(",missing,"));  // shard 0 has not run
  const Result s0 = shell("JOB_COMPLETION_INDEX=0 JOB_COMPLETIONS=3 " + kBin + " dataset run " + (dir_ / "d.json").string() + " -o " + out + " -q");
  ASSERT_EQ(s0.code, 0) << s0.output;
  // Shard 1 ran samples 1 and 4 only.
  EXPECT_EQ(json::parse(slurp(dir_ / "sharded/samples/000004/metadata.json"))["dataset"]["index"], 4);
  expect_same_dataset(dir_ / "serial", dir_ / "sharded");
  const Result st = sh("dataset status " + out);
  EXPECT_THAT(st.output, HasSubstr("6 samples: 6 done, 0 failed, 0 stale, 0 missing"));
  // The index: one row per sample, in order, with its parameters and the summary of its ground truth.
  std::istringstream rows(slurp(dir_ / "serial/index.jsonl"));
  int n = 0;
  for (std::string line; std::getline(rows, line); ++n) {
    const json row = json::parse(line);
    EXPECT_EQ(row["index"], n);
    EXPECT_EQ(row["status"], "done");
    EXPECT_EQ(row["repeats"], json::array({"samples/00000" + std::to_string(n) + "_r01"}));
    EXPECT_EQ(row["parameters"]["laser.average_power_mW"], n % 2 ? 2 : 1);
    EXPECT_EQ(row["ground_truth"]["hit_fraction"], 1.0);  // the crop sees the plate and the sphere everywhere
    EXPECT_NEAR(row["ground_truth"]["range_min_m"].get<double>(), 0.45, 1e-3);
    // the objects: the plate and the sphere, both along the rays of the pixels the sample's ground truth says
    EXPECT_EQ(row["ground_truth"]["objects_in_view"], 2);
    EXPECT_EQ(row["ground_truth"]["max_object_count"], 2);
    const auto gt = spadgen::writers::read_exr((dir_ / "serial" / row["folder"].get<std::string>() / "ground_truth.exr").string());
    const auto& count = gt.channels.at("object_count");
    EXPECT_DOUBLE_EQ(row["ground_truth"]["multi_object_fraction"].get<double>(),
                     double(std::count_if(count.begin(), count.end(), [](float c) { return c >= 2.0f; })) / double(count.size()));
    // and how many of them stand out of the noise, as the sample's labels.exr says
    const auto labels = spadgen::writers::read_exr((dir_ / "serial" / row["folder"].get<std::string>() / "labels.exr").string());
    double pairs = 0, detectable = 0;
    for (int j = 0; labels.channels.count("object" + std::to_string(j) + ".id"); ++j)
      for (size_t i = 0; i < count.size(); ++i)
        if (labels.channels.at("object" + std::to_string(j) + ".id")[i] >= 0)
          ++pairs, detectable += labels.channels.at("object" + std::to_string(j) + ".detectable")[i] > 0.5f;
    EXPECT_DOUBLE_EQ(row["ground_truth"]["detectable_fraction"].get<double>(), detectable / pairs);
    EXPECT_LE(row["ground_truth"]["objects_detectable"].get<int>(), 2);
    const json meta = json::parse(slurp(dir_ / "serial" / row["folder"].get<std::string>() / "metadata.json"));
    EXPECT_EQ(meta["dataset"]["parameters"], row["parameters"]);
    EXPECT_EQ(meta["seeds"]["chip"], 1);
    EXPECT_EQ(meta["seeds"]["noise"], row["seeds"]["noise"]);
    const json rep = json::parse(slurp(dir_ / "serial" / row["repeats"][0].get<std::string>() / "metadata.json"));
    EXPECT_EQ(rep["seeds"]["noise"], row["seeds"]["noise"].get<uint64_t>() + 1);
    EXPECT_NE(slurp(dir_ / "serial" / row["folder"].get<std::string>() / "counts.npy"),
              slurp(dir_ / "serial" / row["repeats"][0].get<std::string>() / "counts.npy"));
  }
  EXPECT_EQ(n, 6);
}

// repeats may grow: the new realisations are sensed from each sample's saved light, the sample and its
// realisations kept as they are, and the folder holds what a run with the new repeats writes (a denoising user
// had to render the whole dataset again for more realisations); it may not shrink.
TEST_F(Dataset, RepeatsGrowWithoutRenderingAgain) {
  write(dir_ / "d.json", small_dataset(2));
  const std::string grown = (dir_ / "grown").string();
  const Result made = sh("dataset run " + (dir_ / "d.json").string() + " -o " + grown);
  ASSERT_EQ(made.code, 0) << made.output;
  const std::string sample = slurp(dir_ / "grown/samples/000001/metadata.json"), first = slurp(dir_ / "grown/samples/000001_r01/metadata.json");
  std::string three = small_dataset(2);
  three.replace(three.find("\"repeats\": 2"), 12, "\"repeats\": 3");
  write(dir_ / "d.json", three);
  // the plan prices what the run does (it priced every sample rendered again: 3.3 times the run's disk)
  const Result plan = sh("dataset plan " + (dir_ / "d.json").string() + " -o " + grown);
  ASSERT_EQ(plan.code, 0) << plan.output;
  EXPECT_THAT(plan.output, HasSubstr("left to generate in " + grown + ": 2 samples (2 of them rendered, with realisations "
                                     "missing: only those are sensed, from the saved light), disk up to about "));
  const Result r = sh("dataset run " + (dir_ / "d.json").string() + " -o " + grown);
  ASSERT_EQ(r.code, 0) << r.output;
  // The run's estimate is of the new realisations only (it was of every sample rendered again with three: about
  // 1.5 times the first run's time and disk): measured 0.1 of the first run's disk.
  // (the number and unit before " on disk" on the line that says what is to generate)
  const auto planned_disk = [](const std::string& out) {
    const size_t line = out.find("to generate"), end = line == std::string::npos ? line : out.find(" on disk", line);
    const size_t at = end == std::string::npos ? end : out.rfind("up to about ", end);
    if (at == std::string::npos) return -1.0;
    std::istringstream in(out.substr(at + 12, end - at - 12));
    double v = -1.0;
    std::string unit;
    in >> v >> unit;
    return v * (unit == "kB" ? 1e3 : unit == "MB" ? 1e6 : unit == "GB" ? 1e9 : 1.0);
  };
  const double before = planned_disk(made.output), added = planned_disk(r.output);
  ASSERT_GT(before, 0.0) << made.output;
  ASSERT_GT(added, 0.0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("2 of 2 samples to generate"));
  EXPECT_LT(added, 0.25 * before) << made.output << r.output;
  // (the plan's "left to generate ... disk up to about X": the run's figure; not a bound with the saved light)
  const size_t left = plan.output.find("left to generate");
  ASSERT_NE(left, std::string::npos);
  const size_t most = plan.output.find("disk up to about ", left) + 17;
  const std::string planned = plan.output.substr(most, plan.output.find(" (free", most) - most);
  EXPECT_THAT(r.output, HasSubstr("up to about " + planned + " on disk")) << plan.output;
  // not rendered or sensed again (their metadata.json hold their runs' own times)
  EXPECT_EQ(slurp(dir_ / "grown/samples/000001/metadata.json"), sample);
  EXPECT_EQ(slurp(dir_ / "grown/samples/000001_r01/metadata.json"), first);
  EXPECT_THAT(sh("dataset status " + grown).output, HasSubstr("2 samples: 2 done, 0 failed, 0 stale, 0 missing"));
  ASSERT_EQ(sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "fresh").string() + " -q").code, 0);
  expect_same_dataset(dir_ / "grown", dir_ / "fresh");
  // fewer: refused, the folder as it was
  write(dir_ / "d.json", small_dataset(2));
  const Result fewer = sh("dataset run " + (dir_ / "d.json").string() + " -o " + grown + " -q");
  EXPECT_EQ(fewer.code, 1);
  EXPECT_THAT(fewer.output, HasSubstr(grown + " holds 3 realisations of each sample's noise (repeats), and " + (dir_ / "d.json").string() +
                                      " asks for 2: repeats may grow, to add realisations, not shrink"));
  // another dataset (another seed) with fewer repeats is told as another dataset (it was told only that repeats
  // may not shrink, as if more repeats would do)
  write(dir_ / "d.json", small_dataset(2, 4));
  const Result other = sh("dataset run " + (dir_ / "d.json").string() + " -o " + grown + " -q");
  EXPECT_EQ(other.code, 1);
  EXPECT_THAT(other.output, HasSubstr(grown + " holds another dataset: its dataset.json differs from " + (dir_ / "d.json").string() +
                                      " at \"seed\""));
  EXPECT_THAT(other.output, Not(HasSubstr("repeats may grow, to add realisations, not shrink")));
  EXPECT_TRUE(fs::exists(dir_ / "grown/samples/000001_r02/counts.npy"));
  // status, of the folder's own record, finds its samples done, and says that the dataset file's run would stop
  // now, and why (it said "2 done" alone)
  const Result st = sh("dataset status " + grown);
  EXPECT_EQ(st.code, 0) << st.output;
  EXPECT_THAT(st.output, HasSubstr("2 samples: 2 done, 0 failed, 0 stale, 0 missing"));
  EXPECT_THAT(st.output, HasSubstr("`spadgen dataset run " + (dir_ / "d.json").string() + "` on this folder would stop now: " + grown +
                                   " holds another dataset: its dataset.json differs from " + (dir_ / "d.json").string() + " at \"seed\""));
  write(dir_ / "d.json", three);  // the file as it was: nothing to say
  EXPECT_THAT(sh("dataset status " + grown).output, Not(HasSubstr("would stop")));
}

// The index is written by the last run on the folder to end: a shard ending while another run is on the
// folder reads and writes nothing (100,000 samples took 29 s and 183 MB per shard's end), and the last one
// writes it complete. The other run is this test holding a run's presence (a shared lock on byte 0 of
// .dataset.runs), as a running `dataset run` does.
TEST_F(Dataset, OnlyTheLastRunOnTheFolderToEndWritesTheIndex) {
  write(dir_ / "d.json", small_dataset(2));
  const fs::path out = dir_ / "out";
  ASSERT_EQ(sh("dataset run " + (dir_ / "d.json").string() + " -o " + out.string() + " -q --shard 0/2").code, 0);
  ASSERT_TRUE(fs::exists(out / "index.jsonl"));  // alone on the folder: written
  fs::remove(out / "index.jsonl"), fs::remove(out / "index.csv"), fs::remove(out / "dataset.md");
  const int fd = hold_dataset_run_presence(out);
  ASSERT_GE(fd, 0);
  const Result shard1 = sh("dataset run " + (dir_ / "d.json").string() + " -o " + out.string() + " --shard 1/2");
  ASSERT_EQ(shard1.code, 0) << shard1.output;
  EXPECT_THAT(shard1.output, HasSubstr("another run is still on the folder: the last to end writes the index (this run: 1 generated"));
  EXPECT_FALSE(fs::exists(out / "index.jsonl"));
  EXPECT_FALSE(fs::exists(out / "dataset.md"));
  ::close(fd);  // the other run ends
  const Result last = sh("dataset run " + (dir_ / "d.json").string() + " -o " + out.string() + " --shard 0/2");
  ASSERT_EQ(last.code, 0) << last.output;
  EXPECT_THAT(last.output, HasSubstr("2 done, 0 failed"));
  std::vector<std::string> status;
  std::istringstream index(slurp(out / "index.jsonl"));
  for (std::string line; std::getline(index, line);) status.push_back(json::parse(line)["status"]);
  EXPECT_EQ(status, (std::vector<std::string>{"done", "done"}));
  EXPECT_TRUE(fs::exists(out / "index.csv"));
}

TEST_F(Dataset, ARunKilledWithSigkillResumesToTheSameBytesAndSkipsWhatIsDone) {
  write(dir_ / "d.json", small_dataset(6));
  ASSERT_EQ(sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "whole").string() + " -q").code, 0);
  const fs::path out = dir_ / "killed";
  const Stopped s = stop_inside_sample_2(dir_ / "d.json", out, SIGKILL);
  EXPECT_TRUE(s.seen) << "the run was not caught inside sample 2";
  EXPECT_TRUE(WIFSIGNALED(s.status));
  EXPECT_FALSE(fs::exists(out / "samples/000002/metadata.json"));
  EXPECT_THAT(sh("dataset status " + out.string()).output, HasSubstr("missing: 2-5"));
  const ino_t first = inode(out / "samples/000000/counts.npy");
  const Result again = sh("dataset run " + (dir_ / "d.json").string() + " -o " + out.string());
  ASSERT_EQ(again.code, 0) << again.output;
  EXPECT_THAT(again.output, HasSubstr("4 of 6 samples to generate (2 done already)"));
  EXPECT_EQ(inode(out / "samples/000000/counts.npy"), first);  // skipped, not rewritten
  EXPECT_EQ(leftovers(out), std::vector<std::string>{});
  expect_same_dataset(dir_ / "whole", out);
  // A lock file a run killed after publishing its sample left (the next runs kept it for good): removed; one a
  // live process holds stays.
  std::ofstream(out / "samples/.000001.spadgen-lock") << "pid 999999\n";
  std::ofstream(out / ".index.jsonl.tmp-999999-7") << "{\"index\": 0";  // an index write killed midway
  const int held = ::open((out / "samples/.000003.spadgen-lock").c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  ASSERT_GE(held, 0);
  ASSERT_EQ(::flock(held, LOCK_EX), 0);
  // Nothing left to do: a third run writes no sample.
  const Result third = sh("dataset run " + (dir_ / "d.json").string() + " -o " + out.string());
  EXPECT_THAT(third.output, HasSubstr("0 of 6 samples to generate (6 done already)"));
  EXPECT_EQ(inode(out / "samples/000000/counts.npy"), first);
  EXPECT_FALSE(fs::exists(out / "samples/.000001.spadgen-lock"));
  EXPECT_FALSE(fs::exists(out / ".index.jsonl.tmp-999999-7"));
  EXPECT_TRUE(fs::exists(out / "samples/.000003.spadgen-lock"));
  ::close(held);
}

// SIGTERM while the samples are checked (before any is generated): exit 2 at once, the index as it was (it
// rewrote the index, resolving every sample the check had not reached: 45-60 s for 200,000, past Slurm's 30 s).
TEST_F(Dataset, ASignalWhileTheSamplesAreCheckedStopsAtOnce) {
  // 600 samples of a random pulse width and jitter: 518 sensor shapes (the durations rounded to 2 significant
  // digits), about 40 ms each to estimate: a check of about 10 s (a random pulse width alone gives 42 shapes,
  // a check of about 1.1 s, which the signal at 1 s could miss)
  write(dir_ / "d.json", "{\"seed\": 1, \"scenes\": [\"" + kScenes + "flat_target.json\"], \"samples\": 600, "
        "\"set\": {\"camera.crop\": [0, 0, 8, 8]}, \"random\": {\"laser.pulse_fwhm_ps\": {\"uniform\": [60, 120]}, "
        "\"sensor.jitter_fwhm_ps\": {\"uniform\": [10, 99]}}}");
  const fs::path out = dir_ / "out";
  // (1 s after the program catches SIGTERM: a fixed second after its start raced its start-up under the sanitizers)
  const Signalled r = signal_once_caught({kBin, "dataset", "run", (dir_ / "d.json").string(), "-o", out.string(), "-q"}, SIGTERM, 1.0);
  ASSERT_TRUE(r.caught) << r.code << r.output;
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_LT(r.after_signal_s, 5.0) << "the run took " << r.after_signal_s << " s to stop";
  EXPECT_THAT(r.output, HasSubstr("the dataset run stopped while it checked the samples, before it generated any; the index is as it was"));
  EXPECT_FALSE(fs::exists(out / "index.jsonl"));
  EXPECT_EQ(leftovers(out), std::vector<std::string>{});  // (temporary files included)
}

// SIGTERM inside a sample: exit 2, and the message says what is kept (it said the run wrote nothing,
// although the samples before were published and stay).
TEST_F(Dataset, ASignalSaysWhichSamplesAreKept) {
  write(dir_ / "d.json", small_dataset(6));
  const fs::path out = dir_ / "stopped", log = dir_ / "stderr.txt";
  const Stopped s = stop_inside_sample_2(dir_ / "d.json", out, SIGTERM, log);
  ASSERT_TRUE(s.seen) << "the run was not caught inside sample 2";
  ASSERT_TRUE(WIFEXITED(s.status));
  EXPECT_EQ(WEXITSTATUS(s.status), 2);
  EXPECT_THAT(slurp(log), HasSubstr("the dataset run stopped in sample 2; the 2 samples it completed are kept (index.jsonl lists them)"));
  EXPECT_TRUE(fs::exists(out / "samples/000001/metadata.json"));
  EXPECT_EQ(leftovers(out), std::vector<std::string>{});
  // the index of the first run into the folder is written (a reader of the folder sees the done samples)
  std::vector<std::string> status;
  std::istringstream index(slurp(out / "index.jsonl"));
  for (std::string line; std::getline(index, line);) status.push_back(json::parse(line)["status"]);
  EXPECT_EQ(status, (std::vector<std::string>{"done", "done", "missing", "missing", "missing", "missing"}));
}

// dataset.json is written with the index: a run of 3 samples whose folder another run (of 2) claimed
// meanwhile (its dataset.json written as it began) left "samples": 2 beside an index of 3.
TEST_F(Dataset, DatasetJsonAndTheIndexAreWrittenTogether) {
  write(dir_ / "d3.json", small_dataset(3));
  write(dir_ / "d2.json", small_dataset(2));
  ASSERT_EQ(sh("dataset run " + (dir_ / "d2.json").string() + " -o " + (dir_ / "other").string() + " -q").code, 0);
  const std::string claimed = slurp(dir_ / "other/dataset.json");
  const fs::path out = dir_ / "out", file = dir_ / "d3.json";
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::execl(kBin.c_str(), kBin.c_str(), "dataset", "run", file.c_str(), "-o", out.c_str(), "-q", nullptr);
    ::_exit(127);
  }
  bool seen = false;  // the other run's claim, while this one writes sample 2
  for (int i = 0; i < 3000 && !seen; ++i) {
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(out / "samples", ec))
      if (e.path().filename().string().find(".000002.spadgen-staging") == 0) seen = true;
    if (!seen) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  if (seen) write(out / "dataset.json", claimed);
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(seen) << "the run was not caught inside sample 2";
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  EXPECT_EQ(json::parse(slurp(out / "dataset.json"))["samples"], 3);
  size_t lines = 0;
  std::istringstream index(slurp(out / "index.jsonl"));
  for (std::string line; std::getline(index, line);) ++lines;
  EXPECT_EQ(lines, 3u);
  EXPECT_THAT(sh("dataset status " + out.string()).output, HasSubstr("3 samples: 3 done"));
}

TEST_F(Dataset, AddingSamplesLeavesTheExistingOnesAndEqualsTheLargerRun) {
  write(dir_ / "d3.json", small_dataset(3));
  write(dir_ / "d5.json", small_dataset(5));
  ASSERT_EQ(sh("dataset run " + (dir_ / "d3.json").string() + " -o " + (dir_ / "grown").string() + " -q").code, 0);
  const ino_t kept = inode(dir_ / "grown/samples/000002/counts.npy");
  const Result grow = sh("dataset run " + (dir_ / "d5.json").string() + " -o " + (dir_ / "grown").string());
  ASSERT_EQ(grow.code, 0) << grow.output;
  EXPECT_THAT(grow.output, HasSubstr("2 of 5 samples to generate (3 done already)"));
  EXPECT_EQ(inode(dir_ / "grown/samples/000002/counts.npy"), kept);
  ASSERT_EQ(sh("dataset run " + (dir_ / "d5.json").string() + " -o " + (dir_ / "fresh").string() + " -q").code, 0);
  // The dataset file's path differs (d3 and d5): dataset.json and the card name it; the samples do not.
  for (const char* f : {"dataset.json", "dataset.md", "index.jsonl"}) fs::remove(dir_ / "grown" / f), fs::remove(dir_ / "fresh" / f);
  for (const char* f : {"samples/000000", "samples/000001", "samples/000002", "samples/000004_r01"})
    for (const auto& e : fs::directory_iterator(dir_ / "grown" / f))
      if (e.path().filename() == "metadata.json") {
        json a = json::parse(slurp(e.path())), b = json::parse(slurp(dir_ / "fresh" / f / "metadata.json"));
        for (json* m : {&a, &b}) m->erase("run"), m->erase("sense"), (*m)["dataset"].erase("dataset_file");
        EXPECT_EQ(a, b) << f;
      } else {
        EXPECT_TRUE(slurp(e.path()) == slurp(dir_ / "fresh" / f / e.path().filename())) << f << "/" << e.path().filename();
      }
  EXPECT_EQ(slurp(dir_ / "grown/index.csv"), slurp(dir_ / "fresh/index.csv"));
}

// A sensor table the scene names (here the pulse shape) is part of the sample: replaced under a done dataset
// it made nothing stale, and a grown dataset mixed samples of two pulses, all "done".
TEST_F(Dataset, AChangedSensorTableMakesSamplesStale) {
  write(dir_ / "pulse.csv", "0,0\n50,1\n100,0\n");
  write(dir_ / "d.json", small_dataset(2, 3, kScenes + "multi_object.json",
                                       ", \"laser.pulse_shape_csv\": [\"" + (dir_ / "pulse.csv").string() + "\"]"));
  ASSERT_EQ(sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q").code, 0);
  EXPECT_THAT(sh("dataset status " + (dir_ / "out").string()).output, HasSubstr("2 samples: 2 done, 0 failed, 0 stale"));
  write(dir_ / "pulse.csv", "0,0\n300,1\n600,0\n");
  const Result st = sh("dataset status " + (dir_ / "out").string());
  EXPECT_THAT(st.output, HasSubstr("stale: 0-1"));
  // and what changed, as far as the samples' metadata.json tell
  EXPECT_THAT(st.output, HasSubstr("stale 0-1: a sensor table the scene file names (a CSV or EXR file) changed since it was "
                                   "generated (`spadgen dataset run` generates them again)"));
  write(dir_ / "pulse.csv", "0,0\n50,1\n100,0\n");  // the same bytes again: done again
  EXPECT_THAT(sh("dataset status " + (dir_ / "out").string()).output, HasSubstr("2 samples: 2 done, 0 failed, 0 stale"));
}

// The scene file edited while the dataset runs (a comment: the same resolved scene): the samples rendered after
// the edit hold its contents under the hash of the contents they were planned from, and are stale; the reason
// says so (it said "a sensor table the scene file names, or the parameters" changed, which neither did).
TEST_F(Dataset, ASceneFileEditedWhileTheDatasetRunsIsToldAsSuch) {
  for (const char* f : {"multi_object.json", "multi_object.gltf", "multi_object.bin"}) fs::copy_file(kScenes + f, dir_ / f);
  const fs::path scene = dir_ / "multi_object.json";
  write(dir_ / "d.json", small_dataset(6, 3, scene.string()));
  const fs::path out = dir_ / "out";
  const auto [pid, seen] = run_until_sample_2(dir_ / "d.json", out);
  ::kill(pid, SIGSTOP);
  std::ofstream(scene, std::ios::app) << "// edited while the dataset ran\n";
  ::kill(pid, SIGCONT);
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(seen);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
  const Result st = sh("dataset status " + out.string());
  // samples 3-5 at least read the edited file (sample 2 may have read it before or after)
  EXPECT_THAT(st.output, HasSubstr("-5: the scene file, its glTF or a file the glTF reads changed while it was generated (it was "
                                   "planned from other contents than it rendered)"));
  EXPECT_THAT(st.output, Not(HasSubstr("sensor table")));
  // and those rendered before it: changed since (sample 2 among them or not)
  EXPECT_THAT(st.output, testing::ContainsRegex("stale 0-[12]: the scene file, its glTF or a file the glTF reads changed since it was "
                                                "generated \\("));
}

// A sensor table edited after the dataset resolved a sample (whose hash holds the tables as they were then) and before
// the run's sensor read it: the run is refused, so that the sample fails and is generated again; it was recorded done
// under the hash of the tables it did not read, and stayed done once they were restored. The dataset hands the run
// the tables' hash of the sample's (RunOptions::tables_hash); a run of the same tables goes on.
TEST_F(Dataset, ARunOfOtherTablesThanItsSampleHashHoldsIsRefused) {
  write(dir_ / "pulse.csv", "0,0\n50,1\n100,0\n");
  spadgen::app::RunOptions o;
  o.scene_file = kScenes + "multi_object.json";
  o.overrides = {"laser.pulse_shape_csv=\"" + (dir_ / "pulse.csv").string() + "\"", "camera.crop=[480,242,8,4]",
                 "render.samples_per_pixel=1", "outputs.previews=false"};
  o.threads = 1;
  o.progress = false;
  o.tables_hash = spadgen::scenes::sensor_tables_hash(spadgen::scenes::load_scene_file(o.scene_file, o.overrides).config);
  o.out_dir = (dir_ / "same").string();
  EXPECT_NO_THROW(spadgen::app::run(o));
  write(dir_ / "pulse.csv", "0,0\n300,1\n600,0\n");  // edited after the sample's hash was taken
  o.out_dir = (dir_ / "edited").string();
  try {
    spadgen::app::run(o);
    ADD_FAILURE() << "a run of other tables than its sample's hash holds was not refused";
  } catch (const spadgen::Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("multi_object.json: a sensor table it names (laser.pulse_shape_csv, sensor.gate.profile_csv, "
                                    "sensor.gate.maps_exr, a pdp_csv) changed since the dataset resolved this sample (the tables' "
                                    "hash " + *o.tables_hash + " then, "));
  }
  EXPECT_FALSE(fs::exists(dir_ / "edited"));
  // and a dataset of such samples goes on as before (AChangedSensorTableMakesSamplesStale: 2 done)
}

TEST_F(Dataset, AChangedSceneMakesSamplesStaleAndReplacesThemWhole) {
  // A copy of the scene whose outputs change: with transients, then without.
  fs::copy(kScenes + "multi_object.gltf", dir_ / "multi_object.gltf");
  fs::copy(kScenes + "multi_object.bin", dir_ / "multi_object.bin");
  std::string scene = slurp(kScenes + "multi_object.json");
  const std::string with = scene.replace(scene.find("\"render\": {"), 11, "\"outputs\": {\"transient\": true},\n  \"render\": {");
  write(dir_ / "scene.json", with);
  write(dir_ / "d.json", small_dataset(2, 3, (dir_ / "scene.json").string()));
  ASSERT_EQ(sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q").code, 0);
  ASSERT_TRUE(fs::exists(dir_ / "out/samples/000001/transient.npy"));
  ASSERT_EQ(sh("evaluate " + (dir_ / "out").string() + " -q").code, 0);
  EXPECT_THAT(sh("dataset status " + (dir_ / "out").string()).output, Not(HasSubstr("evaluation/")));
  write(dir_ / "scene.json", slurp(kScenes + "multi_object.json"));
  const Result st = sh("dataset status " + (dir_ / "out").string());
  EXPECT_THAT(st.output, HasSubstr("stale: 0-1"));
  EXPECT_THAT(st.output, HasSubstr("stale 0-1: the scene file, its glTF or a file the glTF reads changed since it was generated"));
  const Result again = sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string());
  ASSERT_EQ(again.code, 0) << again.output;
  EXPECT_THAT(again.output, HasSubstr("2 of 2 samples to generate"));
  EXPECT_THAT(again.output, ContainsRegex("to generate \\(0 done already\\), about [^,]+, up to about [0-9.]+ [kMG]?B on disk"));
  EXPECT_FALSE(fs::exists(dir_ / "out/samples/000001/transient.npy"));  // no stale file beside the new set
  const json meta = json::parse(slurp(dir_ / "out/samples/000001/metadata.json"));
  for (const json& f : meta["files"]) EXPECT_NE(f, "transient.npy");
  EXPECT_EQ(leftovers(dir_ / "out"), std::vector<std::string>{});
  // the evaluation scored the samples before they were generated again: said by the run (even with -q) and by
  // status (nothing told its metrics were of data no longer there), until evaluate runs again
  const std::string out_of_date = "evaluation/ is out of date: of the 4 sample folders it scored, 4 changed since (generated again "
                                  "with another sample_hash) and 0 are no longer done samples (damaged, failed, stale or missing now, or past the "
                                  "dataset's samples), and 0 done ones are "
                                  "not in it: run `spadgen evaluate " + (dir_ / "out").string() + "` again";
  EXPECT_THAT(again.output, HasSubstr(out_of_date));
  EXPECT_THAT(sh("dataset status " + (dir_ / "out").string()).output, HasSubstr(out_of_date));
  ASSERT_EQ(sh("evaluate " + (dir_ / "out").string() + " -q").code, 0);
  EXPECT_THAT(sh("dataset status " + (dir_ / "out").string()).output, Not(HasSubstr("evaluation/")));
  // a scored sample's metadata.json damaged into JSON that is no object: out of date, not an internal error
  // (status finds the sample missing now: its two folders no longer done)
  write(dir_ / "out/samples/000001/metadata.json", "[]");
  const Result damaged = sh("dataset status " + (dir_ / "out").string());
  EXPECT_EQ(damaged.code, 4) << damaged.output;
  EXPECT_THAT(damaged.output, HasSubstr("evaluation/ is out of date: of the 4 sample folders it scored, 0 changed since (generated "
                                        "again with another sample_hash) and 2 are no longer done samples"));
  // fewer samples: the evaluation scored folders that are no longer the dataset's (it was reported current)
  write(dir_ / "d1.json", small_dataset(1, 3, (dir_ / "scene.json").string()));
  ASSERT_EQ(sh("dataset run " + (dir_ / "d1.json").string() + " -o " + (dir_ / "out").string() + " -q").code, 0);
  EXPECT_THAT(sh("dataset status " + (dir_ / "out").string()).output,
              HasSubstr("of the 4 sample folders it scored, 0 changed since (generated again with another sample_hash) "
                        "and 2 are no longer done samples (damaged, failed, stale or missing now, or past the dataset's samples), "
                        "and 0 done ones are not in it"));
}

// Two datasets started at the same moment on a new folder: one is refused, whichever writes dataset.json
// first (both found the folder empty and both wrote it, 5 times in 12, mixing their samples). A race: six
// tries, each of which showed it with probability about 0.4.
TEST_F(Dataset, TwoDatasetsStartedTogetherOnANewFolderAreNotBothAccepted) {
  write(dir_ / "a.json", small_dataset(1, 3));
  write(dir_ / "b.json", small_dataset(1, 4));
  const std::string& bin = kBin;
  for (int attempt = 0; attempt < 6; ++attempt) {
    const fs::path out = dir_ / ("out" + std::to_string(attempt));
    const std::string one = bin + " dataset run " + (dir_ / "a.json").string() + " -q -o " + out.string() + " >/dev/null 2>&1";
    const std::string two = bin + " dataset run " + (dir_ / "b.json").string() + " -q -o " + out.string() + " >/dev/null 2>&1";
    const Result r = shell("(" + one + " & a=$!; " + two + " & b=$!; wait $a; ea=$?; wait $b; eb=$?; echo codes $ea $eb)");
    EXPECT_THAT(r.output, ::testing::AnyOf(HasSubstr("codes 0 1"), HasSubstr("codes 1 0"))) << "attempt " << attempt;
  }
}

// The same dataset text at another path, beside other scene files of the same names: another dataset while the file
// that wrote the folder is still there (it was accepted, and its samples generated again as stale, so that shards
// of the two copies run at once mixed their samples); the same dataset where the scenes' contents are the same.
TEST_F(Dataset, ACopyOfTheDatasetFileBesideOtherScenesIsAnotherDataset) {
  std::string scene = slurp(kScenes + "multi_object.json");
  const std::string gltf = "\"gltf\": \"multi_object.gltf\"";
  ASSERT_NE(scene.find(gltf), std::string::npos);
  scene.replace(scene.find(gltf), gltf.size(), "\"gltf\": \"" + kScenes + "multi_object.gltf\"");
  std::string other = scene;
  const std::string f_number = "\"f_number\": 1.4";
  ASSERT_NE(other.find(f_number), std::string::npos);
  other.replace(other.find(f_number), f_number.size(), "\"f_number\": 2.0");
  for (const char* d : {"a", "b", "c"}) {
    fs::create_directories(dir_ / d);
    write(dir_ / d / "d.json", small_dataset(2, 3, "scene.json"));
  }
  write(dir_ / "a/scene.json", scene);
  write(dir_ / "b/scene.json", other);
  write(dir_ / "c/scene.json", scene);
  const std::string out = (dir_ / "out").string();
  ASSERT_EQ(sh("dataset run " + (dir_ / "a/d.json").string() + " -o " + out + " -q").code, 0);
  const std::string record = slurp(dir_ / "out/dataset.json");
  const Result mixed = sh("dataset run " + (dir_ / "b/d.json").string() + " -o " + out + " -q");
  EXPECT_EQ(mixed.code, 1) << mixed.output;
  EXPECT_THAT(mixed.output, HasSubstr(out + " holds another dataset: its dataset.json was written by " + (dir_ / "a/d.json").string() +
                                      ", which is still there: its scene file " + (dir_ / "a/scene.json").string() +
                                      " differs from this run's " + (dir_ / "b/scene.json").string()));
  EXPECT_EQ(slurp(dir_ / "out/dataset.json"), record);  // nothing written
  // the same scenes' contents: the same dataset, its samples done
  const Result same = sh("dataset run " + (dir_ / "c/d.json").string() + " -o " + out);
  EXPECT_EQ(same.code, 0) << same.output;
  EXPECT_THAT(same.output, HasSubstr("0 of 2 samples to generate (2 done already)"));
  // the file that wrote the folder moved away: its copy beside other scenes takes the folder (its samples stale)
  fs::remove(dir_ / "c/d.json");
  const Result moved = sh("dataset run " + (dir_ / "b/d.json").string() + " -o " + out);
  EXPECT_EQ(moved.code, 0) << moved.output;
  EXPECT_THAT(moved.output, HasSubstr("2 of 2 samples to generate"));
}

TEST_F(Dataset, RefusesAnotherDatasetsFolderForeignFilesAndTooLittleDisk) {
  write(dir_ / "a.json", small_dataset(2, 3));
  write(dir_ / "b.json", small_dataset(2, 4));
  ASSERT_EQ(sh("dataset run " + (dir_ / "a.json").string() + " -o " + (dir_ / "out").string() + " -q").code, 0);
  const Result other = sh("dataset run " + (dir_ / "b.json").string() + " -o " + (dir_ / "out").string() + " -q");
  EXPECT_EQ(other.code, 1);
  EXPECT_THAT(other.output, HasSubstr("holds another dataset: its dataset.json differs from " + (dir_ / "b.json").string() +
                                      " at \"seed\" (the folder's dataset.json: 3, the dataset file: 4)"));
  // a key deeper down is named down to it (it named "set" alone)
  std::string deeper = small_dataset(2, 3);
  const std::string spp = "\"render.samples_per_pixel\": 2";
  deeper.replace(deeper.find(spp), spp.size(), "\"render.samples_per_pixel\": 5");
  write(dir_ / "c.json", deeper);
  const Result set = sh("dataset run " + (dir_ / "c.json").string() + " -o " + (dir_ / "out").string() + " -q");
  EXPECT_EQ(set.code, 1);
  EXPECT_THAT(set.output, HasSubstr(" at \"set\".\"render.samples_per_pixel\" (the folder's dataset.json: 2, the dataset file: 5)"));
  // plan -o refuses it too (it listed the other dataset's samples as left to generate), and writes nothing
  const std::string before = slurp(dir_ / "out/dataset.json");
  const Result other_plan = sh("dataset plan " + (dir_ / "b.json").string() + " -o " + (dir_ / "out").string());
  EXPECT_EQ(other_plan.code, 1) << other_plan.output;
  EXPECT_THAT(other_plan.output, HasSubstr("holds another dataset"));
  EXPECT_EQ(slurp(dir_ / "out/dataset.json"), before);
  EXPECT_EQ(sh("dataset plan " + (dir_ / "a.json").string() + " -o " + (dir_ / "out").string()).code, 0);
  EXPECT_EQ(sh("dataset plan " + (dir_ / "a.json").string() + " -o " + (dir_ / "absent").string()).code, 0);
  EXPECT_FALSE(fs::exists(dir_ / "absent"));
  // The same keys in another order: the grid's order decides which cell a sample takes.
  const std::string ordered = small_dataset(2, 3, kScenes + "multi_object.json", ", \"camera.f_number\": [1.4]");
  std::string swapped = ordered;
  swapped.replace(swapped.find("\"laser.average_power_mW\": [1, 2], \"camera.f_number\": [1.4]"), 58,
                  "\"camera.f_number\": [1.4], \"laser.average_power_mW\": [1, 2]");
  write(dir_ / "ordered.json", ordered);
  write(dir_ / "swapped.json", swapped);
  ASSERT_EQ(sh("dataset run " + (dir_ / "ordered.json").string() + " -o " + (dir_ / "ord").string() + " -q").code, 0);
  EXPECT_THAT(sh("dataset run " + (dir_ / "swapped.json").string() + " -o " + (dir_ / "ord").string() + " -q").output,
              HasSubstr("differs from " + (dir_ / "swapped.json").string() + " at \"grid\" (the order of its keys, which "
                        "decides the grid cell each sample takes)"));
  // set's and random's keys in another order make the same samples: the same dataset (refused before, "as
  // the order decides the grid cell")
  std::string reordered = ordered;
  const std::string set_keys = "\"render.samples_per_pixel\": 2, \"acquisition.gate_sweep.stop_ns\": 4.2";
  const std::string random_keys = "\"ambient.illuminance_lux\": {\"log_uniform\": [1, 1000]}, \"sensor.preset\": {\"choice\": [\"pixel_A\", \"pixel_B\"]}";
  ASSERT_NE(reordered.find(set_keys), std::string::npos);
  ASSERT_NE(reordered.find(random_keys), std::string::npos);
  reordered.replace(reordered.find(set_keys), set_keys.size(), "\"acquisition.gate_sweep.stop_ns\": 4.2, \"render.samples_per_pixel\": 2");
  reordered.replace(reordered.find(random_keys), random_keys.size(),
                    "\"sensor.preset\": {\"choice\": [\"pixel_A\", \"pixel_B\"]}, \"ambient.illuminance_lux\": {\"log_uniform\": [1, 1000]}");
  write(dir_ / "reordered.json", reordered);
  const Result same = sh("dataset run " + (dir_ / "reordered.json").string() + " -o " + (dir_ / "ord").string());
  EXPECT_EQ(same.code, 0) << same.output;
  EXPECT_THAT(same.output, HasSubstr("0 of 2 samples to generate (2 done already)"));
  // without its dataset.json (damaged, or lost) the folder's samples may be another dataset's: refused (a
  // run of another dataset file replaced them)
  const std::string record = slurp(dir_ / "out/dataset.json");
  write(dir_ / "out/dataset.json", "{\"seed\": ");
  Result lost = sh("dataset run " + (dir_ / "b.json").string() + " -o " + (dir_ / "out").string() + " -q");
  EXPECT_EQ(lost.code, 1);
  EXPECT_THAT(lost.output, HasSubstr("out/dataset.json is damaged (not JSON): it says which dataset file "));
  fs::remove(dir_ / "out/dataset.json");
  lost = sh("dataset run " + (dir_ / "b.json").string() + " -o " + (dir_ / "out").string() + " -q");
  EXPECT_EQ(lost.code, 1);
  EXPECT_THAT(lost.output, HasSubstr("holds a dataset's samples but no dataset.json, which says which dataset file they are of"));
  write(dir_ / "out/dataset.json", record);
  EXPECT_THAT(sh("dataset status " + (dir_ / "out").string()).output, HasSubstr("2 samples: 2 done"));
  fs::create_directories(dir_ / "mine");
  write(dir_ / "mine/notes.txt", "mine");
  const Result foreign = sh("dataset run " + (dir_ / "a.json").string() + " -o " + (dir_ / "mine").string() + " -q");
  EXPECT_EQ(foreign.code, 1);
  EXPECT_THAT(foreign.output, HasSubstr("holds notes.txt, which spadgen did not write there"));
  EXPECT_EQ(slurp(dir_ / "mine/notes.txt"), "mine");
  EXPECT_FALSE(fs::exists(dir_ / "mine/.dataset.lock")) << "a refused folder is left as it was";
  // a run folder is named as one (it was told it held labels.exr, "which spadgen did not write there"); a
  // dataset's sample as the dataset's own
  fs::copy(dir_ / "ord/samples/000000", dir_ / "run0", fs::copy_options::recursive);
  const Result into_run = sh("dataset run " + (dir_ / "a.json").string() + " -o " + (dir_ / "run0").string() + " -q");
  EXPECT_EQ(into_run.code, 1);
  EXPECT_THAT(into_run.output, HasSubstr("run0 is a run folder (it holds metadata.json), not a dataset folder"));
  // (its lock file made the next run into the run folder refuse it as a file spadgen did not write there)
  EXPECT_FALSE(fs::exists(dir_ / "run0/.dataset.lock"));
  const Result into_sample = sh("dataset run " + (dir_ / "a.json").string() + " -o " + (dir_ / "ord/samples/000000").string() + " -q");
  EXPECT_EQ(into_sample.code, 1);
  EXPECT_THAT(into_sample.output, HasSubstr("lies in the dataset " + (dir_ / "ord").string() + "'s own samples"));
  // 200 full-sensor samples with their transients need terabytes.
  write(dir_ / "big.json", "{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"samples\": 200, \"set\": {\"outputs.transient\": true}}");
  const Result disk = sh("dataset run " + (dir_ / "big.json").string() + " -o " + (dir_ / "big").string() + " -q");
  EXPECT_EQ(disk.code, 1);
  EXPECT_THAT(disk.output, HasSubstr("the 200 samples left to generate in"));
  EXPECT_THAT(disk.output, HasSubstr("is free there"));
  EXPECT_FALSE(fs::exists(dir_ / "big/samples/000000"));
  const Result plan = sh("dataset plan " + (dir_ / "big.json").string());
  EXPECT_EQ(plan.code, 0) << plan.output;
  // (the transients' EXR images and the saved light... are counted at their most: a bound, so named)
  EXPECT_THAT(plan.output, HasSubstr("# total: 200 samples, disk at most"));
  EXPECT_THAT(plan.output, Not(HasSubstr("an upper bound")));
  EXPECT_THAT(plan.output, Not(HasSubstr("samples) "))) << "no progress for a plan of a few samples";
  // The cores the process may use (taskset, a Slurm task's cpuset), not the machine's: it planned for 2 on one.
  const Result one_core = shell("taskset -c 0 " + kBin + " dataset plan " + (dir_ / "big.json").string() + " 2>&1");
  EXPECT_EQ(one_core.code, 0) << one_core.output;
  EXPECT_THAT(one_core.output, HasSubstr("(estimates for 1 core: "));
  // A plan of over 10,000 samples (0.2 ms each) says how far it is, on stderr (here not a terminal: lines).
  write(dir_ / "many.json", "{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"samples\": 10001}");
  const Result many = sh("dataset plan " + (dir_ / "many.json").string());
  EXPECT_EQ(many.code, 0) << many.output;
  EXPECT_THAT(many.output, HasSubstr("spadgen: 100% (10001/10001 samples)"));
  // A target error: the time is counted at render.max_samples_per_pixel paths, and said to be a bound.
  const auto per_sample = [](const std::string& text) { return text.substr(text.find("# per sample:")); };
  write(dir_ / "standard.json", "{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"samples\": 200, \"set\": "
        "{\"outputs.transient\": true, \"render.quality\": \"standard\"}}");
  const Result bound = sh("dataset plan " + (dir_ / "standard.json").string());
  EXPECT_EQ(bound.code, 0) << bound.output;
  EXPECT_THAT(bound.output, HasSubstr("the times count render.max_samples_per_pixel for every pixel, an upper bound"));
  EXPECT_NE(per_sample(bound.output), per_sample(plan.output));
}

// The disk of `dataset plan`'s output, in bytes: per sample ("# per sample: disk at most 35 MB, ...": what a
// sample keeps), or the total ("# total: N samples, disk at most 71 MB, ...": every sample and one sample's
// temporary files, freed after it); "about" where nothing is counted at its most.
double planned_disk(const std::string& plan, bool per_sample = false) {
  std::string key;
  size_t at = std::string::npos;
  for (const char* word : {"disk at most ", "disk up to about ", "disk about "}) {
    key = (per_sample ? "# per sample: " : " samples, ") + std::string(word);
    if ((at = plan.find(key, per_sample ? 0 : plan.find("# total: "))) != std::string::npos) break;
  }
  if (at == std::string::npos) return -1.0;
  std::istringstream in(plan.substr(at + key.size()));
  double planned = 0.0;
  std::string unit;
  in >> planned >> unit;  // "35 MB,"
  return planned * (unit.starts_with("TB") ? 1e12 : unit.starts_with("GB") ? 1e9 : unit.starts_with("MB") ? 1e6 : 1e3);
}

// Bytes of the regular files under a folder, each file once (a realisation's links are the sample's files).
double bytes_taken(const fs::path& dir) {
  std::set<ino_t> seen;
  double taken = 0.0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file() && seen.insert(inode(e.path())).second) taken += double(e.file_size());
  return taken;
}

// `dataset plan`, then `dataset run` of DIR/d.json into DIR/out: the plan's output, "" (a failure recorded)
// when either fails.
std::string plan_then_run(const fs::path& dir) {
  const Result plan = sh("dataset plan " + (dir / "d.json").string());
  const Result run = sh("dataset run " + (dir / "d.json").string() + " -o " + (dir / "out").string() + " -q");
  if (plan.code == 0 && run.code == 0) return plan.output;
  ADD_FAILURE() << "plan: " << plan.code << " " << plan.output << "\nrun: " << run.code << " " << run.output;
  return "";
}

// The disk a dataset is planned to take, against what it takes: a further realisation of the noise writes
// its counts and links the sample's light, images and noise-free stacks (each counted as a whole sample
// again, three realisations were planned at 3.5 times the disk they took (94 MB against 27), and a disk that held it
// was refused).
TEST_F(Dataset, ThePlannedDiskCountsTheRealisationsLinks) {
  write(dir_ / "d.json", "{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"samples\": 2, \"repeats\": 3, \"set\": "
        "{\"render.samples_per_pixel\": 1, \"acquisition.gate_sweep.stop_ns\": 4.2, \"camera.crop\": [448, 186, 128, 64], "
        "\"outputs.detection_rate\": true, \"outputs.expected_counts\": true}}");
  const std::string plan = plan_then_run(dir_);
  ASSERT_FALSE(plan.empty());
  const double planned = 2 * planned_disk(plan, true);  // what the 2 samples keep
  ASSERT_GT(planned, 0.0) << plan;
  EXPECT_GT(planned_disk(plan), planned) << "the total holds a sample's temporary files too";
  const double taken = bytes_taken(dir_ / "out/samples");
  // at most 2: the saved light (the realisations' source) is planned at 2.5 ns of bins per pixel, which a
  // plate in front of a sphere reaches; this crop's pixels span less
  EXPECT_LE(planned, 2.0 * taken) << planned << " planned, " << taken << " taken";
  EXPECT_GE(planned, 0.7 * taken) << planned << " planned, " << taken << " taken";
  // The least the samples take, which a run refuses a disk by, is a lower bound: the saved light counted
  // without lit bins (at 2.5 ns of bins the least was 1.8 times what these samples took, and a disk they fit
  // on was refused)
  const size_t at = plan.find("the samples take at least ");
  ASSERT_NE(at, std::string::npos) << plan;
  std::istringstream in(plan.substr(at + 26));
  double least = 0.0;
  std::string unit;
  in >> least >> unit;
  ASSERT_EQ(unit, "MB") << plan;
  EXPECT_LE(least * 1e6, taken) << least << " MB at least, " << taken << " taken";
  EXPECT_GE(least * 1e6, 0.3 * taken) << least << " MB at least, " << taken << " taken";
}

// The saved light as .npy at fine bins, over a crop of the plate in front of the sphere: the plan counts the
// span of arrival times a pixel's light covers, not a fixed number of bins (128 bins planned a quarter of
// the disk 1 ps bins took).
TEST_F(Dataset, ThePlannedDiskOfTheSavedLightFollowsTheBinWidth) {
  write(dir_ / "d.json", "{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"samples\": 1, \"set\": "
        "{\"render.samples_per_pixel\": 2, \"render.time_bin_ps\": 1, \"camera.crop\": [448, 186, 64, 32], "
        "\"outputs.light\": true, \"outputs.counts\": false, \"outputs.previews\": false}}");
  const std::string plan = plan_then_run(dir_);
  ASSERT_FALSE(plan.empty());
  const double planned = planned_disk(plan);
  ASSERT_GT(planned, 0.0) << plan;
  const double light = bytes_taken(dir_ / "out/samples/000000/light"), taken = bytes_taken(dir_ / "out/samples");
  EXPECT_GT(light, 0.5 * taken) << "the light is most of the sample";
  EXPECT_GE(planned, taken) << planned << " planned, " << taken << " taken";
  EXPECT_LE(planned, 3.0 * taken) << planned << " planned, " << taken << " taken";
}

// 6 and 6.0 are one JSON value: a dataset file saved again with its integers written as floats (Python's
// json.dump) makes the same samples (the folder took it as the same dataset, and every sample was stale
// and generated again: their hash covered the values' text).
TEST_F(Dataset, AValueWrittenWithAZeroFractionMakesTheSameSamples) {
  const std::string text = small_dataset(2);
  write(dir_ / "d.json", text);
  ASSERT_EQ(sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q").code, 0);
  std::string floats = text;
  for (const auto& [from, to] : {std::pair<std::string, std::string>{"[1, 2]", "[1.0, 2.0]"}, {"[496, 232, 24, 20]", "[496.0, 232, 24.0, 20]"},
                                 {"samples_per_pixel\": 2,", "samples_per_pixel\": 2.0,"}}) {
    ASSERT_NE(floats.find(from), std::string::npos) << from;
    floats.replace(floats.find(from), from.size(), to);
  }
  write(dir_ / "f.json", floats);
  const Result r = sh("dataset run " + (dir_ / "f.json").string() + " -o " + (dir_ / "out").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("0 of 2 samples to generate (2 done already)"));
  EXPECT_THAT(r.output, HasSubstr("2 done, 0 failed, 0 stale, 0 missing"));
}

// A sample whose error holds bytes that are not UTF-8 (a damaged EXR's channel name, echoed by OpenEXR; the
// file is the header of a fuzzed one) is recorded in failed/ with them written \xNN (the index, JSON, could
// not hold them: "the failure of sample 0 is not recorded in failed/: invalid UTF-8 byte"), and said on one
// line (the name's control byte too).
TEST_F(Dataset, AFailureWhoseMessageIsNotUtf8IsRecorded) {
  const std::string maps = std::string(SPADGEN_SOURCE_DIR) + "/tests/data/exr/channel_name_not_utf8.exr";
  write(dir_ / "d.json", "{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"samples\": 1, \"seed\": 5, \"set\": "
                         "{\"camera.crop\": [400, 200, 8, 8], \"render.samples_per_pixel\": 1, \"sensor.gate.maps_exr\": \"" + maps + "\"}}");
  const Result r = sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("is not recorded in failed/")));
  EXPECT_EQ(spadgen::invalid_utf8_at(r.output), std::string::npos) << r.output;
  EXPECT_THAT(r.output, HasSubstr("sample 0 failed: " + kScenes + "multi_object.json: sensor.gate.maps_exr: cannot read EXR"));
  EXPECT_THAT(r.output, HasSubstr("of the \"count\\xC4\\x02\" channel"));
  const std::string recorded = slurp(dir_ / "out/failed/000000.json");
  EXPECT_THAT(recorded, HasSubstr("count\\\\xC4\\u0002"));  // JSON: the backslash and the control byte escaped
  const Result st = sh("dataset status " + (dir_ / "out").string());
  EXPECT_EQ(st.code, 4);
  EXPECT_THAT(st.output, HasSubstr("of the \"count\\xC4\\x02\" channel"));
  EXPECT_EQ(std::count(st.output.begin(), st.output.end(), '\x02'), 0) << st.output;
}

TEST_F(Dataset, AFailingSampleIsRecordedAndTheOthersGoOn) {
  // camera.width_px 16 leaves the crop outside the sensor: cells with it fail, the others do not.
  write(dir_ / "d.json", small_dataset(4, 3, kScenes + "multi_object.json", ", \"camera.width_px\": [1024, 16]"));
  const Result r = sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("2 samples failed (1, 3)"));
  EXPECT_TRUE(fs::exists(dir_ / "out/samples/000002/metadata.json"));
  EXPECT_FALSE(fs::exists(dir_ / "out/samples/000001"));
  const Result st = sh("dataset status " + (dir_ / "out").string());
  EXPECT_EQ(st.code, 4);
  EXPECT_THAT(st.output, HasSubstr("failed: 1, 3"));
  // (the key named where the dataset file sets it: the sample was given no --set)
  EXPECT_THAT(st.output, HasSubstr("sample 1 (laser.average_power_mW 1, camera.width_px 16, ambient.illuminance_lux "));
  EXPECT_THAT(st.output, HasSubstr(") makes an invalid scene: " + (dir_ / "d.json").string() + ": /set/camera.crop: found [496, 232, 24, 20]"));
  EXPECT_THAT(slurp(dir_ / "out/failed/000001.json"), HasSubstr("/set/camera.crop: found"));
  EXPECT_THAT(slurp(dir_ / "out/index.csv"), HasSubstr(",failed,"));
  // evaluate scores the done samples and counts the others by status, as an object a script reads (it was
  // a sentence)
  const Result ev = sh("evaluate " + (dir_ / "out").string() + " -o " + (dir_ / "ev").string());
  ASSERT_EQ(ev.code, 0) << ev.output;
  EXPECT_THAT(ev.output, HasSubstr("not scored, not done: 2 failed"));
  const auto m = nlohmann::json::parse(slurp(dir_ / "ev/metrics.json"));
  EXPECT_EQ(m["samples"].size(), 4u);  // samples 0 and 2, two realisations each
  EXPECT_EQ(m["not_scored"], nlohmann::json({{"failed", 2}})) << m["not_scored"];
}

// A sample's warnings (a frame longer than the camera's) are not lost among many samples: the plan lists them
// by key with their samples, the run names the sample on stderr, once per sample (its realisations' senses
// said them again), and the index rows (jsonl: the texts, csv: how many) and the card keep them (only each
// sample's metadata.json did).
TEST_F(Dataset, ASamplesWarningsAreNamedListedAndKept) {
  // every sample's frames longer than the camera's (1915 or 2000 cycles: one kind of warning), and a coarse gate
  // (a sensor warning, which each realisation's sense gives again)
  write(dir_ / "d.json", small_dataset(4, 3, kScenes + "multi_object.json",
                                       ", \"acquisition.cycles_per_frame\": [1915, 2000], \"sensor.gate.knots_per_edge\": [8]"));
  const std::string warning = "acquisition.cycles_per_frame: 1915 laser cycles last 47.875 us, longer than one frame at 24000 fps";
  const Result plan = sh("dataset plan " + (dir_ / "d.json").string());
  ASSERT_EQ(plan.code, 0) << plan.output;
  EXPECT_THAT(plan.output, HasSubstr("\nwarning: 4 samples (0, 1, 2, 3): " + warning + "\n"));
  const Result r = shell(kBin + " dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q 2>&1");
  ASSERT_EQ(r.code, 0) << r.output;
  const auto said = [&](const std::string& text) {
    size_t n = 0;
    for (size_t at = r.output.find(text); at != std::string::npos; at = r.output.find(text, at + 1)) ++n;
    return n;
  };
  EXPECT_EQ(said("spadgen: warning: sample 0: " + warning + "\n"), 1u) << r.output;
  EXPECT_EQ(said("spadgen: warning: sample 1: acquisition.cycles_per_frame: 2000 laser cycles last 50 us"), 1u) << r.output;
  EXPECT_EQ(said("spadgen: warning: sample 2: sensor.gate: the gate is tabulated"), 1u) << r.output;
  EXPECT_EQ(said("realisation"), 0u) << r.output;  // the realisations' senses said the same: silent
  std::ifstream index(dir_ / "out/index.jsonl");
  std::string line;
  int rows = 0;
  while (std::getline(index, line)) {
    const json row = json::parse(line);
    const int i = row["index"].get<int>();
    const json meta = json::parse(slurp(dir_ / "out" / row["folder"].get<std::string>() / "metadata.json"));
    EXPECT_EQ(row["warnings"], meta["warnings"]) << i;
    EXPECT_GE(row["warnings"].size(), 2u) << i;  // (and a bright return's gate warning in sample 3)
    ++rows;
  }
  EXPECT_EQ(rows, 4);
  const std::string csv = slurp(dir_ / "out/index.csv");
  EXPECT_TRUE(csv.substr(0, csv.find('\n') + 1).ends_with(",error,warnings\n")) << csv;  // appended last
  const std::string card = slurp(dir_ / "out/dataset.md");
  EXPECT_THAT(card, HasSubstr("## Warnings\n"));
  EXPECT_THAT(card, HasSubstr("\n- 4 samples (0, 1, 2, 3): " + warning + "\n"));
  EXPECT_THAT(card, HasSubstr("\n- 4 samples (0, 1, 2, 3): sensor.gate: the gate is tabulated"));
  // (two realisations: the one besides the sample's own named alone, not "realisations 1 to 1")
  EXPECT_THAT(card, HasSubstr("; its realisation 1 of the temporal noise is `samples/<i>_r01/` (the same light, noise seed S + 1)."));
}

// The card's command pastes into a shell: a dataset file whose name holds a space, or a quote, is quoted
// ("spadgen dataset run my dataset.json -o DIR" ran two files); one path per pixel is one path.
TEST_F(Dataset, TheCardsCommandPastesIntoAShell) {
  std::string text = small_dataset(1);
  const std::string two = "\"render.samples_per_pixel\": 2";
  text.replace(text.find(two), two.size(), "\"render.samples_per_pixel\": 1");
  write(dir_ / "my dataset's.json", text);
  const Result r = shell(kBin + " dataset run '" + (dir_ / "my dataset'\\''s.json").string() + "' -o " + (dir_ / "out").string() + " -q");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string card = slurp(dir_ / "out/dataset.md");
  EXPECT_THAT(card, HasSubstr("spadgen dataset run 'my dataset'\\''s.json' -o DIR"));
  EXPECT_THAT(card, HasSubstr(" | 1 path per pixel |"));
}

// -o naming a file: said so, not "Not a directory"; the file kept.
TEST_F(Dataset, AnOutputThatIsAFileIsNamed) {
  write(dir_ / "d.json", small_dataset(2));
  write(dir_ / "afile", "mine");
  for (const fs::path& out : {dir_ / "afile", dir_ / "afile/sub"}) {
    const Result r = sh("dataset run " + (dir_ / "d.json").string() + " -o " + out.string() + " -q");
    EXPECT_EQ(r.code, 1) << out;
    EXPECT_THAT(r.output, HasSubstr("cannot create the dataset folder " + out.string() + ": a file of that name (or of a folder "
                                    "above it) exists; expected a folder or a new name (-o)")) << out;
  }
  EXPECT_EQ(slurp(dir_ / "afile"), "mine");
}

// A sample whose estimate the sensor refuses (here transients in the intensity mode without a window) is
// listed invalid with why, and the plan goes on (the estimates, computed together, stopped the whole plan);
// the plan then exits 1 (it exited 0) and its averages are of the valid samples. When every probed sample
// of the scene is refused so, the dataset is refused before any work, as for invalid scenes (its run
// recorded every sample in failed/).
TEST_F(Dataset, APlanListsASampleItCannotEstimateAsInvalid) {
  const std::string body = "{\"seed\": 1, \"scenes\": [\"" + kScenes + "flat_target.json\"], \"samples\": 4, "
                           "\"set\": {\"outputs.transient\": true, \"camera.crop\": [0, 0, 8, 8]}, \"grid\": {\"acquisition.mode\": ";
  write(dir_ / "d.json", body + "[\"gate_sweep\", \"intensity\"]}}");
  const Result r = sh("dataset plan " + (dir_ / "d.json").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("# total: 4 samples (the 2 valid ones estimated), disk at most "));
  // each with its parameters, and the closing line with the dataset file and the samples (they named neither)
  EXPECT_THAT(r.output, HasSubstr("error: sample 1 (acquisition.mode intensity): " + (dir_ / "d.json").string() +
                                  ": /set/outputs.transient: found true in the intensity mode, which needs no time bins"));
  EXPECT_THAT(r.output, HasSubstr("error: sample 3 ("));
  EXPECT_THAT(r.output, Not(HasSubstr("error: sample 0")));
  EXPECT_THAT(r.output, HasSubstr("\tintensity\t"));
  EXPECT_THAT(r.output, HasSubstr("\t-\t-\t-\n"));  // no estimate for samples 1 and 3
  EXPECT_THAT(r.output, HasSubstr("spadgen: error: " + (dir_ / "d.json").string() + ": 2 samples (1, 3) make an invalid run"));
  // a key the dataset sets, invalid with a drawn one: named at its place in the dataset file (it was "--set camera.crop")
  write(dir_ / "crop.json", "{\"seed\": 1, \"scenes\": [\"" + kScenes + "flat_target.json\"], \"samples\": 2, \"set\": "
        "{\"camera.crop\": [700, 0, 8, 8]}, \"grid\": {\"camera.width_px\": [1024, 600]}}");
  const Result crop = sh("dataset plan " + (dir_ / "crop.json").string());
  EXPECT_EQ(crop.code, 1) << crop.output;
  EXPECT_THAT(crop.output, HasSubstr("error: sample 1 (camera.width_px 600): " + (dir_ / "crop.json").string() +
                                     ": /set/camera.crop: found [700, 0, 8, 8], expected a rectangle inside the 600 x "));
  // the per-sample disk is sample 0's (and 2's), not halved by the invalid two
  const auto row0 = r.output.find("\n0\t"), per = r.output.find("# per sample: disk at most ");
  ASSERT_NE(row0, std::string::npos);
  ASSERT_NE(per, std::string::npos);
  std::string disk0 = r.output.substr(row0 + 1, r.output.find('\n', row0 + 1) - row0 - 1);
  for (int i = 0; i < 4; ++i) disk0 = disk0.substr(disk0.find('\t') + 1);  // index, scene, mode, seed
  disk0 = disk0.substr(0, disk0.find('\t'));
  EXPECT_EQ(r.output.substr(per + 27, disk0.size() + 1), disk0 + ",") << r.output;

  write(dir_ / "e.json", body + "[\"intensity\"]}}");
  for (const char* cmd : {"dataset plan ", "dataset run "}) {
    const Result e = sh(cmd + (dir_ / "e.json").string() + " -o " + (dir_ / "e").string() + " -q");
    EXPECT_EQ(e.code, 1);
    // the key named at its place in the dataset file, as a failing sample's error names it (it was "--set outputs.transient")
    EXPECT_THAT(e.output, HasSubstr("e.json: sample 0 (acquisition.mode intensity): /set/outputs.transient: found true in the intensity mode, which needs no time "
                                    "bins; set /render/window_start_ns and /render/window_stop_ns to say which window transient.npy "
                                    "should cover (and the next 3 samples of this scene fail too)"));
    EXPECT_EQ(std::count(e.output.begin(), e.output.end(), '\n'), 1) << e.output;
    EXPECT_FALSE(fs::exists(dir_ / "e"));
  }
}

// dataset status checks index.jsonl against the samples: missing, damaged (a row not JSON, a row twice) or out
// of date, it is named with the fix and the dataset is not complete (exit 4): status said all done, exit 0,
// and evaluate and the Python package then refused the folder (an adversarial tester's find).
TEST_F(Dataset, StatusChecksTheIndex) {
  write(dir_ / "d.json", small_dataset(2));
  const std::string out = (dir_ / "out").string(), run = "dataset run " + (dir_ / "d.json").string() + " -o " + out + " -q";
  ASSERT_EQ(sh(run).code, 0);
  const std::string status = "dataset status " + out;
  ASSERT_EQ(sh(status).code, 0);
  const std::string index = slurp(dir_ / "out/index.jsonl"), first = index.substr(0, index.find('\n') + 1);
  const std::string fix = ": `spadgen dataset run` writes it again (with nothing left to generate, it writes only the index and the card)";
  const struct {
    std::string text, says;
  } cases[] = {{"", "index: " + out + "/index.jsonl is missing" + fix},
               {first, "index: " + out + "/index.jsonl has 1 row for the dataset's 2 samples (dataset.json): the index was cut "
                       "short or added to after `spadgen dataset run` wrote it, or a run that changed the dataset's samples was "
                       "killed before it wrote the index; `spadgen dataset run` writes it again"},
               {first + first, "index: " + out + "/index.jsonl row 2 lists sample 0 where sample 1 belongs (damaged since it was written)" + fix},
               {first + "{\"index\": 1, \n", "index: " + out + "/index.jsonl row 2 is not JSON (damaged since it was written)" + fix},
               {index + first, "index: " + out + "/index.jsonl row 3 lists sample 0 where sample 2 belongs"}};
  // A run on the folder (its presence held, as a dataset run holds it) is said; none is when it has ended.
  {
    const int fd = ::open((dir_ / "out/.dataset.runs").c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    ASSERT_GE(fd, 0);
    struct flock l {};
    l.l_type = F_RDLCK, l.l_whence = SEEK_SET, l.l_start = 0, l.l_len = 1;
    ASSERT_EQ(::fcntl(fd, F_OFD_SETLK, &l), 0);
    EXPECT_THAT(sh(status).output, HasSubstr("a dataset run is on the folder now: its samples in progress count as missing"));
    ::close(fd);
    EXPECT_THAT(sh(status).output, Not(HasSubstr("a dataset run is on the folder now")));
  }
  for (const auto& c : cases) {
    if (c.text.empty()) fs::remove(dir_ / "out/index.jsonl");
    else write(dir_ / "out/index.jsonl", c.text);
    const Result r = sh(status);
    EXPECT_EQ(r.code, 4) << c.says << r.output;
    EXPECT_THAT(r.output, HasSubstr("2 samples: 2 done, 0 failed, 0 stale, 0 missing"));
    EXPECT_THAT(r.output, HasSubstr(c.says));
  }
  // out of date: sample 1 listed as missing while it is done
  std::string missing = index;
  const size_t second = index.find('\n') + 1;
  const size_t at = missing.find("\"status\":\"done\"", second);
  ASSERT_NE(at, std::string::npos) << index;
  missing.replace(at, 15, "\"status\":\"missing\"");
  write(dir_ / "out/index.jsonl", missing);
  const Result stale = sh(status);
  EXPECT_EQ(stale.code, 4) << stale.output;
  const std::string hash1 = nlohmann::json::parse(index.substr(second, index.find('\n', second) - second)).at("sample_hash");
  EXPECT_THAT(stale.output, HasSubstr("row 2 lists sample 1 as missing, and it is done (" + hash1 + ") now: the index is out of date" + fix));
  // listed as done, and damaged since (a file gone): said so, not "with another hash" (a user's confusion: the hash is the same)
  {
    write(dir_ / "out/index.jsonl", index);
    const fs::path sample = dir_ / "out/samples/000001";
    const auto files = nlohmann::json::parse(slurp(sample / "metadata.json")).at("files");
    const fs::path gone = sample / files.at(0).get<std::string>(), kept = dir_ / "kept_file";
    fs::rename(gone, kept);
    const Result damaged = sh(status);
    fs::rename(kept, gone);
    EXPECT_EQ(damaged.code, 4) << damaged.output;
    EXPECT_THAT(damaged.output, HasSubstr("row 2 lists sample 1 as done, and it is damaged now: the index is out of date" + fix));
    EXPECT_THAT(damaged.output, Not(HasSubstr("another hash")));
  }
  // ... and a row whose other fields are not what the sample's folder and the dataset file give (other
  // parameters were taken, and the Python package selected the sample by them; an adversarial tester's find);
  // its bytes may differ (a copy of the folder without its hard links holds more)
  const auto edited = [&](const std::function<void(nlohmann::json&)>& edit) {
    std::istringstream rows(index);
    std::string text;
    for (std::string line; std::getline(rows, line);) {
      if (text.empty()) {
        nlohmann::json row = nlohmann::json::parse(line);
        edit(row);
        line = row.dump();
      }
      text += line + "\n";
    }
    write(dir_ / "out/index.jsonl", text);
    return sh(status);
  };
  for (const auto& [edit, says] : std::vector<std::pair<std::function<void(nlohmann::json&)>, std::string>>{
           {[](nlohmann::json& r) { r["parameters"]["laser.average_power_mW"] = 99; }, "row 1 gives sample 0 another parameters than"},
           {[](nlohmann::json& r) { r["seeds"]["chip"] = 12345; }, "row 1 gives sample 0 another seeds than its folder and the dataset file"},
           {[](nlohmann::json& r) { r["folder"] = "samples/000001"; }, "row 1 gives sample 0 another folder than its folder and the dataset "
                                                                        "file (\"samples/000001\", expected \"samples/000000\")"},
           {[](nlohmann::json& r) { r["repeats"] = nlohmann::json::array(); }, "row 1 gives sample 0 another repeats"},
           {[](nlohmann::json& r) { r.erase("ground_truth"); }, "row 1 gives sample 0 another ground_truth than its folder and the dataset file (none, "},
           {[](nlohmann::json& r) { r["note"] = 1; }, "row 1 holds note, which spadgen does not write for a done sample"}}) {
    const Result r = edited(edit);
    EXPECT_EQ(r.code, 4) << says << r.output;
    EXPECT_THAT(r.output, HasSubstr("index: " + out + "/index.jsonl " + says)) << r.output;
  }
  const Result bytes = edited([](nlohmann::json& r) { r["bytes"] = r["bytes"].get<int64_t>() + 4096; });
  EXPECT_EQ(bytes.code, 0) << bytes.output;
  // the run writes it again
  ASSERT_EQ(sh(run).code, 0);
  EXPECT_EQ(slurp(dir_ / "out/index.jsonl"), index);
  EXPECT_EQ(sh(status).code, 0);
}

// A plan of a folder with done samples tells how long they took against their estimates (metadata.json's
// run.wall_seconds) and the time left at that pace: the cost model is of one machine kind, and it planned
// small samples at 3-6 times what they took on another.
TEST_F(Dataset, APlanTellsThePaceOfTheDoneSamples) {
  write(dir_ / "d.json", small_dataset(2));
  const std::string out = (dir_ / "out").string();
  ASSERT_EQ(sh("dataset run " + (dir_ / "d.json").string() + " -o " + out + " -q").code, 0);
  const Result measured = sh("dataset plan " + (dir_ / "d.json").string() + " -o " + out);
  ASSERT_EQ(measured.code, 0) << measured.output;
  EXPECT_THAT(measured.output, HasSubstr("# the 2 done samples took "));
  // small samples' times in two digits (they read "0 s": a new user could not plan from them)
  const size_t per_sample = measured.output.find("# per sample: ");
  ASSERT_NE(per_sample, std::string::npos) << measured.output;
  const std::string line = measured.output.substr(per_sample, measured.output.find('\n', per_sample) - per_sample);
  EXPECT_THAT(line, HasSubstr(", time about 0.")) << line;
  EXPECT_THAT(measured.output, Not(HasSubstr("at that pace")));  // nothing left
  // ... and what they keep on disk against their disk estimates: the index's bytes, a share of the estimates at
  // most 1 where they are bounds (compressed files counted at their most: the example's 22.1 GB at most, 953 MB at
  // least, for about 3 GB written)
  int64_t kept = 0;
  std::istringstream rows(slurp(dir_ / "out/index.jsonl"));
  for (std::string row; std::getline(rows, row);) kept += json::parse(row)["bytes"].get<int64_t>();
  const std::string keep = "# the 2 done samples keep " + spadgen::bytes_text(kept) + " on disk, ";
  const size_t kept_at = measured.output.find(keep);
  ASSERT_NE(kept_at, std::string::npos) << measured.output;
  EXPECT_THAT(measured.output, HasSubstr("# per sample: disk up to about "));  // (the saved light: an estimate)
  const double share = std::stod(measured.output.substr(kept_at + keep.size()));
  EXPECT_GT(share, 0.05) << measured.output;
  EXPECT_LE(share, 1.0) << measured.output;
  EXPECT_THAT(measured.output, Not(HasSubstr("at that share")));  // nothing left
  // Each folder (two samples, two realisations each) said to have taken 50 s: 200 s in all, far more than
  // the model's estimate of these 24 x 20 pixels; the dataset grown to 4 samples, the two left of the
  // same size take about 200 s at that pace.
  for (const char* f : {"000000", "000000_r01", "000001", "000001_r01"}) {
    const fs::path meta = dir_ / "out/samples" / f / "metadata.json";
    json m = json::parse(slurp(meta));
    ASSERT_TRUE(m["run"]["wall_seconds"].is_number()) << f;
    m["run"]["wall_seconds"] = 50.0;
    write(meta, m.dump());
  }
  write(dir_ / "d4.json", small_dataset(4));
  const Result r = sh("dataset plan " + (dir_ / "d4.json").string() + " -o " + out);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string took = "# the 2 done samples took 3 min, ";
  const size_t at = r.output.find(took);
  ASSERT_NE(at, std::string::npos) << r.output;
  const double pace = std::stod(r.output.substr(at + took.size()));
  EXPECT_GT(pace, 20.0) << r.output;
  EXPECT_THAT(r.output, HasSubstr(" times their estimates (their metadata.json's run.wall_seconds, against estimates for the "
                                  "cores they ran on, run.cores): at that pace the samples left take about 3 min\n"));
  // the two left, estimated as the two done, keep what those keep
  EXPECT_THAT(r.output, HasSubstr(" of their disk estimates (their files but metadata.json, as index.jsonl's bytes): at that "
                                  "share the samples left keep about " + spadgen::bytes_text(kept) + "\n"));
  // The pace compares each sample with its estimate on the cores it ran on (run.cores), whatever the plan's
  // --threads (a plan with 2 cores called samples of 1 core's 2 times slower than they were: a new user's find);
  // the time left is for the plan's cores.
  const auto pace_of = [&](const std::string& options) {
    const Result p = sh("dataset plan " + (dir_ / "d4.json").string() + " -o " + out + options);
    const size_t a = p.output.find(took);
    return a == std::string::npos ? -1.0 : std::stod(p.output.substr(a + took.size()));
  };
  for (const char* f : {"000000", "000001"}) {  // the samples ran on 1 core
    const fs::path meta = dir_ / "out/samples" / f / "metadata.json";
    json m = json::parse(slurp(meta));
    ASSERT_TRUE(m["run"]["cores"].is_number_integer()) << f;
    m["run"]["cores"] = 1;
    write(meta, m.dump());
  }
  const double one_core = pace_of(" --threads 1");
  EXPECT_GT(one_core, 20.0);
  if (std::thread::hardware_concurrency() >= 2) {
    EXPECT_NEAR(pace_of(" --threads 2") / one_core, 1.0, 0.02);
  }
  // a sample whose metadata.json records no time does not count
  json m = json::parse(slurp(dir_ / "out/samples/000001/metadata.json"));
  m.erase("run");
  write(dir_ / "out/samples/000001/metadata.json", m.dump());
  json m1 = json::parse(slurp(dir_ / "out/samples/000001_r01/metadata.json"));
  m1.erase("run");
  write(dir_ / "out/samples/000001_r01/metadata.json", m1.dump());
  const Result one = sh("dataset plan " + (dir_ / "d4.json").string() + " -o " + out);
  EXPECT_THAT(one.output, HasSubstr("# the 1 done sample took 2 min, "));
  EXPECT_THAT(one.output, HasSubstr(" times its estimate (its metadata.json's run.wall_seconds"));
  EXPECT_THAT(sh("dataset plan " + (dir_ / "d4.json").string()).output, Not(HasSubstr("done sample")));
}

// A plan estimates a sample from its durations rounded up to 2 significant digits (app::estimate_shape: a
// continuous random pulse width made each sample an estimate of its own, 40 ms each): the rounding is up,
// and the rounded run's time window has as many bins as the exact one's, or a few more.
TEST(DatasetEstimate, TheRoundedDurationsCoverTheExactTimeWindow) {
  const struct {
    double value, rounded;
  } cases[] = {{57.3, 58}, {58, 58}, {123.4, 130}, {9.99, 10}, {1234.5, 1300}, {0, 0}};
  for (const auto& k : cases) {
    RunConfig c;
    c.laser.pulse_fwhm_s = k.value * 1e-12;
    EXPECT_NEAR(app::estimate_shape(c).laser.pulse_fwhm_s, k.rounded * 1e-12, 1e-9 * k.rounded * 1e-12) << k.value;
  }
  // A plan estimates one shape per rounded value: 12 widths in (57, 58] are one shape (they were 12).
  {
    const fs::path dir = fs::temp_directory_path() / ("spadgen_rounded_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    std::ofstream(dir / "d.json") << "{\"scenes\": [\"" + kScenes + "flat_target.json\"], \"samples\": 12, \"set\": "
                                     "{\"camera.crop\": [0, 0, 8, 8]}, \"random\": {\"laser.pulse_fwhm_ps\": {\"uniform\": [57.01, 58]}}}";
    const Result r = sh("dataset plan " + (dir / "d.json").string() + " -q");
    fs::remove_all(dir);
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("# 1 estimate computed, one per distinct shape of run"));
  }
  for (const char* set : {"laser.pulse_fwhm_ps=57.3", "laser.pulse_fwhm_ps=123.4", "sensor.jitter_fwhm_ps=33.3",
                          "sensor.gate.rise_ps=412", "sensor.gate.fall_ps=1234", "sensor.gate.length_ns=3.73",
                          "sensor.gate.length_fwhm_ps=111", "sensor.gate.skew_fwhm_ps=432.1"}) {
    SCOPED_TRACE(set);
    const RunConfig exact = scenes::load_scene_file(kScenes + "multi_object.json", {set}).config;
    const RunConfig rounded = app::estimate_shape(exact);
    EXPECT_NE(exact, rounded);
    const sensor::SensorModel se(sensor_stage(exact)), sr(sensor_stage(rounded));
    const TimeAxis a = app::time_axis(exact, se), b = app::time_axis(rounded, sr);
    EXPECT_LE(b.start_s, a.start_s + 1e-3 * a.bin_width_s);
    EXPECT_GE(b.bins, a.bins);  // what the disk and memory count
    EXPECT_LE(b.bins, a.bins + a.bins / 20) << a.bins << " bins exact, " << b.bins << " rounded";
    EXPECT_EQ(sr.K(), se.K());
  }
}

// A damaged sample whose regeneration fails (a file of the user's in its folder) is failed, with why (status
// and the index said damaged, to be generated again by the next run, which failed the same way).
TEST_F(Dataset, ADamagedSampleThatFailsAgainIsFailed) {
  write(dir_ / "d.json", small_dataset(2));
  const std::string run = "dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q";
  ASSERT_EQ(sh(run).code, 0);
  fs::resize_file(dir_ / "out/samples/000001/counts.npy", 1000);
  std::ofstream(dir_ / "out/samples/000001/notes.txt") << "mine";
  const Result r = sh(run);
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("holds files that spadgen did not write there (notes.txt"));
  const Result st = sh("dataset status " + (dir_ / "out").string());
  EXPECT_EQ(st.code, 4);
  EXPECT_THAT(st.output, HasSubstr("2 samples: 1 done, 1 failed, 0 stale, 0 missing\n"));
  EXPECT_THAT(st.output, HasSubstr("sample 1 failed: the output folder " + (dir_ / "out/samples/000001").string() +
                                   " holds files that spadgen did not write there (notes.txt"));
  EXPECT_THAT(st.output, Not(HasSubstr("damaged")));
  EXPECT_THAT(slurp(dir_ / "out/index.jsonl"), HasSubstr("\"status\":\"failed\""));
  EXPECT_EQ(slurp(dir_ / "out/samples/000001/notes.txt"), "mine");
}

// A sample stale because the scene resolves otherwise now names the first key that differs, with both values
// (a new default of spadgen, the gate's knots, made every sample stale "for a sensor table or the parameters").
TEST_F(Dataset, AStaleSampleNamesTheKeyItsSceneResolvesOtherwiseAt) {
  write(dir_ / "d.json", small_dataset(1));
  ASSERT_EQ(sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q").code, 0);
  const fs::path meta_path = dir_ / "out/samples/000000/metadata.json";
  nlohmann::json meta = nlohmann::json::parse(slurp(meta_path));
  meta["resolved_scene"]["sensor"]["gate"]["knots_per_edge"] = 64;  // as an earlier spadgen resolved it
  meta["dataset"]["sample_hash"] = "0123456789abcdef";
  std::ofstream(meta_path) << meta.dump(2);
  const Result st = sh("dataset status " + (dir_ / "out").string());
  EXPECT_EQ(st.code, 4);
  EXPECT_THAT(st.output, HasSubstr("stale 0: the scene as it resolves now differs at sensor.gate.knots_per_edge (64 in the "
                                   "sample, 256 now): a parameter, or a default of this spadgen"));
}

// A run starting while another holds the folder's lock (it writes the index: minutes for millions of samples)
// says that it waits, after 2 s (it sat silent), and a signal ends the wait.
TEST_F(Dataset, ARunWaitingForTheFoldersLockSaysSoAndStopsOnASignal) {
  write(dir_ / "d.json", small_dataset(1));
  const std::string run = kBin + " dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q";
  ASSERT_EQ(shell(run).code, 0);
  const std::string lock = (dir_ / "out/.dataset.lock").string();
  // (the lock held 5 s: the run's start-up and its check of the sample take over a second under the sanitizers on
  // a loaded machine, and its message comes 2 s after it reaches the lock)
  const Result waited = shell("flock " + lock + " sleep 5 & sleep 0.3; " + run + " 2>&1; echo rc=$?; wait");
  EXPECT_THAT(waited.output, HasSubstr("spadgen: dataset: waiting 2 s for " + lock + ", which another spadgen process holds"));
  EXPECT_THAT(waited.output, HasSubstr("rc=0"));
  // SIGTERM once it waits (not after a fixed second: under AddressSanitizer on a loaded machine the run was still
  // checking its sample then; a background job of a script ignores SIGINT)
  const std::string err = (dir_ / "wait.err").string();
  const Result stopped = shell("flock " + lock + " sleep 30 > /dev/null 2>&1 & f=$!; sleep 0.3; " + run + " 2> " + err + " & p=$!; " +
                               "for i in $(seq 600); do grep -q 'waiting 2 s' " + err + " && break; sleep 0.1; done; " +
                               "kill -TERM $p; wait $p; echo rc=$?; cat " + err + "; kill $f; wait");
  EXPECT_THAT(stopped.output, HasSubstr("interrupted by a signal while waiting for " + lock));
  EXPECT_THAT(stopped.output, HasSubstr("rc=2"));
}

// A sample's folder that holds another sample's run (a mistaken copy, a link) is said to (it was "the scene
// as it resolves now differs at laser.average_power_mW ...: a parameter, or a default of this spadgen"),
// and the next run generates it again.
TEST_F(Dataset, ASampleFolderHoldingAnotherSamplesRunIsNamed) {
  write(dir_ / "d.json", small_dataset(2));
  const std::string run = "dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q";
  ASSERT_EQ(sh(run).code, 0);
  fs::remove_all(dir_ / "out/samples/000000");
  fs::copy(dir_ / "out/samples/000001", dir_ / "out/samples/000000", fs::copy_options::recursive);
  const Result st = sh("dataset status " + (dir_ / "out").string());
  EXPECT_EQ(st.code, 4);
  EXPECT_THAT(st.output, HasSubstr("stale 0: samples/000000 holds the run of sample 1, as its metadata.json's dataset section says: "
                                   "a copy or a link of another sample's folder"));
  ASSERT_EQ(sh(run).code, 0);
  EXPECT_EQ(json::parse(slurp(dir_ / "out/samples/000000/metadata.json"))["dataset"]["index"], 0);
  EXPECT_EQ(sh("dataset status " + (dir_ / "out").string()).code, 0);
}

// What a dataset run killed while it wrote dataset.json or the index left (".dataset.json.tmp-PID-N", which
// stayed after a successful resume) goes with the next run on the folder.
TEST_F(Dataset, ADeadRunsTemporaryFilesGoWithTheNextRun) {
  write(dir_ / "d.json", small_dataset(1));
  const std::string run = "dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q";
  ASSERT_EQ(sh(run).code, 0);
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  ASSERT_GT(child, 0);
  ASSERT_EQ(::waitpid(child, nullptr, 0), child);
  const std::vector<fs::path> left = {dir_ / "out" / (".dataset.json.tmp-" + std::to_string(child) + "-0"),
                                      dir_ / "out" / (".index.csv.tmp-" + std::to_string(child) + "-3")};
  for (const fs::path& f : left) std::ofstream(f) << "{";
  ASSERT_EQ(sh(run).code, 0);
  for (const fs::path& f : left) EXPECT_FALSE(fs::exists(f)) << f;
}

// A sample whose folder another spadgen process holds (a reader: reconstruct, sense; here its lock taken by
// flock(1) as reconstruct takes it) is tried again when the others are done, and generated once the holder
// lets go: it was recorded as failed, the run exiting 1 ("or choose another folder (-o)").
TEST_F(Dataset, ASampleAReaderHoldsIsGeneratedOnceItIsReleased) {
  write(dir_ / "d.json", small_dataset(2));
  const std::string run = "dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q";
  ASSERT_EQ(sh(run).code, 0);
  // the CPU the two samples take, generated again with no holder
  const fs::path cpu0 = dir_ / "cpu0.txt";
  for (const char* f : {"000000", "000001"}) fs::remove(dir_ / "out/samples" / f / "counts.npy");
  ASSERT_EQ(shell("bash -c 'TIMEFORMAT=%U; { time " + kBin + " " + run + "; } 2> " + cpu0.string() + "'").code, 0);
  fs::remove(dir_ / "out/samples/000001/counts.npy");  // damaged: generated again
  const fs::path lock = dir_ / "out/samples/.000001.spadgen-lock";
  const auto started = std::chrono::steady_clock::now();
  // (started once the lock is held: flock writes READY under it; two samples held, so that the run waits on
  // both, which spun without a pause when it restarted its count of held samples on each)
  fs::remove(dir_ / "out/samples/000000/counts.npy");
  const fs::path lock0 = dir_ / "out/samples/.000000.spadgen-lock";
  const std::string ready = (dir_ / "READY").string();
  const fs::path cpu = dir_ / "cpu.txt";
  const Result r = shell("(flock -x " + lock0.string() + " flock -x " + lock.string() + " sh -c 'touch " + ready +
                         "; sleep 5' > /dev/null 2>&1 &) && while [ ! -e " + ready + " ]; do sleep 0.05; done && bash -c " +
                         "'TIMEFORMAT=%U; { time " + kBin + " " + run + "; } 2> " + cpu.string() + "'");
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(r.output, "");
  EXPECT_GE(took, 5.0);  // it waited for the holder
  // Its CPU beside the samples' own: a run that spun while it waited took the 5 s of the hold on top (at least
  // half of it on a loaded 2-core machine). A margin of a quarter of the samples' own: under the sanitizers the
  // samples took 3.8-4.4 s of CPU, and the run that waited 0.03-0.63 s more, with tries every 0.2 s growing to 1 s
  // (0.5-1.03 s more, tried every 0.2 s, once failing a bound of 1 s).
  const double own = std::stod(slurp(cpu0));
  EXPECT_LT(std::stod(slurp(cpu)), 1.25 * own + 1.0) << "seconds of CPU, against the samples' own " << own;
  EXPECT_FALSE(fs::exists(dir_ / "out/failed"));
  const Result st = sh("dataset status " + (dir_ / "out").string());
  EXPECT_EQ(st.code, 0) << st.output;
  EXPECT_THAT(st.output, HasSubstr("2 samples: 2 done, 0 failed, 0 stale, 0 missing"));
}

// A sample made stale (its scene changed) whose regeneration fails is failed, with why, in the status and the
// index (it was "stale" without its error, which only failed/ held); the card escapes a '|' of a scene's path
// or a value in its Markdown tables (a row had 7 cells for 6).
// A sample whose run read other contents of the scene file or glTF than the dataset's hash of them (the glTF
// edited while the dataset ran, and restored after: the sample's data is of the edit, its sample_hash of the
// original) is stale, saying so: it was done (a verifier's find). Its metadata.json records the bytes its run
// read (scene_hash_fnv1a64); here another value stands for the edit's.
TEST_F(Dataset, ASampleRenderedFromEditedSceneFilesIsStale) {
  write(dir_ / "d.json", "{\"seed\": 1, \"scenes\": [\"" + kScenes + "flat_target.json\"], \"samples\": 2, "
        "\"set\": {\"camera.crop\": [500, 240, 4, 4], \"render.samples_per_pixel\": 1}}");
  const std::string run = "dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q";
  ASSERT_EQ(sh(run).code, 0);
  const fs::path meta = dir_ / "out/samples/000001/metadata.json";
  nlohmann::ordered_json m = nlohmann::ordered_json::parse(slurp(meta));
  const std::string read = m["scene_hash_fnv1a64"];
  m["scene_hash_fnv1a64"] = "0123456789abcdef";
  write(meta, m.dump(2));
  const Result status = sh("dataset status " + (dir_ / "out").string());
  EXPECT_EQ(status.code, 4) << status.output;
  EXPECT_THAT(status.output, HasSubstr("rendered from other contents of the scene file or its glTF (scene_hash_fnv1a64 "
                                       "0123456789abcdef, now " + read + "): they changed while it was generated"));
  ASSERT_EQ(sh(run).code, 0);  // generated again
  EXPECT_EQ(nlohmann::json::parse(slurp(meta))["scene_hash_fnv1a64"], read);
  EXPECT_EQ(sh("dataset status " + (dir_ / "out").string()).code, 0);
}

TEST_F(Dataset, AStaleSampleThatFailsAgainIsFailedAndTheCardKeepsItsTables) {
  const fs::path scenes = dir_ / "a|b";
  fs::create_directories(scenes);
  for (const char* f : {"multi_object.json", "multi_object.gltf", "multi_object.bin"}) fs::copy_file(kScenes + f, scenes / f);
  write(dir_ / "d.json", "{\"seed\": 1, \"scenes\": [\"" + (scenes / "multi_object.json").string() + "\"], \"samples\": 2, "
        "\"description\": \"\\nPlates\\nof two lines\", "
        "\"set\": {\"camera.crop\": [500, 240, 4, 4], \"render.samples_per_pixel\": 1}, "
        "\"random\": {\"description\": {\"choice\": [\"x|y\", \"z\"]}}}");
  const std::string run = "dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q";
  ASSERT_EQ(sh(run).code, 0);
  // a description of several lines: its first (not blank) is the title, the rest a paragraph (the heading
  // was broken)
  EXPECT_EQ(slurp(dir_ / "out/dataset.md").rfind("# Plates\n\nof two lines\n\nA synthetic", 0), 0u) << slurp(dir_ / "out/dataset.md");
  std::ifstream card(dir_ / "out/dataset.md");
  int columns = 0, rows = 0;
  for (std::string line; std::getline(card, line);) {
    if (line.empty() || line[0] != '|') {
      columns = 0;
      continue;
    }
    int cells = 0;  // unescaped '|'
    for (size_t i = 0; i < line.size(); ++i) cells += line[i] == '|' && (i == 0 || line[i - 1] != '\\');
    if (columns == 0) columns = cells;
    EXPECT_EQ(cells, columns) << line;
    ++rows;
  }
  EXPECT_GT(rows, 10);
  EXPECT_THAT(slurp(dir_ / "out/dataset.md"), HasSubstr("a\\|b/multi_object.json"));
  std::ofstream(dir_ / "out/samples/000001/notes.txt") << "mine";
  std::string scene = slurp(scenes / "multi_object.json");
  scene.replace(scene.find("\"wavelength_nm\": 510"), 20, "\"wavelength_nm\": 520");
  write(scenes / "multi_object.json", scene);
  EXPECT_EQ(sh(run).code, 1);
  const Result st = sh("dataset status " + (dir_ / "out").string());
  EXPECT_THAT(st.output, HasSubstr("2 samples: 1 done, 1 failed, 0 stale, 0 missing"));
  EXPECT_THAT(st.output, HasSubstr("sample 1 failed: the output folder " + (dir_ / "out/samples/000001").string() +
                                   " holds files that spadgen did not write there (notes.txt"));
  EXPECT_THAT(slurp(dir_ / "out/index.jsonl"), HasSubstr("\"status\":\"failed\""));
}

// The first sample failing is one failing sample too (it was a refusal of the whole dataset); only when
// every sample probed fails is the dataset refused, before any work, in one line.
TEST_F(Dataset, AnInvalidFirstSampleIsRecordedAndAnInvalidDatasetRefused) {
  write(dir_ / "d.json", small_dataset(4, 3, kScenes + "multi_object.json", ", \"camera.width_px\": [16, 1024]"));
  Result r = sh("dataset run " + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("2 samples failed (0, 2)"));
  EXPECT_TRUE(fs::exists(dir_ / "out/samples/000001/metadata.json"));
  EXPECT_TRUE(fs::exists(dir_ / "out/failed/000000.json"));

  write(dir_ / "e.json", small_dataset(4, 3, kScenes + "multi_object.json", ", \"camera.width_px\": [16]"));
  r = sh("dataset run " + (dir_ / "e.json").string() + " -o " + (dir_ / "e").string() + " -q");
  EXPECT_EQ(r.code, 1);
  // the key at its place in the dataset file, with the sample's parameters that make it invalid
  EXPECT_THAT(r.output, HasSubstr("e.json: sample 0 (laser.average_power_mW 1, camera.width_px 16, "));
  EXPECT_THAT(r.output, HasSubstr("): /set/camera.crop: found [496, 232, 24, 20], expected a rectangle inside the 16 x 500 sensor "
                                  "(and the next 3 samples of this scene fail too)"));
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_FALSE(fs::exists(dir_ / "e"));
}

// A scene file whose glTF does not load makes every sample of it invalid: plan says so (exit 1) and run refuses
// the dataset before any work, with the loader's message (plan called it valid, and run failed every sample: a
// verifier's index out of range).
TEST_F(Dataset, ADatasetWhoseGltfDoesNotLoadIsRefusedBeforeAnyWork) {
  std::string bin(44, '\0');  // 3 vertices at the origin, then the indices 0, 1, 5 (UNSIGNED_SHORT) and padding
  bin[37] = 0, bin[38] = 1, bin[40] = 5;
  std::ofstream(dir_ / "m.bin", std::ios::binary) << bin;
  const json g = {
      {"asset", {{"version", "2.0"}}}, {"scene", 0}, {"scenes", {{{"nodes", {0}}}}}, {"nodes", {{{"mesh", 0}}}},
      {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"indices", 1}}}}}}},
      {"accessors", {{{"bufferView", 0}, {"componentType", 5126}, {"count", 3}, {"type", "VEC3"}, {"min", {0, 0, 0}}, {"max", {0, 0, 0}}},
                     {{"bufferView", 1}, {"componentType", 5123}, {"count", 3}, {"type", "SCALAR"}}}},
      {"bufferViews", {{{"buffer", 0}, {"byteLength", 36}}, {{"buffer", 0}, {"byteOffset", 36}, {"byteLength", 6}}}},
      {"buffers", {{{"byteLength", 44}, {"uri", "m.bin"}}}}};
  write(dir_ / "m.gltf", g.dump());
  write(dir_ / "scene.json", R"({"gltf": "m.gltf", "camera": {"position_m": [0, 0, 2], "look_at_m": [0, 0, 0], "width_px": 8,
    "height_px": 8, "vertical_fov_deg": 40}})");
  write(dir_ / "d.json", "{\"scenes\": [\"scene.json\"], \"samples\": 3}");
  const std::string loader = "m.gltf: mesh 0 primitive 0: index 5 at position 2 of accessor 1 is out of range of the 3 vertices";
  for (const char* cmd : {"dataset plan ", "dataset run "}) {
    const Result r = sh(cmd + (dir_ / "d.json").string() + " -o " + (dir_ / "out").string() + " -q");
    EXPECT_EQ(r.code, 1) << cmd << r.output;
    EXPECT_THAT(r.output, HasSubstr("d.json: sample 0: with the scene file scene.json: "));
    EXPECT_THAT(r.output, HasSubstr(loader));
    EXPECT_THAT(r.output, HasSubstr("(and the next 2 samples of this scene fail too)"));
    EXPECT_FALSE(fs::exists(dir_ / "out"));
  }
}

// A sample's metadata.json whose list of files was damaged to hold "" (the sample's folder itself): status
// called the sample damaged and said run would generate it again, while run kept it as done (its check of the
// listed files took the folder for a file of its size). Both now apply one rule: run tries it again, and,
// as the folder holds a file its metadata.json no longer lists, records why it leaves it (never replacing files
// it cannot tell are its own); status says so, before the run (it said the run would generate the sample
// again) and after. Found by the soak of soak_test.cpp.
TEST_F(Dataset, ASampleListingItsOwnFolderAsAFileIsDamagedForStatusAndRunAlike) {
  write(dir_ / "d.json", tiny_dataset());
  const fs::path out = dir_ / "out", meta = out / "samples/000001/metadata.json";
  const std::string run = "dataset run " + (dir_ / "d.json").string() + " -o " + out.string() + " -q";
  ASSERT_EQ(sh(run).code, 0);
  json m = json::parse(slurp(meta));
  ASSERT_EQ(m["files"][4], "labels.exr");
  m["files"][4] = "";
  write(meta, m.dump(1));
  const Result before = sh("dataset status " + out.string());
  EXPECT_EQ(before.code, 4) << before.output;
  EXPECT_THAT(before.output, HasSubstr("sample 1 damaged: listed in metadata.json but gone or changed:  (a folder, where the run wrote a file)"));
  EXPECT_THAT(before.output, HasSubstr("(a folder, where the run wrote a file) (`spadgen dataset run` cannot generate it again: "
                                       "samples/000001 holds labels.exr, which its metadata.json does not list, and a run replaces "
                                       "only files it can tell are its own; move or remove samples/000001 and run again)"));
  const Result r = sh(run);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("sample 1 failed: the output folder " + (out / "samples/000001").string() +
                                  " holds files that spadgen did not write there (labels.exr; not listed in its metadata.json)"));
  EXPECT_TRUE(fs::exists(out / "samples/000001/labels.exr"));  // left where it was
  const Result after = sh("dataset status " + out.string());
  EXPECT_EQ(after.code, 4) << after.output;
  EXPECT_THAT(after.output, HasSubstr("1 done, 1 failed"));
}

}  // namespace
}  // namespace spadgen::testing
