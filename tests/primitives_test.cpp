// primitives_test.cpp — primitive SDFs: analytic distances, unit gradients, Lipschitz bounds.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "sdfprune/builder.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/scene.hpp"

namespace sdfprune {
namespace {

const Aabb kBox{vec3(-8.0f), vec3(8.0f)};
const double kSqrt2 = std::sqrt(2.0);
const double kSqrt5 = std::sqrt(5.0);

struct Case {
    vec3 p;
    double expected;
};

// Checks one primitive (identity placement) at hand-computed points, both through the shared math
// of sdf_math.h and through a built scene.
void check_cases(SceneBuilder& b, Shape s, const std::vector<Case>& cases) {
    const Scene sc = b.build(s, kBox);
    ASSERT_EQ(sc.size(), 1u);
    ASSERT_EQ(sc.primitive_count(), 1u);
    for (const Case& c : cases) {
        SCOPED_TRACE("point (" + std::to_string(c.p.x) + ", " + std::to_string(c.p.y) + ", " +
                     std::to_string(c.p.z) + ")");
        EXPECT_NEAR(eval_point(sc, c.p), c.expected, 2e-6);
        EXPECT_NEAR(math::eval_primitive_local(sc.kind[0], sc.params[0], c.p), c.expected, 2e-6);
    }
}

TEST(Primitives, Sphere) {
    EXPECT_FLOAT_EQ(math::sd_sphere(vec3(3, 4, 0), 2.0f), 3.0f);
    SceneBuilder b;
    check_cases(b, b.sphere(1.5f),
                {{{0, 0, 0}, -1.5},
                 {{3, 0, 0}, 1.5},
                 {{0, -2, 0}, 0.5},
                 {{0, 0, 0.5f}, -1.0},
                 {{3, 4, 0}, 3.5},
                 {{1, 2, 2}, 1.5}});
}

TEST(Primitives, PlainBox) {
    SceneBuilder b;
    // Full sides (2, 4, 6): half sides (1, 2, 3).
    check_cases(b, b.box({2, 4, 6}),
                {{{0, 0, 0}, -1.0},
                 {{0, 1.5f, 0}, -0.5},
                 {{0, 0, -2.8f}, -0.2},
                 {{3, 0, 0}, 2.0},
                 {{0, -2.5f, 0}, 0.5},
                 {{0, 0, 4}, 1.0},
                 {{2, 3, 0}, kSqrt2},          // beyond an edge
                 {{2, 3, 4}, std::sqrt(3.0)},  // beyond a corner
                 {{-4, -6, 3}, 5.0}});         // beyond an edge, level with a face
}

TEST(Primitives, BoxBevelPerQuadrant) {
    SceneBuilder b;
    // Corner radii per xz quadrant: (+x+z, +x-z, -x+z, -x-z). Seen from a point on the quadrant's
    // diagonal, the corner is a circle of radius r centred at (1 - r, 1 - r).
    check_cases(b, b.box({2, 2, 2}, {0.1f, 0.2f, 0.3f, 0.4f}),
                {{{2, 0, 2}, 1.1 * kSqrt2 - 0.1},
                 {{2, 0, -2}, 1.2 * kSqrt2 - 0.2},
                 {{-2, 0, 2}, 1.3 * kSqrt2 - 0.3},
                 {{-2, 0, -2}, 1.4 * kSqrt2 - 0.4},
                 {{2, 0, 0.5f}, 1.0},                       // face, away from the corner
                 {{0.95f, 0, 0.95f}, 0.05 * kSqrt2 - 0.1},  // inside, next to the arc
                 {{0, 3, 0}, 2.0},
                 {{0, 0, 0}, -1.0}});
}

TEST(Primitives, BoxRoundTopAndBottom) {
    SceneBuilder b;
    // round_x rounds the top (+y) rim: the rim is a quarter circle of radius 0.25 centred at
    // (x, y) = (0.75, 0.75) in the xy plane; the bottom rim stays sharp.
    check_cases(b, b.box({2, 2, 2}, {}, 0.25f, 0.0f),
                {{{2, 2, 0}, 1.25 * kSqrt2 - 0.25},
                 {{2, -2, 0}, kSqrt2},
                 {{0, 0.9f, 0}, -0.1},
                 {{0, 3, 0}, 2.0},
                 {{0, -3, 0}, 2.0},
                 {{0, 0, 1.5f}, 0.5}});
    // round_y rounds the bottom (-y) rim only.
    check_cases(b, b.box({2, 2, 2}, {}, 0.0f, 0.5f),
                {{{2, -2, 0}, 1.5 * kSqrt2 - 0.5}, {{2, 2, 0}, kSqrt2}, {{0, -0.7f, 0}, -0.3}});
    // Bevel and rim rounding together: from (2, 2, 2), the profile in the plane of the xz diagonal
    // is a circle of radius 0.2 centred 0.1 out from the corner arc's centre (0.7, 0.7), at y =
    // 0.8.
    const double rho = 1.3 * kSqrt2 - 0.1;
    check_cases(b, b.box({2, 2, 2}, {0.3f, 0.3f, 0.3f, 0.3f}, 0.2f, 0.0f),
                {{{2, 2, 2}, std::sqrt(rho * rho + 1.2 * 1.2) - 0.2},
                 {{2, -2, 2}, std::sqrt(std::pow(1.3 * kSqrt2 - 0.3, 2) + 1.0)}});
}

TEST(Primitives, Cylinder) {
    SceneBuilder b;
    // Radius 0.5, full height 2 along y.
    check_cases(b, b.cylinder(0.5f, 2.0f),
                {{{0, 0, 0}, -0.5},
                 {{0, 0.8f, 0}, -0.2},
                 {{0.3f, 0, 0}, -0.2},
                 {{2, 0, 0}, 1.5},
                 {{0, 0, -2}, 1.5},
                 {{0, 3, 0}, 2.0},
                 {{0, -1.5f, 0}, 0.5},
                 {{1.5f, 2, 0}, kSqrt2},    // beyond the rim
                 {{0.36f, 0, 0.48f}, 0.1},  // off-axis, rho = 0.6
                 {{0.6f, 0.8f, 0}, 0.1}});
}

TEST(Primitives, Cone) {
    SceneBuilder b;
    // Base radius 1 at y = -1, apex at y = +1. In the (rho, y) plane the slant is the line
    // 2 rho + y = 1, outward normal (2, 1) / sqrt 5.
    check_cases(b, b.cone(1.0f, 2.0f),
                {{{0, 2, 0}, 1.0},  // above the apex
                 {{0, 3, 0}, 2.0},
                 {{0, -2, 0}, 1.0},                                       // below the base
                 {{2, -2, 0}, kSqrt2},                                    // beyond the base rim
                 {{float(0.5 + 2 / kSqrt5), float(1 / kSqrt5), 0}, 1.0},  // off the slant
                 {{0, 0, 0}, -1 / kSqrt5},                                // slant is nearest
                 {{0, -0.9f, 0}, -0.1},                                   // base is nearest
                 {{0.3f, -0.5f, 0.4f}, -0.5 / kSqrt5}});
}

TEST(Primitives, Capsule) {
    SceneBuilder b;
    // Radius 0.5 around the segment y in [-1, 1].
    check_cases(b, b.capsule(0.5f, 2.0f),
                {{{0, 0, 0}, -0.5},
                 {{2, 0, 0}, 1.5},
                 {{0, 3, 0}, 1.5},
                 {{0, -2, 0}, 0.5},
                 {{3, 5, 0}, 4.5},
                 {{0, 1.2f, 0}, -0.3},
                 {{0.3f, 0.9f, -0.4f}, 0.0}});
}

TEST(Primitives, Torus) {
    SceneBuilder b;
    // Major radius 2 in the xz plane, minor radius 0.5.
    check_cases(b, b.torus(2.0f, 0.5f),
                {{{2, 0, 0}, -0.5},
                 {{0, 0, -2}, -0.5},
                 {{0, 0, 0}, 1.5},
                 {{0, 0, 3}, 0.5},
                 {{2, 1, 0}, 0.5},
                 {{5, 4, 0}, 4.5},
                 {{0, 2, 0}, std::sqrt(8.0) - 0.5},
                 {{1.2f, 0.3f, 1.6f}, -0.2}});
}

// ---- rigid placements --------------------------------------------------------------------------

// Rotation matrix (row-major 3x3) about a unit axis, in double, for an independent inverse map.
void rotation_matrix(vec3 axis, double angle, double r[9]) {
    const double len =
        std::sqrt(double(axis.x) * axis.x + double(axis.y) * axis.y + double(axis.z) * axis.z);
    const double x = axis.x / len, y = axis.y / len, z = axis.z / len;
    const double c = std::cos(angle), s = std::sin(angle), t = 1 - c;
    const double m[9] = {t * x * x + c,     t * x * y - s * z, t * x * z + s * y,
                         t * x * y + s * z, t * y * y + c,     t * y * z - s * x,
                         t * x * z - s * y, t * y * z + s * x, t * z * z + c};
    std::copy(m, m + 9, r);
}

struct Primitive {
    const char* name;
    std::function<Shape(SceneBuilder&)> make;
    std::function<double(vec3)> local_sdf;  // hand-written reference in the local frame
    float extent;                           // sampling half-size around the shape
};

std::vector<Primitive> all_primitives() {
    return {
        {"sphere", [](SceneBuilder& b) { return b.sphere(0.8f); },
         [](vec3 q) { return double(math::length(q)) - 0.8; }, 1.6f},
        {"box",
         [](SceneBuilder& b) {
             return b.box({1.2f, 0.8f, 1.6f});
         },
         [](vec3 q) {
             return double(math::sd_box(q, {0.6f, 0.4f, 0.8f}, {}, 0, 0));
         },
         1.5f},
        {"bevelled box",
         [](SceneBuilder& b) {
             return b.box({1.2f, 0.8f, 1.6f}, {0.1f, 0.2f, 0.3f, 0.25f}, 0.15f, 0.05f);
         },
         [](vec3 q) {
             return double(
                 math::sd_box(q, {0.6f, 0.4f, 0.8f}, {0.1f, 0.2f, 0.3f, 0.25f}, 0.15f, 0.05f));
         },
         1.5f},
        {"cylinder", [](SceneBuilder& b) { return b.cylinder(0.5f, 1.4f); },
         [](vec3 q) { return double(math::sd_cylinder(q, 0.7f, 0.5f)); }, 1.4f},
        {"cone", [](SceneBuilder& b) { return b.cone(0.6f, 1.2f); },
         [](vec3 q) { return double(math::sd_cone(q, 0.6f, 0.6f)); }, 1.3f},
        {"capsule", [](SceneBuilder& b) { return b.capsule(0.3f, 1.0f); },
         [](vec3 q) {
             const double y = std::clamp(double(q.y), -0.5, 0.5);
             return std::sqrt(double(q.x) * q.x + (q.y - y) * (q.y - y) + double(q.z) * q.z) - 0.3;
         },
         1.2f},
        {"torus", [](SceneBuilder& b) { return b.torus(0.9f, 0.25f); },
         [](vec3 q) {
             const double rho = std::hypot(double(q.x), double(q.z)) - 0.9;
             return std::hypot(rho, double(q.y)) - 0.25;
         },
         1.6f},
    };
}

struct RigidPlacement {
    vec3 axis;
    float angle;
    vec3 t;
};

RigidPlacement random_rigid(Rng& rng) {
    RigidPlacement r;
    do {
        r.axis = vec3(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1));
    } while (math::length(r.axis) < 0.2f);
    r.angle = rng.uniform(-3.1f, 3.1f);
    r.t = vec3(rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-2, 2));
    return r;
}

