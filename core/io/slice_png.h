// Slice PNG: writes one axis-aligned slice of a distance field as a colour-mapped 8-bit RGB PNG for people,
// annotated with its position, a colour bar and the units, so the picture can be read on its own.
// Contract:
//   * The field is given as a sampling function over the voxels of a Grid (or as a DenseField). Only the voxels
//     of the requested slice are sampled, once each, on the calling thread.
//   * Colour map (diverging, saturating): a value v maps to t = clamp(v / limit, -1, 1); t < 0 (inside) blends
//     from white to kSliceInsideColour, t > 0 (outside) from white to kSliceOutsideColour; |v| >= limit is the
//     full colour. Non-finite values are drawn kSliceInvalidColour. A limit that is not finite and positive
//     becomes the largest finite |value| in the slice (1 if there is none); the bar is labelled with that limit.
//   * Zero contour (black): between every pair of 4-neighbours in the slice whose signs differ (v < 0 versus
//     v >= 0), the voxel nearer zero (ties: the inside one) is drawn black — a one-voxel line on the side of the
//     true surface. A distance field is 1-Lipschitz, so a real crossing has |a - b| <= h; pairs that jump by
//     more than `contour_max_jump_world` (default 2h) are background/limit seams, not surfaces, and are skipped.
//   * Orientation: for axis z the image's columns are x and its rows y; for axis y, columns x and rows z; for
//     axis x, columns y and rows z. Row 0 (the top) is the largest row coordinate, so "up" is +row axis, as in
//     a plot. Every voxel becomes a scale x scale block of pixels.
//   * Picture layout, top to bottom, on a white margin: the title strip ("[prefix  |  ]z = 64 (world 0.532)  |
//     distance, world units": axis, voxel index and world coordinate of the slice plane), the slice in a grey
//     frame, then a horizontal colour bar in the slice's colour map with tick labels below it (-limit, 0, limit
//     for a signed field; 0, limit/2, limit for an unsigned one, whose bar starts at white) and a legend line
//     with the units and a swatch of the zero-contour colour. The slice's pixels are exactly those of the bare
//     slice, offset by SlicePngInfo::slice; with neither title nor bar the image is the bare slice alone. Text
//     is the 5x7 bitmap font (core/io/bitmap_font.h) at SlicePngInfo::text_scale: 1 below 256 slice pixels on
//     the longer edge, 2 up to 1023, then growing by one per 512 pixels, at most 4.
//   * Size: the whole image, decorations included, stays within kSliceMaxImageEdge on both edges; a slice that
//     cannot fit is an error. A title wider than that is cut off at the image edge.
//   * The file is written to a temporary file in the same directory and renamed over `path`, so an
//     interrupted run never leaves a partial PNG.
//   * Errors come back as a Status, never thrown: kInvalidArgument for a bad grid, axis, index or option (a slice
//     spec that does not parse, an index outside the grid, a negative scale, a NaN contour jump, no sampler);
//     kResourceExhausted when the picture would exceed kSliceMaxImageEdge; kIoError when the OS cannot create,
//     write or rename the file (libpng's write errors included); kInternal when libpng cannot set itself up.
//   * Limited fields: a DenseField holds +background everywhere not delivered, so its inside beyond the limit
//     shows as outside (the contour check above keeps that seam out of the contour). A VdbFieldBuilder grid after
//     finish() (signed flood fill) reads -background there; sample it with
//     [&builder](const Coord& c) { return builder.value(c); }, for correct inside colours.
// Thread-safety: the functions are re-entrant; the sampler is called from the calling thread only.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

#include "core/io/dense_field.h"
#include "core/io/bitmap_font.h"
#include "core/grid.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

inline constexpr Rgb8 kSliceInsideColour{33, 102, 172};   ///< saturated negative (inside) colour
inline constexpr Rgb8 kSliceOutsideColour{178, 24, 43};   ///< saturated positive (outside) colour
inline constexpr Rgb8 kSliceZeroColour{255, 255, 255};    ///< colour at distance 0
inline constexpr Rgb8 kSliceContourColour{0, 0, 0};       ///< the zero contour
inline constexpr Rgb8 kSliceInvalidColour{128, 128, 128}; ///< NaN / infinite samples
inline constexpr Rgb8 kSliceMarginColour{255, 255, 255};  ///< background around the slice and the bar
inline constexpr Rgb8 kSliceFrameColour{150, 150, 150};   ///< frame around the slice and the bar
inline constexpr Rgb8 kSliceTextColour{20, 20, 20};       ///< title, tick labels and tick marks

