#include "core/stage_clock.h"

#include <chrono>

namespace spadgen {

namespace {

thread_local StageClock::Scope* innermost = nullptr;

int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace

StageClock::Scope::Scope(StageClock* clock, Stage stage) : clock_(clock), stage_(stage), parent_(innermost) {
  if (!clock_) return;
  since_ns_ = now_ns();
  // The enclosing scope's segment ends here (it resumes when this one ends).
  if (parent_ && parent_->clock_) parent_->clock_->ns_[parent_->stage_] += since_ns_ - parent_->since_ns_;
  innermost = this;
}

StageClock::Scope::~Scope() {
  if (!clock_) return;
  const int64_t t = now_ns();
  clock_->ns_[stage_] += t - since_ns_;
  innermost = parent_;
  if (parent_) parent_->since_ns_ = t;
}

StageClock* StageClock::current() { return innermost ? innermost->clock_ : nullptr; }

}  // namespace spadgen
