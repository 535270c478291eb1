// cmd_stats.cpp — `sdfprune stats SCENE`: prune the scene and report the pruning's quality
// (the paper's Table 2 metric and the tape metric), time and memory.
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>

#include "command.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/gpu.hpp"
#include "sdfprune/prune.hpp"
#include "src/core/clock.hpp"

namespace sdfprune::cli {

uint64_t peak_rss_bytes() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return uint64_t(u.ru_maxrss) * 1024;
}

void add_prune_options(CLI::App* sub, PruneOptions& o, bool& lipschitz_bounds) {
    sub->add_option("--grid", o.resolution, "finest grid resolution (cells per axis)")
        ->capture_default_str()
        ->check(CLI::Range(1u, 4096u));
    sub->add_option("--factor", o.factor, "subdivision factor between levels")
        ->capture_default_str()
        ->check(CLI::Range(2u, 64u));
    sub->add_flag("--no-farfield{false}", o.far_field,
                  "ablation: never cull far cells to a constant");
    sub->add_flag("--no-hierarchy{false}", o.hierarchy,
                  "ablation: prune the full tree directly in every finest cell");
    sub->add_option("--farfield-c", o.far_field_c,
                    "far-field threshold C: a cell is far when |f| > C·L·R at its centre")
        ->capture_default_str()
        ->check(CLI::Range(1.0f, 1000.0f));
    sub->add_option("--refine", o.refine,
                    "finest cells are decided again over S³ sub-boxes (1 = off)")
        ->capture_default_str()
        ->check(CLI::Range(1u, 8u));
    sub->add_flag("--lipschitz-bounds", lipschitz_bounds,
                  "the paper's rule: centre ± L·R ranges only (no exact primitive ranges, no "
                  "sub-box refinement)");
    sub->add_flag("--clearance,!--no-clearance", o.clearance,
                  "far-field clearances, so that the tracer skips whole boxes of far-field cells "
                  "(costs pruning time; on by default for render only)");
    sub->add_option("--threads", o.threads, "worker threads (0 = all cores)")
        ->capture_default_str()
        ->check(CLI::Range(0, 1024));
}

PruneOptions with_bounds_flag(PruneOptions options, bool lipschitz_bounds) {
    if (lipschitz_bounds) {
        options.bounds = CellBounds::kLipschitz;
        options.refine = 1;
    }
    return options;
}

struct EditBench {
    double full_ms = 0, incremental_ms = 0;
    double copy_ms = 0;  // copying the grid first (update from a grid still in use)
    double full_words = 0, incremental_words = 0;  // tape words visited (medians)
    bool identical = true;
};

// The figures of the pruned grid itself (not of the work that made it).
bool same_stats(const PruneStats& a, const PruneStats& b) {
    return a.cells == b.cells && a.near_field_cells == b.near_field_cells &&
           a.active_avg == b.active_avg && a.active_std == b.active_std &&
           a.active_max == b.active_max && a.tape_avg == b.tape_avg && a.tape_max == b.tape_max;
}

// Times `count` random single-primitive moves of grid's scene (each a small step, as a drag
// in an editor would make, from the original scene): a full prune against update() in place on
// a copy of the grid (the copy, made first, timed apart: an editor that still renders from the
// old grid pays it too); medians. The copies come from a grid that has been updated once (with
// no edit), as in an editing session, where the statistics' census already exists.
EditBench edit_bench(const PrunedGrid& grid, uint32_t count, uint64_t seed) {
    const Scene& sc = grid.scene();
    const PrunedGrid base = update(grid, sc, SceneEdit{});
    Rng r(seed);
    const float step = math::length(sc.aabb.max - sc.aabb.min) * 0.005f;
    std::vector<double> full, incremental, copies, full_words, incremental_words;
    EditBench out;
    for (uint32_t i = 0; i < count; ++i) {
        const uint32_t p =
            std::min(uint32_t(r.uniform() * float(sc.primitive_count())), sc.primitive_count() - 1);
        const vec3 d(r.uniform(-1.0f, 1.0f), r.uniform(-1.0f, 1.0f), r.uniform(-1.0f, 1.0f));
        const Scene moved = moved_primitive(sc, p, d * step);
        const PrunedGrid a = prune(moved, grid.options());
        const auto t0 = std::chrono::steady_clock::now();
        PrunedGrid copy = base;
        copies.push_back(ms_since(t0));
        const PrunedGrid b = update(std::move(copy), moved, scene_edit(sc, moved));
        full.push_back(a.stats().prune_ms);
        incremental.push_back(b.stats().prune_ms);
        full_words.push_back(double(a.stats().tape_words_visited));
        incremental_words.push_back(double(b.stats().tape_words_visited));
        out.identical = out.identical && same_cells(a, b) && same_stats(a.stats(), b.stats());
    }
    const auto median = [](std::vector<double>& v) {
        std::sort(v.begin(), v.end());
        return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
    };
    out.full_ms = median(full);
    out.incremental_ms = median(incremental);
    out.copy_ms = median(copies);
    out.full_words = median(full_words);
    out.incremental_words = median(incremental_words);
    return out;
}

