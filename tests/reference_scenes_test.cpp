// reference_scenes_test.cpp — reference scenes vs an independent evaluator; exact round trip.
#include <gtest/gtest.h>
#include <rapidjson/document.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "sdfprune/eval.hpp"
#include "sdfprune/io.hpp"
#include "test_util.hpp"

namespace sdfprune {
namespace {

// ---- an independent evaluator: DOM parse, recursion, double precision --------------------------

using Json = rapidjson::Value;

struct Mat {  // row-major 3x4, in double
    double m[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
};

Mat read_matrix(const Json& node) {
    const Json& a = node["matrix"];
    Mat r;
    for (int i = 0; i < 12; ++i) r.m[i] = a[i].GetDouble();
    return r;
}

Mat multiply(const Mat& a, const Mat& b) {  // a · b: apply b first
    Mat r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 4; ++j) {
            double s = j == 3 ? a.m[4 * i + 3] : 0;
            for (int k = 0; k < 3; ++k) s += a.m[4 * i + k] * b.m[4 * k + j];
            r.m[4 * i + j] = s;
        }
    return r;
}

struct P3 {
    double x, y, z;
};

P3 apply(const Mat& a, P3 p) {
    return {a.m[0] * p.x + a.m[1] * p.y + a.m[2] * p.z + a.m[3],
            a.m[4] * p.x + a.m[5] * p.y + a.m[6] * p.z + a.m[7],
            a.m[8] * p.x + a.m[9] * p.y + a.m[10] * p.z + a.m[11]};
}

double num(const Json& node, const char* key) {
    return node[key].GetDouble();
}

// Rounded rectangle of half sizes (hx, hz) with one corner radius per quadrant (+x+z, +x-z,
// -x+z, -x-z), extruded to |y| <= hy with the top (+y) rim rounded by rt, the bottom by rb.
double box_sdf(P3 q, const Json& node) {
    const double hx = node["sides"][0].GetDouble() / 2, hy = node["sides"][1].GetDouble() / 2,
                 hz = node["sides"][2].GetDouble() / 2;
    const Json& bevel = node["bevel"];
    const int quadrant = q.x > 0 ? (q.z > 0 ? 0 : 1) : (q.z > 0 ? 2 : 3);
    const double r = bevel[quadrant].GetDouble();
    const double ax = std::fabs(q.x) - hx + r, az = std::fabs(q.z) - hz + r;
    const double d2 =
        std::min(std::max(ax, az), 0.0) + std::hypot(std::max(ax, 0.0), std::max(az, 0.0)) - r;
    const double rim = q.y > 0 ? num(node, "round_x") : num(node, "round_y");
    const double ex = d2 + rim, ey = std::fabs(q.y) - (hy - rim);
    return std::min(std::max(ex, ey), 0.0) + std::hypot(std::max(ex, 0.0), std::max(ey, 0.0)) - rim;
}

double cylinder_sdf(P3 q, const Json& node) {
    const double dx = std::hypot(q.x, q.z) - num(node, "radius");
    const double dy = std::fabs(q.y) - num(node, "height") / 2;
    return std::min(std::max(dx, dy), 0.0) + std::hypot(std::max(dx, 0.0), std::max(dy, 0.0));
}

// Exact distance to the solid cone: base disc of radius r at y = -h, apex at y = +h, computed in
// the (rho, y) half plane as the distance to the triangle (0,-h), (r,-h), (0,h).
double cone_sdf(P3 q, const Json& node) {
    const double r = num(node, "radius"), h = num(node, "height") / 2;
    const double rho = std::hypot(q.x, q.z), y = q.y;
    auto seg = [](double px, double py, double ax, double ay, double bx, double by) {
        const double ex = bx - ax, ey = by - ay;
        const double t =
            std::clamp(((px - ax) * ex + (py - ay) * ey) / (ex * ex + ey * ey), 0.0, 1.0);
        return std::hypot(px - ax - t * ex, py - ay - t * ey);
    };
    const double d = std::min(seg(rho, y, r, -h, 0, h), seg(rho, y, 0, -h, r, -h));
    // Inside iff above the base and below the slant 2h·rho + r·y <= r·h.
    const bool inside = y > -h && 2 * h * rho + r * y < r * h;
    return inside ? -d : d;
}

double primitive_sdf(P3 q, const Json& node) {
    const std::string type = node["primitiveType"].GetString();
    if (type == "sphere") return std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z) - num(node, "radius");
    if (type == "box") return box_sdf(q, node);
    if (type == "cylinder") return cylinder_sdf(q, node);
    if (type == "cone") return cone_sdf(q, node);
    ADD_FAILURE() << "unexpected primitive type " << type;
    return 0;
}

double phi(double x, double k) {
    if (k <= 0) return 0;
    const double m = std::max(k - x, 0.0);
    return m * m / (4 * k);
}

// The product parent · child (root first) maps world points to the node's local frame.
double eval_ref(const Json& node, const Mat& parent, P3 p) {
    const Mat world = multiply(parent, read_matrix(node));
    if (std::string(node["nodeType"].GetString()) == "primitive")
        return primitive_sdf(apply(world, p), node);
    const double a = eval_ref(node["leftChild"], world, p);
    const double b = eval_ref(node["rightChild"], world, p);
    const double k = num(node, "blendRadius");
    const std::string mode = node["blendMode"].GetString();
    if (mode == "union") return std::min(a, b) - phi(std::fabs(a - b), k);
    if (mode == "inter") return std::max(a, b) + phi(std::fabs(a - b), k);
    EXPECT_EQ(mode, "sub");
    return std::max(a, -b) + phi(std::fabs(a + b), k);
}

// Every primitive's local origin, in world coordinates: points inside or near the surface.
void primitive_centres(const Json& node, const Mat& parent, std::vector<P3>& out) {
    const Mat world = multiply(parent, read_matrix(node));
    if (std::string(node["nodeType"].GetString()) != "primitive") {
        primitive_centres(node["leftChild"], world, out);
        primitive_centres(node["rightChild"], world, out);
        return;
    }
    // Solve world · x = 0 by Cramer's rule.
    const double* m = world.m;
    const double det = m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
                       m[2] * (m[4] * m[9] - m[5] * m[8]);
    const double b[3] = {-m[3], -m[7], -m[11]};
    auto det_with = [&](int col) {
        double c[9] = {m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]};
        for (int r = 0; r < 3; ++r) c[3 * r + col] = b[r];
        return c[0] * (c[4] * c[8] - c[5] * c[7]) - c[1] * (c[3] * c[8] - c[5] * c[6]) +
               c[2] * (c[3] * c[7] - c[4] * c[6]);
    };
    out.push_back({det_with(0) / det, det_with(1) / det, det_with(2) / det});
}

