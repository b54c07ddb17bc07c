// Object File Format (ascii): a keyword ([ST][C][N]OFF), the counts `vertices faces edges` (on the keyword's line or
// on later ones, possibly split over lines), then one vertex per line (x y z, extra values such as colours ignored)
// and one face per line (`k i1 .. ik`, extra values ignored). '#' starts a comment. 4OFF, nOFF and binary OFF are
// refused. The counts are checked against the bytes that follow (a vertex line takes at least 6 bytes, a face line
// at least 2 per value) and against the limits before anything is allocated.
#include <fmt/format.h>

#include "core/mesh/internal/mesh_reader_parts.h"

namespace distband::mesh_internal {
namespace {

std::string at(uint64_t line) { return fmt::format("OFF line {}", line); }

std::string_view stripComment(std::string_view line) { return line.substr(0, line.find('#')); }

bool blank(std::string_view line) {
  for (char c : line)
    if (!isSpace(c)) return false;
  return true;
}

}  // namespace

Status readOff(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out) {
  LineReader lines(bytes);
  std::string_view line;
  // The keyword.
  std::string_view rest;
  for (;;) {
    if (!lines.next(&line)) return Status::InvalidArgument("OFF: the file has no OFF keyword");
    rest = stripComment(line);
    if (!blank(rest)) break;
  }
  const std::string_view keyword = nextToken(&rest);
  const bool known = keyword.size() >= 3 && keyword.substr(keyword.size() - 3) == "OFF" &&
                     keyword.substr(0, keyword.size() - 3).find_first_not_of("STCN") == std::string_view::npos;
  if (!known)
    return Status::InvalidArgument(fmt::format("{}: expected the OFF keyword ([ST][C][N]OFF), found '{}'",
                                               at(lines.number()), meshExcerpt(keyword)));
  // The counts: three integers, possibly spread over several lines.
  int64_t counts[3];
  int have = 0;
  while (have < 3) {
    const std::string_view t = nextToken(&rest);
    if (t.empty()) {
      if (!lines.next(&line))
        return Status::InvalidArgument(
            fmt::format("OFF: the file ends before the counts (vertices faces edges) are complete ({} of 3)", have));
      rest = stripComment(line);
      continue;
    }
    if (t == "BINARY") return Status::InvalidArgument(fmt::format("{}: binary OFF is not supported", at(lines.number())));
    if (!parseInt(t, &counts[have]) || counts[have] < 0)
      return Status::InvalidArgument(fmt::format("{}: the counts must be integers >= 0, found '{}'", at(lines.number()),
                                                 meshExcerpt(t)));
    ++have;
  }
  const int64_t nv = counts[0], nf = counts[1];
  if (!blank(rest))
    return Status::InvalidArgument(fmt::format("{}: unexpected '{}' after the counts", at(lines.number()),
                                               meshExcerpt(rest)));
  // "0 0 0" is the shortest vertex line and "3 0 1 2" the shortest triangle line; with line ends, at least 6 and 8.
  const uint64_t need = uint64_t(nv) * 6 + uint64_t(nf) * 8;
  if (uint64_t(nv) > (uint64_t(1) << 40) || uint64_t(nf) > (uint64_t(1) << 40) || need > lines.remaining() + 2)
    return Status::InvalidArgument(fmt::format(
        "{}: the header declares {} vertices and {} faces (at least {} bytes) but only {} bytes follow", at(lines.number()),
        nv, nf, need, lines.remaining()));
  if (uint64_t(nv) > limits.max_vertices)
    return Status::ResourceExhausted(
        fmt::format("OFF: the header declares {} vertices, more than the server's limit of {}", nv, limits.max_vertices));
  if (uint64_t(nf) > limits.max_triangles)
    return Status::ResourceExhausted(
        fmt::format("OFF: the header declares {} faces, more than the server's limit of {}", nf, limits.max_triangles));
  out->vertices.reserve(size_t(nv));
  out->triangles.reserve(size_t(nf));

  auto nextDataLine = [&](std::string_view* data) {
    while (lines.next(&line)) {
      if (lines.number() % kPollEvery == 0 && isInterrupted(interrupter)) return false;
      *data = stripComment(line);
      if (!blank(*data)) return true;
    }
    return false;
  };
  std::string_view data;
  for (int64_t v = 0; v < nv; ++v) {
    if (!nextDataLine(&data)) {
      if (isInterrupted(interrupter)) return interrupter->status();
      return Status::InvalidArgument(
          fmt::format("OFF: the file ends after {} of the {} vertices the header declares", v, nv));
    }
    double c[3];
    for (double& x : c) {
      const std::string_view t = nextToken(&data);
      if (!parseDouble(t, &x))
        return Status::InvalidArgument(fmt::format("{}: vertex {} needs 3 finite numbers, found '{}'",
                                                   at(lines.number()), v, meshExcerpt(t)));
    }
    out->vertices.push_back({c[0], c[1], c[2]});
  }
  std::vector<uint32_t> corners;
  for (int64_t f = 0; f < nf; ++f) {
    if (!nextDataLine(&data)) {
      if (isInterrupted(interrupter)) return interrupter->status();
      return Status::InvalidArgument(fmt::format("OFF: the file ends after {} of the {} faces the header declares", f, nf));
    }
    const std::string_view size_text = nextToken(&data);
    int64_t k = 0;
    if (!parseInt(size_text, &k) || k < 0)
      return Status::InvalidArgument(fmt::format("{}: face {} must start with its corner count, found '{}'",
                                                 at(lines.number()), f, meshExcerpt(size_text)));
    // Each corner takes at least 2 bytes of this line: a count beyond that cannot be honoured.
    if (uint64_t(k) > data.size() / 2 + 1)
      return Status::InvalidArgument(fmt::format("{}: face {} declares {} corners but its line is {} bytes long",
                                                 at(lines.number()), f, k, data.size()));
    corners.clear();
    for (int64_t i = 0; i < k; ++i) {
      const std::string_view t = nextToken(&data);
      int64_t index = 0;
      if (t.empty())
        return Status::InvalidArgument(
            fmt::format("{}: face {} declares {} corners but lists {}", at(lines.number()), f, k, i));
      if (!parseInt(t, &index))
        return Status::InvalidArgument(
            fmt::format("{}: face {} corner '{}' is not an integer", at(lines.number()), f, meshExcerpt(t)));
      if (index < 0 || index >= nv)
        return Status::InvalidArgument(fmt::format("{}: face {} refers to vertex {} but the file has {} vertices",
                                                   at(lines.number()), f, index, nv));
      corners.push_back(uint32_t(index));
    }
    if (k < 3) {
      ++out->non_triangles;
    } else if (Status s = addFan(corners.data(), corners.size(), limits.max_triangles, at(lines.number()), out);
               !s.ok()) {
      return s;
    }
  }
  return Status::Ok();
}

}  // namespace distband::mesh_internal
