// cmd_view.cpp — `sdfprune view SCENE`: the interactive viewer, a local web server (src/view/)
// serving a page that orbits, shades and edits the scene, re-pruning edits incrementally.
#include <signal.h>

#include <cstdio>
#include <cstdlib>
#include <thread>

#include "command.hpp"
#include "sdfprune/gpu.hpp"
#include "sdfprune/io.hpp"
#include "view_server.hpp"

namespace sdfprune::cli {
namespace {

void add_view(CLI::App& app, std::vector<Command>& commands) {
    struct Args {
        std::string scene, backend = "cpu";
        int port = 8080;
        bool open = false, lipschitz = false;
        PruneOptions prune;
    };
    auto a = std::make_shared<Args>();
    CLI::App* sub = app.add_subcommand(
        "view", "Serve an interactive viewer and editor of a scene file on 127.0.0.1.");
    sub->add_option("SCENE", a->scene, "scene file (.json); watched, and saved by the editor")
        ->required();
    sub->add_option("--port", a->port, "TCP port on 127.0.0.1 (0: any free port)")
        ->capture_default_str()
        ->check(CLI::Range(0, 65535));
    sub->add_option("--backend", a->backend, "cpu, or vulkan: prune and trace on the GPU")
        ->capture_default_str()
        ->check(CLI::IsMember({"cpu", "vulkan"}));
    sub->add_flag("--open", a->open, "open the page in the desktop's browser (xdg-open)");
    a->prune.clearance = true;  // a tracing app, as `render` (--no-clearance: off)
    add_prune_options(sub, a->prune, a->lipschitz);
    sub->footer(
        "The page orbits (drag), zooms (wheel or pinch) and pans (right or shift drag); renders "
        "coarse while moving and full size at rest; shows shaded, normals and heat map views, "
        "pruned or naive; click a surface to select the primitive that decides it, edit it in the "
        "panel (undo, redo, save). The file is reloaded when it changes on disk.\n\n"
        "Examples:\n  sdfprune view scenes/molecule.json\n"
        "  sdfprune view scenes/trees.json --port 9000 --grid 128 --open");
    commands.push_back(
        {sub, [a] {
             if (a->backend == "vulkan" && !gpu::built_with_vulkan())
                 throw std::invalid_argument("--backend vulkan: this build has no Vulkan backend");
             // SIGINT and SIGTERM end the server from a thread of its own:
             // blocked here, before any other thread exists, so in all of them.
             sigset_t stop_signals;
             sigemptyset(&stop_signals);
             sigaddset(&stop_signals, SIGINT);
             sigaddset(&stop_signals, SIGTERM);
             pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
             view::SessionOptions so;
             so.backend = a->backend;
             so.prune = with_bounds_flag(a->prune, a->lipschitz);
             view::Session session(a->scene, so);
             view::Server server(session);
             const int port = server.bind(a->port);
             std::thread waiter([&] {
                 int sig = 0;
                 sigwait(&stop_signals, &sig);
                 server.stop();
             });
             const std::string url = "http://127.0.0.1:" + std::to_string(port) + "/";
             std::printf("sdfprune view: serving %s at %s (Ctrl-C to stop)\n", a->scene.c_str(),
                         url.c_str());
             std::fflush(stdout);
             if (a->open) {
                 const std::string cmd = "xdg-open '" + url + "' >/dev/null 2>&1 &";
                 if (std::system(cmd.c_str()) != 0)
                     std::fprintf(stderr, "sdfprune view: could not open a browser\n");
             }
             server.run();
             // The waiter is still in sigwait when stop() came from elsewhere.
             pthread_kill(waiter.native_handle(), SIGTERM);
             waiter.join();
             return 0;
         }});
}

const CommandRegistrar registrar(35, add_view);

}  // namespace
}  // namespace sdfprune::cli
