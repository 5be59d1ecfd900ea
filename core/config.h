// The resolved run description: every section of a scene file, converted to SI units, every default
// explicit. scenes/ parses and validates the JSON into this; render/, sensor/ and writers/ read it.
// Scene-file key names (with their units) are given beside each field; docs/scene-file.md documents them.
#pragma once
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "tile.h"
#include "units.h"

namespace spadgen {

using Vec3d = std::array<double, 3>;

// The choices a scene file spells as strings are enums inside the code. Each enum's spellings are listed
// once, in EnumNames<E>::values (scene-file spelling, value); the schema, the error messages, the docs
// and metadata.json all read them from there.
template <class E>
struct EnumNames;

enum class Beam { Flood, Cone, GltfLight };
template <>
struct EnumNames<Beam> {
  static constexpr std::array<std::pair<std::string_view, Beam>, 3> values{
      {{"flood", Beam::Flood}, {"cone", Beam::Cone}, {"gltf_light", Beam::GltfLight}}};
};

enum class GateEdge { Linear, Smooth };
template <>
struct EnumNames<GateEdge> {
  static constexpr std::array<std::pair<std::string_view, GateEdge>, 2> values{
      {{"linear", GateEdge::Linear}, {"smooth", GateEdge::Smooth}}};
};

// Which pixel design the rows have; sensor/pixel_layout.h decides row by row.
enum class PixelPreset { PixelA, PixelB, FullChip };
template <>
struct EnumNames<PixelPreset> {
  static constexpr std::array<std::pair<std::string_view, PixelPreset>, 3> values{
      {{"pixel_A", PixelPreset::PixelA}, {"pixel_B", PixelPreset::PixelB}, {"full_chip", PixelPreset::FullChip}}};
};

enum class AcquisitionMode { GateSweep, Intensity };
template <>
struct EnumNames<AcquisitionMode> {
  static constexpr std::array<std::pair<std::string_view, AcquisitionMode>, 2> values{
      {{"gate_sweep", AcquisitionMode::GateSweep}, {"intensity", AcquisitionMode::Intensity}}};
};

enum class Exposure { Single, Dual };
template <>
struct EnumNames<Exposure> {
  static constexpr std::array<std::pair<std::string_view, Exposure>, 2> values{
      {{"single", Exposure::Single}, {"dual", Exposure::Dual}}};
};

// render.quality: a preset of the sampling keys (docs/accuracy.md); custom leaves them as the scene file
// gives them (or their defaults). A key the scene file or --set gives wins over its preset's value.
enum class Quality { Custom, Draft, Standard, Reference };
template <>
struct EnumNames<Quality> {
  static constexpr std::array<std::pair<std::string_view, Quality>, 4> values{
      {{"custom", Quality::Custom}, {"draft", Quality::Draft}, {"standard", Quality::Standard}, {"reference", Quality::Reference}}};
};

// The container of the output stacks (docs/outputs.md, "Storage").
enum class Storage { Npy, Zarr };
template <>
struct EnumNames<Storage> {
  static constexpr std::array<std::pair<std::string_view, Storage>, 2> values{{{"npy", Storage::Npy}, {"zarr", Storage::Zarr}}};
};

// OpenEXR's lossless compressions of 32-bit float channels that the Python package's reader reads too (PIZ,
// the other one, made the images 5 % larger than ZIP: docs/outputs.md, "Storage").
enum class ExrCompression { None, Rle, Zips, Zip };
template <>
struct EnumNames<ExrCompression> {
  static constexpr std::array<std::pair<std::string_view, ExrCompression>, 4> values{
      {{"none", ExrCompression::None}, {"rle", ExrCompression::Rle}, {"zips", ExrCompression::Zips}, {"zip", ExrCompression::Zip}}};
};

// The scene-file spelling of an enum value.
template <class E>
constexpr std::string_view name_of(E e) {
  for (const auto& [name, value] : EnumNames<E>::values)
    if (value == e) return name;
  return "?";
}
template <class E>
std::string to_string(E e) {
  return std::string(name_of(e));
}

struct CameraConfig {
  std::string gltf_camera;          // camera.gltf_camera: name of a glTF camera node; "" = defined here
  Vec3d position_m{0, 0, 0};        // camera.position_m
  Vec3d look_at_m{0, 0, -1};        // camera.look_at_m
  Vec3d up{0, 1, 0};                // camera.up
  int width_px = 1024;              // camera.width_px
  int height_px = 500;              // camera.height_px
  double pixel_pitch_m = 9.4e-6;    // camera.pixel_pitch_um
  double focal_length_m = 12e-3;    // camera.focal_length_mm (ignored when vertical_fov_deg is set)
  std::optional<double> vertical_fov_rad;  // camera.vertical_fov_deg (null: from focal length)
  double f_number = 1.4;            // camera.f_number
  double optics_transmission = 1.0; // camera.optics_transmission, fraction of light the lens passes
  std::optional<PixelRect> crop;    // camera.crop [x0, y0, width, height]: render only this region

