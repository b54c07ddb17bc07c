#include "core/io/point_cloud.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include <fmt/format.h>

#include "core/io/input_file.h"
#include "core/io/npy.h"
#include "core/io/ply_header.h"
#include "core/io/text_scan.h"

namespace distband {
namespace {

constexpr size_t kMaxLine = size_t(64) << 10;
constexpr size_t kMaxHeader = size_t(1) << 20;
constexpr uint64_t kPollEvery = 1 << 16;

/// The bytes of a point file: held in memory, or read from a file a block at a time. view() is what is buffered and
/// not yet consumed; fill(n) buffers at least n bytes unless the input ends first.
class Source {
 public:
  static Source memory(std::string_view bytes) {
    Source s;
    s.view_ = bytes;
    s.size_ = bytes.size();
    return s;
  }
  static Status file(const std::string& path, size_t block, Source* out) {
    if (Status s = InputFile::open(path, &out->file_); !s.ok()) return s;
    out->size_ = out->file_.size();
    out->block_ = std::max<size_t>(block, 64);
    return Status::Ok();
  }

  std::string_view view() const { return view_; }
  /// File offset of view()'s first byte.
  uint64_t offset() const { return offset_; }
  /// The input's total size.
  uint64_t size() const { return size_; }
  uint64_t remaining() const { return size_ - offset_; }
  void consume(size_t n) {
    view_.remove_prefix(n);
    offset_ += n;
  }
  Status fill(size_t want) {
    if (!file_.get() || view_.size() >= want || offset_ + view_.size() >= size_) return Status::Ok();
    // The unread rest moves to the front; its place is taken before a resize can move the buffer under it.
    const size_t keep = view_.size();
    const size_t at = keep ? size_t(view_.data() - buffer_.data()) : 0;
    const size_t capacity = std::max(block_, want);
    if (buffer_.size() < capacity) buffer_.resize(capacity);
    if (keep) std::memmove(buffer_.data(), buffer_.data() + at, keep);
    const size_t ask = size_t(std::min<uint64_t>(capacity - keep, size_ - offset_ - keep));
    if (Status s = file_.readAt(offset_ + keep, buffer_.data() + keep, ask); !s.ok()) return s;
    view_ = std::string_view(buffer_.data(), keep + ask);
    return Status::Ok();
  }

 private:
  InputFile file_;
  std::string buffer_;
  std::string_view view_;
  uint64_t offset_ = 0, size_ = 0;
  size_t block_ = 0;
};

Status notFinite(std::string_view name, uint64_t index, const std::string& where) {
  return Status::InvalidArgument(
      fmt::format("{}: point {} ({}) has a coordinate that is not a finite number", name, index, where));
}

Status tooMany(std::string_view name, uint64_t count, uint64_t limit) {
  return Status::ResourceExhausted(
      fmt::format("{}: {} points, more than the limit of {}", name, count, limit));
}

class NpyPoints final : public PointCloudReader {
 public:
  NpyPoints(Source source, std::string name) : src_(std::move(source)), name_(std::move(name)) {}

  Status open(const PointReadLimits& limits) {
    if (Status s = src_.fill(std::min<uint64_t>(src_.size(), kMaxHeader)); !s.ok()) return s;
    NpyArray header;
    size_t data_offset = 0;
    uint64_t payload = 0;
    if (Status s = parseNpyHeader(src_.view(), name_, &header, &data_offset, &payload); !s.ok()) return s;
    if (header.descr == "<f4" || header.descr == "=f4") item_ = 4;
    else if (header.descr == "<f8" || header.descr == "=f8") item_ = 8;
    else
      return Status::InvalidArgument(fmt::format(
          "{}: points must have dtype little-endian float32 or float64 ('<f4', '<f8'), got '{}'", name_,
          textExcerpt(header.descr)));
    if (header.fortran_order)
      return Status::InvalidArgument(fmt::format("{}: fortran_order arrays are not accepted (save a C-order array)", name_));
    if (header.shape.size() != 2 || header.shape[1] != 3)
      return Status::InvalidArgument(fmt::format("{}: points must be an array of shape (N, 3)", name_));
    count_ = uint64_t(header.shape[0]);
    const uint64_t have = src_.size() - data_offset;
    if (have != payload)
      return Status::InvalidArgument(fmt::format("{}: shape ({}, 3) needs {} data bytes, the file holds {}", name_,
                                                 count_, payload, have));
    if (count_ > limits.max_points) return tooMany(name_, count_, limits.max_points);
    src_.consume(data_offset);
    return Status::Ok();
  }

