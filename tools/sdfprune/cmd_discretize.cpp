// cmd_discretize.cpp — `sdfprune discretize SCENE -o OUT.npy|OUT.vdb [--res N]`: the SDF at the
// cell centres of an N³ grid over the scene's AABB (DESIGN.md §6), written as a NumPy array or
// an OpenVDB level set. Timings separate pruning from evaluation so that --method naive
// measures what pruning buys.
#include <cstdio>

#include "app.hpp"
#include "sdfprune/discretize.hpp"
#include "sdfprune/npy.hpp"
#include "sdfprune/vdb.hpp"

namespace sdfprune::cli {

void add_discretize(CLI::App& app, std::vector<Command>& commands) {
    struct Args {
        std::string scene, output;
        uint32_t res = 256;
        AppOptions app;
    };
    auto args = std::make_shared<Args>();
    CLI::App* sub = app.add_subcommand(
        "discretize",
        "Sample the SDF at the cell centres of an N³ grid spanning the scene's AABB (float32). "
        ".npy: shape (N, N, N), C order, indexed [z][y][x]. .vdb: an OpenVDB level set "
        "(grid \"surface\", narrow band of 3 voxels). With --method pruned, near-field cells "
        "are exact and far-field cells hold their conservative bound (right sign, magnitude "
        "never above the distance).");
    sub->add_option("SCENE", args->scene, "scene file (.json) or builtin:NAME")->required();
    sub->add_option("-o,--output", args->output, "output file, .npy or .vdb")->required();
    add_res_option(sub, args->res, "cells", 2048u);
    add_one_shot_app_options(sub, args->app);
    add_backend_option(sub, args->app.backend);
    sub->footer(
        "Examples:\n  sdfprune discretize scenes/molecule.json -o molecule.npy --res 256\n"
        "  sdfprune discretize scenes/trees.json -o trees.vdb --res 512\n"
        "  sdfprune discretize scenes/molecule.json -o m.npy --method naive --json\n"
        "  sdfprune discretize scenes/molecule.json -o m.npy --backend vulkan");
    commands.push_back(
        {sub, [args, sub] {
             const AppOptions& o = args->app;
             const std::string ext = check_output(args->output, {".npy", ".vdb"});
             const uint32_t n = args->res;
             const AppOptions po = following_res(sub, o, n);
             // Allocated (and touched) before any timing, the same for both methods.
             std::vector<float> values(uint64_t(n) * n * n);

             const Prepared p = prepare(args->scene, po);
             const auto t0 = std::chrono::steady_clock::now();
             double eval_ms = 0;
             gpu::DiscretizeStats gpu_stats;
             if (p.device_grid) {
                 gpu::discretize(*p.device, *p.device_grid, n, values, &gpu_stats);
                 eval_ms = gpu_stats.gpu_ms;
             } else {
                 Progress bar("discretizing", o.quiet);
                 const auto cb = [&bar](double f) { bar.update(f); };
                 if (p.grid)
                     discretize_pruned(*p.grid, n, values, cb);
                 else
                     discretize_naive(*p.scene, n, values, o.prune.threads, cb);
             }
             if (!p.device_grid) eval_ms = ms_since(t0);

             const auto t1 = std::chrono::steady_clock::now();
             if (ext == ".npy") {
                 const uint64_t shape[3] = {n, n, n};
                 write_npy(args->output, shape, values);
             } else {
                 write_vdb_level_set(args->output, p.scene->aabb, n, values);
             }
             const double write_ms = ms_since(t1);

             if (!o.quiet) {
                 std::printf("wrote %s: %u³ float32 SDF samples (%s) of %s\n", args->output.c_str(),
                             n, ext == ".npy" ? "[z][y][x]" : "OpenVDB level set \"surface\"",
                             args->scene.c_str());
                 if (const PruneStats* s = p.stats())
                     std::printf(
                         "  pruned (grid %u³, %llu near-field cells exact, others their "
                         "far-field bound%s%s): prune %.1f ms, eval %.1f ms\n",
                         s->grid, (unsigned long long)s->near_field_cells,
                         p.device ? "; GPU times on " : "",
                         p.device ? p.device->name().c_str() : "", p.prune_ms, eval_ms);
                 else
                     std::printf("  naive (full tree at every cell): eval %.1f ms\n", eval_ms);
             }
             if (o.json) {
                 JsonLine j;
                 j.add("scene", args->scene)
                     .add("path", args->output)
                     .add("format", ext.substr(1))
                     .add("res", n)
                     .add("method", o.method)
                     .add("backend", o.backend)
                     .add("prune_ms", p.prune_ms)
                     .add("eval_ms", eval_ms)
                     .add("write_ms", write_ms);
                 if (const PruneStats* s = p.stats()) {
                     std::string levels;
                     for (uint32_t r : s->levels)
                         levels += (levels.empty() ? "" : "x") + std::to_string(r);
                     j.add("grid", s->grid)
                         .add("levels", levels)
                         .add("refine", po.prune.refine)
                         .add("near_field_cells", s->near_field_cells);
                 }
                 if (p.device)
                     j.add("device", p.device->name())
                         .add("stack_words", gpu_stats.stack_words)
                         .add("full_tree_samples", gpu_stats.full_tree_samples);
                 std::printf("%s\n", j.str().c_str());
             }
             return 0;
         }});
}

namespace {
const CommandRegistrar registrar(40, add_discretize);
}  // namespace

}  // namespace sdfprune::cli
