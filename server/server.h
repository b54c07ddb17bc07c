// DistbandServer: a running distband gRPC server — the DistanceField service, the standard grpc.health.v1
// health service and (only with --reflection) server reflection — on exactly one listening address.
// Contract:
//   * start() reads the TLS and token files (errors name the flag and the file), binds and starts serving; it
//     returns a failed status when the address is taken or a file is unusable. port() is the bound port (useful
//     with "127.0.0.1:0"). Health reports SERVING for "" and "distband.v1.DistanceField".
//   * gRPC's threads are capped (its resource quota: --grpc-threads) and so are its buffers (a share of
//     --memory-budget); HTTP/2 streams per connection are capped at --max-streams.
//   * With --metrics-listen, start() also serves the server's Metrics (server/metrics.h) on that address, its own
//     port (metricsPort()), before the gRPC port opens; the endpoint keeps answering while calls drain and after
//     shutdown(), until the server is destroyed (stopping it takes civetweb up to a second, which the process's
//     exit does not wait for). Without the flag every metric report is a no-op.
//   * shutdown(grace) is the SIGTERM path: health goes NOT_SERVING, new calls get UNAVAILABLE (the port stays open
//     while calls drain, so probes see NOT_SERVING), running calls may continue for `grace`, then every call is
//     cancelled (its Interrupter trips, its engine stops); returns when every handler has returned. Idempotent; the
//     destructor calls it with zero grace. Returns true when every call finished within the grace period.
// start/shutdown from one controlling thread; the service itself is thread-safe.
#pragma once

#include <chrono>
#include <memory>
#include <mutex>

#include <grpcpp/server.h>
#include <grpcpp/support/status.h>

#include "server/distance_field_service.h"
#include "server/metrics.h"
#include "server/server_options.h"

namespace distband {

class DistbandServer {
 public:
  explicit DistbandServer(ServerOptions options, ServerHooks hooks = {});
  ~DistbandServer();

  grpc::Status start();
  int port() const { return port_; }
  /// The metrics endpoint's port (0 without --metrics-listen).
  int metricsPort() const { return metrics_endpoint_ ? metrics_endpoint_->port() : 0; }
  Metrics& metrics() { return *metrics_; }
  bool shutdown(std::chrono::milliseconds grace);
  /// Blocks until shutdown() has completed (from another thread).
  void wait();
  DistanceFieldService& service() { return *service_; }
  const ServerOptions& options() const { return options_; }

 private:
  ServerOptions options_;
  ServerHooks hooks_;
  // Declared before the service (which reports to it) and destroyed after it; the endpoint, which reads the
  // service's state, is destroyed first.
  std::unique_ptr<Metrics> metrics_;
  std::unique_ptr<DistanceFieldService> service_;
  std::unique_ptr<MetricsEndpoint> metrics_endpoint_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  std::mutex shutdown_mu_;
  bool shut_down_ = false;
};

}  // namespace distband
