#include "core/field/field_run.h"

#include <cmath>

#include <fmt/format.h>

namespace distband {

Status validateRunOptions(const Grid& grid, const FieldRunOptions& o) {
  if (Status s = grid.validate(); !s.ok()) return s.withPrefix("grid");
  if (!(o.segment_length_world >= 0) || std::isinf(o.segment_length_world))
    return Status::InvalidArgument(
        fmt::format("segment_length must be finite and >= 0 (got {})", o.segment_length_world));
  if (!(o.limit_world > 0)) return Status::InvalidArgument(fmt::format("limit must be > 0 (got {})", o.limit_world));
  if (o.threads < 0 || o.threads > 4096)
    return Status::InvalidArgument(fmt::format("threads must be in [0, 4096] (got {})", o.threads));
  if (o.segment_length_world > 0 && std::isfinite(o.limit_world) && o.limit_world / o.segment_length_world > 100000)
    return Status::InvalidArgument("limit / segment_length must be <= 100000 segments");
  return Status::Ok();
}

}  // namespace distband
