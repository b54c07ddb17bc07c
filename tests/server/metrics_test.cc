// Metrics: what each report changes in the exposition, that a disabled Metrics reports nothing, that the scrape stays
// bounded however many calls are served, the replica label's bound, and the endpoint on its own address.
#include "server/metrics.h"

#include <cmath>
#include <set>
#include <sstream>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "tests/support/http_get.h"

namespace distband {
namespace {

/// The value of one series ('name' or 'name{a="x",b="y"}': labels in alphabetical order, a bucket's `le` last) in an
/// exposition; NaN when absent.
double sample(const std::string& text, const std::string& series) {
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);)
    if (line.rfind(series + " ", 0) == 0) return std::stod(line.substr(series.size() + 1));
  return std::nan("");
}

TEST(MetricsTest, DisabledReportsNothing) {
  auto m = Metrics::disabled();
  EXPECT_FALSE(m->on());
  m->callEnded(Rpc::kQuery, grpc::StatusCode::OK, 1.0);
  m->queryRunning(1);
  m->tileFailed("ipv4:10.0.0.1:50051", true);
  m->watch({});
  EXPECT_EQ(m->text(), "");
  std::unique_ptr<MetricsEndpoint> endpoint;
  EXPECT_FALSE(MetricsEndpoint::start("127.0.0.1:0", *m, &endpoint).ok());
}

TEST(MetricsTest, CallsByRpcAndCodeWithTheirDurations) {
  auto m = Metrics::enabled();
  m->callEnded(Rpc::kQuery, grpc::StatusCode::OK, 0.2);
  m->callEnded(Rpc::kQuery, grpc::StatusCode::OK, 0.3);
  m->callEnded(Rpc::kQuery, grpc::StatusCode::RESOURCE_EXHAUSTED, 0.001);
  m->callEnded(Rpc::kUploadMesh, grpc::StatusCode::UNAUTHENTICATED, 0.0001);
  const std::string t = m->text();
  EXPECT_EQ(sample(t, R"(distband_calls_total{code="OK",rpc="Query"})"), 2);
  EXPECT_EQ(sample(t, R"(distband_calls_total{code="RESOURCE_EXHAUSTED",rpc="Query"})"), 1);
  EXPECT_EQ(sample(t, R"(distband_calls_total{code="UNAUTHENTICATED",rpc="UploadMesh"})"), 1);
  EXPECT_EQ(sample(t, R"(distband_calls_total{code="OK",rpc="GetInfo"})"), 0);  // every series from the start
  EXPECT_EQ(sample(t, R"(distband_call_duration_seconds_count{rpc="Query"})"), 3);
  EXPECT_NEAR(sample(t, R"(distband_call_duration_seconds_sum{rpc="Query"})"), 0.501, 1e-9);
  EXPECT_EQ(sample(t, R"(distband_call_duration_seconds_bucket{rpc="Query",le="0.25"})"), 2);
  EXPECT_EQ(sample(t, R"(distband_call_duration_seconds_bucket{rpc="Query",le="+Inf"})"), 3);
  EXPECT_EQ(sample(t, R"(distband_build_info{version=")" DISTBAND_VERSION R"("})"), 1);
}

