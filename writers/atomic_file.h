// Internal helpers for "complete or not at all" files: a temporary file beside the destination that is
// either renamed into place (commit) or removed (destruction, failure). Not part of the public API.
#pragma once
#include <cstdint>
#include <string>

namespace spadgen::writers::detail {

// Throws spadgen::Error: "<what> '<path>': <strerror(err)>".
[[noreturn]] void throw_errno(const std::string& what, const std::string& path, int err);

// Opens `path` for reading, only if it is a regular file (a symbolic link followed): a FIFO, a device or a
// folder in its place is refused, naming it, without blocking (the open does not wait for a FIFO's writer).
// Returns the descriptor (blocking mode); throws spadgen::Error.
int open_regular_file(const std::string& path);
// The same check by name, for readers that open the file themselves (OpenEXR, std::ifstream).
void require_regular_file(const std::string& path);

// Writes all `size` bytes at `offset`, retrying short writes and EINTR. Safe to call from several
// threads at once on one descriptor (pwrite does not move a shared file position).
void pwrite_all(int fd, const void* data, uint64_t size, uint64_t offset, const std::string& path);

// A fresh temporary name beside `destination`: ".<name>.tmp-<pid>-<counter>" in its folder.
std::string temp_name(const std::string& destination);

// Makes renames in `folder` durable; best effort (some file systems refuse fsync on a folder).
void fsync_folder(const std::string& folder);

class TempFile {
 public:
  // Creates ".<name>.tmp-<pid>-<counter>" in the destination's folder, exclusively and empty.
  explicit TempFile(const std::string& destination);
  ~TempFile();  // removes the temporary file unless committed
  TempFile(const TempFile&) = delete;
  TempFile& operator=(const TempFile&) = delete;

  int fd() const { return fd_; }
  const std::string& destination() const { return destination_; }
  const std::string& temp_path() const { return temp_path_; }
  bool committed() const { return committed_; }

  // fsync, close, rename over the destination, fsync the folder. On failure the temporary file is
  // removed and spadgen::Error names the destination.
  void commit();

 private:
  void discard() noexcept;
  std::string destination_, temp_path_;
  int fd_ = -1;
  bool committed_ = false;
};

}  // namespace spadgen::writers::detail
