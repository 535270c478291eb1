// prune_check.hpp — helpers of the pruning tests: random CSG scenes (every primitive, operator,
// tree shape and placement kind) and the checks that a PrunedGrid agrees with the full tree
// (near-field tapes exact, far-field constants conservative; DESIGN.md §3–5).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "sdfprune/builder.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/primitives.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune::test {

// ---- random scenes ------------------------------------------------------------------------------

enum class TreeShape { kBalanced, kLeftDeep, kRightDeep, kMixed };
enum class Placement { kRigid, kUniform, kNonUniform, kSheared, kMixed };

inline const char* tree_shape_name(TreeShape t) {
    switch (t) {
        case TreeShape::kBalanced:
            return "balanced";
        case TreeShape::kLeftDeep:
            return "left-deep";
        case TreeShape::kRightDeep:
            return "right-deep";
        default:
            return "mixed";
    }
}

inline const char* placement_name(Placement p) {
    switch (p) {
        case Placement::kRigid:
            return "rigid";
        case Placement::kUniform:
            return "uniform-scale";
        case Placement::kNonUniform:
            return "non-uniform-scale";
        case Placement::kSheared:
            return "sheared";
        default:
            return "mixed";
    }
}

struct RandomSceneSpec {
    uint32_t primitives = 8;
    TreeShape tree = TreeShape::kMixed;
    Placement placement = Placement::kRigid;
    float smooth_prob = 0.5f;    // chance that an operator gets a blend radius k > 0
    float union_share = 0.5f;    // share of unions; the rest: 45 % intersections, 55 % differences
    float subtree_place = 0.0f;  // chance that an operator's result gets its own placement
    bool clip_aabb = false;      // an AABB that cuts through the content instead of holding it
    bool plane_cut = false;      // the tree intersected with, or minus, a random half-space
};

// The i-th of a series of specs that cycles through every tree shape, placement, smoothness
// and plane cut, with `primitives` primitives.
inline RandomSceneSpec varied_spec(uint32_t i, uint32_t primitives) {
    RandomSceneSpec spec;
    spec.primitives = primitives;
    spec.tree = TreeShape(i % 4);
    spec.placement = Placement(i % 5);
    spec.smooth_prob = float(i % 3) * 0.5f;
    spec.plane_cut = i % 5 == 3;
    return spec;
}

inline vec3 random_in_box(Rng& r, vec3 lo, vec3 hi) {
    return {r.uniform(lo.x, hi.x), r.uniform(lo.y, hi.y), r.uniform(lo.z, hi.z)};
}

inline vec3 random_direction(Rng& r) {
    for (;;) {
        const vec3 v = random_in_box(r, vec3(-1.0f), vec3(1.0f));
        const float l = math::length(v);
        if (l > 0.1f && l <= 1.0f) return v / l;
    }
}

