#include "core/band/internal/band_state.h"

namespace distband::band_internal {

Lifespan::Lifespan(const BandOptions& opt, const Stencil& stencil) {
  if (opt.mode == PropagationMode::kPaper) {
    alpha = opt.lifespan_alpha < 0 ? stencil.alpha : opt.lifespan_alpha;
    margin = opt.lifespan_margin < 0 ? defaultLifespanMargin(stencil.kind) : opt.lifespan_margin;
    enabled = std::isfinite(alpha);
  }
  max_link = stencil.fcc ? std::sqrt(2.0) : 0.0;
  if (!stencil.fcc)
    for (const Coord& l : stencil.links)
      max_link = std::max(max_link, std::sqrt(double(l.x * l.x + l.y * l.y + l.z * l.z)));
}

BandState::BandState(const Grid& g, const Seeds& s, const BandOptions& o)
    : grid(g),
      seeds(s),
      opt(o),
      stencil(Stencil::get(o.stencil.value_or(defaultStencil(s.kind, g.cubic())))),
      metric{s, g.axisScale(), !g.cubic()},
      dims(g.dims()),
      region(s.region ? s.region->data() : nullptr),
      links(stencil, g.axisScale()),
      lifespan(o, stencil),
      table(g.brickDims(), lifespan.enabled) {
  const double h = g.voxelSize();
  limit_vox = o.limit_world / h;
  segment_vox = o.segment_length_world / h;
  slack_scale = g.maxAxisScale();
}

}  // namespace distband::band_internal
