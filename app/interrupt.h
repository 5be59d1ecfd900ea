// SIGINT / SIGTERM / SIGHUP during a run: every long loop stops (it polls spadgen::interrupt_flag), the staging
// folder is removed, nothing is published, and the program exits with code 2.
#pragma once
#include <csignal>

namespace spadgen::app {

// From the program's start to its first guard, where nothing is written yet: SIGINT, SIGTERM or SIGHUP ends
// the process at once, with the interrupted message and code 2 (they killed it by the signal, exit 130 or
// 143, within the tens of milliseconds before a run's guard, hundreds under AddressSanitizer). A signal
// ignored when the process started stays ignored. main() calls it first.
void install_startup_interrupt_handlers();

// Installs the handlers for the duration of a run and restores the previous ones after (the startup
// handlers give way to the default actions: the run may have written by then).
class InterruptGuard {
 public:
  InterruptGuard();
  ~InterruptGuard();
  InterruptGuard(const InterruptGuard&) = delete;
  InterruptGuard& operator=(const InterruptGuard&) = delete;
  // Throws spadgen::Interrupted once a signal has arrived (spadgen::throw_if_interrupted, which the
  // renderer polls per pixel, says the same).
  static void check();

 private:
  void (*previous_int_)(int) = SIG_DFL;
  void (*previous_term_)(int) = SIG_DFL;
  void (*previous_hup_)(int) = SIG_DFL;
};

// Within the one guard of a run (not inside a dataset run's, whose other samples write), for work that writes
// nothing and cannot poll: a signal ends the process at once, with the interrupted message and code 2 (a
// 24 MB glTF of a million nodes took 6 s in tinygltf's parse before a Ctrl-C stopped the run).
class StopAtOnce {
 public:
  StopAtOnce();
  ~StopAtOnce();
  StopAtOnce(const StopAtOnce&) = delete;
  StopAtOnce& operator=(const StopAtOnce&) = delete;

 private:
  bool armed_;
};

}  // namespace spadgen::app
