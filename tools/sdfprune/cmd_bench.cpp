// cmd_bench.cpp — `sdfprune bench SCENE...`: the paper's Tables 1–2 measured on this machine
// (ours, no far field, no hierarchy, naive) for each scene, as JSON and markdown beside the
// paper's figures (Barbier et al., EG 2025). The work is in src/bench (sdfprune/bench.hpp).
#include <cmath>
#include <cstdio>
#include <sstream>

#include "app.hpp"
#include "sdfprune/bench.hpp"
#include "sdfprune/io.hpp"

namespace sdfprune::cli {
namespace {

std::vector<Variant> parse_variants(const std::string& list) {
    std::vector<Variant> out;
    std::stringstream in(list);
    std::string name;
    while (std::getline(in, name, ',')) {
        Variant v;
        if (!variant_from_name(name, v))
            throw IoError("--variants: unknown variant \"" + name +
                          "\" (expected ours, no_farfield, no_hierarchy, naive)");
        out.push_back(v);
    }
    if (out.empty()) throw IoError("--variants: empty list");
    return out;
}

std::string ms_or_dash(double ms, bool estimated) {
    if (!std::isfinite(ms)) return "not measured";
    char buf[48];
    std::snprintf(buf, sizeof buf, "%s%.1f ms", estimated ? "~" : "", ms);
    return buf;
}

void add_bench(CLI::App& app, std::vector<Command>& commands) {
    struct Args {
        std::vector<std::string> scenes;
        std::string out, md, plot, variants = "ours,no_farfield,no_hierarchy,naive";
        BenchOptions bench;
        bool json = false, quiet = false;
    };
    auto a = std::make_shared<Args>();
    CLI::App* sub = app.add_subcommand(
        "bench",
        "Measure the paper's Tables 1-2 on this machine: for each scene and each variant (ours, "
        "no_farfield, no_hierarchy, naive) the pruning time, tracing time (one primary + one "
        "shadow ray per pixel), discretization time, memory and active primitives per cell. "
        "Measurements projected beyond --budget-s are estimated from a sample of pixels or "
        "cells and marked as estimates.");
    sub->add_option("SCENE", a->scenes, "scene files (.json) or builtin:NAME")->required();
    sub->add_option("--width", a->bench.width, "traced image width")
        ->capture_default_str()
        ->check(CLI::Range(1u, 16384u));
    sub->add_option("--height", a->bench.height, "traced image height")
        ->capture_default_str()
        ->check(CLI::Range(1u, 16384u));
    sub->add_option("--res", a->bench.res, "discretization resolution (cells per axis)")
        ->capture_default_str()
        ->check(CLI::Range(1u, 2048u));
    sub->add_option("--grid", a->bench.grid, "pruning grid resolution (default: --res)")
        ->check(CLI::Range(1u, 4096u));
    sub->add_option("--variants", a->variants, "comma-separated subset of the variants")
        ->capture_default_str();
    sub->add_option("--budget-s", a->bench.budget_s,
                    "seconds a measurement may take before it is estimated from a sample")
        ->capture_default_str()
        ->check(CLI::Range(1e-6, 1e6));
    sub->add_option("--threads", a->bench.threads, "worker threads (0 = all cores)")
        ->capture_default_str()
        ->check(CLI::Range(0, 1024));
    sub->add_option("-o,--output", a->out, "write {\"machine\": ..., \"rows\": [...]} (.json)");
    sub->add_option("--md", a->md, "write the tables beside the paper's figures (.md)");
    sub->add_option("--plot", a->plot,
                    "write a log-log plot of time against primitive count (.png)");
    sub->add_flag("--json", a->json, "print the same JSON object as the last stdout line");
    sub->add_flag("--quiet", a->quiet, "no progress messages on stderr");
    sub->footer(
        "Examples:\n  sdfprune bench ../shared/scenes/molecule.json --md molecule.md\n"
        "  sdfprune bench builtin:demo --width 480 --height 270 --res 128 -o demo.json\n"
        "  sdfprune bench scenes/*.json --variants ours,naive --budget-s 5 --json");
    commands.push_back(
        {sub, [a] {
             const std::vector<Variant> variants = parse_variants(a->variants);
             if (!a->out.empty()) check_output(a->out, {".json"});
             if (!a->md.empty()) check_output(a->md, {".md"});
             if (!a->plot.empty()) check_output(a->plot, {".png"});
             BenchOptions o = a->bench;
             if (!a->quiet)
                 o.log = [](const std::string& m) {
                     std::fprintf(stderr, "bench: %s\n", m.c_str());
                 };
             const MachineInfo machine = machine_info(o.threads);
             std::vector<BenchRow> rows;
             for (const std::string& source : a->scenes) {
                 const Scene scene = load_scene_arg(source);
                 for (Variant v : variants) {
                     if (o.log)
                         o.log(scene_display_name(source) + " (" + std::to_string(scene.size()) +
                               " nodes): " + variant_name(v));
                     BenchRow row = run_variant(scene, v, o);
                     row.scene = scene_display_name(source);
                     row.source = source;
                     if (!a->json)
                         std::printf(
                             "%s %s: prune %s, trace %s, discretize %s, active %.3f ± %.3f "
                             "(max %u)%s\n",
                             row.scene.c_str(), variant_name(v),
                             v == Variant::kNaive
                                 ? "none"
                                 : ms_or_dash(row.prune_ms, row.prune_estimated).c_str(),
                             ms_or_dash(row.trace_ms, row.trace_estimated).c_str(),
                             ms_or_dash(row.discretize_ms, row.discretize_estimated).c_str(),
                             row.active_avg, row.active_std, row.active_max,
                             row.estimate() ? " (~ estimated)" : "");
                     std::fflush(stdout);
                     rows.push_back(std::move(row));
                 }
             }
             const std::string json = bench_json(machine, rows);
             if (!a->out.empty()) write_file_atomic(a->out, json + "\n");
             if (!a->md.empty())
                 write_file_atomic(a->md, "# sdfprune bench\n\n" + bench_markdown(machine, rows));
             if (!a->plot.empty()) {
                 PlotOptions po;
                 po.title = "sdfprune bench: time against primitive count";
                 po.y_label = "time (ms)";
                 write_loglog_plot(a->plot, bench_cost_series(rows), po);
             }
             if (a->json) {
                 std::printf("%s\n", json.c_str());
             } else {
                 for (const std::string* path : {&a->out, &a->md, &a->plot})
                     if (!path->empty()) std::printf("wrote %s\n", path->c_str());
             }
             return 0;
         }});
}

const CommandRegistrar registrar(80, add_bench);

}  // namespace
}  // namespace sdfprune::cli