TEST(MetricsTest, QueriesUploadsAndScrapeTimeGauges) {
  auto m = Metrics::enabled();
  double reserved = 0;
  Metrics::Sources s;
  s.budget_reserved_bytes = [&] { return reserved; };
  s.budget_bytes = [] { return 1000.0; };
  m->watch(std::move(s));
  m->queryQueued(1);
  m->queryQueued(1);
  m->queryQueued(-1);
  m->queryRunning(1);
  m->queryAdmitted(0.05);
  m->queryFirstBrick(0.1);
  m->queryComputed(0.01, 0.5);
  m->querySentBytes(1000);
  m->querySentBytes(24);
  m->querySentVoxels(512);
  m->uploadReceived(Rpc::kUploadVolume, 4096);
  m->uploadParsed(Rpc::kUploadVolume, 0.002);
  m->uploadRefused(Rpc::kUploadMesh, UploadRefusal::kBudget);
  m->uploadRefused(Rpc::kUploadMesh, UploadRefusal::kBadInput);
  m->uploadRefused(Rpc::kUploadVolume, UploadRefusal::kLimits);
  reserved = 640;
  const std::string t = m->text();
  EXPECT_EQ(sample(t, "distband_queries_queued"), 1);
  EXPECT_EQ(sample(t, "distband_queries_running"), 1);
  EXPECT_EQ(sample(t, "distband_query_queue_wait_seconds_count"), 1);
  EXPECT_EQ(sample(t, "distband_query_first_brick_seconds_count"), 1);
  EXPECT_EQ(sample(t, "distband_query_seed_seconds_count"), 1);
  EXPECT_NEAR(sample(t, "distband_query_compute_seconds_sum"), 0.5, 1e-12);
  EXPECT_EQ(sample(t, "distband_query_sent_bytes_total"), 1024);
  EXPECT_EQ(sample(t, "distband_query_sent_voxels_total"), 512);
  EXPECT_EQ(sample(t, R"(distband_upload_received_bytes_total{rpc="UploadVolume"})"), 4096);
  EXPECT_EQ(sample(t, R"(distband_upload_parse_seconds_count{rpc="UploadVolume"})"), 1);
  EXPECT_EQ(sample(t, R"(distband_upload_refusals_total{reason="budget",rpc="UploadMesh"})"), 1);
  EXPECT_EQ(sample(t, R"(distband_upload_refusals_total{reason="bad_input",rpc="UploadMesh"})"), 1);
  EXPECT_EQ(sample(t, R"(distband_upload_refusals_total{reason="limits",rpc="UploadVolume"})"), 1);
  EXPECT_EQ(sample(t, R"(distband_upload_refusals_total{reason="auth",rpc="UploadVolume"})"), 0);
  EXPECT_EQ(sample(t, "distband_memory_budget_reserved_bytes"), 640);  // read at the scrape
  EXPECT_EQ(sample(t, "distband_memory_budget_bytes"), 1000);
  EXPECT_TRUE(std::isnan(sample(t, "distband_asset_cache_bytes")));  // no source: not exported
  EXPECT_GT(sample(t, "process_resident_memory_bytes"), 1e6);
  EXPECT_GT(sample(t, "process_threads"), 0);
  EXPECT_GT(sample(t, "process_open_fds"), 2);
  EXPECT_GT(sample(t, "process_max_fds"), 0);
  EXPECT_GE(sample(t, "process_cpu_seconds_total"), 0);
  EXPECT_GT(sample(t, "process_start_time_seconds"), 1.6e9);
}

TEST(MetricsTest, NamesFollowPrometheusConventions) {
  auto m = Metrics::enabled();
  Metrics::Sources s;
  s.streams_open = s.budget_reserved_bytes = s.budget_bytes = s.cache_bytes = s.cache_capacity_bytes =
      s.cache_entries = s.compute_threads = s.replicas_known = s.replicas_healthy = [] { return 0.0; };
  m->watch(std::move(s));
  m->tileDispatched("ipv4:10.0.0.1:50051");
  std::istringstream in(m->text());
  std::set<std::string> names;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("# TYPE ", 0) != 0) continue;
    std::istringstream words(line.substr(7));
    std::string name, type;
    words >> name >> type;
    names.insert(name);
    EXPECT_TRUE(name.rfind("distband_", 0) == 0 || name.rfind("process_", 0) == 0) << name;
    EXPECT_EQ(type == "counter", name.size() > 6 && name.compare(name.size() - 6, 6, "_total") == 0) << name;
    for (const char* unit : {"_ms", "_milliseconds", "_microseconds", "_kb", "_mb", "_kib", "_mib"})
      EXPECT_EQ(name.find(unit), std::string::npos) << name;
  }
  EXPECT_GE(names.size(), 30u);
}

TEST(MetricsTest, TheScrapeDoesNotGrowWithTheCallsServed) {
  auto m = Metrics::enabled();
  m->callEnded(Rpc::kGetInfo, grpc::StatusCode::OK, 0.001);
  const size_t before = m->text().size();
  const grpc::StatusCode codes[] = {grpc::StatusCode::OK, grpc::StatusCode::CANCELLED,
                                    grpc::StatusCode::RESOURCE_EXHAUSTED, grpc::StatusCode::UNAUTHENTICATED};
  int64_t ok_get_info = 1;
  for (int i = 0; i < 1000000; ++i) {
    const Rpc rpc = Rpc(i % kRpcCount);
    const grpc::StatusCode code = codes[i / 4 % 4];
    m->callEnded(rpc, code, 1e-4 * (i % 1000));
    ok_get_info += rpc == Rpc::kGetInfo && code == grpc::StatusCode::OK;
  }
  const std::string after = m->text();
  // Only the digits of the counts grow (at most 7 digits each for 10^6).
  EXPECT_LT(after.size(), before + 2048);
  EXPECT_LT(after.size(), size_t(64) << 10);
  EXPECT_EQ(sample(after, R"(distband_calls_total{code="OK",rpc="GetInfo"})"), ok_get_info);
}