struct RefScene {
    rapidjson::Document doc;
    P3 lo, hi;
};

void parse_ref(const std::string& text, RefScene& ref) {
    ref.doc.Parse<rapidjson::kParseFullPrecisionFlag>(text.c_str());
    ASSERT_FALSE(ref.doc.HasParseError());
    const Json& lo = ref.doc["aabb_min"];
    const Json& hi = ref.doc["aabb_max"];
    ref.lo = {lo[0].GetDouble(), lo[1].GetDouble(), lo[2].GetDouble()};
    ref.hi = {hi[0].GetDouble(), hi[1].GetDouble(), hi[2].GetDouble()};
}

// Compares the library to the independent evaluator at 200 pseudo-random points of the AABB and
// at every primitive's centre.
void expect_matches_reference(const Scene& sc, const RefScene& ref) {
    std::vector<P3> points;
    std::mt19937 gen(12345);
    auto unit = [&] { return double(gen() >> 8) * (1.0 / 16777216.0); };
    for (int i = 0; i < 200; ++i)
        points.push_back({ref.lo.x + (ref.hi.x - ref.lo.x) * unit(),
                          ref.lo.y + (ref.hi.y - ref.lo.y) * unit(),
                          ref.lo.z + (ref.hi.z - ref.lo.z) * unit()});
    std::vector<P3> centres;
    primitive_centres(ref.doc, Mat(), centres);
    EXPECT_EQ(centres.size(), sc.primitive_count());
    points.insert(points.end(), centres.begin(), centres.end());

    int negative = 0, positive = 0;
    double worst = 0;
    for (const P3& q : points) {
        const vec3 p(float(q.x), float(q.y), float(q.z));
        const double want = eval_ref(ref.doc, Mat(), {p.x, p.y, p.z});
        const float got = eval_point(sc, p);
        worst = std::max(worst, std::fabs(got - want) / (1 + std::fabs(want)));
        EXPECT_NEAR(got, want, 1e-5 * (1 + std::fabs(want)))
            << "at (" << p.x << ", " << p.y << ", " << p.z << ")";
        negative += want < 0;
        positive += want > 0;
    }
    // Both sides of the surface were sampled.
    EXPECT_GT(negative, 0);
    EXPECT_GT(positive, 0);
    ::testing::Test::RecordProperty("worst_relative_error", ::testing::PrintToString(worst));
}

