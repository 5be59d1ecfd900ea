#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

#include "core/error.h"
#include "core/mapped_files.h"
#include "core/tile.h"
#include "test_util.h"
#include "writers/writers.h"

namespace spadgen::writers {
namespace {

using test::read_bytes;
using test::TempDir;
using Dtype = NpyWriter::Dtype;

struct ParsedHeader {
  int major = 0, minor = 0;
  size_t data_offset = 0;
  std::string dict;
};

// Parses the fixed part of an .npy header the way NumPy's format.read_magic / read_array_header_1_0 do.
ParsedHeader parse(const std::string& bytes) {
  ParsedHeader h;
  EXPECT_GE(bytes.size(), 10u);
  EXPECT_EQ(bytes.substr(0, 6), std::string("\x93NUMPY"));
  h.major = static_cast<unsigned char>(bytes[6]);
  h.minor = static_cast<unsigned char>(bytes[7]);
  const size_t len = static_cast<unsigned char>(bytes[8]) | (size_t(static_cast<unsigned char>(bytes[9])) << 8);
  h.data_offset = 10 + len;
  h.dict = bytes.substr(10, len);
  return h;
}

void expect_header(Dtype dtype, const std::vector<int64_t>& shape, const std::string& descr,
                   const std::string& shape_text) {
  const std::string bytes = NpyWriter::header(dtype, shape);
  const ParsedHeader h = parse(bytes);
  EXPECT_EQ(h.major, 1);
  EXPECT_EQ(h.minor, 0);
  EXPECT_EQ(h.data_offset, bytes.size());
  EXPECT_EQ(bytes.size() % 64, 0u);
  const std::string dict = "{'descr': '" + descr + "', 'fortran_order': False, 'shape': " + shape_text + ", }";
  ASSERT_GE(h.dict.size(), dict.size() + 1);
  EXPECT_EQ(h.dict.substr(0, dict.size()), dict);
  EXPECT_EQ(h.dict.back(), '\n');
  // Padding is spaces only, and no more than needed to reach the next multiple of 64.
  const std::string pad = h.dict.substr(dict.size(), h.dict.size() - dict.size() - 1);
  EXPECT_EQ(pad.find_first_not_of(' '), std::string::npos);
  EXPECT_LT(pad.size(), 64u);
}

TEST(NpyHeader, MatchesTheFormatSpecification) {
  expect_header(Dtype::F32, {2, 3, 4}, "<f4", "(2, 3, 4)");
  expect_header(Dtype::U8, {7}, "|u1", "(7,)");
  expect_header(Dtype::U16, {}, "<u2", "()");
  expect_header(Dtype::U16, {0, 5}, "<u2", "(0, 5)");
  expect_header(Dtype::U8, {4080, 255, 1000, 128}, "|u1", "(4080, 255, 1000, 128)");
  expect_header(Dtype::F32, {int64_t(1) << 40, 3}, "<f4", "(1099511627776, 3)");
}

TEST(NpyWriter, ValuesRoundTripAndFileHasExactSize) {
  TempDir dir;
  const std::string path = dir.file("a.npy");
  std::vector<float> v(24);
  for (size_t i = 0; i < v.size(); ++i) v[i] = 0.5f * float(i) - 3.0f;
  {
    NpyWriter w(path, Dtype::F32, {2, 3, 4});
    w.write(0, v.data(), 10);
    w.write(10, v.data() + 10, 14);
    EXPECT_EQ(w.file_bytes(), w.header_bytes() + 96);
    w.commit();
  }
  const std::string bytes = read_bytes(path);
  const ParsedHeader h = parse(bytes);
  ASSERT_EQ(bytes.size(), h.data_offset + 96);
  std::vector<float> back(24);
  std::memcpy(back.data(), bytes.data() + h.data_offset, 96);
  EXPECT_EQ(back, v);
}

TEST(NpyWriter, ZeroSizedDimensions) {
  TempDir dir;
  {
    NpyWriter w(dir.file("z.npy"), Dtype::U16, {0, 4, 5});
    w.write(0, nullptr, 0);
    w.write_khw(PixelRect{0, 0, 5, 4}, 0, 0, nullptr);
    w.commit();
  }
  const std::string bytes = read_bytes(dir.file("z.npy"));
  EXPECT_EQ(bytes.size(), parse(bytes).data_offset);
  EXPECT_NE(bytes.find("'shape': (0, 4, 5)"), std::string::npos);
}

// A file cut short by another process while it is read through its mapping (a cp over a run's counts.npy while
// spadgen reconstruct read it) ends the program with an error naming the file, exit 1; it was a SIGBUS, exit
// 135 without a word. A SIGBUS elsewhere stays a crash.
TEST(NpyReaderDeathTest, AFileCutShortWhileMappedIsAnErrorNamingIt) {
  TempDir dir;
  const std::string path = dir.file("cut.npy");
  {
    NpyWriter w(path, Dtype::F32, {1 << 16});
    std::vector<float> ones(1 << 16, 1.0f);
    w.write(0, ones.data(), int64_t(ones.size()));
    w.commit();
  }
  const auto read_after_cut = [&] {
    install_mapped_file_fault_handler();
    const NpyReader r(path);
    if (::truncate(path.c_str(), 200) != 0) std::abort();
    float sum = 0;
    const float* d = r.data<float>();
    for (int64_t i = 0; i < r.elements(); i += 1024) sum += d[i];  // pages past the new end: SIGBUS
    std::printf("%g\n", double(sum));
    std::exit(0);
  };
  EXPECT_EXIT(read_after_cut(), testing::ExitedWithCode(1),
              "spadgen: error: .*cut\\.npy was cut short while spadgen read it through its mapping");
  // a SIGBUS outside every registered mapping (raised: it has no faulting address in one) keeps its default action
  EXPECT_EXIT(
      [] {
        install_mapped_file_fault_handler();
        ::raise(SIGBUS);
      }(),
      testing::KilledBySignal(SIGBUS), "");
}

// A shape the header spells wrongly is an error naming the file (std::stoll's exception escaped as an
// internal error: "stoll"); spellings numpy writes are read.
TEST(NpyReader, AMalformedShapeIsAnErrorNamingTheFile) {
  TempDir dir;
  {
    NpyWriter w(dir.file("a.npy"), Dtype::F32, {2, 3});
    w.commit();
  }
  const std::string good = read_bytes(dir.file("a.npy"));
  const size_t at = good.find("(2, 3)");
  ASSERT_NE(at, std::string::npos);
  const auto with_shape = [&](const std::string& shape) {  // same length: the header's padding is kept
    std::string bytes = good;
    bytes.replace(at, 6, shape);
    std::ofstream(dir.file("b.npy"), std::ios::binary) << bytes;
    return dir.file("b.npy");
  };
  for (const char* bad : {"(a, 3)", "(2; 3)", "(2, 3 ", "(-2, 3)", "(2 3) "}) {
    const std::string shape = std::string(bad).substr(0, 6);
    try {
      NpyReader r(with_shape(shape));
      ADD_FAILURE() << shape << " was read";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("b.npy"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("shape"), std::string::npos) << e.what();
    }
  }
  EXPECT_EQ(NpyReader(with_shape("(2,3) ")).shape(), (std::vector<int64_t>{2, 3}));
  EXPECT_EQ(NpyReader(with_shape("(6,)  ")).shape(), (std::vector<int64_t>{6}));
  // A shape without its ')' ran to the header's end, and the header's newline and padding went into the
  // one-line message as they were: escaped.
  try {
    NpyReader r(with_shape("(2, 3,"));
    ADD_FAILURE() << "an unclosed shape was read";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    EXPECT_NE(m.find("malformed shape (2, 3,"), std::string::npos) << m;
    EXPECT_NE(m.find("\\n"), std::string::npos) << m;
  }
}

// A shape whose element count fits 64 bits but whose bytes do not is refused as too large (the message that the
// file holds too few bytes multiplied past 2^63, undefined behaviour: found by fuzz_arrays); one whose bytes fit
// is the file's too few bytes, with the count of bytes it needs.
TEST(NpyReader, AShapeWhoseBytesPass2To63IsTooLarge) {
  TempDir dir;
  const auto with_shape = [&](const std::string& shape) {  // the header padded again to 64 bytes
    std::string header = "{'descr': '<u2', 'fortran_order': False, 'shape': " + shape + ", }";
    header += std::string(size_t(64 - (10 + header.size() + 1) % 64) % 64, ' ') + "\n";
    const std::string bytes = std::string("\x93NUMPY\x01\x00", 8) + char(header.size() & 255) + char(header.size() >> 8) + header +
                              std::string(12, '\0');
    std::ofstream(dir.file("b.npy"), std::ios::binary) << bytes;
    return dir.file("b.npy");
  };
  const auto refused = [&](const std::string& shape, const std::string& why) {
    try {
      NpyReader r(with_shape(shape));
      ADD_FAILURE() << shape << " was read";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  };
  refused("(4, 1152921504606846976)", "shape (4, 1152921504606846976) too large: its '<u2' elements take more than 2^63 bytes");
  refused("(4611686018427387904,)", "too large: its '<u2' elements take more than 2^63 bytes");
  refused("(4611686018427387903,)", "the file holds 12 bytes of data, shape (4611686018427387903,) needs 9223372036854775806");
  EXPECT_EQ(NpyReader(with_shape("(6,)")).elements(), 6);
}

// A structured dtype is named whole (the message was cut at its first comma: "dtype [('a' is not ...").
TEST(NpyReader, AStructuredDtypeIsNamedWhole) {
  TempDir dir;
  std::string header = "{'descr': [('a', '<f4'), ('b', '<f4')], 'fortran_order': False, 'shape': (2,), }";
  header.append(64 - 10 - header.size() % 64 - 1, ' ').push_back('\n');
  std::string bytes = std::string("\x93NUMPY\x01\x00", 8);
  bytes.push_back(char(header.size() & 0xff));
  bytes.push_back(char(header.size() >> 8));
  bytes += header + std::string(16, '\0');
  ASSERT_EQ((bytes.size() - 16) % 64, 0u);
  std::ofstream(dir.file("s.npy"), std::ios::binary) << bytes;
  try {
    NpyReader r(dir.file("s.npy"));
    ADD_FAILURE() << "a structured dtype was read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("dtype [('a', '<f4'), ('b', '<f4')] is not one spadgen writes"), std::string::npos) << e.what();
  }
}

// A header naming a key twice (Python's dict literal takes the later value; the reader took the first) is
// refused, naming the key and the file, whichever quotes name it the second time (Python's "descr" is the
// same key; the reader looked for 'descr' only).
TEST(NpyReader, AKeyNamedTwiceInTheHeaderIsRefused) {
  TempDir dir;
  {
    NpyWriter w(dir.file("a.npy"), Dtype::F32, {2, 3});
    w.commit();
  }
  const std::string good = read_bytes(dir.file("a.npy"));
  ASSERT_EQ(good.find("{'descr': '<f4'"), 10u);
  for (const std::string twice : {"'descr': '<f8', ", "\"descr\": '<f8', "}) {
    SCOPED_TRACE(twice);
    std::string bytes = good;
    const size_t pad = bytes.find("}") + 1;  // the padding's spaces after the dict make room for it
    ASSERT_GE(bytes.find('\n', pad) - pad, twice.size());
    bytes.erase(pad, twice.size());
    bytes.insert(11, twice);
    ASSERT_EQ(bytes.size(), good.size());
    std::ofstream(dir.file("b.npy"), std::ios::binary | std::ios::trunc) << bytes;
    try {
      NpyReader r(dir.file("b.npy"));
      ADD_FAILURE() << "was read as " << writers::numpy_descr(r.dtype());
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("b.npy"), std::string::npos) << m;
      EXPECT_NE(m.find("'descr' twice"), std::string::npos) << m;
    }
  }
  EXPECT_EQ(NpyReader(dir.file("a.npy")).dtype(), Dtype::F32);
}

// A header longer than the file says which format version's prefix it read the length from (a version 3
// file whose prefix was of version 1 was only "the header runs past the end").
TEST(NpyReader, AHeaderPastTheEndNamesItsVersionAndSizes) {
  TempDir dir;
  {
    NpyWriter w(dir.file("a.npy"), Dtype::F32, {2, 3});
    w.commit();
  }
  std::string bytes = read_bytes(dir.file("a.npy"));
  bytes[6] = 3;  // version 3.0 reads a 4-byte length: bytes 8-11, here the v1 length and "{'"
  std::ofstream(dir.file("b.npy"), std::ios::binary) << bytes;
  try {
    NpyReader r(dir.file("b.npy"));
    ADD_FAILURE() << "was read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("b.npy' as a NumPy array: its header (format version 3, "), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("runs past the end of the file (" + std::to_string(bytes.size()) + " bytes)"),
              std::string::npos) << e.what();
  }
}

// Data that do not start at a multiple of their element size (a header not padded as the format asks; the
// data were read through a misaligned pointer) are refused, naming the file and the offset; a header
// padded to 16 bytes only, as NumPy before 1.14 wrote, is read.
TEST(NpyReader, DataOffMultiplesOfTheirElementSizeAreRefused) {
  TempDir dir;
  const auto npy_with = [&](size_t header_bytes) {
    std::string header = "{'descr': '<f8', 'fortran_order': False, 'shape': (2,), }";
    header.append(header_bytes - header.size() - 1, ' ').push_back('\n');
    std::string bytes = std::string("\x93NUMPY\x01\x00", 8);
    bytes.push_back(char(header.size() & 0xff));
    bytes.push_back(char(header.size() >> 8));
    const double v[2] = {1.5, -2.25};
    bytes += header + std::string(reinterpret_cast<const char*>(v), sizeof v);
    std::ofstream(dir.file("d.npy"), std::ios::binary | std::ios::trunc) << bytes;
    return dir.file("d.npy");
  };
  const NpyReader r(npy_with(70));  // data at byte 80: 16-byte alignment
  EXPECT_EQ(r.data<double>()[0], 1.5);
  EXPECT_EQ(r.data<double>()[1], -2.25);
  try {
    NpyReader bad(npy_with(71));
    ADD_FAILURE() << "data at byte 81 were read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("d.npy' as a NumPy array: its data start at byte 81, not a multiple of the 8-byte elements of '<f8'"),
              std::string::npos) << e.what();
  }
}

