// Point clouds: strict, bounded readers of point files — `.npy` (an N x 3 array of little-endian float32 or float64),
// `.xyz` / `.txt` (one point a line: x y z, whitespace-separated, further numeric columns such as normals ignored) and
// `.ply` (the x, y, z of the `vertex` element, ascii or binary) — read whole, or a chunk at a time from a file of any
// size (`distband at` streams its query points).
// Contract:
//   * A reader reads bytes held in memory (fromBytes: seeds, fuzzing) or a file a block at a time (fromFile): memory
//     stays bounded by the block (PointReadLimits::block_bytes) and the chunk asked for, whatever the file's size.
//   * Every count a file declares (the .npy shape, the PLY vertex count) is checked against the bytes actually present
//     and against `max_points` before anything is read or allocated; a .xyz file's points are counted as they come.
//   * Text: numbers are parsed locale-independently (core/io/text_scan.h); blank lines and lines starting with '#'
//     are skipped; every data line holds the same number (>= 3) of finite numbers; a line is at most 64 KiB.
//   * PLY: elements before `vertex` are read past; those after it are not read (a mesh's faces are ignored); the
//     vertex element needs scalar x, y and z properties of any numeric type.
//   * Every coordinate must be finite. Errors: kInvalidArgument for bytes that break the format, naming the point,
//     line or byte offset and quoting at most 32 escaped bytes (never a path other than the one given), kResourceExhausted
//     beyond `max_points`, kNotFound / kIoError for a file that cannot be opened or read, the interrupter's status.
// Not thread-safe (one reader, one thread); the functions are.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/interrupter.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

enum class PointFileFormat { kNpy, kXyz, kPly };

std::string_view pointFileFormatName(PointFileFormat format);  ///< "npy", "xyz", "ply"
/// The format of a file name's extension (case-insensitive .npy, .xyz, .txt, .ply); false when unknown.
bool pointFileFormatFromPath(std::string_view path, PointFileFormat* format);

struct PointReadLimits {
  uint64_t max_points = uint64_t(1) << 32;
  size_t block_bytes = size_t(4) << 20;  ///< fromFile's buffer (a line or a header must fit in it or 1 MiB)
};

class PointCloudReader {
 public:
  /// `bytes` must outlive the reader; `name` labels error messages.
  static Status fromBytes(std::string_view bytes, PointFileFormat format, const PointReadLimits& limits,
                          std::string_view name, std::unique_ptr<PointCloudReader>* out);
  static Status fromFile(const std::string& path, PointFileFormat format, const PointReadLimits& limits,
                         std::unique_ptr<PointCloudReader>* out);
  virtual ~PointCloudReader();

  /// The point count the file declares (.npy, .ply), checked against its size; none for .xyz.
  virtual std::optional<uint64_t> declaredCount() const = 0;
  /// Whether the file holds double precision (.npy float64, PLY double coordinates, text): outputs may follow it.
  virtual bool doublePrecision() const = 0;
  /// Appends the next points, at most `max_points`, to `out`; OK with none appended at the end of the file.
  virtual Status next(size_t max_points, std::vector<Vec3d>* out) = 0;
  /// Points read so far.
  virtual uint64_t pointsRead() const = 0;
};

/// A whole point cloud held in memory.
Status readPointCloud(std::string_view bytes, PointFileFormat format, const PointReadLimits& limits,
                      std::string_view name, const Interrupter* interrupter, std::vector<Vec3d>* points);
/// A whole point-cloud file, its format from its extension (kInvalidArgument naming it when unknown).
Status loadPointCloud(const std::string& path, const PointReadLimits& limits, const Interrupter* interrupter,
                      std::vector<Vec3d>* points);

}  // namespace distband
