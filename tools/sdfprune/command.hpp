// command.hpp — how the CLI's subcommands plug into main: each file registers its CLI11
// subcommand and the function that runs it. Conventions: --help everywhere; with --json the last
// stdout line is exactly one JSON object; exit 0 ok, 2 bad input (one-line message), 1 internal.
#pragma once

#include <CLI/CLI.hpp>

#include <functional>
#include <string>
#include <vector>

#include "json_line.hpp"
#include "sdfprune/prune.hpp"
#include "sdfprune/scene.hpp"

namespace sdfprune::cli {

struct Command {
    CLI::App* app;
    std::function<int()> run;
};

// Each subcommand file registers itself with a static CommandRegistrar; `order` sorts the
// subcommands in --help.
using AddCommand = void (*)(CLI::App& app, std::vector<Command>& commands);
struct CommandRegistrar {
    CommandRegistrar(int order, AddCommand add);
};
// The registered subcommands, sorted by order.
std::vector<AddCommand> registered_commands();

// The pruning flags shared by every subcommand that prunes (--grid, --no-farfield, ...).
void add_prune_options(CLI::App* sub, PruneOptions& options, bool& lipschitz_bounds);
// The options as given, with --lipschitz-bounds applied: the paper's centre ± L·R ranges and
// no sub-box refinement.
PruneOptions with_bounds_flag(PruneOptions options, bool lipschitz_bounds);
// Adds --backend cpu|vulkan (stats, render, discretize).
void add_backend_option(CLI::App* sub, std::string& backend);
uint64_t peak_rss_bytes();

// Loads a scene argument: a file path, or "builtin:NAME" for a scene made in code.
Scene load_scene_arg(const std::string& arg);

}  // namespace sdfprune::cli