TEST(NpyWriter, RejectsWritesOutsideTheArrayAndAfterCommit) {
  TempDir dir;
  NpyWriter w(dir.file("e.npy"), Dtype::U8, {2, 4, 8});
  const std::vector<uint8_t> buf(64, 1);
  EXPECT_THROW(w.write(60, buf.data(), 5), Error);
  EXPECT_THROW(w.write(-1, buf.data(), 1), Error);
  EXPECT_THROW(w.write_khw(PixelRect{4, 0, 8, 4}, 0, 0, buf.data()), Error);  // sticks out on the right
  // As (H, W, T) = (2, 4, 8): the tile's data must cover the pixels written.
  EXPECT_THROW(w.write_hwt(PixelRect{0, 0, 2, 1}, PixelRect{0, 0, 1, 1}, 0, 0, buf.data()), Error);
  EXPECT_NO_THROW(w.write_hwt(PixelRect{1, 1, 1, 1}, PixelRect{0, 0, 2, 2}, 0, 0, buf.data()));
  NpyWriter four(dir.file("f.npy"), Dtype::U8, {1, 1, 2, 2});
  EXPECT_THROW(four.write_khw(PixelRect{0, 0, 1, 1}, 0, 0, buf.data()), Error);
  w.commit();
  EXPECT_THROW(w.write(0, buf.data(), 1), Error);
  EXPECT_THROW(w.commit(), Error);
}

