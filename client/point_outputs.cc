#include "client/point_outputs.h"

#include <set>

#include <fmt/format.h>

#include "client/brick_sink.h"

namespace distband {

void addPointOutputFlags(CLI::App* cmd, PointOutputFlags* f) {
  cmd->add_option("--out", f->out,
                  "Signed distances .npy, shape (N,): world units, negative inside, +-limit beyond it");
  cmd->add_option("--closest-points", f->closest_points, "Closest points .npy, shape (N, 3) (NaN beyond the limit)");
  cmd->add_option("--closest", f->closest,
                  "Closest feature ids .npy, shape (N,): triangle or seed point (int32), seed voxel (int64, its "
                  "linear index); -1 beyond the limit");
  cmd->add_option("--gradient", f->gradient,
                  "Gradients .npy, shape (N, 3): unit vectors, sign-aware (0 beyond the limit)");
}

std::string checkPointOutputFlags(const PointOutputFlags& f) {
  if (f.out.empty() && f.closest_points.empty() && f.closest.empty() && f.gradient.empty())
    return "nothing to write: give --out (or --closest-points, --closest, --gradient)";
  std::set<std::string> paths;
  for (const auto& [flag, path] : {std::pair<const char*, const std::string&>{"--out", f.out},
                                   {"--closest-points", f.closest_points},
                                   {"--closest", f.closest},
                                   {"--gradient", f.gradient}}) {
    if (path.empty()) continue;
    if (std::string e = checkOutputPath(flag, path, {".npy"}); !e.empty()) return e;
    if (!paths.insert(path).second) return fmt::format("{} {}: the path is named twice", flag, path);
  }
  return {};
}

PointOutputs pointOutputsOf(const PointOutputFlags& f) {
  return {!f.closest_points.empty(), !f.closest.empty(), !f.gradient.empty()};
}

Status PointFileOutputs::open(const PointOutputFlags& flags, const PointPacking& packing) {
  const char* values = packing.doubles ? "<f8" : "<f4";
  const struct {
    const std::string& path;
    const char* descr;
    int64_t columns;
  } files[4] = {{flags.out, values, 0},
                {flags.closest_points, values, 3},
                {flags.closest, packing.wide_ids ? "<i8" : "<i4", 0},
                {flags.gradient, values, 3}};
  for (int i = 0; i < 4; ++i) {
    if (files[i].path.empty()) continue;
    files_[size_t(i)] = std::make_unique<NpyRowWriter>();
    if (Status s = files_[size_t(i)]->open(files[i].path, files[i].descr, files[i].columns); !s.ok()) {
      abandon();
      return s;
    }
  }
  return Status::Ok();
}

Status PointFileOutputs::append(size_t n, std::string_view distance, std::string_view closest_points,
                                std::string_view features, std::string_view gradients) {
  const std::string_view data[4] = {distance, closest_points, features, gradients};
  for (size_t i = 0; i < 4; ++i)
    if (files_[i])
      if (Status s = files_[i]->append(data[i].data(), data[i].size(), int64_t(n)); !s.ok()) {
        abandon();
        return s;
      }
  rows_ += int64_t(n);
  return Status::Ok();
}

Status PointFileOutputs::finish(std::vector<std::string>* lines) {
  const char* what[4] = {"distances", "closest points", "closest feature ids", "gradients"};
  for (size_t i = 0; i < 4; ++i) {
    if (!files_[i]) continue;
    if (Status s = files_[i]->finish(); !s.ok()) {
      abandon();
      return s;
    }
    lines->push_back(fmt::format("wrote {} ({} rows of {})", files_[i]->path(), files_[i]->rows(), what[i]));
    files_[i].reset();
  }
  return Status::Ok();
}

void PointFileOutputs::abandon() {
  for (auto& f : files_)
    if (f) f->abandon(), f.reset();
}

}  // namespace distband
