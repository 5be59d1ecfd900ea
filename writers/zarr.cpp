// Zarr v2 array stores (the Zarr storage specification, version 2), the subset spadgen writes: a folder
// holding .zarray (JSON: shape, chunks, dtype, compressor, C order, no filters, fill value NaN for floats and
// none for integers), .zattrs (JSON
// attributes) and one file per chunk named by its grid indices joined by '.', each chunk a full-size
// C-order block (edge chunks padded) compressed as one Blosc buffer. Blosc frames carry their own sizes,
// shuffle and block size, so any Blosc reader (numcodecs, hence zarr-python) decodes them.
#include <blosc.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <list>
#include <mutex>
#include <optional>
#include <sstream>
#include <type_traits>
#include <utility>

#include "core/error.h"
#include "writers/atomic_file.h"
#include "writers/writers.h"

namespace spadgen::writers {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

constexpr size_t kMaxRank = 8;
constexpr const char* kCompressor = "zstd";

std::string tuple_text(const std::vector<int64_t>& v) {
  std::string s = "(";
  for (size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + std::to_string(v[i]);
  return s + (v.size() == 1 ? ",)" : ")");
}

// The chunk grid of an array: which chunk holds an element, where inside it, and each chunk's name.
struct Grid {
  std::vector<int64_t> shape, chunks, counts;  // counts: chunks along each dimension
  int64_t elements = 1, chunk_elements = 1, n_chunks = 1;

  Grid() = default;
  // Checks the rank, the extents and the sizes; `what` names the store in messages.
  Grid(std::vector<int64_t> s, std::vector<int64_t> c, int64_t element_bytes, const std::string& what)
      : shape(std::move(s)), chunks(std::move(c)) {
    if (shape.empty() || shape.size() > kMaxRank || chunks.size() != shape.size())
      throw Error(what + ": a Zarr store of shape " + tuple_text(shape) + " with chunks " + tuple_text(chunks) +
                  " is not supported (1 to 8 dimensions, one chunk extent each)");
    const int64_t limit = std::numeric_limits<int64_t>::max() / element_bytes;
    for (size_t d = 0; d < shape.size(); ++d) {
      if (shape[d] < 0 || chunks[d] < 1)
        throw Error(what + ": shape " + tuple_text(shape) + " and chunks " + tuple_text(chunks) +
                    " need dimensions of at least 0 and chunks of at least 1");
      if (shape[d] != 0 && elements > limit / shape[d]) throw Error(what + ": shape " + tuple_text(shape) + " is too large");
      elements *= shape[d];
      if (chunk_elements > limit / chunks[d]) throw Error(what + ": chunks " + tuple_text(chunks) + " are too large");
      chunk_elements *= chunks[d];
      counts.push_back((shape[d] + chunks[d] - 1) / chunks[d]);
      n_chunks *= counts.back();
    }
    // One Blosc buffer holds at most about 2 GiB.
    if (chunk_elements * element_bytes > int64_t(BLOSC_MAX_BUFFERSIZE))
      throw Error(what + ": a chunk of " + tuple_text(chunks) + " holds more than Blosc's 2 GiB");
  }

  size_t rank() const { return shape.size(); }

  // The chunk holding flat element `offset`, the element's index inside the chunk, and how many elements
  // from there are contiguous in both (along the last dimension, to the chunk's or the array's edge).
  struct Piece {
    int64_t chunk, at, run;
  };
  Piece piece(int64_t offset) const {
    std::array<int64_t, kMaxRank> idx{};
    for (size_t d = rank(); d-- > 0;) idx[d] = offset % shape[d], offset /= shape[d];
    Piece p{0, 0, 0};
    for (size_t d = 0; d < rank(); ++d) p.chunk = p.chunk * counts[d] + idx[d] / chunks[d], p.at = p.at * chunks[d] + idx[d] % chunks[d];
    const size_t last = rank() - 1;
    p.run = std::min(chunks[last] - idx[last] % chunks[last], shape[last] - idx[last]);
    return p;
  }

  // The grid indices of chunk c.
  std::array<int64_t, kMaxRank> grid_index(int64_t c) const {
    std::array<int64_t, kMaxRank> g{};
    for (size_t d = rank(); d-- > 0;) g[d] = c % counts[d], c /= counts[d];
    return g;
  }
  // How far chunk c reaches into the array along each dimension (edge chunks: less than the chunk).
  std::array<int64_t, kMaxRank> extent(int64_t c) const {
    const auto g = grid_index(c);
    std::array<int64_t, kMaxRank> e{};
    for (size_t d = 0; d < rank(); ++d) e[d] = std::min(chunks[d], shape[d] - g[d] * chunks[d]);
    return e;
  }
  int64_t inside(int64_t c) const {
    const auto e = extent(c);
    int64_t n = 1;
    for (size_t d = 0; d < rank(); ++d) n *= e[d];
    return n;
  }
  std::string key(int64_t c) const {
    const auto g = grid_index(c);
    std::string k;
    for (size_t d = 0; d < rank(); ++d) {
      if (d) k += '.';
      k += std::to_string(g[d]);
    }
    return k;
  }
};

void write_whole_file(const std::string& path, const char* data, size_t size) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (fd < 0) detail::throw_errno("cannot create", path, errno);
  try {
    detail::pwrite_all(fd, data, size, 0, path);
  } catch (...) {
    ::close(fd);
    throw;
  }
  // Start writing it out now, without waiting: commit() then finds little left to flush.
  (void)::sync_file_range(fd, 0, 0, SYNC_FILE_RANGE_WRITE);
  if (::close(fd) != 0) detail::throw_errno("cannot write", path, errno);
}

void fsync_file(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) detail::throw_errno("cannot open", path, errno);
  const int rc = ::fsync(fd), err = errno;
  ::close(fd);
  if (rc != 0) detail::throw_errno("cannot flush", path, err);
}

