// Tests for core/io/npy: byte-exact agreement with numpy.save, round trips, and a clear error for every way an
// untrusted .npy file can be malformed.
#include "core/io/npy.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/io/field_metadata.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

constexpr Status::Code kInvalid = Status::Code::kInvalidArgument;

// Headers written by numpy 1.24 (np.save / np.lib.format.write_array) for shape (2, 3, 4).
constexpr char kNumpyU1V1[] =
    "\x93NUMPY\x01\x00v\x00{'descr': '|u1', 'fortran_order': False, 'shape': (2, 3, 4), }"
    "                                                       \x0a";
constexpr char kNumpyF4V1[] =
    "\x93NUMPY\x01\x00v\x00{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3, 4), }"
    "                                                       \x0a";
constexpr char kNumpyU1V3[] =
    "\x93NUMPY\x03\x00t\x00\x00\x00{'descr': '|u1', 'fortran_order': False, 'shape': (2, 3, 4), }"
    "                                                     \x0a";

template <size_t N>
std::string lit(const char (&s)[N]) {
  return std::string(s, N - 1);
}

std::string tempPath(const std::string& name) { return ::testing::TempDir() + "npy_test_" + name; }

void writeBytes(const std::string& path, const std::string& bytes) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(bytes.data(), std::streamsize(bytes.size()));
}

std::string readBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

/// A v1 .npy image with an arbitrary header dict (padded like numpy) and payload.
std::string handMade(const std::string& dict, size_t payload_bytes, int major = 1) {
  std::string h = dict;
  const size_t pre = major == 1 ? 10 : 12;
  while ((pre + h.size() + 1) % 64) h.push_back(' ');
  h.push_back('\n');
  std::string out = "\x93NUMPY";
  out.push_back(char(major));
  out.push_back('\0');
  out.push_back(char(h.size() & 0xff));
  out.push_back(char(h.size() >> 8));
  if (major != 1) out.append(2, '\0');
  return out + h + std::string(payload_bytes, '\x01');
}

std::vector<uint8_t> iota24() {
  std::vector<uint8_t> v(24);
  for (int i = 0; i < 24; ++i) v[i] = uint8_t(i);
  return v;
}

TEST(NpyTest, EncodesExactlyLikeNumpy) {
  const std::vector<uint8_t> data = iota24();
  const std::string ours = encodeNpy("|u1", {2, 3, 4}, data.data(), data.size());
  EXPECT_EQ(ours, lit(kNumpyU1V1) + std::string(data.begin(), data.end()));
  const std::string f4 = encodeNpy("<f4", {2, 3, 4}, nullptr, 0);
  EXPECT_EQ(f4, lit(kNumpyF4V1));
  EXPECT_EQ(f4.size() % 64, 0u);
}

TEST(NpyTest, ParsesNumpyFilesOfEveryVersion) {
  const std::vector<uint8_t> data = iota24();
  const std::string payload(data.begin(), data.end());
  for (const std::string& header : {lit(kNumpyU1V1), lit(kNumpyU1V3)}) {
    NpyArray a;
    ASSERT_TRUE(IsOk(parseNpy(header + payload, "mem", &a)));
    EXPECT_EQ(a.descr, "|u1");
    EXPECT_FALSE(a.fortran_order);
    EXPECT_EQ(a.shape, (std::vector<int64_t>{2, 3, 4}));
    EXPECT_EQ(a.data, data);
  }
  // Version 2.0 uses the same 4-byte length as 3.0.
  std::string v2 = lit(kNumpyU1V3);
  v2[6] = 2;
  NpyArray a;
  EXPECT_TRUE(IsOk(parseNpy(v2 + payload, "mem", &a)));
  // Key order, quotes and spacing are free in a Python dict literal; Python 2 wrote "3L".
  const std::string odd = handMade("{\"shape\":(2,3L,4) ,'fortran_order':False,'descr':'|b1'}", 24);
  EXPECT_TRUE(IsOk(parseNpy(odd, "mem", &a)));
  EXPECT_EQ(a.descr, "|b1");
  EXPECT_EQ(a.shape, (std::vector<int64_t>{2, 3, 4}));
}

