#include <exception>

#include "core/error.h"
#include "writers/writers.h"

namespace spadgen::writers {

void write_json(const std::string& path, const nlohmann::json& value) {
  std::string text;
  try {
    text = value.dump(2);
  } catch (const std::exception& e) {  // e.g. a string that is not valid UTF-8
    throw Error("cannot write JSON '" + path + "': " + e.what());
  }
  text.push_back('\n');
  write_file_atomic(path, text);
}

}  // namespace spadgen::writers
