#include "core/io/slice_png.h"

#include <png.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string_view>
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

/// "[prefix  |  ]z = 64 (world 0.532)  |  distance, world units"
std::string sliceTitle(const Grid& grid, const SliceSpec& spec, const SlicePngOptions& options) {
  Coord plane;
  setComponent(&plane, spec.axis, spec.index);
  const Vec3d world = grid.worldOf(plane);
  const double position = spec.axis == 0 ? world.x : spec.axis == 1 ? world.y : world.z;
  const std::string where = fmt::format("{} = {} (world {:.5g})  |  distance, {}", kAxisNames[spec.axis],
                                        spec.index, position, options.units);
  return options.title_prefix.empty() ? where : options.title_prefix + "  |  " + where;
}

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
/// longjmp (libpng's error path), as setjmp requires. kInternal when libpng cannot allocate its structures;
/// kIoError for an error while writing (the image itself is valid by construction, so that is the file failing).
Status encodePng(std::FILE* file, int width, int height, png_bytepp rows) {
  PngErrorState state;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &state, pngError, pngWarning);
  if (!png) return Status::Internal("libpng: cannot create write struct");
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_write_struct(&png, nullptr);
    return Status::Internal("libpng: cannot create info struct");
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return Status::IoError(std::string("libpng: ") + state.message);
  }
  png_init_io(png, file);
  png_set_IHDR(png, info, png_uint_32(width), png_uint_32(height), 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  png_write_image(png, rows);
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return Status::Ok();
}

/// Writes through a temporary file in the target's directory, then renames it over `path`.
Status writePngAtomically(const std::string& path, RgbImage& image) {
  const int width = image.width, height = image.height;
  std::vector<png_bytep> rows(static_cast<size_t>(height));
  for (int r = 0; r < height; ++r) rows[size_t(r)] = image.pixel(0, r);

  std::string tmp;
  std::FILE* file = nullptr;
  if (Status s = openTempBeside(path, "wb", &tmp, &file); !s.ok()) return s;
  return commitTemp(file, tmp, path, encodePng(file, width, height, rows.data()));
}

/// Glyph scale for the annotations, from the slice's longer pixel edge (see the header's layout paragraph).
int textScaleFor(int slice_width, int slice_height) {
  const int longer = std::max(slice_width, slice_height);
  return longer < 256 ? 1 : std::clamp(longer / 512 + 1, 2, 4);
}

constexpr std::string_view kContourLegend = "zero contour";

/// The colour bar's range and its three tick values with their labels.
struct BarScale {
  double low = 0, high = 0;
  std::array<double, 3> ticks{};
  std::array<std::string, 3> labels;
};

BarScale barScale(double limit, bool signed_bar) {
  BarScale bar;
  bar.low = signed_bar ? -limit : 0.0;
  bar.high = limit;
  bar.ticks = {bar.low, (bar.low + bar.high) / 2, bar.high};
  for (size_t i = 0; i < 3; ++i) bar.labels[i] = fmt::format("{:.4g}", bar.ticks[i]);
  return bar;
}

/// Where everything goes in the picture.
struct Layout {
  int width = 0, height = 0;
  int text_scale = 1;
  int frame = 0;  ///< frame thickness around the slice and the bar
  PixelRect title, slice, bar;
  int tick_length = 0;
  int labels_top = 0;  ///< top of the tick labels' line
  int legend_top = 0;  ///< top of the units / zero-contour line
  int swatch_width = 0;
};

Layout layOut(int slice_width, int slice_height, const SlicePngOptions& options, const std::string& title,
              const BarScale& bar, bool signed_bar) {
  Layout l;
  const int s = l.text_scale = textScaleFor(slice_width, slice_height);
  const bool decorated = options.draw_title || options.draw_colour_bar;
  const int pad = decorated ? 6 * s : 0;
  const int line = kGlyphHeight * s;
  const int gap = 2 * kGlyphAdvance * s;  // between texts on one line
  l.frame = decorated ? std::max(1, s / 2) : 0;
  int y = pad;
  if (options.draw_title) {
    l.title = {pad, y, textWidth(title, s), line};
    y += line + pad;
  }
  l.slice = {pad + l.frame, y + l.frame, slice_width, slice_height};
  y += slice_height + 2 * l.frame;
  int content_width = slice_width;
  if (options.draw_colour_bar) {
    l.swatch_width = 3 * kGlyphAdvance * s;
    const int labels_width =
        textWidth(bar.labels[0], s) + textWidth(bar.labels[1], s) + textWidth(bar.labels[2], s) + 2 * gap;
    const int legend_width = textWidth(options.units, s) + gap + l.swatch_width + kGlyphAdvance * s +
                             textWidth(kContourLegend, s);
    int bar_width = std::max({slice_width, labels_width, legend_width});
    if (signed_bar) bar_width |= 1;  // odd, so the middle column is exactly 0 (white)
    y += pad;
    l.bar = {pad + l.frame, y + l.frame, bar_width, 2 * line};
    y += l.bar.height + 2 * l.frame;
    l.tick_length = 3 * s;
    l.labels_top = y + l.tick_length + s;
    l.legend_top = l.labels_top + line + pad;
    y = l.legend_top + line;
    content_width = std::max(content_width, bar_width);
  }
  l.height = y + pad;
  l.width = content_width + 2 * (pad + l.frame);
  // A long title widens the picture up to the edge limit and is cut off beyond it.
  if (options.draw_title) l.width = std::max(l.width, std::min(kSliceMaxImageEdge, l.title.width + 2 * pad));
  return l;
}