bool is_float(Dtype d) { return d == Dtype::F32 || d == Dtype::F64; }

}  // namespace

ZarrCodec ZarrWriter::codec(Dtype dtype) {
  // zstd at Blosc's clevel 1 (zstd level 1). Wider types byte-shuffled in blocks of 8 MiB, so that a
  // chunk of the app's is one block: float32 rates then compress 30 % better than in Blosc's default
  // blocks at this level, and faster. Bytes (counts) unshuffled in 64 kiB blocks: bit shuffle made them
  // 12 % larger, 8 MiB blocks 4 %. Measured on the multi-object scene at 1024 x 1000 (docs/outputs.md, "Storage").
  if (dtype == Dtype::U8) return {1, BLOSC_NOSHUFFLE, int64_t(64) << 10};
  return {1, BLOSC_SHUFFLE, int64_t(8) << 20};
}

struct ZarrWriter::Impl {
  struct Chunk {
    std::atomic<int64_t> written{0};
    std::atomic<char*> data{nullptr};  // the chunk being filled; null before its first and after its last element
    std::atomic<bool> stored{false};
  };
  std::string path, temp;
  Dtype dtype;
  int64_t eb;
  Grid grid;
  json attributes;
  ZarrCodec codec;
  std::unique_ptr<Chunk[]> chunks;
  std::mutex alloc_mutex;
  std::atomic<int64_t> stored_bytes{0};
  std::atomic<bool> committed{false};
  bool published = false;

  ~Impl() {
    if (chunks)
      for (int64_t c = 0; c < grid.n_chunks; ++c) std::free(chunks[c].data.load());
    std::error_code ec;
    if (!published && !temp.empty()) fs::remove_all(temp, ec);
  }

  char* buffer(int64_t c) {
    Chunk& ch = chunks[c];
    if (char* p = ch.data.load(std::memory_order_acquire)) return p;
    std::lock_guard<std::mutex> lock(alloc_mutex);
    if (char* p = ch.data.load(std::memory_order_acquire)) return p;
    if (ch.stored.load()) throw Error("internal: chunk " + grid.key(c) + " of '" + path + "' written after it was complete");
    // Zeroed: the padding of edge chunks and elements never written are 0.
    char* p = static_cast<char*>(std::calloc(size_t(grid.chunk_elements), size_t(eb)));
    if (!p) throw Error("cannot write '" + path + "': out of memory for a chunk of " + tuple_text(grid.chunks));
    ch.data.store(p, std::memory_order_release);
    return p;
  }

