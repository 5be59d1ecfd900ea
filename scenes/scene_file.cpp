// Scene files: one schema declares every key (type, unit, default, range, meaning); parsing checks the
// user's JSON against it, applies `--set` overrides through the same checks, fills the defaults and
// converts to SI. A typo must never become a silently wrong dataset, so unknown keys are errors.
#include "scene_file.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <utility>

#include "core/error.h"
#include "core/units.h"
#include "scenes/input.h"
#include "scenes/key_path.h"
#include "schema.h"

namespace spadgen::scenes {
namespace {

using json = nlohmann::json;
using ojson = nlohmann::ordered_json;

const Key* find_key(const std::string& path) {
  for (const Key& k : schema())
    if (k.path == path) return &k;
  return nullptr;
}

// True when some key lies below `path` (it is a section).
bool is_section(const std::string& path) {
  const std::string prefix = path + "/";
  for (const Key& k : schema())
    if (k.path.compare(0, prefix.size(), prefix) == 0) return true;
  return false;
}

const NamedSection* find_named(const std::string& path) {
  for (const NamedSection& s : named_sections())
    if (s.path == path) return &s;
  return nullptr;
}

// The key `name` of a named section's elements.
const Key* find_element_key(const NamedSection& s, const std::string& name) {
  for (const Key& k : s.keys)
    if (k.path.compare(1, std::string::npos, name) == 0) return &k;
  return nullptr;
}

std::string element_keys_text(const NamedSection& s) {
  std::string list;
  for (const Key& k : s.keys) list += (list.empty() ? "" : ", ") + k.path.substr(1);
  return list;
}

std::string parent_of(const std::string& path) { return path.substr(0, path.rfind('/')); }
std::string leaf_of(const std::string& path) { return path.substr(path.rfind('/') + 1); }

// The children (keys and sections) the schema allows directly under `parent`.
std::vector<std::string> children_of(const std::string& parent) {
  std::vector<std::string> out;
  const std::string prefix = parent + "/";
  for (const Key& k : schema()) {
    if (k.path.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string rest = k.path.substr(prefix.size());
    const std::string child = prefix + rest.substr(0, rest.find('/'));
    if (std::find(out.begin(), out.end(), child) == out.end()) out.push_back(child);
  }
  for (const NamedSection& s : named_sections())
    if (parent_of(s.path) == parent) out.push_back(s.path);
  return out;
}

// "did you mean" for an unknown path: the closest sibling, else a key of the same name elsewhere.
std::string suggestion(const std::string& path) {
  const std::string leaf = leaf_of(path);
  std::string best;
  size_t best_d = std::max<size_t>(2, leaf.size() / 3) + 1;
  for (const std::string& c : children_of(parent_of(path))) {
    const size_t dist = edit_distance(leaf, leaf_of(c));
    if (dist < best_d) best_d = dist, best = c;
  }
  if (best.empty())
    for (const Key& k : schema())
      if (leaf_of(k.path) == leaf) return "; did you mean " + k.path + "?";
  if (best.empty()) {
    std::string list;
    for (const std::string& c : children_of(parent_of(path))) list += (list.empty() ? "" : ", ") + leaf_of(c);
    return list.empty() ? std::string() : "; the keys here are: " + list;
  }
  return "; did you mean " + best + "?";
}

// "did you mean" for an unknown key `leaf` of the element at `element_pointer` (/nodes/Sphere), else the list.
std::string element_suggestion(const NamedSection& s, const std::string& leaf, const std::string& element_pointer) {
  std::string best;
  size_t best_d = std::max<size_t>(2, leaf.size() / 3) + 1;
  for (const Key& k : s.keys) {
    const size_t dist = edit_distance(leaf, k.path.substr(1));
    if (dist < best_d) best_d = dist, best = k.path.substr(1);
  }
  if (!best.empty()) return "; did you mean " + element_pointer + "/" + pointer_token(best) + "?";
  return "; the keys of a " + s.element + " are: " + element_keys_text(s);
}

// A value as a message shows it: at most 60 characters. Containers are cut before they are dumped, so
// neither the time nor the depth of the dump depends on what the user wrote.
std::string short_dump(const json& v) {
  if (!v.is_structured()) return v.dump();
  std::string s = v.is_array() ? "[" : "{";
  size_t i = 0;
  for (auto it = v.begin(); it != v.end() && s.size() <= 60; ++it, ++i) {
    if (i) s += ",";
    if (v.is_object()) s += json(it.key()).dump() + ":";
    s += it.value().is_structured() ? (it.value().is_array() ? "[...]" : "{...}") : it.value().dump();
  }
  return s + (v.is_array() ? "]" : "}");
}

std::string describe_json(const json& v) {
  std::string s = short_dump(v);
  if (s.size() > 60) s = s.substr(0, 57) + "...";
  switch (v.type()) {
    case json::value_t::string: return s + " (a string)";
    case json::value_t::boolean: return s + " (a boolean)";
    case json::value_t::number_integer:
    case json::value_t::number_unsigned: return s + " (an integer)";
    case json::value_t::number_float: return s + " (a number)";
    case json::value_t::array: return s + " (an array)";
    case json::value_t::object: return s + " (an object)";
    case json::value_t::null: return "null";
    default: return s;
  }
}

std::string format_bound(double v) {
  std::ostringstream o;
  o << v;
  // A bound that six digits do not hold exactly as its digits (the seeds' 2^53 read 9.0072e+15, as if
  // 9007200000000000 were allowed).
  if (std::strtod(o.str().c_str(), nullptr) != v && std::floor(v) == v && std::fabs(v) <= 0x1p53)
    return std::to_string(static_cast<int64_t>(v));
  return o.str();
}

std::string expected_text(const Key& k) {
  std::string range;
  const bool has_lo = std::isfinite(k.lo), has_hi = std::isfinite(k.hi);
  if (has_lo && has_hi)
    range = std::string(k.lo_open ? " in (" : " in [") + format_bound(k.lo) + ", " + format_bound(k.hi) + "]";
  else if (has_lo)
    range = std::string(k.lo_open ? " > " : " >= ") + format_bound(k.lo);
  std::string unit = k.unit.empty() ? "" : " " + k.unit;
  std::string e;
  switch (k.type) {
    case Type::Number: e = "a number" + range + unit; break;
    case Type::Integer:
      e = (k.multiple_of ? "an integer multiple of " + std::to_string(k.multiple_of) : std::string("an integer")) + range + unit;
      break;
    case Type::Bool: e = "true or false"; break;
    case Type::String: e = "a string"; break;
    case Type::Path: e = "a string (a file name)"; break;
    case Type::Enum: {
      e = "one of";
      for (size_t i = 0; i < k.choices.size(); ++i) e += (i ? ", \"" : " \"") + k.choices[i] + "\"";
      break;
    }
    case Type::Vec3:
      e = "an array of 3 numbers" + (has_lo && has_hi ? " each in [" + format_bound(k.lo) + ", " + format_bound(k.hi) + "]" : std::string()) + unit;
      if (k.null_components) e += " or null (keeps the glTF's)";
      break;
    case Type::Rect: e = "[x0, y0, width, height] (integers in [0, 1000000], width and height >= 1)"; break;
  }
  if (k.nullable) e += ", or null";
  return e;
}

bool in_range(const Key& k, double v) {
  if (!std::isfinite(v)) return false;
  if (k.lo_open ? !(v > k.lo) : !(v >= k.lo)) return false;
  return v <= k.hi;
}

// Checks one value against its key; returns "" when it fits.
bool value_fits(const Key& k, const json& v) {
  if (v.is_null()) return k.nullable;
  switch (k.type) {
    case Type::Number: return v.is_number() && in_range(k, v.get<double>());
    case Type::Integer: {
      if (!v.is_number()) return false;
      const double d = v.get<double>();
      // Written as integer digits, the value itself: 2^53 + 1 is not 2^53 (a double would make it so).
      if (v.is_number_unsigned() && static_cast<uint64_t>(d) != v.get<uint64_t>()) return false;
      if (v.is_number_integer() && !v.is_number_unsigned() && static_cast<int64_t>(d) != v.get<int64_t>()) return false;
      // Written with a fraction or an exponent, the digits were rounded to a double: from 2^53 on, another
      // integer's (9007199254740993.0 read as 2^53)
      if (v.is_number_float() && std::fabs(d) >= 0x1p53) return false;
      return std::floor(d) == d && in_range(k, d) && (k.multiple_of == 0 || std::fmod(d, k.multiple_of) == 0.0);
    }
    case Type::Bool: return v.is_boolean();
    case Type::String:
    case Type::Path: return v.is_string();
    case Type::Enum:
      return v.is_string() && std::find(k.choices.begin(), k.choices.end(), v.get<std::string>()) != k.choices.end();
    case Type::Vec3:
      return v.is_array() && v.size() == 3 && std::all_of(v.begin(), v.end(), [&](const json& e) {
               return (e.is_number() && in_range(k, e.get<double>())) || (e.is_null() && k.null_components);
             });
    case Type::Rect: {
      if (!v.is_array() || v.size() != 4) return false;
      for (size_t i = 0; i < 4; ++i) {  // integers as integer keys take them: 8 or 8.0
        if (!v[i].is_number()) return false;
        const double d = v[i].get<double>();
        if (!(std::floor(d) == d && d >= (i < 2 ? 0.0 : 1.0) && d <= 1e6)) return false;
      }
      return true;
    }
  }
  return false;
}

// What a value that does not fit its key was, and what the key expects.
std::string misfit_text(const Key& k, const json& v) {
  std::string expected = expected_text(k), or_null;
  // (the digits are the integer's: ", or null" after them, not "or null written as its digits")
  if (const std::string tail = ", or null"; expected.ends_with(tail)) expected.resize(expected.size() - tail.size()), or_null = tail;
  std::string e = "found " + describe_json(v) + ", expected " + expected;
  if (k.type == Type::Integer && v.is_number_float() && std::fabs(v.get<double>()) >= 0x1p53)
    e += " written as its digits (a number with a fraction or an exponent is rounded to a double, which from 2^53 on may be "
         "another integer)";
  return e + or_null + " (" + k.doc + ")";
}

// A type as the reference and the messages name it.
std::string type_text(const Key& k) {
  switch (k.type) {
    case Type::Number: return "number";
    case Type::Integer: return "integer";
    case Type::Bool: return "bool";
    case Type::String: return "string";
    case Type::Path: return "file";
    case Type::Enum: return "choice";
    case Type::Vec3: return "[x, y, z]";
    case Type::Rect: return "[x0, y0, w, h]";
  }
  return "";
}

struct Checker {
  std::string file;            // "" : messages name no file (check_override)
  std::string set = "--set ";  // how messages name an override: "--set KEY: ..."
  std::vector<std::string> errors;
  // The keys an override gave, by JSON pointer, as the user wrote them: an error in one names the override,
  // not the scene file (which does not hold the value, and for spadgen sense may no longer exist).
  std::map<std::string, std::string> set_keys;

  std::string prefix() const { return file.empty() ? std::string() : file + ": "; }
  void error(const std::string& where, const std::string& what) {
    if (const auto it = set_keys.find(where); it != set_keys.end())
      errors.push_back(set + it->second + ": " + what);
    else
      errors.push_back(prefix() + where + ": " + what);
  }
  void override_error(const std::string& key, const std::string& what) { errors.push_back(prefix() + set + key + ": " + what); }

  // A section of named elements: any non-empty name, each an object of the section's keys.
  void walk_named(const json& node, const NamedSection& s) {
    if (!node.is_object()) {
      error(s.path, "found " + describe_json(node) + ", expected an object of glTF " + s.element + " names (" + s.doc + ")");
      return;
    }
    for (auto it = node.begin(); it != node.end(); ++it) {
      const std::string ep = s.path + "/" + pointer_token(it.key());
      if (it.key().empty()) {
        error(s.path, "found the key \"\", expected the name of a glTF " + s.element);
        continue;
      }
      if (!it.value().is_object()) {
        error(ep, "found " + describe_json(it.value()) + ", expected an object of a " + s.element + "'s keys (" +
                      element_keys_text(s) + ")");
        continue;
      }
      for (auto kv = it.value().begin(); kv != it.value().end(); ++kv) {
        const std::string kp = ep + "/" + pointer_token(kv.key());
        if (const Key* k = find_element_key(s, kv.key())) {
          if (!value_fits(*k, kv.value()))
            error(kp, misfit_text(*k, kv.value()));
        } else {
          error(kp, "unknown key" + element_suggestion(s, kv.key(), ep));
        }
      }
    }
  }

  void walk(const json& node, const std::string& path) {
    for (auto it = node.begin(); it != node.end(); ++it) {
      const std::string p = path + "/" + it.key();
      if (const NamedSection* s = path.empty() ? find_named(p) : nullptr) {
        walk_named(it.value(), *s);
        continue;
      }
      // "camera/f_number" would read as the path /camera/f_number and be checked as that key, yet the
      // section "camera" never sees it: a key name is one level.
      if (it.key().empty() || it.key().find_first_of("/~") != std::string::npos) {
        error(path.empty() ? "/" : path, "found the key " + json(it.key()).dump() +
                                              ", expected a key name without '/' or '~' (write sections as nested objects: "
                                              "{\"camera\": {\"f_number\": 2}})");
        continue;
      }
      if (const Key* k = find_key(p)) {
        if (!value_fits(*k, it.value()))
          error(p, misfit_text(*k, it.value()));
      } else if (is_section(p)) {
        if (!it.value().is_object())
          error(p, "found " + describe_json(it.value()) + ", expected an object (a section of keys)");
        else
          walk(it.value(), p);
      } else {
        error(p, "unknown key" + suggestion(p));
      }
    }
  }
};

// What a key names in the schema: a key (of a named section's element, or not), or why nothing.
struct Target {
  const Key* key = nullptr;
  const NamedSection* section = nullptr;  // the section whose element the key belongs to
  std::string problem;                    // when key is null: "unknown key; did you mean ...?"
};

Target find_target(const KeyPath& p) {
  Target t;
  const std::string ptr = p.pointer();
  if (const NamedSection* s = find_named("/" + pointer_token(p.names[0]))) {
    t.section = s;
    const std::string example = s->path.substr(1) + ".NAME." + s->keys.front().path.substr(1);
    if (p.names.size() == 1)
      t.problem = "is a section of glTF " + s->element + " names, not a key; e.g. " + example;
    else if (p.names.size() == 2)
      t.problem = "names a " + s->element + ", not a key; its keys are: " + element_keys_text(*s) + " (e.g. " +
                  s->path.substr(1) + "." + key_name(p.names[1]) + "." + s->keys.front().path.substr(1) + ")";
    else if (p.names.size() > 3)
      t.problem = "unknown key; a " + s->element + "'s keys are: " + element_keys_text(*s) +
                  " (a name that holds a dot is written in double quotes: " + s->path.substr(1) + ".\"Cube.001\"." +
                  s->keys.front().path.substr(1) + ")";
    else if (!(t.key = find_element_key(*s, p.names[2])))
      t.problem = "unknown key" + element_suggestion(*s, p.names[2], parent_of(ptr));
  } else if (!(t.key = find_key(ptr))) {
    const std::string first = "/" + pointer_token(p.names[0]);
    if (is_section(ptr))
      t.problem = "is a section, not a key";
    else if (p.names.size() > 1 && !is_section(first))
      t.problem = "unknown key: there is no section " + first + suggestion(first);
    else
      t.problem = "unknown key" + suggestion(ptr);
  }
  if (t.key && p.component) {
    const std::string i = "[" + std::to_string(*p.component) + "]";
    if (t.key->type != Type::Vec3)
      t.problem = i + " selects a component of an [x, y, z] key; this key is of type " + type_text(*t.key);
    else if (*p.component > 2)
      t.problem = "has no component " + i + "; expected [0], [1] or [2]";
    if (!t.problem.empty()) t.key = nullptr;
  }
  return t;
}

// Puts `value` where the key `p` names it in `doc`, creating the sections and elements on the way. A
// component [i] replaces one entry of the array the scene file gives, or of the default when it gives
// none ([null, null, null] for a named element's key: the other components stay the glTF's).
void put(json& doc, const KeyPath& p, const Target& t, const json& value, Checker& chk, const std::string& key) {
  json* node = &doc;
  std::string at;
  for (size_t i = 0; i + 1 < p.names.size(); ++i) {
    const std::string& part = p.names[i];
    at += '/';
    at += pointer_token(part);
    if (!node->contains(part)) (*node)[part] = json::object();
    if (!(*node)[part].is_object()) {
      chk.override_error(key, at + " is not " + (i == 0 ? "a section" : "an object") + " in the scene file");
      return;
    }
    node = &(*node)[part];
  }
  const std::string& leaf = p.names.back();
  if (!p.component) {
    (*node)[leaf] = value;
    return;
  }
  json whole = node->contains(leaf) ? (*node)[leaf] : t.section ? json::array({nullptr, nullptr, nullptr}) : t.key->def;
  if (!whole.is_array() || whole.size() != 3) {
    chk.override_error(key, p.pointer() + ": found " + describe_json(whole) + " in the scene file, expected an array of 3 " +
                                "to replace component [" + std::to_string(*p.component) + "] of");
    return;
  }
  whole[static_cast<size_t>(*p.component)] = value;
  (*node)[leaf] = whole;
}

// The key of an override, parsed and looked up; null (with the error recorded) when it names no key.
std::optional<std::pair<KeyPath, Target>> override_target(const std::string& key, Checker& chk) {
  KeyPath p;
  try {
    p = parse_key_path(key);
  } catch (const Error& e) {
    chk.override_error(key, e.what());
    return std::nullopt;
  }
  Target t = find_target(p);
  if (!t.key) {
    chk.override_error(key, p.pointer() + ": " + t.problem);
    return std::nullopt;
  }
  return std::pair{std::move(p), std::move(t)};
}

// "camera.f_number=2.8" -> (/camera/f_number, 2.8). A value that is not JSON is taken as a string.
// Returns the key's path (its JSON pointer), "" when the override was refused.
std::string apply_override(json& doc, const std::string& assignment, Checker& chk) {
  if (const size_t bad = invalid_utf8_at(assignment); bad != std::string::npos) {
    chk.errors.push_back(chk.file + ": --set " + printable(assignment) + ": not valid UTF-8 text (byte " +
                         printable(assignment.substr(bad, 1)) + " at offset " + std::to_string(bad) + ")");
    return {};
  }
  const size_t eq = assignment_split(assignment);
  if (eq == std::string::npos && assignment.find('=') != std::string::npos) {
    // A stray quote hides the '=': the key's own syntax error says more than "expected KEY=VALUE".
    const std::string key = assignment.substr(0, assignment.find('='));
    try {
      parse_key_path(key);
    } catch (const Error& e) {
      chk.override_error(key, e.what());
      return {};
    }
  }
  if (eq == std::string::npos || eq == 0) {
    chk.override_error(assignment, "expected KEY=VALUE, e.g. laser.average_power_mW=5");
    return {};
  }
  const std::string key = assignment.substr(0, eq);
  const std::string text = assignment.substr(eq + 1);
  const auto target = override_target(key, chk);
  if (!target) return {};
  const Key& k = *target->second.key;
  json value;
  try {
    // the override named, not the scene file (which does not hold the value)
    JsonOptions one_value;
    one_value.positions = false;
    value = parse_json(text, chk.set + key, one_value);
  } catch (const JsonLimitError& e) {  // meant as JSON, and refused in a way a string never is
    chk.errors.push_back(e.what());
    return {};
  } catch (const Error&) {  // not JSON: a string
    value = text;
  }
  // A text key (a name, a file, the description) takes a value JSON reads as other than a string or null as
  // written: names that look like numbers (a glTF camera "1", a description "2026").
  if ((k.type == Type::String || k.type == Type::Path) && !value.is_string() && !value.is_null()) value = text;
  const size_t errors = chk.errors.size();
  put(doc, target->first, target->second, value, chk, key);
  // the key's whole pointer (a named element's key: /nodes/NAME/KEY, where k.path is the element's /KEY)
  return chk.errors.size() == errors ? target->first.pointer() : std::string();
}

// A checked value (a scalar, or an array of scalars) as an ordered_json, as ojson::parse(v.dump()) gives it
// (a non-negative integer becomes unsigned) without the text in between.
ojson to_ordered(const json& v) {
  switch (v.type()) {
    case json::value_t::null: return nullptr;
    case json::value_t::boolean: return v.get<bool>();
    case json::value_t::string: return v.get_ref<const std::string&>();
    case json::value_t::number_float: {
      const double d = v.get<double>();
      return d == 0.0 ? 0.0 : d;  // -0.0 as 0 (it was written back as -0.0, and printed as -0 in messages)
    }
    case json::value_t::number_unsigned: return v.get<uint64_t>();
    case json::value_t::number_integer: {
      const int64_t i = v.get<int64_t>();
      return i >= 0 ? ojson(static_cast<uint64_t>(i)) : ojson(i);
    }
    case json::value_t::array: {
      ojson out = ojson::array();
      for (const json& e : v) out.push_back(e.is_structured() ? ojson::parse(e.dump()) : to_ordered(e));
      return out;
    }
    default: return ojson::parse(v.dump());
  }
}

// The value of a key the scene file does not give: its render.quality preset's, else its default.
const json& default_of(const json& doc, const Key& k) {
  static const json::json_pointer quality("/render/quality");
  if (doc.contains(quality) && doc.at(quality).is_string()) {
    const json& presets = quality_presets();
    if (const auto q = presets.find(doc.at(quality).get_ref<const std::string&>()); q != presets.end())
      if (const auto v = q->find(k.path); v != q->end()) return *v;
  }
  return k.def;
}

// Defaults filled, in schema order.
ojson resolve(const json& doc) {
  ojson out = ojson::object();
  for (const Key& k : schema()) {
    const json::json_pointer& ptr = k.pointer;
    json v = doc.contains(ptr) ? doc.at(ptr) : default_of(doc, k);
    // Nested sections are created in schema order as their first key appears.
    ojson* node = &out;
    size_t start = 1;
    while (true) {
      const size_t slash = k.path.find('/', start);
      const std::string part = k.path.substr(start, slash == std::string::npos ? std::string::npos : slash - start);
      if (slash == std::string::npos) {
        (*node)[part] = to_ordered(v);
        break;
      }
      if (!node->contains(part)) (*node)[part] = ojson::object();
      node = &(*node)[part];
      start = slash + 1;
    }
  }
  // A bound not given follows a first round given larger: the preset's or default's max_samples_per_pixel
  // under an explicit samples_per_pixel (render.quality "standard" with samples_per_pixel 1024 was refused
  // for a max of 512 the file never gave, against "a key given explicitly wins over the preset").
  // (only with a target error, the only setting that reads it: the resolved scene of others is as it was)
  if (ojson& render = out["render"]; !doc.contains(json::json_pointer("/render/max_samples_per_pixel")) &&
                                     render["target_relative_error"].is_number() && render["samples_per_pixel"].is_number_integer() && render["max_samples_per_pixel"].is_number_integer() &&
                                     render["samples_per_pixel"].get<int64_t>() > render["max_samples_per_pixel"].get<int64_t>())
    render["max_samples_per_pixel"] = render["samples_per_pixel"];
  // Named sections as given: elements in the order of their names (JSON objects here are sorted by
  // name, byte for byte), each element's keys in the schema's order.
  for (const NamedSection& s : named_sections()) {
    const json::json_pointer ptr(s.path);
    if (!doc.contains(ptr)) continue;
    ojson& section = out[s.path.substr(1)] = ojson::object();
    for (auto it = doc.at(ptr).begin(); it != doc.at(ptr).end(); ++it) {
      ojson& element = section[it.key()] = ojson::object();
      for (const Key& k : s.keys)
        if (const auto v = it.value().find(k.path.substr(1)); v != it.value().end()) element[k.path.substr(1)] = to_ordered(*v);
    }
  }
  return out;
}

RunConfig to_config(const ojson& r, const std::string& scene_path) {
  RunConfig c;
  c.scene_file = scene_path.empty() ? "" : normal_path(scene_path);
  const std::string dir = scene_path.empty() ? std::string(".") : std::filesystem::path(c.scene_file).parent_path().string();
  for (const Key& k : schema())
    if (k.set) k.set(c, r.at(k.pointer), dir);
  for (const NamedSection& s : named_sections()) {
    const auto section = r.find(s.path.substr(1));
    if (section == r.end()) continue;
    for (auto it = section->begin(); it != section->end(); ++it) {
      s.add(c, it.key());
      for (auto v = it.value().begin(); v != it.value().end(); ++v) find_element_key(s, v.key())->set_element(c, it.key(), v.value());
    }
  }
  return c;
}

bool rect_inside(const PixelRect& r, int w, int h) { return r.x0 >= 0 && r.y0 >= 0 && r.x1() <= w && r.y1() <= h; }

// Checks that involve more than one key, in the units the user wrote.
void check_consistency(const RunConfig& c, Checker& chk, std::vector<std::string>& warnings, FileChecks files) {
  const auto err = [&](const std::string& key, const std::string& what) { chk.error(key, what); };
  const int w = c.camera.width_px, h = c.camera.height_px;
  const auto rect_text = [](const PixelRect& r) {
    return "[" + std::to_string(r.x0) + ", " + std::to_string(r.y0) + ", " + std::to_string(r.width) + ", " +
           std::to_string(r.height) + "]";
  };
  if (c.camera.crop && !rect_inside(*c.camera.crop, w, h))
    err("/camera/crop", "found " + rect_text(*c.camera.crop) + ", expected a rectangle inside the " +
                            std::to_string(w) + " x " + std::to_string(h) + " sensor");
  if (c.outputs.transient_crop) {
    const PixelRect img = c.camera.crop.value_or(PixelRect{0, 0, w, h});
    const PixelRect& t = *c.outputs.transient_crop;
    if (!(t.x0 >= img.x0 && t.y0 >= img.y0 && t.x1() <= img.x1() && t.y1() <= img.y1()))
      err("/outputs/transient_crop", "found " + rect_text(t) + ", expected a rectangle inside the rendered region " + rect_text(img));
  }
  const Vec3d& p = c.camera.position_m;
  const Vec3d& a = c.camera.look_at_m;
  const Vec3d axis{a[0] - p[0], a[1] - p[1], a[2] - p[2]};
  const double len = std::sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
  const Vec3d& u = c.camera.up;
  const Vec3d cr{axis[1] * u[2] - axis[2] * u[1], axis[2] * u[0] - axis[0] * u[2], axis[0] * u[1] - axis[1] * u[0]};
  if (c.camera.gltf_camera.empty()) {
    if (len <= 0) err("/camera/look_at_m", "equals /camera/position_m; expected a point the camera looks at");
    else if (u[0] == 0.0 && u[1] == 0.0 && u[2] == 0.0)
      err("/camera/up", "is the zero vector; expected a direction (for example [0, 1, 0], the glTF frame's up)");
    else if (std::sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]) <= 1e-9 * len)
    {
      // the values (the up is often the default, given by neither the file nor --set)
      const auto vec = [](const Vec3d& v) {
        std::ostringstream o;
        o << "[" << v[0] << ", " << v[1] << ", " << v[2] << "]";
        return o.str();
      };
      err("/camera/up", vec(u) + " is parallel to the viewing direction look_at_m - position_m = " + vec(axis) +
                            " (position_m " + vec(p) + ", look_at_m " + vec(a) +
                            "); expected an up not along it (a camera looking straight down -Y: up [0, 0, -1])");
    }
  }
  // (named by the key the user gave: a --set laser.beam was told as the file's gltf_light)
  const auto given = [&](const char* key, const char* other) { return chk.set_keys.count(key) && !chk.set_keys.count(other); };
  if (c.laser.beam == Beam::GltfLight && c.laser.gltf_light.empty()) {
    if (given("/laser/beam", "/laser/gltf_light"))
      err("/laser/beam", "found \"gltf_light\", which needs /laser/gltf_light, the name of a glTF light; it is empty");
    else
      err("/laser/gltf_light", "is empty, expected the name of a glTF light because /laser/beam is \"gltf_light\"");
  }
  // The ambient band above 0 nm: wavelength 200 and bandwidth 2000 nm (each in range) reached -800 nm and
  // weighted the PDP by negative wavelengths, unsaid.
  if (c.ambient.bandwidth_m >= 2.0 * c.ambient.wavelength_m)
    err(chk.set_keys.count("/ambient/wavelength_nm") && !chk.set_keys.count("/ambient/bandwidth_nm") ? "/ambient/wavelength_nm" : "/ambient/bandwidth_nm",
        "makes the ambient band " + format_bound(c.ambient.wavelength_m / kNm) + " +- " + format_bound(c.ambient.bandwidth_m / 2 / kNm) +
            " nm reach " + format_bound((c.ambient.wavelength_m - c.ambient.bandwidth_m / 2) / kNm) +
            " nm; expected a band above 0 nm: /ambient/bandwidth_nm less than twice /ambient/wavelength_nm");
  if (c.acquisition.mode == AcquisitionMode::GateSweep) {
    const GateSweepConfig& g = c.acquisition.gate_sweep;
    const double positions = g.positions();
    if (g.stop_s < g.start_s) {
      // named by the key the user changed (a --set start_ns was told as the file's stop_ns)
      if (chk.set_keys.count("/acquisition/gate_sweep/start_ns") && !chk.set_keys.count("/acquisition/gate_sweep/stop_ns"))
        err("/acquisition/gate_sweep/start_ns", "is after /acquisition/gate_sweep/stop_ns (" + format_bound(g.stop_s / kNs) +
                                                    " ns); expected start <= stop");
      else
        err("/acquisition/gate_sweep/stop_ns", "is before /acquisition/gate_sweep/start_ns; expected stop >= start");
    }
    else if (!(positions <= static_cast<double>(kMaxGatePositions)))
      err("/acquisition/gate_sweep/step_ps",
          "found " + format_bound(g.step_s / kPs) + " ps, which makes " + format_bound(positions) + " gate positions from " +
              format_bound(g.start_s / kNs) + " to " + format_bound(g.stop_s / kNs) +
              " ns (/acquisition/gate_sweep/start_ns, stop_ns); expected at most " + std::to_string(kMaxGatePositions) +
              " positions: a larger step or a shorter sweep");
    // (1 us bins over a 25 ns period halved the summed rates and were told only of blurred edges)
    if (const double period = 1.0 / c.laser.repetition_rate_Hz; c.render.time_bin_s >= period * (1.0 - 1e-9))
      warnings.push_back("render.time_bin_ps: bins of " + format_bound(c.render.time_bin_s / kPs) +
                         " ps are as wide as the laser's period of " + format_bound(period / kNs) +
                         " ns (laser.repetition_rate_MHz) or wider: every return is spread over at least a whole period, and "
                         "the counts hold no timing of it; choose bins narrower than the gate sweep's step");
    else if (c.render.time_bin_s > g.step_s * (1.0 + 1e-9))
      warnings.push_back("render.time_bin_ps: bins of " + format_bound(c.render.time_bin_s / kPs) +
                         " ps are wider than the gate sweep's step of " + format_bound(g.step_s / kPs) +
                         " ps: the sensor takes the light as constant within each bin, so a return's edge in the counts is "
                         "spread over a bin (docs/accuracy.md measures the depth error of the bin width)");
    const double exposure = static_cast<double>(c.acquisition.cycles_per_frame) / c.laser.repetition_rate_Hz;
    if (exposure > 1.0 / c.acquisition.frame_rate_Hz)
      warnings.push_back("acquisition.cycles_per_frame: " + std::to_string(c.acquisition.cycles_per_frame) +
                         " laser cycles last " + format_bound(exposure / kUs) + " us, longer than one frame at " +
                         format_bound(c.acquisition.frame_rate_Hz) + " fps");
  } else {
    if (c.acquisition.intensity.exposure == Exposure::Dual && c.acquisition.frames % 2 != 0)
      err("/acquisition/frames", "found " + std::to_string(c.acquisition.frames) +
                                     ", expected an even number: dual exposure interleaves short and long frames");
    const double longest = c.acquisition.intensity.exposure_s *
                           (c.acquisition.intensity.exposure == Exposure::Dual ? c.acquisition.intensity.dual_ratio : 1.0);
    if (longest > 1.0 / c.acquisition.frame_rate_Hz)
      warnings.push_back("acquisition.intensity: an exposure of " + format_bound(longest / kUs) +
                         " us is longer than one frame at " + format_bound(c.acquisition.frame_rate_Hz) + " fps");
  }
  if (c.render.target_relative_error && c.render.samples_per_pixel < 2)
    err("/render/samples_per_pixel", "found " + std::to_string(c.render.samples_per_pixel) +
                                         ", expected at least 2 with render.target_relative_error: the spread of the first "
                                         "round's paths estimates each pixel's error (one path has none, and would stop there)");
  else if (c.render.target_relative_error && c.render.max_samples_per_pixel < c.render.samples_per_pixel)
    err("/render/max_samples_per_pixel", "found " + std::to_string(c.render.max_samples_per_pixel) +
                                             ", expected at least render.samples_per_pixel (" +
                                             std::to_string(c.render.samples_per_pixel) + "), the paths of the first round");
  if (c.render.window_start_s.has_value() != c.render.window_stop_s.has_value())
    err(c.render.window_start_s ? "/render/window_start_ns" : "/render/window_stop_ns",
        "expected render.window_start_ns and render.window_stop_ns both set or both null (the window is given whole, or "
        "derived from the acquisition)");
  else if (c.render.window_start_s && *c.render.window_stop_s <= *c.render.window_start_s)
    err("/render/window_stop_ns", "expected a window end after render.window_start_ns");
  else if (c.render.window_start_s && time_window_used(c)) {
    const double bins = std::ceil((*c.render.window_stop_s - *c.render.window_start_s) / c.render.time_bin_s - 1e-9);
    if (!(bins <= static_cast<double>(kMaxTimeBins))) {
      // named by the key the user changed: the bin width, or else a window end --set gave
      const char* window_key = chk.set_keys.count("/render/window_stop_ns") ? "/render/window_stop_ns"
                               : chk.set_keys.count("/render/window_start_ns") ? "/render/window_start_ns"
                                                                               : nullptr;
      if (chk.set_keys.count("/render/time_bin_ps") || !window_key)
        err("/render/time_bin_ps", "found " + format_bound(c.render.time_bin_s / kPs) + " ps, which makes " + format_bound(bins) +
                                       " time bins over the window /render/window_start_ns to window_stop_ns; expected at most " +
                                       std::to_string(kMaxTimeBins) + " bins: wider bins or a shorter window");
      else
        err(window_key, "the window from " + format_bound(*c.render.window_start_s / kNs) + " to " +
                            format_bound(*c.render.window_stop_s / kNs) + " ns makes " + format_bound(bins) + " time bins of " +
                            format_bound(c.render.time_bin_s / kPs) + " ps (render.time_bin_ps); expected at most " +
                            std::to_string(kMaxTimeBins) + " bins: a shorter window or wider bins");
    }
  }
  // Every file is read whole, so it must be a regular file of bounded size (a FIFO or /dev/zero would
  // block or never end).
  struct FileKey {
    const char* key;
    const std::string& file;
    uint64_t max_bytes;
  };
  for (const FileKey& f : {FileKey{"/gltf", c.gltf_path, kMaxGltfFileBytes},
                           FileKey{"/laser/pulse_shape_csv", c.laser.pulse_shape_csv, kMaxTableFileBytes},
                           FileKey{"/sensor/gate/profile_csv", c.sensor.gate.profile_csv, kMaxTableFileBytes},
                           FileKey{"/sensor/gate/maps_exr", c.sensor.gate.maps_exr, kMaxImageFileBytes},
                           FileKey{"/sensor/pixel_A/pdp_csv", c.sensor.pixel_A.pdp_csv, kMaxTableFileBytes},
                           FileKey{"/sensor/pixel_B/pdp_csv", c.sensor.pixel_B.pdp_csv, kMaxTableFileBytes}}) {
    if (f.file.empty()) {
      if (std::string(f.key) == "/gltf") err(f.key, "is empty; expected the path of the scene's .gltf or .glb file, relative to the scene file");
      continue;
    }
    // A NUL byte ends a path for the system: the file opened would be another than the one named.
    if (f.file.find('\0') != std::string::npos) {
      err(f.key, "is '" + printable(f.file) + "', which holds a NUL byte; expected a path without one");
      continue;
    }
    if (files == FileChecks::None || (files == FileChecks::Tables && std::string(f.key) == "/gltf")) continue;
    const std::string problem = file_problem(f.file, f.max_bytes);
    const std::string what = std::string(f.key) == "/gltf" ? "the glTF file " : "the file ";
    if (problem == "does not exist")
      err(f.key, what + f.file + " does not exist; expected a path relative to the scene file");
    else if (!problem.empty())
      err(f.key, what + f.file + " " + problem);
  }
}

// Keys the scene file or --set gives a value other than their default although the other settings make
// them do nothing (Key::ignored): a gate sweep's step in the intensity mode is a mistake about the mode.
void ignored_keys(const json& doc, const RunConfig& c, std::vector<std::string>& warnings) {
  for (const Key& k : schema()) {
    if (!k.ignored) continue;
    const json::json_pointer& ptr = k.pointer;
    if (!doc.contains(ptr) || doc.at(ptr) == k.def) continue;
    const std::string why = k.ignored(c);
    if (why.empty()) continue;
    std::string dotted = k.path.substr(1);
    std::replace(dotted.begin(), dotted.end(), '/', '.');
    warnings.push_back(dotted + ": set to " + short_dump(doc.at(ptr)) + " but does nothing: " + why);
  }
}

std::string join_errors(const std::vector<std::string>& errors) {
  std::string out = errors.size() == 1 ? "" : std::to_string(errors.size()) + " errors in the scene file:\n";
  // one line each (a key or a glTF name holding a newline broke a message in two)
  for (size_t i = 0; i < errors.size(); ++i) out += (i ? "\n" : "") + one_line(errors[i]);
  return out;
}

}  // namespace

