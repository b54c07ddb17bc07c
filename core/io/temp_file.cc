#include "core/io/temp_file.h"

#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

#include <fmt/format.h>

namespace distband {
namespace {

mode_t currentUmask() {
  // umask() can only be read by setting it; do it once, before any writer threads exist in practice.
  static const mode_t mask = [] {
    const mode_t m = ::umask(0);
    ::umask(m);
    return m;
  }();
  return mask;
}

}  // namespace

Status openTempBeside(const std::string& path, const char* mode, std::string* tmp, std::FILE** file) {
  *tmp = path + ".tmp-XXXXXX";
  const int fd = ::mkstemp(tmp->data());
  if (fd < 0)
    return Status::IoError(fmt::format("cannot create a temporary file next to '{}': {}", path, std::strerror(errno)));
  if (::fchmod(fd, 0666 & ~currentUmask()) != 0 || !(*file = ::fdopen(fd, mode))) {
    const std::string err = std::strerror(errno);
    ::close(fd);
    ::unlink(tmp->c_str());
    return Status::IoError(fmt::format("cannot open '{}': {}", *tmp, err));
  }
  return Status::Ok();
}

Status commitTemp(std::FILE* file, const std::string& tmp, const std::string& path, Status err) {
  if (std::fflush(file) != 0 && err.ok())
    err = Status::IoError(fmt::format("cannot write '{}': {}", tmp, std::strerror(errno)));
  if (err.ok() && ::fsync(fileno(file)) != 0)
    err = Status::IoError(fmt::format("cannot sync '{}': {}", tmp, std::strerror(errno)));
  if (std::fclose(file) != 0 && err.ok())
    err = Status::IoError(fmt::format("cannot close '{}': {}", tmp, std::strerror(errno)));
  if (err.ok() && std::rename(tmp.c_str(), path.c_str()) != 0)
    err = Status::IoError(fmt::format("cannot rename '{}' to '{}': {}", tmp, path, std::strerror(errno)));
  if (!err.ok()) ::unlink(tmp.c_str());
  return err;
}

}  // namespace distband
