// LogLine: the same fields in text and in JSON, JSON that parses line by line (also for plain messages and hostile
// bytes), and logSafe's bound on client-chosen text.
#include "server/log_line.h"

#include <sstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

namespace distband {
namespace {

LogLine queryLine() {
  LogLine line("Query", "query", "q3");
  line.text("request_id", "abc-1")
      .text("peer", "ipv4:127.0.0.1:5000")
      .quoted("name", "bunny")
      .number("voxels", uint64_t(4096))
      .real("h", 0.25)
      .real("MB", 1.25, "{:.1f}")
      .seconds("time", 0.0123)
      .flag("cached", false);
  return line;
}

/// Routes the default logger into a string for the scope, in `format`; restores text and the old logger after.
class CapturedLog {
 public:
  explicit CapturedLog(LogFormat format) : previous_(spdlog::default_logger()) {
    auto logger = std::make_shared<spdlog::logger>("captured", std::make_shared<spdlog::sinks::ostream_sink_mt>(out_));
    logger->set_level(spdlog::level::info);
    spdlog::set_default_logger(logger);
    setLogFormat(format);
  }
  ~CapturedLog() {
    setLogFormat(LogFormat::kText);
    spdlog::set_default_logger(previous_);
  }
  std::vector<std::string> lines() const {
    std::vector<std::string> out;
    std::istringstream in(out_.str());
    for (std::string l; std::getline(in, l);) out.push_back(l);
    return out;
  }

 private:
  std::ostringstream out_;
  std::shared_ptr<spdlog::logger> previous_;
};

TEST(LogLineTest, TextIsTheServersKeyValueLine) {
  const LogLine line = queryLine();
  EXPECT_EQ(line.payload(),
            "Query q3 request_id=abc-1 peer=ipv4:127.0.0.1:5000 name='bunny' voxels=4096 h=0.25 MB=1.2 time=0.012s "
            "cached=false");
  LogLine failed("GetInfo");
  failed.status(Status::Unauthenticated("no token"));
  EXPECT_EQ(failed.payload(), "GetInfo status=UNAUTHENTICATED \"no token\"");
  LogLine ok("GetInfo");
  ok.status(Status::Ok());
  EXPECT_EQ(ok.payload(), "GetInfo status=OK");
}

TEST(LogLineTest, JsonHasTheSameFieldsInOrderOneObjectALine) {
  CapturedLog log(LogFormat::kJson);
  LogLine line = queryLine();
  line.status(Status::InvalidArgument("grid.dims: \"x\" must be > 0\nsecond line"));
  line.write();
  spdlog::info("a plain message with \"quotes\", a tab\tand a stray byte \xff");
  LogLine debug("Hidden");
  debug.write(spdlog::level::debug);  // below the level: not written
  const auto lines = log.lines();
  ASSERT_EQ(lines.size(), 2u);
  const auto call = nlohmann::json::parse(lines[0]);
  // nlohmann's object sorts its keys: the order on the line is checked on the text itself.
  EXPECT_LT(lines[0].find("\"event\""), lines[0].find("\"query\""));
  EXPECT_LT(lines[0].find("\"query\""), lines[0].find("\"request_id\""));
  EXPECT_LT(lines[0].find("\"time\""), lines[0].find("\"status\""));
  EXPECT_EQ(call["event"], "Query");
  EXPECT_EQ(call["query"], "q3");
  EXPECT_EQ(call["level"], "info");
  EXPECT_TRUE(call["ts"].is_string());
  EXPECT_EQ(call["request_id"], "abc-1");
  EXPECT_EQ(call["name"], "bunny");
  EXPECT_EQ(call["voxels"], 4096);
  EXPECT_DOUBLE_EQ(call["h"].get<double>(), 0.25);
  EXPECT_DOUBLE_EQ(call["time"].get<double>(), 0.0123);
  EXPECT_EQ(call["cached"], false);
  EXPECT_EQ(call["status"], "INVALID_ARGUMENT");
  EXPECT_EQ(call["message"], "grid.dims: \"x\" must be > 0\nsecond line");
  const auto plain = nlohmann::json::parse(lines[1]);
  EXPECT_EQ(plain["msg"], "a plain message with \"quotes\", a tab\tand a stray byte \xc3\xbf");
  EXPECT_EQ(plain["level"], "info");
}

TEST(LogLineTest, JsonNumbersStayValidJson) {
  CapturedLog log(LogFormat::kJson);
  LogLine line("X");
  line.real("nan", std::nan("")).seconds("inf", 1.0 / 0.0).real("tiny", 1e-300);
  line.write();
  const auto j = nlohmann::json::parse(log.lines().at(0));
  EXPECT_TRUE(j["nan"].is_null());
  EXPECT_TRUE(j["inf"].is_null());
  EXPECT_DOUBLE_EQ(j["tiny"].get<double>(), 1e-300);
}

TEST(LogLineTest, JsonQuotedKeepsValidUtf8AndEscapesTheRest) {
  EXPECT_EQ(jsonQuoted("a\"b\\c"), "\"a\\\"b\\\\c\"");
  EXPECT_EQ(jsonQuoted("\x01\x7f"), "\"\\u0001\\u007f\"");
  EXPECT_EQ(jsonQuoted("3\xc2\xb3 \xe2\x89\xa4"), "\"3\xc2\xb3 \xe2\x89\xa4\"");  // 3³ ≤
  EXPECT_EQ(jsonQuoted("\xc0\xaf"), "\"\\u00c0\\u00af\"");                     // overlong '/'
  EXPECT_EQ(jsonQuoted("\xed\xa0\x80"), "\"\\u00ed\\u00a0\\u0080\"");          // a surrogate
  EXPECT_EQ(jsonQuoted("\xe2\x89"), "\"\\u00e2\\u0089\"");                     // truncated
}

TEST(LogLineTest, LogSafeBoundsAndEscapesClientText) {
  EXPECT_EQ(logSafe("bunny.obj"), "bunny.obj");
  EXPECT_EQ(logSafe("a'b\"c\\d\ne"), "a\\x27b\\x22c\\x5cd\\x0ae");
  EXPECT_EQ(logSafe(std::string(100, 'x')), std::string(64, 'x') + "...");
}

TEST(LogLineTest, ParseLogFormat) {
  LogFormat f = LogFormat::kText;
  EXPECT_TRUE(parseLogFormat("json", &f));
  EXPECT_EQ(f, LogFormat::kJson);
  EXPECT_TRUE(parseLogFormat("text", &f));
  EXPECT_EQ(f, LogFormat::kText);
  EXPECT_FALSE(parseLogFormat("xml", &f));
}

}  // namespace
}  // namespace distband