// A primitive of `kind` with random parameters, kept inside each primitive's valid domain
// (bevel and rounding radii no larger than the half sides they round).
inline Shape random_primitive(SceneBuilder& b, Rng& r, uint32_t kind) {
    switch (kind) {
        case math::kPrimSphere:
            return b.sphere(r.uniform(0.12f, 0.6f));
        case math::kPrimBox: {
            const vec3 sides = random_in_box(r, vec3(0.2f), vec3(1.1f));
            const float hxz = std::min(sides.x, sides.z) * 0.5f;
            vec4 bevel;
            if (r.uniform() < 0.6f)
                bevel = vec4(r.uniform(0, 0.95f) * hxz, r.uniform(0, 0.95f) * hxz,
                             r.uniform(0, 0.95f) * hxz, r.uniform(0, 0.95f) * hxz);
            const float hmin = std::min(hxz, sides.y * 0.5f);
            const float top = r.uniform() < 0.5f ? r.uniform(0, 0.95f) * hmin : 0.0f;
            const float bottom = r.uniform() < 0.5f ? r.uniform(0, 0.95f) * hmin : 0.0f;
            return b.box(sides, bevel, top, bottom);
        }
        case math::kPrimCylinder:
            return b.cylinder(r.uniform(0.08f, 0.5f), r.uniform(0.15f, 1.2f));
        case math::kPrimCone:
            return b.cone(r.uniform(0.1f, 0.55f), r.uniform(0.15f, 1.2f));
        case math::kPrimCapsule:
            return b.capsule(r.uniform(0.06f, 0.4f),
                             r.uniform() < 0.15f ? 0.0f : r.uniform(0.05f, 1.0f));
        case math::kPrimTorus: {
            const float major = r.uniform(0.15f, 0.6f);
            // Mostly ring tori; sometimes a spindle torus (minor > major).
            const float minor =
                r.uniform() < 0.15f ? major * r.uniform(1.0f, 1.5f) : major * r.uniform(0.1f, 0.8f);
            return b.torus(major, minor);
        }
        case math::kPrimRoundedCylinder: {
            const float radius = r.uniform(0.08f, 0.5f), height = r.uniform(0.15f, 1.2f);
            const float lim = std::min(radius, height / 2);
            const float u = r.uniform();
            return b.rounded_cylinder(radius, height,
                                      u < 0.15f   ? lim
                                      : u < 0.25f ? 0.0f
                                                  : r.uniform(0, lim));
        }
        case math::kPrimCappedCone: {
            const float u = r.uniform();
            const float r1 = u < 0.15f ? 0.0f : r.uniform(0.05f, 0.55f);
            const float r2 = u > 0.85f ? 0.0f : r.uniform(0.05f, 0.55f);
            return b.capped_cone(r1, r2, r.uniform(0.15f, 1.2f));
        }
        case math::kPrimHexPrism:
            return b.hex_prism(r.uniform(0.1f, 0.55f), r.uniform(0.1f, 1.2f));
        case math::kPrimOctahedron:
            return b.octahedron(r.uniform(0.15f, 0.7f));
        case math::kPrimPlane:
            return b.plane(random_direction(r) * r.uniform(0.5f, 2.0f), r.uniform(-0.3f, 0.3f));
        default:
            throw std::logic_error("random_primitive: no generator for kind " +
                                   std::to_string(kind));
    }
}

// A random invertible linear map with bounded distortion, as an Affine (no translation).
inline Affine random_shear(Rng& r) {
    for (;;) {
        Affine a;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                a.m[4 * i + j] = (i == j ? 1.0f : 0.0f) + r.uniform(-0.6f, 0.6f);
        const float* m = a.m;
        const double det = double(m[0]) * (double(m[5]) * m[10] - double(m[6]) * m[9]) -
                           double(m[1]) * (double(m[4]) * m[10] - double(m[6]) * m[8]) +
                           double(m[2]) * (double(m[4]) * m[9] - double(m[5]) * m[8]);
        if (std::fabs(det) > 0.35) return a;
    }
}

// Moves `s` by a random placement of the given kind (scale/shear first, then rotation, then a
// translation in [-t, t]³).
inline Shape place(Shape s, Rng& r, Placement kind, float t = 0.8f) {
    if (kind == Placement::kMixed) kind = Placement(uint32_t(r.uniform() * 3.999f));
    Shape out = s;
    switch (kind) {
        case Placement::kUniform:
            out = out.scaled(r.uniform(0.45f, 1.8f));
            break;
        case Placement::kNonUniform:
            out = out.scaled(random_in_box(r, vec3(0.4f), vec3(1.8f)));
            break;
        case Placement::kSheared:
            out = out.transformed(random_shear(r));
            break;
        default:
            break;
    }
    out = out.rotated(random_direction(r), r.uniform(0.0f, 6.2831853f));
    return out.translated(random_in_box(r, vec3(-t), vec3(t)));
}

inline uint32_t random_operator(Rng& r, float union_share) {
    const float u = r.uniform();
    if (u < union_share) return math::kOpUnion;
    return u < union_share + (1 - union_share) * 0.45f ? math::kOpIntersection
                                                       : math::kOpDifference;
}

inline Shape random_combine(SceneBuilder& b, Rng& r, const RandomSceneSpec& spec, Shape x,
                            Shape y) {
    const float k = r.uniform() < spec.smooth_prob ? r.uniform(0.02f, 0.35f) : 0.0f;
    Shape s = b.combine(random_operator(r, spec.union_share), x, y, k);
    if (spec.subtree_place > 0 && r.uniform() < spec.subtree_place)
        s = place(s, r, spec.placement == Placement::kRigid ? Placement::kRigid : Placement::kMixed,
                  0.25f);
    return s;
}

