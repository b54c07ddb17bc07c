// Request ids and logs through real server processes (a coordinator and two replicas): the client's x-request-id
// comes back in the initial metadata and is in the coordinator's and every replica's log lines of that call; an
// invalid one is replaced; JSON logs are one object a line (checked with python3 -m json.tool too). The metrics
// endpoint answers without the token, and never on the gRPC port.
#include <signal.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "server/request_id.h"
#include "tests/integration/service_fixture.h"
#include "tests/support/child_server.h"
#include "tests/support/http_get.h"
#include "tests/support/run_command.h"

namespace distband {
namespace {

std::string tetrahedronObj(double s) {
  return fmt::format("v 0 0 0\nv {0} 0 0\nv 0 {0} 0\nv 0 0 {0}\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n", s);
}

std::string initialMetadata(const grpc::ClientContext& context, const std::string& key) {
  const auto& md = context.GetServerInitialMetadata();
  const auto it = md.find(key);
  return it == md.end() ? std::string() : std::string(it->second.data(), it->second.size());
}

/// Waits until `child`'s log contains `needle` (the log is read from a pipe on a thread of its own).
bool logShows(ChildServer& child, const std::string& needle,
              std::chrono::milliseconds timeout = std::chrono::milliseconds(3000)) {
  const auto end = Clock::now() + timeout;
  while (Clock::now() < end) {
    if (child.log().find(needle) != std::string::npos) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return child.log().find(needle) != std::string::npos;
}

/// Whether some object of a JSON line names a key twice (a parser keeps one of them: a field would be lost).
bool duplicateKeys(const std::string& line) {
  std::vector<std::set<std::string>> objects;
  bool duplicate = false;
  using Event = nlohmann::json::parse_event_t;
  const auto on_event = [&](int, Event event, nlohmann::json& parsed) {
    if (event == Event::object_start) objects.emplace_back();
    else if (event == Event::object_end && !objects.empty()) objects.pop_back();
    else if (event == Event::key && !objects.empty() && !objects.back().insert(parsed.get<std::string>()).second)
      duplicate = true;
    return true;
  };
  const auto parsed_line = nlohmann::json::parse(line, on_event, false);
  return duplicate && !parsed_line.is_discarded();
}

std::vector<std::string> lines(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);)
    if (!l.empty()) out.push_back(l);
  return out;
}

TEST(ObservabilityTest, ARequestIdReachesTheLogsOfTheCoordinatorAndEveryReplica) {
  std::vector<std::unique_ptr<ChildServer>> replicas;
  std::string peers = "ipv4:";
  for (int i = 0; i < 2; ++i) {
    replicas.push_back(std::make_unique<ChildServer>(
        DISTBAND_SERVER_BINARY, std::vector<std::string>{"--threads", "1", "--memory-budget", "1G"}));
    ASSERT_GT(replicas.back()->port(), 0) << replicas.back()->log();
    peers += (i ? "," : "") + replicas.back()->target();
  }
  ChildServer coordinator(DISTBAND_SERVER_BINARY,
                          {"--peers", peers, "--tile-voxels", "32768", "--threads", "1", "--memory-budget", "1G",
                           "--log-format", "json"});
  ASSERT_GT(coordinator.port(), 0) << coordinator.log();
  auto stub = v1::DistanceField::NewStub(grpc::CreateChannel(coordinator.target(), grpc::InsecureChannelCredentials()));

  // A mesh query: the coordinator uploads the mesh to each replica, then sends 8 tiles (64^3 in 32^3 tiles).
  v1::UploadReply uploaded;
  {
    grpc::ClientContext context;
    context.AddMetadata(kRequestIdHeader, "upload-7f3a");
    auto writer = stub->UploadMesh(&context, &uploaded);
    v1::UploadMeshChunk chunk;
    chunk.mutable_header()->set_format(v1::MESH_FORMAT_OBJ);
    chunk.mutable_header()->set_name("tet.obj");
    chunk.set_data(tetrahedronObj(1.0));
    ASSERT_TRUE(writer->Write(chunk));
    writer->WritesDone();
    const grpc::Status s = writer->Finish();
    ASSERT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(initialMetadata(context, kRequestIdHeader), "upload-7f3a");
  }
  const std::string id = "client-req.0042:a_b-c";
  v1::QueryRequest request;
  request.set_asset_id(uploaded.asset_id());
  request.mutable_grid()->set_voxel_size(1.0 / 48);
  request.mutable_grid()->mutable_dims()->set_x(64);
  request.mutable_grid()->mutable_dims()->set_y(64);
  request.mutable_grid()->mutable_dims()->set_z(64);
  request.set_limit(0.2);
  grpc::ClientContext context;
  context.AddMetadata(kRequestIdHeader, id);
  auto reader = stub->Query(&context, request);
  v1::QueryReply reply;
  int messages = 0;
  while (reader->Read(&reply)) ++messages;
  const grpc::Status s = reader->Finish();
  ASSERT_TRUE(s.ok()) << s.error_message() << "\n" << coordinator.log();
  EXPECT_GT(messages, 2);
  EXPECT_EQ(initialMetadata(context, kRequestIdHeader), id);

  // The coordinator (JSON): its Query line carries the id.
  ASSERT_TRUE(logShows(coordinator, "\"request_id\":\"" + id + "\"")) << coordinator.log();
  int query_lines = 0;
  for (const std::string& line : lines(coordinator.log())) {
    const auto j = nlohmann::json::parse(line, nullptr, false);
    ASSERT_FALSE(j.is_discarded()) << "not one JSON object: " << line;
    ASSERT_TRUE(j.is_object()) << line;
    EXPECT_FALSE(duplicateKeys(line)) << line;
    EXPECT_TRUE(j.contains("ts") && j.contains("level")) << line;
    if (j.value("event", "") == "Query") {
      ++query_lines;
      EXPECT_EQ(j["request_id"], id);
      EXPECT_EQ(j["status"], "OK");
      EXPECT_EQ(j["tiles"], 8);
      EXPECT_EQ(j["replicas"], 2);
    }
  }
  EXPECT_EQ(query_lines, 1);
  // Every replica: the mesh's upload and at least one tile, each line with the query's id.
  for (auto& r : replicas) {
    EXPECT_TRUE(logShows(*r, "UploadMesh request_id=" + id)) << r->log();
    EXPECT_TRUE(logShows(*r, "request_id=" + id + " peer=")) << r->log();
    const std::regex tile_line("\\] Query q[0-9]+ request_id=" + id +
                               " peer=[^ ]+ seeds=mesh-[0-9a-f]+\\S* tile_window=");
    EXPECT_TRUE(std::regex_search(r->log(), tile_line)) << r->log();
  }
}

TEST(ObservabilityTest, InvalidOrMissingRequestIdsAreReplacedAndJsonLogsPassJsonTool) {
  ChildServer server(DISTBAND_SERVER_BINARY, {"--threads", "1", "--memory-budget", "1G", "--log-format", "json"});
  ASSERT_GT(server.port(), 0) << server.log();
  auto stub = v1::DistanceField::NewStub(grpc::CreateChannel(server.target(), grpc::InsecureChannelCredentials()));
  const std::regex generated("[0-9a-f]{32}");
  for (const std::string& bad : {std::string("has spaces"), std::string("quote\"inside"), std::string(200, 'x'),
                                std::string("")}) {
    grpc::ClientContext context;
    if (!bad.empty()) context.AddMetadata(kRequestIdHeader, bad);
    v1::ServerInfo info;
    ASSERT_TRUE(stub->GetInfo(&context, {}, &info).ok());
    const std::string echoed = initialMetadata(context, kRequestIdHeader);
    EXPECT_TRUE(std::regex_match(echoed, generated)) << "'" << echoed << "' for '" << bad << "'";
  }
  // Refused calls echo it too (here: an invalid query, refused before any work).
  {
    grpc::ClientContext context;
    context.AddMetadata(kRequestIdHeader, "refused-1");
    v1::QueryRequest empty;
    auto reader = stub->Query(&context, empty);
    v1::QueryReply reply;
    while (reader->Read(&reply)) {
    }
    EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_EQ(initialMetadata(context, kRequestIdHeader), "refused-1");
  }
  // And a query computed here (its line has the most fields).
  {
    grpc::ClientContext context;
    auto reader = stub->Query(&context, pointsRequest({{4, 5, 6}}, {32, 32, 32}, 0.5, 2.0, 0));
    v1::QueryReply reply;
    while (reader->Read(&reply)) {
    }
    EXPECT_TRUE(reader->Finish().ok());
  }
  ASSERT_TRUE(logShows(server, "\"request_id\":\"refused-1\"")) << server.log();
  server.signal(SIGTERM);
  EXPECT_EQ(server.waitExit(std::chrono::seconds(10)), 0);
  const std::string log = server.log();
  int replaced = 0;
  for (const std::string& line : lines(log)) {
    const auto j = nlohmann::json::parse(line, nullptr, false);
    ASSERT_TRUE(j.is_object()) << line;
    EXPECT_FALSE(duplicateKeys(line)) << line;
    if (j.value("event", "") == "GetInfo" && j.value("request_id_replaced", false)) ++replaced;
    if (j.value("event", "") == "Query" && j.value("status", "") == "OK") {
      EXPECT_EQ(j["voxels"], 32 * 32 * 32);
      EXPECT_TRUE(j["limit"].is_null());  // no limit: infinite, which JSON cannot write
      EXPECT_TRUE(j["seed_time"].is_number());
    }
  }
  EXPECT_EQ(replaced, 3);  // the three invalid ones; a missing id is generated without a note
  EXPECT_EQ(log.find("has spaces"), std::string::npos) << "a refused id must not reach the log";
  // The acceptance check, as an operator runs it: every line through python3 -m json.tool.
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("distband_json_log_" + std::to_string(::getpid()) + ".log"))
                               .string();
  std::ofstream(path) << log;
  const auto [out, rc] = runCommand(
      "set -e; n=0; while IFS= read -r line; do printf '%s' \"$line\" | python3 -m json.tool >/dev/null; "
      "n=$((n+1)); done < '" + path + "'; echo $n 2>&1");
  std::filesystem::remove(path);
  EXPECT_EQ(rc, 0) << out;
  EXPECT_EQ(std::stoul(out.empty() ? "0" : out), lines(log).size());
}

