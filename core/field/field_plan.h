// FieldPlan: the one place the defaults of a distance-field request are decided, for every caller — the server's
// request validation, `distband compute` and the benches — so a default changes in one line.
// Contract: planField() turns a FieldRequest (any choice may be left unset) into a FieldPlan where every choice is
// made: the algorithm (the request's when it names one; else, in exact mode with no stencil or second ring asked for,
// the separable EDT for a seed volume without closest features — the only one for label volumes and nearest labels —
// and for point seeds without a limit that lie on few lattice planes (separablePointsPay); the band otherwise),
// propagation mode (exact), site kind (triangles for meshes in exact mode, points otherwise), stencil
// (defaultStencil of the site kind), sign (meshes: kDefaultMeshSign, auto, resolved on the mesh's edges with the
// reason; points unsigned; volumes unsigned unless inside_negative), and the limit in world units. The grid comes
// first (core/mesh/mesh_grid.h decides its padding from the same limit): a limit given in voxels needs its voxel
// size. The plan then hands each stage its options, all from the same fields (the limit is stored once, in world
// units): the run's (runOptions), the band's (bandOptions), the mesh seeds' (meshSeedOptions); what the chosen
// algorithm consumes is built from it by core/field/compute_field.h, and its memory estimated by
// core/field/field_memory.h. algorithmDescription() is the one text that tells users what each algorithm does;
// requestSign() reads a sign by the name users give it, for the seeds at hand.
// planField() returns OK or kInvalidArgument naming the choice that does not fit the seeds. Pure; thread-safe.
#pragma once

#include <limits>
#include <optional>
#include <string>
#include <string_view>

#include "core/band/band_engine.h"
#include "core/grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/mesh_seeds.h"
#include "core/seeds/volume_seeds.h"
#include "core/separable/point_edt.h"
#include "core/status.h"
#include "core/stencil.h"

namespace distband {

enum class SeedKind { kPoints, kVolume, kMesh };

/// How the field is computed: the active band's propagation (any seeds), or, in exact mode, a separable exact EDT —
/// for a seed volume (core/separable/volume_edt.h: over the whole grid, or over the bricks within the limit) and for point
/// seeds on few planes without a limit (core/separable/point_edt.h) — several times faster there and exact.
enum class FieldAlgorithm { kBand, kSeparable };
std::string_view algorithmName(FieldAlgorithm algorithm);  ///< "band", "separable"
std::optional<FieldAlgorithm> parseAlgorithm(std::string_view name);

/// What the algorithm does for these seeds, for people (the CLI's header line, the docs, the protocol's comment):
/// e.g. "band: the adaptive iteration on an evolving active band (SMI 2009); segments stream nearest first as the
/// band passes them". `limited`: the query has a finite limit.
std::string algorithmDescription(FieldAlgorithm algorithm, SeedKind seeds, bool limited);

/// The sign of a volume whose mask voxels get -distance (FieldRequest::inside_negative); meshes' signs are
/// signMethodName's.
inline constexpr std::string_view kMaskInsideSign = "mask-inside";

struct FieldRequest {
  SeedKind seeds = SeedKind::kPoints;
  std::optional<PropagationMode> mode;   ///< unset: kExact
  std::optional<StencilKind> stencil;    ///< unset: defaultStencil(the plan's site kind, the grid)
  std::optional<SignMethod> mesh_sign;   ///< meshes only; unset: kDefaultMeshSign
  bool inside_negative = false;          ///< volumes only: mask voxels get -distance to the outside
  /// Volumes only: the multi-label EDT (core/seeds/volume_seeds.h: each voxel of label L != 0 measured to the nearest
  /// voxel of another label) instead of the seed field; unsigned, the separable EDT's.
  bool labels = false;
  bool black_border = false;   ///< with labels: the grid's outside is label 0
  /// Volumes, the seed field: each delivered voxel's closest feature is the label of its nearest seed (the separable
  /// EDT's); exclusive with closest_features.
  bool nearest_label = false;
  /// The limit: in voxels of the grid when limit_voxels > 0, else in world units (+infinity: none).
  double limit_world = std::numeric_limits<double>::infinity();
  double limit_voxels = 0;
  /// The limit as the grid's padding reads it (gridForMesh): the same request fields.
  DistanceLimit limit() const { return {limit_world, limit_voxels}; }
  double segment_length_world = 0;  ///< 0: one segment
  bool closest_features = false;
  std::optional<bool> second_ring;  ///< unset: the engine's default for the site kind
  /// Point seeds: how they lie on the lattice (pointLayout of their world or index coordinates). Unset: the band.
  std::optional<PointLayout> point_layout;
  /// Unset: the planner's choice. kSeparable applies to seed volumes without closest features and to point seeds
  /// without a limit, in exact mode with no stencil or second ring asked for (kInvalidArgument otherwise).
  std::optional<FieldAlgorithm> algorithm;
};

struct FieldPlan {
  SeedKind seeds = SeedKind::kPoints;
  FieldAlgorithm algorithm = FieldAlgorithm::kBand;
  PropagationMode mode = PropagationMode::kExact;
  SiteKind sites = SiteKind::kPoint;
  StencilKind stencil = StencilKind::kCubic26;
  SignMethod mesh_sign = SignMethod::kUnsigned;  ///< meshes: the method in force (never kAuto)
  bool inside_negative = false;                  ///< volumes
  bool labels = false, black_border = false;     ///< volumes: FieldRequest's
  bool nearest_label = false;                    ///< volumes: FieldRequest's
  std::string sign_reason;                       ///< why the sign is what it is ("auto: the mesh is closed", ...)
  double limit_world = std::numeric_limits<double>::infinity();
  double segment_length_world = 0;
  bool closest_features = false;
  std::optional<bool> second_ring;
  std::optional<PointLayout> point_layout;  ///< the request's (point seeds)

