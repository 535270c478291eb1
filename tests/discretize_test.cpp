// discretize_test.cpp — discretization (pruned walk vs naive vs PrunedGrid::eval), the .npy
// reader/writer, the OpenVDB level set, and the `discretize` / `eval` subcommands.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "sdfprune/builder.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/discretize.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/npy.hpp"
#include "sdfprune/prune.hpp"
#include "sdfprune/vdb.hpp"
#include "test_util.hpp"

namespace sdfprune {
namespace {

namespace fs = std::filesystem;

// ---- helpers --------------------------------------------------------------------------------

// A small random CSG scene: every primitive kind, rotations, smooth and hard operators.
Scene random_scene(uint64_t seed, uint32_t primitives) {
    Rng r(seed);
    SceneBuilder b;
    const auto prim = [&]() {
        Shape s;
        switch (r.next_u64() % 6) {
            case 0:
                s = b.sphere(r.uniform(0.15f, 0.5f));
                break;
            case 1:
                s = b.box({r.uniform(0.2f, 0.8f), r.uniform(0.2f, 0.8f), r.uniform(0.2f, 0.8f)});
                break;
            case 2:
                s = b.cylinder(r.uniform(0.1f, 0.4f), r.uniform(0.2f, 0.9f));
                break;
            case 3:
                s = b.cone(r.uniform(0.1f, 0.4f), r.uniform(0.2f, 0.9f));
                break;
            case 4:
                s = b.capsule(r.uniform(0.1f, 0.3f), r.uniform(0.1f, 0.6f));
                break;
            default:
                s = b.torus(r.uniform(0.2f, 0.4f), r.uniform(0.05f, 0.15f));
                break;
        }
        return s.rotated({r.uniform(-1, 1), r.uniform(-1, 1), r.uniform(0.1f, 1)}, r.uniform(0, 3))
            .translated({r.uniform(-0.6f, 0.6f), r.uniform(-0.6f, 0.6f), r.uniform(-0.6f, 0.6f)});
    };
    std::vector<Shape> shapes;
    for (uint32_t i = 0; i < primitives; ++i) shapes.push_back(prim());
    while (shapes.size() > 1) {
        const size_t i = r.next_u64() % (shapes.size() - 1);
        const uint64_t op = r.next_u64() % 4;
        const uint32_t kind = op < 2    ? math::kOpUnion
                              : op == 2 ? math::kOpIntersection
                                        : math::kOpDifference;
        const float k = r.uniform() < 0.5f ? r.uniform(0.01f, 0.2f) : 0.0f;
        shapes[i] = b.combine(kind, shapes[i], shapes[i + 1], k);
        shapes.erase(shapes.begin() + long(i) + 1);
    }
    return b.build(shapes[0], {vec3(-1.1f, -1.0f, -1.2f), vec3(1.1f, 1.0f, 1.0f)});
}

size_t flat(uint32_t n, uint32_t x, uint32_t y, uint32_t z) {
    return (size_t(z) * n + y) * n + x;
}

// Pruned discretization: equal to grid.eval at every centre, to the naive value in near-field
// cells; far-field cells keep the sign and never overstate the distance.
void check_pruned_against_naive(const Scene& sc, const PruneOptions& po, const std::string& what) {
    SCOPED_TRACE(what);
    const PrunedGrid g = prune(sc, po);
    const uint32_t n = g.resolution();
    std::vector<float> pruned(size_t(n) * n * n), naive(pruned.size());
    discretize_pruned(g, pruned);
    discretize_naive(sc, n, naive, 2);
    std::vector<float> stack(sc.max_stack);
    uint64_t near = 0, bad = 0;
    for (uint32_t z = 0; z < n; ++z)
        for (uint32_t y = 0; y < n; ++y)
            for (uint32_t x = 0; x < n; ++x) {
                const size_t i = flat(n, x, y, z);
                const float p = pruned[i], e = naive[i];
                const vec3 c = g.cell_center(x, y, z);
                ASSERT_EQ(e, eval_point(sc, c)) << x << " " << y << " " << z;
                ASSERT_EQ(p, g.eval(c, stack.data())) << x << " " << y << " " << z;
                if (!g.cell(x, y, z).far_field) {
                    ++near;
                    ASSERT_EQ(p, e) << "near-field cell " << x << " " << y << " " << z;
                } else if (!((p > 0) == (e > 0) && std::fabs(p) <= std::fabs(e))) {
                    ++bad;
                    ADD_FAILURE() << "far-field cell " << x << " " << y << " " << z << ": " << p
                                  << " vs exact " << e;
                    if (bad > 5) return;
                }
            }
    EXPECT_EQ(near, g.stats().near_field_cells);
    if (!po.far_field) {
        EXPECT_EQ(pruned, naive);
    }
}

std::string temp_path(const std::string& name) {
    const fs::path dir =
        fs::path(::testing::TempDir()) / ("sdfprune_discretize_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    return (dir / name).string();
}

std::string last_line(const std::string& s) {
    std::string t = s;
    while (!t.empty() && t.back() == '\n') t.pop_back();
    const size_t at = t.rfind('\n');
    return at == std::string::npos ? t : t.substr(at + 1);
}

size_t line_count(const std::string& s) {
    return size_t(std::count(s.begin(), s.end(), '\n'));
}

void write_bytes(const std::string& path, const std::string& bytes) {
    std::ofstream(path, std::ios::binary) << bytes;
}

// ---- discretization ---------------------------------------------------------------------------

TEST(Discretize, PrunedMatchesNaiveOnDemo) {
    const Scene sc = builtin_scene("demo");
    for (uint32_t res : {32u, 64u}) {
        PruneOptions po;
        po.resolution = res;
        check_pruned_against_naive(sc, po, "demo " + std::to_string(res));
    }
}

TEST(Discretize, PrunedMatchesNaiveOnRandomScenes) {
    for (uint64_t seed = 1; seed <= 12; ++seed) {
        const Scene sc = random_scene(seed, 3 + uint32_t(seed % 9));
        PruneOptions po;
        po.resolution = seed % 2 ? 32 : 64;
        check_pruned_against_naive(sc, po, "random " + std::to_string(seed));
    }
}

TEST(Discretize, PrunedMatchesNaiveForAblationsAndOddGrids) {
    const Scene sc = random_scene(99, 10);
    PruneOptions po;
    po.resolution = 48;  // 3 -> 12 -> 48
    check_pruned_against_naive(sc, po, "48");
    po.resolution = 36;
    po.factor = 3;  // 4 -> 12 -> 36
    check_pruned_against_naive(sc, po, "36 factor 3");
    po = {};
    po.resolution = 32;
    po.hierarchy = false;
    check_pruned_against_naive(sc, po, "no hierarchy");
    po = {};
    po.resolution = 32;
    po.far_field = false;
    check_pruned_against_naive(sc, po, "no far field");
    po = {};
    po.resolution = 1;
    check_pruned_against_naive(sc, po, "1 cell");
}

TEST(Discretize, OtherResolutionLooksUpEachCentre) {
    const Scene sc = builtin_scene("demo");
    PruneOptions po;
    po.resolution = 64;
    const PrunedGrid g = prune(sc, po);
    const uint32_t n = 24;
    std::vector<float> out(n * n * n);
    discretize_pruned(g, n, out);
    const vec3 cell = (sc.aabb.max - sc.aabb.min) / float(n);
    std::vector<float> stack(sc.max_stack);
    for (uint32_t z = 0; z < n; ++z)
        for (uint32_t y = 0; y < n; ++y)
            for (uint32_t x = 0; x < n; ++x)
                ASSERT_EQ(out[flat(n, x, y, z)],
                          g.eval(sc.aabb.min +
                                     vec3(float(x) + 0.5f, float(y) + 0.5f, float(z) + 0.5f) * cell,
                                 stack.data()));
    std::vector<float> wrong(10);
    EXPECT_THROW(discretize_pruned(g, wrong), std::invalid_argument);
    EXPECT_THROW(discretize_naive(sc, 4, wrong), std::invalid_argument);
}

TEST(Discretize, ThreadCountDoesNotChangeTheResult) {
    const Scene sc = builtin_scene("demo");
    PruneOptions po;
    po.resolution = 64;
    po.threads = 1;
    const PrunedGrid one = prune(sc, po);
    po.threads = 0;
    const PrunedGrid all = prune(sc, po);
    std::vector<float> a(64 * 64 * 64), b(a.size());
    discretize_pruned(one, a);
    discretize_pruned(all, b);
    EXPECT_EQ(a, b);
}

// ---- .npy -----------------------------------------------------------------------------------

TEST(Npy, RoundTrip) {
    const std::string path = temp_path("round.npy");
    std::vector<float> v(4 * 3 * 2);
    for (size_t i = 0; i < v.size(); ++i) v[i] = float(i) * 0.25f - 3.0f;
    v[5] = -0.0f;
    v[7] = std::numeric_limits<float>::infinity();
    const uint64_t shape[3] = {4, 3, 2};
    write_npy(path, shape, v);
    const std::string bytes = read_file(path);
    EXPECT_EQ(bytes.size() % 64, (v.size() * 4) % 64);  // header padded to 64 bytes
    EXPECT_EQ(bytes.substr(0, 8), std::string("\x93NUMPY\x01\x00", 8));
    const NpyArray a = read_npy(path);
    EXPECT_EQ(a.shape, (std::vector<uint64_t>{4, 3, 2}));
    ASSERT_EQ(a.data.size(), v.size());
    for (size_t i = 0; i < v.size(); ++i) EXPECT_EQ(std::memcmp(&a.data[i], &v[i], 4), 0) << i;

    for (const std::vector<uint64_t>& s :
         {std::vector<uint64_t>{}, std::vector<uint64_t>{5}, std::vector<uint64_t>{0, 3}}) {
        uint64_t count = 1;
        for (uint64_t d : s) count *= d;
        const std::vector<float> data(count, 1.5f);
        write_npy(path, s, data);
        const NpyArray b = read_npy(path);
        EXPECT_EQ(b.shape, s);
        EXPECT_EQ(b.data, data);
    }
    EXPECT_NE(npy_header(std::vector<uint64_t>{5}).find("'shape': (5,)"), std::string::npos);
    EXPECT_THROW(write_npy(path, shape, std::vector<float>(3)), std::invalid_argument);
}

// Bytes of a float32 .npy file with the given header dict (version 1.0 or 2.0).
std::string npy_with_header(const std::string& dict, size_t data_bytes, int version = 1) {
    std::string h = dict + "\n";
    std::string out("\x93NUMPY", 6);
    out += char(version);
    out += char(0);
    const size_t len = h.size();
    out += char(len & 0xff);
    out += char(len >> 8);
    if (version >= 2) out += std::string(2, '\0');
    return out + h + std::string(data_bytes, '\0');
}

TEST(Npy, ReadsWhatNumpyWrites) {
    // Key order, quotes, Python 2 longs and version 2.0 as numpy has written them.
    const NpyArray a = parse_npy(
        npy_with_header("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }", 24), "a");
    EXPECT_EQ(a.shape, (std::vector<uint64_t>{2, 3}));
    const NpyArray b =
        parse_npy(npy_with_header(
                      "{\"shape\": (2L,3L), \"fortran_order\": False, \"descr\": \"<f4\"}", 24, 2),
                  "b");
    EXPECT_EQ(b.shape, (std::vector<uint64_t>{2, 3}));
    // Fortran order is the same layout for a vector.
    EXPECT_NO_THROW(parse_npy(
        npy_with_header("{'descr': '<f4', 'fortran_order': True, 'shape': (4,), }", 16), "c"));
}

TEST(Npy, RefusesBadFiles) {
    const auto refuses = [](const std::string& bytes, const std::string& needle) {
        try {
            parse_npy(bytes, "x.npy");
            ADD_FAILURE() << "accepted; expected: " << needle;
        } catch (const IoError& e) {
            const std::string m = e.what();
            EXPECT_NE(m.find(needle), std::string::npos) << m;
            EXPECT_EQ(m.find('\n'), std::string::npos) << m;
            EXPECT_EQ(m.rfind("x.npy: ", 0), 0u) << m;
        }
    };
    refuses("hello, world", "not a .npy file");
    refuses("", "not a .npy file");
    refuses(npy_with_header("{'descr': '<f8', 'fortran_order': False, 'shape': (2,), }", 16),
            "'<f8'");
    refuses(npy_with_header("{'descr': '>f4', 'fortran_order': False, 'shape': (2,), }", 8),
            "'>f4'");
    refuses(npy_with_header("{'descr': '<f4', 'fortran_order': True, 'shape': (2, 3), }", 24),
            "Fortran");
    refuses(npy_with_header("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }", 20),
            "truncated");
    refuses(npy_with_header("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }", 28),
            "bytes after");
    refuses(npy_with_header("{'descr': '<f4', 'fortran_order': False}", 0), "malformed");
    refuses(npy_with_header("{'descr': '<f4', 'fortran_order': Maybe, 'shape': ()}", 4),
            "malformed");
    refuses(npy_with_header("{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': ()}", 4),
            "malformed");
    refuses(npy_with_header("{'descr': '<f4', 'fortran_order': False, 'shape': (-1,)}", 4),
            "malformed");
    refuses(npy_with_header("{'descr': '<f4', 'fortran_order': False, 'shape': "
                            "(99999999999, 99999999999, 99999999999)}",
                            4),
            "too large");
    std::string cut = npy_with_header("{'descr': '<f4', 'fortran_order': False, 'shape': ()}", 4);
    refuses(cut.substr(0, 20), "truncated");
    std::string v9 = cut;
    v9[6] = 9;
    refuses(v9, "version 9.0");
    EXPECT_THROW(read_npy(temp_path("missing.npy")), IoError);
}

// ---- OpenVDB ----------------------------------------------------------------------------------

TEST(Vdb, LevelSetReadsBack) {
    const Scene sc = builtin_scene("sphere");  // AABB [-2, 2]³: cubic cells
    const uint32_t n = 32;
    PruneOptions po;
    po.resolution = n;
    const PrunedGrid g = prune(sc, po);
    std::vector<float> v(n * n * n);
    discretize_pruned(g, v);
    const std::string path = temp_path("sphere.vdb");
    const VdbStats st = write_vdb_level_set(path, sc.aabb, n, v);
    const float voxel = 4.0f / 32.0f;
    EXPECT_FLOAT_EQ(st.background, 3 * voxel);

    // Probes: in the band, deep inside, far outside.
    std::vector<std::array<int32_t, 3>> probes;
    uint64_t band = 0;
    for (uint32_t z = 0; z < n; ++z)
        for (uint32_t y = 0; y < n; ++y)
            for (uint32_t x = 0; x < n; ++x) {
                if (std::fabs(v[flat(n, x, y, z)]) < st.background) ++band;
                if ((x + 3 * y + 7 * z) % 97 == 0) probes.push_back({int(x), int(y), int(z)});
            }
    probes.push_back({16, 16, 16});  // the centre: inside, beyond the band
    probes.push_back({0, 0, 0});     // a corner: outside
    EXPECT_EQ(st.active_voxels, band);
    const VdbGridInfo info = inspect_vdb(path, probes);
    EXPECT_EQ(info.name, "surface");
    EXPECT_TRUE(info.level_set);
    EXPECT_TRUE(info.linear);
    EXPECT_FLOAT_EQ(info.voxel_size.x, voxel);
    EXPECT_FLOAT_EQ(info.voxel_size.y, voxel);
    EXPECT_FLOAT_EQ(info.voxel_size.z, voxel);
    // Voxel (0, 0, 0) sits at the centre of cell (0, 0, 0).
    EXPECT_FLOAT_EQ(info.origin.x, -2.0f + voxel / 2);
    EXPECT_FLOAT_EQ(info.origin.z, -2.0f + voxel / 2);
    EXPECT_FLOAT_EQ(info.background, st.background);
    EXPECT_EQ(info.active_voxels, band);
    uint64_t in_band = 0;
    for (size_t i = 0; i < probes.size(); ++i) {
        const float want = v[flat(n, probes[i][0], probes[i][1], probes[i][2])];
        if (std::fabs(want) < st.background) {
            ++in_band;
            EXPECT_EQ(info.probes[i], want) << i;
            EXPECT_TRUE(info.probe_active[i]);
        } else {
            EXPECT_EQ(info.probes[i], want > 0 ? st.background : -st.background) << i;
            EXPECT_FALSE(info.probe_active[i]);
        }
    }
    EXPECT_GT(in_band, 0u);
    EXPECT_EQ(info.probes[probes.size() - 2], -st.background);  // flood-filled inside
    EXPECT_EQ(info.probes.back(), st.background);

    // A non-cubic AABB keeps every sample at its cell centre (per-axis voxel size).
    const Scene box = random_scene(5, 4);  // AABB 2.2 x 2.0 x 2.2
    std::vector<float> w(16 * 16 * 16);
    discretize_naive(box, 16, w);
    write_vdb_level_set(path, box.aabb, 16, w);
    const VdbGridInfo bi = inspect_vdb(path);
    EXPECT_FLOAT_EQ(bi.voxel_size.x, 2.2f / 16);
    EXPECT_FLOAT_EQ(bi.voxel_size.y, 2.0f / 16);
    EXPECT_FLOAT_EQ(bi.voxel_size.z, 2.2f / 16);
    EXPECT_FLOAT_EQ(bi.origin.y, -1.0f + 2.0f / 32);
    EXPECT_THROW(inspect_vdb(temp_path("none.vdb")), IoError);
}

// ---- the subcommands ------------------------------------------------------------------------

TEST(DiscretizeCli, NpyOutputLoads) {
    const std::string out = temp_path("sphere.npy");
    fs::remove(out);
    const test::CliResult r =
        test::run_cli("discretize builtin:sphere -o " + out + " --res 32 --json");
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string json = last_line(r.out);
    EXPECT_EQ(json.front(), '{');
    EXPECT_NE(json.find("\"res\":32"), std::string::npos) << json;
    EXPECT_NE(json.find("\"method\":\"pruned\""), std::string::npos) << json;
    EXPECT_NE(json.find("\"prune_ms\":"), std::string::npos) << json;
    EXPECT_NE(json.find("\"eval_ms\":"), std::string::npos) << json;
    EXPECT_NE(json.find("\"near_field_cells\":"), std::string::npos) << json;
    const NpyArray a = read_npy(out);
    EXPECT_EQ(a.shape, (std::vector<uint64_t>{32, 32, 32}));
    // The same values as the library (the grid follows --res).
    const Scene sc = builtin_scene("sphere");
    PruneOptions po;
    po.resolution = 32;
    const PrunedGrid g = prune(sc, po);
    std::vector<float> v(32 * 32 * 32);
    discretize_pruned(g, v);
    EXPECT_EQ(a.data, v);

    const test::CliResult n = test::run_cli("discretize builtin:sphere -o " + out +
                                            " --res 20 --method naive --json --quiet");
    ASSERT_EQ(n.status, 0) << n.err;
    EXPECT_TRUE(n.err.empty()) << n.err;
    EXPECT_NE(last_line(n.out).find("\"prune_ms\":0"), std::string::npos) << n.out;
    std::vector<float> e(20 * 20 * 20);
    discretize_naive(sc, 20, e);
    EXPECT_EQ(read_npy(out).data, e);
}

TEST(DiscretizeCli, GridFollowsResolution) {
    const std::string out = temp_path("demo128.npy");
    test::CliResult r = test::run_cli("discretize builtin:demo -o " + out + " --res 128 --json");
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("\"levels\":\"2x8x32x128\""), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("\"grid\":128"), std::string::npos) << r.out;
    // Each cell is evaluated once: no sub-box refinement unless asked for.
    EXPECT_NE(r.out.find("\"refine\":1"), std::string::npos) << r.out;
    // An explicit --grid wins; values are the pruned field looked up at each centre.
    r = test::run_cli("discretize builtin:demo -o " + out + " --res 24 --grid 64 --json");
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("\"grid\":64"), std::string::npos) << r.out;
    const Scene sc = builtin_scene("demo");
    PruneOptions po;
    po.resolution = 64;
    po.refine = 1;
    std::vector<float> v(24 * 24 * 24);
    discretize_pruned(prune(sc, po), 24, v);
    EXPECT_EQ(read_npy(out).data, v);
    // An explicit --refine is kept.
    r = test::run_cli("discretize builtin:demo -o " + out +
                      " --res 24 --grid 64 --refine 3 --json");
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("\"refine\":3"), std::string::npos) << r.out;
    po.refine = 3;
    discretize_pruned(prune(sc, po), 24, v);
    EXPECT_EQ(read_npy(out).data, v);
}