  // Elements of chunk c delivered: the thread that delivers its last one stores it. Every other thread's
  // copy into the chunk happened before its own count, which this acquire-release sees.
  void delivered(int64_t c, int64_t n) {
    const int64_t inside = grid.inside(c);
    const int64_t written = chunks[c].written.fetch_add(n, std::memory_order_acq_rel) + n;
    if (written > inside) throw Error("internal: elements of chunk " + grid.key(c) + " of '" + path + "' written more than once");
    if (written == inside) store(c);
  }

  // The box [lo, hi) of a 3-dimensional array from `src`, whose element (a, b, c) of the box lies at
  // a * stride[0] + b * stride[1] + c: chunk by chunk, a run along the last dimension per copy.
  void write_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& hi, const char* src,
                 const std::array<int64_t, 2>& stride) {
    if (committed.load(std::memory_order_relaxed)) throw Error("cannot write to '" + path + "': already committed");
    if (grid.rank() != 3) throw Error("a tile needs a 3-dimensional stack, but '" + path + "' has shape " + tuple_text(grid.shape));
    for (size_t d = 0; d < 3; ++d)
      if (lo[d] < 0 || hi[d] > grid.shape[d] || lo[d] > hi[d])
        throw Error("a tile lies outside '" + path + "' (shape " + tuple_text(grid.shape) + ")");
    if (lo[0] == hi[0] || lo[1] == hi[1] || lo[2] == hi[2]) return;
    const std::vector<int64_t>& ch = grid.chunks;
    for (int64_t ca = lo[0] / ch[0]; ca <= (hi[0] - 1) / ch[0]; ++ca)
      for (int64_t cb = lo[1] / ch[1]; cb <= (hi[1] - 1) / ch[1]; ++cb)
        for (int64_t cc = lo[2] / ch[2]; cc <= (hi[2] - 1) / ch[2]; ++cc) {
          const int64_t c = (ca * grid.counts[1] + cb) * grid.counts[2] + cc;
          const int64_t a0 = std::max(lo[0], ca * ch[0]), a1 = std::min(hi[0], (ca + 1) * ch[0]);
          const int64_t b0 = std::max(lo[1], cb * ch[1]), b1 = std::min(hi[1], (cb + 1) * ch[1]);
          const int64_t c0 = std::max(lo[2], cc * ch[2]), c1 = std::min(hi[2], (cc + 1) * ch[2]);
          char* buf = buffer(c);
          const auto run = size_t((c1 - c0) * eb);
          for (int64_t a = a0; a < a1; ++a)
            for (int64_t b = b0; b < b1; ++b) {
              const int64_t to = ((a - ca * ch[0]) * ch[1] + (b - cb * ch[1])) * ch[2] + (c0 - cc * ch[2]);
              const int64_t from = (a - lo[0]) * stride[0] + (b - lo[1]) * stride[1] + (c0 - lo[2]);
              std::memcpy(buf + to * eb, src + from * eb, run);
            }
          delivered(c, (a1 - a0) * (b1 - b0) * (c1 - c0));
        }
  }

  void store(int64_t c) {
    Chunk& ch = chunks[c];
    char* data = ch.data.load(std::memory_order_acquire);
    const size_t nbytes = size_t(grid.chunk_elements * eb), cap = nbytes + BLOSC_MAX_OVERHEAD;
    std::unique_ptr<char[]> out(new char[cap]);
    const int cbytes = blosc_compress_ctx(codec.clevel, codec.shuffle, size_t(eb), nbytes, data, out.get(), cap, kCompressor,
                                          size_t(codec.blocksize), 1);
    if (cbytes <= 0)
      throw Error("cannot compress chunk " + grid.key(c) + " of '" + path + "' (Blosc returned " + std::to_string(cbytes) + ")");
    write_whole_file(temp + "/" + grid.key(c), out.get(), size_t(cbytes));
    ch.data.store(nullptr, std::memory_order_release);
    std::free(data);
    ch.stored.store(true);
    stored_bytes.fetch_add(cbytes);
  }
};

