#include "core/io/vdb_writer.h"

#include <cmath>
#include <cstdio>
#include <filesystem>

#include <fmt/format.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/io/vdb_reader.h"

namespace distband {

struct VdbFieldBuilder::Impl {
  openvdb::FloatGrid::Ptr grid;
  openvdb::FloatGrid::Accessor accessor;
  bool finished = false;
  explicit Impl(openvdb::FloatGrid::Ptr g) : grid(std::move(g)), accessor(grid->getAccessor()) {}
  openvdb::Int32Grid::Ptr closest32;  // at most one of the two
  openvdb::Int64Grid::Ptr closest64;
  void addClosestIds(const Brick& brick);  // into whichever closest grid there is
};

VdbFieldBuilder::VdbFieldBuilder(const Grid& grid, float background) {
  openvdb::initialize();  // idempotent; registers the grid types the writer needs
  // No limit (or a nonsensical one): no distance inside the grid exceeds its diagonal, so that is a safe background.
  if (!(std::isfinite(background) && background > 0)) {
    const Coord d = grid.dims();
    background = float(grid.voxelSize() * std::sqrt(double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z));
  }
  auto g = openvdb::FloatGrid::create(background);
  auto xform = openvdb::math::Transform::createLinearTransform(grid.voxelSize());
  xform->postTranslate(openvdb::Vec3d(grid.origin().x, grid.origin().y, grid.origin().z));
  g->setTransform(xform);
  g->setGridClass(openvdb::GRID_LEVEL_SET);
  g->setName("distance");
  g->insertMeta("distband_dims", openvdb::Vec3IMetadata(openvdb::Vec3i(grid.dims().x, grid.dims().y, grid.dims().z)));
  impl_ = std::make_unique<Impl>(std::move(g));
}

VdbFieldBuilder::~VdbFieldBuilder() = default;

namespace {

using Leaf = openvdb::FloatTree::LeafNodeType;

// The leaf has the brick's layout (offset (x<<6)|(y<<3)|z, bit i of the mask = voxel i): the masked values are
// copied and switched on word by word. Touches this leaf only.
void fillLeaf(Leaf* leaf, const Brick& brick) {
  float* data = leaf->buffer().data();
  auto& mask = leaf->getValueMask();
  for (int w = 0; w < kBrickVoxels / 64; ++w) {
    uint64_t bits = brick.mask.words[w];
    mask.template getWord<uint64_t>(w) |= bits;
    while (bits) {
      const int v = w * 64 + std::countr_zero(bits);
      bits &= bits - 1;
      data[v] = brick.values[v];
    }
  }
}

// The brick's closest-feature ids, set active at its masked voxels (touches the tree: one thread).
template <typename IntGrid>
void addClosest(IntGrid& grid, const Brick& brick) {
  if (brick.closest.size() != size_t(kBrickVoxels) || brick.mask.empty()) return;
  auto* leaf = grid.tree().touchLeaf(openvdb::Coord(brick.origin.x, brick.origin.y, brick.origin.z));
  for (int w = 0; w < kBrickVoxels / 64; ++w)
    for (uint64_t bits = brick.mask.words[w]; bits; bits &= bits - 1) {
      const int v = w * 64 + std::countr_zero(bits);
      leaf->setValueOn(openvdb::Index(v), typename IntGrid::ValueType(brick.closest[size_t(v)]));
    }
}

template <typename IntGrid>
typename IntGrid::Ptr makeClosestGrid(const openvdb::FloatGrid& distance) {
  auto g = IntGrid::create(typename IntGrid::ValueType(-1));
  g->setName("closest");
  g->setTransform(distance.transform().copy());
  return g;
}

}  // namespace

void VdbFieldBuilder::Impl::addClosestIds(const Brick& brick) {
  if (closest32) addClosest(*closest32, brick);
  if (closest64) addClosest(*closest64, brick);
}

void VdbFieldBuilder::addClosestGrid(bool wide) {
  if (wide) impl_->closest64 = makeClosestGrid<openvdb::Int64Grid>(*impl_->grid);
  else impl_->closest32 = makeClosestGrid<openvdb::Int32Grid>(*impl_->grid);
}

void VdbFieldBuilder::add(const Brick& brick) {
  if (brick.mask.empty()) return;
  fillLeaf(impl_->accessor.touchLeaf(openvdb::Coord(brick.origin.x, brick.origin.y, brick.origin.z)), brick);
  impl_->addClosestIds(brick);
}

void VdbFieldBuilder::add(const SegmentBricks& segment) {
  // The tree is only changed (leaves created) on this thread; filling the leaves is then independent per leaf.
  const size_t n = segment.bricks.size();
  std::vector<Leaf*> leaves(n, nullptr);
  for (size_t i = 0; i < n; ++i) {
    const Brick& b = segment.bricks[i];
    if (!b.mask.empty()) leaves[i] = impl_->accessor.touchLeaf(openvdb::Coord(b.origin.x, b.origin.y, b.origin.z));
  }
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 64), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i)
      if (leaves[i]) fillLeaf(leaves[i], segment.bricks[i]);
  });
  for (const Brick& b : segment.bricks) impl_->addClosestIds(b);
}

void VdbFieldBuilder::finish() {
  if (impl_->finished) return;
  impl_->finished = true;
  openvdb::tools::signedFloodFill(impl_->grid->tree());
}

int64_t VdbFieldBuilder::activeVoxels() const { return static_cast<int64_t>(impl_->grid->activeVoxelCount()); }

std::shared_ptr<void> VdbFieldBuilder::gridHandle() { return impl_->grid; }

std::string VdbFieldBuilder::write(const std::string& path) {
  finish();
  const std::string tmp = path + ".tmp";
  try {
    openvdb::io::File file(tmp);
    openvdb::GridPtrVec grids{impl_->grid};
    if (impl_->closest32) grids.push_back(impl_->closest32);
    if (impl_->closest64) grids.push_back(impl_->closest64);
    file.write(grids);
    file.close();
  } catch (const std::exception& e) {
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    return fmt::format("{}: cannot write the VDB file: {}", path, e.what());
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    return fmt::format("{}: cannot move the finished file into place: {}", path, ec.message());
  }
  return {};
}

std::string readVdb(const std::string& path, openvdb::FloatGrid::Ptr* out, const std::string& grid_name) {
  openvdb::initialize();
  try {
    openvdb::io::File file(path);
    file.open();
    openvdb::GridBase::Ptr base = file.readGrid(grid_name);
    file.close();
    auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
    if (!grid) return fmt::format("{}: grid '{}' is not a FloatGrid", path, grid_name);
    *out = grid;
  } catch (const std::exception& e) {
    return fmt::format("{}: cannot read grid '{}': {}", path, grid_name, e.what());
  }
  return {};
}

}  // namespace distband
