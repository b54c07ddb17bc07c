// Tests for `distband compute` (client/compute_command, client/cli): runs the command in-process on tiny inputs,
// checks the written .npy against the expected distances, the limit/sign background, the log, and exit code 2
// with a clear message for every kind of bad flag or input file.
#include "client/compute_command.h"

#include <atomic>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include "client/cli.h"
#include "core/io/npy.h"
#include "core/mesh/triangle_mesh.h"
#include "tests/support/status_testing.h"
#include "tests/support/brute_mesh.h"

namespace distband {
namespace {

struct CliResult {
  int code;
  std::string out, err;
};

CliResult run(const std::vector<std::string>& args, std::function<bool()> interrupted = {}) {
  std::ostringstream out, err;
  const CliContext ctx{out, err, std::move(interrupted)};
  const int code = runDistband(args, ctx);
  return {code, out.str(), err.str()};
}

std::string tmp(const std::string& name) { return ::testing::TempDir() + "compute_test_" + name; }

TEST(ComputeCommandTest, PointsToNpy) {
  const std::string out = tmp("points.npy");
  std::remove(out.c_str());
  const CliResult r = run({"compute", "--points", "2.5,3,4; 12,12,12", "--dims", "16,14,12", "--voxel-size", "0.5",
                           "--origin", "-1,0,1", "--stencil", "fcc12", "--segment", "1.5", "--threads", "2",
                           "--out", out});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("segment   0"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("done:"), std::string::npos) << r.out;
  std::vector<float> v;
  Coord d;
  ASSERT_TRUE(IsOk(readNpyFloat32(out, &v, &d)));
  EXPECT_EQ(d, (Coord{16, 14, 12}));
  // Exact mode is the default: compare with the analytic distance to the nearer point.
  double max_err = 0;
  for (int z = 0; z < 12; ++z)
    for (int y = 0; y < 14; ++y)
      for (int x = 0; x < 16; ++x) {
        const double wx = -1 + 0.5 * x, wy = 0.5 * y, wz = 1 + 0.5 * z;
        const double d1 = std::sqrt((wx - 2.5) * (wx - 2.5) + (wy - 3) * (wy - 3) + (wz - 4) * (wz - 4));
        const double d2 = std::sqrt((wx - 12) * (wx - 12) + (wy - 12) * (wy - 12) + (wz - 12) * (wz - 12));
        max_err = std::max(max_err, std::fabs(v[(z * 14 + y) * 16 + x] - std::min(d1, d2)));
      }
  EXPECT_LT(max_err, 1e-5);
  std::remove(out.c_str());
}

TEST(ComputeCommandTest, LimitBackgroundAndSignedVolume) {
  const Coord dims{20, 18, 16};
  std::vector<uint8_t> mask(size_t(dims.x) * dims.y * dims.z, 0);
  for (int z = 3; z <= 12; ++z)
    for (int y = 3; y <= 14; ++y)
      for (int x = 3; x <= 16; ++x) mask[(size_t(z) * dims.y + y) * dims.x + x] = 1;
  const std::string in = tmp("box.npy"), out = tmp("box_field.npy"), meta = tmp("box_field.json");
  ASSERT_TRUE(IsOk(writeNpyMask(in, mask, dims)));
  const CliResult r = run({"compute", "--volume", in, "--sign", "mask-inside", "--limit", "2", "--segment", "1",
                           "--out", out, "--meta", meta});
  ASSERT_EQ(r.code, 0) << r.err;
  std::vector<float> v;
  Coord d;
  ASSERT_TRUE(IsOk(readNpyFloat32(out, &v, &d)));
  ASSERT_EQ(d, dims);
  auto at = [&](int x, int y, int z) { return v[(size_t(z) * dims.y + y) * dims.x + x]; };
  EXPECT_EQ(at(0, 0, 0), 2.0f);     // outside, beyond the limit: +limit
  EXPECT_EQ(at(9, 9, 8), -2.0f);    // deep inside, beyond the limit: -limit
  EXPECT_EQ(at(3, 9, 8), -1.0f);    // inside, next to the boundary
  EXPECT_EQ(at(2, 9, 8), 1.0f);     // outside, next to the boundary
  EXPECT_EQ(at(1, 9, 8), 2.0f);     // outside, distance 2 = limit: delivered, equal to the background anyway
  EXPECT_EQ(at(4, 4, 8), -2.0f);    // inside, distance 2
  EXPECT_FLOAT_EQ(at(2, 2, 8), std::sqrt(2.0f));
  std::ifstream j(meta);
  const std::string json((std::istreambuf_iterator<char>(j)), {});
  EXPECT_NE(json.find("\"signed\": true"), std::string::npos) << json;
  EXPECT_NE(json.find("\"limit\": 2.0"), std::string::npos) << json;
  std::remove(in.c_str());
  std::remove(out.c_str());
  std::remove(meta.c_str());
}

TEST(ComputeCommandTest, LimitInVoxelsIsTheLimitTimesTheVoxelSize) {
  const std::string a = tmp("limit_world.npy"), b = tmp("limit_voxels.npy");
  const std::vector<std::string> base = {"compute", "--points", "2.5,3,4", "--dims", "16,14,12", "--voxel-size", "0.5"};
  auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> args = base;
    args.insert(args.end(), extra.begin(), extra.end());
    return run(args);
  };
  ASSERT_EQ(with({"--limit", "2", "--out", a}).code, 0);
  const CliResult r = with({"--limit-voxels", "4", "--out", b});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("limit 2,"), std::string::npos) << r.out;  // reported in world units
  std::vector<float> va, vb;
  Coord d;
  ASSERT_TRUE(IsOk(readNpyFloat32(a, &va, &d)));
  ASSERT_TRUE(IsOk(readNpyFloat32(b, &vb, &d)));
  EXPECT_EQ(va, vb);
  EXPECT_EQ(with({"--limit", "2", "--limit-voxels", "4", "--out", b}).code, 2);
  EXPECT_NE(with({"--limit-voxels", "-1", "--out", b}).err.find("--limit-voxels must be finite and > 0"),
            std::string::npos);
  std::remove(a.c_str());
  std::remove(b.c_str());
}

