// `spadgen dataset plan|run|status`: a benchmark dataset from a dataset file (datasets/dataset.h), one
// run folder per sample (datasets/folder.h), sharded over Slurm job arrays or Kubernetes Indexed Jobs.
#pragma once
#include <cstdint>
#include <optional>
#include <string>

#include "core/config.h"

namespace spadgen::app {

struct DatasetOptions {
  std::string file;                  // the dataset file (plan, run)
  std::string out_dir;               // the dataset folder (run: required; plan: optional, to show what is done)
  std::optional<std::string> shard;  // "I/N"; absent: from the environment (Slurm, Kubernetes), else 0/1
  int threads = 0;                   // per sample run, as `spadgen run --threads`
  bool all = false;                  // plan: list every sample, not the first and last 10
  bool progress = true;
};

// The samples with their parameters and seeds, and estimates of disk, memory and time per sample and in
// total; with out_dir, which samples are done there and the free disk. Samples whose parameters make an
// invalid scene (or a run the sensor refuses) are listed with their errors at the end and counted
// (`dataset plan` then exits 1).
struct DatasetPlan {
  std::string text;
  int64_t invalid = 0;
  std::string invalid_text;  // "FILE: 4 samples (1, 3, 5-6) make an invalid run ..." when some do
};
DatasetPlan dataset_plan(const DatasetOptions& options);

// Generates the shard's samples that are not done, each published as one unit; skips done ones; refuses
// to start when the free disk is below the estimate. Rewrites the index and the card at the end when no other
// run is on the folder (the last run to end writes them: datasets::RunPresence). Throws
// spadgen::Error after the index is written when samples failed (their errors are in DIR/failed/).
void dataset_run(const DatasetOptions& options);

// Done, failed, stale, missing and damaged samples of a dataset folder: the report, and whether every
// sample is done (`dataset status` exits kExitIncomplete otherwise).
struct DatasetStatus {
  std::string text;
  bool complete = false;
};
DatasetStatus dataset_status(const std::string& dir);

// The run whose estimate stands for c's in a plan: c with the durations that set the width of the gate
// response (the pulse, the jitter, the gate's edges, its length and its spread) rounded up to 2 significant
// digits. A continuous random pulse width made every sample a distinct estimate of about 40 ms (the gate's
// tabulation and the chip's maps): half an hour of CPU for a plan of 50,000 samples. The rounded values
// widen the time window by up to a tenth of each duration (a gate of 10.1 ns estimated as 11 ns: 100 bins
// more of 3094), never narrow it: the disk and memory are over-estimated a little, never under.
RunConfig estimate_shape(RunConfig c);

// A dataset folder as its dataset.json records it: the dataset's samples, and whether a dataset run is on
// the folder now (its index.jsonl is then the last run's until the last run on it ends).
struct DatasetFolderState {
  int64_t samples = 0;
  bool run_on = false;
};
DatasetFolderState dataset_folder_state(const std::string& dir);
// "INDEX has N rows for the dataset's M samples (dataset.json)": index.jsonl against dataset.json, as `dataset
// status` and `evaluate` say it; with no run on the folder, index_rows_cause follows (why, and the remedy).
std::string index_rows_text(const std::string& index_path, int64_t rows, int64_t samples);
std::string index_rows_cause();

// The dataset file reference (Markdown), for docs/datasets.md.
std::string dataset_schema();

// Seconds a run of `c` is expected to take on this machine kind (2 cores), from a cost model measured on
// the shipped scenes (docs/datasets.md, "Estimates"). threads: as --threads (0 = all cores).
struct RunEstimate {
  int64_t disk_bytes = 0, memory_bytes = 0;
  double seconds = 0.0;
};

}  // namespace spadgen::app