ZarrWriter::ZarrWriter(const std::string& path, Dtype dtype, std::vector<int64_t> shape, std::vector<int64_t> chunks,
                       const json& attributes)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.path = path, m.dtype = dtype, m.eb = element_bytes(dtype), m.codec = codec(dtype), m.attributes = attributes;
  // Chunks larger than the array are clipped to it (at least 1: an empty dimension still has a chunk extent).
  if (chunks.size() == shape.size())
    for (size_t d = 0; d < shape.size(); ++d)
      if (chunks[d] >= 1) chunks[d] = std::max<int64_t>(1, std::min(chunks[d], shape[d]));
  m.grid = Grid(std::move(shape), std::move(chunks), m.eb, "cannot write '" + path + "'");
  if (!m.attributes.is_object()) throw Error("cannot write '" + path + "': its attributes must be a JSON object");
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && !S_ISDIR(st.st_mode)) detail::throw_errno("cannot write", path, ENOTDIR);
  m.temp = detail::temp_name(path);
  if (::mkdir(m.temp.c_str(), 0777) != 0) {
    const int err = errno;
    m.temp.clear();
    detail::throw_errno("cannot create a temporary folder for", path, err);
  }
  m.chunks = std::make_unique<Impl::Chunk[]>(size_t(m.grid.n_chunks));
}

ZarrWriter::~ZarrWriter() = default;

const std::string& ZarrWriter::path() const { return impl_->path; }
Dtype ZarrWriter::dtype() const { return impl_->dtype; }
const std::vector<int64_t>& ZarrWriter::shape() const { return impl_->grid.shape; }
const std::vector<int64_t>& ZarrWriter::chunks() const { return impl_->grid.chunks; }
int64_t ZarrWriter::stored_bytes() const { return impl_->stored_bytes.load(); }

json ZarrWriter::zarray() const {
  const Impl& m = *impl_;
  return {{"zarr_format", 2},
          {"shape", m.grid.shape},
          {"chunks", m.grid.chunks},
          {"dtype", numpy_descr(m.dtype)},
          {"compressor", {{"id", "blosc"}, {"cname", kCompressor}, {"clevel", m.codec.clevel}, {"shuffle", m.codec.shuffle},
                          {"blocksize", m.codec.blocksize}}},
          // Every chunk is stored (commit() stores those never written, as zeros), so the fill value stands only
          // for a chunk lost after the run: NaN for floats (a plain Zarr reader, zarr-python's, then reads a lost
          // chunk as NaN, not as uninitialised memory; xarray masks the fill value as NaN, which leaves NaN as it
          // is). Integers have no value a sample cannot take: none (spadgen's own readers refuse a lost chunk).
          {"fill_value", is_float(m.dtype) ? json("NaN") : json(nullptr)},
          {"order", "C"},
          {"filters", nullptr},
          {"dimension_separator", "."}};
}

void ZarrWriter::write(int64_t offset, const void* data, int64_t count) {
  Impl& m = *impl_;
  if (m.committed.load(std::memory_order_relaxed)) throw Error("cannot write to '" + m.path + "': already committed");
  if (offset < 0 || count < 0 || offset > m.grid.elements || count > m.grid.elements - offset)
    throw Error("write outside '" + m.path + "': elements [" + std::to_string(offset) + ", " + std::to_string(offset + count) +
                ") of " + std::to_string(m.grid.elements));
  const auto* src = static_cast<const char*>(data);
  while (count > 0) {
    const Grid::Piece p = m.grid.piece(offset);
    const int64_t n = std::min(count, p.run);
    std::memcpy(m.buffer(p.chunk) + p.at * m.eb, src, size_t(n * m.eb));
    m.delivered(p.chunk, n);
    offset += n, src += n * m.eb, count -= n;
  }
}

