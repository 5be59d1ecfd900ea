#include "app/interrupt.h"

#include "core/error.h"

#include <unistd.h>

#include <atomic>

namespace spadgen::app {
namespace {

// While a StopAtOnce lives: the process ends in the handler itself.
std::atomic<bool> stop_at_once{false};

// Where nothing is written yet: the message and _exit, both safe in a handler.
[[noreturn]] void stop_now() {
  static constexpr char kMessage[] = "spadgen: interrupted by a signal: the run stopped and wrote nothing\n";
  [[maybe_unused]] const ssize_t written = ::write(2, kMessage, sizeof kMessage - 1);
  ::_exit(2);
}

// Only a lock-free atomic may be touched from a handler; every long loop polls it (core/error.h). Within a
// StopAtOnce, nothing is written yet and nothing polls.
extern "C" void on_interrupt(int) {
  if (stop_at_once.load()) stop_now();
  interrupt_flag().store(true);
}

// Before the first guard: nothing is written yet.
extern "C" void on_startup_interrupt(int) { stop_now(); }

// What a guard hands the signals back to: the startup handlers' place is the default action's.
void (*after_guard(void (*previous)(int)))(int) { return previous == on_startup_interrupt ? SIG_DFL : previous; }

// Guards alive (on the main thread): a guard inside another (a run or a sense inside a dataset run) neither
// clears a signal that already arrived nor hands the signals back to their default action when it ends.
int guards = 0;

}  // namespace

void install_startup_interrupt_handlers() {
  for (const int sig : {SIGINT, SIGTERM, SIGHUP}) {
    struct sigaction now {};
    if (::sigaction(sig, nullptr, &now) == 0 && now.sa_handler != SIG_IGN) std::signal(sig, on_startup_interrupt);  // ignored still (nohup)
  }
}

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
  std::signal(SIGINT, after_guard(previous_int_));
  std::signal(SIGTERM, after_guard(previous_term_));
  std::signal(SIGHUP, after_guard(previous_hup_));
}

void InterruptGuard::check() { throw_if_interrupted(); }

StopAtOnce::StopAtOnce() : armed_(guards == 1) {
  if (!armed_) return;
  throw_if_interrupted();  // (a signal before it)
  stop_at_once.store(true);
}

StopAtOnce::~StopAtOnce() {
  if (armed_) stop_at_once.store(false);
}

}  // namespace spadgen::app
