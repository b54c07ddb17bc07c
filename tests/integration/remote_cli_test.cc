// The `distband query` command against a real in-process server: the .vdb it writes reads back with OpenVDB as a
// level set whose values equal the in-process engine's, the .npy matches, and failures map to exit codes without
// leaving files behind.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <tuple>

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include "client/cli.h"
#include "core/io/dense_field.h"
#include "core/band/band_engine.h"
#include "core/io/npy.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/mesh_seeds.h"
#include "core/stencil.h"
#include "server/server.h"
#include "tests/support/status_testing.h"
#include "tests/support/run_command.h"

namespace distband {
namespace {

namespace fs = std::filesystem;

struct Fixture {
  Fixture() {
    ServerOptions o;
    o.listen_address = "127.0.0.1:0";
    o.compute_threads = 2;
    server = std::make_unique<DistbandServer>(o);
    EXPECT_TRUE(server->start().ok());
    address = "127.0.0.1:" + std::to_string(server->port());
    dir = fs::temp_directory_path() / ("distband_remote_cli_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    std::ofstream(dir / "cube.obj") << "v -1 -1 -1\nv 1 -1 -1\nv -1 1 -1\nv 1 1 -1\nv -1 -1 1\nv 1 -1 1\nv -1 1 1\n"
                                       "v 1 1 1\nf 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n";
  }
  ~Fixture() { fs::remove_all(dir); }
  int run(std::vector<std::string> args, bool interrupt = false) {
    out.str("");
    err.str("");
    CliContext ctx{out, err, [interrupt] { return interrupt; }};
    return runDistband(args, ctx);
  }
  std::string path(const char* name) const { return (dir / name).string(); }

  std::unique_ptr<DistbandServer> server;
  std::string address;
  fs::path dir;
  std::ostringstream out, err;
};

TEST(RemoteCliTest, QueryWritesALevelSetVdbThatMatchesTheEngine) {
  Fixture f;
  const double limit = 0.3;
  const int code = f.run({"query", "--server", f.address, "--mesh", f.path("cube.obj"), "--resolution", "40",
                          "--limit", "0.3", "--segment", "0.1", "--out", f.path("cube.vdb"), "--npy",
                          f.path("cube.npy"), "--slice-png", "z:mid", f.path("cube.png"), "--isosurface", "0",
                          f.path("cube.obj.out.obj"), "--progress", "quiet"});
  ASSERT_EQ(code, 0) << f.err.str() << f.out.str();
  EXPECT_TRUE(fs::exists(f.path("cube.png")));
  EXPECT_TRUE(fs::exists(f.path("cube.obj.out.obj")));

  // In-process reference on the same grid.
  TriangleMesh mesh;
  ASSERT_TRUE(IsOk(loadMesh(f.path("cube.obj"), &mesh, nullptr)));
  MeshGridOptions mo;
  mo.resolution = 40;
  Grid grid;
  ASSERT_TRUE(IsOk(gridForMesh(mesh, mo, {limit, 0}, &grid)));  // the default padding holds the limit
  MeshSeedOptions so;
  so.limit_voxels = limit / grid.voxelSize();
  Seeds seeds;
  ASSERT_TRUE(IsOk(makeMeshSeeds(grid, mesh, so, &seeds)));
  BandOptions eo;
  eo.limit_world = limit;
  eo.segment_length_world = 0.1;
  DenseField ref(grid, float(limit));
  std::vector<uint8_t> delivered(size_t(grid.voxelCount()), 0);
  computeBandField(grid, seeds, eo, [&](SegmentBricks&& s) {
    ref.add(s);
    for (const Brick& b : s.bricks)
      for (int i = 0; i < kBrickVoxels; ++i)
        if (b.mask.test(i) && grid.contains(b.origin + brickLocal(i)))
          delivered[size_t(grid.denseIndex(b.origin + brickLocal(i)))] = 1;
  });

  openvdb::initialize();
  openvdb::io::File file(f.path("cube.vdb"));
  file.open();
  auto base = file.readGrid("distance");
  file.close();
  auto vdb = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
  ASSERT_TRUE(vdb);
  EXPECT_EQ(vdb->getGridClass(), openvdb::GRID_LEVEL_SET);
  EXPECT_FLOAT_EQ(vdb->background(), float(limit));
  EXPECT_NEAR(vdb->voxelSize()[0], grid.voxelSize(), 1e-12);
  const openvdb::Vec3d o = vdb->indexToWorld(openvdb::Coord(0, 0, 0));
  EXPECT_NEAR(o[0], grid.origin().x, 1e-9);
  EXPECT_NEAR(o[1], grid.origin().y, 1e-9);
  EXPECT_NEAR(o[2], grid.origin().z, 1e-9);
  auto acc = vdb->getConstAccessor();
  int64_t active = 0, mismatches = 0;
  for (int z = 0; z < grid.dims().z; ++z)
    for (int y = 0; y < grid.dims().y; ++y)
      for (int x = 0; x < grid.dims().x; ++x) {
        const Coord c{x, y, z};
        if (!delivered[size_t(grid.denseIndex(c))]) continue;
        ++active;
        mismatches += acc.getValue(openvdb::Coord(x, y, z)) != ref.at(c);
      }
  EXPECT_EQ(mismatches, 0);
  EXPECT_EQ(int64_t(vdb->activeVoxelCount()), active);
  // The cube's centre is beyond the limit inside: the flood fill makes it -limit.
  const Vec3d centre = grid.indexOf({0, 0, 0});
  EXPECT_FLOAT_EQ(acc.getValue(openvdb::Coord(int(std::lround(centre.x)), int(std::lround(centre.y)),
                                              int(std::lround(centre.z)))),
                  -float(limit));

  std::vector<float> npy;
  Coord dims;
  ASSERT_TRUE(IsOk(readNpyFloat32(f.path("cube.npy"), &npy, &dims)));
  ASSERT_EQ(dims, grid.dims());
  int64_t npy_mismatches = 0;
  for (size_t i = 0; i < npy.size(); ++i) npy_mismatches += delivered[i] && npy[i] != ref.values()[i];
  EXPECT_EQ(npy_mismatches, 0);
}

TEST(RemoteCliTest, ServerRejectionIsAUsageErrorAndWritesNothing) {
  Fixture f;
  // A combination only the grid's builder judges (a resolution that leaves no voxel inside its padding) the server
  // refuses.
  EXPECT_EQ(f.run({"query", "--server", f.address, "--mesh", f.path("cube.obj"), "--resolution", "4", "--padding", "3",
                   "--limit", "0.3", "--out", f.path("bad.vdb"), "--progress", "quiet"}),
            2);
  // The server's answer reads as a sentence, then its message.
  EXPECT_NE(f.err.str().find("the server refused the request: grid: resolution 4 leaves no voxel"), std::string::npos)
      << f.err.str();
  EXPECT_FALSE(fs::exists(f.path("bad.vdb")));
  // A slice needs a finite limit (its colour scale): refused before contacting the server.
  EXPECT_EQ(f.run({"query", "--server", f.address, "--points", "1,2,3", "--dims", "8,8,8", "--voxel-size", "1",
                   "--slice-png", "z:mid", f.path("nolimit.png")}),
            2);
  EXPECT_NE(f.err.str().find("--slice-png needs a finite --limit"), std::string::npos) << f.err.str();
}

TEST(RemoteCliTest, EveryOutputProblemIsReportedBeforeAnyUpload) {
  Fixture f;
  const std::vector<std::string> base = {"query", "--server", f.address, "--mesh", f.path("cube.obj"),
                                         "--resolution", "32", "--limit", "0.3", "--progress", "quiet"};
  auto run = [&](std::vector<std::string> extra) {
    std::vector<std::string> args = base;
    args.insert(args.end(), extra.begin(), extra.end());
    return f.run(args);
  };
  const std::string missing_dir = f.path("no-such-dir") + "/field.vdb";
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"--out", missing_dir}, "--out " + missing_dir + ": directory"},
      {{"--out", f.path("field.txt")}, "--out " + f.path("field.txt") + ": expected a .vdb, .npy, .nii.gz file"},
      {{"--npy", f.path("field.vdb")}, "--npy"},
      {{"--slice-png", "z:4", f.path("slice.jpg")}, "--slice-png " + f.path("slice.jpg") + ": expected a .png file"},
      {{"--isosurface", "0.1", f.path("iso.stl")}, "--isosurface " + f.path("iso.stl") + ": expected a .obj file"},
      {{"--isosurface", "0.5", f.path("iso.obj")}, "--isosurface 0.5: the surface must lie inside --limit 0.3"},
  };
  for (const auto& [extra, words] : cases) {
    EXPECT_EQ(run(extra), 2) << words;
    EXPECT_NE(f.err.str().find(words), std::string::npos) << f.err.str();
    EXPECT_EQ(f.out.str().find("uploaded"), std::string::npos) << "nothing may be uploaded first: " << f.out.str();
  }
  EXPECT_EQ(f.run({"query", "--server", f.address, "--mesh", f.path("nope.obj"), "--resolution", "32", "--limit",
                   "0.3", "--out", f.path("x.vdb")}),
            2);
  EXPECT_NE(f.err.str().find("--mesh " + f.path("nope.obj") + ": no such file"), std::string::npos) << f.err.str();
  EXPECT_EQ(f.server->service().cache().size(), 0u) << "nothing was uploaded";
  EXPECT_EQ(std::distance(fs::directory_iterator(f.dir), fs::directory_iterator()), 1) << "only cube.obj";
}

