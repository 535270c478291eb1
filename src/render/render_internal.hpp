// render_internal.hpp — image helpers shared by the tracer: background, heatmap colors and
// legend, conversion to 8-bit sRGB.
#pragma once

#include <algorithm>
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
// Linear [0, 1] colors to 8-bit sRGB: through a table of kRgb8CurveSteps + 1 entries
// (rgb8_curve(), built once, thread-safe), one pixel at a time or a whole image.
inline constexpr int kRgb8CurveSteps = 4096;
const uint8_t* rgb8_curve();
inline void store_rgb8(const uint8_t* curve, vec3 color, uint8_t* out) {
    // curve[size_t(std::clamp(c, 0, 1) · kRgb8CurveSteps + 0.5)] for the three channels at once
    // (GCC/Clang vector extension, any target): the same comparisons and IEEE operations lane
    // by lane, and a conversion to int32, which truncates the index (in [0.5, steps + 0.5]) as
    // one to size_t would. A third of the instructions of the scalar loop.
    using float4 = float __attribute__((vector_size(16)));
    using int4 = int32_t __attribute__((vector_size(16)));
    const float4 zero = {0, 0, 0, 0}, one = {1, 1, 1, 1};
    float4 c = {color.x, color.y, color.z, 0};
    c = c < zero ? zero : c;  // std::clamp(c, 0, 1): c < 0 ? 0 : (1 < c ? 1 : c)
    c = one < c ? one : c;
    const int4 index =
        __builtin_convertvector(c * float(kRgb8CurveSteps) + float4{0.5f, 0.5f, 0.5f, 0.5f}, int4);
    for (int k = 0; k < 3; ++k) out[k] = curve[index[k]];
}
void to_rgb8(const std::vector<vec3>& color, Image& img);
// RenderStats from a traced image's totals and its largest per-pixel evaluation count.
void set_render_stats(const RenderOptions& options, const TraceTotals& totals, double max_evals,
                      RenderStats* stats);
// A color bar with its range and the label "node evals/pixel", bottom right.
void draw_heatmap_legend(Image& img, double top);

}  // namespace sdfprune
