// Fuzz target: the .npy reader (core/io/npy.h) on arbitrary bytes. On success the parsed array must be consistent:
// payload size = prod(shape) * item size, rank 3 shapes within the grid limits for masks. On failure the Status must
// say the bytes are malformed (kInvalidArgument) or over a hard limit (kResourceExhausted), naming the input.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "core/io/npy.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  distband::NpyArray array;
  const distband::Status status =
      distband::parseNpy(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.npy", &array);
  if (!status.ok()) {
    using Code = distband::Status::Code;
    if (status.code() != Code::kInvalidArgument && status.code() != Code::kResourceExhausted) __builtin_trap();
    if (status.message().find("fuzz.npy") == std::string::npos) __builtin_trap();
    return 0;
  }
  uint64_t elements = 1;
  for (int64_t extent : array.shape) {
    if (extent < 0) __builtin_trap();
    elements *= uint64_t(extent);
  }
  // The item size is every digit after the (optional) byte-order and the kind characters ("<f4" -> 4, "c16" -> 16).
  const std::string& d = array.descr;
  const size_t digits = !d.empty() && (d[0] == '<' || d[0] == '>' || d[0] == '|' || d[0] == '=') ? 2 : 1;
  uint64_t item = 0;
  for (size_t i = digits; i < d.size(); ++i) {
    const char c = d[i];
    if (c < '0' || c > '9') __builtin_trap();  // the reader accepted a dtype it cannot size
    item = item * 10 + uint64_t(c - '0');
  }
  if (item == 0 || array.data.size() != elements * item) __builtin_trap();
  return 0;
}
