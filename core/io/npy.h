// NumPy .npy files: reading seed masks and writing float32 distance fields.
// Contract:
//   * Layout: a 3-D array of shape (Z, Y, X) in C order, so element [z][y][x] is voxel (x, y, z) — the same
//     x-fastest order as Grid::denseIndex. dims are returned and taken as Coord{X, Y, Z}.
//   * Reading validates everything an untrusted file can get wrong — magic, format version (1.0, 2.0, 3.0),
//     header syntax, dtype, fortran_order, shape (rank 3, every extent in [1, kMaxGridDim]) and the payload
//     size (truncated or trailing bytes) — and returns a message naming the file and the problem, never throws
//     or asserts. Every function returns "" on success; on failure the outputs are left untouched.
//   * Accepted element types: masks are uint8 ('|u1') or bool ('|b1'); nonzero means "seed". float32 ('<f4')
//     can be read for tests and round trips. Writing produces version 1.0 (2.0 for huge headers) files with the
//     header padded to a multiple of 64 bytes, as numpy.save does.
//   * Thread-safe (no shared state).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

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
std::string parseNpy(std::string_view bytes, std::string_view name, NpyArray* out);

/// Reads and parses a .npy file.
std::string readNpy(const std::string& path, NpyArray* out);

/// Reads a 3-D uint8 or bool mask of shape (Z, Y, X); dims = {X, Y, Z}; mask bytes are x-fastest.
std::string readNpyMask(const std::string& path, std::vector<uint8_t>* mask, Coord* dims);

/// Reads a 3-D little-endian float32 array of shape (Z, Y, X); dims = {X, Y, Z}.
std::string readNpyFloat32(const std::string& path, std::vector<float>* values, Coord* dims);

/// Serialises a C-order array to a .npy image. `descr` must be a dtype numpy understands (not checked here);
/// `data` must hold prod(shape) * itemsize bytes.
std::string encodeNpy(std::string_view descr, const std::vector<int64_t>& shape, const void* data, size_t bytes);

/// Writes float32 values (x-fastest, dims.x*dims.y*dims.z of them) as a (Z, Y, X) '<f4' array.
std::string writeNpyFloat32(const std::string& path, const std::vector<float>& values, const Coord& dims);

/// Writes a uint8 mask (x-fastest) as a (Z, Y, X) '|u1' array.
std::string writeNpyMask(const std::string& path, const std::vector<uint8_t>& mask, const Coord& dims);

/// Integer arrays of shape (Z, Y, X) (closest-feature ids), '<i4' or '<i8'; atomic like the others.
std::string writeNpyInt32(const std::string& path, const std::vector<int32_t>& values, const Coord& dims);
std::string writeNpyInt64(const std::string& path, const std::vector<int64_t>& values, const Coord& dims);

}  // namespace distband
