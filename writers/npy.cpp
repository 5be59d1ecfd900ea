// NumPy .npy format 1.0: "\x93NUMPY", major 1, minor 0, little-endian uint16 header length, then an ASCII
// Python dict literal padded with spaces and ending in '\n' so the data starts on a 64-byte boundary
// (what NumPy itself writes, so memory maps of the data are aligned). Format 1.0 caps the header at
// 65535 bytes, far beyond any shape we write.
#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <algorithm>
#include <atomic>
#include <limits>

#include "core/error.h"
#include "writers/atomic_file.h"
#include "writers/writers.h"

namespace spadgen::writers {

struct NpyWriter::Impl {
  std::string path;
  Dtype dtype;
  std::vector<int64_t> shape;
  int64_t elements = 0;
  int64_t elem_bytes = 0;
  int64_t header_bytes = 0;
  detail::TempFile file;
  std::atomic<bool> committed{false};
  // The whole file mapped for writing (null when the mapping failed: writes then go through pwrite).
  char* map = nullptr;
  size_t map_bytes = 0;

  Impl(const std::string& p, Dtype d, std::vector<int64_t> s) : path(p), dtype(d), shape(std::move(s)), file(p) {}
  ~Impl() { unmap(); }
  void unmap() {
    if (map) ::munmap(map, map_bytes);
    map = nullptr;
  }
};

namespace {

const char* descr(NpyWriter::Dtype dtype) {
  switch (dtype) {
    case NpyWriter::Dtype::F32: return "<f4";
    case NpyWriter::Dtype::U8: return "|u1";
    case NpyWriter::Dtype::U16: return "<u2";
  }
  return "";
}

std::string shape_tuple(const std::vector<int64_t>& shape) {
  std::string s = "(";
  for (size_t i = 0; i < shape.size(); ++i) {
    if (i > 0) s += ", ";
    s += std::to_string(shape[i]);
  }
  // A one-element Python tuple needs its trailing comma.
  if (shape.size() == 1) s += ",";
  return s + ")";
}

// Element count, or throws if a dimension is negative or the product does not fit in 63 bits.
int64_t checked_elements(const std::vector<int64_t>& shape, int64_t elem_bytes, const std::string& path) {
  int64_t n = 1;
  for (int64_t d : shape) {
    if (d < 0) throw Error("cannot write '" + path + "': negative dimension in shape " + shape_tuple(shape));
    if (d != 0 && n > std::numeric_limits<int64_t>::max() / elem_bytes / d)
      throw Error("cannot write '" + path + "': shape " + shape_tuple(shape) + " is too large");
    n *= d;
  }
  return n;
}

}  // namespace

int64_t NpyWriter::element_bytes(Dtype dtype) {
  switch (dtype) {
    case Dtype::F32: return 4;
    case Dtype::U8: return 1;
    case Dtype::U16: return 2;
  }
  return 0;
}

std::string NpyWriter::header(Dtype dtype, const std::vector<int64_t>& shape) {
  std::string dict = std::string("{'descr': '") + descr(dtype) + "', 'fortran_order': False, 'shape': " +
                     shape_tuple(shape) + ", }";
  constexpr size_t kPrefix = 10;  // magic (6) + version (2) + header length (2)
  const size_t unpadded = kPrefix + dict.size() + 1;  // + the final '\n'
  const size_t total = (unpadded + 63) / 64 * 64;
  dict.append(total - unpadded, ' ');
  dict.push_back('\n');
  const size_t len = dict.size();
  if (len > 65535) throw Error("NumPy header too long for format 1.0 (shape " + shape_tuple(shape) + ")");
  std::string out = "\x93NUMPY";
  out.push_back('\x01');
  out.push_back('\x00');
  out.push_back(static_cast<char>(len & 0xff));
  out.push_back(static_cast<char>(len >> 8));
  return out + dict;
}

NpyWriter::NpyWriter(const std::string& path, Dtype dtype, std::vector<int64_t> shape) {
  const int64_t eb = element_bytes(dtype);
  const int64_t elements = checked_elements(shape, eb, path);
  const std::string head = header(dtype, shape);
  impl_ = std::make_unique<Impl>(path, dtype, std::move(shape));
  impl_->elements = elements;
  impl_->elem_bytes = eb;
  impl_->header_bytes = static_cast<int64_t>(head.size());
  detail::pwrite_all(impl_->file.fd(), head.data(), head.size(), 0, path);
  // The file gets its full size up front, so tiles can land anywhere in any order. Its blocks are
  // reserved (fallocate): a full disk is an error here, naming the file, and never a SIGBUS later when a
  // write through the mapping finds no block. File systems without fallocate get a sparse file.
  const int fd = impl_->file.fd();
  const auto bytes = static_cast<off_t>(file_bytes());
  if (::fallocate(fd, 0, 0, bytes) != 0) {
    const int err = errno;
    if (err != EOPNOTSUPP && err != ENOSYS) detail::throw_errno("cannot allocate", path, err);
    if (::ftruncate(fd, bytes) != 0) detail::throw_errno("cannot allocate", path, errno);
  }
  // Tiles write short runs (a tile's row of one gate position: 128 bytes; of one binary frame: 4 bytes),
  // one system call each through pwrite; through a shared mapping each is a memcpy into the page cache.
  if (bytes > 0) {
    void* m = ::mmap(nullptr, static_cast<size_t>(bytes), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    if (m != MAP_FAILED) {
      impl_->map = static_cast<char*>(m);
      impl_->map_bytes = static_cast<size_t>(bytes);
    }
  }
}

NpyWriter::~NpyWriter() = default;

const std::string& NpyWriter::path() const { return impl_->path; }
NpyWriter::Dtype NpyWriter::dtype() const { return impl_->dtype; }
const std::vector<int64_t>& NpyWriter::shape() const { return impl_->shape; }
int64_t NpyWriter::header_bytes() const { return impl_->header_bytes; }
int64_t NpyWriter::file_bytes() const { return impl_->header_bytes + impl_->elements * impl_->elem_bytes; }

void NpyWriter::write(int64_t offset, const void* data, int64_t count) {
  if (impl_->committed.load(std::memory_order_relaxed))
    throw Error("cannot write to '" + impl_->path + "': already committed");
  if (offset < 0 || count < 0 || offset > impl_->elements || count > impl_->elements - offset)
    throw Error("write outside '" + impl_->path + "': elements [" + std::to_string(offset) + ", " +
                std::to_string(offset + count) + ") of " + std::to_string(impl_->elements));
  if (count == 0) return;
  const int64_t at = impl_->header_bytes + offset * impl_->elem_bytes, n = count * impl_->elem_bytes;
  if (impl_->map) std::memcpy(impl_->map + at, data, static_cast<size_t>(n));
  else detail::pwrite_all(impl_->file.fd(), data, static_cast<uint64_t>(n), static_cast<uint64_t>(at), impl_->path);
}

void NpyWriter::release_rows(int axis, int64_t row_begin, int64_t row_end) {
  const auto& s = impl_->shape;
  if (!impl_->map || axis < 0 || size_t(axis) >= s.size() || row_begin >= row_end) return;
  row_begin = std::max<int64_t>(row_begin, 0), row_end = std::min(row_end, s[size_t(axis)]);
  int64_t outer = 1, inner = impl_->elem_bytes;
  for (int a = 0; a < axis; ++a) outer *= s[size_t(a)];
  for (size_t a = size_t(axis) + 1; a < s.size(); ++a) inner *= s[a];
  const auto page = static_cast<int64_t>(::sysconf(_SC_PAGESIZE));
  for (int64_t o = 0; o < outer; ++o) {
    const int64_t first = impl_->header_bytes + (o * s[size_t(axis)] + row_begin) * inner;
    const int64_t last = first + (row_end - row_begin) * inner;
    // Whole pages inside the range only: a page it shares with rows still being written stays mapped.
    const int64_t a = (first + page - 1) / page * page, b = last / page * page;
    if (b > a) ::madvise(impl_->map + a, static_cast<size_t>(b - a), MADV_DONTNEED);
  }
}

namespace {

void check_rank(const std::vector<int64_t>& shape, size_t rank, const char* what, const std::string& path) {
  if (shape.size() != rank)
    throw Error(std::string(what) + " needs a " + std::to_string(rank) + "-dimensional stack, but '" + path +
                "' has shape " + shape_tuple(shape));
}

// rect shifted by the origin must lie inside a height x width image.
void check_inside(const PixelRect& rect, int origin_x, int origin_y, int64_t height, int64_t width,
                  const std::string& path) {
  const int64_t x0 = int64_t(rect.x0) - origin_x, y0 = int64_t(rect.y0) - origin_y;
  if (rect.width < 0 || rect.height < 0 || x0 < 0 || y0 < 0 || x0 + rect.width > width || y0 + rect.height > height)
    throw Error("tile at (" + std::to_string(rect.x0) + ", " + std::to_string(rect.y0) + ") size " +
                std::to_string(rect.width) + "x" + std::to_string(rect.height) + " with origin (" +
                std::to_string(origin_x) + ", " + std::to_string(origin_y) + ") lies outside '" + path +
                "' (" + std::to_string(width) + "x" + std::to_string(height) + ")");
}

}  // namespace

void NpyWriter::write_khw(const PixelRect& rect, int origin_x, int origin_y, const void* data) {
  const auto& s = impl_->shape;
  check_rank(s, 3, "write_khw", impl_->path);
  const int64_t K = s[0], H = s[1], W = s[2];
  check_inside(rect, origin_x, origin_y, H, W, impl_->path);
  const auto* src = static_cast<const char*>(data);
  const int64_t eb = impl_->elem_bytes;
  for (int64_t k = 0; k < K; ++k)
    for (int y = rect.y0; y < rect.y1(); ++y) {
      const int64_t dst = (k * H + (y - origin_y)) * W + (rect.x0 - origin_x);
      const int64_t from = k * rect.count() + rect.index(rect.x0, y);
      write(dst, src + from * eb, rect.width);
    }
}

void NpyWriter::write_hwt(const PixelRect& rect, const PixelRect& data_rect, int origin_x, int origin_y,
                          const void* data) {
  const auto& s = impl_->shape;
  check_rank(s, 3, "write_hwt", impl_->path);
  const int64_t H = s[0], W = s[1], T = s[2];
  check_inside(rect, origin_x, origin_y, H, W, impl_->path);
  if (rect.count() > 0 && !(data_rect.contains(rect.x0, rect.y0) && data_rect.contains(rect.x1() - 1, rect.y1() - 1)))
    throw Error("write_hwt to '" + impl_->path + "': the tile's data does not cover the pixels to write");
  const auto* src = static_cast<const char*>(data);
  const int64_t eb = impl_->elem_bytes;
  // One row of the tile is contiguous both in the tile (pixel-major, time-minor) and in the file.
  for (int y = rect.y0; y < rect.y1(); ++y) {
    const int64_t dst = ((y - origin_y) * W + (rect.x0 - origin_x)) * T;
    write(dst, src + data_rect.index(rect.x0, y) * T * eb, int64_t(rect.width) * T);
  }
}

void NpyWriter::write_frames(const PixelRect& rect, int origin_x, int origin_y, const void* data) {
  const auto& s = impl_->shape;
  check_rank(s, 4, "write_frames", impl_->path);
  if (impl_->dtype != Dtype::U8) throw Error("write_frames needs a uint8 stack, but '" + impl_->path + "' is not");
  const int64_t K = s[0], N = s[1], H = s[2], WB = s[3];
  const int64_t x0 = int64_t(rect.x0) - origin_x;
  if (x0 % 8 != 0)
    throw Error("write_frames to '" + impl_->path + "': tile x " + std::to_string(x0) +
                " is not a multiple of 8, so its packed bytes would share a byte with its neighbour");
  check_inside(rect, origin_x, origin_y, H, WB * 8, impl_->path);
  const int64_t bpr = (int64_t(rect.width) + 7) / 8;
  const int64_t first_byte = x0 / 8;
  // A partial last byte is only harmless at the right edge, where its high bits are padding anyway.
  if (rect.width % 8 != 0 && first_byte + bpr != WB)
    throw Error("write_frames to '" + impl_->path + "': a tile of width " + std::to_string(rect.width) +
                " (not a multiple of 8) must end at the right edge of the stack");
  const auto* src = static_cast<const uint8_t*>(data);
  // Bits past the image's right edge are cleared whatever the tile holds there, so that summing
  // unpacked frames never counts pixels that do not exist.
  const int tail_bits = rect.width % 8;
  const auto tail_mask = static_cast<uint8_t>((1u << tail_bits) - 1u);
  std::vector<uint8_t> row_buf(tail_bits ? size_t(bpr) : 0);
  for (int64_t kn = 0; kn < K * N; ++kn)
    for (int64_t row = 0; row < rect.height; ++row) {
      const int64_t dst = (kn * H + (rect.y0 - origin_y) + row) * WB + first_byte;
      const uint8_t* from = src + (kn * rect.height + row) * bpr;
      if (tail_bits) {
        std::copy(from, from + bpr, row_buf.begin());
        row_buf.back() &= tail_mask;
        from = row_buf.data();
      }
      write(dst, from, bpr);
    }
}

void NpyWriter::commit() {
  if (impl_->committed.exchange(true)) throw Error("'" + impl_->path + "' was already committed");
  // Unmapping hands the mapping's dirty pages to the page cache; commit's fsync writes them.
  impl_->unmap();
  impl_->file.commit();
}

}  // namespace spadgen::writers
