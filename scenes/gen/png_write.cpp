// stb_image_write lives here only, with static linkage: libtinygltf carries its own copy of stb, and
// exported duplicates would interpose on each other.
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb/stb_image_write.h>

#include "png_write.h"

#include <stdexcept>
#include <string>

namespace spadgen::scenes_gen {
namespace {

void append(void* context, void* data, int size) {
  auto* out = static_cast<std::vector<unsigned char>*>(context);
  const auto* bytes = static_cast<const unsigned char*>(data);
  out->insert(out->end(), bytes, bytes + size);
}

}  // namespace

std::vector<unsigned char> encode_png(const std::vector<uint8_t>& pixels, int width, int height,
                                      int channels) {
  if (pixels.size() != static_cast<size_t>(width) * static_cast<size_t>(height) * static_cast<size_t>(channels))
    throw std::runtime_error("encode_png: pixel buffer does not match " + std::to_string(width) + "x" +
                             std::to_string(height) + "x" + std::to_string(channels));
  std::vector<unsigned char> out;
  if (!stbi_write_png_to_func(append, &out, width, height, channels, pixels.data(), width * channels))
    throw std::runtime_error("encode_png: stb_image_write failed");
  return out;
}

}  // namespace spadgen::scenes_gen