ResolvedRun parse_scene_text(const std::string& text, const std::string& path, const std::vector<std::string>& overrides,
                             FileChecks files) {
  const std::string file = path.empty() ? "<scene>" : path;
  json doc = parse_json(text, file);
  if (!doc.is_object()) throw Error(file + ": expected a JSON object at the top, found " + describe_json(doc));
  Checker chk{file, "--set ", {}, {}};
  std::set<std::string> overridden;
  for (const std::string& o : overrides)
    if (std::string key = apply_override(doc, o, chk); !key.empty()) {
      chk.set_keys[key] = o.substr(0, assignment_split(o));
      overridden.insert(std::move(key));
    }
  // A quality preset given by --set replaces the sampling keys the scene file gives (the shipped scenes
  // give samples_per_pixel); a key --set gives keeps its own value.
  static const json::json_pointer quality("/render/quality");
  if (overridden.count(quality.to_string()) && doc.at(quality).is_string())
    if (const auto q = quality_presets().find(doc.at(quality).get<std::string>()); q != quality_presets().end())
      for (auto it = q->begin(); it != q->end(); ++it) {
        const json::json_pointer ptr(it.key());
        if (!overridden.count(it.key()) && doc.contains(ptr)) doc.at(ptr.parent_pointer()).erase(ptr.back());
      }
  chk.walk(doc, "");
  for (const Key& k : schema())
    if (k.required && !doc.contains(k.pointer))
      chk.error(k.path, "missing; expected " + expected_text(k) + " (" + k.doc + ")");
  if (!chk.errors.empty()) throw Error(join_errors(chk.errors));

  ResolvedRun run;
  run.resolved = resolve(doc);
  run.config = to_config(run.resolved, path);
  check_consistency(run.config, chk, run.warnings, files);
  if (!chk.errors.empty()) throw Error(join_errors(chk.errors));
  ignored_keys(doc, run.config, run.warnings);
  run.set_keys = chk.set_keys;
  return run;
}