// The builder's placement rotated(...).translated(t) is x -> R x + t (rotation first); the world
// value is the local SDF at R^T (p - t).
TEST(Primitives, RigidPlacementMapsWorldToLocal) {
    Rng rng(11);
    for (const Primitive& prim : all_primitives()) {
        SCOPED_TRACE(prim.name);
        for (int trial = 0; trial < 4; ++trial) {
            const RigidPlacement pl = random_rigid(rng);
            SceneBuilder b;
            const Scene sc =
                b.build(prim.make(b).rotated(pl.axis, pl.angle).translated(pl.t), kBox);
            EXPECT_EQ(sc.lipschitz[0], 1.0f);
            double r[9];
            rotation_matrix(pl.axis, pl.angle, r);
            for (int i = 0; i < 50; ++i) {
                const vec3 p = pl.t + vec3(rng.uniform(-prim.extent, prim.extent),
                                           rng.uniform(-prim.extent, prim.extent),
                                           rng.uniform(-prim.extent, prim.extent));
                const double d[3] = {double(p.x) - pl.t.x, double(p.y) - pl.t.y,
                                     double(p.z) - pl.t.z};
                const vec3 q(float(r[0] * d[0] + r[3] * d[1] + r[6] * d[2]),
                             float(r[1] * d[0] + r[4] * d[1] + r[7] * d[2]),
                             float(r[2] * d[0] + r[5] * d[1] + r[8] * d[2]));
                EXPECT_NEAR(eval_point(sc, p), prim.local_sdf(q), 2e-5);
            }
        }
    }
}

