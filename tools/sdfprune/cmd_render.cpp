// cmd_render.cpp — `sdfprune render SCENE -o OUT.png`: a sphere-traced image (one primary and
// one shadow ray per pixel) on the pruned grid or, with --method naive, on the full tree.
#include <cstdio>
#include <sstream>

#include "app.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/render.hpp"

namespace sdfprune::cli {
namespace {

vec3 parse_vec3(const std::string& s) {
    vec3 v;
    char c1 = 0, c2 = 0;
    std::istringstream in(s);
    if (!(in >> v.x >> c1 >> v.y >> c2 >> v.z) || c1 != ',' || c2 != ',' || !in.eof())
        throw IoError("--target: expected x,y,z (got \"" + s + "\")");
    return v;
}

void add_render(CLI::App& app, std::vector<Command>& commands) {
    struct Args {
        std::string scene, out, target, shading = "shaded";
        uint32_t width = 1920, height = 1080;
        float yaw = 30, pitch = 25, distance = 0, fov = 40;
        bool no_shadows = false, no_tile_cones = false, no_convex_steps = false;
        AppOptions app;
    };
    auto a = std::make_shared<Args>();
    CLI::App* sub = app.add_subcommand(
        "render", "Sphere-trace an image: one primary and one shadow ray per pixel.");
    sub->add_option("SCENE", a->scene, "scene file (.json) or builtin:NAME")->required();
    sub->add_option("-o,--output", a->out, "output image (.png)")->required();
    sub->add_option("--width", a->width, "image width")
        ->capture_default_str()
        ->check(CLI::Range(1u, 16384u));
    sub->add_option("--height", a->height, "image height")
        ->capture_default_str()
        ->check(CLI::Range(1u, 16384u));
    sub->add_option("--yaw", a->yaw, "camera angle about +y, degrees (0 = from +z)")
        ->capture_default_str();
    sub->add_option("--pitch", a->pitch, "camera angle above the xz plane, degrees")
        ->capture_default_str()
        ->check(CLI::Range(-89.0f, 89.0f));
    sub->add_option("--distance", a->distance,
                    "camera distance to the target (default: frames the AABB)")
        ->check(CLI::PositiveNumber);
    sub->add_option("--target", a->target, "point looked at, x,y,z (default: AABB centre)");
    sub->add_option("--fov", a->fov, "vertical field of view, degrees")
        ->capture_default_str()
        ->check(CLI::Range(1.0f, 170.0f));
    sub->add_option("--shading", a->shading,
                    "shaded: colors, light, shadow; normals; heatmap: node evaluations per pixel")
        ->capture_default_str()
        ->check(CLI::IsMember({"shaded", "normals", "heatmap"}));
    sub->add_flag("--no-shadows", a->no_shadows, "trace primary rays only");
    sub->add_flag("--no-tile-cones", a->no_tile_cones,
                  "ablation: primary rays start at the box, not where their 8x8 tile's cone "
                  "stops (pruned CPU tracer)");
    sub->add_flag("--no-convex-steps", a->no_convex_steps,
                  "ablation: plain sphere-tracing steps in cells whose tape is one convex "
                  "primitive (pruned CPU tracer)");
    a->app.prune.clearance = true;  // the tracer's far-field skips (--no-clearance: off)
    add_app_options(sub, a->app);
    add_backend_option(sub, a->app.backend);
    sub->footer(
        "Examples:\n  sdfprune render scenes/molecule.json -o molecule.png\n"
        "  sdfprune render scenes/trees.json -o heat.png --shading heatmap --width 960 --height "
        "540\n"
        "  sdfprune render builtin:demo -o naive.png --method naive --json\n"
        "  sdfprune render scenes/molecule.json -o gpu.png --backend vulkan");
    commands.push_back(
        {sub, [a] {
             check_output(a->out, {".png"});
             vec3 target;
             if (!a->target.empty()) target = parse_vec3(a->target);
             Prepared prep = prepare(a->scene, a->app);
             const Scene& sc = *prep.scene;
             RenderOptions ro;
             ro.width = a->width;
             ro.height = a->height;
             ro.camera = orbit_camera(sc.aabb, a->yaw, a->pitch, a->distance, a->fov,
                                      a->target.empty() ? nullptr : &target);
             ro.shading = a->shading == "normals"   ? Shading::kNormals
                          : a->shading == "heatmap" ? Shading::kHeatmap
                                                    : Shading::kShaded;
             ro.shadows = !a->no_shadows;
             ro.tile_cones = !a->no_tile_cones;
             ro.convex_steps = !a->no_convex_steps;
             ro.threads = a->app.prune.threads;
             Progress bar("tracing", a->app.quiet);
             ro.progress = [&bar](double f) { bar.update(f); };
             RenderStats st;
             const Image img = prep.device_grid
                                   ? gpu::render(*prep.device, *prep.device_grid, ro, &st)
                               : prep.grid ? render(*prep.grid, ro, &st)
                                           : render_naive(sc, ro, &st);
             bar.done();
             write_png(img, a->out);
             if (a->app.json) {
                 JsonLine j;
                 j.add("scene", a->scene)
                     .add("output", a->out)
                     .add("method", a->app.method)
                     .add("backend", a->app.backend)
                     .add("width", a->width)
                     .add("height", a->height)
                     .add("nodes", sc.size())
                     .add("prune_ms", prep.prune_ms)
                     .add("trace_ms", st.trace_ms)
                     .add("steps_avg", st.steps_avg)
                     .add("evals_avg", st.evals_avg)
                     .add("hit_fraction", st.hit_fraction);
                 if (prep.stats()) j.add("grid", prep.stats()->grid);
                 if (prep.device)
                     j.add("device", prep.device->name())
                         .add("stack_words", st.stack_words)
                         .add("full_tree_pixels", st.full_tree_pixels);
                 std::printf("%s\n", j.str().c_str());
             } else if (!a->app.quiet) {
                 std::printf(
                     "wrote %s (%ux%u, %s, %s%s%s): prune %.1f ms, trace %.1f ms, %.1f steps "
                     "and %.0f node evaluations per pixel\n",
                     a->out.c_str(), a->width, a->height, a->shading.c_str(), a->app.method.c_str(),
                     prep.device ? ", Vulkan on " : "",
                     prep.device ? prep.device->name().c_str() : "", prep.prune_ms, st.trace_ms,
                     st.steps_avg, st.evals_avg);
             }
             return 0;
         }});
}

const CommandRegistrar registrar(30, add_render);

}  // namespace
}  // namespace sdfprune::cli
