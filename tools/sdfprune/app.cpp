// app.cpp — shared plumbing of the application subcommands.
#include "app.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

#include "sdfprune/io.hpp"

namespace sdfprune::cli {

void add_app_options(CLI::App* sub, AppOptions& o) {
    sub->add_option("--method", o.method,
                    "pruned: the pruned grid (default); naive: the full tree at every query")
        ->capture_default_str()
        ->check(CLI::IsMember({"pruned", "naive"}));
    add_prune_options(sub, o.prune, o.lipschitz_bounds);
    sub->add_flag("--json", o.json, "print the figures as one JSON object on the last line");
    sub->add_flag("--quiet", o.quiet, "no progress bar and no summary line");
}

void add_one_shot_app_options(CLI::App* sub, AppOptions& o) {
    o.prune.refine = 1;
    add_app_options(sub, o);
}

void add_backend_option(CLI::App* sub, std::string& backend) {
    sub->add_option("--backend", backend,
                    "cpu (default) or vulkan: prune and evaluate on a Vulkan device (the first "
                    "GPU; SDFPRUNE_VULKAN_DEVICE=N picks another)")
        ->capture_default_str()
        ->check(CLI::IsMember({"cpu", "vulkan"}));
}

void add_res_option(CLI::App* sub, uint32_t& res, const char* what, uint32_t max) {
    sub->add_option(
           "--res", res,
           std::string(what) + " per axis; the pruning grid follows it unless --grid is given")
        ->capture_default_str()
        ->check(CLI::Range(1u, max));
}

AppOptions following_res(const CLI::App* sub, const AppOptions& o, uint32_t res) {
    AppOptions r = o;
    if (sub->get_option("--grid")->count() == 0) r.prune.resolution = res;
    return r;
}

Prepared prepare(const std::string& scene_arg, const AppOptions& o) {
    Prepared p;
    p.scene = std::make_unique<Scene>(load_scene_arg(scene_arg));
    if (o.vulkan() && !o.pruned())
        throw std::invalid_argument(
            "--backend vulkan runs the pruned method only (drop "
            "--method naive, or use --backend cpu)");
    if (!o.pruned()) return p;
    PruneOptions po = with_bounds_flag(o.prune, o.lipschitz_bounds);
    if (o.vulkan()) {
        p.device = std::make_unique<gpu::Device>();
        p.device_grid = std::make_unique<gpu::Grid>(gpu::prune(*p.device, *p.scene, po));
        p.prune_ms = p.device_grid->stats().prune_ms;
        return p;
    }
    Progress bar("pruning", o.quiet);
    po.progress = [&bar](double f) { bar.update(f); };
    p.grid = std::make_unique<PrunedGrid>(prune(*p.scene, po));
    bar.done();
    p.prune_ms = p.grid->stats().prune_ms;
    return p;
}

std::string check_output(const std::string& path, std::initializer_list<const char*> extensions) {
    const std::string ext = extension_of(path);
    std::string known;
    for (const char* e : extensions) {
        if (ext == e) {
            check_writable(path);
            return ext;
        }
        known += (known.empty() ? "" : ", ") + std::string(e);
    }
    throw IoError(path + ": unknown output extension \"" + ext + "\" (expected " + known + ")");
}

Progress::Progress(std::string label, bool quiet)
    : label_(std::move(label)),
      enabled_(!quiet && ::isatty(STDERR_FILENO)),
      start_(std::chrono::steady_clock::now()) {}

Progress::~Progress() {
    done();
}

void Progress::update(double fraction) {
    if (!enabled_ || ms_since(start_) < 1000) return;
    shown_ = true;
    const int width = 30, filled = int(std::clamp(fraction, 0.0, 1.0) * width + 0.5);
    std::fprintf(stderr, "\r%-12s [%s%s] %3d%%", label_.c_str(), std::string(filled, '#').c_str(),
                 std::string(width - filled, '.').c_str(), int(fraction * 100 + 0.5));
    std::fflush(stderr);
}

void Progress::done() {
    if (shown_) {
        update(1.0);
        std::fprintf(stderr, "\n");
        shown_ = false;
    }
    enabled_ = false;
}

}  // namespace sdfprune::cli