  bool operator==(const CameraConfig&) const = default;
};

struct LaserConfig {
  double average_power_W = 2e-3;        // laser.average_power_mW
  double repetition_rate_Hz = 40e6;     // laser.repetition_rate_MHz
  double wavelength_m = 637e-9;         // laser.wavelength_nm
  double pulse_fwhm_s = 80e-12;         // laser.pulse_fwhm_ps (Gaussian)
  std::string pulse_shape_csv;          // laser.pulse_shape_csv: table (time_ps, relative power); "" = Gaussian
  double emission_delay_s = 0.0;        // laser.emission_delay_ns: trigger to pulse emission
  Beam beam = Beam::Flood;              // laser.beam: flood (cone covering the field of view),
                                        //   cone (half_angle_deg), gltf_light (a KHR_lights_punctual light)
  double half_angle_rad = 10.0 * kPi / 180.0;  // laser.half_angle_deg (beam cone)
  Vec3d offset_m{0, 0, 0};              // laser.offset_m, in camera coordinates (x right, y up, -z forward)
  std::string gltf_light;               // laser.gltf_light: light name (beam "gltf_light")

  bool operator==(const LaserConfig&) const = default;
};

struct AmbientConfig {
  double illuminance_lux = 0.0;         // ambient.illuminance_lux: uniform environment, equal-energy spectrum
  // ambient.spectral_irradiance_W_m2_nm: the same environment given radiometrically (irradiance on a
  // surface facing it, per nm, flat over the band); when set it replaces illuminance_lux.
  std::optional<double> spectral_irradiance_W_m2_nm;
  double wavelength_m = 550e-9;         // ambient.wavelength_nm: centre of the band the camera sees
  double bandwidth_m = 300e-9;          // ambient.bandwidth_nm: width of that band (filter or sensor)
  bool gltf_lights = true;              // ambient.gltf_lights: glTF punctual lights also light the scene

  bool operator==(const AmbientConfig&) const = default;
};

// One pixel design of the chip. The defaults are the paper's pixel A; paper_pixel_B() is its pixel B
// (Table 1, section 4.A and supplementary note S2), but for the DCR distribution's shape (log sigma, hot pixels),
// which are spadgen's choices (docs/sensor.md, "Where the defaults come from").
struct PixelTypeConfig {
  double fill_factor = 0.07;            // fill_factor
  double pdp_peak = 0.105;              // pdp_peak, at pdp_peak_wavelength_nm
  double pdp_peak_wavelength_m = 520e-9;
  std::string pdp_csv;                  // pdp_csv: table (wavelength_nm, PDP); "" = built-in curve scaled to pdp_peak
  double pdp_nonuniformity = 0.014;     // pdp_nonuniformity: relative spread (sigma) of PDP across pixels
  double dcr_median_cps = 0.4;          // dcr_median_cps at room temperature: the chip's median, hot pixels included
  double dcr_log_sigma = 1.0;           // dcr_log_sigma: spread of log(DCR) of the main population
  double hot_pixel_fraction = 0.05;     // hot_pixel_fraction
  double hot_pixel_factor = 100.0;      // hot_pixel_factor: median hot-pixel DCR / the main population's median
  double crosstalk_probability = 0.0017;  // crosstalk_probability: per detection, per neighbour
  bool single_avalanche_per_frame = false; // pixel B's feedback stops further avalanches in a frame

  static PixelTypeConfig paper_pixel_A() { return {}; }
  static PixelTypeConfig paper_pixel_B() {
    PixelTypeConfig b;
    b.fill_factor = 0.134;
    b.pdp_peak = 0.267;
    b.pdp_nonuniformity = 0.032;
    b.dcr_median_cps = 2.0;
    b.crosstalk_probability = 0.0039;
    b.single_avalanche_per_frame = true;
    return b;
  }

