// Hostile-client tests of the service on an in-process server (127.0.0.1, port 0): authentication, TLS,
// reflection, listeners, stream limits, idle timeouts, byte budgets, early validation, files named by meshes.
// Figures that need the server's own process (RSS, threads, signals) are in server_process_test.cc.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <thread>

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/impl/client_unary_call.h>
#include <grpcpp/support/byte_buffer.h>
#include <gtest/gtest.h>

#include "server/server_options.h"
#include "server/token_auth.h"
#include "tests/integration/service_fixture.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

namespace fs = std::filesystem;

class TempDir {
 public:
  TempDir() {
    path_ = fs::temp_directory_path() / ("distband_hardening_" + std::to_string(::getpid()) + "_" +
                                         std::to_string(counter_++));
    fs::create_directories(path_);
  }
  ~TempDir() { fs::remove_all(path_); }
  std::string path(const std::string& name) const { return (path_ / name).string(); }
  std::string write(const std::string& name, const std::string& text) const {
    std::ofstream(path(name), std::ios::binary) << text;
    return path(name);
  }

 private:
  static inline int counter_ = 0;
  fs::path path_;
};

std::string readAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// ---- Authentication ------------------------------------------------------------------------------------------

constexpr char kToken[] = "s3cret-token-0123456789";

TEST(HardeningTest, TokensAreRequiredExceptForHealth) {
  TempDir dir;
  ServerOptions o = TestServer::defaults();
  o.auth_token_file = dir.write("tokens", std::string("# operators\n\n  other-token-abcdefghijkl \n") + kToken + "\n");
  TestServer ts(o);
  v1::ServerInfo info;
  grpc::Status s = ts.client().info(&info);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED) << s.error_message();
  EXPECT_NE(s.error_message().find("Bearer"), std::string::npos) << s.error_message();
  bool serving = false;
  EXPECT_TRUE(ts.client().health("", &serving, nullptr).ok());
  EXPECT_TRUE(serving);

  RemoteClientOptions wrong;
  wrong.bearer_token = "not-the-token-0123456789";
  EXPECT_EQ(RemoteClient(ts.target(), wrong).info(&info).error_code(), grpc::StatusCode::UNAUTHENTICATED);
  for (const char* token : {kToken, "other-token-abcdefghijkl"}) {
    RemoteClientOptions right;
    right.bearer_token = token;
    RemoteClient client(ts.target(), right);
    ASSERT_TRUE(client.info(&info).ok()) << token;
    EXPECT_TRUE(info.auth_required());
    // Queries and uploads are checked the same way.
    Streamed q = stream(client, pointsRequest({{4, 4, 4}}, {16, 16, 16}, 1.0, 0, 0), 0);
    EXPECT_TRUE(q.result.status.ok()) << q.result.status.error_message();
  }
  Streamed denied = stream(ts.client(), pointsRequest({{4, 4, 4}}, {16, 16, 16}, 1.0, 0, 0), 0);
  EXPECT_EQ(denied.result.status.error_code(), grpc::StatusCode::UNAUTHENTICATED);
  v1::UploadReply up;
  EXPECT_EQ(ts.client().uploadMesh("v 0 0 0\n", v1::MESH_FORMAT_OBJ, "x.obj", &up).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
}

TEST(HardeningTest, TokenFilesAreCheckedAtStartup) {
  TempDir dir;
  std::unique_ptr<TokenAuth> auth;
  Status s = TokenAuth::load(dir.write("short", "abc\n"), &auth);
  EXPECT_EQ(s.code(), Status::Code::kInvalidArgument);
  EXPECT_NE(s.message().find("line 1"), std::string::npos) << s.message();
  EXPECT_EQ(s.message().find("abc"), std::string::npos) << "a token must never be echoed: " << s.message();
  EXPECT_TRUE(IsError(TokenAuth::load(dir.write("empty", "# nothing\n\n"), &auth), Status::Code::kInvalidArgument,
                      "holds no token"));
  EXPECT_TRUE(IsError(TokenAuth::load(dir.path("missing"), &auth), Status::Code::kInvalidArgument, "cannot read"));
  ASSERT_TRUE(TokenAuth::load(dir.write("ok", std::string(kToken) + "\n"), &auth).ok());
  EXPECT_TRUE(auth->acceptsHeader(std::string("Bearer ") + kToken));
  EXPECT_TRUE(auth->acceptsHeader(std::string("bearer ") + kToken));
  EXPECT_FALSE(auth->acceptsHeader(kToken));
  EXPECT_FALSE(auth->acceptsHeader(std::string("Bearer ") + kToken + "x"));
  EXPECT_FALSE(auth->acceptsHeader("Bearer "));
}

