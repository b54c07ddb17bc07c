// Tests for core/io/volume_file, nifti, nrrd and gzip: NIfTI-1/2 and NRRD files built here byte by byte from the
// formats' published layouts (not with core's writer), read back with their labels and geometry — either byte order,
// compressed or not, every element type, sform, qform and pixdims, space directions and spacings — and every kind of
// malformed, oversized or hostile file refused with a message naming it: truncated and trailing data, sizes beyond
// the limits, gzip bombs, rotated directions, detached data. The .nii.gz writer's header read back field by field.
#include "core/io/volume_file.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "core/io/gzip.h"
#include "core/io/nifti.h"
#include "core/io/nrrd.h"
#include "tests/support/status_testing.h"

namespace distband {
namespace {

constexpr Status::Code kInvalid = Status::Code::kInvalidArgument;

template <class T>
void put(std::string& b, size_t at, T v, bool big = false) {
  char raw[sizeof v];
  std::memcpy(raw, &v, sizeof v);
  if (big) std::reverse(raw, raw + sizeof v);
  std::memcpy(b.data() + at, raw, sizeof v);
}

struct NiftiSpec {
  int version = 1;
  bool big = false;
  int dims[3] = {4, 3, 2};
  int16_t datatype = 512;  // uint16
  int16_t bitpix = 16;
  float pixdim[4] = {1, 0.7f, 0.7f, 2.5f};
  int qform = 0, sform = 1;
  float srow[3][4] = {{0.7f, 0, 0, 10}, {0, 0.7f, 0, -20}, {0, 0, 2.5f, 30}};
  float quatern[3] = {0, 0, 0}, qoffset[3] = {0, 0, 0};
  float scl_slope = 0, scl_inter = 0;
  int64_t vox_offset = -1;  // -1: right after the header and the extension flag
  std::string data;         // the elements as they are to be written
};

/// A single-file NIfTI image per the NIfTI-1 / NIfTI-2 layouts.
std::string nifti(const NiftiSpec& s) {
  const bool two = s.version == 2;
  const size_t header = two ? 540 : 348;
  const int64_t offset = s.vox_offset >= 0 ? s.vox_offset : int64_t(header + 4);
  std::string b(size_t(std::max<int64_t>(offset, int64_t(header))), '\0');
  const bool big = s.big;
  put<int32_t>(b, 0, two ? 540 : 348, big);
  if (two) {
    std::memcpy(b.data() + 4, "n+2\0\r\n\032\n", 8);
    put<int16_t>(b, 12, s.datatype, big);
    put<int16_t>(b, 14, s.bitpix, big);
    put<int64_t>(b, 16, 3, big);
    for (int i = 0; i < 3; ++i) put<int64_t>(b, 24 + 8 * i, s.dims[i], big);
    for (int i = 3; i < 7; ++i) put<int64_t>(b, 24 + 8 * i, 1, big);
    for (int i = 0; i < 4; ++i) put<double>(b, 104 + 8 * i, s.pixdim[i], big);
    put<int64_t>(b, 168, offset, big);
    put<double>(b, 176, s.scl_slope, big);
    put<double>(b, 184, s.scl_inter, big);
    put<int32_t>(b, 344, s.qform, big);
    put<int32_t>(b, 348, s.sform, big);
    for (int i = 0; i < 3; ++i)
      put<double>(b, 352 + 8 * i, s.quatern[i], big), put<double>(b, 376 + 8 * i, s.qoffset[i], big);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) put<double>(b, 400 + 32 * r + 8 * c, s.srow[r][c], big);
  } else {
    put<int16_t>(b, 40, 3, big);
    for (int i = 0; i < 3; ++i) put<int16_t>(b, 42 + 2 * i, int16_t(s.dims[i]), big);
    for (int i = 3; i < 7; ++i) put<int16_t>(b, 42 + 2 * i, 1, big);
    put<int16_t>(b, 70, s.datatype, big);
    put<int16_t>(b, 72, s.bitpix, big);
    for (int i = 0; i < 4; ++i) put<float>(b, 76 + 4 * i, s.pixdim[i], big);
    put<float>(b, 108, float(offset), big);
    put<float>(b, 112, s.scl_slope, big);
    put<float>(b, 116, s.scl_inter, big);
    put<int16_t>(b, 252, int16_t(s.qform), big);
    put<int16_t>(b, 254, int16_t(s.sform), big);
    for (int i = 0; i < 3; ++i)
      put<float>(b, 256 + 4 * i, s.quatern[i], big), put<float>(b, 268 + 4 * i, s.qoffset[i], big);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) put<float>(b, 280 + 16 * r + 4 * c, s.srow[r][c], big);
    std::memcpy(b.data() + 344, "n+1\0", 4);
  }
  return b + s.data;
}

