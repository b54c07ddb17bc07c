// Scale-out: a coordinator (--peers) in front of three replicas on loopback gives the same field as one server,
// keeps the stream's nearest-first order, survives a replica killed mid-query, and stops every tile on a cancel.
// The reference is one replica queried directly (itself checked against exact distances by service_test).
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/integration/service_fixture.h"
#include "server/replica_pool.h"
#include "tests/support/build_flavor.h"
#include "tests/support/child_server.h"

namespace distband {
namespace {

ServerOptions coordinatorOptions(const std::vector<std::string>& replicas, uint64_t tile_voxels) {
  ServerOptions o = TestServer::defaults();
  o.peers = "ipv4:";
  for (size_t i = 0; i < replicas.size(); ++i) o.peers += (i ? "," : "") + replicas[i];
  o.tile_voxels = tile_voxels;
  return o;
}

struct Cluster {
  std::vector<std::unique_ptr<TestServer>> replicas;
  std::unique_ptr<TestServer> coordinator;
  explicit Cluster(uint64_t tile_voxels = 32 * 32 * 32) {
    std::vector<std::string> targets;
    for (int i = 0; i < 3; ++i) {
      ServerOptions o = TestServer::defaults();
      o.compute_threads = 1;
      replicas.push_back(std::make_unique<TestServer>(o));
      targets.push_back(replicas.back()->target());
    }
    coordinator = std::make_unique<TestServer>(coordinatorOptions(targets, tile_voxels));
  }
  size_t tileQueries() {
    size_t n = 0;
    for (auto& r : replicas) n += r->records().size();
    return n;
  }
};

struct Comparison {
  int64_t voxels = 0, identical = 0, sign_flips = 0;
  double max_diff = 0;  // voxels
};

Comparison compare(const DenseField& a, const DenseField& b) {
  Comparison c;
  const double h = a.grid().voxelSize();
  for (size_t i = 0; i < a.values().size(); ++i) {
    const float x = a.values()[i], y = b.values()[i];
    ++c.voxels;
    if (std::memcmp(&x, &y, sizeof x) == 0) {
      ++c.identical;
      continue;
    }
    if ((x < 0) != (y < 0)) ++c.sign_flips;
    c.max_diff = std::max(c.max_diff, std::abs(double(x) - double(y)) / h);
  }
  return c;
}

void expectWellOrdered(const Streamed& s) {
  ASSERT_TRUE(s.result.status.ok()) << s.result.status.error_message();
  EXPECT_EQ(s.order_error, "");
  ASSERT_FALSE(s.done.empty());
  for (size_t i = 0; i < s.done.size(); ++i) {
    EXPECT_EQ(s.done[i].segment(), i);
    EXPECT_EQ(s.done[i].last(), i + 1 == s.done.size());
  }
}

std::vector<Vec3d> randomPoints(int n, double extent, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-0.1 * extent, 1.1 * extent);
  std::vector<Vec3d> p;
  for (int i = 0; i < n; ++i) p.push_back({u(rng), u(rng), u(rng)});
  return p;
}

TEST(ScaleOutTest, PointFieldsAreBitIdenticalToOneServerAndNearestFirst) {
  Cluster cluster;
  const Coord dims{96, 80, 72};
  const double h = 0.5;
  const auto points = randomPoints(25, 40.0, 3);
  for (const auto& [segment, limit] : {std::pair{0.0, 3.0}, std::pair{1.5, 6.0}, std::pair{4.0, 0.0}}) {
    const v1::QueryRequest request = pointsRequest(points, dims, h, segment, limit);
    const Streamed one = stream(cluster.replicas[0]->client(), request, -1.0f);
    const size_t before = cluster.tileQueries();
    const Streamed many = stream(cluster.coordinator->client(), request, -1.0f);
    expectWellOrdered(one);
    expectWellOrdered(many);
    const size_t tiles = cluster.tileQueries() - before;
    EXPECT_GT(tiles, 6u) << "the query should have been split into tiles";
    const Comparison c = compare(*one.field, *many.field);
    EXPECT_EQ(c.identical, c.voxels) << "segment " << segment << " limit " << limit << ": max diff " << c.max_diff;
    EXPECT_EQ(many.result.summary.voxels(), one.result.summary.voxels());
    EXPECT_EQ(many.done.size(), one.done.size());
    // Every replica took part (round_robin spreads the tiles).
    for (auto& r : cluster.replicas) EXPECT_TRUE(r->waitRecords(1, std::chrono::seconds(2)));
  }
}

// Points outside a tile's window reach it through the whole grid's algorithm: with the separable point EDT (which
// one server picks for these three points) every tile is exact. The band in a window is not: two points outside it
// can seed the same face voxels and the farther one never enters (0.61 voxel off here before the coordinator sent
// its algorithm; 5.4 voxels off with band tiles in two-brick-margin windows). 27 tiles of 48^3, not 64 of 32^3: each
// band tile is a whole-grid computation, and the smaller tiles made this the suite's slowest test under ASan (245 s).
TEST(ScaleOutTest, UnlimitedPointTilesRunTheWholeGridsAlgorithm) {
  Cluster cluster(48 * 48 * 48);
  for (const v1::Algorithm algorithm : {v1::ALGORITHM_UNSPECIFIED, v1::ALGORITHM_BAND}) {
    v1::QueryRequest request =
        pointsRequest({{20.5, 30, 40}, {90, 80, 70.25}, {64, 64, 64}}, {128, 128, 128}, 1.0, 0, 0);
    request.set_algorithm(algorithm);  // unspecified: the separable point EDT; the band: whole-grid windows
    const Streamed one = stream(cluster.replicas[0]->client(), request, -1.0f);
    const Streamed many = stream(cluster.coordinator->client(), request, -1.0f);
    const std::string expected = algorithm == v1::ALGORITHM_BAND ? "band" : "separable";
    EXPECT_EQ(one.result.header.algorithm(), expected);
    EXPECT_EQ(many.result.header.algorithm(), expected);
    const Comparison c = compare(*one.field, *many.field);
    EXPECT_EQ(c.voxels, 128 * 128 * 128);
    EXPECT_EQ(c.identical, c.voxels) << expected << ": max diff " << c.max_diff;
  }
}

std::vector<uint8_t> blobMask(const Coord& dims);

// Closest-feature ids through the coordinator: the tiles' point indices are mapped back to the request's (the ids
// then equal one server's), volume ids name voxels of the whole grid at exactly the delivered distance.
TEST(ScaleOutTest, ClosestFeaturesCrossTilesIntact) {
  Cluster cluster;
  const Coord dims{96, 80, 72};
  const double h = 0.5;
  const auto points = randomPoints(25, 40.0, 3);
  v1::QueryRequest request = pointsRequest(points, dims, h, 1.5, 6.0);
  request.set_closest_feature(true);
  const Streamed one = stream(cluster.replicas[0]->client(), request, -1.0f);
  const Streamed many = stream(cluster.coordinator->client(), request, -1.0f);
  ASSERT_TRUE(many.result.status.ok()) << many.result.status.error_message();
  EXPECT_EQ(many.result.header.closest_feature(), v1::CLOSEST_FEATURE_POINT);
  ASSERT_FALSE(one.closest.empty());
  ASSERT_EQ(one.closest.size(), many.closest.size());
  int64_t delivered = 0, differ = 0;
  for (size_t i = 0; i < one.closest.size(); ++i) {
    delivered += one.closest[i] >= 0;
    differ += one.closest[i] != many.closest[i];
  }
  EXPECT_GT(delivered, 10000);
  EXPECT_EQ(differ, 0);

  const Coord vdims{72, 70, 64};
  const auto mask = blobMask(vdims);
  v1::UploadReply up;
  ASSERT_TRUE(cluster.coordinator->client().uploadVolumeBytes(vdims, v1::VOXEL_TYPE_UINT8, mask, "blobs", &up).ok());
  v1::QueryRequest r;
  r.set_asset_id(up.asset_id());
  r.mutable_grid()->set_voxel_size(1.0);
  r.set_limit(4.0);
  r.set_closest_feature(true);
  const Streamed vol = stream(cluster.coordinator->client(), r, -1.0f);
  ASSERT_TRUE(vol.result.status.ok()) << vol.result.status.error_message();
  EXPECT_EQ(vol.result.header.closest_feature(), v1::CLOSEST_FEATURE_VOXEL);
  const Grid& grid = vol.field->grid();
  int64_t checked = 0, wrong = 0;
  for (int z = 0; z < vdims.z; ++z)
    for (int y = 0; y < vdims.y; ++y)
      for (int x = 0; x < vdims.x; ++x) {
        const int64_t id = vol.closest[size_t(grid.denseIndex({x, y, z}))];
        if (id < 0) continue;
        ++checked;
        const Coord s{int(id % vdims.x), int(id / vdims.x % vdims.y), int(id / (int64_t(vdims.x) * vdims.y))};
        const double d = (Vec3d{double(x), double(y), double(z)} - Vec3d{double(s.x), double(s.y), double(s.z)}).length();
        wrong += !mask[size_t(id)] || std::abs(d - vol.field->at({x, y, z})) > 1e-5;
      }
  EXPECT_GT(checked, 30000);
  EXPECT_EQ(wrong, 0);
}

TEST(ScaleOutTest, ReplicasNamedHostPortAreResolvedByTheCoordinator) {
  std::vector<std::unique_ptr<TestServer>> replicas;
  std::string peers;
  for (int i = 0; i < 3; ++i) {
    replicas.push_back(std::make_unique<TestServer>());
    peers += (i ? ",localhost:" : "localhost:") + std::to_string(replicas.back()->server().port());
  }
  ServerOptions o = TestServer::defaults();
  o.peers = peers;  // names, as compose gives them: resolved by the coordinator, not by gRPC
  o.tile_voxels = 32 * 32 * 32;
  TestServer coordinator(o);
  v1::ServerInfo info;
  ASSERT_TRUE(coordinator.client().info(&info).ok());
  EXPECT_EQ(info.replicas(), 3u);
  EXPECT_EQ(info.tile_voxels(), 32u * 32 * 32);
  const v1::QueryRequest request = pointsRequest(randomPoints(60, 48.0, 9), {96, 96, 96}, 0.5, 1.0, 3.0);
  const Streamed one = stream(replicas[0]->client(), request, -1.0f);
  const Streamed many = stream(coordinator.client(), request, -1.0f);
  expectWellOrdered(many);
  const Comparison c = compare(*one.field, *many.field);
  EXPECT_EQ(c.identical, c.voxels);
  // Every replica computed tiles (a handler reports just after its stream ends: wait for it).
  for (size_t i = 1; i < replicas.size(); ++i) EXPECT_TRUE(replicas[i]->waitRecords(1, std::chrono::seconds(2)));
  EXPECT_TRUE(replicas[0]->waitRecords(2, std::chrono::seconds(2)));
}

TEST(ScaleOutTest, TheCoordinatorSendsItsPeerTokenToReplicasThatRequireOne) {
  const std::string token_file = ::testing::TempDir() + "scale_out_tokens_" + std::to_string(::getpid());
  std::ofstream(token_file) << "# replicas' token\n\n  replica-token-0123456789  \n";
  std::vector<std::unique_ptr<TestServer>> replicas;
  std::vector<std::string> targets;
  for (int i = 0; i < 2; ++i) {
    ServerOptions o = TestServer::defaults();
    o.auth_token_file = token_file;
    replicas.push_back(std::make_unique<TestServer>(o));
    targets.push_back(replicas.back()->target());
  }
  const v1::QueryRequest request = pointsRequest({{5, 5, 5}, {20, 9, 14}}, {64, 64, 32}, 0.5, 0, 3.0);
  ServerOptions with = coordinatorOptions(targets, 32 * 32 * 32);
  with.peer_token_file = token_file;
  TestServer coordinator(with);
  const Streamed ok = stream(coordinator.client(), request, -1.0f);
  EXPECT_TRUE(ok.result.status.ok()) << ok.result.status.error_message();
  EXPECT_GT(ok.result.summary.voxels(), 0u);
  ServerOptions without = coordinatorOptions(targets, 32 * 32 * 32);
  without.tile_retries = 0;
  TestServer bare(without);
  const Streamed refused = stream(bare.client(), request, -1.0f);
  // A replica that refuses the coordinator is its misconfiguration, not a busy replica: INTERNAL, not retried.
  EXPECT_EQ(refused.result.status.error_code(), grpc::StatusCode::INTERNAL);
  EXPECT_NE(refused.result.status.error_message().find("UNAUTHENTICATED"), std::string::npos)
      << refused.result.status.error_message();
  std::remove(token_file.c_str());
}

TEST(ScaleOutTest, PeerTargetsResolveToEveryReplica) {
  std::string error;
  EXPECT_EQ(resolveReplicaAddresses("ipv4:10.0.0.1:5001,10.0.0.2:5002", &error),
            (std::vector<std::string>{"ipv4:10.0.0.1:5001", "ipv4:10.0.0.2:5002"}));
  const auto named = resolveReplicaAddresses("127.0.0.1:7001,127.0.0.2:7002", &error);
  EXPECT_EQ(named, (std::vector<std::string>{"ipv4:127.0.0.1:7001", "ipv4:127.0.0.2:7002"})) << error;
  EXPECT_EQ(resolveReplicaAddresses("dns:///127.0.0.1:7001", &error), (std::vector<std::string>{"ipv4:127.0.0.1:7001"}));
  EXPECT_TRUE(resolveReplicaAddresses("no-port-here", &error).empty());
  EXPECT_NE(error.find("expected"), std::string::npos);
  EXPECT_TRUE(resolveReplicaAddresses("no-such-host.invalid:5000", &error).empty());
  EXPECT_NE(error.find("cannot resolve"), std::string::npos) << error;
  // A malformed --peers stops the server at start, naming the flag.
  ServerOptions o = TestServer::defaults();
  o.listen_address = "127.0.0.1:0";
  o.peers = "nonsense";
  DistbandServer server(o);
  const grpc::Status s = server.start();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("--peers"), std::string::npos);
}