// ---- TLS -------------------------------------------------------------------------------------------------------

/// A self-signed certificate for localhost / 127.0.0.1 (also usable as its own CA), made with the openssl CLI.
bool makeCertificate(const TempDir& dir, const std::string& name) {
  const std::string cmd = "openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 2 "
                          "-subj /CN=localhost -addext subjectAltName=DNS:localhost,IP:127.0.0.1 "
                          "-addext basicConstraints=critical,CA:TRUE -keyout " +
                          dir.path(name + ".key") + " -out " + dir.path(name + ".pem") + " >/dev/null 2>&1";
  return std::system(cmd.c_str()) == 0;
}

TEST(HardeningTest, TlsServesOnlyTlsClients) {
  TempDir dir;
  ASSERT_TRUE(makeCertificate(dir, "server")) << "openssl is needed (scripts/install-deps installs it)";
  ServerOptions o = TestServer::defaults();
  o.tls_cert_file = dir.path("server.pem");
  o.tls_key_file = dir.path("server.key");
  RemoteClientOptions tls;
  tls.tls = true;
  tls.tls_root_ca_pem = readAll(dir.path("server.pem"));
  TestServer ts(o, tls);
  v1::ServerInfo info;
  ASSERT_TRUE(ts.client().info(&info).ok());
  Streamed q = stream(ts.client(), pointsRequest({{4, 4, 4}}, {16, 16, 16}, 1.0, 0, 0), 0);
  EXPECT_TRUE(q.result.status.ok()) << q.result.status.error_message();
  // A plaintext client cannot talk to it.
  EXPECT_EQ(RemoteClient(ts.target()).info(&info, std::chrono::seconds(2)).error_code(), grpc::StatusCode::UNAVAILABLE);
  // Nor a TLS client that does not trust its certificate.
  RemoteClientOptions untrusting;
  untrusting.tls = true;
  untrusting.tls_root_ca_pem = "-----BEGIN CERTIFICATE-----\nMA==\n-----END CERTIFICATE-----\n";
  EXPECT_EQ(RemoteClient(ts.target(), untrusting).info(&info, std::chrono::seconds(2)).error_code(),
            grpc::StatusCode::UNAVAILABLE);
  // The container's health probe speaks TLS when told to, and fails without it.
  const std::string probe = std::string(DISTBAND_HEALTH_BINARY) + " --timeout 2 --server " + ts.target();
  EXPECT_EQ(std::system((probe + " --tls-ca " + dir.path("server.pem") + " >/dev/null 2>&1").c_str()), 0);
  EXPECT_NE(std::system((probe + " >/dev/null 2>&1").c_str()), 0);
}

TEST(HardeningTest, MutualTlsRequiresAClientCertificate) {
  TempDir dir;
  ASSERT_TRUE(makeCertificate(dir, "server") && makeCertificate(dir, "client"));
  ServerOptions o = TestServer::defaults();
  o.tls_cert_file = dir.path("server.pem");
  o.tls_key_file = dir.path("server.key");
  o.tls_client_ca_file = dir.path("client.pem");
  RemoteClientOptions anonymous;
  anonymous.tls = true;
  anonymous.tls_root_ca_pem = readAll(dir.path("server.pem"));
  TestServer ts(o, anonymous);
  v1::ServerInfo info;
  EXPECT_EQ(ts.client().info(&info, std::chrono::seconds(2)).error_code(), grpc::StatusCode::UNAVAILABLE);
  RemoteClientOptions with_cert = anonymous;
  with_cert.tls_client_cert_pem = readAll(dir.path("client.pem"));
  with_cert.tls_client_key_pem = readAll(dir.path("client.key"));
  EXPECT_TRUE(RemoteClient(ts.target(), with_cert).info(&info).ok());
}