  std::optional<uint64_t> declaredCount() const override { return count_; }
  bool doublePrecision() const override { return item_ == 8; }
  uint64_t pointsRead() const override { return read_; }

  Status next(size_t max_points, std::vector<Vec3d>* out) override {
    const size_t record = 3 * item_;
    size_t n = size_t(std::min<uint64_t>(max_points, count_ - read_));
    while (n > 0) {
      const size_t batch = std::min(n, size_t(1) << 16);
      if (Status s = src_.fill(batch * record); !s.ok()) return s;
      if (src_.view().size() < batch * record)
        return Status::InvalidArgument(fmt::format("{}: the data ends inside point {}", name_, read_));
      const char* p = src_.view().data();
      for (size_t i = 0; i < batch; ++i, p += record) {
        double v[3];
        for (int k = 0; k < 3; ++k) {
          if (item_ == 4) {
            float f;
            std::memcpy(&f, p + 4 * k, 4);
            v[k] = f;
          } else {
            std::memcpy(&v[k], p + 8 * k, 8);
          }
        }
        if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]))
          return notFinite(name_, read_ + i, fmt::format("byte {}", src_.offset() + i * record));
        out->push_back({v[0], v[1], v[2]});
      }
      src_.consume(batch * record);
      read_ += batch;
      n -= batch;
    }
    return Status::Ok();
  }

 private:
  Source src_;
  std::string name_;
  size_t item_ = 4;
  uint64_t count_ = 0, read_ = 0;
};

class XyzPoints final : public PointCloudReader {
 public:
  XyzPoints(Source source, std::string name, uint64_t max_points)
      : src_(std::move(source)), name_(std::move(name)), max_points_(max_points) {}

  std::optional<uint64_t> declaredCount() const override { return std::nullopt; }
  bool doublePrecision() const override { return true; }
  uint64_t pointsRead() const override { return read_; }

  Status next(size_t max_points, std::vector<Vec3d>* out) override {
    for (size_t added = 0; added < max_points;) {
      std::string_view line;
      bool end = false;
      if (Status s = nextLine(&line, &end); !s.ok()) return s;
      if (end) return Status::Ok();
      std::string_view rest = line;
      const std::string_view first = nextToken(&rest);
      if (first.empty() || first.front() == '#') continue;
      rest = line;
      double v[3] = {0, 0, 0};
      int columns = 0;
      for (std::string_view token = nextToken(&rest); !token.empty(); token = nextToken(&rest), ++columns) {
        double value;
        if (!parseDouble(token, &value))
          return Status::InvalidArgument(fmt::format("{}: line {}: '{}' is not a finite number", name_, line_,
                                                     textExcerpt(token)));
        if (columns < 3) v[columns] = value;
      }
      if (columns < 3)
        return Status::InvalidArgument(
            fmt::format("{}: line {}: expected x y z, found {} number{}", name_, line_, columns, columns == 1 ? "" : "s"));
      if (columns_ == 0) columns_ = columns;
      if (columns != columns_)
        return Status::InvalidArgument(fmt::format("{}: line {}: {} numbers, but the first point's line has {}", name_,
                                                   line_, columns, columns_));
      if (read_ >= max_points_) return tooMany(name_, read_ + 1, max_points_);
      out->push_back({v[0], v[1], v[2]});
      ++read_;
      ++added;
    }
    return Status::Ok();
  }