float khw_value(int64_t k, int x, int y) { return float(k * 100000 + y * 1000 + x); }

// A tile's values [k * t.count() + t.index(x, y)] = khw_value(k, x - ox, y - oy).
std::vector<float> khw_tile(const PixelRect& t, int K, int ox, int oy) {
  std::vector<float> data(size_t(K * t.count()));
  for (int k = 0; k < K; ++k)
    for (int y = t.y0; y < t.y1(); ++y)
      for (int x = t.x0; x < t.x1(); ++x) data[size_t(k * t.count() + t.index(x, y))] = khw_value(k, x - ox, y - oy);
  return data;
}

// The file holds a (K, H, W) float32 stack whose element (k, y, x), at (k * H + y) * W + x computed here
// independently, is khw_value(k, x, y).
void expect_khw_file(const std::string& path, int K, int H, int W) {
  const std::string bytes = read_bytes(path);
  const size_t off = parse(bytes).data_offset;
  ASSERT_EQ(bytes.size(), off + size_t(K * H * W) * 4);
  for (int k = 0; k < K; ++k)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        float v;
        std::memcpy(&v, bytes.data() + off + 4 * ((size_t(k) * H + y) * W + x), 4);
        ASSERT_EQ(v, khw_value(k, x, y)) << k << " " << x << " " << y;
      }
}

