#version 450
// trace.comp — sphere tracing on the pruned grid, one pixel per thread: a primary ray, the
// tetrahedron-stencil normal, the blended color, and a shadow ray. Mirrors march() and
// trace_image() in src/render/trace.cpp; the host finishes the image (background, sRGB,
// heatmap) exactly as the CPU tracer does. A pixel whose hit point or normal needs the full
// tree (as the CPU's PrunedField::tape_at gives it) is finished in the full-tree pass
// (slice.glsl).
#extension GL_GOOGLE_include_directive : require
#define SCENE_STACK_BINDING 8
#include "scene.glsl"
#include "grid.glsl"
#include "slice.glsl"

layout(local_size_x = 64) in;

struct TraceParams {
    GridParams grid;
    vec4 march_min;  // the box rays are marched in (PrunedGrid::near_box)
    vec4 march_max;
    vec4 eye;      // w: tan(fov / 2)
    vec4 forward;  // w: aspect
    vec4 right;    // w: normal step h
    vec4 up;
    vec4 light;
    uint width, height, shading, shadows;
};
struct Pixel {
    vec4 color;  // linear rgb; w: 1 if the primary ray hit
    uint evals;  // node evaluations
    uint steps;  // tracing steps
    uint pad0, pad1;
};

layout(std430, binding = 6) readonly buffer TraceParamBlock { TraceParams prm; };
layout(std430, binding = 7) writeonly buffer Pixels { Pixel pixels[]; };  // from index base


// Ray / box intersection (trace.cpp's ray_box): false if missed, always if the box is empty
// (some min > max: PrunedGrid::near_box without a near-field cell), which the slab tests alone
// would take for the box between its corners.
bool ray_box(vec3 o, vec3 inv_dir, vec3 lo, vec3 hi, out float t0, out float t1) {
    t0 = 0.0;
    t1 = kInfinity;
    if (!all(lessThanEqual(lo, hi))) return false;
    for (int a = 0; a < 3; ++a) {
        float ta = (lo[a] - o[a]) * inv_dir[a], tb = (hi[a] - o[a]) * inv_dir[a];
        if (ta > tb) {
            float s = ta;
            ta = tb;
            tb = s;
        }
        t0 = t0 < ta ? ta : t0;
        t1 = tb < t1 ? tb : t1;
    }
    return t0 <= t1;
}

uint g_evals = 0u, g_steps = 0u;
// Set when the pixel needs a tape this pass's stack cannot hold (stack_holds): its values from
// then on are meaningless, and the pixel is deferred to the full-tree pass.
bool g_deferred = false;

// The value of `tape` at p, counted in g_evals; 0 and g_deferred set if the stack cannot hold
// the tape's evaluation.
float value_of(uint tape, vec3 p) {
    if (!stack_holds(tape)) {
        g_deferred = true;
        return 0.0;
    }
    g_evals += pool[tape];
    return eval_tape(tape, p, gl_GlobalInvocationID.x, pc.stack_threads);
}

float march(vec3 o, vec3 dir, float t0, float t1, uint max_steps) {
    GridParams g = prm.grid;
    vec3 inv_dir = vec3(1.0 / dir.x, 1.0 / dir.y, 1.0 / dir.z);
    // the octant the ray heads into: which 4 bits of a far-field cell's word are its clearance
    // (clearance_in, prune.hpp)
    uint octant_shift =
        4u * ((dir.x > 0.0 ? 1u : 0u) | (dir.y > 0.0 ? 2u : 0u) | (dir.z > 0.0 ? 4u : 0u));
    uint near_tape = 0u;
    vec3 near_lo = vec3(kInfinity), near_hi = vec3(-kInfinity);
    precise float t = t0;
    for (uint step = 0u; step < max_steps && t <= t1; ++step) {
        ++g_steps;
        precise vec3 p = min(max(o + dir * t, g.aabb_min.xyz), g.aabb_max.xyz);
        uint tape = kFullTreeTape;  // (p is clamped into the grid: only NaN finds no cell)
        bool cached = p.x >= near_lo.x && p.y >= near_lo.y && p.z >= near_lo.z &&
                      p.x <= near_hi.x && p.y <= near_hi.y && p.z <= near_hi.z;
        Located at;
        if (cached) {
            tape = near_tape;
        } else if (locate(g, p, at)) {
            vec3 size = level_cell_size(g, at.level);
            precise vec3 lo = g.aabb_min.xyz + vec3(at.cell) * size;
            if (at.c.tape == kFarField) {
                // the exit of the box of clear cells from this one, r cells the ray's way
                float r = float((at.c.children >> octant_shift) & 15u);
                float t_exit = kInfinity;
                for (int a = 0; a < 3; ++a) {
                    precise float bound =
                        dir[a] > 0.0 ? lo[a] + size[a] * (r + 1.0) : lo[a] - size[a] * r;
                    float ta = (bound - o[a]) * inv_dir[a];
                    if (!isnan(ta)) t_exit = ta < t_exit ? ta : t_exit;
                }
                float from_centre =
                    abs(at.c.value) * g.aabb_max.w - length(p - (lo + size * 0.5));
                float stepv = max(abs(at.c.bound) * g.aabb_max.w, from_centre);
                float tiny = 1e-4 * min(size.x, min(size.y, size.z));
                t = max(t + stepv, t_exit + tiny);
                continue;
            }
            tape = at.c.tape;
            near_tape = tape;
            near_lo = lo;
            near_hi = lo + size;
        }
        float d = value_of(tape, p);
        if (g_deferred) return -1.0;
        if (d < 5e-4 * min(1.0, t)) return t;
        t += d * g.aabb_max.w;
    }
    return -1.0;
}

