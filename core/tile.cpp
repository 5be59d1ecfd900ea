#include "tile.h"

#include <string>

#include "error.h"

namespace spadgen {

std::vector<PixelRect> make_tiles(int width, int height, int tile_size) {
  if (tile_size <= 0 || tile_size % 8 != 0)
    throw Error("tile size must be a positive multiple of 8 pixels, found " + std::to_string(tile_size));
  std::vector<PixelRect> tiles;
  for (int y = 0; y < height; y += tile_size)
    for (int x = 0; x < width; x += tile_size)
      tiles.push_back({x, y, std::min(tile_size, width - x), std::min(tile_size, height - y)});
  return tiles;
}

}  // namespace spadgen
