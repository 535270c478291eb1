// image.cpp — colors, the heatmap legend (drawn with draw.hpp's 3x5 pixel font) and PNG output.
#include <png.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <string>

#include "draw.hpp"
#include "render_internal.hpp"
#include "sdfprune/io.hpp"

namespace sdfprune {

vec3 background(float v) {
    const float t = std::clamp(0.5f + 0.5f * v, 0.0f, 1.0f);
    return vec3(0.62f, 0.66f, 0.74f) * (1 - t) + vec3(0.86f, 0.89f, 0.94f) * t;
}

vec3 heat_color(double value, double top) {
    const double t = top > 0 ? std::clamp(std::log1p(value) / std::log1p(top), 0.0, 1.0) : 0.0;
    // Black -> purple -> red -> orange -> pale yellow.
    static const vec3 stops[5] = {{0.0f, 0.0f, 0.04f},
                                  {0.33f, 0.06f, 0.5f},
                                  {0.8f, 0.18f, 0.3f},
                                  {0.98f, 0.55f, 0.04f},
                                  {1.0f, 1.0f, 0.62f}};
    const double x = t * 4;
    const int i = std::min(int(x), 3);
    const float f = float(x - i);
    const vec3 c = stops[i] * (1 - f) + stops[i + 1] * f;
    // Stored linear: to_rgb8 applies the sRGB curve; undo it so the ramp is as designed.
    return {std::pow(c.x, 2.2f), std::pow(c.y, 2.2f), std::pow(c.z, 2.2f)};
}

const uint8_t* rgb8_curve() {
    // The sRGB-like curve through a table: pow per channel would cost as much as tracing.
    static const std::vector<uint8_t> curve = [] {
        std::vector<uint8_t> t(kRgb8CurveSteps + 1);
        for (int i = 0; i <= kRgb8CurveSteps; ++i)
            t[i] = uint8_t(std::lround(std::pow(float(i) / kRgb8CurveSteps, 1.0f / 2.2f) * 255.0f));
        return t;
    }();
    return curve.data();
}

void to_rgb8(const std::vector<vec3>& color, Image& img) {
    const uint8_t* curve = rgb8_curve();
    for (size_t i = 0; i < color.size(); ++i) store_rgb8(curve, color[i], &img.rgb[3 * i]);
}

namespace {

std::string compact_number(double v) {
    char buf[32];
    if (v >= 1e6)
        std::snprintf(buf, sizeof buf, "%.1fM", v / 1e6);
    else if (v >= 1e4)
        std::snprintf(buf, sizeof buf, "%.0fk", v / 1e3);
    else
        std::snprintf(buf, sizeof buf, "%.0f", v);
    return buf;
}

}  // namespace

void draw_heatmap_legend(Image& img, double top) {
    using draw::fill;
    using draw::text;
    const int scale = std::max(1, int(img.height) / 270);
    const int bar_w = 60 * scale, bar_h = 6 * scale, pad = 4 * scale;
    const int x0 = int(img.width) - bar_w - 6 * pad,
              y0 = int(img.height) - bar_h - 12 * scale - 3 * pad;
    fill(img, x0 - pad, y0 - pad, bar_w + 2 * pad, bar_h + 12 * scale + 3 * pad, vec3(0.08f));
    for (int x = 0; x < bar_w; ++x) {
        const double value = std::expm1(double(x) / (bar_w - 1) * std::log1p(top));
        vec3 c = heat_color(value, top);
        c = {std::pow(c.x, 1 / 2.2f), std::pow(c.y, 1 / 2.2f), std::pow(c.z, 1 / 2.2f)};
        fill(img, x0 + x, y0, 1, bar_h, c);
    }
    const vec3 white(0.95f);
    const int ty = y0 + bar_h + pad;
    text(img, x0, ty, scale, "0", white);
    const std::string hi = compact_number(top);
    text(img, x0 + bar_w - int(hi.size()) * 4 * scale, ty, scale, hi, white);
    const std::string label = "node evals/pixel";
    text(img, x0 + (bar_w - int(label.size()) * 4 * scale) / 2, ty + 6 * scale, scale, label,
         white);
}

void write_png(const Image& img, const std::string& path) {
    write_atomic_with(path, [&](const std::string& tmp) {
        FILE* f = std::fopen(tmp.c_str(), "wb");
        if (!f) throw IoError(path + ": cannot create");
        png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
        png_infop info = png ? png_create_info_struct(png) : nullptr;
        if (!png || !info || setjmp(png_jmpbuf(png))) {
            png_destroy_write_struct(&png, &info);
            std::fclose(f);
            throw IoError(path + ": PNG encoding failed");
        }
        png_init_io(png, f);
        png_set_IHDR(png, info, img.width, img.height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
                     PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
        png_write_info(png, info);
        for (uint32_t y = 0; y < img.height; ++y)
            png_write_row(png, img.rgb.data() + size_t(y) * img.width * 3);
        png_write_end(png, nullptr);
        png_destroy_write_struct(&png, &info);
        if (std::fclose(f) != 0) throw IoError(path + ": write failed");
    });
}

namespace {
void append_png_bytes(png_structp png, png_bytep data, png_size_t length) {
    auto* out = static_cast<std::vector<uint8_t>*>(png_get_io_ptr(png));
    out->insert(out->end(), data, data + length);
}
void flush_nothing(png_structp) {}
}  // namespace

std::vector<uint8_t> encode_png(const Image& img, int level) {
    std::vector<uint8_t> out;
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    if (!png || !info || setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        throw IoError("PNG encoding failed");
    }
    png_set_write_fn(png, &out, append_png_bytes, flush_nothing);
    png_set_compression_level(png, std::clamp(level, 0, 9));
    png_set_IHDR(png, info, img.width, img.height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    for (uint32_t y = 0; y < img.height; ++y)
        png_write_row(png, img.rgb.data() + size_t(y) * img.width * 3);
    png_write_end(png, nullptr);
    png_destroy_write_struct(&png, &info);
    return out;
}

}  // namespace sdfprune
