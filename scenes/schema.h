// The one declaration of every scene-file key: its JSON path, type, unit, valid range, meaning, and the
// RunConfig field it fills. The default is the field's initializer in core/config.h (converted to the
// key's unit); nothing else declares a key. Parsing (scene_file.cpp), `spadgen schema`, the JSON
// Schema and docs/scene-file.md are all generated from this list.
//
// Adding a key: one field in core/config.h (with its SI default), one line in schema.cpp.
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
  std::vector<std::string> choices;
  bool nullable = false;
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
};

// Every key of a scene file, in the order the resolved scene file lists them.
const std::vector<Key>& schema();

}  // namespace spadgen::scenes
