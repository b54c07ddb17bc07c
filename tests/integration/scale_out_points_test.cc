// QueryPoints through a coordinator (--peers) over three replica processes on loopback: the chunks fan out to every
// replica and the results come back in the client's order and numbering, bit for bit those of one server queried
// directly (itself checked against brute force here and in points_test). A malformed chunk is refused by the
// coordinator naming the chunk and the point; a replica killed mid-stream fails the call with UNAVAILABLE naming it,
// promptly, also for a client that waits for each chunk's results before sending the next; a client's cancel ends
// the call and every replica's stream. The coordinator serves the next call each time.
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <random>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "client/cli.h"
#include "core/io/npy.h"
#include "core/mesh/triangle_mesh.h"
#include "core/points/point_results.h"
#include "server/request_id.h"
#include "tests/integration/points_streams.h"
#include "tests/integration/service_fixture.h"
#include "tests/support/brute_mesh.h"
#include "tests/support/build_flavor.h"
#include "tests/support/child_server.h"

namespace distband {
namespace {

namespace fs = std::filesystem;
using namespace points_streams;

const std::string kBunny = std::string(DISTBAND_TEST_DATA_DIR) + "/meshes/bunny.obj";

/// Three replica processes (so one can be killed and each has its own log) and an in-process coordinator over them.
struct PointsCluster {
  std::vector<std::unique_ptr<ChildServer>> replicas;
  std::vector<std::string> targets;
  std::unique_ptr<TestServer> coordinator;

