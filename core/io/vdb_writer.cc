#include "core/io/vdb_writer.h"

#include <bit>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <tuple>
#include <vector>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/io/vdb_file.h"

namespace distband {
namespace {

// No limit (or a nonsensical one): no distance inside the grid exceeds its diagonal, so that is a safe background.
float levelSetBackground(const Grid& grid, float background) {
  if (std::isfinite(background) && background > 0) return background;
  return float(grid.diagonalWorld(grid.dims()));
}

// The leaf has the brick's layout (offset (x<<6)|(y<<3)|z, bit i of the mask = voxel i): the masked values are
// copied and switched on word by word. Touches this leaf only.
template <class Leaf, class Source>
void fillLeaf(Leaf* leaf, const BrickMask& mask, const Source& source) {
  for (size_t w = 0; w < mask.words.size(); ++w) {
    uint64_t bits = mask.words[w];
    leaf->mask.words[w] |= bits;
    while (bits) {
      const int v = int(w * 64) + std::countr_zero(bits);
      bits &= bits - 1;
      leaf->values[size_t(v)] = source[size_t(v)];
    }
  }
}

}  // namespace

VdbFieldBuilder::VdbFieldBuilder(const Grid& grid, float background)
    : grid_(grid), distance_(levelSetBackground(grid, background)) {}

VdbFieldBuilder::~VdbFieldBuilder() = default;

void VdbFieldBuilder::addClosestGrid(bool wide) {
  if (wide) closest64_ = std::make_unique<VdbTree<int64_t>>(-1);
  else closest32_ = std::make_unique<VdbTree<int32_t>>(-1);
}

template <class Tree>
void VdbFieldBuilder::addClosest(Tree& tree, const Brick& brick) {
  using Value = typename std::remove_reference_t<decltype(tree.leaves()[0]->values[0])>;
  std::array<Value, kBrickVoxels> ids;
  for (int i = 0; i < kBrickVoxels; ++i) ids[size_t(i)] = Value(brick.closest[size_t(i)]);
  fillLeaf(tree.touchLeaf(brick.origin), brick.mask, ids);
}

void VdbFieldBuilder::addClosest(const Brick& brick) {
  if (brick.closest.size() != size_t(kBrickVoxels) || brick.mask.empty()) return;
  if (closest32_) addClosest(*closest32_, brick);
  if (closest64_) addClosest(*closest64_, brick);
}

void VdbFieldBuilder::add(const Brick& brick) {
  if (brick.mask.empty()) return;
  fillLeaf(distance_.touchLeaf(brick.origin), brick.mask, brick.values);
  addClosest(brick);
}

void VdbFieldBuilder::add(const SegmentBricks& segment) {
  const auto& bricks = segment.bricks;
  const size_t n = bricks.size();
  // A segment lists its bricks in (z, y, x) order of origins, each once (Brick's contract); then leaves are created on
  // this thread (index entries only), and made and filled independently per leaf. A segment that breaks the order
  // (a server is not trusted) is applied brick by brick on this thread, in its order: no leaf is filled by two threads.
  auto before = [](const Coord& a, const Coord& b) { return std::tie(a.z, a.y, a.x) < std::tie(b.z, b.y, b.x); };
  bool ordered = true;
  for (size_t i = 1; i < n && ordered; ++i) ordered = before(bricks[i - 1].origin, bricks[i].origin);
  if (!ordered) {
    for (const Brick& b : bricks) add(b);
    return;
  }
  std::vector<VdbTree<float>::Leaf*> leaves(n, nullptr);
  std::vector<uint8_t> created(n, 0);
  for (size_t i = 0; i < n; ++i) {
    if (bricks[i].mask.empty()) continue;
    bool is_new = false;
    leaves[i] = distance_.touchLeaf(bricks[i].origin, &is_new);
    created[i] = is_new;
  }
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 64), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (!leaves[i]) continue;
      if (created[i]) distance_.initLeaf(leaves[i], bricks[i].origin);
      fillLeaf(leaves[i], bricks[i].mask, bricks[i].values);
    }
  });
  if (closest32_ || closest64_)
    for (const Brick& b : bricks) addClosest(b);
}

void VdbFieldBuilder::setRunState(bool complete, int segments) { run_state_ = {complete, segments}; }

void VdbFieldBuilder::finish() {
  if (finished_) return;
  finished_ = true;
  distance_.signedFloodFill();
  if (closest32_) closest32_->seal();
  if (closest64_) closest64_->seal();
}

Status VdbFieldBuilder::write(const std::string& path) {
  finish();
  VdbGridOut distance;
  distance.name = "distance";
  distance.float_tree = &distance_;
  distance.level_set = true;
  distance.metadata.emplace_back("distband_dims", grid_.dims());
  if (run_state_) {
    distance.metadata.emplace_back("distband_complete", run_state_->first);
    distance.metadata.emplace_back("distband_segments", int32_t(run_state_->second));
  }
  std::vector<VdbGridOut> grids{distance};
  if (closest32_ || closest64_) {
    VdbGridOut closest;
    closest.name = "closest";
    closest.int32_tree = closest32_.get();
    closest.int64_tree = closest64_.get();
    grids.push_back(closest);
  }
  const std::string tmp = path + ".tmp";
  std::error_code ec;
  if (Status s = writeVdbFile(tmp, grids, {grid_.spacing(), grid_.origin()}); !s.ok()) {
    std::filesystem::remove(tmp, ec);
    return s.withPrefix(fmt::format("{}: cannot write the VDB file", path));
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    return Status::IoError(fmt::format("{}: cannot move the finished file into place: {}", path, ec.message()));
  }
  return Status::Ok();
}

}  // namespace distband