// Tiles placed by write_khw must land at (k * H + y) * W + x, computed here independently.
TEST(NpyWriter, WriteKhwPlacesTilesAtTheirPixels) {
  TempDir dir;
  const int W = 37, H = 21, K = 3;
  // The stack covers a window of a larger image starting at (5, 2).
  const int ox = 5, oy = 2;
  {
    NpyWriter w(dir.file("khw.npy"), Dtype::F32, {K, H, W});
    for (PixelRect t : make_tiles(W, H, 8)) {
      t.x0 += ox;
      t.y0 += oy;
      w.write_khw(t, ox, oy, khw_tile(t, K, ox, oy).data());
    }
    w.commit();
  }
  expect_khw_file(dir.file("khw.npy"), K, H, W);
}

// Rows released from the resident set (release_rows) keep their data, and rows written after a release,
// on pages shared with released ones, land too: a (K, H, W) stack with rows of 1000 floats, so pages
// straddle rows, released band by band in an arbitrary order and once more over everything.
TEST(NpyWriter, ReleasedRowsKeepTheirData) {
  TempDir dir;
  const int W = 1000, H = 40, K = 3;
  {
    NpyWriter w(dir.file("released.npy"), Dtype::F32, {K, H, W});
    for (int band : {2, 0, 3, 1}) {
      const PixelRect t{0, band * 10, W, 10};
      w.write_khw(t, 0, 0, khw_tile(t, K, 0, 0).data());
      w.release_rows(1, t.y0, t.y1());
    }
    w.release_rows(1, 0, H);
    w.release_rows(1, -5, H + 5);  // out-of-range rows are clipped
    w.commit();
  }
  expect_khw_file(dir.file("released.npy"), K, H, W);
}