TEST(NpyTest, MaskRoundTripAndLayout) {
  const Coord dims{4, 3, 2};  // X, Y, Z -> shape (2, 3, 4)
  const std::vector<uint8_t> mask = iota24();
  const std::string path = tempPath("mask.npy");
  ASSERT_TRUE(IsOk(writeNpyMask(path, mask, dims)));
  EXPECT_EQ(readBytes(path), lit(kNumpyU1V1) + std::string(mask.begin(), mask.end()));
  LabelVolume volume;
  ASSERT_TRUE(IsOk(readNpyVolume(path, &volume)));
  EXPECT_EQ(volume.dims(), dims);
  EXPECT_EQ(volume.type(), VoxelType::kUint8);
  const std::vector<uint8_t>& back = volume.bytes();
  EXPECT_EQ(back, mask);
  // Element [z][y][x] is voxel (x, y, z): x fastest.
  EXPECT_EQ(back[(1 * 3 + 2) * 4 + 3], 23);
  std::remove(path.c_str());
}

TEST(NpyTest, BoolMasksAreAccepted) {
  const std::string path = tempPath("bool.npy");
  std::string bytes = handMade("{'descr': '|b1', 'fortran_order': False, 'shape': (1, 2, 3), }", 0);
  bytes += std::string("\x00\x01\x00\x01\x01\x00", 6);
  writeBytes(path, bytes);
  LabelVolume v;
  ASSERT_TRUE(IsOk(readNpyVolume(path, &v)));
  EXPECT_EQ(v.dims(), (Coord{3, 2, 1}));
  EXPECT_EQ(v.bytes(), (std::vector<uint8_t>{0, 1, 0, 1, 1, 0}));
  std::remove(path.c_str());
}

// Label volumes: uint16 and uint32 in either byte order, written back with the element type.
TEST(NpyTest, LabelVolumesOfEveryWidthRoundTrip) {
  const std::string path = tempPath("labels.npy");
  for (VoxelType type : {VoxelType::kUint16, VoxelType::kUint32}) {
    const size_t w = voxelTypeBytes(type);
    std::vector<uint8_t> bytes(2 * 3 * 4 * w);
    for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = uint8_t(i * 7 + 1);
    const LabelVolume labels({4, 3, 2}, type, std::make_shared<const std::vector<uint8_t>>(bytes));
    ASSERT_TRUE(IsOk(writeNpyVolume(path, labels)));
    LabelVolume back;
    ASSERT_TRUE(IsOk(readNpyVolume(path, &back)));
    EXPECT_EQ(back.type(), type);
    EXPECT_EQ(back.dims(), labels.dims());
    EXPECT_EQ(back.bytes(), labels.bytes());
    // The same values written big-endian read back alike.
    std::vector<uint8_t> swapped = bytes;
    for (size_t i = 0; i < swapped.size(); i += w) std::reverse(swapped.begin() + int64_t(i), swapped.begin() + int64_t(i + w));
    writeBytes(path, encodeNpy(w == 2 ? ">u2" : ">u4", {2, 3, 4}, swapped.data(), swapped.size()));
    ASSERT_TRUE(IsOk(readNpyVolume(path, &back)));
    EXPECT_EQ(back.bytes(), labels.bytes());
    EXPECT_EQ(back.at(5), labels.at(5));
  }
  std::remove(path.c_str());
}

