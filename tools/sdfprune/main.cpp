// main.cpp — the sdfprune command-line tool: parses the subcommand and maps errors to exit codes
// (2 for bad input or unwritable output with a one-line message, 1 for internal errors).
#include <algorithm>
#include <cstdio>
#include <exception>

#include "command.hpp"
#include "sdfprune/gpu.hpp"
#include "sdfprune/io.hpp"

namespace sdfprune::cli {
namespace {
std::vector<std::pair<int, AddCommand>>& registry() {
    static std::vector<std::pair<int, AddCommand>> r;
    return r;
}
}  // namespace

CommandRegistrar::CommandRegistrar(int order, AddCommand add) {
    registry().push_back({order, add});
}

std::vector<AddCommand> registered_commands() {
    auto r = registry();
    std::stable_sort(r.begin(), r.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    std::vector<AddCommand> out;
    for (const auto& [order, add] : r) out.push_back(add);
    return out;
}
}  // namespace sdfprune::cli

int main(int argc, char** argv) {
    using namespace sdfprune;
    CLI::App app{
        "sdfprune — fast evaluation of primitive-based signed distance fields by Lipschitz "
        "pruning (Barbier et al., Eurographics 2025)."};
    app.require_subcommand(1);
    app.set_version_flag("--version", "sdfprune 0.1.0");
    std::vector<cli::Command> commands;
    for (cli::AddCommand add : cli::registered_commands()) add(app, commands);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        const int code = app.exit(e);
        return code == 0 ? 0 : 2;
    }
    try {
        for (const cli::Command& c : commands)
            if (c.app->parsed()) return c.run();
    } catch (const SceneError& e) {
        std::fprintf(stderr, "sdfprune: %s\n", e.what());
        return 2;
    } catch (const IoError& e) {
        std::fprintf(stderr, "sdfprune: %s\n", e.what());
        return 2;
    } catch (const gpu::GpuError& e) {
        std::fprintf(stderr, "sdfprune: %s\n", e.what());
        return 2;
    } catch (const std::invalid_argument& e) {
        std::fprintf(stderr, "sdfprune: %s\n", e.what());
        return 2;
    } catch (const std::bad_alloc&) {
        std::fprintf(stderr, "sdfprune: out of memory\n");
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "sdfprune: internal error: %s\n", e.what());
        return 1;
    }
    return 1;
}