/// `count` uint16 values i * 7 % 300 in either byte order.
std::string u16(size_t count, bool big = false) {
  std::string d(2 * count, '\0');
  for (size_t i = 0; i < count; ++i) put<uint16_t>(d, 2 * i, uint16_t(i * 7 % 300), big);
  return d;
}

std::string gz(const std::string& raw) {
  std::string out;
  EXPECT_TRUE(IsOk(gzipCompress(raw, &out)));
  return out;
}

void expectLabels(const VolumeImage& image, const Coord& dims) {
  ASSERT_EQ(image.volume.dims(), dims);
  for (int64_t i = 0; i < image.volume.voxelCount(); ++i) ASSERT_EQ(image.volume.at(i), uint32_t(i * 7 % 300)) << i;
}

TEST(NiftiTest, ReadsBothVersionsBothByteOrdersCompressedOrNot) {
  for (int version : {1, 2})
    for (bool big : {false, true})
      for (bool compressed : {false, true}) {
        NiftiSpec s;
        s.version = version;
        s.big = big;
        s.data = u16(24, big);
        const std::string raw = nifti(s);
        VolumeImage image;
        const std::string what = fmt::format("version {} big {} gz {}", version, big, compressed);
        ASSERT_TRUE(IsOk(parseNifti(compressed ? gz(raw) : raw, "a.nii", {}, &image))) << what;
        expectLabels(image, {4, 3, 2});
        EXPECT_EQ(image.volume.type(), VoxelType::kUint16) << what;
        EXPECT_NEAR(image.geometry.spacing.x, 0.7, 1e-6) << what;
        EXPECT_NEAR(image.geometry.spacing.z, 2.5, 1e-6) << what;
        EXPECT_EQ(image.geometry.origin, (Vec3d{10, -20, 30})) << what;
        EXPECT_TRUE(image.geometry.from_header);
        EXPECT_FALSE(image.geometry.reoriented);
      }
}

TEST(NiftiTest, GeometryFromTheSformTheQformOrThePixdims) {
  NiftiSpec s;
  s.data = u16(24);
  // A flipped x axis (LAS): accepted, spacing positive, the affine kept for writing back.
  s.srow[0][0] = -0.7f;
  VolumeImage image;
  ASSERT_TRUE(IsOk(parseNifti(nifti(s), "flip.nii", {}, &image)));
  EXPECT_NEAR(image.geometry.spacing.x, 0.7, 1e-6);
  EXPECT_TRUE(image.geometry.reoriented);
  EXPECT_NEAR((*image.geometry.affine)[0][0], -0.7, 1e-6);
  // The qform: a quaternion of 180 degrees about z (b = c = 0, d = 1) flips x and y; qfac -1 flips z.
  s.sform = 0;
  s.qform = 1;
  s.quatern[2] = 1;
  s.qoffset[0] = 5;
  s.pixdim[0] = -1;
  ASSERT_TRUE(IsOk(parseNifti(nifti(s), "q.nii", {}, &image)));
  EXPECT_NEAR(image.geometry.spacing.y, 0.7, 1e-6);
  EXPECT_NEAR(image.geometry.spacing.z, 2.5, 1e-6);
  EXPECT_NEAR((*image.geometry.affine)[0][0], -0.7, 1e-6);
  EXPECT_NEAR((*image.geometry.affine)[1][1], -0.7, 1e-6);
  EXPECT_NEAR((*image.geometry.affine)[2][2], -2.5, 1e-6);
  EXPECT_EQ(image.geometry.origin.x, 5);
  // Neither: the pixdims.
  s.qform = 0;
  ASSERT_TRUE(IsOk(parseNifti(nifti(s), "p.nii", {}, &image)));
  EXPECT_NEAR(image.geometry.spacing.z, 2.5, 1e-6);
  EXPECT_EQ(image.geometry.origin, (Vec3d{0, 0, 0}));
  // A rotated sform is refused.
  s = NiftiSpec{};
  s.data = u16(24);
  s.srow[0][1] = 0.3f;
  EXPECT_TRUE(IsError(parseNifti(nifti(s), "rot.nii", {}, &image), kInvalid, "rot.nii: the sform is rotated"));
}

