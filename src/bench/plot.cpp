// plot.cpp — log-log line plots drawn into an Image (the benchmark's cost-versus-size curves):
// decade grid with labels, minor ticks, one polyline per series, legend.
#include "sdfprune/plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

#include "../render/draw.hpp"

namespace sdfprune {

std::string decade_label(int e) {
    static const char* const kPositive[] = {"1",   "10",   "100", "1k",  "10k",  "100k", "1M",
                                            "10M", "100M", "1G",  "10G", "100G", "1T"};
    if (e >= 0 && e < int(std::size(kPositive))) return kPositive[e];
    if (e < 0 && e >= -3) return "0." + std::string(size_t(-e - 1), '0') + "1";
    return "1e" + std::to_string(e);
}

namespace {

const vec3 kPalette[] = {{0.12f, 0.47f, 0.71f}, {0.89f, 0.45f, 0.05f}, {0.17f, 0.6f, 0.17f},
                         {0.84f, 0.15f, 0.16f}, {0.58f, 0.4f, 0.74f},  {0.55f, 0.34f, 0.29f},
                         {0.89f, 0.47f, 0.76f}, {0.4f, 0.4f, 0.4f}};

bool valid(double x, double y) {
    return std::isfinite(x) && std::isfinite(y) && x > 0 && y > 0;
}

// The axis range in log10 units: the options' when set, else the data's widened to decades.
void axis_range(double lo_opt, double hi_opt, double data_lo, double data_hi, double& lo,
                double& hi) {
    lo = lo_opt > 0 ? std::log10(lo_opt) : std::floor(std::log10(data_lo));
    hi = hi_opt > 0 ? std::log10(hi_opt) : std::ceil(std::log10(data_hi));
    if (!(hi > lo)) {
        lo = std::floor(lo) - (lo == std::floor(lo) ? 1 : 0);
        hi = std::max(hi, lo + 1);
        if (!(hi > lo)) hi = lo + 1;
    }
}

void marker(Image& img, float x, float y, int size, vec3 c, bool hollow) {
    const int x0 = int(std::lround(x)) - size / 2, y0 = int(std::lround(y)) - size / 2;
    draw::fill(img, x0, y0, size, size, c);
    if (hollow && size > 2)
        draw::fill(img, x0 + 1 + size / 6, y0 + 1 + size / 6, size - 2 - size / 3,
                   size - 2 - size / 3, vec3(1.0f));
}

}  // namespace

Image draw_loglog_plot(std::span<const PlotSeries> series, const PlotOptions& opt) {
    if (opt.width < 120 || opt.height < 90)
        throw std::invalid_argument("plot size must be at least 120x90");
    for (const PlotSeries& s : series)
        if (s.x.size() != s.y.size() || (!s.estimated.empty() && s.estimated.size() != s.x.size()))
            throw std::invalid_argument("plot series \"" + s.label + "\": sizes differ");
    Image img;
    img.width = opt.width;
    img.height = opt.height;
    img.rgb.assign(size_t(img.width) * img.height * 3, 255);

    // Data range over valid points (1..10 when there are none).
    double dx0 = std::numeric_limits<double>::max(), dx1 = 0, dy0 = dx0, dy1 = 0;
    bool any_estimated = false;
    for (const PlotSeries& s : series)
        for (size_t i = 0; i < s.x.size(); ++i) {
            if (!valid(s.x[i], s.y[i])) continue;
            dx0 = std::min(dx0, s.x[i]);
            dx1 = std::max(dx1, s.x[i]);
            dy0 = std::min(dy0, s.y[i]);
            dy1 = std::max(dy1, s.y[i]);
            any_estimated |= !s.estimated.empty() && s.estimated[i];
        }
    if (dx1 == 0) dx0 = dy0 = 1, dx1 = dy1 = 10;
    double lx0, lx1, ly0, ly1;
    axis_range(opt.x_min, opt.x_max, dx0, dx1, lx0, lx1);
    axis_range(opt.y_min, opt.y_max, dy0, dy1, ly0, ly1);

    const int s = std::max(1, int(std::min(img.width * 2 / 3, img.height) / 300));
    const int glyph_h = draw::kGlyphHeight * s, gap = 4 * s;
    const int left = gap + glyph_h + 2 * gap + draw::text_width("0.001", s) + gap;
    const int right = 6 * gap;
    const int top = opt.title.empty() ? 3 * gap : 3 * gap + glyph_h + 2 * gap;
    const int bottom = gap + glyph_h + 2 * gap + glyph_h + 2 * gap;
    const int px0 = left, px1 = int(img.width) - right, py0 = top, py1 = int(img.height) - bottom;
    const auto to_x = [&](double v) {
        return float(px0 + (std::log10(v) - lx0) / (lx1 - lx0) * (px1 - px0));
    };
    const auto to_y = [&](double v) {
        return float(py1 - (std::log10(v) - ly0) / (ly1 - ly0) * (py1 - py0));
    };
    const vec3 ink(0.15f), grid(0.87f), minor(0.6f);

    // Grid lines and labels at decades, minor ticks at 2..9 times each decade.
    const int label_every_x =
        std::max(1, int(std::ceil((draw::text_width("100k", s) + 2 * gap) /
                                  std::max(1.0, double(px1 - px0) / (lx1 - lx0)))));
    const int label_every_y = std::max(
        1, int(std::ceil((glyph_h + gap) / std::max(1.0, double(py1 - py0) / (ly1 - ly0)))));
    for (int e = int(std::floor(lx0)); e <= int(std::ceil(lx1)); ++e)
        for (int m = 1; m <= 9; ++m) {
            const double v = double(m) * std::pow(10.0, e);
            const float x = to_x(v);
            if (x < float(px0) - 0.01f || x > float(px1) + 0.01f) continue;
            const int xi = int(std::lround(x));
            if (m == 1) {
                draw::fill(img, xi, py0, 1, py1 - py0, grid);
                if (e % label_every_x == 0) {
                    const std::string l = decade_label(e);
                    draw::text(img, xi - draw::text_width(l, s) / 2, py1 + gap, s, l, ink);
                }
            }
            draw::fill(img, xi, py1 - (m == 1 ? 2 * gap : gap), 1, m == 1 ? 2 * gap : gap, minor);
        }
    for (int e = int(std::floor(ly0)); e <= int(std::ceil(ly1)); ++e)
        for (int m = 1; m <= 9; ++m) {
            const double v = double(m) * std::pow(10.0, e);
            const float y = to_y(v);
            if (y < float(py0) - 0.01f || y > float(py1) + 0.01f) continue;
            const int yi = int(std::lround(y));
            if (m == 1) {
                draw::fill(img, px0, yi, px1 - px0, 1, grid);
                if (e % label_every_y == 0) {
                    const std::string l = decade_label(e);
                    draw::text(img, px0 - gap - draw::text_width(l, s), yi - glyph_h / 2, s, l,
                               ink);
                }
            }
            draw::fill(img, px0, yi, m == 1 ? 2 * gap : gap, 1, minor);
        }
    // Frame, axis labels, title.
    draw::fill(img, px0, py0, px1 - px0 + 1, s, ink);
    draw::fill(img, px0, py1, px1 - px0 + 1, s, ink);
    draw::fill(img, px0, py0, s, py1 - py0 + 1, ink);
    draw::fill(img, px1, py0, s, py1 - py0 + 1, ink);
    draw::text(img, (px0 + px1 - draw::text_width(opt.x_label, s)) / 2,
               py1 + gap + glyph_h + 2 * gap, s, opt.x_label, ink);
    draw::text_vertical(img, gap, (py0 + py1 - draw::text_width(opt.y_label, s)) / 2, s,
                        opt.y_label, ink);
    if (!opt.title.empty())
        draw::text(img, (int(img.width) - draw::text_width(opt.title, s)) / 2, 3 * gap, s,
                   opt.title, ink);

    // Series: lines between consecutive valid points, then markers on top.
    const float line_w = 1.5f * float(s);
    const int marker_size = 3 * s + 1;
    for (size_t k = 0; k < series.size(); ++k) {
        const PlotSeries& ser = series[k];
        const vec3 c = kPalette[k % std::size(kPalette)];
        bool have = false;
        float x_prev = 0, y_prev = 0;
        for (size_t i = 0; i < ser.x.size(); ++i) {
            if (!valid(ser.x[i], ser.y[i])) continue;
            const float x = to_x(ser.x[i]), y = to_y(ser.y[i]);
            if (have) draw::line(img, x_prev, y_prev, x, y, line_w, c);
            have = true;
            x_prev = x;
            y_prev = y;
        }
        for (size_t i = 0; i < ser.x.size(); ++i)
            if (valid(ser.x[i], ser.y[i]))
                marker(img, to_x(ser.x[i]), to_y(ser.y[i]), marker_size, c,
                       !ser.estimated.empty() && ser.estimated[i]);
    }

    // Legend, top left inside the frame.
    const int rows = int(series.size()) + (any_estimated ? 1 : 0);
    if (rows > 0) {
        int w = 0;
        for (const PlotSeries& ser : series) w = std::max(w, draw::text_width(ser.label, s));
        const std::string note = "hollow: estimated";
        if (any_estimated) w = std::max(w, draw::text_width(note, s));
        const int row_h = glyph_h + 2 * gap, lx = px0 + 3 * gap, ly = py0 + 3 * gap;
        draw::fill(img, lx - gap, ly - gap, w + 8 * gap, rows * row_h + gap, ink);
        draw::fill(img, lx - gap + s, ly - gap + s, w + 8 * gap - 2 * s, rows * row_h + gap - 2 * s,
                   vec3(1.0f));
        for (size_t k = 0; k < series.size(); ++k) {
            const vec3 c = kPalette[k % std::size(kPalette)];
            const float yc = float(ly + int(k) * row_h + glyph_h / 2) + 0.5f;
            draw::line(img, float(lx), yc, float(lx + 4 * gap), yc, line_w, c);
            marker(img, float(lx + 2 * gap), yc, marker_size, c, false);
            draw::text(img, lx + 6 * gap, ly + int(k) * row_h, s, series[k].label, ink);
        }
        if (any_estimated) {
            const int yr = ly + int(series.size()) * row_h;
            marker(img, float(lx + 2 * gap), float(yr + glyph_h / 2) + 0.5f, marker_size, ink,
                   true);
            draw::text(img, lx + 6 * gap, yr, s, note, ink);
        }
    }
    return img;
}

void write_loglog_plot(const std::string& path, std::span<const PlotSeries> series,
                       const PlotOptions& options) {
    write_png(draw_loglog_plot(series, options), path);
}

}  // namespace sdfprune
