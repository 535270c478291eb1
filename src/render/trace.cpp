// trace.cpp — sphere tracing on the pruned grid or on the full tree (DESIGN.md §6): one
// primary and one shadow ray per pixel. On the pruned grid, a ray in a far-field cell (of any
// level) jumps to the cell's exit — no surface can be inside it — or by the cell's constant if
// that is longer; in a near-field cell it steps by the value of the cell's tape. Both fields
// run the same loop, so their time ratio is the pruning's alone.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <numbers>

#include "../core/parallel.hpp"
#include "render_internal.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/render.hpp"

namespace sdfprune {

float orbit_distance(const Aabb& aabb, float distance, float fov) {
    if (distance > 0) return distance;
    const float radius = math::length(aabb.max - aabb.min) * 0.5f;
    return radius / std::sin(fov * std::numbers::pi_v<float> / 360.0f) * 0.8f;
}

Camera orbit_camera(const Aabb& aabb, float yaw, float pitch, float distance, float fov,
                    const vec3* target) {
    Camera c;
    c.fov_degrees = fov;
    c.target = target ? *target : (aabb.min + aabb.max) * 0.5f;
    distance = orbit_distance(aabb, distance, fov);
    const float y = yaw * std::numbers::pi_v<float> / 180,
                p = pitch * std::numbers::pi_v<float> / 180;
    c.eye = c.target +
            vec3(std::cos(p) * std::sin(y), std::sin(p), std::cos(p) * std::cos(y)) * distance;
    return c;
}

namespace {

vec3 normalize(vec3 v) {
    return v / math::length(v);
}
vec3 cross(vec3 a, vec3 b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

// Ray / box intersection: [t0, t1] inside the box, false if missed.
bool ray_box(vec3 o, vec3 inv_dir, vec3 lo, vec3 hi, float& t0, float& t1) {
    t0 = 0;
    t1 = INFINITY;
    for (int a = 0; a < 3; ++a) {
        float ta = (lo[a] - o[a]) * inv_dir[a], tb = (hi[a] - o[a]) * inv_dir[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    return t0 <= t1;
}

struct Counters {
    uint64_t steps = 0;
    uint64_t evals = 0;
};

// The full tree at every query.
struct NaiveField {
    const Scene& sc;
    // The exact value at p; `hint` (a tape valid near p) is unused.
    float value(vec3 p, std::span<const uint32_t>, float* stack, Counters& c) const {
        c.evals += sc.size();
        return eval_tape(sc, sc.full_tape, p, stack);
    }
    std::span<const uint32_t> tape_at(vec3) const { return sc.full_tape; }
};

// The pruned grid.
struct PrunedField {
    const PrunedGrid& g;
    std::span<const uint32_t> tape_at(vec3 p) const {
        PrunedGrid::Located at;
        if (!g.locate(p, at) || at.far_field()) return g.scene().full_tape;
        return g.tape_at(at.cell->tape);
    }
    float value(vec3 p, std::span<const uint32_t> hint, float* stack, Counters& c) const {
        PrunedGrid::Located at;
        std::span<const uint32_t> tape = hint;
        if (g.locate(p, at) && !at.far_field()) tape = g.tape_at(at.cell->tape);
        c.evals += tape.size();
        return eval_tape(g.scene(), tape, p, stack);
    }
};

struct TraceContext {
    const Scene& sc;
    float inv_lipschitz;
    vec3 aabb_lo, aabb_hi;
};

// Marches o + t·dir over [t0, t1]; returns the hit t or a negative value.
template <class Field>
float march(const Field& field, const TraceContext& ctx, vec3 o, vec3 dir, float t0, float t1,
            uint32_t max_steps, float* stack, Counters& c) {
    const vec3 inv_dir(1.0f / dir.x, 1.0f / dir.y, 1.0f / dir.z);
    // The last near-field cell and its tape: consecutive steps near the surface often stay in
    // one cell, and then need no lookup.
    std::span<const uint32_t> near_tape;
    vec3 near_lo(INFINITY), near_hi(-INFINITY);
    float t = t0;
    for (uint32_t step = 0; step < max_steps && t <= t1; ++step) {
        ++c.steps;
        // [t0, t1] lies in the AABB: clamp away the rounding that would put p just outside.
        const vec3 p = math::min(math::max(o + dir * t, ctx.aabb_lo), ctx.aabb_hi);
        std::span<const uint32_t> tape = ctx.sc.full_tape;
        if constexpr (std::is_same_v<Field, PrunedField>) {
            const bool cached = p.x >= near_lo.x && p.y >= near_lo.y && p.z >= near_lo.z &&
                                p.x <= near_hi.x && p.y <= near_hi.y && p.z <= near_hi.z;
            PrunedGrid::Located at;
            if (cached) {
                tape = near_tape;
            } else if (field.g.locate(p, at)) {
                const vec3 size = field.g.level_cell_size(at.level);
                const vec3 lo = ctx.aabb_lo + vec3(float(at.x), float(at.y), float(at.z)) * size;
                if (at.far_field()) {
                    // No surface in this cell: continue from its exit (or by its constant).
                    float t_exit = INFINITY;
                    for (int a = 0; a < 3; ++a) {
                        const float bound = dir[a] > 0 ? lo[a] + size[a] : lo[a];
                        const float ta = (bound - o[a]) * inv_dir[a];
                        if (ta == ta) t_exit = std::min(t_exit, ta);  // skips 0·inf
                    }
                    // |f(p)| >= |f(centre)| - L·|p - centre|: often far beyond the cell.
                    const float from_centre = std::fabs(at.cell->value) * ctx.inv_lipschitz -
                                              math::length(p - (lo + size * 0.5f));
                    const float step =
                        std::max(std::fabs(at.cell->bound) * ctx.inv_lipschitz, from_centre);
                    const float tiny = 1e-4f * std::min({size.x, size.y, size.z});
                    t = std::max(t + step, t_exit + tiny);
                    continue;
                }
                tape = field.g.tape_at(at.cell->tape);
                near_tape = tape;
                near_lo = lo;
                near_hi = lo + size;
            }
        }
        c.evals += tape.size();
        const float d = eval_tape(ctx.sc, tape, p, stack);
        if (d < 5e-4f * std::min(1.0f, t)) return t;
        t += d * ctx.inv_lipschitz;
    }
    return -1;
}

}  // namespace

vec3 pixel_direction(const CameraFrame& f, uint32_t W, uint32_t H, uint32_t x, uint32_t y) {
    const float u = (2.0f * (float(x) + 0.5f) / float(W) - 1.0f) * f.tan_half * f.aspect;
    const float v = (1.0f - 2.0f * (float(y) + 0.5f) / float(H)) * f.tan_half;
    return normalize(f.forward + f.right * u + f.up * v);
}

CameraFrame camera_frame(const Scene& sc, const RenderOptions& opt) {
    const Camera& cam = opt.camera;
    CameraFrame f;
    f.forward = normalize(cam.target - cam.eye);
    f.right = normalize(cross(f.forward, cam.up));
    f.up = cross(f.right, f.forward);
    f.tan_half = std::tan(cam.fov_degrees * std::numbers::pi_v<float> / 360.0f);
    f.aspect = float(opt.width) / float(opt.height);
    f.light = normalize(f.up * 0.9f - f.right * 0.5f - f.forward * 0.45f);
    f.normal_h = 2e-4f * math::length(sc.aabb.max - sc.aabb.min);
    return f;
}

namespace {

template <class Field>
Image trace_image(const Field& field, const Scene& sc, const RenderOptions& opt,
                  RenderStats* stats) {
    const auto t_start = std::chrono::steady_clock::now();
    const uint32_t W = opt.width, H = opt.height;
    if (W == 0 || H == 0) throw std::invalid_argument("image size must be positive");
    std::vector<uint32_t> evals(size_t(W) * H, 0);
    std::vector<vec3> color(size_t(W) * H);

    const TraceContext ctx{sc, 1.0f / sc.lipschitz[sc.root()], sc.aabb.min, sc.aabb.max};
    const Camera& cam = opt.camera;
    const CameraFrame frame = camera_frame(sc, opt);
    const vec3 light = frame.light;
    const float tan_half = frame.tan_half, normal_h = frame.normal_h;

    std::atomic<uint64_t> total_steps{0}, total_evals{0}, hits{0};
    // Square tiles rather than rows: neighbouring rays visit the same cells and tapes.
    constexpr uint32_t kTile = 16;
    const uint32_t tiles_x = (W + kTile - 1) / kTile, tiles_y = (H + kTile - 1) / kTile;
    const uint32_t tiles = tiles_x * tiles_y;

    // One chunk per tile.
    const auto trace_tile = [&](uint64_t chunk) {
        const uint32_t tile = uint32_t(chunk);
        thread_local std::vector<float> stack;
        thread_local std::vector<vec3> color_stack;
        thread_local std::vector<uint32_t> winner_stack;
        stack.resize(sc.max_stack);
        color_stack.resize(sc.max_stack);
        if (opt.highlight_primitive >= 0) winner_stack.resize(sc.max_stack);
        Counters sum;
        uint64_t tile_hits = 0;
        const uint32_t x0 = tile % tiles_x * kTile, y0 = tile / tiles_x * kTile;
        for (uint32_t y = y0; y < std::min(H, y0 + kTile); ++y)
            for (uint32_t x = x0; x < std::min(W, x0 + kTile); ++x) {
                Counters c;
                const float v = (1.0f - 2.0f * (float(y) + 0.5f) / float(H)) * tan_half;
                const vec3 dir = pixel_direction(frame, W, H, x, y);
                const vec3 inv(1.0f / dir.x, 1.0f / dir.y, 1.0f / dir.z);
                float t0, t1;
                vec3 out = background(v / tan_half);
                if (ray_box(cam.eye, inv, ctx.aabb_lo, ctx.aabb_hi, t0, t1)) {
                    const float t = march(field, ctx, cam.eye, dir, t0, t1, 1024, stack.data(), c);
                    if (t >= 0) {
                        ++tile_hits;
                        const vec3 p = cam.eye + dir * t;
                        const std::span<const uint32_t> tape = field.tape_at(p);
                        // Tetrahedron-stencil gradient.
                        const vec3 k[4] = {{1, -1, -1}, {-1, -1, 1}, {-1, 1, -1}, {1, 1, 1}};
                        vec3 n(0.0f);
                        for (const vec3& ki : k)
                            n = n + ki * field.value(p + ki * normal_h, tape, stack.data(), c);
                        const float len = math::length(n);
                        n = len > 0 ? n / len : -dir;
                        c.evals += tape.size();
                        const vec3 albedo =
                            eval_tape_color(sc, tape, p, stack.data(), color_stack.data());
                        float lit = std::max(0.0f, math::dot(n, light));
                        if (opt.shadows && lit > 0) {
                            const vec3 so = p + n * (4.0f * normal_h);
                            const vec3 sinv(1.0f / light.x, 1.0f / light.y, 1.0f / light.z);
                            float s0, s1;
                            if (ray_box(so, sinv, ctx.aabb_lo, ctx.aabb_hi, s0, s1) &&
                                march(field, ctx, so, light, s0 + normal_h, s1, 512, stack.data(),
                                      c) >= 0)
                                lit = 0;
                        }
                        out = opt.shading == Shading::kNormals
                                  ? n * 0.5f + 0.5f
                                  : albedo * (0.22f + 0.78f * lit) +
                                        vec3(0.06f) *
                                            std::pow(std::max(0.0f, math::dot(n, -dir)), 8.0f);
                        if (opt.highlight_primitive >= 0 &&
                            eval_tape_winner(sc, tape, p, stack.data(), winner_stack.data()) ==
                                uint64_t(opt.highlight_primitive))
                            out = out * 0.45f + vec3(1.0f, 0.5f, 0.08f) * 0.55f;
                    }
                }
                const size_t i = size_t(y) * W + x;
                color[i] = out;
                evals[i] = uint32_t(std::min<uint64_t>(c.evals, 0xffffffffu));
                sum.steps += c.steps;
                sum.evals += c.evals;
            }
        total_steps += sum.steps;
        total_evals += sum.evals;
        hits += tile_hits;
    };
    parallel_for<NotCancellable>(tiles, parallel_options(opt), trace_tile);

    const double trace_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_start)
            .count();
    return finish_image(opt, color, evals, {trace_ms, total_steps, total_evals, hits}, stats);
}

}  // namespace

Image finish_image(const RenderOptions& opt, std::vector<vec3>& color,
                   std::span<const uint32_t> evals, const TraceTotals& totals, RenderStats* stats) {
    Image img;
    img.width = opt.width;
    img.height = opt.height;
    img.rgb.assign(size_t(opt.width) * opt.height * 3, 0);
    double max_evals = 0;
    for (uint32_t e : evals) max_evals = std::max(max_evals, double(e));
    if (opt.shading == Shading::kHeatmap) {
        const double top = opt.heatmap_max > 0 ? opt.heatmap_max : max_evals;
        for (size_t i = 0; i < evals.size(); ++i) color[i] = heat_color(double(evals[i]), top);
        to_rgb8(color, img);
        draw_heatmap_legend(img, top);
    } else {
        to_rgb8(color, img);
    }
    if (stats) {
        const double px = double(opt.width) * opt.height;
        stats->trace_ms = totals.trace_ms;
        stats->steps_avg = double(totals.steps) / px;
        stats->evals_avg = double(totals.evals) / px;
        stats->hit_fraction = double(totals.hits) / px;
        stats->evals_max = max_evals;
    }
    return img;
}

Image render(const PrunedGrid& grid, const RenderOptions& options, RenderStats* stats) {
    const Scene& sc = grid.scene();
    return trace_image(PrunedField{grid}, sc, options, stats);
}

PickResult pick(const PrunedGrid& grid, const RenderOptions& opt, uint32_t x, uint32_t y) {
    if (x >= opt.width || y >= opt.height)
        throw std::invalid_argument("pick: pixel (" + std::to_string(x) + ", " + std::to_string(y) +
                                    ") lies outside the image");
    const Scene& sc = grid.scene();
    const TraceContext ctx{sc, 1.0f / sc.lipschitz[sc.root()], sc.aabb.min, sc.aabb.max};
    const CameraFrame frame = camera_frame(sc, opt);
    const vec3 eye = opt.camera.eye, dir = pixel_direction(frame, opt.width, opt.height, x, y);
    const vec3 inv(1.0f / dir.x, 1.0f / dir.y, 1.0f / dir.z);
    std::vector<float> stack(sc.max_stack);
    std::vector<uint32_t> winners(sc.max_stack);
    PickResult r;
    float t0, t1;
    Counters c;
    if (!ray_box(eye, inv, ctx.aabb_lo, ctx.aabb_hi, t0, t1)) return r;
    const PrunedField field{grid};
    const float t = march(field, ctx, eye, dir, t0, t1, 1024, stack.data(), c);
    if (t < 0) return r;
    r.hit = true;
    r.t = t;
    r.point = eye + dir * t;
    r.primitive =
        eval_tape_winner(sc, field.tape_at(r.point), r.point, stack.data(), winners.data());
    return r;
}

Image render_naive(const Scene& scene, const RenderOptions& options, RenderStats* stats) {
    return trace_image(NaiveField{scene}, scene, options, stats);
}

}  // namespace sdfprune
