// The output layout: every file a run writes (EXR images, NumPy stacks, previews), when it is written,
// its type, shape and units, and how the tiles fill it. Adding an output file is a change here only:
// metadata.json lists, and the staging folder publishes, whatever files() holds. Files that only one
// acquisition mode has are those the mode declares (sensor::Acquisition::outputs()).
#pragma once
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "app/metadata.h"
#include "core/config.h"
#include "core/tile.h"
#include "core/time_axis.h"
#include "sensor/acquisition/acquisition.h"
#include "sensor/sensor.h"
#include "writers/writers.h"

namespace spadgen::app {

class Staging;

// The object slots the images hold: render.max_layers, or the scene's objects when fewer (objects < 0:
// unknown), at least one (labels.exr keeps slot 0 when nothing is in view).
inline int image_object_slots(int max_layers, int objects) {
  return objects < 0 ? max_layers : std::max(1, std::min(max_layers, objects));
}

// The stacks, in the order metadata.json lists them; they index stack_layout().
enum Stack : size_t { kExpectedCounts, kDetectionRate, kCounts, kFrames, kTransient, kTransientIndirect, kStackCount };

struct StackLayout {
  std::string file;  // relative to the output folder: "counts.npy", or "counts.zarr" with outputs.storage = zarr
  writers::Dtype dtype;
  std::vector<int64_t> shape;
  bool written = false;  // the scene file's outputs ask for it
  // A Zarr store's chunks (fixed per stack, whatever the tiles and threads); empty: a .npy file.
  std::vector<int64_t> chunks;
  // What an element is, its unit and the names of the dimensions (a Zarr store's .zattrs).
  std::string what, unit;
  std::vector<std::string> dims;
  // Bytes of data, without the header (uncompressed).
  int64_t bytes() const;
  // A (K, H, W) stack: an image per gate position or exposure (expected counts, detection rate, counts).
  bool khw() const { return dims.size() == 3 && dims.front() == "k"; }
  // The (K, N, H, W / 8) bit-packed frames.
  bool frames() const { return dims.size() == 4 && dims[1] == "n"; }
};

// Every stack a run of this scene can write, written or not, indexed by Stack.
std::vector<StackLayout> stack_layout(const RunConfig& c, const sensor::SensorModel& sensor, const PixelRect& img,
                                      const TimeAxis& axis);
// Opens a stack for writing at `path`: a .npy file, or a Zarr store with its attributes.
std::unique_ptr<writers::StackWriter> open_stack(const StackLayout& s, const std::string& path);
// What metadata.json records of a stack's container: its format, and a Zarr store's chunks and compressor.
nlohmann::json storage_json(const StackLayout& s);
// Makes `folder` (relative to the output folder, "" for it) a Zarr group holding the stores in it: writes
// its .zgroup and lists it in `files`. Then zarr.open(run folder) and xarray.open_zarr open them together.
void write_zarr_group(const Staging& staging, const std::string& folder, std::vector<std::string>& files);

// Whether the (K, H, W) .npy stacks and the frames are assembled band by band in memory (one pwrite per
// gate position; the frames' rows gathered whole, writers::NpyWriter::write_frames_band) or written
// through a mapping of the file: in bands while the bands in
// flight (one per thread and one more) take at most kBandMemory, else through the mapping, whose pages the
// kernel can write out and drop while a band is still open (a sweep of 100,000 gate positions has bands
// of tens of GB). The files are the same bytes either way. threads: as --threads (0 = all cores).
inline constexpr int64_t kBandMemory = int64_t(2) << 30;
bool write_in_bands(const std::vector<StackLayout>& layout, const PixelRect& img, int tile_size, int threads);

class Outputs {
 public:
  // Opens the stacks in the staging folder (the tiles stream into them) and allocates the images.
  // objects: the scene's objects (scenes::objects_of), so that the images hold no more object slots.
  // provided: files another folder already holds (spadgen sense --repeats links them): not written here.
  // threads: as --threads (0 = all cores), for write_in_bands. laser: whether the light holds the laser's
  // (laser_traced of the run that rendered it): else no laser.exr and no laser channels in the ground truth.
  Outputs(const RunConfig& c, const sensor::SensorModel& sensor, const PixelRect& img, const TimeAxis& axis,
          const Staging& staging, int objects, int threads, bool laser, const std::set<std::string>& provided = {});
  ~Outputs();
  Outputs(const Outputs&) = delete;
  Outputs& operator=(const Outputs&) = delete;

  // One tile's data; called from several threads at once, for disjoint tiles.
  void put_ground_truth(const GroundTruthTile& g);
  // Whether the run writes labels.exr (a gate sweep with the ground truth at hand), and one tile of it.
  bool labels() const;
  void put_labels(const ObjectLabelsTile& l);
  // The tile's frames are kept (moved) until its band of tiles is written.
  void put(const TransientTile& t, const sensor::SensorMapsTile& m, SensorTile&& s);

  // After the last tile: the images, stamped with their provenance, and the previews into the staging folder.
  void write(const Provenance& p);
  // Completes the stacks; the last step before publishing.
  void commit();

  // Written so far, relative to the output folder, in the order metadata.json lists them.
  const std::vector<std::string>& files() const { return files_; }
  // What metadata.json reports about the outputs (totals, layers, dtypes, crops, probed pixels).
  void report(RunRecord& r) const;

 private:
  class Images;
  class Stacks;
  class ProfileProbe;

  const RunConfig& cfg_;
  TimeAxis axis_;
  std::vector<double> gate_positions_s_;
  std::vector<sensor::DeclaredOutput> declared_;
  const Staging& staging_;
  std::vector<std::string> files_;
  std::unique_ptr<Images> images_;
  std::unique_ptr<Stacks> stacks_;
  std::unique_ptr<ProfileProbe> probe_;
  std::atomic<float> laser_open_rate_{0.0f};  // of the sensor's tiles (SensorTile::laser_open_rate)
};

}  // namespace spadgen::app
