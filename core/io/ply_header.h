// PLY: the header and the typed values of Stanford PLY files (ascii, binary_little_endian, binary_big_endian), for the
// strict readers that take PLY from untrusted bytes: core/mesh's mesh reader and core/io/point_cloud.h.
// Contract:
//   * parseHeader() reads the header (at most 64 KiB, up to its end_header line) into the elements it declares, each
//     with its count and properties (scalars, or lists with a count type and an item type); for `vertex` it notes the
//     scalar x, y, z, for `face` the vertex_indices (or vertex_index) list. It checks the syntax only: counts are
//     the caller's to check against the bytes that follow and its limits. Errors are kInvalidArgument naming the
//     header line, quoting at most 32 escaped bytes.
//   * Cursor reads a data section held in memory value by value (binary: the type's bytes in the file's byte order;
//     ascii: one whitespace-separated token) and says where it is for error messages ("byte N" or "line N");
//     decode() is its binary conversion, for readers that hold the bytes themselves.
// Pure; thread-safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/status.h"

namespace distband::ply {

enum class Type { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };
enum class Encoding { kAscii, kLittle, kBig };

bool typeOf(std::string_view name, Type* t);
size_t sizeOf(Type t);
bool isInteger(Type t);

struct Property {
  std::string name;
  bool list = false;
  Type count_type = Type::kUint8;
  Type type = Type::kFloat32;
};

struct Element {
  std::string name;
  uint64_t count = 0;
  std::vector<Property> properties;
  int x = -1, y = -1, z = -1;  // vertex: property positions
  int indices = -1;            // face: the index list's position
};

Status parseHeader(std::string_view bytes, Encoding* encoding, std::vector<Element>* elements, size_t* data_offset,
                   uint64_t* header_lines);

/// The data section, read as binary values or as ascii tokens, with positions for error messages.
class Cursor {
 public:
  Cursor(std::string_view data, size_t data_offset, uint64_t header_lines, Encoding encoding)
      : data_(data), base_(data_offset), line_(header_lines + 1), encoding_(encoding) {}

  size_t remaining() const { return data_.size() - pos_; }
  /// "byte N" (binary) or "line N" (ascii): where the cursor is.
  std::string where() const;
  /// Reads one value of type `t`; false at the end of the data or on a malformed ascii token (`bad` set).
  bool read(Type t, double* as_double, int64_t* as_int, std::string* bad);
  /// Ascii only: after the last element only white space may follow.
  bool onlySpaceLeft() const;

  /// The value of type `t` held in `bytes` (sizeOf(t) of them) in `encoding`'s byte order (binary encodings).
  static void decode(Type t, const unsigned char* bytes, Encoding encoding, double* as_double, int64_t* as_int);

 private:
  bool readText(Type t, double* as_double, int64_t* as_int, std::string* bad);

  std::string_view data_;
  size_t pos_ = 0;
  size_t base_;
  uint64_t line_;
  Encoding encoding_;
};

}  // namespace distband::ply
