// operators_test.cpp — the blending kernel and smooth/hard CSG operators of DESIGN.md §2.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "sdfprune/builder.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/eval.hpp"

namespace sdfprune {
namespace {

const Aabb kBox{vec3(-4.0f), vec3(4.0f)};

// DESIGN.md §2, in double.
double phi(double x, double k) {
    if (k <= 0) return 0;
    const double m = std::max(k - x, 0.0);
    return m * m / (4 * k);
}
double smooth_union_ref(double a, double b, double k) {
    return std::min(a, b) - phi(std::fabs(a - b), k);
}
double smooth_inter_ref(double a, double b, double k) {
    return std::max(a, b) + phi(std::fabs(a - b), k);
}
double smooth_diff_ref(double a, double b, double k) {
    return std::max(a, -b) + phi(std::fabs(a + b), k);
}

TEST(BlendKernel, HandComputedValues) {
    EXPECT_FLOAT_EQ(math::blend_kernel(0.0f, 1.0f), 0.25f);
    EXPECT_FLOAT_EQ(math::blend_kernel(0.25f, 1.0f), 0.140625f);  // 0.75^2 / 4
    EXPECT_FLOAT_EQ(math::blend_kernel(0.1f, 0.4f), 0.05625f);    // 0.3^2 / 1.6
    EXPECT_FLOAT_EQ(math::blend_kernel(0.0f, 0.5f), 0.125f);
    // Zero at and beyond x = k, and for k = 0 (hard CSG) whatever x is.
    EXPECT_EQ(math::blend_kernel(0.5f, 0.5f), 0.0f);
    EXPECT_EQ(math::blend_kernel(3.0f, 0.5f), 0.0f);
    EXPECT_EQ(math::blend_kernel(0.0f, 0.0f), 0.0f);
    EXPECT_EQ(math::blend_kernel(-1.0f, 0.0f), 0.0f);
}

TEST(BlendKernel, MatchesFormulaOnAGrid) {
    for (float k : {0.0f, 0.01f, 0.1f, 0.5f, 2.0f})
        for (int i = 0; i <= 100; ++i) {
            const float x = float(i) * 0.03f;
            EXPECT_NEAR(math::blend_kernel(x, k), phi(x, k), 1e-6 * (1 + phi(x, k)))
                << "x " << x << " k " << k;
        }
}

TEST(ApplyOperator, MatchesTheFormulasOfDesign) {
    Rng rng(3);
    for (int i = 0; i < 2000; ++i) {
        const float a = rng.uniform(-2, 2), b = rng.uniform(-2, 2);
        const float k = i % 4 == 0 ? 0.0f : rng.uniform(0, 1.5f);
        const double tol = 1e-6 * (1 + std::fabs(a) + std::fabs(b));
        // s = +1: union; s = -1: intersection; a difference is an intersection with -b.
        EXPECT_NEAR(math::apply_operator(1.0f, k, a, b), smooth_union_ref(a, b, k), tol);
        EXPECT_NEAR(math::apply_operator(-1.0f, k, a, b), smooth_inter_ref(a, b, k), tol);
        EXPECT_NEAR(math::apply_operator(-1.0f, k, a, -b), smooth_diff_ref(a, b, k), tol);
    }
    EXPECT_EQ(math::operator_s(math::kOpUnion), 1.0f);
    EXPECT_EQ(math::operator_s(math::kOpIntersection), -1.0f);
    EXPECT_EQ(math::operator_s(math::kOpDifference), -1.0f);
}

TEST(ApplyOperator, HandComputedValues) {
    // a = 0.1, b = 0.3, k = 0.4: |a - b| = 0.2, phi = 0.2^2 / 1.6 = 0.025.
    EXPECT_FLOAT_EQ(math::apply_operator(1.0f, 0.4f, 0.1f, 0.3f), 0.075f);
    EXPECT_FLOAT_EQ(math::apply_operator(-1.0f, 0.4f, 0.1f, 0.3f), 0.325f);
    // Difference a - b with a = 0.1, b = -0.3 (passed negated): max(0.1, 0.3) + phi(0.2) = 0.325.
    const float b = -0.3f;
    EXPECT_FLOAT_EQ(math::apply_operator(-1.0f, 0.4f, 0.1f, -b), 0.325f);
    // ... and with b = 0.3: max(0.1, -0.3) + phi(|0.1 + 0.3|) = 0.1 + 0 (|a + b| = k).
    EXPECT_FLOAT_EQ(math::apply_operator(-1.0f, 0.4f, 0.1f, -0.3f), 0.1f);
    // Operands further apart than k: the kernel vanishes.
    EXPECT_EQ(math::apply_operator(1.0f, 0.4f, -1.0f, 0.5f), -1.0f);
    EXPECT_EQ(math::apply_operator(-1.0f, 0.4f, -1.0f, 0.5f), 0.5f);
}

// Two unit spheres centred at x = -0.5 and x = +0.5, blended with k = 0.5.
struct TwoSpheres {
    SceneBuilder b;
    Shape a = b.sphere(1.0f).translated({-0.5f, 0, 0});
    Shape c = b.sphere(1.0f).translated({0.5f, 0, 0});
};

struct Expected {
    vec3 p;
    double a, b, uni, inter, diff;  // the spheres' distances and the three smooth operators
};

// Written out by hand (python, double precision) from DESIGN.md §2.
const Expected kTwoSpheres[] = {
    {{0, 0, 0}, -0.5, -0.5, -0.625, -0.375, 0.5},
    {{0, 1, 0}, 0.118033989, 0.118033989, -0.006966011, 0.243033989, 0.152864045},
    {{2, 0, 0}, 1.5, 0.5, 0.5, 1.5, 1.5},
    {{0.2f, 0.9f, 0}, 0.140175425, -0.051316702, -0.098905256, 0.187763979, 0.224694000},
    {{0.1f, 0.3f, -0.8f}, 0.044030651, -0.056601887, -0.136349072, 0.123777836, 0.175395287},
    {{-1.6f, 0, 0}, 0.1, 1.1, 0.1, 1.1, 0.1},
};

TEST(SmoothOperators, TwoSpheresHandComputed) {
    for (uint32_t kind : {math::kOpUnion, math::kOpIntersection, math::kOpDifference}) {
        TwoSpheres t;
        const Scene sc = t.b.build(t.b.combine(kind, t.a, t.c, 0.5f), kBox);
        ASSERT_EQ(sc.size(), 3u);
        EXPECT_EQ(sc.kind[2], kind);
        EXPECT_FLOAT_EQ(sc.blend[2], 0.5f);
        for (const Expected& e : kTwoSpheres) {
            const double want = kind == math::kOpUnion          ? e.uni
                                : kind == math::kOpIntersection ? e.inter
                                                                : e.diff;
            EXPECT_NEAR(eval_point(sc, e.p), want, 2e-6)
                << operator_kind_name(kind) << " at (" << e.p.x << ", " << e.p.y << ", " << e.p.z
                << ")";
        }
    }
    // The builder's named helpers build the same operators.
    TwoSpheres t;
    const Scene u = t.b.build(smooth_union(t.a, t.c, 0.5f), kBox);
    const Scene i = t.b.build(smooth_intersection(t.a, t.c, 0.5f), kBox);
    const Scene d = t.b.build(smooth_difference(t.a, t.c, 0.5f), kBox);
    for (const Expected& e : kTwoSpheres) {
        EXPECT_NEAR(eval_point(u, e.p), e.uni, 2e-6);
        EXPECT_NEAR(eval_point(i, e.p), e.inter, 2e-6);
        EXPECT_NEAR(eval_point(d, e.p), e.diff, 2e-6);
    }
}

// Each operand alone, as the scene built from it evaluates it.
struct Operands {
    SceneBuilder b;
    Shape left = b.box({1.0f, 0.6f, 0.8f}, {0.1f, 0.1f, 0.1f, 0.1f}).rotated({1, 2, 3}, 0.4f);
    Shape right = b.torus(0.5f, 0.2f).rotated({1, 0, 0}, 1.2f).translated({0.3f, 0.1f, 0});
};

TEST(HardCsg, EqualsMinAndMaxExactly) {
    Operands o;
    const Scene a = o.b.build(o.left, kBox), c = o.b.build(o.right, kBox);
    const Scene uni = o.b.build(o.left | o.right, kBox);
    const Scene inter = o.b.build(o.left & o.right, kBox);
    const Scene diff = o.b.build(o.left - o.right, kBox);
    EXPECT_EQ(uni.kind[2], math::kOpUnion);
    EXPECT_EQ(inter.kind[2], math::kOpIntersection);
    EXPECT_EQ(diff.kind[2], math::kOpDifference);
    for (const Scene* s : {&uni, &inter, &diff}) EXPECT_EQ(s->blend[2], 0.0f);
    // The right operand of a difference is negated, nothing else.
    EXPECT_EQ(diff.negated, (std::vector<uint8_t>{0, 1, 0}));
    EXPECT_EQ(uni.negated, (std::vector<uint8_t>{0, 0, 0}));
    Rng rng(17);
    int inside = 0;
    for (int i = 0; i < 2000; ++i) {
        const vec3 p(rng.uniform(-0.8f, 0.8f), rng.uniform(-0.8f, 0.8f), rng.uniform(-0.8f, 0.8f));
        const float fa = eval_point(a, p), fb = eval_point(c, p);
        inside += fa < 0 && fb < 0;
        EXPECT_EQ(eval_point(uni, p), std::min(fa, fb));
        EXPECT_EQ(eval_point(inter, p), std::max(fa, fb));
        EXPECT_EQ(eval_point(diff, p), std::max(fa, -fb));
    }
    EXPECT_GT(inside, 10);  // the operands overlap, so every branch of min/max is exercised
}

TEST(HardCsg, DifferenceOfSpheresHandComputed) {
    // Unit sphere minus a sphere of radius 0.5 centred at (1, 0, 0).
    SceneBuilder b;
    const Scene sc = b.build(b.sphere(1.0f) - b.sphere(0.5f).translated({1, 0, 0}), kBox);
    EXPECT_FLOAT_EQ(eval_point(sc, {0, 0, 0}), -0.5f);       // max(-1, -(1 - 0.5))
    EXPECT_FLOAT_EQ(eval_point(sc, {1, 0, 0}), 0.5f);        // inside the hole: max(0, 0.5)
    EXPECT_FLOAT_EQ(eval_point(sc, {-2, 0, 0}), 1.0f);       // far side: max(1, -2.5)
    EXPECT_FLOAT_EQ(eval_point(sc, {0.25f, 0, 0}), -0.25f);  // max(-0.75, -(0.75 - 0.5))
}

TEST(SmoothOperators, NestedDifferencesComposeSigns) {
    // A - (B - C) and (A - B) - C: the signs of nested right operands compose.
    Operands o;
    Shape extra = o.b.sphere(0.4f).translated({0, 0.2f, 0.1f});
    const Scene a = o.b.build(o.left, kBox), bb = o.b.build(o.right, kBox),
                c = o.b.build(extra, kBox);
    const Scene nested_right =
        o.b.build(smooth_difference(o.left, smooth_difference(o.right, extra, 0.1f), 0.2f), kBox);
    const Scene nested_left =
        o.b.build(smooth_difference(smooth_difference(o.left, o.right, 0.1f), extra, 0.2f), kBox);
    const Scene mixed = o.b.build(
        smooth_intersection(o.left, smooth_union(o.right, extra, 0.15f), 0.05f) - extra, kBox);
    Rng rng(23);
    for (int i = 0; i < 500; ++i) {
        const vec3 p(rng.uniform(-1.5f, 1.5f), rng.uniform(-1.5f, 1.5f), rng.uniform(-1.5f, 1.5f));
        const double fa = eval_point(a, p), fb = eval_point(bb, p), fc = eval_point(c, p);
        EXPECT_NEAR(eval_point(nested_right, p),
                    smooth_diff_ref(fa, smooth_diff_ref(fb, fc, 0.1), 0.2), 1e-5);
        EXPECT_NEAR(eval_point(nested_left, p),
                    smooth_diff_ref(smooth_diff_ref(fa, fb, 0.1), fc, 0.2), 1e-5);
        EXPECT_NEAR(eval_point(mixed, p),
                    std::max(smooth_inter_ref(fa, smooth_union_ref(fb, fc, 0.15), 0.05), -fc),
                    1e-5);
    }
}

TEST(SmoothOperators, PlacementOfAnOperatorMovesBothOperands) {
    // Translating a combined shape is the same as translating each operand.
    SceneBuilder b;
    Shape s1 = b.sphere(0.6f), s2 = b.cylinder(0.2f, 2.0f).rotated({0, 0, 1}, 0.5f);
    const Scene moved =
        b.build(smooth_union(s1, s2, 0.3f).rotated({0, 1, 0}, 0.8f).translated({1, 2, 3}), kBox);
    const Scene each =
        b.build(smooth_union(s1.rotated({0, 1, 0}, 0.8f).translated({1, 2, 3}),
                             s2.rotated({0, 1, 0}, 0.8f).translated({1, 2, 3}), 0.3f),
                kBox);
    // At the centre: sphere -0.6, cylinder -0.2 (on its axis); |a - b| = 0.4 > k, so min wins.
    EXPECT_NEAR(eval_point(moved, {1, 2, 3}), -0.6f, 1e-5);
    Rng rng(8);
    for (int i = 0; i < 200; ++i) {
        const vec3 p(rng.uniform(-1, 3), rng.uniform(0, 4), rng.uniform(1, 5));
        EXPECT_NEAR(eval_point(moved, p), eval_point(each, p), 1e-5);
    }
}

}  // namespace
}  // namespace sdfprune
