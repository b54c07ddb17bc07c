// Tests of the distband-server binary as its own process on a loopback port: figures only the server's own
// process shows (threads from /proc/PID/status) and its signal handling (SIGTERM drains, a second signal exits).
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "client/remote_client.h"
#include "tests/integration/service_fixture.h"
#include "server/request_validation.h"
#include "tests/support/build_flavor.h"
#include "tests/support/child_server.h"

namespace distband {
namespace {

/// The server binary this build made, as a child process.
class ServerProcess : public ChildServer {
 public:
  explicit ServerProcess(const std::vector<std::string>& args) : ChildServer(DISTBAND_SERVER_BINARY, args) {}
};

/// A mesh upload that sends one chunk and then waits (until cancelled or the server ends it).
struct HeldUpload {
  grpc::ClientContext ctx;
  v1::UploadReply reply;
  std::unique_ptr<grpc::ClientWriter<v1::UploadMeshChunk>> writer;
  grpc::Status status;
  std::atomic<int> code{-1};  ///< status.error_code() once the call ended; read by other threads while it runs
  void run(v1::DistanceField::Stub& stub) {
    writer = stub.UploadMesh(&ctx, &reply);
    v1::UploadMeshChunk chunk;
    chunk.mutable_header()->set_format(v1::MESH_FORMAT_OBJ);
    chunk.set_data("v 0 0 0\n");
    writer->Write(chunk);
    status = writer->Finish();  // returns when the server ends the call (or our context is cancelled)
    code = int(status.error_code());
  }
};

TEST(ServerProcessTest, FiveHundredConcurrentCallsKeepTheThreadCount) {
  ServerProcess server({"--threads", "2", "--max-queries", "2", "--max-streams", "64", "--idle-timeout", "30"});
  ASSERT_GT(server.port(), 0) << server.log();
  const int idle_threads = server.threads();
  std::vector<std::shared_ptr<grpc::Channel>> channels;
  std::vector<std::unique_ptr<v1::DistanceField::Stub>> stubs;
  for (int c = 0; c < 8; ++c) {
    grpc::ChannelArguments args;
    args.SetInt("grpc.channel_id", c);  // distinct connections
    channels.push_back(grpc::CreateCustomChannel(server.target(), grpc::InsecureChannelCredentials(), args));
    stubs.push_back(v1::DistanceField::NewStub(channels.back()));
    // Connected before the flood: a channel connects lazily on its first call, and a connection still being made
    // while hundreds of calls start would fail that channel's calls with UNAVAILABLE instead of reaching the server.
    ASSERT_TRUE(channels.back()->WaitForConnected(std::chrono::system_clock::now() + std::chrono::seconds(10))) << "channel " << c;
  }
  constexpr int kCalls = 500;
  constexpr int kAdmitted = 64;  // --max-streams
  std::vector<HeldUpload> calls(kCalls);
  std::vector<std::thread> clients;
  std::atomic<int> peak{0};
  std::atomic<bool> sampling{true};
  std::thread sampler([&] {
    while (sampling) {
      peak = std::max(peak.load(), server.threads());
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  });
  for (int i = 0; i < kCalls; ++i) clients.emplace_back([&, i] { calls[size_t(i)].run(*stubs[size_t(i) % stubs.size()]); });
  // Let every call reach the server; the ones beyond --max-streams are refused at once.
  const auto deadline = Clock::now() + std::chrono::seconds(20);
  auto ended = [&](int code) {
    int n = 0;
    for (auto& c : calls) n += code < 0 ? c.code.load() >= 0 : c.code.load() == code;
    return n;
  };
  const int refused_code = int(grpc::StatusCode::RESOURCE_EXHAUSTED);
  while (Clock::now() < deadline && ended(-1) < kCalls - kAdmitted) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const int refused = ended(refused_code);
  std::map<int, int> codes;  // how every call that ended before the cancel ended, for the failure message
  std::string first_other;
  for (auto& c : calls) {
    const int code = c.code.load();
    if (code < 0) continue;
    ++codes[code];
    if (code != refused_code && first_other.empty()) first_other = c.status.error_message();
  }
  std::string histogram;
  for (auto [code, n] : codes) histogram += " code " + std::to_string(code) + ": " + std::to_string(n) + ";";
  for (auto& c : calls) c.ctx.TryCancel();
  for (auto& t : clients) t.join();
  sampling = false;
  sampler.join();
  const int cap = kAdmitted + 16;  // --grpc-threads default: --max-streams + 16
  std::printf("server threads: idle %d, peak %d with %d concurrent calls (gRPC cap %d); %d refused at once\n",
              idle_threads, peak.load(), kCalls, cap, refused);
  EXPECT_EQ(refused, kCalls - kAdmitted) << "ended before the cancel:" << histogram << " first other: '" << first_other
                                         << "'\n" << server.log();
  EXPECT_LE(peak.load(), cap + 16) << "threads must stay near the gRPC cap (compute arena, watchdog, main are extra)";
}

TEST(ServerProcessTest, SigtermDrainsAndExitsZero) {
  ServerProcess server({"--threads", "2", "--grace-seconds", "20"});
  ASSERT_GT(server.port(), 0) << server.log();
  RemoteClient client(server.target());
  std::atomic<bool> finished{false};
  Streamed result;
  // A query that takes a while (a 192^3 field without a limit), started before the signal.
  std::thread q([&] {
    result = stream(client, pointsRequest({{10, 10, 10}}, {192, 192, 192}, 1.0, 0, 0), 0);
    finished = true;
  });
  const auto deadline = Clock::now() + std::chrono::seconds(10);
  while (server.log().find("Query") == std::string::npos && result.batch_segments.empty() && Clock::now() < deadline &&
         !finished)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  server.signal(SIGTERM);
  const int code = server.waitExit(std::chrono::seconds(25));
  q.join();
  EXPECT_EQ(code, 0) << server.log();
  EXPECT_TRUE(result.result.status.ok()) << "the running query must finish during the grace period: "
                                         << result.result.status.error_message();
}

TEST(ServerProcessTest, ASecondSignalExitsWithinOneSecond) {
  ServerProcess server({"--threads", "2", "--grace-seconds", "60"});
  ASSERT_GT(server.port(), 0) << server.log();
  HeldUpload held;  // keeps the drain waiting
  auto stub = v1::DistanceField::NewStub(grpc::CreateChannel(server.target(), grpc::InsecureChannelCredentials()));
  std::thread t([&] { held.run(*stub); });
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  server.signal(SIGTERM);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(server.waitExit(std::chrono::milliseconds(1)), -1) << "the first signal drains (60 s grace)";
  const auto t0 = Clock::now();
  server.signal(SIGTERM);
  const int code = server.waitExit(std::chrono::seconds(5));
  const double took = ms(Clock::now() - t0);
  held.ctx.TryCancel();
  t.join();
  EXPECT_EQ(code, 1) << server.log();
  EXPECT_LT(took, 1000);
}

TEST(ServerProcessTest, GraceExpiryCancelsStalledCallsAndExitsZero) {
  ServerProcess server({"--threads", "2", "--grace-seconds", "0.5"});
  ASSERT_GT(server.port(), 0) << server.log();
  HeldUpload held;
  auto stub = v1::DistanceField::NewStub(grpc::CreateChannel(server.target(), grpc::InsecureChannelCredentials()));
  std::thread t([&] { held.run(*stub); });
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const auto t0 = Clock::now();
  server.signal(SIGTERM);
  const int code = server.waitExit(std::chrono::seconds(5));
  const double took = ms(Clock::now() - t0);
  t.join();
  EXPECT_EQ(code, 0) << server.log();
  EXPECT_GE(took, 450);
  EXPECT_LT(took, 1500);
  // A call blocked on its client can only be ended by cancelling it.
  EXPECT_EQ(held.status.error_code(), grpc::StatusCode::CANCELLED) << held.status.error_message();
}

}  // namespace
}  // namespace distband

namespace distband {
namespace {

TEST(ServerProcessTest, ConcurrentMaximalQueriesStayWithinTheMemoryBudget) {
  ServerProcess server({"--threads", "2", "--max-queries", "4", "--memory-budget", "512M", "--queue-wait-ms", "500"});
  ASSERT_GT(server.port(), 0) << server.log();
  RemoteClient client(server.target());
  v1::ServerInfo info;
  ASSERT_TRUE(client.info(&info).ok());
  // The largest cube the budget admits on its own, then 24 clients asking for it at once.
  int n = 64;
  while (n < 512) {
    ServerOptions o;
    AssetCache cache(1 << 20);
    ResolvedQuery q;
    ASSERT_TRUE(resolveQuery(pointsRequest({{1, 2, 3}}, {n + 16, n + 16, n + 16}, 1.0, 0, 0), o, cache, nullptr, &q).ok());
    if (q.memory.total() + o.stream_buffer_bytes > info.memory_budget_bytes()) break;
    n += 16;
  }
  std::atomic<int64_t> peak_kb{0};
  std::atomic<bool> sampling{true};
  std::thread sampler([&] {
    while (sampling) {
      peak_kb = std::max<int64_t>(peak_kb, server.status("VmRSS:"));
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  });
  std::vector<std::thread> clients;
  std::atomic<int> ok{0}, exhausted{0};
  for (int c = 0; c < 24; ++c)
    clients.emplace_back([&, c] {
      RemoteClient own(server.target());
      Streamed s = stream(own, pointsRequest({{double(c), 5, 7}}, {n, n, n}, 1.0, 0, 0), 0);
      if (s.result.status.ok()) ++ok;
      if (s.result.status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED) ++exhausted;
    });
  for (auto& t : clients) t.join();
  sampling = false;
  sampler.join();
  const double budget = 512.0 * 1024 * 1024;
  std::printf("%d^3 queries: %d ok, %d refused; server peak RSS %.0f MiB = %.2f x the 512 MiB budget\n", n, ok.load(),
              exhausted.load(), peak_kb / 1024.0, peak_kb * 1024.0 / budget);
  EXPECT_GE(ok.load(), 1);
  EXPECT_EQ(ok.load() + exhausted.load(), 24);
  EXPECT_LE(peak_kb * 1024.0, testing::residentBoundBytes(1.1 * budget));
}

}  // namespace
}  // namespace distband
