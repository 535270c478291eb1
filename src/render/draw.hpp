// draw.hpp — minimal raster drawing on an 8-bit RGB Image, shared by the heatmap legend
// (image.cpp) and the benchmark plots (src/bench/plot.cpp): filled rectangles, lines and text
// in a 3x5 pixel font. Colors are display values in [0, 1] (no sRGB curve applied).
// Everything clips to the image; nothing allocates.
#pragma once

#include <cstdint>
#include <string_view>

#include "sdfprune/render.hpp"

namespace sdfprune::draw {

// Width of one character cell at scale 1, in pixels (3 for the glyph, 1 for spacing); a glyph is
// 5 pixels tall.
inline constexpr int kGlyphAdvance = 4;
inline constexpr int kGlyphHeight = 5;

// The 3x5 bitmap of a character: 15 bits, 3 bits per row, top row in the high bits. Digits,
// letters (lower case drawn as small letters where legible, else as capitals), space and
// . / - + ( ) : , _ % = * ^ ; 0 (blank) for anything else.
uint16_t glyph(char ch);

// Width in pixels of `s` drawn at `scale` (without the trailing spacing column).
int text_width(std::string_view s, int scale);

void fill(Image& img, int x0, int y0, int w, int h, vec3 c);
// Blends `c` over pixel (x, y) with coverage a in [0, 1].
void blend(Image& img, int x, int y, vec3 c, float a);
// Text with its top-left corner at (x, y), each font pixel a scale x scale square.
void text(Image& img, int x, int y, int scale, std::string_view s, vec3 c);
// The same text turned 90° counter-clockwise (reads bottom to top), its top-left corner at (x, y).
void text_vertical(Image& img, int x, int y, int scale, std::string_view s, vec3 c);
// An anti-aliased line of the given width (pixels) between two points.
void line(Image& img, float x0, float y0, float x1, float y1, float width, vec3 c);

}  // namespace sdfprune::draw
