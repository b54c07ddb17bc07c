// resolveQuery (server/request_validation.h): every rule the .proto states, one table row each, checked for its
// status code and for a message that names the field; then the defaults it resolves (sign, limit in voxels, the
// grid's padding, the algorithm, closest features, batch size, the voxel estimates) and the header fillQueryHeader
// writes. Seeds: points, an inline volume, an inline OBJ cube parsed as the service parses it (parseMeshAsset, then
// resolveQuery with the parsed asset), and a cached volume by asset_id.
#include "server/request_validation.h"

#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/mesh/mesh_grid.h"
#include "server/asset_parsing.h"

namespace distband {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// A closed unit cube, outward faces (quads, fanned into 12 triangles by the reader).
constexpr const char* kCubeObj =
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
    "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 4 8 7 3\nf 1 5 8 4\nf 2 3 7 6\n";

void setVec(v1::Vec3* v, double x, double y, double z) {
  v->set_x(x);
  v->set_y(y);
  v->set_z(z);
}
void setDims(v1::Dims* d, uint32_t x, uint32_t y, uint32_t z) {
  d->set_x(x);
  d->set_y(y);
  d->set_z(z);
}
void setBox(v1::VoxelBox* b, uint32_t mx, uint32_t my, uint32_t mz, uint32_t sx, uint32_t sy, uint32_t sz) {
  b->set_min_x(mx), b->set_min_y(my), b->set_min_z(mz);
  b->set_size_x(sx), b->set_size_y(sy), b->set_size_z(sz);
}

/// Points (4,5,6) and (10,10,10) on a 32³ grid of voxel size 1 at the origin (GridSpec way a).
v1::QueryRequest pointsOnDims() {
  v1::QueryRequest r;
  setVec(r.mutable_points()->add_points(), 4, 5, 6);
  setVec(r.mutable_points()->add_points(), 10, 10, 10);
  r.mutable_grid()->set_voxel_size(1);
  setDims(r.mutable_grid()->mutable_dims(), 32, 32, 32);
  return r;
}

/// Points (0,0,0) and (4,2,1), grid fitted around them with voxel size 0.5 (way c).
v1::QueryRequest pointsFitted() {
  v1::QueryRequest r;
  setVec(r.mutable_points()->add_points(), 0, 0, 0);
  setVec(r.mutable_points()->add_points(), 4, 2, 1);
  r.mutable_grid()->set_voxel_size(0.5);
  return r;
}

/// A 16³ mask with a 4³ block of seeds in the middle: the grid is the volume's (way a, voxel size 1).
std::string blockMask(int n = 16) {
  std::string mask(size_t(n) * n * n, '\0');
  for (int z = 6; z < 10; ++z)
    for (int y = 6; y < 10; ++y)
      for (int x = 6; x < 10; ++x) mask[(size_t(z) * n + y) * n + x] = 1;
  return mask;
}
v1::QueryRequest inlineVolume() {
  v1::QueryRequest r;
  setDims(r.mutable_volume()->mutable_dims(), 16, 16, 16);
  r.mutable_volume()->set_mask(blockMask());
  r.mutable_grid();  // present, empty: the volume gives dims and voxel size 1
  return r;
}

v1::QueryRequest inlineCube() {
  v1::QueryRequest r;
  r.mutable_mesh()->set_format(v1::MESH_FORMAT_OBJ);
  r.mutable_mesh()->set_data(kCubeObj);
  r.mutable_grid()->set_voxel_size(0.1);
  return r;
}

std::shared_ptr<const Asset> parsedCube() {
  std::shared_ptr<const Asset> asset;
  const Status s = parseMeshAsset(kCubeObj, v1::MESH_FORMAT_OBJ, "cube.obj", "mesh", MeshLimits{}, nullptr, &asset);
  EXPECT_TRUE(s.ok()) << s.toString();
  return asset;
}

class ResolveQueryTest : public ::testing::Test {
 protected:
  /// Resolves `r` as the service does: an inline mesh is parsed first and handed over.
  Status resolve(const v1::QueryRequest& r, ResolvedQuery* q) {
    std::shared_ptr<const Asset> mesh;
    if (r.seeds_case() == v1::QueryRequest::kMesh) mesh = parsedCube();
    return resolveQuery(r, options, cache, mesh, q);
  }
  ResolvedQuery resolveOk(const v1::QueryRequest& r) {
    ResolvedQuery q;
    const Status s = resolve(r, &q);
    EXPECT_TRUE(s.ok()) << s.toString();
    return q;
  }

