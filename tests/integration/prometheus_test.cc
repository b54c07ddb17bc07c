// The metrics as an operator sees them: a real Prometheus server (Debian's `prometheus`, started here on a free
// loopback port with a generated config, scraping every second) scrapes real distband servers, and every figure is
// read back through Prometheus' HTTP query API.
//   * One server: N uploads (and refused ones), M queries of which K are refused and J cancelled: the counters are
//     exactly N, M, K, J and every histogram's count matches what ran; `promtool check metrics` finds no problem.
//   * A coordinator with two replicas, one killed mid-query: tiles dispatched per replica agree with the calls the
//     surviving replica counted, the retries with the query's own record, and the replica gauges follow the kill.
// Skipped, saying so, only when the prometheus binary is absent (scripts/install-deps installs it).
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/integration/service_fixture.h"
#include "tests/support/child_server.h"
#include "tests/support/http_get.h"
#include "tests/support/run_command.h"

namespace distband {
namespace {

namespace fs = std::filesystem;

/// The first of `names` found on PATH (then /usr/bin); "" when none.
std::string findBinary(const std::string& name) {
  if (const char* path = std::getenv("PATH")) {
    std::string dirs = path;
    for (size_t start = 0; start <= dirs.size();) {
      const size_t end = std::min(dirs.find(':', start), dirs.size());
      const fs::path candidate = fs::path(dirs.substr(start, end - start)) / name;
      if (::access(candidate.c_str(), X_OK) == 0) return candidate.string();
      start = end + 1;
    }
  }
  const std::string fallback = "/usr/bin/" + name;
  return ::access(fallback.c_str(), X_OK) == 0 ? fallback : "";
}

int freeLoopbackPort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof addr;
  int port = 0;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0 &&
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0)
    port = ntohs(addr.sin_port);
  ::close(fd);
  return port;
}

double unixNow() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

/// A Prometheus server scraping `targets` (job name -> metrics port) every second, in a temporary directory that
/// goes with it. Its port is picked free and tried again (up to 3 times) if another process took it meanwhile.
class PrometheusServer {
 public:
  struct Target {
    std::string job;
    int port;
  };

