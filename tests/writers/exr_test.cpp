#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCompression.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <iterator>
#include <fstream>
#include <limits>

#include "core/error.h"
#include "test_util.h"
#include "writers/writers.h"

namespace spadgen::writers {
namespace {

using test::TempDir;

const float kInf = std::numeric_limits<float>::infinity();

float value(int c, int x, int y) { return (x == 3 && y == 2) ? kInf : float(c) * 0.125f + float(y * 10 + x) * 1.5f; }

ExrImage sample_image(const std::vector<std::string>& names) {
  ExrImage im(7, 5);
  for (size_t c = 0; c < names.size(); ++c) {
    float* p = im.channel(names[c]);
    for (int y = 0; y < 5; ++y)
      for (int x = 0; x < 7; ++x) p[y * 7 + x] = value(int(c), x, y);
  }
  im.set_attribute("spadgen.seed", "12345");
  im.set_attribute("spadgen.scene_hash", "sha256:00ff");
  im.set_attribute("spadgen.time_axis", R"({"start_s": 1e-9, "bins": 0})");
  return im;
}

const std::vector<std::string> kNames = {"range", "normal.X", "layer0.range", "layer12.transmittance"};

TEST(Exr, RoundTripThroughReadExr) {
  TempDir dir;
  sample_image(kNames).write(dir.file("gt.exr"));
  const ExrData d = read_exr(dir.file("gt.exr"));
  EXPECT_EQ(d.width, 7);
  EXPECT_EQ(d.height, 5);
  ASSERT_EQ(d.channels.size(), kNames.size());
  for (size_t c = 0; c < kNames.size(); ++c) {
    const auto& v = d.channels.at(kNames[c]);
    for (int y = 0; y < 5; ++y)
      for (int x = 0; x < 7; ++x) ASSERT_EQ(v[size_t(y * 7 + x)], value(int(c), x, y)) << kNames[c];
  }
  EXPECT_EQ(d.attributes.at("spadgen.seed"), "12345");
  EXPECT_EQ(d.attributes.at("spadgen.scene_hash"), "sha256:00ff");
  EXPECT_EQ(d.attributes.at("spadgen.time_axis"), R"({"start_s": 1e-9, "bins": 0})");
  EXPECT_EQ(d.partial_window, "");  // the whole image
}

// The same file read with OpenEXR directly: FLOAT channels, ZIP, string attributes.
TEST(Exr, ReadableByOpenExrDirectly) {
  TempDir dir;
  sample_image(kNames).write(dir.file("gt.exr"));
  Imf::InputFile in(dir.file("gt.exr").c_str());
  const Imf::Header& h = in.header();
  EXPECT_EQ(h.compression(), Imf::ZIP_COMPRESSION);
  const Imath::Box2i dw = h.dataWindow();
  EXPECT_EQ(dw.min.x, 0);
  EXPECT_EQ(dw.max.x, 6);
  EXPECT_EQ(dw.max.y, 4);
  for (const auto& n : kNames) {
    const Imf::Channel* ch = h.channels().findChannel(n);
    ASSERT_NE(ch, nullptr) << n;
    EXPECT_EQ(ch->type, Imf::FLOAT);
  }
  const auto* seed = h.findTypedAttribute<Imf::StringAttribute>("spadgen.seed");
  ASSERT_NE(seed, nullptr);
  EXPECT_EQ(seed->value(), "12345");
  std::vector<float> normal_x(35);
  Imf::FrameBuffer fb;
  fb.insert("normal.X", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(normal_x.data()), 4, 28));
  in.setFrameBuffer(fb);
  in.readPixels(0, 4);
  EXPECT_EQ(normal_x[2 * 7 + 1], value(1, 1, 2));
  EXPECT_TRUE(std::isinf(normal_x[2 * 7 + 3]));
}

// Every compression outputs.exr_compression offers is lossless: the channels read back bit for bit (NaN,
// infinities, -0.0 and subnormals included), and OpenEXR records the compression asked for.
TEST(Exr, EveryCompressionReadsBackBitForBit) {
  TempDir dir;
  ExrImage im(61, 37);  // not a multiple of ZIP's 16 scanlines
  float* a = im.channel("range");
  float* b = im.channel("noise");
  for (int i = 0; i < 61 * 37; ++i) {
    a[i] = i % 7 == 0 ? kInf : float(i) * 0.001f;
    b[i] = std::sin(float(i)) * 1e3f;
  }
  a[1] = std::numeric_limits<float>::quiet_NaN(), a[2] = -0.0f, a[3] = std::numeric_limits<float>::denorm_min();
  const std::pair<ExrCompression, Imf::Compression> cases[] = {{ExrCompression::None, Imf::NO_COMPRESSION},
                                                               {ExrCompression::Rle, Imf::RLE_COMPRESSION},
                                                               {ExrCompression::Zips, Imf::ZIPS_COMPRESSION},
                                                               {ExrCompression::Zip, Imf::ZIP_COMPRESSION}};
  ASSERT_EQ(std::size(cases), EnumNames<ExrCompression>::values.size());
  for (const auto& [c, imf] : cases) {
    const std::string path = dir.file(to_string(c) + ".exr");
    im.write(path, c);
    EXPECT_EQ(Imf::InputFile(path.c_str()).header().compression(), imf) << to_string(c);
    const ExrData d = read_exr(path);
    EXPECT_EQ(std::memcmp(d.channels.at("range").data(), a, 61 * 37 * sizeof(float)), 0) << to_string(c);
    EXPECT_EQ(std::memcmp(d.channels.at("noise").data(), b, 61 * 37 * sizeof(float)), 0) << to_string(c);
  }
}

// HALF and UINT channels and an offset data window, written by OpenEXR itself.
TEST(Exr, ReadExrConvertsHalfAndUintAndOffsetWindows) {
  TempDir dir;
  const std::string path = dir.file("foreign.exr");
  {
    Imf::Header h(Imath::Box2i({0, 0}, {9, 9}), Imath::Box2i({2, 3}, {4, 4}));  // 3 x 2 pixels
    h.channels().insert("h", Imf::Channel(Imf::HALF));
    h.channels().insert("u", Imf::Channel(Imf::UINT));
    h.insert("note", Imf::StringAttribute("hello"));
    std::vector<Imath::half> hv(6);
    std::vector<uint32_t> uv(6);
    for (int i = 0; i < 6; ++i) hv[size_t(i)] = Imath::half(float(i) * 0.5f), uv[size_t(i)] = uint32_t(i * 1000);
    Imf::FrameBuffer fb;
    fb.insert("h", Imf::Slice::Make(Imf::HALF, hv.data(), h.dataWindow()));
    fb.insert("u", Imf::Slice::Make(Imf::UINT, uv.data(), h.dataWindow()));
    Imf::OutputFile out(path.c_str(), h);
    out.setFrameBuffer(fb);
    out.writePixels(2);
  }
  const ExrData d = read_exr(path);
  EXPECT_EQ(d.width, 3);
  EXPECT_EQ(d.height, 2);
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(d.channels.at("h")[size_t(i)], float(i) * 0.5f);
    EXPECT_EQ(d.channels.at("u")[size_t(i)], float(i * 1000));
  }
  EXPECT_EQ(d.attributes.at("note"), "hello");
  EXPECT_EQ(d.partial_window, "data window (2, 3)-(4, 4) is not its display window (0, 0)-(9, 9)");
}

