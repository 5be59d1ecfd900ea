// The one exception type spadgen throws for bad input or failed I/O. Its message is what the user
// sees: it names the file, the key or the glTF element, what was found and what was expected.
#pragma once
#include <stdexcept>
#include <string>

namespace spadgen {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

}  // namespace spadgen
