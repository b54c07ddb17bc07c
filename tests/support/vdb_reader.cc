#include "tests/support/vdb_reader.h"

#include <exception>

#include <fmt/format.h>

namespace distband {

std::string readVdbGrid(const std::string& path, const std::string& grid_name, openvdb::GridBase::Ptr* out) {
  openvdb::initialize();
  try {
    openvdb::io::File file(path);
    file.open();
    openvdb::GridBase::Ptr base = file.readGrid(grid_name);
    file.close();
    *out = base;
  } catch (const std::exception& e) {
    return fmt::format("{}: cannot read grid '{}': {}", path, grid_name, e.what());
  }
  return {};
}

std::string readVdb(const std::string& path, openvdb::FloatGrid::Ptr* out, const std::string& grid_name) {
  openvdb::GridBase::Ptr base;
  if (std::string e = readVdbGrid(path, grid_name, &base); !e.empty()) return e;
  auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
  if (!grid) return fmt::format("{}: grid '{}' is not a FloatGrid", path, grid_name);
  *out = grid;
  return {};
}

}  // namespace distband