ResolvedRun load_scene_file(const std::string& path, const std::vector<std::string>& overrides) {
  // metadata.json records the path as JSON text, which must be UTF-8: refused now, not after the run.
  if (invalid_utf8_at(path) != std::string::npos)
    throw Error("scene file " + printable(path) + ": its name is not valid UTF-8 text, which metadata.json needs; rename it");
  return parse_scene_text(read_file_bounded(path, kMaxSceneFileBytes, "scene file"), path, overrides);
}

std::vector<std::string> check_override(const std::string& key, const nlohmann::json& value) {
  Checker chk{"", "", {}, {}};
  if (const size_t bad = invalid_utf8_at(key); bad != std::string::npos) {
    chk.override_error(printable(key), "not valid UTF-8 text (byte " + printable(key.substr(bad, 1)) + " at offset " +
                                           std::to_string(bad) + ")");
    return chk.errors;
  }
  const auto target = override_target(key, chk);
  if (!target) return chk.errors;
  json doc = json::object();
  put(doc, target->first, target->second, value, chk, key);
  if (chk.errors.empty()) chk.walk(doc, "");
  return chk.errors;
}

namespace {

// One row of the reference table.
std::string markdown_row(const Key& k, const std::string& dotted, const std::string& def) {
  std::string type = type_text(k);
  if (k.nullable) type += " or null";
  std::string valid = k.type == Type::Number || k.type == Type::Integer || k.type == Type::Enum || k.type == Type::Vec3 ||
                              k.type == Type::Rect
                          ? expected_text(k)
                          : "";
  if (const size_t u = valid.rfind(" " + k.unit); !k.unit.empty() && u != std::string::npos && u + k.unit.size() + 1 == valid.size())
    valid = valid.substr(0, u);
  return "| `" + dotted + "` | " + type + " | " + k.unit + " | " + def + " | " + valid + " | " + k.doc + " |\n";
}

// One key as a JSON Schema property.
ojson key_schema(const Key& k) {
  ojson p = ojson::object();
  const auto typed = [&](const char* type) {
    p["type"] = k.nullable ? ojson::array({type, "null"}) : ojson(type);
  };
  switch (k.type) {
    case Type::Number:
    case Type::Integer:
      typed(k.type == Type::Number ? "number" : "integer");
      if (std::isfinite(k.lo)) p[k.lo_open ? "exclusiveMinimum" : "minimum"] = k.lo;
      if (std::isfinite(k.hi)) p["maximum"] = k.hi;
      if (k.multiple_of) p["multipleOf"] = k.multiple_of;
      break;
    case Type::Bool: typed("boolean"); break;
    case Type::String:
    case Type::Path: typed("string"); break;
    case Type::Enum: {
      ojson choices = ojson::array();
      for (const std::string& c : k.choices) choices.push_back(c);
      if (k.nullable) choices.push_back(nullptr);
      p["enum"] = choices;
      break;
    }
    case Type::Vec3:
      typed("array");
      p["items"] = {{"type", k.null_components ? ojson::array({"number", "null"}) : ojson("number")}};
      if (std::isfinite(k.lo)) p["items"]["minimum"] = k.lo;
      if (std::isfinite(k.hi)) p["items"]["maximum"] = k.hi;
      p["minItems"] = 3, p["maxItems"] = 3;
      break;
    case Type::Rect:
      typed("array");
      p["prefixItems"] = ojson::array({{{"type", "integer"}, {"minimum", 0}, {"maximum", 1000000}},
                                       {{"type", "integer"}, {"minimum", 0}, {"maximum", 1000000}},
                                       {{"type", "integer"}, {"minimum", 1}, {"maximum", 1000000}},
                                       {{"type", "integer"}, {"minimum", 1}, {"maximum", 1000000}}});
      p["minItems"] = 4, p["maxItems"] = 4;
      break;
  }
  p["description"] = k.doc + (k.unit.empty() ? "" : " [" + k.unit + "]");
  return p;
}

}  // namespace