TEST(DiscretizeCli, VdbOutput) {
    const std::string out = temp_path("demo.vdb");
    const test::CliResult r =
        test::run_cli("discretize builtin:demo -o " + out + " --res 40 --json --quiet");
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("\"format\":\"vdb\""), std::string::npos) << r.out;
    const VdbGridInfo info = inspect_vdb(out);
    EXPECT_TRUE(info.level_set);
    EXPECT_EQ(info.name, "surface");
    EXPECT_GT(info.active_voxels, 0u);
}

TEST(DiscretizeCli, RefusesBadOutputsBeforeWork) {
    const std::string dir = temp_path("");
    write_bytes(dir + "file", "not a directory");
    for (const std::string& out :
         {dir + "x.txt", dir + "x", dir + "missing/x.npy", dir + "file/x.npy", dir + "x.vdb/"}) {
        const test::CliResult r = test::run_cli("discretize builtin:demo -o " + out + " --res 16");
        EXPECT_EQ(r.status, 2) << out << ": " << r.err;
        EXPECT_EQ(line_count(r.err), 1u) << r.err;
        EXPECT_FALSE(fs::exists(out)) << out;
    }
    const test::CliResult r = test::run_cli("discretize builtin:demo -o " + dir + "d.npy --res 0");
    EXPECT_EQ(r.status, 2);
    const test::CliResult s = test::run_cli("discretize builtin:nope -o " + dir + "d.npy");
    EXPECT_EQ(s.status, 2);
    EXPECT_FALSE(fs::exists(dir + "d.npy"));
    // No temporary files left beside the outputs.
    for (const auto& e : fs::directory_iterator(dir))
        EXPECT_EQ(e.path().string().find(".tmp-"), std::string::npos) << e.path();
}

