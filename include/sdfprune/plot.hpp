// plot.hpp — log-log line plots as PNG images, for the benchmark's cost-versus-size curves
// (`make bench`: prune, trace, discretize and naive times against primitive count). No plotting
// library: the axes, decade grid, tick labels and legend are drawn with a 3x5 pixel font.
//
// Thread-safety: pure functions of their inputs. Errors: write_loglog_plot throws IoError when
// the file cannot be written; points with x <= 0 or y <= 0 (or not finite) are skipped.
#pragma once

#include <span>
#include <string>
#include <vector>

#include "render.hpp"

namespace sdfprune {

struct PlotSeries {
    std::string label;
    std::vector<double> x, y;  // same length; drawn in the given order, joined by lines
    // Optional, empty or same length as x: points drawn hollow (estimated, not measured).
    std::vector<bool> estimated;
};

struct PlotOptions {
    uint32_t width = 960, height = 640;  // pixels
    std::string title;
    std::string x_label = "primitives";
    std::string y_label = "ms";
    // Axis ranges; 0 = from the data, widened to whole decades.
    double x_min = 0, x_max = 0, y_min = 0, y_max = 0;
};

// Draws the plot: decade grid lines with labels (1, 10, 100, 1k, 10k, 100k, 1M, ...; 0.1, 0.01
// below 1), minor ticks at 2..9, one colored polyline with square markers per series, a legend
// at the top left (with "hollow = estimated" when any point is estimated).
Image draw_loglog_plot(std::span<const PlotSeries> series, const PlotOptions& options = {});

// draw_loglog_plot, written as a PNG atomically.
void write_loglog_plot(const std::string& path, std::span<const PlotSeries> series,
                       const PlotOptions& options = {});

// The tick label of a power of ten: "1", "10", "100", "1k", ..., "1M", "1G"; "0.1", "0.01", ...
std::string decade_label(int exponent);

}  // namespace sdfprune
