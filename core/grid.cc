#include "core/grid.h"

#include <cmath>

#include <fmt/format.h>

namespace distband {

Grid::Grid(Vec3d origin, Vec3d spacing, Coord dims)
    : origin_(origin), spacing_(spacing), unit_(std::min(spacing.x, std::min(spacing.y, spacing.z))), dims_(dims) {
  // A cubic grid keeps exact unit scales; validate() refuses what would make them meaningless (unit <= 0, NaN).
  scale_ = cubic() ? Vec3d{1, 1, 1} : Vec3d{spacing.x / unit_, spacing.y / unit_, spacing.z / unit_};
}

double Grid::diagonalWorld(const Coord& d) const {
  if (cubic()) return unit_ * std::sqrt(double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z);
  const double x = spacing_.x * d.x, y = spacing_.y * d.y, z = spacing_.z * d.z;
  return std::sqrt(x * x + y * y + z * z);
}

Status Grid::validate() const {
  for (double s : {spacing_.x, spacing_.y, spacing_.z})
    if (!(std::isfinite(s) && s > 0)) {
      if (cubic()) return Status::InvalidArgument(fmt::format("voxel size must be finite and > 0 (got {})", s));
      return Status::InvalidArgument(fmt::format("spacing must be finite and > 0 along every axis (got {}, {}, {})",
                                                 spacing_.x, spacing_.y, spacing_.z));
    }
  if (maxAxisScale() > kMaxSpacingRatio)
    return Status::InvalidArgument(fmt::format("spacing {}, {}, {}: the largest is more than {} times the smallest",
                                               spacing_.x, spacing_.y, spacing_.z, kMaxSpacingRatio));
  if (!(std::isfinite(origin_.x) && std::isfinite(origin_.y) && std::isfinite(origin_.z)))
    return Status::InvalidArgument("origin must be finite");
  for (int d : {dims_.x, dims_.y, dims_.z})
    if (d < 1 || d > kMaxGridDim)
      return Status::InvalidArgument(fmt::format("dims must be in [1, {}] along every axis (got {}x{}x{})", kMaxGridDim,
                                                 dims_.x, dims_.y, dims_.z));
  return Status::Ok();
}

}  // namespace distband