TEST(NpyTest, Float32RoundTrip) {
  const Coord dims{5, 7, 3};
  std::vector<float> v(5 * 7 * 3);
  for (size_t i = 0; i < v.size(); ++i) v[i] = float(i) * 0.37f - 11.0f;
  v[4] = std::numeric_limits<float>::infinity();
  v[5] = -0.0f;
  const std::string path = tempPath("field.npy");
  ASSERT_TRUE(IsOk(writeNpyFloat32(path, v, dims)));
  std::vector<float> back;
  Coord d;
  ASSERT_TRUE(IsOk(readNpyFloat32(path, &back, &d)));
  EXPECT_EQ(d, dims);
  ASSERT_EQ(back.size(), v.size());
  EXPECT_EQ(std::memcmp(back.data(), v.data(), v.size() * sizeof(float)), 0);
  NpyArray a;
  ASSERT_TRUE(IsOk(readNpy(path, &a)));
  EXPECT_EQ(a.shape, (std::vector<int64_t>{3, 7, 5}));
  EXPECT_EQ(a.descr, "<f4");
  EXPECT_TRUE(IsError(writeNpyFloat32(path, std::vector<float>(3), dims), kInvalid, "3 values do not fill dims 5x7x3"))
      << "size mismatch must be refused";
  std::remove(path.c_str());
}

TEST(NpyTest, WriteToAnUnwritablePathFails) {
  // The OS refuses the file (its directory does not exist): an I/O error naming the path, not a bad argument.
  EXPECT_TRUE(IsError(writeNpyFloat32("/nonexistent-dir/x/field.npy", std::vector<float>(1), {1, 1, 1}),
                      Status::Code::kIoError, "/nonexistent-dir/x/field.npy"));
}

TEST(NpyTest, WritesAreAtomicAndLeaveNoTemporaryBehind) {
  // A fresh directory: after writes (and a failed one), it holds exactly the targets, no "*.tmp-*" file.
  const std::string dir = ::testing::TempDir() + "npy_atomic_" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string npy = dir + "/field.npy", json = dir + "/field.json";
  ASSERT_TRUE(IsOk(writeNpyFloat32(npy, std::vector<float>(8, 1.0f), {2, 2, 2})));
  // A reader holding the old file keeps seeing a whole array while the next write replaces it (rename, not truncate).
  std::ifstream old(npy, std::ios::binary);
  ASSERT_TRUE(IsOk(writeNpyFloat32(npy, std::vector<float>(27, 2.0f), {3, 3, 3})));
  const std::string old_bytes((std::istreambuf_iterator<char>(old)), std::istreambuf_iterator<char>());
  NpyArray a;
  ASSERT_TRUE(IsOk(parseNpy(old_bytes, "old", &a)));
  EXPECT_EQ(a.shape, (std::vector<int64_t>{2, 2, 2}));
  std::vector<float> back;
  Coord d;
  ASSERT_TRUE(IsOk(readNpyFloat32(npy, &back, &d)));
  EXPECT_EQ(d, (Coord{3, 3, 3}));
  FieldMetadata meta;
  meta.grid = Grid({}, 1.0, {3, 3, 3});
  ASSERT_TRUE(IsOk(writeFieldMetadata(json, meta)));
  EXPECT_TRUE(IsError(writeNpyFloat32(npy, std::vector<float>(5), {3, 3, 3}), kInvalid, "5 values do not fill dims"));
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"field.json", "field.npy"}));
  std::filesystem::remove_all(dir);
}

struct Malformed {
  std::string name;
  std::string bytes;
  std::string expect;  ///< substring of the error message
  Status::Code code = Status::Code::kInvalidArgument;
};

