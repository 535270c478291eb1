// deep_chain_test.cpp — 100,000-deep CSG chains through loader, builder, evaluator and saver.
#include <gtest/gtest.h>

#include <charconv>
#include <cmath>
#include <string>
#include <vector>

#include "sdfprune/builder.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/io.hpp"

namespace sdfprune {
namespace {

constexpr uint32_t kDepth = 100000;  // operators in the chain; spheres = kDepth + 1
constexpr float kBlend = 0.02f;

struct Sphere {
    vec3 c;
    float r;
};

// kDepth + 1 small spheres on a wound-up helix inside [-1, 1]^3, close enough to blend.
std::vector<Sphere> chain_spheres() {
    std::vector<Sphere> s;
    Rng rng(42);
    for (uint32_t i = 0; i <= kDepth; ++i) {
        const float t = float(i) * 0.013f;
        s.push_back({vec3(0.7f * std::cos(t) + rng.uniform(-0.05f, 0.05f),
                          -0.9f + 1.8f * float(i) / float(kDepth),
                          0.7f * std::sin(t) + rng.uniform(-0.05f, 0.05f)),
                     rng.uniform(0.01f, 0.03f)});
    }
    return s;
}

void append_float(std::string& out, float x) {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, x);
    out.append(buf, r.ptr);
}

void append_sphere(std::string& out, const Sphere& s) {
    out += R"({"nodeType":"primitive","primitiveType":"sphere","radius":)";
    append_float(out, s.r);
    out += R"(,"matrix":[1,0,0,)";
    append_float(out, -s.c.x);
    out += ",0,1,0,";
    append_float(out, -s.c.y);
    out += ",0,0,1,";
    append_float(out, -s.c.z);
    out += "]}";
}

const char* const kOpenUnion =
    R"({"nodeType":"binaryOperator","blendMode":"union","blendRadius":0.02,)"
    R"("matrix":[1,0,0,0,0,1,0,0,0,0,1,0],)";
const char* const kAabb = R"("aabb_min":[-1.5,-1.5,-1.5],"aabb_max":[1.5,1.5,1.5],)";

// union(union(...union(s0, s1)..., s_{n-1}), s_n): the JSON nests down the left children.
std::string left_deep_json(const std::vector<Sphere>& s) {
    std::string out;
    out.reserve(s.size() * 260);
    for (uint32_t i = 0; i < kDepth; ++i) {
        out += kOpenUnion;
        if (i == 0) out += kAabb;
        out += R"("leftChild":)";
    }
    append_sphere(out, s[0]);
    for (uint32_t i = 1; i <= kDepth; ++i) {
        out += R"(,"rightChild":)";
        append_sphere(out, s[i]);
        out += "}";
    }
    return out;
}

// union(s0, union(s1, ... union(s_{n-1}, s_n))): the JSON nests down the right children.
std::string right_deep_json(const std::vector<Sphere>& s) {
    std::string out;
    out.reserve(s.size() * 260);
    for (uint32_t i = 0; i < kDepth; ++i) {
        out += kOpenUnion;
        if (i == 0) out += kAabb;
        out += R"("leftChild":)";
        append_sphere(out, s[i]);
        out += R"(,"rightChild":)";
    }
    append_sphere(out, s[kDepth]);
    out.append(kDepth, '}');
    return out;
}

float sphere_value(const Sphere& s, vec3 p) {
    return math::length(p - s.c) - s.r;
}

// The same folds, as plain loops.
float left_fold(const std::vector<Sphere>& s, vec3 p) {
    float v = sphere_value(s[0], p);
    for (uint32_t i = 1; i <= kDepth; ++i)
        v = math::apply_operator(1.0f, kBlend, v, sphere_value(s[i], p));
    return v;
}

float right_fold(const std::vector<Sphere>& s, vec3 p) {
    float v = sphere_value(s[kDepth], p);
    for (uint32_t i = kDepth; i-- > 0;)
        v = math::apply_operator(1.0f, kBlend, sphere_value(s[i], p), v);
    return v;
}

// Query points: random ones in the box, and points on and near the helix.
std::vector<vec3> query_points(const std::vector<Sphere>& s) {
    std::vector<vec3> pts;
    Rng rng(1);
    for (int i = 0; i < 24; ++i)
        pts.emplace_back(rng.uniform(-1.2f, 1.2f), rng.uniform(-1.2f, 1.2f),
                         rng.uniform(-1.2f, 1.2f));
    for (uint32_t i = 0; i <= kDepth; i += kDepth / 12)
        pts.push_back(s[i].c + vec3(0.0f, 0.0f, 0.01f * float(i % 3)));
    return pts;
}

void expect_chain_values(const Scene& sc, const std::vector<Sphere>& s, bool left_deep) {
    int inside = 0;
    for (const vec3& p : query_points(s)) {
        const float want = left_deep ? left_fold(s, p) : right_fold(s, p);
        EXPECT_NEAR(eval_point(sc, p), want, 1e-5f * (1 + std::fabs(want)))
            << "at (" << p.x << ", " << p.y << ", " << p.z << ")";
        inside += want < 0;
    }
    EXPECT_GT(inside, 5);
}

void expect_chain_shape(const Scene& sc, bool left_deep) {
    const SceneInfo info = scene_info(sc);
    EXPECT_EQ(info.nodes, 2 * kDepth + 1);
    EXPECT_EQ(info.primitives, kDepth + 1);
    EXPECT_EQ(info.operators, kDepth);
    EXPECT_EQ(info.depth, kDepth);
    EXPECT_EQ(info.smooth_operators, kDepth);
    // Post-order of a left-deep chain holds two values at most; a right-deep one holds them all.
    EXPECT_EQ(sc.max_stack, left_deep ? 2u : kDepth + 1);
    EXPECT_EQ(sc.kind[sc.root()], math::kOpUnion);
}

TEST(DeepChain, LeftDeepJsonLoadsAndEvaluates) {
    const std::vector<Sphere> s = chain_spheres();
    const Scene sc = parse_scene(left_deep_json(s), "left_deep.json");
    expect_chain_shape(sc, true);
    expect_chain_values(sc, s, true);
}

TEST(DeepChain, RightDeepJsonLoadsAndEvaluates) {
    const std::vector<Sphere> s = chain_spheres();
    const Scene sc = parse_scene(right_deep_json(s), "right_deep.json");
    expect_chain_shape(sc, false);
    expect_chain_values(sc, s, false);
    // The batch evaluator sizes its value stacks from the scene too.
    const std::vector<vec3> pts = query_points(s);
    std::vector<float> out(pts.size());
    eval_points(sc, pts, out);
    for (size_t i = 0; i < pts.size(); ++i) EXPECT_EQ(out[i], eval_point(sc, pts[i]));
}

TEST(DeepChain, BuilderChainEvaluates) {
    const std::vector<Sphere> s = chain_spheres();
    SceneBuilder b;
    Shape chain = b.sphere(s[0].r).translated(s[0].c);
    for (uint32_t i = 1; i <= kDepth; ++i)
        chain = smooth_union(chain, b.sphere(s[i].r).translated(s[i].c), kBlend);
    const Scene sc = b.build(chain, {vec3(-1.5f), vec3(1.5f)});
    expect_chain_shape(sc, true);
    expect_chain_values(sc, s, true);

    // A right-deep chain from the builder, and the automatic bounding box.
    SceneBuilder rb;
    Shape right = rb.sphere(s[kDepth].r).translated(s[kDepth].c);
    for (uint32_t i = kDepth; i-- > 0;)
        right = smooth_union(rb.sphere(s[i].r).translated(s[i].c), right, kBlend);
    const Scene rsc = rb.build(right);
    expect_chain_shape(rsc, false);
    expect_chain_values(rsc, s, false);
    for (int c = 0; c < 3; ++c) {
        EXPECT_LT(rsc.aabb.min[c], -0.7f);
        EXPECT_GT(rsc.aabb.max[c], 0.7f);
        EXPECT_GT(rsc.aabb.min[c], -1.2f);
        EXPECT_LT(rsc.aabb.max[c], 1.2f);
    }
}

TEST(DeepChain, RoundTripOfBothShapes) {
    const std::vector<Sphere> s = chain_spheres();
    for (bool left_deep : {true, false}) {
        SCOPED_TRACE(left_deep ? "left-deep" : "right-deep");
        const Scene first =
            parse_scene(left_deep ? left_deep_json(s) : right_deep_json(s), "chain.json");
        const std::string json = scene_to_json(first);
        const Scene second = parse_scene(json, "saved.json");
        EXPECT_EQ(first.kind, second.kind);
        EXPECT_EQ(first.left, second.left);
        EXPECT_EQ(first.right, second.right);
        EXPECT_EQ(first.blend, second.blend);
        EXPECT_EQ(first.local, second.local);
        EXPECT_EQ(first.shape, second.shape);
        EXPECT_EQ(first.max_stack, second.max_stack);
        EXPECT_EQ(scene_to_json(second), json);
        for (const vec3& p : query_points(s))
            EXPECT_EQ(eval_point(first, p), eval_point(second, p));
    }
}

}  // namespace
}  // namespace sdfprune