// Random points in and around the AABB of `sc`.
std::vector<float> random_points(const Scene& sc, uint32_t m, uint64_t seed) {
    Rng r(seed);
    std::vector<float> p(3 * size_t(m));
    const vec3 lo = sc.aabb.min, hi = sc.aabb.max, pad = (hi - lo) * 0.1f;
    for (uint32_t i = 0; i < m; ++i)
        for (int a = 0; a < 3; ++a) p[3 * i + a] = r.uniform(lo[a] - pad[a], hi[a] + pad[a]);
    return p;
}

TEST(EvalCli, MatchesSinglePointEvaluation) {
    const Scene sc = builtin_scene("demo");
    const uint32_t m = 3000;
    const std::vector<float> p = random_points(sc, m, 7);
    const std::string pts = temp_path("pts.npy"), out = temp_path("vals.npy");
    const uint64_t shape[2] = {m, 3};
    write_npy(pts, shape, p);

    test::CliResult r =
        test::run_cli("eval builtin:demo " + pts + " -o " + out + " --method naive --json");
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(last_line(r.out).find("\"points\":3000"), std::string::npos) << r.out;
    NpyArray v = read_npy(out);
    ASSERT_EQ(v.shape, (std::vector<uint64_t>{m}));
    for (uint32_t i = 0; i < m; ++i)
        ASSERT_EQ(v.data[i], eval_point(sc, {p[3 * i], p[3 * i + 1], p[3 * i + 2]})) << i;

    // Pruned: PrunedGrid::eval — exact in near-field cells and outside the AABB,
    // the conservative bound in far-field cells.
    r = test::run_cli("eval builtin:demo " + pts + " -o " + out + " --grid 64 --json --quiet");
    ASSERT_EQ(r.status, 0) << r.err;
    v = read_npy(out);
    PruneOptions po;
    po.resolution = 64;
    const PrunedGrid g = prune(sc, po);
    std::vector<float> stack(sc.max_stack);
    uint32_t near = 0;
    for (uint32_t i = 0; i < m; ++i) {
        const vec3 q{p[3 * i], p[3 * i + 1], p[3 * i + 2]};
        const float exact = eval_point(sc, q), got = v.data[i];
        ASSERT_EQ(got, g.eval(q, stack.data())) << i;
        uint32_t x, y, z;
        if (!g.cell_index(q, x, y, z) || !g.cell(x, y, z).far_field) {
            ++near;
            ASSERT_EQ(got, exact) << i;
        } else {
            ASSERT_TRUE((got > 0) == (exact > 0) && std::fabs(got) <= std::fabs(exact)) << i;
        }
    }
    EXPECT_GT(near, 0u);

    // --no-farfield: exact everywhere.
    r = test::run_cli("eval builtin:demo " + pts + " -o " + out + " --grid 32 --no-farfield");
    ASSERT_EQ(r.status, 0) << r.err;
    v = read_npy(out);
    for (uint32_t i = 0; i < m; ++i)
        ASSERT_EQ(v.data[i], eval_point(sc, {p[3 * i], p[3 * i + 1], p[3 * i + 2]})) << i;

    // No points: an empty result.
    const uint64_t none[2] = {0, 3};
    write_npy(pts, none, {});
    r = test::run_cli("eval builtin:sphere " + pts + " -o " + out + " --grid 8");
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(read_npy(out).shape, (std::vector<uint64_t>{0}));
}

