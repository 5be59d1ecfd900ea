#include "app/resources.h"

#include <sys/resource.h>
#include <sys/statvfs.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <string>

#include <tbb/info.h>

#include "app/outputs.h"
#include "core/error.h"
#include "scenes/scene.h"
#include "render/renderer.h"

namespace spadgen::app {
namespace fs = std::filesystem;

namespace {
// A number read from a cgroup file ("max", absent or unreadable: -1).
int64_t cgroup_number(const fs::path& file) {
  std::ifstream in(file);
  std::string text;
  int64_t v = -1;
  if (!(in >> text) || std::from_chars(text.data(), text.data() + text.size(), v).ptr != text.data() + text.size() || v < 0) return -1;
  return v;
}
// A key's value in a cgroup's memory.stat (-1: none).
int64_t cgroup_stat(const fs::path& file, const std::string& key) {
  std::ifstream in(file);
  std::string k;
  for (int64_t v = 0; in >> k >> v;)
    if (k == key) return v;
  return -1;
}
}  // namespace

int64_t cgroup_memory_left(const std::string& proc_self_cgroup, const fs::path& root) {
  int64_t least = -1;
  const auto limit = [&](int64_t max, int64_t usage, int64_t inactive_file) {
    if (max < 0 || usage < 0) return;
    const int64_t left = std::max<int64_t>(0, max - std::max<int64_t>(0, usage - std::max<int64_t>(0, inactive_file)));
    least = least < 0 ? left : std::min(least, left);
  };
  std::istringstream lines(proc_self_cgroup);
  for (std::string line; std::getline(lines, line);) {
    const size_t a = line.find(':'), b = a == std::string::npos ? a : line.find(':', a + 1);
    if (b == std::string::npos) continue;
    const std::string controllers = line.substr(a + 1, b - a - 1), path = line.substr(b + 1);
    if (path.empty() || path[0] != '/' || path.find("/..") != std::string::npos) continue;
    bool v1 = false;
    std::istringstream names(controllers);
    for (std::string name; std::getline(names, name, ',');) v1 = v1 || name == "memory";
    const bool v2 = controllers.empty();
    if (!v2 && !v1) continue;
    // the hierarchy's mount: cgroup v2 at the root (or at unified/ beside v1's), v1's memory controller at memory/
    std::error_code ec;
    fs::path g = v1 ? root / "memory" : fs::exists(root / "cgroup.controllers", ec) ? root : root / "unified";
    // the group and every group above it: each may set a limit
    std::vector<fs::path> groups = {g};
    for (const fs::path& part : fs::path(path).relative_path())
      if (!part.empty() && part != ".") groups.push_back(g /= part);
    for (const fs::path& at : groups)
      if (v2) limit(cgroup_number(at / "memory.max"), cgroup_number(at / "memory.current"), cgroup_stat(at / "memory.stat", "inactive_file"));
      else limit(cgroup_number(at / "memory.limit_in_bytes"), cgroup_number(at / "memory.usage_in_bytes"),
                 cgroup_stat(at / "memory.stat", "total_inactive_file"));
  }
  return least;
}

int64_t available_memory() {
  int64_t available = -1;
  std::ifstream meminfo("/proc/meminfo");
  for (std::string key; meminfo >> key;) {
    int64_t kb = 0;
    meminfo >> kb;
    if (key == "MemAvailable:") available = kb * 1024;
    meminfo.ignore(256, '\n');
  }
  std::ifstream proc("/proc/self/cgroup");
  const std::string groups((std::istreambuf_iterator<char>(proc)), std::istreambuf_iterator<char>());
  if (const int64_t left = cgroup_memory_left(groups, "/sys/fs/cgroup"); left >= 0)
    available = available < 0 ? left : std::min(available, left);
  // and the address-space limit (ulimit -v, SGE's h_vmem): a run planned past it failed after its start with
  // "out of memory" and no figures (an auditor's find). The limit itself, not what it leaves above the process's
  // mappings: a dataset's later samples reuse the heap the earlier ones left mapped, and were refused by it (a
  // reviewer's find). (Virtual, so a run under it may still fail: this refuses only what surely does not fit.)
  if (rlimit lim{}; getrlimit(RLIMIT_AS, &lim) == 0 && lim.rlim_cur != RLIM_INFINITY &&
                    lim.rlim_cur <= rlim_t(std::numeric_limits<int64_t>::max())) {
    const auto limit = static_cast<int64_t>(lim.rlim_cur);
    available = available < 0 ? limit : std::min(available, limit);
  }
  return available;
}

namespace {

std::string join_parts(std::vector<ResourcePlan::Part> parts) {
  std::sort(parts.begin(), parts.end(), [](const auto& a, const auto& b) { return a.bytes > b.bytes; });
  std::string s;
  for (const ResourcePlan::Part& p : parts)
    if (p.bytes > 0) s += (s.empty() ? "" : "; ") + p.what + " " + bytes_text(p.bytes);
  return s;
}

std::vector<ResourcePlan::Part> required(const std::vector<ResourcePlan::Part>& parts) {
  std::vector<ResourcePlan::Part> r;
  for (const ResourcePlan::Part& p : parts)
    if (!p.file_backed) r.push_back(p);
  return r;
}

}  // namespace

fs::path existing_ancestor(fs::path p) {
  std::error_code ec;
  p = fs::absolute(p, ec);
  while (!p.empty() && !fs::exists(p, ec) && p != p.parent_path()) p = p.parent_path();
  return p;
}

int64_t free_disk(fs::path p) {
  p = existing_ancestor(p);
  struct statvfs s {};
  if (p.empty() || ::statvfs(p.c_str(), &s) != 0) return -1;
  // A file system of no blocks (/proc, /sys) stores no files: unknown, so that writing there fails with
  // its own message (it was reported as a full disk, 0 kB free)
  if (s.f_blocks == 0) return -1;
  return static_cast<int64_t>(s.f_bavail) * static_cast<int64_t>(s.f_frsize);
}

int64_t ResourcePlan::memory_needed() const {
  int64_t n = 0;
  for (const Part& p : memory)
    if (!p.file_backed) n += p.bytes;
  return n;
}

LeastParts least_parts(const std::vector<ResourcePlan::Part>& disk) {
  LeastParts l;
  for (const ResourcePlan::Part& p : disk) {
    l.compressed = l.compressed || (p.compressed && p.bytes > 0);
    l.light = l.light || (p.least >= 0 && p.least < p.bytes);
  }
  return l;
}

std::string least_text(LeastParts l) {
  std::string r = l.compressed ? "the compressed files, EXR images, Zarr stores and previews, not counted: zeros compress to "
                                 "almost nothing" : "";
  if (l.light) r += std::string(r.empty() ? "" : ", ") + "the saved light without lit bins";
  return r;
}

int64_t ResourcePlan::Part::at_least() const {
  // A compressed part's least is nothing: no ratio bounds what zeros compress to (a twentieth was counted, and a
  // Zarr transient store of 118 MB took 668 kB: a run that fitted was refused; an auditor's find).
  const int64_t bound = compressed ? 0 : bytes;
  return least >= 0 ? std::min(least, bound) : bound;
}

int64_t ResourcePlan::disk_sum(bool at_least, bool kept_only) const {
  int64_t n = 0;
  for (const Part& p : disk)
    if (!(kept_only && p.freed_at_end)) n += at_least ? p.at_least() : p.bytes;
  return n;
}

// The cores the process may run on (its CPU affinity, as TBB's default arena counts them; taskset, a Slurm
// task's cpuset): every core of the machine had been counted.
int allowed_cores() { return std::max(1, tbb::info::default_concurrency()); }

int64_t worker_threads(int threads) { return threads > 0 ? threads : allowed_cores(); }

int usable_cores(int threads) { return threads > 0 ? std::min(threads, allowed_cores()) : allowed_cores(); }

// The arrival times a pixel's saved light spans, for the plan (outputs.light).
constexpr double kLitSpan_s = 2.5e-9;

Geometry geometry_of(const scenes::Scene& scene) {
  Geometry g{static_cast<int64_t>(scene.triangle_count()), static_cast<int64_t>(scene.meshes.size())};
  std::set<const void*> images;  // textures of one image share its texels
  for (const scenes::Texture& t : scene.textures)
    if (images.insert(t.texels.get()).second) ++g.textures, g.texture_bytes += static_cast<int64_t>(t.rgba().size());
  return g;
}

ResourcePlan plan_resources(const RunConfig& c, const sensor::SensorModel& sensor, const PixelRect& img,
                            const TimeAxis& axis, int threads, const fs::path& out, int objects, const Geometry* geometry, int realisations,
                            std::optional<bool> laser) {
  ResourcePlan plan;
  const int64_t tile = std::min(c.render.tile_size, std::max(img.width, img.height));
  // Threads at work: at most one per tile (a 40 x 40 crop at --threads 1024 was refused for 26.7 GB; it
  // peaks at 118 MB).
  const int64_t tiles = (int64_t(img.width) + tile - 1) / tile * ((int64_t(img.height) + tile - 1) / tile);
  const int64_t T = std::min(worker_threads(threads), std::max<int64_t>(1, tiles));
  // Tiles in flight: one per thread, and one more that a thread waiting inside a tile may start.
  const int64_t in_flight = std::min(T + 1, std::max<int64_t>(1, tiles));
  const int64_t halo = sensor.halo();
  const int64_t tile_pixels = std::min<int64_t>(tile * tile, img.count());
  const int64_t data_pixels = (tile + 2 * halo) * (tile + 2 * halo);
  const int64_t bins = axis.bins, pixels = img.count();
  const std::string th = std::to_string(T) + " threads";

  // A block's samples are traced ahead 64 at a time and its pixels accumulate their bins side by side
  // (render/renderer.cpp).
  constexpr int64_t block = render::Renderer::kBlockPixels;
  const bool adaptive = c.render.target_relative_error.has_value();
  const int ahead = std::min(render::Renderer::kSamplesAhead,
                             adaptive ? std::max(c.render.samples_per_pixel, c.render.max_samples_per_pixel)
                                      : c.render.samples_per_pixel);
  plan.memory.push_back({"camera paths (" + std::to_string(ahead) + " samples traced ahead for " + std::to_string(block) +
                             " pixels, " + th + ")",
                         static_cast<int64_t>(render::Renderer::bytes_per_thread(ahead)) * T});
  const int64_t split = c.render.split_direct_indirect ? 2 : 1;
  plan.memory.push_back({"transient tiles (render.tile_size_px = " + std::to_string(c.render.tile_size) + ", " +
                             std::to_string(bins) + " time bins of render.time_bin_ps, " + th + ")",
                         in_flight * data_pixels * bins * 4 * split + T * bins * 8 * split * block});
  // The sensor's tile: its share of every (K, ...) stack, written or not (the sensor computes them all).
  const std::vector<StackLayout> stacks = stack_layout(c, sensor, img, axis);
  int64_t sensor_tile = 0, resident = 0, bands = 0, chunks = 0;
  const bool in_bands = write_in_bands(stacks, img, c.render.tile_size, threads);
  for (const StackLayout& s : stacks) {
    const bool per_k = s.file.find("transient") == std::string::npos;  // (H, W, T) stacks: the transient tile above
    // the temporal noise's stacks, one per realisation sampled together (sense --repeats: R = 8 with frames
    // peaked at 945 MB against 301 MB planned for one)
    const int64_t copies = s.file.rfind("counts.", 0) == 0 || s.file.rfind("frames.", 0) == 0 ? std::max(1, realisations) : 1;
    if (per_k && (s.written || s.file.rfind("frames.", 0) != 0))
      sensor_tile += copies * (s.bytes() / std::max<int64_t>(1, pixels) * tile_pixels);
    if (!s.written) continue;
    // H: of (K, H, W), (K, N, H, W / 8) and (H, W, T)
    const size_t rows_axis = size_t(std::find_if(s.dims.begin(), s.dims.end(), [](const std::string& d) { return d.front() == 'y'; }) -
                                    s.dims.begin());
    const int64_t rows = std::max<int64_t>(1, s.shape[rows_axis]), row_bytes = s.bytes() / rows;
    // A (K, H, W) .npy and the frames are assembled band by band in memory (write_in_bands, unless the bands
    // are too large); the transients and too large bands are written through a memory map whose completed
    // bands leave the resident set; a Zarr store holds the chunks being filled: for each thread at most its
    // tiles' rows grown to whole chunks.
    const bool banded = s.chunks.empty() && (s.khw() || s.frames()) && in_bands;
    if (banded) bands += copies * std::min(s.bytes(), row_bytes * tile * in_flight);
    else if (s.chunks.empty()) resident += copies * std::min(s.bytes(), row_bytes * tile * in_flight);
    else chunks += copies * row_bytes * std::min(rows, (tile + s.chunks[rows_axis]) * T);
  }
  // And its working arrays over the tile and its halo (sensor/sensor.cpp, process): every pixel's lambda per
  // k, 8 bytes; its own avalanches' probability where crosstalk or frames read it, 8 more; with frames, the
  // (p, q, -lambda) of each, 24 more. At 10,001 gate positions they are most of a tile (a 32 x 32 crop
  // peaked at 311 MB against 222 MB planned without them).
  const bool frames = c.outputs.frames;
  sensor_tile += data_pixels * sensor.K() * (8 + (frames || halo > 0 ? 8 : 0) + (frames ? 24 : 0));
  const std::string each = realisations > 1 ? ", the counts and frames of " + std::to_string(realisations) + " realisations (--repeats)" : "";
  plan.memory.push_back({"sensor tiles (K = " + std::to_string(sensor.K()) + " gate positions or exposures, " + th + each + ")",
                         in_flight * sensor_tile});
  plan.memory.push_back({"bands of (K, H, W) .npy stacks and frames being assembled (camera.width_px, render.tile_size_px, " + th + each + ")", bands});
  plan.memory.push_back({"output pages in flight, file-backed (camera.width_px, render.tile_size_px)", resident, true});
  plan.memory.push_back({"Zarr chunks being filled, at most (camera.width_px, render.tile_size_px, " + th + ")", chunks});
  // EXR images held whole until the end: ground truth (8 channels and 2 per layer, 4 and 5 per object
  // slot), laser (photons, out of window, standard error), ambient (photons, standard error), maps (5),
  // intensity, and in a sweep labels.exr (4 per object slot).
  const int64_t slots = image_object_slots(c.render.max_layers, objects);
  const bool sweep = c.acquisition.mode == AcquisitionMode::GateSweep;
  const int64_t channels = (c.outputs.ground_truth ? 8 + 2 * c.render.max_layers + 4 + 5 * slots : 0) + 3 + 2 + 5 +
                           (sweep ? 0 : 2) + (sweep && c.outputs.ground_truth ? 4 * slots : 0);
  plan.memory.push_back({"images (" + std::to_string(img.width) + " x " + std::to_string(img.height) +
                             " pixels: camera.crop or width_px x height_px; " + std::to_string(channels) +
                             " channels with render.max_layers and the scene's objects)",
                         pixels * channels * 4});
  // The program itself, whatever the image: code, libraries, Embree's and TBB's pools, the sensor's tables
  // (an 8 x 8 crop peaks at about 50 MB of resident memory; measured with /usr/bin/time -v).
  plan.memory.push_back({"the program (code, libraries, Embree and TBB, the sensor's tables)", int64_t{48} << 20});
  if (geometry != nullptr)
    plan.memory.push_back({"the scene's geometry and Embree's BVH (" + std::to_string(geometry->triangles) + " triangles in " +
                               std::to_string(geometry->meshes) + " meshes)",
                           geometry->triangles * kBytesPerTriangle + geometry->meshes * kBytesPerMesh});
  // Decoded textures, shared by the loaded scene and the renderer's copy of it (the test chart's 16.8 MB
  // texture: 252 MB planned against a 267 MB peak on 2 threads).
  if (geometry != nullptr && geometry->texture_bytes > 0)
    plan.memory.push_back({"the scene's textures, decoded (" + std::to_string(geometry->textures) +
                               (geometry->textures == 1 ? " texture" : " textures") + ")",
                           geometry->texture_bytes});
  plan.memory_available = available_memory();

  // A Zarr store is at most its data uncompressed (and a few bytes a chunk).
  for (const StackLayout& s : stacks)
    if (s.written) {
      const bool noise_free = s.file.starts_with("detection_rate.") || s.file.starts_with("expected_counts.") ||
                              s.file.starts_with("transient.");  // (a realisation writes no transient)
      plan.disk.push_back({s.file + (s.chunks.empty() ? "" : " (uncompressed)"), s.bytes(), false, s.file, !s.chunks.empty(), false,
                           noise_free});
    }
  // (a 2D run's intensity.exr, 2 channels, holds counts: a further realisation writes it; the rest it links)
  const bool compressed_images = c.outputs.exr_compression != ExrCompression::None;
  const std::string uncompressed = compressed_images ? " (uncompressed)" : "";
  // (a run that traces no laser writes no laser.exr and no laser channels of the ground truth)
  const int64_t untraced = laser.value_or(laser_traced(c)) ? 0 : 3 + (c.outputs.ground_truth ? 2 + slots : 0);
  plan.disk.push_back({"images" + uncompressed, pixels * (channels - untraced - (sweep ? 0 : 2)) * 4, false, "", compressed_images,
                       false, true});
  if (!sweep) plan.disk.push_back({"intensity.exr" + uncompressed, pixels * 2 * 4, false, "", compressed_images});
  // metadata.json (about 16 kB) and the previews (three PNG images, compressed: at most 3 bytes a pixel each,
  // and the 800 x 450 RGB plot of the gate profiles: 50-200 kB measured, with more curves where pixels see
  // more returns; counted at 256 kB, above all measured (it was 64 kB, and a dataset's small crops took 1.1
  // times the "at most"; an auditor's find), not at its 1.08 MB of pixels, which no plot of lines comes near)
  constexpr int64_t kPlotBytes = int64_t{256} << 10;
  plan.disk.push_back({std::string("metadata.json") + (c.outputs.previews ? " and previews/ (uncompressed)" : ""),
                       kMetadataBytes + std::max(objects, 0) * kMetadataBytesPerObject +
                           (c.outputs.previews ? 9 * pixels + kPlotBytes : 0),
                       false, "", c.outputs.previews});
  if (c.outputs.light) {
    // light/: per pixel of the image grown by one, its bin range, offset, totals, standard errors and paths,
    // and the values of its
    // bins from its first arrival to its last, which the scene decides: on the multi-object scene 113 bins of
    // 9 ps per pixel on average over the image (1.0 ns), up to 2.3 ns over crops of the plate in front of the
    // sphere (where a fixed 128 bins planned a quarter of the disk 1 ps bins took). Planned at 2.5 ns.
    const int64_t ring = (img.width + 2) * (img.height + 2);
    const bool zarr = c.outputs.storage == Storage::Zarr;
    // (the bins' count bounds the span's first: a bin width of 1e-20 ps made it overflow)
    const auto lit = static_cast<int64_t>(std::min(static_cast<double>(bins), std::ceil(kLitSpan_s / c.render.time_bin_s)));
    char span[32];
    std::snprintf(span, sizeof span, "%g", kLitSpan_s * 1e9);
    plan.disk.push_back({std::string("light/ (outputs.light; ") +
                             (bins > 0 ? "about " + std::to_string(lit) + " lit bins per pixel, " + span + " ns" : "no time bins: the totals") +
                             (zarr ? ", uncompressed)" : ")"),
                         ring * (8 + 8 + 8 + 8 + 4 + 4 + 4 + 4 + lit * 4), false, "", zarr, false, true,
                         /*least: no lit bins*/ ring * (8 + 8 + 8 + 8 + 4 + 4 + 4 + 4)});
    // The values are spilled to a temporary file as the tiles finish, in tile order, and copied into
    // light/values (.npy or .zarr) in pixel order at the end: both are on the disk at that moment.
    plan.disk.push_back({std::string("the light's values spilled while the tiles render (outputs.light; freed once light/values") +
                             (zarr ? ".zarr" : ".npy") + " is written)",
                         ring * lit * 4, false, "", false, true, false, /*least*/ 0});
  }
  plan.disk_available = out.empty() ? -1 : free_disk(out);
  return plan;
}

void check_resources(const RunConfig& c, const sensor::SensorModel& sensor, const PixelRect& img, const TimeAxis& axis,
                     int threads, const fs::path& out, int objects, const Geometry* geometry) {
  check_resources(plan_resources(c, sensor, img, axis, threads, out, objects, geometry), c, out);
}

void check_resources(const ResourcePlan& plan, const RunConfig& c, const fs::path& out, const std::string& who,
                     const std::string& remedy) {
  const std::string file = !who.empty() ? who : c.scene_file.empty() ? std::string("<scene>") : c.scene_file;
  std::string memory, disk;
  if (plan.memory_available >= 0 && plan.memory_needed() > plan.memory_available)
    memory = (who.empty() ? file + ": the run" : who) + " needs about " + bytes_text(plan.memory_needed()) + " of memory, and " +
             bytes_text(plan.memory_available) + " is available: " + join_parts(required(plan.memory)) +
             "; lower the keys of the largest parts, or run with fewer --threads";
  // The earlier set in the output folder stays until the new one is complete: the new one needs its
  // whole size free. Compressed stores (Zarr) count nothing here, the saved light no lit
  // bins: refused only when even that does not fit (their size is known once written; a run that then
  // finds the disk full fails cleanly, the folder as it was).
  if (plan.disk_available >= 0 && plan.disk_at_least() > plan.disk_available) {
    const bool any_compressed = plan.disk_at_least() != plan.disk_needed();
    const auto [need, free] = bytes_texts(any_compressed ? plan.disk_at_least() : plan.disk_needed(), plan.disk_available);
    disk = "writes " + (any_compressed ? "at least " + need + " (" + least_text(least_parts(plan.disk)) +
                                             "; at most " + bytes_text(plan.disk_needed()) + ")"
                                       : "about " + need) +
           " into " + out.string() + ", and " + free + " is free there: " + join_parts(plan.disk) +
           "; " + (remedy.empty() ? "switch outputs off (outputs.*), crop (camera.crop), or choose another folder (-o)" : remedy);
  }
  // both said at once (the disk's refusal was hidden behind the memory's)
  if (!memory.empty() && !disk.empty()) throw Error(memory + "; and it " + disk);
  if (!memory.empty()) throw Error(memory);
  if (!disk.empty()) throw Error((who.empty() ? file + ": the run " : who + " ") + disk);
}

std::string resource_summary(const ResourcePlan& plan) {
  std::string s = "memory: about " + bytes_text(plan.memory_needed());
  if (plan.memory_available >= 0) s += " (available: " + bytes_text(plan.memory_available) + ")";
  // (a least of nothing, all of it compressed, is no figure: "up to" the most)
  s += "; disk: " + (plan.disk_at_least() == plan.disk_needed() ? "about " + bytes_text(plan.disk_needed())
                     : plan.disk_at_least() == 0 ? "up to " + bytes_text(plan.disk_needed()) + " (the compressed files counted uncompressed: they take less, zeros almost nothing)"
                     : bytes_text(plan.disk_at_least()) + " to " + bytes_text(plan.disk_needed()) + " (the least: " + least_text(least_parts(plan.disk)) + ")");
  if (plan.disk_available >= 0) s += " (free: " + bytes_text(plan.disk_available) + ")";
  return s + "\n  memory: " + join_parts(plan.memory) + "\n  disk: " + join_parts(plan.disk) + "\n";
}

}  // namespace spadgen::app
