// spadgen sense: the sensor stage alone, from the light a run saved. The scene is not loaded and nothing
// is rendered: the run folder's metadata.json holds the resolved scene file, light/ what the renderer
// delivered to the sensor. The sensor settings may change (--set sensor.*, acquisition.*, seeds), the
// light may not.
#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <fstream>
#include <limits>
#include <memory>
#include <set>
#include <sstream>

#include "app/interrupt.h"
#include "app/light.h"
#include "app/metadata.h"
#include "app/outputs.h"
#include "app/pipeline.h"
#include "app/preflight.h"
#include "app/resources.h"
#include "app/progress.h"
#include "app/run_parts.h"
#include "app/staging.h"
#include "app/warnings.h"
#include "core/error.h"
#include "core/stage_clock.h"
#include "reconstruct/run_folder.h"
#include "scenes/input.h"
#include "scenes/key_path.h"
#include "scenes/scene_file.h"
#include "sensor/labels.h"
#include "sensor/model/pixel_layout.h"
#include "sensor/sensor.h"
#include "writers/writers.h"

namespace spadgen::app {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

// Keys sense may change: the sensor's, the acquisition's, the chip's and the noise's seeds, and the files
// the sensor writes. Everything else shaped the light, which sense cannot change.
// A key as --set wrote it, in its plain form ("sensor"."gate".length_ns is sensor.gate.length_ns); a
// malformed key as written (it is reported as such when the scene file is parsed).
std::string plain_key(const std::string& written) {
  try {
    return scenes::parse_key_path(written).text();
  } catch (const Error&) {
    return written;
  }
}

// The laser's pulse table: the sensor convolves with it, and it sized the time window the run rendered, so a
// --set of it is taken only as the run's table moved (its contents checked against the run's record).
constexpr const char* kPulseTable = "laser.pulse_shape_csv";

bool sense_may_set(const std::string& written) {
  const std::string key = plain_key(written);
  if (key == kPulseTable || key == "description") return true;  // (description: free text, copied into metadata.json)
  for (const char* section : {"sensor.", "acquisition."})
    if (key.rfind(section, 0) == 0) return true;
  // whole keys or a component of one ("seeds.noiseX" is another key, which the schema refuses)
  for (const std::string k : {"seeds.chip", "seeds.noise", "outputs.expected_counts", "outputs.detection_rate", "outputs.counts",
                              "outputs.frames", "outputs.previews", "outputs.storage", "outputs.exr_compression"})
    if (key.rfind(k, 0) == 0 && (key.size() == k.size() || key[k.size()] == '.' || key[k.size()] == '['))
      return true;
  return false;
}

json read_metadata(const fs::path& dir) { return reconstruct::read_run_metadata(dir.string()); }

// "0.10.2" -> {0, 10, 2}, trailing zeros left out ("0.1.0.0" is "0.1"); empty when not numbers and dots.
std::vector<long> version_numbers(const std::string& v) {
  std::vector<long> n;
  size_t i = 0;
  while (i < v.size()) {
    size_t j = i;
    while (j < v.size() && v[j] >= '0' && v[j] <= '9' && j - i < 9) ++j;
    if (j == i || (j < v.size() && v[j] != '.')) return {};
    n.push_back(std::stol(v.substr(i, j - i)));
    i = j + 1;
  }
  while (n.size() > 1 && n.back() == 0) n.pop_back();
  return n;
}

// A run of a later spadgen may lay out its light or its keys otherwise than this one reads them: refused,
// named, rather than re-sampled on a guess. An earlier version's run is read as long as its keys are there.
void refuse_later_version(const json& meta, const fs::path& src) {
  const json* v = meta.contains("spadgen_version") ? &meta.at("spadgen_version") : nullptr;
  if (!v) return;
  const std::vector<long> theirs = v->is_string() ? version_numbers(v->get<std::string>()) : std::vector<long>{};
  if (theirs.empty())
    throw Error((src / "metadata.json").string() + ": spadgen_version " + v->dump() +
                "; expected a version such as \"" SPADGEN_VERSION "\" (a damaged metadata.json: run the scene again)");
  if (theirs > version_numbers(SPADGEN_VERSION))
    throw Error((src / "metadata.json").string() + ": written by spadgen " + v->get<std::string>() +
                ", later than this spadgen " SPADGEN_VERSION ", whose sense may read its light otherwise: use spadgen " +
                v->get<std::string>() + " or later");
}

template <class T>
T field(const json& meta, const json::json_pointer& p, const fs::path& dir) {
  if (!meta.contains(p)) throw Error((dir / "metadata.json").string() + ": no " + p.to_string() + "; was it written by this spadgen?");
  return meta.at(p).get<T>();
}

PixelRect rect_of(const json& a) { return {a.at(0).get<int>(), a.at(1).get<int>(), a.at(2).get<int>(), a.at(3).get<int>()}; }

// A copy whose failure names the file and the cause (std::filesystem::copy_file reported a full disk
// as an input/output error, through an exception the program took for a bug of its own).
void copy_checked(const fs::path& a, const fs::path& b) {
  const auto fail = [&](const char* what, int err) {
    throw Error(std::string("cannot copy ") + a.string() + " to " + b.string() + " (" + what + "): " + std::strerror(err));
  };
  // (O_NONBLOCK: a FIFO in the run's place would block the open; only a regular file is copied)
  const int in = ::open(a.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (in < 0) fail("open the run's file", errno);
  struct stat st {};
  if (::fstat(in, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(in);
    throw Error(a.string() + ": is not a regular file (" + (S_ISFIFO(st.st_mode) ? "a FIFO" : S_ISDIR(st.st_mode) ? "a folder" : "a device or socket") +
                "); expected the run's file as spadgen wrote it");
  }
  const int out = ::open(b.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (out < 0) {
    const int err = errno;
    ::close(in);
    fail("create", err);
  }
  std::vector<char> buf(size_t{1} << 20);
  for (;;) {
    const ssize_t n = ::read(in, buf.data(), buf.size());
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int err = errno;
      ::close(in), ::close(out);
      fail("read", err);
    }
    if (n == 0) break;
    for (ssize_t done = 0; done < n;) {
      const ssize_t w = ::write(out, buf.data() + done, size_t(n - done));
      if (w < 0 && errno == EINTR) continue;
      if (w < 0) {
        const int err = errno;
        ::close(in), ::close(out);
        fail("write", err);
      }
      done += w;
    }
  }
  ::close(in);
  if (::close(out) != 0) fail("write", errno);
}

// The run's file `rel` into the staging folder: a hard link (the run's files are never modified in place;
// a later run replaces them with a new file), or a copy across file systems. A Zarr store's folder is
// made anew and its files linked.
void link_into(const fs::path& from, const Staging& staging, const std::string& rel) {
  const fs::path to = staging.path(rel);
  fs::create_directories(to.parent_path());
  // (a symbolic link in the run is followed: its target is linked, not the link, whose relative target would
  // point elsewhere from the staging folder, or at nothing)
  const auto link = [](const fs::path& a, const fs::path& b) {
    if (::linkat(AT_FDCWD, a.c_str(), AT_FDCWD, b.c_str(), AT_SYMLINK_FOLLOW) != 0) copy_checked(a, b);
  };
  if (!fs::is_directory(from)) return link(from, to);
  fs::create_directories(to);
  for (const auto& e : fs::directory_iterator(from)) link(e.path(), to / e.path().filename());
}

std::string text(uint64_t v) { return std::to_string(v); }

// What labels.exr needs of the run's ground truth over rect: the object slots' ids, ranges, paths and laser light,
// exactly as ground_truth.exr holds them (so the labels equal a run's bit for bit). Slots beyond the
// image's object<j> channels are unused (id -1), as the run's were.
GroundTruthTile object_truth(const writers::ExrData& e, const PixelRect& img, const PixelRect& rect, int slots,
                             const fs::path& file) {
  if (e.width != img.width || e.height != img.height)
    throw Error(file.string() + ": expected " + std::to_string(img.width) + " x " + std::to_string(img.height) + " pixels");
  GroundTruthTile gt;
  gt.rect = rect;
  gt.max_layers = slots;
  const auto n = static_cast<size_t>(rect.count()) * static_cast<size_t>(slots);
  gt.object_slot_id.assign(n, -1);
  gt.object_range.assign(n, std::numeric_limits<float>::infinity());
  gt.object_path.assign(n, std::numeric_limits<float>::infinity());
  gt.object_laser.assign(n, 0.0f);
  for (int j = 0; j < slots; ++j) {
    const std::string name = "object" + std::to_string(j);
    const auto id = e.channels.find(name + ".id"), range = e.channels.find(name + ".range"), laser = e.channels.find(name + ".laser");
    const auto path = e.channels.find(name + ".path");
    if (id == e.channels.end()) break;
    if (range == e.channels.end() || laser == e.channels.end() || path == e.channels.end())
      throw Error(file.string() + ": has " + name + ".id but not " + name + ".range, " + name + ".path and " + name +
                  ".laser (a run of an older spadgen: run it again)");
    for (int y = rect.y0; y < rect.y1(); ++y)
      for (int x = rect.x0; x < rect.x1(); ++x) {
        const size_t o = size_t(y - img.y0) * size_t(img.width) + size_t(x - img.x0);
        const size_t i = size_t(rect.index(x, y)) * size_t(slots) + size_t(j);
        gt.object_slot_id[i] = static_cast<int32_t>(id->second[o]);
        gt.object_range[i] = range->second[o];
        gt.object_path[i] = path->second[o];
        gt.object_laser[i] = laser->second[o];
      }
  }
  return gt;
}

// The run's ground truth for another pixel design: its laser channels (photons reaching the pixel's
// active area, the fill factor in them) times row_scale of the image's sensor rows.
void scale_truth(writers::ExrData& e, const PixelRect& img, const std::vector<double>& row_scale) {
  for (auto& [name, values] : e.channels) {
    if (!(name == "direct_other_laser" || name == "indirect_laser" || (name.starts_with("object") && name.ends_with(".laser"))))
      continue;
    for (int y = 0; y < e.height; ++y) {
      const double s = row_scale[size_t(img.y0 + y)];
      for (int x = 0; x < e.width; ++x) {
        float& v = values[size_t(y) * size_t(e.width) + size_t(x)];
        v = static_cast<float>(double(v) * s);
      }
    }
  }
}

void write_exr_as(const writers::ExrData& e, const std::string& path, ExrCompression compression) {
  writers::ExrImage image(e.width, e.height);
  for (const auto& [name, values] : e.channels) std::copy(values.begin(), values.end(), image.channel(name));
  for (const auto& [key, value] : e.attributes) image.set_attribute(key, value);
  image.write(path, compression);
}

// A run's (H, W, T) transient of the sensor rows crop.y0 .., each row's photons times its row_scale.
void write_rescaled_transient(const fs::path& from, const std::string& to, const std::vector<double>& row_scale, const PixelRect& crop) {
  const writers::NpyReader in(from.string());
  if (in.shape().size() != 3 || in.shape()[0] != crop.height)
    throw Error(from.string() + ": expected (" + std::to_string(crop.height) + ", W, T) as metadata.json's transient crop");
  const float* v = in.data<float>();
  const int64_t row = in.shape()[1] * in.shape()[2];
  writers::NpyWriter out(to, writers::Dtype::F32, in.shape(), /*mapped=*/false);
  std::vector<float> buf(static_cast<size_t>(row));
  for (int64_t y = 0; y < in.shape()[0]; ++y) {
    const double s = row_scale[size_t(crop.y0 + y)];
    for (int64_t i = 0; i < row; ++i) buf[size_t(i)] = static_cast<float>(double(v[y * row + i]) * s);
    out.write(y * row, buf.data(), row);
  }
  out.commit();
}

// The resolved scene less what does not change the sensor's noise-free files: the noise's seed and
// whether counts and frames are written.
// (the tables by their content, sensor_tables_hash, not by where they are: a --set may give them moved)
nlohmann::ordered_json noise_free_part(nlohmann::ordered_json resolved) {
  std::vector<std::string> keys = {"/seeds/noise", "/outputs/counts", "/outputs/frames", "/description"};
  for (const scenes::SensorTable& t : scenes::sensor_tables(RunConfig{})) {  // (their keys: "sensor.gate.profile_csv")
    std::string pointer = "/" + t.key;
    std::replace(pointer.begin(), pointer.end(), '.', '/');
    keys.push_back(pointer);
  }
  for (const std::string& key : keys) {
    const json::json_pointer p(key);
    if (resolved.contains(p)) resolved[p.parent_pointer()].erase(p.back());
  }
  return resolved;
}

}  // namespace

std::vector<RunResult> sense(const SenseOptions& options) {
  // From the start: the scene is resolved once per realisation before any work, and a signal meanwhile is an
  // interruption (exit 2), not a kill.
  InterruptGuard interrupt_guard;
  const auto started = std::chrono::steady_clock::now();
  require_utf8_path(options.run_dir, "the run folder", "which metadata.json records (sense.from)");
  const fs::path src = options.run_dir;
  // The run folder's lock, shared with other senses of it, held until the realisations are published: a run
  // replacing the folder meanwhile would give them its light beside counts of the earlier one.
  std::optional<FolderLock> run_lock;
  if (fs::is_regular_file(src / "metadata.json")) run_lock.emplace(src, true);
  const json meta = read_metadata(src);
  if (!meta.is_object())
    throw Error((src / "metadata.json").string() + ": not a JSON object; expected a run's metadata.json (a damaged one: run the scene again)");
  refuse_later_version(meta, src);
  if (!meta.contains("light"))
    throw Error(src.string() + ": the run saved no light; run it again with --set outputs.light=true to re-sample its sensor");
  // Everything sense reads from metadata.json, checked once: a folder of another spadgen version is named.
  for (const char* key : {"/resolved_scene", "/scene_file", "/scene_hash_fnv1a64", "/warnings", "/files", "/camera",
                          "/photons_per_pulse_emitted", "/ground_truth_layers", "/light/crop_in_sensor", "/light/values_bytes",
                          "/light/time_axis_s/start", "/light/time_axis_s/bin_width", "/light/time_axis_s/bins",
                          "/light/time_axis_s/laser_period"})
    if (!meta.contains(json::json_pointer(key)))
      throw Error((src / "metadata.json").string() + ": no " + key + "; expected a run folder written by spadgen " SPADGEN_VERSION
                  " with outputs.light (run the scene again)");
  // ... and of the types a run writes (a wrong one was an internal error, exit 3, naming neither file nor key)
  {
    const auto is_text = [](const json& v) { return v.is_string(); };
    const auto is_number = [](const json& v) { return v.is_number(); };
    const auto is_positive = [](const json& v) { return v.is_number() && v.get<double>() > 0.0; };
    const auto is_count = [](const json& v) { return v.is_number_unsigned(); };
    const auto is_texts = [](const json& v) { return v.is_array() && std::all_of(v.begin(), v.end(), [](const json& t) { return t.is_string(); }); };
    const auto is_rect = [](const json& v) {
      return v.is_array() && v.size() == 4 && std::all_of(v.begin(), v.end(), [](const json& t) { return t.is_number_unsigned() && t.get<uint64_t>() <= (1u << 20); }) &&
             v[2].get<uint64_t>() > 0 && v[3].get<uint64_t>() > 0;
    };
    const auto is_object = [](const json& v) { return v.is_object(); };
    const auto is_array = [](const json& v) { return v.is_array(); };
    struct Typed {
      const char* key;
      bool required;
      std::function<bool(const json&)> ok;
      const char* expected;
    };
    const Typed typed[] = {
        {"/resolved_scene", true, is_object, "an object"}, {"/scene_file", true, is_text, "text"},
        {"/scene_hash_fnv1a64", true, is_text, "text"}, {"/warnings", true, is_texts, "a list of texts"},
        {"/files", true, is_texts, "a list of file names"}, {"/camera", true, is_object, "an object"},
        {"/photons_per_pulse_emitted", true, is_number, "a number"}, {"/ground_truth_layers", true, is_count, "an integer >= 0"},
        {"/light/crop_in_sensor", true, is_rect, "[x, y, width, height] in pixels"},
        {"/light/values_bytes", true, is_count, "an integer >= 0"}, {"/light/time_axis_s/start", true, is_number, "a number"},
        {"/light/time_axis_s/bin_width", true, is_positive, "a number > 0"},
        {"/light/time_axis_s/bins", true, is_count, "an integer >= 0"},
        {"/light/time_axis_s/laser_period", true, is_positive, "a number > 0"},
        {"/sensor_tables_fnv1a64", false, is_text, "text"}, {"/ground_truth_objects", false, is_count, "an integer >= 0"},
        {"/objects", false, is_array, "a list"}, {"/transient", false, is_object, "an object"},
        {"/transient/crop_in_sensor", false, is_rect, "[x, y, width, height] in pixels"},
        {"/ground_truth_summary", false, is_object, "an object"}, {"/file_bytes", false, is_object, "an object"},
        {"/storage/files", false, is_object, "an object"}, {"/light/fill_factor", false, is_array, "a list"},
        {"/laser_photons_per_pulse", false, [](const json& v) { return v.is_object() || v.is_null(); }, "an object, or null"},
        // sense carries the scene's components over from the run (model_components)
        {"/model", false,
         [](const json& v) {
           return v.is_array() && std::all_of(v.begin(), v.end(), [](const json& e) {
                    return e.is_object() && e.contains("component") && e.at("component").is_string() && e.contains("active") &&
                           e.at("active").is_boolean() && e.contains("why") && e.at("why").is_string();
                  });
         },
         "a list of {component: text, active: true or false, why: text}"}};
    for (const Typed& t : typed) {
      const json::json_pointer p(t.key);
      if (!meta.contains(p)) continue;
      if (!t.ok(meta.at(p)))
        throw Error((src / "metadata.json").string() + ": " + t.key + " is " + scenes::one_line(meta.at(p).dump().substr(0, 80)) +
                    "; expected " + t.expected + ", as a run writes it (a damaged metadata.json: run the scene again)");
    }
  }
  // A run that kept its transient says where (sense rescales it to that crop; without it: an internal error).
  if (meta.contains("transient") && !meta.contains("/transient/crop_in_sensor"_json_pointer))
    throw Error((src / "metadata.json").string() + ": transient has no crop_in_sensor; expected [x, y, width, height] in pixels, "
                "as a run writes it (a damaged metadata.json: run the scene again)");
  // Every run lists its files, metadata.json last: a list without it is damaged (an emptied one made sense
  // write a folder without the ground truth, labels and depth preview the run had, exit 0).
  if (const json& files = meta.at("files");
      !files.is_array() || std::none_of(files.begin(), files.end(), [](const json& f) { return f == "metadata.json"; }))
    throw Error((src / "metadata.json").string() + ": files does not list metadata.json, as every run's list does: the list "
                "is damaged (run the scene again)");
  for (const std::string& o : options.overrides) {
    const std::string key = o.substr(0, scenes::assignment_split(o));
    if (sense_may_set(key)) continue;
    // A key the scene file does not have (a typo) gets the schema's message, with its suggestion, rather
    // than being called a key of the rendered light.
    (void)scenes::parse_scene_text(meta.at("resolved_scene").dump(), field<std::string>(meta, "/scene_file"_json_pointer, src), {o},
                                   scenes::FileChecks::None);
    throw Error("--set " + key + ": sense re-samples the sensor only, so it takes sensor.*, acquisition.*, seeds.chip, "
                  "seeds.noise and outputs.{expected_counts,detection_rate,counts,frames,previews,storage,exr_compression}; " + key +
                  (plain_key(key) == "render.tile_size_px" ? " is the renderer's tile edge, on which no output depends: leave it out"
                                                           : " shapes the rendered light: use spadgen run"));
  }
  if (options.repeats < 1) throw Error("--repeats: expected at least 1, found " + std::to_string(options.repeats));
  // A seed given twice, as an option and by --set, is refused rather than one silently winning.
  bool noise_by_set = false;
  for (const std::string& o : options.overrides) {
    const std::string key = plain_key(o.substr(0, scenes::assignment_split(o)));
    if ((key == "seeds.noise" && options.noise_seed) || (key == "seeds.chip" && options.chip_seed))
      throw Error("--set " + key + " and --" + (key == "seeds.noise" ? "noise" : "chip") + "-seed both give the seed: give one");
    noise_by_set = noise_by_set || key == "seeds.noise";
  }

  // The run's scene file as it resolved, with this call's changes.
  const std::string scene_text = meta.at("resolved_scene").dump();
  const std::string scene_file = field<std::string>(meta, "/scene_file"_json_pointer, src);
  std::vector<std::string> overrides = options.overrides;
  if (options.chip_seed) overrides.push_back("seeds.chip=" + text(*options.chip_seed));
  if (options.noise_seed) overrides.push_back("seeds.noise=" + text(*options.noise_seed));
  // The run's scene as it resolved, read from its metadata.json (and parsed as the run's below, for its
  // warnings and light): a mistake in it is named there, not against the scene file it names, which may
  // hold a good value. Its tables are looked for only as this call uses them: a --set may give a table
  // moved since the run in its new place.
  const auto in_metadata = [&](const Error& e) {
    return Error((src / "metadata.json").string() + ": resolved_scene (the run's scene file as it resolved; sense reads it "
                 "from here): " + e.what());
  };
  const scenes::ResolvedRun source = [&] {
    try {
      return scenes::parse_scene_text(scene_text, scene_file, {}, scenes::FileChecks::None);
    } catch (const Error& e) {
      throw in_metadata(e);
    }
  }();
  const scenes::ResolvedRun first = [&] {
    try {
      return scenes::parse_scene_text(scene_text, scene_file, overrides, scenes::FileChecks::Tables);
    } catch (const Error&) {
      // A table the run's scene names that is gone and that no --set gives anew is the run's mistake: named
      // there (the run's scene with this call's tables alone).
      std::vector<std::string> tables;
      for (const std::string& o : overrides)
        for (const scenes::SensorTable& t : scenes::sensor_tables(RunConfig{}))
          if (o.substr(0, scenes::assignment_split(o)) == t.key) tables.push_back(o);
      try {
        (void)scenes::parse_scene_text(scene_text, scene_file, tables, scenes::FileChecks::Tables);
      } catch (const Error& own) {
        throw in_metadata(own);
      }
      throw;
    }
  }();
  // One resolved scene per realisation: noise seeds S, S + 1, ... (S itself when there is one). The scene
  // is resolved once with seeds.noise = S; realisation r is that with the seed S + r in its configuration
  // and its resolved scene file, as `--set seeds.noise=S+r` resolves it (tested: a realisation's metadata
  // equals the run's with that seed), without parsing the scene R times.
  std::vector<scenes::ResolvedRun> runs;
  const uint64_t noise0 = first.config.noise_seed();
  if (options.repeats == 1) {
    runs.push_back(first);
  } else {
    std::vector<std::string> o = overrides;
    o.push_back("seeds.noise=" + text(noise0));
    const scenes::ResolvedRun base = scenes::parse_scene_text(scene_text, scene_file, o, scenes::FileChecks::Tables);
    runs.reserve(size_t(options.repeats));
    for (int r = 0; r + 1 < options.repeats; ++r) {
      scenes::ResolvedRun& run = runs.emplace_back(base);
      run.config.seeds.noise = noise0 + uint64_t(r);
      run.resolved["seeds"]["noise"] = noise0 + uint64_t(r);
    }
    // Seeds past the key's range (0 .. scenes::kMaxSeed) are refused in terms of what the user gave: the first
    // seed's source and --repeats.
    using scenes::kMaxSeed;
    const uint64_t last = noise0 + uint64_t(options.repeats - 1);
    if (last > kMaxSeed) {
      const json& run_seeds = meta.at("resolved_scene").at("seeds");
      const std::string given_by = options.noise_seed ? "--noise-seed"
                                 : noise_by_set   ? "--set seeds.noise"
                                 : run_seeds.contains("noise") && !run_seeds.at("noise").is_null() ? "the run's seeds.noise"
                                                                                                  : "the run's seed";
      throw Error("--repeats " + std::to_string(options.repeats) + ": the realisations' noise seeds would run from " +
                  text(noise0) + " (" + given_by + ") to " + text(last) + "; expected seeds of at most " + text(kMaxSeed) +
                  ": a smaller first seed or fewer repeats");
    }
    // The last seed resolved in full, as `--set seeds.noise` resolves it.
    o.back() = "seeds.noise=" + text(last);
    runs.push_back(scenes::parse_scene_text(scene_text, scene_file, o, scenes::FileChecks::Tables));
  }
  const RunConfig& cfg = first.config;
  for (const std::string& w : first.warnings) print_warning(w);
  // What the run warned about its glTF and its light: the run's warnings less the scene file's and less
  // its sensor's (this call's sensor warns below).
  std::vector<std::string> scene_warnings;
  {
    const std::vector<std::string>& file_warnings = source.warnings;
    for (const auto& w : meta.at("warnings"))
      if (std::find(file_warnings.begin(), file_warnings.end(), w.get<std::string>()) == file_warnings.end() &&
          !is_sensor_warning(w.get<std::string>()))
        scene_warnings.push_back(w.get<std::string>());
  }

  const ThreadLimit threads(options.threads);

  const SensorTables tables_read = SensorTables::hashed(cfg);
  if (std::any_of(options.overrides.begin(), options.overrides.end(),
                  [](const std::string& o) { return plain_key(o.substr(0, scenes::assignment_split(o))) == kPulseTable; })) {
    const json::json_pointer recorded_at("/sensor_table_fnv1a64/laser.pulse_shape_csv");
    // (tables_read lists every table key, set or not)
    const scenes::SensorTable& given = *std::find_if(tables_read.tables.begin(), tables_read.tables.end(),
                                                     [](const scenes::SensorTable& t) { return t.key == kPulseTable; });
    const std::string recorded = meta.contains(recorded_at) && meta.at(recorded_at).is_string() ? meta.at(recorded_at).get<std::string>() : "";
    if (recorded.empty() || given.hash != recorded)
      throw Error(std::string("--set ") + kPulseTable + ": " + (given.path.empty() ? std::string("no table") : given.path) +
                  (recorded.empty() ? " cannot be checked against the run's pulse (its metadata.json records no sensor_table_fnv1a64)"
                                    : " is not the pulse the run rendered with (its contents hash to " + given.hash +
                                          ", the run's table to " + recorded + ": metadata.json, sensor_table_fnv1a64)") +
                  "; the pulse sized the light's time window the run rendered, so sense takes the run's table moved, not "
                  "another: use spadgen run for another pulse");
  }
  sensor::SensorModel sensor(sensor_stage(cfg));
  apply_user_maps(sensor, cfg);
  tables_read.check_unchanged(cfg);
  tables_read.check_expected(cfg, options.tables_hash);
  for (std::string& w : sensor_warnings(sensor, cfg.sensor.gate.grid_s)) {
    print_warning(w);
    scene_warnings.push_back(std::move(w));
  }

  // The light's time axis, exactly as the run used it; the sensor's window must lie inside it.
  const json& la = meta.at("light").at("time_axis_s");
  TimeAxis axis{la.at("start").get<double>(), la.at("bin_width").get<double>(), la.at("bins").get<int64_t>(),
                la.at("laser_period").get<double>()};
  // ... as the run computed it from its scene: the bin width is render.time_bin_ps and the period the laser's,
  // the bins at most kMaxTimeBins and the start within the gate's reach (the start and the bins also depend on
  // the sensor, which an earlier sense may have changed). An edited axis crashed sense (2^62 bins) or drew
  // counts from rates on another axis than the detection_rate.npy it linked (a bin width of 0.5 s).
  {
    const auto off = [](double a, double b) { return !(std::abs(a - b) <= 1e-12 * std::abs(b)); };
    const std::string where = (src / "metadata.json").string() + ": light.time_axis_s.";
    const std::string damaged = " (a damaged metadata.json: run the scene again)";
    if (off(axis.bin_width_s, source.config.render.time_bin_s))
      throw Error(where + "bin_width is " + la.at("bin_width").dump() + " s, but the run's render.time_bin_ps gives " +
                  json(source.config.render.time_bin_s).dump() + damaged);
    if (off(axis.period_s, 1.0 / source.config.laser.repetition_rate_Hz))
      throw Error(where + "laser_period is " + la.at("laser_period").dump() + " s, but the run's laser.repetition_rate_MHz gives " +
                  json(1.0 / source.config.laser.repetition_rate_Hz).dump() + damaged);
    if (axis.bins < 0 || axis.bins > scenes::kMaxTimeBins)  // (2^64 - 1 read as -1)
      throw Error(where + "bins is " + la.at("bins").dump() + "; expected at most " + std::to_string(scenes::kMaxTimeBins) +
                  ", as every run's" + damaged);
    if (!(std::abs(axis.start_s) <= 1e-2))
      throw Error(where + "start is " + la.at("start").dump() + " s; expected within +-0.01 s, as every run's" + damaged);
  }
  // Whether the saved light holds the laser's: not when the run traced none (an intensity run without laser_on,
  // laser_photons_per_pulse null), which a sense that images the laser cannot do without.
  const bool light_laser = !meta.contains("laser_photons_per_pulse") || !meta.at("laser_photons_per_pulse").is_null();
  if (!light_laser && laser_traced(cfg))
    throw Error(src.string() + ": the run traced no laser (the intensity mode without acquisition.intensity.laser_on), so its "
                "saved light holds none, and " +
                std::string(cfg.acquisition.mode == AcquisitionMode::GateSweep ? "a gate sweep" : "acquisition.intensity.laser_on") +
                " images the laser's light; run the scene again with these settings and outputs.light=true");
  // What the sensor needs (the run's transient.npy, linked when sensed, does not depend on the mode: a gate
  // sweep run with transients sensed in 2D needs no bins).
  RunConfig sensor_cfg = cfg;
  sensor_cfg.outputs.transient = false;
  const TimeAxis need = time_axis(sensor_cfg, sensor);
  if (need.bins > 0 && (axis.bins == 0 || need.start_s < axis.start_s - 1e-3 * axis.bin_width_s ||
                        need.end_s() > axis.end_s() + 1e-3 * axis.bin_width_s)) {
    char buf[400];
    std::snprintf(buf, sizeof buf,
                  "the acquisition needs arrival times from %.6g to %.6g ns, but the run saved light from %.6g to %.6g ns%s; "
                  "run the scene again with these settings (or with render.window_start_ns / window_stop_ns covering them)",
                  need.start_s * 1e9, need.end_s() * 1e9, axis.start_s * 1e9, axis.end_s() * 1e9,
                  axis.bins == 0 ? " (none: a 2D run)" : "");
    throw Error(src.string() + ": " + buf);
  }

  const PixelRect img = image_rect(cfg);
  check_derived(cfg, sensor, img, need, first.set_keys);  // the sensor's own overrides may give negative gate lengths
  const PixelRect region = rect_of(meta.at("light").at("crop_in_sensor"));
  if (region != light_region(img, cfg.camera.width_px, cfg.camera.height_px))
    throw Error((src / "metadata.json").string() + ": light.crop_in_sensor does not match the run's image");
  // The light as the run stored it, whatever this call's storage is: the format metadata.json records for it (a
  // sense's light is its source's, linked, whatever the sense's own outputs.storage), else the run's storage.
  Storage light_storage = source.config.outputs.storage;
  if (const json* files = meta.contains("storage") && meta.at("storage").is_object() && meta.at("storage").contains("files")
                              ? &meta.at("storage").at("files") : nullptr;
      files && files->is_object())
    for (const auto& [name, storage] : {std::pair{"light/ranges.npy", Storage::Npy}, std::pair{"light/ranges.zarr", Storage::Zarr}})
      if (files->contains(name)) light_storage = storage;
  SavedLight light(src.string(), region, axis, light_storage);
  // The renderer applied a fill factor to each row; another pixel design rescales by this call's over it,
  // row by row (empty: the same design).
  const std::vector<double> now = sensor.row_fill_factor();
  const auto scale_from = [&](const std::vector<double>& was) {
    std::vector<double> scale;
    if (was != now)
      for (size_t y = 0; y < now.size(); ++y) scale.push_back(now[y] / was[y]);
    return scale;
  };
  // The run folder's files of photons (its ground truth, transients) are its own design's, which this
  // call rewrites rather than links for another; its light is the design light.fill_factor records (a
  // sense with another design links the light unchanged; a run before the record, its own design's).
  const std::vector<double> design = sensor::PixelLayout(source.config.sensor.preset, cfg.camera.height_px).row_fill_factor(source.config.sensor);
  const std::vector<double> file_scale = scale_from(design);
  std::vector<double> was = design;
  if (const json::json_pointer p("/light/fill_factor"); meta.contains(p)) {
    std::vector<double> recorded;
    for (const json& r : meta.at(p)) {
      if (!r.is_array() || r.size() != 3 || !r[0].is_number_unsigned() || !r[1].is_number_unsigned() || !r[2].is_number() ||
          r[0].get<size_t>() != recorded.size() || !(r[2].get<double>() > 0.0) || !(r[2].get<double>() <= 1.0) ||
          r[1].get<size_t>() > size_t{1} << 20)
        throw Error((src / "metadata.json").string() + ": light.fill_factor: expected runs of rows [first, count, fill factor in (0, 1]] from row 0");
      recorded.insert(recorded.end(), r[1].get<size_t>(), r[2].get<double>());
    }
    if (recorded.size() != was.size())
      throw Error((src / "metadata.json").string() + ": light.fill_factor covers " + std::to_string(recorded.size()) +
                  " rows, the sensor has " + std::to_string(was.size()));
    was = std::move(recorded);
  }
  if (std::vector<double> row_scale = scale_from(was); !row_scale.empty()) light.set_row_scale(std::move(row_scale));

  // The files the sensor does not write come from the run: the exact ground truth, the transients, the light.
  // labels.exr is the sensor's: recomputed from the run's ground truth for this call's settings.
  std::vector<std::string> linked;
  std::set<std::string> rescaled;  // of those, the files of photons another pixel design rewrites
  for (const auto& f : meta.at("files")) {
    const std::string name = f.get<std::string>();
    const std::string stem = name.substr(0, name.rfind('.'));
    const bool transient = stem == "transient" || stem == "transient_indirect";
    if (name == "ground_truth.exr" || (name == "previews/depth.png" && cfg.outputs.previews) || transient ||
        name.rfind("light/", 0) == 0)
      linked.push_back(name);
    if (!file_scale.empty() && (name == "ground_truth.exr" || transient)) {
      if (transient && !name.ends_with(".npy"))
        throw Error(src.string() + ": its " + name + " holds the light of the run's pixel design, which sense rescales for "
                    "another design in .npy transients only; sense a run with outputs.storage = npy, or keep the run's "
                    "sensor.preset and fill factors");
      rescaled.insert(name);
    }
  }
  // Zarr stores of the run linked into a folder whose own stacks are .npy: the folder is still a Zarr group
  // (docs/outputs.md), so the run's .zgroup comes too.
  if (cfg.outputs.storage != Storage::Zarr && std::any_of(linked.begin(), linked.end(), [](const std::string& f) {
        return f.find('/') == std::string::npos && f.ends_with(".zarr");
      }))
    for (const auto& f : meta.at("files"))
      if (f.get<std::string>() == ".zgroup") linked.push_back(".zgroup");
  // The same sensor as the run's (settings, chip, tables; only the noise may differ): what does not depend
  // on the noise (the rates, the maps, the laser and ambient images, the labels) is the run's, bit for
  // bit, and is linked rather than computed and written again.
  // (the tables as the sensor read them, not read again)
  const bool same_tables = meta.value("sensor_tables_fnv1a64", std::string()) == tables_read.hash;
  const bool same_sensor = same_tables && noise_free_part(first.resolved) == noise_free_part(source.resolved);
  // The run's own tables that this call reads where the run read them and that changed there since (a table
  // --set gives anew, in another place or of other contents, is this call's own: nothing to say of it).
  if (!same_tables) {
    std::string changed;
    const std::vector<scenes::SensorTable> run_tables = scenes::sensor_tables(source.config), &tables = tables_read.tables;
    const json* recorded = meta.contains("sensor_table_fnv1a64") && meta.at("sensor_table_fnv1a64").is_object()
                               ? &meta.at("sensor_table_fnv1a64") : nullptr;
    bool all_same_paths = true;
    for (size_t i = 0; i < run_tables.size(); ++i) {
      all_same_paths = all_same_paths && run_tables[i].path == tables[i].path;
      if (recorded && !tables[i].path.empty() && tables[i].path == run_tables[i].path && recorded->contains(tables[i].key) &&
          recorded->at(tables[i].key) != tables[i].hash)
        changed += (changed.empty() ? "" : ", ") + tables[i].key;
    }
    // (a run saved before the per-table hashes: its tables at their paths, one hash of them all)
    if (!recorded && all_same_paths && meta.contains("sensor_tables_fnv1a64"))
      changed = "laser.pulse_shape_csv, sensor.gate.profile_csv or maps_exr, a pdp_csv";
    if (!changed.empty()) {
      std::string w = std::string(kTablesChangedWarning) + changed + ") have changed on disk since the run: this sense "
                      "uses them as they are now";
      print_warning(w);
      scene_warnings.push_back(std::move(w));  // metadata.json's warnings hold it too (it was on stderr only)
    }
  }
  RunConfig write_cfg = cfg;  // what the sensor stage writes itself
  write_cfg.outputs.ground_truth = false, write_cfg.outputs.transient = false, write_cfg.outputs.light = false;

  // The run's folder as a name (RUN/, ./RUN/. and RUN are one folder): the default output is beside it.
  const fs::path run_abs = resolved_folder(src);
  fs::path run_named = fs::absolute(src).lexically_normal();  // as named: beside a link, not its target
  if (!run_named.has_filename()) run_named = run_named.parent_path();
  // A realisation of a sense --repeats set (set/repeat_001): beside the set (set-repeat_001-sense), which holds
  // its realisations only; a dataset's sample (DATASET/samples/000001): beside the dataset
  // (DATASET-000001-sense), whose samples/ holds its samples only.
  const fs::path set = run_named.parent_path(), dataset = set.parent_path();
  const bool of_dataset = set.filename() == "samples" && fs::is_regular_file(dataset / "dataset.json");
  const fs::path beside =
      realisations_of(meta) > 0 ? set.parent_path() / (set.filename().string() + "-" + run_named.filename().string() + "-sense")
      : of_dataset             ? dataset.parent_path() / (dataset.filename().string() + "-" + run_named.filename().string() + "-sense")
                               : set / (run_named.filename().string() + "-sense");
  const fs::path out = options.out_dir.empty() ? beside : fs::path(options.out_dir);
  {
    const fs::path out_abs = resolved_folder(out);
    const auto [end, it] = std::mismatch(run_abs.begin(), run_abs.end(), out_abs.begin(), out_abs.end());
    if (end == run_abs.end())  // out is the run's folder or inside it
      throw Error("-o " + out.string() + ": sense writes a new folder beside the run, not into it");
    if (it == out_abs.end())  // out holds the run: its swap would remove the run (a repeats set's realisation)
      throw Error("-o " + out.string() + ": it holds the run " + run_abs.string() + ", which sense reads, and sense replaces " +
                  "its output folder as a whole; write beside the run, not around it");
  }
  // Not inside another run folder, a set of realisations or a dataset's own entries, but a dataset's sample
  // when the dataset writes its realisations (samples/000003_r01).
  refuse_run_folder_inside(out, !options.out_dir.empty(), options.dataset.has_value());
  // Realisations differ in their sampled counts and frames only (a gate sweep's; a 2D run's images hold its
  // counts): without them R folders of the same files (it wrote them, exit 0).
  const std::vector<sensor::DeclaredOutput> declared = sensor.acquisition().outputs();
  if (runs.size() > 1 && !cfg.outputs.counts && !cfg.outputs.frames && !cfg.outputs.previews &&
      std::none_of(declared.begin(), declared.end(), [](const sensor::DeclaredOutput& d) { return d.file == "intensity.exr"; }))
    throw Error("--repeats " + std::to_string(runs.size()) + ": the realisations differ in their counts, frames and the " +
                "previews of the counts only, and outputs.counts, outputs.frames and outputs.previews are false: each " +
                "would hold the same files; set one of them true (--set outputs.counts=true), or sense once");
  // The run's objects bound labels.exr's slots (a run before objects had none).
  const int objects = meta.contains("objects") ? int(meta.at("objects").size()) : 0;
  std::vector<fs::path> dirs;
  // With --repeats OUT holds the realisations' folders, staged together and published as one: OUT holds
  // the earlier set or the new one, never a mix of their realisations, never one left from a call with more.
  // Without -o the output folder is the default beside the run: a refusal of it says so, not "(-o)".
  const auto staged = [&](const auto& make) {
    try {
      return make();
    } catch (const Error& e) {
      std::string message = e.what();
      const std::string given = " as the output folder (-o)";
      if (const size_t at = message.find(given); at != std::string::npos && options.out_dir.empty())
        message.replace(at, given.size(), " as the output folder (sense's default without -o, the run's name and '-sense' "
                                          "beside it; name another with -o)");
      throw Error(message);
    }
  };
  std::unique_ptr<Staging> top =
      runs.size() > 1 ? staged([&] { return std::make_unique<Staging>(out, Staging::OfRuns{}); }) : nullptr;
  std::vector<std::unique_ptr<Staging>> staging;
  std::vector<std::unique_ptr<Outputs>> outputs;
  std::vector<uint64_t> seeds;
  // Realisations differ in their counts and frames only: the others link the files of the first.
  std::set<std::string> shared = {"laser.exr", "ambient.exr", "sensor_maps.exr", "labels.exr"};
  const bool run_truth = std::find(linked.begin(), linked.end(), "ground_truth.exr") != linked.end();
  std::set<std::string> from_run;
  if (run_truth) from_run.insert("ground_truth.exr");
  for (const StackLayout& l : stack_layout(write_cfg, sensor, img, axis))
    if (l.file.starts_with("detection_rate.") || l.file.starts_with("expected_counts.")) shared.insert(l.file);
  bool two_d = false;
  for (const sensor::DeclaredOutput& d : declared) two_d |= d.file == "intensity.exr";
  if (!two_d) shared.insert("previews/intensity.png");  // the laser light, in a gate sweep
  if (same_sensor)
    for (const auto& f : meta.at("files"))
      if (shared.count(f.get<std::string>())) {
        from_run.insert(f.get<std::string>());
        linked.push_back(f.get<std::string>());
      }
  // The run's files this call links must all be there, before any work (a user may have removed one to
  // save space: the run is then incomplete for sense).
  for (const std::string& f : linked) {
    if (!fs::exists(src / f))
      throw Error((src / f).string() + ": listed in " + (src / "metadata.json").string() +
                  " (files) but missing; sense links the run's files as they are: restore it, or run the scene again");
    // ... a file as the run wrote it (a FIFO or a folder in its place was said to hold 0 bytes) ...
    std::error_code ec;
    const fs::file_status st = fs::status(src / f, ec);
    if (!fs::is_regular_file(st) && !fs::is_directory(st))
      throw Error((src / f).string() + ": listed in " + (src / "metadata.json").string() + " (files) but is not a regular file "
                  "(a FIFO, a socket or a device); sense links the run's files as they are: restore it, or run the scene again");
    // (a folder only where the run wrote one, a Zarr store: a folder labels.exr was said to hold 0 bytes)
    if (fs::is_directory(st) && !f.ends_with(".zarr"))
      throw Error((src / f).string() + ": listed in " + (src / "metadata.json").string() + " (files) as a file but is a folder; "
                  "sense links the run's files as they are: restore it, or run the scene again");
    // ... and whole: as many bytes as the run wrote (a copy cut short would be linked as it is)
    if (meta.contains("file_bytes") && meta["file_bytes"].contains(f) && meta["file_bytes"][f].is_number_integer())
      if (const int64_t want = meta["file_bytes"][f].get<int64_t>(), have = writers::bytes_on_disk((src / f).string()); have != want)
        throw Error((src / f).string() + ": holds " + std::to_string(have) + " bytes, and the run wrote " + std::to_string(want) +
                    " (" + (src / "metadata.json").string() + ", file_bytes): changed or cut short since; sense links the "
                    "run's files as they are: restore it, or run the scene again");
  }
  // Memory: the realisations' counts and frames each, their rates shared. Disk: the stacks the run's folder provides are links
  // and take none; each further realisation writes its own counts and frames (its images are links).
  {
    const fs::path where = out.parent_path().empty() ? fs::path(".") : out.parent_path();
    ResourcePlan plan = plan_resources(write_cfg, sensor, img, axis, options.threads, where, objects, nullptr, int(runs.size()),
                                       light_laser);
    // Sense traces no camera paths; its transient tiles are rebuilt from the saved light.
    std::erase_if(plan.memory, [](const ResourcePlan::Part& p) { return p.what.starts_with("camera paths"); });
    for (ResourcePlan::Part& p : plan.memory)
      if (p.what.starts_with("transient tiles")) p.what.insert(15, " rebuilt from the saved light");
    std::vector<ResourcePlan::Part> disk;
    for (ResourcePlan::Part p : plan.disk) {
      if (from_run.count(p.file)) continue;
      disk.push_back(p);
      if (runs.size() > 1 && !p.file.empty() && !shared.count(p.file)) {
        p.what += " x " + std::to_string(runs.size() - 1) + (runs.size() == 2 ? " more realisation" : " more realisations") + " (--repeats)";
        p.bytes *= int64_t(runs.size() - 1);
        disk.push_back(p);
      }
    }
    // Across file systems the run's files are copied, not linked (once: the other realisations link the
    // first's copies).
    const fs::path existing = existing_ancestor(where);
    struct stat st_run {}, st_out {};
    if (::stat(src.c_str(), &st_run) == 0 && ::stat(existing.c_str(), &st_out) == 0 && st_run.st_dev != st_out.st_dev &&
        !linked.empty()) {
      ResourcePlan::Part copies{"the run's " + std::to_string(linked.size()) + " files it keeps, copied (another file system: no hard links)"};
      for (const std::string& f : linked) copies.bytes += writers::bytes_on_disk((src / f).string());
      disk.push_back(copies);
    }
    plan.disk = std::move(disk);
    check_resources(plan, write_cfg, out, "sense " + src.string(),
                    "switch outputs off (--set outputs.*), ask for fewer --repeats, or choose another folder (-o)");
    // Every realisation holds its folder's lock and its .npy stacks open until it commits.
    int64_t held = 0;
    for (const StackLayout& l : stack_layout(write_cfg, sensor, img, axis))
      if (l.written && l.chunks.empty()) held += int64_t(runs.size()) - (from_run.count(l.file) ? 1 : 0) -
                                                (shared.count(l.file) ? int64_t(runs.size()) - 1 : 0);
    held += 2 * int64_t(runs.size());  // the lock, and a margin for the staging folder
    // The process's own: what it has open now (the standard streams, and whatever its parent left open to
    // it), and 5 for the run's files while they are read and the libraries' (TBB, Embree, OpenEXR).
    // Measured: one realisation of a 16 x 16 run with frames needs ulimit -n 8 from a shell, ten 40.
    int64_t open_now = 3;
    if (std::error_code ec; fs::is_directory("/proc/self/fd", ec)) {
      open_now = 0;
      for (fs::directory_iterator it("/proc/self/fd", ec), end; !ec && it != end; it.increment(ec)) ++open_now;
      open_now = std::max<int64_t>(open_now - 1, 3);  // less the iterator's own descriptor
    }
    const int64_t own_files = open_now + 5;
    rlimit lim{};
    const bool limited = getrlimit(RLIMIT_NOFILE, &lim) == 0 && lim.rlim_cur != RLIM_INFINITY;
    const int64_t per_realisation = (held + int64_t(runs.size()) - 1) / int64_t(runs.size());
    if (limited && per_realisation + own_files > int64_t(lim.rlim_cur))
      throw Error("sense holds about " + std::to_string(per_realisation + own_files) + " files open (its stacks, a lock, the " +
                  std::to_string(open_now) + " it has open, and 5 to read the run), and this process may open " + std::to_string(lim.rlim_cur) + " (ulimit -n): raise the limit");
    if (limited && held + own_files > int64_t(lim.rlim_cur))
      throw Error("--repeats " + std::to_string(runs.size()) + ": the realisations hold about " + std::to_string(held) +
                  " files open until they are written, and this process may open " + std::to_string(lim.rlim_cur) +
                  " (ulimit -n): ask for at most " +
                  std::to_string(std::max<int64_t>(1, (int64_t(lim.rlim_cur) - own_files) * int64_t(runs.size()) / held)) +
                  " realisations per call, or raise the limit");
  }
  for (size_t r = 0; r < runs.size(); ++r) {
    char name[32];
    std::snprintf(name, sizeof name, "repeat_%03zu", r);
    dirs.push_back(runs.size() == 1 ? out : out / name);
    staging.push_back(top ? std::make_unique<Staging>(*top, name) : staged([&] { return std::make_unique<Staging>(dirs.back()); }));
    std::set<std::string> provided = r == 0 ? from_run : shared;
    provided.insert(from_run.begin(), from_run.end());
    // (the laser's images where the saved light holds its light)
    outputs.push_back(std::make_unique<Outputs>(write_cfg, sensor, img, axis, *staging.back(), objects, options.threads,
                                                light_laser, provided));
    seeds.push_back(runs[r].config.noise_seed());
  }

  std::vector<PixelRect> tiles = make_tiles(img.width, img.height, cfg.render.tile_size);
  for (PixelRect& t : tiles) t.x0 += img.x0, t.y0 += img.y0;
  if (options.progress)
    std::fprintf(stderr, "spadgen: sense %s: %d x %d pixels, K = %d, %zu realisation(s)\n", src.string().c_str(), img.width,
                 img.height, sensor.K(), runs.size());
  const bool labels_from_truth = outputs.front()->labels() && !from_run.count("labels.exr");
  std::unique_ptr<writers::ExrData> truth;  // the run's, for the labels and the ground truth rescaled
  if (labels_from_truth || rescaled.count("ground_truth.exr")) {
    const std::string path = (src / "ground_truth.exr").string();
    truth = std::make_unique<writers::ExrData>(writers::read_exr(path));
    // the run's image (another run's of another size or crop would label the counts with its objects)
    const std::string crop = nlohmann::json::array({img.x0, img.y0, img.width, img.height}).dump();
    const auto at = truth->attributes.find("spadgen_crop");
    if (truth->width != img.width || truth->height != img.height || (at != truth->attributes.end() && at->second != crop))
      throw Error(path + ": an image of " + std::to_string(truth->width) + " x " + std::to_string(truth->height) + " pixels" +
                  (at != truth->attributes.end() ? " at the crop " + scenes::one_line(at->second.substr(0, 80)) : std::string()) +
                  ", and the run's is " + crop + " (metadata.json image.crop_in_sensor): a file of another run; restore the "
                  "run's, or run the scene again");
    if (!file_scale.empty()) scale_truth(*truth, img, file_scale);
  }
  const double setup_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  Progress progress(tiles.size(), options.progress);
  StageClock clock;  // where the tiles' time goes (metadata.json "run")
  tbb::parallel_for(size_t(0), tiles.size(), [&](size_t ti) {
    InterruptGuard::check();
    const PixelRect& rect = tiles[ti];
    TransientTile t;
    {
      const StageClock::Scope time(&clock, StageClock::kSavedLight);
      t = light.tile(rect, grow_clipped(rect, sensor.halo(), cfg.camera.width_px, cfg.camera.height_px));
    }
    std::vector<SensorTile> s;
    {
      const StageClock::Scope time(&clock, StageClock::kSensorRates);  // the noise inside it times itself
      s = sensor.process(t, seeds);
    }
    const StageClock::Scope time(&clock, StageClock::kOutputs);
    const sensor::SensorMapsTile maps = sensor.maps(rect);
    // The labels do not depend on the noise: the first realisation's serve all (the others link them).
    if (labels_from_truth)
      outputs.front()->put_labels(sensor::object_labels(
          sensor, object_truth(*truth, img, rect, cfg.render.max_layers, src / "ground_truth.exr"), s.front(), axis,
          cfg.laser.emission_delay_s));
    for (size_t r = 0; r < s.size(); ++r) {
      InterruptGuard::check();  // --repeats 400: a tile's realisations took seconds to store after a signal
      outputs[r]->put(t, maps, std::move(s[r]));
    }
    light.recycle(std::move(t));
    progress.tick();
  });
  const double tiles_seconds = progress.seconds();
  const auto tiles_done = std::chrono::steady_clock::now();

  const Provenance prov{scene_file, field<std::string>(meta, "/scene_hash_fnv1a64"_json_pointer, src), cfg.seed, img, cfg.chip_seed(),
                        tables_read.hash, tables_read.tables};
  std::vector<RunResult> results;
  json first_storage = json::object();
  json labels_summary;  // Outputs::report's, of the first realisation: what this call's labels say
  for (size_t r = 0; r < runs.size(); ++r) {
    InterruptGuard::check();
    outputs[r]->write(prov);
    std::vector<std::string> files = outputs[r]->files();
    for (const std::string& f : linked) {  // the later realisations link the first's (copies across file systems)
      if (r == 0 && rescaled.count(f)) {
        if (f == "ground_truth.exr") write_exr_as(*truth, staging[r]->path(f), cfg.outputs.exr_compression);
        else write_rescaled_transient(src / f, staging[r]->path(f), file_scale, rect_of(meta.at("transient").at("crop_in_sensor")));
      } else {
        link_into(r == 0 ? src / f : fs::path(staging.front()->path(f)), *staging[r], f);
      }
      files.push_back(f);
    }
    if (r > 0)
      for (const std::string& f : results.front().files)
        if (shared.count(f) && !from_run.count(f)) {
          link_into(staging.front()->path(f), *staging[r], f);
          files.push_back(f);
        }
    files.push_back("metadata.json");
    order_files(files);

    RunRecord record;
    outputs[r]->report(record);
    if (r == 0) {  // the realisations share their rates and labels
      std::vector<std::string> ws = bright_gate_warnings(sensor, record.laser_open_rate);
      if (!from_run.count("labels.exr")) {
        for (std::string& w : sweep_edge_warnings(cfg, record)) ws.push_back(std::move(w));
      } else {  // the run's labels, linked, are not counted here (put_labels counts): the run's words of them
        for (const auto& w : meta.at("warnings"))
          if (w.get<std::string>().find(kSweepEdgeWarning) != std::string::npos) ws.push_back(w.get<std::string>());
      }
      for (std::string& w : ws) {
        print_warning(w);
        scene_warnings.push_back(std::move(w));
      }
    }
    // The containers of the files linked from the run or from the first realisation, as recorded there.
    const json& run_storage = meta.contains("/storage/files"_json_pointer) ? meta.at("/storage/files"_json_pointer) : json::object();
    for (const std::string& f : files) {
      if (record.storage.contains(f)) continue;
      if (run_storage.contains(f)) record.storage[f] = run_storage.at(f);
      else if (r > 0 && first_storage.contains(f)) record.storage[f] = first_storage.at(f);
    }
    if (r == 0) first_storage = record.storage;
    record.files = files;
    record.photons_per_pulse_emitted = meta.at("photons_per_pulse_emitted").get<double>();
    record.camera = meta.at("camera");
    record.ground_truth_layers = meta.at("ground_truth_layers").get<int>();
    if (meta.contains("ground_truth_objects")) record.ground_truth_objects = meta.at("ground_truth_objects").get<int>();
    if (meta.contains("objects")) record.objects = meta.at("objects");
    record.laser_traced = light_laser;
    record.model = model_components(cfg, nullptr, light_laser, meta.contains("model") ? meta.at("model") : nlohmann::json(nullptr));
    // The run's summary of its ground truth; what this call's labels say (the first realisation computed
    // them for all) replaces the run's.
    if (r == 0) labels_summary = record.ground_truth_summary;
    if (meta.contains("ground_truth_summary")) record.ground_truth_summary = meta.at("ground_truth_summary");
    if (record.ground_truth_summary.is_object() && std::find(files.begin(), files.end(), "labels.exr") == files.end())
      for (const char* key : {"objects_detectable", "detectable_fraction"}) record.ground_truth_summary.erase(key);  // no labels
    if (!labels_summary.is_null() && record.ground_truth_summary.is_object()) record.ground_truth_summary.update(labels_summary);
    record.dataset = options.dataset;
    if (meta.contains("transient")) record.transient_crop = rect_of(meta.at("transient").at("crop_in_sensor"));
    record.light_region = region;
    record.light_values_bytes = meta.at("light").at("values_bytes").get<int64_t>();
    record.light_fill_factor = was;  // the light is linked as the run saved it
    record.threads = options.threads;
    record.seconds = tiles_seconds;
    record.times.setup_seconds = setup_seconds;
    record.times.tiles_seconds = tiles_seconds;
    record.times.take_stages(clock);
    // The realisations' images so far (a sense with --repeats writes them one after the other).
    record.times.finish_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - tiles_done).count();
    record.sense = json{{"from", fs::absolute(src).lexically_normal().string()}, {"repeat", r}, {"repeats", runs.size()}};
    InterruptGuard::check();
    outputs[r]->commit();
    record.file_bytes = file_bytes(staging[r]->path(""), files);  // every file complete: metadata.json goes last
    writers::write_json(staging[r]->path("metadata.json"), metadata(runs[r], scene_warnings, sensor, prov, axis, record));
    if (top) staging[r]->finish_sub();
    else staging[r]->publish(files);
    results.push_back({dirs[r].string(), files});
  }
  if (top) {  // the realisations as one
    std::vector<std::string> all;
    for (size_t r = 0; r < results.size(); ++r)
      for (const std::string& f : results[r].files) all.push_back(dirs[r].filename().string() + "/" + f);
    InterruptGuard::check();
    top->publish(all);
  }
  if (options.progress)
    std::fprintf(stderr, "spadgen: wrote %zu folder(s) to %s in %.1f s\n", results.size(), out.string().c_str(),
                 std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
  return results;
}

}  // namespace spadgen::app
