// readVdb: loads the "distance" FloatGrid written by VdbFieldBuilder (or any .vdb with a FloatGrid), for tests
// and tools. Returns "" or a message naming the path and the problem; `out` is untouched on failure.
#pragma once

#include <string>

#include <openvdb/openvdb.h>

namespace distband {

std::string readVdb(const std::string& path, openvdb::FloatGrid::Ptr* out, const std::string& grid_name = "distance");

}  // namespace distband
