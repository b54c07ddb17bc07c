#include "core/io/npy.h"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <limits>

#include <fmt/format.h>

#include "core/grid.h"
#include "core/io/input_file.h"
#include "core/io/temp_file.h"

namespace distband {
namespace {

static_assert(std::endian::native == std::endian::little, "the .npy code assumes a little-endian host");

constexpr char kMagic[] = "\x93NUMPY";
constexpr size_t kMagicLen = 6;
constexpr int64_t kMaxExtent = int64_t(1) << 40;

// --- header parsing: the header is a Python dict literal such as
//     {'descr': '<f4', 'fortran_order': False, 'shape': (3, 4, 5), }
class HeaderParser {
 public:
  explicit HeaderParser(std::string_view text) : s_(text) {}

  Status parse(NpyArray* out) {
    auto invalid = [](std::string m) { return Status::InvalidArgument(std::move(m)); };
    bool have_descr = false, have_order = false, have_shape = false;
    skipSpace();
    if (!eat('{')) return invalid("header is not a Python dict (expected '{')");
    for (;;) {
      skipSpace();
      if (eat('}')) break;
      std::string key;
      if (!parseString(&key)) return invalid(fmt::format("header: expected a quoted key at offset {}", pos_));
      skipSpace();
      if (!eat(':')) return invalid(fmt::format("header: expected ':' after key '{}'", key));
      skipSpace();
      if (key == "descr") {
        if (peek() == '[') return invalid("unsupported dtype: structured arrays are not accepted");
        if (!parseString(&out->descr)) return invalid("header: 'descr' must be a quoted dtype string");
        have_descr = true;
      } else if (key == "fortran_order") {
        if (matchWord("True")) {
          out->fortran_order = true;
        } else if (matchWord("False")) {
          out->fortran_order = false;
        } else {
          return invalid("header: 'fortran_order' must be True or False");
        }
        have_order = true;
      } else if (key == "shape") {
        if (Status s = parseShape(&out->shape); !s.ok()) return s;
        have_shape = true;
      } else {
        return invalid(fmt::format("header: unexpected key '{}'", key));
      }
      skipSpace();
      if (eat(',')) continue;
      skipSpace();
      if (eat('}')) break;
      return invalid(fmt::format("header: expected ',' or '}}' at offset {}", pos_));
    }
    skipSpace();
    if (pos_ != s_.size()) return invalid("header: unexpected text after the dict");
    if (!have_descr) return invalid("header: missing 'descr'");
    if (!have_order) return invalid("header: missing 'fortran_order'");
    if (!have_shape) return invalid("header: missing 'shape'");
    return Status::Ok();
  }

 private:
  char peek() const { return pos_ < s_.size() ? s_[pos_] : '\0'; }
  bool eat(char c) {
    if (peek() != c) return false;
    ++pos_;
    return true;
  }
  void skipSpace() {
    while (pos_ < s_.size() && (s_[pos_] == ' ' || s_[pos_] == '\t' || s_[pos_] == '\n' || s_[pos_] == '\r')) ++pos_;
  }
  bool matchWord(std::string_view w) {
    if (s_.substr(pos_, w.size()) != w) return false;
    pos_ += w.size();
    return true;
  }
  bool parseString(std::string* out) {
    const char q = peek();
    if (q != '\'' && q != '"') return false;
    const size_t end = s_.find(q, pos_ + 1);
    if (end == std::string_view::npos) return false;
    *out = std::string(s_.substr(pos_ + 1, end - pos_ - 1));
    pos_ = end + 1;
    return true;
  }
  /// kInvalidArgument for a malformed tuple; kResourceExhausted for an extent above kMaxExtent (a hard limit).
  Status parseShape(std::vector<int64_t>* shape) {
    shape->clear();
    if (!eat('(')) return Status::InvalidArgument("header: 'shape' must be a tuple");
    for (;;) {
      skipSpace();
      if (eat(')')) return Status::Ok();
      if (!std::isdigit(static_cast<unsigned char>(peek())))
        return Status::InvalidArgument(
            fmt::format("header: 'shape' holds a non-integer or negative extent at offset {}", pos_));
      int64_t v = 0;
      while (std::isdigit(static_cast<unsigned char>(peek()))) {
        v = v * 10 + (s_[pos_++] - '0');
        if (v > kMaxExtent) return Status::ResourceExhausted("header: a shape extent is absurdly large");
      }
      if (eat('L')) {
      }  // Python 2 long suffix, as old numpy wrote it
      shape->push_back(v);
      skipSpace();
      if (eat(',')) continue;
      skipSpace();
      if (eat(')')) return Status::Ok();
      return Status::InvalidArgument(fmt::format("header: malformed 'shape' tuple at offset {}", pos_));
    }
  }