// Central differences; returns false where the gradient is ill-defined (a kink: the medial axis,
// a crease, a quadrant switch), detected by one-sided differences that disagree.
bool numerical_gradient(const Scene& sc, vec3 p, float h, vec3& grad) {
    const float f0 = eval_point(sc, p);
    for (int axis = 0; axis < 3; ++axis) {
        vec3 e(0.0f);
        e[axis] = h;
        const float fp = eval_point(sc, p + e), fm = eval_point(sc, p - e);
        const float forward = (fp - f0) / h, backward = (f0 - fm) / h;
        if (std::fabs(forward - backward) > 0.05f) return false;
        grad[axis] = (fp - fm) / (2 * h);
    }
    return true;
}

TEST(Primitives, UnitGradientUnderRigidPlacements) {
    Rng rng(2024);
    for (const Primitive& prim : all_primitives()) {
        SCOPED_TRACE(prim.name);
        int tested = 0, sampled = 0;
        for (int trial = 0; trial < 5; ++trial) {
            const RigidPlacement pl = random_rigid(rng);
            SceneBuilder b;
            const Scene sc =
                b.build(prim.make(b).rotated(pl.axis, pl.angle).translated(pl.t), kBox);
            for (int i = 0; i < 200; ++i) {
                const vec3 p = pl.t + vec3(rng.uniform(-prim.extent, prim.extent),
                                           rng.uniform(-prim.extent, prim.extent),
                                           rng.uniform(-prim.extent, prim.extent));
                // Keep off the surface itself, where the curvature of small roundings is high.
                if (std::fabs(eval_point(sc, p)) < 0.03f) continue;
                ++sampled;
                vec3 g;
                if (!numerical_gradient(sc, p, 1e-3f, g)) continue;
                ++tested;
                EXPECT_NEAR(math::length(g), 1.0f, 1e-2f)
                    << "at (" << p.x << ", " << p.y << ", " << p.z << ")";
            }
        }
        // Kinks are a set of measure zero: nearly every sample must have been checked.
        EXPECT_GT(tested, sampled * 9 / 10);
        EXPECT_GT(tested, 700);
    }
}

