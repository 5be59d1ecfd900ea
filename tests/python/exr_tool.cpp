// The C++ side of the Python EXR reader's tests, through the OpenEXR library itself:
//   exr_tool dump IN.exr OUT_DIR
//       every channel of IN.exr, read by OpenEXR in its stored type, as OUT_DIR/<channel>.bin (raw
//       little-endian samples, row-major over the data window), OUT_DIR/channels.txt (one line per
//       channel: name, type, width, height) and OUT_DIR/attributes.txt (one line per string attribute:
//       name, a tab, value);
//   exr_tool write OUT.exr COMPRESSION [tiled] [decreasing]
//       a fixture with HALF, FLOAT and UINT channels whose values follow fixture_value() below (the test
//       repeats the formula), on a 37 x 41 data window that starts at (3, -2), so chunks of 16 and 32
//       lines end with a partial one; COMPRESSION is an OpenEXR name (NONE, RLE, ZIPS, ZIP, PIZ, ...).
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCompression.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfTiledOutputFile.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <fstream>
#include <limits>
#include <map>
#include <string>
#include <vector>

namespace {

constexpr int kX0 = 3, kY0 = -2, kWidth = 37, kHeight = 41;

// Pixel (x, y) of the data window (0-based) of each fixture channel. Python's test holds the same formulas.
double fixture_value(const std::string& channel, int x, int y) {
  const double i = y * kWidth + x;
  if (channel == "half") return (x == 0 && y == 0) ? 65504.0 : (x == 1 && y == 0) ? -std::numeric_limits<double>::infinity()
                                : (i - 700.0) / 8.0;
  if (channel == "float") return (x == 0 && y == 1) ? std::numeric_limits<double>::infinity() : std::sin(i) * 1e3 + i * 1e-3;
  if (channel == "layer0.range") return 0.45 + 1e-4 * i;
  return 4294967295.0 - i * 104729.0;  // "uint": large values a float would round
}

const std::map<std::string, Imf::PixelType> kFixtureChannels = {
    {"half", Imf::HALF}, {"float", Imf::FLOAT}, {"layer0.range", Imf::FLOAT}, {"uint", Imf::UINT}};

int dump(const std::string& in, const std::string& dir) {
  Imf::InputFile file(in.c_str());
  const Imath::Box2i dw = file.header().dataWindow();
  const int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
  const size_t n = size_t(w) * size_t(h);
  std::map<std::string, std::vector<char>> buffers;
  std::ofstream list(dir + "/channels.txt");
  Imf::FrameBuffer fb;
  for (auto it = file.header().channels().begin(); it != file.header().channels().end(); ++it) {
    const Imf::PixelType t = it.channel().type;
    const size_t bytes = t == Imf::HALF ? 2 : 4;
    auto& buf = buffers[it.name()];
    buf.assign(n * bytes, 0);
    // Slice::Make places pixel (dw.min.x, dw.min.y) at the start of the buffer.
    fb.insert(it.name(), Imf::Slice::Make(t, buf.data(), dw));
    list << it.name() << ' ' << (t == Imf::HALF ? "HALF" : t == Imf::FLOAT ? "FLOAT" : "UINT") << ' ' << w << ' ' << h << '\n';
  }
  file.setFrameBuffer(fb);
  file.readPixels(dw.min.y, dw.max.y);
  std::ofstream attributes(dir + "/attributes.txt");
  for (auto it = file.header().begin(); it != file.header().end(); ++it)
    if (const auto* a = dynamic_cast<const Imf::StringAttribute*>(&it.attribute()))
      attributes << it.name() << '\t' << a->value() << '\n';
  for (const auto& [name, buf] : buffers) {
    std::ofstream out(dir + "/" + name + ".bin", std::ios::binary);
    out.write(buf.data(), std::streamsize(buf.size()));
  }
  return 0;
}

int write(const std::string& out, const std::string& compression, bool tiled, bool decreasing) {
  Imf::Compression c = Imf::NUM_COMPRESSION_METHODS;
  const std::map<std::string, Imf::Compression> names = {
      {"NONE", Imf::NO_COMPRESSION},   {"RLE", Imf::RLE_COMPRESSION},   {"ZIPS", Imf::ZIPS_COMPRESSION},
      {"ZIP", Imf::ZIP_COMPRESSION},   {"PIZ", Imf::PIZ_COMPRESSION},   {"PXR24", Imf::PXR24_COMPRESSION},
      {"B44", Imf::B44_COMPRESSION},   {"B44A", Imf::B44A_COMPRESSION}, {"DWAA", Imf::DWAA_COMPRESSION},
      {"DWAB", Imf::DWAB_COMPRESSION}};
  if (auto it = names.find(compression); it != names.end()) c = it->second;
  if (c == Imf::NUM_COMPRESSION_METHODS) {
    std::fprintf(stderr, "exr_tool: unknown compression '%s'\n", compression.c_str());
    return 2;
  }
  const Imath::Box2i dw({kX0, kY0}, {kX0 + kWidth - 1, kY0 + kHeight - 1});
  Imf::Header header(dw, dw);
  header.compression() = c;
  if (decreasing) header.lineOrder() = Imf::DECREASING_Y;
  header.insert("spadgen_fixture", Imf::StringAttribute("written by exr_tool"));
  std::map<std::string, std::vector<char>> buffers;
  Imf::FrameBuffer fb;
  for (const auto& [name, type] : kFixtureChannels) {
    header.channels().insert(name, Imf::Channel(type));
    auto& buf = buffers[name];
    buf.resize(size_t(kWidth) * kHeight * (type == Imf::HALF ? 2 : 4));
    for (int y = 0; y < kHeight; ++y)
      for (int x = 0; x < kWidth; ++x) {
        const double v = fixture_value(name, x, y);
        const size_t i = size_t(y) * kWidth + size_t(x);
        if (type == Imf::HALF) {
          const half hv(static_cast<float>(v));
          std::memcpy(buf.data() + 2 * i, &hv, 2);
        } else if (type == Imf::FLOAT) {
          const float fv = static_cast<float>(v);
          std::memcpy(buf.data() + 4 * i, &fv, 4);
        } else {
          const auto uv = static_cast<uint32_t>(v);
          std::memcpy(buf.data() + 4 * i, &uv, 4);
        }
      }
    fb.insert(name, Imf::Slice::Make(type, buf.data(), dw));
  }
  if (tiled) {
    header.setTileDescription(Imf::TileDescription(16, 16));
    Imf::TiledOutputFile file(out.c_str(), header);
    file.setFrameBuffer(fb);
    file.writeTiles(0, file.numXTiles() - 1, 0, file.numYTiles() - 1);
  } else {
    Imf::OutputFile file(out.c_str(), header);
    file.setFrameBuffer(fb);
    file.writePixels(kHeight);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const std::vector<std::string> a(argv + 1, argv + argc);
    if (a.size() == 3 && a[0] == "dump") return dump(a[1], a[2]);
    if (a.size() >= 3 && a[0] == "write") {
      bool tiled = false, decreasing = false;
      for (size_t i = 3; i < a.size(); ++i) {
        if (a[i] == "tiled") tiled = true;
        else if (a[i] == "decreasing") decreasing = true;
        else return std::fprintf(stderr, "exr_tool: unknown option '%s'\n", a[i].c_str()), 2;
      }
      return write(a[1], a[2], tiled, decreasing);
    }
    std::fprintf(stderr, "usage: exr_tool dump IN.exr OUT_DIR | exr_tool write OUT.exr COMPRESSION [tiled] [decreasing]\n");
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "exr_tool: %s\n", e.what());
    return 1;
  }
}