  std::string_view s_;
  size_t pos_ = 0;
};

/// Bytes per element of a simple numpy dtype ("<f4" -> 4), or 0 if unsupported.
size_t itemSize(std::string_view descr) {
  if (!descr.empty() && (descr[0] == '<' || descr[0] == '>' || descr[0] == '|' || descr[0] == '=')) descr.remove_prefix(1);
  if (descr.size() < 2 || std::strchr("biufc", descr[0]) == nullptr) return 0;
  size_t n = 0;
  for (char c : descr.substr(1)) {
    if (!std::isdigit(static_cast<unsigned char>(c))) return 0;
    n = n * 10 + size_t(c - '0');
    if (n > 64) return 0;
  }
  return n;
}

/// Reads the fixed preamble (magic, version, header length). `prefix` must hold at least 12 bytes or the
/// whole file. Sets the header text offset/length. Every failure is kInvalidArgument (malformed bytes).
Status parsePreamble(std::string_view prefix, std::string_view name, size_t* header_start, size_t* header_len) {
  auto invalid = [&](std::string_view problem) {
    return Status::InvalidArgument(fmt::format("{}: {}", name, problem));
  };
  if (prefix.size() < kMagicLen || std::memcmp(prefix.data(), kMagic, kMagicLen) != 0)
    return invalid("not a .npy file (missing the \\x93NUMPY magic)");
  if (prefix.size() < 10) return invalid("truncated .npy preamble");
  const int major = static_cast<uint8_t>(prefix[6]);
  const int minor = static_cast<uint8_t>(prefix[7]);
  if ((major != 1 && major != 2 && major != 3) || minor != 0)
    return invalid(fmt::format("unsupported .npy format version {}.{} (expected 1.0, 2.0 or 3.0)", major, minor));
  auto byte = [&](size_t i) { return size_t(static_cast<uint8_t>(prefix[i])); };
  if (major == 1) {
    *header_start = 10;
    *header_len = byte(8) | (byte(9) << 8);
  } else {
    if (prefix.size() < 12) return invalid("truncated .npy preamble");
    *header_start = 12;
    *header_len = byte(8) | (byte(9) << 8) | (byte(10) << 16) | (byte(11) << 24);
  }
  if (*header_len == 0) return invalid("empty .npy header");
  return Status::Ok();
}

/// Parses the header dict and computes the payload size. kInvalidArgument for a malformed header or an unsupported
/// dtype; kResourceExhausted when the shape exceeds a hard limit (an extent above kMaxExtent, over 2^46 bytes).
Status parseHeader(std::string_view header, std::string_view name, NpyArray* out, uint64_t* payload_bytes) {
  for (char c : header)
    if (c == '\0') return Status::InvalidArgument(fmt::format("{}: .npy header contains a NUL byte", name));
  if (Status s = HeaderParser(header).parse(out); !s.ok()) return s.withPrefix(name);
  const size_t item = itemSize(out->descr);
  if (item == 0) return Status::InvalidArgument(fmt::format("{}: unsupported dtype '{}'", name, out->descr));
  uint64_t n = item;
  for (int64_t e : out->shape)
    if (__builtin_mul_overflow(n, uint64_t(e), &n) || n > (uint64_t(1) << 46))
      return Status::ResourceExhausted(fmt::format("{}: the array is too large", name));
  *payload_bytes = n;
  return Status::Ok();
}

std::string shapeText(const std::vector<int64_t>& shape) {
  std::string s = "(";
  for (size_t i = 0; i < shape.size(); ++i) s += fmt::format("{}{}", i ? ", " : "", shape[i]);
  if (shape.size() == 1) s += ",";
  return s + ")";
}

/// Checks a parsed array is a C-order (Z, Y, X) volume and returns dims {X, Y, Z}; kInvalidArgument otherwise (an
/// extent outside [1, kMaxGridDim] is a shape no grid can have).
Status volumeDims(const NpyArray& a, std::string_view name, Coord* dims) {
  if (a.fortran_order)
    return Status::InvalidArgument(
        fmt::format("{}: fortran_order arrays are not accepted (save a C-order array)", name));
  if (a.shape.size() != 3)
    return Status::InvalidArgument(
        fmt::format("{}: expected a 3-D array of shape (Z, Y, X), got shape {}", name, shapeText(a.shape)));
  for (int64_t e : a.shape)
    if (e < 1 || e > kMaxGridDim)
      return Status::InvalidArgument(
          fmt::format("{}: every extent must be in [1, {}], got shape {}", name, kMaxGridDim, shapeText(a.shape)));
  *dims = {int32_t(a.shape[2]), int32_t(a.shape[1]), int32_t(a.shape[0])};
  return Status::Ok();
}

/// kIoError when the OS cannot create, write or rename the file.
Status writeNpyFile(const std::string& path, std::string_view descr, const Coord& dims, const void* data,
                    size_t bytes) {
  const std::vector<int64_t> shape{dims.z, dims.y, dims.x};
  std::string header = encodeNpy(descr, shape, nullptr, 0);
  // Atomic: a temporary beside the target renamed over it, so an interrupted write never leaves a truncated array.
  std::string tmp;
  std::FILE* f = nullptr;
  if (Status s = openTempBeside(path, "wb", &tmp, &f); !s.ok()) return s;
  Status err;
  if (std::fwrite(header.data(), 1, header.size(), f) != header.size() ||
      std::fwrite(data, 1, bytes, f) != bytes)
    err = Status::IoError(fmt::format("{}: write failed: {}", path, std::strerror(errno)));
  return commitTemp(f, tmp, path, err);
}

/// OK when the data after the header is exactly what the shape and dtype need, otherwise kInvalidArgument saying what
/// is wrong (truncated data or trailing bytes).
Status checkPayloadSize(std::string_view name, const NpyArray& a, uint64_t payload, uint64_t have) {
  if (have < payload)
    return Status::InvalidArgument(fmt::format("{}: truncated: shape {} of '{}' needs {} data bytes, the file holds {}",
                                               name, shapeText(a.shape), a.descr, payload, have));
  if (have > payload)
    return Status::InvalidArgument(fmt::format("{}: {} unexpected bytes after the {} data bytes of shape {}", name,
                                               have - payload, payload, shapeText(a.shape)));
  return Status::Ok();
}

}  // namespace

Status parseNpyHeader(std::string_view prefix, std::string_view name, NpyArray* header, size_t* data_offset,
                      uint64_t* payload_bytes) {
  size_t start = 0, len = 0;
  if (Status s = parsePreamble(prefix, name, &start, &len); !s.ok()) return s;
  if (prefix.size() < start + len)
    return Status::InvalidArgument(fmt::format("{}: truncated .npy header ({} bytes declared, {} present)", name, len,
                                               prefix.size() - start));
  NpyArray a;
  if (Status s = parseHeader(prefix.substr(start, len), name, &a, payload_bytes); !s.ok()) return s;
  *data_offset = start + len;
  *header = std::move(a);
  return Status::Ok();
}

Status parseNpy(std::string_view bytes, std::string_view name, NpyArray* out) {
  NpyArray a;
  uint64_t payload = 0;
  size_t data_offset = 0;
  if (Status s = parseNpyHeader(bytes, name, &a, &data_offset, &payload); !s.ok()) return s;
  const uint64_t have = bytes.size() - data_offset;
  if (Status s = checkPayloadSize(name, a, payload, have); !s.ok()) return s;
  const auto* p = reinterpret_cast<const uint8_t*>(bytes.data()) + data_offset;
  a.data.assign(p, p + payload);
  *out = std::move(a);
  return Status::Ok();
}

Status readNpy(const std::string& path, NpyArray* out) {
  InputFile f;
  if (Status s = InputFile::open(path, &f); !s.ok()) return s;
  const uint64_t file_size = f.size();
  // The preamble is 10 (v1) or 12 (v2/3) bytes; read what exists and let parsePreamble judge.
  std::string pre(size_t(std::min<uint64_t>(file_size, 12)), '\0');
  if (Status s = f.readAt(0, pre.data(), pre.size()); !s.ok()) return s;
  size_t start = 0, len = 0;
  if (Status s = parsePreamble(pre, path, &start, &len); !s.ok()) return s;
  if (file_size < start + len)
    return Status::InvalidArgument(fmt::format("{}: truncated .npy header ({} bytes declared, {} present)", path, len,
                                               file_size - std::min<uint64_t>(start, file_size)));
  std::string header(len, '\0');
  if (Status s = f.readAt(start, header.data(), len); !s.ok()) return s;
  NpyArray a;
  uint64_t payload = 0;
  if (Status s = parseHeader(header, path, &a, &payload); !s.ok()) return s;
  const uint64_t have = file_size - start - len;
  if (Status s = checkPayloadSize(path, a, payload, have); !s.ok()) return s;
  a.data.resize(payload);
  if (Status s = f.readAt(start + len, a.data.data(), payload); !s.ok()) return s;
  *out = std::move(a);
  return Status::Ok();
}

Status npyVolume(NpyArray a, std::string_view name, LabelVolume* out) {
  const std::string_view d = a.descr;
  const char order = d.empty() ? '?' : d[0];
  const std::string_view kind = d.size() == 3 && std::strchr("|<>=", order) ? d.substr(1) : std::string_view();
  VoxelType type;
  if (kind == "u1" || kind == "b1") type = VoxelType::kUint8;
  else if (kind == "u2" && order != '|') type = VoxelType::kUint16;
  else if (kind == "u4" && order != '|') type = VoxelType::kUint32;
  else
    return Status::InvalidArgument(fmt::format(
        "{}: a seed or label volume must have dtype bool, uint8, uint16 or uint32, got '{}'", name, a.descr));
  Coord dims;
  if (Status s = volumeDims(a, name, &dims); !s.ok()) return s;
  if (order == '>') {  // big-endian elements: to the host's (little-endian) order
    const size_t w = voxelTypeBytes(type);
    for (size_t i = 0; i + w <= a.data.size(); i += w) std::reverse(a.data.begin() + int64_t(i), a.data.begin() + int64_t(i + w));
  }
  return LabelVolume::make(dims, type, std::make_shared<const std::vector<uint8_t>>(std::move(a.data)), out);
}

Status readNpyVolume(const std::string& path, LabelVolume* out) {
  NpyArray a;
  if (Status s = readNpy(path, &a); !s.ok()) return s;
  return npyVolume(std::move(a), path, out);
}

Status readNpyFloat32(const std::string& path, std::vector<float>* values, Coord* dims) {
  NpyArray a;
  if (Status s = readNpy(path, &a); !s.ok()) return s;
  if (a.descr != "<f4" && a.descr != "=f4")
    return Status::InvalidArgument(
        fmt::format("{}: expected dtype little-endian float32 ('<f4'), got '{}'", path, a.descr));
  Coord c;
  if (Status s = volumeDims(a, path, &c); !s.ok()) return s;
  std::vector<float> v(a.data.size() / sizeof(float));
  if (!v.empty()) std::memcpy(v.data(), a.data.data(), v.size() * sizeof(float));
  *values = std::move(v);
  *dims = c;
  return Status::Ok();
}

std::string encodeNpy(std::string_view descr, const std::vector<int64_t>& shape, const void* data, size_t bytes) {
  std::string dict = fmt::format("{{'descr': '{}', 'fortran_order': False, 'shape': {}, }}", descr, shapeText(shape));
  // Pad with spaces so magic + version + length + header + '\n' is a multiple of 64 (numpy.save's alignment).
  size_t preamble = 10;
  size_t total = preamble + dict.size() + 1;
  if ((total + 63) / 64 * 64 - preamble > 65535) preamble = 12;
  total = preamble + dict.size() + 1;
  const size_t padded = (total + 63) / 64 * 64;
  dict.append(padded - total, ' ');
  dict.push_back('\n');
  const size_t hlen = dict.size();
  std::string out(kMagic, kMagicLen);
  out.push_back(static_cast<char>(preamble == 10 ? 1 : 2));
  out.push_back('\0');
  out.push_back(static_cast<char>(hlen & 0xff));
  out.push_back(static_cast<char>((hlen >> 8) & 0xff));
  if (preamble == 12) {
    out.push_back(static_cast<char>((hlen >> 16) & 0xff));
    out.push_back(static_cast<char>((hlen >> 24) & 0xff));
  }
  out += dict;
  if (bytes) out.append(static_cast<const char*>(data), bytes);
  return out;
}

Status writeNpyFloat32(const std::string& path, const std::vector<float>& values, const Coord& dims) {
  if (int64_t(values.size()) != int64_t(dims.x) * dims.y * dims.z)
    return Status::InvalidArgument(
        fmt::format("{}: {} values do not fill dims {}x{}x{}", path, values.size(), dims.x, dims.y, dims.z));
  static_assert(std::numeric_limits<float>::is_iec559, "float32 output assumes IEEE-754 floats");
  return writeNpyFile(path, "<f4", dims, values.data(), values.size() * sizeof(float));
}

Status writeNpyMask(const std::string& path, const std::vector<uint8_t>& mask, const Coord& dims) {
  if (int64_t(mask.size()) != int64_t(dims.x) * dims.y * dims.z)
    return Status::InvalidArgument(
        fmt::format("{}: {} bytes do not fill dims {}x{}x{}", path, mask.size(), dims.x, dims.y, dims.z));
  return writeNpyFile(path, "|u1", dims, mask.data(), mask.size());
}

Status writeNpyVolume(const std::string& path, const LabelVolume& volume) {
  static constexpr const char* kDescr[] = {"|u1", "<u2", "<u4"};
  return writeNpyFile(path, kDescr[int(volume.type())], volume.dims(), volume.bytes().data(), volume.bytes().size());
}

namespace {
template <typename T>
Status writeNpyInts(const std::string& path, const char* descr, const std::vector<T>& values, const Coord& dims) {
  if (int64_t(values.size()) != int64_t(dims.x) * dims.y * dims.z)
    return Status::InvalidArgument(
        fmt::format("{}: {} values do not fill dims {}x{}x{}", path, values.size(), dims.x, dims.y, dims.z));
  return writeNpyFile(path, descr, dims, values.data(), values.size() * sizeof(T));
}
}  // namespace

Status writeNpyInt32(const std::string& path, const std::vector<int32_t>& values, const Coord& dims) {
  return writeNpyInts(path, "<i4", values, dims);
}
Status writeNpyInt64(const std::string& path, const std::vector<int64_t>& values, const Coord& dims) {
  return writeNpyInts(path, "<i8", values, dims);
}

std::string NpyRowWriter::header() const {
  const std::string shape =
      columns_ > 0 ? fmt::format("({}, {})", rows_, columns_) : fmt::format("({},)", rows_);
  std::string dict = fmt::format("{{'descr': '{}', 'fortran_order': False, 'shape': {}, }}", descr_, shape);
  // A fixed 128-byte header (preamble, dict, spaces, newline), so the final count rewrites it in place.
  constexpr size_t kHeaderBytes = 128, kPreamble = 10;
  dict.append(kHeaderBytes - kPreamble - 1 - dict.size(), ' ');
  dict.push_back('\n');
  std::string out(kMagic, kMagicLen);
  out.push_back('\x01');
  out.push_back('\0');
  out.push_back(char(dict.size() & 0xff));
  out.push_back(char(dict.size() >> 8));
  return out + dict;
}

Status NpyRowWriter::open(const std::string& path, std::string_view descr, int64_t columns) {
  abandon();
  path_ = path;
  descr_ = std::string(descr);
  columns_ = columns;
  rows_ = 0;
  if (descr_.size() > 8 || columns < 0) return Status::InvalidArgument(fmt::format("{}: bad dtype or columns", path));
  if (Status s = openTempBeside(path, "wb", &tmp_, &file_); !s.ok()) return s;
  const std::string h = header();
  if (std::fwrite(h.data(), 1, h.size(), file_) != h.size()) {
    abandon();
    return Status::IoError(fmt::format("{}: write failed: {}", path, std::strerror(errno)));
  }
  return Status::Ok();
}

Status NpyRowWriter::append(const void* data, size_t bytes, int64_t rows) {
  if (!file_) return Status::IoError(fmt::format("{}: not open", path_));
  if (bytes > 0 && std::fwrite(data, 1, bytes, file_) != bytes) {
    const Status s = Status::IoError(fmt::format("{}: write failed: {}", path_, std::strerror(errno)));
    abandon();
    return s;
  }
  rows_ += rows;
  return Status::Ok();
}

Status NpyRowWriter::finish() {
  if (!file_) return Status::IoError(fmt::format("{}: not open", path_));
  const std::string h = header();
  Status err;
  if (std::fseek(file_, 0, SEEK_SET) != 0 || std::fwrite(h.data(), 1, h.size(), file_) != h.size())
    err = Status::IoError(fmt::format("{}: write failed: {}", path_, std::strerror(errno)));
  std::FILE* f = file_;
  file_ = nullptr;
  const Status s = commitTemp(f, tmp_, path_, err);
  tmp_.clear();
  return s;
}

void NpyRowWriter::abandon() {
  if (!file_) return;
  std::fclose(file_);
  file_ = nullptr;
  std::remove(tmp_.c_str());
  tmp_.clear();
}

}  // namespace distband