TEST(NpyWriter, WriteHwtSkipsTheHaloAndKeepsTimeInnermost) {
  TempDir dir;
  const int W = 20, H = 10, T = 5;
  {
    NpyWriter w(dir.file("t.npy"), Dtype::F32, {H, W, T});
    for (const PixelRect& r : make_tiles(W, H, 8)) {
      const PixelRect data_rect = grow_clipped(r, 1, W, H);
      std::vector<float> data(size_t(data_rect.count() * T));
      for (int y = data_rect.y0; y < data_rect.y1(); ++y)
        for (int x = data_rect.x0; x < data_rect.x1(); ++x)
          for (int t = 0; t < T; ++t)
            // Halo pixels carry a marker that must never reach the file.
            data[size_t(data_rect.index(x, y) * T + t)] = r.contains(x, y) ? float(y * 1000 + x * 10 + t) : -1.0f;
      w.write_hwt(r, data_rect, 0, 0, data.data());
    }
    w.commit();
  }
  const std::string bytes = read_bytes(dir.file("t.npy"));
  const size_t off = parse(bytes).data_offset;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int t = 0; t < T; ++t) {
        float v;
        std::memcpy(&v, bytes.data() + off + 4 * ((size_t(y) * W + x) * T + t), 4);
        ASSERT_EQ(v, float(y * 1000 + x * 10 + t));
      }
}

bool frame_bit(int k, int n, int y, int x) { return ((k * 7919 + n * 104729 + y * 31 + x * 17) % 5) < 2; }

// A tile's frames as SensorTile holds them, from frame_bit at the tile's image coordinates.
std::vector<uint8_t> tile_frames(const PixelRect& r, int K, int N, int origin_x, int origin_y) {
  const int bpr = (r.width + 7) / 8;
  std::vector<uint8_t> data(size_t(K * N * r.height * bpr), 0);
  for (int k = 0; k < K; ++k)
    for (int n = 0; n < N; ++n)
      for (int row = 0; row < r.height; ++row)
        for (int i = 0; i < r.width; ++i)
          if (frame_bit(k, n, r.y0 - origin_y + row, r.x0 - origin_x + i))
            data[size_t(((k * N + n) * r.height + row) * bpr + i / 8)] |= uint8_t(1u << (i % 8));
  return data;
}

