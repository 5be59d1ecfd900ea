// The command line in spadgen's own words: CLI11's parse errors become "spadgen: error: ..." with exit
// code 1, and every exception a command throws becomes one line on stderr and the documented exit code:
//   0 success; 1 bad input or an environment problem (spadgen::Error, out of memory); 2 interrupted
//   (SIGINT, SIGTERM: spadgen::Interrupted); 3 internal error (a bug: please report it); 4 `dataset status`
//   of a dataset whose samples are not all done (the report says which).
// Part of the spadgen executable only (it needs CLI11), not of spadgen_app.
#pragma once
#include <CLI/CLI.hpp>

#include <cstdint>
#include <functional>
#include <optional>
#include <string>

namespace spadgen::app {

inline constexpr int kExitOk = 0, kExitBadInput = 1, kExitInterrupted = 2, kExitInternal = 3, kExitIncomplete = 4;

// Parses the command line. nullopt: go on; otherwise the exit code, after printing help or the version
// (0) or a usage error in spadgen's format (1).
std::optional<int> parse_command_line(CLI::App& cli, int argc, char** argv);

// main found standard output closed (>&-) and opened /dev/full in its place: what a command prints there fails,
// and run_command says the stream was closed (schema, info, plan, status and evaluate's scores were lost,
// exit 0). A command that prints nothing there (run, sense, reconstruct) is not affected.
void note_stdout_closed();

// Runs a command and returns its exit code, printing what went wrong on stderr. `name` names the command
// in the message of a signal ("spadgen sense stopped and wrote nothing"; "the run" by default).
int run_command(const std::function<void()>& command, const std::string& name = "");

// `--seed S` (or --noise-seed, --chip-seed: `option`): an integer in [0, 2^53] written as digits; throws
// spadgen::Error naming the option otherwise (CLI11 read "-1" as 18446744073709551615).
uint64_t parse_seed(const std::string& text, const std::string& option = "--seed");

}  // namespace spadgen::app