/// Largest image edge (pixels) the writer produces; protects against absurd scale requests.
inline constexpr int kSliceMaxImageEdge = 16384;

/// An axis-aligned slice: axis 0 = x, 1 = y, 2 = z; index is the voxel index along that axis.
struct SliceSpec {
  int axis = 2;
  int index = 0;
};

/// Parses "AXIS:INDEX" (axis x|y|z, case-insensitive; index a non-negative integer, or "mid" for the middle
/// slice, resolved against a grid by resolveSlice). Returns OK, or kInvalidArgument saying why not (`spec` is then
/// untouched). A "mid" index is stored as -1.
Status parseSliceSpec(std::string_view text, SliceSpec* spec);

/// Checks the slice against the grid (and resolves index -1 = "mid" to dims/2). Returns OK, or kInvalidArgument
/// for an axis other than 0..2 or an index outside the grid.
Status resolveSlice(const Grid& grid, SliceSpec* spec);

/// Which colour bar a field gets: -limit..limit (signed) or 0..limit (unsigned).
enum class SliceSign {
  kAuto,      ///< signed when the slice holds a finite negative value
  kSigned,
  kUnsigned,
};

struct SlicePngOptions {
  /// Distance (world units) at which the colours saturate. <= 0 or non-finite: the largest finite |value| in
  /// the slice (1 if the slice is all zero).
  double limit_world = 0;
  /// Pixels per voxel along each axis. 0: automatic — the smallest factor making the slice's longer edge at
  /// least 512 pixels, capped at 16.
  int scale = 0;
  bool draw_contour = true;
  /// Largest |a - b| (world units) of a sign-changing neighbour pair that still counts as a zero crossing.
  /// <= 0: 2 * voxel size. Infinity: every sign change is drawn.
  double contour_max_jump_world = 0;
  /// Title strip above the slice; `title_prefix` (e.g. the input file name) leads it when not empty.
  bool draw_title = true;
  std::string title_prefix;
  /// Colour bar, tick labels and legend below the slice.
  bool draw_colour_bar = true;
  SliceSign sign = SliceSign::kAuto;
  /// Units of the distances, shown in the title and the legend.
  std::string units = "world units";
};

/// A rectangle of pixels, row 0 at the top of the image.
struct PixelRect {
  int left = 0, top = 0, width = 0, height = 0;
};

/// What was written (for logs and tests).
struct SlicePngInfo {
  int width = 0, height = 0;  ///< whole image size in pixels
  int scale = 1;              ///< pixels per voxel used
  double limit_world = 0;     ///< saturation distance used
  int64_t contour_voxels = 0; ///< voxels drawn as zero contour
  PixelRect slice;            ///< where the slice's pixels are
  PixelRect title;            ///< the title's text line (empty without a title; cut off past the image edge)
  PixelRect bar;              ///< the colour bar's gradient, without its frame (empty without a bar)
  bool signed_bar = true;     ///< the bar spans -limit..limit (else 0..limit)
  int text_scale = 1;         ///< pixels per font pixel
};

using VoxelSampler = std::function<float(const Coord&)>;

/// Maps a value to its colour (exposed so tests and docs share the exact map).
Rgb8 sliceColour(float value, double limit_world);

/// Writes the slice `spec` of the field `sample` over `grid` to `path`. Returns OK or a Status with the codes above.
Status writeSlicePng(const std::string& path, const Grid& grid, const VoxelSampler& sample, SliceSpec spec,
                     const SlicePngOptions& options = {}, SlicePngInfo* info = nullptr);

/// Same for a dense field (its own grid).
Status writeSlicePng(const std::string& path, const DenseField& field, SliceSpec spec,
                     const SlicePngOptions& options = {}, SlicePngInfo* info = nullptr);

}  // namespace distband
