#include "client/field_flags.h"

#include <charconv>
#include <cmath>
#include <limits>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "core/band/band_engine.h"
#include "core/io/point_cloud.h"
#include "core/seeds/mesh_seeds.h"
#include "core/stencil.h"

namespace distband {
namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

std::vector<std::string_view> split(std::string_view s, char sep) {
  std::vector<std::string_view> parts;
  size_t start = 0;
  for (;;) {
    const size_t at = s.find(sep, start);
    parts.push_back(s.substr(start, at == std::string_view::npos ? std::string_view::npos : at - start));
    if (at == std::string_view::npos) return parts;
    start = at + 1;
  }
}

bool parseDouble(std::string_view s, double* out) {
  s = trim(s);
  if (s.empty()) return false;
  if (s.front() == '+') s.remove_prefix(1);
  const auto r = std::from_chars(s.data(), s.data() + s.size(), *out);
  return r.ec == std::errc() && r.ptr == s.data() + s.size() && std::isfinite(*out);
}

/// Core's names of `values`, joined by `sep` ("cubic26 | cubic18 | ...").
template <typename Range, typename NameOf>
std::string joinNames(const Range& values, NameOf name_of, std::string_view sep) {
  std::string text;
  for (const auto& v : values) text += fmt::format("{}{}", text.empty() ? "" : sep, name_of(v));
  return text;
}

// The help of the flags whose names come from core's tables, and the defaults core decides.
std::string stencilHelp() {
  return fmt::format("auto (default: {} for meshes in exact mode, else {}; naming one runs the band) | {}",
                     stencilName(defaultStencil(SiteKind::kTriangle)), stencilName(defaultStencil(SiteKind::kPoint)),
                     joinNames(kStencilKinds, stencilName, " | "));
}

std::string modeHelp() {
  return fmt::format(
      "{} (default: propagation to convergence; meshes: of closest triangles, also spelt {}) | {} (the SMI "
      "2009 lifespan band)",
      modeName(PropagationMode::kExact), meshSiteModeName(MeshSiteMode::kExactFeature),
      modeName(PropagationMode::kPaper));
}

std::string signHelp() {
  std::vector<SignMethod> methods;  // the mesh-only methods: neither the default nor "unsigned"
  for (SignMethod m : kSignMethods)
    if (m != SignMethod::kAuto && m != SignMethod::kUnsigned) methods.push_back(m);
  return fmt::format(
      "{} (default: meshes {} when closed, {} when open or when closed parts overlap; points and volumes "
      "unsigned) | {} (meshes) | "
      "{} | {} (volumes: negative inside the mask)",
      signMethodName(SignMethod::kAuto), signMethodName(SignMethod::kPseudonormal),
      signMethodName(SignMethod::kWinding), joinNames(methods, signMethodName, " | "),
      signMethodName(SignMethod::kUnsigned), kMaskInsideSign);
}

/// Registers an option that sets `target` only when it is given (unset: core's default).
template <typename T>
CLI::Option* addOptional(CLI::App* cmd, const std::string& name, std::optional<T>* target, const std::string& help) {
  return cmd->add_option_function<T>(
      name, [target](const T& value) { *target = value; }, help);
}

std::string parseSeeds(const FieldFlags& f, FieldSpec* s) {
  const int given = int(!f.mesh.empty()) + int(!f.points.empty()) + int(!f.points_file.empty()) +
                    int(!f.volume.empty()) + int(!f.asset.empty());
  if (given != 1)
    return fmt::format(
        "give exactly one seed source: --mesh FILE, --points \"x,y,z;...\", --points-file CLOUD{} --volume FILE{}",
        f.assets == AssetSeeds::kYes ? "," : " or", f.assets == AssetSeeds::kYes ? " or --asset ID" : "");
  if (!f.mesh.empty()) {
    s->seeds = SeedKind::kMesh;
    s->source = f.mesh;
  } else if (!f.volume.empty()) {
    s->seeds = SeedKind::kVolume;
    s->source = f.volume;
  } else if (!f.points.empty()) {
    s->seeds = SeedKind::kPoints;
    if (std::string e = parsePointList(f.points, &s->points); !e.empty()) return e;
  } else if (!f.points_file.empty()) {
    s->seeds = SeedKind::kPoints;
    PointFileFormat format;
    if (!pointFileFormatFromPath(f.points_file, &format))
      return fmt::format("--points-file {}: unknown point file format (expected .npy, .xyz, .txt or .ply)",
                         f.points_file);
    s->points_file = s->source = f.points_file;
  } else {
    // Upload names every asset by its kind (UploadReply.asset_id): the kind decides the grid and the sign.
    if (f.asset.rfind("mesh-", 0) == 0)
      s->seeds = SeedKind::kMesh;
    else if (f.asset.rfind("volume-", 0) == 0)
      s->seeds = SeedKind::kVolume;
    else
      return fmt::format("--asset '{}': not an asset id (`distband upload` prints mesh-... or volume-...)", f.asset);
    s->source = f.asset;
    s->asset = true;
  }
  s->request.seeds = s->seeds;
  return {};
}

std::string parseGrid(const FieldFlags& f, FieldSpec* s) {
  GridChoice& g = s->grid;
  if (f.voxel_size && !(std::isfinite(*f.voxel_size) && *f.voxel_size > 0))
    return fmt::format("--voxel-size must be finite and > 0 (got {})", *f.voxel_size);
  if (f.resolution && *f.resolution < 2)
    return fmt::format("--resolution must be at least 2 voxels (got {})", *f.resolution);
  if (f.resolution && *f.resolution > kMaxGridDim)
    return fmt::format("--resolution must be at most {} voxels (got {})", kMaxGridDim, *f.resolution);
  if (f.padding && (*f.padding < 0 || *f.padding > kMaxPaddingVoxels))
    return fmt::format("--padding must be in [0, {}] voxels (got {})", kMaxPaddingVoxels, *f.padding);
  if (!f.dims.empty()) {
    Coord dims;
    if (std::string e = parseDims(f.dims, &dims); !e.empty()) return e;
    g.dims = dims;
  }
  Vec3d origin{};
  if (!f.origin.empty())
    if (std::string e = parseVec3(f.origin, "--origin", &origin); !e.empty()) return e;
  std::optional<Vec3d> spacing;
  if (!f.spacing.empty()) {
    if (f.voxel_size) return "--spacing and --voxel-size exclude each other (--voxel-size v means --spacing v,v,v)";
    Vec3d v;
    if (std::string e = parseVec3(f.spacing, "--spacing", &v); !e.empty()) return e;
    if (!(v.x > 0 && v.y > 0 && v.z > 0)) return fmt::format("--spacing '{}': every spacing must be > 0", f.spacing);
    spacing = v;
  }
  if (!f.box.empty()) {
    Vec3d lo, hi;
    if (std::string e = parseBox(f.box, &lo, &hi); !e.empty()) return e;
    g.box_min = lo;
    g.box_max = hi;
  }
  g.lattice = g.dims || s->seeds == SeedKind::kVolume;
  if (g.lattice) {
    const std::string_view lattice = g.dims ? "--dims" : "a volume's grid (its mask's shape)";
    if (f.resolution) return fmt::format("--resolution does not apply to {} (give --voxel-size)", lattice);
    if (f.padding) return fmt::format("--padding does not apply to {}", lattice);
    if (g.box_min) return fmt::format("--box does not apply to {}", lattice);
    g.origin = origin;
    if (!f.origin.empty()) g.origin_given = origin;
    g.voxel_size = f.voxel_size.value_or(kDefaultVoxelSize);
    if (f.voxel_size) spacing = Vec3d{*f.voxel_size, *f.voxel_size, *f.voxel_size};
    g.spacing = spacing;
    return {};
  }
  if (spacing)
    return "--spacing applies to --dims or a volume's grid only (around the seeds or --box give --voxel-size or "
           "--resolution)";
  if (!f.origin.empty())
    return "--origin applies to --dims or a volume's grid only (around the seeds or --box, the box places the grid)";
  if (f.voxel_size.has_value() == f.resolution.has_value())
    return fmt::format(
        "the grid around {} needs exactly one of --resolution N and --voxel-size H (or --dims X,Y,Z "
        "with --voxel-size for an explicit grid)",
        g.box_min ? "--box" : "the seeds");
  g.voxel_size = f.voxel_size.value_or(0);
  g.resolution = f.resolution.value_or(0);
  g.padding = f.padding;
  return {};
}

std::string parseField(const FieldFlags& f, FieldSpec* s) {
  FieldRequest& r = s->request;
  if (!f.algorithm.empty() && f.algorithm != "auto") {
    r.algorithm = parseAlgorithm(f.algorithm);
    if (!r.algorithm)
      return fmt::format("--algorithm '{}': expected auto, {} or {}", f.algorithm,
                         algorithmName(FieldAlgorithm::kBand), algorithmName(FieldAlgorithm::kSeparable));
  }
  if (!f.stencil.empty() && f.stencil != "auto") {
    r.stencil = parseStencil(f.stencil);
    if (!r.stencil)
      return fmt::format("--stencil '{}': expected auto, {}", f.stencil, joinNames(kStencilKinds, stencilName, ", "));
  }
  if (!f.mode.empty()) {
    PropagationMode mode;
    MeshSiteMode sites;
    if (parseMode(f.mode, &mode))
      r.mode = mode;
    else if (s->seeds == SeedKind::kMesh && parseMeshSiteMode(f.mode, &sites))
      r.mode = sites == MeshSiteMode::kPaper ? PropagationMode::kPaper : PropagationMode::kExact;
    else
      return fmt::format("--mode '{}': expected {} (meshes: also {})", f.mode,
                         joinNames(kPropagationModes, modeName, " or "), meshSiteModeName(MeshSiteMode::kExactFeature));
  }
  if (!f.sign.empty())
    if (Status st = requestSign(f.sign, &r); !st.ok()) return fmt::format("--sign '{}': {}", f.sign, st.message());
  if (f.limit && f.limit_voxels)
    return "--limit and --limit-voxels exclude each other: give the limit in world units or in voxels";
  if (f.limit) {
    if (std::isnan(*f.limit) || *f.limit <= 0) return fmt::format("--limit must be > 0 (got {})", *f.limit);
    r.limit_world = *f.limit;
  }
  if (f.limit_voxels) {
    if (!(std::isfinite(*f.limit_voxels) && *f.limit_voxels > 0))
      return fmt::format("--limit-voxels must be finite and > 0 (got {})", *f.limit_voxels);
    r.limit_voxels = *f.limit_voxels;
  }
  if (f.segment) {
    if (!(*f.segment >= 0) || std::isinf(*f.segment))
      return fmt::format("--segment must be finite and >= 0 (got {})", *f.segment);
    r.segment_length_world = *f.segment;
  }
  if (f.second_ring) {
    if (s->seeds != SeedKind::kMesh)
      return "--second-ring applies to meshes (point and volume seeds get the correction by default in exact mode)";
    // The correction costs several times the propagation on triangle sites for ~0.01 voxel: meshes opt in.
    r.second_ring = true;
  }
  if (f.labels && s->seeds != SeedKind::kVolume)
    return "--labels applies to volume seeds (--volume, or a volume --asset)";
  if (f.black_border && !f.labels) return "--black-border applies with --labels (the multi-label EDT)";
  r.labels = f.labels;
  r.black_border = f.black_border;
  if (f.deadline) {
    if (!(std::isfinite(*f.deadline) && *f.deadline >= 0))
      return fmt::format("--deadline must be finite and >= 0 seconds (got {})", *f.deadline);
    s->deadline_s = *f.deadline;
  }
  return {};
}

// Each flag is registered by one function, whichever command takes it, so its name, help and type cannot differ.
void addSeedFlags(CLI::App* cmd, FieldFlags* f, AssetSeeds assets) {
  f->assets = assets;
  cmd->add_option("--mesh", f->mesh,
                  "Seed mesh (OBJ, OFF, PLY, STL): the distance to its triangles, signed per --sign");
  cmd->add_option("--points", f->points, "Seed points in world coordinates: \"x,y,z;x,y,z\" (unsigned distances)");
  cmd->add_option("--points-file", f->points_file,
                  "Seed points from a point cloud: .npy (N x 3 float32/float64), .xyz/.txt (x y z a line) or .ply "
                  "(its vertices); the same field as the points given inline");
  cmd->add_option("--volume", f->volume,
                  "Seed or label volume: .npy (bool/uint8/16/32, shape (Z, Y, X)), NIfTI (.nii, .nii.gz) or NRRD "
                  "(.nrrd, .nhdr); nonzero = seed; its shape gives the grid's dims, its header the spacing and origin");
  if (assets == AssetSeeds::kYes)
    cmd->add_option("--asset", f->asset, "A mesh or volume the server holds (the id `distband upload` printed)");
}

void addVoxelSizeFlag(CLI::App* cmd, FieldFlags* f) {
  addOptional(
      cmd, "--voxel-size", &f->voxel_size,
      fmt::format("Voxel size in world units (with --dims or a volume: default {:g}; around the seeds or --box: "
                  "this or --resolution)",
                  kDefaultVoxelSize));
  cmd->add_option("--spacing", f->spacing,
                  "Voxel spacing X,Y,Z in world units with --dims or a volume (anisotropic voxels; default: the volume "
                  "file's header, else the voxel size); overrides the file's");
}

void addOriginFlag(CLI::App* cmd, FieldFlags* f) {
  cmd->add_option("--origin", f->origin,
                  "World position of voxel (0,0,0) with --dims or a volume: x,y,z (default 0,0,0)");
}

void addSignFlag(CLI::App* cmd, FieldFlags* f) { cmd->add_option("--sign", f->sign, signHelp()); }

void addLimitFlag(CLI::App* cmd, FieldFlags* f) {
  addOptional(cmd, "--limit", &f->limit,
              "Distance limit in world units (default: none); voxels beyond it hold +limit (-limit inside)");
}

void addDeadlineFlag(CLI::App* cmd, FieldFlags* f) {
  addOptional(cmd, "--deadline", &f->deadline,
              "Give up this many seconds after the start (default: never): the complete segments are kept as on "
              "Ctrl-C, exit 1");
}

}  // namespace

