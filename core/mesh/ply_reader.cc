// Stanford PLY: ascii, binary_little_endian and binary_big_endian. The header declares elements (name, count) and
// their properties (scalars, or lists with a count type and an item type). Geometry comes from the `vertex` element
// (scalar x, y, z of any numeric type) and the `face` element (a list named vertex_indices or vertex_index of an
// integer type); every other element and property is read past. Elements may come in any order: face indices are
// checked against the vertex count the header declares.
// Bounds: before an element is read, count x its smallest possible record must fit in the bytes that follow; every
// list count must fit in the bytes that follow before its items are read; vertex and face counts are checked against
// the limits before anything is allocated.
#include <algorithm>
#include <bit>
#include <cstring>

#include <fmt/format.h>

#include "core/mesh/internal/mesh_reader_parts.h"

namespace distband::mesh_internal {
namespace {

enum class Type { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };
enum class Encoding { kAscii, kLittle, kBig };

bool typeOf(std::string_view name, Type* t) {
  static const std::pair<std::string_view, Type> kNames[] = {
      {"char", Type::kInt8},     {"int8", Type::kInt8},       {"uchar", Type::kUint8},   {"uint8", Type::kUint8},
      {"short", Type::kInt16},   {"int16", Type::kInt16},     {"ushort", Type::kUint16}, {"uint16", Type::kUint16},
      {"int", Type::kInt32},     {"int32", Type::kInt32},     {"uint", Type::kUint32},   {"uint32", Type::kUint32},
      {"float", Type::kFloat32}, {"float32", Type::kFloat32}, {"double", Type::kFloat64}, {"float64", Type::kFloat64}};
  for (const auto& [n, type] : kNames)
    if (n == name) {
      *t = type;
      return true;
    }
  return false;
}

size_t sizeOf(Type t) {
  switch (t) {
    case Type::kInt8: case Type::kUint8: return 1;
    case Type::kInt16: case Type::kUint16: return 2;
    case Type::kInt32: case Type::kUint32: case Type::kFloat32: return 4;
    case Type::kFloat64: return 8;
  }
  return 1;
}

bool isInteger(Type t) { return t != Type::kFloat32 && t != Type::kFloat64; }

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

/// The data section, read as binary values or as ascii tokens, with positions for error messages.
class Cursor {
 public:
  Cursor(std::string_view data, size_t data_offset, uint64_t header_lines, Encoding encoding)
      : data_(data), base_(data_offset), line_(header_lines + 1), encoding_(encoding) {}

  size_t remaining() const { return data_.size() - pos_; }
  /// "byte N" (binary) or "line N" (ascii): where the cursor is.
  std::string where() const {
    return encoding_ == Encoding::kAscii ? fmt::format("line {}", line_) : fmt::format("byte {}", base_ + pos_);
  }

  /// Reads one value of type `t`; false at the end of the data or on a malformed ascii token (`bad` set).
  bool read(Type t, double* as_double, int64_t* as_int, std::string* bad) {
    if (encoding_ == Encoding::kAscii) return readText(t, as_double, as_int, bad);
    const size_t n = sizeOf(t);
    if (remaining() < n) return false;
    unsigned char b[8];
    std::memcpy(b, data_.data() + pos_, n);
    pos_ += n;
    if ((encoding_ == Encoding::kBig) == (std::endian::native == std::endian::little)) std::reverse(b, b + n);
    switch (t) {
      case Type::kInt8: *as_int = int8_t(b[0]); break;
      case Type::kUint8: *as_int = b[0]; break;
      case Type::kInt16: { int16_t v; std::memcpy(&v, b, 2); *as_int = v; break; }
      case Type::kUint16: { uint16_t v; std::memcpy(&v, b, 2); *as_int = v; break; }
      case Type::kInt32: { int32_t v; std::memcpy(&v, b, 4); *as_int = v; break; }
      case Type::kUint32: { uint32_t v; std::memcpy(&v, b, 4); *as_int = v; break; }
      case Type::kFloat32: { float v; std::memcpy(&v, b, 4); *as_double = v; return true; }
      case Type::kFloat64: { double v; std::memcpy(&v, b, 8); *as_double = v; return true; }
    }
    *as_double = double(*as_int);
    return true;
  }

  /// Ascii only: after the last element only white space may follow.
  bool onlySpaceLeft() {
    std::string_view rest = data_.substr(pos_);
    return nextToken(&rest).empty();
  }

 private:
  bool readText(Type t, double* as_double, int64_t* as_int, std::string* bad) {
    while (pos_ < data_.size() && (isSpace(data_[pos_]) || data_[pos_] == '\n')) line_ += data_[pos_++] == '\n';
    size_t e = pos_;
    while (e < data_.size() && !isSpace(data_[e]) && data_[e] != '\n') ++e;
    const std::string_view token = data_.substr(pos_, e - pos_);
    if (token.empty()) return false;
    pos_ = e;
    const bool ok = isInteger(t) ? parseInt(token, as_int) : parseDouble(token, as_double);
    if (!ok) {
      *bad = meshExcerpt(token);
      return false;
    }
    if (isInteger(t)) *as_double = double(*as_int);
    return true;
  }