void ZarrWriter::write_khw(const PixelRect& rect, int origin_x, int origin_y, const void* data) {
  Impl& m = *impl_;
  const int64_t K = m.grid.rank() == 3 ? m.grid.shape[0] : 0;
  const int64_t y0 = int64_t(rect.y0) - origin_y, x0 = int64_t(rect.x0) - origin_x;
  m.write_box({0, y0, x0}, {K, y0 + rect.height, x0 + rect.width}, static_cast<const char*>(data), {rect.count(), rect.width});
}

void ZarrWriter::write_hwt(const PixelRect& rect, const PixelRect& data_rect, int origin_x, int origin_y, const void* data) {
  Impl& m = *impl_;
  if (rect.count() > 0 && !(data_rect.contains(rect.x0, rect.y0) && data_rect.contains(rect.x1() - 1, rect.y1() - 1)))
    throw Error("write_hwt to '" + m.path + "': the tile's data does not cover the pixels to write");
  if (rect.count() == 0) return;
  const int64_t T = m.grid.rank() == 3 ? m.grid.shape[2] : 0;
  const int64_t y0 = int64_t(rect.y0) - origin_y, x0 = int64_t(rect.x0) - origin_x;
  const char* src = static_cast<const char*>(data) + data_rect.index(rect.x0, rect.y0) * T * m.eb;
  m.write_box({y0, x0, 0}, {y0 + rect.height, x0 + rect.width, T}, src, {int64_t(data_rect.width) * T, T});
}

void ZarrWriter::commit() {
  Impl& m = *impl_;
  if (m.committed.exchange(true)) throw Error("'" + m.path + "' was already committed");
  // Chunks partly written, and chunks never written (zeros, as a .npy holds where nothing was written).
  for (int64_t c = 0; c < m.grid.n_chunks; ++c)
    if (!m.chunks[c].stored.load()) m.buffer(c), m.store(c);
  write_file_atomic(m.temp + "/.zarray", zarray().dump(4) + "\n");
  write_file_atomic(m.temp + "/.zattrs", m.attributes.dump(4) + "\n");
  for (int64_t c = 0; c < m.grid.n_chunks; ++c)
    if (m.chunks[c].stored.load()) fsync_file(m.temp + "/" + m.grid.key(c));
  detail::fsync_folder(m.temp);
  if (::rename(m.temp.c_str(), m.path.c_str()) != 0) {
    const int err = errno;
    // An earlier store of the same name: exchanged with the new one in one step, then removed.
    if ((err != ENOTEMPTY && err != EEXIST) ||
        ::renameat2(AT_FDCWD, m.temp.c_str(), AT_FDCWD, m.path.c_str(), RENAME_EXCHANGE) != 0)
      detail::throw_errno("cannot rename the temporary folder onto", m.path, err);
    std::error_code ec;
    fs::remove_all(m.temp, ec);
  }
  m.published = true;
  detail::fsync_folder(fs::path(m.path).parent_path().empty() ? "." : fs::path(m.path).parent_path().string());
}

struct ZarrReader::Impl {
  std::string path;
  Dtype dtype = Dtype::U8;
  int64_t eb = 1;
  Grid grid;
  bool blosc = false;
  std::vector<char> fill;  // one element of the fill value
  bool has_fill = false;   // .zarray names one
  bool every_chunk = true;  // a missing chunk is an error whatever the fill value (spadgen's stores)
  size_t capacity = 16;
  using Chunk = std::shared_ptr<const std::vector<char>>;
  mutable std::mutex mutex;
  mutable std::list<std::pair<int64_t, Chunk>> cache;  // most recently used first

  std::string error(const std::string& what) const { return "cannot read '" + path + "' as a Zarr array: " + what; }

