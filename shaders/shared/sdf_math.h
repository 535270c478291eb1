// sdf_math.h — the math of sdfprune, written once: primitive SDFs, the blending kernel, the
// unified CSG operator, the pruning test and the tape-word packing (DESIGN.md §2–3).
// It is valid C++20 (through glsl_compat.hpp) and GLSL 450, so the CPU backend and the Vulkan
// shaders cannot drift. Rules for this file: value parameters only, no recursion, no templates,
// no swizzles (C++ has none), float literals with an 'f' suffix, every id defined here once.
#ifndef SDFPRUNE_SDF_MATH_H
#define SDFPRUNE_SDF_MATH_H

#ifdef __cplusplus
#include "glsl_compat.hpp"
#define SDFPRUNE_FN inline
#define SDFPRUNE_CONST inline constexpr
#define SDFPRUNE_PRECISE  // the CPU build contracts nothing (-ffp-contract=off)
namespace sdfprune::math {
using namespace sdfprune::glsl;
#else
#define SDFPRUNE_FN
#define SDFPRUNE_CONST const
#define SDFPRUNE_PRECISE precise  // no fused multiply-add: it rounds as on the CPU
#endif
// What a primitive's and an operator's values, and the lengths that ranges and far-field tests
// take, pass through: themselves, but in the shaders of a test build that stands in for a GPU
// whose rounding differs from the CPU's (scene.glsl: SDFPRUNE_ROUNDING_SALT).
#ifndef SDFPRUNE_DEVICE_ROUNDING
#define SDFPRUNE_DEVICE_ROUNDING(x) (x)
#endif

// ---- ids, defined once ----------------------------------------------------------------------
// Primitive kinds (a node's kind < kPrimitiveKindCount means it is a primitive).
SDFPRUNE_CONST uint kPrimSphere = 0u;
SDFPRUNE_CONST uint kPrimBox = 1u;
SDFPRUNE_CONST uint kPrimCylinder = 2u;
SDFPRUNE_CONST uint kPrimCone = 3u;
SDFPRUNE_CONST uint kPrimCapsule = 4u;
SDFPRUNE_CONST uint kPrimTorus = 5u;
SDFPRUNE_CONST uint kPrimRoundedCylinder = 6u;
SDFPRUNE_CONST uint kPrimCappedCone = 7u;
SDFPRUNE_CONST uint kPrimHexPrism = 8u;
SDFPRUNE_CONST uint kPrimOctahedron = 9u;
SDFPRUNE_CONST uint kPrimPlane = 10u;
SDFPRUNE_CONST uint kPrimitiveKindCount = 11u;
// Operator kinds, stored in the same field as the primitive kinds.
SDFPRUNE_CONST uint kOpUnion = 16u;
SDFPRUNE_CONST uint kOpIntersection = 17u;
SDFPRUNE_CONST uint kOpDifference = 18u;

// Pruning decisions for one operator in one cell.
SDFPRUNE_CONST uint kKeepBoth = 0u;
SDFPRUNE_CONST uint kLeftWins = 1u;
SDFPRUNE_CONST uint kRightWins = 2u;

// ---- tape words: 31-bit node index + sign bit --------------------------------------------------
SDFPRUNE_CONST uint kTapeSignBit = 0x80000000u;
SDFPRUNE_CONST uint kTapeNodeMask = 0x7fffffffu;

SDFPRUNE_FN uint tape_word(uint node, bool negate) {
    return negate ? (node | kTapeSignBit) : node;
}
SDFPRUNE_FN uint tape_node(uint word) { return word & kTapeNodeMask; }
SDFPRUNE_FN bool tape_negated(uint word) { return (word & kTapeSignBit) != 0u; }
SDFPRUNE_FN float tape_sign(uint word) { return tape_negated(word) ? -1.0f : 1.0f; }

// ---- primitives ------------------------------------------------------------------------------
// One primitive in std430 layout: rows of the world->local 3x4 affine map, then three parameter
// vectors whose meaning depends on the kind (see Scene in include/sdfprune/scene.hpp):
//   sphere   a.x radius
//   box      a.xyz half sides, b = corner radii (x>0,z>0 / x>0,z<0 / x<0,z>0 / x<0,z<0),
//            c.x top (+y) edge rounding, c.y bottom (-y) edge rounding
//   cylinder a.x half height (y), a.y radius
//   cone     a.x base radius (at y = -h), a.y half height h
//   capsule  a.x half length of the inner segment (y), a.y radius
//   torus    a.x major radius (in xz), a.y minor radius
//   rounded_cylinder  a.x half height (y), a.y radius, a.z rim rounding
//   capped_cone       a.x half height h (y), a.y radius at y = -h, a.z radius at y = +h
//   hex_prism         a.x apothem a (the hexagon's inradius, flat sides at z = ±a), a.y half height
//   octahedron        a.x radius s (|x| + |y| + |z| <= s)
//   plane             a.xyz normal n (any length), a.w offset: the half-space dot(q, n/|n|) <=
//   offset
// (include/sdfprune/primitives.hpp maps each kind's scene-file fields to these slots.)
// Every primitive below is an exact distance (1-Lipschitz, |f| = distance to the surface), so the
// Lipschitz range f(c) ± L·R holds; each bounded one says why it lies in the ball of radius rho
// that similarity_range uses (primitives.hpp gives rho and the local box).
struct PrimitiveParams {
    vec4 row0;
    vec4 row1;
    vec4 row2;
    vec4 a;
    vec4 b;
    vec4 c;
};

SDFPRUNE_FN vec3 to_local(PrimitiveParams prm, vec3 p) {
    return vec3(prm.row0.x * p.x + prm.row0.y * p.y + prm.row0.z * p.z + prm.row0.w,
                prm.row1.x * p.x + prm.row1.y * p.y + prm.row1.z * p.z + prm.row1.w,
                prm.row2.x * p.x + prm.row2.y * p.y + prm.row2.z * p.z + prm.row2.w);
}

SDFPRUNE_FN float sd_sphere(vec3 q, float radius) { return length(q) - radius; }

// 2D rectangle (half sizes hs) with one corner radius per quadrant of p = (x, z).
SDFPRUNE_FN float sd_rounded_rect(vec2 p, vec2 hs, vec4 radii) {
    float r = p.x > 0.0f ? (p.y > 0.0f ? radii.x : radii.y) : (p.y > 0.0f ? radii.z : radii.w);
    vec2 q = abs(p) - hs + r;
    return min(max(q.x, q.y), 0.0f) + length(max(q, 0.0f)) - r;
}

// Extrudes a 2D distance d along y to |y| <= h, rounding the rim by `rounding`.
SDFPRUNE_FN float sd_extrude(float d, float y, float h, float rounding) {
    vec2 q = vec2(d + rounding, abs(y) - (h - rounding));
    return min(max(q.x, q.y), 0.0f) + length(max(q, 0.0f)) - rounding;
}

SDFPRUNE_FN float sd_box(vec3 q, vec3 hs, vec4 corner_radii, float round_top, float round_bottom) {
    float d2 = sd_rounded_rect(vec2(q.x, q.z), vec2(hs.x, hs.z), corner_radii);
    float rounding = q.y > 0.0f ? round_top : round_bottom;
    return sd_extrude(d2, q.y, hs.y, rounding);
}

SDFPRUNE_FN float sd_cylinder(vec3 q, float half_height, float radius) {
    vec2 d = abs(vec2(length(vec2(q.x, q.z)), q.y)) - vec2(radius, half_height);
    return min(max(d.x, d.y), 0.0f) + length(max(d, 0.0f));
}

// Cone with its base disc (radius) at y = -h and its apex at y = +h.
SDFPRUNE_FN float sd_cone(vec3 q, float radius, float h) {
    vec2 p = vec2(length(vec2(q.x, q.z)) - radius, q.y + h);
    vec2 e = vec2(-radius, 2.0f * h);
    vec2 d = p - e * clamp(dot(p, e) / dot(e, e), 0.0f, 1.0f);
    float dist = length(d);
    if (max(d.x, d.y) > 0.0f) return dist;
    return -min(dist, p.y);
}

SDFPRUNE_FN float sd_capsule(vec3 q, float half_length, float radius) {
    return length(vec3(q.x, q.y - clamp(q.y, -half_length, half_length), q.z)) - radius;
}

SDFPRUNE_FN float sd_torus(vec3 q, float major, float minor) {
    return length(vec2(length(vec2(q.x, q.z)) - major, q.y)) - minor;
}

// A cylinder (half height h, radius r, along y) with both rims rounded by `rounding` <= min(r, h):
// the Minkowski sum of the convex cylinder (r − rounding, h − rounding) and a ball of radius
// `rounding`, whose exact signed distance is the inner cylinder's minus `rounding` (sd_extrude of
// the disc). Range: the shape lies in the cylinder (r, h), so in the ball of radius |(r, h)|.
SDFPRUNE_FN float sd_rounded_cylinder(vec3 q, float half_height, float radius, float rounding) {
    return sd_extrude(length(vec2(q.x, q.z)) - radius, q.y, half_height, rounding);
}

// A cone frustum along y: radius r1 at y = -h, r2 at y = +h (either may be 0, not both). In the
// (rho, y) half-plane its profile is a convex trapezoid; the value is the distance to the nearer
// of the cap segment on the point's side (ca) and the slanted side (cb), negative inside: the
// exact signed distance. Range: the shape lies in the cylinder (max(r1, r2), h), so in the ball
// of radius |(max(r1, r2), h)|.
SDFPRUNE_FN float sd_capped_cone(vec3 q, float h, float r1, float r2) {
    vec2 p = vec2(length(vec2(q.x, q.z)), q.y);
    vec2 k1 = vec2(r2, h);
    vec2 k2 = vec2(r2 - r1, 2.0f * h);
    vec2 ca = vec2(p.x - min(p.x, p.y < 0.0f ? r1 : r2), abs(p.y) - h);
    vec2 cb = p - k1 + k2 * clamp(dot(k1 - p, k2) / dot(k2, k2), 0.0f, 1.0f);
    float s = (cb.x < 0.0f && ca.y < 0.0f) ? -1.0f : 1.0f;
    return s * sqrt(min(dot(ca, ca), dot(cb, cb)));
}

// A hexagonal prism along y: a regular hexagon in xz with vertices at x = ±2a/√3 and flat sides
// at z = ±a (a: the apothem), extruded to |y| <= h. Reflections (isometries) fold (x, z) into the
// sector of the side z = a, where the 2D value is the signed distance to that side's segment:
// exact. The extrusion of an exact 2D distance is exact. Range: the shape lies in the cylinder
// (2a/√3, h), so in the ball of radius |(2a/√3, h)|.
SDFPRUNE_FN float sd_hex_prism(vec3 q, float apothem, float h) {
    vec2 k = vec2(-0.8660254f, 0.5f);
    vec2 p = abs(vec2(q.x, q.z));
    p = p - 2.0f * min(dot(k, p), 0.0f) * k;
    float half_side = 0.57735027f * apothem;
    float e = length(p - vec2(clamp(p.x, -half_side, half_side), apothem));
    vec2 w = vec2(p.y > apothem ? e : -e, abs(q.y) - h);
    return min(max(w.x, w.y), 0.0f) + length(max(w, 0.0f));
}

// The regular octahedron |x| + |y| + |z| <= s (vertices on the axes at distance s). Where the
// point projects into its octant's face (every |p_i| >= m/3, m = |x| + |y| + |z| − s; always so
// inside) the distance is to that face's plane, m/√3 (inside, the octant's face plane is the
// nearest of the eight). Elsewhere it is the distance to the face's boundary: in the octant's
// frame rotated so that the coordinate below m/3 comes first, to the edge from (0, s, 0) to
// (0, 0, s), clamped to it. Exact (1-Lipschitz). Range: the shape lies in the ball of radius s.
SDFPRUNE_FN float sd_octahedron(vec3 q, float s) {
    vec3 p = abs(q);
    float m = p.x + p.y + p.z - s;
    vec3 r;
    if (3.0f * p.x < m) {
        r = p;
    } else if (3.0f * p.y < m) {
        r = vec3(p.y, p.z, p.x);
    } else if (3.0f * p.z < m) {
        r = vec3(p.z, p.x, p.y);
    } else {
        return m * 0.57735027f;
    }
    float k = clamp(0.5f * (r.z - r.y + s), 0.0f, s);
    return length(vec3(r.x, r.y - s + k, r.z - k));
}

// The half-space dot(q, n)/|n| <= offset: the exact signed distance to its boundary plane
// (1-Lipschitz, so the Lipschitz range holds). Unbounded: no ball holds it and f(q) >= |q| − rho
// fails for every rho, so it gets no similarity bound (PrimitiveBound::scale = 0) and pruning
// uses its Lipschitz range only; scenes with one need care for their AABB (bounding_box).
SDFPRUNE_FN float sd_plane(vec3 q, vec3 n, float offset) {
    return dot(q, n) / length(n) - offset;
}

SDFPRUNE_FN float eval_primitive_local(uint kind, PrimitiveParams prm, vec3 q) {
    if (kind == kPrimSphere) return sd_sphere(q, prm.a.x);
    if (kind == kPrimBox)
        return sd_box(q, vec3(prm.a.x, prm.a.y, prm.a.z), prm.b, prm.c.x, prm.c.y);
    if (kind == kPrimCylinder) return sd_cylinder(q, prm.a.x, prm.a.y);
    if (kind == kPrimCone) return sd_cone(q, prm.a.x, prm.a.y);
    if (kind == kPrimCapsule) return sd_capsule(q, prm.a.x, prm.a.y);
    if (kind == kPrimTorus) return sd_torus(q, prm.a.x, prm.a.y);
    if (kind == kPrimRoundedCylinder) return sd_rounded_cylinder(q, prm.a.x, prm.a.y, prm.a.z);
    if (kind == kPrimCappedCone) return sd_capped_cone(q, prm.a.x, prm.a.y, prm.a.z);
    if (kind == kPrimHexPrism) return sd_hex_prism(q, prm.a.x, prm.a.y);
    if (kind == kPrimOctahedron) return sd_octahedron(q, prm.a.x);
    return sd_plane(q, vec3(prm.a.x, prm.a.y, prm.a.z), prm.a.w);
}

SDFPRUNE_FN float eval_primitive(uint kind, PrimitiveParams prm, vec3 p) {
    return SDFPRUNE_DEVICE_ROUNDING(eval_primitive_local(kind, prm, to_local(prm, p)));
}

// Whether a primitive's value is a convex function of the point. The exact signed distance of
// a convex solid is one: it is the largest of the signed distances to the planes that support
// the solid, each affine in the point. A convex function of an affine map of the point (a
// primitive's placement: rotation, scale, shear) is convex in the point. Every kind is the exact
// distance of a convex solid, but the torus. The CPU tracer's convex steps rely on it: the
// secant of a convex function, extended, lies below it (PrimitivesExact.ConvexKinds... tests it).
SDFPRUNE_FN bool primitive_value_is_convex(uint kind) { return kind != kPrimTorus; }

// ---- operators -------------------------------------------------------------------------------
// The quadratic blending kernel phi(x, k) = max(k - x, 0)^2 / (4k); 0 when k = 0.
// Written as selects, without branches, so that loops over boxes vectorize.
SDFPRUNE_FN float blend_kernel(float x, float k) {
    float m = max(k - x, 0.0f);
    return k > 0.0f ? m * m / (4.0f * k) : 0.0f;
}

// s = +1: union; s = -1: intersection (a difference is an intersection whose right operand
// was negated by its tape sign). a and b are the operands with their signs applied.
SDFPRUNE_FN float apply_operator(float s, float k, float a, float b) {
    return SDFPRUNE_DEVICE_ROUNDING(s * (min(s * a, s * b) - blend_kernel(abs(a - b), k)));
}

SDFPRUNE_FN float operator_s(uint kind) { return kind == kOpUnion ? 1.0f : -1.0f; }

// The weight of operand b in apply_operator's result (its partial derivative; a's is 1 − it):
// used to blend the operands' colors the way the smooth operator blends their shapes.
SDFPRUNE_FN float operator_weight_b(float s, float k, float a, float b) {
    float h = k > 0.0f ? max(k - abs(a - b), 0.0f) / (2.0f * k) : 0.0f;
    return s * b < s * a ? 1.0f - h : h;
}

// ---- pruning ---------------------------------------------------------------------------------
// Relative safety margin of the pruning test: float rounding in the values at the cell centre
// can never make an operator look decided when it is not.
SDFPRUNE_CONST float kPruneMarginRel = 4e-6f;
SDFPRUNE_CONST float kPruneMarginAbs = 1e-6f;

// Decides one operator over a cell, given a conservative range [lo, hi] of each (signed) operand
// over the cell. If one operand is below the other by more than k everywhere (in the operator's
// min-space), it wins everywhere and the kernel is zero everywhere: the operator can be replaced
// by it. With ranges centre ± L·R this is the paper's test |A − B| > (L_a + L_b)·R + k.
SDFPRUNE_FN uint prune_decision(float s, float k, float a_lo, float a_hi, float b_lo, float b_hi) {
    // Into min-space: the union of s·a and s·b.
    float ua_lo = s > 0.0f ? a_lo : -a_hi;
    float ua_hi = s > 0.0f ? a_hi : -a_lo;
    float ub_lo = s > 0.0f ? b_lo : -b_hi;
    float ub_hi = s > 0.0f ? b_hi : -b_lo;
    float margin = kPruneMarginAbs +
                   kPruneMarginRel * (abs(a_lo) + abs(a_hi) + abs(b_lo) + abs(b_hi) + k);
    // Selects rather than branches (loops over boxes vectorize); at most one test holds.
    uint right_wins = ub_hi + k + margin < ua_lo ? kRightWins : kKeepBoth;
    return ua_hi + k + margin < ub_lo ? kLeftWins : right_wins;
}

// Sub-box refinement of finest cells (PruneOptions::refine) is for short tapes only: its cost
// grows with the tape's length times the sub-boxes, its gain is in the few operators of the
// cells near blends.
SDFPRUNE_CONST uint kRefineMaxTape = 128u;

// Whether an operator of blend radius k whose operands are worth a and b (signs applied) at a
// cell's centre might be decided in every sub-box of the cell (refinement). It must then be
// decided in the sub-box holding the centre, whose operand ranges hold a and b, so one operand
// lies below the other there by more than k (prune_decision) plus a margin that covers the
// rounding of a and b. Operands within 0.9·k of each other, less a rounding allowance, never
// are: the centre lies deep in the operator's blend. (A hard operator, k = 0, always might.)
SDFPRUNE_FN bool blend_may_decide(float a, float b, float k) {
    return !(abs(a - b) < 0.9f * k - 1e-5f * (abs(a) + abs(b)));
}

// Lower (x) and upper (y) bound of an undecided operator over a cell from its operands' ranges.
// Every operator is non-decreasing in both operands (d/da of the smooth min is in [1/2, 1]), so
// its range over a box of operand values is spanned by the box's two extreme corners.
SDFPRUNE_FN vec2 operator_range(float s, float k, float a_lo, float a_hi, float b_lo, float b_hi) {
    return vec2(apply_operator(s, k, a_lo, b_lo), apply_operator(s, k, a_hi, b_hi));
}

// Range over an axis-aligned cell (centre cc, half sizes hs) of a primitive whose world->local
// map is a similarity of scale `scale` sending `centre` to the local origin, given f0 = the local
// SDF at the origin and rho = the radius of a local ball around the origin holding the shape.
// Uses |q| - rho <= f(q) <= |q| + f0 (f is 1-Lipschitz); exact for a sphere (f0 = -r, rho = r).
// `scale` is the map's scale rounded down by up to 2e-6 (PrimitiveBound): right for the lower
// bound, but the upper one needs it rounded up, or a far-field constant deep inside a large
// primitive ends up a few 1e-6 beyond f (fuzz/regressions/prune_eval/sphere_far_field_scale.bin).
SDFPRUNE_FN vec2 similarity_range(vec3 centre, float scale, float f0, float rho, vec3 cc, vec3 hs) {
    vec3 d = abs(centre - cc);
    float near_dist = SDFPRUNE_DEVICE_ROUNDING(length(max(d - hs, 0.0f)));
    float far_dist = SDFPRUNE_DEVICE_ROUNDING(length(d + hs));
    return vec2(scale * near_dist - rho, scale * (1.0f + 6e-6f) * far_dist + f0);
}

// ---- a node's range over a box (the pruning steps of both backends) --------------------------
// A primitive's range over a box (centre p, half sizes h) from its value v at the centre: v ±
// spread (spread: its Lipschitz bound times the box's radius), narrowed by its similarity range
// where `narrow` (similarity_range's arguments): with interval bounds, for a primitive that has
// one (scale > 0; primitive_narrows).
SDFPRUNE_FN bool primitive_narrows(bool interval, float scale) { return interval && scale > 0.0f; }
SDFPRUNE_FN vec2 primitive_box_range(float v, float spread, bool narrow, vec3 centre, float scale,
                                     float f0, float rho, vec3 p, vec3 h) {
    vec2 r = vec2(v - spread, v + spread);
    if (narrow) {
        vec2 s = similarity_range(centre, scale, f0, rho, p, h);
        r = vec2(max(r.x, s.x), min(r.y, s.y));
    }
    return r;
}
// An operator's range over a box, from its decision there (prune_decision) and its operands'
// ranges [a_lo, a_hi] and [b_lo, b_hi]: a skipped operator's range is its winner's. Else, with
// `lipschitz`, v ± spread around its value v at the centre, narrowed with interval bounds by its
// range over its operands' ranges (operator_range); without (refinement's sub-boxes, interval
// bounds only), that range alone. It holds the Lipschitz range up to rounding: every operator
// is 1-Lipschitz in the max-norm of its operands and shift-invariant (op(a − t, b − t) =
// op(a, b) − t), and each operand's range holds its own Lipschitz range, so op(a_lo, b_lo) >=
// op(a, b) − max(L_a, L_b)·R (the operator's L is that max), and alike above. Selects, no
// branches on the decision, so that the CPU's loop over boxes vectorizes.
SDFPRUNE_FN vec2 operator_box_range(uint decision, float s, float k, float v, float spread,
                                    bool interval, bool lipschitz, float a_lo, float a_hi,
                                    float b_lo, float b_hi) {
    float lo = v - spread, hi = v + spread;
    if (interval) {
        vec2 r = operator_range(s, k, a_lo, a_hi, b_lo, b_hi);
        lo = lipschitz ? max(lo, r.x) : r.x;
        hi = lipschitz ? min(hi, r.y) : r.y;
    }
    bool left = decision == kLeftWins, right = decision == kRightWins;
    return vec2(left ? a_lo : (right ? b_lo : lo), left ? a_hi : (right ? b_hi : hi));
}

// ---- far field -------------------------------------------------------------------------------
// The far-field test of a (sub-)box of radius R: its root's range [lo, hi], widened by the
// rounding margin of the value v at its centre (L: the root's Lipschitz bound) ...
SDFPRUNE_FN vec2 far_field_range(float v, float lo, float hi, float L, float R) {
    float margin = kPruneMarginAbs + kPruneMarginRel * (abs(v) + L * R);
    return vec2(lo - margin, hi + margin);
}
// ... must clear the cell's clearance above zero or below it. The clearance of a cell of radius
// R under far-field threshold C, for a root with Lipschitz bound L, is (C − 1)·max(L, 1)·R. It
// makes two promises about every point p of a far-field cell:
//   |f(p)| >= (C − 1)·R          (a point with |f| < (C − 1)·R is always in a near-field cell);
//   dist(p, surface) >= (C − 1)·R  (since |f(p)| <= L·dist(p, surface)).
// The paper's test (L = 1) is |f(c)| > C·R. For L > 1 the first promise alone would let the
// surface come within (C − 1)·R/L; for L < 1 (a primitive enlarged by its transform) the second
// alone, (C − 1)·L·R, let cells whose |f| was as small as (C − 1)·L·R become far-field, and the
// pruned grid returned a constant where users expect the exact value (issue 12).
SDFPRUNE_FN float far_field_clearance(float far_field_c, float L, float R) {
    return (far_field_c - 1.0f) * max(L, 1.0f) * R;
}
SDFPRUNE_FN bool clears_above(float lo, float clearance) { return lo > clearance && lo > 0.0f; }
SDFPRUNE_FN bool clears_below(float hi, float clearance) { return hi < -clearance && hi < 0.0f; }

// Whether refinement's far-field test (every sub-box of a cell clears the cell's clearance) can
// pass for a cell whose tape's value at the centre is `value`. It must pass in the sub-box that
// holds the centre, whose range holds `value` within rounding: so not when |value| lies well
// inside the clearance (0.9 of it: rounding is far below a tenth). For a tape of one primitive
// under a similarity map of scale sigma (> 0; a lower bound of it), sigma times an exact signed
// distance, not either when |value| lies inside the clearance plus sigma·h (h: the cell's
// smallest half side, `half_size` its half sizes): from the centre towards the nearest surface point
// |f| falls at rate sigma, so the cell, which holds the ball of radius h about its centre, has a
// point where |f| <= |value| − sigma·h, in a sub-box whose range reaches as low. `sigma` <= 0:
// no such primitive.
SDFPRUNE_FN bool refine_far_possible(float value, float clearance, float sigma, vec3 half_size) {
    float reach = sigma > 0.0f ? sigma * min(half_size.x, min(half_size.y, half_size.z)) : 0.0f;
    return abs(value) > 0.9f * (clearance + reach);
}

// The reach of a far-field cell's centre value over `distance` with Lipschitz bound
// `lipschitz`, rounding margins included (PrunedGrid::far_field_constant, discretization) ...
SDFPRUNE_FN float far_field_reach(float lipschitz, float distance) {
    return lipschitz * distance * (1.0f + 1e-5f) + kPruneMarginAbs;
}
// ... and the constant of a point within that reach of a far-field cell's centre: the tighter
// of the cell's bound and the Lipschitz bound from its centre value (same sign as f, never
// larger in magnitude).
SDFPRUNE_FN float far_field_combine(float value, float bound, float reach) {
    float lipschitz_bound = abs(value) - reach;
    return value > 0.0f ? max(bound, lipschitz_bound) : min(bound, -lipschitz_bound);
}

// ---- the grid's cells (PrunedGrid and shaders/gpu/grid.glsl, the pruning steps) ---------------
// The centre of cell (x, y, z) of a grid of cells of size `size` from `origin`. Computed as
// written (SDFPRUNE_PRECISE), so that both backends find the same centre, and a point the same
// cell.
SDFPRUNE_FN vec3 cell_centre(vec3 origin, vec3 size, uint x, uint y, uint z) {
    SDFPRUNE_PRECISE vec3 centre =
        origin + vec3(float(x) + 0.5f, float(y) + 0.5f, float(z) + 0.5f) * size;
    return centre;
}
// The finest cell along one axis that holds coordinate x of a point in the grid's closed box
// (lo: its min face; inv_cell: 1 / the finest cells' size, as the host computes it; last: the
// finest resolution − 1): (x − lo) · inv_cell rounded down, at most `last` (on the max face it
// rounds to N or past).
SDFPRUNE_FN uint finest_cell_on_axis(float x, float lo, float inv_cell, uint last) {
    SDFPRUNE_PRECISE float q = (x - lo) * inv_cell;
    return min(uint(q), last);
}
// The index within its block of the cell of a level that holds finest cell (x, y, z): the
// level's cells are `scale` finest cells a side, its blocks `factor` cells a side, x fastest.
SDFPRUNE_FN uint block_local_index(uint x, uint y, uint z, uint scale, uint factor) {
    return (((z / scale) % factor) * factor + (y / scale) % factor) * factor + (x / scale) % factor;
}
// The far-field constant of finest cell (x, y, z) (of size `cell`, from `origin`) inside the
// far-field cell that decides it, `scale` finest cells a side, with centre value `value` and bound
// `bound`: the Lipschitz bound from the coarse centre over the distance to this finest cell's far
// corner, which is tighter than the coarse cell's own constant for cells near its centre.
SDFPRUNE_FN float far_field_cell_constant(vec3 origin, vec3 cell, uint scale, float lipschitz,
                                          float value, float bound, uint x, uint y, uint z) {
    vec3 coarse = cell_centre(origin, cell * float(scale), x / scale, y / scale, z / scale);
    vec3 d = abs(cell_centre(origin, cell, x, y, z) - coarse) + cell * 0.5f;
    return far_field_combine(value, bound,
                             far_field_reach(lipschitz, SDFPRUNE_DEVICE_ROUNDING(length(d))));
}

#ifdef __cplusplus
}  // namespace sdfprune::math
#endif

#endif  // SDFPRUNE_SDF_MATH_H