// Leaves [lo, hi) combined into a tree of the given shape (recursion depth <= leaf count).
inline Shape random_tree(SceneBuilder& b, Rng& r, const RandomSceneSpec& spec,
                         const std::vector<Shape>& leaves, size_t lo, size_t hi) {
    if (hi - lo == 1) return leaves[lo];
    switch (spec.tree) {
        case TreeShape::kLeftDeep: {
            Shape acc = leaves[lo];
            for (size_t i = lo + 1; i < hi; ++i) acc = random_combine(b, r, spec, acc, leaves[i]);
            return acc;
        }
        case TreeShape::kRightDeep: {
            Shape acc = leaves[hi - 1];
            for (size_t i = hi - 1; i-- > lo;) acc = random_combine(b, r, spec, leaves[i], acc);
            return acc;
        }
        case TreeShape::kBalanced: {
            const size_t mid = lo + (hi - lo) / 2;
            const Shape a = random_tree(b, r, spec, leaves, lo, mid);
            const Shape c = random_tree(b, r, spec, leaves, mid, hi);
            return random_combine(b, r, spec, a, c);
        }
        default: {
            const size_t mid = lo + 1 + size_t(r.uniform() * float(hi - lo - 1));
            const Shape a = random_tree(b, r, spec, leaves, lo, std::min(mid, hi - 1));
            const Shape c = random_tree(b, r, spec, leaves, std::min(mid, hi - 1), hi);
            return random_combine(b, r, spec, a, c);
        }
    }
}

// A random scene over an AABB around its content (padded by 5–35 % on each side, so cells are
// generally not cubes), or cutting through it with spec.clip_aabb.
inline Scene random_scene(uint64_t seed, const RandomSceneSpec& spec) {
    Rng r(seed);
    SceneBuilder b;
    std::vector<Shape> leaves;
    // Leaves of every bounded kind; half-spaces only through spec.plane_cut.
    std::vector<uint32_t> kinds;
    for (uint32_t k = 0; k < math::kPrimitiveKindCount; ++k)
        if (primitive_info(k).bounded) kinds.push_back(k);
    const uint32_t n_kinds = uint32_t(kinds.size());
    for (uint32_t i = 0; i < spec.primitives; ++i) {
        const uint32_t kind = kinds[uint32_t(r.uniform() * float(n_kinds)) % n_kinds];
        leaves.push_back(place(random_primitive(b, r, kind), r, spec.placement));
    }
    Shape root = random_tree(b, r, spec, leaves, 0, leaves.size());
    if (spec.plane_cut) {
        const Shape plane = place(
            random_primitive(b, r, math::kPrimPlane), r,
            spec.placement == Placement::kRigid ? Placement::kRigid : Placement::kMixed, 0.2f);
        const float k = r.uniform() < spec.smooth_prob ? r.uniform(0.02f, 0.35f) : 0.0f;
        root = b.combine(r.uniform() < 0.5f ? math::kOpIntersection : math::kOpDifference, root,
                         plane, k);
    }
    const Aabb content = b.build(root).aabb;  // bounding_box() of the built scene
    const vec3 size = content.max - content.min;
    Aabb box;
    for (int a = 0; a < 3; ++a) {
        if (spec.clip_aabb) {
            box.min[a] = content.min[a] + size[a] * r.uniform(0.1f, 0.3f);
            box.max[a] = content.max[a] - size[a] * r.uniform(0.1f, 0.3f);
        } else {
            box.min[a] = content.min[a] - size[a] * r.uniform(0.05f, 0.35f);
            box.max[a] = content.max[a] + size[a] * r.uniform(0.05f, 0.35f);
        }
    }
    return b.build(root, box);
}

// The smallest Lipschitz bound of any primitive: every pruned tape's root bound is at least this.
inline float min_primitive_lipschitz(const Scene& sc) {
    float l = INFINITY;
    for (uint32_t p = 0; p < sc.primitive_count(); ++p)
        l = std::min(l, sc.lipschitz[sc.primitive_node[p]]);
    return l;
}

