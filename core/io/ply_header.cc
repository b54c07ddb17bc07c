#include "core/io/ply_header.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <utility>

#include <fmt/format.h>

#include "core/io/text_scan.h"

namespace distband::ply {

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


std::string Cursor::where() const {
  return encoding_ == Encoding::kAscii ? fmt::format("line {}", line_) : fmt::format("byte {}", base_ + pos_);
}

void Cursor::decode(Type t, const unsigned char* bytes, Encoding encoding, double* as_double, int64_t* as_int) {
  const size_t n = sizeOf(t);
  unsigned char b[8];
  std::memcpy(b, bytes, n);
  if ((encoding == Encoding::kBig) == (std::endian::native == std::endian::little)) std::reverse(b, b + n);
  switch (t) {
    case Type::kInt8: *as_int = int8_t(b[0]); break;
    case Type::kUint8: *as_int = b[0]; break;
    case Type::kInt16: { int16_t v; std::memcpy(&v, b, 2); *as_int = v; break; }
    case Type::kUint16: { uint16_t v; std::memcpy(&v, b, 2); *as_int = v; break; }
    case Type::kInt32: { int32_t v; std::memcpy(&v, b, 4); *as_int = v; break; }
    case Type::kUint32: { uint32_t v; std::memcpy(&v, b, 4); *as_int = v; break; }
    case Type::kFloat32: { float v; std::memcpy(&v, b, 4); *as_double = v; return; }
    case Type::kFloat64: { double v; std::memcpy(&v, b, 8); *as_double = v; return; }
  }
  *as_double = double(*as_int);
}

bool Cursor::read(Type t, double* as_double, int64_t* as_int, std::string* bad) {
  if (encoding_ == Encoding::kAscii) return readText(t, as_double, as_int, bad);
  const size_t n = sizeOf(t);
  if (remaining() < n) return false;
  decode(t, reinterpret_cast<const unsigned char*>(data_.data() + pos_), encoding_, as_double, as_int);
  pos_ += n;
  return true;
}

bool Cursor::onlySpaceLeft() const {
  std::string_view rest = data_.substr(pos_);
  return nextToken(&rest).empty();
}

bool Cursor::readText(Type t, double* as_double, int64_t* as_int, std::string* bad) {
  while (pos_ < data_.size() && (isSpace(data_[pos_]) || data_[pos_] == '\n')) line_ += data_[pos_++] == '\n';
  size_t e = pos_;
  while (e < data_.size() && !isSpace(data_[e]) && data_[e] != '\n') ++e;
  const std::string_view token = data_.substr(pos_, e - pos_);
  if (token.empty()) return false;
  pos_ = e;
  const bool ok = isInteger(t) ? parseInt(token, as_int) : parseDouble(token, as_double);
  if (!ok) {
    *bad = textExcerpt(token);
    return false;
  }
  if (isInteger(t)) *as_double = double(*as_int);
  return true;
}

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
      else return Status::InvalidArgument(fmt::format("{}: unknown format '{}'", at, textExcerpt(f)));
      if (version != "1.0")
        return Status::InvalidArgument(fmt::format("{}: unsupported version '{}'", at, textExcerpt(version)));
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
          return Status::InvalidArgument(fmt::format("{}: element '{}' is declared twice", at, textExcerpt(e.name)));
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
        return Status::InvalidArgument(fmt::format("{}: unknown property type '{}'", at, textExcerpt(type)));
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
      return Status::InvalidArgument(fmt::format("{}: unknown header keyword '{}'", at, textExcerpt(key)));
    }
  }
  if (!have_format) return Status::InvalidArgument("PLY: the header has no format line");
  *data_offset = bytes.size() - lines.remaining();
  *header_lines = lines.number();
  return Status::Ok();
}

}  // namespace distband::ply