TEST(RemoteCliTest, LimitInVoxelsGivesTheSameFieldAsTheWorldLimit) {
  Fixture f;
  const std::vector<std::string> base = {"query", "--server", f.address, "--points", "1,2,3;6,5,4", "--dims",
                                         "24,20,16", "--voxel-size", "0.5", "--progress", "quiet"};
  auto run = [&](std::vector<std::string> extra) {
    std::vector<std::string> args = base;
    args.insert(args.end(), extra.begin(), extra.end());
    return f.run(args);
  };
  ASSERT_EQ(run({"--limit", "1.5", "--out", f.path("world.npy")}), 0) << f.err.str();
  ASSERT_EQ(run({"--limit-voxels", "3", "--out", f.path("voxels.npy"), "--isosurface", "0.5", f.path("iso.obj")}), 0)
      << f.err.str();
  EXPECT_NE(f.out.str().find("limit 1.5,"), std::string::npos) << f.out.str();
  std::vector<float> a, b;
  Coord d;
  ASSERT_TRUE(IsOk(readNpyFloat32(f.path("world.npy"), &a, &d)));
  ASSERT_TRUE(IsOk(readNpyFloat32(f.path("voxels.npy"), &b, &d)));
  EXPECT_EQ(a, b);
  EXPECT_EQ(run({"--limit", "1.5", "--limit-voxels", "3", "--out", f.path("both.npy")}), 2);
  // In voxels the isosurface is checked against the limit once the header gives the voxel size.
  EXPECT_EQ(run({"--limit-voxels", "3", "--out", f.path("v.vdb"), "--isosurface", "2", f.path("far.obj")}), 2);
  EXPECT_NE(f.err.str().find("--isosurface 2: the surface must lie inside the limit 1.5"), std::string::npos)
      << f.err.str();
}