void addFieldFlags(CLI::App* cmd, FieldFlags* f, AssetSeeds assets) {
  addSeedFlags(cmd, f, assets);
  cmd->add_option("--dims", f->dims, "Explicit grid dims X,Y,Z (a volume's: its shape, which --dims must equal)");
  addVoxelSizeFlag(cmd, f);
  addOriginFlag(cmd, f);
  addOptional(cmd, "--resolution", &f->resolution,
              "Voxels along the longest side of the padded box around the seeds or --box (the paper's N^3)");
  addOptional(cmd, "--padding", &f->padding,
              fmt::format("Margin around the seeds' bounds or --box, in voxels (default: around the seeds at least {} "
                          "and at least the limit; around --box 0)",
                          kDefaultPaddingVoxels));
  cmd->add_option("--box", f->box, "World box x0,y0,z0,x1,y1,z1 to cover instead of the seeds' bounds");
  cmd->add_option("--algorithm", f->algorithm,
                  fmt::format("auto (default: the planner's choice, the fastest exact one) | {} | {} (seed volumes "
                              "without closest features, point seeds without a limit)",
                              algorithmName(FieldAlgorithm::kBand), algorithmName(FieldAlgorithm::kSeparable)));
  cmd->add_option("--stencil", f->stencil, stencilHelp());
  cmd->add_option("--mode", f->mode, modeHelp());
  addSignFlag(cmd, f);
  addOptional(cmd, "--segment", &f->segment, "Segment length in world units (default: one segment)");
  addLimitFlag(cmd, f);
  addOptional(cmd, "--limit-voxels", &f->limit_voxels, "Distance limit in voxels of the grid (instead of --limit)");
  cmd->add_flag("--second-ring", f->second_ring,
                "Meshes: also run the engine's second-ring correction (slower; query refuses it: the service's "
                "QueryRequest has no field for it)");
  cmd->add_flag("--labels", f->labels,
                "Volumes: the multi-label EDT (each voxel of label L != 0 gets its distance to the nearest voxel of "
                "another label; label 0 gets 0) instead of the distance to the nonzero voxels");
  cmd->add_flag("--black-border", f->black_border, "With --labels: the voxels just outside the grid are label 0");
  addDeadlineFlag(cmd, f);
}

