// Tests for core/mesh/mesh_reader: every format and encoding, the hostile inputs of the security review (declared
// counts far beyond the bytes, truncation, huge lists, files named by statements), limits, error messages, and the
// memory a parse allocates (counted by replacing the global allocator of this test binary).
#include <malloc.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <new>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "core/mesh/mesh_reader.h"

// ---- Allocation counting (the whole binary; a few atomic adds per allocation) ---------------------------------------
namespace {
std::atomic<int64_t> g_live{0}, g_peak{0};
void* countedAlloc(size_t n) {
  void* p = std::malloc(n ? n : 1);
  if (!p) throw std::bad_alloc();
  const int64_t live = g_live.fetch_add(int64_t(malloc_usable_size(p))) + int64_t(malloc_usable_size(p));
  for (int64_t peak = g_peak.load(); live > peak && !g_peak.compare_exchange_weak(peak, live);) {
  }
  return p;
}
void countedFree(void* p) {
  if (!p) return;
  g_live.fetch_sub(int64_t(malloc_usable_size(p)));
  std::free(p);
}
}  // namespace
void* operator new(size_t n) { return countedAlloc(n); }
void* operator new[](size_t n) { return countedAlloc(n); }
void operator delete(void* p) noexcept { countedFree(p); }
void operator delete[](void* p) noexcept { countedFree(p); }
void operator delete(void* p, size_t) noexcept { countedFree(p); }
void operator delete[](void* p, size_t) noexcept { countedFree(p); }

