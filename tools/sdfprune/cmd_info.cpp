// cmd_info.cpp — `sdfprune info SCENE [--json]`: what a scene contains.
#include <cstdio>

#include "command.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/io.hpp"

namespace sdfprune::cli {

Scene load_scene_arg(const std::string& arg) {
    constexpr std::string_view kBuiltin = "builtin:";
    if (arg.starts_with(kBuiltin)) return builtin_scene(arg.substr(kBuiltin.size()));
    return load_scene(arg);
}

void add_info(CLI::App& app, std::vector<Command>& commands) {
    struct Args {
        std::string scene;
        bool json = false;
    };
    auto args = std::make_shared<Args>();
    CLI::App* sub = app.add_subcommand("info",
                                       "Print what a scene contains (node counts, depth, "
                                       "bounds, Lipschitz bound).");
    sub->add_option("SCENE", args->scene, "scene file (.json) or builtin:NAME")->required();
    sub->add_flag("--json", args->json, "print the figures as one JSON object on the last line");
    sub->footer("Example: sdfprune info scenes/molecule.json --json");
    commands.push_back(
        {sub, [args] {
             const Scene sc = load_scene_arg(args->scene);
             const SceneInfo info = scene_info(sc);
             JsonLine kinds, ops;
             for (uint32_t k = 0; k < math::kPrimitiveKindCount; ++k)
                 kinds.add(primitive_kind_name(k), info.per_primitive_kind[k]);
             ops.add("union", info.unions)
                 .add("inter", info.intersections)
                 .add("sub", info.differences);
             if (args->json) {
                 JsonLine j;
                 j.add("scene", args->scene)
                     .add("nodes", info.nodes)
                     .add("primitives", info.primitives)
                     .add("operators", info.operators)
                     .add("smooth_operators", info.smooth_operators)
                     .add("depth", info.depth)
                     .add("aabb_min", sc.aabb.min)
                     .add("aabb_max", sc.aabb.max)
                     .add("max_lipschitz", info.max_lipschitz)
                     .add("primitive_kinds", kinds)
                     .add("operator_kinds", ops);
                 std::printf("%s\n", j.str().c_str());
                 return 0;
             }
             std::printf("%s\n", args->scene.c_str());
             std::printf("  nodes          %u (%u primitives, %u operators, %u smooth)\n",
                         info.nodes, info.primitives, info.operators, info.smooth_operators);
             std::printf("  depth          %u\n", info.depth);
             std::printf("  aabb           [%g, %g, %g] .. [%g, %g, %g]\n", sc.aabb.min.x,
                         sc.aabb.min.y, sc.aabb.min.z, sc.aabb.max.x, sc.aabb.max.y, sc.aabb.max.z);
             std::printf("  primitives    ");
             for (uint32_t k = 0; k < math::kPrimitiveKindCount; ++k)
                 if (info.per_primitive_kind[k])
                     std::printf(" %s %u", primitive_kind_name(k), info.per_primitive_kind[k]);
             std::printf("\n  operators      union %u, inter %u, sub %u\n", info.unions,
                         info.intersections, info.differences);
             std::printf("  max lipschitz  %.6g\n", info.max_lipschitz);
             return 0;
         }});
}

namespace {
const CommandRegistrar registrar(10, add_info);
}  // namespace

}  // namespace sdfprune::cli
