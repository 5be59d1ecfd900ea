#include "tile.h"

#include <cstdint>
#include <mutex>
#include <new>
#include <string>
#include <utility>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

#include "buffer_cache.h"
#include "error.h"

namespace spadgen {

namespace {
// A large buffer's own mapping: its size in whole 2 MB pages, so that no other allocation shares them.
size_t mapped_bytes(size_t bytes) { return (bytes + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes; }
// Mapped when the whole pages exceed the buffer by at most an eighth of it (a 1024 x 500 float image, 1.95
// MiB, is; a 1.5 MiB buffer is not).
[[maybe_unused]] bool huge(size_t bytes) { return bytes >= kHugePageBytes / 2 && mapped_bytes(bytes) - bytes <= bytes / 8; }
}  // namespace

#if defined(SPADGEN_HUGE_BUFFERS)
namespace {
// Freed mappings kept for the next buffer of the same size (the next band's tiles), newest last: a
// reused mapping costs neither page faults nor the kernel's zeroing of its pages. At most kCachedBytes;
// the oldest are unmapped first.
class MappingCache {
 public:
  static constexpr size_t kCachedBytes = size_t{512} << 20;
  void* take(size_t size) {
    std::lock_guard<std::mutex> lock(mutex_);
    for (size_t i = entries_.size(); i-- > 0;)
      if (entries_[i].first == size) {
        void* p = entries_[i].second;
        entries_.erase(entries_.begin() + static_cast<ptrdiff_t>(i));
        bytes_ -= size;
        return p;
      }
    return nullptr;
  }
  void put(void* p, size_t size) noexcept {
    if (size > kCachedBytes) {
      munmap(p, size);
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    size_t n = 0;  // the oldest entries that make room
    for (size_t kept = bytes_; kept + size > kCachedBytes; ++n) {
      kept -= entries_[n].first;
      munmap(entries_[n].second, entries_[n].first);
      bytes_ -= entries_[n].first;
    }
    entries_.erase(entries_.begin(), entries_.begin() + static_cast<ptrdiff_t>(n));
    entries_.emplace_back(size, p);  // within the capacity reserved: no allocation
    bytes_ += size;
  }
  void release() noexcept {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& [size, p] : entries_) munmap(p, size);
    entries_.clear();
    bytes_ = 0;
  }
  MappingCache() { entries_.reserve(kCachedBytes / kHugePageBytes + 1); }  // a mapping is >= 2 MB

 private:
  std::mutex mutex_;
  std::vector<std::pair<size_t, void*>> entries_;  // (size, address)
  size_t bytes_ = 0;
};
// Never destroyed: buffers may be freed by static destructors after it would be.
MappingCache& mapping_cache() {
  static auto* c = new MappingCache;
  return *c;
}
}  // namespace
#endif

void release_cached_buffers() noexcept {
#if defined(SPADGEN_HUGE_BUFFERS)
  mapping_cache().release();
#endif
}

void* allocate_buffer(size_t bytes) {
#if defined(SPADGEN_HUGE_BUFFERS)
  if (huge(bytes)) {
    const size_t size = mapped_bytes(bytes);
    if (void* p = mapping_cache().take(size)) return p;
    // Mapped with 2 MB to spare; the spare before the first 2 MB boundary and after the buffer unmapped.
    auto* m = static_cast<char*>(mmap(nullptr, size + kHugePageBytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0));
    if (m == MAP_FAILED) throw std::bad_alloc();
    const size_t head = (kHugePageBytes - reinterpret_cast<uintptr_t>(m) % kHugePageBytes) % kHugePageBytes;
    if (head > 0) munmap(m, head);
    munmap(m + head + size, kHugePageBytes - head);
#if defined(MADV_HUGEPAGE)
    (void)madvise(m + head, size, MADV_HUGEPAGE);  // advice: without THP, small pages
#endif
    return m + head;
  }
#endif
  return ::operator new(bytes);
}

void deallocate_buffer(void* p, [[maybe_unused]] size_t bytes) noexcept {
#if defined(SPADGEN_HUGE_BUFFERS)
  if (huge(bytes)) {
    mapping_cache().put(p, mapped_bytes(bytes));
    return;
  }
#endif
  ::operator delete(p);  // unsized: clang 14 declares sized deallocation only with -fsized-deallocation
}

std::vector<PixelRect> make_tiles(int width, int height, int tile_size) {
  if (tile_size <= 0 || tile_size % 8 != 0)
    throw Error("tile size must be a positive multiple of 8 pixels, found " + std::to_string(tile_size));
  std::vector<PixelRect> tiles;
  for (int y = 0; y < height; y += tile_size)
    for (int x = 0; x < width; x += tile_size)
      tiles.push_back({x, y, std::min(tile_size, width - x), std::min(tile_size, height - y)});
  return tiles;
}

}  // namespace spadgen