TEST(HardeningTest, BadTlsFilesStopTheStartWithTheFlagNamed) {
  TempDir dir;
  ServerOptions o = TestServer::defaults();
  o.listen_address = "127.0.0.1:0";
  o.tls_cert_file = dir.write("cert.pem", "not a certificate");
  o.tls_key_file = dir.write("key.pem", "not a key");
  DistbandServer server(o);
  const grpc::Status s = server.start();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
  EXPECT_NE(s.error_message().find("--tls-"), std::string::npos) << s.error_message();
}

// ---- Reflection and listeners ------------------------------------------------------------------------------------

grpc::StatusCode callReflection(const std::string& target) {
  auto channel = grpc::CreateChannel(target, grpc::InsecureChannelCredentials());
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  grpc::Slice empty("");  // an empty ServerReflectionRequest
  grpc::ByteBuffer request(&empty, 1), response;
  const grpc::internal::RpcMethod method("/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo",
                                         grpc::internal::RpcMethod::NORMAL_RPC);
  return grpc::internal::BlockingUnaryCall<grpc::ByteBuffer, grpc::ByteBuffer>(channel.get(), method, &ctx, request,
                                                                               &response)
      .error_code();
}

TEST(HardeningTest, ReflectionIsOffUnlessAsked) {
  {
    TestServer ts;
    EXPECT_EQ(callReflection(ts.target()), grpc::StatusCode::UNIMPLEMENTED);
  }
  ServerOptions o = TestServer::defaults();
  o.reflection = true;
  TestServer ts(o);
  EXPECT_NE(callReflection(ts.target()), grpc::StatusCode::UNIMPLEMENTED);
}

/// Listening TCP sockets of this process on `port` (from /proc/net/tcp{,6} and /proc/self/fd).
int listenersOnPort(int port) {
  std::set<std::string> own_inodes;
  for (const auto& fd : fs::directory_iterator("/proc/self/fd")) {
    std::error_code ec;
    const std::string link = fs::read_symlink(fd.path(), ec).string();
    if (!ec && link.rfind("socket:[", 0) == 0) own_inodes.insert(link.substr(8, link.size() - 9));
  }
  int n = 0;
  for (const char* table : {"/proc/net/tcp", "/proc/net/tcp6"}) {
    std::ifstream in(table);
    std::string line;
    std::getline(in, line);  // header
    while (std::getline(in, line)) {
      std::istringstream f(line);
      std::string sl, local, remote, state, queues, timer, retr, uid, timeout, inode;
      f >> sl >> local >> remote >> state >> queues >> timer >> retr >> uid >> timeout >> inode;
      const int p = std::stoi(local.substr(local.find(':') + 1), nullptr, 16);
      if (state == "0A" && p == port && own_inodes.count(inode)) ++n;
    }
  }
  return n;
}

TEST(HardeningTest, ListenOpensExactlyOneListenerAndDefaultsToLoopback) {
  EXPECT_EQ(ServerOptions().listen_address, "127.0.0.1:50051");
  TestServer ts;
  EXPECT_EQ(listenersOnPort(ts.server().port()), 1);
}

// ---- Stream limits and idle clients --------------------------------------------------------------------------

/// An upload that sends its first chunk and then nothing: the server's handler waits on it.
class StalledUpload {
 public:
  StalledUpload(const std::string& target, uint64_t total_bytes = 0) {
    channel_ = grpc::CreateChannel(target, grpc::InsecureChannelCredentials());
    stub_ = v1::DistanceField::NewStub(channel_);
    writer_ = stub_->UploadMesh(&ctx_, &reply_);
    v1::UploadMeshChunk chunk;
    chunk.mutable_header()->set_format(v1::MESH_FORMAT_OBJ);
    chunk.mutable_header()->set_total_bytes(total_bytes);
    chunk.set_data(std::string(1000, ' '));
    wrote_ = writer_->Write(chunk);
  }
  grpc::Status finish() {
    writer_->WritesDone();
    finished_ = true;
    return writer_->Finish();
  }
  /// The status the server ended the call with, without closing our side first.
  grpc::Status awaitServer() {
    finished_ = true;
    return writer_->Finish();
  }
  ~StalledUpload() {
    ctx_.TryCancel();
    if (!finished_) writer_->Finish();
  }
  bool wrote() const { return wrote_; }