 private:
  Status nextLine(std::string_view* line, bool* end) {
    size_t eol = src_.view().find('\n');
    if (eol == std::string_view::npos) {
      if (Status s = src_.fill(kMaxLine + 1); !s.ok()) return s;
      eol = src_.view().find('\n');
    }
    if (eol == std::string_view::npos) {
      if (src_.view().size() > kMaxLine)
        return Status::InvalidArgument(fmt::format("{}: line {} is longer than 64 KiB", name_, line_ + 1));
      if (src_.view().empty()) {
        *end = true;
        return Status::Ok();
      }
      eol = src_.view().size();
    }
    if (eol > kMaxLine) return Status::InvalidArgument(fmt::format("{}: line {} is longer than 64 KiB", name_, line_ + 1));
    *line = src_.view().substr(0, eol);
    // The line stays valid until the next fill: it is consumed now, parsed before the next call.
    src_.consume(std::min(eol + 1, src_.view().size()));
    ++line_;
    return Status::Ok();
  }

  Source src_;
  std::string name_;
  uint64_t max_points_;
  uint64_t read_ = 0, line_ = 0;
  int columns_ = 0;
};

class PlyPoints final : public PointCloudReader {
 public:
  PlyPoints(Source source, std::string name) : src_(std::move(source)), name_(std::move(name)) {}

  Status open(const PointReadLimits& limits) {
    if (Status s = src_.fill(std::min<uint64_t>(src_.size(), kMaxHeader)); !s.ok()) return s;
    std::vector<ply::Element> elements;
    size_t data_offset = 0;
    if (Status s = ply::parseHeader(src_.view(), &encoding_, &elements, &data_offset, &line_); !s.ok())
      return s.withPrefix(name_);
    ++line_;
    src_.consume(data_offset);
    auto vertex = std::find_if(elements.begin(), elements.end(), [](const ply::Element& e) { return e.name == "vertex"; });
    if (vertex == elements.end()) return Status::InvalidArgument(fmt::format("{}: PLY: no 'vertex' element", name_));
    if (vertex->x < 0 || vertex->y < 0 || vertex->z < 0)
      return Status::InvalidArgument(fmt::format("{}: PLY: element 'vertex' lacks a scalar x, y or z property", name_));
    vertex_ = *vertex;
    double_ = vertex_.properties[size_t(vertex_.x)].type == ply::Type::kFloat64;
    // What the header declares must fit in the bytes that follow it (ascii: at least a digit and a separator per
    // value), before any limit applies and before anything is read.
    uint64_t need = 0;
    for (auto e = elements.begin(); e <= vertex; ++e) {
      uint64_t record = 0;
      for (const ply::Property& p : e->properties)
        record += encoding_ == ply::Encoding::kAscii ? 2 : ply::sizeOf(p.list ? p.count_type : p.type);
      if (record > 0 && e->count > (src_.remaining() + 1 - std::min(need, src_.remaining() + 1)) / record)
        return Status::InvalidArgument(fmt::format(
            "{}: PLY element '{}': the header declares {} records of at least {} bytes but only {} bytes of data follow",
            name_, textExcerpt(e->name), e->count, record, src_.remaining()));
      need += e->count * record;
    }
    if (vertex_.count > limits.max_points) return tooMany(name_, vertex_.count, limits.max_points);
    for (auto e = elements.begin(); e != vertex; ++e) {
      if (e->properties.empty()) continue;  // records of no bytes: any count (the bytes bound none) skips at once
      for (uint64_t r = 0; r < e->count; ++r)
        if (Status s = readRecord(*e, r, nullptr); !s.ok()) return s;
    }
    return Status::Ok();
  }

  std::optional<uint64_t> declaredCount() const override { return vertex_.count; }
  bool doublePrecision() const override { return double_; }
  uint64_t pointsRead() const override { return read_; }

  Status next(size_t max_points, std::vector<Vec3d>* out) override {
    const size_t n = size_t(std::min<uint64_t>(max_points, vertex_.count - read_));
    for (size_t i = 0; i < n; ++i) {
      Vec3d p;
      if (Status s = readRecord(vertex_, read_, &p); !s.ok()) return s;
      out->push_back(p);
      ++read_;
    }
    return Status::Ok();
  }

 private:
  std::string where() const {
    return encoding_ == ply::Encoding::kAscii ? fmt::format("line {}", line_) : fmt::format("byte {}", src_.offset());
  }