  // Chunk c decompressed (a missing chunk: an error for spadgen's stores, which have every chunk stored, so
  // one gone was lost, not zeros or NaN: reconstruct scored a store without a quarter of its counts as
  // complete; for another program's store the fill value throughout, an error without one).
  Chunk load(int64_t c) const {
    const size_t nbytes = size_t(grid.chunk_elements * eb);
    const std::string file = path + "/" + grid.key(c);
    struct stat entry {};
    const int fd = ::stat(file.c_str(), &entry) != 0 && errno == ENOENT ? -1 : detail::open_regular_file(file);
    if (fd < 0) {
      if (every_chunk)
        throw Error(error("chunk " + grid.key(c) + " is missing: spadgen stores every chunk, so the store was damaged after it "
                          "was written"));
      if (!has_fill)
        throw Error(error("chunk " + grid.key(c) + " is missing, and the store has no fill value to stand for it"));
      auto out = std::make_shared<std::vector<char>>(nbytes);
      for (size_t i = 0; i < nbytes; i += size_t(eb)) std::memcpy(out->data() + i, fill.data(), size_t(eb));
      return out;
    }
    std::vector<char> raw;
    {
      struct Closer {
        int fd;
        ~Closer() { ::close(fd); }
      } closer{fd};
      struct stat st {};
      if (::fstat(fd, &st) != 0) detail::throw_errno("cannot read", file, errno);
      if (st.st_size > off_t(nbytes) + BLOSC_MAX_OVERHEAD)
        throw Error(error("chunk " + grid.key(c) + " has " + std::to_string(st.st_size) + " bytes, more than its " + std::to_string(nbytes)));
      raw.resize(size_t(st.st_size));
      for (size_t got = 0; got < raw.size();) {
        const ssize_t n = ::pread(fd, raw.data() + got, raw.size() - got, off_t(got));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) detail::throw_errno("cannot read", file, n < 0 ? errno : EIO);
        got += size_t(n);
      }
    }
    // The chunk's bytes are checked against its size before its buffer is allocated: a damaged .zarray's chunks
    // of gigabytes are refused by their small files, not allocated first.
    if (!blosc) {
      if (raw.size() != nbytes) throw Error(error("chunk " + grid.key(c) + " holds " + std::to_string(raw.size()) + " bytes, not " + std::to_string(nbytes)));
      return std::make_shared<std::vector<char>>(std::move(raw));
    }
    size_t decoded = 0;
    const auto not_blosc = [&] { return Error(error("chunk " + grid.key(c) + " is not a Blosc buffer of " + std::to_string(nbytes) + " bytes")); };
    if (blosc_cbuffer_validate(raw.data(), raw.size(), &decoded) != 0 || decoded != nbytes) throw not_blosc();
    auto out = std::make_shared<std::vector<char>>(nbytes);
    if (blosc_decompress_ctx(raw.data(), out->data(), nbytes, 1) != int(nbytes)) throw not_blosc();
    return out;
  }

  Chunk get(int64_t c) const {
    {
      std::lock_guard<std::mutex> lock(mutex);
      for (auto it = cache.begin(); it != cache.end(); ++it)
        if (it->first == c) {
          cache.splice(cache.begin(), cache, it);
          return cache.front().second;
        }
    }
    Chunk chunk = load(c);  // outside the lock: other threads read other chunks meanwhile
    std::lock_guard<std::mutex> lock(mutex);
    cache.emplace_front(c, chunk);
    while (cache.size() > capacity) cache.pop_back();
    return chunk;
  }
};

