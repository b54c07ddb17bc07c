// distband-health: the container image's HEALTHCHECK. The same grpc.health.v1 check as `distband health`
// (RemoteClient::health, exit 0 iff SERVING, the status name on stdout), built without the CLI's output writers,
// so it links no libblosc or libpng and the runtime image can leave those libraries out. Takes the CLI's connection
// flags (--tls, --tls-ca, client certificates), so it can probe a server that serves TLS.
#include <chrono>
#include <cstdio>
#include <string>

#include <CLI/CLI.hpp>

#include "client/remote_client.h"
#include "client/remote_connection.h"

int main(int argc, char** argv) {
  distband::ConnectionArgs connection;
  std::string service;
  double timeout_seconds = 5;
  CLI::App app{"distband-health: grpc.health.v1 check of a distband server (exit 0 iff SERVING)"};
  distband::addConnectionFlags(&app, &connection);
  app.add_option("--service", service, "Service name (\"\": the whole server)");
  app.add_option("--timeout", timeout_seconds, "Deadline of the check, seconds")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  distband::RemoteClientOptions options;
  if (std::string error = distband::makeClientOptions(connection, &options); !error.empty()) {
    std::fprintf(stderr, "distband-health: %s\n", error.c_str());
    return 2;
  }
  const std::string& server = connection.server;
  distband::RemoteClient client(server, options);
  bool serving = false;
  std::string status_name;
  const auto deadline = std::chrono::milliseconds(static_cast<long long>(timeout_seconds * 1000));
  if (grpc::Status s = client.health(service, &serving, &status_name, deadline); !s.ok()) {
    std::fprintf(stderr, "distband-health: %s: %s\n", server.c_str(), s.error_message().c_str());
    return 1;
  }
  std::printf("%s\n", status_name.c_str());
  return serving ? 0 : 1;
}