TEST(ComputeCommandTest, HelpExitsZero) {
  const CliResult r = run({"compute", "--help"});
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("--volume"), std::string::npos) << r.out;
  const CliResult top = run({"--help"});
  EXPECT_EQ(top.code, 0);
  EXPECT_NE(top.out.find("compute"), std::string::npos);
}

TEST(ComputeCommandTest, UsageAndInputErrorsExitTwo) {
  const std::string good_mask = tmp("good.npy");
  ASSERT_TRUE(IsOk(writeNpyMask(good_mask, std::vector<uint8_t>(64, 1), {4, 4, 4})));
  const std::string text_file = tmp("text.npy");
  std::ofstream(text_file) << "not a numpy file\n";
  const std::string empty_mask = tmp("empty.npy");
  ASSERT_TRUE(IsOk(writeNpyMask(empty_mask, std::vector<uint8_t>(64, 0), {4, 4, 4})));
  const std::string out = tmp("never.npy");
  const std::vector<std::string> pts = {"compute", "--points", "1,1,1", "--dims", "8,8,8", "--out", out};
  auto with = [&](std::vector<std::string> extra, std::vector<std::string> base) {
    base.insert(base.end(), extra.begin(), extra.end());
    return base;
  };
  struct Case {
    std::string name;
    std::vector<std::string> args;
    std::string expect;  ///< substring of stderr
  };
  const std::vector<Case> cases = {
      {"no_command", {}, "subcommand"},
      {"unknown_command", {"frobnicate"}, "frobnicate"},
      {"unknown_flag", with({"--bogus"}, pts), "--bogus"},
      {"missing_out", {"compute", "--points", "1,1,1", "--dims", "8,8,8"}, "--out"},
      {"no_seeds", {"compute", "--dims", "8,8,8", "--out", out}, "exactly one seed source"},
      {"both_seeds", with({"--volume", good_mask}, pts), "exactly one seed source"},
      {"signed_points", with({"--sign", "mask-inside"}, pts), "--sign 'mask-inside': mask-inside is for volume seeds"},
      {"mesh_sign_on_points", with({"--sign", "winding"}, pts), "--sign 'winding': winding is for meshes"},
      {"origin_without_dims",
       {"compute", "--points", "1,1,1", "--voxel-size", "1", "--origin", "1,2,3", "--out", out},
       "--origin applies to --dims"},
      {"resolution_with_dims", with({"--resolution", "16"}, pts), "--resolution does not apply to --dims"},
      {"box_with_volume",
       {"compute", "--volume", good_mask, "--box", "0,0,0,1,1,1", "--out", out},
       "--box does not apply"},
      {"inverted_box",
       {"compute", "--points", "1,1,1", "--voxel-size", "1", "--box", "2,0,0,1,1,1", "--out", out},
       "--box '2,0,0,1,1,1': the max corner"},
      {"second_ring_points", with({"--second-ring"}, pts), "--second-ring applies to meshes"},
      {"both_limits", with({"--limit", "2", "--limit-voxels", "2"}, pts), "--limit and --limit-voxels"},
      {"negative_deadline", with({"--deadline", "-1"}, pts), "--deadline"},
      {"points_without_grid", {"compute", "--points", "1,1,1", "--out", out}, "or --dims X,Y,Z"},
      {"dims_two", {"compute", "--points", "1,1,1", "--dims", "8,8", "--out", out}, "three comma-separated"},
      {"dims_zero", {"compute", "--points", "1,1,1", "--dims", "0,8,8", "--out", out}, "[1, 16384]"},
      {"dims_huge", {"compute", "--points", "1,1,1", "--dims", "8,99999,8", "--out", out}, "[1, 16384]"},
      {"dims_text", {"compute", "--points", "1,1,1", "--dims", "a,b,c", "--out", out}, "not an integer"},
      {"bad_point", {"compute", "--points", "1,1,1;2,x,2", "--dims", "8,8,8", "--out", out}, "point 2"},
      {"short_point", {"compute", "--points", "1,1", "--dims", "8,8,8", "--out", out}, "three comma-separated"},
      {"nan_point", {"compute", "--points", "1,nan,1", "--dims", "8,8,8", "--out", out}, "not a finite number"},
      {"empty_points", {"compute", "--points", ";", "--dims", "8,8,8", "--out", out}, "no point"},
      {"bad_origin", with({"--origin", "1,2"}, pts), "--origin"},
      {"missing_volume", {"compute", "--volume", tmp("nope.npy"), "--out", out}, "cannot open"},
      {"malformed_volume", {"compute", "--volume", text_file, "--out", out}, "not a .npy file"},
      {"empty_volume", {"compute", "--volume", empty_mask, "--out", out}, "no nonzero voxel"},
      {"signed_full_volume",
       {"compute", "--volume", good_mask, "--sign", "mask-inside", "--out", out},
       "no zero voxel"},
      {"dims_mismatch", {"compute", "--volume", good_mask, "--dims", "4,4,5", "--out", out}, "disagrees"},
      {"bad_stencil", with({"--stencil", "cubic27"}, pts), "--stencil 'cubic27'"},
      {"bad_mode", with({"--mode", "fast"}, pts), "--mode 'fast'"},
      {"negative_limit", with({"--limit", "-1"}, pts), "--limit"},
      {"zero_limit", with({"--limit", "0"}, pts), "--limit"},
      {"text_limit", with({"--limit", "far"}, pts), "--limit"},
      {"negative_segment", with({"--segment", "-2"}, pts), "--segment"},
      {"negative_threads", with({"--threads", "-1"}, pts), "--threads"},
      {"zero_voxel_size", with({"--voxel-size", "0"}, pts), "--voxel-size"},
      {"zero_resolution",
       {"compute", "--mesh", std::string(DISTBAND_TEST_DATA_DIR) + "/meshes/bunny.obj", "--resolution", "0", "--out",
        out},
       "--resolution must be at least 2 voxels (got 0)"},
      {"unsupported_out",
       {"compute", "--points", "1,1,1", "--dims", "8,8,8", "--out", tmp("f.txt")},
       "--out " + tmp("f.txt") + ": expected a .vdb, .npy, .nii.gz file"},
      {"unwritable_out",
       {"compute", "--points", "1,1,1", "--dims", "8,8,8", "--out", "/nonexistent/d/f.npy"},
       "does not exist"},
  };
  for (const Case& c : cases) {
    const CliResult r = run(c.args);
    EXPECT_EQ(r.code, 2) << c.name << "\nstdout: " << r.out << "\nstderr: " << r.err;
    EXPECT_NE(r.err.find(c.expect), std::string::npos) << c.name << ": stderr was: " << r.err;
    EXPECT_FALSE(std::filesystem::exists(out)) << c.name << ": nothing may be written on error";
  }
  std::remove(good_mask.c_str());
  std::remove(text_file.c_str());
  std::remove(empty_mask.c_str());
}

