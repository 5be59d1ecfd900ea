// The resource plan of a run: the memory and the disk it will need, worked out from the scene file's keys
// before any work, against what the machine has (available memory, the cgroup's limit, free disk at the
// output folder). A run that cannot fit is refused with the figures and the keys that drive them, instead
// of failing with std::bad_alloc or a full disk after minutes of work. The figures are estimates of the
// largest parts, not a bound on every byte.
#pragma once
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/config.h"
#include "core/tile.h"
#include "core/time_axis.h"
#include "core/units.h"  // bytes_text, bytes_texts
#include "sensor/sensor.h"

namespace spadgen::scenes {
struct Scene;
}  // namespace spadgen::scenes

namespace spadgen::app {

// What the process's memory cgroups still allow, in bytes (-1: no limit found): the least, over every group
// of its lines of /proc/self/cgroup (cgroup v2's "0::/path" and v1's memory controller) and the groups above
// each, of the limit less the usage not reclaimable (less the inactive file cache). root: where the cgroup
// file systems are mounted (/sys/fs/cgroup). A Slurm job's --mem, a systemd slice, a container's limit; only
// the namespace's root group had been read (memory.max), so a run past a job's limit was killed, not refused.
int64_t cgroup_memory_left(const std::string& proc_self_cgroup, const std::filesystem::path& root);

// MemAvailable of /proc/meminfo, lowered to what the process's memory cgroups still allow and to an
// address-space limit (ulimit -v); -1 unknown.
int64_t available_memory();

struct ResourcePlan {
  struct Part {
    std::string what;  // "camera paths of 2 threads", with the keys that drive it
    int64_t bytes = 0;
    bool file_backed = false;  // memory-mapped output pages the kernel can write out: shown, not required
    std::string file = "";     // a disk part that is one output (a stack's file or Zarr folder); "" otherwise
    bool compressed = false;   // a disk part written compressed (Zarr, EXR): `bytes` is its uncompressed size, at most
    bool freed_at_end = false; // a disk part the run frees before it ends (a temporary file): its peak, not kept
    // A disk part that a further realisation of the temporal noise (sense --noise-seed, a dataset's repeats)
    // links from the run rather than writes: the light, the noise-free stacks, a gate sweep's images.
    bool noise_free = false;
    // The least the part can take when the scene decides its size (the saved light's lit bins: a pixel may
    // have none); -1: `bytes`, or a compressed part's bound.
    int64_t least = -1;
    int64_t at_least() const;  // least, else bytes (a compressed part: 0)
  };
  std::vector<Part> memory, disk;
  int64_t memory_available = -1;  // bytes; -1 unknown
  int64_t disk_available = -1;    // bytes free at the output folder; -1 unknown
  int64_t memory_needed() const;
  int64_t disk_needed() const { return disk_sum(false, false); }  // at most: compressed parts at their uncompressed size
  // At least: compressed parts not counted (no ratio bounds what they compress to: a transient store of
  // mostly zeros took 1/176 to 1/611 of its size; the rates compress about 3 times). A run is refused when even
  // this does not fit; between the two it may fit.
  int64_t disk_at_least() const { return disk_sum(true, false); }
  // What stays once the run has ended (without the temporary parts): at most, and at least.
  int64_t disk_kept() const { return disk_sum(false, true); }
  int64_t disk_kept_at_least() const { return disk_sum(true, true); }

 private:
  int64_t disk_sum(bool at_least, bool kept_only) const;
};
// What makes disk_at_least() less than disk_needed(): compressed parts, the saved light (its lit bins), and
// the words for them ("the compressed files, ... not counted", "the saved light without lit bins").
struct LeastParts {
  bool compressed = false, light = false;
};
LeastParts least_parts(const std::vector<ResourcePlan::Part>& disk);
std::string least_text(LeastParts parts);

// The worker threads of --threads (0: all cores).
int64_t worker_threads(int threads);
// The cores a run with --threads `threads` (0: all) can use: at most the machine's (metadata.json run.cores;
// the dataset estimates are for them).
int usable_cores(int threads);

// Memory of the scene's geometry in a run: its meshes and Embree's BVH, per triangle and per mesh (2,000,000
// triangles in one mesh peaked 384 MB above an 8 x 8 crop's 50 MB; 100,000 meshes of 2 triangles 444 MB).
inline constexpr int64_t kBytesPerTriangle = 200, kBytesPerMesh = 4096;
// metadata.json's size: 32 kB, and its list of the scene's objects (100,000 objects: 17 MB).
inline constexpr int64_t kMetadataBytes = 32 << 10, kMetadataBytesPerObject = 256;

// The size of a loaded scene's geometry, for a plan of a run's peak before the scene is in memory (info, a
// dataset's estimates).
struct Geometry {
  int64_t triangles = 0, meshes = 0;
  int64_t textures = 0, texture_bytes = 0;  // decoded RGBA images (textures of one image count it once)
};
Geometry geometry_of(const scenes::Scene& scene);

// threads: as --threads (0 = all cores). out: the output folder ("" = no disk check). objects: the scene's
// objects (scenes::objects_of), which bound the object slots of the images and size metadata.json; -1 unknown
// (render.max_layers). geometry: the scene's, when it is not in memory yet. realisations: of the temporal
// noise sampled together (sense --repeats), each with its own counts and frames in the tiles and bands.
ResourcePlan plan_resources(const RunConfig& c, const sensor::SensorModel& sensor, const PixelRect& img,
                            const TimeAxis& axis, int threads, const std::filesystem::path& out, int objects = -1,
                            const Geometry* geometry = nullptr, int realisations = 1, std::optional<bool> laser = {});

// Throws spadgen::Error, with the figures and the keys of the largest parts, when the run needs more
// memory or disk than there is.
void check_resources(const RunConfig& c, const sensor::SensorModel& sensor, const PixelRect& img, const TimeAxis& axis,
                     int threads, const std::filesystem::path& out, int objects = -1, const Geometry* geometry = nullptr);
// The same for a plan already made (spadgen sense adjusts its disk: linked files, realisations). `who`
// begins the messages (the scene file when empty); `remedy` replaces the disk message's advice when given.
void check_resources(const ResourcePlan& plan, const RunConfig& c, const std::filesystem::path& out,
                     const std::string& who = {}, const std::string& remedy = {});

// "memory: about 270 MB (available: 5.1 GB); disk: about 0.9 GB" for spadgen info.
std::string resource_summary(const ResourcePlan& plan);

// Free bytes for an unprivileged writer on the file system the folder `p` is (or will be) on: its nearest
// existing ancestor's; -1 when unknown.
int64_t free_disk(std::filesystem::path p);
// p made absolute, or the nearest folder above it that exists (a folder a run will create); "" if none.
std::filesystem::path existing_ancestor(std::filesystem::path p);


}  // namespace spadgen::app
