#include "core/points/point_plan.h"

#include <cmath>

#include <fmt/format.h>

namespace distband {

std::string_view PointPlan::signName() const {
  if (seeds == SeedKind::kMesh) return signMethodName(mesh_sign);
  return seeds == SeedKind::kVolume && inside_negative ? kMaskInsideSign : signMethodName(SignMethod::kUnsigned);
}

SignMethod PointPlan::farSign() const {
  return seeds == SeedKind::kMesh && mesh_sign == SignMethod::kPseudonormal && std::isfinite(limit_world)
             ? SignMethod::kWinding
             : SignMethod::kUnsigned;
}

Status planPoints(const FieldRequest& r, const MeshReport* mesh_report, const Grid* lattice, PointPlan* out) {
  if (r.mode || r.stencil || r.algorithm || r.second_ring || r.segment_length_world != 0 || r.closest_features)
    return Status::InvalidArgument(
        "a point query has no grid: mode, stencil, algorithm, second ring, segments and closest features (per voxel) "
        "do not apply");
  PointPlan p;
  p.seeds = r.seeds;
  SignPlan sign;
  if (Status s = planSign(r, mesh_report, &sign); !s.ok()) return s;
  p.mesh_sign = sign.mesh_sign;
  p.inside_negative = sign.inside_negative;
  p.sign_reason = std::move(sign.reason);
  if (r.limit_voxels > 0) {
    if (r.seeds != SeedKind::kVolume || !lattice)
      return Status::InvalidArgument("limit_voxels: a limit in voxels needs a volume's lattice; give it in world units");
    p.limit_world = r.limit_voxels * lattice->voxelSize();
  } else {
    p.limit_world = r.limit_world;
  }
  if (!(p.limit_world > 0)) return Status::InvalidArgument(fmt::format("limit must be > 0 (got {})", p.limit_world));
  *out = std::move(p);
  return Status::Ok();
}

namespace {

Status buildSign(const TriangleMesh& mesh, SignMethod method, const Interrupter* interrupter,
                 std::shared_ptr<const MeshSign>* out) {
  std::unique_ptr<MeshSign> sign;
  if (Status s = MeshSign::build(std::make_shared<const std::vector<Vec3d>>(mesh.vertices),
                                 std::make_shared<const std::vector<std::array<uint32_t, 3>>>(mesh.triangles), method,
                                 interrupter, &sign);
      !s.ok())
    return s;
  *out = std::move(sign);
  return Status::Ok();
}

}  // namespace

Status completePointSearch(const PointPlan& plan, const PointSeedSource& source, const Interrupter* interrupter,
                           PointSearch* search) {
  search->seeds = plan.seeds;
  switch (plan.seeds) {
    case SeedKind::kMesh: {
      if (!source.mesh) return Status::InvalidArgument("a mesh point search needs the mesh");
      if (!search->mesh) {
        auto bvh = std::make_shared<TriangleBvh>();
        if (Status s = TriangleBvh::build(*source.mesh, interrupter, bvh.get()); !s.ok()) return s;
        search->mesh = std::move(bvh);
      }
      if (plan.mesh_sign == SignMethod::kUnsigned) {
        search->sign.reset();
      } else if (!search->sign || search->sign->method() != plan.mesh_sign) {
        if (Status s = buildSign(*source.mesh, plan.mesh_sign, interrupter, &search->sign); !s.ok()) return s;
      }
      const SignMethod far = plan.farSign();
      if (far == SignMethod::kUnsigned) {
        search->far_sign.reset();
      } else if (!search->far_sign || search->far_sign->method() != far) {
        if (Status s = buildSign(*source.mesh, far, interrupter, &search->far_sign); !s.ok()) return s;
      }
      return Status::Ok();
    }
    case SeedKind::kPoints: {
      if (!source.points) return Status::InvalidArgument("a point-seed search needs the points");
      if (!search->points) {
        auto set = std::make_shared<PointSet>();
        if (Status s = PointSet::build(*source.points, {}, interrupter, set.get()); !s.ok()) return s;
        search->points = std::move(set);
      }
      return Status::Ok();
    }
    case SeedKind::kVolume: {
      if (!search->volume || search->volume->insideNegative() != plan.inside_negative) {
        auto volume = std::make_shared<VolumeSearch>();
        if (Status s = VolumeSearch::build(source.mask, source.lattice, plan.inside_negative, interrupter, volume.get());
            !s.ok())
          return s;
        search->volume = std::move(volume);
      }
      return Status::Ok();
    }
  }
  return Status::InvalidArgument("unknown seeds");
}

uint64_t pointSearchBytes(const PointPlan& plan, const PointSeedCounts& c, const PointSearch& have) {
  switch (plan.seeds) {
    case SeedKind::kMesh: {
      uint64_t bytes = have.mesh ? 0 : TriangleBvh::estimateBytes(c.mesh_triangles);
      if (plan.mesh_sign != SignMethod::kUnsigned && !(have.sign && have.sign->method() == plan.mesh_sign))
        bytes += MeshSign::estimateBytes(plan.mesh_sign, c.mesh_vertices, c.mesh_triangles);
      const SignMethod far = plan.farSign();
      if (far != SignMethod::kUnsigned && !(have.far_sign && have.far_sign->method() == far))
        bytes += MeshSign::estimateBytes(far, c.mesh_vertices, c.mesh_triangles);
      return bytes;
    }
    case SeedKind::kPoints: return have.points ? 0 : PointSet::estimateBytes(c.points);
    case SeedKind::kVolume:
      return have.volume && have.volume->insideNegative() == plan.inside_negative
                 ? 0
                 : VolumeSearch::estimateBytes(c.volume_boundary_voxels);
  }
  return 0;
}

}  // namespace distband