  ServerOptions options;
  AssetCache cache{64 << 20};
};

// ---------------------------------------------------------------------------------------------------------------
// Rules: one row per rule; the message must name the field (every listed substring).

enum class Base { kPointsOnDims, kPointsFitted, kVolume, kMesh };

struct RuleCase {
  const char* name;
  Base base;
  std::function<void(v1::QueryRequest&)> edit;
  Status::Code code;
  std::vector<std::string> names;
  std::function<void(ServerOptions&)> tune = nullptr;
};

std::ostream& operator<<(std::ostream& os, const RuleCase& c) { return os << c.name; }

using C = Status::Code;
const C kInvalid = C::kInvalidArgument;

const RuleCase kRules[] = {
    // seeds
    {"NoSeeds", Base::kPointsOnDims, [](auto& r) { r.clear_points(); }, kInvalid, {"seeds"}},
    {"EmptyPointList",
     Base::kPointsOnDims,
     [](auto& r) { r.mutable_points()->clear_points(); },
     kInvalid,
     {"points.points"}},
    {"NonFinitePoint",
     Base::kPointsOnDims,
     [](auto& r) { r.mutable_points()->mutable_points(1)->set_y(kNaN); },
     kInvalid,
     {"points.points[1]"}},
    {"InfinitePoint",
     Base::kPointsOnDims,
     [](auto& r) { r.mutable_points()->mutable_points(0)->set_x(kInf); },
     kInvalid,
     {"points.points[0]"}},
    {"EmptyAssetId", Base::kPointsOnDims, [](auto& r) { r.set_asset_id(""); }, kInvalid, {"asset_id"}},
    {"OverlongAssetId",
     Base::kPointsOnDims,
     [](auto& r) { r.set_asset_id(std::string(129, 'a')); },
     kInvalid,
     {"asset_id"}},
    {"UnknownAssetId",
     Base::kPointsOnDims,
     [](auto& r) { r.set_asset_id("volume-0123"); },
     C::kNotFound,
     {"asset_id", "volume-0123"}},
    // enumerations
    {"UnknownStencil",
     Base::kPointsOnDims,
     [](auto& r) { r.set_stencil(v1::Stencil(99)); },
     kInvalid,
     {"stencil", "99"}},
    {"UnknownAlgorithm",
     Base::kPointsOnDims,
     [](auto& r) { r.set_algorithm(v1::Algorithm(5)); },
     kInvalid,
     {"algorithm", "5"}},
    {"SeparableWithALimit",
     Base::kPointsOnDims,
     [](auto& r) {
       r.set_algorithm(v1::ALGORITHM_SEPARABLE);
       r.set_limit(4);
     },
     kInvalid,
     {"algorithm", "separable"}},
    {"SeparableWithAStencil",
     Base::kVolume,
     [](auto& r) {
       r.set_algorithm(v1::ALGORITHM_SEPARABLE);
       r.set_stencil(v1::STENCIL_CUBIC26);
     },
     kInvalid,
     {"algorithm", "stencil"}},
    {"UnknownMode", Base::kPointsOnDims, [](auto& r) { r.set_mode(v1::PropagationMode(3)); }, kInvalid, {"mode"}},
    {"UnknownEncoding",
     Base::kPointsOnDims,
     [](auto& r) { r.set_encoding(v1::BrickEncoding(3)); },
     kInvalid,
     {"encoding"}},
    {"UnknownSign", Base::kPointsOnDims, [](auto& r) { r.set_sign(v1::SignMode(7)); }, kInvalid, {"sign", "7"}},
    {"NegativeSign", Base::kPointsOnDims, [](auto& r) { r.set_sign(v1::SignMode(-1)); }, kInvalid, {"sign"}},
    {"SignedPoints",
     Base::kPointsOnDims,
     [](auto& r) { r.set_sign(v1::SIGN_MODE_PSEUDONORMAL); },
     kInvalid,
     {"sign", "SIGN_MODE_PSEUDONORMAL"}},
    {"MaskInsidePoints",
     Base::kPointsOnDims,
     [](auto& r) { r.set_sign(v1::SIGN_MODE_MASK_INSIDE); },
     kInvalid,
     {"sign"}},
    {"WindingVolume",
     Base::kVolume,
     [](auto& r) { r.set_sign(v1::SIGN_MODE_WINDING); },
     kInvalid,
     {"sign", "SIGN_MODE_WINDING"}},
    {"MaskInsideMesh",
     Base::kMesh,
     [](auto& r) { r.set_sign(v1::SIGN_MODE_MASK_INSIDE); },
     kInvalid,
     {"sign", "SIGN_MODE_MASK_INSIDE"}},
    {"MaskInsideFullVolume",
     Base::kVolume,
     [](auto& r) {
       r.mutable_volume()->set_mask(std::string(16 * 16 * 16, '\1'));
       r.set_sign(v1::SIGN_MODE_MASK_INSIDE);
     },
     kInvalid,
     {"sign"}},
    // segment length and limits
    {"NegativeSegmentLength",
     Base::kPointsOnDims,
     [](auto& r) { r.set_segment_length(-1); },
     kInvalid,
     {"segment_length"}},
    {"NaNSegmentLength",
     Base::kPointsOnDims,
     [](auto& r) { r.set_segment_length(kNaN); },
     kInvalid,
     {"segment_length"}},
    {"InfiniteSegmentLength",
     Base::kPointsOnDims,
     [](auto& r) { r.set_segment_length(kInf); },
     kInvalid,
     {"segment_length"}},
    {"TooManySegments",
     Base::kPointsOnDims,
     [](auto& r) { r.set_segment_length(1e-6); },
     kInvalid,
     {"segment_length", "100000"}},
    {"NegativeLimit", Base::kPointsOnDims, [](auto& r) { r.set_limit(-1); }, kInvalid, {"limit"}},
    {"MinusInfinityLimit", Base::kPointsOnDims, [](auto& r) { r.set_limit(-kInf); }, kInvalid, {"limit"}},
    {"NaNLimit", Base::kPointsOnDims, [](auto& r) { r.set_limit(kNaN); }, kInvalid, {"limit"}},
    {"NegativeLimitVoxels", Base::kPointsOnDims, [](auto& r) { r.set_limit_voxels(-2); }, kInvalid, {"limit_voxels"}},
    {"InfiniteLimitVoxels", Base::kPointsOnDims, [](auto& r) { r.set_limit_voxels(kInf); }, kInvalid, {"limit_voxels"}},
    {"NaNLimitVoxels", Base::kPointsOnDims, [](auto& r) { r.set_limit_voxels(kNaN); }, kInvalid, {"limit_voxels"}},
    {"LimitAndLimitVoxels",
     Base::kPointsOnDims,
     [](auto& r) {
       r.set_limit(2);
       r.set_limit_voxels(2);
     },
     kInvalid,
     {"limit", "limit_voxels"}},
    // grid
    {"NoGrid", Base::kPointsOnDims, [](auto& r) { r.clear_grid(); }, kInvalid, {"grid"}},
    {"NegativeVoxelSize",
     Base::kPointsFitted,
     [](auto& r) { r.mutable_grid()->set_voxel_size(-0.5); },
     kInvalid,
     {"grid.voxel_size"}},
    {"NaNVoxelSize",
     Base::kPointsFitted,
     [](auto& r) { r.mutable_grid()->set_voxel_size(kNaN); },
     kInvalid,
     {"grid.voxel_size"}},
    {"InfiniteVoxelSize",
     Base::kPointsOnDims,
     [](auto& r) { r.mutable_grid()->set_voxel_size(kInf); },
     kInvalid,
     {"grid.voxel_size"}},
    {"ResolutionOne",
     Base::kPointsFitted,
     [](auto& r) {
       r.mutable_grid()->set_voxel_size(0);
       r.mutable_grid()->set_resolution(1);
     },
     kInvalid,
     {"grid.resolution", "(got 1)"}},
    {"ResolutionTooLarge",
     Base::kPointsFitted,
     [](auto& r) {
       r.mutable_grid()->set_voxel_size(0);
       r.mutable_grid()->set_resolution(16385);
     },
     kInvalid,
     {"grid.resolution"}},
    {"PaddingTooLarge",
     Base::kPointsFitted,
     [](auto& r) { r.mutable_grid()->set_padding(4097); },
     kInvalid,
     {"grid.padding"}},
    {"NonFiniteOrigin",
     Base::kPointsOnDims,
     [](auto& r) { setVec(r.mutable_grid()->mutable_origin(), 0, kInf, 0); },
     kInvalid,
     {"grid.origin"}},
    {"OriginWithoutDims",
     Base::kPointsFitted,
     [](auto& r) { setVec(r.mutable_grid()->mutable_origin(), 1, 1, 1); },
     kInvalid,
     {"grid.origin"}},
    {"BothVoxelSizeAndResolution",
     Base::kPointsFitted,
     [](auto& r) { r.mutable_grid()->set_resolution(16); },
     kInvalid,
     {"grid", "voxel_size", "resolution"}},
    {"NeitherVoxelSizeNorResolution",
     Base::kPointsFitted,
     [](auto& r) { r.mutable_grid()->set_voxel_size(0); },
     kInvalid,
     {"grid", "voxel_size", "resolution"}},
    {"DimsAndBox",
     Base::kPointsOnDims,
     [](auto& r) {
       setVec(r.mutable_grid()->mutable_box()->mutable_min(), 0, 0, 0);
       setVec(r.mutable_grid()->mutable_box()->mutable_max(), 1, 1, 1);
     },
     kInvalid,
     {"grid.box", "grid.dims"}},
    {"DimsAndResolution",
     Base::kPointsOnDims,
     [](auto& r) { r.mutable_grid()->set_resolution(16); },
     kInvalid,
     {"grid.resolution", "grid.dims"}},
    {"DimsAndPadding",
     Base::kPointsOnDims,
     [](auto& r) { r.mutable_grid()->set_padding(2); },
     kInvalid,
     {"grid.padding", "grid.dims"}},
    {"ZeroDim",
     Base::kPointsOnDims,
     [](auto& r) { r.mutable_grid()->mutable_dims()->set_y(0); },
     kInvalid,
     {"grid.dims.y"}},
    {"DimTooLarge",
     Base::kPointsOnDims,
     [](auto& r) { r.mutable_grid()->mutable_dims()->set_z(16385); },
     kInvalid,
     {"grid.dims.z"}},
    {"DimsWithoutVoxelSize",
     Base::kPointsOnDims,
     [](auto& r) { r.mutable_grid()->set_voxel_size(0); },
     kInvalid,
     {"grid.voxel_size"}},
    {"InvertedBox",
     Base::kPointsFitted,
     [](auto& r) {
       setVec(r.mutable_grid()->mutable_box()->mutable_min(), 0, 2, 0);
       setVec(r.mutable_grid()->mutable_box()->mutable_max(), 1, 1, 1);
     },
     kInvalid,
     {"grid.box"}},
    {"NonFiniteBox",
     Base::kPointsFitted,
     [](auto& r) {
       setVec(r.mutable_grid()->mutable_box()->mutable_min(), 0, 0, 0);
       setVec(r.mutable_grid()->mutable_box()->mutable_max(), kNaN, 1, 1);
     },
     kInvalid,
     {"grid.box"}},
    {"GridOverVoxelBudget",
     Base::kPointsOnDims,
     [](auto&) {},
     C::kResourceExhausted,
     {"grid", "32768"},
     [](ServerOptions& o) { o.max_voxels_per_query = 32767; }},
    // volumes
    {"VolumeMaskSizeMismatch",
     Base::kVolume,
     [](auto& r) { r.mutable_volume()->set_mask(std::string(10, '\1')); },
     kInvalid,
     {"volume"}},
    {"VolumeZeroDim",
     Base::kVolume,
     [](auto& r) { r.mutable_volume()->mutable_dims()->set_x(0); },
     kInvalid,
     {"volume.dims.x"}},
    {"VolumeWithoutSeeds",
     Base::kVolume,
     [](auto& r) { r.mutable_volume()->set_mask(std::string(16 * 16 * 16, '\0')); },
     kInvalid,
     {"volume"}},
    {"VolumeOverVoxelBudget",
     Base::kVolume,
     [](auto&) {},
     C::kResourceExhausted,
     {"volume.dims"},
     [](ServerOptions& o) { o.max_voxels_per_query = 4095; }},
    {"VolumeGridDimsMismatch",
     Base::kVolume,
     [](auto& r) { setDims(r.mutable_grid()->mutable_dims(), 16, 16, 8); },
     kInvalid,
     {"grid.dims"}},
    {"VolumeWithBox",
     Base::kVolume,
     [](auto& r) {
       setVec(r.mutable_grid()->mutable_box()->mutable_min(), 0, 0, 0);
       setVec(r.mutable_grid()->mutable_box()->mutable_max(), 1, 1, 1);
     },
     kInvalid,
     {"grid.box"}},
    {"VolumeWithResolution",
     Base::kVolume,
     [](auto& r) { r.mutable_grid()->set_resolution(16); },
     kInvalid,
     {"grid.resolution"}},
    {"VolumeTileWithoutGridDims",
     Base::kVolume,
     [](auto& r) {
       setBox(r.mutable_tile()->mutable_window(), 0, 0, 0, 16, 16, 16);
       setBox(r.mutable_tile()->mutable_deliver(), 0, 0, 0, 16, 16, 16);
     },
     kInvalid,
     {"grid.dims"}},
    {"VolumeTileWindowDimsMismatch",
     Base::kVolume,
     [](auto& r) {
       setDims(r.mutable_grid()->mutable_dims(), 32, 32, 32);
       setBox(r.mutable_tile()->mutable_window(), 0, 0, 0, 16, 16, 8);
       setBox(r.mutable_tile()->mutable_deliver(), 0, 0, 0, 8, 8, 8);
     },
     kInvalid,
     {"volume", "16x16x8"}},
    // tiles (32³ grid)
    {"TileWindowMinNotBrickAligned",
     Base::kPointsOnDims,
     [](auto& r) {
       setBox(r.mutable_tile()->mutable_window(), 3, 0, 0, 13, 16, 16);
       setBox(r.mutable_tile()->mutable_deliver(), 8, 0, 0, 8, 8, 8);
     },
     kInvalid,
     {"tile.window.min_x"}},
    {"TileWindowEmpty",
     Base::kPointsOnDims,
     [](auto& r) {
       setBox(r.mutable_tile()->mutable_window(), 0, 0, 0, 16, 0, 16);
       setBox(r.mutable_tile()->mutable_deliver(), 0, 0, 0, 8, 8, 8);
     },
     kInvalid,
     {"tile.window", "size_y"}},
    {"TileWindowBeyondGrid",
     Base::kPointsOnDims,
     [](auto& r) {
       setBox(r.mutable_tile()->mutable_window(), 0, 0, 24, 16, 16, 16);
       setBox(r.mutable_tile()->mutable_deliver(), 0, 0, 24, 8, 8, 8);
     },
     kInvalid,
     {"tile.window", "size_z"}},
    {"TileWindowEndNotBrickAligned",
     Base::kPointsOnDims,
     [](auto& r) {
       setBox(r.mutable_tile()->mutable_window(), 0, 0, 0, 16, 12, 16);
       setBox(r.mutable_tile()->mutable_deliver(), 0, 0, 0, 8, 8, 8);
     },
     kInvalid,
     {"tile.window", "size_y"}},
    {"TileDeliverNotBrickAligned",
     Base::kPointsOnDims,
     [](auto& r) {
       setBox(r.mutable_tile()->mutable_window(), 0, 0, 0, 16, 16, 16);
       setBox(r.mutable_tile()->mutable_deliver(), 0, 4, 0, 8, 4, 8);
     },
     kInvalid,
     {"tile.deliver.min_y"}},
    {"TileDeliverOutsideWindow",
     Base::kPointsOnDims,
     [](auto& r) {
       setBox(r.mutable_tile()->mutable_window(), 0, 0, 0, 16, 16, 16);
       setBox(r.mutable_tile()->mutable_deliver(), 16, 0, 0, 8, 8, 8);
     },
     kInvalid,
     {"tile.deliver", "tile.window"}},
    // anisotropic grids and label volumes
    {"SpacingNegative",
     Base::kVolume,
     [](auto& r) { setVec(r.mutable_grid()->mutable_spacing(), 1, -1, 1); },
     kInvalid,
     {"grid.spacing"}},
    {"SpacingNaN",
     Base::kPointsOnDims,
     [](auto& r) {
       r.mutable_grid()->clear_voxel_size();
       setVec(r.mutable_grid()->mutable_spacing(), 1, kNaN, 1);
     },
     kInvalid,
     {"grid.spacing"}},
    {"SpacingWithVoxelSize",
     Base::kPointsOnDims,
     [](auto& r) { setVec(r.mutable_grid()->mutable_spacing(), 1, 1, 2); },
     kInvalid,
     {"grid.spacing", "voxel_size"}},
    {"SpacingTooFarApart",
     Base::kVolume,
     [](auto& r) { setVec(r.mutable_grid()->mutable_spacing(), 1, 1, 5000); },
     kInvalid,
     {"grid.spacing"}},
    {"SpacingAroundTheSeeds",
     Base::kPointsFitted,
     [](auto& r) {
       r.mutable_grid()->clear_voxel_size();
       setVec(r.mutable_grid()->mutable_spacing(), 1, 1, 2);
     },
     kInvalid,
     {"grid.spacing"}},
    {"LabelsOnPoints", Base::kPointsOnDims, [](auto& r) { r.set_labels(true); }, kInvalid, {"labels", "volume"}},
    {"NearestLabelOnAMesh", Base::kMesh, [](auto& r) { r.set_nearest_label(true); }, kInvalid, {"nearest_label"}},
    {"BlackBorderWithoutLabels",
     Base::kVolume,
     [](auto& r) { r.set_black_border(true); },
     kInvalid,
     {"black_border", "labels"}},
    {"LabelsWithClosestFeature",
     Base::kVolume,
     [](auto& r) {
       r.set_labels(true);
       r.set_closest_feature(true);
     },
     kInvalid,
     {"labels", "closest_feature"}},
    {"NearestLabelWithClosestFeature",
     Base::kVolume,
     [](auto& r) {
       r.set_nearest_label(true);
       r.set_closest_feature(true);
     },
     kInvalid,
     {"nearest_label", "closest_feature"}},
    {"LabelsSigned",
     Base::kVolume,
     [](auto& r) {
       r.set_labels(true);
       r.set_sign(v1::SIGN_MODE_MASK_INSIDE);
     },
     kInvalid,
     {"labels", "unsigned"}},
    {"LabelsOnTheBand",
     Base::kVolume,
     [](auto& r) {
       r.set_labels(true);
       r.set_algorithm(v1::ALGORITHM_BAND);
     },
     kInvalid,
     {"labels"}},
    {"TileWindowOverVoxelBudget",
     Base::kPointsOnDims,
     [](auto& r) {
       setBox(r.mutable_tile()->mutable_window(), 0, 0, 0, 32, 32, 8);
       setBox(r.mutable_tile()->mutable_deliver(), 0, 0, 0, 8, 8, 8);
     },
     C::kResourceExhausted,
     {"tile.window", "8192"},
     [](ServerOptions& o) { o.max_voxels_per_query = 5000; }},
};

class ResolveQueryRuleTest : public ResolveQueryTest, public ::testing::WithParamInterface<RuleCase> {};

TEST_P(ResolveQueryRuleTest, RefusedWithTheFieldNamed) {
  const RuleCase& c = GetParam();
  v1::QueryRequest r;
  switch (c.base) {
    case Base::kPointsOnDims: r = pointsOnDims(); break;
    case Base::kPointsFitted: r = pointsFitted(); break;
    case Base::kVolume: r = inlineVolume(); break;
    case Base::kMesh: r = inlineCube(); break;
  }
  {  // the base request is valid: the edit alone must make it fail
    ResolvedQuery q;
    const Status s = resolve(r, &q);
    ASSERT_TRUE(s.ok()) << "base request: " << s.toString();
  }
  c.edit(r);
  if (c.tune) c.tune(options);
  ResolvedQuery q;
  const Status s = resolve(r, &q);
  ASSERT_FALSE(s.ok()) << "the edited request was accepted";
  EXPECT_EQ(s.code(), c.code) << s.toString();
  for (const std::string& name : c.names)
    EXPECT_NE(s.message().find(name), std::string::npos) << "message does not name '" << name << "': " << s.message();
}

INSTANTIATE_TEST_SUITE_P(Rules, ResolveQueryRuleTest, ::testing::ValuesIn(kRules),
                         [](const ::testing::TestParamInfo<RuleCase>& info) { return std::string(info.param.name); });

// ---------------------------------------------------------------------------------------------------------------
// Seeds

TEST_F(ResolveQueryTest, AnisotropicLabelVolumeIsResolvedAndItsHeaderSaysSo) {
  v1::QueryRequest r = inlineVolume();
  setVec(r.mutable_grid()->mutable_spacing(), 0.5, 0.5, 2.5);
  setVec(r.mutable_grid()->mutable_origin(), 10, -20, 30);
  r.set_labels(true);
  r.set_black_border(true);
  const ResolvedQuery q = resolveOk(r);
  EXPECT_EQ(q.grid.spacing(), (Vec3d{0.5, 0.5, 2.5}));
  EXPECT_EQ(q.grid.voxelSize(), 0.5);
  EXPECT_TRUE(q.plan.labels && q.plan.black_border);
  EXPECT_EQ(q.plan.algorithm, FieldAlgorithm::kSeparable);
  v1::QueryHeader h;
  fillQueryHeader(q, "q", &h);
  EXPECT_EQ(h.spacing().z(), 2.5);
  EXPECT_EQ(h.voxel_size(), 0.5);
  EXPECT_TRUE(h.labels() && h.black_border());
  EXPECT_EQ(h.label_type(), v1::VOXEL_TYPE_UINT8);
  EXPECT_EQ(h.closest_feature(), v1::CLOSEST_FEATURE_NONE);

  v1::QueryRequest n = inlineVolume();
  n.set_nearest_label(true);
  const ResolvedQuery qn = resolveOk(n);
  EXPECT_TRUE(qn.plan.nearest_label);
  fillQueryHeader(qn, "n", &h);
  EXPECT_EQ(h.closest_feature(), v1::CLOSEST_FEATURE_LABEL);
  EXPECT_FALSE(h.labels());
}

TEST_F(ResolveQueryTest, PointsAreResolvedInWorldCoordinates) {
  const ResolvedQuery q = resolveOk(pointsOnDims());
  EXPECT_EQ(q.seed_kind, SeedKind::kPoints);
  ASSERT_EQ(q.points.size(), 2u);
  EXPECT_EQ(q.points[1].x, 10);
  EXPECT_EQ(q.points[0].z, 6);
  EXPECT_EQ(q.grid.dims(), (Coord{32, 32, 32}));
  EXPECT_EQ(q.grid.voxelSize(), 1);
  EXPECT_FALSE(q.tile.has_value());
}

TEST_F(ResolveQueryTest, FewPointsWithoutLimitUseTheSeparablePointEdtAndAreChargedForIt) {
  const ResolvedQuery q = resolveOk(pointsOnDims());  // two points on a 32^3 grid
  EXPECT_EQ(q.plan.algorithm, FieldAlgorithm::kSeparable);
  ASSERT_TRUE(q.plan.point_layout.has_value());
  EXPECT_EQ(q.plan.point_layout->planes, 2);
  // A nearest-point index per voxel and pass 2's 12 bytes per (plane, x, y): at least 4 bytes a voxel.
  EXPECT_GE(q.memory.engine_bytes, 32u * 32 * 32 * 4 + 2u * 32 * 32 * 12);
  v1::QueryRequest limited = pointsOnDims();
  limited.set_limit(4);
  EXPECT_EQ(resolveOk(limited).plan.algorithm, FieldAlgorithm::kBand) << "a limit: the band's work follows it";
  v1::QueryRequest spread = pointsOnDims();  // points on 20 planes of a 32^3 grid: more than the separable pass pays for
  for (int i = 0; i < 18; ++i) setVec(spread.mutable_points()->add_points(), i, i, i + 0.5);
  EXPECT_EQ(resolveOk(spread).plan.algorithm, FieldAlgorithm::kBand);
}

TEST_F(ResolveQueryTest, InlineMeshNeedsItsParsedAsset) {
  ResolvedQuery q;
  const Status s = resolveQuery(inlineCube(), options, cache, nullptr, &q);
  EXPECT_EQ(s.code(), Status::Code::kInternal) << s.toString();
}

TEST_F(ResolveQueryTest, CachedVolumeByAssetId) {
  v1::Dims dims;
  setDims(&dims, 16, 16, 16);
  std::shared_ptr<const Asset> asset;
  ASSERT_TRUE(parseVolumeAsset(dims, v1::VOXEL_TYPE_UINT8, blockMask(), "block", "volume", options.max_voxels_per_query, nullptr, &asset).ok());
  ASSERT_TRUE(cache.insert(asset));
  v1::QueryRequest r;
  r.set_asset_id(asset->id);
  r.mutable_grid();
  const ResolvedQuery q = resolveOk(r);
  EXPECT_EQ(q.seed_kind, SeedKind::kVolume);
  EXPECT_EQ(q.asset, asset);
  EXPECT_EQ(q.grid.dims(), (Coord{16, 16, 16}));
  EXPECT_NE(q.seeds_label.find("block"), std::string::npos) << q.seeds_label;
}

TEST_F(ResolveQueryTest, CheckInlineMeshRules) {
  EXPECT_TRUE(checkInlineMesh(pointsOnDims(), options).ok());
  EXPECT_TRUE(checkInlineMesh(inlineCube(), options).ok());

  v1::QueryRequest r = inlineCube();
  r.mutable_mesh()->set_format(v1::MESH_FORMAT_UNSPECIFIED);
  Status s = checkInlineMesh(r, options);
  EXPECT_EQ(s.code(), Status::Code::kInvalidArgument);
  EXPECT_NE(s.message().find("mesh.format"), std::string::npos) << s.message();

  r = inlineCube();
  r.mutable_mesh()->clear_data();
  s = checkInlineMesh(r, options);
  EXPECT_EQ(s.code(), Status::Code::kInvalidArgument);
  EXPECT_NE(s.message().find("mesh.data"), std::string::npos) << s.message();

  options.max_upload_bytes = 10;
  s = checkInlineMesh(inlineCube(), options);
  EXPECT_EQ(s.code(), Status::Code::kResourceExhausted);
  EXPECT_NE(s.message().find("mesh.data"), std::string::npos) << s.message();
}

// ---------------------------------------------------------------------------------------------------------------
// Defaults

TEST_F(ResolveQueryTest, PointsDefaultToUnsigned) {
  for (v1::SignMode sign : {v1::SIGN_MODE_UNSPECIFIED, v1::SIGN_MODE_AUTO, v1::SIGN_MODE_UNSIGNED}) {
    v1::QueryRequest r = pointsOnDims();
    r.set_sign(sign);
    const ResolvedQuery q = resolveOk(r);
    EXPECT_EQ(signOf(q.plan), v1::SIGN_MODE_UNSIGNED) << v1::SignMode_Name(sign);
    EXPECT_FALSE(q.plan.signedField());
  }
}

TEST_F(ResolveQueryTest, DefaultsOfUnsetChoices) {
  const ResolvedQuery q = resolveOk(pointsOnDims());
  EXPECT_EQ(q.encoding, v1::BRICK_ENCODING_FLOAT32) << "never UNSPECIFIED";
  EXPECT_EQ(modeOf(q.plan), v1::PROPAGATION_MODE_EXACT);
  EXPECT_EQ(q.plan.limit_world, kInf) << "limit 0 means no limit";
  EXPECT_EQ(q.plan.segment_length_world, 0);
  EXPECT_EQ(closestOf(q.plan), v1::CLOSEST_FEATURE_NONE);
  EXPECT_EQ(q.batch_bytes, options.batch_bytes);
  EXPECT_EQ(q.plan.algorithm, FieldAlgorithm::kSeparable) << "two points, no limit: the separable point EDT";
}

TEST_F(ResolveQueryTest, ExplicitChoicesAreKept) {
  v1::QueryRequest r = pointsOnDims();
  r.set_stencil(v1::STENCIL_CUBIC6);
  r.set_mode(v1::PROPAGATION_MODE_PAPER);
  r.set_encoding(v1::BRICK_ENCODING_FLOAT16);
  r.set_limit(3.5);
  r.set_segment_length(1);
  const ResolvedQuery q = resolveOk(r);
  EXPECT_EQ(stencilOf(q.plan), v1::STENCIL_CUBIC6);
  EXPECT_EQ(modeOf(q.plan), v1::PROPAGATION_MODE_PAPER);
  EXPECT_EQ(q.encoding, v1::BRICK_ENCODING_FLOAT16);
  EXPECT_EQ(q.plan.limit_world, 3.5);
  EXPECT_EQ(q.plan.segment_length_world, 1);
}

TEST_F(ResolveQueryTest, InfiniteLimitIsAccepted) {
  v1::QueryRequest r = pointsOnDims();
  r.set_limit(kInf);
  EXPECT_EQ(resolveOk(r).plan.limit_world, kInf);
}

TEST_F(ResolveQueryTest, BatchBytesAreClamped) {
  v1::QueryRequest r = pointsOnDims();
  r.set_max_batch_bytes(1);
  EXPECT_EQ(resolveOk(r).batch_bytes, 64u << 10);
  r.set_max_batch_bytes(UINT32_MAX);
  EXPECT_EQ(resolveOk(r).batch_bytes, options.max_message_bytes);
  r.set_max_batch_bytes(100000);
  EXPECT_EQ(resolveOk(r).batch_bytes, 100000u);
}

TEST_F(ResolveQueryTest, LimitInVoxelsBecomesWorldUnits) {
  v1::QueryRequest r = pointsOnDims();
  r.mutable_grid()->set_voxel_size(0.25);
  r.set_limit_voxels(6);
  const ResolvedQuery q = resolveOk(r);
  EXPECT_DOUBLE_EQ(q.plan.limit_world, 1.5);
  v1::QueryHeader h;
  fillQueryHeader(q, "q1", &h);
  EXPECT_DOUBLE_EQ(h.limit(), 1.5) << "the header reports the limit in world units";
}

TEST_F(ResolveQueryTest, DefaultPaddingHoldsTheLimit) {
  v1::QueryRequest r = pointsFitted();  // voxel size 0.5
  r.set_limit_voxels(7);
  const ResolvedQuery q = resolveOk(r);
  EXPECT_GE(q.padding.voxels, 7);
  EXPECT_FALSE(q.padding.band_clipped);
  // The origin is the bounds' min corner minus the padding; the grid holds the bounds plus the padding.
  const double h = 0.5, pad = q.padding.voxels;
  EXPECT_DOUBLE_EQ(q.grid.voxelSize(), h);
  EXPECT_DOUBLE_EQ(q.grid.origin().x, -pad * h);
  EXPECT_DOUBLE_EQ(q.grid.origin().z, -pad * h);
  EXPECT_EQ(q.grid.dims().x, 4 / h + 1 + 2 * pad);
  EXPECT_EQ(q.grid.dims().y, 2 / h + 1 + 2 * pad);
  EXPECT_EQ(q.grid.dims().z, 1 / h + 1 + 2 * pad);
}

TEST_F(ResolveQueryTest, DefaultPaddingHoldsAWorldLimit) {
  v1::QueryRequest r = pointsFitted();
  r.set_limit(4.2);  // 8.4 voxels of 0.5
  const ResolvedQuery q = resolveOk(r);
  EXPECT_GE(q.padding.voxels, 9);
  EXPECT_FALSE(q.padding.band_clipped);
}

TEST_F(ResolveQueryTest, DefaultPaddingWithoutLimit) {
  const ResolvedQuery q = resolveOk(pointsFitted());
  EXPECT_EQ(q.padding.voxels, kDefaultPaddingVoxels);
  EXPECT_FALSE(q.padding.band_clipped);
}

TEST_F(ResolveQueryTest, DefaultPaddingWithResolutionHoldsTheLimit) {
  v1::QueryRequest r = pointsFitted();
  r.mutable_grid()->set_voxel_size(0);
  r.mutable_grid()->set_resolution(64);
  r.set_limit_voxels(5);
  const ResolvedQuery q = resolveOk(r);
  EXPECT_GE(q.padding.voxels, 5);
  EXPECT_FALSE(q.padding.band_clipped);
  EXPECT_EQ(q.grid.dims().x, 64) << "the longest side spans the resolution";
}

TEST_F(ResolveQueryTest, ExplicitSmallerPaddingClipsTheBand) {
  v1::QueryRequest r = pointsFitted();
  r.set_limit_voxels(7);
  r.mutable_grid()->set_padding(2);
  const ResolvedQuery q = resolveOk(r);
  EXPECT_EQ(q.padding.voxels, 2);
  EXPECT_TRUE(q.padding.band_clipped);
  v1::QueryHeader h;
  fillQueryHeader(q, "q", &h);
  EXPECT_EQ(h.padding(), 2u);
  EXPECT_TRUE(h.band_clipped());
}

TEST_F(ResolveQueryTest, ExplicitLargerPaddingDoesNotClip) {
  v1::QueryRequest r = pointsFitted();
  r.set_limit_voxels(3);
  r.mutable_grid()->set_padding(5);
  const ResolvedQuery q = resolveOk(r);
  EXPECT_EQ(q.padding.voxels, 5);
  EXPECT_FALSE(q.padding.band_clipped);
}

TEST_F(ResolveQueryTest, BoxGridHasNoDefaultPadding) {
  v1::QueryRequest r = pointsFitted();
  setVec(r.mutable_grid()->mutable_box()->mutable_min(), -1, -1, -1);
  setVec(r.mutable_grid()->mutable_box()->mutable_max(), 3, 3, 3);
  r.set_limit_voxels(4);
  const ResolvedQuery q = resolveOk(r);
  EXPECT_EQ(q.padding.voxels, 0);
  EXPECT_DOUBLE_EQ(q.grid.origin().x, -1);
  EXPECT_EQ(q.grid.dims(), (Coord{9, 9, 9}));
}

TEST_F(ResolveQueryTest, DimsGridReportsNoPadding) {
  v1::QueryRequest r = pointsOnDims();
  r.set_limit_voxels(5);
  setVec(r.mutable_grid()->mutable_origin(), -2, 0, 1);
  const ResolvedQuery q = resolveOk(r);
  EXPECT_EQ(q.padding.voxels, 0);
  EXPECT_FALSE(q.padding.band_clipped);
  EXPECT_EQ(q.grid.origin().x, -2);
  EXPECT_EQ(q.grid.origin().z, 1);
}

TEST_F(ResolveQueryTest, VolumeWithoutLimitUsesTheSeparableEdt) {
  const ResolvedQuery q = resolveOk(inlineVolume());
  EXPECT_EQ(q.seed_kind, SeedKind::kVolume);
  EXPECT_EQ(q.plan.algorithm, FieldAlgorithm::kSeparable);
  EXPECT_EQ(q.grid.dims(), (Coord{16, 16, 16}));
  EXPECT_EQ(q.grid.voxelSize(), 1) << "a volume's voxel size defaults to 1";
  EXPECT_EQ(signOf(q.plan), v1::SIGN_MODE_UNSIGNED);
}

TEST_F(ResolveQueryTest, VolumeWithLimitUsesTheSeparableEdtWithinIt) {
  v1::QueryRequest r = inlineVolume();
  r.set_limit(3);
  EXPECT_EQ(resolveOk(r).plan.algorithm, FieldAlgorithm::kSeparable);
  r = inlineVolume();
  r.set_limit_voxels(3);
  EXPECT_EQ(resolveOk(r).plan.algorithm, FieldAlgorithm::kSeparable);
}

TEST_F(ResolveQueryTest, VolumeAskingForTheBandsChoicesUsesTheBand) {
  v1::QueryRequest r = inlineVolume();
  r.set_stencil(v1::STENCIL_CUBIC26);
  EXPECT_EQ(resolveOk(r).plan.algorithm, FieldAlgorithm::kBand) << "a stencil asks for the band";
  r = inlineVolume();
  r.set_mode(v1::PROPAGATION_MODE_PAPER);
  EXPECT_EQ(resolveOk(r).plan.algorithm, FieldAlgorithm::kBand) << "paper mode";
  r = inlineVolume();
  r.set_closest_feature(true);
  EXPECT_EQ(resolveOk(r).plan.algorithm, FieldAlgorithm::kBand) << "closest features come from the band's sites";
}

TEST_F(ResolveQueryTest, VolumeMaskInsideIsSigned) {
  v1::QueryRequest r = inlineVolume();
  r.set_sign(v1::SIGN_MODE_MASK_INSIDE);
  const ResolvedQuery q = resolveOk(r);
  EXPECT_TRUE(q.plan.inside_negative);
  EXPECT_TRUE(q.plan.signedField());
  EXPECT_EQ(signOf(q.plan), v1::SIGN_MODE_MASK_INSIDE);
}

TEST_F(ResolveQueryTest, VolumeWithMatchingGridDimsAndVoxelSize) {
  v1::QueryRequest r = inlineVolume();
  setDims(r.mutable_grid()->mutable_dims(), 16, 16, 16);
  r.mutable_grid()->set_voxel_size(0.25);
  setVec(r.mutable_grid()->mutable_origin(), 1, 2, 3);
  const ResolvedQuery q = resolveOk(r);
  EXPECT_EQ(q.grid.voxelSize(), 0.25);
  EXPECT_EQ(q.grid.origin().y, 2);
}

TEST_F(ResolveQueryTest, VolumeTileCoversItsWindow) {
  v1::QueryRequest r = inlineVolume();  // a 16³ volume: the window's voxels
  setDims(r.mutable_grid()->mutable_dims(), 32, 32, 32);
  setBox(r.mutable_tile()->mutable_window(), 16, 0, 8, 16, 16, 16);
  setBox(r.mutable_tile()->mutable_deliver(), 16, 8, 8, 8, 8, 8);
  const ResolvedQuery q = resolveOk(r);
  ASSERT_TRUE(q.tile.has_value());
  EXPECT_EQ(q.grid.dims(), (Coord{32, 32, 32}));
  EXPECT_EQ(q.engineGrid().dims(), (Coord{16, 16, 16}));
  EXPECT_EQ(q.engineGrid().origin().x, 16);
  EXPECT_EQ(q.engineGrid().origin().z, 8);
}

TEST_F(ResolveQueryTest, PointTileAtTheGridsEdge) {
  v1::QueryRequest r = pointsOnDims();
  r.mutable_grid()->mutable_dims()->set_x(30);  // the last window ends at the grid's extent, not a multiple of 8
  setBox(r.mutable_tile()->mutable_window(), 16, 0, 0, 14, 16, 8);
  setBox(r.mutable_tile()->mutable_deliver(), 24, 8, 0, 6, 8, 8);
  const ResolvedQuery q = resolveOk(r);
  ASSERT_TRUE(q.tile.has_value());
  EXPECT_EQ(q.tile->window.min, (Coord{16, 0, 0}));
  EXPECT_EQ(q.tile->window.dims, (Coord{14, 16, 8}));
  EXPECT_EQ(q.tile->deliver.min, (Coord{24, 8, 0}));
  EXPECT_EQ(q.engineGrid().dims(), (Coord{14, 16, 8}));
}

TEST_F(ResolveQueryTest, TileBudgetCountsTheWindowNotTheGrid) {
  options.max_voxels_per_query = 16 * 16 * 16;  // the 32³ grid is over it, one 16³ window is not
  v1::QueryRequest r = pointsOnDims();
  setBox(r.mutable_tile()->mutable_window(), 0, 0, 0, 16, 16, 16);
  setBox(r.mutable_tile()->mutable_deliver(), 0, 0, 0, 8, 8, 8);
  EXPECT_TRUE(resolveOk(r).tile.has_value());
}

TEST_F(ResolveQueryTest, MeshSignDefaultsToAutoOnItsEdges) {
  const ResolvedQuery q = resolveOk(inlineCube());
  EXPECT_EQ(q.seed_kind, SeedKind::kMesh);
  EXPECT_EQ(signOf(q.plan), v1::SIGN_MODE_PSEUDONORMAL) << "AUTO on a closed mesh";
  EXPECT_NE(q.plan.sign_reason.find("closed"), std::string::npos) << q.plan.sign_reason;
  EXPECT_TRUE(q.plan.signedField());
}

TEST_F(ResolveQueryTest, MeshSignAsRequested) {
  for (auto [sign, expected] : {std::pair{v1::SIGN_MODE_WINDING, v1::SIGN_MODE_WINDING},
                                {v1::SIGN_MODE_PARITY, v1::SIGN_MODE_PARITY},
                                {v1::SIGN_MODE_UNSIGNED, v1::SIGN_MODE_UNSIGNED},
                                {v1::SIGN_MODE_AUTO, v1::SIGN_MODE_PSEUDONORMAL}}) {
    v1::QueryRequest r = inlineCube();
    r.set_sign(sign);
    EXPECT_EQ(signOf(resolveOk(r).plan), expected) << v1::SignMode_Name(sign);
  }
}

TEST_F(ResolveQueryTest, MeshGridIsFittedAroundTheMesh) {
  v1::QueryRequest r = inlineCube();  // voxel size 0.1, the unit cube: 10 cells + 1 + 2 padding per axis
  const ResolvedQuery q = resolveOk(r);
  const int pad = q.padding.voxels;
  EXPECT_EQ(pad, kDefaultPaddingVoxels);
  EXPECT_EQ(q.grid.dims(), (Coord{11 + 2 * pad, 11 + 2 * pad, 11 + 2 * pad}));
  EXPECT_NEAR(q.grid.origin().x, -0.1 * pad, 1e-12);
}

TEST_F(ResolveQueryTest, ClosestFeatureKindFollowsTheSeeds) {
  v1::QueryRequest points = pointsOnDims(), volume = inlineVolume(), mesh = inlineCube();
  for (v1::QueryRequest* r : {&points, &volume, &mesh}) {
    EXPECT_EQ(closestOf(resolveOk(*r).plan), v1::CLOSEST_FEATURE_NONE);
    r->set_closest_feature(true);
  }
  EXPECT_EQ(closestOf(resolveOk(points).plan), v1::CLOSEST_FEATURE_POINT);
  EXPECT_EQ(closestOf(resolveOk(volume).plan), v1::CLOSEST_FEATURE_VOXEL);
  EXPECT_EQ(closestOf(resolveOk(mesh).plan), v1::CLOSEST_FEATURE_TRIANGLE);
  EXPECT_TRUE(resolveOk(points).plan.closest_features);
}

TEST_F(ResolveQueryTest, VoxelEstimatesAreBounded) {
  struct Named {
    const char* name;
    v1::QueryRequest r;
  };
  v1::QueryRequest limited_points = pointsOnDims(), limited_volume = inlineVolume(), limited_mesh = inlineCube(),
                   signed_volume = inlineVolume();
  limited_points.set_limit(3);
  limited_volume.set_limit_voxels(2);
  limited_mesh.set_limit(0.25);
  signed_volume.set_sign(v1::SIGN_MODE_MASK_INSIDE);
  for (const Named& n : {Named{"points", pointsOnDims()}, Named{"points, limit 3", limited_points},
                         Named{"volume", inlineVolume()}, Named{"volume, limit 2 voxels", limited_volume},
                         Named{"mask-inside volume", signed_volume}, Named{"mesh", inlineCube()},
                         Named{"mesh, limit 0.25", limited_mesh}}) {
    SCOPED_TRACE(n.name);
    const ResolvedQuery q = resolveOk(n.r);
    EXPECT_GT(q.expected_voxels, 0u);
    EXPECT_LE(q.expected_voxels, q.touched_voxels_bound);
    EXPECT_LE(q.touched_voxels_bound, uint64_t(q.engineGrid().voxelCount()));
    EXPECT_GT(q.memory.total(), 0u);
  }
}

TEST_F(ResolveQueryTest, ExpectedVoxelsAreCappedByTheBound) {
  // A ball of radius 20 voxels around a corner holds ~33500 voxels, more than the 32³ grid: the estimate is capped.
  v1::QueryRequest corner = pointsOnDims();
  corner.mutable_points()->clear_points();
  setVec(corner.mutable_points()->add_points(), 0, 0, 0);
  corner.set_limit(20);
  const ResolvedQuery qc = resolveOk(corner);
  EXPECT_LE(qc.expected_voxels, qc.touched_voxels_bound);
  EXPECT_LE(qc.expected_voxels, uint64_t(32 * 32 * 32));
  // A point far outside the grid, beyond the limit: nothing is touched, nothing expected.
  v1::QueryRequest far = pointsOnDims();
  far.mutable_points()->clear_points();
  setVec(far.mutable_points()->add_points(), 1000, 1000, 1000);
  far.set_limit(3);
  const ResolvedQuery qf = resolveOk(far);
  EXPECT_EQ(qf.touched_voxels_bound, 0u);
  EXPECT_EQ(qf.expected_voxels, 0u);
}

TEST_F(ResolveQueryTest, LimitShrinksTheEstimates) {
  v1::QueryRequest whole = pointsOnDims(), band = pointsOnDims();
  band.set_limit(2);
  const ResolvedQuery qw = resolveOk(whole), qb = resolveOk(band);
  EXPECT_EQ(qw.touched_voxels_bound, uint64_t(32 * 32 * 32)) << "no limit: every voxel";
  EXPECT_LT(qb.touched_voxels_bound, qw.touched_voxels_bound);
  EXPECT_LT(qb.expected_voxels, qw.expected_voxels);
  // Two balls of radius 2 voxels: about 2 * 4/3 pi 2³ = 67 voxels expected.
  EXPECT_NEAR(double(qb.expected_voxels), 2 * 4.18879 * 8, 2);
}

TEST_F(ResolveQueryTest, HeaderDescribesTheResolvedQuery) {
  v1::QueryRequest r = inlineCube();
  r.set_limit_voxels(4);
  r.set_encoding(v1::BRICK_ENCODING_FLOAT16);
  r.set_closest_feature(true);
  r.set_segment_length(0.2);
  const ResolvedQuery q = resolveOk(r);
  v1::QueryHeader h;
  fillQueryHeader(q, "query-7", &h);
  EXPECT_EQ(h.query_id(), "query-7");
  EXPECT_EQ(h.algorithm(), "band");
  EXPECT_EQ(h.padding(), uint32_t(q.padding.voxels));
  EXPECT_GE(h.padding(), 4u);
  EXPECT_FALSE(h.band_clipped());
  EXPECT_EQ(h.sign(), v1::SIGN_MODE_PSEUDONORMAL);
  EXPECT_EQ(h.sign_reason(), q.plan.sign_reason);
  EXPECT_FALSE(h.sign_reason().empty());
  EXPECT_TRUE(h.signed_());
  EXPECT_DOUBLE_EQ(h.limit(), 0.4);
  EXPECT_DOUBLE_EQ(h.voxel_size(), 0.1);
  EXPECT_EQ(h.dims().x(), uint32_t(q.grid.dims().x));
  EXPECT_EQ(h.dims().z(), uint32_t(q.grid.dims().z));
  EXPECT_DOUBLE_EQ(h.origin().y(), q.grid.origin().y);
  EXPECT_EQ(h.encoding(), v1::BRICK_ENCODING_FLOAT16);
  EXPECT_EQ(h.stencil(), stencilOf(q.plan));
  EXPECT_EQ(h.mode(), v1::PROPAGATION_MODE_EXACT);
  EXPECT_DOUBLE_EQ(h.segment_length(), 0.2);
  EXPECT_EQ(h.closest_feature(), v1::CLOSEST_FEATURE_TRIANGLE);
  EXPECT_EQ(h.expected_voxels(), q.expected_voxels);
}

TEST_F(ResolveQueryTest, HeaderOfAWholeGridVolume) {
  const ResolvedQuery q = resolveOk(inlineVolume());
  v1::QueryHeader h;
  fillQueryHeader(q, "v", &h);
  EXPECT_EQ(h.algorithm(), "separable");
  EXPECT_EQ(h.padding(), 0u);
  EXPECT_EQ(h.sign(), v1::SIGN_MODE_UNSIGNED);
  EXPECT_EQ(h.sign_reason(), q.plan.sign_reason);
  EXPECT_FALSE(h.signed_());
  EXPECT_EQ(h.limit(), kInf);
  EXPECT_EQ(h.encoding(), v1::BRICK_ENCODING_FLOAT32);
  EXPECT_EQ(h.closest_feature(), v1::CLOSEST_FEATURE_NONE);
}

}  // namespace
}  // namespace distband
