// cmd_eval.cpp — `sdfprune eval SCENE POINTS.npy -o OUT.npy`: the SDF at a batch of points,
// (M, 3) float32 in, (M,) float32 out. --method pruned answers through the pruned grid
// (PrunedGrid::eval: exact in near-field cells, the conservative far-field bound elsewhere, the
// full tree outside the AABB); --method naive evaluates the full tree at every point.
#include <cstdio>

#include "app.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/npy.hpp"

namespace sdfprune::cli {

void add_eval(CLI::App& app, std::vector<Command>& commands) {
    struct Args {
        std::string scene, points, output;
        AppOptions app;
    };
    auto args = std::make_shared<Args>();
    CLI::App* sub = app.add_subcommand(
        "eval",
        "Evaluate the SDF at points: POINTS.npy holds an (M, 3) float32 array (x, y, z per "
        "row), OUT.npy receives (M,) float32. With --method pruned, points in far-field cells "
        "get the cell's conservative bound (right sign, magnitude never above the distance); "
        "use --method naive or --no-farfield for exact values everywhere.");
    sub->add_option("SCENE", args->scene, "scene file (.json) or builtin:NAME")->required();
    sub->add_option("POINTS", args->points, "(M, 3) float32 .npy file of points")->required();
    sub->add_option("-o,--output", args->output, "output .npy file")->required();
    add_app_options(sub, args->app);
    sub->footer(
        "Examples:\n  sdfprune eval scenes/molecule.json points.npy -o values.npy\n"
        "  sdfprune eval builtin:demo points.npy -o exact.npy --method naive --json");
    commands.push_back(
        {sub, [args] {
             const AppOptions& o = args->app;
             check_output(args->output, {".npy"});
             const NpyArray in = read_npy(args->points);
             if (in.shape.size() != 2 || in.shape[1] != 3) {
                 std::string shape;
                 for (uint64_t d : in.shape)
                     shape += (shape.empty() ? "" : ", ") + std::to_string(d);
                 throw IoError(args->points + ": expected an (M, 3) array of points, got shape (" +
                               shape + (in.shape.size() == 1 ? ",)" : ")"));
             }
             const uint64_t m = in.shape[0];
             std::vector<vec3> points(m);
             for (uint64_t i = 0; i < m; ++i)
                 points[i] = vec3(in.data[3 * i], in.data[3 * i + 1], in.data[3 * i + 2]);
             std::vector<float> values(m);

             const Prepared p = prepare(args->scene, o);
             const auto t0 = std::chrono::steady_clock::now();
             {
                 // In slices, so a long naive run shows progress.
                 Progress bar("evaluating", o.quiet);
                 constexpr uint64_t kSlice = uint64_t(1) << 20;
                 for (uint64_t at = 0; at < m; at += kSlice) {
                     const uint64_t len = std::min(kSlice, m - at);
                     const std::span<const vec3> pts(points.data() + at, len);
                     const std::span<float> out(values.data() + at, len);
                     if (p.grid)
                         p.grid->eval_points(pts, out);
                     else
                         eval_points(*p.scene, pts, out, {o.prune.threads});
                     bar.update(double(at + len) / double(m));
                 }
             }
             const double eval_ms = ms_since(t0);
             const uint64_t shape[1] = {m};
             write_npy(args->output, shape, values);

             if (!o.quiet)
                 std::printf("wrote %s: %llu float32 SDF values (%s) at the points of %s\n",
                             args->output.c_str(), (unsigned long long)m,
                             p.grid ? "pruned" : "naive", args->points.c_str());
             if (o.json) {
                 JsonLine j;
                 j.add("scene", args->scene)
                     .add("path", args->output)
                     .add("points", m)
                     .add("method", o.method)
                     .add("prune_ms", p.prune_ms)
                     .add("eval_ms", eval_ms);
                 if (p.grid) j.add("grid", p.grid->resolution());
                 std::printf("%s\n", j.str().c_str());
             }
             return 0;
         }});
}

namespace {
const CommandRegistrar registrar(60, add_eval);
}  // namespace

}  // namespace sdfprune::cli
