#include "scenes/image_decode.h"

#include <png.h>
#include <turbojpeg.h>

#include <algorithm>
#include <csetjmp>
#include <cstdio>
#include <cstring>

namespace spadgen::scenes {
namespace {

constexpr uint64_t kMaxDeflateRatio = 1032;

std::string size_problem(uint64_t width, uint64_t height) {
  if (width < 1 || height < 1) return "an image of " + std::to_string(width) + " x " + std::to_string(height) + " texels";
  if (width > uint64_t(kMaxImageSide) || height > uint64_t(kMaxImageSide) || width * height > kMaxImageTexels)
    return std::to_string(width) + " x " + std::to_string(height) + " texels, expected at most " +
           std::to_string(kMaxImageSide) + " on a side and " + std::to_string(kMaxImageTexels) + " in all";
  return "";
}

// libpng reports errors by longjmp: the two functions that call it (png_header, png_texels) hold only
// plain C between their setjmp and their end, messages go to fixed buffers, and the texels to vectors that
// decode_png (which no longjmp crosses) owns.
struct PngSource {
  const unsigned char* data = nullptr;
  size_t size = 0, at = 0;
  char error[256] = {};
  char warning[256] = {};
};

extern "C" void png_read_error_fn(png_structp png, png_const_charp msg) {
  auto* src = static_cast<PngSource*>(png_get_error_ptr(png));
  std::snprintf(src->error, sizeof src->error, "%s", msg);
  png_longjmp(png, 1);
}

extern "C" void png_read_warning_fn(png_structp png, png_const_charp msg) {
  auto* src = static_cast<PngSource*>(png_get_error_ptr(png));
  if (src->warning[0] == '\0') std::snprintf(src->warning, sizeof src->warning, "%s", msg);
}

extern "C" void png_read_fn(png_structp png, png_bytep out, png_size_t n) {
  auto* src = static_cast<PngSource*>(png_get_io_ptr(png));
  if (n > src->size - src->at) png_error(png, "the file ends inside a chunk");
  std::memcpy(out, src->data + src->at, n);
  src->at += n;
}

// Reads the header into *width, *height and sets the expansion to RGBA8; false on an error (src->error).
bool png_header(png_structp png, png_infop info, PngSource* src, uint32_t* width, uint32_t* height) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_set_read_fn(png, src, png_read_fn);
  png_set_user_limits(png, uint32_t(kMaxImageSide), uint32_t(kMaxImageSide));
  png_read_info(png, info);
  *width = png_get_image_width(png, info);
  *height = png_get_image_height(png, info);
  const int color = png_get_color_type(png, info), depth = png_get_bit_depth(png, info);
  if (depth == 16) png_set_strip_16(png);  // the high byte
  if (color == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (color == PNG_COLOR_TYPE_GRAY && depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (png_get_valid(png, info, PNG_INFO_tRNS)) png_set_tRNS_to_alpha(png);
  if (color == PNG_COLOR_TYPE_GRAY || color == PNG_COLOR_TYPE_GRAY_ALPHA) png_set_gray_to_rgb(png);
  if (!(color & PNG_COLOR_MASK_ALPHA) && !png_get_valid(png, info, PNG_INFO_tRNS))
    png_set_filler(png, 0xff, PNG_FILLER_AFTER);
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  if (png_get_rowbytes(png, info) != size_t(*width) * 4) png_error(png, "unexpected row size after the expansion to RGBA");
  return true;
}

// Reads the texels into the rows; false on an error (src->error).
bool png_texels(png_structp png, png_bytep* rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_read_image(png, rows);
  png_read_end(png, nullptr);
  return true;
}

std::string decode_png(const unsigned char* bytes, size_t size, DecodedImage* out, std::string* warning) {
  PngSource src;
  src.data = bytes;
  src.size = size;
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &src, png_read_error_fn, png_read_warning_fn);
  if (!png) return "could not start the PNG decoder";
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_read_struct(&png, nullptr, nullptr);
    return "could not start the PNG decoder";
  }
  struct Destroy {
    png_structp* png;
    png_infop* info;
    ~Destroy() { png_destroy_read_struct(png, info, nullptr); }
  } destroy{&png, &info};
  uint32_t width = 0, height = 0;
  // The size from the IHDR chunk first: libpng refuses one past its user limits as "Invalid IHDR data"
  if (src.size >= 24 && std::memcmp(src.data + 12, "IHDR", 4) == 0) {
    const auto be32 = [&src](size_t at) {
      return uint32_t(src.data[at]) << 24 | uint32_t(src.data[at + 1]) << 16 | uint32_t(src.data[at + 2]) << 8 | uint32_t(src.data[at + 3]);
    };
    if (std::string p = size_problem(be32(16), be32(20)); !p.empty()) return p;
    // Deflate writes at most 1032 bytes for each byte it is given (a 258-byte match in two bits), so a file
    // too short for the header's texels is refused before they are allocated (a 200-byte file claiming
    // 60000 x 4000 had taken 0.95 GB to fail at libpng's "Not enough image data").
    if (src.size >= 26) {
      const int channels_of[7] = {1, 0, 3, 1, 2, 0, 4};  // by colour type: grey, -, RGB, palette, grey+alpha, -, RGBA
      const unsigned depth = src.data[24], color = src.data[25];
      const uint64_t bits = uint64_t(be32(16)) * be32(20) * depth * (color < 7 ? channels_of[color] : 0);
      if (bits / 8 / kMaxDeflateRatio > src.size)
        return std::to_string(be32(16)) + " x " + std::to_string(be32(20)) + " texels of " + std::to_string(bits / 8) +
               " bytes in a file of " + std::to_string(src.size) + " bytes, which deflate holds at most " +
               std::to_string(kMaxDeflateRatio) + " times: the file is cut short or its header is wrong";
    }
  }
  if (!png_header(png, info, &src, &width, &height)) return std::string("not a readable PNG (libpng: ") + src.error + ")";
  if (std::string p = size_problem(width, height); !p.empty()) return p;
  std::vector<uint8_t> rgba(size_t(width) * size_t(height) * 4);
  std::vector<png_bytep> rows(height);
  for (uint32_t y = 0; y < height; ++y) rows[y] = rgba.data() + size_t(y) * size_t(width) * 4;
  if (!png_texels(png, rows.data())) return std::string("not a readable PNG (libpng: ") + src.error + ")";
  out->width = int(width);
  out->height = int(height);
  out->rgba = std::move(rgba);
  if (src.warning[0] != '\0') *warning = std::string("libpng: ") + src.warning;
  return "";
}

std::string decode_jpeg(const unsigned char* bytes, size_t size, DecodedImage* out, std::string* warning) {
  tjhandle tj = tjInitDecompress();
  if (!tj) return "could not start the JPEG decoder";
  struct Close {
    tjhandle h;
    ~Close() { tjDestroy(h); }
  } close{tj};
  int width = 0, height = 0, subsampling = 0, colorspace = 0;
  if (tjDecompressHeader3(tj, bytes, static_cast<unsigned long>(size), &width, &height, &subsampling, &colorspace) != 0)
    return std::string("not a readable JPEG (libjpeg-turbo: ") + tjGetErrorStr2(tj) + ")";
  // (a header cut inside its first table reads as 0 x 0: said as what it is)
  if (width <= 0 || height <= 0) return "not a readable JPEG: its header gives no image size (a file cut short?)";
  if (std::string p = size_problem(uint64_t(std::max(width, 0)), uint64_t(std::max(height, 0))); !p.empty()) return p;
  std::vector<uint8_t> rgba(size_t(width) * size_t(height) * 4);
  if (tjDecompress2(tj, bytes, static_cast<unsigned long>(size), rgba.data(), width, 0, height, TJPF_RGBA,
                    TJFLAG_ACCURATEDCT) != 0) {
    // A warning of a slightly corrupt file (extraneous bytes before a marker) still gives its texels; a file
    // cut short is refused, as a PNG cut short is (its missing texels were filled grey, with a warning).
    const std::string what = tjGetErrorStr2(tj);
    if (tjGetErrorCode(tj) != TJERR_WARNING) return "not a readable JPEG (libjpeg-turbo: " + what + ")";
    if (what.find("Premature end") != std::string::npos)
      return "not a readable JPEG: the file ends before its image data (libjpeg-turbo: " + what + ")";
    *warning = "libjpeg-turbo: " + what;
  }
  out->width = width;
  out->height = height;
  out->rgba = std::move(rgba);
  return "";
}

}  // namespace

