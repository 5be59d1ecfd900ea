// The one declaration of every scene-file key: its JSON path, type, unit, valid range, meaning, and the
// RunConfig field it fills. The default is the field's initializer in core/config.h (converted to the
// key's unit); nothing else declares a key. Parsing (scene_file.cpp), `spadgen schema`, the JSON
// Schema and docs/scene-file.md are all generated from this list.
//
// Adding a key: one field in core/config.h (with its SI default), one line in schema.cpp. A key of the
// glTF's nodes or materials (the named sections below): one optional field in NodeEdit or MaterialEdit,
// one line in schema.cpp, and where the loader applies it (gltf_loader.cpp).
#pragma once
#include <nlohmann/json.hpp>

#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "core/config.h"

namespace spadgen::scenes {

enum class Type { Number, Integer, Bool, String, Path, Enum, Vec3, Rect };

// A unit: how a value in the scene file becomes SI and back.
struct Unit {
  const char* name;                // as written in docs and messages ("" for plain numbers)
  double (*to_si)(double);
  double (*from_si)(double);
};

struct Key {
  std::string path;  // JSON pointer, e.g. "/camera/f_number"
  nlohmann::json::json_pointer pointer;  // the same, parsed once (json and ordered_json share the type)
  Type type = Type::Number;
  nlohmann::json def;  // in the key's unit; null for nullable keys without one; required keys have none
  double lo = -std::numeric_limits<double>::infinity();
  double hi = std::numeric_limits<double>::infinity();
  bool lo_open = false;  // lo is exclusive
  int multiple_of = 0;   // Integer: valid values are multiples of it (0: any)
  std::vector<std::string> choices;
  bool nullable = false;
  bool null_components = false;  // Vec3: each component may be null instead (a named element's: the glTF's)
  bool required = false;
  std::string unit;
  std::string doc;
  // Stores a valid value (in the key's unit, as resolved) into its RunConfig field, in SI. Paths are made
  // absolute against `dir`, the scene file's folder. Null for keys that fill no field (description).
  std::function<void(RunConfig&, const nlohmann::ordered_json&, const std::string& dir)> set;
  // Why the key does nothing under the other settings (e.g. "acquisition.mode is \"intensity\""), or "" when
  // it takes effect; null for keys that always do. A scene file or --set giving such a key a value other than
  // its default gets a warning (the default changes nothing either way).
  std::function<std::string(const RunConfig&)> ignored;
  // A key of a named section's elements: stores a valid value into the element named `name` (in SI). Null
  // for every other key.
  std::function<void(RunConfig&, const std::string& name, const nlohmann::ordered_json&)> set_element;
};

// A section whose keys are names the glTF file chooses (its nodes, its materials), each holding an object
// of the same few keys, e.g. "nodes": {"Sphere": {"translation_m": [0, 0, -0.75]}}. A name is any non-empty
// string; which names exist is the glTF's to say (the loader checks them). The element keys have no
// default: a key left out keeps the glTF's value.
struct NamedSection {
  std::string path;         // "/nodes": a top-level section
  std::string element;      // "node": what each name names, in messages and docs
  std::string doc;
  std::vector<Key> keys;    // Key::path relative to the element ("/translation_m"), in resolved order
  // Adds the element named `name` (no value replaced yet) to the run description.
  std::function<void(RunConfig&, const std::string& name)> add;
};

// Every key of a scene file, in the order the resolved scene file lists them.
// render.quality's presets: for each preset name, the keys (JSON pointers) it sets and their values in the
// scene file's units. A key the scene file gives keeps its own value (docs/accuracy.md).
const nlohmann::json& quality_presets();

const std::vector<Key>& schema();

// The sections of named elements, listed after every key of schema() in the resolved scene file.
const std::vector<NamedSection>& named_sections();

}  // namespace spadgen::scenes
