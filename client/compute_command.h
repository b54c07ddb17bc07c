// `distband compute`: runs the engine in-process (no server) and writes the field to files.
//   distband compute (--mesh FILE | --points "x,y,z;x,y,z" | --volume MASK.npy)
//                    [--dims X,Y,Z [--voxel-size H] [--origin x,y,z]
//                     | (--resolution N | --voxel-size H) [--padding P] [--box x0,y0,z0,x1,y1,z1]]
//                    [--stencil S] [--mode exact|paper] [--sign auto|pseudonormal|winding|parity|unsigned|mask-inside]
//                    [--segment L] [--limit L | --limit-voxels V] [--second-ring] [--deadline SECONDS]
//                    [--threads N]
//                    --out FIELD.npy|FIELD.vdb [--npy F] [--meta F.json] [--closest IDS.npy]
//                    [--slice-png AXIS:INDEX F.png] [--isosurface D F.obj]
// Contract:
//   * The field flags (seeds, grid, field) are `query`'s, registered by the same function with the same meaning and
//     defaults (client/field_flags.h); so are the outputs (client/field_outputs.h). --threads is compute's own: it
//     bounds the whole command (mesh validation, seeds, the engine, VDB assembly), 0 = all cores.
//   * Every flag and output path is checked before any file is read. Then the seeds are read (a mesh, a .npy mask
//     whose shape gives the dims, or the points), the grid built (the lattice, or gridForMesh around the seeds' bounds
//     or --box), core's planner makes every choice left open, and the algorithm runs; its inputs are built under the
//     same interrupter as the run.
//   * Logs to `out`: one header line (the seeds, voxel size, mode, segment, limit, threads), the algorithm line
//     (algorithmLine: core's algorithmDescription), one line per finished segment (index, |distance| range, voxels,
//     bricks, seconds), the files written and a summary starting "done:". Warnings and errors go to `err`.
//   * Distances are world units (voxel size H, origin = world position of voxel (0,0,0)); negative inside a signed
//     mesh or a mask-inside volume (OpenVDB's convention). Voxels beyond the limit hold +limit (-limit inside).
//   * Ctrl-C, or --deadline passing, keeps the complete segments computed so far: the outputs are written with
//     complete=false metadata. Stopped before the first segment, nothing is written.
//   * Exit codes (client/command.h): 2 for usage/input errors (bad flags, unreadable or malformed files, bad dims,
//     bad numbers), 1 when computing or writing fails or the deadline passed, 130 when interrupted, 0 on success.
#pragma once

#include "client/command.h"
#include "client/field_flags.h"
#include "client/field_outputs.h"

namespace distband {

struct ComputeArgs {
  FieldFlags field;     ///< the field flags, shared with query (client/field_flags.h)
  int threads = 0;      ///< --threads; 0: all cores
  OutputFlags outputs;  ///< --out, --npy, --meta, --closest, --slice-png, --isosurface (client/field_outputs.h)
};

CliCommand registerComputeCommand(CLI::App& app, const CliContext& context);

/// Runs a parsed compute request; returns the exit code.
int runCompute(const ComputeArgs& args, const CliContext& context);

}  // namespace distband
