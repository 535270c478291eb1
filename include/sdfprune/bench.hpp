// bench.hpp — the measurements of the paper's Tables 1 and 2 (Barbier et al., "Lipschitz
// Pruning", EG 2025), run on this machine: for one scene and one variant (ours, the two
// ablations, the naive baseline) the pruning, tracing and discretization times, memory and the
// active-primitive statistics; reports as JSON and markdown beside the paper's own figures.
//
// Timing rules (what `sdfprune bench` and BENCHMARKS.md report):
//   - prune_ms: prune() wall time on the pruning grid (PruneStats::prune_ms).
//   - trace_ms: render()/render_naive() at width x height, shaded, one primary and one shadow
//     ray per pixel (RenderStats::trace_ms).
//   - discretize_ms: discretize_pruned()/discretize_naive() at res³, output allocated beforehand.
//   - measurements under 100 ms are repeated (up to 5 runs within about a second) and the median
//     is kept.
//   - budget: a measurement whose projected time exceeds budget_s is *estimated*: a pilot on a
//     small sample gives the cost per unit (pixel, cell), the sample grows until it takes about
//     budget_s / 8, and the figure is that sample's time scaled to the full count. Samples keep
//     the work's distribution: the same camera at a lower resolution (pixels spread uniformly
//     over the image), a coarser grid over the same AABB, random groups of 64 neighbouring
//     cells of the finest grid. Estimated fields are flagged in the row (and "≈" in markdown).
//   - no_hierarchy: when its pruning is estimated (K random finest cells pruned from the full
//     tape as prune() prunes them, 64 neighbours a pass, refinement included, scaled to res³),
//     the grid is never built: trace and discretize are not measured (NaN), and the statistics
//     and memory are estimated from the same sample.
//
// Thread-safety: run_variant() uses the machine (all threads unless BenchOptions::threads); call
// it from one thread at a time. The report functions are pure.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "plot.hpp"
#include "scene.hpp"

namespace sdfprune {

enum class Variant {
    kOurs,         // hierarchy + far-field culling (the default prune())
    kNoFarField,   // PruneOptions::far_field = false
    kNoHierarchy,  // PruneOptions::hierarchy = false: the full tree pruned in every finest cell
    kNaive,        // no pruning: the full tree at every query (the paper's baseline)
};
inline constexpr Variant kAllVariants[] = {Variant::kOurs, Variant::kNoFarField,
                                           Variant::kNoHierarchy, Variant::kNaive};
// "ours", "no_farfield", "no_hierarchy", "naive".
const char* variant_name(Variant v);
// False when `name` is none of the above.
bool variant_from_name(std::string_view name, Variant& out);

struct BenchOptions {
    uint32_t width = 1920, height = 1080;  // traced image
    uint32_t res = 256;                    // discretization: res³ cell centres
    uint32_t grid = 0;                     // pruning grid resolution; 0 = res
    double budget_s = 20;                  // per measurement, before it is estimated (> 0)
    int threads = 0;                       // 0 = all hardware threads
    float yaw = 30, pitch = 25, fov = 40;  // camera: orbit_camera over the AABB, degrees
    uint64_t seed = 1;                     // random cell groups of the no_hierarchy sample
    // Progress messages ("no_hierarchy: pilot on 4096 cells ..."); may be empty.
    std::function<void(const std::string&)> log;
    uint32_t grid_resolution() const { return grid ? grid : res; }
};

inline constexpr double kNotMeasured = std::numeric_limits<double>::quiet_NaN();

struct BenchRow {
    std::string scene;   // display name (scene_display_name of source)
    std::string source;  // the scene argument: a path or builtin:NAME
    uint32_t nodes = 0, primitives = 0;
    Variant variant = Variant::kOurs;
    uint32_t width = 0, height = 0, res = 0, grid = 0;  // sizes measured at

    double prune_ms = 0;  // 0 for naive (nothing to prune)
    double trace_ms = kNotMeasured;
    double discretize_ms = kNotMeasured;
    uint64_t prune_peak_bytes = 0;  // PruneStats::prune_peak_bytes; naive: 0
    // Memory the tracer reads: the pruned structure (PruneStats::tape_bytes), or for naive the
    // scene's arrays (scene_bytes).
    uint64_t trace_bytes = 0;
    // Active primitives per finest cell, far-field = 1 (paper Table 2); naive: all primitives.
    double active_avg = 0, active_std = 0;
    uint32_t active_max = 0;
    double near_field_fraction = 0;  // near-field finest cells / cells (naive: 1)

