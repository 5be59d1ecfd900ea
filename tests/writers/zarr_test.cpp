// writers::ZarrWriter and ZarrReader: every chunk decompressed with Blosc directly (independently of the
// reader) against the array cut into full-size chunks, the metadata, the order the parts arrive in, what a
// store is before and after commit, and what the reader refuses. zarr-python reads the same stores in
// tests/python/test_zarr.py.
#include <blosc.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <thread>

#include "core/error.h"
#include "core/tile.h"
#include "test_util.h"
#include "writers/writers.h"

namespace spadgen::writers {
namespace {

using test::read_bytes;
using test::TempDir;
namespace fs = std::filesystem;

template <class T>
std::vector<T> ramp(int64_t n) {
  std::vector<T> v(static_cast<size_t>(n));
  for (int64_t i = 0; i < n; ++i) v[size_t(i)] = T(i % 7 == 0 ? 0 : (i * 37) % 251);
  return v;
}

// The chunk with grid indices g of a C-order array, full size, padded with zeros, as the store must hold it.
template <class T>
std::vector<T> expected_chunk(const std::vector<T>& a, const std::vector<int64_t>& shape, const std::vector<int64_t>& chunks,
                              const std::vector<int64_t>& g) {
  int64_t n = 1;
  for (int64_t c : chunks) n *= c;
  std::vector<T> out(static_cast<size_t>(n), T(0));
  std::vector<int64_t> i(chunks.size(), 0);
  for (int64_t e = 0; e < n; ++e) {
    int64_t rem = e, flat = 0;
    bool inside = true;
    for (size_t d = chunks.size(); d-- > 0;) i[d] = rem % chunks[d], rem /= chunks[d];
    for (size_t d = 0; d < chunks.size(); ++d) {
      const int64_t at = g[d] * chunks[d] + i[d];
      inside = inside && at < shape[d];
      flat = flat * shape[d] + at;
    }
    if (inside) out[size_t(e)] = a[size_t(flat)];
  }
  return out;
}

template <class T>
std::vector<T> decompress(const std::string& file, size_t elements) {
  const std::string bytes = read_bytes(file);
  size_t nbytes = 0, cbytes = 0, blocksize = 0;
  blosc_cbuffer_sizes(bytes.data(), &nbytes, &cbytes, &blocksize);
  EXPECT_EQ(cbytes, bytes.size()) << file;
  EXPECT_EQ(nbytes, elements * sizeof(T)) << file;
  std::vector<T> out(elements);
  EXPECT_EQ(blosc_decompress_ctx(bytes.data(), out.data(), nbytes, 1), int(nbytes)) << file;
  return out;
}

template <class T>
void expect_chunks(const std::string& store, const std::vector<T>& a, const std::vector<int64_t>& shape,
                   const std::vector<int64_t>& chunks) {
  std::vector<int64_t> grid;
  int64_t n_chunks = 1, chunk_elements = 1;
  for (size_t d = 0; d < shape.size(); ++d) {
    grid.push_back((shape[d] + chunks[d] - 1) / chunks[d]);
    n_chunks *= grid.back(), chunk_elements *= chunks[d];
  }
  for (int64_t c = 0; c < n_chunks; ++c) {
    std::vector<int64_t> g(shape.size());
    int64_t rem = c;
    for (size_t d = shape.size(); d-- > 0;) g[d] = rem % grid[d], rem /= grid[d];
    std::string key;
    for (size_t d = 0; d < g.size(); ++d) {
      if (d) key += '.';
      key += std::to_string(g[d]);
    }
    ASSERT_TRUE(fs::is_regular_file(store + "/" + key)) << key;
    EXPECT_EQ(decompress<T>(store + "/" + key, size_t(chunk_elements)), expected_chunk(a, shape, chunks, g)) << key;
  }
}

TEST(ZarrWriter, ChunksDecompressWithBloscToTheArrayCutIntoChunks) {
  TempDir dir;
  const std::vector<int64_t> shape{5, 45, 70}, chunks{5, 32, 64};
  const std::vector<float> a = ramp<float>(5 * 45 * 70);
  {
    ZarrWriter w(dir.file("rate.zarr"), Dtype::F32, shape, chunks, {{"units", "avalanches per frame"}});
    w.write(0, a.data(), int64_t(a.size()));
    w.commit();
    EXPECT_GT(w.stored_bytes(), 0);
  }
  expect_chunks(dir.file("rate.zarr"), a, shape, chunks);
  const auto zarray = nlohmann::json::parse(read_bytes(dir.file("rate.zarr/.zarray")));
  EXPECT_EQ(zarray["zarr_format"], 2);
  EXPECT_EQ(zarray["shape"], nlohmann::json({5, 45, 70}));
  EXPECT_EQ(zarray["chunks"], nlohmann::json({5, 32, 64}));
  EXPECT_EQ(zarray["dtype"], "<f4");
  EXPECT_EQ(zarray["order"], "C");
  EXPECT_EQ(zarray["fill_value"], "NaN");  // a float store: NaN stands for a chunk lost after the run
  EXPECT_TRUE(zarray["filters"].is_null());
  EXPECT_EQ(zarray["compressor"], nlohmann::json({{"id", "blosc"}, {"cname", "zstd"}, {"clevel", 1}, {"shuffle", 1},
                                                  {"blocksize", 8 << 20}}));
  EXPECT_EQ(nlohmann::json::parse(read_bytes(dir.file("rate.zarr/.zattrs"))), nlohmann::json({{"units", "avalanches per frame"}}));
  // Only the store: its temporary folder is gone.
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"rate.zarr"});
}