  std::string_view data_;
  size_t pos_ = 0;
  size_t base_;
  uint64_t line_;
  Encoding encoding_;
};

Status parseHeader(std::string_view bytes, Encoding* encoding, std::vector<Element>* elements, size_t* data_offset,
                   uint64_t* header_lines) {
  LineReader lines(bytes);
  std::string_view line;
  if (!lines.next(&line) || line != "ply") return Status::InvalidArgument("PLY: the file does not start with 'ply'");
  bool have_format = false;
  for (;;) {
    if (!lines.next(&line)) return Status::InvalidArgument("PLY: the header has no end_header line");
    if (bytes.size() - lines.remaining() > (size_t(1) << 16))
      return Status::InvalidArgument("PLY: the header is longer than 64 KiB");
    std::string_view rest = line;
    const std::string_view key = nextToken(&rest);
    const std::string at = fmt::format("PLY header line {}", lines.number());
    if (key == "end_header") break;
    if (key == "comment" || key == "obj_info" || key.empty()) continue;
    if (key == "format") {
      const std::string_view f = nextToken(&rest), version = nextToken(&rest);
      if (f == "ascii") *encoding = Encoding::kAscii;
      else if (f == "binary_little_endian") *encoding = Encoding::kLittle;
      else if (f == "binary_big_endian") *encoding = Encoding::kBig;
      else return Status::InvalidArgument(fmt::format("{}: unknown format '{}'", at, meshExcerpt(f)));
      if (version != "1.0")
        return Status::InvalidArgument(fmt::format("{}: unsupported version '{}'", at, meshExcerpt(version)));
      have_format = true;
    } else if (key == "element") {
      Element e;
      e.name = std::string(nextToken(&rest));
      int64_t count = 0;
      const std::string_view count_text = nextToken(&rest);
      if (e.name.empty() || !parseInt(count_text, &count) || count < 0)
        return Status::InvalidArgument(fmt::format("{}: expected 'element NAME COUNT'", at));
      for (const Element& other : *elements)
        if (other.name == e.name)
          return Status::InvalidArgument(fmt::format("{}: element '{}' is declared twice", at, meshExcerpt(e.name)));
      e.count = uint64_t(count);
      elements->push_back(std::move(e));
    } else if (key == "property") {
      if (elements->empty()) return Status::InvalidArgument(fmt::format("{}: a property before any element", at));
      Property p;
      std::string_view type = nextToken(&rest);
      if (type == "list") {
        p.list = true;
        if (!typeOf(nextToken(&rest), &p.count_type) || !isInteger(p.count_type))
          return Status::InvalidArgument(fmt::format("{}: a list's count type must be an integer type", at));
        type = nextToken(&rest);
      }
      if (!typeOf(type, &p.type))
        return Status::InvalidArgument(fmt::format("{}: unknown property type '{}'", at, meshExcerpt(type)));
      p.name = std::string(nextToken(&rest));
      if (p.name.empty()) return Status::InvalidArgument(fmt::format("{}: a property needs a name", at));
      Element& e = elements->back();
      const int position = int(e.properties.size());
      if (e.name == "vertex" && !p.list) {
        if (p.name == "x") e.x = position;
        if (p.name == "y") e.y = position;
        if (p.name == "z") e.z = position;
      }
      if (e.name == "face" && p.list && (p.name == "vertex_indices" || p.name == "vertex_index")) {
        if (!isInteger(p.type))
          return Status::InvalidArgument(fmt::format("{}: face indices must have an integer type", at));
        e.indices = position;
      }
      e.properties.push_back(std::move(p));
    } else {
      return Status::InvalidArgument(fmt::format("{}: unknown header keyword '{}'", at, meshExcerpt(key)));
    }
  }
  if (!have_format) return Status::InvalidArgument("PLY: the header has no format line");
  *data_offset = bytes.size() - lines.remaining();
  *header_lines = lines.number();
  return Status::Ok();
}

}  // namespace

Status readPly(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out) {
  Encoding encoding = Encoding::kAscii;
  std::vector<Element> elements;
  size_t data_offset = 0;
  uint64_t header_lines = 0;
  if (Status s = parseHeader(bytes, &encoding, &elements, &data_offset, &header_lines); !s.ok()) return s;

  // The elements' smallest records: every scalar, and every list's count with no items (ascii: one digit and a
  // separator per value). What the header declares must fit in the bytes that follow it, before any limit applies.
  auto minRecord = [&](const Element& e) {
    uint64_t bytes_per_record = 0;
    for (const Property& p : e.properties)
      bytes_per_record += encoding == Encoding::kAscii ? 2 : sizeOf(p.list ? p.count_type : p.type);
    return bytes_per_record;
  };
  const uint64_t data_bytes = bytes.size() - data_offset;
  uint64_t need = 0;
  for (const Element& e : elements) {
    const uint64_t m = minRecord(e);
    if (m > 0 && e.count > (data_bytes + 1 - std::min(need, data_bytes + 1)) / m)
      return Status::InvalidArgument(fmt::format(
          "PLY element '{}': the header declares {} records of at least {} bytes but only {} bytes of data follow the "
          "header{}",
          meshExcerpt(e.name), e.count, m, data_bytes, need ? " and the elements before it" : ""));
    need += e.count * m;
  }
  uint64_t vertex_count = 0;
  bool have_vertex = false, have_face = false;
  for (const Element& e : elements) {
    if (e.name == "vertex") {
      if (e.x < 0 || e.y < 0 || e.z < 0)
        return Status::InvalidArgument("PLY: element 'vertex' lacks a scalar x, y or z property");
      have_vertex = true;
      vertex_count = e.count;
      if (e.count > limits.max_vertices)
        return Status::ResourceExhausted(fmt::format(
            "PLY: element 'vertex' declares {} vertices, more than the server's limit of {}", e.count, limits.max_vertices));
    }
    if (e.name == "face") {
      if (e.indices < 0)
        return Status::InvalidArgument("PLY: element 'face' lacks a vertex_indices (or vertex_index) list");
      have_face = true;
      if (e.count > limits.max_triangles)
        return Status::ResourceExhausted(fmt::format(
            "PLY: element 'face' declares {} faces, more than the server's limit of {}", e.count, limits.max_triangles));
    }
  }
  if (!have_vertex || !have_face) return Status::InvalidArgument("PLY: the file needs a 'vertex' and a 'face' element");

  Cursor cursor(bytes.substr(data_offset), data_offset, header_lines, encoding);
  std::vector<uint32_t> corners;
  for (const Element& e : elements) {
    const uint64_t min_record = minRecord(e);
    if (min_record > 0 && e.count > (cursor.remaining() + 1) / min_record)
      return Status::InvalidArgument(fmt::format(
          "PLY element '{}': the header declares {} records of at least {} bytes but only {} bytes follow ({})",
          meshExcerpt(e.name), e.count, min_record, cursor.remaining(), cursor.where()));
    if (e.properties.empty()) continue;  // records of nothing take no bytes, however many are declared
    const bool vertex = e.name == "vertex", face = e.name == "face";
    if (vertex) out->vertices.reserve(size_t(e.count));
    if (face) out->triangles.reserve(size_t(e.count));
    for (uint64_t r = 0; r < e.count; ++r) {
      if (r % kPollEvery == 0 && isInterrupted(interrupter)) return interrupter->status();
      double xyz[3] = {0, 0, 0};
      for (int pi = 0; pi < int(e.properties.size()); ++pi) {
        const Property& p = e.properties[size_t(pi)];
        double d = 0;
        int64_t i = 0;
        std::string bad;
        auto fail = [&](const char* what) {
          const std::string where = cursor.where();
          return Status::InvalidArgument(
              bad.empty() ? fmt::format("PLY element '{}' {} ({}): the data ends inside property '{}' {}",
                                        meshExcerpt(e.name), r, where, meshExcerpt(p.name), what)
                          : fmt::format("PLY element '{}' {} ({}): property '{}' {} '{}' is not a finite number of its type",
                                        meshExcerpt(e.name), r, where, meshExcerpt(p.name), what, bad));
        };
        if (!p.list) {
          if (!cursor.read(p.type, &d, &i, &bad)) return fail("");
          if (vertex && pi == e.x) xyz[0] = d;
          if (vertex && pi == e.y) xyz[1] = d;
          if (vertex && pi == e.z) xyz[2] = d;
          continue;
        }
        if (!cursor.read(p.count_type, &d, &i, &bad)) return fail("count");
        const uint64_t item_bytes = encoding == Encoding::kAscii ? 2 : sizeOf(p.type);
        if (i < 0 || uint64_t(i) > (cursor.remaining() + 1) / item_bytes)
          return Status::InvalidArgument(
              fmt::format("PLY element '{}' {} ({}): list '{}' declares {} items but only {} bytes follow",
                          meshExcerpt(e.name), r, cursor.where(), meshExcerpt(p.name), i, cursor.remaining()));
        const bool indices = face && pi == e.indices;
        if (indices) corners.clear();
        for (int64_t k = 0, n = i; k < n; ++k) {
          if (!cursor.read(p.type, &d, &i, &bad)) return fail("item");
          if (!indices) continue;
          if (i < 0 || uint64_t(i) >= vertex_count)
            return Status::InvalidArgument(
                fmt::format("PLY element 'face' {} ({}): index {} is out of range (the header declares {} vertices)", r,
                            cursor.where(), i, vertex_count));
          corners.push_back(uint32_t(i));
        }
        if (indices) {
          if (corners.size() < 3) {
            ++out->non_triangles;
          } else if (Status s = addFan(corners.data(), corners.size(), limits.max_triangles,
                                       fmt::format("PLY element 'face' {}", r), out);
                     !s.ok()) {
            return s;
          }
        }
      }
      if (vertex) out->vertices.push_back({xyz[0], xyz[1], xyz[2]});
    }
  }
  if (encoding == Encoding::kAscii && !cursor.onlySpaceLeft())
    return Status::InvalidArgument(
        fmt::format("PLY ({}): unexpected data after the last element the header declares", cursor.where()));
  return Status::Ok();
}

}  // namespace distband::mesh_internal
