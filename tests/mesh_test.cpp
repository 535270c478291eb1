// mesh_test.cpp — isosurface extraction: closed 2-manifold meshes with outward orientation,
// analytic volumes, pruned == naive bit for bit, determinism across thread counts, capping at
// the AABB, the writers (read back by small readers here) and the `mesh` subcommand.
#include <gtest/gtest.h>
#include <rapidjson/document.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <numbers>
#include <set>
#include <sstream>

#include "prune_check.hpp"
#include "sdfprune/builder.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/mesh.hpp"
#include "test_util.hpp"

namespace sdfprune {
namespace {

// ---- mesh checks -----------------------------------------------------------------------------

// Every directed edge appears once and its reverse once (closed, 2-manifold, consistently
// oriented); no degenerate, repeated-index or duplicate triangles; every vertex used.
// Returns the Euler characteristic.
int64_t check_closed_manifold(const Mesh& m) {
    EXPECT_EQ(m.triangles.size() % 3, 0u);
    std::map<std::pair<uint32_t, uint32_t>, int> directed;
    std::set<std::array<uint32_t, 3>> seen;
    std::vector<uint8_t> used(m.vertices.size(), 0);
    size_t bad_index = 0, repeated = 0, duplicates = 0, zero_area = 0;
    for (size_t t = 0; t < m.triangle_count(); ++t) {
        const uint32_t* v = &m.triangles[3 * t];
        if (v[0] >= m.vertices.size() || v[1] >= m.vertices.size() || v[2] >= m.vertices.size()) {
            ++bad_index;
            continue;
        }
        if (v[0] == v[1] || v[1] == v[2] || v[0] == v[2]) ++repeated;
        std::array<uint32_t, 3> key{v[0], v[1], v[2]};
        std::sort(key.begin(), key.end());
        if (!seen.insert(key).second) ++duplicates;
        const vec3 a = m.vertices[v[0]], b = m.vertices[v[1]], c = m.vertices[v[2]];
        const double ux = double(b.x) - a.x, uy = double(b.y) - a.y, uz = double(b.z) - a.z;
        const double wx = double(c.x) - a.x, wy = double(c.y) - a.y, wz = double(c.z) - a.z;
        const double nx = uy * wz - uz * wy, ny = uz * wx - ux * wz, nz = ux * wy - uy * wx;
        if (nx == 0 && ny == 0 && nz == 0) ++zero_area;
        for (int k = 0; k < 3; ++k) {
            ++directed[{v[k], v[(k + 1) % 3]}];
            used[v[k]] = 1;
        }
    }
    EXPECT_EQ(bad_index, 0u);
    EXPECT_EQ(repeated, 0u);
    EXPECT_EQ(duplicates, 0u);
    EXPECT_EQ(zero_area, 0u);
    size_t twice = 0, unmatched = 0;
    for (const auto& [e, count] : directed) {
        if (count != 1) ++twice;
        const auto r = directed.find({e.second, e.first});
        if (r == directed.end() || r->second != 1) ++unmatched;
    }
    EXPECT_EQ(twice, 0u) << "directed edges used more than once (orientation or manifoldness)";
    EXPECT_EQ(unmatched, 0u) << "edges without their reverse (cracks)";
    EXPECT_EQ(size_t(std::count(used.begin(), used.end(), 0)), 0u) << "unused vertices";
    const int64_t v = int64_t(m.vertices.size()), e = int64_t(directed.size() / 2),
                  f = int64_t(m.triangle_count());
    return v - e + f;
}

double signed_volume(const Mesh& m) {
    double vol = 0;
    for (size_t t = 0; t < m.triangle_count(); ++t) {
        const vec3 a = m.vertices[m.triangles[3 * t]], b = m.vertices[m.triangles[3 * t + 1]],
                   c = m.vertices[m.triangles[3 * t + 2]];
        vol += (double(a.x) * (double(b.y) * c.z - double(b.z) * c.y) -
                double(a.y) * (double(b.x) * c.z - double(b.z) * c.x) +
                double(a.z) * (double(b.x) * c.y - double(b.y) * c.x)) /
               6.0;
    }
    return vol;
}

void expect_identical(const Mesh& a, const Mesh& b) {
    ASSERT_EQ(a.vertices.size(), b.vertices.size());
    ASSERT_EQ(a.triangles.size(), b.triangles.size());
    EXPECT_TRUE(a.triangles == b.triangles);
    size_t differ = 0;
    for (size_t i = 0; i < a.vertices.size(); ++i)
        if (std::memcmp(&a.vertices[i], &b.vertices[i], sizeof(vec3)) != 0) ++differ;
    EXPECT_EQ(differ, 0u) << "vertex positions differ bit-wise";
}

Mesh pruned_mesh(const Scene& sc, uint32_t res, PruneOptions po = {}, int threads = 0,
                 MeshStats* stats = nullptr) {
    if (po.resolution == PruneOptions{}.resolution) po.resolution = res;
    po.threads = threads;
    const PrunedGrid g = prune(sc, po);
    MeshOptions mo;
    mo.resolution = res;
    mo.threads = threads;
    return mesh(g, mo, stats);
}

Mesh naive_mesh(const Scene& sc, uint32_t res, int threads = 0) {
    MeshOptions mo;
    mo.resolution = res;
    mo.threads = threads;
    return mesh(sc, mo);
}

// ---- extraction ------------------------------------------------------------------------------

TEST(MeshSphere, ClosedManifoldWithAnalyticVolume) {
    const Scene sc = builtin_scene("sphere");
    MeshStats stats;
    const Mesh m = pruned_mesh(sc, 64, {}, 0, &stats);
    ASSERT_GT(m.triangle_count(), 1000u);
    EXPECT_EQ(check_closed_manifold(m), 2);
    const double vol = signed_volume(m), exact = 4.0 / 3.0 * std::numbers::pi;
    EXPECT_GT(vol, 0) << "outward orientation gives a positive signed volume";
    EXPECT_NEAR(vol, exact, 0.01 * exact);
    // Vertices lie on the sphere within a fraction of a cell (4/64).
    double worst = 0;
    for (const vec3& p : m.vertices)
        worst = std::max(worst, std::fabs(double(math::length(p)) - 1));
    EXPECT_LT(worst, 0.01);
    // Only the near-field band was evaluated.
    EXPECT_LT(stats.corners_evaluated, uint64_t(65 * 65 * 65) / 4);
    EXPECT_EQ(stats.resolution, 64u);
}

TEST(MeshSphere, PrunedEqualsNaive) {
    const Scene sc = builtin_scene("sphere");
    const Mesh naive = naive_mesh(sc, 64);
    expect_identical(pruned_mesh(sc, 64), naive);
    PruneOptions no_far;
    no_far.far_field = false;
    expect_identical(pruned_mesh(sc, 64, no_far), naive);
    PruneOptions no_hier;
    no_hier.hierarchy = false;
    expect_identical(pruned_mesh(sc, 64, no_hier), naive);
    PruneOptions lipschitz;
    lipschitz.bounds = CellBounds::kLipschitz;
    expect_identical(pruned_mesh(sc, 64, lipschitz), naive);
}

TEST(MeshSphere, PrunedGridOfAnotherResolution) {
    // Cubes and cells need not coincide: coarser, finer and non-dividing grids.
    const Scene sc = builtin_scene("sphere");
    const Mesh naive = naive_mesh(sc, 48);
    for (uint32_t grid : {16u, 32u, 100u, 192u}) {
        SCOPED_TRACE("grid " + std::to_string(grid));
        PruneOptions po;
        po.resolution = grid;
        expect_identical(pruned_mesh(sc, 48, po), naive);
    }
}

TEST(MeshSphere, SameMeshForAnyThreadCount) {
    const Scene sc = builtin_scene("sphere");
    expect_identical(pruned_mesh(sc, 64, {}, 1), pruned_mesh(sc, 64, {}, 0));
    expect_identical(pruned_mesh(sc, 64, {}, 3), pruned_mesh(sc, 64, {}, 0));
    expect_identical(naive_mesh(sc, 40, 1), naive_mesh(sc, 40, 0));
}

TEST(MeshShapes, BoxIsClosedWithItsVolume) {
    SceneBuilder b;
    const Scene sc =
        b.build(b.box({1.2f, 0.8f, 1.0f}).rotated({1, 2, 3}, 0.4f), {vec3(-1.5f), vec3(1.5f)});
    const Mesh m = pruned_mesh(sc, 64);
    EXPECT_EQ(check_closed_manifold(m), 2);
    EXPECT_NEAR(signed_volume(m), 1.2 * 0.8 * 1.0, 0.02 * 0.96);
    expect_identical(m, naive_mesh(sc, 64));
}

TEST(MeshShapes, TorusHasGenusOne) {
    SceneBuilder b;
    const Scene sc =
        b.build(b.torus(1.0f, 0.35f).rotated({1, 0, 0}, 0.3f), {vec3(-1.6f), vec3(1.6f)});
    const Mesh m = pruned_mesh(sc, 64);
    EXPECT_EQ(check_closed_manifold(m), 0);
    const double exact = 2 * std::numbers::pi * std::numbers::pi * 1.0 * 0.35 * 0.35;
    EXPECT_NEAR(signed_volume(m), exact, 0.02 * exact);
}

TEST(MeshShapes, DemoSceneIsClosedAndMatchesNaive) {
    const Scene sc = builtin_scene("demo");
    MeshStats stats;
    const Mesh m = pruned_mesh(sc, 64, {}, 0, &stats);
    ASSERT_GT(m.triangle_count(), 1000u);
    check_closed_manifold(m);
    EXPECT_GT(signed_volume(m), 0);
    EXPECT_LT(stats.corners_evaluated, uint64_t(65 * 65 * 65));
    expect_identical(m, naive_mesh(sc, 64));
}

TEST(MeshShapes, ShapesCutByTheAabbAreCapped) {
    SceneBuilder b;
    // A hemisphere: the AABB cuts the unit sphere at z = 0.
    const Scene half = b.build(b.sphere(1.0f), {vec3(-1.5f, -1.5f, 0.0f), vec3(1.5f)});
    const Mesh m = pruned_mesh(half, 60);
    EXPECT_EQ(check_closed_manifold(m), 2);
    const double exact = 2.0 / 3.0 * std::numbers::pi;
    EXPECT_NEAR(signed_volume(m), exact, 0.02 * exact);
    expect_identical(m, naive_mesh(half, 60));
    // The AABB inside the shape: the mesh is the AABB with its edges chamfered by a cube.
    SceneBuilder b2;
    const Scene full = b2.build(b2.sphere(3.0f), {vec3(-1.0f), vec3(1.0f)});
    const Mesh box = pruned_mesh(full, 16);
    EXPECT_EQ(check_closed_manifold(box), 2);
    EXPECT_GT(signed_volume(box), 7.5);
    EXPECT_LT(signed_volume(box), 8.0);
}

TEST(MeshShapes, CapsWithAnyPrunedGrid) {
    // Caps come from far-field cells of any level; cells and cubes need not coincide.
    SceneBuilder b;
    const Scene half = b.build(b.sphere(1.0f).translated({0.1f, 0, 0}),
                               {vec3(-1.5f, -1.5f, 0.0f), vec3(1.5f, 0.7f, 1.5f)});
    const Mesh naive = naive_mesh(half, 60);
    EXPECT_EQ(check_closed_manifold(naive), 2);
    for (uint32_t grid : {15u, 32u, 60u, 128u, 240u}) {
        SCOPED_TRACE("grid " + std::to_string(grid));
        PruneOptions po;
        po.resolution = grid;
        expect_identical(pruned_mesh(half, 60, po), naive);
    }
}

TEST(MeshShapes, GridsWhoseCellsTileTheCubes) {
    // Cells of 2³, 3³, 4³ and 8³ cubes (their corners taken cell by cell, in vector lanes), a
    // grid of the cubes, and one that does not tile them: always the naive mesh, caps included.
    const Scene demo = builtin_scene("demo");
    const Mesh naive = naive_mesh(demo, 48);
    SceneBuilder b;
    const Scene half = b.build(b.sphere(1.0f).translated({0.1f, 0, 0}),
                               {vec3(-1.5f, -1.5f, 0.0f), vec3(1.5f, 0.7f, 1.5f)});
    const Mesh naive_half = naive_mesh(half, 48);
    for (uint32_t grid : {48u, 24u, 16u, 12u, 6u, 20u}) {
        SCOPED_TRACE("grid " + std::to_string(grid));
        PruneOptions po;
        po.resolution = grid;
        po.refine = 1 + grid % 3;
        expect_identical(pruned_mesh(demo, 48, po), naive);
        expect_identical(pruned_mesh(half, 48, po), naive_half);
    }
    EXPECT_EQ(default_mesh_grid(48), 6u);
    EXPECT_EQ(default_mesh_grid(20), 5u);
    EXPECT_EQ(default_mesh_grid(6), 3u);
    EXPECT_EQ(default_mesh_grid(49), 49u);
}

TEST(MeshShapes, RandomScenesUnderEveryPlacementMatchNaive) {
    // Cube culling inside near-field cells leans on the root's Lipschitz bound: scenes with
    // similarity maps (scales 0.3-3), non-uniform scales and shears, smooth operators and plane
    // cuts, meshed at the default pruning grid and at one of 2³ cubes per cell.
    for (uint32_t i = 0; i < 10; ++i) {
        SCOPED_TRACE("random scene " + std::to_string(i));
        test::RandomSceneSpec spec = test::varied_spec(i, 4 + 3 * i);
        spec.union_share = 0.8f;
        spec.clip_aabb = i % 4 == 2;
        const Scene sc = test::random_scene(9300 + i, spec);
        const uint32_t res = 40;
        const Mesh naive = naive_mesh(sc, res);
        ASSERT_GT(naive.triangle_count(), 100u);
        check_closed_manifold(naive);
        PruneOptions po;
        po.resolution = default_mesh_grid(res);
        po.refine = 1;
        expect_identical(pruned_mesh(sc, res, po), naive);
        po.resolution = res / 2;
        expect_identical(pruned_mesh(sc, res, po), naive);
    }
}

TEST(MeshShapes, ZeroAtGridCornersCountsAsOutside) {
    // The box's faces lie on grid planes: f == 0 exactly at many corners.
    SceneBuilder b;
    const Scene sc = b.build(b.box({1.0f, 1.0f, 1.0f}), {vec3(-1.0f), vec3(1.0f)});
    const Mesh m = pruned_mesh(sc, 16);
    EXPECT_EQ(check_closed_manifold(m), 2);
    // The surface sits just inside the box (zero counts as outside): within one cube.
    EXPECT_GT(signed_volume(m), std::pow(0.75, 3));
    EXPECT_LT(signed_volume(m), 1.0);
    expect_identical(m, naive_mesh(sc, 16));
}

TEST(MeshShapes, ReferenceMoleculeMatchesNaive) {
    SDFPRUNE_REQUIRE_SCENE(path, "molecule.json");
    const Scene sc = load_scene(path);
    MeshStats stats;
    const Mesh m = pruned_mesh(sc, 40, {}, 0, &stats);
    ASSERT_GT(m.triangle_count(), 1000u);
    check_closed_manifold(m);
    EXPECT_GT(signed_volume(m), 0);
    EXPECT_LT(stats.corners_evaluated, uint64_t(41 * 41 * 41) / 2);
    expect_identical(m, naive_mesh(sc, 40));
}

TEST(MeshShapes, TinyAndInvalidResolutions) {
    const Scene sc = builtin_scene("sphere");
    // One cube: all corners lie on the AABB, hence outside: nothing.
    EXPECT_EQ(naive_mesh(sc, 1).triangle_count(), 0u);
    EXPECT_EQ(pruned_mesh(sc, 1).triangle_count(), 0u);
    // Two cubes per axis: the centre corner alone is inside: an octahedron.
    const Mesh m = naive_mesh(sc, 2);
    EXPECT_EQ(check_closed_manifold(m), 2);
    expect_identical(pruned_mesh(sc, 2), m);
    MeshOptions bad;
    bad.resolution = 0;
    EXPECT_THROW(mesh(sc, bad), std::invalid_argument);
    bad.resolution = kMaxMeshResolution + 1;
    EXPECT_THROW(mesh(sc, bad), std::invalid_argument);
}

TEST(MeshShapes, Cancel) {
    const Scene sc = builtin_scene("sphere");
    std::atomic<bool> cancel{true};
    MeshOptions mo;
    mo.resolution = 32;
    mo.cancel = &cancel;
    EXPECT_THROW(mesh(sc, mo), MeshCancelled);
}

// ---- writers ---------------------------------------------------------------------------------

std::string temp_path(const std::string& name) {
    return ::testing::TempDir() + "sdfprune_mesh_" + std::to_string(::getpid()) + "_" + name;
}

uint32_t get_u32(const std::string& s, size_t at) {
    uint32_t v = 0;
    for (int k = 3; k >= 0; --k) v = v << 8 | uint8_t(s[at + k]);
    return v;
}
float get_f32(const std::string& s, size_t at) {
    return std::bit_cast<float>(get_u32(s, at));
}

TEST(MeshWriters, RoundTrip) {
    const Mesh m = pruned_mesh(builtin_scene("sphere"), 16);
    ASSERT_GT(m.triangle_count(), 0u);

    {  // STL: triangles with their corners (unshared)
        const std::string path = temp_path("x.stl");
        write_mesh(m, path);
        const std::string s = read_file(path);
        ASSERT_EQ(s.size(), 84 + 50 * m.triangle_count());
        EXPECT_NE(s.compare(0, 5, "solid"), 0);
        ASSERT_EQ(get_u32(s, 80), m.triangle_count());
        size_t bad = 0;
        for (size_t t = 0; t < m.triangle_count(); ++t) {
            const size_t at = 84 + 50 * t;
            const vec3 n(get_f32(s, at), get_f32(s, at + 4), get_f32(s, at + 8));
            if (std::fabs(math::length(n) - 1) > 1e-5f) ++bad;
            for (int k = 0; k < 3; ++k) {
                const vec3 p = m.vertices[m.triangles[3 * t + k]];
                const size_t v = at + 12 + 12 * k;
                if (get_f32(s, v) != p.x || get_f32(s, v + 4) != p.y || get_f32(s, v + 8) != p.z)
                    ++bad;
            }
            // The normal agrees with the winding (outward on a sphere: along the position).
            if (math::dot(n, m.vertices[m.triangles[3 * t]]) <= 0) ++bad;
        }
        EXPECT_EQ(bad, 0u);
        std::filesystem::remove(path);
    }
    {  // PLY: header, then shared vertices and faces
        const std::string path = temp_path("x.ply");
        write_mesh(m, path);
        const std::string s = read_file(path);
        const size_t end = s.find("end_header\n");
        ASSERT_NE(end, std::string::npos);
        std::istringstream header(s.substr(0, end));
        std::string line;
        size_t nv = 0, nf = 0;
        bool binary_le = false;
        while (std::getline(header, line)) {
            if (line == "format binary_little_endian 1.0") binary_le = true;
            std::sscanf(line.c_str(), "element vertex %zu", &nv);
            std::sscanf(line.c_str(), "element face %zu", &nf);
        }
        EXPECT_TRUE(binary_le);
        ASSERT_EQ(nv, m.vertices.size());
        ASSERT_EQ(nf, m.triangle_count());
        size_t at = end + 11;
        ASSERT_EQ(s.size(), at + 12 * nv + 13 * nf);
        Mesh r;
        for (size_t i = 0; i < nv; ++i, at += 12)
            r.vertices.push_back(vec3(get_f32(s, at), get_f32(s, at + 4), get_f32(s, at + 8)));
        for (size_t i = 0; i < nf; ++i, at += 13) {
            ASSERT_EQ(uint8_t(s[at]), 3);
            for (int k = 0; k < 3; ++k) r.triangles.push_back(get_u32(s, at + 1 + 4 * k));
        }
        expect_identical(r, m);
        std::filesystem::remove(path);
    }
    {                                                 // OBJ: text, 1-based
        const std::string path = temp_path("x.OBJ");  // extensions in any case
        write_mesh(m, path);
        std::istringstream in(read_file(path));
        std::string line;
        Mesh r;
        while (std::getline(in, line)) {
            if (line.rfind("v ", 0) == 0) {
                vec3 p;
                ASSERT_EQ(std::sscanf(line.c_str(), "v %f %f %f", &p.x, &p.y, &p.z), 3);
                r.vertices.push_back(p);
            } else if (line.rfind("f ", 0) == 0) {
                uint32_t a, b, c;
                ASSERT_EQ(std::sscanf(line.c_str(), "f %u %u %u", &a, &b, &c), 3);
                ASSERT_GE(std::min({a, b, c}), 1u);
                r.triangles.insert(r.triangles.end(), {a - 1, b - 1, c - 1});
            }
        }
        expect_identical(r, m);
        std::filesystem::remove(path);
    }
    EXPECT_THROW(write_mesh(m, temp_path("x.xyz")), IoError);
    EXPECT_FALSE(std::filesystem::exists(temp_path("x.xyz")));
    EXPECT_THROW(write_mesh(m, "/nonexistent/x.stl"), IoError);
}

TEST(MeshWriters, EmptyMesh) {
    const Mesh empty;
    EXPECT_EQ(encode_mesh(empty, MeshFormat::kStl).size(), 84u);
    EXPECT_NE(encode_mesh(empty, MeshFormat::kPly).find("element face 0\n"), std::string::npos);
    EXPECT_EQ(encode_mesh(empty, MeshFormat::kObj).find("\nv "), std::string::npos);
}

// ---- the subcommand --------------------------------------------------------------------------

rapidjson::Document last_json_line(const std::string& out) {
    std::string s = out;
    while (!s.empty() && s.back() == '\n') s.pop_back();
    const size_t nl = s.rfind('\n');
    rapidjson::Document d;
    d.Parse(s.substr(nl == std::string::npos ? 0 : nl + 1).c_str());
    return d;
}

// Runs `sdfprune mesh ARGS --json` and reads its summary into d: the command must exit 0 and end
// with a JSON object (call through ASSERT_NO_FATAL_FAILURE).
void mesh_json(const std::string& args, rapidjson::Document& d) {
    const test::CliResult r = test::run_cli("mesh " + args + " --json");
    ASSERT_EQ(r.status, 0) << r.err;
    d = last_json_line(r.out);
    ASSERT_TRUE(d.IsObject()) << r.out;
}

TEST(MeshCli, WritesPlyAndReportsJson) {
    const std::string path = temp_path("cli.ply");
    std::filesystem::remove(path);
    rapidjson::Document d;
    ASSERT_NO_FATAL_FAILURE(mesh_json("builtin:sphere -o " + path + " --res 32", d));
    for (const char* key : {"triangles", "vertices", "ms", "prune_ms", "method", "res", "path"})
        EXPECT_TRUE(d.HasMember(key)) << key;
    EXPECT_EQ(std::string(d["method"].GetString()), "pruned");
    EXPECT_EQ(d["res"].GetDouble(), 32);
    EXPECT_EQ(d["grid"].GetDouble(), default_mesh_grid(32)) << "the pruned grid follows --res";
    EXPECT_EQ(d["grid"].GetDouble(), 4);
    EXPECT_EQ(d["refine"].GetDouble(), 1) << "no refinement for a one-shot query";
    ASSERT_TRUE(std::filesystem::exists(path));
    const std::string s = read_file(path);
    EXPECT_NE(s.find("element face " + std::to_string(int64_t(d["triangles"].GetDouble())) + "\n"),
              std::string::npos);

    // The naive method gives the same mesh; an explicit --grid is kept.
    rapidjson::Document dn;
    ASSERT_NO_FATAL_FAILURE(
        mesh_json("builtin:sphere -o " + path + " --res 32 --method naive", dn));
    EXPECT_EQ(dn["triangles"].GetDouble(), d["triangles"].GetDouble());
    EXPECT_EQ(dn["vertices"].GetDouble(), d["vertices"].GetDouble());
    EXPECT_EQ(read_file(path), s);
    rapidjson::Document dg;
    ASSERT_NO_FATAL_FAILURE(mesh_json("builtin:sphere -o " + path + " --res 32 --grid 16", dg));
    EXPECT_EQ(dg["grid"].GetDouble(), 16);
    EXPECT_EQ(dg["triangles"].GetDouble(), d["triangles"].GetDouble());
    rapidjson::Document d32;
    ASSERT_NO_FATAL_FAILURE(mesh_json("builtin:sphere -o " + path + " --res 32 --grid 32", d32));
    EXPECT_EQ(d32["grid"].GetDouble(), 32);
    EXPECT_EQ(read_file(path), s) << "the same mesh from any pruning grid";
    // An odd resolution prunes at itself.
    rapidjson::Document dodd;
    ASSERT_NO_FATAL_FAILURE(mesh_json("builtin:sphere -o " + path + " --res 33", dodd));
    EXPECT_EQ(dodd["grid"].GetDouble(), 33);
    std::filesystem::remove(path);
}

TEST(MeshCli, HumanOutputAndFormats) {
    for (const char* ext : {".stl", ".obj"}) {
        const std::string path = temp_path(std::string("human") + ext);
        const test::CliResult r = test::run_cli("mesh builtin:sphere -o " + path + " --res 16");
        ASSERT_EQ(r.status, 0) << r.err;
        EXPECT_NE(r.out.find("wrote " + path), std::string::npos) << r.out;
        EXPECT_TRUE(std::filesystem::exists(path));
        std::filesystem::remove(path);
    }
}

TEST(MeshCli, RefusesBadOutputsBeforeWork) {
    const std::string xyz = temp_path("bad.xyz");
    const test::CliResult r = test::run_cli("mesh builtin:sphere -o " + xyz + " --res 16");
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("extension"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(xyz));
    const test::CliResult u = test::run_cli("mesh builtin:sphere -o /nonexistent/x.stl --res 16");
    EXPECT_EQ(u.status, 2);
    EXPECT_NE(u.err.find("/nonexistent"), std::string::npos) << u.err;
    const test::CliResult res = test::run_cli("mesh builtin:sphere -o " + xyz + " --res 0");
    EXPECT_EQ(res.status, 2);
}

}  // namespace
}  // namespace sdfprune
