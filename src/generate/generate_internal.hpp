// generate_internal.hpp — what the scene generators share: tree shapes (balanced unions,
// left-deep chains), exact primitive budgets, spatial ordering, placement helpers, and an
// Assembly that writes node descriptions directly for scenes of millions of primitives.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <span>
#include <vector>

#include "sdfprune/builder.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/scene.hpp"

namespace sdfprune::gen {

inline constexpr float kPi = std::numbers::pi_v<float>;

// ---- small vector helpers (the shared math header has no cross/normalize) -------------------
inline vec3 cross(vec3 a, vec3 b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline vec3 normalized(vec3 v) {
    return v / math::length(v);
}
inline vec3 lerp(vec3 a, vec3 b, float t) {
    return a + (b - a) * t;
}
inline float smoothstep(float e0, float e1, float x) {
    const float t = std::clamp((x - e0) / (e1 - e0), 0.0f, 1.0f);
    return t * t * (3 - 2 * t);
}

// ---- randomness: every draw is its own statement (argument evaluation order is unspecified) --
inline int uniform_int(Rng& rng, int lo, int hi) {  // in [lo, hi]
    return lo + int(rng.next_u64() % uint64_t(hi - lo + 1));
}
inline vec3 uniform_vec3(Rng& rng, float lo, float hi) {
    const float x = rng.uniform(lo, hi);
    const float y = rng.uniform(lo, hi);
    const float z = rng.uniform(lo, hi);
    return {x, y, z};
}
// `c` with each channel moved by up to ±amount, clamped to [0, 1].
vec3 vary(vec3 c, float amount, Rng& rng);
// One of `palette`, uniformly.
vec3 pick(std::span<const vec3> palette, Rng& rng);

// ---- tree shapes with SceneBuilder ----------------------------------------------------------
// Joins shapes pairwise, level by level: depth ceil(log2 n). Neighbours in the list end up in
// the same subtree, so a spatially ordered list gives spatially compact subtrees.
Shape union_all(std::span<const Shape> shapes, float k = 0);
// Left-deep: ((s0 ∪ s1) ∪ s2) ∪ ... — depth n − 1.
Shape chain(std::span<const Shape> shapes, float k = 0);

// Capsule / cylinder from a to b (their local y axis turned onto b − a).
Shape capsule_between(SceneBuilder& b, vec3 from, vec3 to, float radius);
Shape cylinder_between(SceneBuilder& b, vec3 from, vec3 to, float radius);
// The rotation that turns +y onto `dir` (unit or not).
Affine rotation_from_y(vec3 dir);
// A shape whose local +y axis (cylinder, cone, capsule axis; box extrusion) is turned onto
// world +z or +x, before any other placement.
inline Shape face_z(Shape s) {
    return s.rotated({1, 0, 0}, kPi / 2);
}
inline Shape face_x(Shape s) {
    return s.rotated({0, 0, 1}, -kPi / 2);
}
// A cube of side `size` standing in for the half-space n·(p − point) <= 0 near `point`: its
// face through `point` has outward normal `normal`. Intersect with it to cut a slope.
Shape half_space(SceneBuilder& b, vec3 point, vec3 normal, float size);

// ---- bounds ---------------------------------------------------------------------------------
// An AABB of the surface rather than of every primitive: primitive boxes combined up the tree
// (union: hull, grown by what smooth blends can add; intersection: overlap; difference: the
// left box), then padded by `pad` times its largest side. Cutters and half-space boxes do not
// inflate it.
Aabb surface_bounds(const Scene& scene, float pad = 0.04f);
// Turns -0 into +0 in the node and primitive matrices (the scene format reads "-0" as 0).
void positive_zeros(Scene& scene);
// builder.build(root) over surface_bounds(), zeros made positive.
Scene build_scene_of(const SceneBuilder& b, Shape root);

// ---- budgets and order ----------------------------------------------------------------------
// Splits `total` into parts in [lo, hi] that sum to it exactly (needs total >= lo and
// hi >= 2·lo − 1); part sizes are drawn from `rng`.
std::vector<uint32_t> split_budget(uint32_t total, uint32_t lo, uint32_t hi, Rng& rng);
// The permutation that sorts `points` along a Morton (Z-order) curve of their bounding box.
std::vector<uint32_t> morton_order(std::span<const vec3> points);
// Cells of a near-square grid for n items: cols >= rows, cols·rows >= n.
void grid_shape(uint32_t n, uint32_t& cols, uint32_t& rows);

// ---- Assembly: node descriptions written directly -------------------------------------------
// For scenes of up to millions of primitives. Objects are made by small SceneBuilders and
// appended as descriptions, single primitives written in place; balanced() and chain() join
// roots. Memory: one SceneNodeDesc per node (about 130 bytes), nothing else.
class Assembly {
  public:
    void reserve(size_t nodes) { nodes_.reserve(nodes); }
    // Appends the description of `root` (its placements baked); returns its root's index.
    uint32_t add(const SceneBuilder& b, Shape root);
    // One primitive; `world_to_local` maps world points into its frame.
    uint32_t add_primitive(uint32_t kind, const PrimitiveShape& shape, const Affine& world_to_local,
                           vec3 color);
    uint32_t sphere(vec3 centre, float radius, vec3 color);
    uint32_t combine(uint32_t op, uint32_t a, uint32_t b, float k);
    // Pairwise, level by level (see union_all); `roots` must be non-empty. Only the lowest
    // `smooth_levels` levels blend with k, the ones above are hard: a balanced tree of smooth
    // unions lowers the field by up to k/4 per level wherever many operands are close, which
    // bloats the shape and defeats pruning (far groups never look far).
    uint32_t balanced(std::span<const uint32_t> roots, uint32_t op, float k,
                      uint32_t smooth_levels = 0xffffffffu);
    // Left-deep.
    uint32_t chain(std::span<const uint32_t> roots, uint32_t op, float k);
    // The scene rooted at `root` over surface_bounds(); releases the descriptions.
    Scene build(uint32_t root);
    size_t size() const { return nodes_.size(); }

  private:
    std::vector<SceneNodeDesc> nodes_;
};

// ---- the generators (one per kind; count is already validated, 0 = the paper's size) --------
// organic.cpp
Scene character(uint64_t seed);
Scene raccoon(uint64_t seed);
Scene crowd(uint64_t seed, uint32_t primitives);
// particles.cpp
Scene molecule(uint64_t seed, uint32_t atoms);
Scene fluid(uint64_t seed, uint32_t spheres);
// devices.cpp
Scene console(uint64_t seed);
Scene gameboy(uint64_t seed);
Scene camera(uint64_t seed);
// vehicles.cpp
Scene car(uint64_t seed);
Scene car_chase(uint64_t seed);
Scene train_station(uint64_t seed);
// architecture.cpp
Scene city(uint64_t seed, uint32_t primitives);
Scene monument(uint64_t seed);
Scene trees(uint64_t seed);

// Shared between files: a person of exactly `primitives` (7..16) primitives, feet at the
// origin, facing +z, about 1.75 tall (organic.cpp; crowd, train-station, car-chase).
Shape person(SceneBuilder& b, Rng& rng, uint32_t primitives);
// A car of exactly kCarPrimitives primitives, wheels on y = 0, length along x, front at +x
// (vehicles.cpp). `police` adds a light bar in place of the roof spoiler and antenna.
inline constexpr uint32_t kCarPrimitives = 59;
Shape car_shape(SceneBuilder& b, Rng& rng, vec3 paint, bool police);

}  // namespace sdfprune::gen
