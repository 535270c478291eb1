// trace.cpp — sphere tracing on the pruned grid or on the full tree (DESIGN.md §6): one
// primary and one shadow ray per pixel. On the pruned grid, a ray in a far-field cell (of any
// level) jumps to the cell's exit — no surface can be inside it — or by the cell's constant if
// that is longer; in a near-field cell it steps by the value of the cell's tape. Rays are
// marched within the near-field cells' box only (PrunedGrid::near_box). Both fields run the same
// loop; the pruned one also starts a tile's primary rays where the tile's cone stops
// (start_at_cones) and steps by secants in cells of one convex primitive (convex_step). The
// fields themselves, and the vector helpers, are in trace_fields.hpp.
#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <numbers>
#include <vector>

#include "../core/clock.hpp"
#include "../core/parallel.hpp"
#include "render_internal.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/render.hpp"
#include "trace_fields.hpp"

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

struct TraceContext {
    const Scene& sc;
    float inv_lipschitz;
    vec3 aabb_lo, aabb_hi;
    bool convex_steps;  // RenderOptions::convex_steps (the pruned field's only)
};

// A ray to march over [t0, t1] (its span inside the AABB); `t` receives the hit, or -1.
struct Ray {
    vec3 o, dir;
    float t0, t1;
    uint32_t max_steps;
    float t;
    Counters* counters;  // the pixel's
};

// One ray in flight. A step of a plain sphere tracer is split in two halves, taken at two turns
// of the lane (see march): the first finds the point and what decides it (the cached near-field
// cell, or the grid cell, whose address it prefetches); the second reads that cell or evaluates
// that tape and moves t.
// Points and directions are held as float4 (x, y, z, unused): see float4's comment.
struct Lane {
    enum class Next : uint8_t {
        kWalk,  // read what `walk` names (prefetched): the lookup's next word, or the deciding
                // cell: then a far-field step, or fetch its tape
        kEval,  // evaluate `tape` (prefetched) at p
    };
    Ray* ray = nullptr;
    float t1 = 0;  // the ray's t1 and max_steps, held here to save a load per step
    uint32_t max_steps = 0;
    float4 o, dir, inv_dir;
    int4 up;  // all ones on the axes where the ray leaves cells by their upper face
    float4 exit_sign, exit_up;  // per axis, 1 and 1 where `up`, else -1 and 0 (far_field_advance)
    uint32_t octant;            // the same as bits: x 1, y 2, z 4 (see clearance_in)
    float t = 0;
    uint32_t step = 0;
    Next next = Next::kEval;
    bool inf_inverse = false;  // some lane of inv_dir (x, y, z) is ±inf (far_field_advance)
    float4 p;
    PrunedGrid::Walk walk;  // kWalk: the lookup of p's cell
    int4 index;             // kWalk: p's finest cell
    // The tape kEval evaluates: the last near-field cell's (the full tree's, on the naive
    // field). Consecutive steps near the surface often stay in one cell, and then need no
    // lookup. (One copy only: a second, copied from it per step, cost a store-forwarding stall
    // that perf put at 9 % of march's time on console.)
    std::span<const uint32_t> tape;
    float4 near_lo = splat(INFINITY), near_hi = splat(-INFINITY);
    // The last value taken of a convex primitive's tape (see convex_step): its word (kNoWord:
    // none yet), t and value.
    static constexpr uint32_t kNoWord = 0xffffffffu;
    uint32_t convex_word = kNoWord;
    float convex_t = 0, convex_d = 0;
    uint64_t evals = 0;  // node evaluations, added to the ray's counters when it is done
};

// The t at which lane l's ray reaches the faces `exit` (per axis, the face it leaves a box by:
// the upper one where it goes up) first.
float exit_time(const Lane& l, float4 exit) {
    float4 t_axis = (exit - l.o) * l.inv_dir;
    // NaN (0·inf): the ray runs in the face's plane, which it never leaves. Which of equal
    // candidates wins (+0 or -0) does not matter: callers add a tiny step. exit - o is finite,
    // so only an infinite 1 / dir (dir ±0, or so small that its inverse overflows) can make a
    // NaN: other rays skip the select (8 instructions a far-field step).
    if (l.inf_inverse) t_axis = t_axis == t_axis ? t_axis : splat(INFINITY);
    return std::min(std::min(t_axis[0], t_axis[1]), t_axis[2]);
}