// The file's frames are frame_bit's, and its padding bits beyond the width W are clear.
void expect_frame_bits(const std::string& file, int K, int N, int H, int W) {
  const int WB = (W + 7) / 8;
  const std::string bytes = read_bytes(file);
  const size_t off = parse(bytes).data_offset;
  ASSERT_EQ(bytes.size(), off + size_t(K) * size_t(N) * size_t(H) * size_t(WB));
  for (int k = 0; k < K; ++k)
    for (int n = 0; n < N; ++n)
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < WB * 8; ++x) {
          const auto byte = static_cast<unsigned char>(bytes[off + ((size_t(k) * N + n) * H + y) * WB + x / 8]);
          ASSERT_EQ(bool((byte >> (x % 8)) & 1u), x < W && frame_bit(k, n, y, x)) << k << " " << n << " " << y << " " << x;
        }
}

TEST(NpyWriter, WriteFramesPacksBitsLeastSignificantFirst) {
  TempDir dir;
  const int W = 21, H = 9, K = 2, N = 3, WB = (W + 7) / 8;
  {
    NpyWriter w(dir.file("frames.npy"), Dtype::U8, {K, N, H, WB});
    for (const PixelRect& r : make_tiles(W, H, 8)) w.write_frames(r, 0, 0, tile_frames(r, K, N, 0, 0).data());
    w.commit();
  }
  expect_frame_bits(dir.file("frames.npy"), K, N, H, W);
}

TEST(NpyWriter, WriteFramesBandGivesTheBitsOfEveryTile) {
  TempDir dir;
  const int W = 1020, K = 3, N = 130, WB = (W + 7) / 8, ox = 64, oy = 10;
  for (const int H : {32, 40})
    for (const bool mapped : {true, false}) {
      SCOPED_TRACE("H " + std::to_string(H) + (mapped ? " mapped" : " unmapped"));
      const std::string file = dir.file("band" + std::to_string(H) + (mapped ? "m" : "u") + ".npy");
      {
        NpyWriter w(file, Dtype::U8, {K, N, H, WB}, mapped);
        std::vector<PixelRect> tiles = make_tiles(W, H, 32);
        for (PixelRect& r : tiles) r.x0 += ox, r.y0 += oy;
        for (int y = oy; y < oy + H; y += 32) {
          std::vector<std::vector<uint8_t>> data;
          std::vector<NpyWriter::FramesTile> band;
          for (const PixelRect& r : tiles)
            if (r.y0 == y) data.push_back(tile_frames(r, K, N, ox, oy)), band.push_back({r, nullptr});
          for (size_t i = 0; i < band.size(); ++i) band[i].frames = data[i].data();
          std::reverse(band.begin(), band.end());  // in any order
          std::thread other([&] { w.write_frames_band(band, ox, oy, 2, 3); });
          w.write_frames_band(band, ox, oy, 0, 2);
          other.join();
        }
        w.commit();
      }
      expect_frame_bits(file, K, N, H, W);
    }
}

TEST(NpyWriter, WriteFramesBandRejectsWhatIsNotABand) {
  TempDir dir;
  NpyWriter w(dir.file("frames.npy"), Dtype::U8, {2, 1, 8, 3}, /*mapped=*/false);  // 24 pixels a row
  const std::vector<uint8_t> buf(64, 0);
  const auto band = [&](std::vector<PixelRect> rects) {
    std::vector<NpyWriter::FramesTile> b;
    for (const PixelRect& r : rects) b.push_back({r, buf.data()});
    return b;
  };
  EXPECT_NO_THROW(w.write_frames_band(band({{0, 0, 8, 4}, {8, 0, 16, 4}}), 0, 0, 0, 2));
  EXPECT_THROW(w.write_frames_band(band({{0, 0, 8, 4}, {16, 0, 8, 4}}), 0, 0, 0, 2), Error);  // a gap
  EXPECT_THROW(w.write_frames_band(band({{0, 0, 8, 4}, {8, 0, 8, 4}}), 0, 0, 0, 2), Error);   // short of the width
  EXPECT_THROW(w.write_frames_band(band({{0, 0, 8, 4}, {8, 4, 16, 4}}), 0, 0, 0, 2), Error);  // other rows
  EXPECT_THROW(w.write_frames_band(band({{0, 0, 5, 4}, {5, 0, 19, 4}}), 0, 0, 0, 2), Error);  // off a byte boundary
  EXPECT_THROW(w.write_frames_band(band({{0, 6, 24, 4}}), 0, 0, 0, 2), Error);                // below the stack
  EXPECT_THROW(w.write_frames_band(band({{0, 0, 24, 4}}), 0, 0, 1, 3), Error);                // no gate position 2
}