TEST(ObservabilityTest, TheMetricsEndpointNeedsNoTokenAndIsNotOnTheGrpcPort) {
  const std::string tokens = (std::filesystem::temp_directory_path() /
                              ("distband_metrics_tokens_" + std::to_string(::getpid())))
                                 .string();
  std::ofstream(tokens) << "metrics-test-token-0123456789\n";
  ServerOptions o = TestServer::defaults();
  o.auth_token_file = tokens;
  o.metrics_listen = "127.0.0.1:0";
  TestServer ts(o);
  std::filesystem::remove(tokens);
  const int metrics_port = ts.server().metricsPort();
  ASSERT_GT(metrics_port, 0);
  ASSERT_NE(metrics_port, ts.server().port());

  // No token: the upload is refused (reason auth), and the scrape needs none.
  v1::UploadReply up;
  EXPECT_EQ(ts.client().uploadMesh(tetrahedronObj(1), v1::MESH_FORMAT_OBJ, "t.obj", &up).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  const HttpResponse scrape = httpGet(metrics_port, "/metrics");
  ASSERT_EQ(scrape.status, 200);
  EXPECT_NE(scrape.body.find("distband_upload_refusals_total{reason=\"auth\",rpc=\"UploadMesh\"} 1\n"),
            std::string::npos)
      << scrape.body;
  EXPECT_NE(scrape.body.find("distband_calls_total{code=\"UNAUTHENTICATED\",rpc=\"UploadMesh\"} 1\n"),
            std::string::npos);
  // The gRPC port speaks HTTP/2 only: no metrics there.
  EXPECT_NE(httpGet(ts.server().port(), "/metrics", std::chrono::milliseconds(2000)).status, 200);

  // The two listeners never share a port; without the flag there is no endpoint.
  ServerOptions same = TestServer::defaults();
  same.listen_address = "127.0.0.1:50999";
  same.metrics_listen = "127.0.0.1:50999";
  EXPECT_NE(same.validate().find("--metrics-listen"), std::string::npos);
  same.metrics_listen = "localhost:9100";
  EXPECT_NE(same.validate().find("--metrics-listen"), std::string::npos);
  TestServer plain;
  EXPECT_EQ(plain.server().metricsPort(), 0);
}

}  // namespace
}  // namespace distband