void add_stats(CLI::App& app, std::vector<Command>& commands) {
    struct Args {
        std::string scene;
        PruneOptions prune;
        bool lipschitz = false;
        bool json = false;
        std::string backend = "cpu";
        uint32_t edit_bench = 0;
        uint64_t seed = 1;
        uint32_t repeat = 1;
    };
    auto args = std::make_shared<Args>();
    CLI::App* sub =
        app.add_subcommand("stats",
                           "Prune a scene over its grid and report active primitives per cell (the "
                           "paper's Table 2 metric), tape lengths, time and memory.");
    sub->add_option("SCENE", args->scene, "scene file (.json) or builtin:NAME")->required();
    add_prune_options(sub, args->prune, args->lipschitz);
    sub->add_flag("--json", args->json, "print the figures as one JSON object on the last line");
    add_backend_option(sub, args->backend);
    sub->add_option("--edit-bench", args->edit_bench,
                    "also time N random single-primitive moves: incremental update against a full "
                    "prune (medians; CPU backend)")
        ->check(CLI::Range(0u, 100000u));
    sub->add_option("--seed", args->seed, "random seed of --edit-bench's moves")
        ->capture_default_str();
    sub->add_option("--repeat", args->repeat,
                    "prune N times on one device, each while the last grid is still held (as an "
                    "animation's frames): the figures are the last call's, buffers by then "
                    "reused; --json adds the first call's (first_*) (vulkan backend)")
        ->capture_default_str()
        ->check(CLI::Range(1u, 1000u));
    sub->footer(
        "Examples:\n  sdfprune stats scenes/molecule.json\n"
        "  sdfprune stats scenes/trees.json --grid 128 --no-farfield --json\n"
        "  sdfprune stats scenes/molecule.json --edit-bench 20 --json\n"
        "  sdfprune stats scenes/molecule.json --backend vulkan   (times and bytes on the GPU)");
    commands.push_back(
        {sub, [args] {
             const Scene sc = load_scene_arg(args->scene);
             PruneOptions o = with_bounds_flag(args->prune, args->lipschitz);
             if (args->edit_bench > 0 && args->backend != "cpu")
                 throw std::invalid_argument("--edit-bench runs on the CPU backend only");
             if (args->repeat > 1 && args->backend != "vulkan")
                 throw std::invalid_argument("--repeat runs on the vulkan backend only");
             // Incremental updates need the coarse cells' own tapes.
             if (args->edit_bench > 0) o.coarse_tapes = true;
             if (!o.hierarchy && !args->json)
                 std::fprintf(stderr, "pruning the full tree in all %u³ cells (no hierarchy)...\n",
                              o.resolution);
             // The CPU grid, or the device and its grid: the statistics are the same either way.
             std::unique_ptr<PrunedGrid> cpu_grid;
             std::unique_ptr<gpu::Device> device;
             std::unique_ptr<gpu::Grid> device_grid;
             gpu::DevicePruneStats first;  // the first call's, with --repeat
             double device_ms = 0;         // the device's making (its reserve's thread apart)
             if (args->backend == "vulkan") {
                 const auto made = std::chrono::steady_clock::now();
                 device = std::make_unique<gpu::Device>();
                 device_ms = ms_since(made);
                 device_grid = std::make_unique<gpu::Grid>(gpu::prune(*device, sc, o));
                 first = device_grid->stats();
                 for (uint32_t i = 1; i < args->repeat; ++i) {
                     auto next = std::make_unique<gpu::Grid>(gpu::prune(*device, sc, o));
                     device_grid = std::move(next);
                 }
             } else {
                 cpu_grid = std::make_unique<PrunedGrid>(prune(sc, o));
             }
             const PruneStats& s = device_grid ? device_grid->stats() : cpu_grid->stats();
             const EditBench edits = args->edit_bench > 0
                                         ? edit_bench(*cpu_grid, args->edit_bench, args->seed)
                                         : EditBench{};
             if (args->json) {
                 std::string levels;
                 for (uint32_t r : s.levels)
                     levels += (levels.empty() ? "" : "x") + std::to_string(r);
                 JsonLine j;
                 j.add("scene", args->scene)
                     .add("nodes", sc.size())
                     .add("grid", s.grid)
                     .add("levels", levels)
                     .add("bounds", args->lipschitz ? "lipschitz" : "interval")
                     .add("backend", args->backend)
                     .add("far_field", o.far_field)
                     .add("hierarchy", o.hierarchy)
                     .add("farfield_c", o.far_field_c)
                     .add("refine", o.refine)
                     .add("clearance", o.clearance)
                     .add("cells", s.cells)
                     .add("near_field_cells", s.near_field_cells)
                     .add("active_avg", s.active_avg)
                     .add("active_std", s.active_std)
                     .add("active_max", s.active_max)
                     .add("near_field_active_avg", s.near_field_prims_avg)
                     .add("tape_avg", s.tape_avg)
                     .add("tape_max", s.tape_max)
                     .add("prune_ms", s.prune_ms)
                     .add("prune_peak_bytes", s.prune_peak_bytes)
                     .add("tape_bytes", s.tape_bytes)
                     .add("tape_words_visited", s.tape_words_visited)
                     .add("clearance_ms", s.clearance_ms)
                     .add("clearance_bytes", s.clearance_bytes)
                     .add("peak_rss_bytes", peak_rss_bytes());
                 if (device) {
                     std::vector<JsonLine> steps;
                     for (const gpu::GpuStepShape& st : device_grid->stats().steps) {
                         JsonLine step;
                         gpu::for_each_figure(st, [&](const char* k, auto v) { step.add(k, v); });
                         steps.push_back(step);
                     }
                     j.add("device", device->name());
                     gpu::for_each_figure(device_grid->stats(),
                                          [&](const char* k, auto v) { j.add(k, v); });
                     j.add("device_ms", device_ms)
                         .add("device_reserve_bytes", device->memory_reserved())
                         .add("device_reserve_ms", device->reserve_ms());
                     // The device's idle buffers, kept for the next call (the grid held).
                     j.add("idle_cache_bytes", device->memory_cached());
                     if (args->repeat > 1) {
                         // The first call's figures, each as first_NAME.
                         j.add("repeat", args->repeat)
                             .add("first_prune_ms", first.prune_ms)
                             .add("first_prune_peak_bytes", first.prune_peak_bytes);
                         gpu::for_each_figure(first, [&](const char* k, auto v) {
                             j.add(std::string("first_") + k, v);
                         });
                     }
                     j.add("gpu_steps", steps);
                 }
                 if (args->edit_bench > 0)
                     j.add("edit_count", args->edit_bench)
                         .add("edit_full_ms", edits.full_ms)
                         .add("edit_incremental_ms", edits.incremental_ms)
                         .add("edit_copy_ms", edits.copy_ms)
                         .add("edit_identical", edits.identical)
                         .add("edit_full_words", edits.full_words)
                         .add("edit_incremental_words", edits.incremental_words);
                 std::printf("%s\n", j.str().c_str());
                 return 0;
             }
             std::string levels;
             for (uint32_t r : s.levels)
                 levels += (levels.empty() ? "" : " -> ") + std::to_string(r) + "³";
             std::printf("%s: %u nodes, grid %s%s%s\n", args->scene.c_str(), sc.size(),
                         levels.c_str(), o.far_field ? "" : ", no far field",
                         o.hierarchy ? "" : ", no hierarchy");
             std::printf("  active primitives per cell (all cells, far = 1)  %.4f ± %.4f, max %u\n",
                         s.active_avg, s.active_std, s.active_max);
             std::printf(
                 "  near-field cells          %llu of %llu (%.2f %%), %.2f primitives each\n",
                 (unsigned long long)s.near_field_cells, (unsigned long long)s.cells,
                 100.0 * double(s.near_field_cells) / double(s.cells), s.near_field_prims_avg);
             std::printf("  tape length (near-field)  %.2f nodes avg, %u max (full tree: %u)\n",
                         s.tape_avg, s.tape_max, sc.size());
             if (device) {
                 const gpu::DevicePruneStats& ds = device_grid->stats();
                 std::printf(
                     "  pruning on %s: %.1f ms GPU (%.1f ms wall, %u submissions, %u pool "
                     "grows), peak %.1f MB device memory\n"
                     "    host: %llu buffers made (%llu device allocations, %.1f MB) and %llu "
                     "reused in "
                     "%.1f ms, %llu submissions waited for in %.1f ms\n",
                     device->name().c_str(), s.prune_ms, ds.wall_ms, ds.submissions, ds.pool_grows,
                     double(s.prune_peak_bytes) / 1e6, (unsigned long long)ds.host_buffers,
                     (unsigned long long)ds.host_allocations, double(ds.host_allocated_bytes) / 1e6,
                     (unsigned long long)ds.host_buffers_reused, ds.host_buffer_ms,
                     (unsigned long long)ds.host_submissions, ds.host_submit_ms);
                 std::printf("    device made in %.1f ms", device_ms);
                 if (device->memory_reserved() > 0)
                     std::printf("; its reserve of %.1f MB allocated beside it in %.1f ms",
                                 double(device->memory_reserved()) / 1e6, device->reserve_ms());
                 std::printf("\n");
                 static const char* const kModes[] = {"cells", "octants", "cells from octants",
                                                      "refinement"};
                 for (const gpu::GpuStepShape& st : device_grid->stats().steps) {
                     std::printf(
                         "    level %u %-18s %s%u dispatches, %llu workgroups, %llu jobs "
                         "on %llu lanes (%u to a tape), longest walk <= %llu words, %.2f ms",
                         st.level, kModes[std::min(st.mode, 3u)], st.wide ? "wide: " : "",
                         st.dispatches, (unsigned long long)st.workgroups,
                         (unsigned long long)st.jobs, (unsigned long long)st.lanes,
                         st.lanes_per_tape, (unsigned long long)st.longest_walk_words, st.gpu_ms);
                     if (st.walked_words > 0)
                         std::printf(" (walked %llu, all workgroups %llu)",
                                     (unsigned long long)st.walked_words,
                                     (unsigned long long)st.walked_sum_words);
                     if (st.taken) std::printf(", jobs taken as workgroups come free");
                     if (st.wide_runs) std::printf(", long runs staged in shared memory");
                     if (st.scratch_bytes > 0)
                         std::printf(", scratch %.1f MB", double(st.scratch_bytes) / 1e6);
                     if (st.mode == 3)  // refinement: its lane pass
                         std::printf(
                             " (%llu only copied; lane pass over tapes of up to %u words %.2f "
                             "ms, %llu cells past the first sub-boxes, %llu left to squads)",
                             (unsigned long long)st.copy_jobs, st.lane_tape, st.lanes_ms,
                             (unsigned long long)st.more_jobs, (unsigned long long)st.long_jobs);
                     std::printf("\n");
                 }
             } else
                 std::printf(
                     "  pruning                   %.1f ms, peak %.1f MB in pruning buffers\n",
                     s.prune_ms, double(s.prune_peak_bytes) / 1e6);
             std::printf("  pruned grid               %.1f MB; process peak RSS %.1f MB\n",
                         double(s.tape_bytes) / 1e6, double(peak_rss_bytes()) / 1e6);
             if (args->edit_bench > 0)
                 std::printf(
                     "  %u single-primitive moves: full prune %.1f ms, incremental %.2f ms "
                     "(medians, %.1f %%; copying the grid first: %.1f ms more), %s\n",
                     args->edit_bench, edits.full_ms, edits.incremental_ms,
                     100.0 * edits.incremental_ms / edits.full_ms, edits.copy_ms,
                     edits.identical ? "identical to the full prunes"
                                     : "NOT identical to the full prunes");
             return edits.identical ? 0 : 1;
         }});
}

namespace {
const CommandRegistrar registrar(20, add_stats);
}  // namespace

}  // namespace sdfprune::cli
