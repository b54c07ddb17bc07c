#include "core/seeds/volume_seeds.h"

#include <algorithm>
#include <atomic>
#include <cstring>
#include <iterator>
#include <limits>
#include <memory>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace distband {
namespace {

// What one z-slice contributes, found independently of the other slices (in parallel): its boundary voxels in scan
// order (their linear indices, for the neighbour lookups of the signed case, and their positions: the sites), and
// its band. Site ids are numbered slice after slice in scan order, so the result does not depend on threads.
struct Slice {
  std::vector<int64_t> boundary;
  std::vector<BandVoxel> band;  // unsigned: sites numbered within the slice, made global on concatenation
  int64_t inside = 0;
};

}  // namespace

Status checkVolumeMeasure(const LabelVolume& volume, const VolumeMeasure& measure) {
  if (measure.labels) {
    if (!measure.black_border && volume.at(0) != 0 && !volumeHasTwoLabels(volume))
      return Status::InvalidArgument(fmt::format(
          "every voxel has label {}: no voxel of another label, so the distance is undefined (a black border gives "
          "the grid's outside label 0)",
          volume.at(0)));
    return Status::Ok();
  }
  if (!volumeHas(volume, false)) return Status::InvalidArgument("the seed volume has no nonzero voxel");
  if (measure.inside_negative && !volumeHas(volume, true))
    return Status::InvalidArgument("the seed volume has no zero voxel, so a signed field is undefined");
  return Status::Ok();
}

