#include <png.h>

#include <gtest/gtest.h>

#include "core/error.h"
#include "test_util.h"
#include "writers/previews.h"
#include "writers/writers.h"

namespace spadgen::writers {
namespace {

using test::TempDir;

struct Decoded {
  int width = 0, height = 0, channels = 0;
  std::vector<uint8_t> pixels;
};

// Reads a PNG through libpng's simplified API, keeping the file's own channel layout.
Decoded decode(const std::string& path) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  EXPECT_NE(png_image_begin_read_from_file(&image, path.c_str()), 0) << image.message;
  Decoded d;
  d.width = int(image.width);
  d.height = int(image.height);
  d.channels = int(PNG_IMAGE_PIXEL_CHANNELS(image.format));
  // Keep 8-bit sRGB samples as stored (no colour-map or linear conversion).
  image.format &= ~uint32_t(PNG_FORMAT_FLAG_LINEAR | PNG_FORMAT_FLAG_COLORMAP);
  d.pixels.resize(PNG_IMAGE_SIZE(image));
  EXPECT_NE(png_image_finish_read(&image, nullptr, d.pixels.data(), 0, nullptr), 0) << image.message;
  return d;
}

class PngRoundTrip : public ::testing::TestWithParam<int> {};

TEST_P(PngRoundTrip, PixelsComeBackExactly) {
  TempDir dir;
  const int channels = GetParam(), w = 13, h = 6;
  std::vector<uint8_t> px(size_t(w * h * channels));
  for (size_t i = 0; i < px.size(); ++i) px[i] = uint8_t(i * 37 + 11);
  write_png(dir.file("p.png"), w, h, channels, px);
  const Decoded d = decode(dir.file("p.png"));
  EXPECT_EQ(d.width, w);
  EXPECT_EQ(d.height, h);
  EXPECT_EQ(d.channels, channels);
  EXPECT_EQ(d.pixels, px);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"p.png"});
}

INSTANTIATE_TEST_SUITE_P(GrayRgbRgba, PngRoundTrip, ::testing::Values(1, 3, 4));

TEST(Png, RgbImageOverload) {
  TempDir dir;
  Rgb8Image im(4, 3, {10, 20, 30});
  im.at(3, 2)[0] = 200;
  write_png(dir.file("i.png"), im);
  const Decoded d = decode(dir.file("i.png"));
  EXPECT_EQ(d.channels, 3);
  EXPECT_EQ(d.pixels, im.pixels);
}

TEST(Png, RejectsBadArguments) {
  TempDir dir;
  EXPECT_THROW(write_png(dir.file("a.png"), 2, 2, 2, std::vector<uint8_t>(8)), Error);
  EXPECT_THROW(write_png(dir.file("a.png"), 2, 2, 3, std::vector<uint8_t>(11)), Error);
  EXPECT_THROW(write_png(dir.file("a.png"), 0, 2, 3, {}), Error);
  EXPECT_TRUE(dir.entries().empty());
}

}  // namespace
}  // namespace spadgen::writers
