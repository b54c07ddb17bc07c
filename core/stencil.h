// Stencil: the neighbourhood a voxel propagates its closest site to, and the lifespan coefficient alpha.
// Contract: immutable tables; the derivation of each alpha is in docs/algorithm.md.
//   cubic6  : the 6 axial links; a site at distance l arrives after l..sqrt(3)*l steps  -> alpha = sqrt(3)-1
//   cubic18 : axial + face-diagonal links; arrival l/sqrt(2)..l steps                  -> alpha = sqrt(2)-1
//   cubic26 : all 26 links (Chebyshev steps); arrival l/sqrt(3)..l steps              -> alpha = sqrt(3)-1
//   fcc12   : the FCC half of the grid (i+j+k even), links (±1,±1,0) and permutations  -> alpha = sqrt(2)-1;
//             the odd half receives from its 6 axial (even) neighbours and never propagates further.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/types.h"

namespace distband {

enum class StencilKind { kCubic6, kCubic18, kCubic26, kFcc12 };
/// Every stencil, in the order names are listed to users.
inline constexpr StencilKind kStencilKinds[] = {StencilKind::kCubic26, StencilKind::kCubic18, StencilKind::kCubic6,
                                                StencilKind::kFcc12};

struct Stencil {
  StencilKind kind;
  std::vector<Coord> links;  ///< offsets a propagating voxel offers its site to
  double alpha;              ///< the paper's lifespan coefficient for this lattice
  bool fcc;                  ///< only even voxels (i+j+k even) propagate

  static const Stencil& get(StencilKind kind);
  bool propagates(const Coord& c) const { return !fcc || ((c.x + c.y + c.z) & 1) == 0; }
};

std::string_view stencilName(StencilKind kind);
std::optional<StencilKind> parseStencil(std::string_view name);  ///< "cubic6", "cubic18", "cubic26", "fcc12"

}  // namespace distband
