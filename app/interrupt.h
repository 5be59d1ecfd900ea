// SIGINT / SIGTERM during a run: the tiles stop, the staging folder is removed, nothing is published.
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
  // Throws spadgen::Error once a signal has arrived; the tiles call it so that the run stops early.
  static void check();

 private:
  void (*previous_int_)(int) = SIG_DFL;
  void (*previous_term_)(int) = SIG_DFL;
};

}  // namespace spadgen::app
