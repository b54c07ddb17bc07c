// Field flags: what `distband compute` and `distband query` compute — the seeds, the grid and the field — registered
// once for both commands, so the two take the same names with the same meaning and the same defaults.
//   seeds  --mesh FILE | --points "x,y,z;..." | --points-file CLOUD (.npy .xyz .txt .ply)
//          | --volume FILE.{npy,nii,nii.gz,nrrd,nhdr} | --asset ID (query only: an uploaded mesh/volume)
//   grid   --dims X,Y,Z [--voxel-size H | --spacing X,Y,Z] [--origin x,y,z]  an explicit lattice (a volume: its shape)
//          | (--resolution N | --voxel-size H) [--padding P] [--box x0,y0,z0,x1,y1,z1]   around the seeds or the box
//   field  [--algorithm A] [--stencil S] [--mode M] [--sign S] [--segment L] [--limit L | --limit-voxels V]
//          [--second-ring] [--deadline SECONDS] [--labels [--black-border]]
// Contract:
//   * addFieldFlags() registers them on a command. A flag not given stays unset and core decides what it stands for:
//     planField (core/field/field_plan.h) the algorithm, mode, stencil and sign; gridForMesh (core/mesh/mesh_grid.h)
//     the padding; kDefaultVoxelSize (core/grid.h) an explicit lattice's voxel. Names are read with core's tables
//     (parseStencil, parseMode, requestSign) and the help lists them from the same tables.
//   * parseFieldFlags() checks every value and every combination before any file is read or any byte is sent, and
//     turns them into core's types: the seeds' source, the grid's options and a FieldRequest. It returns "" or a
//     message naming the flag. checkMaskDims() checks a volume's shape against --dims once the mask is read.
//   * The grid is given in GridSpec's three ways (proto/distband/v1/distband.proto): --dims or a volume fix the
//     lattice (--resolution, --padding and --box do not apply there); otherwise exactly one of --resolution and
//     --voxel-size sizes the seeds' bounding box, or --box, grown by --padding (--origin does not apply: the box
//     places the grid).
//   * A volume's lattice: --spacing (or --voxel-size v, meaning v,v,v) and --origin override the file's header
//     (NIfTI, NRRD), which overrides core's defaults (overrideGeometry, core/io/volume_file.h). --labels (volumes)
//     asks for the multi-label EDT, --black-border (with --labels) makes the grid's outside label 0.
//   * --second-ring applies to meshes; --deadline stops the command that many seconds after it started (the
//     commands keep the complete segments, as on Ctrl-C, and exit 1).
//   * `distband at` (distances at points: no grid) takes the flags that apply there, registered by the same functions
//     (addPointQueryFlags): the seeds, a volume's lattice (--voxel-size, --origin), --sign, --limit and --deadline.
//   * --points-file is read by the command once every flag is checked (loadSeedPoints; core/io/point_cloud.h), so a
//     cloud gives exactly the field of the same points given inline.
#pragma once

#include <chrono>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/field/field_plan.h"
#include "core/grid.h"
#include "core/interrupter.h"
#include "core/mesh/mesh_grid.h"
#include "core/types.h"

namespace CLI {
class App;
}

namespace distband {

/// Whether a command takes --asset: seeds a server holds already (query).
enum class AssetSeeds { kNo, kYes };

/// The field flags as given on the command line (unset: not given).
struct FieldFlags {
  AssetSeeds assets = AssetSeeds::kNo;  ///< whether the command takes --asset (addFieldFlags sets it)
  std::string mesh, points, points_file, volume, asset;
  std::optional<int> resolution, padding;
  std::optional<double> voxel_size;
  std::string dims, origin, box, spacing;
  std::string stencil, mode, sign, algorithm;
  std::optional<double> segment, limit, limit_voxels, deadline;
  bool second_ring = false;
  bool labels = false, black_border = false;
};

/// Registers the field flags on `command`; they fill `flags` when it is parsed.
void addFieldFlags(CLI::App* command, FieldFlags* flags, AssetSeeds assets);

/// The grid the flags ask for: an explicit lattice, or a box sized by gridForMesh.
struct GridChoice {
  bool lattice = false;       ///< --dims or a volume: origin + voxel_size + dims (dims unset: the volume's)
  std::optional<Coord> dims;  ///< --dims
  Vec3d origin{};             ///< lattice: --origin (default 0,0,0)
  double voxel_size = 0;      ///< lattice: --voxel-size or kDefaultVoxelSize; else --voxel-size or 0 (unset)
  /// Lattice: --spacing, or --voxel-size on every axis; unset: a volume file's header, else the default.
  std::optional<Vec3d> spacing;
  std::optional<Vec3d> origin_given;  ///< lattice: --origin when given (a volume file's header gives it otherwise)
  int resolution = 0;         ///< --resolution, 0: unset (never with a lattice)
  std::optional<int> padding;
  std::optional<Vec3d> box_min, box_max;  ///< --box
};

/// What the field flags ask for, in core's types.
struct FieldSpec {
  SeedKind seeds = SeedKind::kPoints;
  std::string source;         ///< the --mesh or --volume file, or the --asset id; "" for --points
  bool asset = false;         ///< `source` is an uploaded asset's id
  std::vector<Vec3d> points;  ///< --points, or --points-file's once loadSeedPoints() read it
  std::string points_file;    ///< --points-file
  GridChoice grid;
  /// Seeds, mode, stencil, sign, limit, segments and second ring; the commands add closest features (--closest)
  /// and a point layout.
  FieldRequest request;
  double deadline_s = 0;  ///< 0: none

  /// gridForMesh's options for a box grid: the sizing, padding and box, and the limit that sets the padding.
  MeshGridOptions meshGridOptions() const;
  /// The limit for checkOutputFlags(): world units (+infinity: none), or NaN when given in voxels.
  double outputLimit() const;
  /// The stop time --deadline asks for, counted from `start`; unset without one.
  std::optional<Interrupter::Clock::time_point> deadline(Interrupter::Clock::time_point start) const;
};

/// Checks the field flags and fills `spec`; returns "" or a message naming the flag.
std::string parseFieldFlags(const FieldFlags& flags, FieldSpec* spec);

/// Registers the field flags a point query takes (`distband at`): the same options as addFieldFlags's.
void addPointQueryFlags(CLI::App* command, FieldFlags* flags, AssetSeeds assets);
/// Checks them and fills `spec` (its grid: a volume's lattice); returns "" or a message naming the flag.
std::string parsePointQueryFlags(const FieldFlags& flags, FieldSpec* spec);

/// Reads --points-file into spec->points (nothing to do for other seeds); errors name the file.
Status loadSeedPoints(FieldSpec* spec, const Interrupter* interrupter);

/// A volume's mask shape against --dims; returns "" or a message naming both.
std::string checkMaskDims(const FieldSpec& spec, const Coord& mask_dims);

/// The line both commands print about how the field is computed: core's algorithmDescription(), with the stencil
/// when the band runs.
std::string algorithmLine(const FieldPlan& plan);

// Parsers for the list-valued flags ("" on success, otherwise a message naming the flag).
std::string parseVec3(std::string_view text, std::string_view flag, Vec3d* out);
std::string parseDims(std::string_view text, Coord* out);
std::string parsePointList(std::string_view text, std::vector<Vec3d>* out);
std::string parseBox(std::string_view text, Vec3d* min, Vec3d* max);

}  // namespace distband
