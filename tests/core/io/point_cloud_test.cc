// Tests for core/io/point_cloud: the three formats read whole and chunk by chunk (from memory and from files with
// blocks smaller than a line), the same points from every format, and malformed, hostile and oversized inputs refused
// with a message naming the point, line or byte.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "core/io/npy.h"
#include "core/io/point_cloud.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

std::vector<Vec3d> somePoints(int n) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-100, 100);
  std::vector<Vec3d> p;
  for (int i = 0; i < n; ++i) p.push_back({u(rng), u(rng), u(rng)});
  return p;
}

std::string npyOf(const std::vector<Vec3d>& points, bool doubles) {
  std::string data;
  for (const Vec3d& p : points)
    for (double v : {p.x, p.y, p.z}) {
      if (doubles) data.append(reinterpret_cast<const char*>(&v), 8);
      else {
        const float f = float(v);
        data.append(reinterpret_cast<const char*>(&f), 4);
      }
    }
  return encodeNpy(doubles ? "<f8" : "<f4", {int64_t(points.size()), 3}, data.data(), data.size());
}

std::string xyzOf(const std::vector<Vec3d>& points) {
  std::string text = "# a comment\n\n";
  for (const Vec3d& p : points) text += fmt::format("{:.17g} {:.17g}\t{:.17g}  0 0 1\r\n", p.x, p.y, p.z);
  return text;
}

std::string plyOf(const std::vector<Vec3d>& points, const char* format) {
  std::string h = fmt::format(
      "ply\nformat {} 1.0\ncomment points\nelement camera 1\nproperty float a\nproperty list uchar int ids\n"
      "element vertex {}\nproperty double x\nproperty double y\nproperty double z\nproperty uchar red\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n",
      format, points.size());
  if (std::string(format) == "ascii") {
    h += "1.5 2 7 8\n";
    for (const Vec3d& p : points) h += fmt::format("{:.17g} {:.17g} {:.17g} 255\n", p.x, p.y, p.z);
    h += "3 0 1 2\n";
    return h;
  }
  const float a = 1.5f;
  h.append(reinterpret_cast<const char*>(&a), 4);
  h.push_back('\x02');
  const int32_t ids[2] = {7, 8};
  h.append(reinterpret_cast<const char*>(ids), 8);
  for (const Vec3d& p : points) {
    for (double v : {p.x, p.y, p.z}) h.append(reinterpret_cast<const char*>(&v), 8);
    h.push_back('\xff');
  }
  return h;
}

std::vector<Vec3d> readAll(const std::string& bytes, PointFileFormat format, PointReadLimits limits = {}) {
  std::vector<Vec3d> out;
  const Status s = readPointCloud(bytes, format, limits, "cloud", nullptr, &out);
  EXPECT_TRUE(IsOk(s));
  return out;
}