  /// One value of property `p` of record `record` of `e` (`what`: "", "count" or "item", for messages).
  Status readValue(ply::Type t, double* d, int64_t* i, const ply::Element& e, uint64_t record, const ply::Property& p,
                   const char* what) {
    auto fail = [&](const std::string& bad) {
      return Status::InvalidArgument(
          bad.empty() ? fmt::format("{}: PLY element '{}' {} ({}): the data ends inside property '{}' {}", name_,
                                    textExcerpt(e.name), record, where(), textExcerpt(p.name), what)
                      : fmt::format("{}: PLY element '{}' {} ({}): property '{}' {} '{}' is not a finite number of its type",
                                    name_, textExcerpt(e.name), record, where(), textExcerpt(p.name), what, bad));
    };
    if (encoding_ != ply::Encoding::kAscii) {
      const size_t n = ply::sizeOf(t);
      if (Status s = src_.fill(n); !s.ok()) return s;
      if (src_.view().size() < n) return fail("");
      ply::Cursor::decode(t, reinterpret_cast<const unsigned char*>(src_.view().data()), encoding_, d, i);
      src_.consume(n);
      return Status::Ok();
    }
    // Ascii: skip white space (counting lines), then one token of at most 256 bytes.
    for (;;) {
      if (Status s = src_.fill(512); !s.ok()) return s;
      const std::string_view v = src_.view();
      size_t k = 0;
      while (k < v.size() && (isSpace(v[k]) || v[k] == '\n')) line_ += v[k++] == '\n';
      src_.consume(k);
      if (k < v.size() || src_.remaining() == 0) break;
    }
    if (Status s = src_.fill(512); !s.ok()) return s;
    const std::string_view v = src_.view();
    size_t e_end = 0;
    while (e_end < v.size() && !isSpace(v[e_end]) && v[e_end] != '\n') ++e_end;
    const std::string_view token = v.substr(0, e_end);
    if (token.empty()) return fail("");
    const bool ok = ply::isInteger(t) ? parseInt(token, i) : parseDouble(token, d);
    if (!ok || token.size() > 256) return fail(textExcerpt(token));
    if (ply::isInteger(t)) *d = double(*i);
    src_.consume(e_end);
    return Status::Ok();
  }

  /// One record of `e`; the vertex's x, y, z into `point` when given.
  Status readRecord(const ply::Element& e, uint64_t record, Vec3d* point) {
    double xyz[3] = {0, 0, 0};
    for (int pi = 0; pi < int(e.properties.size()); ++pi) {
      const ply::Property& p = e.properties[size_t(pi)];
      double d = 0;
      int64_t i = 0;
      if (!p.list) {
        if (Status s = readValue(p.type, &d, &i, e, record, p, ""); !s.ok()) return s;
        if (pi == e.x) xyz[0] = d;
        if (pi == e.y) xyz[1] = d;
        if (pi == e.z) xyz[2] = d;
        continue;
      }
      if (Status s = readValue(p.count_type, &d, &i, e, record, p, "count"); !s.ok()) return s;
      const uint64_t item_bytes = encoding_ == ply::Encoding::kAscii ? 2 : ply::sizeOf(p.type);
      if (i < 0 || uint64_t(i) > (src_.remaining() + 1) / item_bytes)
        return Status::InvalidArgument(fmt::format("{}: PLY element '{}' {} ({}): list '{}' declares {} items but only {} bytes follow",
                                                   name_, textExcerpt(e.name), record, where(), textExcerpt(p.name), i,
                                                   src_.remaining()));
      for (int64_t k = 0, n = i; k < n; ++k)
        if (Status s = readValue(p.type, &d, &i, e, record, p, "item"); !s.ok()) return s;
    }
    if (point) {
      if (!std::isfinite(xyz[0]) || !std::isfinite(xyz[1]) || !std::isfinite(xyz[2]))
        return notFinite(name_, record, where());
      *point = {xyz[0], xyz[1], xyz[2]};
    }
    return Status::Ok();
  }

