// readVdb: loads a FloatGrid (by default "distance", as VdbFieldBuilder writes it) from a .vdb file with OpenVDB's own
// reader — the independent check that the files core/io/vdb_file.cc writes are what OpenVDB reads. For tests and
// benches only: distband itself does not link OpenVDB. Returns "" or a message naming the path and the problem; `out`
// is untouched on failure. readVdbGrid reads a grid of any type.
#pragma once

#include <string>

#include <openvdb/openvdb.h>

namespace distband {

std::string readVdb(const std::string& path, openvdb::FloatGrid::Ptr* out, const std::string& grid_name = "distance");
std::string readVdbGrid(const std::string& path, const std::string& grid_name, openvdb::GridBase::Ptr* out);

}  // namespace distband