TEST(Exr, ErrorsNameTheFile) {
  TempDir dir;
  const std::string missing = dir.file("missing.exr");
  try {
    read_exr(missing);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(missing), std::string::npos) << e.what();
  }
  const std::string junk = dir.file("junk.exr");
  std::ofstream(junk) << "not an image";
  try {
    read_exr(junk);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(junk), std::string::npos) << e.what();
  }
  const std::string nowhere = dir.file("no/such/folder/x.exr");
  try {
    sample_image(kNames).write(nowhere);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(nowhere), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("No such file"), std::string::npos) << e.what();
  }
}

TEST(Exr, RejectsReservedAttributeNamesAndEmptyImages) {
  ExrImage im(2, 2);
  EXPECT_THROW(im.set_attribute("channels", "x"), Error);
  EXPECT_THROW(im.set_attribute("compression", "x"), Error);
  EXPECT_NO_THROW(im.set_attribute("spadgen.version", "0.1.0"));
  EXPECT_THROW(ExrImage(0, 3), Error);
  EXPECT_THROW(im.channel(""), Error);
}

TEST(Exr, ChannelIsZeroFilledAndStable) {
  ExrImage im(3, 2);
  float* a = im.channel("a");
  for (int i = 0; i < 6; ++i) EXPECT_EQ(a[i], 0.0f);
  a[4] = 2.0f;
  im.channel("b");
  im.channel("c");
  EXPECT_EQ(im.channel("a"), a);
  EXPECT_EQ(im.channel("a")[4], 2.0f);
}

}  // namespace
}  // namespace spadgen::writers