std::string schema_reference_markdown() {
  std::ostringstream o;
  o << "| key | type | unit | default | valid | meaning |\n|---|---|---|---|---|---|\n";
  for (const Key& k : schema()) {
    std::string dotted = k.path.substr(1);
    std::replace(dotted.begin(), dotted.end(), '/', '.');
    o << markdown_row(k, dotted, k.required ? std::string("required") : "`" + k.def.dump() + "`");
  }
  for (const NamedSection& s : named_sections()) {
    const std::string name = s.path.substr(1);
    o << "| `" << name << "` | object by " << s.element << " name |  | `{}` | names of the glTF's " << s.element << "s | " << s.doc << " |\n";
    for (const Key& k : s.keys) o << markdown_row(k, name + ".NAME." + k.path.substr(1), "the glTF's");
  }
  return o.str();
}

std::string schema_json() {
  ojson root = {{"$schema", "https://json-schema.org/draft/2020-12/schema"},
                {"title", "spadgen scene file"},
                {"description", "A spadgen run: the glTF scene, camera, laser, ambient light, sensor, acquisition, "
                                "rendering and outputs (docs/scene-file.md)"},
                {"type", "object"},
                {"additionalProperties", false},
                {"properties", ojson::object()}};
  for (const Key& k : schema()) {
    // The sections on the way to the key, created as they first appear (in schema order).
    ojson* node = &root;
    size_t start = 1;
    for (size_t slash; (slash = k.path.find('/', start)) != std::string::npos; start = slash + 1) {
      ojson& sec = (*node)["properties"][k.path.substr(start, slash - start)];
      if (sec.is_null()) sec = {{"type", "object"}, {"additionalProperties", false}, {"properties", ojson::object()}};
      node = &sec;
    }
    const std::string name = k.path.substr(start);
    ojson p = key_schema(k);
    if (!k.required) p["default"] = ojson::parse(k.def.dump());
    else (*node)["required"].push_back(name);
    (*node)["properties"][name] = p;
  }
  // A named section: any non-empty name, each name an object of the element's keys and no others.
  for (const NamedSection& s : named_sections()) {
    ojson element = {{"type", "object"}, {"additionalProperties", false}, {"properties", ojson::object()}};
    for (const Key& k : s.keys) element["properties"][k.path.substr(1)] = key_schema(k);
    root["properties"][s.path.substr(1)] = {{"type", "object"},
                                           {"description", s.doc},
                                           {"default", ojson::object()},
                                           {"propertyNames", {{"minLength", 1}}},
                                           {"additionalProperties", element}};
  }
  return root.dump(2) + "\n";
}