// ---- tests -------------------------------------------------------------------------------------

TEST(ReferenceScenes, MoleculeShape) {
    SDFPRUNE_REQUIRE_SCENE(path, "molecule.json");
    const Scene sc = load_scene(path);
    const SceneInfo info = scene_info(sc);
    EXPECT_EQ(info.nodes, 2001u);
    EXPECT_EQ(info.primitives, 1001u);
    EXPECT_EQ(info.operators, 1000u);
    EXPECT_EQ(info.depth, 1000u);
    EXPECT_EQ(info.per_primitive_kind[math::kPrimSphere], 1001u);
    EXPECT_EQ(info.unions, 1000u);
    EXPECT_EQ(info.smooth_operators, 1000u);
    EXPECT_FLOAT_EQ(info.max_lipschitz, 1.0f);
    EXPECT_EQ(sc.aabb.min.z, -1.1f);
    EXPECT_EQ(sc.aabb.max.x, 1.0f);
    // A left-deep chain: the post-order evaluation never holds more than two values.
    EXPECT_EQ(sc.max_stack, 2u);
}

TEST(ReferenceScenes, TreesShape) {
    SDFPRUNE_REQUIRE_SCENE(path, "trees.json");
    const Scene sc = load_scene(path);
    const SceneInfo info = scene_info(sc);
    EXPECT_EQ(info.nodes, 371u);
    EXPECT_EQ(info.primitives, 186u);
    EXPECT_EQ(info.operators, 185u);
    EXPECT_EQ(info.per_primitive_kind[math::kPrimBox], 186u);
    EXPECT_EQ(info.unions, 185u);
    EXPECT_NEAR(info.max_lipschitz, 1.0f, 1e-5f);
}

TEST(ReferenceScenes, TestSceneShape) {
    SDFPRUNE_REQUIRE_SCENE(path, "test.json");
    const Scene sc = load_scene(path);
    const SceneInfo info = scene_info(sc);
    EXPECT_EQ(info.nodes, 3u);
    EXPECT_EQ(info.primitives, 2u);
    EXPECT_EQ(info.depth, 1u);
    EXPECT_EQ(info.differences, 1u);
    EXPECT_EQ(info.per_primitive_kind[math::kPrimSphere], 1u);
    EXPECT_EQ(info.per_primitive_kind[math::kPrimCylinder], 1u);
    EXPECT_FLOAT_EQ(sc.blend[2], 0.1f);
    EXPECT_EQ(sc.negated, (std::vector<uint8_t>{0, 1, 0}));
    // At the origin the unit sphere gives -1; the cylinder (radius 0.5, height 2, local point
    // x + 1, the root's rotation about x leaves x alone) gives +0.5:
    // max(-1, -0.5) + phi(|-1 + 0.5|, 0.1) = -0.5.
    EXPECT_NEAR(eval_point(sc, {0, 0, 0}), -0.5f, 1e-6f);
}