TEST(ZarrWriter, ChunksLargerThanTheArrayAreClippedToIt) {
  TempDir dir;
  const std::vector<uint16_t> a = ramp<uint16_t>(2 * 3 * 4);
  ZarrWriter w(dir.file("c.zarr"), Dtype::U16, {2, 3, 4}, {351, 32, 64});
  EXPECT_TRUE(w.zarray()["fill_value"].is_null());  // integers: every value can be a sample's, so none
  EXPECT_EQ(w.chunks(), (std::vector<int64_t>{2, 3, 4}));
  w.write(0, a.data(), 24);
  w.commit();
  expect_chunks(dir.file("c.zarr"), a, {2, 3, 4}, {2, 3, 4});
  EXPECT_EQ(ZarrWriter::codec(Dtype::U16).shuffle, BLOSC_SHUFFLE);
  EXPECT_EQ(ZarrWriter::codec(Dtype::U8).shuffle, BLOSC_NOSHUFFLE);
}

// Tiles from several threads in any order give the same bytes as one write of the whole array: a chunk's
// bytes depend on its data only.
TEST(ZarrWriter, TilesInAnyOrderFromThreadsGiveTheSameBytes) {
  TempDir dir;
  const int64_t K = 9;
  const int H = 70, W = 100;
  const std::vector<uint8_t> a = ramp<uint8_t>(K * H * W);
  {
    ZarrWriter whole(dir.file("whole.zarr"), Dtype::U8, {K, H, W}, {K, 32, 64});
    whole.write(0, a.data(), int64_t(a.size()));
    whole.commit();
  }
  for (int tile : {8, 24, 48}) {
    const std::string name = "tiles" + std::to_string(tile) + ".zarr";
    ZarrWriter w(dir.file(name), Dtype::U8, {K, H, W}, {K, 32, 64});
    std::vector<PixelRect> tiles = make_tiles(W, H, tile);
    std::shuffle(tiles.begin(), tiles.end(), std::mt19937(unsigned(tile)));
    std::vector<std::thread> threads;
    for (size_t t0 = 0; t0 < 3; ++t0)
      threads.emplace_back([&, t0] {
        for (size_t t = t0; t < tiles.size(); t += 3) {
          const PixelRect& r = tiles[t];
          std::vector<uint8_t> data(size_t(K * r.count()));
          for (int64_t k = 0; k < K; ++k)
            for (int y = r.y0; y < r.y1(); ++y)
              for (int x = r.x0; x < r.x1(); ++x) data[size_t(k * r.count() + r.index(x, y))] = a[size_t((k * H + y) * W + x)];
          w.write_khw(r, 0, 0, data.data());
        }
      });
    for (auto& t : threads) t.join();
    w.commit();
    for (const auto& e : fs::directory_iterator(dir.file("whole.zarr")))
      EXPECT_EQ(read_bytes(e.path().string()), read_bytes(dir.file(name) + "/" + e.path().filename().string()))
          << name << " " << e.path().filename();
  }
}