TEST(NpyTest, EveryMalformedFileGivesAClearError) {
  const std::string good = lit(kNumpyU1V1) + std::string(24, '\x01');
  std::string bad_version = good;
  bad_version[6] = 4;
  std::string bad_minor = good;
  bad_minor[7] = 1;
  std::string long_header = good.substr(0, 8) + std::string("\xff\xff", 2) + good.substr(10);
  const std::vector<Malformed> cases = {
      {"empty", "", "not a .npy file"},
      {"text", "hello, world\n", "not a .npy file"},
      {"magic_only", "\x93NUMPY", "truncated"},
      {"bad_version", bad_version, "version 4.0"},
      {"bad_minor", bad_minor, "version 1.1"},
      {"header_beyond_file", long_header, "truncated .npy header"},
      {"truncated_header", good.substr(0, 60), "truncated .npy header"},
      {"truncated_data", good.substr(0, good.size() - 5), "truncated: shape (2, 3, 4)"},
      {"no_data", lit(kNumpyU1V1), "truncated"},
      {"trailing_bytes", good + "xyz", "3 unexpected bytes"},
      {"not_a_dict", handMade("['descr', '|u1']", 24), "not a Python dict"},
      {"missing_shape", handMade("{'descr': '|u1', 'fortran_order': False}", 24), "missing 'shape'"},
      {"missing_descr", handMade("{'fortran_order': False, 'shape': (2, 3, 4)}", 24), "missing 'descr'"},
      {"missing_order", handMade("{'descr': '|u1', 'shape': (2, 3, 4)}", 24), "missing 'fortran_order'"},
      {"extra_key", handMade("{'descr': '|u1', 'fortran_order': False, 'shape': (2, 3, 4), 'x': 1}", 24),
       "unexpected key 'x'"},
      {"bad_order", handMade("{'descr': '|u1', 'fortran_order': 0, 'shape': (2, 3, 4)}", 24), "True or False"},
      {"negative_shape", handMade("{'descr': '|u1', 'fortran_order': False, 'shape': (2, -3, 4)}", 24),
       "non-integer or negative"},
      {"shape_not_tuple", handMade("{'descr': '|u1', 'fortran_order': False, 'shape': [2, 3, 4]}", 24),
       "must be a tuple"},
      {"unterminated_dict", handMade("{'descr': '|u1', 'fortran_order': False, 'shape': (2, 3, 4)", 24),
       "expected ',' or '}'"},
      {"structured_dtype",
       handMade("{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (2, 3, 4)}", 96), "structured"},
      {"object_dtype", handMade("{'descr': '|O', 'fortran_order': False, 'shape': (2, 3, 4)}", 192),
       "unsupported dtype '|O'"},
      {"huge_shape",
       handMade("{'descr': '<f8', 'fortran_order': False, 'shape': (1000000, 1000000, 1000000)}", 0), "too large",
       Status::Code::kResourceExhausted},
      {"absurd_extent", handMade("{'descr': '|u1', 'fortran_order': False, 'shape': (1, 1, 99999999999999)}", 0),
       "absurdly large", Status::Code::kResourceExhausted},
      {"nul_in_header", handMade(std::string("{'descr': '|u1',") + std::string(1, '\0') + " 'fortran_order': False, 'shape': (2, 3, 4)}", 24),
       "NUL"},
  };
  for (const Malformed& m : cases) {
    NpyArray a;
    const Status mem_err = parseNpy(m.bytes, "mem.npy", &a);
    EXPECT_TRUE(IsError(mem_err, m.code, m.expect)) << m.name;
    EXPECT_NE(mem_err.message().find("mem.npy"), std::string::npos) << m.name << ": the message must name the file";
    const std::string path = tempPath(m.name + ".npy");
    writeBytes(path, m.bytes);
    const Status file_err = readNpy(path, &a);
    EXPECT_TRUE(IsError(file_err, m.code, m.expect)) << m.name << " (file)";
    EXPECT_NE(file_err.message().find(path), std::string::npos) << m.name << ": got " << file_err.toString();
    std::remove(path.c_str());
  }
}