// The next t of lane l at p in far-field cell c (corner lo, level geometry geo): no surface
// is in the cell nor in the box of cells its clearance in the ray's octant gives, so continue
// from the exit of that box, or by the cell's constant if that is longer.
float far_field_advance(const Lane& l, float4 p, float4 lo, const LevelGeometry& geo,
                        const PrunedCell& c, float inv_lipschitz) {
    const float r = float(clearance_in(c, l.octant));
    // lo + size·(r + 1) on the axes the ray goes up, lo - size·r on the others: lo + size·(-r)
    // is the same float (negation is exact), so one multiply-add serves both. The factor
    // r·(±1) + (1 or 0) is r + 1 or -r exactly (small integers); -r is +0 rather than -0 for
    // r = 0, which gives the same exit (lo is never -0: a sum with +0·size).
    const float t_exit = exit_time(l, lo + geo.size * (splat(r) * l.exit_sign + l.exit_up));
    // |f(p)| >= |f(centre)| - L·|p - centre|: often far beyond the cell.
    const float from_centre = std::fabs(c.value) * inv_lipschitz - length3(p - (lo + geo.half));
    const float step = std::max(std::fabs(c.bound) * inv_lipschitz, from_centre);
    return std::max(l.t + step, t_exit + geo.tiny);
}

// Where lane l goes on from t, in a near-field cell whose tape is one primitive with a convex
// value g(t) along the ray, which is d (not a hit) at l.t; `sphere` is the sphere tracer's next
// t. If the lane's last value of this primitive was taken at an earlier t, the secant through
// the two values, extended, lies below g (convexity), so g has no zero before the secant's;
// where g did not decrease, none in the cell at all. Either way the ray may go on from there,
// or from the cell's exit if that is nearer: the cell's tape gives the field there only. In a
// convex block (PrunedField::convex_box: every near-field cell of the cell's block of finest
// cells has this tape, and the far-field ones hold no zero) the block's exit serves: on
// camera at 1920×1080, 9 % fewer steps. The two values' difference is made larger by the
// field's secant_margin (their rounding): the secant's zero comes no later than the exact
// secant's. Steps are never shorter than the sphere tracer's.
float convex_step(const PrunedField& field, Lane& l, uint32_t word, float d, float sphere) {
    float next = sphere;
    if (l.convex_word == word) {
        float4 lo = l.near_lo, hi = l.near_hi;
        field.convex_box(l.walk.cell, l.index, lo, hi);
        float target = exit_time(l, l.up ? hi : lo) + field.levels.back().tiny;
        const float drop = l.convex_d - d + field.secant_margin;
        if (drop > 0) target = std::min(target, l.t + d * (l.t - l.convex_t) / drop);
        next = std::max(next, target);
    }
    l.convex_word = word;
    l.convex_t = l.t;
    l.convex_d = d;
    return next;
}

