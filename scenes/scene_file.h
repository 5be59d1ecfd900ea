// Scene files: JSON (comments allowed) naming a glTF file and the camera, laser, ambient, sensor,
// acquisition, render and outputs sections. Every key is declared once in a schema with its type, unit,
// default and valid range; unknown keys, wrong types and out-of-range values are errors that name the
// file, the key path (/camera/f_number), what was found and what was expected.
#pragma once
#include <nlohmann/json.hpp>

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "core/config.h"

namespace spadgen::scenes {

// Counts that every later stage must be able to hold, checked when the scene file is read (the time
// axis a gate sweep derives is checked against kMaxTimeBins by the program, app/preflight.h).
inline constexpr int64_t kMaxGatePositions = 100'000;  // acquisition.gate_sweep: (stop - start) / step + 1
inline constexpr int64_t kMaxTimeBins = 1'000'000;     // transient bins: window / render.time_bin_ps
// The largest seed (seed, seeds.*, --seed, a dataset's seeds): 2^53, so that every seed is exact as a JSON
// number in metadata.json.
inline constexpr uint64_t kMaxSeed = uint64_t{1} << 53;

struct ResolvedRun {
  RunConfig config;         // SI units, every default explicit
  // The scene file as the user would write it, every default explicit, keys in schema order.
  nlohmann::ordered_json resolved;
  std::vector<std::string> warnings;  // consistent but suspicious settings, e.g. exposure longer than a frame
  // The keys `--set` gave, by JSON pointer (/render/time_bin_ps), each as the user wrote it
  // (render.time_bin_ps): the program's later checks name the override, not the file, as these do.
  std::map<std::string, std::string> set_keys;
};

// Reads, validates and resolves a scene file. overrides are "key.path=value" strings (as `--set`),
// applied before validation so that a wrong key or value fails exactly as it would inside the file.
ResolvedRun load_scene_file(const std::string& path, const std::vector<std::string>& overrides = {});

// The same from JSON text; `path` names the file in messages and resolves the relative glTF path.
// files: which files the scene names are looked for (regular, of bounded size): all of them; the sensor's
// tables alone (spadgen sense re-samples a run's saved light, which needs the tables but not the geometry);
// none (sense's reading of the run's own scene, whose tables a --set may give anew in another place).
enum class FileChecks { All, Tables, None };
ResolvedRun parse_scene_text(const std::string& text, const std::string& path,
                             const std::vector<std::string>& overrides = {}, FileChecks files = FileChecks::All);

// Checks one override as `--set KEY=VALUE` does, without a scene file: the key's syntax (dots, quoted
// names, a final [i]; scenes/key_path.h), that the schema has the key (a named element's key for
// nodes.NAME.* and materials.NAME.*), that [i] selects a component of an [x, y, z] key, and that the value
// fits the key's type and range. Returns the errors `--set` would report, one line each, without the scene
// file's name and without "--set " ("camera.f_numbr: /camera/f_numbr: unknown key; did you mean
// /camera/f_number?", "/camera/f_number: found 100 (an integer), expected a number in [0.5, 64] (...)"); none
// when the override is valid. `value` is JSON as it would stand in the scene file (for a component [i], the
// component alone): `--set`'s reading of text that is not JSON as a string is not applied.
// Not checked, for want of a scene: whether a glTF node or material of that name exists (the loader's
// check), and the rules that span keys (a crop inside the sensor, ...).
// A dataset file's axes (datasets/) are checked with it before any run.
std::vector<std::string> check_override(const std::string& key, const nlohmann::json& value);

// The reference of every key (path, type, unit, default, range, meaning) as Markdown.
std::string schema_reference_markdown();

// The same as a JSON Schema (draft 2020-12), for editors: types, units and meanings, ranges, choices,
// defaults, and no keys but these. Scene files may hold comments, so editors should read them as JSONC.
std::string schema_json();

// A table the sensor stage reads besides the scene file: its key (laser.pulse_shape_csv, ...), its path (as
// the scene resolved it, "" when not set) and the FNV-1a 64 (hex) of its bytes (of "" when not set or not
// readable).
struct SensorTable {
  std::string key, path, hash;
};
// FNV-1a 64 (hex) of the tables the sensor stage reads besides the scene file (laser.pulse_shape_csv,
// sensor.gate.profile_csv and maps_exr, each pixel design's pdp_csv), each as its length and bytes ("" for
// a table not set, or not readable): a run's metadata.json records it, so that `spadgen sense` knows
// whether the sensor it rebuilds is the run's, and a dataset's sample hash holds it.
// each (not null): every table, in that key order, from the same reading of each file.
std::string sensor_tables_hash(const RunConfig& c, std::vector<SensorTable>* each = nullptr);
// Every table, in that key order (sensor_tables_hash's `each`).
std::vector<SensorTable> sensor_tables(const RunConfig& c);
// Whether c names any of those tables.
bool uses_sensor_tables(const RunConfig& c);

// Whether the run uses a time window (render.window_start_ns, window_stop_ns, time_bin_ps): a gate sweep
// does; the intensity mode, which needs no time bins, only for transient.npy or the saved light (which a
// sense in a gate sweep reads). Elsewhere those keys do nothing: the bins they would make are not checked.
bool time_window_used(const RunConfig& c);

}  // namespace spadgen::scenes
