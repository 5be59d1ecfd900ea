#include "tile.h"

#include <cstdint>
#include <new>
#include <string>

#if defined(__linux__)
#include <sys/mman.h>
#endif

#include "error.h"

namespace spadgen {

// Under AddressSanitizer every buffer comes from operator new, so that ASan checks its bounds.
#if defined(__linux__) && defined(MADV_HUGEPAGE) && !defined(__SANITIZE_ADDRESS__)
#define SPADGEN_HUGE_BUFFERS 1
#endif

namespace {
// A large buffer's own mapping: its size in whole 2 MB pages, so that no other allocation shares them.
size_t mapped_bytes(size_t bytes) { return (bytes + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes; }
// Mapped when the whole pages exceed the buffer by at most an eighth of it (a 1024 x 500 float image, 1.95
// MiB, is; a 1.5 MiB buffer is not).
[[maybe_unused]] bool huge(size_t bytes) { return bytes >= kHugePageBytes / 2 && mapped_bytes(bytes) - bytes <= bytes / 8; }
}  // namespace

void* allocate_buffer(size_t bytes) {
#if SPADGEN_HUGE_BUFFERS
  if (huge(bytes)) {
    // Mapped with 2 MB to spare, then trimmed to a 2 MB aligned start.
    const size_t size = mapped_bytes(bytes);
    void* m = mmap(nullptr, size + kHugePageBytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (m == MAP_FAILED) throw std::bad_alloc();
    const auto a = reinterpret_cast<uintptr_t>(m);
    const uintptr_t start = (a + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes;
    if (start > a) munmap(m, start - a);
    if (const size_t tail = a + size + kHugePageBytes - (start + size); tail > 0)
      munmap(reinterpret_cast<void*>(start + size), tail);
    (void)madvise(reinterpret_cast<void*>(start), size, MADV_HUGEPAGE);  // advice: without THP, small pages
    return reinterpret_cast<void*>(start);
  }
#endif
  return ::operator new(bytes);
}

void deallocate_buffer(void* p, size_t bytes) noexcept {
#if SPADGEN_HUGE_BUFFERS
  if (huge(bytes)) {
    munmap(p, mapped_bytes(bytes));
    return;
  }
#endif
  ::operator delete(p, bytes);
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
