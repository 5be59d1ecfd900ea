#include "core/mapped_files.h"

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <mutex>

namespace spadgen {
namespace {

// A slot: begin 0 is free. The handler reads the slots without the lock (it may not take one): a slot is
// published by storing `begin` last (release) and withdrawn by clearing `begin` first.
struct Slot {
  std::atomic<uintptr_t> begin{0};
  std::atomic<uintptr_t> end{0};
  char path[kMaxMappedPathBytes] = {};
};
Slot g_slots[kMaxMappedFiles];
std::mutex g_lock;  // writers of the slots

void write_all(const char* s, size_t n) {
  while (n > 0) {
    const ssize_t w = ::write(2, s, n);
    if (w <= 0) return;
    s += w, n -= size_t(w);
  }
}

void on_bus(int sig, siginfo_t* info, void*) {
  const auto at = reinterpret_cast<uintptr_t>(info ? info->si_addr : nullptr);
  for (Slot& s : g_slots) {
    const uintptr_t b = s.begin.load(std::memory_order_acquire);
    if (b != 0 && at >= b && at < s.end.load(std::memory_order_relaxed)) {
      static const char head[] = "spadgen: error: ";
      static const char tail[] =
          " was cut short while spadgen read it through its mapping (another process truncated it, or wrote over it in "
          "place: a cp onto it); its outputs were not published (a staging folder it leaves is removed by the next run): "
          "run again once the file is whole\n";
      write_all(head, sizeof head - 1);
      write_all(s.path, ::strnlen(s.path, sizeof s.path));
      write_all(tail, sizeof tail - 1);
      ::_exit(1);
    }
  }
  // not a file's mapping: the default action (a crash, with its core), as without this handler
  ::signal(sig, SIG_DFL);
  ::raise(sig);
}

}  // namespace

void register_mapped_file(const void* begin, size_t bytes, const std::string& path) {
  if (!begin || bytes == 0) return;
  std::lock_guard<std::mutex> hold(g_lock);
  for (Slot& s : g_slots)
    if (s.begin.load(std::memory_order_relaxed) == 0) {
      const size_t n = std::min(path.size(), sizeof s.path - 1);
      std::memcpy(s.path, path.data(), n);
      s.path[n] = '\0';
      s.end.store(reinterpret_cast<uintptr_t>(begin) + bytes, std::memory_order_relaxed);
      s.begin.store(reinterpret_cast<uintptr_t>(begin), std::memory_order_release);
      return;
    }
}

void unregister_mapped_file(const void* begin) {
  if (!begin) return;
  std::lock_guard<std::mutex> hold(g_lock);
  for (Slot& s : g_slots)
    if (s.begin.load(std::memory_order_relaxed) == reinterpret_cast<uintptr_t>(begin)) {
      s.begin.store(0, std::memory_order_release);
      return;
    }
}

void install_mapped_file_fault_handler() {
  struct sigaction sa {};
  sa.sa_sigaction = on_bus;
  sa.sa_flags = SA_SIGINFO | SA_ONSTACK;
  sigemptyset(&sa.sa_mask);
  ::sigaction(SIGBUS, &sa, nullptr);
}

}  // namespace spadgen