class ReferenceScene : public ::testing::TestWithParam<const char*> {};

TEST_P(ReferenceScene, MatchesIndependentEvaluator) {
    SDFPRUNE_REQUIRE_SCENE(path, GetParam());
    RefScene ref;
    ASSERT_NO_FATAL_FAILURE(parse_ref(read_file(path), ref));
    expect_matches_reference(load_scene(path), ref);
}

// The reference scenes have only unions (and one difference) and identity operator matrices; this
// scene has every operator, all four primitives of the format, rotated, scaled and sheared
// operator and primitive matrices, bevels and rim roundings.
TEST(ReferenceEvaluator, SyntheticSceneWithEveryOperator) {
    const std::string json = R"({
      "aabb_min": [-2, -2, -2], "aabb_max": [2, 2, 2],
      "nodeType": "binaryOperator", "blendMode": "inter", "blendRadius": 0.15,
      "matrix": [0.8, 0, 0.6, 0.1, 0, 1, 0, -0.05, -0.6, 0, 0.8, 0.2],
      "leftChild": {
        "nodeType": "binaryOperator", "blendMode": "sub", "blendRadius": 0.1,
        "matrix": [1.25, 0, 0, 0, 0, 1.25, 0, 0, 0, 0, 1.25, 0],
        "leftChild": {
          "nodeType": "primitive", "primitiveType": "box",
          "sides": [1.2, 0.8, 1.0], "bevel": [0.1, 0.2, 0.15, 0.05],
          "round_x": 0.1, "round_y": 0.05, "color": [0.5, 0.5, 0.5],
          "matrix": [1, 0, 0, 0, 0, 0.6, -0.8, 0, 0, 0.8, 0.6, 0]
        },
        "rightChild": {
          "nodeType": "primitive", "primitiveType": "cylinder", "height": 2, "radius": 0.3,
          "round_x": 0, "round_y": 0, "color": [1, 0, 0],
          "matrix": [1, 0, 0, 0.2, 0, 1, 0, 0, 0, 0, 1, -0.1]
        }
      },
      "rightChild": {
        "nodeType": "binaryOperator", "blendMode": "union", "blendRadius": 0.2,
        "matrix": [1, 0.3, 0, 0, 0, 1, 0, 0.1, 0, 0, 1, 0],
        "leftChild": {
          "nodeType": "primitive", "primitiveType": "cone", "height": 1.5, "radius": 0.6,
          "round_x": 0, "round_y": 0, "color": [0, 1, 0],
          "matrix": [1, 0, 0, 0.3, 0, 1, 0, -0.2, 0, 0, 1, 0]
        },
        "rightChild": {
          "nodeType": "primitive", "primitiveType": "sphere", "radius": 0.9,
          "round_x": 0, "round_y": 0, "color": [0, 0, 1],
          "matrix": [0.8, 0, 0, 0.1, 0, 1.1, 0, 0, 0, 0, 1, -0.2]
        }
      }
    })";
    RefScene ref;
    ASSERT_NO_FATAL_FAILURE(parse_ref(json, ref));
    const Scene sc = parse_scene(json, "synthetic");
    EXPECT_EQ(sc.size(), 7u);
    EXPECT_EQ(sc.negated, (std::vector<uint8_t>{0, 1, 0, 0, 0, 0, 0}));
    expect_matches_reference(sc, ref);
}

