// NumPy .npy format 1.0: "\x93NUMPY", major 1, minor 0, little-endian uint16 header length, then an ASCII
// Python dict literal padded with spaces and ending in '\n' so the data starts on a 64-byte boundary
// (what NumPy itself writes, so memory maps of the data are aligned). Format 1.0 caps the header at
// 65535 bytes, far beyond any shape we write. Also the tile helpers every StackWriter shares
// (write_khw, write_hwt), which reach the file through write().
#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <algorithm>
#include <charconv>
#include <atomic>
#include <limits>
#include <type_traits>
#include <utility>

#include "core/error.h"
#include "core/mapped_files.h"
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
    if (map) unregister_mapped_file(map), ::munmap(map, map_bytes);
    map = nullptr;
  }
};

namespace {

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

const char* numpy_descr(Dtype dtype) {
  switch (dtype) {
    case Dtype::F32: return "<f4";
    case Dtype::U8: return "|u1";
    case Dtype::U16: return "<u2";
    case Dtype::I32: return "<i4";
    case Dtype::I64: return "<i8";
    case Dtype::F64: return "<f8";
  }
  return "";
}

std::string dtype_mismatch(Dtype found, Dtype expected) {
  return std::string("its dtype is ") + numpy_descr(found) + ", expected " + numpy_descr(expected) +
         " (NumPy's descr: <f4 float32, <f8 float64, |u1 uint8, <u2 uint16, <i4 int32, <i8 int64)";
}

int64_t element_bytes(Dtype dtype) {
  switch (dtype) {
    case Dtype::F32: return 4;
    case Dtype::U8: return 1;
    case Dtype::U16: return 2;
    case Dtype::I32: return 4;
    case Dtype::I64: return 8;
    case Dtype::F64: return 8;
  }
  return 0;
}

std::string NpyWriter::header(Dtype dtype, const std::vector<int64_t>& shape) {
  std::string dict = std::string("{'descr': '") + numpy_descr(dtype) + "', 'fortran_order': False, 'shape': " +
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

NpyWriter::NpyWriter(const std::string& path, Dtype dtype, std::vector<int64_t> shape, bool mapped) {
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
  // write through the mapping finds no block. File systems without fallocate (ext2, some network ones)
  // get a sparse file, written through pwrite only: a full disk is then an error of the write that finds
  // it (through a mapping it was a SIGBUS, the process killed without a word).
  const int fd = impl_->file.fd();
  const auto bytes = static_cast<off_t>(file_bytes());
  bool reserved = true;
  if (::fallocate(fd, 0, 0, bytes) != 0) {
    const int err = errno;
    if (err != EOPNOTSUPP && err != ENOSYS) detail::throw_errno("cannot allocate", path, err);
    if (::ftruncate(fd, bytes) != 0) detail::throw_errno("cannot allocate", path, errno);
    reserved = false;
  }
  // Tiles write short runs (a tile's row of one gate position: 128 bytes; of one binary frame: 4 bytes),
  // one system call each through pwrite; through a shared mapping each is a memcpy into the page cache.
  if (bytes > 0 && mapped && reserved) {
    void* m = ::mmap(nullptr, static_cast<size_t>(bytes), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    if (m != MAP_FAILED) {
      impl_->map = static_cast<char*>(m);
      impl_->map_bytes = static_cast<size_t>(bytes);
      register_mapped_file(m, impl_->map_bytes, path);
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
  if (axis < 0 || size_t(axis) >= s.size() || row_begin >= row_end) return;
  row_begin = std::max<int64_t>(row_begin, 0), row_end = std::min(row_end, s[size_t(axis)]);
  int64_t outer = 1, inner = impl_->elem_bytes;
  for (int a = 0; a < axis; ++a) outer *= s[size_t(a)];
  for (size_t a = size_t(axis) + 1; a < s.size(); ++a) inner *= s[a];
  const auto page = static_cast<int64_t>(::sysconf(_SC_PAGESIZE));
  if (!impl_->map) {
    // Written by pwrite, which callers use for bands written whole: the dirty pages between the first and
    // the last row released hold complete rows, so one call starts them all (one per plane of the frames
    // was 89,250 calls for a band of the paper's sweep). Starting writeback is only I/O: a page written
    // again later is written out again.
    const int64_t first = impl_->header_bytes + row_begin * inner;
    const int64_t last = impl_->header_bytes + ((outer - 1) * s[size_t(axis)] + row_end) * inner;
    const int64_t a = first / page * page, b = (last + page - 1) / page * page;
    if (b > a) (void)::sync_file_range(impl_->file.fd(), a, b - a, SYNC_FILE_RANGE_WRITE);
    return;
  }
  for (int64_t o = 0; o < outer; ++o) {
    const int64_t first = impl_->header_bytes + (o * s[size_t(axis)] + row_begin) * inner;
    const int64_t last = first + (row_end - row_begin) * inner;
    // Whole pages inside the range only: a page it shares with rows still being written stays mapped.
    const int64_t a = (first + page - 1) / page * page, b = last / page * page;
    if (b <= a) continue;
    if (impl_->map) ::madvise(impl_->map + a, static_cast<size_t>(b - a), MADV_DONTNEED);
    // Written out now, while the next rows are computed, rather than all by commit()'s fsync.
    (void)::sync_file_range(impl_->file.fd(), a, b - a, SYNC_FILE_RANGE_WRITE);
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

void StackWriter::write_khw(const PixelRect& rect, int origin_x, int origin_y, const void* data) {
  const auto& s = shape();
  check_rank(s, 3, "write_khw", path());
  const int64_t K = s[0], H = s[1], W = s[2];
  check_inside(rect, origin_x, origin_y, H, W, path());
  const auto* src = static_cast<const char*>(data);
  const int64_t eb = element_bytes(dtype());
  for (int64_t k = 0; k < K; ++k)
    for (int y = rect.y0; y < rect.y1(); ++y) {
      const int64_t dst = (k * H + (y - origin_y)) * W + (rect.x0 - origin_x);
      const int64_t from = k * rect.count() + rect.index(rect.x0, y);
      write(dst, src + from * eb, rect.width);
    }
}

void StackWriter::write_hwt(const PixelRect& rect, const PixelRect& data_rect, int origin_x, int origin_y,
                            const void* data) {
  const auto& s = shape();
  check_rank(s, 3, "write_hwt", path());
  const int64_t H = s[0], W = s[1], T = s[2];
  check_inside(rect, origin_x, origin_y, H, W, path());
  if (rect.count() > 0 && !(data_rect.contains(rect.x0, rect.y0) && data_rect.contains(rect.x1() - 1, rect.y1() - 1)))
    throw Error("write_hwt to '" + path() + "': the tile's data does not cover the pixels to write");
  const auto* src = static_cast<const char*>(data);
  const int64_t eb = element_bytes(dtype());
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
  if (impl_->map && tail_bits == 0) {
    // Mapped, whole bytes (every tile but a right-edge one of odd width): the tile's rows go straight into
    // the mapping, checked once above for the whole tile, each row a copy of a size known at compile time
    // for the usual tile widths (a 32-pixel tile: 4 bytes a row, millions of rows per band).
    if (impl_->committed.load(std::memory_order_relaxed))
      throw Error("cannot write to '" + impl_->path + "': already committed");
    auto* base = reinterpret_cast<uint8_t*>(impl_->map + impl_->header_bytes + ((rect.y0 - origin_y) * WB + first_byte));
    const int64_t planes = K * N, rows = rect.height, plane_bytes = H * WB;
    const auto copy = [&](auto width) {
      constexpr int64_t B = decltype(width)::value;
      const int64_t b = B > 0 ? B : bpr;
      for (int64_t kn = 0; kn < planes; ++kn) {
        uint8_t* d = base + kn * plane_bytes;
        for (int64_t row = 0; row < rows; ++row, d += WB, src += b) std::memcpy(d, src, size_t(b));
      }
    };
    switch (bpr) {
      case 1: copy(std::integral_constant<int64_t, 1>()); break;
      case 2: copy(std::integral_constant<int64_t, 2>()); break;
      case 4: copy(std::integral_constant<int64_t, 4>()); break;
      case 8: copy(std::integral_constant<int64_t, 8>()); break;
      case 16: copy(std::integral_constant<int64_t, 16>()); break;
      default: copy(std::integral_constant<int64_t, 0>()); break;
    }
    return;
  }
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

void NpyWriter::write_frames_band(const std::vector<FramesTile>& tiles, int origin_x, int origin_y, int64_t k_begin,
                                  int64_t k_end) {
  const auto& s = impl_->shape;
  check_rank(s, 4, "write_frames_band", impl_->path);
  if (impl_->dtype != Dtype::U8) throw Error("write_frames_band needs a uint8 stack, but '" + impl_->path + "' is not");
  const int64_t K = s[0], N = s[1], H = s[2], WB = s[3];
  if (k_begin < 0 || k_end > K || k_begin > k_end)
    throw Error("write_frames_band to '" + impl_->path + "': gate positions [" + std::to_string(k_begin) + ", " +
                std::to_string(k_end) + ") outside [0, " + std::to_string(K) + ")");
  if (tiles.empty() || k_begin == k_end || N == 0) return;
  // The band: tiles side by side from x = 0 to the stack's width, sharing their rows.
  std::vector<const FramesTile*> order;
  for (const FramesTile& t : tiles) order.push_back(&t);
  std::sort(order.begin(), order.end(), [](const FramesTile* a, const FramesTile* b) { return a->rect.x0 < b->rect.x0; });
  const int rows = order.front()->rect.height, band_y0 = order.front()->rect.y0;
  int64_t x = 0;
  for (const FramesTile* t : order) {
    check_inside(t->rect, origin_x, origin_y, H, WB * 8, impl_->path);
    if (t->rect.y0 != band_y0 || t->rect.height != rows || int64_t(t->rect.x0) - origin_x != x || x % 8 != 0)
      throw Error("write_frames_band to '" + impl_->path + "': the tile at (" + std::to_string(t->rect.x0) + ", " +
                  std::to_string(t->rect.y0) + ") size " + std::to_string(t->rect.width) + "x" +
                  std::to_string(t->rect.height) + " does not continue a band of tiles of " + std::to_string(rows) +
                  " rows from x = " + std::to_string(x + origin_x) + " on a byte boundary");
    x += t->rect.width;
  }
  if ((x + 7) / 8 != WB)
    throw Error("write_frames_band to '" + impl_->path + "': the band's tiles cover " + std::to_string(x) +
                " pixels of the stack's " + std::to_string(WB) + " bytes a row");
  if (rows == 0) return;
  const int64_t y0 = band_y0 - origin_y, plane = int64_t(rows) * WB;  // one plane's share of the band, bytes
  const int64_t group = std::clamp<int64_t>(kFramesBuffer / plane, 1, N);
  std::vector<uint8_t> buf(size_t(group * plane));
  const auto tail_mask = static_cast<uint8_t>((1u << (x % 8)) - 1u);
  for (int64_t k = k_begin; k < k_end; ++k)
    for (int64_t n0 = 0; n0 < N; n0 += group) {
      const int64_t planes = std::min(group, N - n0), lines = planes * rows;
      for (const FramesTile* t : order) {
        const int64_t bpr = (int64_t(t->rect.width) + 7) / 8;
        const uint8_t* src = t->frames + (k * N + n0) * rows * bpr;
        uint8_t* dst = buf.data() + (t->rect.x0 - origin_x) / 8;
        const auto gather = [&](auto width) {
          constexpr int64_t B = decltype(width)::value;
          const int64_t b = B > 0 ? B : bpr;
          for (int64_t j = 0; j < lines; ++j) std::memcpy(dst + j * WB, src + j * b, size_t(b));
        };
        switch (bpr) {
          case 4: gather(std::integral_constant<int64_t, 4>()); break;
          case 8: gather(std::integral_constant<int64_t, 8>()); break;
          case 16: gather(std::integral_constant<int64_t, 16>()); break;
          default: gather(std::integral_constant<int64_t, 0>()); break;
        }
      }
      // Bits past the image's right edge are cleared, as write_frames does.
      if (x % 8 != 0)
        for (int64_t j = 0; j < lines; ++j) buf[size_t(j * WB + WB - 1)] &= tail_mask;
      if (rows == H) {
        write((k * N + n0) * H * WB, buf.data(), planes * plane);
      } else {
        for (int64_t p = 0; p < planes; ++p) write(((k * N + n0 + p) * H + y0) * WB, buf.data() + p * plane, plane);
      }
    }
}

void NpyWriter::commit() {
  if (impl_->committed.exchange(true)) throw Error("'" + impl_->path + "' was already committed");
  // Unmapping hands the mapping's dirty pages to the page cache; commit's fsync writes them.
  impl_->unmap();
  impl_->file.commit();
}

}  // namespace spadgen::writers

namespace spadgen::writers {

namespace {

std::string read_error(const std::string& path, const std::string& what) {
  return "cannot read '" + path + "' as a NumPy array: " + what;
}

// Header text in a one-line message: control bytes escaped (\n, \xNN), at most 80 characters.
std::string shown(const std::string& text) {
  std::string out;
  for (size_t i = 0; i < text.size() && i < 80; ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c == '\n') out += "\\n";
    else if (c < 0x20 || c >= 0x7f) {
      const char hex[] = "0123456789abcdef";
      out += std::string("\\x") + hex[c >> 4] + hex[c & 15];
    } else
      out += char(c);
  }
  return text.size() > 80 ? out + "..." : out;
}

// The value of `key` in the header's Python dict literal, as its raw text (a quoted string, False/True or a tuple).
std::string dict_value(const std::string& dict, const std::string& key, const std::string& path) {
  const size_t k = dict.find("'" + key + "'");
  if (k == std::string::npos) throw Error(read_error(path, "the header has no '" + key + "'"));
  // NumPy's header is a Python dict literal, whose later value of a repeated key wins: a header naming a
  // key twice, in either quotes, is refused rather than read either way
  if (dict.find("'" + key + "'", k + key.size() + 2) != std::string::npos ||
      dict.find("\"" + key + "\"") != std::string::npos)
    throw Error(read_error(path, "the header names '" + key + "' twice"));
  size_t v = dict.find(':', k);
  if (v == std::string::npos) throw Error(read_error(path, "malformed header"));
  ++v;
  while (v < dict.size() && dict[v] == ' ') ++v;
  if (v < dict.size() && dict[v] == '(') return dict.substr(v, dict.find(')', v) - v + 1);
  if (v < dict.size() && dict[v] == '[') {  // a structured dtype's list, whole (it was cut at its first comma)
    int depth = 0;
    for (size_t e = v; e < dict.size(); ++e) {
      depth += dict[e] == '[' || dict[e] == '(' ? 1 : dict[e] == ']' || dict[e] == ')' ? -1 : 0;
      if (depth == 0) return dict.substr(v, e - v + 1);
    }
    throw Error(read_error(path, "malformed header"));
  }
  size_t e = v;
  if (v < dict.size() && dict[v] == '\'') e = dict.find('\'', v + 1) + 1;
  else
    while (e < dict.size() && dict[e] != ',' && dict[e] != '}') ++e;
  return dict.substr(v, e - v);
}

}  // namespace

NpyReader::NpyReader(const std::string& path) : path_(path) {
  const int fd = detail::open_regular_file(path);
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  const off_t size = ::lseek(fd, 0, SEEK_END);
  if (size < 0) detail::throw_errno("cannot read", path, errno);
  if (size < 12) throw Error(read_error(path, "too short for a .npy header"));
  map_bytes_ = static_cast<size_t>(size);
  void* m = ::mmap(nullptr, map_bytes_, PROT_READ, MAP_SHARED, fd, 0);
  if (m == MAP_FAILED) detail::throw_errno("cannot map", path, errno);
  map_ = static_cast<const char*>(m);
  // a file cut short while mapped is told by name (core/mapped_files.h), not a SIGBUS without a word
  register_mapped_file(map_, map_bytes_, path);
  // a header refused below unmaps it (the destructor does not run for a constructor that throws)
  struct Unmap {
    NpyReader* r;
    bool keep = false;
    ~Unmap() {
      if (keep) return;
      unregister_mapped_file(r->map_);
      ::munmap(const_cast<char*>(r->map_), r->map_bytes_);
      r->map_ = nullptr;
    }
  } unmap_unless_read{this};
  const auto* u = reinterpret_cast<const unsigned char*>(map_);
  if (std::memcmp(map_, "\x93NUMPY", 6) != 0) throw Error(read_error(path, "no \\x93NUMPY magic"));
  const int major = u[6];
  int64_t header_len = 0, prefix = 0;
  if (major == 1) header_len = u[8] | (u[9] << 8), prefix = 10;
  else if (major == 2 || major == 3) header_len = int64_t(u[8]) | int64_t(u[9]) << 8 | int64_t(u[10]) << 16 | int64_t(u[11]) << 24, prefix = 12;
  else throw Error(read_error(path, "format version " + std::to_string(major) + " is not 1, 2 or 3"));
  data_offset_ = prefix + header_len;
  if (data_offset_ > size)
    throw Error(read_error(path, "its header (format version " + std::to_string(major) + ", " + std::to_string(header_len) +
                                     " bytes after a " + std::to_string(prefix) + "-byte prefix) runs past the end of the file (" +
                                     std::to_string(size) + " bytes)"));
  const std::string dict(map_ + prefix, static_cast<size_t>(header_len));
  const std::string d = dict_value(dict, "descr", path);
  const std::pair<const char*, NpyWriter::Dtype> known[] = {
      {"'<f4'", NpyWriter::Dtype::F32}, {"'|u1'", NpyWriter::Dtype::U8},  {"'<u2'", NpyWriter::Dtype::U16},
      {"'<i4'", NpyWriter::Dtype::I32}, {"'<i8'", NpyWriter::Dtype::I64}, {"'<f8'", NpyWriter::Dtype::F64}};
  bool found = false;
  for (const auto& [text, dt] : known)
    if (d == text) dtype_ = dt, found = true;
  if (!found) throw Error(read_error(path, "dtype " + shown(d) + " is not one spadgen writes (<f4, <f8, |u1, <u2, <i4, <i8)"));
  if (dict_value(dict, "fortran_order", path) != "False") throw Error(read_error(path, "Fortran order is not supported"));
  const std::string s = dict_value(dict, "shape", path);
  // (d0, d1, ...) of non-negative integers, a trailing comma allowed: "(5,)", "()".
  const auto malformed = [&] { return Error(read_error(path, "malformed shape " + shown(s) + ", expected (d0, d1, ...) of integers >= 0")); };
  if (s.size() < 2 || s.front() != '(' || s.back() != ')') throw malformed();
  int64_t n = 1;
  const size_t end = s.size() - 1;
  for (size_t i = 1;;) {
    while (i < end && s[i] == ' ') ++i;
    if (i == end) break;
    int64_t v = 0;
    const auto [next, ec] = std::from_chars(s.data() + i, s.data() + end, v);
    if (ec == std::errc::result_out_of_range) throw Error(read_error(path, "shape " + shown(s) + " too large"));
    if (ec != std::errc() || v < 0) throw malformed();
    shape_.push_back(v);
    if (v != 0 && n > std::numeric_limits<int64_t>::max() / v) throw Error(read_error(path, "shape " + shown(s) + " too large"));
    n *= v;
    i = size_t(next - s.data());
    while (i < end && s[i] == ' ') ++i;
    if (i < end && s[i++] != ',') throw malformed();
  }
  elements_ = n;
  const int64_t eb = NpyWriter::element_bytes(dtype_);
  // (its bytes must be a number too: the message below multiplied past 2^63, found by fuzz_arrays)
  if (elements_ > std::numeric_limits<int64_t>::max() / eb)
    throw Error(read_error(path, "shape " + shown(s) + " too large: its " + shown(d) + " elements take more than 2^63 bytes"));
  // The format pads the header so that the data start at a multiple of 64 bytes (16 in NumPy before 1.14):
  // data() hands out the mapping as an array of the dtype, which must be aligned to it.
  if (data_offset_ % eb != 0)
    throw Error(read_error(path, "its data start at byte " + std::to_string(data_offset_) + ", not a multiple of the " +
                                 std::to_string(eb) + "-byte elements of " + shown(d) +
                                 " (the .npy format pads its header to 64 bytes; np.save writes such files)"));
  if (elements_ > (size - data_offset_) / eb)
    throw Error(read_error(path, "the file holds " + std::to_string(size - data_offset_) + " bytes of data, shape " + shown(s) +
                                 " needs " + std::to_string(elements_ * eb)));
  unmap_unless_read.keep = true;
}

NpyReader::~NpyReader() {
  if (map_) unregister_mapped_file(map_), ::munmap(const_cast<char*>(map_), map_bytes_);
}
NpyReader::NpyReader(NpyReader&& o) noexcept { *this = std::move(o); }
NpyReader& NpyReader::operator=(NpyReader&& o) noexcept {
  if (this != &o) {
    if (map_) unregister_mapped_file(map_), ::munmap(const_cast<char*>(map_), map_bytes_);
    path_ = std::move(o.path_), dtype_ = o.dtype_, shape_ = std::move(o.shape_), elements_ = o.elements_;
    map_ = std::exchange(o.map_, nullptr), map_bytes_ = o.map_bytes_, data_offset_ = o.data_offset_;
  }
  return *this;
}

void NpyReader::expect_shape(const std::vector<int64_t>& expected, const std::string& what) const {
  if (shape_ == expected) return;
  const auto text = [](const std::vector<int64_t>& v) {
    std::string t = "(";
    for (size_t i = 0; i < v.size(); ++i) t += (i ? ", " : "") + std::to_string(v[i]);
    return t + ")";
  };
  throw Error("'" + path_ + "': " + what + ": expected shape " + text(expected) + ", found " + text(shape_));
}

template <class T>
const T* NpyReader::data() const {
  constexpr NpyWriter::Dtype want = std::is_same_v<T, float>      ? NpyWriter::Dtype::F32
                                    : std::is_same_v<T, double>   ? NpyWriter::Dtype::F64
                                    : std::is_same_v<T, int32_t>  ? NpyWriter::Dtype::I32
                                    : std::is_same_v<T, int64_t>  ? NpyWriter::Dtype::I64
                                    : std::is_same_v<T, uint16_t> ? NpyWriter::Dtype::U16
                                                                  : NpyWriter::Dtype::U8;
  if (dtype_ != want) throw Error(read_error(path_, dtype_mismatch(dtype_, want)));
  return reinterpret_cast<const T*>(map_ + data_offset_);
}
template const float* NpyReader::data<float>() const;
template const double* NpyReader::data<double>() const;
template const int32_t* NpyReader::data<int32_t>() const;
template const int64_t* NpyReader::data<int64_t>() const;
template const uint8_t* NpyReader::data<uint8_t>() const;
template const uint16_t* NpyReader::data<uint16_t>() const;

}  // namespace spadgen::writers
