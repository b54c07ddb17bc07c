#include "server/metrics.h"

#include <arpa/inet.h>
#include <dirent.h>
#include <sys/resource.h>
#include <unistd.h>

#include <array>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>

#include <CivetServer.h>
#include <fmt/format.h>
#include <prometheus/collectable.h>
#include <prometheus/counter.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/metric_family.h>
#include <prometheus/registry.h>
#include <prometheus/text_serializer.h>

namespace distband {
namespace {

using prometheus::ClientMetric;
using prometheus::Counter;
using prometheus::Gauge;
using prometheus::Histogram;
using prometheus::MetricFamily;
using prometheus::MetricType;

constexpr int kCodeCount = 17;  // grpc::StatusCode OK (0) .. UNAUTHENTICATED (16)

const char* codeName(int code) {
  // grpc::StatusCode's values in order.
  static constexpr std::array<const char*, kCodeCount> names = {
      "OK",           "CANCELLED",         "UNKNOWN",            "INVALID_ARGUMENT",    "DEADLINE_EXCEEDED",
      "NOT_FOUND",    "ALREADY_EXISTS",    "PERMISSION_DENIED",  "RESOURCE_EXHAUSTED",  "FAILED_PRECONDITION",
      "ABORTED",      "OUT_OF_RANGE",      "UNIMPLEMENTED",      "INTERNAL",            "UNAVAILABLE",
      "DATA_LOSS",    "UNAUTHENTICATED"};
  return names[size_t(code)];
}

// From 1 ms (a refused call, GetInfo) to 5 minutes (a large query); the same for every duration, so they compare.
const Histogram::BucketBoundaries& durationBuckets() {
  static const Histogram::BucketBoundaries b = {0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25,
                                                0.5,   1,      2.5,   5,    10,    30,   60,  300};
  return b;
}

MetricFamily gaugeFamily(const char* name, const char* help, double value, MetricType type = MetricType::Gauge) {
  MetricFamily f;
  f.name = name;
  f.help = help;
  f.type = type;
  ClientMetric m;
  if (type == MetricType::Counter) m.counter.value = value;
  else m.gauge.value = value;
  f.metric.push_back(std::move(m));
  return f;
}

// The standard process_ family (as Prometheus' own client libraries name it), read from /proc/self at each scrape.
class ProcessCollector final : public prometheus::Collectable {
 public:
  std::vector<MetricFamily> Collect() const override {
    std::vector<MetricFamily> out;
    std::ifstream stat_file("/proc/self/stat");
    std::string stat((std::istreambuf_iterator<char>(stat_file)), std::istreambuf_iterator<char>());
    const size_t close = stat.rfind(')');
    if (close == std::string::npos) return out;
    std::istringstream fields(stat.substr(close + 2));
    std::vector<std::string> f;  // f[0] is field 3 (state) of proc(5)
    for (std::string x; fields >> x;) f.push_back(x);
    if (f.size() < 22) return out;
    auto field = [&](int n) { return std::stod(f[size_t(n - 3)]); };
    const double tick = double(sysconf(_SC_CLK_TCK));
    out.push_back(gaugeFamily("process_cpu_seconds_total", "User and system CPU time spent in seconds.",
                              (field(14) + field(15)) / tick, MetricType::Counter));
    out.push_back(gaugeFamily("process_resident_memory_bytes", "Resident memory size in bytes.",
                              field(24) * double(sysconf(_SC_PAGESIZE))));
    out.push_back(gaugeFamily("process_virtual_memory_bytes", "Virtual memory size in bytes.", field(23)));
    out.push_back(gaugeFamily("process_threads", "Number of OS threads in the process.", field(20)));
    if (boot_time_ > 0)
      out.push_back(gaugeFamily("process_start_time_seconds", "Start time of the process since unix epoch in seconds.",
                                boot_time_ + field(22) / tick));
    int fds = 0;
    if (DIR* d = opendir("/proc/self/fd")) {
      while (const dirent* e = readdir(d))
        if (e->d_name[0] != '.') ++fds;
      closedir(d);
      out.push_back(gaugeFamily("process_open_fds", "Number of open file descriptors.", fds - 1));  // less opendir's
    }
    rlimit limit{};
    if (getrlimit(RLIMIT_NOFILE, &limit) == 0)
      out.push_back(gaugeFamily("process_max_fds", "Maximum number of open file descriptors.", double(limit.rlim_cur)));
    return out;
  }

