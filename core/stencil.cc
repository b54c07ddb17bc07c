#include "core/stencil.h"

#include <cmath>
#include <cstdlib>

namespace distband {
namespace {

Stencil makeStencil(StencilKind kind) {
  Stencil s{kind, {}, 0.0, kind == StencilKind::kFcc12};
  for (int z = -1; z <= 1; ++z)
    for (int y = -1; y <= 1; ++y)
      for (int x = -1; x <= 1; ++x) {
        const int n = std::abs(x) + std::abs(y) + std::abs(z);
        if (n == 0) continue;
        bool take = false;
        switch (kind) {
          case StencilKind::kCubic6: take = n == 1; break;
          case StencilKind::kCubic18: take = n <= 2; break;
          case StencilKind::kCubic26: take = true; break;
          // FCC links plus the 6 axial links that feed the odd half (those voxels never propagate).
          case StencilKind::kFcc12: take = n <= 2; break;
        }
        if (take) s.links.push_back({x, y, z});
      }
  switch (kind) {
    case StencilKind::kCubic6:
    case StencilKind::kCubic26: s.alpha = std::sqrt(3.0) - 1.0; break;
    case StencilKind::kCubic18:
    case StencilKind::kFcc12: s.alpha = std::sqrt(2.0) - 1.0; break;
  }
  return s;
}

}  // namespace

const Stencil& Stencil::get(StencilKind kind) {
  static const Stencil kAll[] = {makeStencil(StencilKind::kCubic6), makeStencil(StencilKind::kCubic18),
                                 makeStencil(StencilKind::kCubic26), makeStencil(StencilKind::kFcc12)};
  return kAll[static_cast<int>(kind)];
}

std::string_view stencilName(StencilKind kind) {
  switch (kind) {
    case StencilKind::kCubic6: return "cubic6";
    case StencilKind::kCubic18: return "cubic18";
    case StencilKind::kCubic26: return "cubic26";
    case StencilKind::kFcc12: return "fcc12";
  }
  return "?";
}

std::optional<StencilKind> parseStencil(std::string_view name) {
  for (StencilKind k : kStencilKinds)
    if (stencilName(k) == name) return k;
  return std::nullopt;
}

}  // namespace distband
