#include "server/replica_pool.h"

#include <netdb.h>
#include <sys/socket.h>
#include <arpa/inet.h>

#include <algorithm>
#include <sstream>

#include <fmt/format.h>

#include "grpc/health/v1/health.grpc.pb.h"
#include "server/token_auth.h"

namespace distband {
namespace {

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string part; std::getline(in, part, sep);)
    if (!part.empty()) out.push_back(part);
  return out;
}

// "host:port" or "[v6]:port" -> host, port.
bool splitHostPort(const std::string& s, std::string* host, std::string* port) {
  if (!s.empty() && s.front() == '[') {
    const size_t close = s.find(']');
    if (close == std::string::npos || close + 1 >= s.size() || s[close + 1] != ':') return false;
    *host = s.substr(1, close - 1);
    *port = s.substr(close + 2);
  } else {
    const size_t colon = s.rfind(':');
    if (colon == std::string::npos) return false;
    *host = s.substr(0, colon);
    *port = s.substr(colon + 1);
  }
  return !host->empty() && !port->empty() && std::all_of(port->begin(), port->end(), ::isdigit);
}

// The addresses one HOST:PORT resolves to (getaddrinfo), as single-address gRPC targets.
std::vector<std::string> resolveName(const std::string& name, const std::string& target, std::string* error) {
  std::vector<std::string> out;
  std::string host, port;
  if (!splitHostPort(name, &host, &port)) {
    *error = fmt::format("--peers {}: expected ipv4:ADDR:PORT,..., dns:///HOST:PORT or HOST:PORT,HOST:PORT,...", target);
    return out;
  }
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (int rc = getaddrinfo(host.c_str(), port.c_str(), &hints, &found); rc != 0) {
    *error = fmt::format("--peers {}: cannot resolve {}: {}", target, host, gai_strerror(rc));
    return out;
  }
  for (addrinfo* a = found; a; a = a->ai_next) {
    char text[INET6_ADDRSTRLEN] = {};
    if (a->ai_family == AF_INET) {
      inet_ntop(AF_INET, &reinterpret_cast<sockaddr_in*>(a->ai_addr)->sin_addr, text, sizeof text);
      out.push_back(fmt::format("ipv4:{}:{}", text, port));
    } else if (a->ai_family == AF_INET6) {
      inet_ntop(AF_INET6, &reinterpret_cast<sockaddr_in6*>(a->ai_addr)->sin6_addr, text, sizeof text);
      out.push_back(fmt::format("ipv6:[{}]:{}", text, port));
    }
  }
  freeaddrinfo(found);
  if (out.empty()) *error = fmt::format("--peers {}: {} resolves to no address", target, host);
  return out;
}

// One round_robin target for single-address targets: gRPC's ipv4:/ipv6: schemes take one family each (IPv4 wins).
std::string combinedTarget(const std::vector<std::string>& addresses) {
  std::string v4, v6;
  for (const std::string& a : addresses) {
    std::string& list = a.rfind("ipv4:", 0) == 0 ? v4 : v6;
    list += (list.empty() ? "" : ",") + a.substr(5);
  }
  return !v4.empty() ? "ipv4:" + v4 : (!v6.empty() ? "ipv6:" + v6 : "");
}

}  // namespace

std::vector<std::string> resolveReplicaAddresses(const std::string& target, std::string* error) {
  std::vector<std::string> out;
  if (target.rfind("ipv4:", 0) == 0 || target.rfind("ipv6:", 0) == 0) {
    const std::string scheme = target.substr(0, 5);
    for (const std::string& a : split(target.substr(5), ',')) out.push_back(scheme + a);
    if (out.empty()) *error = fmt::format("--peers {}: no address after '{}'", target, scheme);
    return out;
  }
  std::vector<std::string> names;
  if (target.rfind("dns:///", 0) == 0) names = {target.substr(7)};
  else if (target.rfind("dns:", 0) == 0) names = {target.substr(4)};
  else names = split(target, ',');
  if (names.empty()) *error = fmt::format("--peers {}: no replica named", target);
  for (const std::string& name : names) {
    std::string one_error;
    for (std::string& a : resolveName(name, target, &one_error)) out.push_back(std::move(a));
    if (!one_error.empty()) *error = one_error;  // reported only when nothing resolves
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  if (!out.empty()) error->clear();
  return out;
}


Status ReplicaPool::create(const ServerOptions& o, std::unique_ptr<ReplicaPool>* out) {
  std::unique_ptr<ReplicaPool> pool(new ReplicaPool());
  pool->target_ = o.peers;
  pool->max_message_bytes_ = int(std::max<uint32_t>(o.max_message_bytes, 64u << 20));
  if (o.peer_ca_file.empty()) {
    pool->credentials_ = grpc::InsecureChannelCredentials();
  } else {
    grpc::SslCredentialsOptions ssl;
    if (Status s = readPemFile(o.peer_ca_file, "--peer-ca", &ssl.pem_root_certs); !s.ok()) return s;
    pool->credentials_ = grpc::SslCredentials(ssl);
    pool->tls_name_ = o.peer_tls_name;
  }
  if (!o.peer_token_file.empty()) {  // the first token (the replicas check it)
    std::vector<TokenLine> tokens;
    if (Status s = readTokenLines(o.peer_token_file, "--peer-token-file", &tokens); !s.ok()) return s;
    pool->token_ = tokens.front().token;
  }
  std::string error;
  if (resolveReplicaAddresses(o.peers, &error).empty() && error.find("expected") != std::string::npos)
    return Status::InvalidArgument(error);  // malformed; a name that does not resolve yet may later (pods starting)
  pool->name_list_ = o.peers.rfind("ipv4:", 0) != 0 && o.peers.rfind("ipv6:", 0) != 0 && o.peers.rfind("dns:", 0) != 0;
  if (!pool->name_list_) {
    pool->balanced_target_ = o.peers;
    pool->balanced_stub_ = v1::DistanceField::NewStub(pool->makeChannel(o.peers, true));
  }
  *out = std::move(pool);
  return Status::Ok();
}

std::shared_ptr<v1::DistanceField::Stub> ReplicaPool::balanced() {
  if (name_list_) replicas();  // refreshes the channel when the names resolve to other addresses
  std::lock_guard lock(mu_);
  return balanced_stub_;
}

std::shared_ptr<grpc::Channel> ReplicaPool::makeChannel(const std::string& target, bool round_robin) const {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(max_message_bytes_);
  args.SetMaxSendMessageSize(max_message_bytes_);
  if (round_robin) args.SetLoadBalancingPolicyName("round_robin");
  if (!tls_name_.empty()) args.SetSslTargetNameOverride(tls_name_);
  // A replica that restarts is tried again within a second, not after gRPC's default back-off of up to 2 minutes.
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 200);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 1000);
  args.SetInt(GRPC_ARG_DNS_MIN_TIME_BETWEEN_RESOLUTIONS_MS, 1000);
  auto channel = grpc::CreateCustomChannel(target, credentials_, args);
  // Connect now, not on the first tile: round_robin spreads calls over the replicas that are READY, so a query that
  // arrives while connections are still being made would put its first tiles on whichever replica answered first.
  channel->GetState(true);
  return channel;
}