TEST(RemoteCliTest, InterruptCancelsTheQueryAndWritesNothing) {
  Fixture f;
  const int code = f.run({"query", "--server", f.address, "--points", "1,2,3", "--dims", "256,256,256",
                          "--voxel-size", "1", "--segment", "1", "--limit", "200", "--out", f.path("never.vdb"),
                          "--progress", "quiet"},
                         /*interrupt=*/true);
  EXPECT_EQ(code, 130) << f.err.str();
  EXPECT_FALSE(fs::exists(f.path("never.vdb")));
}

// The field flags mean the same in both commands (client/field_flags.h): the same flags give the same field, byte for
// byte, whether the engine runs in-process or on the server, in each of the grid's three ways and for every seed kind.
TEST(RemoteCliTest, TheSameFieldFlagsGiveComputeAndQueryTheSameField) {
  Fixture f;
  const Coord dims{20, 18, 16};
  std::vector<uint8_t> mask(size_t(dims.x) * dims.y * dims.z, 0);
  for (int z = 4; z < 12; ++z)
    for (int y = 5; y < 13; ++y)
      for (int x = 6; x < 14; ++x) mask[(size_t(z) * dims.y + y) * dims.x + x] = 1;
  ASSERT_TRUE(IsOk(writeNpyMask(f.path("box.npy"), mask, dims)));
  const std::vector<std::vector<std::string>> cases = {
      {"--mesh", f.path("cube.obj"), "--voxel-size", "0.1", "--box", "-1.2,-1.2,-1.2,1.2,1.2,1.2", "--padding", "1",
       "--sign", "winding", "--stencil", "cubic26", "--limit", "0.4"},
      {"--mesh", f.path("cube.obj"), "--dims", "24,24,24", "--voxel-size", "0.1", "--origin", "-1.15,-1.15,-1.15",
       "--limit", "0.3", "--mode", "paper", "--segment", "0.1"},
      {"--mesh", f.path("cube.obj"), "--resolution", "30", "--limit-voxels", "3", "--sign", "parity"},
      {"--points", "1,2,3;6,5,4", "--voxel-size", "0.5", "--limit", "2", "--segment", "0.5"},
      {"--points", "1,2,3;9,9,9", "--dims", "16,16,16"},
      {"--volume", f.path("box.npy"), "--sign", "mask-inside", "--limit-voxels", "3"},
      {"--volume", f.path("box.npy"), "--stencil", "fcc12", "--voxel-size", "0.25", "--origin", "1,2,3"},
  };
  for (const std::vector<std::string>& flags : cases) {
    std::string label;
    for (const std::string& a : flags) label += a + " ";
    std::vector<std::string> compute = {"compute", "--out", f.path("compute.npy")};
    std::vector<std::string> query = {"query", "--server", f.address,          "--progress",
                                      "quiet", "--out",    f.path("query.npy")};
    compute.insert(compute.end(), flags.begin(), flags.end());
    query.insert(query.end(), flags.begin(), flags.end());
    ASSERT_EQ(f.run(compute), 0) << label << f.err.str();
    const std::string compute_algorithm = f.out.str().substr(f.out.str().find("algorithm: "));
    ASSERT_EQ(f.run(query), 0) << label << f.err.str();
    const std::string query_out = f.out.str();
    EXPECT_NE(query_out.find(compute_algorithm.substr(0, compute_algorithm.find('\n') + 1)), std::string::npos)
        << label << "\ncompute: " << compute_algorithm << "\nquery: " << query_out;
    std::ifstream a(f.path("compute.npy"), std::ios::binary), b(f.path("query.npy"), std::ios::binary);
    const std::string bytes_a((std::istreambuf_iterator<char>(a)), {}),
        bytes_b((std::istreambuf_iterator<char>(b)), {});
    EXPECT_GT(bytes_a.size(), 128u) << label;
    EXPECT_TRUE(bytes_a == bytes_b) << label << ": the two commands wrote different fields";
  }
}