void setBox(v1::VoxelBox* b, int x, int y, int z, int sx, int sy, int sz) {
  b->set_min_x(x), b->set_min_y(y), b->set_min_z(z);
  b->set_size_x(sx), b->set_size_y(sy), b->set_size_z(sz);
}

TEST(ScaleOutTest, TileRequestsAreValidatedFieldByField) {
  TestServer server;
  auto check = [&](const v1::QueryRequest& r, grpc::StatusCode code, const std::string& words) {
    const Streamed s = stream(server.client(), r, -1.0f);
    EXPECT_EQ(s.result.status.error_code(), code) << s.result.status.error_message();
    EXPECT_NE(s.result.status.error_message().find(words), std::string::npos) << s.result.status.error_message();
  };
  v1::QueryRequest r = pointsRequest({{5, 5, 5}}, {64, 64, 60}, 1.0, 0, 3.0);
  setBox(r.mutable_tile()->mutable_window(), 0, 0, 0, 32, 32, 32);
  setBox(r.mutable_tile()->mutable_deliver(), 4, 0, 0, 8, 8, 8);
  check(r, grpc::StatusCode::INVALID_ARGUMENT, "tile.deliver.min_x must be a multiple of 8");
  setBox(r.mutable_tile()->mutable_deliver(), 0, 0, 0, 8, 8, 7);
  check(r, grpc::StatusCode::INVALID_ARGUMENT, "tile.deliver: min_z + size_z must be a multiple of 8 or the grid's extent");
  setBox(r.mutable_tile()->mutable_deliver(), 32, 0, 0, 8, 8, 8);
  check(r, grpc::StatusCode::INVALID_ARGUMENT, "tile.deliver must lie inside tile.window");
  setBox(r.mutable_tile()->mutable_window(), 0, 0, 40, 64, 64, 24);
  check(r, grpc::StatusCode::INVALID_ARGUMENT, "tile.window: min_z + size_z must lie in [1, grid dims.z = 60]");
  // The budget applies to the window: a huge grid whose window is small is fine, a window beyond it is not.
  ServerOptions small = TestServer::defaults();
  small.max_voxels_per_query = 40000;
  TestServer budget(small);
  v1::QueryRequest big = pointsRequest({{5, 5, 5}}, {4096, 4096, 4096}, 1.0, 0, 3.0);
  setBox(big.mutable_tile()->mutable_window(), 0, 0, 0, 32, 32, 32);
  setBox(big.mutable_tile()->mutable_deliver(), 0, 0, 0, 16, 16, 16);
  RemoteQueryCallbacks count_only;  // no dense field: the whole grid is 4096^3
  const RemoteQueryResult ok = budget.client().query(big, count_only);
  ASSERT_TRUE(ok.status.ok()) << ok.status.error_message();
  EXPECT_EQ(ok.header.dims().x(), 4096u);  // the header describes the whole grid
  EXPECT_GT(ok.summary.voxels(), 0u);
  setBox(big.mutable_tile()->mutable_window(), 0, 0, 0, 48, 48, 48);
  const RemoteQueryResult over = budget.client().query(big, count_only);
  EXPECT_EQ(over.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(over.status.error_message().find("tile.window"), std::string::npos);
  // Volume seeds of a tile cover its window.
  v1::QueryRequest vol;
  vol.mutable_volume()->mutable_dims()->set_x(16), vol.mutable_volume()->mutable_dims()->set_y(16);
  vol.mutable_volume()->mutable_dims()->set_z(16);
  vol.mutable_volume()->set_mask(std::string(16 * 16 * 16, '\1'));
  vol.mutable_grid()->set_voxel_size(1.0);
  vol.mutable_grid()->mutable_dims()->set_x(64), vol.mutable_grid()->mutable_dims()->set_y(64);
  vol.mutable_grid()->mutable_dims()->set_z(64);
  setBox(vol.mutable_tile()->mutable_window(), 0, 0, 0, 32, 32, 32);
  setBox(vol.mutable_tile()->mutable_deliver(), 0, 0, 0, 16, 16, 16);
  check(vol, grpc::StatusCode::INVALID_ARGUMENT, "a tile's volume covers its window: dims must be 32x32x32");
  // A coordinator makes its own tiles.
  Cluster cluster;
  const Streamed refused = stream(cluster.coordinator->client(), r, -1.0f);
  EXPECT_EQ(refused.result.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(refused.result.status.error_message().find("coordinator"), std::string::npos);
}

std::vector<uint8_t> blobMask(const Coord& dims) {
  std::vector<uint8_t> mask(size_t(dims.x) * dims.y * dims.z, 0);
  const Vec3d centres[3] = {{20, 22, 18}, {50, 40, 30}, {30, 55, 45}};
  const double radii[3] = {9, 13, 7};
  for (int z = 0; z < dims.z; ++z)
    for (int y = 0; y < dims.y; ++y)
      for (int x = 0; x < dims.x; ++x)
        for (int b = 0; b < 3; ++b)
          if ((Vec3d{double(x), double(y), double(z)} - centres[b]).length() <= radii[b])
            mask[(size_t(z) * dims.y + y) * dims.x + x] = 1;
  return mask;
}

void expectClose(const Comparison& c, const char* what) {
  std::printf("%s: %lld of %lld voxels identical, max difference %.4f voxel, %lld sign differences\n", what,
              (long long)c.identical, (long long)c.voxels, c.max_diff, (long long)c.sign_flips);
  EXPECT_GE(double(c.identical), 0.9999 * double(c.voxels)) << what << ": " << c.voxels - c.identical << " differ";
  EXPECT_LE(c.max_diff, 0.05) << what;
  EXPECT_EQ(c.sign_flips, 0) << what;
}

TEST(ScaleOutTest, SignedVolumeMatchesOneServer) {
  Cluster cluster;
  const Coord dims{72, 70, 64};
  const auto mask = blobMask(dims);
  for (double limit : {4.0, 0.0}) {
    v1::UploadReply up_one, up_many;
    ASSERT_TRUE(cluster.replicas[0]->client().uploadVolumeBytes(dims, v1::VOXEL_TYPE_UINT8, mask, "blobs", &up_one).ok());
    ASSERT_TRUE(cluster.coordinator->client().uploadVolumeBytes(dims, v1::VOXEL_TYPE_UINT8, mask, "blobs", &up_many).ok());
    v1::QueryRequest r;
    r.set_sign(v1::SIGN_MODE_MASK_INSIDE);
    r.mutable_grid()->set_voxel_size(1.0);
    r.set_limit(limit);
    r.set_segment_length(2.0);
    r.set_asset_id(up_one.asset_id());
    const Streamed one = stream(cluster.replicas[0]->client(), r, -1.0f);
    r.set_asset_id(up_many.asset_id());
    const Streamed many = stream(cluster.coordinator->client(), r, -1.0f);
    expectWellOrdered(one);
    expectWellOrdered(many);
    expectClose(compare(*one.field, *many.field), limit > 0 ? "volume, limit 4" : "volume, no limit");
  }
}

TEST(ScaleOutTest, MeshMatchesOneServer) {
  Cluster cluster(24 * 24 * 24);
  const std::string bunny = std::string(DISTBAND_TEST_DATA_DIR) + "/meshes/bunny.obj";
  v1::UploadReply up_one, up_many;
  ASSERT_TRUE(cluster.replicas[0]->client().uploadMeshFile(bunny, &up_one).ok());
  ASSERT_TRUE(cluster.coordinator->client().uploadMeshFile(bunny, &up_many).ok());
  v1::QueryRequest r;
  r.mutable_grid()->set_resolution(80);
  r.mutable_grid()->set_padding(3);  // fixed, so the probe's voxel size stays the grid's with the limit below
  r.set_limit(0.0);  // set below in world units
  // Limit of 4 voxels: the grid is resolved the same way by both (voxel size from the first query's header).
  r.set_asset_id(up_one.asset_id());
  const Streamed probe = stream(cluster.replicas[0]->client(), r, 0.0f);
  ASSERT_TRUE(probe.result.status.ok());
  const double h = probe.result.header.voxel_size();
  r.set_limit(4 * h);
  r.set_segment_length(1.5 * h);
  const Streamed one = stream(cluster.replicas[0]->client(), r, -1.0f);
  r.set_asset_id(up_many.asset_id());
  const Streamed many = stream(cluster.coordinator->client(), r, -1.0f);
  expectWellOrdered(one);
  expectWellOrdered(many);
  EXPECT_EQ(many.result.header.dims().x(), one.result.header.dims().x());
  expectClose(compare(*one.field, *many.field), "bunny, limit 4 voxels");
  EXPECT_GT(one.result.summary.voxels(), 10000u);
}

/// Replicas as processes (so they can be killed or stopped), 1 thread each.
bool startChildReplicas(int n, std::vector<std::unique_ptr<ChildServer>>* replicas, std::vector<std::string>* targets) {
  for (int i = 0; i < n; ++i) {
    replicas->push_back(std::make_unique<ChildServer>(DISTBAND_SERVER_BINARY, std::vector<std::string>{
                                                          "--threads", "1", "--memory-budget", "2G"}));
    if (replicas->back()->port() == 0) {
      ADD_FAILURE() << replicas->back()->log();
      return false;
    }
    targets->push_back(replicas->back()->target());
  }
  return true;
}

TEST(ScaleOutTest, AReplicaKilledMidQueryCostsARetryNotTheField) {
  // Replicas as processes, so one can be SIGKILLed; small tiles and a slow-enough query so the kill lands mid-way.
  std::vector<std::unique_ptr<ChildServer>> replicas;
  std::vector<std::string> targets;
  ASSERT_TRUE(startChildReplicas(3, &replicas, &targets));
  ServerOptions o = coordinatorOptions(targets, 32 * 32 * 32);
  o.tiles_in_flight_per_replica = 1;
  TestServer coordinator(o);
  const Coord dims{128, 128, 128};
  const auto points = randomPoints(40, 64.0, 11);
  const v1::QueryRequest request = pointsRequest(points, dims, 0.5, 1.0, 8.0);

  RemoteClient direct(targets[1]);
  const Streamed one = stream(direct, request, -1.0f);
  ASSERT_TRUE(one.result.status.ok());
  bool killed = false;
  // Replica 0 is stopped before the query, so the tile it is sent hangs there, unanswered, until the kill at the first
  // batch (the others' work): the kill always finds a tile in flight with nothing of it merged. Killed while running,
  // it had sometimes just streamed its tile whole (then kept, not retried) or run out of tiles: ~1 run in 6 saw no
  // retry.
  replicas[0]->signal(SIGSTOP);
  const Streamed many = stream(coordinator.client(), request, -1.0f, [&](int batches) {
    if (!killed && batches == 1) {
      replicas[0]->signal(SIGKILL);
      killed = true;
    }
    return true;
  });
  EXPECT_TRUE(killed);
  expectWellOrdered(many);
  const Comparison c = compare(*one.field, *many.field);
  EXPECT_EQ(c.identical, c.voxels) << "max diff " << c.max_diff;
  ASSERT_TRUE(coordinator.waitRecords(1));
  EXPECT_GE(coordinator.records().back().tile_retries, 1) << "the killed replica's tiles should have been retried";
  EXPECT_GT(coordinator.records().back().tiles, 6);
}

TEST(ScaleOutTest, AStalledReplicaIsNotWaitedOnPastTheTileTimeout) {
  // A replica that accepts calls and never answers (SIGSTOP: its connections stay up, so round_robin keeps it).
  std::vector<std::unique_ptr<ChildServer>> replicas;
  std::vector<std::string> targets;
  ASSERT_TRUE(startChildReplicas(3, &replicas, &targets));
  ServerOptions o = coordinatorOptions(targets, 32 * 32 * 32);
  o.tile_timeout_seconds = 1.0;
  TestServer coordinator(o);
  const v1::QueryRequest request = pointsRequest(randomPoints(40, 48.0, 13), {96, 96, 96}, 0.5, 1.0, 4.0);
  RemoteClient direct(targets[1]);
  const Streamed one = stream(direct, request, -1.0f);
  ASSERT_TRUE(one.result.status.ok());
  {  // the coordinator has connected to every replica before one of them stalls
    v1::ServerInfo info;
    ASSERT_TRUE(coordinator.client().info(&info).ok());
  }
  replicas[2]->signal(SIGSTOP);
  const auto t0 = Clock::now();
  const Streamed many = stream(coordinator.client(), request, -1.0f);
  const double seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  replicas[2]->signal(SIGCONT);
  expectWellOrdered(many);
  const Comparison c = compare(*one.field, *many.field);
  EXPECT_EQ(c.identical, c.voxels);
  ASSERT_TRUE(coordinator.waitRecords(1));
  EXPECT_GE(coordinator.records().back().tile_retries, 1);
  // Each stalled tile costs one tile timeout (1 s) before its retry elsewhere, not the query's whole life.
  EXPECT_LT(seconds, 8.0);
  std::printf("a stalled replica: %d tiles retried elsewhere, the query took %.2f s (tile timeout 1 s)\n",
              coordinator.records().back().tile_retries, seconds);
}

TEST(ScaleOutTest, ATileThatCannotBeComputedAnywhereEndsInUnavailable) {
  // Replicas that refuse the tiles (a voxel budget below a tile's window) exhaust the retries.
  std::vector<std::unique_ptr<TestServer>> replicas;
  std::vector<std::string> targets;
  for (int i = 0; i < 2; ++i) {
    ServerOptions o = TestServer::defaults();
    o.max_voxels_per_query = 1000;
    replicas.push_back(std::make_unique<TestServer>(o));
    targets.push_back(replicas.back()->target());
  }
  ServerOptions o = coordinatorOptions(targets, 32 * 32 * 32);
  o.tile_retries = 2;
  TestServer coordinator(o);
  const Streamed s = stream(coordinator.client(), pointsRequest({{5, 5, 5}}, {64, 64, 64}, 1.0, 0, 3.0), -1.0f);
  EXPECT_EQ(s.result.status.error_code(), grpc::StatusCode::UNAVAILABLE) << s.result.status.error_message();
  EXPECT_NE(s.result.status.error_message().find("after 3 attempts"), std::string::npos)
      << s.result.status.error_message();
  EXPECT_NE(s.result.status.error_message().find("voxel budget"), std::string::npos);
}

TEST(ScaleOutTest, CancelAtTheCoordinatorStopsEveryTileWithin100ms) {
  // Unlimited point seeds on a large grid in tiles of 160^3 (8 tiles, 4 M voxels each): every tile computes for a
  // while (hundreds of milliseconds on one thread), so the cancel finds tiles running on every replica.
  Cluster cluster(160 * 160 * 160);
  const v1::QueryRequest request = pointsRequest(randomPoints(30, 160.0, 5), {320, 320, 320}, 0.5, 0, 0);
  QueryCanceller canceller;
  RemoteQueryOptions options;
  options.canceller = &canceller;
  std::thread cancel([&] {
    // Cancel once tiles are computing on every replica.
    const auto end = Clock::now() + std::chrono::seconds(20);
    while (Clock::now() < end) {
      int busy = 0;
      for (auto& r : cluster.replicas) busy += r->server().service().activeQueries() > 0;
      if (busy == 3) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    canceller.cancel();
  });
  RemoteQueryCallbacks cb;
  const RemoteQueryResult r = cluster.coordinator->client().query(request, cb, options);
  cancel.join();
  EXPECT_EQ(r.status.error_code(), grpc::StatusCode::CANCELLED);
  ASSERT_TRUE(cluster.coordinator->waitRecords(1));
  const auto cancel_time = canceller.cancelTime();
  // Every tile that was running stopped its engine within 100 ms of the client's cancel.
  size_t running = 0;
  double worst_ms = 0;
  for (auto& replica : cluster.replicas) {
    const auto end = Clock::now() + std::chrono::seconds(5);
    while (Clock::now() < end && replica->server().service().activeQueries() > 0)
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    for (const QueryRecord& rec : replica->records()) {
      if (!rec.engine_ran || !rec.interrupted) continue;
      ++running;
      const double stop_ms = ms(rec.engine_stopped - cancel_time);
      EXPECT_LT(stop_ms, testing::latencyBoundMs(100.0))
          << "a tile's engine stopped " << stop_ms << " ms after the cancel";
      worst_ms = std::max(worst_ms, stop_ms);
    }
  }
  EXPECT_GE(running, 3u);
  std::printf("cancel at the coordinator: %zu running tiles, the last engine stopped %.1f ms after the client's cancel\n",
              running, worst_ms);
}

}  // namespace
}  // namespace distband
