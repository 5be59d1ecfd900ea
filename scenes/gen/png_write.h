// PNG encoding for the generator's procedural textures (stb_image_write kept private to one file).
#pragma once
#include <cstdint>
#include <vector>

namespace spadgen::scenes_gen {

// Encodes an 8-bit image with `channels` (1 to 4) interleaved channels, rows top to bottom.
std::vector<unsigned char> encode_png(const std::vector<uint8_t>& pixels, int width, int height,
                                      int channels);

}  // namespace spadgen::scenes_gen