// The tape valid at p: its near-field cell's, else the full tree's.
uint tape_at(vec3 p) {
    Located at;
    if (!locate(prm.grid, p, at) || at.c.tape == kFarField) return kFullTreeTape;
    return at.c.tape;
}

float value_at(vec3 p, uint hint) {
    Located at;
    uint tape = hint;
    if (locate(prm.grid, p, at) && at.c.tape != kFarField) tape = at.c.tape;
    return value_of(tape, p);
}

void main() {
    uint tid = gl_GlobalInvocationID.x;
    if (tid >= pc.count) return;
    uint index = slice_item(tid);
    uint x = index % prm.width, y = index / prm.width;
    GridParams g = prm.grid;
    float tan_half = prm.eye.w, aspect = prm.forward.w, h = prm.right.w;
    vec3 eye = prm.eye.xyz, forward = prm.forward.xyz, right = prm.right.xyz, up = prm.up.xyz;
    vec3 light = prm.light.xyz;
    float u = (2.0 * (float(x) + 0.5) / float(prm.width) - 1.0) * tan_half * aspect;
    float v = (1.0 - 2.0 * (float(y) + 0.5) / float(prm.height)) * tan_half;
    vec3 dir = forward + right * u + up * v;
    dir = dir / length(dir);
    vec3 inv = vec3(1.0 / dir.x, 1.0 / dir.y, 1.0 / dir.z);
    float t0, t1;
    vec4 out_color = vec4(0.0);
    if (ray_box(eye, inv, prm.march_min.xyz, prm.march_max.xyz, t0, t1)) {
        float t = march(eye, dir, t0, t1, 1024u);
        if (g_deferred) {
            defer_item(index);
            return;
        }
        if (t >= 0.0) {
            precise vec3 p = eye + dir * t;
            uint tape = tape_at(p);
            // The normal and color then use this tape wherever no near-field cell decides.
            if (!stack_holds(tape)) {
                defer_item(index);
                return;
            }
            vec3 n = vec3(0.0);
            n = n + vec3(1.0, -1.0, -1.0) * value_at(p + vec3(1.0, -1.0, -1.0) * h, tape);
            n = n + vec3(-1.0, -1.0, 1.0) * value_at(p + vec3(-1.0, -1.0, 1.0) * h, tape);
            n = n + vec3(-1.0, 1.0, -1.0) * value_at(p + vec3(-1.0, 1.0, -1.0) * h, tape);
            n = n + vec3(1.0, 1.0, 1.0) * value_at(p + vec3(1.0, 1.0, 1.0) * h, tape);
            float len = length(n);
            n = len > 0.0 ? n / len : -dir;
            g_evals += pool[tape];
            vec3 albedo = eval_tape_color(tape, p, tid, pc.stack_threads);
            float lit = max(0.0, dot(n, light));
            if (prm.shadows != 0u && lit > 0.0) {
                precise vec3 so = p + n * (4.0 * h);
                vec3 sinv = vec3(1.0 / light.x, 1.0 / light.y, 1.0 / light.z);
                float s0, s1;
                if (ray_box(so, sinv, prm.march_min.xyz, prm.march_max.xyz, s0, s1) &&
                    march(so, light, s0 + h, s1, 512u) >= 0.0)
                    lit = 0.0;
                if (g_deferred) {
                    defer_item(index);
                    return;
                }
            }
            vec3 c = prm.shading == 1u
                         ? n * 0.5 + 0.5
                         : albedo * (0.22 + 0.78 * lit) +
                               vec3(0.06) * pow(max(0.0, dot(n, -dir)), 8.0);
            out_color = vec4(c, 1.0);
        }
    }
    probe_loop_limit();
    pixels[index - pc.base].color = out_color;
    pixels[index - pc.base].evals = g_evals;
    pixels[index - pc.base].steps = g_steps;
}