  explicit PointsCluster(int n = 3) {
    for (int i = 0; i < n; ++i) {
      replicas.push_back(std::make_unique<ChildServer>(
          DISTBAND_SERVER_BINARY, std::vector<std::string>{"--threads", "1", "--memory-budget", "1G"}));
      EXPECT_GT(replicas.back()->port(), 0) << replicas.back()->log();
      targets.push_back(replicas.back()->target());
    }
    ServerOptions o = TestServer::defaults();
    o.peers = "ipv4:";
    for (size_t i = 0; i < targets.size(); ++i) o.peers += (i ? "," : "") + targets[i];
    coordinator = std::make_unique<TestServer>(o);
  }
  bool ready() const {
    for (const auto& r : replicas)
      if (r->port() == 0) return false;
    return true;
  }
};

/// `points` packed in chunks of `chunk_points`.
std::vector<std::string> chunked(const std::vector<Vec3d>& points, size_t chunk_points, bool doubles) {
  std::vector<std::string> chunks;
  for (size_t at = 0; at < points.size(); at += chunk_points)
    chunks.push_back(packXyz(
        {points.begin() + long(at), points.begin() + long(std::min(points.size(), at + chunk_points))}, doubles));
  return chunks;
}

/// What a QueryPoints stream delivered.
struct PointsRun {
  grpc::Status status;
  std::optional<v1::PointsReplyHeader> header;
  std::vector<v1::PointsResults> results;
  std::optional<v1::PointsSummary> summary;
  /// Each output's bytes, the chunks' concatenated in arrival order.
  std::string distance, closest_points, closest_feature, gradient;
};

std::shared_ptr<grpc::Channel> channelTo(const std::string& target) {
  return grpc::CreateChannel(target, grpc::InsecureChannelCredentials());
}

std::unique_ptr<v1::DistanceField::Stub> stubFor(const std::string& target) {
  return v1::DistanceField::NewStub(channelTo(target));
}

/// A stream as a pipelining client makes it: a writer thread sends the header and every chunk, then half-closes,
/// while the replies are read. `keep_going` (after each result) returning false cancels the call.
PointsRun streamPoints(const std::string& target, const v1::PointsHeader& header,
                       const std::vector<std::string>& chunks, const std::string& request_id = {},
                       const std::function<bool(size_t)>& keep_going = {}) {
  auto stub = stubFor(target);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  if (!request_id.empty()) context.AddMetadata(kRequestIdHeader, request_id);
  auto stream = stub->QueryPoints(&context);
  std::thread writer([&] {
    v1::PointsRequest m;
    *m.mutable_header() = header;
    if (!stream->Write(m)) return;
    for (const std::string& c : chunks) {
      m.mutable_chunk()->set_xyz(c);
      if (!stream->Write(m)) return;
    }
    stream->WritesDone();
  });
  PointsRun run;
  v1::PointsReply reply;
  while (stream->Read(&reply)) {
    if (reply.has_header()) run.header = reply.header();
    if (reply.has_summary()) run.summary = reply.summary();
    if (!reply.has_results()) continue;
    const v1::PointsResults& r = reply.results();
    run.distance += r.distance();
    run.closest_points += r.closest_points();
    run.closest_feature += r.closest_feature();
    run.gradient += r.gradient();
    run.results.push_back(r);
    if (keep_going && !keep_going(run.results.size())) context.TryCancel();
  }
  writer.join();
  run.status = stream->Finish();
  return run;
}

/// Every result in the client's order and numbering, as many points as each chunk held.
void expectClientNumbering(const PointsRun& run, const std::vector<std::string>& chunks, size_t record) {
  ASSERT_EQ(run.results.size(), chunks.size());
  uint64_t first = 0;
  for (size_t i = 0; i < chunks.size(); ++i) {
    EXPECT_EQ(run.results[i].chunk(), i);
    EXPECT_EQ(run.results[i].first_point(), first) << "chunk " << i;
    EXPECT_EQ(run.results[i].points(), chunks[i].size() / record) << "chunk " << i;
    first += run.results[i].points();
  }
}

/// The two runs delivered the same bytes of every output, and described the query alike.
void expectIdentical(const PointsRun& direct, const PointsRun& fanned, const char* what) {
  ASSERT_TRUE(direct.status.ok()) << what << ": " << direct.status.error_message();
  ASSERT_TRUE(fanned.status.ok()) << what << ": " << fanned.status.error_message();
  EXPECT_EQ(fanned.distance, direct.distance) << what;
  EXPECT_EQ(fanned.closest_points, direct.closest_points) << what;
  EXPECT_EQ(fanned.closest_feature, direct.closest_feature) << what;
  EXPECT_EQ(fanned.gradient, direct.gradient) << what;
  ASSERT_TRUE(direct.header && fanned.header && direct.summary && fanned.summary) << what;
  v1::PointsReplyHeader a = *direct.header, b = *fanned.header;
  a.clear_query_id();
  b.clear_query_id();
  EXPECT_EQ(a.SerializeAsString(), b.SerializeAsString())
      << what << ": " << a.ShortDebugString() << " vs " << b.ShortDebugString();
  EXPECT_EQ(fanned.summary->points(), direct.summary->points()) << what;
  EXPECT_EQ(fanned.summary->chunks(), direct.summary->chunks()) << what;
  EXPECT_EQ(fanned.summary->beyond_limit(), direct.summary->beyond_limit()) << what;
}

template <typename T>
std::vector<T> unpack(const std::string& bytes) {
  std::vector<T> v(bytes.size() / sizeof(T));
  std::memcpy(v.data(), bytes.data(), v.size() * sizeof(T));
  return v;
}

/// Chunks each replica's QueryPoints line with `request_id` reports (waiting up to 3 s for each line: a replica
/// logs once its handler returned, just after the coordinator saw its summary); -1 for a replica without one.
std::vector<int> chunksPerReplica(PointsCluster& cluster, const std::string& request_id, const std::string& status) {
  const std::regex line("QueryPoints p[0-9]+ request_id=" + request_id +
                        " [^\n]* chunks=([0-9]+) [^\n]*status=" + status);
  std::vector<int> counts;
  for (auto& r : cluster.replicas) {
    int found = -1;
    const auto end = Clock::now() + std::chrono::seconds(3);
    while (found < 0 && Clock::now() < end) {
      std::smatch m;
      const std::string log = r->log();
      if (std::regex_search(log, m, line))
        found = std::stoi(m[1]);
      else
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    counts.push_back(found);
  }
  return counts;
}

std::vector<Vec3d> uniformPoints(size_t n, const Vec3d& lo, const Vec3d& hi, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Vec3d> p(n);
  for (Vec3d& q : p) q = {lo.x + (hi.x - lo.x) * u(rng), lo.y + (hi.y - lo.y) * u(rng), lo.z + (hi.z - lo.z) * u(rng)};
  return p;
}

v1::PointsHeader allOutputs(v1::PointsHeader h, v1::ValueType type) {
  h.set_coordinates(type);
  h.set_closest_points(true);
  h.set_closest_feature(true);
  h.set_gradient(true);
  return h;
}

v1::PointsHeader pointSeedsHeader(const std::vector<Vec3d>& seeds) {
  v1::PointsHeader h;
  for (const Vec3d& s : seeds) {
    v1::Vec3* v = h.mutable_points()->add_points();
    v->set_x(s.x);
    v->set_y(s.y);
    v->set_z(s.z);
  }
  return h;
}

TEST(ScaleOutPointsTest, ChunksFanOutToEveryReplicaAndComeBackBitIdenticalInOrder) {
  PointsCluster cluster;
  ASSERT_TRUE(cluster.ready());
  TestServer direct;

  {  // A mesh asset (the coordinator ships its canonical PLY to the replicas), float64, every output.
    TriangleMesh mesh;
    MeshReport report;
    ASSERT_TRUE(loadMesh(kBunny, &mesh, &report).ok());
    v1::UploadReply up_direct, up_coordinator;
    ASSERT_TRUE(direct.client().uploadMeshFile(kBunny, &up_direct).ok());
    ASSERT_TRUE(cluster.coordinator->client().uploadMeshFile(kBunny, &up_coordinator).ok());
    const std::vector<Vec3d> at = samplePoints(mesh, 3000, 5);
    const std::vector<std::string> chunks = chunked(at, 97, true);  // 31 chunks
    v1::PointsHeader h;
    h.set_asset_id(up_direct.asset_id());
    h = allOutputs(h, v1::VALUE_TYPE_FLOAT64);
    const PointsRun one = streamPoints(direct.target(), h, chunks);
    h.set_asset_id(up_coordinator.asset_id());
    const PointsRun many = streamPoints(cluster.coordinator->target(), h, chunks, "fanout-mesh-1");
    expectIdentical(one, many, "bunny asset");
    expectClientNumbering(many, chunks, 24);
    // Exact against brute force (every 10th point: a scan of every triangle each).
    const std::vector<double> d = unpack<double>(many.distance);
    ASSERT_EQ(d.size(), at.size());
    for (size_t i = 0; i < at.size(); i += 10)
      ASSERT_NEAR(std::abs(d[i]), testing::bruteDistance(mesh, at[i]), 1e-9) << "point " << i;
    // Every replica computed some of the chunks, and together all of them.
    const std::vector<int> per_replica = chunksPerReplica(cluster, "fanout-mesh-1", "OK");
    int total = 0;
    for (size_t r = 0; r < per_replica.size(); ++r) {
      EXPECT_GT(per_replica[r], 0) << "replica " << r << " computed no chunk:\n" << cluster.replicas[r]->log();
      total += per_replica[r];
    }
    EXPECT_EQ(total, int(chunks.size()));
  }

  {  // Inline point seeds with a limit, float32, every output; many small chunks.
    const std::vector<Vec3d> seeds = uniformPoints(60, {0, 0, 0}, {10, 10, 10}, 7);
    const std::vector<Vec3d> at = uniformPoints(2500, {-2, -2, -2}, {12, 12, 12}, 9);
    const std::vector<std::string> chunks = chunked(at, 61, false);  // 41 chunks
    v1::PointsHeader h = allOutputs(pointSeedsHeader(seeds), v1::VALUE_TYPE_FLOAT32);
    h.set_limit(1.5);
    const PointsRun one = streamPoints(direct.target(), h, chunks);
    const PointsRun many = streamPoints(cluster.coordinator->target(), h, chunks, "fanout-points-1");
    expectIdentical(one, many, "point seeds");
    expectClientNumbering(many, chunks, 12);
    EXPECT_GT(many.summary->beyond_limit(), 100u);
    // Exact against brute force (the query points as sent: float32).
    const std::vector<float> d = unpack<float>(many.distance);
    const std::vector<int32_t> ids = unpack<int32_t>(many.closest_feature);
    ASSERT_EQ(d.size(), at.size());
    for (size_t i = 0; i < at.size(); ++i) {
      const Vec3d q{double(float(at[i].x)), double(float(at[i].y)), double(float(at[i].z))};
      double best = 1e300;
      int32_t best_id = -1;
      for (size_t s = 0; s < seeds.size(); ++s)
        if ((q - seeds[s]).length() < best) best = (q - seeds[s]).length(), best_id = int32_t(s);
      if (best > 1.5) {
        ASSERT_EQ(d[i], 1.5f) << i;
        ASSERT_EQ(ids[i], -1) << i;
      } else {
        ASSERT_NEAR(d[i], best, 1e-5) << i;
        ASSERT_EQ(ids[i], best_id) << i;
      }
    }
    const std::vector<int> per_replica = chunksPerReplica(cluster, "fanout-points-1", "OK");
    for (size_t r = 0; r < per_replica.size(); ++r) EXPECT_GT(per_replica[r], 0) << "replica " << r;
  }
}

v1::PointsRequest headerMessage(const v1::PointsHeader& h) {
  v1::PointsRequest m;
  *m.mutable_header() = h;
  return m;
}

TEST(ScaleOutPointsTest, TheCoordinatorRefusesMalformedChunksAndHeadersItselfAndKeepsServing) {
  PointsCluster cluster;
  ASSERT_TRUE(cluster.ready());
  const std::string target = cluster.coordinator->target();
  const v1::PointsRequest header = headerMessage(pointSeedsHeader({{0, 0, 0}, {4, 0, 0}}));
  const v1::PointsRequest good = chunkOf({{0, 0, 0}, {2, 0, 0}});

  // Malformed chunks: named in the client's numbering, after the chunks before them were answered.
  v1::PointsRequest odd = good;
  odd.mutable_chunk()->mutable_xyz()->push_back('x');
  RawResult r = rawStream(channelTo(target), {header, good, good, odd}, "fanout-odd");
  expectRefused(r, grpc::StatusCode::INVALID_ARGUMENT, {"chunk 2", "25 bytes"});
  EXPECT_EQ(r.results, 2);
  const double nan = std::nan("");
  r = rawStream(channelTo(target), {header, good, good, good, chunkOf({{0, 0, 0}, {1, 1, 1}, {0, nan, 0}})});
  expectRefused(r, grpc::StatusCode::INVALID_ARGUMENT, {"chunk 3", "point 2", "point 8 of the stream", "not finite"});
  EXPECT_EQ(r.results, 3);
  r = rawStream(channelTo(target), {header, good, header});
  expectRefused(r, grpc::StatusCode::INVALID_ARGUMENT, {"chunk 1", "header"});
  // The replicas' streams of those calls were cancelled, not failed (the coordinator refused the chunk).
  for (const int n : chunksPerReplica(cluster, "fanout-odd", "CANCELLED")) EXPECT_GE(n, 0);

  // Headers are checked as a replica checks them, before any traffic to the replicas.
  v1::PointsRequest h = header;
  h.mutable_header()->set_limit(-1);
  expectRefused(rawStream(channelTo(target), {h, good}), grpc::StatusCode::INVALID_ARGUMENT, {"header", "limit"});
  h = header;
  h.mutable_header()->set_sign(v1::SIGN_MODE_MASK_INSIDE);
  expectRefused(rawStream(channelTo(target), {h, good}), grpc::StatusCode::INVALID_ARGUMENT, {"sign", "MASK_INSIDE"});
  h = header;
  h.mutable_header()->set_coordinates(v1::ValueType(7));
  expectRefused(rawStream(channelTo(target), {h, good}), grpc::StatusCode::INVALID_ARGUMENT, {"coordinates"});
  v1::PointsRequest unknown;
  unknown.mutable_header()->set_asset_id("mesh-0123");
  expectRefused(rawStream(channelTo(target), {unknown, good}), grpc::StatusCode::NOT_FOUND, {"asset_id"});
  expectRefused(rawStream(channelTo(target), {good}), grpc::StatusCode::INVALID_ARGUMENT, {"header"});
  for (auto& replica : cluster.replicas) {
    auto lines = [&] {
      const std::string log = replica->log();
      int n = 0;
      for (size_t at = log.find("QueryPoints "); at != std::string::npos; at = log.find("QueryPoints ", at + 1)) ++n;
      return n;
    };
    const auto end = Clock::now() + std::chrono::seconds(3);  // the cancelled streams' lines come as they end
    while (lines() < 3 && Clock::now() < end) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    EXPECT_EQ(lines(), 3) << "only the three calls with a valid header reach a replica:\n" << replica->log();
  }

  // Nothing broke: a good stream is answered.
  r = rawStream(channelTo(target), {header, good, good, good, good});
  EXPECT_TRUE(r.status.ok()) << r.status.error_message();
  EXPECT_EQ(r.results, 4);
}

/// The status of a lockstep stream (each chunk's results read before the next chunk is sent) on which `replica`
/// is killed once `answered_before_kill` chunks were answered, and the seconds from the kill to the status.
struct KilledRun {
  grpc::Status status;
  int answered = 0;
  double seconds_after_kill = -1;
};
KilledRun lockstepKill(const std::string& target, const v1::PointsHeader& header, const std::string& chunk,
                       ChildServer& replica, int answered_before_kill) {
  auto stub = stubFor(target);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  auto stream = stub->QueryPoints(&context);
  KilledRun run;
  v1::PointsRequest m = headerMessage(header);
  v1::PointsReply reply;
  Clock::time_point killed{};
  if (stream->Write(m) && stream->Read(&reply)) {  // the header
    m.mutable_chunk()->set_xyz(chunk);
    for (int i = 0; i < 1000; ++i) {
      if (run.answered == answered_before_kill && killed == Clock::time_point{}) {
        replica.signal(SIGKILL);
        killed = Clock::now();
      }
      if (!stream->Write(m) || !stream->Read(&reply)) break;
      run.answered += reply.has_results();
    }
  }
  run.status = stream->Finish();
  if (killed != Clock::time_point{})
    run.seconds_after_kill = std::chrono::duration<double>(Clock::now() - killed).count();
  return run;
}

TEST(ScaleOutPointsTest, AReplicaKilledMidStreamFailsTheCallNamingItAndTheNextCallUsesTheOthers) {
  PointsCluster cluster;
  ASSERT_TRUE(cluster.ready());
  const std::string target = cluster.coordinator->target();
  const std::vector<Vec3d> seeds = uniformPoints(40, {0, 0, 0}, {10, 10, 10}, 3);
  const v1::PointsHeader h = allOutputs(pointSeedsHeader(seeds), v1::VALUE_TYPE_FLOAT32);
  const std::string chunk = packXyz(uniformPoints(500, {-1, -1, -1}, {11, 11, 11}, 4), false);

  // A client that waits for each chunk's results before it sends the next: the coordinator is reading its next
  // chunk when the replica dies, and still answers at once with the replica's failure.
  const KilledRun killed = lockstepKill(target, h, chunk, *cluster.replicas[1], 6);
  EXPECT_EQ(killed.status.error_code(), grpc::StatusCode::UNAVAILABLE) << killed.status.error_message();
  EXPECT_NE(killed.status.error_message().find("replica ipv4:" + cluster.targets[1]), std::string::npos)
      << killed.status.error_message();
  EXPECT_GE(killed.answered, 6);
  EXPECT_LT(killed.seconds_after_kill, 5.0);
  std::printf("a replica killed under a lockstep client: UNAVAILABLE %.3f s after the kill: %s\n",
              killed.seconds_after_kill, killed.status.error_message().c_str());

  // The next call goes to the two replicas left (the dead one is left out as its stream fails to open), and a
  // pipelining client sees the same when a second replica dies under it.
  const std::vector<std::string> chunks(30, chunk);
  TestServer direct;
  const PointsRun one = streamPoints(direct.target(), h, chunks);
  const PointsRun two = streamPoints(target, h, chunks, "fanout-after-kill");
  expectIdentical(one, two, "over the replicas left");
  const std::vector<int> per_replica = chunksPerReplica(cluster, "fanout-after-kill", "OK");
  EXPECT_GT(per_replica[0], 0);
  EXPECT_GT(per_replica[2], 0);

  std::atomic<int64_t> killed_ns{0};
  const PointsRun cut = streamPoints(target, h, std::vector<std::string>(2000, chunk), {}, [&](size_t results) {
    if (results == 4) {
      cluster.replicas[2]->signal(SIGKILL);
      killed_ns = Clock::now().time_since_epoch().count();
    }
    return true;
  });
  const double after_kill = ms(Clock::now() - Clock::time_point(Clock::duration(killed_ns.load())));
  EXPECT_EQ(cut.status.error_code(), grpc::StatusCode::UNAVAILABLE) << cut.status.error_message();
  EXPECT_NE(cut.status.error_message().find("replica ipv4:" + cluster.targets[2]), std::string::npos)
      << cut.status.error_message();
  EXPECT_LT(cut.results.size(), 2000u);
  EXPECT_LT(after_kill, 5000.0);

  // One replica left: the coordinator still answers.
  const PointsRun last = streamPoints(target, h, std::vector<std::string>(5, chunk));
  EXPECT_TRUE(last.status.ok()) << last.status.error_message();
  EXPECT_EQ(last.results.size(), 5u);
}

TEST(ScaleOutPointsTest, ACancelledCallEndsPromptlyAndEndsEveryReplicaStream) {
  PointsCluster cluster;
  ASSERT_TRUE(cluster.ready());
  TriangleMesh mesh;
  MeshReport report;
  ASSERT_TRUE(loadMesh(kBunny, &mesh, &report).ok());
  v1::UploadReply up;
  ASSERT_TRUE(cluster.coordinator->client().uploadMeshFile(kBunny, &up).ok());
  v1::PointsHeader h;
  h.set_asset_id(up.asset_id());
  h.set_gradient(true);
  // Full chunks (tens of ms of compute each on a replica's one thread), so the cancel finds them computing.
  const std::string xyz = packXyz(samplePoints(mesh, kMaxChunkPoints, 11), false);
  std::atomic<int64_t> cancelled_ns{0};
  std::atomic<double> stop_ms{-1};
  std::thread watcher([&] {  // the coordinator's call ends after the cancel
    const auto end = Clock::now() + std::chrono::seconds(30);
    while (Clock::now() < end && (cancelled_ns == 0 || cluster.coordinator->server().service().activeCalls() > 0))
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    if (cancelled_ns != 0) stop_ms = ms(Clock::now() - Clock::time_point(Clock::duration(cancelled_ns.load())));
  });
  const PointsRun run = streamPoints(cluster.coordinator->target(), h, std::vector<std::string>(200, xyz),
                                     "fanout-cancel", [&](size_t results) {
                                       if (results < 4) return true;
                                       cancelled_ns = Clock::now().time_since_epoch().count();
                                       return false;
                                     });
  watcher.join();
  EXPECT_EQ(run.status.error_code(), grpc::StatusCode::CANCELLED) << run.status.error_message();
  EXPECT_GE(stop_ms.load(), 0);
  EXPECT_LT(stop_ms.load(), testing::latencyBoundMs(100));
  // Every replica's stream ended, cancelled (its log line says so).
  const auto cancelled = Clock::time_point(Clock::duration(cancelled_ns.load()));
  const std::vector<int> per_replica = chunksPerReplica(cluster, "fanout-cancel", "CANCELLED");
  const double replicas_ms = ms(Clock::now() - cancelled);
  for (size_t r = 0; r < per_replica.size(); ++r)
    EXPECT_GE(per_replica[r], 0) << "replica " << r << " logged no cancelled stream:\n" << cluster.replicas[r]->log();
  std::printf(
      "a cancel through the coordinator: its call ended %.1f ms after the client's cancel, every replica had "
      "logged its cancelled stream %.1f ms after it\n",
      stop_ms.load(), replicas_ms);
  EXPECT_LT(replicas_ms, 3000.0);

  // The coordinator serves the next call.
  const PointsRun again = streamPoints(cluster.coordinator->target(), h, {xyz});
  EXPECT_TRUE(again.status.ok()) << again.status.error_message();
  EXPECT_EQ(again.results.size(), 1u);
}

TEST(ScaleOutPointsTest, TheCliAtCommandWorksThroughTheCoordinator) {
  PointsCluster cluster;
  ASSERT_TRUE(cluster.ready());
  TestServer direct;
  const fs::path dir = fs::temp_directory_path() / ("distband_fanout_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  TriangleMesh mesh;
  MeshReport report;
  ASSERT_TRUE(loadMesh(kBunny, &mesh, &report).ok());
  const std::vector<Vec3d> at = samplePoints(mesh, 1500, 13);
  std::ofstream((dir / "q.npy").string(), std::ios::binary)
      << encodeNpy("<f8", {int64_t(at.size()), 3}, at.data(), at.size() * sizeof(Vec3d));
  auto run = [&](const std::string& server, const std::string& out) {
    std::ostringstream o, e;
    CliContext ctx{o, e, [] { return false; }};
    const int code =
        runDistband({"at", "--mesh", kBunny, "--at", (dir / "q.npy").string(), "--chunk-points", "100", "--server",
                     server, "--out", (dir / out).string(), "--closest", (dir / ("ids_" + out)).string()},
                    ctx);
    EXPECT_EQ(code, 0) << e.str() << o.str();
    std::ifstream d((dir / out).string(), std::ios::binary), ids((dir / ("ids_" + out)).string(), std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(d), {}) + std::string(std::istreambuf_iterator<char>(ids), {});
  };
  const std::string one = run(direct.target(), "direct.npy");
  const std::string many = run(cluster.coordinator->target(), "coordinator.npy");
  EXPECT_FALSE(one.empty());
  EXPECT_EQ(many, one);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace distband
