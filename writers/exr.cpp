#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCompression.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfIO.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfThreading.h>

#include <cstdio>
#include <exception>
#include <limits>

#include "core/error.h"
#include "writers/atomic_file.h"
#include "writers/writers.h"

namespace spadgen::writers {
namespace {

// Streams OpenEXR's output into our temporary file, so the same fsync-and-rename path (and the same
// errno-based messages) serve every format.
class FdOStream : public Imf::OStream {
 public:
  FdOStream(int fd, const std::string& path) : Imf::OStream(path.c_str()), fd_(fd), path_(path) {}
  void write(const char c[], int n) override {
    detail::pwrite_all(fd_, c, static_cast<uint64_t>(n), pos_, path_);
    pos_ += static_cast<uint64_t>(n);
  }
  uint64_t tellp() override { return pos_; }
  void seekp(uint64_t pos) override { pos_ = pos; }

 private:
  int fd_;
  std::string path_;
  uint64_t pos_ = 0;
};

}  // namespace

ExrImage::ExrImage(int width, int height) : width_(width), height_(height) {
  if (width < 1 || height < 1)
    throw Error("an EXR image needs at least one pixel, got " + std::to_string(width) + "x" + std::to_string(height));
}

float* ExrImage::channel(const std::string& name) {
  if (name.empty()) throw Error("an EXR channel needs a name");
  auto it = channels_.find(name);
  if (it == channels_.end())
    it = channels_.emplace(name, LargeBuffer<float>(size_t(width_) * size_t(height_), 0.0f)).first;
  return it->second.data();
}

void ExrImage::remove_channel(const std::string& name) { channels_.erase(name); }

void ExrImage::set_attribute(const std::string& key, const std::string& value) {
  if (key.empty()) throw Error("an EXR attribute needs a name");
  // The standard attributes (channels, compression, dataWindow, ...) have fixed types; a string under
  // one of those names would make the header unwritable.
  const Imf::Header standard(1, 1);
  if (standard.find(key) != standard.end())
    throw Error("EXR attribute name '" + key + "' is reserved by the OpenEXR header");
  attributes_[key] = value;
}

namespace {

Imf::Compression exr_compression(ExrCompression c) {
  switch (c) {
    case ExrCompression::None: return Imf::NO_COMPRESSION;
    case ExrCompression::Rle: return Imf::RLE_COMPRESSION;
    case ExrCompression::Zips: return Imf::ZIPS_COMPRESSION;
    case ExrCompression::Zip: return Imf::ZIP_COMPRESSION;
  }
  return Imf::ZIP_COMPRESSION;
}

}  // namespace

void ExrImage::write(const std::string& path, ExrCompression compression) const {
  Imf::Header header(width_, height_);
  header.compression() = exr_compression(compression);
  for (const auto& [key, value] : attributes_) header.insert(key, Imf::StringAttribute(value));
  Imf::FrameBuffer fb;
  const size_t xs = sizeof(float), ys = sizeof(float) * size_t(width_);
  for (const auto& [name, values] : channels_) {
    header.channels().insert(name, Imf::Channel(Imf::FLOAT));
    // OpenEXR's interface takes a mutable pointer even for writing; it only reads through it.
    fb.insert(name, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(values.data())), xs, ys));
  }
  detail::TempFile file(path);
  try {
    FdOStream os(file.fd(), path);
    Imf::OutputFile out(os, header);
    out.setFrameBuffer(fb);
    out.writePixels(height_);
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error("cannot write EXR '" + path + "': " + e.what());
  }
  file.commit();
}

void set_exr_threads(int threads) { Imf::setGlobalThreadCount(threads > 0 ? threads : 0); }

ExrData read_exr(const std::string& path) {
  ExrData data;
  detail::require_regular_file(path);  // (a FIFO would block OpenEXR's open)
  try {
    Imf::InputFile in(path.c_str());
    const Imf::Header& h = in.header();
    const Imath::Box2i dw = h.dataWindow();
    const int64_t w = int64_t(dw.max.x) - dw.min.x + 1, hh = int64_t(dw.max.y) - dw.min.y + 1;
    if (w < 1 || hh < 1 || w > std::numeric_limits<int>::max() || hh > std::numeric_limits<int>::max())
      throw Error("EXR '" + path + "' has an empty or oversized data window");
    data.width = int(w);
    data.height = int(hh);
    if (const Imath::Box2i disp = h.displayWindow(); disp != dw) {
      const auto box = [](const Imath::Box2i& b) {
        char text[96];
        std::snprintf(text, sizeof text, "(%d, %d)-(%d, %d)", b.min.x, b.min.y, b.max.x, b.max.y);
        return std::string(text);
      };
      data.partial_window = "data window " + box(dw) + " is not its display window " + box(disp);
    }
    Imf::FrameBuffer fb;
    for (auto it = h.channels().begin(); it != h.channels().end(); ++it) {
      if (it.channel().xSampling != 1 || it.channel().ySampling != 1)
        throw Error("EXR '" + path + "': channel '" + it.name() + "' is subsampled, which is not supported");
      auto& values = data.channels[it.name()];
      values.assign(size_t(w) * size_t(hh), 0.0f);
      fb.insert(it.name(), Imf::Slice::Make(Imf::FLOAT, values.data(), dw));
    }
    in.setFrameBuffer(fb);
    in.readPixels(dw.min.y, dw.max.y);
    for (auto it = h.begin(); it != h.end(); ++it)
      if (const auto* s = dynamic_cast<const Imf::StringAttribute*>(&it.attribute()))
        data.attributes[it.name()] = s->value();
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error("cannot read EXR '" + path + "': " + e.what());
  }
  return data;
}

}  // namespace spadgen::writers
