#include "app/interrupt.h"

#include <atomic>

#include "core/error.h"

namespace spadgen::app {
namespace {

// A signal handler may only touch a lock-free atomic; the run polls it between tiles.
std::atomic<bool> g_interrupted{false};
extern "C" void on_interrupt(int) { g_interrupted.store(true); }

}  // namespace

InterruptGuard::InterruptGuard() {
  g_interrupted.store(false);
  previous_int_ = std::signal(SIGINT, on_interrupt);
  previous_term_ = std::signal(SIGTERM, on_interrupt);
}

InterruptGuard::~InterruptGuard() {
  std::signal(SIGINT, previous_int_);
  std::signal(SIGTERM, previous_term_);
}

void InterruptGuard::check() {
  if (g_interrupted.load()) throw Error("interrupted by a signal: the run stopped and wrote nothing");
}

}  // namespace spadgen::app
