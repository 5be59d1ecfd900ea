// Progress of a run on stderr: a bar on a terminal, a line every 10 % otherwise (logs, CI), each with an
// estimate of the time left.
#pragma once
#include <atomic>
#include <chrono>
#include <cstddef>
#include <mutex>

namespace spadgen::app {

class Progress {
 public:
  // `unit` names what is counted in the messages ("tiles", "samples").
  Progress(size_t total, bool enabled, const char* unit = "tiles");
  // One more done; safe to call from every worker thread.
  void tick();
  // Seconds since construction.
  double seconds() const;

 private:
  size_t total_;
  bool enabled_, tty_;
  const char* unit_;
  std::atomic<size_t> done_{0};
  std::mutex mutex_;
  double last_print_ = -1.0;
  size_t last_decile_ = 0;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

}  // namespace spadgen::app
