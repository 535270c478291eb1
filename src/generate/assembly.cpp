// assembly.cpp — the generators' shared machinery: balanced and chained trees, exact primitive
// budgets, Morton ordering, placement helpers, and the Assembly that writes node descriptions
// directly so that scenes of millions of primitives build fast and lean.
#include <algorithm>
#include <cmath>

#include "generate_internal.hpp"
#include "sdfprune/primitives.hpp"

namespace sdfprune::gen {

vec3 vary(vec3 c, float amount, Rng& rng) {
    vec3 out;
    for (int i = 0; i < 3; ++i)
        out[i] = std::clamp(c[i] + rng.uniform(-amount, amount), 0.0f, 1.0f);
    return out;
}

vec3 pick(std::span<const vec3> palette, Rng& rng) {
    return palette[size_t(rng.next_u64() % palette.size())];
}

Shape union_all(std::span<const Shape> shapes, float k) {
    if (shapes.empty()) throw SceneError("union of no shapes");
    std::vector<Shape> level(shapes.begin(), shapes.end());
    while (level.size() > 1) {
        size_t w = 0;
        for (size_t i = 0; i + 1 < level.size(); i += 2)
            level[w++] = smooth_union(level[i], level[i + 1], k);
        if (level.size() % 2) level[w++] = level.back();
        level.resize(w);
    }
    return level[0];
}

Shape chain(std::span<const Shape> shapes, float k) {
    if (shapes.empty()) throw SceneError("chain of no shapes");
    Shape s = shapes[0];
    for (size_t i = 1; i < shapes.size(); ++i) s = smooth_union(s, shapes[i], k);
    return s;
}

Affine rotation_from_y(vec3 dir) {
    const vec3 d = normalized(dir);
    const vec3 axis = cross(vec3(0, 1, 0), d);
    const float s = math::length(axis);
    if (s < 1e-6f) return d.y > 0 ? Affine() : Affine::rotation({1, 0, 0}, kPi);
    return Affine::rotation(axis, std::atan2(s, d.y));
}

Shape capsule_between(SceneBuilder& b, vec3 from, vec3 to, float radius) {
    const float len = math::length(to - from);
    return b.capsule(radius, len)
        .transformed(rotation_from_y(to - from))
        .translated((from + to) * 0.5f);
}

Shape cylinder_between(SceneBuilder& b, vec3 from, vec3 to, float radius) {
    const float len = math::length(to - from);
    return b.cylinder(radius, len)
        .transformed(rotation_from_y(to - from))
        .translated((from + to) * 0.5f);
}

Shape half_space(SceneBuilder& b, vec3 point, vec3 normal, float size) {
    const vec3 n = normalized(normal);
    return b.box(vec3(size)).transformed(rotation_from_y(n)).translated(point - n * (size / 2));
}

Aabb surface_bounds(const Scene& sc, float pad) {
    std::vector<Aabb> box(sc.size());
    std::vector<float> deficit(sc.size(), 0.0f);
    for (uint32_t i = 0; i < sc.size(); ++i) {
        if (sc.is_primitive(i)) {
            const uint32_t p = sc.primitive[i];
            const PrimitiveShape& s = sc.shape[p];
            const vec3 h = primitive_half_extents(sc.kind[i], s);
            const math::PrimitiveParams& prm = sc.params[p];
            Affine world;
            const vec4 rows[3] = {prm.row0, prm.row1, prm.row2};
            for (int r = 0; r < 3; ++r)
                for (int c = 0; c < 4; ++c) world.m[4 * r + c] = rows[r][c];
            const Affine inv = world.inverse();
            const vec3 c = inv.apply(vec3(0.0f));
            vec3 e;
            for (int r = 0; r < 3; ++r)
                e[r] = std::fabs(inv.m[4 * r]) * h.x + std::fabs(inv.m[4 * r + 1]) * h.y +
                       std::fabs(inv.m[4 * r + 2]) * h.z;
            box[i] = {c - e, c + e};
            continue;
        }
        // A union's value is at least the smooth min of its children's lower bounds, so the
        // surface lies within `deficit` of the hull: max of the children's deficits plus the
        // kernel at their difference (k/4 when equal: balanced smooth trees add up).
        const uint32_t l = sc.left[i], r = sc.right[i];
        if (sc.kind[i] == math::kOpUnion) {
            box[i] = {math::min(box[l].min, box[r].min), math::max(box[l].max, box[r].max)};
            deficit[i] = std::max(deficit[l], deficit[r]) +
                         math::blend_kernel(std::fabs(deficit[l] - deficit[r]), sc.blend[i]);
        } else if (sc.kind[i] == math::kOpIntersection) {
            box[i] = {math::max(box[l].min - deficit[l], box[r].min - deficit[r]),
                      math::min(box[l].max + deficit[l], box[r].max + deficit[r])};
        } else {
            box[i] = {box[l].min - deficit[l], box[l].max + deficit[l]};
        }
    }
    const Aabb b{box[sc.root()].min - deficit[sc.root()], box[sc.root()].max + deficit[sc.root()]};
    const vec3 size = b.max - b.min;
    if (!(size.x > 0 && size.y > 0 && size.z > 0)) return bounding_box(sc);
    const float m = std::max({size.x, size.y, size.z}) * pad;
    return {b.min - m, b.max + m};
}

void positive_zeros(Scene& s) {
    // The scene format reads "-0" back as 0: write +0 so that files round-trip byte for byte.
    auto fix = [](float& v) {
        if (v == 0.0f) v = 0.0f;
    };
    for (Affine& a : s.local)
        for (float& v : a.m) fix(v);
    for (math::PrimitiveParams& p : s.params)
        for (vec4* row : {&p.row0, &p.row1, &p.row2})
            for (int i = 0; i < 4; ++i) fix((*row)[i]);
}

Scene build_scene_of(const SceneBuilder& b, Shape root) {
    Scene s = b.build(root, {vec3(-1.0f), vec3(1.0f)});
    positive_zeros(s);
    s.aabb = surface_bounds(s);
    return s;
}

std::vector<uint32_t> split_budget(uint32_t total, uint32_t lo, uint32_t hi, Rng& rng) {
    if (total < lo || hi + 1 < 2 * lo) throw SceneError("budget cannot be split");
    std::vector<uint32_t> parts;
    while (total > hi) {
        // Leave at least `lo` for the rest, so the last part is always in range.
        const uint32_t top = std::min(hi, total - lo);
        const uint32_t part = uint32_t(uniform_int(rng, int(lo), int(top)));
        parts.push_back(part);
        total -= part;
    }
    parts.push_back(total);
    return parts;
}

namespace {
uint64_t spread_bits(uint64_t v) {  // 21 bits -> every third bit of 63
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffull;
    v = (v | v << 16) & 0x1f0000ff0000ffull;
    v = (v | v << 8) & 0x100f00f00f00f00full;
    v = (v | v << 4) & 0x10c30c30c30c30c3ull;
    v = (v | v << 2) & 0x1249249249249249ull;
    return v;
}
}  // namespace

std::vector<uint32_t> morton_order(std::span<const vec3> points) {
    vec3 lo(INFINITY), hi(-INFINITY);
    for (const vec3& p : points) {
        lo = math::min(lo, p);
        hi = math::max(hi, p);
    }
    const vec3 size = hi - lo;
    const float extent = std::max({size.x, size.y, size.z, 1e-30f});
    std::vector<std::pair<uint64_t, uint32_t>> keyed(points.size());
    for (size_t i = 0; i < points.size(); ++i) {
        uint64_t key = 0;
        for (int a = 0; a < 3; ++a) {
            const float t = std::clamp((points[i][a] - lo[a]) / extent, 0.0f, 1.0f);
            key |= spread_bits(uint64_t(t * 2097151.0f)) << a;
        }
        keyed[i] = {key, uint32_t(i)};
    }
    std::sort(keyed.begin(), keyed.end());  // ties broken by index: deterministic
    std::vector<uint32_t> order(points.size());
    for (size_t i = 0; i < keyed.size(); ++i) order[i] = keyed[i].second;
    return order;
}

void grid_shape(uint32_t n, uint32_t& cols, uint32_t& rows) {
    cols = std::max(1u, uint32_t(std::ceil(std::sqrt(double(n)))));
    rows = (n + cols - 1) / cols;
}

// ---- Assembly --------------------------------------------------------------------------------

uint32_t Assembly::add(const SceneBuilder& b, Shape root) {
    std::vector<SceneNodeDesc> d = b.describe(root);
    const uint32_t base = uint32_t(nodes_.size());
    if (size_t(base) + d.size() >= kMaxNodes) throw SceneError("scene has too many nodes");
    for (SceneNodeDesc& n : d) {
        if (n.left != kNone) n.left += base;
        if (n.right != kNone) n.right += base;
        nodes_.push_back(n);
    }
    return uint32_t(nodes_.size() - 1);
}

uint32_t Assembly::add_primitive(uint32_t kind, const PrimitiveShape& shape,
                                 const Affine& world_to_local, vec3 color) {
    if (nodes_.size() >= kMaxNodes) throw SceneError("scene has too many nodes");
    SceneNodeDesc d;
    d.kind = kind;
    d.shape = shape;
    d.matrix = world_to_local;
    d.color = color;
    nodes_.push_back(d);
    return uint32_t(nodes_.size() - 1);
}

uint32_t Assembly::sphere(vec3 centre, float radius, vec3 color) {
    PrimitiveShape s;
    s.radius = radius;
    return add_primitive(math::kPrimSphere, s, Affine::translation(-centre), color);
}

uint32_t Assembly::combine(uint32_t op, uint32_t a, uint32_t b, float k) {
    if (nodes_.size() >= kMaxNodes) throw SceneError("scene has too many nodes");
    SceneNodeDesc d;
    d.kind = op;
    d.left = a;
    d.right = b;
    d.blend = k;
    nodes_.push_back(d);
    return uint32_t(nodes_.size() - 1);
}

uint32_t Assembly::balanced(std::span<const uint32_t> roots, uint32_t op, float k,
                            uint32_t smooth_levels) {
    if (roots.empty()) throw SceneError("union of no shapes");
    std::vector<uint32_t> level(roots.begin(), roots.end());
    for (uint32_t depth = 0; level.size() > 1; ++depth) {
        const float blend = depth < smooth_levels ? k : 0.0f;
        size_t w = 0;
        for (size_t i = 0; i + 1 < level.size(); i += 2)
            level[w++] = combine(op, level[i], level[i + 1], blend);
        if (level.size() % 2) level[w++] = level.back();
        level.resize(w);
    }
    return level[0];
}

uint32_t Assembly::chain(std::span<const uint32_t> roots, uint32_t op, float k) {
    if (roots.empty()) throw SceneError("chain of no shapes");
    uint32_t r = roots[0];
    for (size_t i = 1; i < roots.size(); ++i) r = combine(op, r, roots[i], k);
    return r;
}

Scene Assembly::build(uint32_t root) {
    // build_scene ignores the AABB except to store it: measure the surface afterwards.
    Scene s = build_scene(nodes_, root, {vec3(-1.0f), vec3(1.0f)});
    std::vector<SceneNodeDesc>().swap(nodes_);
    positive_zeros(s);
    s.aabb = surface_bounds(s);
    return s;
}

}  // namespace sdfprune::gen
