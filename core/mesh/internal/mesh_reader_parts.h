// Internals of core/mesh/mesh_reader: the raw mesh each format reader fills, and the text scanning they share.
// Not part of the public API (only mesh_reader*.cc and tests include it).
#pragma once

#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <string_view>
#include <system_error>
#include <vector>

#include "core/interrupter.h"
#include "core/mesh/mesh_reader.h"
#include "core/status.h"
#include "core/types.h"

namespace distband::mesh_internal {

/// What a reader produces before validation: vertices as read, polygons fanned into triangles.
struct RawMesh {
  std::vector<Vec3d> vertices;
  std::vector<std::array<uint32_t, 3>> triangles;
  int64_t non_triangles = 0;  ///< point and line primitives (and faces with fewer than 3 corners)
  int64_t degenerate = 0;     ///< fan triangles that repeat a corner, dropped while reading
};

Status readObj(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out);
Status readOff(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out);
Status readPly(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out);
Status readStl(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out);

/// Polled every this many lines or records.
inline constexpr uint64_t kPollEvery = 1 << 16;

inline bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

/// Splits off the next whitespace-separated token of `*rest` ("" when none is left).
inline std::string_view nextToken(std::string_view* rest) {
  size_t b = 0;
  while (b < rest->size() && (isSpace((*rest)[b]) || (*rest)[b] == '\n')) ++b;
  size_t e = b;
  while (e < rest->size() && !isSpace((*rest)[e]) && (*rest)[e] != '\n') ++e;
  const std::string_view token = rest->substr(b, e - b);
  rest->remove_prefix(e);
  return token;
}

/// A whole token as a finite double (locale-independent; a leading '+' is accepted; inf, nan and values beyond the
/// double range are refused).
inline bool parseDouble(std::string_view t, double* out) {
  if (!t.empty() && t.front() == '+') t.remove_prefix(1);
  const auto [p, ec] = std::from_chars(t.data(), t.data() + t.size(), *out);
  return ec == std::errc() && p == t.data() + t.size() && !t.empty() && std::isfinite(*out);
}

/// A whole token as a signed 64-bit integer.
inline bool parseInt(std::string_view t, int64_t* out) {
  if (!t.empty() && t.front() == '+') t.remove_prefix(1);
  const auto [p, ec] = std::from_chars(t.data(), t.data() + t.size(), *out);
  return ec == std::errc() && p == t.data() + t.size() && !t.empty();
}

/// Lines of a text file, with their 1-based numbers; '\r' before '\n' is dropped.
class LineReader {
 public:
  explicit LineReader(std::string_view text) : rest_(text) {}
  bool next(std::string_view* line) {
    if (rest_.empty()) return false;
    const size_t eol = rest_.find('\n');
    *line = rest_.substr(0, eol);
    rest_.remove_prefix(eol == std::string_view::npos ? rest_.size() : eol + 1);
    if (!line->empty() && line->back() == '\r') line->remove_suffix(1);
    ++number_;
    return true;
  }
  uint64_t number() const { return number_; }
  size_t remaining() const { return rest_.size(); }

 private:
  std::string_view rest_;
  uint64_t number_ = 0;
};

/// Adds the fan of polygon `corners` (k >= 3) to `out`, dropping triangles that repeat a corner.
/// kResourceExhausted when the triangles would exceed `max_triangles`.
Status addFan(const uint32_t* corners, size_t k, uint64_t max_triangles, std::string_view where, RawMesh* out);

}  // namespace distband::mesh_internal
