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

std::string openTempBeside(const std::string& path, const char* mode, std::string* tmp, std::FILE** file) {
  *tmp = path + ".tmp-XXXXXX";
  const int fd = ::mkstemp(tmp->data());
  if (fd < 0) return fmt::format("cannot create a temporary file next to '{}': {}", path, std::strerror(errno));
  if (::fchmod(fd, 0666 & ~currentUmask()) != 0 || !(*file = ::fdopen(fd, mode))) {
    const std::string err = std::strerror(errno);
    ::close(fd);
    ::unlink(tmp->c_str());
    return fmt::format("cannot open '{}': {}", *tmp, err);
  }
  return {};
}

std::string commitTemp(std::FILE* file, const std::string& tmp, const std::string& path, std::string err) {
  if (std::fflush(file) != 0 && err.empty()) err = fmt::format("cannot write '{}': {}", tmp, std::strerror(errno));
  if (err.empty() && ::fsync(fileno(file)) != 0)
    err = fmt::format("cannot sync '{}': {}", tmp, std::strerror(errno));
  if (std::fclose(file) != 0 && err.empty()) err = fmt::format("cannot close '{}': {}", tmp, std::strerror(errno));
  if (err.empty() && std::rename(tmp.c_str(), path.c_str()) != 0)
    err = fmt::format("cannot rename '{}' to '{}': {}", tmp, path, std::strerror(errno));
  if (!err.empty()) ::unlink(tmp.c_str());
  return err;
}

}  // namespace distband
