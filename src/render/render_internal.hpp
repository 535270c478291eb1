// render_internal.hpp — image helpers shared by the tracer: background, heatmap colors and
// legend, conversion to 8-bit sRGB.
#pragma once

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

// Sky gradient; v in [-1, 1] from the bottom to the top of the view.
vec3 background(float v);
// Heatmap color of `value` on a log scale up to `top`.
vec3 heat_color(double value, double top);
// Linear [0, 1] colors to 8-bit sRGB.
void to_rgb8(const std::vector<vec3>& color, Image& img);
// A color bar with its range and the label "node evals/pixel", bottom right.
void draw_heatmap_legend(Image& img, double top);

}  // namespace sdfprune
