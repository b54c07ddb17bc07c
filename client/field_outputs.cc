#include "client/field_outputs.h"

#include <cmath>
#include <filesystem>
#include <limits>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "core/io/field_metadata.h"
#include "core/io/isosurface.h"
#include "core/io/npy.h"
#include "core/io/vdb_writer.h"

namespace distband {
namespace {

bool endsWith(const std::string& s, const char* suffix) {
  const std::string t(suffix);
  return s.size() >= t.size() && s.compare(s.size() - t.size(), t.size(), t) == 0;
}

std::string replaceExtension(const std::string& path, const char* extension) {
  return std::filesystem::path(path).replace_extension(extension).string();
}

/// Voxel indices and labels (uint32) take int64 ids; triangle and point ids int32.
bool wideClosest(const std::string& feature) { return feature == "voxel" || feature == "label"; }

}  // namespace

void addOutputFlags(CLI::App* cmd, OutputFlags* f) {
  cmd->add_option("--out", f->out,
                  "Output: FIELD.vdb (OpenVDB level set), FIELD.npy (dense float32, shape (Z, Y, X)) or FIELD.nii.gz "
                  "(NIfTI float32 with the input volume's affine)");
  cmd->add_option("--npy", f->npy, "Also write a dense float32 .npy (small grids)");
  cmd->add_option("--meta", f->meta, "Also write a JSON description of the field (grid, units, limit, sign, completeness)");
  cmd->add_option("--closest", f->closest,
                  "IDS.npy, or --out's FIELD.vdb (a grid \"closest\" beside the distances): each voxel's closest "
                  "feature (mesh triangle or point index: int32; seed voxel's linear index: int64; -1 where not "
                  "delivered)");
  cmd->add_option("--nearest-label", f->nearest_label,
                  "Volumes: LABELS.npy (int64, shape (Z, Y, X)), or --out's FIELD.vdb: each voxel's nearest seed "
                  "voxel's label (a Voronoi map; -1 where not delivered); excludes --closest and --labels");
  cmd->add_option("--slice-png", f->slice_png,
                  "AXIS:INDEX PNG (e.g. z:mid) - a colour-mapped slice with the zero contour and a colour bar")
      ->expected(2);
  cmd->add_option("--isosurface", f->isosurface, "D OBJ - the surface at distance D as a Wavefront OBJ")->expected(2);
}

std::string clippedBandWarning(int padding_voxels, double limit_voxels, bool padding_given) {
  return fmt::format("warning: the band is clipped at the grid's faces: padding {} voxels < limit {:g} voxels{}",
                     padding_voxels, limit_voxels,
                     padding_given ? " (--padding)" : "; give a larger --resolution or --padding");
}

std::string checkOutputFlags(const OutputFlags& f, double limit_world, OutputPlan* plan) {
  if (f.out.empty() && f.npy.empty() && f.slice_png.empty() && f.isosurface.empty())
    return "nothing to write: give --out (or --npy, --slice-png, --isosurface)";
  OutputPlan p;
  p.flags = f;
  std::vector<std::pair<std::string, std::string>> files;  // (flag, path): no file may be named twice
  if (!f.out.empty()) {
    if (std::string e = checkOutputPath("--out", f.out, {".vdb", ".npy", ".nii.gz"}); !e.empty()) return e;
    files.emplace_back("--out", f.out);
  }
  if (!f.npy.empty()) {
    if (std::string e = checkOutputPath("--npy", f.npy, {".npy"}); !e.empty()) return e;
    files.emplace_back("--npy", f.npy);
  }
  if (!f.meta.empty()) {
    if (std::string e = checkOutputPath("--meta", f.meta, {".json"}); !e.empty()) return e;
    files.emplace_back("--meta", f.meta);
  }
  if (!f.closest.empty()) {
    if (std::string e = checkOutputPath("--closest", f.closest, {".npy", ".vdb"}); !e.empty()) return e;
    if (!endsWith(f.closest, ".vdb")) files.emplace_back("--closest", f.closest);
    else if (f.closest != f.out)  // a grid beside the distances, in the same file
      return fmt::format("--closest {}: a .vdb closest grid is stored in --out's .vdb: give the same path, or a .npy",
                         f.closest);
  }
  if (!f.nearest_label.empty()) {
    if (!f.closest.empty()) return "--nearest-label and --closest exclude each other (one closest feature per voxel)";
    if (std::string e = checkOutputPath("--nearest-label", f.nearest_label, {".npy", ".vdb"}); !e.empty()) return e;
    if (!endsWith(f.nearest_label, ".vdb"))
      files.emplace_back("--nearest-label", f.nearest_label);
    else if (f.nearest_label != f.out)
      return fmt::format(
          "--nearest-label {}: a .vdb label grid is stored in --out's .vdb: give the same path, or a .npy",
          f.nearest_label);
    p.flags.closest = f.nearest_label;  // written as the closest features are
    p.nearest_label = true;
  }
  const bool limit_in_voxels = std::isnan(limit_world);
  const bool finite_limit = limit_in_voxels || std::isfinite(limit_world);
  if (!f.slice_png.empty()) {
    if (f.slice_png.size() != 2) return "--slice-png takes AXIS:INDEX and a PNG path";
    if (Status s = parseSliceSpec(f.slice_png[0], &p.slice); !s.ok()) return "--slice-png: " + s.message();
    if (std::string e = checkOutputPath("--slice-png", f.slice_png[1], {".png"}); !e.empty()) return e;
    if (!finite_limit) return "--slice-png needs a finite --limit or --limit-voxels (the colour scale's range)";
    files.emplace_back("--slice-png", f.slice_png[1]);
  }
  if (!f.isosurface.empty()) {
    if (f.isosurface.size() != 2) return "--isosurface takes a distance D and an OBJ path";
    try {
      size_t used = 0;
      p.isosurface = std::stod(f.isosurface[0], &used);
      if (used != f.isosurface[0].size() || !std::isfinite(p.isosurface)) throw std::invalid_argument("x");
    } catch (const std::exception&) {
      return fmt::format("--isosurface: '{}' is not a finite number", f.isosurface[0]);
    }
    if (!finite_limit)
      return "--isosurface needs a finite --limit or --limit-voxels (beyond the limit the field holds only the "
             "background)";
    if (!limit_in_voxels && !(std::abs(p.isosurface) < limit_world))  // in voxels: checked by open()
      return fmt::format("--isosurface {:g}: the surface must lie inside --limit {:g} (beyond it the field holds "
                         "only the background)",
                         p.isosurface, limit_world);
    if (std::string e = checkOutputPath("--isosurface", f.isosurface[1], {".obj"}); !e.empty()) return e;
    files.emplace_back("--isosurface", f.isosurface[1]);
  }
  for (size_t i = 0; i < files.size(); ++i)
    for (size_t j = 0; j < i; ++j)
      if (std::filesystem::weakly_canonical(files[i].second) == std::filesystem::weakly_canonical(files[j].second))
        return fmt::format("{} {}: the same file as {}", files[i].first, files[i].second, files[j].first);
  *plan = std::move(p);
  return {};
}

FieldDescription describeField(const FieldPlan& plan, const Grid& grid, const GridPadding& padding, std::string title,
                               LabelVolume inside) {
  FieldDescription d;
  d.grid = grid;
  d.limit_world = plan.limit_world;
  d.signed_distance = plan.signedField();
  d.sign_from_band = d.signed_distance && !bool(inside);
  d.inside = std::move(inside);
  d.stencil = std::string(stencilName(plan.stencil));
  d.mode = std::string(modeName(plan.mode));
  if (d.signed_distance) d.sign = std::string(plan.signName());
  d.sign_reason = plan.sign_reason;
  d.padding_voxels = padding.voxels;
  d.band_clipped = padding.band_clipped;
  d.segment_length_world = plan.segment_length_world;
  if (plan.hasClosestFeatures()) d.closest_feature = std::string(plan.closestFeatureName());
  d.title = std::move(title);
  return d;
}

int finishStoppedRun(FieldOutputs& outputs, const RunOutcome& run, RunStop stop, std::string_view command,
                     const CliContext& ctx) {
  std::vector<std::string> wrote;
  const std::string error = outputs.finish(run, &wrote);
  for (const std::string& line : wrote) ctx.out << line << "\n";
  ctx.err << "distband " << command << ": "
          << (stop == RunStop::kDeadline ? "the deadline (--deadline) passed" : "interrupted") << "; "
          << (error.empty() ? outputs.keptSummary() : error) << "\n";
  return stop == RunStop::kDeadline ? kExitFailure : kExitInterrupted;
}

FieldOutputs::FieldOutputs(OutputPlan plan) : plan_(std::move(plan)) {}
FieldOutputs::~FieldOutputs() = default;

std::string FieldOutputs::open(const FieldDescription& field) {
  field_ = field;
  const OutputFlags& f = plan_.flags;
  if (!f.slice_png.empty())
    if (Status s = resolveSlice(field.grid, &plan_.slice); !s.ok()) return "--slice-png: " + s.message();
  if (!f.isosurface.empty() && !(std::abs(plan_.isosurface) < field.limit_world))
    return fmt::format("--isosurface {:g}: the surface must lie inside the limit {:g} (beyond it the field holds "
                       "only the background)",
                       plan_.isosurface, field.limit_world);
  if (plan_.wants_closest() && field.closest_feature.empty())
    return plan_.nearest_label ? "--nearest-label: the field carries no nearest labels"
                               : "--closest: the field carries no closest-feature ids";
  FieldLayout layout;
  layout.grid = field.grid;
  layout.background =
      std::isfinite(field.limit_world) ? float(field.limit_world) : std::numeric_limits<float>::infinity();
  layout.signed_distance = field.signed_distance;
  layout.inside = field.inside;
  layout.sign_from_band = field.sign_from_band;
  layout.affine = field.affine;
  if (endsWith(f.out, ".nii.gz"))
    if (std::string e = openBrickSink(f.out, layout, &nifti_); !e.empty()) return e;
  const std::string npy_path = endsWith(f.out, ".npy") ? f.out : f.npy;
  if (!npy_path.empty())
    if (std::string e = openBrickSink(npy_path, layout, &npy_); !e.empty()) return e;
  if (endsWith(f.out, ".vdb") || !f.slice_png.empty() || !f.isosurface.empty())
    vdb_ = std::make_unique<VdbFieldBuilder>(field.grid, layout.background);
  if (plan_.wants_closest()) {
    if (endsWith(f.closest, ".vdb"))
      vdb_->addClosestGrid(wideClosest(field.closest_feature));
    else closest_.assign(size_t(field.grid.voxelCount()), -1);
  }
  return {};
}

void FieldOutputs::add(SegmentBricks&& batch) { open_segment_.push_back(std::move(batch)); }

void FieldOutputs::commitSegment(double upper_world) {
  for (const SegmentBricks& batch : open_segment_) build(batch);
  open_segment_.clear();
  ++segments_;
  complete_up_to_ = upper_world;
}

void FieldOutputs::build(const SegmentBricks& batch) {
  if (npy_) npy_->add(batch);
  if (nifti_) nifti_->add(batch);
  if (vdb_) vdb_->add(batch);
  if (closest_.empty()) return;
  const Grid& grid = field_.grid;
  for (const Brick& b : batch.bricks) {
    if (b.closest.size() != size_t(kBrickVoxels)) continue;
    for (int i = 0; i < kBrickVoxels; ++i) {
      const Coord c = b.origin + brickLocal(i);
      if (b.mask.test(i) && grid.contains(c)) closest_[size_t(grid.denseIndex(c))] = b.closest[size_t(i)];
    }
  }
}

Status FieldOutputs::writeClosest() {
  const std::string& path = plan_.flags.closest;
  if (wideClosest(field_.closest_feature)) return writeNpyInt64(path, closest_, field_.grid.dims());
  std::vector<int32_t> ids(closest_.begin(), closest_.end());  // triangle and point ids are < 2^27
  return writeNpyInt32(path, ids, field_.grid.dims());
}

std::string FieldOutputs::keptSummary() const {
  return fmt::format("kept the {} complete segment{} (every voxel with |distance| <= {:g}), marked complete=false",
                     segments_, segments_ == 1 ? "" : "s", complete_up_to_);
}

std::string FieldOutputs::finish(const RunOutcome& run, std::vector<std::string>* lines) {
  if (run.complete && !open_segment_.empty()) commitSegment(std::numeric_limits<double>::infinity());
  open_segment_.clear();  // interrupted: the half-delivered segment is dropped
  if (!run.complete && segments_ == 0) return "no segment was complete yet: nothing written";
  const OutputFlags& f = plan_.flags;
  const double up_to = run.complete ? field_.limit_world : complete_up_to_;
  Status first_error;
  auto report = [&](const Status& status, const std::string& line) {
    if (!status.ok()) {
      if (first_error.ok()) first_error = status;
    } else if (lines) {
      lines->push_back(line);
    }
  };
  if (npy_) {
    const Status s = npy_->finish();
    report(s, "wrote " + npy_->description());
  }
  if (nifti_) {
    const Status s = nifti_->finish();
    report(s, "wrote " + nifti_->description());
  }
  if (vdb_) {
    vdb_->setRunState(run.complete, segments_);
    vdb_->finish();
    if (endsWith(f.out, ".vdb"))
      report(vdb_->write(f.out),
             fmt::format("wrote {} (OpenVDB level set \"distance\", {} active voxels{})", f.out, vdb_->activeVoxels(),
                         f.closest == f.out ? fmt::format(", and grid \"closest\" of {} ids", field_.closest_feature)
                                            : std::string()));
    if (!f.slice_png.empty()) {
      const VoxelSampler sample = [&](const Coord& c) { return vdb_->value(c); };
      SlicePngOptions so;
      so.limit_world = field_.limit_world;
      so.sign = field_.signed_distance ? SliceSign::kSigned : SliceSign::kUnsigned;
      so.title_prefix = field_.title;
      report(writeSlicePng(f.slice_png[1], field_.grid, sample, plan_.slice, so),
             fmt::format("wrote {} (slice {})", f.slice_png[1], f.slice_png[0]));
    }
    if (!f.isosurface.empty()) {
      TriangleMeshF mesh;
      IsosurfaceOptions io;
      io.distance_world = plan_.isosurface;
      const Status s = writeIsosurfaceObj(f.isosurface[1], vdb_->distance(), vdb_->grid(), io, &mesh);
      report(s, fmt::format("wrote {} (isosurface at {:g}: {} vertices, {} triangles)", f.isosurface[1],
                            plan_.isosurface, mesh.vertices.size(), mesh.triangles.size()));
    }
  }
  if (!closest_.empty())
    report(writeClosest(),
           fmt::format("wrote {} (closest {} ids, {}, -1 where not delivered)", f.closest, field_.closest_feature,
                       wideClosest(field_.closest_feature) ? "int64" : "int32"));
  const std::string field_file = !f.out.empty() ? f.out : f.npy;
  std::string meta_path = f.meta;
  if (meta_path.empty() && !run.complete && !field_file.empty()) meta_path = replaceExtension(field_file, ".json");
  if (!meta_path.empty()) {
    FieldMetadata meta;
    meta.grid = field_.grid;
    meta.data_file = std::filesystem::path(field_file).filename().string();
    meta.signed_distance = field_.signed_distance;
    meta.limit_world = field_.limit_world;
    meta.background_world = field_.limit_world;  // +infinity without a limit
    meta.stencil = field_.stencil;
    meta.mode = field_.mode;
    meta.sign = field_.sign;
    meta.sign_reason = field_.sign_reason;
    meta.sign_shares = run.sign_shares;
    meta.padding_voxels = field_.padding_voxels;
    meta.band_clipped = field_.band_clipped;
    meta.segment_length_world = field_.segment_length_world;
    meta.voxels_delivered = run.voxels;
    meta.seconds = run.seconds;
    meta.complete = run.complete;
    meta.segments = segments_;
    meta.complete_up_to_world = up_to;
    if (plan_.wants_closest()) {
      meta.closest_file = std::filesystem::path(f.closest).filename().string();
      meta.closest_feature = field_.closest_feature;
    }
    report(writeFieldMetadata(meta_path, meta),
           fmt::format("wrote {} (metadata{})", meta_path, run.complete ? "" : ", complete=false"));
  }
  return first_error.message();  // the commands deal in messages; "" when every file was written
}

}  // namespace distband
