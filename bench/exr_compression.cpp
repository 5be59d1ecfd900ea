// The EXR images of a run folder rewritten with each lossless compression spadgen offers
// (outputs.exr_compression): bytes, write and read time, and a check that every channel reads back bit
// for bit. The images are the run's own, so the figures are those of its scene.
//
//   build/bench/exr_compression RUN_DIR [REPEATS]
//
// Prints one line per image and compression, then the totals; bench/storage.sh calls it.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <unistd.h>
#include <vector>

#include "core/config.h"
#include "core/error.h"
#include "writers/writers.h"

namespace {
namespace fs = std::filesystem;
using spadgen::ExrCompression;

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s RUN_DIR [REPEATS]\n", argv[0]);
    return 2;
  }
  const fs::path run = argv[1];
  const int repeats = argc > 2 ? std::max(1, std::atoi(argv[2])) : 3;
  try {
    std::vector<fs::path> images;
    for (const auto& e : fs::directory_iterator(run))
      if (e.path().extension() == ".exr") images.push_back(e.path());
    std::sort(images.begin(), images.end());
    const fs::path tmp = fs::temp_directory_path() / ("spadgen_exr_compression_" + std::to_string(::getpid()));
    fs::create_directories(tmp);
    std::printf("%-18s %-5s %12s %9s %9s %s\n", "image", "comp", "bytes", "write_s", "read_s", "identical");
    std::vector<double> total_bytes(spadgen::EnumNames<ExrCompression>::values.size()), total_write(total_bytes.size()),
        total_read(total_bytes.size());
    for (const fs::path& p : images) {
      const spadgen::writers::ExrData in = spadgen::writers::read_exr(p.string());
      spadgen::writers::ExrImage image(in.width, in.height);
      for (const auto& [name, values] : in.channels) std::copy(values.begin(), values.end(), image.channel(name));
      for (const auto& [key, value] : in.attributes) image.set_attribute(key, value);
      size_t ci = 0;
      for (const auto& [cname, c] : spadgen::EnumNames<ExrCompression>::values) {
        const fs::path out = tmp / (p.stem().string() + "." + std::string(cname) + ".exr");
        double write_s = 1e30, read_s = 1e30;  // the fastest of the repeats
        bool identical = true;
        for (int r = 0; r < repeats; ++r) {
          auto t0 = std::chrono::steady_clock::now();
          image.write(out.string(), c);
          write_s = std::min(write_s, seconds_since(t0));
          t0 = std::chrono::steady_clock::now();
          const spadgen::writers::ExrData back = spadgen::writers::read_exr(out.string());
          read_s = std::min(read_s, seconds_since(t0));
          for (const auto& [name, values] : in.channels)
            identical = identical && back.channels.count(name) &&
                        std::memcmp(back.channels.at(name).data(), values.data(), values.size() * sizeof(float)) == 0;
        }
        const auto bytes = double(fs::file_size(out));
        std::printf("%-18s %-5s %12.0f %9.3f %9.3f %s\n", p.filename().c_str(), std::string(cname).c_str(), bytes, write_s,
                    read_s, identical ? "yes" : "NO");
        total_bytes[ci] += bytes, total_write[ci] += write_s, total_read[ci] += read_s;
        ++ci;
      }
    }
    size_t ci = 0;
    for (const auto& [cname, c] : spadgen::EnumNames<ExrCompression>::values) {
      std::printf("%-18s %-5s %12.0f %9.3f %9.3f\n", "all images", std::string(cname).c_str(), total_bytes[ci], total_write[ci],
                  total_read[ci]);
      ++ci;
    }
    fs::remove_all(tmp);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "exr_compression: %s\n", e.what());
    return 1;
  }
  return 0;
}
