// gpu_check.cpp — the Vulkan tests' shared helpers (gpu_check.hpp): the one device, devices and
// prunings with environment settings, and the checks of a device's grids against the CPU's.
#include "gpu_check.hpp"

#include <stdlib.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "prune_check.hpp"
#include "sdfprune/eval.hpp"

namespace sdfprune::test {

// ---- devices and environment settings -----------------------------------------------------------

gpu::Device* device(std::string& why) {
    static std::string error;
    static std::unique_ptr<gpu::Device> dev = [] {
        try {
            return std::make_unique<gpu::Device>();
        } catch (const gpu::GpuError& e) {
            error = e.what();
            return std::unique_ptr<gpu::Device>();
        }
    }();
    why = error;
    return dev.get();
}

ScopedEnv::ScopedEnv(EnvSettings settings) {
    for (const auto& [name, value] : settings) {
        const char* was = std::getenv(name);
        before_.emplace_back(name, was ? std::optional<std::string>(was) : std::nullopt);
        ::setenv(name, value, 1);
    }
}

ScopedEnv::~ScopedEnv() {
    for (auto it = before_.rbegin(); it != before_.rend(); ++it) {
        if (it->second)
            ::setenv(it->first.c_str(), it->second->c_str(), 1);
        else
            ::unsetenv(it->first.c_str());
    }
}

gpu::Grid prune_with_env(gpu::Device& dev, const Scene& sc, const PruneOptions& o,
                         EnvSettings settings) {
    const ScopedEnv env(settings);
    return gpu::prune(dev, sc, o);
}
gpu::Grid prune_with_env(gpu::Device& dev, const Scene& sc, const PruneOptions& o, const char* name,
                         const char* value) {
    return prune_with_env(dev, sc, o, {{name, value}});
}

std::unique_ptr<gpu::Device> device_with_envs(EnvSettings settings) {
    const ScopedEnv env(settings);
    try {
        return std::make_unique<gpu::Device>();
    } catch (const gpu::GpuError& e) {
        ADD_FAILURE() << "no Vulkan device (install mesa-vulkan-drivers): " << e.what();
        return nullptr;
    }
}
std::unique_ptr<gpu::Device> device_with_env(const char* name, const char* value) {
    return device_with_envs({{name, value}});
}

std::unique_ptr<gpu::Device> device_planned_as_h100() {
    return device_with_env("SDFPRUNE_VULKAN_RESIDENT_THREADS", "270336");
}

// ---- checks -------------------------------------------------------------------------------------

bool is_lavapipe(const gpu::Device& dev) {
    return dev.name().find("llvmpipe") != std::string::npos;
}

bool exact_device(const gpu::Device& dev) {
    if (const char* env = std::getenv("SDFPRUNE_GPU_EXACT")) return std::string(env) != "0";
    return is_lavapipe(dev);
}

void expect_same_stats(const PruneStats& cpu, const PruneStats& gpu, const std::string& what,
                       bool exact) {
    EXPECT_EQ(cpu.levels, gpu.levels) << what;
    if (exact) return expect_same_prune_stats(cpu, gpu, what);
    SCOPED_TRACE(what);
    EXPECT_EQ(cpu.cells, gpu.cells);
    const auto near = [](double a, double b) {
        return std::fabs(a - b) <= 0.01 * (1 + std::fabs(a));
    };
    EXPECT_PRED2(near, double(cpu.near_field_cells), double(gpu.near_field_cells));
    EXPECT_PRED2(near, cpu.active_avg, gpu.active_avg);
    EXPECT_PRED2(near, cpu.tape_avg, gpu.tape_avg);
}

void expect_walks_within_bound(const gpu::Device& dev, const gpu::GpuStepShape& st,
                               const std::string& what, uint64_t slack) {
    const bool takes_uncapped = st.taken && !dev.loop_limited();
    SCOPED_TRACE(what + ": level " + std::to_string(st.level) + " mode " + std::to_string(st.mode) +
                 (st.wide ? " wide" : "") + (st.wide_runs ? " runs" : "") +
                 (st.taken ? " taken" : "") + ", " + std::to_string(st.jobs) + " jobs, " +
                 std::to_string(st.workgroups) + " workgroups, " +
                 std::to_string(st.lanes_per_tape) + " lanes a tape");
    EXPECT_GT(st.walked_words, 0u);
    // (Lavapipe planned as a GPU runs a few workgroups at a time: its first take most of the
    // jobs, which no plan bounds.)
    if (!(is_lavapipe(dev) && takes_uncapped)) {
        EXPECT_LE(st.walked_words, (takes_uncapped ? 2 : 1) * slack * st.longest_walk_words);
    }
    EXPECT_GE(st.walked_sum_words, st.walked_words);
    EXPECT_LE(st.walked_sum_words, st.workgroups * st.walked_words);
}

bool runnable_tape(const Scene& sc, std::span<const uint32_t> tape) {
    uint64_t depth = 0;
    for (const uint32_t w : tape) {
        const uint32_t n = math::tape_node(w);
        if (n >= sc.size()) return false;
        if (sc.is_primitive(n)) {
            if (++depth > sc.max_stack) return false;
        } else if (depth < 2) {
            return false;
        } else {
            --depth;
        }
    }
    return depth == 1;
}

void expect_valid_cells(const Scene& sc, const gpu::Grid& gpu, const std::string& what) {
    SCOPED_TRACE(what);
    const uint32_t N = gpu.stats().grid;
    const vec3 cs = (sc.aabb.max - sc.aabb.min) / float(N);
    // Cell i's point k: its centre (k = 0), then 8 points near its corners.
    const auto point = [&](uint64_t i, uint32_t k) {
        const uint32_t x = uint32_t(i % N), y = uint32_t(i / N % N), z = uint32_t(i / N / N);
        const vec3 d =
            k == 0 ? vec3(0, 0, 0)
                   : vec3(k & 1 ? 0.45f : -0.45f, k & 2 ? 0.45f : -0.45f, k & 4 ? 0.45f : -0.45f);
        return sc.aabb.min + vec3(float(x) + 0.5f, float(y) + 0.5f, float(z) + 0.5f) * cs + d * cs;
    };
    const auto where = [&](uint64_t i) {
        return "cell (" + std::to_string(i % N) + ", " + std::to_string(i / N % N) + ", " +
               std::to_string(i / N / N) + ")";
    };
    constexpr uint32_t kPoints = 9;
    static_assert(kPoints <= kEvalLanes);
    // The cells a chunk at a time (a copy: CellContents' tape lives only within the visit), the
    // full tree at their points, then each cell's own check, both in parallel and in vector
    // lanes: at 128³ and finer, one point after another took minutes on one core.
    struct Cell {
        uint64_t index;
        bool far_field;
        float constant;
        std::vector<uint32_t> tape;
    };
    constexpr size_t kChunk = size_t(1) << 16;
    std::vector<Cell> chunk;
    std::vector<vec3> points;
    std::vector<float> full;
    std::atomic<uint64_t> bad = 0;
    std::mutex failures_mutex;
    std::vector<std::string> failures;  // the first 3
    const auto fail = [&](std::string message) {
        if (++bad > 3) return;
        const std::lock_guard<std::mutex> lock(failures_mutex);
        failures.push_back(std::move(message));
    };
    // `tape` at points [first, first + n) of the chunk's (n <= kEvalLanes) into out[0, n).
    const auto eval_in_lanes = [&](std::span<const uint32_t> tape, size_t first, uint32_t n,
                                   float* out, float* stack) {
        PointLanes lanes;
        for (uint32_t j = 0; j < n; ++j) {
            lanes.x[j] = points[first + j].x;
            lanes.y[j] = points[first + j].y;
            lanes.z[j] = points[first + j].z;
        }
        eval_tape_lanes(sc, tape, lanes, n, out, stack);
    };
    const auto check_chunk = [&] {
        points.resize(chunk.size() * kPoints);
        full.resize(points.size());
        for (size_t c = 0; c < chunk.size(); ++c)
            for (uint32_t k = 0; k < kPoints; ++k)
                points[c * kPoints + k] = point(chunk[c].index, k);
        // The full tree at the chunk's points, kEvalLanes points at a time (eval_tape's values).
        tbb::parallel_for(
            tbb::blocked_range<size_t>(0, points.size(), 64 * kEvalLanes), [&](const auto& range) {
                std::vector<float> stack(size_t(sc.max_stack + 1) * kEvalLanes);
                for (size_t at = range.begin(); at < range.end(); at += kEvalLanes) {
                    const uint32_t n = uint32_t(std::min<size_t>(kEvalLanes, range.end() - at));
                    eval_in_lanes(sc.full_tape, at, n, &full[at], stack.data());
                }
            });
        tbb::parallel_for(tbb::blocked_range<size_t>(0, chunk.size()), [&](const auto& range) {
            std::vector<float> stack(size_t(sc.max_stack + 1) * kEvalLanes);
            float own[kEvalLanes];
            for (size_t c = range.begin(); c < range.end(); ++c) {
                const Cell& cell = chunk[c];
                if (!cell.far_field) {
                    if (!runnable_tape(sc, cell.tape)) {
                        fail(where(cell.index) + ": a tape of " + std::to_string(cell.tape.size()) +
                             " words that no walk can run");
                        continue;
                    }
                    eval_in_lanes(cell.tape, c * kPoints, kPoints, own, stack.data());
                }
                for (uint32_t k = 0; k < kPoints; ++k) {
                    const float f = full[c * kPoints + k];
                    const float tol = 1e-5f * (1 + std::fabs(f));
                    const bool ok = cell.far_field ? (cell.constant > 0 ? f >= cell.constant - tol
                                                                        : f <= cell.constant + tol)
                                                   : std::fabs(own[k] - f) <= tol;
                    if (!ok)
                        fail(where(cell.index) + " point " + std::to_string(k) + ": full tree " +
                             std::to_string(f) + ", " +
                             (cell.far_field ? "far " + std::to_string(cell.constant)
                                             : "tape gives " + std::to_string(own[k])));
                }
            }
        });
        chunk.clear();
    };
    gpu.for_each_finest_cell([&](uint64_t i, const gpu::Grid::CellContents& c) {
        chunk.push_back({i, c.far_field, c.constant, {c.tape.begin(), c.tape.end()}});
        if (chunk.size() == kChunk) check_chunk();
    });
    check_chunk();
    for (const std::string& f : failures) ADD_FAILURE() << f;
    EXPECT_EQ(bad.load(), 0u);
}

void expect_same_cells(const PrunedGrid& cpu, const gpu::Grid& gpu, const std::string& what) {
    SCOPED_TRACE(what);
    const uint32_t N = cpu.resolution();
    uint64_t visited = 0, mismatches = 0;
    gpu.for_each_finest_cell([&](uint64_t i, const gpu::Grid::CellContents& c) {
        ++visited;
        const uint32_t x = uint32_t(i % N), y = uint32_t(i / N % N), z = uint32_t(i / N / N);
        const CellView v = cpu.cell(x, y, z);
        const bool same =
            v.far_field == c.far_field &&
            (v.far_field ? v.constant == c.constant
                         : std::equal(v.tape.begin(), v.tape.end(), c.tape.begin(), c.tape.end()));
        if (!same && ++mismatches <= 3)
            ADD_FAILURE() << "cell (" << x << ", " << y << ", " << z << "): cpu "
                          << (v.far_field ? "far " + std::to_string(v.constant)
                                          : "tape of " + std::to_string(v.tape.size()))
                          << ", gpu "
                          << (c.far_field ? "far " + std::to_string(c.constant)
                                          : "tape of " + std::to_string(c.tape.size()));
    });
    EXPECT_EQ(visited, uint64_t(N) * N * N);
    EXPECT_EQ(mismatches, 0u);
}

void expect_matches_cpu(const Scene& sc, const PrunedGrid& cpu, const gpu::Grid& gpu,
                        const gpu::Device& dev, const std::string& what) {
    const bool exact = exact_device(dev);
    expect_same_stats(cpu.stats(), gpu.stats(), what, exact);
    if (exact)
        expect_same_cells(cpu, gpu, what);
    else
        expect_valid_cells(sc, gpu, what);
}

void expect_same_device_cells(const gpu::Grid& a, const gpu::Grid& b, const std::string& what) {
    SCOPED_TRACE(what);
    struct Cell {  // a copy (CellContents' tape lives only within the visit)
        bool far_field;
        float constant;
        std::vector<uint32_t> tape;
    };
    std::vector<Cell> cells;
    a.for_each_finest_cell([&](uint64_t, const gpu::Grid::CellContents& c) {
        cells.push_back({c.far_field, c.constant, {c.tape.begin(), c.tape.end()}});
    });
    uint64_t mismatches = 0, i = 0;
    b.for_each_finest_cell([&](uint64_t, const gpu::Grid::CellContents& c) {
        ASSERT_LT(i, cells.size());
        const Cell& want = cells[i];
        const bool same = want.far_field == c.far_field &&
                          (c.far_field ? want.constant == c.constant
                                       : std::equal(want.tape.begin(), want.tape.end(),
                                                    c.tape.begin(), c.tape.end()));
        if (!same && ++mismatches <= 3) ADD_FAILURE() << "finest cell " << i << " differs";
        ++i;
    });
    EXPECT_EQ(i, cells.size());
    EXPECT_EQ(mismatches, 0u);
}

void expect_same_grid_if_exact(const Scene& sc, const gpu::Grid& a, const gpu::Grid& b,
                               const gpu::Device& dev, const std::string& what) {
    const bool exact = exact_device(dev);
    expect_same_stats(a.stats(), b.stats(), what, exact);
    if (exact) return expect_same_device_cells(a, b, what);
    expect_valid_cells(sc, a, what);
    expect_valid_cells(sc, b, what);
}

// ---- scenes -------------------------------------------------------------------------------------

Scene right_deep_chain(uint32_t depth) {
    SceneBuilder b;
    Shape chain = b.sphere(0.05f).translated(vec3(0.9f, 0, 0));
    for (uint32_t i = 1; i <= depth; ++i) {
        const float a = float(i) * 0.0031f;
        const Shape s =
            b.sphere(0.04f).translated(vec3(std::cos(a), std::sin(a), 0.1f * std::sin(3 * a)));
        chain = smooth_union(s, chain, 0.02f);
    }
    return b.build(chain);
}

Shape mixed_chain(SceneBuilder& b, Shape base, uint32_t ops, vec3 centre) {
    Shape chain = base;
    for (uint32_t i = 1; i <= ops; ++i) {
        const float a = float(i) * 0.21f;
        const Shape s = b.sphere(0.03f + 0.01f * float(i % 3))
                            .translated(centre + vec3(0.3f * std::cos(a), 0.3f * std::sin(a),
                                                      0.5f * float(i) / float(ops) - 0.25f));
        switch (i % 6) {
            case 0:
                chain = smooth_union(chain, s, 0.03f);
                break;
            case 1:
                chain = chain | s;
                break;
            case 2:
                chain = smooth_difference(chain, s.scaled(0.5f), 0.01f);
                break;
            case 3:
                chain = chain & b.sphere(0.6f).translated(centre);
                break;
            case 4:
                chain = smooth_union(s, chain, 0.02f);
                break;
            default:
                chain = smooth_intersection(chain, b.box(vec3(0.8f)).translated(centre), 0.05f);
        }
        if (i % 16 == 0) chain = b.sphere(0.7f).translated(centre) - chain;
    }
    return chain;
}

}  // namespace sdfprune::test
