#include "core/field/field_plan.h"

#include <cmath>
#include <stdexcept>

#include <fmt/format.h>

namespace distband {

std::string_view algorithmName(FieldAlgorithm algorithm) {
  return algorithm == FieldAlgorithm::kSeparable ? "separable" : "band";
}

std::optional<FieldAlgorithm> parseAlgorithm(std::string_view name) {
  for (FieldAlgorithm a : {FieldAlgorithm::kBand, FieldAlgorithm::kSeparable})
    if (name == algorithmName(a)) return a;
  return std::nullopt;
}

std::string_view FieldPlan::signName() const {
  if (seeds == SeedKind::kMesh) return signMethodName(mesh_sign);
  return seeds == SeedKind::kVolume && inside_negative ? kMaskInsideSign : signMethodName(SignMethod::kUnsigned);
}

std::string_view FieldPlan::closestFeatureName() const {
  if (nearest_label) return "label";
  switch (seeds) {
    case SeedKind::kMesh: return "triangle";
    case SeedKind::kVolume: return "voxel";
    default: return "point";
  }
}

std::string algorithmDescription(FieldAlgorithm algorithm, SeedKind seeds, bool limited) {
  if (algorithm == FieldAlgorithm::kBand)
    return "band: the adaptive iteration on an evolving active band (SMI 2009); segments stream nearest first as "
           "the band passes them";
  if (seeds == SeedKind::kPoints)
    return "separable: an exact point EDT over the whole grid, axis by axis (points on few lattice planes); the first "
           "segment comes once the whole field is known";
  if (limited)
    return "separable: an exact EDT, axis by axis, over the bricks within the limit of the seed volume's boundary; "
           "with segments and a limit of many bricks the first segment comes first from the bricks within its bound";
  return "separable: an exact EDT over the whole grid, axis by axis; with segments the first segment comes first "
         "from the bricks within its bound, the rest once the whole field is known";
}

std::string FieldPlan::algorithmDescription() const {
  std::string text = distband::algorithmDescription(algorithm, seeds, std::isfinite(limit_world));
  if (labels)
    text += fmt::format("; labels: each voxel of a label measured to the nearest voxel of another label{}",
                        black_border ? " or the grid's outside (black border)" : "");
  if (nearest_label) text += "; with each voxel's nearest seed label";
  return text;
}

Status requestSign(std::string_view name, FieldRequest* r) {
  std::string mesh_names;  // "auto, pseudonormal, winding, parity or unsigned"
  for (SignMethod m : kSignMethods) {
    const bool last = m == kSignMethods[std::size(kSignMethods) - 1];
    mesh_names += fmt::format("{}{}", mesh_names.empty() ? "" : last ? " or " : ", ", signMethodName(m));
  }
  const std::string takes = r->seeds == SeedKind::kMesh ? "meshes take " + mesh_names
                            : r->seeds == SeedKind::kVolume
                                ? fmt::format("volume seeds take auto, unsigned or {}", kMaskInsideSign)
                                : std::string("point seeds take auto or unsigned");
  SignMethod method;
  if (name == kMaskInsideSign) {
    if (r->seeds != SeedKind::kVolume)
      return Status::InvalidArgument(fmt::format("{} is for volume seeds; {}", name, takes));
    r->inside_negative = true;
  } else if (!parseSignMethod(name, &method)) {
    return Status::InvalidArgument(fmt::format("unknown sign '{}': {}", name, takes));
  } else if (r->seeds == SeedKind::kMesh) {
    r->mesh_sign = method;
  } else if (method != SignMethod::kAuto && method != SignMethod::kUnsigned) {
    return Status::InvalidArgument(fmt::format("{} is for meshes; {}", name, takes));
  }
  return Status::Ok();
}

FieldRunOptions FieldPlan::runOptions() const {
  FieldRunOptions o;
  o.limit_world = limit_world;
  o.segment_length_world = segment_length_world;
  o.closest_features = hasClosestFeatures();
  return o;
}

BandOptions FieldPlan::bandOptions(const FieldRunOptions& run) const {
  BandOptions o;
  static_cast<FieldRunOptions&>(o) = run;
  o.mode = mode;
  o.stencil = stencil;
  o.second_ring = second_ring;
  return o;
}

MeshSeedOptions FieldPlan::meshSeedOptions(const Grid& grid) const {
  MeshSeedOptions o;
  o.mode = mode == PropagationMode::kPaper ? MeshSiteMode::kPaper : MeshSiteMode::kExactFeature;
  o.sign = mesh_sign;
  o.limit_voxels = limitVoxels(grid);
  return o;
}

Status planSign(const FieldRequest& r, const MeshReport* mesh_report, SignPlan* out) {
  SignPlan p;
  switch (r.seeds) {
    case SeedKind::kPoints:
      if (r.inside_negative) return Status::InvalidArgument("sign: point seeds are unsigned");
      p.reason = "points are unsigned";
      break;
    case SeedKind::kVolume:
      p.inside_negative = r.inside_negative;
      p.reason = r.inside_negative ? "requested" : "default";
      break;
    case SeedKind::kMesh:
      if (r.inside_negative) return Status::InvalidArgument("sign: mask-inside is for volume seeds");
      if (!mesh_report) throw std::invalid_argument("planSign: a mesh's sign needs its report");
      p.mesh_sign = resolveSignMethod(r.mesh_sign.value_or(kDefaultMeshSign), *mesh_report, &p.reason);
      break;
  }
  if (r.seeds != SeedKind::kMesh && r.mesh_sign && *r.mesh_sign != SignMethod::kUnsigned &&
      *r.mesh_sign != SignMethod::kAuto)
    return Status::InvalidArgument(fmt::format("sign: {} is for meshes", signMethodName(*r.mesh_sign)));
  *out = std::move(p);
  return Status::Ok();
}

Status planField(const FieldRequest& r, const Grid& grid, const MeshReport* mesh_report, FieldPlan* out) {
  FieldPlan p;
  p.seeds = r.seeds;
  p.mode = r.mode.value_or(PropagationMode::kExact);
  // Meshes in exact mode propagate triangle sites; paper mode and the other seeds propagate points.
  p.sites = r.seeds == SeedKind::kMesh && p.mode == PropagationMode::kExact ? SiteKind::kTriangle : SiteKind::kPoint;
  p.stencil = r.stencil.value_or(defaultStencil(p.sites, grid.cubic()));
  SignPlan sign;
  if (Status st = planSign(r, mesh_report, &sign); !st.ok()) return st;
  p.mesh_sign = sign.mesh_sign;
  p.inside_negative = sign.inside_negative;
  p.sign_reason = std::move(sign.reason);
  if (r.seeds != SeedKind::kVolume && (r.labels || r.black_border || r.nearest_label))
    return Status::InvalidArgument("labels, black border and nearest labels are for volume seeds");
  if (r.black_border && !r.labels)
    return Status::InvalidArgument("black border: it applies to the multi-label EDT (labels)");
  if (r.labels && r.inside_negative)
    return Status::InvalidArgument("labels: the multi-label EDT is unsigned (mask-inside is the seed field's)");
  if (r.labels && (r.nearest_label || r.closest_features))
    return Status::InvalidArgument(
        "labels: the multi-label EDT has no closest features (nearest labels are the seed field's)");
  if (r.nearest_label && r.closest_features)
    return Status::InvalidArgument("nearest label and closest features exclude each other (one id per voxel)");
  p.labels = r.labels;
  p.black_border = r.black_border;
  p.nearest_label = r.nearest_label;
  if (r.labels) p.sign_reason = "labels are unsigned";
  p.limit_world = r.limit_voxels > 0 ? r.limit_voxels * grid.voxelSize() : r.limit_world;
  p.segment_length_world = r.segment_length_world;
  p.closest_features = r.closest_features;
  p.second_ring = r.second_ring;
  p.point_layout = r.point_layout;
  // A volume's exact field is what a separable EDT computes fastest, over the whole grid or, with a limit, over the
  // bricks within it (docs/benchmarks.md, edt_peer_bench); a stencil, a second ring or paper mode asks for the
  // propagation itself, and a volume's closest features come from the propagation's sites. Point seeds on few lattice
  // planes take the separable point EDT over the whole grid; with a limit the band's work follows the limit instead.
  const bool propagation_asked = p.mode != PropagationMode::kExact || r.stencil || r.second_ring;
  const bool separable_applies =
      !propagation_asked && ((r.seeds == SeedKind::kVolume && !r.closest_features) ||
                             (r.seeds == SeedKind::kPoints && std::isinf(p.limit_world)));
  if ((r.labels || r.nearest_label) && (!separable_applies || r.algorithm == FieldAlgorithm::kBand))
    return Status::InvalidArgument(fmt::format(
        "{}: only the separable EDT computes it (exact mode, the default stencil, no second ring, not the band)",
        r.labels ? "labels" : "nearest label"));
  if (r.algorithm) {
    if (*r.algorithm == FieldAlgorithm::kSeparable && !separable_applies)
      return Status::InvalidArgument(
          "algorithm: separable applies to seed volumes without closest features and to point seeds without a "
          "limit, in exact mode with the default stencil and no second ring");
    p.algorithm = *r.algorithm;
  } else if (separable_applies && (r.seeds == SeedKind::kVolume ||
                                   (r.point_layout && separablePointsPay(grid.dims(), *r.point_layout)))) {
    p.algorithm = FieldAlgorithm::kSeparable;
  }
  *out = std::move(p);
  return Status::Ok();
}

}  // namespace distband
