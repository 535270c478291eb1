// primitives_exact_test.cpp — the primitives added after the paper's four (rounded cylinder,
// capped cone, hexagonal prism, octahedron, half-space) against distances computed another way:
// hand-worked points, then many random points against a brute-force distance (dense samples of
// a solid of revolution's profile, exact polygon and triangle distances), under the scene's own
// evaluator. Their ranges over boxes are tested with every kind in primitive_range_test.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "prune_check.hpp"
#include "sdfprune/builder.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/primitives.hpp"

namespace sdfprune {
namespace {

const Aabb kBox{vec3(-8.0f), vec3(8.0f)};
const double kSqrt2 = std::sqrt(2.0);

struct P2 {
    double x, y;
};

double dist_segment(P2 p, P2 a, P2 b) {
    const double ex = b.x - a.x, ey = b.y - a.y;
    const double len2 = ex * ex + ey * ey;
    double t = len2 > 0 ? ((p.x - a.x) * ex + (p.y - a.y) * ey) / len2 : 0;
    t = std::clamp(t, 0.0, 1.0);
    return std::hypot(p.x - a.x - t * ex, p.y - a.y - t * ey);
}

// Distance from p to a polyline (the densely sampled boundary of a profile).
double dist_polyline(P2 p, const std::vector<P2>& line) {
    double d = INFINITY;
    for (size_t i = 0; i + 1 < line.size(); ++i)
        d = std::min(d, dist_segment(p, line[i], line[i + 1]));
    return d;
}

// Appends a quarter (or any) arc of circle (centre c, radius r) from angle a0 to a1.
void arc(std::vector<P2>& line, P2 c, double r, double a0, double a1, int n = 4000) {
    for (int i = 0; i <= n; ++i) {
        const double a = a0 + (a1 - a0) * i / n;
        line.push_back({c.x + r * std::cos(a), c.y + r * std::sin(a)});
    }
}

// A solid of revolution about y given by its half profile (rho >= 0) and an inside test.
struct Revolution {
    std::vector<P2> profile;
    std::function<bool(P2)> inside;
    double distance(vec3 p) const {
        const P2 q{std::hypot(double(p.x), double(p.z)), p.y};
        const double d = dist_polyline(q, profile);
        return inside(q) ? -d : d;
    }
};

// Checks `s` at the hand-worked points, then at random points against `reference`.
void check_shape(SceneBuilder& b, Shape s, const std::vector<std::pair<vec3, double>>& cases,
                 const std::function<double(vec3)>& reference, double tol, float extent) {
    const Scene sc = b.build(s, kBox);
    ASSERT_EQ(sc.size(), 1u);
    for (const auto& [p, expected] : cases) {
        SCOPED_TRACE("point (" + std::to_string(p.x) + ", " + std::to_string(p.y) + ", " +
                     std::to_string(p.z) + ")");
        EXPECT_NEAR(eval_point(sc, p), expected, 2e-6);
        EXPECT_NEAR(reference(p), expected, tol) << "the reference itself";
    }
    Rng r(11);
    int bad = 0;
    for (int i = 0; i < 3000; ++i) {
        // Half the points near the surface, half anywhere around the shape.
        const vec3 p(r.uniform(-extent, extent), r.uniform(-extent, extent),
                     r.uniform(-extent, extent));
        const double want = reference(p);
        const double got = eval_point(sc, p);
        if (std::fabs(got - want) > tol && ++bad <= 5)
            ADD_FAILURE() << "at (" << p.x << ", " << p.y << ", " << p.z << "): " << got
                          << ", brute force " << want;
    }
    EXPECT_EQ(bad, 0);
}

// ---- rounded cylinder ------------------------------------------------------------------------

Revolution rounded_cylinder_reference(double r, double h, double rho) {
    Revolution rev;
    auto& l = rev.profile;
    l.push_back({0, -h});
    arc(l, {r - rho, -h + rho}, rho, -M_PI / 2, 0);
    arc(l, {r - rho, h - rho}, rho, 0, M_PI / 2);
    l.push_back({0, h});
    rev.inside = [=](P2 q) {
        if (std::fabs(q.y) > h || q.x > r) return false;
        const double dx = q.x - (r - rho), dy = std::fabs(q.y) - (h - rho);
        return dx <= 0 || dy <= 0 || dx * dx + dy * dy <= rho * rho;
    };
    return rev;
}

TEST(PrimitivesExact, RoundedCylinder) {
    SceneBuilder b;
    // Radius 1, full height 2, rims rounded by 0.25: the rim arcs are centred at (0.75, ±0.75)
    // in the (rho, y) plane.
    const Revolution ref = rounded_cylinder_reference(1.0, 1.0, 0.25);
    check_shape(
        b, b.rounded_cylinder(1.0f, 2.0f, 0.25f),
        {{{0, 0, 0}, -1.0},
         {{3, 0, 0}, 2.0},
         {{0, 0, -3}, 2.0},
         {{0, 3, 0}, 2.0},
         {{0, -1.5f, 0}, 0.5},
         {{2, 2, 0}, 1.25 * kSqrt2 - 0.25},
         {{0, -2, 2}, 1.25 * kSqrt2 - 0.25},
         {{0.5f, 0.9f, 0}, -0.1},
         {{0.95f, 0.95f, 0}, 0.2 * kSqrt2 - 0.25},
         {{0.6f, 0, 0.8f}, 0.0}},
        [&](vec3 p) { return ref.distance(p); }, 2e-5, 2.0f);
    // No rounding: a plain cylinder; rounding = radius = height / 2: a sphere.
    const Scene plain = b.build(b.rounded_cylinder(0.5f, 2.0f, 0.0f), kBox);
    const Scene cyl = b.build(b.cylinder(0.5f, 2.0f), kBox);
    const Scene ball = b.build(b.rounded_cylinder(0.7f, 1.4f, 0.7f), kBox);
    Rng r(3);
    for (int i = 0; i < 500; ++i) {
        const vec3 p(r.uniform(-2, 2), r.uniform(-2, 2), r.uniform(-2, 2));
        EXPECT_NEAR(eval_point(plain, p), eval_point(cyl, p), 1e-6);
        EXPECT_NEAR(eval_point(ball, p), math::length(p) - 0.7f, 2e-6);
    }
}

// ---- capped cone ---------------------------------------------------------------------------

// The trapezoid (0, -h), (r1, -h), (r2, h), (0, h): exact segment distances, sign by the
// trapezoid's half-planes.
double capped_cone_reference(vec3 p, double h, double r1, double r2) {
    const P2 q{std::hypot(double(p.x), double(p.z)), p.y};
    const double d =
        std::min({dist_segment(q, {0, -h}, {r1, -h}), dist_segment(q, {r1, -h}, {r2, h}),
                  dist_segment(q, {r2, h}, {0, h})});
    const bool inside = std::fabs(q.y) <= h && q.x <= r1 + (r2 - r1) * (q.y + h) / (2 * h);
    return inside ? -d : d;
}

TEST(PrimitivesExact, CappedCone) {
    SceneBuilder b;
    // Radius 1 at y = -1, 0.5 at y = +1: the side runs from (1, -1) to (0.5, 1) in the (rho, y)
    // plane, along (-1, 4) / sqrt 17, outward normal (4, 1) / sqrt 17.
    const double s17 = std::sqrt(17.0);
    auto ref = [](vec3 p) { return capped_cone_reference(p, 1, 1, 0.5); };
    check_shape(b, b.capped_cone(1.0f, 0.5f, 2.0f),
                {{{0, 0, 0}, -std::min(1.0, 3.0 / s17)},  // side at 0.75: distance 3/sqrt 17
                 {{0, 3, 0}, 2.0},
                 {{0, -2, 0}, 1.0},
                 {{0.25f, 1.5f, 0}, 0.5},
                 {{0, -1.5f, 0.5f}, 0.5},
                 {{2, -2, 0}, kSqrt2},                               // beyond the bottom rim
                 {{1.5f, 2, 0}, kSqrt2},                             // beyond the top rim
                 {{float(0.75 + 4 / s17), float(1 / s17), 0}, 1.0},  // off the side
                 {{0, -0.9f, 0}, -0.1}},
                ref, 1e-5, 2.0f);
    // Pointed and flat extremes: a cone (top radius 0) matches `cone`, equal radii `cylinder`.
    const Scene pointed = b.build(b.capped_cone(0.6f, 0.0f, 1.4f), kBox);
    const Scene cone = b.build(b.cone(0.6f, 1.4f), kBox);
    const Scene flat = b.build(b.capped_cone(0.6f, 0.6f, 1.4f), kBox);
    const Scene cyl = b.build(b.cylinder(0.6f, 1.4f), kBox);
    Rng r(5);
    for (int i = 0; i < 1000; ++i) {
        const vec3 p(r.uniform(-2, 2), r.uniform(-2, 2), r.uniform(-2, 2));
        EXPECT_NEAR(eval_point(pointed, p), eval_point(cone, p), 2e-6);
        EXPECT_NEAR(eval_point(flat, p), eval_point(cyl, p), 2e-6);
    }
    // An inverted cone (apex down) against the reference.
    check_shape(
        b, b.capped_cone(0.0f, 0.8f, 1.0f), {{{0, 2, 0}, 1.5}},
        [](vec3 p) { return capped_cone_reference(p, 0.5, 0, 0.8); }, 1e-5, 1.5f);
    PrimitiveShape bad;
    bad.height = 1;
    EXPECT_EQ(validate_primitive(math::kPrimCappedCone, bad), "radius or top_radius must be > 0");
}

// ---- hexagonal prism ---------------------------------------------------------------------

// The hexagon's 6 sides as exact segment distances, inside by its 6 half-planes, extruded case
// by case (not by the min/max formula of sd_extrude).
double hex_prism_reference(vec3 p, double radius, double h) {
    P2 v[6];
    for (int i = 0; i < 6; ++i)
        v[i] = {radius * std::cos(M_PI / 3 * i), radius * std::sin(M_PI / 3 * i)};
    const P2 q{p.x, p.z};
    double d = INFINITY;
    bool inside = true;
    for (int i = 0; i < 6; ++i) {
        const P2 a = v[i], b = v[(i + 1) % 6];
        d = std::min(d, dist_segment(q, a, b));
        // Counter-clockwise vertices: inside is left of every side.
        if ((b.x - a.x) * (q.y - a.y) - (b.y - a.y) * (q.x - a.x) < 0) inside = false;
    }
    const double d2 = inside ? -d : d, dy = std::fabs(p.y) - h;
    if (d2 > 0 && dy > 0) return std::hypot(d2, dy);
    if (d2 > 0) return d2;
    if (dy > 0) return dy;
    return std::max(d2, dy);
}

TEST(PrimitivesExact, HexPrism) {
    SceneBuilder b;
    // Circumradius 1 (vertices at (±1, 0) and (±1/2, ±√3/2) in xz), apothem √3/2, full height 2.
    const double a = std::sqrt(3.0) / 2;
    check_shape(
        b, b.hex_prism(1.0f, 2.0f),
        {{{0, 0, 0}, -a},
         {{0, 0, 2}, 2 - a},    // off a flat side
         {{3, 0, 0}, 2.0},      // off a vertex
         {{0, 1.5f, 0}, 0.5},   // above the top
         {{0, 0.5f, 0}, -0.5},  // the top is nearer than the sides
         {{0.5f, 0, 0}, -a / 2},
         {{3, 3, 0}, std::sqrt(8.0)},
         {{0, 3, 2}, std::hypot(2.0, 2 - a)}},
        [](vec3 p) { return hex_prism_reference(p, 1, 1); }, 2e-6, 2.0f);
    check_shape(
        b, b.hex_prism(0.3f, 3.0f), {{{0, 2, 0}, 0.5}},
        [](vec3 p) { return hex_prism_reference(p, 0.3, 1.5); }, 2e-6, 2.0f);
}

// ---- octahedron ----------------------------------------------------------------------------

using D3 = std::array<double, 3>;
D3 sub(D3 a, D3 b) {
    return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
double dot3(D3 a, D3 b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// Distance from p to the triangle abc (closest point by Voronoi regions, Ericson 5.1.5).
double dist_triangle(D3 p, D3 a, D3 b, D3 c) {
    const D3 ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
    auto at = [&](double v, double w) {
        const D3 x{a[0] + ab[0] * v + ac[0] * w, a[1] + ab[1] * v + ac[1] * w,
                   a[2] + ab[2] * v + ac[2] * w};
        const D3 d = sub(p, x);
        return std::sqrt(dot3(d, d));
    };
    const double d1 = dot3(ab, ap), d2 = dot3(ac, ap);
    if (d1 <= 0 && d2 <= 0) return at(0, 0);
    const D3 bp = sub(p, b);
    const double d3 = dot3(ab, bp), d4 = dot3(ac, bp);
    if (d3 >= 0 && d4 <= d3) return at(1, 0);
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return at(d1 / (d1 - d3), 0);
    const D3 cp = sub(p, c);
    const double d5 = dot3(ab, cp), d6 = dot3(ac, cp);
    if (d6 >= 0 && d5 <= d6) return at(0, 1);
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return at(0, d2 / (d2 - d6));
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
        const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return at(1 - w, w);
    }
    const double denom = 1 / (va + vb + vc);
    return at(vb * denom, vc * denom);
}

// The eight faces as triangles; inside, the distance to the nearest face plane.
double octahedron_reference(vec3 p, double s) {
    const D3 q{p.x, p.y, p.z};
    double d = INFINITY, plane = -INFINITY;
    for (int f = 0; f < 8; ++f) {
        const double sx = f & 1 ? -1 : 1, sy = f & 2 ? -1 : 1, sz = f & 4 ? -1 : 1;
        d = std::min(d, dist_triangle(q, {sx * s, 0, 0}, {0, sy * s, 0}, {0, 0, sz * s}));
        plane = std::max(plane, (sx * q[0] + sy * q[1] + sz * q[2] - s) / std::sqrt(3.0));
    }
    return plane <= 0 ? plane : d;
}

TEST(PrimitivesExact, Octahedron) {
    SceneBuilder b;
    const double s3 = std::sqrt(3.0);
    check_shape(
        b, b.octahedron(1.0f),
        {{{0, 0, 0}, -1 / s3},
         {{2, 0, 0}, 1.0},  // off a vertex
         {{0, -3, 0}, 2.0},
         {{1, 1, 0}, std::sqrt(0.5)},      // off an edge's midpoint
         {{1, 1, 1}, 2 / s3},              // off a face's centre
         {{0.2f, 0.2f, 0.2f}, -0.4 / s3},  // inside, nearest face
         {{0, 0, 0.5f}, -0.5 / s3}},
        [](vec3 p) { return octahedron_reference(p, 1); }, 2e-6, 2.0f);
    check_shape(
        b, b.octahedron(0.35f), {{{0, 0, 1}, 0.65}},
        [](vec3 p) { return octahedron_reference(p, 0.35); }, 2e-6, 1.0f);
}

// ---- half-space --------------------------------------------------------------------------

TEST(PrimitivesExact, Plane) {
    SceneBuilder b;
    // Normal (0, 2, 0) (not unit), offset 0.5: the half-space y <= 0.5.
    const Scene sc = b.build(b.plane({0, 2, 0}, 0.5f), kBox);
    EXPECT_NEAR(eval_point(sc, {0, 0, 0}), -0.5, 1e-7);
    EXPECT_NEAR(eval_point(sc, {3, 2, -1}), 1.5, 1e-6);
    EXPECT_NEAR(eval_point(sc, {0, -4, 7}), -4.5, 1e-6);
    // A tilted one against dot(p, n̂) − offset written in double.
    const vec3 n(1, -2, 2);  // |n| = 3
    const Scene tilted = b.build(b.plane(n, -0.25f), kBox);
    Rng r(9);
    for (int i = 0; i < 1000; ++i) {
        const vec3 p(r.uniform(-4, 4), r.uniform(-4, 4), r.uniform(-4, 4));
        const double want = (double(p.x) - 2.0 * p.y + 2.0 * p.z) / 3.0 + 0.25;
        EXPECT_NEAR(eval_point(tilted, p), want, 2e-6);
    }
    // Moved by a placement: the plane y <= 0 rotated to x <= 0, then shifted to x <= 1.
    const Scene moved =
        b.build(b.plane({0, 1, 0}).rotated({0, 0, 1}, -1.5707963f).translated({1, 0, 0}), kBox);
    EXPECT_NEAR(eval_point(moved, {3, 5, -2}), 2.0, 2e-6);
    EXPECT_NEAR(eval_point(moved, {0, 1, 1}), -1.0, 2e-6);
    EXPECT_EQ(sc.bound[0].scale, 0.0f) << "no similarity bound for an unbounded primitive";
    PrimitiveShape zero;
    EXPECT_EQ(validate_primitive(math::kPrimPlane, zero), "normal must not be zero");
}

// Scene bounds with half-spaces: the hull of the bounded primitives where the tree bounds the
// shape, else a one-line refusal.
TEST(PrimitivesExact, PlaneSceneBounds) {
    SceneBuilder b;
    const Shape ball = b.sphere(1.0f).translated({2, 0, 0});
    const Shape half = b.plane({0, 1, 0}, 0.25f);
    const Scene alone = b.build(ball);
    for (const Shape s : {ball & half, ball - half, smooth_intersection(half, ball, 0.2f),
                          (ball & half) | b.box({1, 1, 1})}) {
        const Scene sc = b.build(s);
        EXPECT_TRUE(shape_is_bounded(sc));
        if (sc.primitive_count() == 2) {
            EXPECT_EQ(sc.aabb.min, alone.aabb.min);
            EXPECT_EQ(sc.aabb.max, alone.aabb.max);
        }
    }
    for (const Shape s : {half, ball | half, half - ball, smooth_union(ball, half, 0.1f),
                          (ball | half) & (half - ball)}) {
        try {
            (void)b.build(s);
            ADD_FAILURE() << "an unbounded scene was built without an aabb";
        } catch (const SceneError& e) {
            EXPECT_STREQ(e.what(),
                         "the scene's shape is unbounded (a plane not cut off by bounded shapes): "
                         "give it an explicit aabb");
        }
        EXPECT_NO_THROW((void)b.build(s, kBox)) << "an explicit aabb is always accepted";
    }
}

// ---- convexity, which the tracer's convex steps rely on --------------------------------------

// math::primitive_value_is_convex: along random lines through and around random shapes of every
// kind, under rotations and uniform and non-uniform scales (non-uniform after a rotation: a
// shear), no value lies above the chord of two others beyond float rounding. The torus, the one
// kind said not to be convex, must show it: the check can fail.
TEST(PrimitivesExact, ConvexKindsHaveConvexValues) {
    Rng r(33);
    for (uint32_t k = 0; k < math::kPrimitiveKindCount; ++k) {
        uint32_t violations = 0, chords = 0;
        for (int shape = 0; shape < 60; ++shape) {
            SceneBuilder b;
            Shape s = test::random_primitive(b, r, k);
            const float scale = std::exp(r.uniform(std::log(0.3f), std::log(3.0f)));
            s = shape % 3 == 0 ? s.scaled(scale)
                               : s.scaled(test::random_in_box(r, vec3(0.4f), vec3(2.0f)));
            s = s.rotated(test::random_direction(r), r.uniform(0.0f, 6.2831853f));
            if (shape % 3 == 2) s = s.scaled(test::random_in_box(r, vec3(0.4f), vec3(2.0f)));
            s = s.translated(test::random_in_box(r, vec3(-1.0f), vec3(1.0f)));
            const Scene sc = b.build(s, kBox);
            for (int line = 0; line < 150; ++line) {
                const vec3 o = test::random_in_box(r, vec3(-2.0f), vec3(2.0f));
                const vec3 d = test::random_direction(r);
                float t[3];
                for (float& ti : t) ti = r.uniform(-4.0f, 4.0f);
                std::sort(t, t + 3);
                if (t[2] - t[0] < 1e-3f) continue;
                float g[3];
                for (int i = 0; i < 3; ++i) g[i] = eval_point(sc, o + d * t[i]);
                const float w = (t[1] - t[0]) / (t[2] - t[0]);
                const float chord = g[0] * (1 - w) + g[2] * w;
                const float tol = 1e-5f + 2e-6f * (std::fabs(g[0]) + std::fabs(g[2]) + 8.0f);
                ++chords;
                violations += g[1] > chord + tol;
            }
        }
        EXPECT_GT(chords, 8000u);
        if (math::primitive_value_is_convex(k))
            EXPECT_EQ(violations, 0u) << primitive_kind_name(k) << ": values above a chord";
        else
            EXPECT_GT(violations, 0u) << primitive_kind_name(k) << " is convex after all";
    }
}

// ---- every kind through the scene format ----------------------------------------------------

TEST(PrimitivesExact, EveryKindRoundTripsThroughJson) {
    Rng r(21);
    for (uint32_t k = 0; k < math::kPrimitiveKindCount; ++k) {
        SceneBuilder b;
        const Shape s = test::random_primitive(b, r, k).translated({0.1f, 0.2f, 0.3f});
        const Scene sc = b.build(s | b.sphere(0.1f), kBox);
        const std::string json = scene_to_json(sc);
        EXPECT_NE(json.find(std::string("\"primitiveType\":\"") + primitive_kind_name(k) + "\""),
                  std::string::npos);
        const Scene back = parse_scene(json, "round trip");
        EXPECT_EQ(back.kind, sc.kind) << primitive_kind_name(k);
        ASSERT_EQ(back.params.size(), sc.params.size());
        EXPECT_EQ(back.params[0].a, sc.params[0].a) << primitive_kind_name(k);
        EXPECT_EQ(back.params[0].b, sc.params[0].b);
        EXPECT_EQ(back.params[0].c, sc.params[0].c);
        EXPECT_EQ(scene_to_json(back), json);
        // A required field missing is named.
        const PrimitiveKindInfo& info = primitive_info(k);
        for (uint32_t f = 0; f < info.field_count; ++f) {
            if (!info.fields[f].required) continue;
            const std::string key = std::string("\"") + info.fields[f].name + "\":";
            std::string broken = json;
            const size_t at = broken.find(key);
            ASSERT_NE(at, std::string::npos);
            broken.replace(at, key.size(), "\"ignored_field\":");
            try {
                (void)parse_scene(broken, "broken");
                ADD_FAILURE() << primitive_kind_name(k) << " loaded without " << key;
            } catch (const SceneError& e) {
                EXPECT_NE(std::string(e.what()).find("missing field \"" +
                                                     std::string(info.fields[f].name) + "\""),
                          std::string::npos)
                    << e.what();
            }
        }
    }
}

// ---- parameters -----------------------------------------------------------------------------

TEST(PrimitivesExact, InvalidParametersAreRefused) {
    auto error = [](uint32_t kind, const PrimitiveShape& s) { return validate_primitive(kind, s); };
    PrimitiveShape rc;
    rc.radius = 0.5f;
    rc.height = 2.0f;
    rc.rounding = 0.6f;
    EXPECT_EQ(error(math::kPrimRoundedCylinder, rc), "rounding must be <= radius and <= height/2");
    rc.rounding = -0.1f;
    EXPECT_NE(error(math::kPrimRoundedCylinder, rc).find("rounding must be >= 0"),
              std::string::npos);
    rc.rounding = 0.5f;
    EXPECT_EQ(error(math::kPrimRoundedCylinder, rc), "");
}

}  // namespace
}  // namespace sdfprune
