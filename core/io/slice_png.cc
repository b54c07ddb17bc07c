#include "core/io/slice_png.h"

#include <png.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <vector>

#include <fmt/format.h>

#include "core/io/temp_file.h"

namespace distband {
namespace {

constexpr const char* kAxisNames = "xyz";

/// The two in-slice axes (column axis, row axis) for a slice normal to `axis`.
void sliceAxes(int axis, int* col_axis, int* row_axis) {
  switch (axis) {
    case 0: *col_axis = 1; *row_axis = 2; break;
    case 1: *col_axis = 0; *row_axis = 2; break;
    default: *col_axis = 0; *row_axis = 1; break;
  }
}

int component(const Coord& c, int axis) { return axis == 0 ? c.x : axis == 1 ? c.y : c.z; }
void setComponent(Coord* c, int axis, int v) { (axis == 0 ? c->x : axis == 1 ? c->y : c->z) = v; }

uint8_t blend(uint8_t a, uint8_t b, double t) { return uint8_t(std::lround(a + (double(b) - a) * t)); }

struct PngErrorState {
  char message[256] = {0};
};

void pngError(png_structp png, png_const_charp msg) {
  auto* state = static_cast<PngErrorState*>(png_get_error_ptr(png));
  std::snprintf(state->message, sizeof state->message, "%s", msg ? msg : "unknown libpng error");
  png_longjmp(png, 1);
}
void pngWarning(png_structp, png_const_charp) {}

/// Encodes an RGB8 image into an open FILE. Kept free of C++ objects with destructors between setjmp and any
/// longjmp (libpng's error path), as setjmp requires.
std::string encodePng(std::FILE* file, int width, int height, png_bytepp rows) {
  PngErrorState state;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &state, pngError, pngWarning);
  if (!png) return "libpng: cannot create write struct";
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_write_struct(&png, nullptr);
    return "libpng: cannot create info struct";
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return std::string("libpng: ") + state.message;
  }
  png_init_io(png, file);
  png_set_IHDR(png, info, png_uint_32(width), png_uint_32(height), 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  png_write_image(png, rows);
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return {};
}

/// Writes through a temporary file in the target's directory, then renames it over `path`.
std::string writePngAtomically(const std::string& path, int width, int height, std::vector<uint8_t>& pixels) {
  std::vector<png_bytep> rows(static_cast<size_t>(height));
  for (int r = 0; r < height; ++r) rows[size_t(r)] = pixels.data() + size_t(r) * size_t(width) * 3;

  std::string tmp;
  std::FILE* file = nullptr;
  if (std::string err = openTempBeside(path, "wb", &tmp, &file); !err.empty()) return err;
  return commitTemp(file, tmp, path, encodePng(file, width, height, rows.data()));
}

}  // namespace

std::string parseSliceSpec(std::string_view text, SliceSpec* spec) {
  const size_t colon = text.find(':');
  if (colon == std::string_view::npos)
    return fmt::format("slice must be AXIS:INDEX with AXIS x, y or z (got '{}')", text);
  const std::string_view axis = text.substr(0, colon);
  const std::string_view index = text.substr(colon + 1);
  if (axis.size() != 1 || !std::strchr(kAxisNames, std::tolower(static_cast<unsigned char>(axis[0]))) ||
      axis[0] == '\0')
    return fmt::format("slice axis must be x, y or z (got '{}')", axis);
  SliceSpec out;
  out.axis = int(std::strchr(kAxisNames, std::tolower(static_cast<unsigned char>(axis[0]))) - kAxisNames);
  if (index == "mid") {
    out.index = -1;
  } else {
    int value = 0;
    const auto [end, ec] = std::from_chars(index.data(), index.data() + index.size(), value);
    if (index.empty() || ec != std::errc() || end != index.data() + index.size() || value < 0)
      return fmt::format("slice index must be a non-negative integer or 'mid' (got '{}')", index);
    out.index = value;
  }
  *spec = out;
  return {};
}

std::string resolveSlice(const Grid& grid, SliceSpec* spec) {
  if (spec->axis < 0 || spec->axis > 2) return fmt::format("slice axis must be 0, 1 or 2 (got {})", spec->axis);
  const int extent = component(grid.dims(), spec->axis);
  if (spec->index == -1) spec->index = extent / 2;
  if (spec->index < 0 || spec->index >= extent)
    return fmt::format("slice index {}:{} is outside the grid (valid: 0..{} along {})", kAxisNames[spec->axis],
                       spec->index, extent - 1, kAxisNames[spec->axis]);
  return {};
}