// The flags' names reach the server and come back in the header as the same names (no table on either side: the
// protocol's values are core's names in upper case), for every stencil and every mesh sign core knows.
TEST(RemoteCliTest, EveryStencilAndSignNameRoundTripsThroughTheProtocol) {
  Fixture f;
  auto meta = [&] {
    std::ifstream in(f.path("q.json"));
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  for (StencilKind k : kStencilKinds) {
    const std::string name(stencilName(k));
    ASSERT_EQ(f.run({"query", "--server", f.address, "--progress", "quiet", "--points", "3,3,3", "--dims", "12,12,12",
                     "--stencil", name, "--limit", "3", "--out", f.path("q.npy"), "--meta", f.path("q.json")}),
              0)
        << f.err.str();
    EXPECT_NE(meta().find("\"stencil\": \"" + name + "\""), std::string::npos) << name << meta();
  }
  for (SignMethod m : kSignMethods) {
    if (m == SignMethod::kUnsigned) continue;  // an unsigned field's metadata names no method
    ASSERT_EQ(f.run({"query", "--server", f.address, "--progress", "quiet", "--mesh", f.path("cube.obj"),
                     "--resolution", "16", "--sign", std::string(signMethodName(m)), "--limit", "0.3", "--out",
                     f.path("q.npy"), "--meta", f.path("q.json")}),
              0)
        << f.err.str();
    const std::string method = m == SignMethod::kAuto ? "pseudonormal" : std::string(signMethodName(m));  // closed
    EXPECT_NE(meta().find("\"method\": \"" + method + "\""), std::string::npos) << method << meta();
  }
}

// --second-ring is a field flag query shares but cannot send: QueryRequest has no field for it. It is refused, not
// dropped, before anything is uploaded.
TEST(RemoteCliTest, QueryRefusesTheSecondRingItCannotSend) {
  Fixture f;
  EXPECT_EQ(f.run({"query", "--server", f.address, "--mesh", f.path("cube.obj"), "--resolution", "16", "--second-ring",
                   "--out", f.path("never.npy")}),
            kExitUsage);
  EXPECT_NE(f.err.str().find("--second-ring: the service's QueryRequest has no field"), std::string::npos)
      << f.err.str();
  EXPECT_EQ(f.out.str().find("uploaded"), std::string::npos) << f.out.str();
  EXPECT_FALSE(fs::exists(f.path("never.npy")));
}

// --deadline stops a query as Ctrl-C does (the server stops its engine; the complete segments are kept), with exit 1.
TEST(RemoteCliTest, DeadlineStopsTheQueryAndExitsOne) {
  Fixture f;
  const int code =
      f.run({"query", "--server", f.address, "--points", "1,2,3", "--dims", "256,256,256", "--segment", "1", "--limit",
             "200", "--deadline", "0.000001", "--out", f.path("late.npy"), "--progress", "quiet"});
  EXPECT_EQ(code, kExitFailure) << f.err.str();
  EXPECT_NE(f.err.str().find("the deadline (--deadline) passed"), std::string::npos) << f.err.str();
}

TEST(RemoteCliTest, UploadInfoHealth) {
  Fixture f;
  ASSERT_EQ(f.run({"upload", "--server", f.address, "--mesh", f.path("cube.obj")}), 0) << f.err.str();
  EXPECT_EQ(f.out.str().rfind("mesh-", 0), 0u) << f.out.str();
  ASSERT_EQ(f.run({"info", "--server", f.address}), 0) << f.err.str();
  EXPECT_NE(f.out.str().find("compute threads    2"), std::string::npos) << f.out.str();
  ASSERT_EQ(f.run({"health", "--server", f.address}), 0) << f.err.str();
  EXPECT_EQ(f.out.str(), "SERVING\n");
  EXPECT_EQ(f.run({"upload", "--server", f.address, "--mesh", f.path("missing.obj")}), 2);
}

// The front `distband` binary has no gRPC in it: it hands the service's commands, arguments unchanged, to the
// distband-remote binary beside it. Run as a real process against the in-process server.
TEST(RemoteCliTest, TheFrontBinaryHandsServiceCommandsToDistbandRemote) {
  Fixture f;
  auto run = [&](const std::string& args, std::string* out) {
    int status;
    std::tie(*out, status) = runCommand(std::string(DISTBAND_CLI_BINARY) + " " + args + " 2>&1");
    return status;
  };
  std::string out;
  ASSERT_EQ(run("info --server " + f.address, &out), 0) << out;
  EXPECT_NE(out.find("compute threads    2"), std::string::npos) << out;
  ASSERT_EQ(run("health --server " + f.address, &out), 0) << out;
  EXPECT_EQ(out, "SERVING\n");
  EXPECT_EQ(run("query --help", &out), 0) << out;
  EXPECT_NE(out.find("Usage: distband query"), std::string::npos) << out;  // the helper keeps the user's argv[0]
  EXPECT_EQ(run("--help", &out), 0) << out;
  for (const RemoteCommandName& r : kRemoteCommands) EXPECT_NE(out.find(r.name), std::string::npos) << out;
  EXPECT_EQ(run("upload --server " + f.address + " --mesh " + f.path("missing.obj"), &out), 2) << out;
}

}  // namespace
}  // namespace distband
