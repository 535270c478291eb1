// render_internal.hpp — image helpers shared by the tracer: background, heatmap colors and
// legend, conversion to 8-bit sRGB.
#pragma once

#include <vector>

#include "sdfprune/render.hpp"

namespace sdfprune {

// Sky gradient; v in [-1, 1] from the bottom to the top of the view.
vec3 background(float v);
// Heatmap color of `value` on a log scale up to `top`.
vec3 heat_color(double value, double top);
// Linear [0, 1] colors to 8-bit sRGB.
void to_rgb8(const std::vector<vec3>& color, Image& img);
// A color bar with its range and the label "node evals/pixel", bottom right.
void draw_heatmap_legend(Image& img, double top);

}  // namespace sdfprune
