// `distband compute`: runs the engine in-process (no server) and writes the field to a file.
//   distband compute (--volume seeds.npy [--signed] | --points "x,y,z;x,y,z" --dims X,Y,Z
//                     | --mesh FILE (--resolution N [--padding P] | --voxel-size H) [--sign METHOD])
//                    [--voxel-size H] [--origin x,y,z] [--stencil cubic26|cubic18|cubic6|fcc12]
//                    [--mode exact|paper|exact-feature] [--segment L] [--limit L] [--threads N]
//                    --out field.npy|field.vdb [--npy F] [--meta f.json] [--closest ids.npy]
//                    [--slice-png AXIS:INDEX F.png] [--isosurface D F.obj]   (the same outputs as `query`)
// Contract:
//   * Seeds: a .npy uint8/bool mask of shape (Z, Y, X) (its shape gives the dims; --dims, if given, must agree),
//     a list of world-space points with --dims, or a triangle mesh (OBJ/OFF/PLY/STL) whose grid comes from
//     --resolution (voxels along the longest padded side) or --voxel-size. Mesh modes: exact-feature (default,
//     "exact" is an alias: closest-triangle propagation) or paper (closest-point propagation); --sign picks
//     auto (default: pseudonormal for a closed mesh, winding for an open one; the log says which and why),
//     pseudonormal, winding, parity or unsigned; --second-ring adds the engine's correction. --padding defaults
//     to core's (at least 3 voxels and at least the limit); a padding that clips the band is warned about.
//   * Ctrl-C keeps the complete segments computed so far: the outputs are written with complete=false metadata.
//   * Distances are world units (voxel size H, origin = world position of voxel (0,0,0)); --signed makes mask
//     voxels negative (OpenVDB's convention).
//   * Voxels beyond --limit hold +limit (-limit inside a signed mask). Logs one line per finished segment
//     (index, |distance| range, voxels, bricks, seconds) and a summary to `out`; errors go to `err`.
//   * Exit codes (client/command.h): 2 for usage/input errors (bad flags, unreadable or malformed files, bad
//     dims, bad numbers), 1 when computing or writing fails, 130 when interrupted, 0 on success.
#pragma once

#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "client/command.h"
#include "client/field_outputs.h"
#include "core/types.h"

namespace distband {

struct ComputeArgs {
  std::string volume;            ///< seed mask (.npy), or empty
  bool signed_distance = false;  ///< volume only
  std::string points;            ///< "x,y,z;x,y,z" world coordinates, or empty
  std::string dims;              ///< "X,Y,Z"; required with --points
  double voxel_size = 1.0;       ///< world units (meshes: only when voxel_size_given, else --resolution)
  bool voxel_size_given = false; ///< --voxel-size was on the command line
  bool resolution_given = false; ///< --resolution was on the command line (so 0 is an error, not "unset")
  std::string mesh;              ///< triangle mesh file, or empty
  int resolution = 0;            ///< mesh: voxels along the longest side of the padded box (the paper's N)
  int padding = -1;              ///< mesh: margin in voxels on every side; -1: core's default (>= the limit)
  std::string sign = "auto";     ///< mesh: auto | pseudonormal | winding | parity | unsigned
  bool second_ring = false;      ///< mesh: also run the engine's second-ring correction
  std::string origin = "0,0,0";
  std::string stencil = "auto";
  std::string mode = "exact";
  double segment = 0;                                         ///< world units; 0: one segment
  double limit = std::numeric_limits<double>::infinity();     ///< world units
  double limit_voxels = 0;  ///< > 0: the limit in voxels of the grid instead (exclusive with --limit)
  int threads = 0;                                            ///< 0: all cores
  OutputFlags outputs;  ///< --out, --npy, --meta, --closest, --slice-png, --isosurface (client/field_outputs.h)
};

CliCommand registerComputeCommand(CLI::App& app, const CliContext& context);

/// Runs a parsed compute request; returns the exit code.
int runCompute(const ComputeArgs& args, const CliContext& context);

// Parsers for the list-valued flags ("" on success, otherwise a message naming the flag).
std::string parseVec3(std::string_view text, std::string_view flag, Vec3d* out);
std::string parseDims(std::string_view text, Coord* out);
std::string parsePointList(std::string_view text, std::vector<Vec3d>* out);

}  // namespace distband
