#include "core/io/input_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <fmt/format.h>

namespace distband {

Status InputFile::open(const std::string& path, InputFile* out) {
  // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer before fstat could refuse it.
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    const int error = errno;
    std::string m = fmt::format("{}: cannot open: {}", path, std::strerror(error));
    return error == ENOENT || error == ENOTDIR ? Status::NotFound(std::move(m)) : Status::IoError(std::move(m));
  }
  struct stat st {};
  if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return Status::InvalidArgument(fmt::format("{}: not a regular file", path));
  }
  std::FILE* f = fdopen(fd, "rb");
  if (!f) {
    const int error = errno;
    ::close(fd);
    return Status::IoError(fmt::format("{}: cannot open: {}", path, std::strerror(error)));
  }
  InputFile file;
  file.file_.reset(f);
  file.size_ = uint64_t(st.st_size);
  file.path_ = path;
  *out = std::move(file);
  return Status::Ok();
}

Status InputFile::readAt(uint64_t offset, void* dst, size_t n) {
  if (offset > size_ || n > size_ - offset)
    return Status::IoError(fmt::format("{}: {} bytes at byte {} are past the end of the file ({} bytes)", path_, n,
                                       offset, size_));
  if (n == 0) return Status::Ok();
  if (fseeko(file_.get(), off_t(offset), SEEK_SET) != 0)
    return Status::IoError(fmt::format("{}: cannot seek to byte {}: {}", path_, offset, std::strerror(errno)));
  const size_t got = std::fread(dst, 1, n, file_.get());
  if (got != n) return Status::IoError(fmt::format("{}: read failed at byte {}", path_, offset + got));
  return Status::Ok();
}

Status readWholeFile(const std::string& path, uint64_t max_bytes, const char* what, std::string* out) {
  InputFile f;
  if (Status s = InputFile::open(path, &f); !s.ok()) return s;
  if (f.size() > max_bytes)
    return Status::ResourceExhausted(
        fmt::format("{}: {} bytes are more than {} of the limits holds ({} bytes)", path, f.size(), what, max_bytes));
  std::string bytes(size_t(f.size()), '\0');
  if (Status s = f.readAt(0, bytes.data(), bytes.size()); !s.ok()) return s;
  *out = std::move(bytes);
  return Status::Ok();
}

}  // namespace distband