  bool operator==(const PixelTypeConfig&) const = default;
};

struct GateConfig {
  double length_s = 3.8e-9;             // sensor.gate.length_ns (50 % to 50 %)
  double rise_s = 400e-12;              // sensor.gate.rise_ps (10 % to 90 %)
  double fall_s = 400e-12;              // sensor.gate.fall_ps (90 % to 10 %)
  GateEdge edge_shape = GateEdge::Smooth;  // sensor.gate.edge_shape
  std::string profile_csv;              // sensor.gate.profile_csv: measured (time_ps, response) table
  double delay_s = 0.0;                 // sensor.gate.delay_ns: trigger to gate opening at position 0
  double skew_fwhm_s = 410e-12;         // sensor.gate.skew_fwhm_ps
  double length_fwhm_s = 120e-12;       // sensor.gate.length_fwhm_ps
  std::string maps_exr;                 // sensor.gate.maps_exr: EXR with channels skew_ps, length_ps
  double jitter_fwhm_s = 60e-12;        // sensor.jitter_fwhm_ps: SPAD timing jitter (Gaussian)
  // The numerical gate model (docs/sensor.md, "Knots"; their cost and error in docs/accuracy.md):
  int knots_per_edge = 256;             // sensor.gate.knots_per_edge: knots of a tabulated edge
  double grid_s = 0.25e-12;             // sensor.gate.grid_ps: step of the fine grid the edges and the
                                        // instrument response are tabulated on (at least span / 12000)

  bool operator==(const GateConfig&) const = default;
};

struct SensorConfig {
  PixelPreset preset = PixelPreset::PixelA;  // sensor.preset (full_chip: A top half, B bottom; sensor/pixel_layout.h)
  PixelTypeConfig pixel_A = PixelTypeConfig::paper_pixel_A();  // sensor.pixel_A
  PixelTypeConfig pixel_B = PixelTypeConfig::paper_pixel_B();  // sensor.pixel_B
  GateConfig gate;                      // sensor.gate
  double temperature_C = 25.0;          // sensor.temperature_C
  bool dark_counts = true;              // sensor.dark_counts
  bool crosstalk = true;                // sensor.crosstalk
  bool skew = true;                     // sensor.gate_skew: per-pixel gate position and length maps
  bool pdp_nonuniformity = true;        // sensor.pdp_nonuniformity

  bool operator==(const SensorConfig&) const = default;
};

struct GateSweepConfig {
  double start_s = 0.6e-9;              // acquisition.gate_sweep.start_ns
  double stop_s = 13.2e-9;              // acquisition.gate_sweep.stop_ns (inclusive when on the grid)
  double step_s = 36e-12;               // acquisition.gate_sweep.step_ps

  // How many positions start, start + step, ... up to stop: stop counts when on the grid within the rounding
  // of the three in seconds (an absolute 1e-9 of a step left out the last of 5 to 5.00001 ns in 1e-6 ps steps).
  double positions() const {
    const double rounding = 64.0 * std::numeric_limits<double>::epsilon() * std::max(std::fabs(start_s), std::fabs(stop_s)) / step_s;
    return std::floor((stop_s - start_s) / step_s + 1e-9 + rounding) + 1.0;
  }

  bool operator==(const GateSweepConfig&) const = default;
};

struct IntensityConfig {
  Exposure exposure = Exposure::Single;  // acquisition.intensity.exposure
  double exposure_s = 10e-6;            // acquisition.intensity.exposure_us: single exposure, or tau_S in dual
  double dual_ratio = 8.0;              // acquisition.intensity.dual_ratio: tau_L / tau_S
  bool laser_on = false;                // acquisition.intensity.laser_on: add the laser's mean photon rate

  bool operator==(const IntensityConfig&) const = default;
};

struct AcquisitionConfig {
  AcquisitionMode mode = AcquisitionMode::GateSweep;  // acquisition.mode: gate_sweep (3D) or intensity (2D)
  int frames = 255;                     // acquisition.frames: per gate position (sweep) or per image (2D)
  double frame_rate_Hz = 24000.0;       // acquisition.frame_rate_fps: the exposure check, metadata
  int64_t cycles_per_frame = 1000;      // acquisition.cycles_per_frame: laser cycles in one binary frame
  GateSweepConfig gate_sweep;
  IntensityConfig intensity;

