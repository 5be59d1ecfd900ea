#include "app/staging.h"

#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdlib>

#include "core/error.h"

namespace spadgen::app {
namespace fs = std::filesystem;

namespace {
const std::string kPrefix = ".spadgen-staging-";
}  // namespace

Staging::Staging(const fs::path& out) : out_(out) {
  try {
    fs::create_directories(out_);
    remove_abandoned();
    dir_ = out_ / (kPrefix + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "previews");
    fs::create_directories(dir_ / "light");
  } catch (const fs::filesystem_error& e) {
    throw Error("cannot use " + out_.string() + " as the output folder (-o): " + e.code().message() +
                "; expected a folder that exists or can be created");
  }
}

Staging::~Staging() {
  std::error_code ec;
  fs::remove_all(dir_, ec);
}

std::string Staging::path(const std::string& rel) const { return (dir_ / rel).string(); }

// Staging folders of runs that were killed outright (SIGKILL, power loss) hold only temporary files.
void Staging::remove_abandoned() const {
  for (const auto& e : fs::directory_iterator(out_)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(kPrefix, 0) != 0) continue;
    const long pid = std::strtol(name.c_str() + kPrefix.size(), nullptr, 10);
    if (pid > 0 && pid != ::getpid() && ::kill(pid_t(pid), 0) != 0 && errno == ESRCH) {
      std::error_code ec;
      fs::remove_all(e.path(), ec);
    }
  }
}

void Staging::publish(const std::vector<std::string>& files) {
  for (const std::string& f : files)
    if (f != "metadata.json") {
      fs::create_directories((out_ / f).parent_path());
      fs::rename(dir_ / f, out_ / f);
    }
  fs::rename(dir_ / "metadata.json", out_ / "metadata.json");
}

}  // namespace spadgen::app
