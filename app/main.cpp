// spadgen: synthetic datasets for time-gated SPAD cameras.
//   spadgen run SCENE.json [-o DIR] [--set KEY=VALUE]... [--seed S] [--threads N]
//   spadgen info SCENE.json [--set KEY=VALUE]...
//   spadgen schema                 # the reference of every scene-file key (Markdown)
#include <CLI/CLI.hpp>

#include <cstdio>
#include <iostream>

#include "app/cli.h"
#include "app/pipeline.h"
#include "core/error.h"
#include "scenes/scene_file.h"

#ifndef SPADGEN_VERSION
#define SPADGEN_VERSION "dev"
#endif

int main(int argc, char** argv) {
  CLI::App cli{"spadgen " SPADGEN_VERSION ": synthetic datasets for time-gated SPAD cameras.\n"
               "Path-traces a glTF scene into per-pixel transients in photons per laser pulse, then samples what a\n"
               "time-gated SPAD camera streams out (counts over a gate sweep, binary frames, 2D intensity), with\n"
               "exact ground truth. See README.md and docs/."};
  cli.require_subcommand(1);
  cli.set_version_flag("--version", SPADGEN_VERSION);

  spadgen::app::RunOptions run;
  std::string seed;
  CLI::App* run_cmd = cli.add_subcommand("run", "render and sample a scene file into an output folder");
  run_cmd->add_option("scene", run.scene_file, "scene file (.json)")->required()->check(CLI::ExistingFile);
  run_cmd->add_option("-o,--out", run.out_dir, "output folder (default: out/<scene file name>)");
  run_cmd->add_option("--set", run.overrides, "override one scene-file key, e.g. --set laser.average_power_mW=5")
      ->type_name("KEY=VALUE");
  CLI::Option* seed_opt = run_cmd->add_option("--seed", seed, "seed of every random stream (replaces the scene file's)");
  run_cmd->add_option("--threads", run.threads, "worker threads (default: all cores); outputs do not depend on it")
      ->check(CLI::NonNegativeNumber);
  bool quiet = false;
  run_cmd->add_flag("-q,--quiet", quiet, "nothing on stderr but warnings and errors");

  std::string info_scene;
  std::vector<std::string> info_overrides;
  CLI::App* info_cmd = cli.add_subcommand("info", "print the resolved scene file, a summary of the glTF and the run's size");
  info_cmd->add_option("scene", info_scene, "scene file (.json)")->required()->check(CLI::ExistingFile);
  info_cmd->add_option("--set", info_overrides, "override one scene-file key")->type_name("KEY=VALUE");

  CLI::App* schema_cmd = cli.add_subcommand("schema", "print the reference of every scene-file key (Markdown)");
  bool json_schema = false;
  schema_cmd->add_flag("--json-schema", json_schema, "print it as a JSON Schema (for editors) instead");

  if (const std::optional<int> code = spadgen::app::parse_command_line(cli, argc, argv)) return *code;
  return spadgen::app::run_command([&] {
    if (*run_cmd) {
      if (*seed_opt) run.seed = spadgen::app::parse_seed(seed);
      run.progress = !quiet;
      spadgen::app::run(run);
    } else if (*info_cmd) {
      std::cout << spadgen::app::info(info_scene, info_overrides);
    } else if (*schema_cmd) {
      std::cout << (json_schema ? spadgen::scenes::schema_json() : spadgen::scenes::schema_reference_markdown());
    }
  });
}
