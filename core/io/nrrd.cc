#include "core/io/nrrd.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <map>
#include <optional>
#include <vector>

#include <fmt/format.h>

#include "core/grid.h"
#include "core/io/gzip.h"

namespace distband {
namespace {

constexpr size_t kMaxHeaderBytes = size_t(64) << 10;
constexpr size_t kMaxLineBytes = 1024;

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

/// A short printable excerpt of untrusted text for messages.
std::string excerpt(std::string_view s) {
  std::string out;
  for (char c : s.substr(0, 40)) out += (c >= 32 && c < 127) ? c : '?';
  if (s.size() > 40) out += "...";
  return out;
}

std::vector<std::string_view> words(std::string_view s) {
  std::vector<std::string_view> out;
  size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
    size_t j = i;
    while (j < s.size() && s[j] != ' ' && s[j] != '\t') ++j;
    if (j > i) out.push_back(s.substr(i, j - i));
    i = j;
  }
  return out;
}

bool parseNumber(std::string_view s, double* v) {
  s = trim(s);
  if (s == "nan" || s == "NaN" || s == "NAN") return *v = std::nan(""), true;
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  const auto r = std::from_chars(s.data(), s.data() + s.size(), *v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

bool parseInt(std::string_view s, int64_t* v) {
  s = trim(s);
  const auto r = std::from_chars(s.data(), s.data() + s.size(), *v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

/// "(x,y,z)" -> three numbers.
bool parseVector(std::string_view s, double v[3]) {
  s = trim(s);
  if (s.size() < 2 || s.front() != '(' || s.back() != ')') return false;
  s = s.substr(1, s.size() - 2);
  for (int i = 0; i < 3; ++i) {
    const size_t comma = s.find(',');
    if ((i < 2) != (comma != std::string_view::npos)) return false;
    if (!parseNumber(s.substr(0, comma), &v[i]) || !std::isfinite(v[i])) return false;
    if (i < 2) s.remove_prefix(comma + 1);
  }
  return true;
}

/// The vectors of a "space directions" value: "(..) (..) (..)" (spaces inside parentheses allowed).
bool parseVectors(std::string_view s, double v[3][3]) {
  int n = 0;
  size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
    if (i == s.size()) break;
    if (n == 3) return false;
    if (s[i] != '(') return false;
    const size_t close = s.find(')', i);
    if (close == std::string_view::npos) return false;
    std::string compact;
    for (char c : s.substr(i, close - i + 1))
      if (c != ' ' && c != '\t') compact += c;
    if (!parseVector(compact, v[n++])) return false;
    i = close + 1;
  }
  return n == 3;
}

/// (kind, bytes) of an NRRD type name.
bool typeOf(std::string_view t, char* kind, int* bytes) {
  static const std::map<std::string_view, std::pair<char, int>> kTypes = {
      {"uchar", {'u', 1}},
      {"unsigned char", {'u', 1}},
      {"uint8", {'u', 1}},
      {"uint8_t", {'u', 1}},
      {"signed char", {'i', 1}},
      {"int8", {'i', 1}},
      {"int8_t", {'i', 1}},
      {"short", {'i', 2}},
      {"short int", {'i', 2}},
      {"signed short", {'i', 2}},
      {"signed short int", {'i', 2}},
      {"int16", {'i', 2}},
      {"int16_t", {'i', 2}},
      {"ushort", {'u', 2}},
      {"unsigned short", {'u', 2}},
      {"unsigned short int", {'u', 2}},
      {"uint16", {'u', 2}},
      {"uint16_t", {'u', 2}},
      {"int", {'i', 4}},
      {"signed int", {'i', 4}},
      {"int32", {'i', 4}},
      {"int32_t", {'i', 4}},
      {"uint", {'u', 4}},
      {"unsigned int", {'u', 4}},
      {"uint32", {'u', 4}},
      {"uint32_t", {'u', 4}},
      {"longlong", {'i', 8}},
      {"long long", {'i', 8}},
      {"long long int", {'i', 8}},
      {"signed long long", {'i', 8}},
      {"signed long long int", {'i', 8}},
      {"int64", {'i', 8}},
      {"int64_t", {'i', 8}},
      {"ulonglong", {'u', 8}},
      {"unsigned long long", {'u', 8}},
      {"unsigned long long int", {'u', 8}},
      {"uint64", {'u', 8}},
      {"uint64_t", {'u', 8}},
      {"float", {'f', 4}},
      {"double", {'f', 8}},
  };
  const auto it = kTypes.find(t);
  if (it == kTypes.end()) return false;
  *kind = it->second.first;
  *bytes = it->second.second;
  return true;
}

}  // namespace

Status parseNrrd(std::string_view bytes, std::string_view name, const VolumeReadLimits& limits,
                 const NrrdDataFile* detached, VolumeImage* out) {
  auto invalid = [&](const std::string& what) { return Status::InvalidArgument(fmt::format("{}: {}", name, what)); };
  if (bytes.size() < 8 || bytes.substr(0, 7) != "NRRD000" || bytes[7] < '1' || bytes[7] > '5')
    return invalid("not an NRRD file (expected the magic NRRD0001..NRRD0005)");
  // The header: lines up to an empty one (or the end, for a detached header).
  std::map<std::string, std::string> fields;
  size_t pos = 0, data_at = std::string::npos;
  bool first = true;
  while (pos < bytes.size()) {
    if (pos > kMaxHeaderBytes) return invalid(fmt::format("the header is longer than {} bytes", kMaxHeaderBytes));
    size_t end = bytes.find('\n', pos);
    if (end == std::string_view::npos) end = bytes.size();
    if (end - pos > kMaxLineBytes) return invalid(fmt::format("a header line is longer than {} bytes", kMaxLineBytes));
    std::string_view line = bytes.substr(pos, end - pos);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos = end + 1;
    if (first) {
      first = false;
      continue;  // the magic
    }
    if (line.empty()) {
      data_at = std::min(pos, bytes.size());
      break;
    }
    if (line.front() == '#') continue;
    if (line.find('\0') != std::string_view::npos) return invalid("a NUL byte in the header");
    const size_t kv = line.find(":=");
    const size_t colon = line.find(": ");
    if (kv != std::string_view::npos && (colon == std::string_view::npos || kv < colon)) continue;  // key/value
    if (colon == std::string_view::npos)
      return invalid(fmt::format("header line '{}' is no \"field: value\"", excerpt(line)));
    std::string key(trim(line.substr(0, colon)));
    std::transform(key.begin(), key.end(), key.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (key == "datafile") key = "data file";
    if (key == "spacedirections") key = "space directions";
    if (key == "spaceorigin") key = "space origin";
    if (!fields.emplace(key, std::string(trim(line.substr(colon + 2)))).second)
      return invalid(fmt::format("field '{}' is given twice", excerpt(key)));
  }
  auto field = [&](const char* key) -> const std::string* {
    const auto it = fields.find(key);
    return it == fields.end() ? nullptr : &it->second;
  };
  for (const char* required : {"type", "dimension", "sizes", "encoding"})
    if (!field(required)) return invalid(fmt::format("the header has no '{}' field", required));
  char kind;
  int width;
  if (!typeOf(*field("type"), &kind, &width))
    return invalid(fmt::format("type '{}' is not an integer or floating type", excerpt(*field("type"))));
  int64_t dimension;
  if (!parseInt(*field("dimension"), &dimension) || dimension != 3)
    return invalid(fmt::format("dimension '{}': a seed or label volume is 3-D", excerpt(*field("dimension"))));
  const std::vector<std::string_view> sizes = words(*field("sizes"));
  int64_t extent[3];
  if (sizes.size() != 3) return invalid("sizes must give three extents");
  for (int i = 0; i < 3; ++i)
    if (!parseInt(sizes[size_t(i)], &extent[i]) || extent[i] < 1 || extent[i] > kMaxGridDim)
      return invalid(fmt::format("sizes: '{}' is not an extent in [1, {}]", excerpt(sizes[size_t(i)]), kMaxGridDim));
  const uint64_t voxels = uint64_t(extent[0]) * uint64_t(extent[1]) * uint64_t(extent[2]);
  if (voxels > limits.max_voxels)
    return Status::ResourceExhausted(fmt::format("{}: {}x{}x{} = {} voxels exceed the limit of {}", name, extent[0],
                                                 extent[1], extent[2], voxels, limits.max_voxels));
  const std::string& encoding = *field("encoding");
  const bool gz = encoding == "gzip" || encoding == "gz";
  if (!gz && encoding != "raw")
    return invalid(fmt::format("encoding '{}' is not read (raw or gzip)", excerpt(encoding)));
  bool big_endian = false;
  if (const std::string* e = field("endian")) {
    if (*e != "little" && *e != "big")
      return invalid(fmt::format("endian '{}' is neither little nor big", excerpt(*e)));
    big_endian = *e == "big";
  }
  for (const char* skip : {"byte skip", "line skip", "byteskip", "lineskip"})
    if (const std::string* s = field(skip); s && *s != "0") return invalid(fmt::format("'{}' is not supported", skip));
  // Geometry.
  VolumeImage image;
  if (const std::string* dirs = field("space directions")) {
    double v[3][3];
    if (!parseVectors(*dirs, v)) return invalid("space directions: expected three vectors (x,y,z)");
    double origin[3] = {0, 0, 0};
    if (const std::string* o = field("space origin"))
      if (!parseVector(*o, origin)) return invalid("space origin: expected a vector (x,y,z)");
    std::array<std::array<double, 4>, 3> a{};
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) a[size_t(r)][size_t(c)] = v[c][r];
      a[size_t(r)][3] = origin[r];
    }
    if (Status s = axisAlignedGeometry(a, name, "space directions", &image.geometry); !s.ok()) return s;
  } else if (const std::string* sp = field("spacings")) {
    const std::vector<std::string_view> w = words(*sp);
    double s[3];
    if (w.size() != 3) return invalid("spacings must give three numbers");
    for (int i = 0; i < 3; ++i)
      if (!parseNumber(w[size_t(i)], &s[i]) || !(std::isfinite(s[i]) && s[i] > 0))
        return invalid(fmt::format("spacings: '{}' is not a finite spacing > 0", excerpt(w[size_t(i)])));
    image.geometry.spacing = {s[0], s[1], s[2]};
    image.geometry.from_header = true;
  }
  // The data.
  const uint64_t data_bytes = voxels * uint64_t(width);
  std::string detached_bytes;
  std::string_view data;
  if (const std::string* file = field("data file")) {
    if (!detached)
      return invalid("the header names a detached data file: only NRRD files with their data attached are read here");
    if (words(*file).size() != 1 || file->find("%") != std::string::npos || *file == "LIST")
      return invalid("data file: only a single file name is supported");
    // Raw data are exactly the declared bytes; compressed ones at most that many and then some.
    const uint64_t max = gz ? data_bytes + data_bytes / 8 + (uint64_t(1) << 20) : data_bytes;
    if (Status s = (*detached)(*file, max, &detached_bytes); !s.ok()) return s;
    data = detached_bytes;
  } else {
    if (data_at == std::string::npos) return invalid("the header does not end with an empty line before the data");
    data = bytes.substr(data_at);
  }
  std::string inflated;
  if (gz) {
    if (Status s = gunzip(data, data_bytes, name, &inflated); !s.ok()) return s;
    data = inflated;
  } else if (data.size() != data_bytes) {
    return invalid(fmt::format("{} data bytes, the header's {} voxels of {} bytes need {}", data.size(), voxels, width,
                               data_bytes));
  }
  const Coord dims{int(extent[0]), int(extent[1]), int(extent[2])};
  if (Status s = labelsFromElements(data, dims, kind, width, big_endian, name, &image.volume); !s.ok()) return s;
  *out = std::move(image);
  return Status::Ok();
}

}  // namespace distband