 private:
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::DistanceField::Stub> stub_;
  grpc::ClientContext ctx_;
  v1::UploadReply reply_;
  std::unique_ptr<grpc::ClientWriter<v1::UploadMeshChunk>> writer_;
  bool wrote_ = false, finished_ = false;
};

TEST(HardeningTest, CallsBeyondMaxStreamsAreRefusedAtOnce) {
  ServerOptions o = TestServer::defaults();
  o.max_streams = 3;
  TestServer ts(o);
  std::vector<std::unique_ptr<StalledUpload>> held;
  for (int i = 0; i < 3; ++i) held.push_back(std::make_unique<StalledUpload>(ts.target()));
  const auto deadline = Clock::now() + std::chrono::seconds(5);
  while (ts.server().service().activeCalls() < 3 && Clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_EQ(ts.server().service().activeCalls(), 3);
  const auto t0 = Clock::now();
  v1::ServerInfo info;
  const grpc::Status s = ts.client().info(&info);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_NE(s.error_message().find("--max-streams"), std::string::npos) << s.error_message();
  EXPECT_LT(ms(Clock::now() - t0), 1000);
  bool serving = false;
  EXPECT_TRUE(ts.client().health("", &serving, nullptr).ok()) << "probes must pass while the streams are full";
  held.clear();
  while (ts.server().service().activeCalls() > 0 && Clock::now() < deadline + std::chrono::seconds(5))
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_TRUE(ts.client().info(&info).ok());
}

TEST(HardeningTest, AStalledUploadIsCancelledAfterTheIdleTimeoutAndItsMemoryFreed) {
  ServerOptions o = TestServer::defaults();
  o.idle_timeout_seconds = 0.3;
  TestServer ts(o);
  const auto t0 = Clock::now();
  StalledUpload upload(ts.target(), 64 << 20);  // declares 64 MiB, sends 1000 bytes: holds only what it sent
  ASSERT_TRUE(upload.wrote());
  const auto deadline = Clock::now() + std::chrono::seconds(5);
  while (ts.server().service().budget().used() == 0 && Clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  EXPECT_GT(ts.server().service().budget().used(), 0u);
  EXPECT_LT(ts.server().service().budget().used(), uint64_t(1) << 20);
  const grpc::Status s = upload.awaitServer();
  const double waited = ms(Clock::now() - t0);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::CANCELLED) << s.error_message();
  EXPECT_GE(waited, 250);
  EXPECT_LT(waited, 2000);
  while (ts.server().service().activeCalls() > 0 && Clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  EXPECT_EQ(ts.server().service().budget().used(), 0u);
  EXPECT_EQ(ts.server().service().calls().idleCancels(), 1u);
}

TEST(HardeningTest, AClientThatStopsReadingIsCancelledAndItsSlotFreed) {
  ServerOptions o = TestServer::defaults();
  o.idle_timeout_seconds = 0.5;
  o.max_concurrent_queries = 1;
  o.stream_buffer_bytes = 1 << 20;
  o.batch_bytes = 64 << 10;
  TestServer ts(o);
  // A 192^3 point field (28 MB of values) cannot fit the transport's windows: the server's writes block.
  auto channel = grpc::CreateChannel(ts.target(), grpc::InsecureChannelCredentials());
  auto stub = v1::DistanceField::NewStub(channel);
  grpc::ClientContext ctx;
  auto reader = stub->Query(&ctx, pointsRequest({{90, 90, 90}}, {192, 192, 192}, 1.0, 0, 0));
  v1::QueryReply header;
  ASSERT_TRUE(reader->Read(&header));
  ASSERT_TRUE(header.has_header());
  ASSERT_TRUE(ts.waitRecords(1, std::chrono::seconds(20))) << "the server must give up on a client that reads nothing";
  const QueryRecord r = ts.records()[0];
  EXPECT_EQ(r.code, grpc::StatusCode::CANCELLED);
  EXPECT_NE(r.message.find("idle"), std::string::npos) << r.message;
  EXPECT_EQ(ts.server().service().activeQueries(), 0);
  EXPECT_EQ(ts.server().service().budget().used(), 0u);
  ctx.TryCancel();
  // The slot is free again for a well-behaved client.
  Streamed q = stream(ts.client(), pointsRequest({{4, 4, 4}}, {16, 16, 16}, 1.0, 0, 0), 0);
  EXPECT_TRUE(q.result.status.ok()) << q.result.status.error_message();
}

// ---- Early answers -------------------------------------------------------------------------------------------------

TEST(HardeningTest, DeclaredTotalBytesOverTheLimitIsRefusedOnTheFirstChunk) {
  ServerOptions o = TestServer::defaults();
  o.max_upload_bytes = 1 << 20;
  TestServer ts(o);
  const auto t0 = Clock::now();
  StalledUpload upload(ts.target(), uint64_t(1) << 40);
  const grpc::Status s = upload.awaitServer();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_NE(s.error_message().find("total_bytes"), std::string::npos) << s.error_message();
  EXPECT_LT(ms(Clock::now() - t0), 1000);
}

TEST(HardeningTest, EveryRuleIsCheckedBeforeComputeWithin50ms) {
  TestServer ts;
  struct Case {
    const char* what;
    v1::QueryRequest request;
    grpc::StatusCode code;
  };
  std::vector<Case> cases;
  auto big = [] { return pointsRequest({{10, 10, 10}}, {1024, 1024, 1024}, 1.0, 0, 0); };
  cases.push_back({"too many segments", big(), grpc::StatusCode::INVALID_ARGUMENT});
  cases.back().request.set_segment_length(1e-3);
  cases.push_back({"segments of a huge finite limit", big(), grpc::StatusCode::INVALID_ARGUMENT});
  cases.back().request.set_limit(1e12);
  cases.back().request.set_segment_length(1);
  cases.push_back({"negative limit", big(), grpc::StatusCode::INVALID_ARGUMENT});
  cases.back().request.set_limit(-1);
  cases.push_back({"unknown stencil", big(), grpc::StatusCode::INVALID_ARGUMENT});
  cases.back().request.set_stencil(v1::Stencil(77));
  cases.push_back({"dims over 16384", big(), grpc::StatusCode::INVALID_ARGUMENT});
  cases.back().request.mutable_grid()->mutable_dims()->set_x(16385);
  cases.push_back({"voxel budget", big(), grpc::StatusCode::RESOURCE_EXHAUSTED});
  cases.back().request.mutable_grid()->mutable_dims()->set_x(4096);
  for (const Case& c : cases) {
    const auto t0 = Clock::now();
    Streamed s = stream(ts.client(), c.request, 0);
    const double took = ms(Clock::now() - t0);
    EXPECT_EQ(s.result.status.error_code(), c.code) << c.what << ": " << s.result.status.error_message();
    EXPECT_LT(took, 50) << c.what;
    EXPECT_FALSE(s.result.have_header) << c.what;
  }
}

TEST(HardeningTest, AQueryOverTheMemoryBudgetIsRefusedSayingWhatWasAskedAndWhatIsFree) {
  ServerOptions o = TestServer::defaults();
  o.memory_budget_bytes = uint64_t(512) << 20;
  TestServer ts(o);
  v1::ServerInfo info;
  ASSERT_TRUE(ts.client().info(&info).ok());
  EXPECT_GT(info.memory_budget_bytes(), 0u);
  EXPECT_LT(info.memory_budget_bytes(), uint64_t(512) << 20);
  // 512^3 without a limit: about 1.6 GB for the engine alone.
  const auto t0 = Clock::now();
  Streamed s = stream(ts.client(), pointsRequest({{10, 10, 10}}, {512, 512, 512}, 1.0, 0, 0), 0);
  EXPECT_EQ(s.result.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.result.status.error_message();
  EXPECT_NE(s.result.status.error_message().find("needs an estimated"), std::string::npos);
  EXPECT_NE(s.result.status.error_message().find("budget"), std::string::npos);
  EXPECT_LT(ms(Clock::now() - t0), 200);
  // The same grid with a limit follows the band, and fits.
  Streamed limited = stream(ts.client(), pointsRequest({{100, 100, 100}}, {512, 512, 512}, 1.0, 0, 6), 6);
  EXPECT_TRUE(limited.result.status.ok()) << limited.result.status.error_message();
  EXPECT_EQ(ts.server().service().budget().used(), 0u);
}

TEST(HardeningTest, ADeadlineStopsTheQueryWithDeadlineExceeded) {
  TestServer ts;
  RemoteQueryOptions opts;
  opts.deadline = std::chrono::milliseconds(150);
  const auto t0 = Clock::now();
  RemoteQueryResult r = ts.client().query(pointsRequest({{10, 10, 10}}, {384, 384, 384}, 1.0, 0, 0), {}, opts);
  EXPECT_EQ(r.status.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  ASSERT_TRUE(ts.waitRecords(1));
  const QueryRecord rec = ts.records()[0];
  EXPECT_TRUE(rec.interrupted || !rec.engine_ran);
  EXPECT_LT(ms(rec.finished - t0), 150 + 500) << "the engine must stop soon after the deadline";
}

// ---- Meshes never make the server open files -----------------------------------------------------------------

TEST(HardeningTest, AMeshNamingAFifoNeverMakesTheServerOpenIt) {
  TempDir dir;
  const std::string fifo = dir.path("trap.mtl");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  TestServer ts;
  const std::string obj = "mtllib " + fifo + "\nusemtl trap\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                          "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\ncall " + fifo + "\n";
  std::atomic<bool> done{false};
  grpc::Status s;
  std::thread upload([&] {
    v1::UploadReply up;
    s = ts.client().uploadMesh(obj, v1::MESH_FORMAT_OBJ, "trap.obj", &up);
    done = true;
  });
  // Opening a FIFO for writing without blocking fails with ENXIO while nobody has it open for reading.
  bool reader_seen = false;
  const auto deadline = Clock::now() + std::chrono::seconds(3);
  while (!done && Clock::now() < deadline) {
    const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
    if (fd >= 0) {
      reader_seen = true;
      ::close(fd);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (!done) {  // unblock a server that did open it, so the test ends
    const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
    if (fd >= 0) ::close(fd);
  }
  upload.join();
  EXPECT_FALSE(reader_seen) << "the server opened the FIFO named by the mesh";
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(s.error_message().find(fifo), std::string::npos);
}

TEST(HardeningTest, HostileMeshHeadersAreRejectedQuicklyNamingTheElement) {
  TestServer ts;
  struct Case {
    const char* what;
    v1::MeshFormat format;
    std::string bytes;
    const char* expect;
  };
  std::string ply_list = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                         "property float z\nelement face 1\nproperty list int int vertex_indices\nend_header\n";
  ply_list += std::string(36, '\0');
  const int32_t huge = 0x7fffffff;
  ply_list.append(reinterpret_cast<const char*>(&huge), 4);
  const std::vector<Case> cases = {
      {"ASCII PLY declaring 1e8 vertices in a few bytes", v1::MESH_FORMAT_PLY,
       "ply\nformat ascii 1.0\nelement vertex 100000000\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n",
       "vertex"},
      {"binary PLY face list of 2^31-1 indices", v1::MESH_FORMAT_PLY, ply_list, "face"},
      {"OFF counts split over lines", v1::MESH_FORMAT_OFF, "OFF\n100000000\n100000000 0\n0 0 0\n", ""},
      {"truncated binary STL", v1::MESH_FORMAT_STL, std::string(80, ' ') + std::string("\xff\xff\xff\x0f", 4), ""},
      {"truncated ascii PLY", v1::MESH_FORMAT_PLY,
       "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n",
       "PLY element 'face' 0 (line"},
  };
  for (const Case& c : cases) {
    const auto t0 = Clock::now();
    v1::UploadReply up;
    const grpc::Status s = ts.client().uploadMesh(c.bytes, c.format, "hostile", &up);
    EXPECT_FALSE(s.ok()) << c.what;
    EXPECT_TRUE(s.error_code() == grpc::StatusCode::INVALID_ARGUMENT ||
                s.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED)
        << c.what << ": " << s.error_message();
    EXPECT_NE(s.error_message().find(c.expect), std::string::npos) << c.what << ": " << s.error_message();
    const double took = ms(Clock::now() - t0);
    EXPECT_LT(took, 500) << c.what;
    std::printf("%s (%zu bytes): %s in %.1f ms: %s\n", c.what, c.bytes.size(),
                s.error_code() == grpc::StatusCode::INVALID_ARGUMENT ? "INVALID_ARGUMENT" : "RESOURCE_EXHAUSTED", took,
                s.error_message().c_str());
  }
  EXPECT_EQ(ts.server().service().budget().used(), 0u);
}

}  // namespace
}  // namespace distband

namespace distband {
namespace {

std::set<std::string> filesIn(const fs::path& dir) {
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.insert(e.path().filename().string());
  return names;
}

TEST(HardeningTest, UploadsNeverWriteFiles) {
  // Watched: a private TMPDIR (where temp_directory_path() and mkstemp-style code would write; it must stay
  // empty) and /tmp itself, where other tests running in parallel create their own distband_* fixtures.
  const fs::path tmp = "/tmp";
  TempDir private_tmp;
  const char* old_tmpdir = std::getenv("TMPDIR");
  const std::string saved = old_tmpdir ? old_tmpdir : "";
  ::setenv("TMPDIR", private_tmp.path("").c_str(), 1);
  {
    TestServer ts;
    const auto before = filesIn(tmp);
    v1::UploadReply up;
    const std::string bunny = readAll(DISTBAND_TEST_DATA_DIR "/meshes/bunny.obj");
    ASSERT_TRUE(ts.client().uploadMesh(bunny, v1::MESH_FORMAT_OBJ, "bunny.obj", &up).ok());
    EXPECT_EQ(ts.client().uploadMesh("ply\nformat ascii 1.0\n", v1::MESH_FORMAT_PLY, "bad.ply", &up).error_code(),
              grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_TRUE(filesIn(private_tmp.path("")).empty()) << "the server wrote into TMPDIR";
    for (const std::string& f : filesIn(tmp))
      EXPECT_TRUE(before.count(f) || f.rfind("distband_", 0) == 0) << "the server created " << (tmp / f).string();
  }
  if (old_tmpdir) ::setenv("TMPDIR", saved.c_str(), 1);
  else ::unsetenv("TMPDIR");
}

TEST(HardeningTest, ACancelledUploadStopsItsParseAndFreesItsMemory) {
  TestServer ts;
  // A 60 MB OBJ: parsing it takes far longer than the cancel below.
  std::string obj;
  obj.reserve(60 << 20);
  for (int i = 0; obj.size() < (60u << 20); ++i)
    obj += "v " + std::to_string(i % 1000) + " " + std::to_string(i / 1000 % 1000) + " " + std::to_string(i / 1000000) + "\n";
  obj += "f 1 2 3\n";
  std::atomic<bool> done{false};
  grpc::Status status;
  auto channel = grpc::CreateChannel(ts.target(), grpc::InsecureChannelCredentials());
  auto stub = v1::DistanceField::NewStub(channel);
  grpc::ClientContext ctx;
  std::thread upload([&] {
    v1::UploadReply reply;
    auto writer = stub->UploadMesh(&ctx, &reply);
    for (size_t off = 0; off < obj.size(); off += 4 << 20) {
      v1::UploadMeshChunk chunk;
      if (off == 0) chunk.mutable_header()->set_format(v1::MESH_FORMAT_OBJ);
      chunk.set_data(obj.substr(off, 4 << 20));
      if (!writer->Write(chunk)) break;
    }
    writer->WritesDone();
    status = writer->Finish();
    done = true;
  });
  // Wait until the server is parsing (its parse reservation, 24 x the upload, is in the budget), then cancel.
  const auto deadline = Clock::now() + std::chrono::seconds(20);
  while (ts.server().service().budget().used() < 20 * obj.size() && Clock::now() < deadline && !done)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const auto t0 = Clock::now();
  ctx.TryCancel();
  while (ts.server().service().activeCalls() > 0 && Clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  const double stop_ms = ms(Clock::now() - t0);
  upload.join();
  EXPECT_EQ(status.error_code(), grpc::StatusCode::CANCELLED);
  EXPECT_EQ(ts.server().service().budget().used(), 0u);
  EXPECT_LT(stop_ms, 1000) << "a generous bound (bench/cancel_bench measures the latency)";
  std::printf("upload parse stopped %.1f ms after the client's cancel\n", stop_ms);
}

}  // namespace
}  // namespace distband