std::vector<ReplicaPool::Replica> ReplicaPool::replicas() {
  std::lock_guard lock(mu_);
  const auto now = std::chrono::steady_clock::now();
  if (!replicas_.empty() && now - resolved_at_ < std::chrono::seconds(1)) return replicas_;
  std::string error;
  std::vector<Replica> fresh;
  for (const std::string& a : resolveReplicaAddresses(target_, &error)) {
    auto old = std::find_if(replicas_.begin(), replicas_.end(), [&](const Replica& r) { return r.address == a; });
    fresh.push_back({a, old != replicas_.end() ? old->channel : makeChannel(a, false)});
  }
  const bool changed = fresh.size() != replicas_.size() ||
                       !std::equal(fresh.begin(), fresh.end(), replicas_.begin(),
                                   [](const Replica& a, const Replica& b) { return a.address == b.address; });
  replicas_ = std::move(fresh);
  resolved_at_ = now;
  if (changed && on_resolved_) {
    std::vector<std::string> addresses;
    for (const Replica& r : replicas_) addresses.push_back(r.address);
    on_resolved_(addresses);
  }
  if (name_list_) {
    std::vector<std::string> addresses;
    for (const Replica& r : replicas_) addresses.push_back(r.address);
    const std::string target = combinedTarget(addresses);
    if (target != balanced_target_ && !target.empty()) {
      balanced_target_ = target;
      balanced_stub_ = v1::DistanceField::NewStub(makeChannel(target, true));
    }
  }
  return replicas_;
}

size_t ReplicaPool::lastReplicaCount() const {
  std::lock_guard lock(mu_);
  return replicas_.size();
}

ReplicaPool::~ReplicaPool() {
  {
    std::lock_guard lock(health_mu_);
    health_stop_ = true;
  }
  health_cv_.notify_all();
  if (health_thread_.joinable()) health_thread_.join();
}

void ReplicaPool::onResolved(ResolvedCallback callback) {
  std::lock_guard lock(mu_);
  on_resolved_ = std::move(callback);
}

void ReplicaPool::watchHealth(std::chrono::milliseconds interval) {
  if (health_thread_.joinable()) return;
  health_thread_ = std::thread([this, interval] { healthRounds(interval); });
}

void ReplicaPool::healthRounds(std::chrono::milliseconds interval) {
  for (;;) {
    size_t serving = 0;
    for (const Replica& r : replicas()) {
      grpc::ClientContext context;
      context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(1));
      grpc::health::v1::HealthCheckRequest request;
      request.set_service("distband.v1.DistanceField");
      grpc::health::v1::HealthCheckResponse response;
      const grpc::Status s = grpc::health::v1::Health::NewStub(r.channel)->Check(&context, request, &response);
      if (s.ok() && response.status() == grpc::health::v1::HealthCheckResponse::SERVING) ++serving;
    }
    healthy_.store(serving);
    std::unique_lock lock(health_mu_);
    if (health_cv_.wait_for(lock, interval, [&] { return health_stop_; })) return;
  }
}

void ReplicaPool::prepare(grpc::ClientContext* context, std::chrono::system_clock::time_point deadline) const {
  if (!token_.empty()) context->AddMetadata("authorization", "Bearer " + token_);
  context->set_deadline(deadline);
}

}  // namespace distband
