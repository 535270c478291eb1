// render_internal.hpp — image helpers shared by the tracer: background, heatmap colors and
// legend, conversion to 8-bit sRGB.
#pragma once

#include <span>
#include <vector>

#include "sdfprune/render.hpp"

namespace sdfprune {

// The camera's frame, light and normal step for an image: shared by the CPU tracer and the
// GPU backend so that both shoot the same rays.
struct CameraFrame {
    vec3 forward, right, up;
    vec3 light;          // unit direction towards the light
    float tan_half = 1;  // tan(vertical fov / 2)
    float aspect = 1;    // width / height
    float normal_h = 0;  // step of the tetrahedron-stencil gradient
};
CameraFrame camera_frame(const Scene& scene, const RenderOptions& options);
// The unit direction of the primary ray through the centre of pixel (x, y) of a W×H image.
vec3 pixel_direction(const CameraFrame& frame, uint32_t W, uint32_t H, uint32_t x, uint32_t y);

// The last step of every tracer: the 8-bit image from the pixels' linear colors (or, for the
// heatmap, from their node evaluations, with a legend) and the statistics.
struct TraceTotals {
    double trace_ms = 0;
    uint64_t steps = 0, evals = 0, hits = 0;
};
Image finish_image(const RenderOptions& options, std::vector<vec3>& color,
                   std::span<const uint32_t> evals, const TraceTotals& totals, RenderStats* stats);

// Sky gradient; v in [-1, 1] from the bottom to the top of the view.
vec3 background(float v);
// Heatmap color of `value` on a log scale up to `top`.
vec3 heat_color(double value, double top);
// Linear [0, 1] colors to 8-bit sRGB.
void to_rgb8(const std::vector<vec3>& color, Image& img);
// A color bar with its range and the label "node evals/pixel", bottom right.
void draw_heatmap_legend(Image& img, double top);

}  // namespace sdfprune