void addPointQueryFlags(CLI::App* cmd, FieldFlags* f, AssetSeeds assets) {
  addSeedFlags(cmd, f, assets);
  addVoxelSizeFlag(cmd, f);
  addOriginFlag(cmd, f);
  addSignFlag(cmd, f);
  addLimitFlag(cmd, f);
  addDeadlineFlag(cmd, f);
}

std::string parsePointQueryFlags(const FieldFlags& flags, FieldSpec* spec) {
  FieldSpec s;
  if (std::string e = parseSeeds(flags, &s); !e.empty()) return e;
  if (s.seeds == SeedKind::kVolume && !s.asset) {
    if (std::string e = parseGrid(flags, &s); !e.empty()) return e;  // the lattice: --voxel-size, --origin
  } else if (flags.voxel_size || !flags.origin.empty()) {
    return "--voxel-size and --origin place a volume's voxels; the other seeds have no lattice";
  }
  if (std::string e = parseField(flags, &s); !e.empty()) return e;
  *spec = std::move(s);
  return {};
}

Status loadSeedPoints(FieldSpec* spec, const Interrupter* interrupter) {
  if (spec->points_file.empty()) return Status::Ok();
  std::vector<Vec3d> points;
  if (Status s = loadPointCloud(spec->points_file, {}, interrupter, &points); !s.ok())
    return s.withPrefix("--points-file");
  if (points.empty())
    return Status::InvalidArgument(fmt::format("--points-file {}: the cloud holds no point", spec->points_file));
  spec->points = std::move(points);
  return Status::Ok();
}

