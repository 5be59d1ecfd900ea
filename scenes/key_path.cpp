#include "key_path.h"

#include "core/error.h"

namespace spadgen::scenes {
namespace {

// Characters a bare (unquoted) name cannot hold: they separate names, quote them or select a component,
// and '=' ends the key of an assignment.
constexpr const char* kSpecial = ".\"[]=\\";

std::string column(size_t i) { return "at character " + std::to_string(i + 1); }

}  // namespace

std::string pointer_token(const std::string& name) {
  std::string out;
  for (char c : name) {
    if (c == '~') out += "~0";
    else if (c == '/') out += "~1";
    else out += c;
  }
  return out;
}

std::string key_name(const std::string& name) {
  if (!name.empty() && name.find_first_of(kSpecial) == std::string::npos) return name;
  std::string out = "\"";
  for (char c : name) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

std::string KeyPath::pointer() const {
  std::string out;
  for (const std::string& n : names) {
    out += '/';  // appended piece by piece: GCC 12 warns falsely (-Wrestrict) on "/" + std::string
    out += pointer_token(n);
  }
  return out;
}

std::string KeyPath::text() const {
  std::string out;
  for (size_t i = 0; i < names.size(); ++i) {
    if (i) out += '.';
    out += key_name(names[i]);
  }
  if (component) {
    out += '[';
    out += std::to_string(*component);
    out += ']';
  }
  return out;
}

size_t assignment_split(const std::string& assignment) {
  bool quoted = false;
  for (size_t i = 0; i < assignment.size(); ++i) {
    const char c = assignment[i];
    if (quoted && c == '\\') ++i;  // \" and \\ inside quotes
    else if (c == '"') quoted = !quoted;
    else if (c == '=' && !quoted) return i;
  }
  return std::string::npos;
}

KeyPath parse_key_path(const std::string& key) {
  KeyPath p;
  if (key.empty()) throw Error("an empty key; expected names separated by dots, e.g. camera.f_number");
  size_t i = 0;
  while (true) {
    std::string name;
    if (i < key.size() && key[i] == '"') {
      const size_t open = i++;
      while (i < key.size() && key[i] != '"') {
        if (key[i] == '\\') {
          if (i + 1 >= key.size() || (key[i + 1] != '"' && key[i + 1] != '\\'))
            throw Error("a backslash " + column(i) + " inside quotes; only \\\" (a quote) and \\\\ (a backslash) are escapes");
          ++i;
        }
        name += key[i++];
      }
      if (i >= key.size()) throw Error("the quote " + column(open) + " is not closed");
      ++i;  // the closing quote
      if (name.empty()) throw Error("an empty name in quotes " + column(open));
    } else {
      const size_t start = i;
      while (i < key.size() && key[i] != '.' && key[i] != '[') {
        if (key[i] == '"' || key[i] == ']' || key[i] == '=' || key[i] == '\\')
          throw Error("'" + std::string(1, key[i]) + "' " + column(i) +
                      " inside a name; a name that holds . \" [ ] = or \\ is written in double quotes: nodes.\"Cube.001\".scale");
        ++i;
      }
      name = key.substr(start, i - start);
      if (name.empty()) throw Error("an empty name " + column(start) + "; expected names separated by single dots, e.g. camera.f_number");
    }
    p.names.push_back(std::move(name));
    if (i == key.size()) return p;
    if (key[i] == '.') {
      ++i;
      if (i == key.size()) throw Error("a dot at the end; expected a name after it");
      continue;
    }
    if (key[i] != '[')
      throw Error("'" + std::string(1, key[i]) + "' " + column(i) + " after a quoted name; expected a dot, [i] or the end");
    // [i]: digits, then the end of the key.
    const size_t open = i++;
    const size_t digits = i;
    while (i < key.size() && key[i] >= '0' && key[i] <= '9') ++i;
    if (i == digits || i >= key.size() || key[i] != ']' || i + 1 != key.size())
      throw Error("the bracket " + column(open) +
                  " is not a final [i] with i a component index (0, 1 or 2), e.g. camera.position_m[2]");
    if (i - digits > 1 && key[digits] == '0')  // ([01] was read as [1])
      throw Error("the component index " + key.substr(digits, i - digits) + " has a leading zero; expected 0, 1 or 2, written so");
    if (i - digits > 6) throw Error("the component index " + key.substr(digits, i - digits) + " is too large; expected 0, 1 or 2");
    p.component = std::stoi(key.substr(digits, i - digits));
    return p;
  }
}

}  // namespace spadgen::scenes