namespace {

// Nothing here allocates per grid voxel beyond the signed case's region (1 byte a voxel, which the engine needs): a
// dense table of site ids would take 4 bytes a voxel (4 GiB at 1024^3), and filling it, one thread first-touching
// every page, seconds that a cancel could not interrupt.
template <class T>
Status buildVolumeSeeds(const Grid& grid, const LabelVolume& volume, const T* labels, bool signed_distance, Seeds* out,
                        const Interrupter* interrupter) {
  const Coord d = grid.dims();
  const int64_t sy = d.x, sz = int64_t(d.x) * d.y;
  auto inside = [&](int64_t i) { return labels[i] != 0; };
  // A voxel is on its side's boundary when a 6-neighbour lies on the other side.
  auto onBoundary = [&](int x, int y, int z, int64_t i) {
    const bool in = inside(i);
    return (x > 0 && inside(i - 1) != in) || (x + 1 < d.x && inside(i + 1) != in) ||
           (y > 0 && inside(i - sy) != in) || (y + 1 < d.y && inside(i + sy) != in) ||
           (z > 0 && inside(i - sz) != in) || (z + 1 < d.z && inside(i + sz) != in);
  };
  std::vector<Slice> slices(size_t(d.z));
  auto stop = [&] { return isInterrupted(interrupter); };
  // 1. Boundary voxels (the sites) and, unsigned, the band: every mask voxel, the boundary ones with their site.
  tbb::parallel_for(0, d.z, [&](int z) {
    if (stop()) return;
    Slice& s = slices[size_t(z)];
    for (int y = 0; y < d.y; ++y)
      for (int x = 0; x < d.x; ++x) {
        const int64_t i = (int64_t(z) * d.y + y) * d.x + x;
        s.inside += inside(i);
        if (!signed_distance && !inside(i)) continue;
        const bool boundary = onBoundary(x, y, z, i);
        if (boundary) s.boundary.push_back(i);
        if (!signed_distance) s.band.push_back({{x, y, z}, boundary ? uint32_t(s.boundary.size() - 1) : kNoSite});
      }
  });
  if (stop()) return interruptedStatus(interrupter);
  std::vector<uint32_t> first_site(slices.size() + 1, 0);
  int64_t n_inside = 0;
  for (size_t z = 0; z < slices.size(); ++z) {
    n_inside += slices[z].inside;
    const uint64_t next = uint64_t(first_site[z]) + slices[z].boundary.size();
    if (next >= kNoSite)
      return Status::ResourceExhausted(fmt::format("the seed mask has more than {} boundary voxels", kNoSite - 1));
    first_site[z + 1] = uint32_t(next);
  }
  if (n_inside == 0 || (signed_distance && n_inside == grid.voxelCount()))
    return checkVolumeMeasure(volume, {false, signed_distance, false});

  if (signed_distance) {
    // 2. Each boundary voxel starts with the nearest voxel across the boundary (a 6-neighbour, distance 1): the
    // lowest site id among them, so the choice does not depend on scan order.
    auto siteOf = [&](int64_t j) {  // j is a boundary voxel: its site id
      const int zj = int(j / sz);
      const auto& b = slices[size_t(zj)].boundary;
      return first_site[size_t(zj)] + uint32_t(std::lower_bound(b.begin(), b.end(), j) - b.begin());
    };
    // On an anisotropic grid the nearest of them is along the axis of the smallest scale: the nearest first, then
    // the lowest id (its site must be offered: propagation never crosses the boundary to bring it).
    const Vec3d scale = grid.axisScale();
    tbb::parallel_for(0, d.z, [&](int z) {
      if (stop()) return;
      Slice& s = slices[size_t(z)];
      s.band.reserve(s.boundary.size());
      for (const int64_t i : s.boundary) {
        const int x = int(i % sy), y = int((i / sy) % d.y);
        const bool in = inside(i);
        uint32_t best = kNoSite;
        double best_step = std::numeric_limits<double>::infinity();
        // A 6-neighbour on the other side is itself on the boundary, so it has a site.
        auto consider = [&](bool ok, int64_t j, double step) {
          if (!ok || inside(j) == in || step > best_step) return;
          const uint32_t site = siteOf(j);
          if (step < best_step || site < best) best = site;
          best_step = step;
        };
        consider(x > 0, i - 1, scale.x);
        consider(x + 1 < d.x, i + 1, scale.x);
        consider(y > 0, i - sy, scale.y);
        consider(y + 1 < d.y, i + sy, scale.y);
        consider(z > 0, i - sz, scale.z);
        consider(z + 1 < d.z, i + sz, scale.z);
        s.band.push_back({{x, y, z}, best});
      }
    });
    if (stop()) return interruptedStatus(interrupter);
  }

  // 3. Concatenate, slice by slice with a poll between slices (the copies first-touch fresh memory on one thread),
  // freeing each slice as it is taken.
  Seeds seeds;
  seeds.kind = SiteKind::kPoint;
  size_t band_total = 0;
  for (const Slice& s : slices) band_total += s.band.size();
  seeds.feature_kind = Seeds::FeatureKind::kSiteVoxel;  // sites are boundary voxels
  seeds.points.reserve(first_site.back());
  seeds.band.reserve(band_total);
  for (size_t z = 0; z < slices.size(); ++z) {
    if (stop()) return interruptedStatus(interrupter);
    Slice& s = slices[z];
    for (const int64_t i : s.boundary)
      seeds.points.push_back(grid.unitsOfIndex({double(i % sy), double((i / sy) % d.y), double(z)}));
    for (BandVoxel v : s.band) {
      if (!signed_distance && v.site != kNoSite) v.site += first_site[z];
      seeds.band.push_back(v);
    }
    std::vector<int64_t>().swap(s.boundary);
    std::vector<BandVoxel>().swap(s.band);
  }

  if (signed_distance) {
    // Which side each voxel is on, 0/1 (the engine keeps each side's distances to its own sites). Copied in 4 MiB
    // steps with a poll between them, for the same reason as above.
    auto region = std::make_shared<std::vector<uint8_t>>();
    const size_t count = size_t(grid.voxelCount());
    region->reserve(count);
    constexpr size_t kStep = size_t(4) << 20;
    for (size_t i = 0; i < count; i += kStep) {
      if (stop()) return interruptedStatus(interrupter);
      const size_t end = std::min(count, i + kStep);
      std::transform(labels + i, labels + end, std::back_inserter(*region), [](T m) { return uint8_t(m != 0); });
    }
    seeds.region = region;
    const Grid g = grid;
    seeds.sign = [region, g](Brick& brick, const uint32_t*) {
      for (int i = 0; i < kBrickVoxels; ++i) {
        if (!brick.mask.test(i)) continue;
        const Coord c = brick.origin + brickLocal(i);
        if ((*region)[g.denseIndex(c)]) brick.values[i] = -brick.values[i];
      }
    };
  }
  *out = std::move(seeds);
  return Status::Ok();
}

}  // namespace

Status makeVolumeSeeds(const Grid& grid, const LabelVolume& volume, bool signed_distance, Seeds* out,
                       const Interrupter* interrupter) {
  if (!volume || !(volume.dims() == grid.dims()))
    return Status::InvalidArgument(fmt::format("the volume has {} voxels, the grid {}",
                                               volume ? volume.voxelCount() : 0, grid.voxelCount()));
  return volume.visit([&](const auto* labels) {
    return buildVolumeSeeds(grid, volume, labels, signed_distance, out, interrupter);
  });
}

}  // namespace distband