std::string parseFieldFlags(const FieldFlags& flags, FieldSpec* spec) {
  FieldSpec s;
  if (std::string e = parseSeeds(flags, &s); !e.empty()) return e;
  if (std::string e = parseGrid(flags, &s); !e.empty()) return e;
  if (std::string e = parseField(flags, &s); !e.empty()) return e;
  *spec = std::move(s);
  return {};
}

MeshGridOptions FieldSpec::meshGridOptions() const {
  MeshGridOptions o;
  o.voxel_size = grid.voxel_size;
  o.resolution = grid.resolution;
  o.padding_voxels = grid.padding;
  o.box_min = grid.box_min;
  o.box_max = grid.box_max;
  return o;
}

double FieldSpec::outputLimit() const {
  return request.limit_voxels > 0 ? std::numeric_limits<double>::quiet_NaN() : request.limit_world;
}

std::optional<Interrupter::Clock::time_point> FieldSpec::deadline(Interrupter::Clock::time_point start) const {
  if (!(deadline_s > 0)) return std::nullopt;
  return start + std::chrono::duration_cast<Interrupter::Clock::duration>(std::chrono::duration<double>(deadline_s));
}

std::string checkMaskDims(const FieldSpec& spec, const Coord& mask_dims) {
  if (!spec.grid.dims || *spec.grid.dims == mask_dims) return {};
  const Coord d = *spec.grid.dims;
  return fmt::format("--dims {}x{}x{} disagrees with {} of shape (Z, Y, X) = ({}, {}, {})", d.x, d.y, d.z, spec.source,
                     mask_dims.z, mask_dims.y, mask_dims.x);
}