TEST(ComputeCommandTest, InterruptedRunWritesNothing) {
  const std::string out = tmp("interrupted.npy");
  std::remove(out.c_str());
  const CliResult r =
      run({"compute", "--points", "1,1,1", "--dims", "32,32,32", "--segment", "2", "--out", out}, [] { return true; });
  EXPECT_EQ(r.code, 130) << r.err;
  EXPECT_NE(r.err.find("interrupted"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(ComputeCommandTest, ListParsers) {
  Vec3d v;
  EXPECT_EQ(parseVec3(" 1.5, -2,3e1 ", "--origin", &v), "");
  EXPECT_EQ(v, (Vec3d{1.5, -2, 30}));
  EXPECT_NE(parseVec3("1,2,3,4", "--origin", &v).find("--origin '1,2,3,4': expected three"), std::string::npos);
  EXPECT_NE(parseVec3("1,,3", "--origin", &v).find("--origin '1,,3': '' is not a finite number"), std::string::npos);
  EXPECT_NE(parseVec3("1,inf,3", "--origin", &v).find("'inf' is not a finite number"), std::string::npos);
  Coord c;
  EXPECT_EQ(parseDims("256, 128,64", &c), "");
  EXPECT_EQ(c, (Coord{256, 128, 64}));
  EXPECT_NE(parseDims("256,128,64.5", &c).find("'64.5' is not an integer"), std::string::npos);
  EXPECT_NE(parseDims("-1,2,3", &c).find("every extent must be in [1,"), std::string::npos);
  std::vector<Vec3d> pts;
  EXPECT_EQ(parsePointList("1,2,3;4,5,6;", &pts), "");
  ASSERT_EQ(pts.size(), 2u);
  EXPECT_EQ(pts[1], (Vec3d{4, 5, 6}));
}

}  // namespace
}  // namespace distband

namespace distband {
namespace {

// Sets a flag once the text written to it contains `needle` (the watch thread reads only the flag).
class Tripwire : public std::stringbuf {
 public:
  explicit Tripwire(std::string needle) : needle_(std::move(needle)) {}
  std::atomic<bool> tripped{false};

 protected:
  std::streamsize xsputn(const char* s, std::streamsize n) override {
    const std::streamsize r = std::stringbuf::xsputn(s, n);
    if (str().find(needle_) != std::string::npos) tripped = true;
    return r;
  }
  int overflow(int c) override {
    const int r = std::stringbuf::overflow(c);
    if (str().find(needle_) != std::string::npos) tripped = true;
    return r;
  }

 private:
  std::string needle_;
};

std::string readText(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// Ctrl-C after a few segments: the complete ones are written (atomically) with complete=false metadata beside the
// field, every voxel up to the last complete segment's bound holds its exact distance, the rest the background.
TEST(ComputeCommandTest, InterruptKeepsEveryCompleteSegment) {
  const std::string out = tmp("interrupted.npy"), meta = tmp("interrupted.json");
  std::remove(out.c_str());
  std::remove(meta.c_str());
  Tripwire trip("segment   3");
  std::ostream out_stream(&trip);
  std::ostringstream err;
  const CliContext ctx{out_stream, err, [&trip] { return trip.tripped.load(); }};
  const int code = runDistband({"compute", "--points", "80,80,80", "--dims", "160,160,160", "--segment", "0.5",
                                "--threads", "2", "--out", out},
                               ctx);
  ASSERT_EQ(code, kExitInterrupted) << trip.str() << err.str();
  EXPECT_NE(err.str().find("interrupted; kept the"), std::string::npos) << err.str();
  EXPECT_NE(err.str().find("complete=false"), std::string::npos) << err.str();
  const std::string json = readText(meta);
  ASSERT_FALSE(json.empty()) << "the metadata goes beside an incomplete field";
  EXPECT_NE(json.find("\"complete\": false"), std::string::npos) << json;
  const size_t at = json.find("\"complete_up_to\": ");
  ASSERT_NE(at, std::string::npos) << json;
  const double up_to = std::stod(json.substr(at + 18));
  const size_t seg_at = json.find("\"segments\": ");
  ASSERT_NE(seg_at, std::string::npos);
  const int segments = std::stoi(json.substr(seg_at + 12));
  EXPECT_GE(segments, 4);
  EXPECT_NEAR(up_to, 0.5 * segments, 1e-9);
  EXPECT_LT(up_to, 130) << "the run should have been stopped well before its end";
  std::vector<float> v;
  Coord d;
  ASSERT_TRUE(IsOk(readNpyFloat32(out, &v, &d)));
  int64_t kept = 0, wrong = 0;
  for (int z = 0; z < d.z; ++z)
    for (int y = 0; y < d.y; ++y)
      for (int x = 0; x < d.x; ++x) {
        const double exact = std::sqrt(double((x - 80) * (x - 80) + (y - 80) * (y - 80) + (z - 80) * (z - 80)));
        const float got = v[(size_t(z) * d.y + y) * d.x + x];
        if (exact <= up_to - 1e-6) {
          ++kept;
          wrong += std::abs(got - exact) > 1e-5;
        } else if (exact > up_to + 1e-6) {
          wrong += !std::isinf(got);  // beyond the complete segments: the background (no limit: +infinity)
        }
      }
  EXPECT_GT(kept, 20);  // at least the 4 segments up to 2 voxels
  EXPECT_EQ(wrong, 0);
  std::remove(out.c_str());
  std::remove(meta.c_str());
}

// compute writes what query writes: closest-feature ids (checked against the brute-force distance of the recorded
// triangle), a slice picture, an isosurface and metadata naming the sign method and why, and the padding.
TEST(ComputeCommandTest, SharesQuerysOutputsIncludingClosestFeatures) {
  const std::string mesh_path = std::string(DISTBAND_TEST_DATA_DIR) + "/meshes/fandisk.off";
  const std::string out = tmp("fandisk.npy"), ids = tmp("fandisk_ids.npy"), png = tmp("fandisk.png"),
                    obj = tmp("fandisk.obj"), meta = tmp("fandisk.json");
  const CliResult r = run({"compute", "--mesh", mesh_path, "--resolution", "40", "--limit-voxels", "3", "--out", out,
                           "--closest", ids, "--slice-png", "z:mid", png, "--isosurface", "0", obj, "--meta", meta});
  ASSERT_EQ(r.code, 0) << r.err << r.out;
  EXPECT_NE(r.out.find("sign pseudonormal (auto: the mesh is closed)"), std::string::npos) << r.out;
  for (const std::string& f : {png, obj}) EXPECT_GT(std::filesystem::file_size(f), 100u) << f;
  const std::string json = readText(meta);
  EXPECT_NE(json.find("\"reason\": \"auto: the mesh is closed\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"padding_voxels\": 3"), std::string::npos) << json;
  EXPECT_NE(json.find("\"feature\": \"triangle\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"complete\": true"), std::string::npos) << json;

  std::vector<float> field;
  Coord d;
  ASSERT_TRUE(IsOk(readNpyFloat32(out, &field, &d)));
  NpyArray id_array;
  ASSERT_TRUE(IsOk(readNpy(ids, &id_array)));
  EXPECT_EQ(id_array.descr, "<i4");
  ASSERT_EQ(id_array.data.size(), field.size() * 4);
  TriangleMesh mesh;
  ASSERT_TRUE(IsOk(loadMesh(mesh_path, &mesh, nullptr)));
  // The grid as the command built it: origin from the metadata would do too; the npy's voxel (0,0,0) is the origin.
  const size_t o = json.find("\"origin\": [");
  ASSERT_NE(o, std::string::npos);
  std::istringstream origin_text(json.substr(o + 11));
  Vec3d origin;
  char comma;
  origin_text >> origin.x >> comma >> origin.y >> comma >> origin.z;
  const size_t h_at = json.find("\"voxel_size\": ");
  const double h = std::stod(json.substr(h_at + 14));
  const Grid grid(origin, h, d);
  int64_t with_id = 0, wrong = 0;
  for (int64_t i = 0; i < int64_t(field.size()); ++i) {
    int32_t id;
    std::memcpy(&id, id_array.data.data() + 4 * i, 4);
    if (id < 0) continue;
    ++with_id;
    const Coord c{int(i % d.x), int(i / d.x % d.y), int(i / (int64_t(d.x) * d.y))};
    TriangleMesh one;
    for (uint32_t v : mesh.triangles[size_t(id)]) one.vertices.push_back(mesh.vertices[v]);
    one.triangles = {{0, 1, 2}};
    wrong += std::abs(testing::bruteDistance(one, grid.worldOf(c)) - std::abs(double(field[size_t(i)]))) > 1e-5 * h + 1e-6;
  }
  EXPECT_GT(with_id, 1000);
  EXPECT_EQ(wrong, 0);
  for (const std::string& f : {out, ids, png, obj, meta}) std::remove(f.c_str());
}

}  // namespace
}  // namespace distband

namespace distband {
namespace {

// --closest naming --out's .vdb: an Int32Grid "closest" beside the distances, each id the point at the voxel's value.
TEST(ComputeCommandTest, ClosestGridBesideTheDistancesInTheVdb) {
  const std::string out = tmp("closest.vdb");
  const std::vector<Vec3d> points = {{3, 4, 5}, {12.5, 9, 7}, {6, 13, 10}};
  const CliResult r = run({"compute", "--points", "3,4,5;12.5,9,7;6,13,10", "--dims", "24,20,16", "--limit", "4",
                           "--out", out, "--closest", out});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("and grid \"closest\" of point ids"), std::string::npos) << r.out;
  EXPECT_EQ(run({"compute", "--points", "1,1,1", "--dims", "8,8,8", "--limit", "2", "--out", tmp("a.vdb"),
                 "--closest", tmp("b.vdb")})
                .code,
            kExitUsage);
  openvdb::initialize();
  openvdb::io::File file(out);
  file.open();
  auto distance = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("distance"));
  auto closest = openvdb::gridPtrCast<openvdb::Int32Grid>(file.readGrid("closest"));
  file.close();
  ASSERT_TRUE(distance && closest);
  EXPECT_EQ(closest->background(), -1);
  EXPECT_EQ(closest->activeVoxelCount(), distance->activeVoxelCount());
  auto acc = distance->getConstAccessor();
  int64_t wrong = 0;
  for (auto it = closest->cbeginValueOn(); it; ++it) {
    const openvdb::Coord c = it.getCoord();
    const Vec3d p = points.at(size_t(*it));
    const double d = (Vec3d{double(c.x()), double(c.y()), double(c.z())} - p).length();
    wrong += std::abs(d - acc.getValue(c)) > 1e-5;
  }
  EXPECT_GT(closest->activeVoxelCount(), 500u);
  EXPECT_EQ(wrong, 0);
  std::remove(out.c_str());
}

}  // namespace
}  // namespace distband

