#include "app/progress.h"

#include <unistd.h>

#include <cstdio>
#include <string>

namespace spadgen::app {

Progress::Progress(size_t total, bool enabled, const char* unit)
    : total_(total), enabled_(enabled), tty_(isatty(2) != 0), unit_(unit) {}

void Progress::tick() {
  const size_t done = ++done_;
  if (!enabled_) return;
  std::lock_guard<std::mutex> lock(mutex_);
  const double elapsed = seconds();
  const double left = done ? elapsed * double(total_ - done) / double(done) : 0.0;
  if (tty_) {
    if (elapsed - last_print_ < 0.1 && done != total_) return;
    last_print_ = elapsed;
    const int width = 30, filled = int(double(width) * double(done) / double(total_));
    std::fprintf(stderr, "\r[%s%s] %3d%%  %zu/%zu %s  %.1f s, ~%.0f s left ", std::string(size_t(filled), '#').c_str(),
                 std::string(size_t(width - filled), '.').c_str(), int(100.0 * double(done) / double(total_)), done,
                 total_, unit_, elapsed, left);
    if (done == total_) std::fprintf(stderr, "\n");
  } else {
    const size_t decile = 10 * done / total_;
    if (decile > last_decile_ || done == total_) {
      last_decile_ = decile;
      std::fprintf(stderr, "spadgen: %3d%% (%zu/%zu %s) %.1f s elapsed, ~%.0f s left\n",
                   int(100.0 * double(done) / double(total_)), done, total_, unit_, elapsed, left);
    }
  }
}

double Progress::seconds() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

}  // namespace spadgen::app
