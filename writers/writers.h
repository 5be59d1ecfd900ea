// Output files. Every file appears complete or not at all: it is written under a temporary name in the
// output folder and renamed into place by commit(); a writer destroyed without commit() removes its
// temporary file. The app commits every writer only after the whole run succeeded.
#pragma once
#include <nlohmann/json.hpp>

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/tile.h"

namespace spadgen::writers {

// A .npy file (format 1.0, C order) whose shape is known up front; blocks are written at any offset
// from any thread (pwrite), so tiles stream straight to disk and memory stays bounded.
class NpyWriter {
 public:
  enum class Dtype { F32, U8, U16 };
  NpyWriter(const std::string& path, Dtype dtype, std::vector<int64_t> shape);
  ~NpyWriter();
  NpyWriter(const NpyWriter&) = delete;
  NpyWriter& operator=(const NpyWriter&) = delete;

  // Writes `count` elements (raw bytes of this file's dtype) starting at flat element index `offset`.
  void write(int64_t offset, const void* data, int64_t count);
  // For a (K, H, W) stack: writes tile values [k * rect.count() + rect.index(x, y)] where the stack's
  // pixel (x, y) is (x - origin_x, y - origin_y).
  void write_khw(const PixelRect& rect, int origin_x, int origin_y, const void* data);
  void commit();
  const std::string& path() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// A scanline OpenEXR image with named float channels and string attributes (provenance) in its header.
class ExrImage {
 public:
  ExrImage(int width, int height);
  float* channel(const std::string& name);  // created zero-filled on first use; row-major
  void set_attribute(const std::string& key, const std::string& value);
  // Writes the image (ZIP compression) to path atomically.
  void write(const std::string& path) const;
  int width() const { return width_; }
  int height() const { return height_; }

 private:
  int width_, height_;
  std::map<std::string, std::vector<float>> channels_;
  std::map<std::string, std::string> attributes_;
};

// Reads every float channel of an EXR (for tests and for user-supplied maps).
struct ExrData {
  int width = 0, height = 0;
  std::map<std::string, std::vector<float>> channels;
  std::map<std::string, std::string> attributes;
};
ExrData read_exr(const std::string& path);

// 8-bit PNG (gray, RGB or RGBA), written atomically.
void write_png(const std::string& path, int width, int height, int channels, const std::vector<uint8_t>& pixels);
// JSON, pretty-printed, written atomically.
void write_json(const std::string& path, const nlohmann::json& value);
// Any bytes, written atomically (temporary file, fsync, rename).
void write_file_atomic(const std::string& path, const std::string& bytes);

}  // namespace spadgen::writers
