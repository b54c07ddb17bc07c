#include "client/brick_sink.h"

#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>

#include "core/io/dense_field.h"
#include "core/io/nifti.h"
#include "core/io/npy.h"
#include "core/io/vdb_writer.h"

namespace distband {
namespace {

class NpyBrickSink : public BrickSink {
 public:
  NpyBrickSink(std::string path, const FieldLayout& layout)
      : path_(std::move(path)), field_(layout.grid, layout.background), sign_from_band_(layout.sign_from_band) {
    if (sign_from_band_) delivered_.assign(size_t(layout.grid.voxelCount()), 0);
    if (layout.signed_distance && layout.inside) {
      std::vector<float>& v = field_.values();
      layout.inside.visit([&](const auto* in) {
        const size_t n = std::min(v.size(), size_t(layout.inside.voxelCount()));
        for (size_t i = 0; i < n; ++i)
          if (in[i]) v[i] = -layout.background;
      });
    }
  }
  void add(const SegmentBricks& segment) override {
    field_.add(segment);
    if (!sign_from_band_) return;
    for (const Brick& b : segment.bricks)
      for (int i = 0; i < kBrickVoxels; ++i)
        if (b.mask.test(i)) {
          const Coord c = b.origin + brickLocal(i);
          if (field_.grid().contains(c)) delivered_[field_.grid().denseIndex(c)] = 1;
        }
  }
  Status finish() override {
    if (sign_from_band_) fillSignsAlongRows();
    if (nifti_) {
      VolumeGeometry g;
      g.spacing = field_.grid().spacing();
      g.origin = field_.grid().origin();
      g.affine = affine_;
      return writeNiftiField(path_, field_.values(), field_.grid().dims(), g);
    }
    return writeNpyFloat32(path_, field_.values(), field_.grid().dims());
  }
  std::string description() const override {
    const Coord d = field_.grid().dims();
    if (nifti_) return fmt::format("{} (NIfTI float32, {}x{}x{})", path_, d.x, d.y, d.z);
    return fmt::format("{} (float32, shape (Z, Y, X) = ({}, {}, {}))", path_, d.z, d.y, d.x);
  }
  /// Writes a .nii.gz with `affine` (unset: the grid's) instead of a .npy.
  void asNifti(const std::optional<std::array<std::array<double, 4>, 3>>& affine) {
    nifti_ = true;
    affine_ = affine;
  }

 private:
  // Undelivered voxels (+background) between delivered ones take the sign of the nearest delivered voxel before
  // them in their x row (after them at the row's start); rows with none stay positive.
  void fillSignsAlongRows() {
    const Coord d = field_.grid().dims();
    std::vector<float>& v = field_.values();
    for (int64_t row = 0; row < int64_t(d.y) * d.z; ++row) {
      const int64_t base = row * d.x;
      float sign = 0;
      for (int x = 0; x < d.x && sign == 0; ++x)
        if (delivered_[base + x]) sign = v[base + x] < 0 ? -1.f : 1.f;
      if (sign == 0) continue;
      for (int x = 0; x < d.x; ++x) {
        if (delivered_[base + x]) sign = v[base + x] < 0 ? -1.f : 1.f;
        else v[base + x] = sign * std::fabs(v[base + x]);
      }
    }
  }

  std::string path_;
  DenseField field_;
  bool sign_from_band_;
  std::vector<uint8_t> delivered_;
  bool nifti_ = false;
  std::optional<std::array<std::array<double, 4>, 3>> affine_;
};

/// An OpenVDB level set (class level set, background = the limit, negative inside), streamed leaf by leaf.
class VdbBrickSink : public BrickSink {
 public:
  VdbBrickSink(std::string path, const FieldLayout& layout) : path_(std::move(path)), builder_(layout.grid, layout.background) {}
  void add(const SegmentBricks& segment) override { builder_.add(segment); }
  Status finish() override { return builder_.write(path_); }
  std::string description() const override {
    return fmt::format("{} (OpenVDB level set \"distance\", {} active voxels)", path_, builder_.activeVoxels());
  }

 private:
  std::string path_;
  VdbFieldBuilder builder_;
};

bool endsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

/// "" if `path` can be created or overwritten, without touching it.
std::string checkWritable(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path p(path);
  if (fs::is_directory(p, ec)) return fmt::format("{}: is a directory", path);
  if (fs::exists(p, ec)) {
    if (::access(path.c_str(), W_OK) != 0) return fmt::format("{}: not writable: {}", path, std::strerror(errno));
    return {};
  }
  const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
  if (!fs::is_directory(dir, ec)) return fmt::format("{}: directory '{}' does not exist", path, dir.string());
  if (::access(dir.c_str(), W_OK) != 0)
    return fmt::format("{}: directory '{}' is not writable: {}", path, dir.string(), std::strerror(errno));
  return {};
}

}  // namespace

std::string checkOutputPath(const std::string& flag, const std::string& path,
                            std::initializer_list<const char*> extensions) {
  if (path.empty()) return fmt::format("{}: the path is empty", flag);
  bool known = false;
  std::string list;
  for (const char* e : extensions) {
    known |= endsWith(path, e);
    list += (list.empty() ? "" : ", ") + std::string(e);
  }
  if (!known) return fmt::format("{} {}: expected a {} file", flag, path, list);
  if (std::string err = checkWritable(path); !err.empty()) return fmt::format("{} {}", flag, err);
  return {};
}

std::string openBrickSink(const std::string& path, const FieldLayout& layout, std::unique_ptr<BrickSink>* out) {
  if (path.empty()) return "no output path given";
  const bool npy = endsWith(path, ".npy"), vdb = endsWith(path, ".vdb"), nii = endsWith(path, ".nii.gz");
  if (!npy && !vdb && !nii) return fmt::format("{}: unsupported output format (supported: .npy, .vdb, .nii.gz)", path);
  if (std::string err = checkWritable(path); !err.empty()) return err;
  if (Status s = layout.grid.validate(); !s.ok()) return s.message();
  if (nii) {
    auto sink = std::make_unique<NpyBrickSink>(path, layout);
    sink->asNifti(layout.affine);
    *out = std::move(sink);
  } else if (npy) {
    *out = std::make_unique<NpyBrickSink>(path, layout);
  } else {
    *out = std::make_unique<VdbBrickSink>(path, layout);
  }
  return {};
}

}  // namespace distband
