// Output files. Every file appears complete or not at all: it is written under a temporary name in the
// output folder and renamed into place by commit(); a writer destroyed without commit() removes its
// temporary file. The app commits every writer only after the whole run succeeded.
#pragma once
#include <nlohmann/json.hpp>

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/config.h"
#include "core/tile.h"

namespace spadgen::writers {

// The element types of the stacks, spelled in files as NumPy's descr ("<f4", "|u1", "<u2", "<i4", "<i8", "<f8").
enum class Dtype { F32, U8, U16, I32, I64, F64 };
int64_t element_bytes(Dtype dtype);
const char* numpy_descr(Dtype dtype);
// "its dtype is <f8, expected <f4 (NumPy's descr: ...)": a reader's message for a stack of another type.
std::string dtype_mismatch(Dtype found, Dtype expected);

// A C-order array written in parts from several threads at once (each element once), completed by
// commit(): a .npy file (NpyWriter) or a Zarr store (ZarrWriter). The app streams its tiles through this.
class StackWriter {
 public:
  virtual ~StackWriter() = default;
  // Writes `count` elements (raw bytes of this stack's dtype) starting at flat element index `offset`.
  virtual void write(int64_t offset, const void* data, int64_t count) = 0;
  // For a (K, H, W) stack: writes tile values [k * rect.count() + rect.index(x, y)] where the stack's
  // pixel (x, y) is (x - origin_x, y - origin_y). (Row by row through write(), unless overridden.)
  virtual void write_khw(const PixelRect& rect, int origin_x, int origin_y, const void* data);
  // For an (H, W, T) stack (transients): writes the pixels of `rect`, whose T values each lie in `data`
  // at [data_rect.index(x, y) * T + t] (data_rect contains rect: a TransientTile's halo is skipped).
  virtual void write_hwt(const PixelRect& rect, const PixelRect& data_rect, int origin_x, int origin_y, const void* data);
  // A hint that rows [row_begin, row_end) along `axis` are complete (NpyWriter: their pages leave the
  // resident set). A ZarrWriter needs no hint: a chunk leaves memory when its last element is written.
  virtual void release_rows(int axis, int64_t row_begin, int64_t row_end) {
    (void)axis, (void)row_begin, (void)row_end;
  }
  // Makes the stack durable under path(). Writes after commit() throw.
  virtual void commit() = 0;
  virtual const std::string& path() const = 0;
  virtual Dtype dtype() const = 0;
  virtual const std::vector<int64_t>& shape() const = 0;
};

// A .npy file (format 1.0, C order) whose shape is known up front; blocks are written at any offset
// from any thread (pwrite), so tiles stream straight to disk and memory stays bounded.
class NpyWriter : public StackWriter {
 public:
  using Dtype = writers::Dtype;
  // mapped: the file is mapped for writing, so that short runs (a tile's row) are a memcpy each; else
  // every write() is one pwrite, for a caller that writes long runs (whole bands of rows).
  NpyWriter(const std::string& path, Dtype dtype, std::vector<int64_t> shape, bool mapped = true);
  ~NpyWriter() override;
  NpyWriter(const NpyWriter&) = delete;
  NpyWriter& operator=(const NpyWriter&) = delete;

