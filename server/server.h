// DistbandServer: a running distband gRPC server — the DistanceField service, the standard grpc.health.v1
// health service and server reflection — on one listening address.
// Contract:
//   * start() binds and starts serving (returns a failed status, e.g. when the address is taken). port() is the
//     bound port (useful with "127.0.0.1:0"). Health reports SERVING for "" and "distband.v1.DistanceField".
//   * shutdown(grace) is the SIGTERM path: health goes NOT_SERVING, new queries/uploads get UNAVAILABLE (the
//     port stays open while queries drain, so probes see NOT_SERVING), running streams may continue for
//     `grace`, then they are cancelled (their engines stop); returns when every handler has returned. Idempotent; the destructor calls it with zero grace.
// start/shutdown from one controlling thread; the service itself is thread-safe.
#pragma once

#include <chrono>
#include <memory>
#include <mutex>

#include <grpcpp/server.h>
#include <grpcpp/support/status.h>

#include "server/distance_field_service.h"
#include "server/server_options.h"

namespace distband {

class DistbandServer {
 public:
  explicit DistbandServer(ServerOptions options, ServerHooks hooks = {});
  ~DistbandServer();

  grpc::Status start();
  int port() const { return port_; }
  void shutdown(std::chrono::milliseconds grace);
  /// Blocks until shutdown() has completed (from another thread).
  void wait();
  DistanceFieldService& service() { return *service_; }

 private:
  ServerOptions options_;
  std::unique_ptr<DistanceFieldService> service_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  std::mutex shutdown_mu_;
  bool shut_down_ = false;
};

}  // namespace distband
