// Text scanning shared by the strict readers of untrusted text (core/mesh's mesh readers, core/io/ply_header.h,
// core/io/point_cloud.h): whitespace tokens, locale-independent numbers, numbered lines, and excerpts of the input
// for error messages.
// Contract: pure functions over views of the caller's bytes; nothing allocates but textExcerpt; thread-safe.
#pragma once

#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <system_error>

namespace distband {

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

/// `text` for an error message: at most `max_bytes`, non-printable bytes as \xNN, quotes escaped, "..." when cut.
std::string textExcerpt(std::string_view text, size_t max_bytes = 32);

}  // namespace distband