namespace distband {
namespace {

/// Bytes allocated at the peak of `fn` beyond what was live when it started.
template <typename Fn>
int64_t peakBytesOf(Fn&& fn) {
  const int64_t base = g_live.load();
  g_peak.store(base);
  fn();
  return g_peak.load() - base;
}

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

struct Parsed {
  Status status;
  TriangleMesh mesh;
  MeshReport report;
};

Parsed parse(const std::string& bytes, MeshFormat format, MeshReadLimits limits = {},
             const Interrupter* interrupter = nullptr) {
  Parsed p;
  p.status = readMesh(bytes, format, limits, interrupter, &p.mesh, &p.report);
  return p;
}

// A unit tetrahedron, outward, in each encoding.
const double kTetV[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
const int kTetF[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};

template <typename T>
void appendValue(std::string* s, T v, bool big_endian) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big_endian) std::reverse(b, b + sizeof(T));
  s->append(b, sizeof(T));
}

/// A binary PLY of the tetrahedron with an extra vertex property, a list-valued extra element before the faces,
/// and faces of `index_type` (int or uchar counts).
std::string tetPlyBinary(bool big_endian) {
  std::string s = std::string("ply\nformat ") + (big_endian ? "binary_big_endian" : "binary_little_endian") +
                  " 1.0\ncomment made by a test\nelement vertex 4\nproperty double x\nproperty float y\n"
                  "property uchar red\nproperty float z\nelement material 1\nproperty list uchar float coefficients\n"
                  "element face 4\nproperty list uchar int vertex_indices\nproperty int flags\nend_header\n";
  for (const auto& v : kTetV) {
    appendValue<double>(&s, v[0], big_endian);
    appendValue<float>(&s, float(v[1]), big_endian);
    appendValue<uint8_t>(&s, 200, big_endian);
    appendValue<float>(&s, float(v[2]), big_endian);
  }
  appendValue<uint8_t>(&s, 2, big_endian);
  appendValue<float>(&s, 0.5f, big_endian);
  appendValue<float>(&s, 0.25f, big_endian);
  for (const auto& f : kTetF) {
    appendValue<uint8_t>(&s, 3, big_endian);
    for (int k : f) appendValue<int32_t>(&s, k, big_endian);
    appendValue<int32_t>(&s, 7, big_endian);
  }
  return s;
}

std::string tetStlBinary(const std::string& header_start = "") {
  std::string s = header_start + std::string(80 - header_start.size(), ' ');
  appendValue<uint32_t>(&s, 4, false);
  for (const auto& f : kTetF) {
    for (int i = 0; i < 3; ++i) appendValue<float>(&s, 0.f, false);
    for (int k : f)
      for (int a = 0; a < 3; ++a) appendValue<float>(&s, float(kTetV[k][a]), false);
    s.append(2, '\0');
  }
  return s;
}

std::string stlVertexLine(const double* v) {
  return "      vertex " + std::to_string(v[0]) + " " + std::to_string(v[1]) + " " + std::to_string(v[2]) + "\n";
}

void expectTetrahedron(const Parsed& p, const char* what) {
  ASSERT_TRUE(p.status.ok()) << what << ": " << p.status.toString();
  EXPECT_EQ(p.report.vertices, 4) << what;
  EXPECT_EQ(p.report.triangles, 4) << what;
  EXPECT_TRUE(p.report.closed()) << what;
  EXPECT_EQ(p.report.bbox_max.x, 1) << what;
}

TEST(MeshReaderTest, EveryFormatAndEncodingReadsTheTetrahedron) {
  expectTetrahedron(parse("# c\nmtllib x.mtl\no tet\nv 0 0 0\nv 1 0 0 1\nv 0 1 0 0.5 0.5 0.5\nv 0 0 1\nvn 0 0 1\n"
                          "vt 0 0\nusemtl m\ns off\nf 1/1/1 3//1 2\nf -4 -3 -1\nf 1/1 4 3\nf 2 3 4\n",
                          MeshFormat::kObj),
                    "OBJ");
  expectTetrahedron(parse("OFF # comment\n4 4 0\n0 0 0\n1 0 0\n\n0 1 0 # x\n0 0 1\n3 0 2 1\n3 0 1 3 255 0 0\n"
                          "3 0 3 2\n3 1 2 3\n",
                          MeshFormat::kOff),
                    "OFF");
  expectTetrahedron(parse("COFF\n4 4\n0\n0 0 0 1 1 1 1\n1 0 0 1 1 1 1\n0 1 0 1 1 1 1\n0 0 1 1 1 1 1\n3 0 2 1\n"
                          "3 0 1 3\n3 0 3 2\n3 1 2 3\n",
                          MeshFormat::kOff),
                    "COFF, counts split over lines");
  expectTetrahedron(parse("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                          "property float z\nelement face 4\nproperty list uchar int vertex_index\nend_header\n"
                          "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n",
                          MeshFormat::kPly),
                    "PLY ascii");
  expectTetrahedron(parse(tetPlyBinary(false), MeshFormat::kPly), "PLY binary little endian");
  expectTetrahedron(parse(tetPlyBinary(true), MeshFormat::kPly), "PLY binary big endian");
  expectTetrahedron(parse(tetStlBinary(), MeshFormat::kStl), "STL binary");
  expectTetrahedron(parse(tetStlBinary("solid but binary"), MeshFormat::kStl), "STL binary starting with 'solid'");
  std::string ascii = "solid tet\n";
  for (const auto& f : kTetF) {
    ascii += "  facet normal 0 0 0\n    outer loop\n";
    for (int k : f) ascii += stlVertexLine(kTetV[k]);
    ascii += "    endloop\n  endfacet\n";
  }
  expectTetrahedron(parse(ascii + "endsolid tet\n", MeshFormat::kStl), "STL ascii");
}

TEST(MeshReaderTest, PolygonsAreFannedAndFacesMayPrecedeVertices) {
  // A unit cube of 6 quads; PLY with the face element first.
  std::string ply = "ply\nformat ascii 1.0\nelement face 6\nproperty list uchar int vertex_indices\nelement vertex 8\n"
                    "property float x\nproperty float y\nproperty float z\nend_header\n"
                    "4 0 3 2 1\n4 4 5 6 7\n4 0 1 5 4\n4 1 2 6 5\n4 2 3 7 6\n4 3 0 4 7\n"
                    "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n1 1 1\n0 1 1\n";
  const Parsed p = parse(ply, MeshFormat::kPly);
  ASSERT_TRUE(p.status.ok()) << p.status.toString();
  EXPECT_EQ(p.report.triangles, 12);
  EXPECT_TRUE(p.report.closed());
  // An OFF face with more than 9 corners (a decagon) is a fan of 8 triangles.
  std::string off = "OFF\n11 1 0\n";
  for (int i = 0; i < 10; ++i) off += std::to_string(std::cos(i * 0.6283185307)) + " " + std::to_string(std::sin(i * 0.6283185307)) + " 0\n";
  off += "0 0 5\n10 0 1 2 3 4 5 6 7 8 9\n";
  const Parsed d = parse(off, MeshFormat::kOff);
  ASSERT_TRUE(d.status.ok()) << d.status.toString();
  EXPECT_EQ(d.report.triangles, 8);
}

std::string repeat(const std::string& s, int n) {
  std::string out;
  for (int i = 0; i < n; ++i) out += s;
  return out;
}

TEST(MeshReaderTest, HostileDeclaredCountsAreRefusedBeforeAnyAllocation) {
  struct Case {
    const char* what;
    MeshFormat format;
    std::string bytes;
    Status::Code code;
    const char* message;
  };
  std::string list = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                     "property float z\nelement face 1\nproperty list int int vertex_indices\nend_header\n";
  list += std::string(36, '\0');
  appendValue<int32_t>(&list, 0x7fffffff, false);
  const Case cases[] = {
      {"188-byte ascii PLY declaring 1e8 vertices", MeshFormat::kPly,
       "ply\nformat ascii 1.0\nelement vertex 100000000\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n",
       Status::Code::kInvalidArgument, "PLY element 'vertex'"},
      {"binary PLY face list of 2^31-1 indices", MeshFormat::kPly, list, Status::Code::kInvalidArgument,
       "PLY element 'face' 0 (byte"},
      {"OFF counts split over lines", MeshFormat::kOff, "OFF\n100000000\n\n100000000 0\n0 0 0\n",
       Status::Code::kInvalidArgument, "bytes follow"},
      {"binary STL declaring 2^28 triangles", MeshFormat::kStl,
       std::string(80, 'x') + std::string("\x00\x00\x00\x10", 4) + std::string(100, '\0'),
       Status::Code::kInvalidArgument, "truncated"},
      {"OFF face declaring a million corners", MeshFormat::kOff, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n1000000 0 1 2\n",
       Status::Code::kInvalidArgument, "declares 1000000 corners"},
      {"PLY element of 2^60 empty records (found by fuzzing: a reader must not loop over them)", MeshFormat::kPly,
       "ply\nformat ascii 1.0\nelement empty 1152921504606846976\nelement vertex 3\nproperty float x\n"
       "property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
       Status::Code::kInvalidArgument, "out of range"},
      {"PLY vertex count over the limit", MeshFormat::kPly,
       "ply\nformat ascii 1.0\nelement vertex 2000\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 0\nproperty list uchar int vertex_indices\nend_header\n" + repeat("0 0 0\n", 2000),
       Status::Code::kResourceExhausted, "limit"},
  };
  MeshReadLimits limits;
  limits.max_vertices = 1000;
  for (const Case& c : cases) {
    Parsed p;
    const int64_t peak = peakBytesOf([&] { p = parse(c.bytes, c.format, limits); });
    EXPECT_EQ(p.status.code(), c.code) << c.what << ": " << p.status.toString();
    EXPECT_NE(p.status.message().find(c.message), std::string::npos) << c.what << ": " << p.status.message();
    EXPECT_LT(peak, 64 << 10) << c.what << " allocated " << peak << " bytes";
  }
}

TEST(MeshReaderTest, TruncatedFilesNameTheElementAndWhere) {
  std::string ply = tetPlyBinary(false);
  const Parsed p = parse(ply.substr(0, ply.size() - 10), MeshFormat::kPly);
  EXPECT_EQ(p.status.code(), Status::Code::kInvalidArgument);
  EXPECT_NE(p.status.message().find("PLY element 'face' 3 (byte"), std::string::npos) << p.status.message();
  const Parsed ascii = parse("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                             "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                             "0 0 0\n1 0 0\n0 1 0\n3 0 1\n",
                             MeshFormat::kPly);
  EXPECT_NE(ascii.status.message().find("line"), std::string::npos) << ascii.status.message();
  const Parsed off = parse("OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n", MeshFormat::kOff);
  EXPECT_NE(off.status.message().find("bytes follow"), std::string::npos) << off.status.message();
  const Parsed off_long = parse("OFF\n4 4 0\n0.000000 0.000000 0.000000\n1.000000 0.000000 0.000000\n"
                                "0.000000 1.000000 0.000000\n0.000000 0.000000 1.000000\n3 0 2 1\n3 0 1 3\n3 0 3 2\n",
                                MeshFormat::kOff);
  EXPECT_NE(off_long.status.message().find("3 of the 4 faces"), std::string::npos) << off_long.status.message();
  std::string stl = tetStlBinary();
  EXPECT_FALSE(parse(stl.substr(0, stl.size() - 1), MeshFormat::kStl).status.ok());
  EXPECT_NE(parse("solid x\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\n", MeshFormat::kStl).status.message().find(
                "expected 'vertex'"),
            std::string::npos);
}

TEST(MeshReaderTest, StatementsNamingFilesAreIgnoredAndNothingIsQuotedBeyondAnExcerpt) {
  const std::string secret = "/etc/shadow";
  const Parsed ok = parse("mtllib " + secret + "\ncall " + secret + "\nmaplib " + secret +
                              "\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
                          MeshFormat::kObj);
  EXPECT_TRUE(ok.status.ok()) << ok.status.toString();
  const std::string junk = "v 0 0 \x01\x02" + std::string(200, 'A') + "\n";
  const Parsed bad = parse(junk, MeshFormat::kObj);
  EXPECT_EQ(bad.status.code(), Status::Code::kInvalidArgument);
  EXPECT_NE(bad.status.message().find("\\x01\\x02"), std::string::npos) << bad.status.message();
  EXPECT_EQ(bad.status.message().find(std::string(40, 'A')), std::string::npos) << "an excerpt is at most 32 bytes";
  EXPECT_NE(bad.status.message().find("OBJ line 1"), std::string::npos);
}

TEST(MeshReaderTest, LimitsAndInterruption) {
  MeshReadLimits limits;
  limits.max_triangles = 3;
  const std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
  EXPECT_EQ(parse(obj, MeshFormat::kObj, limits).status.code(), Status::Code::kResourceExhausted);
  EXPECT_EQ(parse(tetStlBinary(), MeshFormat::kStl, limits).status.code(), Status::Code::kResourceExhausted);
  Interrupter cancelled;
  cancelled.cancel();
  EXPECT_EQ(parse(obj, MeshFormat::kObj, {}, &cancelled).status.code(), Status::Code::kCancelled);
  EXPECT_EQ(parse(tetPlyBinary(false), MeshFormat::kPly, {}, &cancelled).status.code(), Status::Code::kCancelled);
}

TEST(MeshReaderTest, OutOfRangeAndNonFiniteValuesAreErrors) {
  EXPECT_NE(parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", MeshFormat::kObj).status.message().find("vertex number"),
            std::string::npos);
  EXPECT_NE(parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n", MeshFormat::kObj).status.message().find("out of range"),
            std::string::npos);
  EXPECT_NE(parse("v 0 0 inf\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", MeshFormat::kObj).status.message().find("finite"),
            std::string::npos);
  EXPECT_NE(parse("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 -1\n", MeshFormat::kOff).status.message().find("vertex -1"),
            std::string::npos);
  EXPECT_FALSE(parse("ply\nformat binary_middle_endian 1.0\nend_header\n", MeshFormat::kPly).status.ok());
  EXPECT_FALSE(parse("OFF BINARY\n3 1 0\n", MeshFormat::kOff).status.ok());
  EXPECT_FALSE(parse("4OFF\n3 1 0\n", MeshFormat::kOff).status.ok());
}

// ---- Memory: peak allocation while parsing <= meshReadPeakBytes(input) -------------------------------------------

/// `mesh` as text in `format` (the shortest number formatting, as real exporters write).
std::string serialise(const TriangleMesh& mesh, MeshFormat format) {
  std::string s;
  auto num = [](double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%.9g", v);
    return std::string(b);
  };
  if (format == MeshFormat::kObj) {
    for (const Vec3d& v : mesh.vertices) s += "v " + num(v.x) + " " + num(v.y) + " " + num(v.z) + "\n";
    for (const auto& t : mesh.triangles)
      s += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " + std::to_string(t[2] + 1) + "\n";
  } else if (format == MeshFormat::kPly) {
    s = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(mesh.vertices.size()) +
        "\nproperty float x\nproperty float y\nproperty float z\nelement face " + std::to_string(mesh.triangles.size()) +
        "\nproperty list uchar int vertex_indices\nend_header\n";
    for (const Vec3d& v : mesh.vertices)
      for (double c : {v.x, v.y, v.z}) appendValue<float>(&s, float(c), false);
    for (const auto& t : mesh.triangles) {
      appendValue<uint8_t>(&s, 3, false);
      for (uint32_t i : t) appendValue<int32_t>(&s, int32_t(i), false);
    }
  } else if (format == MeshFormat::kStl) {
    s = std::string(80, ' ');
    appendValue<uint32_t>(&s, uint32_t(mesh.triangles.size()), false);
    for (const auto& t : mesh.triangles) {
      for (int i = 0; i < 3; ++i) appendValue<float>(&s, 0.f, false);
      for (uint32_t i : t)
        for (double c : {mesh.vertices[i].x, mesh.vertices[i].y, mesh.vertices[i].z}) appendValue<float>(&s, float(c), false);
      s.append(2, '\0');
    }
  }
  return s;
}

TEST(MeshReaderTest, ParsingAllocatesAtMostTheStatedBoundPerInputByte) {
  const std::string dir = DISTBAND_TEST_DATA_DIR "/meshes/";
  TriangleMesh bunny;
  ASSERT_TRUE(readMesh(readFile(dir + "bunny.obj"), MeshFormat::kObj, {}, nullptr, &bunny, nullptr).ok());
  struct Input {
    std::string name;
    std::string bytes;
    MeshFormat format;
  };
  std::vector<Input> inputs = {
      {"bunny.obj", readFile(dir + "bunny.obj"), MeshFormat::kObj},
      {"teapot.obj", readFile(dir + "teapot.obj"), MeshFormat::kObj},
      {"fandisk.off", readFile(dir + "fandisk.off"), MeshFormat::kOff},
      {"bunny as binary PLY", serialise(bunny, MeshFormat::kPly), MeshFormat::kPly},
      {"bunny as binary STL", serialise(bunny, MeshFormat::kStl), MeshFormat::kStl},
      {"bunny as short OBJ", serialise(bunny, MeshFormat::kObj), MeshFormat::kObj},
  };
  // Adversarial densities: one huge polygon (2-3 bytes per fan triangle), and the shortest possible vertex lines.
  std::string polygon = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 1\nf 1";
  for (int i = 0; i < 100000; ++i) polygon += i % 2 ? " 2 3" : " 3 4";
  inputs.push_back({"OBJ polygon of 200k corners", polygon + "\n", MeshFormat::kObj});
  std::string grid_off = "OFF\n40000 1 0\n";
  for (int i = 0; i < 40000; ++i) grid_off += std::to_string(i % 10) + " " + std::to_string(i / 10 % 10) + " " +
                                              std::to_string(i / 100 % 10) + "\n";
  inputs.push_back({"OFF of short vertex lines", grid_off + "3 0 1 10\n", MeshFormat::kOff});
  for (const Input& in : inputs) {
    Parsed p;
    const int64_t peak = peakBytesOf([&] { p = parse(in.bytes, in.format); });
    ASSERT_TRUE(p.status.ok()) << in.name << ": " << p.status.toString();
    const double ratio = double(peak) / double(in.bytes.size());
    std::printf("%-28s %9zu bytes in, peak %10lld bytes allocated = %5.2f x input\n", in.name.c_str(), in.bytes.size(),
                (long long)peak, ratio);
    EXPECT_LE(uint64_t(peak), meshReadPeakBytes(in.bytes.size())) << in.name;
  }
}

}  // namespace
}  // namespace distband
