// Scene-file keys as `--set` (and a dataset file's axes) write them: names separated by dots, e.g.
// `camera.position_m`; a name that holds a dot, a double quote, a bracket, '=' or a backslash written in
// double quotes, `nodes."Cube.001".translation_m` (inside the quotes \" is a quote and \\ a backslash);
// and after the last name an optional `[i]` that selects one component of an [x, y, z] key,
// `camera.position_m[2]`. This is only the syntax: what a key means is the schema's (scenes/schema.h), and
// scenes::check_override (scene_file.h) checks a key and its value as `--set` does.
#pragma once
#include <optional>
#include <string>
#include <vector>

namespace spadgen::scenes {

struct KeyPath {
  std::vector<std::string> names;  // {"nodes", "Cube.001", "translation_m"}: quotes removed, never empty
  std::optional<int> component;    // i of a trailing [i], as written (the key's type decides whether it exists)

  // The JSON pointer of the key (RFC 6901: '~' as ~0, '/' as ~1): /nodes/Cube.001/translation_m. The
  // component is not part of it.
  std::string pointer() const;
  // The key written back in this syntax, names quoted where they need it and [i] appended.
  std::string text() const;
};

// Parses a key. Throws spadgen::Error saying what is wrong and where, without naming the key (callers
// name it: "--set KEY: ..."): an empty name, an unterminated quote, text after a closing quote, a bracket
// that is not a final [i] with i a non-negative integer.
KeyPath parse_key_path(const std::string& key);

// Where the key of a `--set KEY=VALUE` assignment ends: the first '=' outside double quotes, or
// std::string::npos when there is none.
size_t assignment_split(const std::string& assignment);

// One name as a JSON pointer token: '~' as ~0, '/' as ~1.
std::string pointer_token(const std::string& name);

// One name as a key writes it: as it is, or in double quotes when it holds . " [ ] = \ or is empty.
std::string key_name(const std::string& name);

}  // namespace spadgen::scenes
