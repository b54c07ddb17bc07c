#include "server/server_options.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

#include <fmt/format.h>

#include "server/metrics.h"

namespace distband {
namespace {

// Reads the first token of a cgroup file: a byte count, or "max" / absent = unlimited (0).
uint64_t readLimitFile(const std::string& path) {
  std::ifstream in(path);
  std::string token;
  if (!(in >> token) || token == "max") return 0;
  try {
    return std::stoull(token);
  } catch (...) {
    return 0;
  }
}

// The cgroup (v2 unified, or v1 memory controller) this process belongs to, from /proc/self/cgroup.
uint64_t cgroupMemoryLimit() {
  std::ifstream in("/proc/self/cgroup");
  std::string line;
  uint64_t limit = 0;
  auto consider = [&](uint64_t v) {
    // cgroup v1 reports "no limit" as a huge page-aligned number.
    if (v > 0 && v < (uint64_t(1) << 60)) limit = limit ? std::min(limit, v) : v;
  };
  while (std::getline(in, line)) {
    const size_t a = line.find(':'), b = line.find(':', a + 1);
    if (a == std::string::npos || b == std::string::npos) continue;
    const std::string controllers = line.substr(a + 1, b - a - 1), path = line.substr(b + 1);
    if (controllers.empty()) {  // v2: walk up the hierarchy, the tightest limit applies
      for (std::string p = path;; p = p.substr(0, p.find_last_of('/'))) {
        consider(readLimitFile("/sys/fs/cgroup" + p + "/memory.max"));
        if (p.empty() || p == "/") break;
      }
    } else if (controllers.find("memory") != std::string::npos) {
      consider(readLimitFile("/sys/fs/cgroup/memory" + path + "/memory.limit_in_bytes"));
      consider(readLimitFile("/sys/fs/cgroup/memory/memory.limit_in_bytes"));
    }
  }
  return limit;
}

}  // namespace

uint64_t processMemoryLimitBytes() {
  uint64_t limit = uint64_t(sysconf(_SC_PHYS_PAGES)) * uint64_t(sysconf(_SC_PAGESIZE));
  if (const uint64_t c = cgroupMemoryLimit(); c) limit = std::min(limit, c);
  rlimit rl{};
  if (getrlimit(RLIMIT_AS, &rl) == 0 && rl.rlim_cur != RLIM_INFINITY) limit = std::min<uint64_t>(limit, rl.rlim_cur);
  return limit;
}

std::string ServerOptions::validate() const {
  if (listen_address.empty()) return "--listen must not be empty";
  if (compute_threads < 0 || compute_threads > 1024) return "--threads must be in [0, 1024]";
  if (max_concurrent_queries < 1 || max_concurrent_queries > 1024) return "--max-queries must be in [1, 1024]";
  if (queue_wait_ms < 0 || queue_wait_ms > 600000) return "--queue-wait-ms must be in [0, 600000]";
  if (max_voxels_per_query < 1) return "--max-voxels must be >= 1";
  if (max_upload_bytes < 1) return "--max-upload-bytes must be >= 1";
  if (max_triangles < 1 || max_triangles > (uint64_t(1) << 27))
    return "--max-triangles must be in [1, 134217728] (the engine's site index has 27 bits)";
  if (max_vertices < 3 || max_vertices > (uint64_t(1) << 32) - 2) return "--max-vertices must be in [3, 2^32 - 2]";
  if (max_message_bytes < (64u << 10) || max_message_bytes > (1u << 30))
    return "--max-message-bytes must be in [64 KiB, 1 GiB]";
  if (batch_bytes < (64u << 10) || batch_bytes > max_message_bytes)
    return "--batch-bytes must be in [64 KiB, --max-message-bytes]";
  if (stream_buffer_bytes < batch_bytes) return "--stream-buffer-bytes must be >= --batch-bytes";
  if (!(grace_seconds >= 0 && grace_seconds <= 3600)) return "--grace-seconds must be in [0, 3600]";
  if (!(idle_timeout_seconds > 0 && idle_timeout_seconds <= 86400)) return "--idle-timeout must be in (0, 86400]";
  if (max_streams < 1 || max_streams > 100000) return "--max-streams must be in [1, 100000]";
  if (grpc_threads < 0 || (grpc_threads > 0 && grpc_threads < 4)) return "--grpc-threads must be 0 (auto) or >= 4";
  if (tls_cert_file.empty() != tls_key_file.empty()) return "--tls-cert and --tls-key must be given together";
  if (!tls_client_ca_file.empty() && tls_cert_file.empty())
    return "--tls-client-ca needs --tls-cert and --tls-key (mutual TLS is TLS first)";
  if (tile_voxels < 512 || tile_voxels > (uint64_t(1) << 36)) return "--tile-voxels must be in [512, 2^36]";
  if (tiles_in_flight_per_replica < 1 || tiles_in_flight_per_replica > 64) return "--tiles-in-flight must be in [1, 64]";
  if (tile_retries < 0 || tile_retries > 100) return "--tile-retries must be in [0, 100]";
  if (!(tile_timeout_seconds > 0 && tile_timeout_seconds <= 86400)) return "--tile-timeout must be in (0, 86400]";
  if (tile_buffer_bytes < (uint64_t(1) << 20)) return "--tile-buffer-bytes must be at least 1 MiB";
  if (peers.empty() && !(peer_ca_file.empty() && peer_tls_name.empty() && peer_token_file.empty()))
    return "--peer-ca, --peer-tls-name and --peer-token-file need --peers";
  if (!peer_tls_name.empty() && peer_ca_file.empty()) return "--peer-tls-name needs --peer-ca (TLS to the replicas)";
  if (!metrics_listen.empty()) {
    int port = 0;
    if (!validMetricsAddress(metrics_listen, &port))
      return fmt::format("--metrics-listen '{}' must be IPV4:PORT or [IPV6]:PORT (an address literal, e.g. "
                         "127.0.0.1:9100)",
                         metrics_listen);
    const size_t colon = listen_address.rfind(':');
    if (port != 0 && colon != std::string::npos && listen_address.substr(colon + 1) == std::to_string(port))
      return "--metrics-listen must use another port than --listen (the metrics never share the gRPC port)";
  }
  const uint64_t budget = resolvedMemoryBudget();
  if (budget < (uint64_t(64) << 20)) return fmt::format("--memory-budget must be at least 64 MiB (got {})", budget);
  if (resolvedCacheBytes() > budget / 2)
    return fmt::format("--cache-bytes ({}) must be at most half of --memory-budget ({})", resolvedCacheBytes(), budget);
  return {};
}

Status readPemFile(const std::string& path, const char* flag, std::string* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::InvalidArgument(fmt::format("{} {}: cannot read the file", flag, path));
  std::ostringstream ss;
  ss << in.rdbuf();
  *out = ss.str();
  if (out->find("-----BEGIN ") == std::string::npos)
    return Status::InvalidArgument(fmt::format("{} {}: not a PEM file (no -----BEGIN line)", flag, path));
  return Status::Ok();
}

int ServerOptions::resolvedComputeThreads() const {
  if (compute_threads > 0) return compute_threads;
  const unsigned n = std::thread::hardware_concurrency();
  return n ? int(n) : 1;
}

uint64_t ServerOptions::resolvedMemoryBudget() const {
  return memory_budget_bytes ? memory_budget_bytes : processMemoryLimitBytes() / 2;
}

uint64_t ServerOptions::resolvedCacheBytes() const {
  return cache_bytes ? cache_bytes : std::min<uint64_t>(uint64_t(1) << 30, resolvedMemoryBudget() / 4);
}

int ServerOptions::resolvedGrpcThreads() const { return grpc_threads ? grpc_threads : max_streams + 16; }

}  // namespace distband