/// The colour bar, its ticks, tick labels and legend (units, zero-contour swatch).
void drawColourBar(RgbImage* image, const Layout& l, const BarScale& bar, double limit, const std::string& units) {
  const int s = l.text_scale;
  const PixelRect& r = l.bar;
  image->fillRect(r.left - l.frame, r.top - l.frame, r.width + 2 * l.frame, r.height + 2 * l.frame,
                  kSliceFrameColour);
  // Column i shows low + (high - low) * i / (width - 1): both ends exact.
  auto columnOf = [&](double v) { return int(std::lround((v - bar.low) / (bar.high - bar.low) * (r.width - 1))); };
  for (int i = 0; i < r.width; ++i) {
    const double v = bar.low + (bar.high - bar.low) * i / (r.width - 1);
    image->fillRect(r.left + i, r.top, 1, r.height, sliceColour(float(v), limit));
  }
  const int ticks_top = r.top + r.height + l.frame;
  const int right = r.left + r.width;
  for (size_t t = 0; t < 3; ++t) {
    const int x = r.left + columnOf(bar.ticks[t]);
    image->fillRect(x - (s - 1) / 2, ticks_top, s, l.tick_length, kSliceTextColour);
    // Labels sit under their ticks; the end ones are aligned to the bar's ends so they stay inside the image.
    const int w = textWidth(bar.labels[t], s);
    const int label_left = t == 0 ? r.left : t == 2 ? right - w : x - w / 2;
    drawText(image, label_left, l.labels_top, bar.labels[t], s, kSliceTextColour);
  }
  drawText(image, r.left, l.legend_top, units, s, kSliceTextColour);
  const int legend_text_left = right - textWidth(kContourLegend, s);
  const int swatch_left = legend_text_left - kGlyphAdvance * s - l.swatch_width;
  image->fillRect(swatch_left, l.legend_top + 2 * s, l.swatch_width, 3 * s, kSliceContourColour);
  drawText(image, legend_text_left, l.legend_top, kContourLegend, s, kSliceTextColour);
}

}  // namespace

Status parseSliceSpec(std::string_view text, SliceSpec* spec) {
  const size_t colon = text.find(':');
  if (colon == std::string_view::npos)
    return Status::InvalidArgument(fmt::format("slice must be AXIS:INDEX with AXIS x, y or z (got '{}')", text));
  const std::string_view axis = text.substr(0, colon);
  const std::string_view index = text.substr(colon + 1);
  if (axis.size() != 1 || !std::strchr(kAxisNames, std::tolower(static_cast<unsigned char>(axis[0]))) ||
      axis[0] == '\0')
    return Status::InvalidArgument(fmt::format("slice axis must be x, y or z (got '{}')", axis));
  SliceSpec out;
  out.axis = int(std::strchr(kAxisNames, std::tolower(static_cast<unsigned char>(axis[0]))) - kAxisNames);
  if (index == "mid") {
    out.index = -1;
  } else {
    int value = 0;
    const auto [end, ec] = std::from_chars(index.data(), index.data() + index.size(), value);
    if (index.empty() || ec != std::errc() || end != index.data() + index.size() || value < 0)
      return Status::InvalidArgument(
          fmt::format("slice index must be a non-negative integer or 'mid' (got '{}')", index));
    out.index = value;
  }
  *spec = out;
  return Status::Ok();
}

