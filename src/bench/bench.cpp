// bench.cpp — one row of the paper's Tables 1–2 (Barbier et al., EG 2025) measured here: prune,
// trace and discretize one scene with one variant, estimating from samples what would exceed
// the time budget (the naive baseline and the no-hierarchy ablation on large scenes).
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <thread>

#include "../core/clock.hpp"
#include "../prune/prune_level.hpp"
#include "sdfprune/bench.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/discretize.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/prune.hpp"
#include "sdfprune/render.hpp"

namespace sdfprune {

const char* variant_name(Variant v) {
    switch (v) {
        case Variant::kOurs:
            return "ours";
        case Variant::kNoFarField:
            return "no_farfield";
        case Variant::kNoHierarchy:
            return "no_hierarchy";
        case Variant::kNaive:
            return "naive";
    }
    return "?";
}

bool variant_from_name(std::string_view name, Variant& out) {
    for (Variant v : kAllVariants)
        if (name == variant_name(v)) {
            out = v;
            return true;
        }
    return false;
}

std::string scene_display_name(const std::string& source) {
    constexpr std::string_view kBuiltin = "builtin:";
    if (source.starts_with(kBuiltin)) return source.substr(kBuiltin.size());
    const std::string stem = std::filesystem::path(source).stem().string();
    return stem.empty() ? source : stem;
}

uint64_t scene_bytes(const Scene& sc) {
    const auto b = [](const auto& v) { return uint64_t(v.capacity()) * sizeof(v[0]); };
    return b(sc.kind) + b(sc.left) + b(sc.right) + b(sc.parent) + b(sc.negated) + b(sc.blend) +
           b(sc.lipschitz) + b(sc.primitive) + b(sc.local) + b(sc.primitive_node) + b(sc.params) +
           b(sc.shape) + b(sc.color) + b(sc.bound) + b(sc.full_tape);
}

namespace {

using Clock = std::chrono::steady_clock;

// Node evaluations a pilot sample aims at (about 0.1 s of one core): the first sample's size
// follows from the scene's node count, so pilots stay short on million-node scenes.
constexpr double kPilotNodeEvals = 3e7;
// Tracing steps per pixel assumed for sizing the pilot (primary + shadow ray).
constexpr double kStepsGuess = 64;
// An estimate's sample grows until it takes about budget / kSampleShare.
constexpr double kSampleShare = 8;

void say(const BenchOptions& o, const char* fmt, auto... args) {
    if (!o.log) return;
    char buf[512];
    std::snprintf(buf, sizeof buf, fmt, args...);
    o.log(buf);
}

int concurrency(int threads) {
    const int hw = std::max(1, int(std::thread::hardware_concurrency()));
    return threads > 0 ? std::min(threads, hw) : hw;
}

// Runs `once` (which returns its time in ms); a run under 100 ms is repeated, up to 5 runs
// within about a second, and the median kept.
template <class Fn>
double median_ms(Fn&& once) {
    std::vector<double> t{once()};
    double total = t[0];
    while (t.back() < 100 && t.size() < 5 && total < 1000) {
        t.push_back(once());
        total += t.back();
    }
    std::sort(t.begin(), t.end());
    return t[t.size() / 2];
}

struct SampleRun {
    double ms = 0;
    double units = 0;  // work units actually run (pixels, cells)
};
struct Projection {
    bool fits = true;     // the full run is projected within budget: measure it
    double ms = 0;        // otherwise the estimate for the full run
    double fraction = 1;  // and the fraction of the work its sample ran
};

// Pilot, then growing samples, until either the full run is projected within the budget or a
// sample took about budget / kSampleShare (the estimate is then that sample, scaled).
template <class Run>
Projection project(const BenchOptions& o, const char* what, const char* unit, double full_units,
                   double pilot_units, Run&& run) {
    const double budget_ms = o.budget_s * 1000;
    const double target_ms = budget_ms / kSampleShare;
    double units = std::clamp(pilot_units, 1.0, full_units);
    for (;;) {
        const SampleRun r = run(units);
        if (r.units >= full_units) return {};
        const double projected = r.ms * full_units / r.units;
        say(o, "%s: sample of %.0f of %.0f %s took %.1f ms: %.1f s projected (budget %.1f s)", what,
            r.units, full_units, unit, r.ms, projected / 1000, o.budget_s);
        if (projected <= budget_ms) return {};
        const double next = std::min(
            full_units * 0.5, units * std::clamp(target_ms / std::max(r.ms, 1e-3), 2.0, 64.0));
        if (r.ms >= target_ms * 0.5 || next <= units)
            return {false, projected, r.units / full_units};
        units = next;
    }
}

Camera bench_camera(const Scene& sc, const BenchOptions& o) {
    return orbit_camera(sc.aabb, o.yaw, o.pitch, 0, o.fov);
}

RenderOptions render_options(const Scene& sc, const BenchOptions& o, uint32_t w, uint32_t h) {
    RenderOptions ro;
    ro.width = w;
    ro.height = h;
    ro.camera = bench_camera(sc, o);
    ro.shading = Shading::kShaded;
    ro.shadows = true;
    ro.threads = o.threads;
    return ro;
}

// ---- naive ---------------------------------------------------------------------------------

void measure_naive(const Scene& sc, const BenchOptions& o, BenchRow& row) {
    const int T = concurrency(o.threads);
    const double nodes = double(sc.size());

    // Tracing: the same camera at a lower resolution samples the image's pixels uniformly.
    // Rows are the tracer's parallel tasks: a sample with fewer rows than threads is scaled by
    // the share of threads it could use.
    const double pixels = double(o.width) * o.height;
    const Projection tp =
        project(o, "naive trace", "pixels", pixels, kPilotNodeEvals / (nodes * kStepsGuess),
                [&](double units) {
                    const double s = std::sqrt(units / pixels);
                    const uint32_t w = std::max(1u, uint32_t(std::lround(o.width * s)));
                    const uint32_t h = std::max(1u, uint32_t(std::lround(o.height * s)));
                    RenderStats st;
                    render_naive(sc, render_options(sc, o, w, h), &st);
                    const double used = double(std::min<int>(int(h), T)) / T;
                    return SampleRun{st.trace_ms * used, double(w) * h};
                });
    if (tp.fits) {
        const RenderOptions ro = render_options(sc, o, o.width, o.height);
        row.trace_ms = median_ms([&] {
            RenderStats st;
            render_naive(sc, ro, &st);
            return st.trace_ms;
        });
    } else {
        row.trace_ms = tp.ms;
        row.trace_estimated = true;
        row.trace_sample = tp.fraction;
    }

    // Discretization: the cell centres of a coarser grid over the same AABB, with the same
    // evaluator as discretize_naive, in small parallel tasks so that samples use every thread.
    const double N = o.res, cells = N * N * N;
    const Projection dp =
        project(o, "naive discretize", "cells", cells, kPilotNodeEvals / nodes, [&](double units) {
            const uint32_t n = std::max(1u, uint32_t(std::lround(N * std::cbrt(units / cells))));
            const uint64_t count = uint64_t(n) * n * n;
            std::vector<float> out(count);
            const vec3 lo = sc.aabb.min, cell = (sc.aabb.max - sc.aabb.min) / float(n);
            const auto t0 = Clock::now();
            with_threads(o.threads, [&] {
                tbb::parallel_for(tbb::blocked_range<uint64_t>(0, count, 64),
                                  [&](const tbb::blocked_range<uint64_t>& r) {
                                      std::vector<float> stack(sc.max_stack);
                                      for (uint64_t i = r.begin(); i != r.end(); ++i) {
                                          const vec3 c(float(i % n) + 0.5f, float(i / n % n) + 0.5f,
                                                       float(i / n / n) + 0.5f);
                                          out[i] = eval_tape(sc, sc.full_tape, lo + c * cell,
                                                             stack.data());
                                      }
                                  });
            });
            return SampleRun{ms_since(t0), double(count)};
        });
    if (dp.fits) {
        std::vector<float> values(size_t(cells), 0.0f);
        row.discretize_ms = median_ms([&] {
            const auto t0 = Clock::now();
            discretize_naive(sc, o.res, values, o.threads);
            return ms_since(t0);
        });
    } else {
        row.discretize_ms = dp.ms;
        row.discretize_estimated = true;
        row.discretize_sample = dp.fraction;
    }

    row.prune_ms = 0;
    row.prune_peak_bytes = 0;
    row.trace_bytes = scene_bytes(sc);
    row.active_avg = row.active_max = sc.primitive_count();
    row.active_std = 0;
    row.near_field_fraction = 1;
}

// ---- pruned variants -------------------------------------------------------------------------

PruneOptions prune_options(Variant v, const BenchOptions& o) {
    PruneOptions po;
    po.resolution = o.grid_resolution();
    po.far_field = v != Variant::kNoFarField;
    po.hierarchy = v != Variant::kNoHierarchy;
    po.threads = o.threads;
    po.clearance = true;  // as `sdfprune render`: the tracer's far-field skips, in T_p
    return po;
}

// Prunes (median of repeats when fast), then traces and discretizes on the grid.
void measure_pruned(const Scene& sc, Variant v, const BenchOptions& o, BenchRow& row) {
    const PruneOptions po = prune_options(v, o);
    std::optional<PrunedGrid> grid;
    row.prune_ms = median_ms([&] {
        grid.reset();
        grid.emplace(prune(sc, po));
        return grid->stats().prune_ms;
    });
    const PruneStats& st = grid->stats();
    row.prune_peak_bytes = st.prune_peak_bytes;
    row.trace_bytes = st.tape_bytes;
    row.active_avg = st.active_avg;
    row.active_std = st.active_std;
    row.active_max = st.active_max;
    row.near_field_fraction = st.cells ? double(st.near_field_cells) / double(st.cells) : 0;

    const RenderOptions ro = render_options(sc, o, o.width, o.height);
    row.trace_ms = median_ms([&] {
        RenderStats rs;
        render(*grid, ro, &rs);
        return rs.trace_ms;
    });
    std::vector<float> values(size_t(o.res) * o.res * o.res, 0.0f);
    row.discretize_ms = median_ms([&] {
        const auto t0 = Clock::now();
        discretize_pruned(*grid, o.res, values);
        return ms_since(t0);
    });
}

// What pruning a sample of finest cells from the full tape found.
struct CellSample {
    uint64_t cells = 0, near = 0;
    double prims = 0, prims_sq = 0, words = 0;
    uint32_t prims_max = 0;
};

// Prunes about `count` random finest cells (of an N³ grid) from the full tape, in parallel, the
// way prune() does without hierarchy (prune_level_step over the level's one block of N³ cells,
// refinement included): groups of kSiblingGroupLanes cells that follow each other in the block,
// a group taken as prune() takes such cells (stage 1 in one pass over a short tape), at random
// places.
SampleRun prune_random_cells(const Scene& sc, const PruneOptions& po, uint64_t count, uint64_t seed,
                             CellSample& sample) {
    const uint32_t N = po.resolution;
    const uint64_t total = uint64_t(N) * N * N;
    const uint64_t group = std::min<uint64_t>(kSiblingGroupLanes, total);
    const uint64_t groups = std::max<uint64_t>(1, (count + group - 1) / group);
    const LevelGeometry geo = level_geometry(sc, po, N, N, true, kPruneChunkCells);
    const std::vector<ParentBlock> root{
        {{0, 0, 0}, uint32_t(sc.full_tape.size()), sc.full_tape.data()}};
    tbb::enumerable_thread_specific<CellScratch> scratch;
    tbb::enumerable_thread_specific<LevelChunk> part;
    tbb::enumerable_thread_specific<std::vector<PrunedCell>> cells;
    const auto t0 = Clock::now();
    with_threads(po.threads, [&] {
        tbb::parallel_for(
            tbb::blocked_range<uint64_t>(0, groups, 4), [&](const tbb::blocked_range<uint64_t>& r) {
                CellScratch& s = scratch.local();
                LevelChunk& out = part.local();
                std::vector<PrunedCell>& mine = cells.local();
                mine.resize(group);
                for (uint64_t g = r.begin(); g != r.end(); ++g) {
                    // Group g of the sample: its own stream, so the sample does not depend
                    // on the thread count.
                    Rng rng(seed * 0x100000000ull + g);
                    const uint64_t first =
                        std::min(rng.next_u64() % (total / group) * group, total - group);
                    out.words.clear();  // (offsets within the group only)
                    prune_level_step(sc, po, geo, root, first, first + group, mine, s, out);
                }
            });
    });
    const double ms = ms_since(t0);
    sample = {};
    for (const LevelChunk& p : part) {
        // A far-field cell counts one primitive (Table 2's metric).
        sample.near += p.near;
        sample.prims += double(p.prim_sum);
        sample.prims_sq += double(p.prim_sq_sum);
        sample.words += double(p.tape_sum);
        sample.prims_max = std::max(sample.prims_max, p.prim_max);
    }
    sample.cells = groups * group;
    const uint64_t far = sample.cells - sample.near;
    sample.prims += double(far);
    sample.prims_sq += double(far);
    if (far > 0) sample.prims_max = std::max(sample.prims_max, 1u);
    return {ms, double(sample.cells)};
}

void measure_no_hierarchy(const Scene& sc, const BenchOptions& o, BenchRow& row) {
    const PruneOptions po = prune_options(Variant::kNoHierarchy, o);
    const double N = po.resolution, cells = N * N * N;
    CellSample sample;
    // Evaluate, decide and compact: about three passes over the tape per cell.
    const Projection p = project(
        o, "no_hierarchy prune", "cells", cells, kPilotNodeEvals / (3.0 * sc.size()),
        [&](double units) { return prune_random_cells(sc, po, uint64_t(units), o.seed, sample); });
    if (p.fits) return measure_pruned(sc, Variant::kNoHierarchy, o, row);

    row.prune_ms = p.ms;
    row.prune_estimated = true;
    row.prune_sample = p.fraction;
    row.stats_estimated = true;
    const double n = double(sample.cells);
    row.active_avg = sample.prims / n;
    row.active_std =
        std::sqrt(std::max(0.0, sample.prims_sq / n - row.active_avg * row.active_avg));
    row.active_max = sample.prims_max;  // the sample's: a lower bound of the grid's
    row.near_field_fraction = double(sample.near) / n;
    // The structure prune() would build: one level of N³ cells, the full tape, and per
    // near-field cell its tape with a 2-word header (no sharing assumed).
    const double near_cells = row.near_field_fraction * cells;
    const double tape_words = sample.near ? sample.words / double(sample.near) : 0;
    row.trace_bytes = uint64_t(cells * sizeof(PrunedCell) + (sc.size() + 2.0) * 4 +
                               near_cells * (tape_words + 2) * 4);
    row.prune_peak_bytes = row.trace_bytes;
    say(o, "no_hierarchy: not built (estimated %.1f s); trace and discretize not measured",
        p.ms / 1000);
}

}  // namespace

BenchRow run_variant(const Scene& sc, Variant v, const BenchOptions& o) {
    if (!(o.budget_s > 0)) throw std::invalid_argument("bench: budget must be > 0 s");
    if (o.width == 0 || o.height == 0 || o.res == 0)
        throw std::invalid_argument("bench: image size and resolution must be positive");
    BenchRow row;
    row.nodes = sc.size();
    row.primitives = sc.primitive_count();
    row.variant = v;
    row.width = o.width;
    row.height = o.height;
    row.res = o.res;
    row.grid = v == Variant::kNaive ? 0 : o.grid_resolution();
    switch (v) {
        case Variant::kOurs:
        case Variant::kNoFarField:
            measure_pruned(sc, v, o, row);
            break;
        case Variant::kNoHierarchy:
            measure_no_hierarchy(sc, o, row);
            break;
        case Variant::kNaive:
            measure_naive(sc, o, row);
            break;
    }
    return row;
}

}  // namespace sdfprune
