// SIGINT / SIGTERM / SIGHUP during a run: every long loop stops (it polls spadgen::interrupt_flag), the staging
// folder is removed, nothing is published, and the program exits with code 2.
#pragma once
#include <csignal>

namespace spadgen::app {

// Installs the handlers for the duration of a run and restores the previous ones after.
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

}  // namespace spadgen::app