ZarrReader::ZarrReader(const std::string& path, size_t cache_chunks, MissingChunks missing) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.path = path, m.capacity = std::max<size_t>(1, cache_chunks);
  m.every_chunk = missing == MissingChunks::Error;
  if (!fs::exists(path + "/.zarray")) throw Error(m.error("no .zarray in it"));
  detail::require_regular_file(path + "/.zarray");
  std::ifstream in(path + "/.zarray", std::ios::binary);
  if (!in) throw Error(m.error("no .zarray in it"));
  std::ostringstream text;
  text << in.rdbuf();
  if (text.str().size() > (size_t(1) << 20)) throw Error(m.error(".zarray is larger than 1 MiB"));
  const json z = json::parse(text.str(), nullptr, /*allow_exceptions=*/false);
  if (!z.is_object()) throw Error(m.error(".zarray is not a JSON object"));
  const auto get = [&](const char* key) -> const json& {
    if (!z.contains(key)) throw Error(m.error(".zarray has no '" + std::string(key) + "'"));
    return z.at(key);
  };
  if (get("zarr_format") != 2) throw Error(m.error("zarr_format is not 2"));
  if (get("order") != "C") throw Error(m.error("only C order is supported"));
  if (z.contains("filters") && !z.at("filters").is_null() && !(z.at("filters").is_array() && z.at("filters").empty()))
    throw Error(m.error("filters are not supported"));
  if (z.contains("dimension_separator") && z.at("dimension_separator") != ".")
    throw Error(m.error("only the '.' dimension separator is supported"));
  const json& d = get("dtype");
  bool known = false;
  for (Dtype t : {Dtype::F32, Dtype::U8, Dtype::U16, Dtype::I32, Dtype::I64, Dtype::F64})
    if (d.is_string() && (d == numpy_descr(t) || (t == Dtype::U8 && d == "<u1"))) m.dtype = t, known = true;
  if (!known) throw Error(m.error("dtype " + d.dump() + " is not one spadgen writes (<f4, <f8, |u1, <u2, <i4, <i8)"));
  m.eb = element_bytes(m.dtype);
  const auto extents = [&](const char* key) {
    const json& a = get(key);
    std::vector<int64_t> v;
    if (!a.is_array()) throw Error(m.error(std::string(key) + " is not a list"));
    for (const json& e : a) {
      if (!e.is_number_integer()) throw Error(m.error(std::string(key) + " holds something other than integers"));
      v.push_back(e.get<int64_t>());
    }
    return v;
  };
  m.grid = Grid(extents("shape"), extents("chunks"), m.eb, "cannot read '" + path + "' as a Zarr array");
  const json& c = get("compressor");
  if (!c.is_null()) {
    if (!c.is_object() || c.value("id", "") != "blosc") throw Error(m.error("only the blosc compressor (or none) is supported"));
    m.blosc = true;
  }
  // The fill value as one element of the dtype (null: none).
  m.fill.assign(size_t(m.eb), 0);
  const json& f = get("fill_value");
  if (!f.is_null()) {
    // The Zarr v2 specification writes a float's non-finite fill value as "NaN", "Infinity" or "-Infinity".
    std::optional<double> named;
    if (f == "NaN") named = std::numeric_limits<double>::quiet_NaN();
    else if (f == "Infinity") named = std::numeric_limits<double>::infinity();
    else if (f == "-Infinity") named = -std::numeric_limits<double>::infinity();
    if (!f.is_number() && !(named && is_float(m.dtype)))
      throw Error(m.error("fill_value " + f.dump().substr(0, 40) +
                          (is_float(m.dtype) ? " is not a number, \"NaN\", \"Infinity\" or \"-Infinity\"" : " is not a number")));
    m.has_fill = true;
    // A value of the dtype: an integer dtype's an integer in its range, a float dtype's a number within its
    // range (a conversion out of range was undefined behaviour, or wrapped: -5 read as 251 in a |u1 store).
    const auto outside = [&](const char* what) {
      return Error(m.error("fill_value " + f.dump().substr(0, 40) + " is not " + what + " of dtype " + numpy_descr(m.dtype)));
    };
    const auto integer = [&](auto zero) {
      using T = decltype(zero);
      constexpr auto lo = int64_t(std::numeric_limits<T>::min());
      constexpr auto hi = uint64_t(std::numeric_limits<T>::max());
      if (f.is_number_unsigned()) {  // nlohmann's kind of every integer >= 0
        if (const auto v = f.get<uint64_t>(); v <= hi) return static_cast<T>(v);
      } else if (f.is_number_integer()) {
        if (const auto v = f.get<int64_t>(); v >= lo) return static_cast<T>(v);  // < 0 here, so <= hi
      }
      throw outside("an integer in the range");
    };
    const auto put = [&](auto v) { std::memcpy(m.fill.data(), &v, sizeof v); };
    switch (m.dtype) {
      case Dtype::F32: {
        const double v = named ? *named : f.get<double>();
        if (std::isfinite(v) && std::fabs(v) > double(std::numeric_limits<float>::max())) throw outside("a number in the range");
        put(static_cast<float>(v));
        break;
      }
      case Dtype::F64: put(named ? *named : f.get<double>()); break;
      case Dtype::U8: put(integer(uint8_t{0})); break;
      case Dtype::U16: put(integer(uint16_t{0})); break;
      case Dtype::I32: put(integer(int32_t{0})); break;
      case Dtype::I64: put(integer(int64_t{0})); break;
    }
  }
}