TEST(ZarrReader, ReadsEveryDtypeBackWholeAndInParts) {
  TempDir dir;
  const std::vector<int64_t> shape{3, 50, 33}, chunks{2, 16, 32};
  const auto round_trip = [&](auto zero, Dtype dtype) {
    using T = decltype(zero);
    const std::vector<T> a = ramp<T>(3 * 50 * 33);
    const std::string path = dir.file(std::string(numpy_descr(dtype)).substr(1) + ".zarr");
    ZarrWriter w(path, dtype, shape, chunks);
    w.write(0, a.data(), int64_t(a.size()));
    w.commit();
    const ZarrReader r(path, 2);
    EXPECT_EQ(r.dtype(), dtype);
    EXPECT_EQ(r.shape(), shape);
    EXPECT_EQ(r.chunks(), chunks);
    EXPECT_EQ(r.read_all<T>(), a) << numpy_descr(dtype);
    // Runs across chunk boundaries, from two threads sharing the cache of 2 chunks.
    const auto part = [&](int64_t from) {
      for (int64_t at = from; at < int64_t(a.size()); at += 1000) {
        const int64_t n = std::min<int64_t>(777, int64_t(a.size()) - at);
        std::vector<T> got(static_cast<size_t>(n));
        r.read(at, n, got.data());
        ASSERT_TRUE(std::equal(got.begin(), got.end(), a.begin() + at)) << numpy_descr(dtype) << " at " << at;
      }
    };
    std::thread other(part, 500);
    part(0);
    other.join();
  };
  round_trip(uint8_t(0), Dtype::U8);
  round_trip(uint16_t(0), Dtype::U16);
  round_trip(float(0), Dtype::F32);
  round_trip(double(0), Dtype::F64);
  round_trip(int32_t(0), Dtype::I32);
  round_trip(int64_t(0), Dtype::I64);
}

// As in a .npy, what is never written is 0: at commit a partly written chunk is stored with zeros, and so
// is a chunk never touched (every chunk is stored: .zarray's fill value NaN only stands for a lost one).
TEST(ZarrWriter, UnwrittenElementsAreZero) {
  TempDir dir;
  const float v[3] = {1.5f, 2.5f, 3.5f};
  {
    ZarrWriter w(dir.file("p.zarr"), Dtype::F32, {100}, {10});
    w.write(42, v, 3);
    w.commit();
  }
  std::vector<float> expected(100, 0.0f);
  std::copy(v, v + 3, expected.begin() + 42);
  for (int c = 0; c < 10; ++c) {
    ASSERT_TRUE(fs::is_regular_file(dir.file("p.zarr/" + std::to_string(c)))) << c;
    EXPECT_EQ(decompress<float>(dir.file("p.zarr/" + std::to_string(c)), 10),
              std::vector<float>(expected.begin() + 10 * c, expected.begin() + 10 * c + 10)) << c;
  }
  EXPECT_EQ(ZarrReader(dir.file("p.zarr")).read_all<float>(), expected);
  // A missing chunk of spadgen's store was lost: refused, naming the store and the chunk, although .zarray
  // has a fill value (it was read as zeros, and reconstruct scored a store without a quarter of its counts as
  // complete).
  fs::remove(dir.file("p.zarr/4"));
  const auto refused = [&](MissingChunks missing, const std::string& why) {
    try {
      (void)ZarrReader(dir.file("p.zarr"), 16, missing).read_all<float>();
      ADD_FAILURE() << "a missing chunk was read";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("p.zarr' as a Zarr array: chunk 4 is missing" + why), std::string::npos) << e.what();
    }
  };
  refused(MissingChunks::Error, ": spadgen stores every chunk");
  // Read as another program's store: the fill value throughout (NaN, as zarr-python reads it), a number
  // given as one, an error without one.
  std::vector<float> got = ZarrReader(dir.file("p.zarr"), 16, MissingChunks::Fill).read_all<float>();
  for (size_t i = 0; i < got.size(); ++i) {
    if (i >= 40 && i < 50)
      EXPECT_TRUE(std::isnan(got[i])) << i;
    else
      EXPECT_EQ(got[i], expected[i]) << i;
  }
  nlohmann::json zarray = nlohmann::json::parse(read_bytes(dir.file("p.zarr/.zarray")));
  const auto set_fill = [&](const nlohmann::json& f) {
    zarray["fill_value"] = f;
    std::ofstream(dir.file("p.zarr/.zarray"), std::ios::trunc) << zarray.dump();
  };
  set_fill("-Infinity");
  EXPECT_EQ(ZarrReader(dir.file("p.zarr"), 16, MissingChunks::Fill).read_all<float>()[45], -std::numeric_limits<float>::infinity());
  set_fill(0.5);
  std::fill(expected.begin() + 40, expected.begin() + 50, 0.5f);
  EXPECT_EQ(ZarrReader(dir.file("p.zarr"), 16, MissingChunks::Fill).read_all<float>(), expected);
  set_fill(nullptr);
  refused(MissingChunks::Fill, ", and the store has no fill value to stand for it");
  // Other strings are refused, naming the value and what was expected.
  set_fill("nan");
  try {
    (void)ZarrReader(dir.file("p.zarr"));
    ADD_FAILURE() << "fill_value \"nan\" was taken";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("fill_value \"nan\" is not a number, \"NaN\", \"Infinity\" or \"-Infinity\""), std::string::npos)
        << e.what();
  }
}