// ---- Lipschitz bounds --------------------------------------------------------------------------

TEST(Lipschitz, NonUniformScaleGivesLargestInverseScale) {
    SceneBuilder b;
    // Placement scale (2, 0.5, 1): world->local is diag(1/2, 2, 1), spectral norm 2.
    const Scene sc = b.build(b.sphere(1.0f).scaled(vec3(2.0f, 0.5f, 1.0f)), kBox);
    ASSERT_EQ(sc.size(), 1u);
    EXPECT_FLOAT_EQ(sc.lipschitz[0], 2.0f);
    EXPECT_FLOAT_EQ(scene_info(sc).max_lipschitz, 2.0f);
    // The bound is attained far along y: the local point moves twice as fast as the world one.
    const float f10 = eval_point(sc, {0, 10, 0}), f11 = eval_point(sc, {0, 11, 0});
    EXPECT_NEAR(f10, 19.0f, 1e-5f);
    EXPECT_NEAR(f11 - f10, 2.0f, 1e-5f);
    // Along x it shrinks by half.
    EXPECT_NEAR(eval_point(sc, {4, 0, 0}), 1.0f, 1e-6f);

    // Uniform scales: 1 / s.
    SceneBuilder b2;
    EXPECT_FLOAT_EQ(b2.build(b2.box({1, 1, 1}).scaled(4.0f), kBox).lipschitz[0], 0.25f);
    EXPECT_FLOAT_EQ(b2.build(b2.torus(1, 0.2f).scaled(0.5f), kBox).lipschitz[0], 2.0f);
}

