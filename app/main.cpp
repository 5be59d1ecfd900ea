// spadgen: synthetic datasets for time-gated SPAD cameras.
//   spadgen run SCENE.json [-o DIR] [--set KEY=VALUE]... [--seed S] [--threads N]
//   spadgen sense RUN_DIR [-o DIR] [--set KEY=VALUE]... [--noise-seed S] [--chip-seed S] [--repeats R]
//   spadgen info SCENE.json [--set KEY=VALUE]...
//   spadgen schema                 # the reference of every scene-file key (Markdown)
//   spadgen dataset plan FILE [-o DIR] [--shard I/N] [--all] [-q]
//   spadgen dataset run FILE -o DIR [--shard I/N] [--threads N] [-q]
//   spadgen dataset status DIR
//   spadgen dataset schema         # the reference of the dataset file (Markdown)
//   spadgen reconstruct RUN_DIR [--detector edges|paper] [-o FILE] [--noise-free]
//   spadgen evaluate RUN_DIR|DATASET_DIR [--detections FILE] [--tolerance-m T] [--region X,Y,W,H]
#include <CLI/CLI.hpp>

#include <malloc.h>
#include <sys/resource.h>

#include <fcntl.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <csignal>
#include <filesystem>
#include <cstdio>
#include <iostream>
#include <sstream>

#include "app/cli.h"
#include "app/dataset.h"
#include "datasets/dataset.h"
#include "app/interrupt.h"
#include "app/pipeline.h"
#include "app/reconstruct.h"
#include "app/run_parts.h"
#include "core/error.h"
#include "core/mapped_files.h"
#include "scenes/scene_file.h"

#ifndef SPADGEN_VERSION
#define SPADGEN_VERSION "dev"
#endif