// Marches `rays`, kLanes at a time, each lane taking part of a step in turn: the steps of
// different rays are independent, so while one lane waits for memory the others work. The
// lookup of a step's cell in the grid (tens of MB, mostly out of cache) is split at its reads:
// the end of a step prefetches the shortcut's entry for the next point; the lane's next turn
// reads it and the coarse cell it names, and if that cell is near-field, prefetches the finest
// one and reads it at the turn after; a near-field cell's tape is prefetched and evaluated at
// the next turn too. Measured on molecule (960x540, one thread): the finest cell's load held a
// third of the tracer's time when read at once; prefetching 11 % faster; 16 lanes 3 % faster
// than 8, 32 no better. Every ray takes exactly the steps and values a ray marched alone would:
// only their order in time differs.
template <class Field>
void march(const Field& field, const TraceContext& ctx, std::span<Ray> rays, float* stack) {
    constexpr bool kPruned = std::is_same_v<Field, PrunedField>;
    constexpr uint32_t kLanes = kPruned ? 16 : 1;
    Lane lanes[kLanes];
    size_t next = 0;
    const float4 aabb_lo = load4(ctx.aabb_lo), aabb_hi = load4(ctx.aabb_hi);
    const auto finish = [&](Lane& l) {
        l.ray->counters->steps += l.step;
        l.ray->counters->evals += l.evals;
        return false;
    };
    // The first half of lane l's next step; false when its ray is done (left the AABB or out
    // of steps).
    const auto begin_step = [&](Lane& l) -> bool {
        if (l.step >= l.max_steps || !(l.t <= l.t1)) return finish(l);
        ++l.step;
        // [t0, t1] lies in the AABB: clamp away the rounding that would put p just outside.
        l.p = min4(max4(l.o + l.dir * l.t, aabb_lo), aabb_hi);
        l.next = Lane::Next::kEval;
        if constexpr (kPruned) {
            if (in_box(l.p, l.near_lo, l.near_hi)) return true;
            // p lies in the grid's box: every lookup finds a cell.
            const int4 i = l.index = field.finest_index(l.p);
            l.walk = field.g.walk_begin(uint32_t(i[0]), uint32_t(i[1]), uint32_t(i[2]));
            // The walk's first word (the shortcut's entry: a small table, mostly in cache) is
            // read at once; what it names is prefetched for the next turn.
            field.g.walk_step(l.walk);
            __builtin_prefetch(l.walk.next());
            l.next = Lane::Next::kWalk;
        }
        return true;
    };
    const auto start = [&](Lane& l) {
        Ray& r = rays[next++];
        l.ray = &r;
        l.t1 = r.t1;
        l.max_steps = r.max_steps;
        l.o = load4(r.o);
        l.dir = load4(r.dir);
        // (1 / dir in one vector division, the same quotients; the unused lane's is not used)
        l.inv_dir = splat(1.0f) / float4{r.dir.x, r.dir.y, r.dir.z, 1};
        l.up = l.dir > 0;
        l.exit_sign = l.up ? splat(1.0f) : splat(-1.0f);
        l.exit_up = l.up ? splat(1.0f) : splat(0.0f);
        const float4 abs_inv = l.inv_dir < 0 ? -l.inv_dir : l.inv_dir;
        const int4 inf = abs_inv == splat(INFINITY);
#if defined(__SSE__)
        l.octant = __builtin_ia32_movmskps(float4(l.up)) & 7;
        l.inf_inverse = (__builtin_ia32_movmskps(float4(inf)) & 7) != 0;
#else
        l.octant = (l.up[0] & 1) | (l.up[1] & 2) | (l.up[2] & 4);
        l.inf_inverse = (inf[0] | inf[1] | inf[2]) != 0;
#endif
        l.t = r.t0;
        l.step = 0;
        l.near_lo = splat(INFINITY);
        l.near_hi = splat(-INFINITY);
        l.convex_word = Lane::kNoWord;
        if constexpr (!kPruned) l.tape = ctx.sc.full_tape;
        l.evals = 0;
        r.t = -1;
        return begin_step(l);
    };
    // The second half of lane l's step, and the first half of its next one; false when its ray
    // is done (hit, left the AABB or out of steps).
    const auto advance = [&](Lane& l) -> bool {
        if constexpr (kPruned) {
            if (l.next == Lane::Next::kWalk) {
                if (!field.g.walk_step(l.walk)) {
                    __builtin_prefetch(l.walk.next());
                    return true;
                }
                // The deciding cell, its level and its coordinates at that level (walk_located's,
                // by one vector shift where the levels allow it).
                const PrunedCell& cell = *l.walk.cell;
                const LevelGeometry& geo = field.levels[l.walk.level];
                int4 coords = l.index >> geo.shift;
                if (!field.pow2) {
                    const PrunedGrid::Located at = field.g.walk_located(l.walk);
                    coords = int4{int32_t(at.x), int32_t(at.y), int32_t(at.z), 0};
                }
                // (one conversion of the three coordinates, each exact: below 2^24)
                const float4 lo = aabb_lo + __builtin_convertvector(coords, float4) * geo.size;
                if (cell.tape == PrunedCell::kFarField) {
                    l.t = far_field_advance(l, l.p, lo, geo, cell, ctx.inv_lipschitz);
                    return begin_step(l);
                }
                l.tape = field.g.tape_at(cell.tape);
                l.near_lo = lo;
                l.near_hi = lo + geo.size;
                // The tape is likely not in cache: evaluate it at the next turn.
                __builtin_prefetch(l.tape.data());
                l.next = Lane::Next::kEval;
                return true;
            }
        }
        l.evals += l.tape.size();
        // (the naive tracer's tape is the full tree: eval_tape, as before tape_value)
        const vec3 p(l.p[0], l.p[1], l.p[2]);
        const float d =
            kPruned ? tape_value(ctx.sc, l.tape, p, stack) : eval_tape(ctx.sc, l.tape, p, stack);
        if (d < kHitBelow * std::min(1.0f, l.t)) {
            l.ray->t = l.t;
            return finish(l);
        }
        const float sphere = l.t + d * ctx.inv_lipschitz;
        if constexpr (kPruned) {
            l.t = ctx.convex_steps && field.convex_tape(l.tape)
                      ? convex_step(field, l, l.tape[0], d, sphere)
                      : sphere;
        } else {
            l.t = sphere;
        }
        return begin_step(l);
    };
    // A lane whose ray is done takes the next ray, or the last active lane's place.
    Lane* end = lanes;
    const auto refill = [&](Lane& l) {
        while (next < rays.size())
            if (start(l)) return true;
        l = *--end;
        return false;
    };
    while (end < lanes + kLanes && next < rays.size())
        if (start(*end)) ++end;
    while (end > lanes) {
        for (Lane* l = lanes; l < end;) {
            if (advance(*l) || refill(*l)) ++l;
        }
    }
}

}  // namespace

