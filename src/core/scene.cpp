// scene.cpp — flattening a described CSG tree into the immutable post-order Scene: composed and
// baked transforms, Lipschitz bounds, difference signs, per-primitive pruning bounds. Iterative
// throughout (explicit stacks), so depth is limited by memory only.
#include <algorithm>
#include <cmath>
#include <string>

#include "sdfprune/primitives.hpp"
#include "sdfprune/scene.hpp"

namespace sdfprune {
namespace {

bool finite(float x) {
    return std::isfinite(x);
}
bool finite(vec3 v) {
    return finite(v.x) && finite(v.y) && finite(v.z);
}

std::string non_negative_error(const char* field, float v) {
    if (!finite(v)) return std::string(field) + " must be finite";
    if (!(v >= 0)) return std::string(field) + " must be >= 0 (got " + std::to_string(v) + ")";
    return {};
}

math::PrimitiveParams bake_params(uint32_t kind, const PrimitiveShape& s, const Affine& world) {
    math::PrimitiveParams p;
    p.row0 = vec4(world.m[0], world.m[1], world.m[2], world.m[3]);
    p.row1 = vec4(world.m[4], world.m[5], world.m[6], world.m[7]);
    p.row2 = vec4(world.m[8], world.m[9], world.m[10], world.m[11]);
    primitive_slots(kind, s, p.a, p.b, p.c);
    return p;
}

PrimitiveBound primitive_bound(uint32_t kind, const PrimitiveShape& shape,
                               const math::PrimitiveParams& params, const Affine& world) {
    PrimitiveBound b;
    // Similarity test: the columns of the linear part are orthogonal with equal lengths.
    double c[3][3];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) c[j][i] = world.m[4 * i + j];
    auto dotc = [&](int i, int j) {
        return c[i][0] * c[j][0] + c[i][1] * c[j][1] + c[i][2] * c[j][2];
    };
    const double s2 = (dotc(0, 0) + dotc(1, 1) + dotc(2, 2)) / 3;
    const double tol = 1e-5 * s2;
    const bool similarity = s2 > 0 && std::fabs(dotc(0, 0) - s2) < tol &&
                            std::fabs(dotc(1, 1) - s2) < tol && std::fabs(dotc(2, 2) - s2) < tol &&
                            std::fabs(dotc(0, 1)) < tol && std::fabs(dotc(0, 2)) < tol &&
                            std::fabs(dotc(1, 2)) < tol;
    // An unbounded primitive (a half-space) has no ball holding it: Lipschitz range only.
    if (!similarity || !primitive_info(kind).bounded) return b;
    b.centre = world.inverse().apply(vec3(0.0f));
    b.f0 = math::eval_primitive_local(kind, params, vec3(0.0f));
    b.rho = primitive_bounding_radius(kind, shape);
    // Rounding of the centre and the scale is absorbed into a slightly looser scale/rho.
    b.scale = float(std::sqrt(s2) * (1 - 2e-6));
    b.rho *= 1 + 1e-6f;
    return b;
}

}  // namespace

std::string validate_node(const SceneNodeDesc& n) {
    for (float v : n.matrix.m)
        if (!finite(v)) return "matrix entries must be finite";
    if (n.kind >= math::kOpUnion) {
        if (n.kind > math::kOpDifference) return "unknown operator";
        return non_negative_error("blendRadius", n.blend);
    }
    if (std::string e = validate_primitive(n.kind, n.shape); !e.empty()) return e;
    if (!finite(n.color) || n.color.x < 0 || n.color.y < 0 || n.color.z < 0 || n.color.x > 1 ||
        n.color.y > 1 || n.color.z > 1)
        return "color components must be in [0, 1]";
    return {};
}