Status resolveSlice(const Grid& grid, SliceSpec* spec) {
  if (spec->axis < 0 || spec->axis > 2)
    return Status::InvalidArgument(fmt::format("slice axis must be 0, 1 or 2 (got {})", spec->axis));
  const int extent = component(grid.dims(), spec->axis);
  if (spec->index == -1) spec->index = extent / 2;
  if (spec->index < 0 || spec->index >= extent)
    return Status::InvalidArgument(fmt::format("slice index {}:{} is outside the grid (valid: 0..{} along {})",
                                               kAxisNames[spec->axis], spec->index, extent - 1,
                                               kAxisNames[spec->axis]));
  return Status::Ok();
}

Rgb8 sliceColour(float value, double limit_world) {
  if (!std::isfinite(value)) return kSliceInvalidColour;
  const double t = std::clamp(double(value) / limit_world, -1.0, 1.0);
  const Rgb8& end = t < 0 ? kSliceInsideColour : kSliceOutsideColour;
  const double a = std::abs(t);
  return {blend(kSliceZeroColour[0], end[0], a), blend(kSliceZeroColour[1], end[1], a),
          blend(kSliceZeroColour[2], end[2], a)};
}

Status writeSlicePng(const std::string& path, const Grid& grid, const VoxelSampler& sample, SliceSpec spec,
                     const SlicePngOptions& options, SlicePngInfo* info) {
  if (Status s = grid.validate(); !s.ok()) return s.withPrefix("slice grid");
  if (!sample) return Status::InvalidArgument("slice: no field to sample");
  if (Status s = resolveSlice(grid, &spec); !s.ok()) return s;
  if (options.scale < 0)
    return Status::InvalidArgument(fmt::format("slice scale must be >= 0 (got {})", options.scale));
  if (std::isnan(options.contour_max_jump_world))
    return Status::InvalidArgument("slice contour_max_jump_world must not be NaN");

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
    return Status::ResourceExhausted(fmt::format("slice image {}x{} voxels at scale {} exceeds the {}-pixel edge limit",
                                                 cols, rows, scale, kSliceMaxImageEdge));

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
        options.contour_max_jump_world > 0 ? options.contour_max_jump_world
                                           : 2.0 * grid.voxelSize() * grid.maxAxisScale();
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

  bool signed_bar = options.sign == SliceSign::kSigned;
  if (options.sign == SliceSign::kAuto)
    signed_bar = std::any_of(values.begin(), values.end(), [](float v) { return std::isfinite(v) && v < 0; });
  const BarScale bar = barScale(limit, signed_bar);
  const std::string title = sliceTitle(grid, spec, options);
  const Layout layout = layOut(cols * scale, rows * scale, options, title, bar, signed_bar);
  if (layout.width > kSliceMaxImageEdge || layout.height > kSliceMaxImageEdge)
    return Status::ResourceExhausted(
        fmt::format("slice image {}x{} voxels at scale {} needs {}x{} pixels with its title and colour bar, "
                    "which exceeds the {}-pixel edge limit",
                    cols, rows, scale, layout.width, layout.height, kSliceMaxImageEdge));

  RgbImage image(layout.width, layout.height, kSliceMarginColour);
  const PixelRect& area = layout.slice;
  image.fillRect(area.left - layout.frame, area.top - layout.frame, area.width + 2 * layout.frame,
                 area.height + 2 * layout.frame, kSliceFrameColour);
  for (int r = 0; r < rows; ++r) {
    const int top = area.top + (rows - 1 - r) * scale;  // flip: largest row coordinate at the top
    for (int c = 0; c < cols; ++c) {
      const size_t i = size_t(r) * cols + c;
      const Rgb8 colour = contour[i] ? kSliceContourColour : sliceColour(values[i], limit);
      image.fillRect(area.left + c * scale, top, scale, scale, colour);
    }
  }
  if (options.draw_title)
    drawText(&image, layout.title.left, layout.title.top, title, layout.text_scale, kSliceTextColour);
  if (options.draw_colour_bar) drawColourBar(&image, layout, bar, limit, options.units);

  if (Status s = writePngAtomically(path, image); !s.ok()) return s;
  if (info)
    *info = {.width = layout.width, .height = layout.height, .scale = scale, .limit_world = limit,
             .contour_voxels = contour_voxels, .slice = layout.slice, .title = layout.title, .bar = layout.bar,
             .signed_bar = signed_bar, .text_scale = layout.text_scale};
  return Status::Ok();
}

Status writeSlicePng(const std::string& path, const DenseField& field, SliceSpec spec,
                     const SlicePngOptions& options, SlicePngInfo* info) {
  return writeSlicePng(
      path, field.grid(), [&field](const Coord& c) { return field.at(c); }, spec, options, info);
}

}  // namespace distband
