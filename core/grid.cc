#include "core/grid.h"

#include <cmath>

#include <fmt/format.h>

namespace distband {

std::string Grid::validate() const {
  if (!(std::isfinite(voxel_size_) && voxel_size_ > 0))
    return fmt::format("voxel size must be finite and > 0 (got {})", voxel_size_);
  if (!(std::isfinite(origin_.x) && std::isfinite(origin_.y) && std::isfinite(origin_.z)))
    return "origin must be finite";
  for (int d : {dims_.x, dims_.y, dims_.z})
    if (d < 1 || d > kMaxGridDim)
      return fmt::format("dims must be in [1, {}] along every axis (got {}x{}x{})", kMaxGridDim, dims_.x, dims_.y,
                         dims_.z);
  return {};
}

}  // namespace distband