TEST(NiftiTest, ElementTypesSignedAndFloatLabelsAreConvertedWhenTheyAreLabels) {
  struct Case {
    int16_t datatype, bitpix;
    std::string data;
    bool ok;
    VoxelType type;
  };
  std::string i16(48, '\0'), f32(96, '\0'), bad_f32(96, '\0'), neg(48, '\0'), u8(24, '\0'), big_f64(192, '\0');
  for (int i = 0; i < 24; ++i) {
    put<int16_t>(i16, 2 * size_t(i), int16_t(i * 7 % 300));
    put<float>(f32, 4 * size_t(i), float(i * 7 % 300));
    put<float>(bad_f32, 4 * size_t(i), i == 5 ? 2.5f : float(i));
    put<int16_t>(neg, 2 * size_t(i), int16_t(i == 9 ? -3 : i));
    u8[size_t(i)] = char(i * 7 % 300 % 256);
    put<double>(big_f64, 8 * size_t(i), i == 2 ? 70000.0 : 1.0);
  }
  const Case cases[] = {
      {4, 16, i16, true, VoxelType::kUint8},       {16, 32, f32, true, VoxelType::kUint8},
      {16, 32, bad_f32, false, VoxelType::kUint8}, {4, 16, neg, false, VoxelType::kUint8},
      {64, 64, big_f64, true, VoxelType::kUint32}, {16, 16, f32, false, VoxelType::kUint8},  // bitpix mismatch
      {32, 64, f32, false, VoxelType::kUint8},                                               // complex64
  };
  for (const Case& c : cases) {
    NiftiSpec s;
    s.datatype = c.datatype;
    s.bitpix = c.bitpix;
    s.data = c.data;
    VolumeImage image;
    const Status st = parseNifti(nifti(s), "t.nii", {}, &image);
    EXPECT_EQ(st.ok(), c.ok) << c.datatype << " bitpix " << c.bitpix << " " << st.toString();
    if (st.ok()) {
      EXPECT_EQ(image.volume.type(), c.type) << c.datatype;
    }
  }
  NiftiSpec s;
  s.data = u16(24);
  s.scl_slope = 2;
  VolumeImage image;
  EXPECT_TRUE(IsError(parseNifti(nifti(s), "s.nii", {}, &image), kInvalid, "scaled data"));
}

