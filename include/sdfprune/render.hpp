// render.hpp — sphere-traced images of a scene (DESIGN.md §6): one primary and one shadow ray per
// pixel, either on the pruned grid (far-field blocks skipped whole, near-field cells evaluated
// with their tapes) or naively (the full tree at every step, the paper's baseline). Both use
// the same tracer, evaluator and threading, so their time ratio measures what the pruned grid
// gives: shorter tapes, and the longer steps its far-field cells and one-primitive tapes allow
// (RenderOptions::tile_cones, convex_steps; PruneOptions::clearance).
//
// Thread-safety: render() is reentrant; it runs on oneTBB.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "prune.hpp"

namespace sdfprune {

struct Camera {
    vec3 eye;
    vec3 target;
    vec3 up{0.0f, 1.0f, 0.0f};
    float fov_degrees = 40;  // vertical field of view
};

// A camera looking at `target` (default: the AABB's centre) from angles yaw (about +y, 0 = from
// +z) and pitch (up from the xz plane), in degrees, at `distance` (<= 0: far enough for the
// AABB's bounding sphere to fit the view).
Camera orbit_camera(const Aabb& aabb, float yaw_degrees, float pitch_degrees, float distance,
                    float fov_degrees, const vec3* target = nullptr);
// The distance orbit_camera uses: `distance`, or when it is <= 0 the one that fits the AABB.
float orbit_distance(const Aabb& aabb, float distance, float fov_degrees);

enum class Shading {
    kShaded,   // albedo from the primitives' colors, diffuse light, hard shadow, ambient
    kNormals,  // 0.5 + 0.5·n
    kHeatmap,  // node evaluations per pixel, log scale, with a legend
};

struct RenderOptions {
    uint32_t width = 1920, height = 1080;
    Camera camera;
    Shading shading = Shading::kShaded;
    bool shadows = true;
    int threads = 0;  // 0 = all cores
    // Heatmap scale maximum (node evaluations per pixel); 0 = the image's own maximum.
    double heatmap_max = 0;
    std::function<void(double)> progress;  // called from the calling thread, fraction done
    // Shaded and normals views: tints the pixels where this primitive (an index into the
    // scene's per-primitive arrays) decides the surface (eval_tape_winner); -1: none. The
    // Vulkan renderer ignores it.
    int64_t highlight_primitive = -1;
    // Two ways the pruned CPU tracer steps further than a sphere tracer, each only over space
    // where no ray can stop (trace.cpp; the naive tracer and the Vulkan renderer take neither):
    // - tile_cones: each 8×8 tile of primary rays first marches one cone that holds them
    //   through the grid's free space (far-field boxes, and balls from the field's value), and
    //   its rays start where the cone stops, or are not marched where it leaves the box;
    // - convex_steps: in a near-field cell whose tape is one convex primitive, a ray goes on
    //   to the zero of the secant through its last two values of that primitive, or to the
    //   cell's exit where that is nearer or the value did not decrease (the exit of the
    //   cell's block of finest cells, where all its near-field cells have that primitive).
    // Off: each ray takes the plain sphere tracer's steps (as up to stop 30).
    bool tile_cones = true;
    bool convex_steps = true;
};

struct Image {
    uint32_t width = 0, height = 0;
    std::vector<uint8_t> rgb;  // row-major from the top, 3 bytes per pixel
};

struct RenderStats {
    double trace_ms = 0;
    double steps_avg = 0;     // tracing steps per pixel (primary + shadow)
    double evals_avg = 0;     // node evaluations per pixel (steps, normal and color)
    double hit_fraction = 0;  // pixels whose primary ray hit the surface
    double evals_max = 0;
    // Vulkan only (0 on the CPU): the 32-bit words of evaluation stack each thread of the
    // tracing kernel held (4 per value: the value and a color), sized from the finest cells'
    // tapes; and the pixels traced again with stacks deep enough for the full tree because
    // their hit point or its normal needed it (gpu.hpp, render).
    uint64_t stack_words = 0;
    uint64_t full_tree_pixels = 0;
};

// On the pruned grid (grid.scene() is the scene).
Image render(const PrunedGrid& grid, const RenderOptions& options, RenderStats* stats = nullptr);
// Naive: the full tree at every step.
Image render_naive(const Scene& scene, const RenderOptions& options, RenderStats* stats = nullptr);

// The primary ray through the centre of pixel (x, y) of the image `options` describe (its size
// and camera), traced on the pruned grid: whether it hits the surface, where, and the primitive
// that decides the surface there (eval_tape_winner on the hit cell's tape). Throws
// std::invalid_argument for a pixel outside the image.
struct PickResult {
    bool hit = false;
    vec3 point;
    float t = 0;             // distance along the ray
    uint32_t primitive = 0;  // valid when hit
};
PickResult pick(const PrunedGrid& grid, const RenderOptions& options, uint32_t x, uint32_t y);

// Writes a PNG (8-bit RGB) atomically; throws IoError.
void write_png(const Image& image, const std::string& path);
// The PNG file's bytes, in memory; zlib `level` 0-9 (1: fast, for interactive frames).
std::vector<uint8_t> encode_png(const Image& image, int level = 6);

}  // namespace sdfprune