 private:
  static double bootTime() {
    std::ifstream in("/proc/stat");
    for (std::string line; std::getline(in, line);)
      if (line.rfind("btime ", 0) == 0) return std::stod(line.substr(6));
    return 0;
  }
  const double boot_time_ = bootTime();
};

// Gauges whose value lives elsewhere (the budget, the cache, the pool), read when Prometheus scrapes.
class ScrapeGauges final : public prometheus::Collectable {
 public:
  struct Entry {
    const char* name;
    const char* help;
    std::function<double()> read;
  };
  explicit ScrapeGauges(std::vector<Entry> entries) : entries_(std::move(entries)) {}
  std::vector<MetricFamily> Collect() const override {
    std::vector<MetricFamily> out;
    for (const Entry& e : entries_) out.push_back(gaugeFamily(e.name, e.help, e.read()));
    return out;
  }

 private:
  const std::vector<Entry> entries_;
};

}  // namespace

const char* rpcName(Rpc rpc) {
  switch (rpc) {
    case Rpc::kUploadMesh: return "UploadMesh";
    case Rpc::kUploadVolume: return "UploadVolume";
    case Rpc::kQuery: return "Query";
    case Rpc::kGetInfo: return "GetInfo";
    case Rpc::kQueryPoints: return "QueryPoints";
  }
  return "?";
}

const char* refusalName(UploadRefusal reason) {
  switch (reason) {
    case UploadRefusal::kAuth: return "auth";
    case UploadRefusal::kBadInput: return "bad_input";
    case UploadRefusal::kLimits: return "limits";
    case UploadRefusal::kBudget: return "budget";
  }
  return "?";
}

struct Metrics::Impl {
  std::shared_ptr<prometheus::Registry> registry = std::make_shared<prometheus::Registry>();
  std::shared_ptr<ProcessCollector> process = std::make_shared<ProcessCollector>();
  std::shared_ptr<ScrapeGauges> scrape;

  std::array<std::array<Counter*, kCodeCount>, kRpcCount> calls{};
  std::array<Histogram*, kRpcCount> call_seconds{};
  Gauge *queries_queued = nullptr, *queries_running = nullptr;
  Histogram *queue_wait = nullptr, *first_brick = nullptr, *seed = nullptr, *compute = nullptr;
  Counter *sent_bytes = nullptr, *sent_voxels = nullptr;
  // Uploads: index 0 UploadMesh, 1 UploadVolume.
  std::array<Counter*, 2> upload_bytes{};
  std::array<Histogram*, 2> parse_seconds{};
  std::array<std::array<Counter*, kUploadRefusalCount>, 2> refusals{};
  // Coordinator.
  prometheus::Family<Counter>* tiles_dispatched = nullptr;
  prometheus::Family<Counter>* tiles_retried = nullptr;
  prometheus::Family<Counter>* tiles_failed = nullptr;
  Gauge* merge_buffer = nullptr;
  struct ReplicaSeries {
    Counter *dispatched, *retried, *failed;
  };
  std::mutex replicas_mu;  // guards `replicas` and every increment of its counters (a series may be removed)
  std::map<std::string, ReplicaSeries> replicas;

