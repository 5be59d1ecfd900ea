#include "app/interrupt.h"

#include "core/error.h"

namespace spadgen::app {
namespace {

// Only a lock-free atomic may be touched from a handler; every long loop polls it (core/error.h).
extern "C" void on_interrupt(int) { interrupt_flag().store(true); }

// Guards alive (on the main thread): a guard inside another (a run or a sense inside a dataset run) neither
// clears a signal that already arrived nor hands the signals back to their default action when it ends.
int guards = 0;

}  // namespace

InterruptGuard::InterruptGuard() {
  if (guards++ > 0) return;
  interrupt_flag().store(false);
  previous_int_ = std::signal(SIGINT, on_interrupt);
  previous_term_ = std::signal(SIGTERM, on_interrupt);
  previous_hup_ = std::signal(SIGHUP, on_interrupt);  // the terminal closed: stop as for SIGTERM
  // Ignored when the process started (nohup; a shell's background job without job control, for SIGINT):
  // ignored still, as the user asked (a nohup run was stopped by the hangup).
  if (previous_hup_ == SIG_IGN) std::signal(SIGHUP, SIG_IGN);
  if (previous_int_ == SIG_IGN) std::signal(SIGINT, SIG_IGN);
}

InterruptGuard::~InterruptGuard() {
  if (--guards > 0) return;
  std::signal(SIGINT, previous_int_);
  std::signal(SIGTERM, previous_term_);
  std::signal(SIGHUP, previous_hup_);
}

void InterruptGuard::check() { throw_if_interrupted(); }

}  // namespace spadgen::app