  void write(int64_t offset, const void* data, int64_t count) override;
  // For a (K, N, H, ceil(W / 8)) uint8 stack of bit-packed frames: writes a SensorTile's frames
  // [((k * N + n) * rect.height + row) * bytes_per_row + byte], bytes_per_row = ceil(rect.width / 8).
  // The tile's bytes land at byte column (rect.x0 - origin_x) / 8, so that must be a multiple of 8, and
  // only the tile at the right edge of the stack may have a width that is not a multiple of 8 (the
  // bits of its last byte beyond rect.width are written as 0).
  void write_frames(const PixelRect& rect, int origin_x, int origin_y, const void* data);
  // One tile's frames for write_frames_band, laid out as write_frames reads them.
  struct FramesTile {
    PixelRect rect;
    const uint8_t* frames = nullptr;
  };
  // The frames of gate positions [k_begin, k_end) of a band of tiles: tiles of one row of tiles (the same
  // y0 and height) that together cover the stack's width, each as write_frames takes it. Each gate
  // position's rows are gathered into a buffer of at most kFramesBuffer bytes, row by row of whole stack
  // width, and written in as few writes as the file allows: one per buffer when the band spans the
  // stack's height (its planes are then contiguous in the file), else one per plane. So the file
  // receives whole rows in order instead of a tile's 4-byte rows scattered over every page of the band
  // (write_frames). Calls for disjoint ranges of gate positions may run at once.
  static constexpr int64_t kFramesBuffer = int64_t(256) << 10;
  void write_frames_band(const std::vector<FramesTile>& tiles, int origin_x, int origin_y, int64_t k_begin, int64_t k_end);
  // Rows [row_begin, row_end) along `axis` (H: 1 for (K, H, W), 2 for (K, N, H, W/8), 0 for (H, W, T))
  // are complete: their pages leave this process's resident set, and the page cache starts writing them
  // to the file without waiting (writing there again only costs a page fault). Keeps a run's resident
  // memory bounded by the rows in flight although the whole file is mapped for writing, and leaves
  // commit()'s fsync little to flush.
  void release_rows(int axis, int64_t row_begin, int64_t row_end) override;
  // fsync, rename onto path(). Writes after commit() throw.
  void commit() override;
  const std::string& path() const override;
  Dtype dtype() const override;
  const std::vector<int64_t>& shape() const override;
  // Bytes before the first element (a multiple of 64) and the total file size.
  int64_t header_bytes() const;
  int64_t file_bytes() const;
  static int64_t element_bytes(Dtype dtype) { return writers::element_bytes(dtype); }
  // The complete header ("\x93NUMPY", version 1.0, length, dict, padding) for a C-order array.
  static std::string header(Dtype dtype, const std::vector<int64_t>& shape);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The compressor of every chunk of a Zarr store: Blosc with zstd at clevel, the given shuffle
// (0 none, 1 byte, 2 bit) and blocksize (bytes), one thread, so that the bytes depend on the data only.
struct ZarrCodec {
  int clevel = 1;
  int shuffle = 1;
  int64_t blocksize = 0;
};

// A Zarr v2 array store: the folder `path` (e.g. "counts.zarr") holding .zarray, .zattrs and one file
// per chunk named by its grid indices joined by '.' ("0.3.1"), each chunk C-order, full size (edge
// chunks padded with 0) and compressed by Blosc (ZarrCodec); every chunk is stored, and .zarray's fill
// value ("NaN" for float dtypes, none for integers) stands only for a chunk lost afterwards, so that a plain
// Zarr reader reads a lost float chunk as NaN. Writes land in chunk
// buffers; a chunk is compressed and written by the thread that writes its last element, and then leaves
// memory, so memory is bounded by the chunks being filled, not by the array. The store is built in a
// hidden folder beside `path` and renamed onto it by commit() (files fsynced first); a writer destroyed
// without commit() removes it. Elements never written are 0, as in a .npy.
class ZarrWriter : public StackWriter {
 public:
  // chunks: one extent per dimension (each at least 1), clipped to the shape. attributes: .zattrs.
  ZarrWriter(const std::string& path, Dtype dtype, std::vector<int64_t> shape, std::vector<int64_t> chunks,
             const nlohmann::json& attributes = nlohmann::json::object());
  ~ZarrWriter() override;
  ZarrWriter(const ZarrWriter&) = delete;
  ZarrWriter& operator=(const ZarrWriter&) = delete;

  void write(int64_t offset, const void* data, int64_t count) override;
  // A tile chunk by chunk (one count per chunk, not per row).
  void write_khw(const PixelRect& rect, int origin_x, int origin_y, const void* data) override;
  void write_hwt(const PixelRect& rect, const PixelRect& data_rect, int origin_x, int origin_y, const void* data) override;
  // Compresses the chunks not yet stored (their missing elements are 0), writes .zarray and .zattrs,
  // fsyncs every file and renames the store onto path().
  void commit() override;
  const std::string& path() const override;
  Dtype dtype() const override;
  const std::vector<int64_t>& shape() const override;
  const std::vector<int64_t>& chunks() const;  // as clipped to the shape
  // The content of .zarray.
  nlohmann::json zarray() const;
  // Compressed bytes of the chunks stored so far.
  int64_t stored_bytes() const;
  // The codec for a dtype (measured on the multi-object scene; docs/outputs.md, "Storage").
  static ZarrCodec codec(Dtype dtype);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// A Zarr v2 array as ZarrWriter writes it (C order, '.' separated chunk keys, Blosc or no compressor, no
// filters), read chunk by chunk. Throws spadgen::Error naming the store when it is not such an array or
// a chunk does not decompress to its size. A missing chunk is an error (MissingChunks::Error: spadgen's
// stores, whose every chunk is stored), or reads as the fill value (MissingChunks::Fill: another program's
// store; an error when it has none).
enum class MissingChunks { Error, Fill };
class ZarrReader {
 public:
  // cache_chunks: decompressed chunks kept for read() (least recently used ones go first).
  explicit ZarrReader(const std::string& path, size_t cache_chunks = 16, MissingChunks missing = MissingChunks::Error);
  ~ZarrReader();
  ZarrReader(ZarrReader&&) noexcept;
  ZarrReader& operator=(ZarrReader&&) noexcept;

