// A running maximum shared by threads: tiles processed in parallel each offer their own value.
#pragma once
#include <atomic>

namespace spadgen {

// Raises m to v when v is larger (a NaN v leaves m as it is). Lock-free on every target spadgen builds for.
template <class T>
inline void store_max(std::atomic<T>& m, T v) {
  for (T seen = m.load(std::memory_order_relaxed); v > seen && !m.compare_exchange_weak(seen, v, std::memory_order_relaxed);) {
  }
}

}  // namespace spadgen