std::string algorithmLine(const FieldPlan& plan) {
  std::string line = "algorithm: " + plan.algorithmDescription();
  if (plan.algorithm == FieldAlgorithm::kBand) line += fmt::format("; stencil {}", stencilName(plan.stencil));
  return line;
}

std::string parseVec3(std::string_view text, std::string_view flag, Vec3d* out) {
  const std::vector<std::string_view> parts = split(text, ',');
  double v[3];
  if (parts.size() != 3) return fmt::format("{} '{}': expected three comma-separated numbers x,y,z", flag, text);
  for (int i = 0; i < 3; ++i)
    if (!parseDouble(parts[i], &v[i]))
      return fmt::format("{} '{}': '{}' is not a finite number", flag, text, trim(parts[i]));
  *out = {v[0], v[1], v[2]};
  return {};
}

std::string parseDims(std::string_view text, Coord* out) {
  const std::vector<std::string_view> parts = split(text, ',');
  if (parts.size() != 3) return fmt::format("--dims '{}': expected three comma-separated integers X,Y,Z", text);
  int v[3];
  for (int i = 0; i < 3; ++i) {
    const std::string_view p = trim(parts[i]);
    const auto r = std::from_chars(p.data(), p.data() + p.size(), v[i]);
    if (p.empty() || r.ec != std::errc() || r.ptr != p.data() + p.size())
      return fmt::format("--dims '{}': '{}' is not an integer", text, p);
    if (v[i] < 1 || v[i] > kMaxGridDim)
      return fmt::format("--dims '{}': every extent must be in [1, {}]", text, kMaxGridDim);
  }
  *out = {v[0], v[1], v[2]};
  return {};
}

std::string parsePointList(std::string_view text, std::vector<Vec3d>* out) {
  std::vector<Vec3d> points;
  int n = 0;
  for (std::string_view item : split(text, ';')) {
    ++n;
    if (trim(item).empty()) continue;  // allows a trailing ';'
    Vec3d p;
    if (std::string e = parseVec3(item, fmt::format("--points (point {})", n), &p); !e.empty()) return e;
    points.push_back(p);
  }
  if (points.empty()) return "--points: no point given (expected \"x,y,z;x,y,z;...\")";
  *out = std::move(points);
  return {};
}

std::string parseBox(std::string_view text, Vec3d* min, Vec3d* max) {
  const std::vector<std::string_view> parts = split(text, ',');
  double v[6];
  if (parts.size() != 6) return fmt::format("--box '{}': expected six comma-separated numbers x0,y0,z0,x1,y1,z1", text);
  for (int i = 0; i < 6; ++i)
    if (!parseDouble(parts[i], &v[i]))
      return fmt::format("--box '{}': '{}' is not a finite number", text, trim(parts[i]));
  if (!(v[3] >= v[0] && v[4] >= v[1] && v[5] >= v[2]))
    return fmt::format("--box '{}': the max corner x1,y1,z1 must be >= the min corner x0,y0,z0", text);
  *min = {v[0], v[1], v[2]};
  *max = {v[3], v[4], v[5]};
  return {};
}

}  // namespace distband
