#include "bench/planned_field.h"

#include <chrono>
#include <cstdio>
#include <cstring>

#include <fmt/format.h>

namespace distband::bench {
namespace {

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

bool sameBits(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

std::string valueText(float v) { return std::isnan(v) ? std::string("none") : fmt::format("{:.9g}", v); }

}  // namespace

Status planMeshField(const FieldRequest& request, const TriangleMesh& mesh, const MeshReport& report,
                     const MeshGridOptions& grid_options, PlannedField* out) {
  PlannedField p;
  if (request.seeds != SeedKind::kMesh) return Status::InvalidArgument("planMeshField: the request's seeds are not a mesh");
  if (Status s = gridForMesh(mesh, grid_options, request.limit(), &p.grid, &p.padding); !s.ok()) return s;
  if (Status s = planField(request, p.grid, &report, &p.plan); !s.ok()) return s;
  *out = std::move(p);
  return Status::Ok();
}

Status planGridField(const FieldRequest& request, const Grid& grid, PlannedField* out) {
  PlannedField p;
  if (request.seeds == SeedKind::kMesh) return Status::InvalidArgument("planGridField: meshes take planMeshField");
  p.grid = grid;
  if (Status s = p.grid.validate(); !s.ok()) return s;
  if (Status s = planField(request, p.grid, nullptr, &p.plan); !s.ok()) return s;
  *out = std::move(p);
  return Status::Ok();
}

Status buildPlannedInputs(const PlannedField& planned, const SeedSource& source, const Interrupter* interrupter,
                          FieldInputs* out) {
  return buildFieldInputs(planned.plan, planned.grid, nullptr, source, interrupter, out);
}

FieldRunResult computePlanned(const PlannedField& planned, FieldInputs inputs, const RunSettings& settings,
                              const SegmentCallback& on_segment) {
  FieldRunOptions run = planned.plan.runOptions();
  run.threads = settings.threads;
  run.interrupter = settings.interrupter;
  run.max_chunk_bricks = settings.max_chunk_bricks;
  return computeField(planned.plan, planned.grid, std::move(inputs), run, on_segment);
}

PlannedRun runPlannedField(const PlannedField& planned, const SeedSource& source, const RunSettings& settings,
                           const SegmentCallback& on_segment) {
  PlannedRun r;
  const auto t0 = std::chrono::steady_clock::now();
  FieldInputs inputs;
  r.status = buildPlannedInputs(planned, source, settings.interrupter, &inputs);
  r.inputs_seconds = secondsSince(t0);
  if (r.status.ok()) r.result = computePlanned(planned, std::move(inputs), settings, on_segment);
  r.total_seconds = secondsSince(t0);
  return r;
}

double meshErrorBoundVoxels(const FieldPlan& plan) {
  if (plan.sites == SiteKind::kTriangle) return plan.stencil == StencilKind::kCubic26 ? 0.05 : 0.15;
  return 0.2;
}

std::string gridText(const Grid& grid) {
  const Coord d = grid.dims();
  const Vec3d o = grid.origin();
  return fmt::format("{}x{}x{} voxels of {:.9g}, origin ({:.9g}, {:.9g}, {:.9g})", d.x, d.y, d.z, grid.voxelSize(), o.x,
                     o.y, o.z);
}

DeliveredField::DeliveredField(const Grid& grid)
    : grid_(grid),
      values_(size_t(grid.voxelCount()), std::numeric_limits<float>::quiet_NaN()),
      times_(size_t(grid.voxelCount()), 0) {}

void DeliveredField::add(const Brick& b) {
  for (int i = 0; i < kBrickVoxels; ++i) {
    if (!b.mask.test(i)) continue;
    const Coord c = b.origin + brickLocal(i);
    if (!grid_.contains(c)) {
      if (outside_++ == 0) first_outside_ = c;
      continue;
    }
    const size_t k = size_t(grid_.denseIndex(c));
    if (times_[k] == 0) {
      ++voxels_;
    } else if (repeats_++ == 0) {
      first_repeat_ = c;
    }
    if (times_[k] < 255) ++times_[k];
    values_[k] = b.values[i];
  }
}

void DeliveredField::add(const SegmentBricks& s) {
  for (const Brick& b : s.bricks) add(b);
}

std::string FieldDiff::describe() const {
  if (!grid_mismatch.empty()) return grid_mismatch;
  std::string text;
  if (identical == union_voxels && repeats == 0 && outside == 0) {
    text = fmt::format("identical ({} voxels)", union_voxels);
  } else {
    text = fmt::format("{} of {} voxels not identical ({} beyond the tolerance, max difference {:.4g} voxel, {} sign "
                       "flips), {} missing, {} extra",
                       union_voxels - identical, union_voxels, beyond_tolerance, max_diff_voxels, sign_flips, missing,
                       extra);
    if (repeats) text += fmt::format(", {} delivered more than once", repeats);
    if (outside) text += fmt::format(", {} delivered outside the grid", outside);
  }
  if (first.x >= 0)
    text += fmt::format("; first at voxel ({}, {}, {}): expected {}, got {}", first.x, first.y, first.z,
                        valueText(first_expected), valueText(first_got));
  return text;
}

FieldDiff compareFields(const DeliveredField& expected, const DeliveredField& got, const FieldTolerance& tol) {
  FieldDiff d;
  const Grid &a = expected.grid(), &b = got.grid();
  if (!(a.dims() == b.dims()) || !(a.origin().x == b.origin().x && a.origin().y == b.origin().y &&
                                    a.origin().z == b.origin().z) ||
      a.voxelSize() != b.voxelSize()) {
    d.ok = false;
    d.grid_mismatch = fmt::format("grids differ: expected {}, got {}", gridText(a), gridText(b));
    return d;
  }
  d.repeats = got.repeats();
  d.outside = got.outside();
  const double h = a.voxelSize();
  const Coord dims = a.dims();
  Coord first_breaking{-1, -1, -1}, first_other{-1, -1, -1};
  float fb_e = NAN, fb_g = NAN, fo_e = NAN, fo_g = NAN;
  int64_t i = 0;
  for (int z = 0; z < dims.z; ++z)
    for (int y = 0; y < dims.y; ++y)
      for (int x = 0; x < dims.x; ++x, ++i) {
        const bool in_a = expected.delivered(i), in_b = got.delivered(i);
        if (!in_a && !in_b) continue;
        ++d.union_voxels;
        const float va = expected.value(i), vb = got.value(i);
        bool breaking = false;
        if (in_a && in_b) {
          if (sameBits(va, vb)) {
            ++d.identical;
            continue;
          }
          const double diff = std::abs(double(va) - double(vb)) / h;
          d.max_diff_voxels = std::max(d.max_diff_voxels, diff);
          const bool flip = tol.same_sign && (va < 0) != (vb < 0) && std::min(std::abs(va), std::abs(vb)) > 1e-6 * h;
          d.sign_flips += flip;
          breaking = flip || !(diff <= tol.max_diff_voxels);
          d.beyond_tolerance += breaking;
        } else {
          d.missing += in_a;
          d.extra += in_b;
          breaking = tol.max_diff_voxels == 0;  // a tolerant comparison counts them against the identical fraction
        }
        if (breaking && first_breaking.x < 0) {
          first_breaking = {x, y, z};
          fb_e = va;
          fb_g = vb;
        }
        if (first_other.x < 0) {
          first_other = {x, y, z};
          fo_e = va;
          fo_g = vb;
        }
      }
  const bool fraction_ok =
      d.union_voxels == 0 || double(d.identical) >= tol.min_identical_fraction * double(d.union_voxels);
  d.ok = d.beyond_tolerance == 0 && fraction_ok && d.repeats == 0 && d.outside == 0 &&
         (tol.max_diff_voxels > 0 || d.identical == d.union_voxels);
  if (first_breaking.x >= 0) {
    d.first = first_breaking;
    d.first_expected = fb_e;
    d.first_got = fb_g;
  } else if (!d.ok && first_other.x >= 0) {
    d.first = first_other;
    d.first_expected = fo_e;
    d.first_got = fo_g;
  }
  if (!d.ok && d.first.x < 0 && d.repeats) d.first = got.firstRepeat();
  return d;
}

void Verdict::fail(std::string_view case_name, const Grid& grid, std::string_view what) {
  fail(case_name, fmt::format("[{}] {}", gridText(grid), what));
}

void Verdict::fail(std::string_view case_name, std::string_view what) {
  const std::string line = fmt::format("FAIL {}: {}", case_name, what);
  std::lock_guard lock(mu_);
  failures_.push_back(line);
  std::fprintf(stderr, "%s: %s\n", bench_.c_str(), line.c_str());
  std::fflush(stderr);
}

void Verdict::check(std::string_view case_name, const FieldDiff& diff, const Grid& grid) {
  if (!diff.ok) fail(case_name, grid, diff.describe());
}

bool Verdict::ok() const {
  std::lock_guard lock(mu_);
  return failures_.empty();
}

int Verdict::failures() const {
  std::lock_guard lock(mu_);
  return int(failures_.size());
}

int Verdict::finish() const {
  std::lock_guard lock(mu_);
  if (failures_.empty()) {
    std::fprintf(stderr, "%s: PASS (every result checked against its reference)\n", bench_.c_str());
    return 0;
  }
  std::fprintf(stderr, "%s: %zu failure%s; first: %s\n", bench_.c_str(), failures_.size(),
               failures_.size() == 1 ? "" : "s", failures_.front().c_str());
  return kExitWrong;
}

}  // namespace distband::bench