ZarrReader::~ZarrReader() = default;
ZarrReader::ZarrReader(ZarrReader&&) noexcept = default;
ZarrReader& ZarrReader::operator=(ZarrReader&&) noexcept = default;

const std::string& ZarrReader::path() const { return impl_->path; }
Dtype ZarrReader::dtype() const { return impl_->dtype; }
const std::vector<int64_t>& ZarrReader::shape() const { return impl_->grid.shape; }
const std::vector<int64_t>& ZarrReader::chunks() const { return impl_->grid.chunks; }
int64_t ZarrReader::elements() const { return impl_->grid.elements; }

void ZarrReader::read(int64_t offset, int64_t count, void* dest) const {
  const Impl& m = *impl_;
  if (offset < 0 || count < 0 || offset > m.grid.elements || count > m.grid.elements - offset)
    throw Error(m.error("elements [" + std::to_string(offset) + ", " + std::to_string(offset + count) + ") lie outside its " +
                        std::to_string(m.grid.elements)));
  auto* out = static_cast<char*>(dest);
  while (count > 0) {
    const Grid::Piece p = m.grid.piece(offset);
    const int64_t n = std::min(count, p.run);
    const Impl::Chunk chunk = m.get(p.chunk);
    std::memcpy(out, chunk->data() + p.at * m.eb, size_t(n * m.eb));
    offset += n, out += n * m.eb, count -= n;
  }
}

template <class T>
std::vector<T> ZarrReader::read_all() const {
  const Impl& m = *impl_;
  constexpr Dtype want = std::is_same_v<T, float>      ? Dtype::F32
                         : std::is_same_v<T, double>   ? Dtype::F64
                         : std::is_same_v<T, int32_t>  ? Dtype::I32
                         : std::is_same_v<T, int64_t>  ? Dtype::I64
                         : std::is_same_v<T, uint16_t> ? Dtype::U16
                                                       : Dtype::U8;
  if (m.dtype != want) throw Error(m.error(dtype_mismatch(m.dtype, want)));
  std::vector<T> out(size_t(m.grid.elements));
  const size_t rank = m.grid.rank(), last = rank - 1;
  // Chunk by chunk, each decompressed once; its rows (runs along the last dimension) copied into place.
  for (int64_t c = 0; c < m.grid.n_chunks; ++c) {
    const Impl::Chunk chunk = m.load(c);
    const auto g = m.grid.grid_index(c), e = m.grid.extent(c);
    std::array<int64_t, kMaxRank> i{};  // row index inside the chunk, dimensions 0 .. last - 1
    for (bool more = true; more;) {
      int64_t dst = 0, src = 0;
      for (size_t d = 0; d < rank; ++d) {
        const int64_t at = d == last ? 0 : i[d];
        dst = dst * m.grid.shape[d] + g[d] * m.grid.chunks[d] + at;
        src = src * m.grid.chunks[d] + at;
      }
      std::memcpy(out.data() + dst, chunk->data() + src * m.eb, size_t(e[last] * m.eb));
      more = false;
      for (size_t d = last; d-- > 0;) {
        if (++i[d] < e[d]) {
          more = true;
          break;
        }
        i[d] = 0;
      }
    }
  }
  return out;
}
template std::vector<float> ZarrReader::read_all<float>() const;
template std::vector<double> ZarrReader::read_all<double>() const;
template std::vector<int32_t> ZarrReader::read_all<int32_t>() const;
template std::vector<int64_t> ZarrReader::read_all<int64_t>() const;
template std::vector<uint8_t> ZarrReader::read_all<uint8_t>() const;
template std::vector<uint16_t> ZarrReader::read_all<uint16_t>() const;

}  // namespace spadgen::writers
