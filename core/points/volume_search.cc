#include "core/points/volume_search.h"

#include <cmath>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace distband {
namespace {

struct Boundary {
  std::vector<Vec3d> centres;
  std::vector<int64_t> ids;
};

/// The voxels of kind `seed` (nonzero) or not, with a 6-neighbour of the other kind; `faces`: also those on the grid's
/// faces (whose missing neighbour counts as the other kind).
Status boundaryVoxels(const std::vector<uint8_t>& mask, const Grid& lattice, bool seed, bool faces,
                      const Interrupter* interrupter, Boundary* out) {
  const Coord d = lattice.dims();
  std::vector<Boundary> per_slice(size_t(d.z));
  auto kind = [&](int x, int y, int z) { return mask[size_t(lattice.denseIndex({x, y, z}))] != 0; };
  tbb::parallel_for(0, d.z, [&](int z) {
    if (isInterrupted(interrupter)) return;
    Boundary& b = per_slice[size_t(z)];
    for (int y = 0; y < d.y; ++y)
      for (int x = 0; x < d.x; ++x) {
        if (kind(x, y, z) != seed) continue;
        bool edge = false;
        const int n[6][3] = {{x - 1, y, z}, {x + 1, y, z}, {x, y - 1, z}, {x, y + 1, z}, {x, y, z - 1}, {x, y, z + 1}};
        for (const auto& c : n) {
          if (!lattice.contains({c[0], c[1], c[2]})) edge = edge || faces;
          else edge = edge || kind(c[0], c[1], c[2]) != seed;
        }
        if (!edge) continue;
        b.centres.push_back(lattice.worldOf({x, y, z}));
        b.ids.push_back(lattice.denseIndex({x, y, z}));
      }
  });
  if (isInterrupted(interrupter)) return interrupter->status();
  for (Boundary& b : per_slice) {
    out->centres.insert(out->centres.end(), b.centres.begin(), b.centres.end());
    out->ids.insert(out->ids.end(), b.ids.begin(), b.ids.end());
    Boundary().centres.swap(b.centres);
    std::vector<int64_t>().swap(b.ids);
  }
  return Status::Ok();
}

}  // namespace

Status VolumeSearch::build(std::shared_ptr<const std::vector<uint8_t>> mask, const Grid& lattice, bool inside_negative,
                           const Interrupter* interrupter, VolumeSearch* out) {
  if (Status s = lattice.validate(); !s.ok()) return s.withPrefix("the volume's lattice");
  if (!mask || int64_t(mask->size()) != lattice.voxelCount())
    return Status::InvalidArgument(fmt::format("the mask holds {} bytes for {} voxels", mask ? mask->size() : 0,
                                               lattice.voxelCount()));
  VolumeSearch v;
  v.mask_ = std::move(mask);
  v.lattice_ = lattice;
  v.inside_negative_ = inside_negative;
  Boundary seeds;
  if (Status s = boundaryVoxels(*v.mask_, lattice, true, true, interrupter, &seeds); !s.ok()) return s;
  if (seeds.centres.empty()) return Status::InvalidArgument("the volume has no seed voxel");
  if (Status s = PointSet::build(seeds.centres, seeds.ids, interrupter, &v.seeds_); !s.ok()) return s;
  if (inside_negative) {
    Boundary free;
    if (Status s = boundaryVoxels(*v.mask_, lattice, false, false, interrupter, &free); !s.ok()) return s;
    if (free.centres.empty())
      return Status::InvalidArgument("the volume has no voxel outside the mask (its inside has no distance to it)");
    v.free_ = std::make_unique<PointSet>();
    if (Status s = PointSet::build(free.centres, free.ids, interrupter, v.free_.get()); !s.ok()) return s;
  }
  *out = std::move(v);
  return Status::Ok();
}

std::optional<int64_t> VolumeSearch::seedCell(const Vec3d& p) const {
  const Vec3d q = lattice_.indexOf(p);
  const double r[3] = {std::round(q.x), std::round(q.y), std::round(q.z)};
  const Coord d = lattice_.dims();
  if (!(r[0] >= 0 && r[1] >= 0 && r[2] >= 0 && r[0] < d.x && r[1] < d.y && r[2] < d.z)) return std::nullopt;
  const int64_t i = lattice_.denseIndex({int(r[0]), int(r[1]), int(r[2])});
  return (*mask_)[size_t(i)] != 0 ? std::optional<int64_t>(i) : std::nullopt;
}

bool VolumeSearch::nearest(const Vec3d& p, double limit, NearestVoxel* out) const {
  const double limit2 = limit * limit;
  const std::optional<int64_t> cell = seedCell(p);
  NearestPoint found;
  if (cell && !inside_negative_) {
    const Coord d = lattice_.dims();
    const int64_t i = *cell;
    const Vec3d c = lattice_.worldOf({int(i % d.x), int(i / d.x % d.y), int(i / (int64_t(d.x) * d.y))});
    const double d2 = (p - c).lengthSqr();
    if (d2 > limit2) return false;
    *out = {std::sqrt(d2), i, c};
    return true;
  }
  const PointSet& set = cell ? *free_ : seeds_;
  if (!set.nearest(p, limit2, &found)) return false;
  const double distance = std::sqrt(found.dist2);
  *out = {cell ? -distance : distance, found.id, found.point};
  return true;
}

}  // namespace distband