// A fill value is a value of the store's dtype: an integer dtype's an integer in its range, a float dtype's a
// number within its range. One outside was converted regardless: undefined behaviour for 1e300 in an int32
// store (found by fuzz_arrays), -5 read as 251 in a uint8 one.
TEST(ZarrReader, RefusesAFillValueOutsideItsDtype) {
  TempDir dir;
  const auto store = [&](Dtype dtype, const nlohmann::json& fill) {
    fs::remove_all(dir.file("f.zarr"));
    {
      ZarrWriter w(dir.file("f.zarr"), dtype, {8}, {4});
      const std::vector<uint8_t> zeros(8 * 8, 0);
      w.write(0, zeros.data(), 4);  // chunk 0 written, chunk 1 missing
      w.commit();
    }
    fs::remove(dir.file("f.zarr/1"));
    nlohmann::json z = nlohmann::json::parse(read_bytes(dir.file("f.zarr/.zarray")));
    z["fill_value"] = fill;
    write_file_atomic(dir.file("f.zarr/.zarray"), z.dump());
    return dir.file("f.zarr");
  };
  const auto refused = [&](Dtype dtype, const nlohmann::json& fill, const std::string& why) {
    try {
      (void)ZarrReader(store(dtype, fill), 16, MissingChunks::Fill);
      ADD_FAILURE() << "fill_value " << fill.dump() << " was taken for " << numpy_descr(dtype);
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("fill_value " + fill.dump() + " is not " + why + " of dtype " + numpy_descr(dtype)),
                std::string::npos) << e.what();
    }
  };
  refused(Dtype::I32, 1e300, "an integer in the range");
  refused(Dtype::I32, 2147483648LL, "an integer in the range");
  refused(Dtype::I32, 1.5, "an integer in the range");
  refused(Dtype::U8, -5, "an integer in the range");
  refused(Dtype::U8, 256, "an integer in the range");
  refused(Dtype::U16, 65536, "an integer in the range");
  refused(Dtype::I64, 18446744073709551615ULL, "an integer in the range");
  refused(Dtype::F32, 1e39, "a number in the range");
  refused(Dtype::F32, -1e39, "a number in the range");
  // The ends of each range are values of it, read into the missing chunk.
  EXPECT_EQ(ZarrReader(store(Dtype::U8, 255), 16, MissingChunks::Fill).read_all<uint8_t>()[6], 255);
  EXPECT_EQ(ZarrReader(store(Dtype::U16, 0), 16, MissingChunks::Fill).read_all<uint16_t>()[6], 0);
  EXPECT_EQ(ZarrReader(store(Dtype::I32, -2147483648LL), 16, MissingChunks::Fill).read_all<int32_t>()[6],
            std::numeric_limits<int32_t>::min());
  EXPECT_EQ(ZarrReader(store(Dtype::I64, 9223372036854775807LL), 16, MissingChunks::Fill).read_all<int64_t>()[6],
            std::numeric_limits<int64_t>::max());
  EXPECT_EQ(ZarrReader(store(Dtype::F32, 3.4e38), 16, MissingChunks::Fill).read_all<float>()[6], 3.4e38f);
  EXPECT_EQ(ZarrReader(store(Dtype::F64, 1e300), 16, MissingChunks::Fill).read_all<double>()[6], 1e300);
}

TEST(ZarrWriter, WithoutCommitNothingIsLeftAndCommitReplacesAnEarlierStore) {
  TempDir dir;
  const std::vector<int32_t> a = ramp<int32_t>(40), b(40, 7);
  {
    ZarrWriter w(dir.file("s.zarr"), Dtype::I32, {40}, {16});
    w.write(0, a.data(), 40);
  }
  EXPECT_TRUE(dir.entries().empty());
  for (const auto* v : {&a, &b}) {
    ZarrWriter w(dir.file("s.zarr"), Dtype::I32, {40}, {16});
    w.write(0, v->data(), 40);
    w.commit();
    EXPECT_EQ(ZarrReader(dir.file("s.zarr")).read_all<int32_t>(), *v);
  }
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"s.zarr"});
}