namespace {
// The tables the sensor stage reads besides the scene file, by key, in the order their hashes take them.
std::array<std::pair<const char*, const std::string*>, 5> table_paths(const RunConfig& c) {
  return {{{"laser.pulse_shape_csv", &c.laser.pulse_shape_csv},
           {"sensor.gate.profile_csv", &c.sensor.gate.profile_csv},
           {"sensor.gate.maps_exr", &c.sensor.gate.maps_exr},
           {"sensor.pixel_A.pdp_csv", &c.sensor.pixel_A.pdp_csv},
           {"sensor.pixel_B.pdp_csv", &c.sensor.pixel_B.pdp_csv}}};
}
}  // namespace

std::string sensor_tables_hash(const RunConfig& c, std::vector<SensorTable>* each) {
  uint64_t h = fnv1a64("");
  if (each) each->clear();
  for (const auto& [key, path] : table_paths(c)) {
    const std::string bytes = path->empty() ? std::string() : file_bytes(*path);
    // The length first, so that tables moved from one key to the next do not hash alike.
    h = fnv1a64(std::to_string(bytes.size()) + ":" + bytes, h);
    if (each) each->push_back({key, *path, hex64(fnv1a64(bytes))});
  }
  return hex64(h);
}

std::vector<SensorTable> sensor_tables(const RunConfig& c) {
  std::vector<SensorTable> out;
  (void)sensor_tables_hash(c, &out);
  return out;
}

bool time_window_used(const RunConfig& c) {
  return c.acquisition.mode == AcquisitionMode::GateSweep || c.outputs.transient || c.outputs.light;
}

bool uses_sensor_tables(const RunConfig& c) {
  const auto paths = table_paths(c);
  return std::any_of(paths.begin(), paths.end(), [](const auto& t) { return !t.second->empty(); });
}

}  // namespace spadgen::scenes