TEST(EvalCli, RefusesBadInput) {
    const std::string pts = temp_path("bad.npy"), out = temp_path("bad_out.npy");
    const auto refused = [&](const std::string& bytes, const std::string& needle) {
        write_bytes(pts, bytes);
        fs::remove(out);
        const test::CliResult r =
            test::run_cli("eval builtin:sphere " + pts + " -o " + out + " --grid 8");
        EXPECT_EQ(r.status, 2) << needle << ": " << r.err;
        EXPECT_EQ(line_count(r.err), 1u) << r.err;
        EXPECT_NE(r.err.find(needle), std::string::npos) << r.err;
        EXPECT_FALSE(fs::exists(out));
    };
    const std::string hdr = "{'descr': '<f4', 'fortran_order': False, 'shape': ";
    refused(npy_with_header("{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), }", 48),
            "'<f8'");
    refused(npy_with_header(hdr + "(4, 2), }", 32), "(M, 3)");
    refused(npy_with_header(hdr + "(12,), }", 48), "(M, 3)");
    refused(npy_with_header(hdr + "(2, 3), }", 10), "truncated");
    refused("x,y,z\n1,2,3\n", "not a .npy file");
    refused(npy_with_header("{'descr': '<f4', 'fortran_order': True, 'shape': (2, 3), }", 24),
            "Fortran");
    // A missing input file, an unknown output extension, an unwritable output path.
    test::CliResult r =
        test::run_cli("eval builtin:sphere " + temp_path("nothing.npy") + " -o " + out);
    EXPECT_EQ(r.status, 2) << r.err;
    EXPECT_EQ(line_count(r.err), 1u) << r.err;
    const std::vector<float> one{0, 0, 0};
    const uint64_t shape[2] = {1, 3};
    write_npy(pts, shape, one);
    for (const std::string& o : {temp_path("out.csv"), temp_path("missing/out.npy")}) {
        r = test::run_cli("eval builtin:sphere " + pts + " -o " + o);
        EXPECT_EQ(r.status, 2) << r.err;
        EXPECT_EQ(line_count(r.err), 1u) << r.err;
        EXPECT_FALSE(fs::exists(o));
    }
}

}  // namespace
}  // namespace sdfprune