TEST(Lipschitz, OperatorsTakeTheMaxOfTheirChildren) {
    SceneBuilder b;
    Shape small = b.sphere(0.5f).scaled(0.25f);                                           // L = 4
    Shape squashed = b.box({1, 1, 1}).scaled(vec3(1.0f, 1.0f, 0.5f));                     // L = 2
    Shape rigid = b.cylinder(0.3f, 1.0f).rotated({1, 1, 0}, 0.7f).translated({1, 0, 0});  // L = 1
    Shape inner = smooth_union(squashed, rigid, 0.1f);
    Shape root = smooth_difference(inner, small, 0.05f);
    const Scene sc = b.build(root, kBox);
    // Post-order: squashed, rigid, inner union, small, root difference.
    ASSERT_EQ(sc.size(), 5u);
    EXPECT_FLOAT_EQ(sc.lipschitz[0], 2.0f);
    EXPECT_FLOAT_EQ(sc.lipschitz[1], 1.0f);
    EXPECT_FLOAT_EQ(sc.lipschitz[2], 2.0f);
    EXPECT_FLOAT_EQ(sc.lipschitz[3], 4.0f);
    EXPECT_FLOAT_EQ(sc.lipschitz[4], 4.0f);
    EXPECT_FLOAT_EQ(scene_info(sc).max_lipschitz, 4.0f);
}

// The exact spectral norm of the inverse of a 3x3 matrix, in double (power iteration on A^T A).
double inverse_spectral_norm(const double a[9]) {
    const double det = a[0] * (a[4] * a[8] - a[5] * a[7]) - a[1] * (a[3] * a[8] - a[5] * a[6]) +
                       a[2] * (a[3] * a[7] - a[4] * a[6]);
    const double inv[9] = {(a[4] * a[8] - a[5] * a[7]) / det, (a[2] * a[7] - a[1] * a[8]) / det,
                           (a[1] * a[5] - a[2] * a[4]) / det, (a[5] * a[6] - a[3] * a[8]) / det,
                           (a[0] * a[8] - a[2] * a[6]) / det, (a[2] * a[3] - a[0] * a[5]) / det,
                           (a[3] * a[7] - a[4] * a[6]) / det, (a[1] * a[6] - a[0] * a[7]) / det,
                           (a[0] * a[4] - a[1] * a[3]) / det};
    double v[3] = {1, 0.3, -0.2}, norm = 0;
    for (int it = 0; it < 500; ++it) {
        double w[3], u[3];
        for (int i = 0; i < 3; ++i)
            w[i] = inv[3 * i] * v[0] + inv[3 * i + 1] * v[1] + inv[3 * i + 2] * v[2];
        for (int j = 0; j < 3; ++j) u[j] = inv[j] * w[0] + inv[3 + j] * w[1] + inv[6 + j] * w[2];
        const double len = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        norm = std::sqrt(len);
        for (int i = 0; i < 3; ++i) v[i] = u[i] / len;
    }
    return norm;
}