int main(int argc, char** argv) {
  spadgen::app::flush_denormals();  // before TBB or any thread starts (app/run_parts.h)
  spadgen::install_mapped_file_fault_handler();  // a mapped input cut short: an error naming it, not a SIGBUS
  spadgen::app::install_startup_interrupt_handlers();  // a signal before a run's guard: exit 2, as within it
  // Closed standard streams are opened on /dev/null first: else the next file opened takes descriptor 2
  // (or 0, 1) and progress lines and warnings are written into it (a counts.npy began "spadgen: ...").
  // Standard output on /dev/full: a command's output printed there fails, said, rather than lost with exit 0.
  for (int fd = 0; fd <= 2; ++fd)
    if (::fcntl(fd, F_GETFD) == -1 && errno == EBADF) {
      int opened = fd == 1 ? ::open("/dev/full", O_WRONLY) : -1;
      if (opened == fd) spadgen::app::note_stdout_closed();
      else opened = ::open("/dev/null", fd == 0 ? O_RDONLY : O_WRONLY);
      if (opened != fd) return spadgen::app::kExitInternal;  // the lowest free descriptor is fd: it cannot differ
    }
  // --threads: 0 is every core; beyond kMaxThreads the system refuses threads (a 100000 failed in TBB).
  // (a whole number: 1e3 was "not in range 0 to 1024")
  const auto whole_in = [](int lo, int hi, const std::string& expected) {
    return CLI::Validator(
        [lo, hi, expected](std::string& v) {
          const bool digits = !v.empty() && v.size() <= 9 && v.find_first_not_of("0123456789") == std::string::npos;
          if (digits && std::stoi(v) >= lo && std::stoi(v) <= hi) return std::string();
          return "found '" + v + "', expected " + expected;
        },
        expected);
  };
  const CLI::Validator kThreadsRange =
      whole_in(0, spadgen::app::kMaxThreads, "an integer in [0, " + std::to_string(spadgen::app::kMaxThreads) + "] (0: every core)");
  // A folder to read. One absent because a run replacing it was stopped in its swap (a file system without an
  // atomic exchange) names the earlier set the run moved aside (it said only "Directory does not exist").
  const CLI::Validator kExistingFolder(
      [](std::string& v) {
        namespace fs = std::filesystem;
        std::error_code ec;
        if (fs::is_directory(v, ec)) return std::string();
        if (fs::exists(v, ec)) return v + " is not a folder";
        fs::path p = fs::path(v).lexically_normal();
        if (p.filename().empty()) p = p.parent_path();
        const fs::path parent = p.parent_path().empty() ? fs::path(".") : p.parent_path();
        const std::string aside = "." + p.filename().string() + ".spadgen-old-";
        std::string found;  // the newest, as the next run takes it back (Staging)
        fs::file_time_type newest{};
        for (const auto& e : fs::directory_iterator(parent, ec))
          if (e.path().filename().string().rfind(aside, 0) == 0 && e.is_directory(ec))
            if (const auto t = e.last_write_time(ec); found.empty() || t > newest) found = e.path().string(), newest = t;
        if (found.empty()) return "no such folder: " + v;
        return "no such folder: " + v + "; a run replacing it was stopped during its swap and left its earlier files in " +
               found + ", which the next `spadgen run -o " + v + "` puts back and then replaces with its own files (to keep them, " +
               "move it back yourself: mv " + found + " " + v + ")";
      },
      "DIR");
  // A file to read, said in spadgen's words (CLI11's were "scene: File is actually a directory: d"); a FIFO or
  // a device passes here and is refused when read, named as such.
  const auto existing_file = [](const std::string& expected) {
    return CLI::Validator(
        [expected](std::string& v) {
          namespace fs = std::filesystem;
          std::error_code ec;
          const auto st = fs::status(v, ec);
          if (fs::is_directory(st)) return v + " is a folder; expected " + expected;
          if (fs::exists(st)) return std::string();
          if (ec && ec != std::errc::no_such_file_or_directory) return v + ": " + ec.message() + "; expected " + expected;
          // (`--set A=1 B=2 SCENE`: B=2 was taken for the scene)
          return "no such file: " + v + "; expected " + expected +
                 (v.find('=') != std::string::npos ? " (each --set takes one KEY=VALUE: --set " + v + ")" : std::string());
        },
        "FILE");
  };
  const CLI::Validator kSceneFile = existing_file("a scene file (.json)");
  const CLI::Validator kDatasetFile = existing_file("a dataset file (.json)");
  // -o "" (an unset shell variable) is a mistake, not a request for the default folder; so is an option's name
  // (`-o -q` wrote into a folder named -q, and the run was not quiet).
  const CLI::Validator kNamed(
      [](std::string& v) {
        if (v.empty()) return std::string("expected a path, found an empty one");
        const bool short_option = v.size() == 2 && v[0] == '-' && std::isalpha(static_cast<unsigned char>(v[1]));
        const bool long_option = v.size() > 2 && v.compare(0, 2, "--") == 0 && std::isalpha(static_cast<unsigned char>(v[2]));
        if (short_option || long_option)
          return "expected a path, found '" + v + "', an option's name (a folder of that name: ./" + v + ")";
        return std::string();
      },
      "");
  // Every tile allocates and frees buffers of megabytes (a transient tile of 32 x 32 pixels x 2394 bins is
  // 9.8 MB). glibc serves those with mmap and returns them with munmap, so each tile paid page faults and
  // the kernel's zeroing of every page again (a quarter of `sense`'s time). Kept in the heap instead, freed
  // tiles are reused by the next: peak memory is unchanged, the faults are gone.
  mallopt(M_MMAP_THRESHOLD, 64 << 20);
  mallopt(M_TRIM_THRESHOLD, 256 << 20);
  // A file-size limit (ulimit -f) is a write's error (EFBIG, naming the file), not a signal that kills the
  // process without a word.
  std::signal(SIGXFSZ, SIG_IGN);
  // Nor is a closed pipe on stderr or stdout (`spadgen run ... 2>&1 | head -1`): the run goes on, its messages
  // lost, instead of dying mid-write.
  std::signal(SIGPIPE, SIG_IGN);
  // Open files up to the hard limit (a `sense --repeats` holds a few per realisation until it commits).
  if (rlimit lim{}; getrlimit(RLIMIT_NOFILE, &lim) == 0 && lim.rlim_cur < lim.rlim_max) {
    lim.rlim_cur = lim.rlim_max;
    (void)setrlimit(RLIMIT_NOFILE, &lim);
  }
  CLI::App cli{"spadgen " SPADGEN_VERSION ": synthetic datasets for time-gated SPAD cameras.\n"
               "Path-traces a glTF scene into per-pixel transients in photons per laser pulse, then samples what a\n"
               "time-gated SPAD camera streams out (counts over a gate sweep, binary frames, 2D intensity), with\n"
               "exact ground truth. See README.md and docs/."};
  cli.require_subcommand(1);
  cli.set_version_flag("--version", SPADGEN_VERSION);

  spadgen::app::RunOptions run;
  std::string seed;
  CLI::App* run_cmd = cli.add_subcommand("run", "render and sample a scene file into an output folder");
  run_cmd->add_option("scene", run.scene_file, "scene file (.json)")->required()->check(kSceneFile);
  run_cmd->add_option("-o,--out", run.out_dir, "output folder (default: out/<scene file name>)")->check(kNamed);
  run_cmd->add_option("--set", run.overrides, "override one scene-file key, e.g. --set laser.average_power_mW=5")
      ->type_name("KEY=VALUE")
      ->allow_extra_args(false);  // one KEY=VALUE each: `--set K=V SCENE` left the scene to it
  CLI::Option* seed_opt = run_cmd->add_option("--seed", seed, "the scene file's seed replaced: every random stream that seeds.* does not set");
  run_cmd->add_option("--threads", run.threads, "worker threads (default: all cores); outputs do not depend on it")
      ->check(kThreadsRange);
  bool quiet = false;
  run_cmd->add_flag("-q,--quiet", quiet, "nothing on stderr but warnings and errors");

  spadgen::app::SenseOptions sense;
  std::string noise_seed, chip_seed;
  CLI::App* sense_cmd = cli.add_subcommand(
      "sense", "re-sample the sensor from a run's saved light (outputs.light) without rendering: other sensor or acquisition "
               "settings, another chip, other noise");
  sense_cmd->add_option("run_dir", sense.run_dir, "folder of a run written with outputs.light=true")->required()->check(kExistingFolder);
  sense_cmd->add_option("-o,--out", sense.out_dir, "output folder (default: RUN_DIR-sense)")->check(kNamed);
  sense_cmd->add_option("--set", sense.overrides, "override a sensor.*, acquisition.*, seeds.chip, seeds.noise or outputs.{counts,frames,expected_counts,detection_rate,previews,storage,exr_compression} key")
      ->type_name("KEY=VALUE")
      ->allow_extra_args(false);  // one KEY=VALUE each: `--set K=V SCENE` left the scene to it
  CLI::Option* noise_opt = sense_cmd->add_option("--noise-seed", noise_seed, "seed of the temporal noise (seeds.noise)");
  CLI::Option* chip_opt = sense_cmd->add_option("--chip-seed", chip_seed, "seed of the chip's fixed pattern (seeds.chip)");
  sense_cmd->add_option("--repeats", sense.repeats, "realisations of the temporal noise, noise seeds S, S + 1, ...: for R > 1 one "
                                                    "folder each, OUT/repeat_000, ... (rates computed once); 1: OUT is the run folder")
      ->check(whole_in(1, 100000, "an integer in [1, 100000]"));
  sense_cmd->add_option("--threads", sense.threads, "worker threads (default: all cores); outputs do not depend on it")
      ->check(kThreadsRange);
  bool sense_quiet = false;
  sense_cmd->add_flag("-q,--quiet", sense_quiet, "nothing on stderr but warnings and errors");

  std::string info_scene;
  std::vector<std::string> info_overrides;
  CLI::App* info_cmd = cli.add_subcommand("info", "print the resolved scene file, a summary of the glTF and the run's size");
  info_cmd->add_option("scene", info_scene, "scene file (.json)")->required()->check(kSceneFile);
  info_cmd->add_option("--set", info_overrides, "override one scene-file key")->type_name("KEY=VALUE")
      ->allow_extra_args(false);  // one KEY=VALUE each: `--set K=V SCENE` left the scene to it

  CLI::App* schema_cmd = cli.add_subcommand("schema", "print the reference of every scene-file key (Markdown)");
  bool json_schema = false;
  schema_cmd->add_flag("--json-schema", json_schema, "print it as a JSON Schema (for editors) instead");

  spadgen::app::DatasetOptions dataset;
  std::string dataset_shard, status_dir;
  bool dataset_quiet = false;
  CLI::App* dataset_cmd = cli.add_subcommand("dataset", "benchmark datasets: variations of scene files, one run folder per sample");
  dataset_cmd->require_subcommand(1);
  CLI::App* plan_cmd = dataset_cmd->add_subcommand("plan", "list the samples with their parameters, and estimate disk, memory and time");
  plan_cmd->add_option("file", dataset.file, "dataset file (.json)")->required()->check(kDatasetFile);
  plan_cmd->add_option("-o,--out", dataset.out_dir, "dataset folder: also show which samples are done there and the free disk")->check(kNamed);
  CLI::Option* plan_shard = plan_cmd->add_option("--shard", dataset_shard, "only shard I of N (samples i with i mod N = I); default: as dataset run's")->type_name("I/N");
  plan_cmd->add_flag("--all", dataset.all, "list every sample (default: the first and the last 10)");
  plan_cmd->add_option("--threads", dataset.threads, "worker threads (default: all cores): the plan's, and each sample's for the time estimate")
      ->check(kThreadsRange);
  plan_cmd->add_flag("-q,--quiet", dataset_quiet, "no progress on stderr (shown for plans of over 10,000 samples)");
  CLI::App* drun_cmd = dataset_cmd->add_subcommand("run", "generate the samples that are not done, each into its own folder, as one unit");
  drun_cmd->add_option("file", dataset.file, "dataset file (.json)")->required()->check(kDatasetFile);
  drun_cmd->add_option("-o,--out", dataset.out_dir, "dataset folder")->required()->check(kNamed);
  CLI::Option* run_shard = drun_cmd->add_option("--shard", dataset_shard,
                                                "only shard I of N (samples i with i mod N = I); default: from a Slurm job array (SLURM_ARRAY_TASK_ID, "
                                                "_MIN, _STEP, _MAX, _COUNT: docs/datasets.md) or JOB_COMPLETION_INDEX / JOB_COMPLETIONS, else 0/1")
                                 ->type_name("I/N");
  drun_cmd->add_option("--threads", dataset.threads, "worker threads per sample (default: all cores); outputs do not depend on it")
      ->check(kThreadsRange);
  drun_cmd->add_flag("-q,--quiet", dataset_quiet, "nothing on stderr but warnings and errors");
  CLI::App* status_cmd = dataset_cmd->add_subcommand("status", "done, failed, stale, missing and damaged samples of a dataset folder");
  status_cmd->add_option("dir", status_dir, "dataset folder")->required()->check(kExistingFolder);
  CLI::App* dschema_cmd = dataset_cmd->add_subcommand("schema", "print the reference of the dataset file's keys (Markdown)");
  bool dataset_json_schema = false;
  dschema_cmd->add_flag("--json-schema", dataset_json_schema, "print it as a JSON Schema (for editors) instead");

  spadgen::app::ReconstructOptions rec;
  bool rec_quiet = false;
  CLI::App* rec_cmd = cli.add_subcommand("reconstruct", "reference detectors of the returns in each pixel's gate profile (detections_<detector>.exr), "
                                                        "or the HDR inversion of a 2D run (hdr.exr); docs/detection.md");
  rec_cmd->add_option("run_dir", rec.run_dir, "run folder")->required()->check(kExistingFolder);
  CLI::Option* rec_detector = rec_cmd->add_option("--detector", rec.detector, "edges (multi-scale rising and falling edges, default) or paper (the paper's virtual window)")
      ->check(CLI::IsMember({"edges", "paper"}));
  rec_cmd->add_option("-o,--out", rec.out, "output file, its name ending in .exr (default RUN_DIR/detections_<detector>.exr, or RUN_DIR/hdr.exr for a 2D run; with --noise-free "
                     "detections_<detector>_noise_free.exr, hdr_noise_free.exr)")->check(kNamed);
  rec_cmd->add_flag("--noise-free", rec.noise_free, "from the noise-free rates (detection_rate) instead of the sampled counts");
  CLI::Option* rec_max = rec_cmd->add_option("--max-detections", rec.max_detections, "detection slots per pixel (the strongest are kept)")
                             ->check(whole_in(1, 64, "an integer in [1, 64]"));
  rec_cmd->add_option("--threads", rec.threads, "worker threads (default: all cores)")->check(kThreadsRange);
  rec_cmd->add_flag("-q,--quiet", rec_quiet, "nothing on stderr but warnings and errors");

  spadgen::app::EvaluateCommand eval;
  std::string eval_region;
  double eval_min_score = 0.0;
  std::string eval_samples;
  CLI::App* eval_cmd = cli.add_subcommand("evaluate", "score detections against the object labels of a run or of every sample of a dataset: "
                                                      "metrics.json, error maps; docs/detection.md");
  eval_cmd->add_option("target", eval.target, "run folder or dataset folder")->required()->check(kExistingFolder);
  CLI::Option* eval_detections = eval_cmd->add_option("--detections", eval.detections, "detections file (.exr or .npy; for a dataset: its name inside each sample, or a path with {sample}, the sample folder's name); default "
                                                        "detections_<detector>.exr, computed in memory when absent")
                                     ->check(kNamed);  // (an empty name was ignored: the detector ran instead)
  // --detector and --noise-free choose the default file and the detector that runs without one: with
  // --detections they would be ignored without a word, so they are refused.
  eval_cmd->add_option("--detector", eval.detector, "the detector whose file is the default, or that runs when it is absent")
      ->check(CLI::IsMember({"edges", "paper"}))
      ->excludes(eval_detections);
  eval_cmd->add_option("-o,--out", eval.out_dir, "output folder (default TARGET/evaluation)")->check(kNamed);
  eval_cmd->add_option("--tolerance-m", eval.tolerance_m, "a detection further than this from every unmatched object is false (default 0.05)");
  CLI::Option* min_score_opt = eval_cmd->add_option("--min-score", eval_min_score, "ignore detections scoring below this");
  eval_cmd->add_option("--region", eval_region, "accuracy and precision of the nearest object over this rectangle (image pixels)")
      ->type_name("X,Y,W,H");
  eval_cmd->add_flag("--noise-free", eval.noise_free, "when the detector runs: on the noise-free rates (detection_rate)")
      ->excludes(eval_detections);
  CLI::Option* samples_opt = eval_cmd->add_option("--samples", eval_samples, "for a dataset: score these samples only (dataset indices, 0,3,5-8; their "
                                                  "realisations too), e.g. a validation split; @FILE reads them from a file")
      ->type_name("LIST");
  eval_cmd->add_option("--threads", eval.threads, "worker threads (default: all cores)")->check(kThreadsRange);
  bool eval_quiet = false;  // accepted as by every command: evaluate writes nothing on stderr but warnings and errors
  eval_cmd->add_flag("-q,--quiet", eval_quiet, "nothing on stderr but warnings and errors (as always: the scores go to stdout)");

  if (const std::optional<int> code = spadgen::app::parse_command_line(cli, argc, argv)) return *code;
  int done_code = spadgen::app::kExitOk;  // the exit code of a command that ran to its end
  std::string command_name;  // "sense", "dataset run": for the message of a signal
  for (const CLI::App* c = &cli; !c->get_subcommands().empty();) {
    c = c->get_subcommands().front();
    command_name += (command_name.empty() ? "" : " ") + c->get_name();
  }
  const int code = spadgen::app::run_command([&] {
    if (*run_cmd) {
      if (*seed_opt) run.seed = spadgen::app::parse_seed(seed);
      run.progress = !quiet;
      spadgen::app::run(run);
    } else if (*sense_cmd) {
      if (*noise_opt) sense.noise_seed = spadgen::app::parse_seed(noise_seed, "--noise-seed");
      if (*chip_opt) sense.chip_seed = spadgen::app::parse_seed(chip_seed, "--chip-seed");
      sense.progress = !sense_quiet;
      spadgen::app::sense(sense);
    } else if (*info_cmd) {
      std::cout << spadgen::app::info(info_scene, info_overrides);
    } else if (*dataset_cmd) {
      if ((*plan_shard && *plan_cmd) || (*run_shard && *drun_cmd)) dataset.shard = dataset_shard;
      dataset.progress = !dataset_quiet;
      if (*plan_cmd) {
        const spadgen::app::DatasetPlan plan = spadgen::app::dataset_plan(dataset);
        std::cout << plan.text;
        if (plan.invalid > 0) {
          std::cerr << "spadgen: error: " << plan.invalid_text << "\n";
          done_code = spadgen::app::kExitBadInput;
        }
      }
      else if (*drun_cmd) spadgen::app::dataset_run(dataset);
      else if (*status_cmd) {
        const spadgen::app::DatasetStatus st = spadgen::app::dataset_status(status_dir);
        std::cout << st.text;
        if (!st.complete) done_code = spadgen::app::kExitIncomplete;
      }
      else if (*dschema_cmd) std::cout << (dataset_json_schema ? spadgen::datasets::dataset_schema_json() : spadgen::app::dataset_schema());
    } else if (*rec_cmd) {
      rec.progress = !rec_quiet;
      rec.detector_given = rec_detector->count() > 0, rec.max_detections_given = rec_max->count() > 0;
      const std::string path = spadgen::app::reconstruct(rec);
      if (!rec_quiet) std::cerr << "wrote " << path << "\n";
    } else if (*eval_cmd) {
      if (*min_score_opt) eval.min_score = eval_min_score;
      if (*samples_opt) eval.samples = eval_samples;  // (given empty: refused, as selecting nothing)
      if (!eval_region.empty()) {
        spadgen::PixelRect r;
        char c1 = 0, c2 = 0, c3 = 0;
        std::istringstream in(eval_region);
        if (!(in >> r.x0 >> c1 >> r.y0 >> c2 >> r.width >> c3 >> r.height) || c1 != ',' || c2 != ',' || c3 != ',' || !in.eof() ||
            r.x0 < 0 || r.y0 < 0 || r.width < 1 || r.height < 1)
          throw spadgen::Error("--region " + eval_region + ": expected X,Y,W,H (non-negative corner, positive size, image pixels)");
        eval.region = r;
      }
      std::cout << spadgen::app::evaluate(eval);
    } else if (*schema_cmd) {
      std::cout << (json_schema ? spadgen::scenes::schema_json() : spadgen::scenes::schema_reference_markdown());
    }
  }, command_name);
  return code == spadgen::app::kExitOk ? done_code : code;
}
