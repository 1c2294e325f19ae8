#include "dataset/file_io.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>

namespace layersnet::io {
namespace {

[[noreturn]] void fail(const std::string& path, const std::string& action, int err) {
  std::string msg = path + ": cannot be " + action + ": " + std::strerror(err);
  const std::string hint = write_failure_hint(err);
  if (!hint.empty()) msg += " (" + hint + ")";
  throw std::runtime_error(msg);
}

// write(2) until done; returns 0 or the errno of the failure.
int write_all(int fd, std::string_view bytes) {
  const char* p = bytes.data();
  std::size_t left = bytes.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, p, left);
    if (n < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    if (n == 0) return EIO;
    p += n;
    left -= static_cast<std::size_t>(n);
  }
  return 0;
}

std::string folder_of(const std::string& path) {
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  return parent.empty() ? "." : parent.string();
}

}  // namespace

std::string write_failure_hint(int err) {
  switch (err) {
    case ENOSPC:
    case EDQUOT: return "free space on that disk or write elsewhere";
    case EFBIG: return "the file exceeds the file-size limit (ulimit -f) or the file system's maximum";
    case EACCES:
    case EPERM:
    case EROFS: return "check the folder's permissions or write elsewhere";
    case ENOENT:
    case ENOTDIR: return "the folder does not exist";
    default: return "";
  }
}

void write_file_atomic(const std::filesystem::path& file, std::string_view bytes) {
  const std::string path = file.string();
  const std::string tmp = path + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) fail(path, "written", errno);
  int err = write_all(fd, bytes);
  if (err == 0 && ::fsync(fd) != 0 && errno != EINVAL) err = errno;  // EINVAL: no fsync on this file (a pipe, /dev/...)
  if (::close(fd) != 0 && err == 0) err = errno;  // NFS and some FUSE report ENOSPC only here
  if (err != 0) {
    ::unlink(tmp.c_str());
    fail(path, "written", err);
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    err = errno;
    ::unlink(tmp.c_str());
    fail(path, "written (renaming " + tmp + " into place)", err);
  }
  // The rename itself survives a power cut only once the folder is on disk.
  if (const int dir = ::open(folder_of(path).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC); dir >= 0) {
    ::fsync(dir);
    ::close(dir);
  }
}

void append_line(const std::string& path, std::string_view line) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) fail(path, "appended to", errno);
  std::string buf(line);
  buf += '\n';
  const off_t before = ::lseek(fd, 0, SEEK_END);
  int err = write_all(fd, buf);
  if (err != 0 && before >= 0) {
    // Drop a half-written line so the file stays one record per line; the write error is what gets reported.
    [[maybe_unused]] const int dropped = ::ftruncate(fd, before);
  }
  if (::close(fd) != 0 && err == 0) err = errno;
  if (err != 0) fail(path, "appended to", err);
}

}  // namespace layersnet::io
