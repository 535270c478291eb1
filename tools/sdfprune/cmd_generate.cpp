// cmd_generate.cpp — `sdfprune generate KIND [--seed S] [--count N] -o OUT.json`: writes one of
// the procedural stand-ins for the paper's scenes (include/sdfprune/generate.hpp) in the
// reference scene format.
#include <chrono>
#include <cstdio>

#include "app.hpp"
#include "sdfprune/generate.hpp"
#include "sdfprune/io.hpp"

namespace sdfprune::cli {
namespace {

void add_generate(CLI::App& app, std::vector<Command>& commands) {
    struct Args {
        std::string kind, out;
        uint64_t seed = 1;
        uint32_t count = 0;
        bool json = false;
    };
    auto args = std::make_shared<Args>();
    std::string kinds_help =
        "KIND, one of (paper's node count; scalable kinds say what --count counts):";
    for (const GeneratorInfo& g : generator_info())
        kinds_help += "\n  " + g.kind +
                      std::string(g.kind.size() < 14 ? 14 - g.kind.size() : 1, ' ') +
                      std::to_string(g.paper_nodes) + " nodes  " + g.summary;
    CLI::App* sub = app.add_subcommand(
        "generate",
        "Write a procedural scene shaped like one of the paper's (same node count "
        "within 5 %), deterministic for a seed.");
    sub->add_option("KIND", args->kind, "what to generate (see below)")
        ->required()
        ->check(CLI::IsMember(generator_kinds()));
    sub->add_option("-o,--output", args->out, "output scene file (.json)")->required();
    sub->add_option("--seed", args->seed, "random seed: same seed, same scene")
        ->capture_default_str();
    sub->add_option("--count", args->count,
                    "size of a scalable kind (city, crowd: primitives; molecule: atoms; fluid: "
                    "spheres), up to " +
                        std::to_string(kMaxGeneratedPrimitives) + "; 0 = the paper's size")
        ->capture_default_str();
    sub->add_flag("--json", args->json, "print a summary as one JSON object on the last line");
    sub->footer(kinds_help +
                "\n\nExamples:\n  sdfprune generate car -o car.json\n"
                "  sdfprune generate city --seed 3 --count 20000 -o city.json --json\n"
                "  sdfprune generate fluid --count 1000000 -o fluid.json");
    commands.push_back({sub, [args] {
                            check_output(args->out, {".json"});
                            const auto t0 = std::chrono::steady_clock::now();
                            const Scene scene = generate_scene(args->kind, args->seed, args->count);
                            save_scene(scene, args->out);
                            const double ms = ms_since(t0);
                            if (args->json) {
                                JsonLine j;
                                j.add("kind", args->kind)
                                    .add("seed", args->seed)
                                    .add("count", args->count)
                                    .add("nodes", scene.size())
                                    .add("primitives", scene.primitive_count())
                                    .add("path", args->out)
                                    .add("ms", ms);
                                std::printf("%s\n", j.str().c_str());
                                return 0;
                            }
                            std::printf("%s: %s, seed %llu: %u nodes (%u primitives) in %.0f ms\n",
                                        args->out.c_str(), args->kind.c_str(),
                                        (unsigned long long)args->seed, scene.size(),
                                        scene.primitive_count(), ms);
                            return 0;
                        }});
}

const CommandRegistrar registrar(70, add_generate);

}  // namespace
}  // namespace sdfprune::cli