namespace {
// pixel_direction's image-plane coordinates of column x and row y.
float pixel_u(const CameraFrame& f, uint32_t W, uint32_t x) {
    return (2.0f * (float(x) + 0.5f) / float(W) - 1.0f) * f.tan_half * f.aspect;
}
float pixel_v(const CameraFrame& f, uint32_t H, uint32_t y) {
    return (1.0f - 2.0f * (float(y) + 0.5f) / float(H)) * f.tan_half;
}

// ray_box for rays from one origin (an image's primary rays): the box's corners relative to
// the origin are worked out once, and the slabs of the three axes are taken in vector lanes.
// The same operations in the same order as ray_box, so the same t0, t1 bit for bit.
struct BoxFromOrigin {
    float4 lo, hi;  // box corners - origin
    bool empty;     // empty_box: no ray hits it
    BoxFromOrigin(vec3 origin, vec3 box_lo, vec3 box_hi)
        : lo(load4(box_lo) - load4(origin)),
          hi(load4(box_hi) - load4(origin)),
          empty(empty_box(box_lo, box_hi)) {}
    // dir: (x, y, z, any)
    bool hit(float4 dir, float& t0, float& t1) const {
        if (empty) return false;
        // (one division in vector lanes: the same quotients as three scalar ones; the unused
        // lane is never read)
        const float4 inv = splat(1.0f) / dir;
        const float4 ta = lo * inv, tb = hi * inv;
        // ray_box's swap when ta > tb (not when either is NaN)
        const int4 swap = ta > tb;
        const float4 near = swap ? tb : ta, far = swap ? ta : tb;
        t0 = 0;
        t1 = INFINITY;
        for (int a = 0; a < 3; ++a) {
            t0 = std::max(t0, near[a]);
            t1 = std::min(t1, far[a]);
        }
        return t0 <= t1;
    }
};
}  // namespace

