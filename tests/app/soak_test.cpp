// Soaks of what spadgen reads back: its outputs damaged or edited at random places (a value of another type or out
// of range, a key or element removed), from fixed seeds, read by every command that reads them. Each command
// ends by itself in success or spadgen's own error, never an internal error, a signal or the time limit, and
// prints UTF-8 lines of spadgen's own. Each soak found bugs when it was first run by hand (the tests say which);
// here they keep the whole class covered. A program of its own: the sanitizer build runs its hundreds of
// commands with the instrumented program, slower than the hardening tests' time limit allows.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "app_fixture.h"

namespace spadgen::testing {
namespace {

using json = nlohmann::json;
using ::testing::HasSubstr;
using ::testing::Not;
using Soak = App;

void write(const fs::path& p, const std::string& text) { std::ofstream(p) << text; }

// `spadgen ARGS` under a time limit of 60 s (exit 124 at it): its exit code and its stderr alone (its stdout
// into *out, if given).
std::pair<int, std::string> stderr_of(const std::string& args, std::string* out = nullptr) {
  const fs::path err = fs::temp_directory_path() / ("spadgen_soak_err_" + std::to_string(::getpid()));
  const Result r = shell("(timeout -s KILL 60 " + kBin + " " + args + " 2> " + err.string() + ")");
  std::pair<int, std::string> result{r.code, slurp(err)};
  if (out) *out = r.output;
  fs::remove(err);
  return result;
}

// The samples `dataset status`'s report (its stdout) calls damaged and says `dataset run` generates again
// (first) or cannot (second).
std::pair<std::set<int>, std::set<int>> damaged_remedies(const std::string& report) {
  std::pair<std::set<int>, std::set<int>> r;
  std::istringstream in(report);
  for (std::string line; std::getline(in, line);) {
    int sample = -1;
    if (std::sscanf(line.c_str(), "sample %d damaged:", &sample) != 1) continue;
    if (line.ends_with("(`spadgen dataset run` generates it again)")) r.first.insert(sample);
    else if (line.find("(`spadgen dataset run` cannot generate it again: ") != std::string::npos) r.second.insert(sample);
    else ADD_FAILURE() << "a damaged sample without what the run does: " << line;
  }
  return r;
}

// A run folder's metadata.json damaged at random (a value of another type or out of range, a key or element
// removed, at any place of it: 48 cases from a fixed seed), then read by `reconstruct`, `evaluate` and `sense`:
// each ends by itself in success or an error of spadgen's (exit 0 or 1), never an internal error, a signal or
// the time limit, and prints UTF-8 text: lines of spadgen's own, the error last (1,500 cases from another seed
// passed too, in 102 s). A soak of 2,800 such cases found four internal errors (an entry of /model of another
// shape, the gate's rise as an object, a detections file's spadgen_source, an earlier metrics.json), each fixed
// with a test of its own; this keeps the whole class in the suite.
TEST_F(Soak, ADamagedMetadataJsonIsAnErrorOfSpadgensInEveryReader) {
  const fs::path run = dir_ / "run";
  ASSERT_EQ(stderr_of("run " + kTiny + " --set outputs.light=true -q -o " + run.string()).first, 0);
  const std::string original = slurp(run / "metadata.json");
  const nlohmann::json meta = nlohmann::json::parse(original);
  const size_t places = json_places(meta).size();
  ASSERT_GT(places, 200u);
  const auto commands = [&] {
    return std::vector<std::pair<std::string, std::string>>{
        {"reconstruct", "reconstruct " + run.string() + " -q"},
        {"evaluate", "evaluate " + run.string() + " -q -o " + (dir_ / "evaluation").string()},
        {"sense", "sense " + run.string() + " -q -o " + (dir_ / "sense").string()}};
  };
  // The run as it was: every reader succeeds.
  for (const auto& [name, args] : commands()) EXPECT_EQ(stderr_of(args).first, 0) << name << " of the undamaged run";
  Splitmix rng{20261207};
  size_t errors = 0, successes = 0;
  constexpr int kCases = 48;
  for (int c = 0; c < kCases; ++c) {
    nlohmann::json m = meta;
    const std::string what = damage_json(m, rng);
    std::ofstream(run / "metadata.json", std::ios::trunc) << m.dump(1);
    for (const auto& [name, args] : commands()) {
      fs::remove_all(dir_ / "evaluation");
      fs::remove_all(dir_ / "sense");
      const auto [code, err] = stderr_of(args);
      const std::string where = name + " with " + what;
      EXPECT_TRUE(code == 0 || code == 1) << where << ": exit " << code << " (124: the time limit)\n" << err;
      EXPECT_EQ(stderr_problem(err, code == 1), "") << where << ": " << err;
      (code == 1 ? errors : successes) += 1;
    }
  }
  std::ofstream(run / "metadata.json", std::ios::trunc) << original;
  std::printf("%zu places of metadata.json; %d damaged: %zu errors and %zu successes of the three readers\n", places, kCases,
              errors, successes);
  EXPECT_GT(errors, 20u);  // the damage is read, and named, not ignored wholesale
}

// A dataset folder's own files damaged at random (dataset.json, a row of index.jsonl or a sample's metadata.json:
// a value of another type or out of range, a key or element removed; or a sample's data: a file it lists removed
// or cut short, its entry in the list renamed, its recorded size edited; 40 cases from a fixed seed), then read
// by `dataset status` and `dataset run`: each ends by itself in success, an error (exit 1) or, for status,
// samples not done (exit 4), never an internal error, a signal or the time limit, its stderr spadgen's own
// lines; what status says the run does with each damaged sample (generate it again, or leave it failed for a
// file its list does not name), the run does; and after a run that succeeds, status finds every sample done.
// (The soak of 400 such cases that kept this in mind ran the same checks.)
TEST_F(Soak, ADamagedDatasetFolderIsNamedByStatusAndRepairedOrRefusedByRun) {
  write(dir_ / "d.json", tiny_dataset(", \"random\": {\"laser.average_power_mW\": {\"uniform\": [1, 2]}}"));
  const fs::path pristine = dir_ / "pristine", out = dir_ / "out";
  ASSERT_EQ(sh("dataset run " + (dir_ / "d.json").string() + " -o " + pristine.string() + " -q").code, 0);
  Splitmix rng{7};
  std::map<std::string, int> outcomes;
  size_t promised_again = 0, promised_not = 0;  // damaged samples status said run generates again, or cannot
  for (int c = 0; c < 40; ++c) {
    fs::remove_all(out);
    fs::copy(pristine, out, fs::copy_options::recursive);
    // the file, and its damage
    const size_t which = rng.below(4);
    std::string what;
    if (which == 3) {  // a sample's files: one it lists removed or cut short, its entry renamed, its size edited
      const std::string folder = "samples/00000" + std::to_string(rng.below(2));
      const fs::path meta_path = out / folder / "metadata.json";
      json meta = json::parse(slurp(meta_path));
      std::vector<size_t> listed;  // the entries of files but metadata.json
      for (size_t e = 0; e < meta["files"].size(); ++e)
        if (meta["files"][e] != "metadata.json") listed.push_back(e);
      ASSERT_FALSE(listed.empty());
      const size_t e = listed[rng.below(listed.size())];
      const std::string name = meta["files"][e];
      const fs::path file = out / folder / name;
      switch (rng.below(4)) {
        case 0:
          fs::remove_all(file);
          what = folder + "/" + name + " removed";
          break;
        case 1:
          if (fs::is_regular_file(file)) fs::resize_file(file, fs::file_size(file) / 2);
          else fs::remove_all(file);
          what = folder + "/" + name + " cut short";
          break;
        case 2: {
          const std::string names[] = {"", "other.npy", meta["files"][listed[rng.below(listed.size())]]};
          meta["files"][e] = names[rng.below(3)];
          what = folder + "/metadata.json files[" + std::to_string(e) + "] " + name + " -> \"" + meta["files"][e].get<std::string>() + "\"";
          break;
        }
        default:
          meta["file_bytes"][name] = rng.below(1000);
          what = folder + "/metadata.json file_bytes of " + name + " -> " + meta["file_bytes"][name].dump();
      }
      write(meta_path, meta.dump(1));
    } else if (which == 1) {  // a row of index.jsonl
      std::vector<std::string> rows;
      for (std::istringstream in(slurp(out / "index.jsonl")); std::getline(in, rows.emplace_back());) {
      }
      rows.pop_back();
      ASSERT_EQ(rows.size(), 2u);
      const size_t r = rng.below(rows.size());
      json row = json::parse(rows[r]);
      what = "index.jsonl row " + std::to_string(r) + " " + damage_json(row, rng);
      rows[r] = row.dump();
      std::string text;
      for (const std::string& line : rows) text += line + "\n";
      write(out / "index.jsonl", text);
    } else {
      const std::string file = which == 0 ? "dataset.json" : "samples/00000" + std::to_string(rng.below(2)) + "/metadata.json";
      json doc = json::parse(slurp(out / file));
      what = file + " " + damage_json(doc, rng);
      write(out / file, doc.dump(1));
    }
    std::string report, run_out;
    const auto [status_code, status_err] = stderr_of("dataset status " + out.string(), &report);
    EXPECT_TRUE(status_code == 0 || status_code == 1 || status_code == 4) << "status with " << what << ": exit " << status_code
                                                                          << "\n" << status_err;
    EXPECT_EQ(stderr_problem(status_err, status_code == 1), "") << "status with " << what << ": " << status_err;
    const auto [run_code, run_err] = stderr_of("dataset run " + (dir_ / "d.json").string() + " -o " + out.string() + " -q", &run_out);
    EXPECT_TRUE(run_code == 0 || run_code == 1) << "run with " << what << ": exit " << run_code << "\n" << run_err;
    EXPECT_EQ(stderr_problem(run_err, run_code == 1), "") << "run with " << what << ": " << run_err;
    // a folder status found all done, the run takes, unless status said the dataset file's run would stop, and why
    const std::string would_stop = " on this folder would stop now: ";
    if (const size_t stop = report.find(would_stop); stop != std::string::npos) {
      EXPECT_EQ(run_code, 1) << "status said the run would stop, with " << what << "\n" << report;
      const size_t from = stop + would_stop.size(), end = report.find('\n', from);
      EXPECT_THAT(run_err, HasSubstr(report.substr(from, end - from))) << "with " << what;
    } else if (status_code == 0) {
      EXPECT_EQ(run_code, 0) << "status found every sample done, with " << what << "\n" << report << run_err;
    }
    // what status said the run does with each damaged sample, it does
    const auto [again, not_again] = damaged_remedies(report);
    for (int sample : again)
      EXPECT_THAT(run_out + run_err, Not(HasSubstr("sample " + std::to_string(sample) + " failed")))
          << "status said run generates sample " << sample << " again, with " << what << "\n" << report;
    for (int sample : not_again)
      EXPECT_THAT(run_out + run_err, HasSubstr("sample " + std::to_string(sample) + " failed: the output folder "))
          << "status said run cannot generate sample " << sample << " again, with " << what << "\n" << report;
    promised_again += again.size(), promised_not += not_again.size();
    if (run_code == 0) {
      const auto [after, after_err] = stderr_of("dataset status " + out.string());
      EXPECT_EQ(after, 0) << "status after the run with " << what << "\n" << after_err;
    }
    ++outcomes["status " + std::to_string(status_code) + ", run " + std::to_string(run_code)];
  }
  for (const auto& [o, n] : outcomes) std::printf("%s: %d\n", o.c_str(), n);
  std::printf("damaged samples: %zu that the run generates again, %zu that it leaves failed, as status said\n", promised_again,
              promised_not);
  EXPECT_GE(promised_again + promised_not, 5u);  // the sample damage reaches status as damage
  EXPECT_GE(outcomes.size(), 2u);  // the damage is read, not ignored wholesale
}

}  // namespace
}  // namespace spadgen::testing