  Source src_;
  std::string name_;
  ply::Encoding encoding_ = ply::Encoding::kAscii;
  ply::Element vertex_;
  bool double_ = false;
  uint64_t line_ = 0, read_ = 0;
};

Status open(Source source, PointFileFormat format, const PointReadLimits& limits, std::string name,
            std::unique_ptr<PointCloudReader>* out) {
  switch (format) {
    case PointFileFormat::kNpy: {
      auto r = std::make_unique<NpyPoints>(std::move(source), std::move(name));
      if (Status s = r->open(limits); !s.ok()) return s;
      *out = std::move(r);
      return Status::Ok();
    }
    case PointFileFormat::kXyz:
      *out = std::make_unique<XyzPoints>(std::move(source), std::move(name), limits.max_points);
      return Status::Ok();
    case PointFileFormat::kPly: {
      auto r = std::make_unique<PlyPoints>(std::move(source), std::move(name));
      if (Status s = r->open(limits); !s.ok()) return s;
      *out = std::move(r);
      return Status::Ok();
    }
  }
  return Status::InvalidArgument("unknown point file format");
}

Status readAll(PointCloudReader& reader, const Interrupter* interrupter, std::vector<Vec3d>* points) {
  std::vector<Vec3d> all;
  if (const std::optional<uint64_t> n = reader.declaredCount()) all.reserve(size_t(*n));
  for (;;) {
    if (isInterrupted(interrupter)) return interrupter->status();
    const size_t before = all.size();
    if (Status s = reader.next(kPollEvery, &all); !s.ok()) return s;
    if (all.size() == before) break;
  }
  *points = std::move(all);
  return Status::Ok();
}

}  // namespace

PointCloudReader::~PointCloudReader() = default;

std::string_view pointFileFormatName(PointFileFormat format) {
  switch (format) {
    case PointFileFormat::kNpy: return "npy";
    case PointFileFormat::kXyz: return "xyz";
    case PointFileFormat::kPly: return "ply";
  }
  return "?";
}

bool pointFileFormatFromPath(std::string_view path, PointFileFormat* format) {
  const size_t dot = path.rfind('.');
  if (dot == std::string_view::npos) return false;
  std::string ext(path.substr(dot + 1));
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (ext == "npy") *format = PointFileFormat::kNpy;
  else if (ext == "xyz" || ext == "txt") *format = PointFileFormat::kXyz;
  else if (ext == "ply") *format = PointFileFormat::kPly;
  else return false;
  return true;
}

Status PointCloudReader::fromBytes(std::string_view bytes, PointFileFormat format, const PointReadLimits& limits,
                                   std::string_view name, std::unique_ptr<PointCloudReader>* out) {
  return open(Source::memory(bytes), format, limits, std::string(name), out);
}

Status PointCloudReader::fromFile(const std::string& path, PointFileFormat format, const PointReadLimits& limits,
                                  std::unique_ptr<PointCloudReader>* out) {
  Source source;
  if (Status s = Source::file(path, limits.block_bytes, &source); !s.ok()) return s;
  return open(std::move(source), format, limits, path, out);
}

Status readPointCloud(std::string_view bytes, PointFileFormat format, const PointReadLimits& limits,
                      std::string_view name, const Interrupter* interrupter, std::vector<Vec3d>* points) {
  std::unique_ptr<PointCloudReader> reader;
  if (Status s = PointCloudReader::fromBytes(bytes, format, limits, name, &reader); !s.ok()) return s;
  return readAll(*reader, interrupter, points);
}

Status loadPointCloud(const std::string& path, const PointReadLimits& limits, const Interrupter* interrupter,
                      std::vector<Vec3d>* points) {
  PointFileFormat format;
  if (!pointFileFormatFromPath(path, &format))
    return Status::InvalidArgument(
        fmt::format("{}: unknown point file format (expected .npy, .xyz, .txt or .ply)", path));
  std::unique_ptr<PointCloudReader> reader;
  if (Status s = PointCloudReader::fromFile(path, format, limits, &reader); !s.ok()) return s;
  return readAll(*reader, interrupter, points);
}

}  // namespace distband