Scene build_scene(std::span<const SceneNodeDesc> nodes, uint32_t root, const Aabb& aabb) {
    if (root >= nodes.size()) throw SceneError("scene has no root node");
    for (int i = 0; i < 3; ++i) {
        if (!finite(aabb.min[i]) || !finite(aabb.max[i])) throw SceneError("aabb must be finite");
        if (!(aabb.max[i] > aabb.min[i]))
            throw SceneError("aabb_max must be greater than aabb_min on every axis");
    }

    Scene sc;
    sc.aabb = aabb;
    struct Visit {
        uint32_t desc;
        bool expanded;
        bool negated;
        Affine world;  // composed world->local map down to and including this node
    };
    std::vector<Visit> stack;
    std::vector<uint32_t> emitted;  // output indices of finished subtrees awaiting their parent
    stack.push_back({root, false, false, nodes[root].matrix});
    while (!stack.empty()) {
        Visit v = stack.back();
        stack.pop_back();
        const SceneNodeDesc& d = nodes[v.desc];
        const bool op = d.kind >= math::kOpUnion;
        if (op && !v.expanded) {
            if (d.left >= nodes.size() || d.right >= nodes.size())
                throw SceneNodeError(v.desc, "operator needs two children");
            stack.push_back({v.desc, true, v.negated, v.world});
            const bool sub = d.kind == math::kOpDifference;
            stack.push_back({d.right, false, sub, v.world.compose(nodes[d.right].matrix)});
            stack.push_back({d.left, false, false, v.world.compose(nodes[d.left].matrix)});
            continue;
        }
        if (std::string e = validate_node(d); !e.empty()) throw SceneNodeError(v.desc, e);
        if (sc.kind.size() >= kMaxNodes) throw SceneError("scene has too many nodes");
        const uint32_t out = uint32_t(sc.kind.size());
        sc.kind.push_back(d.kind);
        sc.negated.push_back(v.negated ? 1 : 0);
        sc.blend.push_back(op ? d.blend : 0.0f);
        sc.local.push_back(d.matrix);
        sc.parent.push_back(kNone);
        if (op) {
            const uint32_t r = emitted.back();
            emitted.pop_back();
            const uint32_t l = emitted.back();
            emitted.pop_back();
            sc.left.push_back(l);
            sc.right.push_back(r);
            sc.parent[l] = sc.parent[r] = out;
            sc.lipschitz.push_back(std::max(sc.lipschitz[l], sc.lipschitz[r]));
            sc.primitive.push_back(kNone);
        } else {
            sc.left.push_back(kNone);
            sc.right.push_back(kNone);
            const float lip = spectral_norm(v.world);
            if (!(lip > 0) || !std::isfinite(lip))
                throw SceneNodeError(v.desc, "degenerate transform");
            try {
                (void)v.world.inverse();
            } catch (const SceneError&) {
                throw SceneNodeError(v.desc, "transform is singular");
            }
            sc.lipschitz.push_back(lip);
            sc.primitive.push_back(uint32_t(sc.primitive_node.size()));
            sc.primitive_node.push_back(out);
            sc.params.push_back(bake_params(d.kind, d.shape, v.world));
            sc.shape.push_back(d.shape);
            sc.color.push_back(d.color);
            sc.bound.push_back(primitive_bound(d.kind, d.shape, sc.params.back(), v.world));
        }
        emitted.push_back(out);
    }
    sc.full_tape.resize(sc.size());
    uint32_t depth = 0;
    for (uint32_t i = 0; i < sc.size(); ++i) {
        sc.full_tape[i] = math::tape_word(i, sc.negated[i]);
        depth = sc.is_primitive(i) ? depth + 1 : depth - 1;
        sc.max_stack = std::max(sc.max_stack, depth);
    }
    return sc;
}