// ---- checks -------------------------------------------------------------------------------------

// Reports the first few failures in full and counts the rest.
class Failures {
  public:
    explicit Failures(std::string context, int shown = 6)
        : context_(std::move(context)), shown_(shown) {}
    template <typename F>
    void add(F&& describe) {
        if (count_++ < uint64_t(shown_)) {
            std::ostringstream os;
            os.precision(9);
            describe(os);
            ADD_FAILURE() << context_ << ": " << os.str();
        }
    }
    uint64_t count() const { return count_; }
    const std::string& context() const { return context_; }

  private:
    std::string context_;
    int shown_;
    uint64_t count_ = 0;
};

inline std::string str(vec3 p) {
    std::ostringstream os;
    os.precision(9);
    os << "(" << p.x << ", " << p.y << ", " << p.z << ")";
    return os.str();
}

// Two prunings of one scene and grid found the same cells and tapes: equal Table 2 and tape
// statistics (callers add what else must agree, or must differ, between their two).
inline void expect_same_prune_stats(const PruneStats& a, const PruneStats& b,
                                    const std::string& what) {
    SCOPED_TRACE(what);
    EXPECT_EQ(a.cells, b.cells);
    EXPECT_EQ(a.near_field_cells, b.near_field_cells);
    EXPECT_EQ(a.active_avg, b.active_avg);
    EXPECT_EQ(a.active_std, b.active_std);
    EXPECT_EQ(a.active_max, b.active_max);
    EXPECT_EQ(a.tape_avg, b.tape_avg);
    EXPECT_EQ(a.tape_max, b.tape_max);
}

// Whether a tape is well formed for the evaluator: valid nodes, never pops an empty stack, ends
// with one value, needs at most scene.max_stack entries, and holds `primitives` primitives.
inline bool tape_well_formed(const Scene& sc, std::span<const uint32_t> tape, uint32_t primitives,
                             std::string& why) {
    uint32_t depth = 0, prims = 0;
    for (const uint32_t w : tape) {
        const uint32_t n = math::tape_node(w);
        if (n >= sc.size()) {
            why = "node index out of range";
            return false;
        }
        if (sc.is_primitive(n)) {
            ++prims;
            if (++depth > sc.max_stack) {
                why = "needs more than scene.max_stack";
                return false;
            }
        } else {
            if (depth < 2) {
                why = "operator with fewer than two operands";
                return false;
            }
            --depth;
        }
    }
    if (depth != 1) {
        why = "does not end with exactly one value";
        return false;
    }
    if (prims != primitives) {
        why = "primitive count " + std::to_string(primitives) + " but the tape holds " +
              std::to_string(prims);
        return false;
    }
    return true;
}

struct PointStats {
    uint64_t near = 0, far = 0, bitwise = 0;
};

inline bool within_rel(float a, float b, double rel = 1e-6) {
    return std::fabs(double(a) - double(b)) <= rel * (1.0 + std::fabs(double(b)));
}

