#include "writers/atomic_file.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>

#include "core/error.h"
#include "writers/writers.h"

namespace spadgen::writers {
namespace detail {
namespace {

std::atomic<uint64_t> g_temp_counter{0};

struct PathParts {
  std::string folder, name;
};

// Splits "dir/name" into ("dir", "name"); a bare name lives in ".".
PathParts split_path(const std::string& path) {
  const auto slash = path.find_last_of('/');
  if (slash == std::string::npos) return {std::string("."), path};
  return {slash == 0 ? std::string("/") : path.substr(0, slash), path.substr(slash + 1)};
}

}  // namespace

// The rename is only durable once the folder entry is on disk too. Some file systems refuse fsync on
// a folder (EINVAL); the file itself is already safe then, so that is not an error.
void fsync_folder(const std::string& folder) {
  const int dfd = ::open(folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd < 0) return;
  (void)::fsync(dfd);
  ::close(dfd);
}

}  // namespace detail

int remove_dead_temporaries(const std::string& folder, const std::vector<std::string>& names) {
  std::error_code ec;
  int removed = 0;
  for (const auto& e : std::filesystem::directory_iterator(folder, ec)) {
    const std::string f = e.path().filename().string();
    for (const std::string& name : names) {
      const std::string prefix = "." + name + ".tmp-";
      if (f.size() <= prefix.size() || f.compare(0, prefix.size(), prefix) != 0) continue;
      // <pid>-<counter>, digits
      const size_t dash = f.find('-', prefix.size());
      const std::string pid = f.substr(prefix.size(), dash == std::string::npos ? std::string::npos : dash - prefix.size());
      const std::string counter = dash == std::string::npos ? std::string() : f.substr(dash + 1);
      const auto digits = [](const std::string& t) {
        return !t.empty() && t.size() <= 10 && t.find_first_not_of("0123456789") == std::string::npos;
      };
      if (!digits(pid) || !digits(counter)) continue;
      const long p = std::stol(pid);
      if (p <= 0 || p == long(::getpid())) continue;
      if (::kill(pid_t(p), 0) == 0 || errno != ESRCH) continue;  // running (or not ours to signal: running)
      if (e.is_regular_file(ec) && !e.is_symlink(ec) && ::unlink(e.path().c_str()) == 0) ++removed;
    }
  }
  return removed;
}

namespace detail {

std::string temp_name(const std::string& destination) {
  const std::string name = split_path(destination).name;
  const auto slash = destination.find_last_of('/');
  const std::string prefix = slash == std::string::npos ? std::string() : destination.substr(0, slash + 1);
  return prefix + "." + name + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(g_temp_counter.fetch_add(1));
}

void throw_errno(const std::string& what, const std::string& path, int err) {
  throw Error(what + " '" + path + "': " + std::strerror(err));
}

namespace {
std::string not_regular(const std::string& path, mode_t mode) {
  return "'" + path + "': is " + (S_ISFIFO(mode) ? "a FIFO" : S_ISDIR(mode) ? "a folder" : S_ISSOCK(mode) ? "a socket" : "a device") +
         ", not a regular file; expected the file as spadgen wrote it";
}
}  // namespace

int open_regular_file(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) throw_errno("cannot open", path, errno);
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    throw_errno("cannot read", path, err);
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    throw Error(not_regular(path, st.st_mode));
  }
  (void)::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  return fd;
}

void require_regular_file(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw_errno("cannot open", path, errno);
  if (!S_ISREG(st.st_mode)) throw Error(not_regular(path, st.st_mode));
}

void pwrite_all(int fd, const void* data, uint64_t size, uint64_t offset, const std::string& path) {
  const char* p = static_cast<const char*>(data);
  // Linux moves at most about 2 GiB per call; larger blocks need several.
  constexpr uint64_t kMaxChunk = uint64_t(1) << 30;
  while (size > 0) {
    const size_t chunk = static_cast<size_t>(std::min(size, kMaxChunk));
    const ssize_t n = ::pwrite(fd, p, chunk, static_cast<off_t>(offset));
    if (n < 0) {
      if (errno == EINTR) continue;
      throw_errno("cannot write", path, errno);
    }
    if (n == 0) throw_errno("cannot write", path, EIO);
    p += n;
    size -= static_cast<uint64_t>(n);
    offset += static_cast<uint64_t>(n);
  }
}

TempFile::TempFile(const std::string& destination) : destination_(destination) {
  const std::string name = split_path(destination).name;
  if (name.empty() || name == "." || name == "..") throw Error("cannot write '" + destination + "': not a file name");
  // Refuse early: otherwise the whole file would be written and only the final rename would fail.
  struct stat st{};
  if (::stat(destination.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) throw_errno("cannot write", destination, EISDIR);

  // The temporary lives in the destination's folder so that rename() is atomic (same file system).
  for (int attempt = 0; attempt < 100; ++attempt) {
    temp_path_ = temp_name(destination);
    fd_ = ::open(temp_path_.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd_ >= 0) return;
    // EEXIST: a stale temporary of an earlier process with our pid; take the next number.
    if (errno != EEXIST) throw_errno("cannot create a temporary file for", destination, errno);
  }
  throw_errno("cannot create a temporary file for", destination, EEXIST);
}

TempFile::~TempFile() { discard(); }

void TempFile::discard() noexcept {
  if (fd_ >= 0) {
    ::close(fd_);
    fd_ = -1;
  }
  if (!committed_ && !temp_path_.empty()) {
    ::unlink(temp_path_.c_str());
    temp_path_.clear();
  }
}

void TempFile::commit() {
  if (committed_) throw Error("'" + destination_ + "' was already committed");
  if (fd_ < 0) throw Error("cannot commit '" + destination_ + "': the temporary file was discarded");
  if (::fsync(fd_) != 0) {
    const int err = errno;
    discard();
    throw_errno("cannot flush", destination_, err);
  }
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) {
    const int err = errno;
    discard();
    throw_errno("cannot close", destination_, err);
  }
  if (::rename(temp_path_.c_str(), destination_.c_str()) != 0) {
    const int err = errno;
    discard();
    throw_errno("cannot rename the temporary file onto", destination_, err);
  }
  committed_ = true;
  fsync_folder(split_path(destination_).folder);
}

}  // namespace detail

int64_t bytes_on_disk(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return -1;
  if (!S_ISDIR(st.st_mode)) return int64_t(st.st_size);
  int64_t total = 0;
  std::error_code ec;
  for (const auto& e : std::filesystem::recursive_directory_iterator(path, ec))
    if (e.is_regular_file(ec)) total += int64_t(e.file_size(ec));
  return total;
}

void write_file_atomic(const std::string& path, const std::string& bytes) {
  detail::TempFile file(path);
  detail::pwrite_all(file.fd(), bytes.data(), bytes.size(), 0, path);
  file.commit();
}

struct AtomicWriter::Impl {
  explicit Impl(const std::string& path) : file(path) {}
  void flush() {
    detail::pwrite_all(file.fd(), buffer.data(), buffer.size(), offset, file.destination());
    offset += buffer.size();
    buffer.clear();
  }
  detail::TempFile file;
  std::string buffer;
  uint64_t offset = 0;
};

AtomicWriter::AtomicWriter(const std::string& path) : impl_(std::make_unique<Impl>(path)) {}
AtomicWriter::~AtomicWriter() = default;

void AtomicWriter::append(const std::string& bytes) {
  impl_->buffer += bytes;
  if (impl_->buffer.size() >= (size_t{1} << 20)) impl_->flush();
}

void AtomicWriter::commit() {
  impl_->flush();
  impl_->file.commit();
}

}  // namespace spadgen::writers
