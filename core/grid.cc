#include "core/grid.h"

#include <cmath>

#include <fmt/format.h>

namespace distband {

Status Grid::validate() const {
  if (!(std::isfinite(voxel_size_) && voxel_size_ > 0))
    return Status::InvalidArgument(fmt::format("voxel size must be finite and > 0 (got {})", voxel_size_));
  if (!(std::isfinite(origin_.x) && std::isfinite(origin_.y) && std::isfinite(origin_.z)))
    return Status::InvalidArgument("origin must be finite");
  for (int d : {dims_.x, dims_.y, dims_.z})
    if (d < 1 || d > kMaxGridDim)
      return Status::InvalidArgument(fmt::format("dims must be in [1, {}] along every axis (got {}x{}x{})", kMaxGridDim, dims_.x, dims_.y,
                         dims_.z));
  return Status::Ok();
}

}  // namespace distband