TEST(NpyWriter, WriteFramesRejectsMisalignedTiles) {
  TempDir dir;
  NpyWriter w(dir.file("frames.npy"), Dtype::U8, {1, 1, 4, 3});
  const std::vector<uint8_t> buf(64, 0);
  EXPECT_THROW(w.write_frames(PixelRect{4, 0, 8, 4}, 0, 0, buf.data()), Error);  // x not a multiple of 8
  EXPECT_THROW(w.write_frames(PixelRect{0, 0, 5, 4}, 0, 0, buf.data()), Error);  // partial byte mid-row
  EXPECT_NO_THROW(w.write_frames(PixelRect{16, 0, 5, 4}, 0, 0, buf.data()));    // partial byte at the edge
}

TEST(NpyWriter, WriteFramesClearsBitsBeyondTheRightEdge) {
  TempDir dir;
  {
    NpyWriter w(dir.file("frames.npy"), Dtype::U8, {1, 2, 3, 2});  // W = 13: 3 padding bits per row
    const std::vector<uint8_t> ones(size_t(2 * 3 * 1), 0xff);
    w.write_frames(PixelRect{8, 0, 5, 3}, 0, 0, ones.data());
    w.commit();
  }
  const std::string bytes = read_bytes(dir.file("frames.npy"));
  const size_t off = parse(bytes).data_offset;
  for (size_t r = 0; r < 6; ++r) {
    EXPECT_EQ(static_cast<unsigned char>(bytes[off + 2 * r]), 0u);  // untouched left tile
    EXPECT_EQ(static_cast<unsigned char>(bytes[off + 2 * r + 1]), 0x1fu);
  }
}

// pwrite from several threads at once must give exactly the bytes of a serial write.
TEST(NpyWriter, ConcurrentTilesEqualSerialWrite) {
  TempDir dir;
  const int W = 203, H = 77, K = 4;
  const auto tiles = make_tiles(W, H, 16);
  std::vector<std::vector<uint16_t>> data(tiles.size());
  std::mt19937 rng(42);
  for (size_t i = 0; i < tiles.size(); ++i) {
    data[i].resize(size_t(K * tiles[i].count()));
    for (auto& v : data[i]) v = uint16_t(rng());
  }
  {
    NpyWriter serial(dir.file("serial.npy"), Dtype::U16, {K, H, W});
    for (size_t i = 0; i < tiles.size(); ++i) serial.write_khw(tiles[i], 0, 0, data[i].data());
    serial.commit();
  }
  {
    NpyWriter par(dir.file("parallel.npy"), Dtype::U16, {K, H, W});
    std::vector<std::thread> threads;
    const size_t n_threads = 4;
    for (size_t t = 0; t < n_threads; ++t)
      threads.emplace_back([&, t] {
        // Each thread walks its share backwards so neighbouring tiles are in flight together.
        for (size_t i = tiles.size(); i-- > 0;)
          if (i % n_threads == t) par.write_khw(tiles[i], 0, 0, data[i].data());
      });
    for (auto& th : threads) th.join();
    par.commit();
  }
  EXPECT_EQ(read_bytes(dir.file("serial.npy")), read_bytes(dir.file("parallel.npy")));
}