  Impl();
  ReplicaSeries& replica(const std::string& address);  // under replicas_mu
  std::vector<std::weak_ptr<prometheus::Collectable>> collectables() const {
    std::vector<std::weak_ptr<prometheus::Collectable>> out = {registry, process};
    if (scrape) out.push_back(scrape);
    return out;
  }
};

Metrics::Impl::Impl() {
  prometheus::Registry& r = *registry;
  prometheus::BuildGauge()
      .Name("distband_build_info")
      .Help("Always 1; the version of distband-server as a label.")
      .Register(r)
      .Add({{"version", DISTBAND_VERSION}})
      .Set(1);
  auto& calls_family = prometheus::BuildCounter()
                           .Name("distband_calls_total")
                           .Help("DistanceField calls ended, by RPC and gRPC status code (refused calls included).")
                           .Register(r);
  auto& seconds_family = prometheus::BuildHistogram()
                             .Name("distband_call_duration_seconds")
                             .Help("Time from a call's arrival to its status, by RPC.")
                             .Register(r);
  for (int rpc = 0; rpc < kRpcCount; ++rpc) {
    const std::string name = rpcName(Rpc(rpc));
    for (int code = 0; code < kCodeCount; ++code)
      calls[size_t(rpc)][size_t(code)] = &calls_family.Add({{"rpc", name}, {"code", codeName(code)}});
    call_seconds[size_t(rpc)] = &seconds_family.Add({{"rpc", name}}, durationBuckets());
  }

  auto gauge = [&](const char* name, const char* help) {
    return &prometheus::BuildGauge().Name(name).Help(help).Register(r).Add({});
  };
  auto counter = [&](const char* name, const char* help) {
    return &prometheus::BuildCounter().Name(name).Help(help).Register(r).Add({});
  };
  auto histogram = [&](const char* name, const char* help) {
    return &prometheus::BuildHistogram().Name(name).Help(help).Register(r).Add({}, durationBuckets());
  };
  queries_queued = gauge("distband_queries_queued", "Queries waiting for admission (memory budget, compute slot).");
  queries_running = gauge("distband_queries_running", "Queries admitted and streaming.");
  queue_wait = histogram("distband_query_queue_wait_seconds",
                         "Time a query waited for admission (memory budget and compute slot), admitted or refused.");
  first_brick = histogram("distband_query_first_brick_seconds",
                          "Time from a query's arrival to its first brick batch sent (queries that sent one).");
  seed = histogram("distband_query_seed_seconds",
                   "Time building a query's seeds (queries computed here, to their end).");
  compute = histogram("distband_query_compute_seconds",
                      "Time computing a query's field (queries computed here, to their end).");
  sent_bytes = counter("distband_query_sent_bytes_total", "Bytes of Query reply messages sent to clients.");
  sent_voxels = counter("distband_query_sent_voxels_total", "Voxels delivered to clients by Query calls.");

  auto& upload_bytes_family = prometheus::BuildCounter()
                                  .Name("distband_upload_received_bytes_total")
                                  .Help("Bytes of upload data received, by RPC.")
                                  .Register(r);
  auto& parse_family = prometheus::BuildHistogram()
                           .Name("distband_upload_parse_seconds")
                           .Help("Time parsing and analysing an upload (not for uploads already cached), by RPC.")
                           .Register(r);
  auto& refusal_family = prometheus::BuildCounter()
                             .Name("distband_upload_refusals_total")
                             .Help("Uploads refused, by RPC and reason (auth, bad_input, limits, budget).")
                             .Register(r);
  for (int k = 0; k < 2; ++k) {
    const std::string name = rpcName(k == 0 ? Rpc::kUploadMesh : Rpc::kUploadVolume);
    upload_bytes[size_t(k)] = &upload_bytes_family.Add({{"rpc", name}});
    parse_seconds[size_t(k)] = &parse_family.Add({{"rpc", name}}, durationBuckets());
    for (int reason = 0; reason < kUploadRefusalCount; ++reason)
      refusals[size_t(k)][size_t(reason)] =
          &refusal_family.Add({{"rpc", name}, {"reason", refusalName(UploadRefusal(reason))}});
  }

  tiles_dispatched = &prometheus::BuildCounter()
                          .Name("distband_coordinator_tiles_dispatched_total")
                          .Help("Tile calls a coordinator sent, by replica.")
                          .Register(r);
  tiles_retried = &prometheus::BuildCounter()
                       .Name("distband_coordinator_tiles_retried_total")
                       .Help("Tile calls that failed on a replica and were retried elsewhere, by the replica.")
                       .Register(r);
  tiles_failed = &prometheus::BuildCounter()
                      .Name("distband_coordinator_tiles_failed_total")
                      .Help("Tile calls that failed on a replica (retried or not), by replica.")
                      .Register(r);
  merge_buffer = gauge("distband_coordinator_merge_buffer_bytes",
                       "Bytes of later segments a coordinator holds while earlier ones wait for slower tiles.");
}

Metrics::Impl::ReplicaSeries& Metrics::Impl::replica(const std::string& address) {
  std::string label = address.empty() ? "unknown" : address;
  auto it = replicas.find(label);
  if (it != replicas.end()) return it->second;
  if (replicas.size() >= kMaxReplicaLabels) {
    label = "other";
    it = replicas.find(label);
    if (it != replicas.end()) return it->second;
  }
  const prometheus::Labels l = {{"replica", label}};
  const ReplicaSeries series{&tiles_dispatched->Add(l), &tiles_retried->Add(l), &tiles_failed->Add(l)};
  return replicas.emplace(label, series).first->second;
}

Metrics::Metrics(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Metrics::~Metrics() = default;

std::unique_ptr<Metrics> Metrics::disabled() { return std::unique_ptr<Metrics>(new Metrics(nullptr)); }
std::unique_ptr<Metrics> Metrics::enabled() { return std::unique_ptr<Metrics>(new Metrics(std::make_unique<Impl>())); }

void Metrics::watch(Sources s) {
  if (!impl_) return;
  std::vector<ScrapeGauges::Entry> e;
  auto add = [&](const char* name, const char* help, std::function<double()>& read) {
    if (read) e.push_back({name, help, std::move(read)});
  };
  add("distband_streams_open", "DistanceField calls in flight (bounded by --max-streams).", s.streams_open);
  add("distband_memory_budget_reserved_bytes", "Bytes of the requests' memory budget reserved by uploads and queries.",
      s.budget_reserved_bytes);
  add("distband_memory_budget_bytes", "The requests' memory budget (--memory-budget less the process, cache and gRPC).",
      s.budget_bytes);
  add("distband_asset_cache_bytes", "Bytes held by the asset cache.", s.cache_bytes);
  add("distband_asset_cache_capacity_bytes", "Capacity of the asset cache (--cache-bytes).", s.cache_capacity_bytes);
  add("distband_asset_cache_entries", "Assets (meshes, volumes) in the asset cache.", s.cache_entries);
  add("distband_compute_threads", "Threads computing one query (--threads).", s.compute_threads);
  add("distband_coordinator_replicas_known", "Replicas --peers resolves to now.", s.replicas_known);
  add("distband_coordinator_replicas_healthy", "Replicas whose health service answered SERVING at the last check.",
      s.replicas_healthy);
  impl_->scrape = std::make_shared<ScrapeGauges>(std::move(e));
}

void Metrics::callEnded(Rpc rpc, grpc::StatusCode code, double seconds) {
  if (!impl_) return;
  const int c = int(code) >= 0 && int(code) < kCodeCount ? int(code) : int(grpc::StatusCode::UNKNOWN);
  impl_->calls[size_t(rpc)][size_t(c)]->Increment();
  impl_->call_seconds[size_t(rpc)]->Observe(seconds);
}

void Metrics::queryQueued(int delta) {
  if (impl_) impl_->queries_queued->Increment(delta);
}
void Metrics::queryRunning(int delta) {
  if (impl_) impl_->queries_running->Increment(delta);
}
void Metrics::queryAdmitted(double queue_wait_seconds) {
  if (impl_) impl_->queue_wait->Observe(queue_wait_seconds);
}
void Metrics::queryFirstBrick(double seconds) {
  if (impl_) impl_->first_brick->Observe(seconds);
}
void Metrics::queryComputed(double seed_seconds, double compute_seconds) {
  if (!impl_) return;
  impl_->seed->Observe(seed_seconds);
  impl_->compute->Observe(compute_seconds);
}
void Metrics::querySentBytes(uint64_t bytes) {
  if (impl_) impl_->sent_bytes->Increment(double(bytes));
}
void Metrics::querySentVoxels(uint64_t voxels) {
  if (impl_) impl_->sent_voxels->Increment(double(voxels));
}

namespace {
size_t uploadIndex(Rpc rpc) { return rpc == Rpc::kUploadVolume ? 1 : 0; }
}  // namespace

void Metrics::uploadReceived(Rpc rpc, uint64_t bytes) {
  if (impl_) impl_->upload_bytes[uploadIndex(rpc)]->Increment(double(bytes));
}
void Metrics::uploadParsed(Rpc rpc, double seconds) {
  if (impl_) impl_->parse_seconds[uploadIndex(rpc)]->Observe(seconds);
}
void Metrics::uploadRefused(Rpc rpc, UploadRefusal reason) {
  if (impl_) impl_->refusals[uploadIndex(rpc)][size_t(reason)]->Increment();
}

void Metrics::tileDispatched(const std::string& replica) {
  if (!impl_) return;
  std::lock_guard lock(impl_->replicas_mu);
  impl_->replica(replica).dispatched->Increment();
}

void Metrics::tileFailed(const std::string& replica, bool retried) {
  if (!impl_) return;
  std::lock_guard lock(impl_->replicas_mu);
  Impl::ReplicaSeries& s = impl_->replica(replica);
  s.failed->Increment();
  if (retried) s.retried->Increment();
}

void Metrics::replicasResolved(const std::vector<std::string>& addresses) {
  if (!impl_) return;
  const std::set<std::string> now(addresses.begin(), addresses.end());
  std::lock_guard lock(impl_->replicas_mu);
  for (auto it = impl_->replicas.begin(); it != impl_->replicas.end();) {
    if (now.count(it->first) || it->first == "unknown" || it->first == "other") {
      ++it;
      continue;
    }
    impl_->tiles_dispatched->Remove(it->second.dispatched);
    impl_->tiles_retried->Remove(it->second.retried);
    impl_->tiles_failed->Remove(it->second.failed);
    it = impl_->replicas.erase(it);
  }
}

void Metrics::mergeBufferChanged(int64_t delta_bytes) {
  if (impl_ && delta_bytes != 0) impl_->merge_buffer->Increment(double(delta_bytes));
}

std::string Metrics::text() const {
  if (!impl_) return "";
  std::vector<MetricFamily> families;
  for (const auto& weak : impl_->collectables())
    if (auto c = weak.lock()) {
      auto f = c->Collect();
      families.insert(families.end(), std::make_move_iterator(f.begin()), std::make_move_iterator(f.end()));
    }
  return prometheus::TextSerializer().Serialize(families);
}

bool validMetricsAddress(const std::string& address, int* port) {
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos || colon + 1 >= address.size() || address.size() - colon - 1 > 5) return false;
  const std::string host = address.substr(0, colon), digits = address.substr(colon + 1);
  for (const char c : digits)
    if (c < '0' || c > '9') return false;
  const int p = std::stoi(digits);
  if (p > 65535) return false;
  unsigned char buf[16];
  bool ok;
  if (host.size() > 2 && host.front() == '[' && host.back() == ']')
    ok = inet_pton(AF_INET6, host.substr(1, host.size() - 2).c_str(), buf) == 1;
  else
    ok = inet_pton(AF_INET, host.c_str(), buf) == 1;
  if (ok && port) *port = p;
  return ok;
}

// prometheus-cpp's own Exposer adds metrics of its own (exposer_*, outside distband_ and in microseconds), so the
// endpoint is the same HTTP server it uses, civetweb, with one handler.
struct MetricsEndpoint::Impl final : CivetHandler {
  const Metrics& metrics;
  std::unique_ptr<CivetServer> server;
  explicit Impl(const Metrics& m) : metrics(m) {}
  ~Impl() override { server.reset(); }  // stops serving (joins civetweb's threads) before the handler goes
  bool handleGet(CivetServer*, mg_connection* connection) override {
    const std::string body = metrics.text();
    mg_printf(connection,
              "HTTP/1.1 200 OK\r\nContent-Type: text/plain; version=0.0.4; charset=utf-8\r\nContent-Length: %zu\r\n"
              "Cache-Control: no-store\r\nConnection: close\r\n\r\n",
              body.size());
    mg_write(connection, body.data(), body.size());
    return true;
  }
};

MetricsEndpoint::~MetricsEndpoint() = default;

Status MetricsEndpoint::start(const std::string& address, Metrics& metrics, std::unique_ptr<MetricsEndpoint>* out) {
  if (!validMetricsAddress(address))
    return Status::InvalidArgument(fmt::format(
        "--metrics-listen '{}': expected IPV4:PORT or [IPV6]:PORT (an address literal: 127.0.0.1:9100, 0.0.0.0:9100)",
        address));
  if (!metrics.on()) return Status::Internal("the metrics endpoint needs enabled metrics");
  if (address.front() == '[' && !mg_check_feature(8))
    return Status::InvalidArgument(fmt::format(
        "--metrics-listen '{}': this build's HTTP server (civetweb) has no IPv6 support; use an IPv4 address", address));
  std::unique_ptr<MetricsEndpoint> endpoint(new MetricsEndpoint());
  endpoint->impl_ = std::make_unique<Impl>(metrics);
  try {
    // Two threads: Prometheus scrapes one request at a time; a slow or stalled client is dropped after 10 s. No
    // document root: nothing but /metrics is served.
    endpoint->impl_->server = std::make_unique<CivetServer>(std::vector<std::string>{
        "listening_ports", address, "num_threads", "2", "request_timeout_ms", "10000", "enable_keep_alive", "no"});
  } catch (const std::exception& e) {
    return Status::InvalidArgument(fmt::format("--metrics-listen '{}': cannot listen there ({})", address, e.what()));
  }
  endpoint->impl_->server->addHandler("/metrics$", *endpoint->impl_);
  const std::vector<int> ports = endpoint->impl_->server->getListeningPorts();
  endpoint->port_ = ports.empty() ? 0 : ports.front();
  *out = std::move(endpoint);
  return Status::Ok();
}

}  // namespace distband