namespace {
constexpr unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'}, kJpeg[3] = {0xff, 0xd8, 0xff};
bool is_png(const unsigned char* bytes, size_t size) { return size >= 8 && std::memcmp(bytes, kPng, 8) == 0; }
bool is_jpeg(const unsigned char* bytes, size_t size) { return size >= 3 && std::memcmp(bytes, kJpeg, 3) == 0; }
}  // namespace

bool is_png_or_jpeg(const unsigned char* bytes, size_t size) { return is_png(bytes, size) || is_jpeg(bytes, size); }

std::string decode_image(const unsigned char* bytes, size_t size, DecodedImage* out, std::string* warning) {
  warning->clear();
  if (is_png(bytes, size)) return decode_png(bytes, size, out, warning);
  if (is_jpeg(bytes, size)) return decode_jpeg(bytes, size, out, warning);
  if (size == 0) return "neither PNG nor JPEG (it is empty); glTF 2.0 images are PNG (starting 0x89 'PNG') or JPEG (0xff 0xd8 0xff)";
  std::string first;
  char hex[8];
  for (size_t i = 0; i < std::min<size_t>(size, 4); ++i) {
    std::snprintf(hex, sizeof hex, "%s0x%02x", i ? " " : "", unsigned(bytes[i]));
    first += hex;
  }
  return "neither PNG nor JPEG (its first bytes are " + first +
         "); glTF 2.0 images are PNG (starting 0x89 'PNG') or JPEG (0xff 0xd8 0xff)";
}

}  // namespace spadgen::scenes