    // Which figures are estimates, and the fraction of the work actually run for them.
    bool prune_estimated = false, trace_estimated = false, discretize_estimated = false;
    bool stats_estimated = false;  // active_*, near_field_fraction, memory (no_hierarchy)
    double prune_sample = 1, trace_sample = 1, discretize_sample = 1;

    bool estimate() const {
        return prune_estimated || trace_estimated || discretize_estimated || stats_estimated;
    }
};

// Measures one variant on `scene` (row.scene and row.source are left empty for the caller).
// Throws what prune/render/discretize throw (std::bad_alloc included).
BenchRow run_variant(const Scene& scene, Variant variant, const BenchOptions& options);

// "builtin:demo" -> "demo", "../scenes/car-chase.json" -> "car-chase".
std::string scene_display_name(const std::string& source);

// Bytes of a scene's arrays (what the naive tracer reads), capacities included.
uint64_t scene_bytes(const Scene& scene);

// ---- reports ---------------------------------------------------------------------------------

struct MachineInfo {
    std::string cpu;            // /proc/cpuinfo "model name" (or "unknown")
    uint32_t cores = 0;         // hardware threads
    int threads = 0;            // threads the benchmark used (0 = all)
    uint64_t memory_bytes = 0;  // /proc/meminfo MemTotal
    std::string os;             // /etc/os-release PRETTY_NAME, else uname
    std::string compiler;       // the compiler that built the library (__VERSION__)
    std::string date;           // UTC, ISO 8601 ("2025-01-31T12:00:00Z")
};
MachineInfo machine_info(int threads = 0);

// {"machine": {...}, "rows": [...]} on one line, no trailing newline. Row fields: scene, source,
// nodes, primitives, variant, width, height, res, grid, prune_ms, trace_ms, discretize_ms (null
// when not measured), prune_peak_bytes, trace_bytes, active_avg, active_std, active_max,
// near_field_fraction, estimate (bool), estimated (names of the estimated fields), sample
// (fraction of the work run, per estimated time).
std::string bench_json(const MachineInfo& machine, std::span<const BenchRow> rows);

// Markdown: the machine, a summary table (speed-ups and Table 2 metric against the paper), then
// per scene a table of the variants (times, speed-ups over naive, memory, active primitives) and,
// when the paper has the scene, its Tables 1–2 figures for comparison. Rows of one scene are
// grouped by `scene` in order of first appearance.
std::string bench_markdown(const MachineInfo& machine, std::span<const BenchRow> rows);

// Cost against primitive count for a log-log plot (write_loglog_plot): series "prune",
// "trace", "discretize" (variant ours) and "naive trace", "naive discretize", one point per
// scene in order of primitive count, estimated points flagged; variants not in `rows` give
// empty series, which are left out.
std::vector<PlotSeries> bench_cost_series(std::span<const BenchRow> rows);

// ---- the paper's figures (bench/paper/*.csv, embedded at build time) --------------------------

// One variant's figures in the paper; NaN where the paper has none.
struct PaperFigures {
    double prune_ms = kNotMeasured, trace_ms = kNotMeasured, discretize_ms = kNotMeasured;
    double prune_gb = kNotMeasured, trace_gb = kNotMeasured;
    bool prune_gb_lower_bound = false;  // "11.5*": a theoretical lower bound
    bool did_not_finish = false;        // "x"
    double active_avg = kNotMeasured, active_std = kNotMeasured, active_max = kNotMeasured;
};
struct PaperScene {
    std::string name;  // as printed: "Car Chase"
    uint32_t nodes = 0;
    PaperFigures figures[4];  // indexed by Variant
    const PaperFigures& operator[](Variant v) const { return figures[int(v)]; }
};
// The paper's 14 scenes, parsed from the embedded tables.
const std::vector<PaperScene>& paper_scenes();
// The scene whose name matches `name` ignoring case, spaces, '-' and '_' ("car-chase" matches
// "Car Chase"); nullptr when none.
const PaperScene* find_paper_scene(std::string_view name);
// The embedded CSV texts, verbatim copies of bench/paper/table1.csv and table2.csv.
std::string_view paper_table1_csv();
std::string_view paper_table2_csv();

}  // namespace sdfprune
