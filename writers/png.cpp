#include <png.h>

#include <csetjmp>
#include <cstdio>
#include <limits>

#include "core/error.h"
#include "writers/writers.h"

namespace spadgen::writers {
namespace {

// libpng reports errors by longjmp, so everything between setjmp and the end of encode() is plain C:
// no object with a destructor is created there, and messages go to a fixed buffer.
struct PngContext {
  std::string* out = nullptr;
  char message[256] = {};
};

extern "C" void png_error_fn(png_structp png, png_const_charp msg) {
  auto* ctx = static_cast<PngContext*>(png_get_error_ptr(png));
  std::snprintf(ctx->message, sizeof ctx->message, "%s", msg);
  png_longjmp(png, 1);
}

extern "C" void png_warning_fn(png_structp, png_const_charp) {}

extern "C" void png_write_fn(png_structp png, png_bytep data, png_size_t size) {
  auto* ctx = static_cast<PngContext*>(png_get_io_ptr(png));
  bool failed = false;
  try {
    ctx->out->append(reinterpret_cast<const char*>(data), size);
  } catch (...) {
    failed = true;
  }
  if (failed) png_error(png, "out of memory");
}

extern "C" void png_flush_fn(png_structp) {}

bool encode(png_structp png, png_infop info, int width, int height, int color_type, const uint8_t* pixels,
            size_t stride) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_set_IHDR(png, info, png_uint_32(width), png_uint_32(height), 8, color_type, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < height; ++y) png_write_row(png, pixels + size_t(y) * stride);
  png_write_end(png, info);
  return true;
}

}  // namespace

void write_png(const std::string& path, int width, int height, int channels, const std::vector<uint8_t>& pixels) {
  int color_type = 0;
  switch (channels) {
    case 1: color_type = PNG_COLOR_TYPE_GRAY; break;
    case 3: color_type = PNG_COLOR_TYPE_RGB; break;
    case 4: color_type = PNG_COLOR_TYPE_RGBA; break;
    default: throw Error("cannot write PNG '" + path + "': " + std::to_string(channels) + " channels (1, 3 or 4)");
  }
  // PNG has no empty images; its size limit is 2^31 - 1 per side.
  if (width < 1 || height < 1)
    throw Error("cannot write PNG '" + path + "': empty image " + std::to_string(width) + "x" + std::to_string(height));
  const size_t stride = size_t(width) * size_t(channels);
  if (pixels.size() != stride * size_t(height))
    throw Error("cannot write PNG '" + path + "': " + std::to_string(pixels.size()) + " bytes for a " +
                std::to_string(width) + "x" + std::to_string(height) + "x" + std::to_string(channels) + " image");

  std::string bytes;
  PngContext ctx;
  ctx.out = &bytes;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &ctx, png_error_fn, png_warning_fn);
  if (!png) throw Error("cannot write PNG '" + path + "': libpng could not start");
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_write_struct(&png, nullptr);
    throw Error("cannot write PNG '" + path + "': libpng could not start");
  }
  png_set_write_fn(png, &ctx, png_write_fn, png_flush_fn);
  const bool ok = encode(png, info, width, height, color_type, pixels.data(), stride);
  png_destroy_write_struct(&png, &info);
  if (!ok) throw Error("cannot write PNG '" + path + "': " + ctx.message);
  write_file_atomic(path, bytes);
}

}  // namespace spadgen::writers
