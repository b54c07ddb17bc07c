#include "server/server.h"

#include <algorithm>
#include <fstream>
#include <sstream>
#include <thread>

#include <fmt/format.h>
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/impl/server_builder_option.h>
#include <grpcpp/impl/server_builder_plugin.h>
#include <grpcpp/resource_quota.h>
#include <grpcpp/security/server_credentials.h>
#include <spdlog/spdlog.h>

#include "server/grpc_status.h"

namespace distband {

namespace {
constexpr char kServiceName[] = "distband.v1.DistanceField";

// Loading libgrpc++_reflection registers its plugin with every ServerBuilder of the process; this option takes it
// back out unless --reflection asked for it.
class WithoutReflection final : public grpc::ServerBuilderOption {
 public:
  void UpdateArguments(grpc::ChannelArguments*) override {}
  void UpdatePlugins(std::vector<std::unique_ptr<grpc::ServerBuilderPlugin>>* plugins) override {
    plugins->erase(std::remove_if(plugins->begin(), plugins->end(),
                                  [](const auto& p) { return p->name() == "proto_server_reflection"; }),
                   plugins->end());
  }
};


Status serverCredentials(const ServerOptions& o, std::shared_ptr<grpc::ServerCredentials>* out) {
  if (o.tls_cert_file.empty()) {
    *out = grpc::InsecureServerCredentials();
    return Status::Ok();
  }
  grpc::SslServerCredentialsOptions ssl;
  grpc::SslServerCredentialsOptions::PemKeyCertPair pair;
  if (Status s = readPemFile(o.tls_key_file, "--tls-key", &pair.private_key); !s.ok()) return s;
  if (Status s = readPemFile(o.tls_cert_file, "--tls-cert", &pair.cert_chain); !s.ok()) return s;
  ssl.pem_key_cert_pairs.push_back(std::move(pair));
  if (!o.tls_client_ca_file.empty()) {
    if (Status s = readPemFile(o.tls_client_ca_file, "--tls-client-ca", &ssl.pem_root_certs); !s.ok()) return s;
    ssl.client_certificate_request = GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY;
  }
  *out = grpc::SslServerCredentials(ssl);
  return Status::Ok();
}

}  // namespace

DistbandServer::DistbandServer(ServerOptions options, ServerHooks hooks)
    : options_(std::move(options)), hooks_(std::move(hooks)) {}

DistbandServer::~DistbandServer() { shutdown(std::chrono::milliseconds(0)); }

grpc::Status DistbandServer::start() {
  if (std::string e = options_.validate(); !e.empty()) return {grpc::StatusCode::INVALID_ARGUMENT, e};
  std::unique_ptr<TokenAuth> auth;
  if (!options_.auth_token_file.empty())
    if (Status s = TokenAuth::load(options_.auth_token_file, &auth); !s.ok()) return toGrpcStatus(s);
  std::shared_ptr<grpc::ServerCredentials> credentials;
  if (Status s = serverCredentials(options_, &credentials); !s.ok()) return toGrpcStatus(s);
  metrics_ = options_.metrics_listen.empty() ? Metrics::disabled() : Metrics::enabled();
  service_ = std::make_unique<DistanceFieldService>(options_, hooks_, std::move(auth), *metrics_);
  if (Status s = service_->connectPeers(); !s.ok()) return toGrpcStatus(s);
  if (metrics_->on()) {
    if (Status s = MetricsEndpoint::start(options_.metrics_listen, *metrics_, &metrics_endpoint_); !s.ok())
      return toGrpcStatus(s);
    // Before the listening line, which tools wait for ("(port N,"): the metrics port is known by then.
    spdlog::info("metrics: http://{}/metrics (port {}; Prometheus text format, no token: keep the address private)",
                 options_.metrics_listen, metrics_endpoint_->port());
  }

  grpc::EnableDefaultHealthCheckService(true);
  if (options_.reflection) grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  if (!options_.reflection) builder.SetOption(std::make_unique<WithoutReflection>());
  builder.AddListeningPort(options_.listen_address, credentials, &port_);
  builder.RegisterService(service_.get());
  builder.SetMaxReceiveMessageSize(int(options_.max_message_bytes));
  builder.SetMaxSendMessageSize(int(options_.max_message_bytes));
  // One listener, never a second socket sharing the port with another process.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.AddChannelArgument(GRPC_ARG_MAX_CONCURRENT_STREAMS, options_.max_streams);
  grpc::ResourceQuota quota("distband-server");
  quota.SetMaxThreads(options_.resolvedGrpcThreads());
  quota.Resize(size_t(service_->memoryPlan().grpc));
  builder.SetResourceQuota(quota);
  server_ = builder.BuildAndStart();
  if (!server_ || port_ == 0)
    return {grpc::StatusCode::UNAVAILABLE, fmt::format("cannot listen on '{}'", options_.listen_address)};
  auto* health = server_->GetHealthCheckService();
  health->SetServingStatus(true);
  health->SetServingStatus(kServiceName, true);
  const MemoryPlan& plan = service_->memoryPlan();
  spdlog::info(
      "distband-server {} listening on {} (port {}, {}{}), compute threads={}, max queries={}, max streams={}, "
      "grpc threads<={}, memory budget {} (requests {}, cache {}, grpc {}), idle timeout {:g}s{}",
      DISTBAND_VERSION, options_.listen_address, port_, options_.tls_cert_file.empty() ? "plaintext" : "TLS",
      options_.tls_client_ca_file.empty() ? "" : ", client certificates required", options_.resolvedComputeThreads(),
      options_.max_concurrent_queries, options_.max_streams, options_.resolvedGrpcThreads(), humanBytes(plan.total),
      humanBytes(plan.requests), humanBytes(plan.cache), humanBytes(plan.grpc), options_.idle_timeout_seconds,
      options_.auth_token_file.empty() ? ", no authentication" : ", bearer tokens required");
  if (service_->coordinating())
    spdlog::info("coordinating: queries are split into tiles of at most {} voxels computed by --peers {} ({} per "
                 "replica in flight, {} retries, tile timeout {:g}s)",
                 options_.tile_voxels, options_.peers, options_.tiles_in_flight_per_replica, options_.tile_retries,
                 options_.tile_timeout_seconds);
  return grpc::Status::OK;
}

bool DistbandServer::shutdown(std::chrono::milliseconds grace) {
  std::lock_guard lock(shutdown_mu_);
  if (shut_down_ || !server_) return true;
  shut_down_ = true;
  service_->beginShutdown();
  auto* health = server_->GetHealthCheckService();
  health->SetServingStatus(false);
  health->SetServingStatus(kServiceName, false);
  spdlog::info("shutting down: health NOT_SERVING, {} running calls get {} ms", service_->activeCalls(), grace.count());
  // Keep accepting RPCs while calls drain, so health checks see NOT_SERVING (and new calls get UNAVAILABLE)
  // instead of connection errors; then cancel whatever is still running and stop.
  const auto deadline = std::chrono::steady_clock::now() + grace;
  while (service_->activeCalls() > 0 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const bool drained = service_->activeCalls() == 0;
  if (!drained) {
    spdlog::info("grace period over: cancelling {} calls", service_->activeCalls());
    service_->stopAll(Status::Unavailable("the server is shutting down"));
  }
  // A handler that has returned may still have its last messages and status queued in gRPC: drained calls keep the
  // rest of the grace period to deliver them (a finished result is never cut off), cancelled ones none.
  const auto steady_left =
      drained ? std::max(deadline - std::chrono::steady_clock::now(), std::chrono::steady_clock::duration::zero())
              : std::chrono::steady_clock::duration::zero();
  server_->Shutdown(std::chrono::system_clock::now() +
                    std::chrono::duration_cast<std::chrono::system_clock::duration>(steady_left));
  server_->Wait();
  spdlog::info("shutdown complete ({})", drained ? "drained" : "calls cancelled");
  return drained;
}

void DistbandServer::wait() {
  if (server_) server_->Wait();
}

}  // namespace distband
