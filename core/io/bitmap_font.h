// Bitmap font: a fixed 5x7-pixel font for short labels drawn into 8-bit RGB images (slice PNG titles and
// colour bars), so pictures carry their own annotations without a font library.
// Contract:
//   * Glyphs exist for the digits, a-z, A-Z, space and . - + = ( ) , : | / _ (bitmapFontCharacters()). Any
//     other byte is drawn as a hollow box, so a missing glyph is visible instead of silently dropped.
//   * A glyph is kGlyphWidth x kGlyphHeight font pixels; each font pixel becomes a scale x scale block.
//     Characters advance kGlyphAdvance * scale pixels (one blank column between glyphs). One line, no kerning.
//   * Drawing writes only the glyphs' set pixels (the background stays) and clips to the image.
// Thread-safety: functions over caller-owned images; the glyph table is immutable.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace distband {

using Rgb8 = std::array<uint8_t, 3>;

inline constexpr int kGlyphWidth = 5;
inline constexpr int kGlyphHeight = 7;
inline constexpr int kGlyphAdvance = kGlyphWidth + 1;

/// An 8-bit RGB image: row-major, 3 bytes per pixel, row 0 at the top.
struct RgbImage {
  RgbImage(int width, int height, Rgb8 background);
  uint8_t* pixel(int x, int y) { return rgb.data() + (size_t(y) * size_t(width) + size_t(x)) * 3; }
  /// Fills the rectangle [x, x + w) x [y, y + h), clipped to the image.
  void fillRect(int x, int y, int w, int h, Rgb8 colour);

  int width = 0, height = 0;
  std::vector<uint8_t> rgb;
};

/// The characters with a glyph of their own, in table order.
std::string bitmapFontCharacters();

/// Width in pixels of `text` drawn at `scale` (no trailing blank column); 0 for empty text.
int textWidth(std::string_view text, int scale);

/// Draws `text` with its top-left corner at (x, y).
void drawText(RgbImage* image, int x, int y, std::string_view text, int scale, Rgb8 colour);

}  // namespace distband
