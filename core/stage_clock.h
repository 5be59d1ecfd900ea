// Where a run's time goes: each stage's time, summed over threads, measured by scopes. A scope counts
// the time its thread spends inside it and not inside a scope nested in it on the same thread, so a
// task that a waiting thread picks up (TBB runs other tiles' work inside a nested parallel loop's wait)
// counts for its own stage, not twice. Time a thread spends outside every scope (idle, or helping a
// parallel loop of another thread's stage from outside a scope) is nobody's.
#pragma once
#include <array>
#include <atomic>
#include <cstdint>

namespace spadgen {

class StageClock {
 public:
  enum Stage : int { kGroundTruth, kLightTransport, kSavedLight, kSensorRates, kSensorNoise, kOutputs, kStageCount };

  // Times `stage` on this thread while it lives; clock null: times nothing. The innermost scope of a
  // thread is the one its time goes to.
  class Scope {
   public:
    Scope(StageClock* clock, Stage stage);
    ~Scope();
    Scope(const Scope&) = delete;
    Scope& operator=(const Scope&) = delete;

   private:
    StageClock* clock_;
    Stage stage_;
    Scope* parent_;
    int64_t since_ns_ = 0;  // this scope's running segment began
    friend class StageClock;
  };

  // The clock of this thread's innermost scope (null outside every scope): what code deeper in a stage
  // times its parts with.
  static StageClock* current();
  // Seconds summed over threads.
  double seconds(Stage stage) const { return double(ns_[stage].load()) * 1e-9; }

 private:
  std::array<std::atomic<int64_t>, kStageCount> ns_{};
};

}  // namespace spadgen