vec3 pixel_direction(const CameraFrame& f, uint32_t W, uint32_t H, uint32_t x, uint32_t y) {
    return normalize(f.forward + f.right * pixel_u(f, W, x) + f.up * pixel_v(f, H, y));
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

// RenderOptions::tile_cones, for the primary rays of a tile whose pixel j = row · w + i has
// the direction column[i] + up · v(row), normalized: the tile's rays in sub-tiles of
// kConeTile² pixels, each sub-tile's marched as one cone (its axis through the middle of its
// corner rays) from where its first ray enters the box. Each ray starts where its cone stopped;
// one whose cone left the box before the ray's exit is dropped (a miss, t = -1). Returns how
// many rays are left, in order, in `rays`. Camera at 1920×1080, trace time against no cones:
// 8 × 8 -11 %, 16 × 16 -9 %, 4 × 4 -4 % (its cones, each from the box, cost more than the
// rays' steps they save). Cones of 4 × 4 from where each 8 × 8 one stopped took 11 % fewer
// steps than 8 × 8 alone but no less time (medians of six alternated renders each, 165.0 and
// 165.5 ms), nor did sizes 16, 8, 4 or 8, 4, 2 in turn.
constexpr uint32_t kConeTile = 8;
uint32_t start_at_cones(const PrunedField& field, const CameraFrame& frame, vec3 eye, uint32_t H,
                        uint32_t y0, const vec3* column, uint32_t w, uint32_t h, Ray* rays,
                        uint32_t* ray_pixel, uint32_t n_rays, float* stack, Counters& counters) {
    constexpr uint32_t kMaxSubTiles = 4;  // of a 16 × 16 tile
    const uint32_t sub_x = (w + kConeTile - 1) / kConeTile, sub_y = (h + kConeTile - 1) / kConeTile;
    float sub_t0[kMaxSubTiles], sub_t1[kMaxSubTiles];
    std::fill_n(sub_t0, sub_x * sub_y, INFINITY);
    std::fill_n(sub_t1, sub_x * sub_y, -INFINITY);
    const auto sub_of = [&](uint32_t j) {
        return (j / w) / kConeTile * sub_x + (j % w) / kConeTile;
    };
    // The cone of each sub-tile spans its rays' [t0, t1].
    for (uint32_t r = 0; r < n_rays; ++r) {
        const uint32_t k = sub_of(ray_pixel[r]);
        sub_t0[k] = std::min(sub_t0[k], rays[r].t0);
        sub_t1[k] = std::max(sub_t1[k], rays[r].t1);
    }
    for (uint32_t sy = 0; sy < sub_y; ++sy)
        for (uint32_t sx = 0; sx < sub_x; ++sx) {
            const uint32_t k = sy * sub_x + sx;
            if (!(sub_t0[k] <= sub_t1[k])) continue;  // no ray
            const uint32_t i0 = sx * kConeTile, i1 = std::min(w, i0 + kConeTile) - 1;
            const uint32_t r0 = sy * kConeTile, r1 = std::min(h, r0 + kConeTile) - 1;
            float4 corner[4];
            int n = 0;
            for (const uint32_t row : {r0, r1})
                for (const uint32_t i : {i0, i1}) {
                    const vec3 c = column[i] + frame.up * pixel_v(frame, H, y0 + row);
                    corner[n++] = load4(c) / splat(math::length(c));
                }
            const float4 sum = corner[0] + corner[1] + corner[2] + corner[3];
            const float4 axis = sum / splat(length3(sum));
            float spread = 0;
            for (const float4& c : corner) spread = std::max(spread, length3(c - axis));
            // (a margin for the rounding of the directions)
            const Cone cone{load4(eye), axis, spread * 1.001f + 1e-6f};
            sub_t0[k] = field.cone_start(cone, sub_t0[k], sub_t1[k], stack, counters);
        }
    uint32_t kept = 0;
    for (uint32_t r = 0; r < n_rays; ++r) {
        const float start = sub_t0[sub_of(ray_pixel[r])];
        if (start > rays[r].t1) continue;
        rays[r].t0 = std::max(rays[r].t0, start);
        rays[kept] = rays[r];
        ray_pixel[kept++] = ray_pixel[r];
    }
    return kept;
}

// `t_start`: when the caller began, the field's making included.
template <class Field>
Image trace_image(const Field& field, const Scene& sc, const RenderOptions& opt, RenderStats* stats,
                  std::chrono::steady_clock::time_point t_start) {
    const uint32_t W = opt.width, H = opt.height;
    if (W == 0 || H == 0) throw std::invalid_argument("image size must be positive");
    // Tiles write their pixels' final bytes: 3 bytes a pixel rather than a float color and an
    // evaluation count (16 bytes) filled in, converted and scanned after. Freshly allocated
    // memory costs page faults: 8 MB at 960x540 took 2-5 ms, a tenth of a small scene's trace.
    // Only the heatmap, colored by the counts after all tiles, keeps a count per pixel.
    const bool heatmap = opt.shading == Shading::kHeatmap;
    std::vector<uint32_t> evals(heatmap ? size_t(W) * H : 0);
    Image img;
    img.width = W;
    img.height = H;
    if (!heatmap) img.rgb.resize(size_t(W) * H * 3);
    const uint8_t* curve = rgb8_curve();
    std::atomic<uint32_t> max_evals{0};

    const TraceContext ctx{sc, 1.0f / sc.lipschitz[sc.root()], sc.aabb.min, sc.aabb.max,
                           opt.convex_steps};
    const Camera& cam = opt.camera;
    const CameraFrame frame = camera_frame(sc, opt);
    const vec3 light = frame.light;
    const float tan_half = frame.tan_half, normal_h = frame.normal_h;
    const Aabb march_box = field.march_box();
    const BoxFromOrigin box_from_eye(cam.eye, march_box.min, march_box.max);

    std::atomic<uint64_t> total_steps{0}, total_evals{0}, hits{0};
    // Square tiles rather than rows: neighbouring rays visit the same cells and tapes.
    constexpr uint32_t kTile = 16;
    const uint32_t tiles_x = (W + kTile - 1) / kTile, tiles_y = (H + kTile - 1) / kTile;
    const uint32_t tiles = tiles_x * tiles_y;

    // What a hit pixel's colour needs once its shadow ray is known.
    struct Hit {
        uint32_t pixel;
        vec3 dir, n, albedo;
        float lit;
        bool highlight;
        int32_t shadow_ray;  // index of its shadow ray, or -1
    };
    struct TileScratch {
        Counters counters[kTile * kTile];
        Ray rays[kTile * kTile], shadow_rays[kTile * kTile];
        uint32_t ray_pixel[kTile * kTile];
        Hit hits[kTile * kTile];
    };
    // One chunk per tile.
    const auto trace_tile = [&](uint64_t chunk) {
        const uint32_t tile = uint32_t(chunk);
        thread_local std::vector<float> stack;
        thread_local std::vector<vec3> color_stack;
        thread_local std::vector<uint32_t> winner_stack;
        stack.resize(sc.max_stack);
        color_stack.resize(sc.max_stack);
        if (opt.highlight_primitive >= 0) winner_stack.resize(sc.max_stack);
        // Three passes over the tile: its primary rays, marched together; the hits' normals
        // and colours; their shadow rays, marched together.
        const uint32_t x0 = tile % tiles_x * kTile, y0 = tile / tiles_x * kTile;
        const uint32_t w = std::min(W, x0 + kTile) - x0, h = std::min(H, y0 + kTile) - y0;
        // Per-thread scratch for the tile's rays (a few tens of KB: not on the stack, and not
        // cleared per tile; a pixel's counters are cleared when it gets a ray, and only pixels
        // with a ray count anything).
        thread_local TileScratch scratch;
        Counters* counters = scratch.counters;
        Counters cone_counters;
        Ray* rays = scratch.rays;
        uint32_t* ray_pixel = scratch.ray_pixel;
        uint32_t n_rays = 0;
        // The tile's pixel j = row · w + i lies at byte 3 · (tile_first + row · W + i).
        const size_t tile_first = size_t(y0) * W + x0;
        // pixel_direction's sum split at its order of operations: (forward + right·u) per
        // column, + up·v per row; the rays are pixel_direction's bit for bit.
        vec3 column[kTile];
        for (uint32_t i = 0; i < w; ++i)
            column[i] = frame.forward + frame.right * pixel_u(frame, W, x0 + i);
        for (uint32_t row = 0, j = 0; row < h; ++row) {
            const float v = pixel_v(frame, H, y0 + row);
            const vec3 up_v = frame.up * v;
            // Most pixels show the background (nine in ten on the small kinds): its bytes are
            // worked out once per row and copied; a hit's pixel is written over at the end.
            if (!heatmap) {
                uint8_t bytes[3];
                store_rgb8(curve, background(v / tan_half), bytes);
                uint8_t* dst = &img.rgb[3 * (tile_first + size_t(row) * W)];
                for (uint32_t i = 0; i < w; ++i) std::memcpy(dst + 3 * i, bytes, 3);
            }
            for (uint32_t i = 0; i < w; ++i, ++j) {
                // normalize's quotients, in one vector division
                const vec3 c = column[i] + up_v;
                const float4 d = load4(c) / splat(math::length(c));
                float t0, t1;
                if (!box_from_eye.hit(d, t0, t1)) continue;
                const vec3 dir(d[0], d[1], d[2]);
                counters[j] = {};
                rays[n_rays] = {cam.eye, dir, t0, t1, 1024, -1, &counters[j]};
                ray_pixel[n_rays++] = j;
            }
        }
        if constexpr (std::is_same_v<Field, PrunedField>) {
            if (opt.tile_cones && n_rays > 0)
                n_rays = start_at_cones(field, frame, cam.eye, H, y0, column, w, h, rays, ray_pixel,
                                        n_rays, stack.data(), cone_counters);
        }
        march(field, ctx, std::span(rays, n_rays), stack.data());

        Hit* hits_of_tile = scratch.hits;
        Ray* shadow_rays = scratch.shadow_rays;
        uint32_t n_hits = 0, n_shadow = 0;
        for (uint32_t r = 0; r < n_rays; ++r) {
            if (rays[r].t < 0) continue;
            const uint32_t j = ray_pixel[r];
            Counters& c = counters[j];
            const vec3 dir = rays[r].dir, p = cam.eye + dir * rays[r].t;
            const auto hint = field.hint_at(p);
            const std::span<const uint32_t> tape = hint.tape;
            // Tetrahedron-stencil gradient.
            const vec3 k[4] = {{1, -1, -1}, {-1, -1, 1}, {-1, 1, -1}, {1, 1, 1}};
            vec3 n(0.0f);
            for (const vec3& ki : k)
                n = n + ki * field.value(p + ki * normal_h, hint, stack.data(), c);
            const float len = math::length(n);
            n = len > 0 ? n / len : -dir;
            c.evals += tape.size();
            Hit& hit = hits_of_tile[n_hits++];
            hit = {j,
                   dir,
                   n,
                   eval_tape_color(sc, tape, p, stack.data(), color_stack.data()),
                   std::max(0.0f, math::dot(n, light)),
                   false,
                   -1};
            hit.highlight = opt.highlight_primitive >= 0 &&
                            eval_tape_winner(sc, tape, p, stack.data(), winner_stack.data()) ==
                                uint64_t(opt.highlight_primitive);
            if (opt.shadows && hit.lit > 0) {
                const vec3 so = p + n * (4.0f * normal_h);
                const vec3 sinv(1.0f / light.x, 1.0f / light.y, 1.0f / light.z);
                float s0, s1;
                if (ray_box(so, sinv, march_box.min, march_box.max, s0, s1)) {
                    hit.shadow_ray = int32_t(n_shadow);
                    shadow_rays[n_shadow++] = {so, light, s0 + normal_h, s1, 512, -1, &c};
                }
            }
        }
        march(field, ctx, std::span(shadow_rays, n_shadow), stack.data());
        for (uint32_t i = 0; i < n_hits; ++i) {
            Hit& hit = hits_of_tile[i];
            if (hit.shadow_ray >= 0 && shadow_rays[hit.shadow_ray].t >= 0) hit.lit = 0;
            vec3 o = opt.shading == Shading::kNormals
                         ? hit.n * 0.5f + 0.5f
                         : hit.albedo * (0.22f + 0.78f * hit.lit) +
                               vec3(0.06f) * pow8(std::max(0.0f, math::dot(hit.n, -hit.dir)));
            if (hit.highlight) o = o * 0.45f + vec3(1.0f, 0.5f, 0.08f) * 0.55f;
            if (!heatmap) {
                const uint32_t row = hit.pixel / w, i = hit.pixel % w;
                store_rgb8(curve, o, &img.rgb[3 * (tile_first + size_t(row) * W + i)]);
            }
        }
        Counters sum = cone_counters;
        uint32_t tile_max = 0;
        // (the other pixels count nothing: their heatmap counts stay 0)
        for (uint32_t r = 0; r < n_rays; ++r) {
            const uint32_t j = ray_pixel[r];
            const uint32_t e = uint32_t(std::min<uint64_t>(counters[j].evals, 0xffffffffu));
            if (heatmap) evals[tile_first + size_t(j / w) * W + j % w] = e;
            tile_max = std::max(tile_max, e);
            sum.steps += counters[j].steps;
            sum.evals += counters[j].evals;
        }
        uint32_t seen = max_evals.load();
        while (seen < tile_max && !max_evals.compare_exchange_weak(seen, tile_max)) {
        }
        total_steps += sum.steps;
        total_evals += sum.evals;
        hits += n_hits;
    };
    parallel_for<NotCancellable>(tiles, parallel_options(opt), trace_tile);

    const double trace_ms = ms_since(t_start);
    const TraceTotals totals{trace_ms, total_steps, total_evals, hits};
    if (heatmap) {
        std::vector<vec3> color(size_t(W) * H);  // finish_image colors it from `evals`
        return finish_image(opt, color, evals, totals, stats);
    }
    set_render_stats(opt, totals, max_evals.load(), stats);
    return img;
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
    set_render_stats(opt, totals, max_evals, stats);
    return img;
}

void set_render_stats(const RenderOptions& opt, const TraceTotals& totals, double max_evals,
                      RenderStats* stats) {
    if (!stats) return;
    const double px = double(opt.width) * opt.height;
    stats->trace_ms = totals.trace_ms;
    stats->steps_avg = double(totals.steps) / px;
    stats->evals_avg = double(totals.evals) / px;
    stats->hit_fraction = double(totals.hits) / px;
    stats->evals_max = max_evals;
}

Image render(const PrunedGrid& grid, const RenderOptions& options, RenderStats* stats) {
    const Scene& sc = grid.scene();
    const auto t_start = std::chrono::steady_clock::now();
    return trace_image(PrunedField(grid, options.convex_steps), sc, options, stats, t_start);
}

PickResult pick(const PrunedGrid& grid, const RenderOptions& opt, uint32_t x, uint32_t y) {
    if (x >= opt.width || y >= opt.height)
        throw std::invalid_argument("pick: pixel (" + std::to_string(x) + ", " + std::to_string(y) +
                                    ") lies outside the image");
    const Scene& sc = grid.scene();
    const TraceContext ctx{sc, 1.0f / sc.lipschitz[sc.root()], sc.aabb.min, sc.aabb.max,
                           opt.convex_steps};
    const CameraFrame frame = camera_frame(sc, opt);
    const vec3 eye = opt.camera.eye, dir = pixel_direction(frame, opt.width, opt.height, x, y);
    const vec3 inv(1.0f / dir.x, 1.0f / dir.y, 1.0f / dir.z);
    std::vector<float> stack(sc.max_stack);
    std::vector<uint32_t> winners(sc.max_stack);
    PickResult r;
    float t0, t1;
    Counters c;
    const PrunedField field(grid);
    if (!ray_box(eye, inv, field.march_box().min, field.march_box().max, t0, t1)) return r;
    Ray ray{eye, dir, t0, t1, 1024, -1, &c};
    march(field, ctx, std::span(&ray, 1), stack.data());
    const float t = ray.t;
    if (t < 0) return r;
    r.hit = true;
    r.t = t;
    r.point = eye + dir * t;
    r.primitive =
        eval_tape_winner(sc, field.hint_at(r.point).tape, r.point, stack.data(), winners.data());
    return r;
}

Image render_naive(const Scene& scene, const RenderOptions& options, RenderStats* stats) {
    return trace_image(NaiveField{scene}, scene, options, stats, std::chrono::steady_clock::now());
}

}  // namespace sdfprune