TEST(NiftiTest, HostileFilesAreRefusedBeforeAnythingLarge) {
  VolumeImage image;
  NiftiSpec s;
  s.data = u16(24);
  const std::string good = nifti(s);
  EXPECT_TRUE(IsError(parseNifti(good.substr(0, good.size() - 1), "t.nii", {}, &image), kInvalid, "(truncated)"));
  EXPECT_TRUE(IsError(parseNifti(good + "x", "t.nii", {}, &image), kInvalid, "(trailing bytes)"));
  EXPECT_TRUE(IsError(parseNifti(good.substr(0, 100), "t.nii", {}, &image), kInvalid, "truncated NIfTI-1 header"));
  std::string pair = good;
  std::memcpy(pair.data() + 344, "ni1\0", 4);
  EXPECT_TRUE(IsError(parseNifti(pair, "t.nii", {}, &image), kInvalid, "single-file .nii"));
  EXPECT_TRUE(IsError(parseNifti(std::string(400, 'x'), "junk.nii", {}, &image), kInvalid, "not a NIfTI file"));
  // Sizes beyond the limits are refused from the header, before any data is read or inflated.
  s.dims[0] = 16000, s.dims[1] = 16000, s.dims[2] = 16000;
  s.data.clear();
  EXPECT_TRUE(IsError(parseNifti(nifti(s), "huge.nii", {1 << 20}, &image), Status::Code::kResourceExhausted,
                      "exceed the limit"));
  s.dims[0] = 20000;
  EXPECT_TRUE(IsError(parseNifti(nifti(s), "wide.nii", {}, &image), kInvalid, "not in [1, 16384]"));
  // A gzip bomb: a header declaring 24 voxels followed by megabytes of zeros inflates no further than declared.
  NiftiSpec bomb;
  bomb.data = std::string(size_t(64) << 20, '\0');
  EXPECT_TRUE(IsError(parseNifti(gz(nifti(bomb)), "bomb.nii.gz", {}, &image), kInvalid,
                      "inflate to more than the 400 bytes the header declares"));
  const std::string cut = gz(good);
  EXPECT_FALSE(parseNifti(cut.substr(0, cut.size() - 12), "cut.nii.gz", {}, &image).ok());
  NiftiSpec offset;
  offset.data = u16(24);
  offset.vox_offset = 100;
  EXPECT_TRUE(
      IsError(parseNifti(nifti(offset), "o.nii", {}, &image), kInvalid, "vox_offset 100 lies inside the header"));
  // Found by nifti_fuzz: a 130-byte .nii.gz whose vox_offset declared gigabytes made the reader allocate them.
  std::string far = good;
  const float far_offset = 4294967296.f;
  std::memcpy(far.data() + 108, &far_offset, 4);  // NIfTI-1's vox_offset
  EXPECT_TRUE(IsError(parseNifti(gz(far), "far.nii.gz", {}, &image), kInvalid, "bytes of extensions"));
  // A short stream whose header declares much inflates into a buffer that grows with the data, and ends short.
  std::string small;
  EXPECT_TRUE(IsError(gunzip(gz(std::string(1000, 'a')), uint64_t(1) << 34, "g", &small), kInvalid, "inflate to 1000"));
}

