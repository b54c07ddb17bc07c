#include "server/log_line.h"

#include <atomic>
#include <cmath>
#include <memory>

#include <fmt/format.h>
#include <spdlog/pattern_formatter.h>
#include <spdlog/spdlog.h>

namespace distband {
namespace {

// JSON lines go through a second logger over the default logger's sinks, so the one formatter of those sinks can
// tell a LogLine's fields (written as they are) from a plain message (written as "msg").
constexpr std::string_view kFieldsLogger = "distband.fields";

std::atomic<LogFormat> g_format{LogFormat::kText};
std::shared_ptr<spdlog::logger> g_fields;  // set once by setLogFormat(kJson), before other threads log

class JsonPayload final : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&, spdlog::memory_buf_t& dest) override {
    const std::string_view payload(msg.payload.data(), msg.payload.size());
    if (std::string_view(msg.logger_name.data(), msg.logger_name.size()) == kFieldsLogger) {
      dest.append(payload.data(), payload.data() + payload.size());
    } else {
      const std::string text = "\"msg\":" + jsonQuoted(payload);
      dest.append(text.data(), text.data() + text.size());
    }
  }
  std::unique_ptr<custom_flag_formatter> clone() const override { return std::make_unique<JsonPayload>(); }
};

// Length of the valid UTF-8 sequence starting at s[i], or 0 when the bytes there are not one.
size_t utf8Length(std::string_view s, size_t i) {
  const auto c = static_cast<unsigned char>(s[i]);
  size_t n;
  uint32_t cp;
  if (c >= 0xc2 && c <= 0xdf) n = 2, cp = c & 0x1fu;
  else if (c >= 0xe0 && c <= 0xef) n = 3, cp = c & 0x0fu;
  else if (c >= 0xf0 && c <= 0xf4) n = 4, cp = c & 0x07u;
  else return 0;
  if (i + n > s.size()) return 0;
  for (size_t k = 1; k < n; ++k) {
    const auto d = static_cast<unsigned char>(s[i + k]);
    if ((d & 0xc0) != 0x80) return 0;
    cp = (cp << 6) | (d & 0x3fu);
  }
  const bool overlong = (n == 3 && cp < 0x800) || (n == 4 && cp < 0x10000);
  if (overlong || cp > 0x10ffff || (cp >= 0xd800 && cp <= 0xdfff)) return 0;
  return n;
}

}  // namespace

bool parseLogFormat(std::string_view name, LogFormat* out) {
  if (name == "text") *out = LogFormat::kText;
  else if (name == "json") *out = LogFormat::kJson;
  else return false;
  return true;
}

void setLogFormat(LogFormat format) {
  auto logger = spdlog::default_logger();
  if (format == LogFormat::kJson) {
    g_fields = std::make_shared<spdlog::logger>(std::string(kFieldsLogger), logger->sinks().begin(),
                                                logger->sinks().end());
    g_fields->set_level(spdlog::level::trace);  // LogLine::write asks the default logger's level
    auto formatter = std::make_unique<spdlog::pattern_formatter>();
    formatter->add_flag<JsonPayload>('*').set_pattern(R"({"ts":"%Y-%m-%dT%H:%M:%S.%e%z","level":"%l",%*})");
    logger->set_formatter(std::move(formatter));
  } else if (g_fields) {
    g_fields.reset();
    logger->set_formatter(std::make_unique<spdlog::pattern_formatter>());  // spdlog's default pattern
  }
  g_format.store(format);
}

LogFormat logFormat() { return g_format.load(); }

std::string jsonQuoted(std::string_view s) {
  std::string out;
  out.reserve(s.size() + 2);
  out += '"';
  for (size_t i = 0; i < s.size();) {
    const auto c = static_cast<unsigned char>(s[i]);
    if (c >= 0x80) {
      // Valid UTF-8 passes; a stray byte becomes its Latin-1 code point, so the line stays valid JSON.
      if (const size_t n = utf8Length(s, i)) {
        out.append(s.substr(i, n));
        i += n;
      } else {
        out += fmt::format("\\u{:04x}", c);
        ++i;
      }
      continue;
    }
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      default:
        if (c < 0x20 || c == 0x7f) out += fmt::format("\\u{:04x}", c);
        else out += char(c);
    }
    ++i;
  }
  out += '"';
  return out;
}

std::string logSafe(std::string_view s) {
  std::string out;
  for (size_t i = 0; i < s.size() && i < 64; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 0x20 && c < 0x7f && c != '\\' && c != '\'' && c != '"') out += char(c);
    else out += fmt::format("\\x{:02x}", c);
  }
  if (s.size() > 64) out += "...";
  return out;
}

LogLine::LogLine(std::string_view event, std::string_view id_name, std::string_view id)
    : json_(logFormat() == LogFormat::kJson) {
  if (json_) {
    out_ = "\"event\":" + jsonQuoted(event);
    if (!id.empty()) {
      key(id_name);
      out_ += jsonQuoted(id);
    }
  } else {
    out_ = std::string(event);
    if (!id.empty()) (out_ += ' ') += id;
  }
}

void LogLine::key(std::string_view k) {
  if (json_) {
    out_ += ',';
    out_ += jsonQuoted(k);
    out_ += ':';
  } else {
    out_ += ' ';
    out_ += k;
    out_ += '=';
  }
}

LogLine& LogLine::text(std::string_view k, std::string_view value) {
  key(k);
  if (json_) out_ += jsonQuoted(value);
  else out_ += value;
  return *this;
}

LogLine& LogLine::quoted(std::string_view k, std::string_view value) {
  key(k);
  if (json_) out_ += jsonQuoted(value);
  else ((out_ += '\'') += value) += '\'';
  return *this;
}

LogLine& LogLine::number(std::string_view k, int64_t value) {
  key(k);
  out_ += fmt::format("{}", value);
  return *this;
}

LogLine& LogLine::number(std::string_view k, uint64_t value) {
  key(k);
  out_ += fmt::format("{}", value);
  return *this;
}

LogLine& LogLine::real(std::string_view k, double value, std::string_view text_format) {
  key(k);
  if (!json_) out_ += fmt::format(fmt::runtime(text_format), value);
  else if (std::isfinite(value)) out_ += fmt::format("{}", value);
  else out_ += "null";
  return *this;
}

LogLine& LogLine::seconds(std::string_view k, double value) {
  key(k);
  if (!json_) out_ += fmt::format("{:.3f}s", value);
  else if (std::isfinite(value)) out_ += fmt::format("{:.6f}", value);
  else out_ += "null";
  return *this;
}

LogLine& LogLine::flag(std::string_view k, bool value) {
  key(k);
  out_ += value ? "true" : "false";
  return *this;
}

LogLine& LogLine::status(const Status& s) {
  if (s.ok()) return text("status", "OK");
  if (json_) return text("status", Status::codeName(s.code())).text("message", s.message());
  key("status");
  out_ += fmt::format("{} \"{}\"", Status::codeName(s.code()), s.message());
  return *this;
}

void LogLine::write(spdlog::level::level_enum level) const {
  const auto logger = spdlog::default_logger();
  if (!logger->should_log(level)) return;
  if (json_ && g_fields) g_fields->log(level, spdlog::string_view_t(out_.data(), out_.size()));
  else logger->log(level, spdlog::string_view_t(out_.data(), out_.size()));
}

}  // namespace distband
