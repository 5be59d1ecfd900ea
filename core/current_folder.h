// A relative path given where the current folder was removed (a shell standing in a folder another removed):
// the file system says "Invalid argument" or "No such file or directory", which names neither cause nor remedy.
#pragma once
#include <filesystem>
#include <string>
#include <system_error>

namespace spadgen {

// Why the current folder cannot be read (no_such_file_or_directory: it was removed), or no error.
inline std::error_code current_folder_error() {
  std::error_code ec;
  static_cast<void>(std::filesystem::current_path(ec));
  return ec;
}

// Why `path`, relative, cannot be resolved against the current folder, in words ending with what to do; ""
// when it is absolute or the current folder is there.
inline std::string relative_path_problem(const std::filesystem::path& path) {
  const std::error_code ec = path.is_absolute() ? std::error_code() : current_folder_error();
  if (!ec) return "";
  return "it is relative to the current folder, which " +
         (ec == std::errc::no_such_file_or_directory ? std::string("no longer exists (removed while this shell stood in it)")
                                                     : "cannot be read (" + ec.message() + ")") +
         "; change to a folder that exists, or give an absolute path";
}

}  // namespace spadgen