// Checks the pruned field at p against the full tree: the cell holding p contains it; a
// near-field cell's tape is well formed and gives f within 1e-6·(1+|f|); a far-field constant
// has the sign of f and |c| <= |f|; PrunedGrid::eval returns that tape value / constant.
inline void check_point(const PrunedGrid& g, vec3 p, std::vector<float>& stack, PointStats& st,
                        Failures& fail) {
    const Scene& sc = g.scene();
    uint32_t ix, iy, iz;
    if (!g.cell_index(p, ix, iy, iz)) {
        fail.add([&](std::ostream& os) {
            os << "cell_index false for p = " << str(p) << " in the AABB";
        });
        return;
    }
    const vec3 c = g.cell_center(ix, iy, iz), cs = g.cell_size();
    for (int a = 0; a < 3; ++a) {
        if (std::fabs(p[a] - c[a]) > cs[a] * 0.5f * (1 + 1e-4f) + 1e-6f) {
            fail.add([&](std::ostream& os) {
                os << "p = " << str(p) << " mapped to cell (" << ix << "," << iy << "," << iz
                   << ") centred at " << str(c) << " that does not hold it";
            });
            return;
        }
    }
    const float f = eval_tape(sc, sc.full_tape, p, stack.data());
    const CellView cv = g.cell(ix, iy, iz);
    const float ge = g.eval(p, stack.data());
    const auto where = [&](std::ostream& os) {
        os << " at p = " << str(p) << ", cell (" << ix << "," << iy << "," << iz << ")";
    };
    if (!cv.far_field) {
        ++st.near;
        std::string why;
        if (!tape_well_formed(sc, cv.tape, cv.primitives, why)) {
            fail.add([&](std::ostream& os) {
                os << "malformed tape: " << why;
                where(os);
            });
            return;
        }
        const float v = eval_tape(sc, cv.tape, p, stack.data());
        if (v == f) ++st.bitwise;
        if (!within_rel(v, f))
            fail.add([&](std::ostream& os) {
                os << "near-field tape gives " << v << ", full tree " << f << " (tape of "
                   << cv.tape.size() << " words)";
                where(os);
            });
        if (!(ge == v))
            fail.add([&](std::ostream& os) {
                os << "PrunedGrid::eval " << ge << " != tape value " << v;
                where(os);
            });
    } else {
        ++st.far;
        const float k = cv.constant;
        const bool ok = (f > 0 && k > 0 && k <= f) || (f < 0 && k < 0 && k >= f);
        if (!ok)
            fail.add([&](std::ostream& os) {
                os << "far-field constant " << k << " not conservative for f = " << f
                   << " (value at centre " << eval_point(sc, c) << ")";
                where(os);
            });
        if (!(ge == k))
            fail.add([&](std::ostream& os) {
                os << "PrunedGrid::eval " << ge << " != far-field constant " << k;
                where(os);
            });
    }
}

// Random points: `uniform` anywhere in the AABB, `in_near` inside random near-field cells (found
// by rejection), `on_faces` on cell faces, edges and corners of the finest grid.
inline std::vector<vec3> sample_points(const PrunedGrid& g, Rng& r, size_t uniform, size_t in_near,
                                       size_t on_faces) {
    const Aabb& box = g.aabb();
    const uint32_t N = g.resolution();
    const vec3 cs = g.cell_size();
    std::vector<vec3> pts;
    pts.reserve(uniform + in_near + on_faces);
    for (size_t i = 0; i < uniform; ++i) pts.push_back(random_in_box(r, box.min, box.max));
    const auto rand_index = [&](uint32_t n) {
        return std::min(uint32_t(r.uniform() * float(n)), n - 1);
    };
    size_t found = 0;
    for (size_t tries = 0; found < in_near && tries < in_near * 400; ++tries) {
        const uint32_t ix = rand_index(N), iy = rand_index(N), iz = rand_index(N);
        if (g.cell(ix, iy, iz).far_field) continue;
        const vec3 c = g.cell_center(ix, iy, iz);
        pts.push_back(random_in_box(r, c - cs * 0.5f, c + cs * 0.5f));
        ++found;
    }
    for (size_t i = 0; i < on_faces; ++i) {
        vec3 p = random_in_box(r, box.min, box.max);
        // Snap 1–3 coordinates onto grid planes strictly inside the AABB.
        const int snapped = 1 + int(r.uniform() * 2.999f);
        for (int a = 0; a < snapped && N > 1; ++a) {
            const int axis = (a + int(i)) % 3;
            p[axis] = box.min[axis] + float(1 + rand_index(N - 1)) * cs[axis];
        }
        pts.push_back(p);
    }
    return pts;
}

// check_point over many points, then PrunedGrid::eval_points against PrunedGrid::eval.
inline PointStats check_points(const PrunedGrid& g, std::span<const vec3> pts, Failures& fail) {
    PointStats st;
    std::vector<float> stack(g.scene().max_stack + 1);
    for (const vec3& p : pts) check_point(g, p, stack, st, fail);
    std::vector<float> batch(pts.size());
    g.eval_points(pts, batch);
    for (size_t i = 0; i < pts.size(); ++i) {
        const float e = g.eval(pts[i], stack.data());
        if (!(batch[i] == e)) {
            fail.add([&](std::ostream& os) {
                os << "eval_points " << batch[i] << " != eval " << e << " at " << str(pts[i]);
            });
        }
    }
    return st;
}

}  // namespace sdfprune::test