// Offsets beyond 4 GiB must not wrap: the file is sparse, so this costs no disk.
TEST(NpyWriter, LargerThanFourGiB) {
  TempDir dir;
  const int64_t n = (int64_t(5) << 30) + 3;
  const std::string path = dir.file("big.npy");
  int64_t header = 0;
  {
    NpyWriter w(path, Dtype::U8, {n});
    header = w.header_bytes();
    const uint8_t a = 0xab, b = 0xcd;
    w.write(int64_t(9) << 29, &a, 1);  // 4.5 GiB
    w.write(n - 1, &b, 1);
    w.commit();
  }
  EXPECT_EQ(std::filesystem::file_size(path), uint64_t(header + n));
  const int fd = ::open(path.c_str(), O_RDONLY);
  ASSERT_GE(fd, 0);
  uint8_t a = 0, b = 0, z = 1;
  EXPECT_EQ(::pread(fd, &a, 1, off_t(header + (int64_t(9) << 29))), 1);
  EXPECT_EQ(::pread(fd, &b, 1, off_t(header + n - 1)), 1);
  EXPECT_EQ(::pread(fd, &z, 1, off_t(header + (int64_t(1) << 32))), 1);
  ::close(fd);
  EXPECT_EQ(a, 0xab);
  EXPECT_EQ(b, 0xcd);
  EXPECT_EQ(z, 0);
}

// The first interpreter that can import numpy: PATH's python3 may be a pyenv or venv without it while
// the system one (python3-numpy) has it. Empty if none.
std::string python_with_numpy() {
  for (const char* py : {"python3", "/usr/bin/python3"}) {
    const std::string cmd = std::string(py) + " -c 'import numpy' >/dev/null 2>&1";
    if (std::system(cmd.c_str()) == 0) return py;
  }
  return {};
}

TEST(NpyWriter, NumpyLoadsItWithMmap) {
  const std::string python = python_with_numpy();
  if (python.empty()) GTEST_SKIP() << "python3 with numpy is not available";
  TempDir dir;
  {
    NpyWriter f(dir.file("f.npy"), Dtype::F32, {2, 3, 4});
    std::vector<float> v(24);
    for (size_t i = 0; i < v.size(); ++i) v[i] = float(i) * 0.25f;
    f.write(0, v.data(), 24);
    f.commit();
    NpyWriter u(dir.file("u.npy"), Dtype::U16, {3, 2});
    const uint16_t uv[6] = {0, 1, 255, 256, 4080, 65535};
    u.write(0, uv, 6);
    u.commit();
    NpyWriter b(dir.file("b.npy"), Dtype::U8, {1, 2, 3, 1});
    const uint8_t bv[6] = {0b00000101, 0, 0, 0, 0, 0x80};
    b.write(0, bv, 6);
    b.commit();
    NpyWriter e(dir.file("e.npy"), Dtype::F32, {0, 7});
    e.commit();
  }
  const std::string script = dir.file("check.py");
  std::ofstream(script) << R"(import sys, numpy as np
d = sys.argv[1]
f = np.load(d + '/f.npy', mmap_mode='r')
assert f.shape == (2, 3, 4) and f.dtype == np.float32, (f.shape, f.dtype)
assert f[1, 2, 3] == 23 * 0.25 and f[0, 1, 0] == 1.0
u = np.load(d + '/u.npy', mmap_mode='r')
assert u.shape == (3, 2) and u.dtype == np.uint16 and u[2, 0] == 4080 and u[2, 1] == 65535
b = np.load(d + '/b.npy', mmap_mode='r')
assert b.shape == (1, 2, 3, 1) and b.dtype == np.uint8
bits = np.unpackbits(b, axis=-1, bitorder='little')
assert list(bits[0, 0, 0, :3]) == [1, 0, 1] and bits[0, 1, 2, 7] == 1
e = np.load(d + '/e.npy')
assert e.shape == (0, 7)
# Byte-identical header to what NumPy itself writes for the same array.
import io
for name, arr in (('f', np.zeros((2, 3, 4), np.float32)), ('u', np.zeros((3, 2), np.uint16)),
                  ('b', np.zeros((1, 2, 3, 1), np.uint8)), ('e', np.zeros((0, 7), np.float32))):
    buf = io.BytesIO()
    np.save(buf, arr)
    ref = buf.getvalue()[:len(buf.getvalue()) - arr.nbytes]
    ours = open(d + '/' + name + '.npy', 'rb').read()[:len(ref)]
    assert ours == ref, (name, ours, ref)
print('ok')
)";
  const std::string cmd = python + " " + script + " " + dir.path().string();
  EXPECT_EQ(std::system(cmd.c_str()), 0);
}

}  // namespace
}  // namespace spadgen::writers