Rgb8 sliceColour(float value, double limit_world) {
  if (!std::isfinite(value)) return kSliceInvalidColour;
  const double t = std::clamp(double(value) / limit_world, -1.0, 1.0);
  const Rgb8& end = t < 0 ? kSliceInsideColour : kSliceOutsideColour;
  const double a = std::abs(t);
  return {blend(kSliceZeroColour[0], end[0], a), blend(kSliceZeroColour[1], end[1], a),
          blend(kSliceZeroColour[2], end[2], a)};
}

std::string writeSlicePng(const std::string& path, const Grid& grid, const VoxelSampler& sample, SliceSpec spec,
                          const SlicePngOptions& options, SlicePngInfo* info) {
  if (std::string err = grid.validate(); !err.empty()) return "slice grid: " + err;
  if (!sample) return "slice: no field to sample";
  if (std::string err = resolveSlice(grid, &spec); !err.empty()) return err;
  if (options.scale < 0) return fmt::format("slice scale must be >= 0 (got {})", options.scale);
  if (std::isnan(options.contour_max_jump_world)) return "slice contour_max_jump_world must not be NaN";

  int col_axis = 0, row_axis = 1;
  sliceAxes(spec.axis, &col_axis, &row_axis);
  const int cols = component(grid.dims(), col_axis);
  const int rows = component(grid.dims(), row_axis);

  int scale = options.scale;
  if (scale == 0) {
    const int edge = std::max(cols, rows);
    scale = std::clamp((512 + edge - 1) / edge, 1, 16);
  }
  if (int64_t(cols) * scale > kSliceMaxImageEdge || int64_t(rows) * scale > kSliceMaxImageEdge)
    return fmt::format("slice image {}x{} voxels at scale {} exceeds the {}-pixel edge limit", cols, rows, scale,
                       kSliceMaxImageEdge);

  // Sample the slice once: values[r * cols + c], r = row coordinate (not yet flipped).
  std::vector<float> values(size_t(cols) * size_t(rows));
  double max_abs = 0;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      Coord p;
      setComponent(&p, spec.axis, spec.index);
      setComponent(&p, col_axis, c);
      setComponent(&p, row_axis, r);
      const float v = sample(p);
      values[size_t(r) * cols + c] = v;
      if (std::isfinite(v)) max_abs = std::max(max_abs, double(std::abs(v)));
    }

  double limit = options.limit_world;
  if (!(std::isfinite(limit) && limit > 0)) limit = max_abs > 0 ? max_abs : 1.0;

  // Zero contour: for each sign-changing 4-neighbour pair, mark the voxel nearer zero.
  std::vector<uint8_t> contour(values.size(), 0);
  int64_t contour_voxels = 0;
  if (options.draw_contour) {
    const double max_jump =
        options.contour_max_jump_world > 0 ? options.contour_max_jump_world : 2.0 * grid.voxelSize();
    auto consider = [&](size_t a, size_t b) {
      const float va = values[a], vb = values[b];
      if (!std::isfinite(va) || !std::isfinite(vb)) return;
      if ((va < 0) == (vb < 0)) return;
      if (std::abs(double(va) - double(vb)) > max_jump) return;
      const float aa = std::abs(va), ab = std::abs(vb);
      const size_t pick = aa < ab ? a : ab < aa ? b : (va < 0 ? a : b);
      if (!contour[pick]) {
        contour[pick] = 1;
        ++contour_voxels;
      }
    };
    for (int r = 0; r < rows; ++r)
      for (int c = 0; c < cols; ++c) {
        const size_t i = size_t(r) * cols + c;
        if (c + 1 < cols) consider(i, i + 1);
        if (r + 1 < rows) consider(i, i + size_t(cols));
      }
  }

  const int width = cols * scale, height = rows * scale;
  std::vector<uint8_t> pixels(size_t(width) * size_t(height) * 3);
  for (int r = 0; r < rows; ++r) {
    const int top = (rows - 1 - r) * scale;  // flip: largest row coordinate at the top
    for (int c = 0; c < cols; ++c) {
      const size_t i = size_t(r) * cols + c;
      const Rgb8 colour = contour[i] ? kSliceContourColour : sliceColour(values[i], limit);
      for (int dy = 0; dy < scale; ++dy) {
        uint8_t* px = pixels.data() + (size_t(top + dy) * width + size_t(c) * scale) * 3;
        for (int dx = 0; dx < scale; ++dx, px += 3) std::memcpy(px, colour.data(), 3);
      }
    }
  }

  if (std::string err = writePngAtomically(path, width, height, pixels); !err.empty()) return err;
  if (info) *info = {width, height, scale, limit, contour_voxels};
  return {};
}

std::string writeSlicePng(const std::string& path, const DenseField& field, SliceSpec spec,
                          const SlicePngOptions& options, SlicePngInfo* info) {
  return writeSlicePng(
      path, field.grid(), [&field](const Coord& c) { return field.at(c); }, spec, options, info);
}

}  // namespace distband