namespace distband {
namespace {

// The grid's other two ways (GridSpec's): around the points' bounds without --dims, and a --box (gridForMesh's box:
// the origin is the box's min, no padding unless asked, the longest side spans --resolution voxels).
TEST(ComputeCommandTest, GridAroundThePointsOrInsideABox) {
  const std::string out = tmp("grid_ways.npy"), meta = tmp("grid_ways.json");
  CliResult r =
      run({"compute", "--points", "1,2,3;4,6,5", "--voxel-size", "0.5", "--limit", "1", "--out", out, "--meta", meta});
  ASSERT_EQ(r.code, 0) << r.err;
  std::vector<float> v;
  Coord d;
  ASSERT_TRUE(IsOk(readNpyFloat32(out, &v, &d)));
  EXPECT_EQ(d, (Coord{13, 15, 11}));  // extents 3, 4, 2 over 0.5, + 1, + core's default padding of 3 on both sides
  EXPECT_NE(readText(meta).find("\"padding_voxels\": 3"), std::string::npos) << readText(meta);

  const std::string mesh = std::string(DISTBAND_TEST_DATA_DIR) + "/meshes/fandisk.off";
  r = run({"compute", "--mesh", mesh, "--resolution", "21", "--box", "0,0,0,1,2,1", "--limit-voxels", "2", "--out", out,
           "--meta", meta});
  ASSERT_EQ(r.code, 0) << r.err;
  ASSERT_TRUE(IsOk(readNpyFloat32(out, &v, &d)));
  EXPECT_EQ(d, (Coord{11, 21, 11}));  // voxel size 2 / 20
  EXPECT_NE(readText(meta).find("\"padding_voxels\": 0"), std::string::npos) << readText(meta);
  std::remove(out.c_str());
  std::remove(meta.c_str());
}

// --deadline stops the run as Ctrl-C does, but exits 1: the command failed to finish in time.
TEST(ComputeCommandTest, DeadlineStopsTheRunAndExitsOne) {
  const std::string out = tmp("deadline.npy");
  const CliResult r = run({"compute", "--points", "80,80,80", "--dims", "160,160,160", "--segment", "0.5", "--deadline",
                           "0.000001", "--out", out});
  EXPECT_EQ(r.code, kExitFailure) << r.err;
  EXPECT_NE(r.err.find("the deadline (--deadline) passed"), std::string::npos) << r.err;
  std::remove(out.c_str());
}

// The header names the algorithm with core's words (algorithmDescription), the band's stencil with it.
TEST(ComputeCommandTest, HeaderNamesTheAlgorithmInCoresWords) {
  const std::string out = tmp("algorithm.npy");
  CliResult r = run({"compute", "--points", "1,1,1", "--dims", "16,16,16", "--stencil", "cubic18", "--out", out});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("algorithm: " + algorithmDescription(FieldAlgorithm::kBand, SeedKind::kPoints, false) +
                       "; stencil cubic18\n"),
            std::string::npos)
      << r.out;
  r = run({"compute", "--points", "1,1,1", "--dims", "16,16,16", "--out", out});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(
      r.out.find("algorithm: " + algorithmDescription(FieldAlgorithm::kSeparable, SeedKind::kPoints, false) + "\n"),
      std::string::npos)
      << r.out;
  // --algorithm names the algorithm; the planner refuses the separable one where it does not apply.
  r = run({"compute", "--points", "1,1,1", "--dims", "16,16,16", "--algorithm", "band", "--out", out});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("algorithm: " + algorithmDescription(FieldAlgorithm::kBand, SeedKind::kPoints, false)),
            std::string::npos)
      << r.out;
  r = run({"compute", "--points", "1,1,1", "--dims", "16,16,16", "--algorithm", "separable", "--limit", "3", "--out",
           out});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_NE(r.err.find("algorithm: separable applies"), std::string::npos) << r.err;
  std::remove(out.c_str());
}

}  // namespace
}  // namespace distband
