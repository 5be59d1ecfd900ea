// Atomic output: a run writes every file into a staging folder inside the output folder and moves them
// into place only when the whole run has succeeded, so a failed or interrupted run never leaves a
// half-written or wrong file behind.
#pragma once
#include <filesystem>
#include <string>
#include <vector>

namespace spadgen::app {

// The staging folder of this run (.spadgen-staging-<pid>), removed with whatever is in it unless published.
class Staging {
 public:
  // Creates the output folder if needed and removes staging folders that killed runs left behind.
  // Throws spadgen::Error when the output folder cannot be used.
  explicit Staging(const std::filesystem::path& out);
  ~Staging();
  Staging(const Staging&) = delete;
  Staging& operator=(const Staging&) = delete;

  // Where the file `rel` (relative to the output folder) is written until it is published.
  std::string path(const std::string& rel) const;
  // Moves every listed file into the output folder; metadata.json comes last so that it never lists a
  // file that is not there yet.
  void publish(const std::vector<std::string>& files);

 private:
  void remove_abandoned() const;

  std::filesystem::path out_, dir_;
};

}  // namespace spadgen::app
