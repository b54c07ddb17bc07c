// Mesh readers: strict, bounded parsers of OBJ, OFF, PLY (ascii and binary) and STL (ascii and binary) that read
// only the bytes they are given.
// Contract:
//   * readMesh() parses a whole file held in memory into a validated TriangleMesh (validateMesh applied). It never
//     touches the file system: statements that name other files (OBJ mtllib/call, texture names, ...) are ignored,
//     like every statement that does not describe geometry. Polygons become fans around their first corner;
//     points and lines are counted in MeshReport::non_triangles and skipped.
//   * Every count a file declares (PLY element and list counts, OFF counts, STL triangle count) and every face size
//     is checked against the bytes actually present and against `limits` before anything is allocated for it; OBJ
//     and ascii STL, which declare nothing, are counted in a first pass for the same purpose. So memory is bounded
//     by the input: readMesh allocates at most meshReadPeakBytes(bytes.size()) (measured by
//     tests/core/mesh/mesh_reader_test.cc with a counting allocator).
//   * Errors: kInvalidArgument for a file that breaks its format (truncated, inconsistent, out-of-range index,
//     non-finite coordinate), kResourceExhausted for a count beyond `limits`, or the interrupter's status. Messages
//     name the element and the line (text) or byte offset (binary), e.g. "PLY element 'face' 12 (byte 1234): ...",
//     and quote at most kMeshExcerptBytes of the input, escaped; they never contain a path.
//   * Numbers are parsed locale-independently (std::from_chars). `interrupter` is polled every 64 Ki lines/records.
// Pure functions; thread-safe.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "core/interrupter.h"
#include "core/mesh/triangle_mesh.h"
#include "core/status.h"

namespace distband {

enum class MeshFormat { kObj, kOff, kPly, kStl };

std::string_view meshFormatName(MeshFormat format);  ///< "OBJ", "OFF", "PLY", "STL"
/// The format of a file name's extension (case-insensitive .obj .off .ply .stl); false when unknown.
bool meshFormatFromPath(std::string_view path, MeshFormat* format);

struct MeshReadLimits {
  uint64_t max_vertices = uint64_t(1) << 26;   ///< after welding; declared counts are checked against it too
  uint64_t max_triangles = uint64_t(1) << 26;  ///< after fanning polygons
};

/// Longest excerpt of the input an error message quotes.
inline constexpr size_t kMeshExcerptBytes = 32;

Status readMesh(std::string_view bytes, MeshFormat format, const MeshReadLimits& limits,
                const Interrupter* interrupter, TriangleMesh* mesh, MeshReport* report);

/// Upper bound on the bytes readMesh allocates while parsing `input_bytes` of input (the input itself excluded).
uint64_t meshReadPeakBytes(uint64_t input_bytes);

/// `text` for an error message: at most kMeshExcerptBytes, non-printable bytes as \xNN, quotes escaped.
std::string meshExcerpt(std::string_view text);

}  // namespace distband