TEST(ZarrWriter, RefusesWritesOutsideTwiceAndAfterCommit) {
  TempDir dir;
  const uint8_t v[8] = {1, 2, 3, 4, 5, 6, 7, 8};
  ZarrWriter w(dir.file("e.zarr"), Dtype::U8, {2, 4}, {2, 4});
  EXPECT_THROW(w.write(6, v, 3), Error);
  EXPECT_THROW(w.write(-1, v, 1), Error);
  w.write(0, v, 4);
  EXPECT_THROW(w.write(2, v, 6), Error);  // 2 and 3 a second time: more elements than the chunk holds
  ZarrWriter x(dir.file("x.zarr"), Dtype::U8, {2, 4}, {2, 4});
  x.write(0, v, 8);
  EXPECT_THROW(x.write(3, v, 1), Error);  // into a chunk already stored
  w.commit();
  EXPECT_THROW(w.write(0, v, 1), Error);
  EXPECT_THROW(w.commit(), Error);
  EXPECT_THROW(ZarrWriter(dir.file("bad.zarr"), Dtype::U8, {2, 4}, {2}), Error);
  EXPECT_THROW(ZarrWriter(dir.file("bad.zarr"), Dtype::U8, {2, 4}, {0, 4}), Error);
}

TEST(ZarrReader, RefusesWhatItCannotReadNamingTheStore) {
  TempDir dir;
  const std::vector<float> a = ramp<float>(64);
  {
    ZarrWriter w(dir.file("a.zarr"), Dtype::F32, {64}, {16});
    w.write(0, a.data(), 64);
    w.commit();
  }
  const auto expect_error = [&](const std::string& what) {
    try {
      ZarrReader(dir.file("a.zarr")).read_all<float>();
      ADD_FAILURE() << "no error for " << what;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(dir.file("a.zarr")), std::string::npos) << e.what();
    }
  };
  const std::string zarray = read_bytes(dir.file("a.zarr/.zarray")), chunk = read_bytes(dir.file("a.zarr/1"));
  write_file_atomic(dir.file("a.zarr/1"), chunk.substr(0, chunk.size() / 2));
  expect_error("a truncated chunk");
  write_file_atomic(dir.file("a.zarr/1"), chunk);
  auto z = nlohmann::json::parse(zarray);
  z["order"] = "F";
  write_file_atomic(dir.file("a.zarr/.zarray"), z.dump());
  expect_error("Fortran order");
  z = nlohmann::json::parse(zarray);
  z["compressor"] = {{"id", "gzip"}};
  write_file_atomic(dir.file("a.zarr/.zarray"), z.dump());
  expect_error("gzip");
  write_file_atomic(dir.file("a.zarr/.zarray"), "{");
  expect_error("broken JSON");
  // A .zarray damaged to chunks of 2 GB over the same files: each chunk is refused by its file's size before
  // its buffer is allocated (it was allocated, and zeroed, first: found by fuzz_arrays under its 2 GB limit).
  for (const nlohmann::json& compressor : {nlohmann::json(nullptr), nlohmann::json::parse(zarray)["compressor"]}) {
    z = nlohmann::json::parse(zarray);
    z["chunks"] = {500000000};
    if (compressor.is_null()) z["compressor"] = nullptr;
    write_file_atomic(dir.file("a.zarr/.zarray"), z.dump());
    try {
      (void)ZarrReader(dir.file("a.zarr")).read_all<float>();
      ADD_FAILURE() << "chunks of 2 GB were read from a chunk of " << read_bytes(dir.file("a.zarr/0")).size() << " bytes";
    } catch (const Error& e) {
      const std::string why = compressor.is_null() ? " bytes, not 2000000000" : "is not a Blosc buffer of 2000000000 bytes";
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(ZarrReader(dir.file("nothing.zarr")), Error);
  // The wrong dtype asked for.
  write_file_atomic(dir.file("a.zarr/.zarray"), zarray);
  EXPECT_THROW(ZarrReader(dir.file("a.zarr")).read_all<double>(), Error);
}

}  // namespace
}  // namespace spadgen::writers