  bool operator==(const AcquisitionConfig&) const = default;
};

struct RenderConfig {
  Quality quality = Quality::Custom;    // render.quality: a preset of the three keys below
  int samples_per_pixel = 16;           // render.samples_per_pixel (with a target error: the first round)
  // render.target_relative_error: null renders samples_per_pixel paths in every pixel; else a first round
  // of samples_per_pixel paths decides how many paths each pixel's estimate takes for its laser return's
  // standard error to be this fraction of it, at most max_samples_per_pixel (docs/render.md, "Accuracy").
  std::optional<double> target_relative_error;
  int max_samples_per_pixel = 1024;     // render.max_samples_per_pixel
  int max_bounces = 4;                  // render.max_bounces (1 = direct light only)
  int russian_roulette_from = 3;        // render.russian_roulette_from: bounce after which paths may stop
  double time_bin_s = 9e-12;            // render.time_bin_ps
  std::optional<double> window_start_s; // render.window_start_ns (null: derived from the acquisition)
  std::optional<double> window_stop_s;  // render.window_stop_ns
  int tile_size = 32;                   // render.tile_size_px (multiple of 8)
  int max_layers = 8;                   // render.max_layers in the ground truth
  bool split_direct_indirect = false;   // render.split_direct_indirect
  // render.guided_connections: glossy and Lambertian vertices also draw directions towards narrow glossy
  // reflections of the laser, weighted against their BSDF draws by MIS (docs/render.md)
  bool guided_connections = true;

  bool operator==(const RenderConfig&) const = default;
};

struct OutputsConfig {
  bool ground_truth = true;             // outputs.ground_truth
  bool transient = false;               // outputs.transient
  std::optional<PixelRect> transient_crop;  // outputs.transient_crop [x0, y0, w, h] (image coordinates)
  bool light = false;                   // outputs.light
  bool expected_counts = false;         // outputs.expected_counts
  bool detection_rate = true;           // outputs.detection_rate
  bool counts = true;                   // outputs.counts
  bool frames = false;                  // outputs.frames
  bool previews = true;                 // outputs.previews
  Storage storage = Storage::Npy;       // outputs.storage
  ExrCompression exr_compression = ExrCompression::Zip;  // outputs.exr_compression

  bool operator==(const OutputsConfig&) const = default;
};

// The seeds of the three random streams that are independent of each other (sensor/streams.h and
// render/ say which draws each drives). Null: the run's `seed`.
struct SeedsConfig {
  std::optional<uint64_t> light;  // seeds.light: Monte Carlo light transport (camera paths, BSDF sampling)
  std::optional<uint64_t> chip;   // seeds.chip: the chip's fixed pattern (gate skew and length, DCR, PDP maps)
  std::optional<uint64_t> noise;  // seeds.noise: temporal noise (binary frames, counts, crosstalk draws)

  bool operator==(const SeedsConfig&) const = default;
};

// Edits of the glTF scene, applied by the loader (scenes::load_gltf) before world transforms are composed:
// the scene file's `nodes` and `materials` sections (docs/scene-file.md, "Varying the glTF scene"). Each
// given value replaces the glTF's; a component left empty (std::nullopt) keeps the glTF's.
using OptionalVec3 = std::array<std::optional<double>, 3>;

struct NodeEdit {
  std::string name;                     // nodes.<name>: the glTF node's name
  OptionalVec3 translation_m;           // translation_m: local translation, in the parent's frame
  OptionalVec3 rotation_rad;            // rotation_deg: XYZ Euler angles, R = Rz * Ry * Rx on column vectors
  OptionalVec3 scale;                   // scale: per local axis

  bool operator==(const NodeEdit&) const = default;
};

struct MaterialEdit {
  std::string name;                     // materials.<name>: the glTF material's name
  OptionalVec3 base_color;              // base_color: linear RGB (baseColorFactor; its alpha is kept)
  std::optional<double> roughness;      // roughness: roughnessFactor
  std::optional<double> metallic;       // metallic: metallicFactor
  std::optional<double> transmission;   // transmission: KHR_materials_transmission transmissionFactor
  std::optional<double> ior;            // ior: KHR_materials_ior
  std::optional<double> thickness_m;    // thickness_mm: KHR_materials_volume thicknessFactor

  bool operator==(const MaterialEdit&) const = default;
};

struct SceneEdits {
  std::vector<NodeEdit> nodes;          // sorted by name (byte order), names unique
  std::vector<MaterialEdit> materials;  // the same

