// `distband at`: the distance field at arbitrary points — in-process, or on a server with --server.
//   distband at (--mesh FILE | --points "x,y,z;..." | --points-file CLOUD | --volume MASK (.npy, .nii[.gz], .nrrd,
//                .nhdr) [--voxel-size H] [--origin x,y,z] | --asset ID (with --server))
//               --at QUERY (.npy N x 3 float32/float64, .xyz/.txt, .ply)
//               [--out D.npy] [--closest-points CP.npy] [--closest IDS.npy] [--gradient G.npy]
//               [--sign auto|pseudonormal|winding|parity|unsigned|mask-inside] [--limit L] [--deadline SECONDS]
//               [--chunk-points N] [--threads N | --server HOST:PORT (and the connection flags)]
// Contract:
//   * The seeds, --sign, --limit, --deadline and a volume's lattice are the field flags of compute and query,
//     registered by the same functions (client/field_flags.h: addPointQueryFlags); core's point planner
//     (core/points/point_plan.h) decides what they leave open, as for grids (auto sign: pseudonormal for a closed mesh,
//     winding for an open one or one whose closed parts overlap).
//   * A volume's lattice is its file's header (spacing and origin; a .npy has none) under --voxel-size / --spacing and
//     --origin, as for compute; it must be cubic and in the array's axis order (cubicVolumeLattice).
//   * Every flag and output path is checked before any file is read; then the query points are read a chunk at a
//     time (--chunk-points, default and at most kMaxChunkPoints), so memory stays bounded whatever the file's size.
//     The results are written in the query file's order (client/point_outputs.h), values in its type (float32 for a
//     float32 .npy, float64 otherwise).
//   * In-process: the search is built once and each chunk evaluated on --threads threads (0: all cores). With
//     --server (a build with the service client; the front binary hands such a command to distband-remote) the chunks
//     stream to the server's QueryPoints and the results stream back, with the connection flags of `query`.
//   * Logs to `out`: the seeds and the sign line, then "done: N points in T s (R points/s)" and the files written.
//     Ctrl-C or --deadline stops the run and writes nothing (exit 130 / 1).
//   * Exit codes (client/command.h): 2 usage or input errors (the server's INVALID_ARGUMENT / NOT_FOUND included),
//     1 compute, server or write failures and a passed deadline, 130 interrupted.
#pragma once

#include <functional>
#include <memory>

#include "client/command.h"
#include "client/field_flags.h"
#include "client/point_outputs.h"
#include "core/io/point_cloud.h"
#include "core/io/volume_file.h"
#include "core/points/point_results.h"

namespace distband {

struct AtArgs {
  FieldFlags field;  ///< the field flags that apply to points (addPointQueryFlags)
  std::string at;    ///< --at: the query points' file
  PointOutputFlags outputs;
  int threads = 0;
  int chunk_points = int(kMaxChunkPoints);
};

/// The flags checked and the query file opened.
struct AtSetup {
  FieldSpec spec;
  std::unique_ptr<PointCloudReader> points;  ///< --at, positioned at its first point
  PointPacking packing;                      ///< the query points' value type; int64 ids for volumes
};

/// Checks every flag (`remote`: --server was given) and opens --at; "" or a message naming the flag or the file.
std::string checkAtFlags(const AtArgs& args, bool remote, AtSetup* setup);

/// The voxel size of a seed volume's cubic lattice for point queries: `geometry` (the file's header under --spacing /
/// --voxel-size and --origin, client/field_flags.h) places voxel (i, j, k) at origin + h * (i, j, k). "" and *h, or a
/// message naming --volume `source` when its spacing is anisotropic or its header's axes are flipped or permuted
/// (the point search takes neither yet; compute and query do).
std::string cubicVolumeLattice(const VolumeGeometry& geometry, const std::string& source, double* h);

/// What a service client adds to `at`: its connection flags, and the run with --server.
struct AtRemote {
  std::function<void(CLI::App* command)> add_flags;
  std::function<int(const AtArgs& args, const CliContext& ctx)> run;
};

CliCommand registerAtCommand(CLI::App& app, const CliContext& context, AtRemote remote);

}  // namespace distband
