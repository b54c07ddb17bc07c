// NumPy .npy files: reading seed masks and writing float32 distance fields.
// Contract:
//   * Layout: a 3-D array of shape (Z, Y, X) in C order, so element [z][y][x] is voxel (x, y, z) — the same
//     x-fastest order as Grid::denseIndex. dims are returned and taken as Coord{X, Y, Z}.
//   * Reading validates everything an untrusted file can get wrong — magic, format version (1.0, 2.0, 3.0),
//     header syntax, dtype, fortran_order, shape (rank 3, every extent in [1, kMaxGridDim]) and the payload
//     size (truncated or trailing bytes) — and returns a Status whose message names the file and the problem; it
//     never throws or asserts. On failure the outputs are left untouched.
//   * Codes: kInvalidArgument for malformed bytes or an array of the wrong kind (bad magic, version, header, dtype,
//     order or rank, an extent outside [1, kMaxGridDim], a payload that does not match the shape) and for values
//     that do not fill `dims` when writing; kResourceExhausted for a header whose shape exceeds the reader's hard
//     limits (an extent above 2^40, or more than 2^46 payload bytes); kNotFound when the file to read does not
//     exist; kIoError when the OS cannot open, read, write or rename a file.
//   * Accepted element types: seed and label volumes are bool ('|b1'), uint8 ('|u1'), uint16 or uint32 (either byte
//     order); nonzero means "seed", the value is the label. float32 ('<f4') can be read for tests and round trips. Writing produces version 1.0 (2.0 for huge headers) files with the
//     header padded to a multiple of 64 bytes, as numpy.save does.
//   * Thread-safe (no shared state).
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

#include "core/seeds/label_volume.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

/// A parsed .npy file whose payload has not been interpreted yet.
struct NpyArray {
  std::string descr;           ///< numpy dtype string, e.g. "|u1", "<f4"
  bool fortran_order = false;
  std::vector<int64_t> shape;  ///< as written in the header (C order: slowest axis first)
  std::vector<uint8_t> data;   ///< raw payload, exactly prod(shape) * itemsize bytes
};

/// Parses a whole .npy image held in memory. `name` only labels error messages.
Status parseNpy(std::string_view bytes, std::string_view name, NpyArray* out);

/// The header of a .npy image whose first bytes `prefix` holds (at least the preamble and the header; the whole image
/// will do): the array's dtype, order and shape (`header->data` stays empty), where its data starts and how many bytes
/// the shape and dtype need. Same checks and codes as parseNpy, but the payload's size is the caller's to check.
Status parseNpyHeader(std::string_view prefix, std::string_view name, NpyArray* header, size_t* data_offset,
                      uint64_t* payload_bytes);

/// Reads and parses a .npy file.
Status readNpy(const std::string& path, NpyArray* out);

/// A parsed 3-D array of shape (Z, Y, X) as a seed or label volume: dtype bool or uint8 ('|b1', '|u1'), uint16 or
/// uint32 (either byte order, converted to the host's); dims = {X, Y, Z}. kInvalidArgument naming `name` otherwise.
Status npyVolume(NpyArray array, std::string_view name, LabelVolume* out);

/// readNpy, then npyVolume.
Status readNpyVolume(const std::string& path, LabelVolume* out);

/// Reads a 3-D little-endian float32 array of shape (Z, Y, X); dims = {X, Y, Z}.
Status readNpyFloat32(const std::string& path, std::vector<float>* values, Coord* dims);

/// Serialises a C-order array to a .npy image. `descr` must be a dtype numpy understands (not checked here);
/// `data` must hold prod(shape) * itemsize bytes.
std::string encodeNpy(std::string_view descr, const std::vector<int64_t>& shape, const void* data, size_t bytes);

/// Writes float32 values (x-fastest, dims.x*dims.y*dims.z of them) as a (Z, Y, X) '<f4' array.
Status writeNpyFloat32(const std::string& path, const std::vector<float>& values, const Coord& dims);

/// Writes a uint8 mask (x-fastest) as a (Z, Y, X) '|u1' array.
Status writeNpyMask(const std::string& path, const std::vector<uint8_t>& mask, const Coord& dims);

/// Writes a volume as a (Z, Y, X) array of its element type ('|u1', '<u2', '<u4').
Status writeNpyVolume(const std::string& path, const LabelVolume& volume);

/// Integer arrays of shape (Z, Y, X) (closest-feature ids), '<i4' or '<i8'; atomic like the others.
Status writeNpyInt32(const std::string& path, const std::vector<int32_t>& values, const Coord& dims);
Status writeNpyInt64(const std::string& path, const std::vector<int64_t>& values, const Coord& dims);

/// A .npy array of rows — shape (rows,) or (rows, columns) — written block by block while the row count is not known
/// yet (streamed outputs): the header is rewritten with the final count by finish(). Atomic like the writers above:
/// the rows go to a temporary beside `path`, renamed over it by finish(); a writer destroyed unfinished (or
/// abandon()ed) removes its temporary. Errors are kIoError naming the file.
class NpyRowWriter {
 public:
  NpyRowWriter() = default;
  ~NpyRowWriter() { abandon(); }
  NpyRowWriter(const NpyRowWriter&) = delete;
  NpyRowWriter& operator=(const NpyRowWriter&) = delete;

  /// `columns` 0: a 1-D array. `descr`: e.g. "<f4", "<f8", "<i4", "<i8".
  Status open(const std::string& path, std::string_view descr, int64_t columns);
  /// Appends `rows` rows of `bytes` bytes in all.
  Status append(const void* data, size_t bytes, int64_t rows);
  Status finish();
  void abandon();
  int64_t rows() const { return rows_; }
  const std::string& path() const { return path_; }

 private:
  std::string header() const;
  std::string path_, tmp_, descr_;
  std::FILE* file_ = nullptr;
  int64_t columns_ = 0, rows_ = 0;
};

}  // namespace distband
