#include "server/server.h"

#include <algorithm>
#include <thread>

#include <fmt/format.h>
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/spdlog.h>

namespace distband {

namespace {
constexpr char kServiceName[] = "distband.v1.DistanceField";
}

DistbandServer::DistbandServer(ServerOptions options, ServerHooks hooks)
    : options_(std::move(options)), service_(std::make_unique<DistanceFieldService>(options_, std::move(hooks))) {}

DistbandServer::~DistbandServer() { shutdown(std::chrono::milliseconds(0)); }

grpc::Status DistbandServer::start() {
  if (std::string e = options_.validate(); !e.empty()) return {grpc::StatusCode::INVALID_ARGUMENT, e};
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  builder.AddListeningPort(options_.listen_address, grpc::InsecureServerCredentials(), &port_);
  builder.RegisterService(service_.get());
  builder.SetMaxReceiveMessageSize(int(options_.max_message_bytes));
  builder.SetMaxSendMessageSize(int(options_.max_message_bytes));
  server_ = builder.BuildAndStart();
  if (!server_ || port_ == 0)
    return {grpc::StatusCode::UNAVAILABLE, fmt::format("cannot listen on '{}'", options_.listen_address)};
  auto* health = server_->GetHealthCheckService();
  health->SetServingStatus(true);
  health->SetServingStatus(kServiceName, true);
  spdlog::info("distband-server {} listening on {} (port {}), compute threads={}, max queries={}", DISTBAND_VERSION,
               options_.listen_address, port_, options_.resolvedComputeThreads(), options_.max_concurrent_queries);
  return grpc::Status::OK;
}

void DistbandServer::shutdown(std::chrono::milliseconds grace) {
  std::lock_guard lock(shutdown_mu_);
  if (shut_down_ || !server_) return;
  shut_down_ = true;
  service_->beginShutdown();
  auto* health = server_->GetHealthCheckService();
  health->SetServingStatus(false);
  health->SetServingStatus(kServiceName, false);
  spdlog::info("shutting down: health NOT_SERVING, {} running queries get {} ms", service_->activeQueries(),
               grace.count());
  // Keep accepting RPCs while queries drain, so health checks see NOT_SERVING (and new queries get UNAVAILABLE)
  // instead of connection errors; then stop, cancelling whatever is still running at the deadline.
  const auto deadline = std::chrono::steady_clock::now() + grace;
  while (service_->activeQueries() > 0 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const auto left = std::max(deadline - std::chrono::steady_clock::now(), std::chrono::steady_clock::duration(0));
  server_->Shutdown(std::chrono::system_clock::now() +
                    std::chrono::duration_cast<std::chrono::system_clock::duration>(left));
  server_->Wait();
  spdlog::info("shutdown complete");
}

void DistbandServer::wait() {
  if (server_) server_->Wait();
}

}  // namespace distband