  bool signedField() const {
    return seeds == SeedKind::kMesh ? mesh_sign != SignMethod::kUnsigned : seeds == SeedKind::kVolume && inside_negative;
  }
  /// "pseudonormal", "winding", "parity", "mask-inside" or "unsigned".
  std::string_view signName() const;
  /// What a voxel's closest-feature id names for these seeds: "triangle", "point" or "voxel" (Seeds::FeatureKind),
  /// or "label" (nearest_label).
  std::string_view closestFeatureName() const;
  /// Whether delivered voxels carry a closest feature (closest_features or nearest_label).
  bool hasClosestFeatures() const { return closest_features || nearest_label; }
  /// What a volume run measures.
  VolumeMeasure volumeMeasure() const { return {labels, inside_negative, black_border ? kAllFaces : uint8_t(0)}; }
  double limitVoxels(const Grid& grid) const { return limit_world / grid.voxelSize(); }
  /// The run's options this plan fixes (limit, segments, closest features); threads, interrupter and chunking
  /// belong to the caller's run and are left at their defaults.
  FieldRunOptions runOptions() const;
  /// The band engine's options for a run of this plan: `run` plus the plan's mode, stencil and second ring.
  BandOptions bandOptions(const FieldRunOptions& run) const;
  std::string algorithmDescription() const;
  /// Mesh seeds on `grid` (the grid the engine runs on: for a tile, its window).
  MeshSeedOptions meshSeedOptions(const Grid& grid) const;
};

/// Sets the sign `request` asks for from its name: "auto" and "unsigned" (any seeds: the seeds' default, or no sign),
/// a mesh sign method (signMethodName: pseudonormal, winding, parity) or kMaskInsideSign (volumes). Returns OK or
/// kInvalidArgument saying which names the seeds take.
Status requestSign(std::string_view name, FieldRequest* request);

/// The sign a request's seeds get — planField's rule, and the point queries' (core/points/point_plan.h): meshes
/// the requested method or kDefaultMeshSign, resolved on the mesh's edges (resolveSignMethod); points unsigned;
/// volumes unsigned unless inside_negative. kInvalidArgument for a sign the seeds do not take.
struct SignPlan {
  SignMethod mesh_sign = SignMethod::kUnsigned;  ///< meshes: the method in force (never kAuto)
  bool inside_negative = false;                  ///< volumes
  std::string reason;                            ///< why ("auto: the mesh is closed", "requested", ...)
};
Status planSign(const FieldRequest& request, const MeshReport* mesh_report, SignPlan* out);

/// `mesh_report`: the loaded mesh's report (needed for meshes: the automatic sign reads its edges), else null.
Status planField(const FieldRequest& request, const Grid& grid, const MeshReport* mesh_report, FieldPlan* plan);

}  // namespace distband
