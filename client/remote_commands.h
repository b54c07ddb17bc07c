// The service subcommands of `distband`: query, upload, info, health (client side of distband.v1).
//   distband query  --server HOST:PORT (--mesh FILE | --points "x,y,z;..." | --volume MASK.npy | --asset ID)
//                   [--dims X,Y,Z [--voxel-size H] [--origin x,y,z]
//                    | (--resolution N | --voxel-size H) [--padding P] [--box x0,y0,z0,x1,y1,z1]]
//                   [--stencil S] [--mode exact|paper] [--sign auto|pseudonormal|winding|parity|unsigned|mask-inside]
//                   [--segment L] [--limit L | --limit-voxels V] [--deadline SECONDS]
//                   [--encoding float32|float16] [--progress auto|plain|terminal|quiet]
//                   [--out FIELD.vdb|FIELD.npy] [--npy FIELD.npy] [--meta F.json] [--closest IDS.npy]
//                   [--slice-png AXIS:INDEX PNG] [--isosurface D OBJ]
//   distband upload --server HOST:PORT (--mesh FILE | --volume MASK.npy)      prints the asset id
//   distband info   --server HOST:PORT                                         prints the server's limits
//   distband health --server HOST:PORT [--service NAME]                        exit 0 iff SERVING
// Contract:
//   * query's field flags (seeds, grid, field) are compute's, registered by the same function with the same meaning
//     and defaults (client/field_flags.h); so are its outputs (client/field_outputs.h). A choice not given is not
//     sent: the server's planner decides it as compute's does. --second-ring is refused: QueryRequest has no field
//     for it. The connection flags (client/remote_connection.h), --encoding and --progress are query's own.
//   * Every flag and output path is checked before any network traffic. Meshes and volumes are uploaded first
//     (client-streaming, so any size the server accepts) and then queried by id; points travel inline; --asset
//     names a mesh or volume uploaded before (its id says which).
//   * Logs to `out`: the header (grid, limit, sign), the algorithm line (algorithmLine: core's algorithmDescription
//     of the algorithm the stream's header names, for these seeds and limit), the per-segment table and summary,
//     the files written. Progress: a redrawn bar on a terminal, one log line per segment otherwise (client/progress.h).
//   * Outputs are written only after the stream ended, each through a temporary file renamed into place. Ctrl-C or
//     --deadline cancels the query on the server and keeps every complete segment received (complete=false
//     metadata), as compute does; a failed query writes nothing. The .vdb is an OpenVDB level set
//     (core/io/vdb_writer.h: class level set, transform of the grid, background = the limit, which it requires).
//   * Exit codes (client/command.h): 0 ok; 1 server or write failure, or the deadline passed; 2 usage or input error
//     (including the server's INVALID_ARGUMENT / NOT_FOUND); 130 interrupted.
#pragma once

#include <vector>

#include "client/at_command.h"
#include "client/command.h"

namespace distband {

std::vector<CliCommand> registerRemoteCommands(CLI::App& app, const CliContext& context);

/// `distband at --server`: the connection flags, and the run that streams the query points to QueryPoints.
AtRemote remoteAt();

}  // namespace distband
