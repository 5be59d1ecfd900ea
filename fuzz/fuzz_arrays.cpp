// libFuzzer harness of the array readers: writers::NpyReader (a .npy file: the run's and the saved light's
// arrays, and the detections a user hands `spadgen evaluate`) and writers::ZarrReader (a Zarr v2 store: the
// same arrays with outputs.storage = zarr). Both parse headers of spadgen's own code (the .npy header's
// Python dict, the .zarray) and read what those headers promise from files that may be damaged or cut short.
//
// Input: byte 0 chooses the reader (even: .npy, odd: Zarr; bit 1 of a Zarr input: missing chunks read as the
// fill value instead of refused). A .npy input is the file's bytes. A Zarr input is a little-endian 16-bit
// length L, then L bytes of .zarray, then the bytes of the store's first chunk (key "0", "0.0", ... by the
// .zarray's rank); the other chunks are missing.
//
// Every input must end in a reader or a spadgen::Error. On a reader, its promises: the shape's product is its
// element count, every element it reports can be read (a .npy's data lie inside the file; a store's
// elements decode from their chunks or are refused with a spadgen::Error), and no allocation exceeds what
// the files can justify (libFuzzer's -rss_limit_mb: a stored chunk's buffer is allocated for the size its
// file holds; in the fill mode, chunks of more than 64 Mi elements are not read). Anything else, a crash or
// a sanitizer report, is a finding.
#include <nlohmann/json.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "fuzz_common.h"
#include "writers/writers.h"

namespace {

namespace fs = std::filesystem;
using spadgen::fuzz::broken;
using spadgen::writers::Dtype;

// A folder of this process's own, made once, emptied of the previous input's files before each input.
const fs::path& work_dir() {
  static const fs::path dir = [] {
    std::string t = (fs::temp_directory_path() / "spadgen_fuzz_arrays_XXXXXX").string();
    if (::mkdtemp(t.data()) == nullptr) {
      std::perror("mkdtemp");
      std::abort();
    }
    return fs::path(t);
  }();
  return dir;
}

void write_file(const fs::path& p, const uint8_t* data, size_t size) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  if (!out) broken("cannot write " + p.string());
}

int64_t product(const std::vector<int64_t>& shape) {
  int64_t n = 1;
  for (const int64_t d : shape) n *= d;  // the readers refuse shapes whose product overflows
  return n;
}

template <class T>
double sum(const T* v, int64_t n) {
  double s = 0.0;
  for (int64_t i = 0; i < n; ++i) s += static_cast<double>(v[i]);
  return s;
}

void npy(const uint8_t* data, size_t size) {
  const fs::path p = work_dir() / "a.npy";
  write_file(p, data, size);
  spadgen::writers::NpyReader r(p.string());
  if (product(r.shape()) != r.elements()) broken("a .npy whose shape's product is not its element count");
  // every element (the mapping ends with the file: reading past it is a crash)
  double s = 0.0;
  switch (r.dtype()) {
    case Dtype::F32: s = sum(r.data<float>(), r.elements()); break;
    case Dtype::F64: s = sum(r.data<double>(), r.elements()); break;
    case Dtype::I32: s = sum(r.data<int32_t>(), r.elements()); break;
    case Dtype::I64: s = sum(r.data<int64_t>(), r.elements()); break;
    case Dtype::U8: s = sum(r.data<uint8_t>(), r.elements()); break;
    case Dtype::U16: s = sum(r.data<uint16_t>(), r.elements()); break;
  }
  volatile double sink = s;
  (void)sink;
}

// The chunk key of chunk 0 for the .zarray's rank (1 when it has no readable shape).
std::string first_chunk_key(const std::string& zarray) {
  const auto z = nlohmann::json::parse(zarray, nullptr, /*allow_exceptions=*/false);
  size_t rank = 1;
  if (z.is_object() && z.contains("shape") && z["shape"].is_array() && !z["shape"].empty() && z["shape"].size() <= 16)
    rank = z["shape"].size();
  std::string key = "0";
  for (size_t i = 1; i < rank; ++i) key += ".0";
  return key;
}

template <class T>
void read_store(const spadgen::writers::ZarrReader& z) {
  const int64_t n = z.elements();
  if (n <= (int64_t{1} << 16)) {
    const std::vector<T> all = z.read_all<T>();
    if (static_cast<int64_t>(all.size()) != n) broken("read_all returned another element count than the shape's");
    return;
  }
  // a large array: its first and last elements, and a run across the first chunk's edge
  T v[64];
  z.read(0, 1, v);
  z.read(n - 1, 1, v);
  const int64_t c = z.chunks().back();
  if (c < n - 32) z.read(c - 32 < 0 ? 0 : c - 32, 64, v);
}

void zarr(const uint8_t* data, size_t size, bool fill) {
  size_t len = size >= 2 ? size_t(data[0]) | size_t(data[1]) << 8 : 0;
  data += size >= 2 ? 2 : size;
  size -= size >= 2 ? 2 : size;
  if (len > size) len = size;
  const std::string zarray(reinterpret_cast<const char*>(data), len);
  const fs::path store = work_dir() / "a.zarr";
  fs::remove_all(store);
  fs::create_directories(store);
  write_file(store / ".zarray", data, len);
  write_file(store / first_chunk_key(zarray), data + len, size - len);
  const spadgen::writers::ZarrReader z(store.string(), 2,
                                       fill ? spadgen::writers::MissingChunks::Fill : spadgen::writers::MissingChunks::Error);
  if (product(z.shape()) != z.elements()) broken("a Zarr store whose shape's product is not its element count");
  if (z.chunks().size() != z.shape().size()) broken("a Zarr store whose chunks and shape differ in rank");
  // A missing chunk read as the fill value is a whole chunk of it: a header's chunks of up to 2 GiB justify
  // that. Stored chunks are read whatever their size: their files must justify their buffers.
  if (fill && product(z.chunks()) > (int64_t{64} << 20)) return;
  switch (z.dtype()) {
    case Dtype::F32: read_store<float>(z); break;
    case Dtype::F64: read_store<double>(z); break;
    case Dtype::I32: read_store<int32_t>(z); break;
    case Dtype::I64: read_store<int64_t>(z); break;
    case Dtype::U8: read_store<uint8_t>(z); break;
    case Dtype::U16: read_store<uint16_t>(z); break;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  try {
    if (data[0] % 2 == 0)
      npy(data + 1, size - 1);
    else
      zarr(data + 1, size - 1, (data[0] & 2) != 0);
  } catch (const spadgen::Error& e) {
    spadgen::fuzz::refused(e);
  }
  return 0;
}