TEST(Lipschitz, ShearedAndScaledPlacementsRespectTheBound) {
    // Local->world placements with shear and non-uniform scale.
    const double placements[][12] = {
        {1, 0.6, 0, 0.1, 0, 1, 0.3, -0.2, 0.2, 0, 0.8, 0.05},
        {1.5, 0, 0, 0, 0.4, 0.7, 0, 0.3, 0, 0, 1, 0},
        {0.5, 0.2, -0.1, 0, 0, 2, 0.5, 0, 0.3, 0, 1.2, -0.4},
    };
    Rng rng(99);
    for (const auto& m : placements) {
        Affine a;
        for (int i = 0; i < 12; ++i) a.m[i] = float(m[i]);
        const double linear[9] = {m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]};
        const double expected = inverse_spectral_norm(linear);
        for (const Primitive& prim : all_primitives()) {
            SCOPED_TRACE(prim.name);
            SceneBuilder b;
            const Scene sc = b.build(prim.make(b).transformed(a), kBox);
            const float lip = sc.lipschitz[0];
            EXPECT_NEAR(lip, expected, 1e-5 * expected);
            EXPECT_GE(double(lip), expected * (1 - 1e-6));
            float worst = 0;
            for (int i = 0; i < 300; ++i) {
                const vec3 p(rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-3, 3));
                const float step = i % 2 ? 0.05f : 2.0f;
                const vec3 q = p + vec3(rng.uniform(-step, step), rng.uniform(-step, step),
                                        rng.uniform(-step, step));
                const float dist = math::length(p - q);
                if (dist < 1e-3f) continue;
                const float ratio = std::fabs(eval_point(sc, p) - eval_point(sc, q)) / dist;
                worst = std::max(worst, ratio);
            }
            EXPECT_LE(worst, lip * (1 + 1e-4f));
            EXPECT_GT(worst, 0.3f * lip);  // a real bound of this field, not a degenerate one
        }
    }
}

TEST(Lipschitz, SphereUnderShearAttainsTheBound) {
    // For a sphere, |f(p) - f(q)| / |p - q| -> |M v| far along the direction v in which the
    // world->local map M stretches most, so the bound must be tight there.
    Affine a;
    const float m[12] = {1, 0.6f, 0, 0, 0, 1, 0.3f, 0, 0.2f, 0, 0.8f, 0};
    std::copy(m, m + 12, a.m);
    SceneBuilder b;
    const Scene sc = b.build(b.sphere(0.5f).transformed(a), kBox);
    const float lip = sc.lipschitz[0];
    float best = 0;
    Rng rng(5);
    for (int i = 0; i < 2000; ++i) {
        vec3 v(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1));
        if (math::length(v) < 0.1f) continue;
        v = v / math::length(v);
        best = std::max(best, eval_point(sc, v * 21.0f) - eval_point(sc, v * 20.0f));
    }
    EXPECT_LE(best, lip * (1 + 1e-4f));
    EXPECT_GT(best, 0.98f * lip);
}

TEST(Lipschitz, CombinedSceneRespectsItsBound) {
    SceneBuilder b;
    Affine shear;
    const float m[12] = {1, 0.5f, 0, 0, 0, 1, 0, 0, 0, 0.4f, 1, 0};
    std::copy(m, m + 12, shear.m);
    Shape s = smooth_union(b.box({1, 0.5f, 0.8f}, {0.1f, 0.1f, 0.1f, 0.1f}).transformed(shear),
                           b.torus(0.7f, 0.2f).scaled(vec3(1.5f, 0.7f, 1.0f)), 0.2f);
    s = smooth_difference(s, b.capsule(0.2f, 1.0f).rotated({0, 0, 1}, 1.0f), 0.1f);
    s = smooth_intersection(s, b.sphere(1.5f), 0.3f);
    const Scene sc = b.build(s, kBox);
    const float lip = sc.lipschitz[sc.root()];
    EXPECT_GT(lip, 1.0f / 0.7f - 1e-5f);  // at least the squashed torus's 1/0.7
    Rng rng(77);
    for (int i = 0; i < 2000; ++i) {
        const vec3 p(rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-2, 2));
        const vec3 q =
            p + vec3(rng.uniform(-0.1f, 0.1f), rng.uniform(-0.1f, 0.1f), rng.uniform(-0.1f, 0.1f));
        const float dist = math::length(p - q);
        if (dist < 1e-3f) continue;
        EXPECT_LE(std::fabs(eval_point(sc, p) - eval_point(sc, q)),
                  lip * dist * (1 + 1e-4f) + 1e-6f);
    }
}

}  // namespace
}  // namespace sdfprune
