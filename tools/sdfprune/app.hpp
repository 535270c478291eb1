// app.hpp — what the application subcommands (render, discretize, mesh, eval) share: the
// --method/--grid/... flags, loading and pruning, output checks, the progress bar.
#pragma once

#include <chrono>
#include <initializer_list>
#include <memory>
#include <string>

#include "command.hpp"
#include "sdfprune/gpu.hpp"
#include "sdfprune/prune.hpp"
#include "src/core/clock.hpp"  // ms_since

namespace sdfprune::cli {

struct AppOptions {
    std::string method = "pruned";  // "pruned" or "naive" (the full tree at every query)
    std::string backend = "cpu";    // "cpu" or "vulkan" (where the subcommand offers --backend)
    PruneOptions prune;
    bool lipschitz_bounds = false;
    bool json = false;
    bool quiet = false;
    bool pruned() const { return method == "pruned"; }
    bool vulkan() const { return backend == "vulkan"; }
};

// Adds --method, --grid, --factor, --no-farfield, --no-hierarchy, --farfield-c,
// --lipschitz-bounds, --threads, --json, --quiet.
void add_app_options(CLI::App* sub, AppOptions& o);
// The same for subcommands that evaluate each finest cell once (discretize, mesh), where
// --refine defaults to 1 (off): refinement spends pruning time to make later queries cheaper,
// and with a single query per cell it costs more than it saves (molecule 256³: prune + eval
// 2.2× faster without it). The values stay exact in every near-field cell either way.
void add_one_shot_app_options(CLI::App* sub, AppOptions& o);

// Adds --res (the output grid's cells per axis, 1..max, default 256); with `following` the
// pruning grid follows it unless --grid is given (see following_res()).
void add_res_option(CLI::App* sub, uint32_t& res, const char* what, uint32_t max);
// The options with the pruning grid set to `res`, unless --grid was given explicitly: then
// small outputs don't pay for a 256³ pruning.
AppOptions following_res(const CLI::App* sub, const AppOptions& o, uint32_t res);

// A loaded scene and, for --method pruned, its pruned grid (prune_ms = 0 for naive): on the
// CPU (grid), or with --backend vulkan on the device (device, device_grid; prune_ms is GPU time).
struct Prepared {
    std::unique_ptr<Scene> scene;
    std::unique_ptr<PrunedGrid> grid;
    std::unique_ptr<gpu::Device> device;
    std::unique_ptr<gpu::Grid> device_grid;
    double prune_ms = 0;
    const PruneStats* stats() const {
        return grid ? &grid->stats() : device_grid ? &device_grid->stats() : nullptr;
    }
};
Prepared prepare(const std::string& scene_arg, const AppOptions& o);

// Refuses (IoError, exit status 2) an output path whose extension is not one of `extensions`
// (lower case, with the dot) or that cannot be written; returns the extension.
std::string check_output(const std::string& path, std::initializer_list<const char*> extensions);

// A progress bar on stderr, shown only when stderr is a terminal, not --quiet, and the work has
// lasted more than a second. update() is called from one thread.
class Progress {
  public:
    Progress(std::string label, bool quiet);
    ~Progress();
    void update(double fraction);
    void done();

  private:
    std::string label_;
    bool enabled_;
    bool shown_ = false;
    std::chrono::steady_clock::time_point start_;
};

}  // namespace sdfprune::cli
