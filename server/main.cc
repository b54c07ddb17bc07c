// distband-server: serves distband.v1.DistanceField over gRPC. See server/flags.cc for the flags and
// docs/protocol.md for the protocol.
// Signals: the first SIGTERM/SIGINT stops accepting new calls, lets running ones finish within --grace-seconds,
// cancels what is left and exits 0. A second signal during that drain exits at once (status 1).
#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <thread>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include "server/flags.h"
#include "server/log_line.h"
#include "server/server.h"

int main(int argc, char** argv) {
  distband::ServerOptions options;
  CLI::App app{"distband-server: distance fields over gRPC (distband.v1.DistanceField)"};
  app.set_version_flag("--version", DISTBAND_VERSION);
  distband::addServerFlags(app, &options);
  std::string log_level = "info";
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error, off")->capture_default_str();
  std::string log_format = "text";
  app.add_option("--log-format", log_format,
                 "text, or json: one JSON object a line with the text's fields (docs/operations.md)")
      ->check(CLI::IsMember({"text", "json"}))
      ->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  if (std::string e = options.validate(); !e.empty()) {
    std::fprintf(stderr, "distband-server: %s\n", e.c_str());
    return 2;
  }
  spdlog::set_level(spdlog::level::from_str(log_level));
  distband::LogFormat format = distband::LogFormat::kText;
  distband::parseLogFormat(log_format, &format);
  distband::setLogFormat(format);

  // Handle SIGINT/SIGTERM on this thread: block them everywhere before any other thread starts.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  distband::DistbandServer server(options);
  if (grpc::Status s = server.start(); !s.ok()) {
    std::fprintf(stderr, "distband-server: %s\n", s.error_message().c_str());
    return s.error_code() == grpc::StatusCode::INVALID_ARGUMENT ? 2 : 1;
  }
  int sig = 0;
  sigwait(&signals, &sig);
  spdlog::info("received {}: draining for up to {:g} s (send it again to exit at once)",
               sig == SIGTERM ? "SIGTERM" : "SIGINT", options.grace_seconds);
  std::atomic<bool> done{false};
  std::thread drain([&] {
    server.shutdown(std::chrono::milliseconds(int64_t(options.grace_seconds * 1000)));
    done.store(true);
  });
  // Wait for the drain, or for a second signal.
  const timespec tick{0, 50 * 1000 * 1000};
  while (!done.load()) {
    siginfo_t info;
    if (sigtimedwait(&signals, &info, &tick) > 0) {
      spdlog::warn("received a second signal: exiting without draining");
      spdlog::shutdown();
      std::_Exit(1);
    }
  }
  drain.join();
  // Everything is stopped and nothing is left to flush but the log. gRPC's global shutdown at exit would wait for
  // its executor's next timer (up to ~10 s after a busy run), so leave without running it.
  spdlog::info("exiting");
  spdlog::shutdown();
  std::fflush(nullptr);
  std::_Exit(0);
}