  const std::string& path() const;
  Dtype dtype() const;
  const std::vector<int64_t>& shape() const;
  const std::vector<int64_t>& chunks() const;
  int64_t elements() const;
  // Copies `count` elements from flat C-order index `offset` into dest; safe from several threads.
  void read(int64_t offset, int64_t count, void* dest) const;
  // The whole array, checked against dtype as NpyReader::data<T>() is.
  template <class T>
  std::vector<T> read_all() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// A .npy file (format 1.0 or 2.0, C order, little-endian or byte-sized dtype) mapped read-only: nothing is
// read until it is indexed. Throws spadgen::Error naming the file when it is not such a file, or, from
// data<T>(), when its dtype is not the one asked for.
class NpyReader {
 public:
  explicit NpyReader(const std::string& path);
  ~NpyReader();
  NpyReader(NpyReader&&) noexcept;
  NpyReader& operator=(NpyReader&&) noexcept;

  const std::string& path() const { return path_; }
  Dtype dtype() const { return dtype_; }
  const std::vector<int64_t>& shape() const { return shape_; }
  int64_t elements() const { return elements_; }
  // The elements, checked against dtype (float: F32, double: F64, int32_t: I32, int64_t: I64, uint8_t: U8,
  // uint16_t: U16).
  template <class T>
  const T* data() const;
  // Throws unless the shape is `expected` (named `what` in the message).
  void expect_shape(const std::vector<int64_t>& expected, const std::string& what) const;

 private:
  std::string path_;
  Dtype dtype_ = Dtype::U8;
  std::vector<int64_t> shape_;
  int64_t elements_ = 0;
  const char* map_ = nullptr;
  size_t map_bytes_ = 0;
  int64_t data_offset_ = 0;
};

// A scanline OpenEXR image with named float channels and string attributes (provenance) in its header.
class ExrImage {
 public:
  ExrImage(int width, int height);
  float* channel(const std::string& name);  // created zero-filled on first use; row-major
  void remove_channel(const std::string& name);  // no-op when absent
  void set_attribute(const std::string& key, const std::string& value);
  // Writes the image to path atomically, with a lossless compression.
  void write(const std::string& path, ExrCompression compression = ExrCompression::Zip) const;
  int width() const { return width_; }
  int height() const { return height_; }

 private:
  int width_, height_;
  std::map<std::string, LargeBuffer<float>> channels_;  // large images in huge pages (core/tile.h)
  std::map<std::string, std::string> attributes_;
};

// Reads every channel of an EXR as float (HALF and UINT are converted) and its string attributes (for
// tests and for user-supplied maps). A data window that does not start at (0, 0) is read as if it did.
// Throws spadgen::Error naming the file.
struct ExrData {
  int width = 0, height = 0;  // of the data window, whose pixels the channels hold
  // Empty when the data window is the display window (the whole image); otherwise both, as text, for the
  // readers that take an image's pixels at their positions (detections, gate maps).
  std::string partial_window;
  std::map<std::string, std::vector<float>> channels;
  std::map<std::string, std::string> attributes;
};
ExrData read_exr(const std::string& path);
// OpenEXR compresses (and decompresses) an image's blocks of scanlines on its own pool of `threads` worker
// threads (0: all on the calling thread); the files are the same bytes whatever the count. The app sets
// it once to its own thread count, before it reads or writes an image, never while one is in use.
void set_exr_threads(int threads);

// 8-bit PNG (gray, RGB or RGBA), written atomically.
// `pixels` is row-major, top row first, `channels` bytes per pixel (1 gray, 3 RGB, 4 RGBA).
void write_png(const std::string& path, int width, int height, int channels, const std::vector<uint8_t>& pixels);
// JSON, pretty-printed, written atomically.
void write_json(const std::string& path, const nlohmann::json& value);
// Any bytes, written atomically (temporary file, fsync, rename).
void write_file_atomic(const std::string& path, const std::string& bytes);

// Removes the temporary files of `names` in `folder` (".<name>.tmp-<pid>-<n>", as the writers make them) that a
// process killed while it wrote left behind: those of a pid no longer running (not this one's). For a command
// that holds the folder (its lock) before it writes those files there. Returns how many it removed.
int remove_dead_temporaries(const std::string& folder, const std::vector<std::string>& names);

// A file written in pieces and published whole, as write_file_atomic does, by commit(); removed when never
// committed. For files too large to hold in memory first (a dataset's index of millions of samples).
class AtomicWriter {
 public:
  explicit AtomicWriter(const std::string& path);
  ~AtomicWriter();
  AtomicWriter(const AtomicWriter&) = delete;
  AtomicWriter& operator=(const AtomicWriter&) = delete;
  void append(const std::string& bytes);  // buffered: written a megabyte at a time
  void commit();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The bytes of a written output: a file's size, or a folder's (a Zarr store) as the sum of the regular
// files in it; -1 when the path does not exist. metadata.json records them (file_bytes), so that a file
// cut short or removed after the run is told apart from the one it wrote.
int64_t bytes_on_disk(const std::string& path);

}  // namespace spadgen::writers