TEST(MetricsTest, ReplicaLabelsAreBoundedAndFollowThePool) {
  auto m = Metrics::enabled();
  for (size_t i = 0; i < kMaxReplicaLabels + 10; ++i) m->tileDispatched(fmt::format("ipv4:10.0.0.{}:50051", i));
  m->tileFailed("", true);  // never reached a replica
  std::string t = m->text();
  EXPECT_EQ(sample(t, R"(distband_coordinator_tiles_dispatched_total{replica="ipv4:10.0.0.0:50051"})"), 1);
  EXPECT_EQ(sample(t, R"(distband_coordinator_tiles_dispatched_total{replica="other"})"), 10);
  EXPECT_EQ(sample(t, R"(distband_coordinator_tiles_failed_total{replica="other"})"), 1);   // the cap was reached
  EXPECT_EQ(sample(t, R"(distband_coordinator_tiles_retried_total{replica="other"})"), 1);
  // The pool now resolves to two replicas: the others' series go, freeing room under the cap.
  m->replicasResolved({"ipv4:10.0.0.1:50051", "ipv4:10.0.0.2:50051"});
  m->tileFailed("", false);
  m->tileFailed("ipv4:10.0.0.1:50051", true);
  t = m->text();
  EXPECT_TRUE(std::isnan(sample(t, R"(distband_coordinator_tiles_dispatched_total{replica="ipv4:10.0.0.0:50051"})")));
  EXPECT_EQ(sample(t, R"(distband_coordinator_tiles_dispatched_total{replica="ipv4:10.0.0.1:50051"})"), 1);
  EXPECT_EQ(sample(t, R"(distband_coordinator_tiles_failed_total{replica="ipv4:10.0.0.1:50051"})"), 1);
  EXPECT_EQ(sample(t, R"(distband_coordinator_tiles_failed_total{replica="unknown"})"), 1);
  EXPECT_EQ(sample(t, R"(distband_coordinator_tiles_retried_total{replica="unknown"})"), 0);
  m->mergeBufferChanged(4096);
  m->mergeBufferChanged(-1024);
  EXPECT_EQ(sample(m->text(), "distband_coordinator_merge_buffer_bytes"), 3072);
}

TEST(MetricsTest, MetricsAddressesAreLiteralsWithAPort) {
  int port = -1;
  EXPECT_TRUE(validMetricsAddress("127.0.0.1:9100", &port));
  EXPECT_EQ(port, 9100);
  EXPECT_TRUE(validMetricsAddress("0.0.0.0:0"));
  EXPECT_TRUE(validMetricsAddress("[::1]:9100"));
  for (const char* bad : {"9100", ":9100", "localhost:9100", "127.0.0.1", "127.0.0.1:", "127.0.0.1:99999",
                          "127.0.0.1:9100s", "127.0.0.1:+9100", "::1:9100", "[::1]", "127.0.0.1:9100,0.0.0.0:9101"})
    EXPECT_FALSE(validMetricsAddress(bad)) << bad;
}

TEST(MetricsTest, TheEndpointServesOnlyMetricsOnItsAddress) {
  auto m = Metrics::enabled();
  m->callEnded(Rpc::kQuery, grpc::StatusCode::OK, 0.01);
  std::unique_ptr<MetricsEndpoint> endpoint;
  ASSERT_TRUE(MetricsEndpoint::start("127.0.0.1:0", *m, &endpoint).ok());
  ASSERT_GT(endpoint->port(), 0);
  const HttpResponse r = httpGet(endpoint->port(), "/metrics");
  EXPECT_EQ(r.status, 200);
  EXPECT_EQ(sample(r.body, R"(distband_calls_total{code="OK",rpc="Query"})"), 1);
  EXPECT_EQ(httpGet(endpoint->port(), "/").status, 404);
  EXPECT_EQ(httpGet(endpoint->port(), "/metrics/x").status, 404);
  EXPECT_EQ(httpGet(endpoint->port(), "/../etc/passwd").status / 100, 4);
  // The port is taken: a second endpoint there fails with a message naming the flag.
  std::unique_ptr<MetricsEndpoint> second;
  const Status s = MetricsEndpoint::start(fmt::format("127.0.0.1:{}", endpoint->port()), *m, &second);
  EXPECT_EQ(s.code(), Status::Code::kInvalidArgument);
  EXPECT_NE(s.message().find("--metrics-listen"), std::string::npos) << s.message();
  EXPECT_EQ(MetricsEndpoint::start("localhost:0", *m, &second).code(), Status::Code::kInvalidArgument);
  // IPv6 where civetweb has it; else a message saying so (Debian bookworm's civetweb is built without IPv6).
  const Status v6 = MetricsEndpoint::start("[::1]:0", *m, &second);
  if (!v6.ok()) {
    EXPECT_NE(v6.message().find("IPv6"), std::string::npos) << v6.message();
  }
  const int port = endpoint->port();
  endpoint.reset();
  EXPECT_EQ(httpGet(port, "/metrics").status, -1);  // closed with the endpoint
}

}  // namespace
}  // namespace distband