TEST(NiftiTest, TheWriterStoresFloatsAndTheAffine) {
  const std::string path =
      (std::filesystem::temp_directory_path() / ("distband_nifti_" + std::to_string(::getpid()) + ".nii.gz")).string();
  VolumeGeometry g;
  g.spacing = {0.7, 0.7, 2.5};
  g.affine = {{{-0.7, 0, 0, 10}, {0, 0.7, 0, -20}, {0, 0, 2.5, 30}}};
  std::vector<float> values(24);
  for (size_t i = 0; i < values.size(); ++i) values[i] = 0.25f * float(i);
  ASSERT_TRUE(IsOk(writeNiftiField(path, values, {4, 3, 2}, g)));
  std::ifstream f(path, std::ios::binary);
  const std::string compressed((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  std::filesystem::remove(path);
  std::string raw;
  ASSERT_TRUE(IsOk(gunzip(compressed, 352 + 24 * 4, "w", &raw)));
  auto get = [&](size_t at, auto v) {
    std::memcpy(&v, raw.data() + at, sizeof v);
    return v;
  };
  EXPECT_EQ(get(0, int32_t()), 348);
  EXPECT_EQ(std::memcmp(raw.data() + 344, "n+1\0", 4), 0);
  EXPECT_EQ(get(42, int16_t()), 4);
  EXPECT_EQ(get(70, int16_t()), 16);  // float32
  EXPECT_EQ(get(108, float()), 352.f);
  EXPECT_GT(get(254, int16_t()), 0);  // sform_code
  EXPECT_EQ(get(280, float()), -0.7f);
  EXPECT_EQ(get(292, float()), 10.f);
  EXPECT_EQ(get(300, float()), 0.7f);
  EXPECT_EQ(get(324, float()), 30.f);
  EXPECT_EQ(get(352 + 4 * 5, float()), 1.25f);
}

std::string nrrdHeader(const std::string& extra, const std::string& type = "uint16", const std::string& enc = "raw") {
  return "NRRD0004\n# a comment\ntype: " + type + "\ndimension: 3\nsizes: 4 3 2\nencoding: " + enc + "\n" + extra;
}

TEST(NrrdTest, ReadsAttachedRawAndGzipDataWithTheirGeometry) {
  const std::string dirs =
      "space: left-posterior-superior\nspace directions: (0.7,0,0) (0, 0.7, 0) (0,0,2.5)\nspace origin: "
      "(10,-20,30)\nendian: little\nkeyword:=value\n\n";
  VolumeImage image;
  ASSERT_TRUE(IsOk(parseNrrd(nrrdHeader(dirs) + u16(24), "a.nrrd", {}, nullptr, &image)));
  expectLabels(image, {4, 3, 2});
  EXPECT_NEAR(image.geometry.spacing.z, 2.5, 1e-12);
  EXPECT_EQ(image.geometry.origin, (Vec3d{10, -20, 30}));
  ASSERT_TRUE(IsOk(parseNrrd(nrrdHeader(dirs, "unsigned short", "gzip") + gz(u16(24)), "b.nrrd", {}, nullptr, &image)));
  expectLabels(image, {4, 3, 2});
  ASSERT_TRUE(IsOk(
      parseNrrd(nrrdHeader("spacings: 0.5 0.5 3\nendian: big\n\n") + u16(24, true), "c.nrrd", {}, nullptr, &image)));
  expectLabels(image, {4, 3, 2});
  EXPECT_EQ(image.geometry.spacing, (Vec3d{0.5, 0.5, 3}));
}

TEST(NrrdTest, DetachedDataOnlyThroughTheProviderAndHostileHeadersRefused) {
  VolumeImage image;
  const std::string detached = nrrdHeader("data file: labels.raw\n");
  EXPECT_TRUE(IsError(parseNrrd(detached, "d.nhdr", {}, nullptr, &image), kInvalid, "detached data file"));
  std::string asked;
  const NrrdDataFile provider = [&](const std::string& file, uint64_t max, std::string* out) {
    asked = file;
    *out = u16(24);
    return Status::Ok();
  };
  ASSERT_TRUE(IsOk(parseNrrd(detached, "d.nhdr", {}, &provider, &image)));
  EXPECT_EQ(asked, "labels.raw");
  expectLabels(image, {4, 3, 2});
  const struct {
    std::string bytes, expect;
    Status::Code code = kInvalid;
  } cases[] = {
      {"NRRD0009\n", "not an NRRD file"},
      {"NRRD0004\ntype: uint16\n\n", "has no 'dimension' field"},
      {nrrdHeader("\n", "uint16", "bzip2"), "encoding 'bzip2' is not read"},
      {nrrdHeader("\n", "complex"), "type 'complex' is not"},
      {nrrdHeader("type: uint8\n\n"), "given twice"},
      {nrrdHeader("space directions: (0.7,0.1,0) (0,0.7,0) (0,0,2.5)\n\n") + u16(24), "rotated or sheared"},
      {nrrdHeader("spacings: 1 1 -2\n\n") + u16(24), "not a finite spacing"},
      {nrrdHeader("byte skip: 16\n\n") + u16(24), "not supported"},
      {nrrdHeader("\n") + u16(23), "data bytes"},
      {nrrdHeader("\n") + u16(25), "data bytes"},
      {nrrdHeader("no colon here\n\n"), "is no \"field: value\""},
      {"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 16000 16000 16000\nencoding: raw\n\n", "exceed the limit",
       Status::Code::kResourceExhausted},
      {"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 1 1 0\nencoding: raw\n\n", "not an extent"},
      {"NRRD0004\ntype: uint8\ndimension: 4\nsizes: 1 1 1 1\nencoding: raw\n\n", "is 3-D"},
      {"NRRD0004\n" + std::string(2000, 'a') + "\n", "longer than 1024"},
  };
  for (const auto& c : cases)
    EXPECT_TRUE(IsError(parseNrrd(c.bytes, "h.nrrd", {1 << 20}, nullptr, &image), c.code, c.expect)) << c.expect;
  // A gzip bomb behind a small header.
  const std::string bomb = nrrdHeader("\n", "uint16", "gzip") + gz(std::string(size_t(32) << 20, '\0'));
  EXPECT_TRUE(IsError(parseNrrd(bomb, "bomb.nrrd", {}, nullptr, &image), kInvalid, "inflate to more than"));
}

TEST(VolumeFileTest, FormatsByExtensionAndTheCliReaderKeepsNhdrDataBesideIt) {
  EXPECT_EQ(volumeFileFormatOf("a/b.NII.GZ"), VolumeFileFormat::kNifti);
  EXPECT_EQ(volumeFileFormatOf("x.nii"), VolumeFileFormat::kNifti);
  EXPECT_EQ(volumeFileFormatOf("x.nhdr"), VolumeFileFormat::kNrrd);
  EXPECT_EQ(volumeFileFormatOf("x.npy"), VolumeFileFormat::kNpy);
  EXPECT_FALSE(volumeFileFormatOf("x.raw"));
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("distband_vf_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  std::ofstream((dir / "labels.raw").string(), std::ios::binary) << u16(24);
  std::ofstream((dir / "a.nhdr").string(), std::ios::binary) << nrrdHeader("data file: labels.raw\n");
  std::ofstream((dir / "b.nhdr").string(), std::ios::binary) << nrrdHeader("data file: ../labels.raw\n");
  VolumeImage image;
  ASSERT_TRUE(IsOk(readVolumeFile((dir / "a.nhdr").string(), {}, &image)));
  expectLabels(image, {4, 3, 2});
  EXPECT_TRUE(
      IsError(readVolumeFile((dir / "b.nhdr").string(), {}, &image), kInvalid, "only a file beside the header"));
  EXPECT_TRUE(IsError(readVolumeFile((dir / "none.nii").string(), {}, &image), Status::Code::kNotFound, "cannot open"));
  std::filesystem::remove_all(dir);
}

TEST(VolumeFileTest, OverridesReplaceTheHeadersSpacingAndOriginAndKeepItsDirections) {
  VolumeGeometry header;
  header.spacing = {0.7, 0.7, 2.5};
  header.origin = {10, -20, 30};
  header.affine = {{{-0.7, 0, 0, 10}, {0, 0.7, 0, -20}, {0, 0, 2.5, 30}}};
  header.from_header = true;
  // Nothing given: the header's.
  const VolumeGeometry same = overrideGeometry(header, std::nullopt, std::nullopt);
  EXPECT_EQ(same.spacing, header.spacing);
  EXPECT_EQ(volumeAffine(same), *header.affine);
  // A spacing keeps the flipped x axis, an origin moves the translation.
  const VolumeGeometry g = overrideGeometry(header, Vec3d{1, 2, 3}, Vec3d{0, 0, 0});
  EXPECT_EQ(g.spacing, (Vec3d{1, 2, 3}));
  EXPECT_EQ(g.origin, (Vec3d{0, 0, 0}));
  const auto a = volumeAffine(g);
  EXPECT_DOUBLE_EQ(a[0][0], -1);
  EXPECT_DOUBLE_EQ(a[1][1], 2);
  EXPECT_DOUBLE_EQ(a[2][2], 3);
  EXPECT_DOUBLE_EQ(a[0][3], 0);
  EXPECT_DOUBLE_EQ(a[2][3], 0);
  // No header (.npy): core's default voxel, unless given.
  EXPECT_EQ(VolumeGeometry().spacing, (Vec3d{kDefaultVoxelSize, kDefaultVoxelSize, kDefaultVoxelSize}));
  EXPECT_EQ(overrideGeometry({}, Vec3d{0.5, 0.5, 2}, std::nullopt).spacing, (Vec3d{0.5, 0.5, 2}));
  EXPECT_FALSE(overrideGeometry({}, Vec3d{0.5, 0.5, 2}, std::nullopt).affine.has_value());
}

}  // namespace
}  // namespace distband