  bool empty() const { return nodes.empty() && materials.empty(); }
  bool operator==(const SceneEdits&) const = default;
};

struct RunConfig {
  std::string scene_file;               // absolute path of the scene file ("" when built in code)
  std::string gltf_path;                // gltf: resolved absolute path
  std::string gltf_scene;               // gltf_scene: name of the glTF scene; "" = the file's default
  SceneEdits edits;                     // nodes, materials: changes to the glTF's nodes and materials
  uint64_t seed = 1;                    // seed
  SeedsConfig seeds;                    // seeds.*: each stream's own seed (null: seed)
  CameraConfig camera;
  LaserConfig laser;
  AmbientConfig ambient;
  SensorConfig sensor;
  AcquisitionConfig acquisition;
  RenderConfig render;
  OutputsConfig outputs;

  // The seed each stream uses: its own when set, else `seed`.
  uint64_t light_seed() const { return seeds.light.value_or(seed); }
  uint64_t chip_seed() const { return seeds.chip.value_or(seed); }
  uint64_t noise_seed() const { return seeds.noise.value_or(seed); }

  bool operator==(const RunConfig&) const = default;
};

// What each stage receives: its own part of the run description, already validated (scenes/ checks every
// key and every rule that spans keys once, when the scene file is read; the stages do not check again).

// The sensor stage (sensor/): the chip and the acquisition, and the few facts about the camera and the
// light it needs: the sensor's size, the optics transmission (for the informative PDE), the laser's
// wavelength, period and pulse, and the ambient band.
struct SensorStageConfig {
  struct Geometry {
    int width_px = CameraConfig{}.width_px;    // the full sensor
    int height_px = CameraConfig{}.height_px;
    double optics_transmission = CameraConfig{}.optics_transmission;
  } camera;
  LaserConfig laser;
  struct Band {
    double wavelength_m = AmbientConfig{}.wavelength_m;
    double bandwidth_m = AmbientConfig{}.bandwidth_m;
  } ambient;
  SensorConfig sensor;
  AcquisitionConfig acquisition;
  struct Outputs {
    bool frames = OutputsConfig{}.frames;  // sample binary frames (else counts directly)
    bool detection_rate = OutputsConfig{}.detection_rate;  // keep lambda per image (SensorTile::rate)
  } outputs;
  uint64_t chip_seed = RunConfig{}.seed;   // the chip's fixed pattern (RunConfig::chip_seed())
  uint64_t noise_seed = RunConfig{}.seed;  // temporal noise (RunConfig::noise_seed())
};

// The renderer (render/): the camera, the laser, the ambient light, its numerical settings and seed, and
// the fill factor of every sensor row, which the sensor's pixel layout decides (sensor/pixel_layout.h).
struct RenderStageConfig {
  CameraConfig camera;
  LaserConfig laser;
  AmbientConfig ambient;
  RenderConfig render;
  uint64_t light_seed = RunConfig{}.seed;  // light transport (RunConfig::light_seed())
  std::vector<double> row_fill_factor;  // camera.height_px values, row 0 at the top
  // What render.target_relative_error holds to the target: the laser return (unless the acquisition sees
  // none: the intensity mode without laser_on) and the ambient light, which every mode's counts see (a gate
  // sweep's background; a pixel without ambient light takes the laser's paths).
  bool target_laser = true, target_ambient = true;
  // Per sensor row (empty: 0), photons per second: the ambient light a gate sweep's counts hardly see against
  // their own noise (the ambient rate that gives one expected count over a gate position's frames, plus the
  // dark counts as ambient photons; SensorModel::row_ambient_floor). The target holds the ambient light's
  // error against its rate plus this floor, so that a negligible background costs no paths.
  std::vector<double> row_ambient_floor{};
  // Whether the renderer traces the laser at all: not in the intensity mode without laser_on unless
  // outputs.transient keeps its light, or outputs.light with a time window (render.window_start_ns) for a later
  // spadgen sense as a gate sweep (without one it keeps what the run's counts see, and its sense needs no laser). Untraced, the
  // paths are drawn as they would be (the ambient light's estimate is the same unless guided connections
  // would draw towards the laser: render::guided_connections_active) but connect nothing to the
  // laser, and the laser's images are not written.
  bool trace_laser = true;
};

SensorStageConfig sensor_stage(const RunConfig& c);
// RenderStageConfig::trace_laser of the run (whether the laser's images and ground truth channels exist).
bool laser_traced(const RunConfig& c);
RenderStageConfig render_stage(const RunConfig& c, std::vector<double> row_fill_factor,
                               std::vector<double> row_ambient_floor = {});

}  // namespace spadgen
