// Integration tests of the distband service: a real DistbandServer on 127.0.0.1 port 0, driven by the real
// client library (client/remote_client.h). The streamed field is compared bit for bit with the in-process
// engine on the same grid and seeds.
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "client/remote_client.h"
#include "core/io/dense_field.h"
#include "core/band/band_engine.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/mesh_seeds.h"
#include "core/seeds/point_seeds.h"
#include "core/seeds/volume_seeds.h"
#include "proto/brick_codec.h"
#include "server/server.h"
#include "tests/integration/service_fixture.h"
#include "tests/support/status_testing.h"
#include "tests/support/build_flavor.h"
#include "tests/support/exact_edt.h"

namespace distband {
namespace {


DenseField reference(const Grid& grid, const Seeds& seeds, BandOptions options, float background) {
  DenseField f(grid, background);
  options.threads = 1;
  computeBandField(grid, seeds, options, [&](SegmentBricks&& s) { f.add(s); });
  return f;
}

void expectBitIdentical(const DenseField& a, const DenseField& b) {
  ASSERT_EQ(a.values().size(), b.values().size());
  size_t diff = 0, first = 0;
  for (size_t i = 0; i < a.values().size(); ++i)
    if (std::memcmp(&a.values()[i], &b.values()[i], sizeof(float)) != 0 && diff++ == 0) first = i;
  EXPECT_EQ(diff, 0u) << "first difference at " << first << ": " << a.values()[first] << " vs " << b.values()[first];
  EXPECT_EQ(a.written(), b.written());
}

// A closed, outward-oriented cube [lo, hi]^3 as OBJ text.
std::string cubeObj(double lo, double hi) {
  std::string s;
  for (int i = 0; i < 8; ++i)
    s += "v " + std::to_string(i & 1 ? hi : lo) + " " + std::to_string(i & 2 ? hi : lo) + " " +
         std::to_string(i & 4 ? hi : lo) + "\n";
  s += "f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n";
  return s;
}

// A closed mesh with one face (two triangles) reversed is repaired on upload, and the reply says so.
TEST(ServiceTest, MeshUploadReportsReorientedFaces) {
  TestServer ts;
  std::string obj = cubeObj(-1.0, 1.0);
  const size_t face = obj.find("f 1 3 4 2");
  ASSERT_NE(face, std::string::npos);
  obj.replace(face, 9, "f 1 2 4 3");
  v1::UploadReply up;
  grpc::Status st = ts.client().uploadMesh(obj, v1::MESH_FORMAT_OBJ, "flipped.obj", &up);
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(up.mesh().boundary_edges(), 0u);
  EXPECT_EQ(up.mesh().reoriented_faces(), 2u);
  v1::UploadReply intact;
  st = ts.client().uploadMesh(cubeObj(-1.0, 1.0), v1::MESH_FORMAT_OBJ, "cube.obj", &intact);
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(intact.mesh().reoriented_faces(), 0u);
}

TEST(ServiceTest, PointQueryStreamsTheInProcessFieldBitForBit) {
  TestServer ts;
  const Coord dims{48, 40, 56};
  const double h = 0.5, limit = 9.0, segment = 2.0;
  const std::vector<Vec3d> pts{{5.2, 6.1, 7.7}, {18.0, 12.5, 20.3}};
  Streamed s = stream(ts.client(), pointsRequest(pts, dims, h, segment, limit), float(limit));
  ASSERT_TRUE(s.result.status.ok()) << s.result.status.error_message();
  EXPECT_TRUE(s.order_error.empty()) << s.order_error;
  ASSERT_TRUE(s.result.have_summary);

  const Grid grid({0, 0, 0}, h, dims);
  Seeds seeds;
  ASSERT_TRUE(IsOk(makePointSeeds(grid, pts, &seeds)));
  BandOptions o;
  o.segment_length_world = segment;
  o.limit_world = limit;
  const DenseField ref = reference(grid, seeds, o, float(limit));
  expectBitIdentical(*s.field, ref);
  EXPECT_EQ(s.result.summary.voxels(), uint64_t(ref.written()));
  EXPECT_GT(s.done.size(), 3u);
  EXPECT_TRUE(s.done.back().last());
  EXPECT_EQ(int(s.result.summary.segments_size()), int(s.done.size()));
}

TEST(ServiceTest, Float16EncodingRoundsEachValue) {
  TestServer ts;
  const Coord dims{32, 32, 32};
  const std::vector<Vec3d> pts{{10.3, 11.2, 12.9}};
  v1::QueryRequest r = pointsRequest(pts, dims, 1.0, 0, 0);
  r.set_encoding(v1::BRICK_ENCODING_FLOAT16);
  Streamed s = stream(ts.client(), r, std::numeric_limits<float>::infinity());
  ASSERT_TRUE(s.result.status.ok()) << s.result.status.error_message();
  EXPECT_EQ(s.result.header.encoding(), v1::BRICK_ENCODING_FLOAT16);
  const Grid grid({0, 0, 0}, 1.0, dims);
  Seeds seeds;
  ASSERT_TRUE(IsOk(makePointSeeds(grid, pts, &seeds)));
  DenseField ref = reference(grid, seeds, BandOptions{}, std::numeric_limits<float>::infinity());
  for (float& v : ref.values()) v = halfToFloat(floatToHalf(v));
  expectBitIdentical(*s.field, ref);
}

// A few points without a limit take the separable point EDT: the header says so, and the stream equals the band's
// field bit for bit, closest points included, nearest segment first.
TEST(ServiceTest, FewPointsWithoutLimitAreTheSeparablePointEdtBitForBit) {
  TestServer ts;
  const Coord dims{41, 35, 30};
  const double h = 0.5;
  const std::vector<Vec3d> pts{{5.2, 6.1, 7.7}, {18.0, 12.5, 7.7}, {9.0, 12.5, 7.7}, {30.0, -4.0, 40.0}};
  v1::QueryRequest r = pointsRequest(pts, dims, h, 3.0, 0);
  r.set_closest_feature(true);
  Streamed s = stream(ts.client(), r, NAN);
  ASSERT_TRUE(s.result.status.ok()) << s.result.status.error_message();
  EXPECT_EQ(s.result.header.algorithm(), "separable");
  EXPECT_TRUE(s.order_error.empty()) << s.order_error;
  EXPECT_GT(s.done.size(), 3u);
  const Grid grid({0, 0, 0}, h, dims);
  Seeds seeds;
  ASSERT_TRUE(IsOk(makePointSeeds(grid, pts, &seeds)));
  BandOptions o;
  o.segment_length_world = 3.0;
  expectBitIdentical(*s.field, reference(grid, seeds, o, NAN));
  ASSERT_EQ(s.closest.size(), size_t(grid.voxelCount()));
  int64_t wrong_closest = 0;
  for (int64_t i = 0; i < grid.voxelCount(); ++i) {
    const int64_t id = s.closest[size_t(i)];
    const Vec3d v{double(i % dims.x), double(i / dims.x % dims.y), double(i / (int64_t(dims.x) * dims.y))};
    wrong_closest += id < 0 || id >= int64_t(pts.size()) ||
                     std::abs(std::sqrt((v - seeds.points[size_t(id)]).lengthSqr()) * h - s.field->values()[size_t(i)]) > 1e-5;
  }
  EXPECT_EQ(wrong_closest, 0);
}

TEST(ServiceTest, VolumeUploadAndSignedQueryMatchInProcess) {
  TestServer ts;
  const Coord dims{40, 36, 32};
  std::vector<uint8_t> mask(size_t(dims.x) * dims.y * dims.z, 0);
  for (int z = 0; z < dims.z; ++z)
    for (int y = 0; y < dims.y; ++y)
      for (int x = 0; x < dims.x; ++x) {
        const double d1 = std::hypot(x - 14.0, y - 17.0, z - 15.0), d2 = std::hypot(x - 26.0, y - 19.0, z - 16.0);
        mask[(size_t(z) * dims.y + y) * dims.x + x] = d1 < 7.5 || d2 < 6.0;
      }
  v1::UploadReply up;
  grpc::Status st = ts.client().uploadVolumeBytes(dims, v1::VOXEL_TYPE_UINT8, mask, "blobs", &up);
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(up.asset_id().rfind("volume-", 0), 0u);
  EXPECT_FALSE(up.already_cached());
  v1::UploadReply again;
  ASSERT_TRUE(ts.client().uploadVolumeBytes(dims, v1::VOXEL_TYPE_UINT8, mask, "blobs", &again).ok());
  EXPECT_TRUE(again.already_cached());
  EXPECT_EQ(again.asset_id(), up.asset_id());

  v1::QueryRequest r;
  r.set_asset_id(up.asset_id());
  r.mutable_grid()->set_voxel_size(0.25);
  r.set_sign(v1::SIGN_MODE_MASK_INSIDE);
  r.set_segment_length(0.5);
  r.set_limit(3.0);
  Streamed s = stream(ts.client(), r, 3.0f);
  ASSERT_TRUE(s.result.status.ok()) << s.result.status.error_message();
  EXPECT_TRUE(s.order_error.empty()) << s.order_error;
  EXPECT_TRUE(s.result.header.signed_());

  const Grid grid({0, 0, 0}, 0.25, dims);
  Seeds seeds;
  ASSERT_TRUE(IsOk(makeVolumeSeeds(grid, LabelVolume::ofMask(grid.dims(), mask), true, &seeds)));
  BandOptions o;
  o.segment_length_world = 0.5;
  o.limit_world = 3.0;
  expectBitIdentical(*s.field, reference(grid, seeds, o, 3.0f));
  bool any_negative = false;
  for (float v : s.field->values()) any_negative |= v < 0;
  EXPECT_TRUE(any_negative);
}

// A volume in exact mode takes the separable EDT: the server says so in the header, and the streamed field equals the
// exact EDT (tests/support/exact_edt) at every voxel (whole grid) or at every voxel within the limit, nearest segment
// first.
TEST(ServiceTest, WholeGridVolumeIsTheExactSeparableEdt) {
  TestServer ts;
  const Coord dims{37, 30, 26};
  std::vector<uint8_t> mask(size_t(dims.x) * dims.y * dims.z, 0);
  for (int z = 0; z < dims.z; ++z)
    for (int y = 0; y < dims.y; ++y)
      for (int x = 0; x < dims.x; ++x)
        mask[(size_t(z) * dims.y + y) * dims.x + x] = std::hypot(x - 12.0, y - 15.0, z - 11.0) < 6.5 || (x == 30 && y == 5);
  v1::QueryRequest r;
  r.mutable_volume()->mutable_dims()->set_x(uint32_t(dims.x));
  r.mutable_volume()->mutable_dims()->set_y(uint32_t(dims.y));
  r.mutable_volume()->mutable_dims()->set_z(uint32_t(dims.z));
  r.mutable_volume()->set_mask(std::string(mask.begin(), mask.end()));
  r.mutable_grid()->set_voxel_size(0.5);
  r.set_sign(v1::SIGN_MODE_MASK_INSIDE);
  r.set_segment_length(2.0);
  Streamed s = stream(ts.client(), r, NAN);
  ASSERT_TRUE(s.result.status.ok()) << s.result.status.error_message();
  EXPECT_EQ(s.result.header.algorithm(), "separable");
  EXPECT_TRUE(s.order_error.empty()) << s.order_error;
  EXPECT_GT(s.done.size(), 3u);
  const std::vector<double> exact = oracle::signedEdt(dims.x, dims.y, dims.z, mask);
  int64_t wrong = 0;
  for (size_t i = 0; i < exact.size(); ++i) wrong += !(std::abs(s.field->values()[i] - 0.5 * exact[i]) <= 1e-5);
  EXPECT_EQ(wrong, 0);
  // A limit: the separable passes over the bricks within it, exact there and nothing beyond (background NaN).
  r.set_limit(1.6);
  const Streamed limited = stream(ts.client(), r, NAN);
  ASSERT_TRUE(limited.result.status.ok()) << limited.result.status.error_message();
  EXPECT_EQ(limited.result.header.algorithm(), "separable");
  EXPECT_TRUE(limited.order_error.empty()) << limited.order_error;
  int64_t wrong_within = 0, beyond = 0, within = 0;
  for (size_t i = 0; i < exact.size(); ++i) {
    const float got = limited.field->values()[i];
    if (std::abs(0.5 * exact[i]) > 1.6) {
      beyond += !std::isnan(got);
      continue;
    }
    ++within;
    wrong_within += !(std::abs(got - 0.5 * exact[i]) <= 1e-5);
  }
  EXPECT_GT(within, 1000);
  EXPECT_EQ(wrong_within, 0);
  EXPECT_EQ(beyond, 0);
}

TEST(ServiceTest, MeshUploadInChunksAndQueryMatchInProcess) {
  RemoteClientOptions co;
  co.upload_chunk_bytes = 64;  // force many chunks
  TestServer ts;
  RemoteClient client("127.0.0.1:" + std::to_string(ts.server().port()), co);
  const std::string obj = cubeObj(-1.0, 1.0);
  v1::UploadReply up;
  grpc::Status st = client.uploadMesh(obj, v1::MESH_FORMAT_OBJ, "cube.obj", &up);
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(up.mesh().triangles(), 12u);
  EXPECT_EQ(up.mesh().boundary_edges(), 0u);

  v1::QueryRequest r;
  r.set_asset_id(up.asset_id());
  r.mutable_grid()->set_resolution(40);
  r.mutable_grid()->set_padding(4);
  r.set_segment_length(0.1);
  r.set_limit(0.35);
  Streamed s = stream(client, r, 0.35f);
  ASSERT_TRUE(s.result.status.ok()) << s.result.status.error_message();
  EXPECT_TRUE(s.order_error.empty()) << s.order_error;
  EXPECT_EQ(s.result.header.sign(), v1::SIGN_MODE_PSEUDONORMAL);
  // The summary says how the voxels were signed: all of them by the pseudonormal test here.
  EXPECT_GT(s.result.summary.voxels(), 0u);
  EXPECT_EQ(s.result.summary.sign_shares().pseudonormal(), s.result.summary.voxels());
  EXPECT_EQ(s.result.summary.sign_shares().winding_certified() + s.result.summary.sign_shares().winding_per_voxel() +
                s.result.summary.sign_shares().parity(),
            0u);

  // The same pipeline in-process: parse, grid, seeds, engine.
  const std::string path = (std::filesystem::temp_directory_path() / "distband_service_test_cube.obj").string();
  std::ofstream(path) << obj;
  TriangleMesh mesh;
  ASSERT_TRUE(IsOk(loadMesh(path, &mesh, nullptr)));
  std::filesystem::remove(path);
  MeshGridOptions mo;
  mo.resolution = 40;
  mo.padding_voxels = 4;
  Grid grid;
  ASSERT_TRUE(IsOk(gridForMesh(mesh, mo, {}, &grid)));
  EXPECT_EQ(s.result.grid.dims(), grid.dims());
  EXPECT_EQ(s.result.grid.origin(), grid.origin());
  EXPECT_EQ(s.result.grid.voxelSize(), grid.voxelSize());
  MeshSeedOptions so;
  so.limit_voxels = 0.35 / grid.voxelSize();
  Seeds seeds;
  ASSERT_TRUE(IsOk(makeMeshSeeds(grid, mesh, so, &seeds)));
  BandOptions o;
  o.segment_length_world = 0.1;
  o.limit_world = 0.35;
  expectBitIdentical(*s.field, reference(grid, seeds, o, 0.35f));
  // The centre of the cube is inside: its value must be negative (-limit background or a distance).
  bool any_negative = false;
  for (float v : s.field->values()) any_negative |= v < 0;
  EXPECT_TRUE(any_negative);
}

TEST(ServiceTest, FirstSegmentArrivesBeforeTheEngineFinishes) {
  TestServer ts;
  const Coord dims{96, 96, 96};
  Streamed s = stream(ts.client(), pointsRequest({{48, 48, 48}}, dims, 1.0, 4.0, 0), 0);
  ASSERT_TRUE(s.result.status.ok()) << s.result.status.error_message();
  EXPECT_TRUE(s.order_error.empty()) << s.order_error;
  ASSERT_TRUE(ts.waitRecords(1));
  const QueryRecord rec = ts.records()[0];
  EXPECT_LT(s.first_batch, rec.engine_stopped) << "the first bricks reached the client only after compute ended";
  for (size_t i = 1; i < s.batch_segments.size(); ++i) EXPECT_LE(s.batch_segments[i - 1], s.batch_segments[i]);
  std::printf("[ measure  ] 96^3 point query: first bricks at %.1f ms, engine stopped at %.1f ms, total %.1f ms, "
              "%zu segments\n",
              s.result.first_bricks_seconds * 1e3, ms(rec.engine_stopped - rec.received),
              s.result.total_seconds * 1e3, s.done.size());
}

TEST(ServiceTest, ClientCancelStopsTheEngineWithin100ms) {
  ServerOptions o = TestServer::defaults();
  o.batch_bytes = 64 << 10;
  o.stream_buffer_bytes = 64 << 10;
  TestServer ts(o);
  // A large field with short segments; cancel as soon as the first batch is in.
  v1::QueryRequest r = pointsRequest({{10, 10, 10}}, {256, 256, 256}, 1.0, 2.0, 0);
  Streamed s = stream(ts.client(), r, 0, [](int batches) { return batches < 1; });
  EXPECT_EQ(s.result.status.error_code(), grpc::StatusCode::CANCELLED) << s.result.status.error_message();
  ASSERT_TRUE(s.result.cancelled_by_client);
  ASSERT_TRUE(ts.waitRecords(1));
  const QueryRecord rec = ts.records()[0];
  EXPECT_TRUE(rec.engine_ran);
  EXPECT_TRUE(rec.interrupted) << "the engine ran to completion instead of stopping";
  const double stop_ms = ms(rec.engine_stopped - s.result.cancel_time);
  std::printf("[ measure  ] cancel -> engine stopped: %.1f ms (server noticed after %.1f ms)\n", stop_ms,
              ms(rec.cancel_seen - s.result.cancel_time));
  EXPECT_LT(stop_ms, testing::latencyBoundMs(100.0));
  EXPECT_EQ(ts.server().service().activeQueries(), 0);
  // The server keeps serving.
  Streamed again = stream(ts.client(), pointsRequest({{1, 2, 3}}, {16, 16, 16}, 1.0, 0, 0), 0);
  EXPECT_TRUE(again.result.status.ok()) << again.result.status.error_message();
}

TEST(ServiceTest, CancelDuringComputeStopsTheEngineWithin100ms) {
  TestServer ts;
  // One segment over a 320^3 domain: nothing is sent before the engine ends, so the cancel (from another thread,
  // as a SIGINT watcher would) lands while the engine is computing, not while it waits on the queue.
  QueryCanceller canceller;
  std::thread watcher([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(120));
    canceller.cancel();
  });
  RemoteQueryOptions qo;
  qo.canceller = &canceller;
  const auto t0 = Clock::now();
  const RemoteQueryResult r =
      ts.client().query(pointsRequest({{5, 5, 5}}, {320, 320, 320}, 1.0, 0, 0), RemoteQueryCallbacks{}, qo);
  watcher.join();
  EXPECT_EQ(r.status.error_code(), grpc::StatusCode::CANCELLED) << r.status.error_message();
  ASSERT_TRUE(ts.waitRecords(1));
  const QueryRecord rec = ts.records()[0];
  ASSERT_TRUE(rec.interrupted) << "the engine finished before the cancel; make the domain larger";
  const double stop_ms = ms(rec.engine_stopped - r.cancel_time);
  std::printf("[ measure  ] cancel mid-compute (at %.0f ms) -> engine stopped: %.1f ms\n", ms(r.cancel_time - t0),
              stop_ms);
  EXPECT_LT(stop_ms, testing::latencyBoundMs(100.0));
  EXPECT_EQ(ts.server().service().activeQueries(), 0);
}

TEST(ServiceTest, DeadlineStopsTheEngine) {
  TestServer ts;
  RemoteQueryOptions qo;
  qo.deadline = std::chrono::milliseconds(150);
  const RemoteQueryResult r =
      ts.client().query(pointsRequest({{0, 0, 0}}, {384, 384, 384}, 1.0, 1.0, 0), RemoteQueryCallbacks{}, qo);
  EXPECT_EQ(r.status.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  ASSERT_TRUE(ts.waitRecords(1));
  EXPECT_TRUE(ts.records()[0].interrupted);
}

struct BadCase {
  const char* name;
  std::function<void(v1::QueryRequest*)> edit;
  grpc::StatusCode code;
  const char* message_part;
};

TEST(ServiceTest, EachBadInputGetsItsStatusAndTheServerKeepsServing) {
  ServerOptions o = TestServer::defaults();
  o.max_voxels_per_query = 20000;
  TestServer ts(o);
  const std::vector<BadCase> cases = {
      {"no seeds", [](v1::QueryRequest* r) { r->clear_points(); }, grpc::StatusCode::INVALID_ARGUMENT, "seeds"},
      {"empty points", [](v1::QueryRequest* r) { r->mutable_points()->clear_points(); },
       grpc::StatusCode::INVALID_ARGUMENT, "points.points"},
      {"nan point", [](v1::QueryRequest* r) { r->mutable_points()->mutable_points(0)->set_x(NAN); },
       grpc::StatusCode::INVALID_ARGUMENT, "points.points[0]"},
      {"no grid", [](v1::QueryRequest* r) { r->clear_grid(); }, grpc::StatusCode::INVALID_ARGUMENT, "grid"},
      {"zero dim", [](v1::QueryRequest* r) { r->mutable_grid()->mutable_dims()->set_y(0); },
       grpc::StatusCode::INVALID_ARGUMENT, "grid.dims.y"},
      {"huge dim", [](v1::QueryRequest* r) { r->mutable_grid()->mutable_dims()->set_x(20000); },
       grpc::StatusCode::INVALID_ARGUMENT, "grid.dims.x"},
      {"negative voxel size", [](v1::QueryRequest* r) { r->mutable_grid()->set_voxel_size(-1); },
       grpc::StatusCode::INVALID_ARGUMENT, "grid.voxel_size"},
      {"inf voxel size", [](v1::QueryRequest* r) { r->mutable_grid()->set_voxel_size(INFINITY); },
       grpc::StatusCode::INVALID_ARGUMENT, "grid.voxel_size"},
      {"resolution 1",
       [](v1::QueryRequest* r) {
         r->mutable_grid()->clear_dims();
         r->mutable_grid()->set_voxel_size(0);
         r->mutable_grid()->set_resolution(1);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "grid.resolution"},
      {"both sizes",
       [](v1::QueryRequest* r) {
         r->mutable_grid()->clear_dims();
         r->mutable_grid()->set_resolution(32);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "exactly one of voxel_size"},
      {"box inverted",
       [](v1::QueryRequest* r) {
         r->mutable_grid()->clear_dims();
         r->mutable_grid()->mutable_box()->mutable_max()->set_x(-5);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "grid.box.max"},
      {"over voxel budget", [](v1::QueryRequest* r) { r->mutable_grid()->mutable_dims()->set_x(200); },
       grpc::StatusCode::RESOURCE_EXHAUSTED, "voxel budget"},
      {"negative segment", [](v1::QueryRequest* r) { r->set_segment_length(-1); },
       grpc::StatusCode::INVALID_ARGUMENT, "segment_length"},
      {"nan limit", [](v1::QueryRequest* r) { r->set_limit(NAN); }, grpc::StatusCode::INVALID_ARGUMENT, "limit"},
      {"millions of segments", [](v1::QueryRequest* r) { r->set_segment_length(1e-9); },
       grpc::StatusCode::INVALID_ARGUMENT, "segment_length"},
      {"negative limit", [](v1::QueryRequest* r) { r->set_limit(-2); }, grpc::StatusCode::INVALID_ARGUMENT,
       "limit"},
      {"unknown stencil", [](v1::QueryRequest* r) { r->set_stencil(v1::Stencil(42)); },
       grpc::StatusCode::INVALID_ARGUMENT, "stencil"},
      {"unknown mode", [](v1::QueryRequest* r) { r->set_mode(v1::PropagationMode(9)); },
       grpc::StatusCode::INVALID_ARGUMENT, "mode"},
      {"unknown encoding", [](v1::QueryRequest* r) { r->set_encoding(v1::BrickEncoding(7)); },
       grpc::StatusCode::INVALID_ARGUMENT, "encoding"},
      {"signed points", [](v1::QueryRequest* r) { r->set_sign(v1::SIGN_MODE_WINDING); },
       grpc::StatusCode::INVALID_ARGUMENT, "sign"},
      {"unknown asset", [](v1::QueryRequest* r) { r->set_asset_id("mesh-0000"); }, grpc::StatusCode::NOT_FOUND,
       "asset_id"},
      {"volume size mismatch",
       [](v1::QueryRequest* r) {
         r->mutable_volume()->mutable_dims()->set_x(4);
         r->mutable_volume()->mutable_dims()->set_y(4);
         r->mutable_volume()->mutable_dims()->set_z(4);
         r->mutable_volume()->set_mask(std::string(63, '\1'));
         r->mutable_grid()->clear_dims();
       },
       grpc::StatusCode::INVALID_ARGUMENT, "volume"},
      {"empty volume",
       [](v1::QueryRequest* r) {
         r->mutable_volume()->mutable_dims()->set_x(4);
         r->mutable_volume()->mutable_dims()->set_y(4);
         r->mutable_volume()->mutable_dims()->set_z(4);
         r->mutable_volume()->set_mask(std::string(64, '\0'));
         r->mutable_grid()->clear_dims();
       },
       grpc::StatusCode::INVALID_ARGUMENT, "no nonzero"},
      {"garbage mesh",
       [](v1::QueryRequest* r) {
         r->mutable_mesh()->set_format(v1::MESH_FORMAT_OFF);
         r->mutable_mesh()->set_data("OFF\n3 1 0\n0 0 0\n1 0 0\n");
         r->mutable_grid()->clear_dims();
         r->mutable_grid()->set_voxel_size(0.1);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "mesh"},
      {"mesh without format",
       [](v1::QueryRequest* r) {
         r->mutable_mesh()->set_data(cubeObj(0, 1));
         r->mutable_grid()->clear_dims();
       },
       grpc::StatusCode::INVALID_ARGUMENT, "mesh.format"},
      {"mesh with mask sign",
       [](v1::QueryRequest* r) {
         r->mutable_mesh()->set_format(v1::MESH_FORMAT_OBJ);
         r->mutable_mesh()->set_data(cubeObj(0, 1));
         r->mutable_grid()->clear_dims();
         r->set_sign(v1::SIGN_MODE_MASK_INSIDE);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "sign"},
  };
  for (const BadCase& c : cases) {
    v1::QueryRequest r = pointsRequest({{1, 2, 3}}, {16, 16, 16}, 1.0, 0, 0);
    r.mutable_grid()->mutable_box()->mutable_min();  // only used by the box cases (dims cleared there)
    r.mutable_grid()->clear_box();
    if (std::string(c.name) == "box inverted") {
      r.mutable_grid()->mutable_box()->mutable_max()->set_y(1);
      r.mutable_grid()->mutable_box()->mutable_max()->set_z(1);
    }
    c.edit(&r);
    const RemoteQueryResult res = ts.client().query(r, {});
    EXPECT_EQ(res.status.error_code(), c.code) << c.name << ": " << res.status.error_message();
    EXPECT_NE(res.status.error_message().find(c.message_part), std::string::npos)
        << c.name << ": message '" << res.status.error_message() << "' does not name '" << c.message_part << "'";
  }
  // Upload errors.
  v1::UploadReply up;
  EXPECT_EQ(ts.client().uploadMesh("", v1::MESH_FORMAT_OBJ, "empty.obj", &up).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(ts.client().uploadMesh("v 1 2 3\n", v1::MeshFormat(99), "x", &up).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(ts.client().uploadVolumeBytes({2, 2, 2}, v1::VOXEL_TYPE_UINT8, std::vector<uint8_t>(7, 1), "short", &up).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  // A signed volume needs an outside: refused before compute, naming the field.
  v1::QueryRequest full;
  full.mutable_volume()->mutable_dims()->set_x(8);
  full.mutable_volume()->mutable_dims()->set_y(8);
  full.mutable_volume()->mutable_dims()->set_z(8);
  full.mutable_volume()->set_mask(std::string(512, '\1'));
  full.mutable_grid();
  full.set_sign(v1::SIGN_MODE_MASK_INSIDE);
  const RemoteQueryResult all_inside = ts.client().query(full, {});
  EXPECT_EQ(all_inside.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(all_inside.status.error_message().find("sign: SIGN_MODE_MASK_INSIDE needs a zero voxel"),
            std::string::npos)
      << all_inside.status.error_message();
  // Still serving.
  Streamed ok = stream(ts.client(), pointsRequest({{1, 2, 3}}, {16, 16, 16}, 1.0, 0, 0), 0);
  EXPECT_TRUE(ok.result.status.ok()) << ok.result.status.error_message();
}

TEST(ServiceTest, UploadLimitsAreEnforced) {
  ServerOptions o = TestServer::defaults();
  o.max_upload_bytes = 1000;
  o.cache_bytes = 4096;
  TestServer ts(o);
  v1::UploadReply up;
  grpc::Status s = ts.client().uploadVolumeBytes({20, 10, 10}, v1::VOXEL_TYPE_UINT8, std::vector<uint8_t>(2000, 1), "big", &up);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  // Fits the upload limit but not the cache.
  RemoteClient client("127.0.0.1:" + std::to_string(ts.server().port()));
  s = client.uploadVolumeBytes({10, 10, 9}, v1::VOXEL_TYPE_UINT8, std::vector<uint8_t>(900, 1), "ok", &up);
  EXPECT_TRUE(s.ok()) << s.error_message();
}

TEST(ServiceTest, AnUploadLargerThanTheWholeCacheIsRefusedNamingTheField) {
  ServerOptions o = TestServer::defaults();
  o.cache_bytes = 256;  // below any parsed asset
  TestServer ts(o);
  v1::UploadReply up;
  grpc::Status s =
      ts.client().uploadVolumeBytes({10, 10, 9}, v1::VOXEL_TYPE_UINT8, std::vector<uint8_t>(900, 1), "v", &up);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_NE(s.error_message().find("UploadVolumeChunk.data: the volume needs "), std::string::npos)
      << s.error_message();
  EXPECT_NE(s.error_message().find("more than the whole asset cache (256 bytes)"), std::string::npos)
      << s.error_message();
  const std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n";
  s = ts.client().uploadMesh(obj, v1::MESH_FORMAT_OBJ, "tetra", &up);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_NE(s.error_message().find("UploadMeshChunk.data: the parsed mesh needs "), std::string::npos)
      << s.error_message();
  EXPECT_EQ(ts.server().service().cache().usedBytes(), 0u);  // nothing half-kept
  v1::ServerInfo info;
  EXPECT_TRUE(ts.client().info(&info).ok());  // still serving
}

bool fieldEquals(const DenseField& got, const std::vector<Vec3d>& pts, const Grid& grid, double segment,
                 double limit) {
  Seeds seeds;
  if (!makePointSeeds(grid, pts, &seeds).ok()) return false;
  BandOptions o;
  o.segment_length_world = segment;
  o.limit_world = limit == 0 ? std::numeric_limits<double>::infinity() : limit;
  const DenseField ref = reference(grid, seeds, o, float(limit));
  return std::memcmp(got.values().data(), ref.values().data(), ref.values().size() * sizeof(float)) == 0 &&
         got.written() == ref.written();
}

TEST(ServiceTest, EightConcurrentQueriesAreAllCorrect) {
  TestServer ts;
  std::vector<std::thread> threads;
  std::atomic<int> correct{0};
  std::vector<std::string> errors(8);
  for (int i = 0; i < 8; ++i)
    threads.emplace_back([&, i] {
      const std::vector<Vec3d> pts{{3.0 + i, 20.0 - i, 7.5 + 0.5 * i}};
      const Coord dims{40 + i, 40, 36};
      Streamed s = stream(ts.client(), pointsRequest(pts, dims, 1.0, 3.0, 12.0), 12.0f);
      if (!s.result.status.ok()) errors[size_t(i)] = s.result.status.error_message();
      else if (!s.order_error.empty()) errors[size_t(i)] = s.order_error;
      else if (fieldEquals(*s.field, pts, Grid({0, 0, 0}, 1.0, dims), 3.0, 12.0)) ++correct;
      else errors[size_t(i)] = "field differs";
    });
  for (auto& t : threads) t.join();
  for (int i = 0; i < 8; ++i) EXPECT_EQ(errors[size_t(i)], "") << "query " << i;
  EXPECT_EQ(correct.load(), 8);
}

TEST(ServiceTest, SixteenQueriesOnFourSlotsCompleteOrGetResourceExhausted) {
  ServerOptions o = TestServer::defaults();
  o.max_concurrent_queries = 4;
  o.queue_wait_ms = 30;
  TestServer ts(o);
  std::vector<std::thread> threads;
  std::atomic<int> correct{0}, exhausted{0}, other{0};
  for (int i = 0; i < 16; ++i)
    threads.emplace_back([&, i] {
      const std::vector<Vec3d> pts{{10.0 + i, 30.0, 20.0}};
      const Coord dims{64, 64, 64};
      Streamed s = stream(ts.client(), pointsRequest(pts, dims, 1.0, 4.0, 0), 0.0f);
      if (s.result.status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED) {
        ++exhausted;
        EXPECT_NE(s.result.status.error_message().find("concurrent"), std::string::npos);
      } else if (s.result.status.ok() && fieldEquals(*s.field, pts, Grid({0, 0, 0}, 1.0, dims), 4.0, 0)) {
        ++correct;
      } else {
        ++other;
      }
    });
  for (auto& t : threads) t.join();
  std::printf("[ measure  ] 16 queries on 4 slots: %d correct, %d RESOURCE_EXHAUSTED\n", correct.load(),
              exhausted.load());
  EXPECT_EQ(other.load(), 0);
  EXPECT_EQ(correct.load() + exhausted.load(), 16);
  EXPECT_GE(correct.load(), 4);
}

TEST(ServiceTest, InfoAndHealth) {
  TestServer ts;
  v1::ServerInfo info;
  ASSERT_TRUE(ts.client().info(&info).ok());
  EXPECT_EQ(info.compute_threads(), 2u);
  EXPECT_EQ(info.max_concurrent_queries(), 8u);
  EXPECT_EQ(info.stencils_size(), 4);
  EXPECT_FALSE(info.version().empty());
  bool serving = false;
  std::string name;
  ASSERT_TRUE(ts.client().health("", &serving, &name).ok());
  EXPECT_TRUE(serving) << name;
  ASSERT_TRUE(ts.client().health("distband.v1.DistanceField", &serving, &name).ok());
  EXPECT_TRUE(serving) << name;
}

TEST(ServiceTest, ShutdownDrainsRunningStreamsAndRefusesNewOnes) {
  TestServer ts;
  // The client holds its first batch until the checks below are done, so the stream is still running then
  // (the field is far larger than what HTTP/2 flow control lets the server buffer).
  std::atomic<bool> first_batch{false}, release{false};
  Streamed slow;
  const std::vector<Vec3d> pts{{20, 20, 20}};
  const Coord dims{128, 128, 128};
  std::thread reader([&] {
    slow = stream(ts.client(), pointsRequest(pts, dims, 1.0, 8.0, 0), 0.0f, [&](int) {
      first_batch = true;
      while (!release) std::this_thread::sleep_for(std::chrono::milliseconds(1));
      return true;
    });
  });
  while (!first_batch) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  std::thread stopper([&] { ts.server().shutdown(std::chrono::seconds(20)); });
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  bool serving = true;
  std::string name;
  const grpc::Status hs = ts.client().health("", &serving, &name);
  EXPECT_TRUE(hs.ok()) << hs.error_code() << " " << hs.error_message();
  EXPECT_FALSE(serving);
  EXPECT_EQ(name, "NOT_SERVING");
  const RemoteQueryResult refused = ts.client().query(pointsRequest(pts, {8, 8, 8}, 1.0, 0, 0), {});
  EXPECT_EQ(refused.status.error_code(), grpc::StatusCode::UNAVAILABLE) << refused.status.error_message();
  release = true;
  reader.join();
  stopper.join();
  EXPECT_TRUE(slow.result.status.ok()) << slow.result.status.error_message();
  EXPECT_TRUE(fieldEquals(*slow.field, pts, Grid({0, 0, 0}, 1.0, dims), 8.0, 0));
}

TEST(ServiceTest, ShutdownGraceExpiryCancelsRunningStreams) {
  TestServer ts;
  std::atomic<bool> first_batch{false};
  Streamed slow;
  std::thread reader([&] {
    slow = stream(ts.client(), pointsRequest({{0, 0, 0}}, {256, 256, 256}, 1.0, 1.0, 0), 0.0f, [&](int) {
      first_batch = true;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      return true;
    });
  });
  while (!first_batch) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  const auto t0 = Clock::now();
  ts.server().shutdown(std::chrono::milliseconds(100));
  const double shutdown_ms = ms(Clock::now() - t0);
  reader.join();
  EXPECT_TRUE(slow.result.status.error_code() == grpc::StatusCode::UNAVAILABLE ||
              slow.result.status.error_code() == grpc::StatusCode::CANCELLED)
      << slow.result.status.error_code() << " " << slow.result.status.error_message();
  EXPECT_LT(shutdown_ms, 2000.0);
  ASSERT_TRUE(ts.waitRecords(1));
  EXPECT_TRUE(ts.records()[0].interrupted);
}

}  // namespace
}  // namespace distband
