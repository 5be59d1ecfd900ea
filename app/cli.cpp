#include "app/cli.h"

#include <poll.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <new>

#include "app/staging.h"
#include "core/current_folder.h"
#include "core/error.h"
#include "scenes/input.h"
#include "scenes/scene_file.h"

namespace spadgen::app {

namespace {
bool stdout_closed = false;

// stdout is a pipe whose every reader has closed it (the write end polls POLLERR).
bool stdout_reader_gone() {
  struct stat st {};
  if (::fstat(STDOUT_FILENO, &st) != 0 || !S_ISFIFO(st.st_mode)) return false;
  pollfd p{STDOUT_FILENO, POLLOUT, 0};
  return ::poll(&p, 1, 0) == 1 && (p.revents & POLLERR) != 0;
}

// Flushes stdout: what went there (schema, info, help, scores) must have been written. Empty when it was, or
// when a reader closed the pipe early (`spadgen schema | head -5` has what it wanted: a quiet exit 0, as
// ripgrep does; it was an error or not by the race between the two processes); else why not.
std::string stdout_failure() {
  errno = 0;
  if (std::cout.flush(); std::cout.good() && std::fflush(stdout) == 0 && !std::ferror(stdout)) return "";
  if (errno == EPIPE || stdout_reader_gone()) return "";
  if (stdout_closed)
    return "standard output is closed (>&-): this command's output, which it prints there, was not written; "
           "redirect it to a file or /dev/null instead";
  return std::string("cannot write the output to standard output (a full disk, or a closed pipe): it is incomplete") +
         (errno != 0 ? std::string(": ") + std::strerror(errno) : "");
}
}  // namespace

std::optional<int> parse_command_line(CLI::App& cli, int argc, char** argv) {
  try {
    cli.parse(argc, argv);
    return std::nullopt;
  } catch (const CLI::Success& e) {
    const int code = cli.exit(e);  // --help, --version: printed on stdout, exit 0 once written
    if (const std::string failure = stdout_failure(); !failure.empty()) {
      std::fprintf(stderr, "spadgen: error: %s\n", failure.c_str());
      return kExitBadInput;
    }
    return code;
  } catch (const CLI::ParseError& e) {
    std::string command = "spadgen";
    const CLI::App* at = &cli;
    int next = 1;  // argv's word after the commands named
    while (!at->get_subcommands().empty()) {
      at = at->get_subcommands().front();
      command += " " + at->get_name();
      ++next;
    }
    // A word where a command was expected: name it and the commands there are (CLI11 says only that one is
    // required).
    if (at->get_require_subcommand_min() > 0 && at->get_subcommands().empty() && next < argc && argv[next][0] != '-') {
      std::string names;
      for (const CLI::App* sub : at->get_subcommands({})) names += (names.empty() ? "" : ", ") + sub->get_name();
      std::fprintf(stderr, "spadgen: error: unknown command '%s' after %s; expected one of %s (see %s --help)\n",
                   scenes::one_line(argv[next]).c_str(), command.c_str(), names.c_str(), command.c_str());
      return kExitBadInput;
    }
    // An option that takes a value followed by another option (`--set -o DIR`): CLI11 named DIR, the word it
    // could not place, as the mistake.
    for (int i = next; i + 1 < argc; ++i) {
      const std::string word = argv[i], after = argv[i + 1];
      if (word.size() < 2 || word[0] != '-' || word.find('=') != std::string::npos) continue;
      const CLI::Option* opt = at->get_option_no_throw(word);
      if (!opt || opt->get_expected_min() == 0 || after.size() < 2 || after[0] != '-') continue;
      // (an option of this command, or --help: `-o -results` is a folder's name, which CLI11's own message names)
      if (at->get_option_no_throw(after.substr(0, after.find('='))) == nullptr && after != "-h" && after != "--help") continue;
      const std::string type = opt->get_type_name();  // (TEXT says nothing: "a value")
      std::fprintf(stderr, "spadgen: error: %s: expected %s after it, found the option '%s' (see %s --help)\n", word.c_str(),
                   type.empty() || type == "TEXT" ? "a value" : type.c_str(), scenes::one_line(after).c_str(), command.c_str());
      return kExitBadInput;
    }
    // (one line: a word of the command line holding a newline, a file name, is shown as \n)
    std::fprintf(stderr, "spadgen: error: %s (see %s --help)\n", scenes::one_line(e.what()).c_str(), command.c_str());
    return kExitBadInput;
  }
}


void note_stdout_closed() { stdout_closed = true; }

namespace {
// An error's message on one line (a path holding a newline split it, and a script reading stderr's last line
// lost it), but for the lists of mistakes of a scene or dataset file, one per line as they are built (each
// on one line already).
std::string printable_error(const std::string& what) {
  for (const char* list : {" errors in the scene file:\n", " errors in the dataset file:\n"})
    if (const size_t at = what.find(list); at != std::string::npos) {
      const size_t rest = at + std::strlen(list);
      return scenes::one_line(what.substr(0, rest - 1)) + "\n" + what.substr(rest);
    }
  return scenes::one_line(what);
}
}  // namespace

int run_command(const std::function<void()>& command, const std::string& name) {
  try {
    command();
    // What went to stdout (schema, info, plan, status, scores) was written: a full disk or a closed stream
    // is an error, not a silent exit 0 with a truncated file.
    if (const std::string failure = stdout_failure(); !failure.empty()) throw Error(failure);
    return kExitOk;
  } catch (const Interrupted& e) {
    // The message of throw_if_interrupted (core/error.h) says "the run": another command is named.
    std::string message = scenes::one_line(e.what());
    const std::string run = "the run stopped and wrote nothing";
    if (const size_t at = message.find(run); at != std::string::npos && !name.empty() && name != "run")
      message.replace(at, 7, "spadgen " + name);
    std::fprintf(stderr, "spadgen: %s\n", message.c_str());
    return kExitInterrupted;
  } catch (const Error& e) {
    // A file that failed while being written lies in the output folder's staging folder (hidden, beside
    // it): said so, with what became of the output folder.
    const std::string what = printable_error(e.what());
    const bool staged = what.find(".spadgen-staging-") != std::string::npos && what.find("cannot publish") == std::string::npos;
    const std::string moved = staging_parent_moved();
    const std::string where =
        moved.empty() ? std::string("the staging folder is removed, and the output folder is as it was") : moved;
    std::fprintf(stderr, "spadgen: error: %s%s\n", what.c_str(),
                 staged ? (" (in the staging folder the output is written in before it replaces the output folder: " + where + ")").c_str()
                        : "");
    return kExitBadInput;
  } catch (const std::filesystem::filesystem_error& e) {
    // The file system's refusal (a path in a folder that is gone, permissions): the environment's, not a bug.
    const bool cwd_gone = current_folder_error() == std::errc::no_such_file_or_directory;
    std::fprintf(stderr, "spadgen: error: %s%s\n", scenes::one_line(e.what()).c_str(),
                 cwd_gone ? " (the current folder no longer exists: run from one that does, or give absolute paths)" : "");
    return kExitBadInput;
  } catch (const std::system_error& e) {
    // Threads the process may not start (ulimit -u on a shared node, or memory for their stacks, ulimit -v):
    // the environment's, not a bug.
    if (e.code() == std::errc::resource_unavailable_try_again || e.code() == std::errc::not_enough_memory) {
      std::fprintf(stderr, "spadgen: error: cannot start the threads the command needs: %s (the processes this user may "
                           "run, ulimit -u, or the memory for their stacks, ulimit -v); ask for fewer with --threads N\n",
                   e.what());
      return kExitBadInput;
    }
    std::fprintf(stderr, "spadgen: internal error: %s (a bug in spadgen; please report it with the command line)\n", e.what());
    return kExitInternal;
  } catch (const std::bad_alloc&) {
    // (named by its command: sense, reconstruct and evaluate render nothing)
    const std::string who = name.empty() || name == "run" ? std::string("the run") : "spadgen " + name;
    std::fprintf(stderr, "spadgen: error: out of memory: %s needs more memory than the machine gives it "
                         "(spadgen info shows the sizes of a run)\n", who.c_str());
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "spadgen: internal error: %s (a bug in spadgen; please report it with the command line)\n",
                 scenes::one_line(e.what()).c_str());
    return kExitInternal;
  }
}

uint64_t parse_seed(const std::string& text, const std::string& option) {
  constexpr uint64_t kMax = scenes::kMaxSeed;
  uint64_t v = 0;
  bool ok = !text.empty() && text.size() <= 16;
  for (char c : text) {
    if (c < '0' || c > '9') ok = false;
    if (ok) v = v * 10 + static_cast<uint64_t>(c - '0');
  }
  if (!ok || v > kMax)
    throw Error(option + ": found '" + text + "', expected an integer in [0, " + std::to_string(kMax) + "]");
  return v;
}

}  // namespace spadgen::app
