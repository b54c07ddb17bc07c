// InputFile: a file opened for reading by path — the one place core turns the OS's answer into a Status.
// Contract: open() succeeds only for a regular file (a directory, FIFO or device could block or never end); the
// object then owns the FILE*, closes it on destruction, and size() is the size at open. Every error names the path:
// kNotFound for a missing file or directory on the way (ENOENT, ENOTDIR), kInvalidArgument for something that is not
// a regular file, kIoError with the OS's reason for anything else and for a read that ends early.
#pragma once

#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>

#include "core/status.h"

namespace distband {

class InputFile {
 public:
  static Status open(const std::string& path, InputFile* out);

  std::FILE* get() const { return file_.get(); }
  uint64_t size() const { return size_; }
  const std::string& path() const { return path_; }

  /// Reads exactly `n` bytes at `offset` into `dst`.
  Status readAt(uint64_t offset, void* dst, size_t n);

 private:
  struct Closer {
    void operator()(std::FILE* f) const { std::fclose(f); }
  };
  std::unique_ptr<std::FILE, Closer> file_;
  std::string path_;
  uint64_t size_ = 0;
};

/// The whole of a regular file. A file of more than `max_bytes` is refused with kResourceExhausted before anything
/// is allocated; `what` names what the limit protects ("a volume", "a mesh") in that message.
Status readWholeFile(const std::string& path, uint64_t max_bytes, const char* what, std::string* out);

}  // namespace distband