bool shape_is_bounded(const Scene& sc) {
    // Post-order: children before parents. A difference's right operand (negated) never makes
    // the result bounded or unbounded: the result lies in its left operand.
    std::vector<uint8_t> bounded(sc.size());
    for (uint32_t i = 0; i < sc.size(); ++i) {
        const uint32_t k = sc.kind[i];
        if (sc.is_primitive(i))
            bounded[i] = primitive_info(k).bounded;
        else if (k == math::kOpUnion)
            bounded[i] = bounded[sc.left[i]] && bounded[sc.right[i]];
        else if (k == math::kOpIntersection)
            bounded[i] = bounded[sc.left[i]] || bounded[sc.right[i]];
        else
            bounded[i] = bounded[sc.left[i]];
    }
    return sc.size() == 0 || bounded[sc.root()];
}

Aabb bounding_box(const Scene& scene, float pad) {
    if (!shape_is_bounded(scene))
        throw SceneError(
            "the scene's shape is unbounded (a plane not cut off by bounded shapes): give it an "
            "explicit aabb");
    vec3 lo(INFINITY), hi(-INFINITY);
    for (uint32_t p = 0; p < scene.primitive_count(); ++p) {
        if (!primitive_info(scene.kind[scene.primitive_node[p]]).bounded) continue;
        const math::PrimitiveParams& prm = scene.params[p];
        Affine world;
        const vec4 rows[3] = {prm.row0, prm.row1, prm.row2};
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 4; ++j) world.m[4 * i + j] = rows[i][j];
        const Affine inv = world.inverse();
        const vec3 h = primitive_half_extents(scene.kind[scene.primitive_node[p]], scene.shape[p]);
        const vec3 c = inv.apply(vec3(0.0f));
        for (int i = 0; i < 3; ++i) {
            const float e = std::fabs(inv.m[4 * i]) * h.x + std::fabs(inv.m[4 * i + 1]) * h.y +
                            std::fabs(inv.m[4 * i + 2]) * h.z;
            lo[i] = std::min(lo[i], c[i] - e);
            hi[i] = std::max(hi[i], c[i] + e);
        }
    }
    if (scene.primitive_count() == 0) return {vec3(-1.0f), vec3(1.0f)};
    const vec3 size = hi - lo;
    const float m = std::max({size.x, size.y, size.z}) * pad;
    return {lo - m, hi + m};
}

SceneInfo scene_info(const Scene& sc) {
    SceneInfo info;
    info.nodes = sc.size();
    std::vector<uint32_t> depth(sc.size(), 0);
    // Parents come after their children: a reverse sweep sees every parent first.
    for (uint32_t i = sc.size(); i-- > 0;) {
        if (sc.parent[i] != kNone) depth[i] = depth[sc.parent[i]] + 1;
        info.depth = std::max(info.depth, depth[i]);
        info.max_lipschitz = std::max(info.max_lipschitz, sc.lipschitz[i]);
        const uint32_t k = sc.kind[i];
        if (k < math::kPrimitiveKindCount) {
            ++info.primitives;
            ++info.per_primitive_kind[k];
            continue;
        }
        ++info.operators;
        if (sc.blend[i] > 0) ++info.smooth_operators;
        if (k == math::kOpUnion) ++info.unions;
        if (k == math::kOpIntersection) ++info.intersections;
        if (k == math::kOpDifference) ++info.differences;
    }
    return info;
}

namespace {
constexpr const char* kOperatorNames[3] = {"union", "inter", "sub"};
}  // namespace

const char* primitive_kind_name(uint32_t kind) {
    return kind < math::kPrimitiveKindCount ? kPrimitiveTable[kind].name : "?";
}

const char* operator_kind_name(uint32_t kind) {
    return kind >= math::kOpUnion && kind <= math::kOpDifference
               ? kOperatorNames[kind - math::kOpUnion]
               : "?";
}

uint32_t primitive_kind_from_name(std::string_view name) {
    for (uint32_t k = 0; k < math::kPrimitiveKindCount; ++k)
        if (name == kPrimitiveTable[k].name) return k;
    return kNone;
}

uint32_t operator_kind_from_name(std::string_view name) {
    for (uint32_t k = 0; k < 3; ++k)
        if (name == kOperatorNames[k]) return math::kOpUnion + k;
    return kNone;
}

}  // namespace sdfprune
