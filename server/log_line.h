// LogLine: one log line of a call — an event ("Query", "UploadMesh", "TileRetry", ...), an optional id and named
// fields in a fixed order — written in the server's log format (--log-format):
//   text (default): `Query q3 request_id=8f0c... peer=ipv4:127.0.0.1:5312 grid=64x64x64 time=0.012s status=OK`
//   json:           `{"ts":"2026-11-26T18:16:00.123+00:00","level":"info","event":"Query","query":"q3",
//                    "request_id":"8f0c...","peer":"ipv4:127.0.0.1:5312","grid":"64x64x64","time":0.012,
//                    "status":"OK"}` (one object a line)
// Contract:
//   * The same fields in both formats, in the same order. In JSON, numbers are numbers (the text's unit suffix
//     dropped: "time" and the other durations in seconds, "engine_stop_after_cancel" in milliseconds; NaN and
//     infinities are null), every other value a string, and a failed status is two fields, "status" (the code's
//     name) and "message".
//   * Values are written as given: callers bound and escape client-chosen text first (logSafe()).
//   * Lines that are not a call's (start-up, shutdown) stay plain spdlog messages; in JSON each becomes
//     {"ts":..,"level":..,"msg":".."}, so every line of a JSON log is one object.
//   * setLogFormat() installs the format on spdlog's default logger and its sinks; main() calls it once, after the
//     level and before any other thread logs. Without it the format is text.
// A LogLine is built and written by one thread; writing is thread-safe (spdlog's sinks lock).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include <spdlog/common.h>

#include "core/status.h"

namespace distband {

enum class LogFormat { kText, kJson };

/// "text" or "json"; false for anything else.
bool parseLogFormat(std::string_view name, LogFormat* out);
void setLogFormat(LogFormat format);
LogFormat logFormat();

/// `s` as a JSON string literal, quotes included (control characters and non-ASCII bytes as \u00XX escapes).
std::string jsonQuoted(std::string_view s);

/// Client-chosen text for a log line: at most 64 bytes, non-printables, backslashes and quotes escaped as \xNN, so
/// no client can forge a line or a field.
std::string logSafe(std::string_view s);

class LogLine {
 public:
  /// `id` (optional) follows the event in text ("Query q3") and is the field `id_name` in JSON ("query":"q3").
  explicit LogLine(std::string_view event, std::string_view id_name = {}, std::string_view id = {});

  /// A string field (text: key=value).
  LogLine& text(std::string_view key, std::string_view value);
  /// A string field shown quoted in text (key='value'), for names a client chose.
  LogLine& quoted(std::string_view key, std::string_view value);
  LogLine& number(std::string_view key, int64_t value);
  LogLine& number(std::string_view key, uint64_t value);
  LogLine& number(std::string_view key, int value) { return number(key, int64_t(value)); }
  /// A real number; `text_format` is its fmt format in text ("{:g}", "{:.1f}").
  LogLine& real(std::string_view key, double value, std::string_view text_format = "{:g}");
  /// Seconds: text "0.123s", JSON 0.123.
  LogLine& seconds(std::string_view key, double value);
  LogLine& flag(std::string_view key, bool value);
  /// status=OK, or status=CODE "message" in text; "status" and "message" in JSON.
  LogLine& status(const Status& status);

  void write(spdlog::level::level_enum level = spdlog::level::info) const;
  /// The line as it would be written (without spdlog's time and level in text).
  const std::string& payload() const { return out_; }

 private:
  void key(std::string_view key);
  bool json_;
  std::string out_;
};

}  // namespace distband
