// The service subcommands of `distband`: query, upload, info, health (client side of distband.v1).
//   distband query  --server HOST:PORT (--mesh FILE | --points "x,y,z;..." | --volume MASK.npy | --asset ID)
//                   [--resolution N [--padding P] | --voxel-size H] [--dims X,Y,Z] [--origin x,y,z]
//                   [--box x0,y0,z0,x1,y1,z1] [--stencil S] [--mode exact|paper]
//                   [--sign pseudonormal|winding|parity|unsigned|mask-inside] [--segment L] [--limit L]
//                   [--encoding float32|float16] [--deadline SECONDS] [--progress auto|plain|quiet]
//                   [--out FIELD.vdb|FIELD.npy] [--npy FIELD.npy] [--slice-png AXIS:INDEX PNG]
//                   [--isosurface D OBJ]
//   distband upload --server HOST:PORT (--mesh FILE | --volume MASK.npy)      prints the asset id
//   distband info   --server HOST:PORT                                         prints the server's limits
//   distband health --server HOST:PORT [--service NAME]                        exit 0 iff SERVING
// Contract:
//   * Meshes and volumes are uploaded first (client-streaming, so any size the server accepts) and then queried
//     by id; points travel inline.
//   * Outputs are written only after the stream completed, each through a temporary file renamed into place:
//     an interrupted or failed query never leaves a broken file. The .vdb is an OpenVDB level set
//     (core/io/vdb_writer.h: class level set, transform of the grid, background = --limit, which it requires).
//   * Progress: a redrawn bar on a terminal, one log line per segment otherwise (client/progress.h).
//   * Exit codes (client/command.h): 0 ok; 1 server or write failure; 2 usage or input error (including the
//     server's INVALID_ARGUMENT / NOT_FOUND); 130 interrupted (SIGINT cancels the query on the server).
#pragma once

#include <vector>

#include "client/command.h"

namespace distband {

std::vector<CliCommand> registerRemoteCommands(CLI::App& app, const CliContext& context);

}  // namespace distband