void expect_same_scene(const Scene& a, const Scene& b) {
    EXPECT_EQ(a.kind, b.kind);
    EXPECT_EQ(a.left, b.left);
    EXPECT_EQ(a.right, b.right);
    EXPECT_EQ(a.parent, b.parent);
    EXPECT_EQ(a.negated, b.negated);
    EXPECT_EQ(a.blend, b.blend);
    EXPECT_EQ(a.lipschitz, b.lipschitz);
    EXPECT_EQ(a.primitive, b.primitive);
    EXPECT_EQ(a.local, b.local);
    EXPECT_EQ(a.primitive_node, b.primitive_node);
    EXPECT_EQ(a.shape, b.shape);
    EXPECT_EQ(a.full_tape, b.full_tape);
    EXPECT_EQ(a.max_stack, b.max_stack);
    ASSERT_EQ(a.color.size(), b.color.size());
    for (size_t i = 0; i < a.color.size(); ++i)
        for (int c = 0; c < 3; ++c) EXPECT_EQ(a.color[i][c], b.color[i][c]) << "primitive " << i;
    for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(a.aabb.min[c], b.aabb.min[c]);
        EXPECT_EQ(a.aabb.max[c], b.aabb.max[c]);
    }
    ASSERT_EQ(a.params.size(), b.params.size());
    for (size_t i = 0; i < a.params.size(); ++i) {
        const math::PrimitiveParams &x = a.params[i], &y = b.params[i];
        const vec4 xs[6] = {x.row0, x.row1, x.row2, x.a, x.b, x.c};
        const vec4 ys[6] = {y.row0, y.row1, y.row2, y.a, y.b, y.c};
        for (int v = 0; v < 6; ++v)
            for (int c = 0; c < 4; ++c)
                ASSERT_EQ(xs[v][c], ys[v][c]) << "primitive " << i << " vector " << v;
    }
}

TEST_P(ReferenceScene, RoundTripIsExact) {
    SDFPRUNE_REQUIRE_SCENE(path, GetParam());
    const Scene first = load_scene(path);
    const std::string json = scene_to_json(first);
    const Scene second = parse_scene(json, "saved");
    expect_same_scene(first, second);
    // Saving again gives the same bytes.
    EXPECT_EQ(scene_to_json(second), json);
    std::mt19937 gen(7);
    auto coord = [&](float lo, float hi) {
        return lo + (hi - lo) * float(gen() >> 8) / 16777216.0f;
    };
    for (int i = 0; i < 200; ++i) {
        const vec3 p(coord(first.aabb.min.x, first.aabb.max.x),
                     coord(first.aabb.min.y, first.aabb.max.y),
                     coord(first.aabb.min.z, first.aabb.max.z));
        EXPECT_EQ(eval_point(first, p), eval_point(second, p));
    }
}

TEST_P(ReferenceScene, BatchEvaluationMatchesPointEvaluation) {
    SDFPRUNE_REQUIRE_SCENE(path, GetParam());
    const Scene sc = load_scene(path);
    std::vector<vec3> points;
    std::mt19937 gen(99);
    auto coord = [&](float lo, float hi) {
        return lo + (hi - lo) * float(gen() >> 8) / 16777216.0f;
    };
    for (int i = 0; i < 1000; ++i)
        points.emplace_back(coord(sc.aabb.min.x, sc.aabb.max.x),
                            coord(sc.aabb.min.y, sc.aabb.max.y),
                            coord(sc.aabb.min.z, sc.aabb.max.z));
    std::vector<float> out(points.size());
    eval_points(sc, points, out, {.threads = 2});
    for (size_t i = 0; i < points.size(); ++i) ASSERT_EQ(out[i], eval_point(sc, points[i])) << i;
}

INSTANTIATE_TEST_SUITE_P(All, ReferenceScene,
                         ::testing::Values("molecule.json", "trees.json", "test.json"),
                         [](const ::testing::TestParamInfo<const char*>& info) {
                             std::string name = info.param;
                             return name.substr(0, name.find('.'));
                         });

}  // namespace
}  // namespace sdfprune