std::string writeTemp(const std::string& name, const std::string& bytes) {
  const std::string path = (std::filesystem::temp_directory_path() / ("distband_point_cloud_" + name)).string();
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

TEST(PointCloudTest, EveryFormatGivesTheSamePoints) {
  const std::vector<Vec3d> points = somePoints(1000);
  EXPECT_EQ(readAll(npyOf(points, true), PointFileFormat::kNpy), points);
  EXPECT_EQ(readAll(xyzOf(points), PointFileFormat::kXyz), points);
  EXPECT_EQ(readAll(plyOf(points, "ascii"), PointFileFormat::kPly), points);
  EXPECT_EQ(readAll(plyOf(points, "binary_little_endian"), PointFileFormat::kPly), points);
  const std::vector<Vec3d> floats = readAll(npyOf(points, false), PointFileFormat::kNpy);
  ASSERT_EQ(floats.size(), points.size());
  for (size_t i = 0; i < points.size(); ++i) EXPECT_EQ(floats[i].x, double(float(points[i].x)));
}

TEST(PointCloudTest, FilesReadInChunksThroughSmallBlocksGiveTheSamePoints) {
  const std::vector<Vec3d> points = somePoints(3000);
  const std::pair<std::string, std::string> files[] = {{"a.npy", npyOf(points, true)},
                                                       {"a.xyz", xyzOf(points)},
                                                       {"a.ply", plyOf(points, "ascii")},
                                                       {"b.ply", plyOf(points, "binary_little_endian")}};
  for (const auto& [name, bytes] : files) {
    SCOPED_TRACE(name);
    const std::string path = writeTemp(name, bytes);
    PointFileFormat format;
    ASSERT_TRUE(pointFileFormatFromPath(path, &format));
    PointReadLimits limits;
    limits.block_bytes = 100;  // smaller than a text line: every refill path runs
    std::unique_ptr<PointCloudReader> reader;
    ASSERT_TRUE(IsOk(PointCloudReader::fromFile(path, format, limits, &reader)));
    std::vector<Vec3d> got;
    for (;;) {
      const size_t before = got.size();
      ASSERT_TRUE(IsOk(reader->next(77, &got)));
      if (got.size() == before) break;
      EXPECT_LE(got.size() - before, 77u);
    }
    EXPECT_EQ(got, points);
    EXPECT_EQ(reader->pointsRead(), points.size());
    EXPECT_TRUE(reader->doublePrecision());
    std::vector<Vec3d> whole;
    ASSERT_TRUE(IsOk(loadPointCloud(path, {}, nullptr, &whole)));
    EXPECT_EQ(whole, points);
    std::filesystem::remove(path);
  }
}

TEST(PointCloudTest, MalformedInputsAreRefusedNamingWhere) {
  auto refuses = [](const std::string& bytes, PointFileFormat format, Status::Code code, const std::string& names) {
    std::vector<Vec3d> out;
    const Status s = readPointCloud(bytes, format, {}, "cloud", nullptr, &out);
    EXPECT_TRUE(IsError(s, code, names)) << names;
    EXPECT_TRUE(out.empty());
  };
  using F = PointFileFormat;
  using C = Status::Code;
  refuses("1 2 3\n4 5\n", F::kXyz, C::kInvalidArgument, "line 2: expected x y z, found 2 numbers");
  refuses("1 2 3\n4 5 nan\n", F::kXyz, C::kInvalidArgument, "line 2: 'nan' is not a finite number");
  refuses("1 2 3\n4 5 6 7\n", F::kXyz, C::kInvalidArgument, "line 2: 4 numbers, but the first point's line has 3");
  refuses("1 2 3\n4 5 1e999\n", F::kXyz, C::kInvalidArgument, "line 2");
  refuses(std::string(70000, '1') + "\n", F::kXyz, C::kInvalidArgument, "longer than 64 KiB");
  const std::vector<Vec3d> points = somePoints(4);
  std::string npy = npyOf(points, true);
  refuses(npy.substr(0, npy.size() - 1), F::kNpy, C::kInvalidArgument, "needs 96 data bytes, the file holds 95");
  refuses(npy + "x", F::kNpy, C::kInvalidArgument, "the file holds 97");
  refuses(encodeNpy("<i4", {2, 3}, "000000000000000000000000", 24), F::kNpy, C::kInvalidArgument, "float32 or float64");
  refuses(encodeNpy("<f4", {2, 2}, "0000000000000000", 16), F::kNpy, C::kInvalidArgument, "shape (N, 3)");
  std::string bad = npy;
  const double nan = std::nan("");
  std::memcpy(bad.data() + bad.size() - 8, &nan, 8);
  refuses(bad, F::kNpy, C::kInvalidArgument, "point 3");
  refuses("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nend_header\n1 2\n3 4\n", F::kPly,
          C::kInvalidArgument, "lacks a scalar x, y or z");
  refuses("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
          "1 2 3\n4 5 6\n",
          F::kPly, C::kInvalidArgument, "the header declares 3 records");
  refuses("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
          "1 2 3\n4 zz 6\n",
          F::kPly, C::kInvalidArgument, "(line 9): property 'y'");
  refuses("ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\n"
          "property float z\nend_header\n",
          F::kPly, C::kInvalidArgument, "1000000000 records");
  refuses("ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty list uint float x\nproperty float y\n"
          "property float z\nend_header\n\xff\xff\xff\x7f",
          F::kPly, C::kInvalidArgument, "lacks a scalar x");
  refuses("plx\n", F::kPly, C::kInvalidArgument, "does not start with 'ply'");
}

TEST(PointCloudTest, AnElementWithoutPropertiesIsSkippedWhateverItsCount) {
  // Its records hold no bytes, so no size check bounds its count: skipping 2^62 of them one by one never ended (fuzz).
  for (const char* format : {"ascii", "binary_little_endian"}) {
    std::string ply = fmt::format(
        "ply\nformat {} 1.0\nelement nothing 4611686018427387904\nelement vertex 1\n"
        "property double x\nproperty double y\nproperty double z\nend_header\n",
        format);
    const double xyz[3] = {1.5, -2, 3};
    ply += std::string_view(format) == "ascii" ? "1.5 -2 3\n" : std::string(reinterpret_cast<const char*>(xyz), 24);
    std::vector<Vec3d> out;
    ASSERT_TRUE(IsOk(readPointCloud(ply, PointFileFormat::kPly, {}, "cloud", nullptr, &out))) << format;
    EXPECT_EQ(out, std::vector<Vec3d>({{1.5, -2, 3}})) << format;
  }
}

TEST(PointCloudTest, CountsBeyondTheLimitAreRefusedBeforeReading) {
  const std::vector<Vec3d> points = somePoints(50);
  PointReadLimits limits;
  limits.max_points = 49;
  for (const auto& [bytes, format] : {std::pair{npyOf(points, false), PointFileFormat::kNpy},
                                      std::pair{xyzOf(points), PointFileFormat::kXyz},
                                      std::pair{plyOf(points, "binary_little_endian"), PointFileFormat::kPly}}) {
    std::vector<Vec3d> out;
    EXPECT_TRUE(IsError(readPointCloud(bytes, format, limits, "cloud", nullptr, &out), Status::Code::kResourceExhausted,
                        "more than the limit of 49"));
  }
}

TEST(PointCloudTest, FilesThatCannotBeReadAreNamed) {
  std::vector<Vec3d> out;
  EXPECT_TRUE(IsError(loadPointCloud("/nonexistent/q.npy", {}, nullptr, &out), Status::Code::kNotFound, "q.npy"));
  EXPECT_TRUE(IsError(loadPointCloud("q.obj", {}, nullptr, &out), Status::Code::kInvalidArgument, "q.obj"));
}

}  // namespace
}  // namespace distband
