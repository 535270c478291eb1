// draw.cpp — rectangles, anti-aliased lines and a 3x5 pixel font on 8-bit RGB images (the
// heatmap legend and the benchmark plots).
#include "draw.hpp"

#include <algorithm>
#include <cmath>

namespace sdfprune::draw {

uint16_t glyph(char ch) {
    // One row of 3 bits per octal digit, top row first.
    // clang-format off
    switch (ch) {
        case '0': return 075557; case '1': return 026227; case '2': return 071747;
        case '3': return 071717; case '4': return 055711; case '5': return 074717;
        case '6': return 074757; case '7': return 071111; case '8': return 075757;
        case '9': return 075711;
        case 'A': return 025755; case 'B': return 065656; case 'C': return 034443;
        case 'D': return 065556; case 'E': return 074647; case 'F': return 074644;
        case 'G': return 034553; case 'H': return 055755; case 'I': return 072227;
        case 'J': return 011152; case 'K': return 055655; case 'L': return 044447;
        case 'M': return 057755; case 'N': return 065555; case 'O': return 025552;
        case 'P': return 065644; case 'Q': return 025563; case 'R': return 065655;
        case 'S': return 034216; case 'T': return 072222; case 'U': return 055557;
        case 'V': return 055552; case 'W': return 055775; case 'X': return 055255;
        case 'Y': return 055222; case 'Z': return 071247;
        case 'a': return 007357; case 'b': return 044656; case 'c': return 003443;
        case 'd': return 017557; case 'e': return 003743; case 'f': return 034644;
        case 'g': return 003536; case 'h': return 044755; case 'i': return 020222;
        case 'j': return 010152; case 'k': return 045655; case 'l': return 062227;
        case 'm': return 007755; case 'n': return 006555; case 'o': return 007557;
        case 'p': return 006564; case 'q': return 035311; case 'r': return 005644;
        case 's': return 007637; case 't': return 027223; case 'u': return 005553;
        case 'v': return 005552; case 'w': return 005577; case 'x': return 005255;
        case 'y': return 055316; case 'z': return 007247;
        case '.': return 000002; case '/': return 011244; case '-': return 000700;
        case '+': return 002720; case '(': return 024442; case ')': return 021112;
        case ':': return 002020; case ',': return 000024; case '_': return 000007;
        case '%': return 051245; case '=': return 007070; case '*': return 052500;
        case '^': return 025000;
        default: return 0;
    }
    // clang-format on
}

int text_width(std::string_view s, int scale) {
    return s.empty() ? 0 : (int(s.size()) * kGlyphAdvance - 1) * scale;
}

void fill(Image& img, int x0, int y0, int w, int h, vec3 c) {
    for (int y = std::max(0, y0); y < std::min<int>(int(img.height), y0 + h); ++y)
        for (int x = std::max(0, x0); x < std::min<int>(int(img.width), x0 + w); ++x)
            for (int k = 0; k < 3; ++k)
                img.rgb[3 * (size_t(y) * img.width + x) + k] =
                    uint8_t(std::lround(std::clamp(c[k], 0.0f, 1.0f) * 255));
}

void blend(Image& img, int x, int y, vec3 c, float a) {
    if (x < 0 || y < 0 || x >= int(img.width) || y >= int(img.height) || !(a > 0)) return;
    a = std::min(a, 1.0f);
    uint8_t* p = &img.rgb[3 * (size_t(y) * img.width + x)];
    for (int k = 0; k < 3; ++k)
        p[k] = uint8_t(std::lround(float(p[k]) * (1 - a) + std::clamp(c[k], 0.0f, 1.0f) * 255 * a));
}

void text(Image& img, int x, int y, int scale, std::string_view s, vec3 c) {
    for (char ch : s) {
        const uint16_t g = glyph(ch);
        for (int row = 0; row < kGlyphHeight; ++row)
            for (int col = 0; col < 3; ++col)
                if (g >> ((4 - row) * 3 + (2 - col)) & 1)
                    fill(img, x + col * scale, y + row * scale, scale, scale, c);
        x += kGlyphAdvance * scale;
    }
}

void text_vertical(Image& img, int x, int y, int scale, std::string_view s, vec3 c) {
    // Character i occupies rows [y + W − (i+1)·advance, ...) where W is the text's width.
    int bottom = y + text_width(s, scale);
    for (char ch : s) {
        const uint16_t g = glyph(ch);
        for (int row = 0; row < kGlyphHeight; ++row)
            for (int col = 0; col < 3; ++col)
                if (g >> ((4 - row) * 3 + (2 - col)) & 1)
                    fill(img, x + row * scale, bottom - (col + 1) * scale, scale, scale, c);
        bottom -= kGlyphAdvance * scale;
    }
}

void line(Image& img, float x0, float y0, float x1, float y1, float width, vec3 c) {
    const float r = 0.5f * width;
    const int xa = int(std::floor(std::min(x0, x1) - r - 1)),
              xb = int(std::ceil(std::max(x0, x1) + r + 1));
    const int ya = int(std::floor(std::min(y0, y1) - r - 1)),
              yb = int(std::ceil(std::max(y0, y1) + r + 1));
    const float dx = x1 - x0, dy = y1 - y0, len2 = dx * dx + dy * dy;
    for (int y = std::max(0, ya); y <= std::min(int(img.height) - 1, yb); ++y)
        for (int x = std::max(0, xa); x <= std::min(int(img.width) - 1, xb); ++x) {
            // Distance from the pixel centre to the segment; coverage falls off over one pixel.
            const float px = float(x) + 0.5f - x0, py = float(y) + 0.5f - y0;
            const float t = len2 > 0 ? std::clamp((px * dx + py * dy) / len2, 0.0f, 1.0f) : 0.0f;
            const float ex = px - t * dx, ey = py - t * dy;
            const float d = std::sqrt(ex * ex + ey * ey);
            blend(img, x, y, c, std::clamp(r + 0.5f - d, 0.0f, 1.0f));
        }
}

}  // namespace sdfprune::draw
