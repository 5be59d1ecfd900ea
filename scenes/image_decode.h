// A glTF image's bytes decoded to 8-bit RGBA texels: PNG by libpng, JPEG by libjpeg-turbo (the two formats
// glTF 2.0 allows; stb_image, which tinygltf would call, is never handed a scene's bytes).
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace spadgen::scenes {

// The largest image decoded: per side, and in texels (16384 x 16384, 1 GiB of RGBA), checked on the
// header before any texel is allocated.
constexpr int kMaxImageSide = 65536;
constexpr uint64_t kMaxImageTexels = uint64_t{1} << 28;

struct DecodedImage {
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;  // row by row from the top, 4 bytes per texel
};

// Decodes bytes (a whole PNG or JPEG file). Returns an empty string on success, else what is wrong with
// the bytes (the caller names the image). The colour values are the file's, as glTF asks: no gamma or
// colour-profile conversion; 16-bit channels keep their high byte; grey, palette and transparency-chunk
// images are expanded to RGBA (alpha 255 where the file has none). *warning gets the decoder's warnings
// about data it could still decode (empty when none).
std::string decode_image(const unsigned char* bytes, size_t size, DecodedImage* out, std::string* warning);

// Whether the bytes start as a PNG or a JPEG does (the formats decode_image reads).
bool is_png_or_jpeg(const unsigned char* bytes, size_t size);

}  // namespace spadgen::scenes