  explicit PrometheusServer(const std::vector<Target>& targets) {
    dir_ = fs::temp_directory_path() / ("distband-prometheus-" + std::to_string(::getpid()) + "-" +
                                        std::to_string(std::random_device{}()));
    fs::create_directories(dir_ / "data");
    std::ofstream config(dir_ / "prometheus.yml");
    config << "global:\n  scrape_interval: 1s\n  scrape_timeout: 1s\n  evaluation_interval: 1s\nscrape_configs:\n";
    for (const Target& t : targets)
      config << "  - job_name: " << t.job << "\n    static_configs:\n      - targets: ['127.0.0.1:" << t.port
             << "']\n";
    config.close();
    for (int attempt = 0; attempt < 3 && !ready_; ++attempt) start();
  }
  PrometheusServer(const PrometheusServer&) = delete;
  PrometheusServer& operator=(const PrometheusServer&) = delete;
  ~PrometheusServer() {
    stop();
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  bool ready() const { return ready_; }
  int port() const { return port_; }
  std::string log() const {
    std::ifstream in(dir_ / "prometheus.log");
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }

  /// The instant query `expr` now: the sum of its samples; NaN when it has none (or the API failed).
  double query(const std::string& expr) const {
    const HttpResponse r = httpGet(port_, "/api/v1/query?query=" + urlEncode(expr));
    if (r.status != 200) return std::nan("");
    const auto j = nlohmann::json::parse(r.body, nullptr, false);
    if (j.is_discarded() || j.value("status", "") != "success") return std::nan("");
    const auto& data = j["data"];
    if (data["resultType"] == "scalar") return std::stod(data["result"][1].get<std::string>());
    if (data["result"].empty()) return std::nan("");
    double sum = 0;
    for (const auto& sample : data["result"]) sum += std::stod(sample["value"][1].get<std::string>());
    return sum;
  }

  /// Waits until `expr` equals `value` (within `timeout`); true when it did.
  bool waitFor(const std::string& expr, double value, std::chrono::seconds timeout = std::chrono::seconds(20)) const {
    const auto end = Clock::now() + timeout;
    while (Clock::now() < end) {
      if (query(expr) == value) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
    return query(expr) == value;
  }

  /// Waits until every target has been scraped after this call (so each scrape saw everything done before it).
  bool waitForScrapeAfterNow(std::chrono::seconds timeout = std::chrono::seconds(20)) const {
    const double now = unixNow();
    const auto end = Clock::now() + timeout;
    while (Clock::now() < end) {
      const double oldest = query("min(timestamp(up))");
      if (oldest > now) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
    return false;
  }

 private:
  void start() {
    port_ = freeLoopbackPort();
    const std::string binary = findBinary("prometheus");
    const std::vector<std::string> args = {
        binary,
        "--config.file=" + (dir_ / "prometheus.yml").string(),
        "--storage.tsdb.path=" + (dir_ / "data").string(),
        "--web.listen-address=127.0.0.1:" + std::to_string(port_),
        "--storage.tsdb.retention.time=1h",
        "--log.level=warn"};
    pid_ = ::fork();
    if (pid_ == 0) {
      const int fd = ::open((dir_ / "prometheus.log").c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      if (fd >= 0) {
        ::dup2(fd, 1);
        ::dup2(fd, 2);
      }
      std::vector<char*> argv;
      for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    const auto end = Clock::now() + std::chrono::seconds(30);
    while (Clock::now() < end) {
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {  // exited: the port was taken, or a bad config
        pid_ = -1;
        return;
      }
      if (httpGet(port_, "/-/ready", std::chrono::milliseconds(1000)).status == 200) {
        ready_ = true;
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    stop();
  }

  void stop() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGTERM);
    const auto end = Clock::now() + std::chrono::seconds(10);
    while (Clock::now() < end && ::waitpid(pid_, nullptr, WNOHANG) != pid_)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    if (::kill(pid_, 0) == 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    pid_ = -1;
  }

  fs::path dir_;
  pid_t pid_ = -1;
  int port_ = 0;
  bool ready_ = false;
};

#define REQUIRE_PROMETHEUS()                                                                           \
  do {                                                                                                 \
    if (findBinary("prometheus").empty())                                                              \
      GTEST_SKIP() << "PROMETHEUS TEST NOT RUN: no prometheus binary on PATH or in /usr/bin (Debian's " \
                      "`prometheus` package; scripts/install-deps installs it)";                        \
  } while (0)

std::string tetrahedronObj(double s) {
  return fmt::format("v 0 0 0\nv {0} 0 0\nv 0 {0} 0\nv 0 0 {0}\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n", s);
}

std::vector<Vec3d> randomPointsIn(int n, double extent, unsigned seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> at(0.0, extent);
  std::vector<Vec3d> points;
  for (int i = 0; i < n; ++i) points.push_back({at(random), at(random), at(random)});
  return points;
}

/// A query on an uploaded mesh, `dims`^3 voxels.
v1::QueryRequest meshQuery(const std::string& asset_id, int resolution) {
  v1::QueryRequest r;
  r.set_asset_id(asset_id);
  r.mutable_grid()->set_resolution(uint32_t(resolution));
  r.set_limit(0.3);
  r.set_segment_length(0.1);
  return r;
}

TEST(PrometheusTest, OneServersCountersAndHistogramsMatchTheWorkloadExactly) {
  REQUIRE_PROMETHEUS();
  const auto t0 = Clock::now();
  ServerOptions o = TestServer::defaults();
  o.metrics_listen = "127.0.0.1:0";
  o.max_upload_bytes = 64 << 10;
  TestServer ts(o);
  ASSERT_GT(ts.server().metricsPort(), 0);
  PrometheusServer prometheus({{"distband", ts.server().metricsPort()}});
  ASSERT_TRUE(prometheus.ready()) << prometheus.log();
  ASSERT_TRUE(prometheus.waitFor("up{job=\"distband\"}", 1)) << prometheus.log();

  // N uploads, and two refused: a malformed mesh (bad input) and one over --max-upload-bytes (limits).
  constexpr int N = 3;
  std::vector<std::string> assets;
  for (int i = 0; i < N; ++i) {
    v1::UploadReply up;
    const grpc::Status s = ts.client().uploadMesh(tetrahedronObj(1.0 + i), v1::MESH_FORMAT_OBJ, "tet.obj", &up);
    ASSERT_TRUE(s.ok()) << s.error_message();
    assets.push_back(up.asset_id());
  }
  v1::UploadReply up;
  EXPECT_EQ(ts.client().uploadMesh("v 0 0 0\nf 1 2 3\n", v1::MESH_FORMAT_OBJ, "bad.obj", &up).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(ts.client().uploadMesh(std::string(80 << 10, '#'), v1::MESH_FORMAT_OBJ, "big.obj", &up).error_code(),
            grpc::StatusCode::RESOURCE_EXHAUSTED);

  // M queries: OK ones on points and on the meshes, K refused before any work, J cancelled by the client.
  constexpr int K = 3, J = 2;
  int ok = 0;
  for (unsigned seed = 1; seed <= 3; ++seed) {
    const Streamed s = stream(ts.client(), pointsRequest(randomPointsIn(5, 16.0, seed), {32, 32, 32}, 0.5, 2.0, 0),
                              -1.0f);
    ASSERT_TRUE(s.result.status.ok()) << s.result.status.error_message();
    ++ok;
  }
  for (int i = 0; i < 2; ++i) {
    const Streamed s = stream(ts.client(), meshQuery(assets[size_t(i)], 40), 0.3f);
    ASSERT_TRUE(s.result.status.ok()) << s.result.status.error_message();
    ++ok;
  }
  v1::QueryRequest no_seeds = pointsRequest({}, {32, 32, 32}, 0.5, 0, 0);
  v1::QueryRequest no_dims = pointsRequest(randomPointsIn(2, 8.0, 4), {0, 32, 32}, 0.5, 0, 0);
  v1::QueryRequest too_big = pointsRequest(randomPointsIn(2, 8.0, 5), {2048, 2048, 2048}, 0.5, 0, 0);
  EXPECT_EQ(stream(ts.client(), no_seeds, -1.0f).result.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(stream(ts.client(), no_dims, -1.0f).result.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(stream(ts.client(), too_big, -1.0f).result.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  for (unsigned seed = 6; seed < 6 + J; ++seed) {
    // 160^3 on the band, segments of 2 voxels: far more than one batch, so the cancel lands mid-stream.
    v1::QueryRequest big = pointsRequest(randomPointsIn(3, 80.0, seed), {160, 160, 160}, 0.5, 1.0, 0);
    big.set_stencil(v1::STENCIL_CUBIC26);
    const Streamed s = stream(ts.client(), big, -1.0f, [](int batches) { return batches < 1; });
    EXPECT_TRUE(s.result.cancelled_by_client);
  }
  const int M = ok + K + J;
  ASSERT_TRUE(ts.waitRecords(size_t(M)));
  uint64_t voxels = 0, ok_value_bytes = 0;
  for (const QueryRecord& r : ts.records()) {
    voxels += r.voxels;
    if (r.code == grpc::StatusCode::OK) ok_value_bytes += r.bytes;  // a cancelled query encoded more than it sent
  }
  ASSERT_EQ(ts.records().size(), size_t(M));
  ASSERT_TRUE(prometheus.waitForScrapeAfterNow()) << prometheus.log();

  // Calls by RPC and code.
  EXPECT_EQ(prometheus.query(R"(distband_calls_total{rpc="UploadMesh",code="OK"})"), N);
  EXPECT_EQ(prometheus.query(R"(sum(distband_calls_total{rpc="UploadMesh"}))"), N + 2);
  EXPECT_EQ(prometheus.query(R"(distband_upload_refusals_total{rpc="UploadMesh",reason="bad_input"})"), 1);
  EXPECT_EQ(prometheus.query(R"(distband_upload_refusals_total{rpc="UploadMesh",reason="limits"})"), 1);
  EXPECT_EQ(prometheus.query(R"(sum(distband_upload_refusals_total))"), 2);
  EXPECT_EQ(prometheus.query(R"(sum(distband_calls_total{rpc="Query"}))"), M);
  EXPECT_EQ(prometheus.query(R"(distband_calls_total{rpc="Query",code="OK"})"), M - K - J);
  EXPECT_EQ(prometheus.query(R"(sum(distband_calls_total{rpc="Query",code=~"INVALID_ARGUMENT|RESOURCE_EXHAUSTED"}))"),
            K);
  EXPECT_EQ(prometheus.query(R"(distband_calls_total{rpc="Query",code="CANCELLED"})"), J);
  // Histogram counts: every call has a duration; each phase counts the queries that reached it.
  EXPECT_EQ(prometheus.query(R"(distband_call_duration_seconds_count{rpc="Query"})"), M);
  EXPECT_EQ(prometheus.query(R"(distband_call_duration_seconds_bucket{rpc="Query",le="+Inf"})"), M);
  EXPECT_EQ(prometheus.query(R"(distband_call_duration_seconds_count{rpc="UploadMesh"})"), N + 2);
  EXPECT_EQ(prometheus.query("distband_query_queue_wait_seconds_count"), M - K);
  EXPECT_EQ(prometheus.query("distband_query_first_brick_seconds_count"), M - K);
  EXPECT_EQ(prometheus.query("distband_query_seed_seconds_count"), M - K - J);
  EXPECT_EQ(prometheus.query("distband_query_compute_seconds_count"), M - K - J);
  EXPECT_EQ(prometheus.query(R"(distband_upload_parse_seconds_count{rpc="UploadMesh"})"), N + 1);  // + the malformed
  EXPECT_EQ(prometheus.query(R"(distband_upload_received_bytes_total{rpc="UploadMesh"})"),
            double(tetrahedronObj(1).size() + tetrahedronObj(2).size() + tetrahedronObj(3).size() + 16));
  // What was sent.
  EXPECT_EQ(prometheus.query("distband_query_sent_voxels_total"), double(voxels));
  EXPECT_GT(prometheus.query("distband_query_sent_bytes_total"), double(ok_value_bytes));
  // Gauges at rest.
  EXPECT_EQ(prometheus.query("distband_queries_running"), 0);
  EXPECT_EQ(prometheus.query("distband_queries_queued"), 0);
  EXPECT_EQ(prometheus.query("distband_streams_open"), 0);
  EXPECT_EQ(prometheus.query("distband_memory_budget_reserved_bytes"), 0);
  EXPECT_EQ(prometheus.query("distband_memory_budget_bytes"), double(ts.server().service().budget().capacity()));
  EXPECT_EQ(prometheus.query("distband_asset_cache_entries"), N);
  EXPECT_EQ(prometheus.query("distband_asset_cache_bytes"), double(ts.server().service().cache().usedBytes()));
  EXPECT_EQ(prometheus.query("distband_compute_threads"), 2);
  EXPECT_GT(prometheus.query("process_cpu_seconds_total"), 0);
  EXPECT_GT(prometheus.query("process_resident_memory_bytes"), 1e6);
  // Rates work on them (two scrapes at least).
  EXPECT_GE(prometheus.query(R"(sum(increase(distband_calls_total{rpc="Query"}[1m])))"), 0);

  // The scrape itself passes promtool's checks.
  const std::string promtool = findBinary("promtool");
  if (promtool.empty()) {
    ADD_FAILURE() << "promtool missing beside prometheus";
  } else {
    const HttpResponse scrape = httpGet(ts.server().metricsPort(), "/metrics");
    ASSERT_EQ(scrape.status, 200);
    const fs::path file = fs::temp_directory_path() / ("distband-scrape-" + std::to_string(::getpid()) + ".txt");
    std::ofstream(file) << scrape.body;
    const auto [out, rc] = runCommand(promtool + " check metrics < " + file.string() + " 2>&1");
    fs::remove(file);
    EXPECT_EQ(rc, 0) << out;
    EXPECT_EQ(out, "") << "promtool check metrics reported problems";
    EXPECT_LT(scrape.body.size(), size_t(64) << 10);
  }
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - t0).count(), 60.0);
}

TEST(PrometheusTest, ACoordinatorsTilesAndRetriesMatchItsReplicas) {
  REQUIRE_PROMETHEUS();
  const auto t0 = Clock::now();
  std::vector<std::unique_ptr<ChildServer>> replicas;
  std::vector<int> metrics_ports;
  std::string peers = "ipv4:";
  const std::regex metrics_line(R"(metrics: http://\S+ \(port (\d+);)");
  for (int i = 0; i < 2; ++i) {
    replicas.push_back(std::make_unique<ChildServer>(
        DISTBAND_SERVER_BINARY,
        std::vector<std::string>{"--threads", "1", "--memory-budget", "2G", "--metrics-listen", "127.0.0.1:0"}));
    ASSERT_GT(replicas.back()->port(), 0) << replicas.back()->log();
    std::smatch m;
    const std::string log = replicas.back()->log();
    ASSERT_TRUE(std::regex_search(log, m, metrics_line)) << log;
    metrics_ports.push_back(std::stoi(m[1]));
    peers += (i ? "," : "") + replicas.back()->target();
  }
  ServerOptions o = TestServer::defaults();
  o.peers = peers;
  o.tile_voxels = 32 * 32 * 32;
  o.tiles_in_flight_per_replica = 1;
  o.metrics_listen = "127.0.0.1:0";
  TestServer coordinator(o);
  ASSERT_GT(coordinator.server().metricsPort(), 0);
  PrometheusServer prometheus({{"coordinator", coordinator.server().metricsPort()},
                               {"replica0", metrics_ports[0]},
                               {"replica1", metrics_ports[1]}});
  ASSERT_TRUE(prometheus.ready()) << prometheus.log();
  ASSERT_TRUE(prometheus.waitFor("sum(up)", 3)) << prometheus.log();
  EXPECT_TRUE(prometheus.waitFor("distband_coordinator_replicas_healthy", 2));
  EXPECT_EQ(prometheus.query("distband_coordinator_replicas_known"), 2);

  // 128^3 in 64 tiles of 32^3, one in flight per replica; replica 0 is stopped before the query (its tile hangs there,
  // nothing of it merged) and killed at the first batch, so its tile is always retried (ScaleOutTest has the same).
  const v1::QueryRequest request = pointsRequest(randomPointsIn(40, 64.0, 11), {128, 128, 128}, 0.5, 1.0, 8.0);
  bool killed = false;
  replicas[0]->signal(SIGSTOP);
  const Streamed s = stream(coordinator.client(), request, -1.0f, [&](int batches) {
    if (!killed && batches == 1) {
      replicas[0]->signal(SIGKILL);
      killed = true;
    }
    return true;
  });
  ASSERT_TRUE(s.result.status.ok()) << s.result.status.error_message();
  ASSERT_TRUE(coordinator.waitRecords(1));
  const QueryRecord record = coordinator.records().back();
  ASSERT_GE(record.tile_retries, 1) << "the killed replica's tiles should have been retried";

  EXPECT_TRUE(prometheus.waitFor("distband_coordinator_replicas_healthy", 1));
  EXPECT_TRUE(prometheus.waitFor(R"(up{job="replica0"})", 0));
  ASSERT_TRUE(prometheus.waitForScrapeAfterNow());
  const std::string alive = "ipv4:" + replicas[1]->target();
  const std::string dispatched_alive = "distband_coordinator_tiles_dispatched_total{replica=\"" + alive + "\"}";
  const double to_alive = prometheus.query(dispatched_alive);
  EXPECT_GT(to_alive, 0);
  // The surviving replica counts a call when its handler returns, maybe after the coordinator saw its status.
  EXPECT_TRUE(prometheus.waitFor(R"(sum(distband_calls_total{job="replica1",rpc="Query"}))", to_alive))
      << prometheus.query(R"(sum(distband_calls_total{job="replica1",rpc="Query"}))") << " calls on the replica, "
      << to_alive << " tile calls sent to it";

  EXPECT_EQ(prometheus.query(R"(distband_calls_total{job="coordinator",rpc="Query",code="OK"})"), 1);
  EXPECT_EQ(prometheus.query("sum(distband_coordinator_tiles_retried_total)"), record.tile_retries);
  EXPECT_GE(prometheus.query("sum(distband_coordinator_tiles_failed_total)"), record.tile_retries);
  // Every tile the query planned was computed somewhere: dispatched = first attempts sent + retries.
  EXPECT_GE(prometheus.query("sum(distband_coordinator_tiles_dispatched_total)"), record.tile_retries + 1);
  EXPECT_EQ(prometheus.query("distband_coordinator_replicas_known"), 2);
  EXPECT_EQ(prometheus.query("distband_coordinator_merge_buffer_bytes"), 0);
  EXPECT_EQ(prometheus.query(R"(distband_query_sent_voxels_total{job="coordinator"})"), double(record.voxels));
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - t0).count(), 60.0);
}

}  // namespace
}  // namespace distband