TEST(NpyTest, WrongKindsOfArrayForAMaskOrAField) {
  struct Case {
    std::string name, dict;
    size_t payload;
    bool mask;  ///< read as a mask (else as float32)
    std::string expect;
  };
  const std::vector<Case> cases = {
      {"int32_mask", "{'descr': '<i4', 'fortran_order': False, 'shape': (2, 3, 4)}", 96, true, "uint16 or uint32"},
      {"float_mask", "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3, 4)}", 96, true, "uint16 or uint32"},
      {"int8_mask", "{'descr': '|i1', 'fortran_order': False, 'shape': (2, 3, 4)}", 24, true, "uint16 or uint32"},
      {"u8_labels", "{'descr': '<u8', 'fortran_order': False, 'shape': (2, 3, 4)}", 192, true, "uint16 or uint32"},
      {"fortran_mask", "{'descr': '|u1', 'fortran_order': True, 'shape': (2, 3, 4)}", 24, true, "fortran_order"},
      {"2d_mask", "{'descr': '|u1', 'fortran_order': False, 'shape': (4, 6)}", 24, true, "3-D array"},
      {"4d_mask", "{'descr': '|u1', 'fortran_order': False, 'shape': (1, 2, 3, 4)}", 24, true, "3-D array"},
      {"scalar_mask", "{'descr': '|u1', 'fortran_order': False, 'shape': ()}", 1, true, "3-D array"},
      {"zero_extent", "{'descr': '|u1', 'fortran_order': False, 'shape': (2, 0, 4)}", 0, true, "[1, 16384]"},
      {"too_wide", "{'descr': '|u1', 'fortran_order': False, 'shape': (1, 1, 20000)}", 20000, true, "[1, 16384]"},
      {"f8_field", "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3, 4)}", 192, false, "float32"},
      {"big_endian_field", "{'descr': '>f4', 'fortran_order': False, 'shape': (2, 3, 4)}", 96, false, "'>f4'"},
      {"u1_field", "{'descr': '|u1', 'fortran_order': False, 'shape': (2, 3, 4)}", 24, false, "float32"},
  };
  for (const Case& c : cases) {
    const std::string path = tempPath(c.name + ".npy");
    writeBytes(path, handMade(c.dict, c.payload));
    LabelVolume m;
    std::vector<float> f{4.2f};
    Coord d{9, 9, 9};
    const Status err = c.mask ? readNpyVolume(path, &m) : readNpyFloat32(path, &f, &d);
    EXPECT_TRUE(IsError(err, kInvalid, c.expect)) << c.name;
    EXPECT_NE(err.message().find(path), std::string::npos) << c.name << ": got " << err.toString();
    EXPECT_FALSE(bool(m)) << c.name << ": output touched on error";
    EXPECT_EQ(d, (Coord{9, 9, 9})) << c.name;
    std::remove(path.c_str());
  }
  LabelVolume m;
  const std::string missing = tempPath("does-not-exist.npy");
  const Status err = readNpyVolume(missing, &m);
  EXPECT_TRUE(IsError(err, Status::Code::kNotFound, "cannot open"));
  EXPECT_NE(err.message().find(missing), std::string::npos) << err.toString();
}

TEST(FieldMetadataTest, DescribesTheField) {
  FieldMetadata meta;
  meta.grid = Grid({1.5, -2, 0}, 0.25, {10, 20, 30});
  meta.data_file = "field.npy";
  meta.signed_distance = true;
  meta.limit_world = 2.5;
  meta.background_world = 2.5;
  meta.stencil = "cubic26";
  meta.mode = "exact";
  const std::string j = fieldMetadataJson(meta);
  for (const char* s : {"\"dims\"", "10,", "\"voxel_size\": 0.25", "\"origin\"", "-2.0", "\"limit\": 2.5",
                        "negative inside", "\"stencil\": \"cubic26\"", "[z][y][x]"})
    EXPECT_NE(j.find(s), std::string::npos) << s << " missing in\n" << j;
  EXPECT_EQ(j.find("voxels_by_test"), std::string::npos);  // not a mesh sign
  meta.sign = "winding";
  meta.sign_reason = "auto: the mesh is not closed (12 boundary edges)";
  meta.sign_shares = {0, 700, 300, 0};
  const std::string js = fieldMetadataJson(meta);
  for (const char* s : {"\"method\": \"winding\"", "\"voxels_by_test\"", "\"winding_certified\": 700",
                        "\"winding_per_voxel\": 300", "\"pseudonormal\": 0"})
    EXPECT_NE(js.find(s), std::string::npos) << s << " missing in\n" << js;
  meta.limit_world = std::numeric_limits<double>::infinity();
  EXPECT_NE(fieldMetadataJson(meta).find("\"limit\": null"), std::string::npos);
  const std::string path = tempPath("field.json");
  ASSERT_TRUE(IsOk(writeFieldMetadata(path, meta)));
  EXPECT_EQ(readBytes(path), fieldMetadataJson(meta));
  std::remove(path.c_str());
}

}  // namespace
}  // namespace distband
