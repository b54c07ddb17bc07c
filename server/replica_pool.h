// ReplicaPool: a coordinator's connections to its replicas (distband-server --peers TARGET).
// Contract:
//   * TARGET is a gRPC target naming every replica: "ipv4:10.0.0.1:50051,10.0.0.2:50051", "ipv6:[::1]:5001,...",
//     "dns:///distband-headless.ns.svc.cluster.local:50051" (a Kubernetes headless Service: one A record per pod)
//     or "host:port" (same as dns:///host:port).
//   * balanced() is one channel over all of them with gRPC's round_robin policy: each tile is one call, so tiles
//     spread per call; gRPC re-resolves DNS and drops a dead replica from the rotation by itself.
//   * replicas() lists one channel per replica address (resolved now, at most every second: for uploads, which must
//     reach every replica because round_robin decides where each tile runs).
//   * prepare() adds the call credentials (--peer-token-file) and a deadline to a ClientContext. TLS to the
//     replicas with --peer-ca (and --peer-tls-name when certificates do not name the addresses).
// Thread-safe.
#pragma once

#include <chrono>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "core/status.h"
#include "distband/v1/distband.grpc.pb.h"
#include "server/server_options.h"

namespace distband {

class ReplicaPool {
 public:
  struct Replica {
    std::string address;  ///< a gRPC target naming exactly one replica, e.g. "ipv4:10.0.0.1:50051"
    std::shared_ptr<grpc::Channel> channel;
  };

  /// Reads the credential files named by the options (errors name the flag).
  static Status create(const ServerOptions& options, std::unique_ptr<ReplicaPool>* out);

  v1::DistanceField::Stub& balanced() { return *balanced_stub_; }
  /// Every replica the target names now (resolved at most once a second); empty when none resolves.
  std::vector<Replica> replicas();
  /// Replicas found by the last resolution.
  size_t lastReplicaCount() const;
  void prepare(grpc::ClientContext* context, std::chrono::system_clock::time_point deadline) const;
  const std::string& target() const { return target_; }

 private:
  ReplicaPool() = default;
  std::shared_ptr<grpc::Channel> makeChannel(const std::string& target, bool round_robin) const;

  std::string target_;
  std::shared_ptr<grpc::ChannelCredentials> credentials_;
  std::string tls_name_, token_;
  int max_message_bytes_ = 0;
  std::shared_ptr<grpc::Channel> balanced_;
  std::unique_ptr<v1::DistanceField::Stub> balanced_stub_;
  mutable std::mutex mu_;
  std::chrono::steady_clock::time_point resolved_at_{};
  std::vector<Replica> replicas_;
};

/// The addresses a target names, each as a single-address gRPC target ("ipv4:a:p" / "ipv6:[a]:p"); DNS names are
/// resolved with getaddrinfo. Empty with `error` set when the target is malformed or does not resolve.
std::vector<std::string> resolveReplicaAddresses(const std::string& target, std::string* error);

}  // namespace distband
