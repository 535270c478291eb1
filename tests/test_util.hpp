// test_util.hpp — helpers shared by the tests: locating the reference scenes, running the CLI,
// comparing images, a scene built for the tracer's convex steps.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "sdfprune/render.hpp"
#include "sdfprune/scene.hpp"

namespace sdfprune::test {

// The reference scenes folder ($SDFPRUNE_SCENES, else ../shared/scenes), or "" when absent.
inline std::string scenes_dir() {
    if (const char* env = std::getenv("SDFPRUNE_SCENES"); env && *env)
        return std::filesystem::is_directory(env) ? env : "";
    return std::filesystem::is_directory(SDFPRUNE_DEFAULT_SCENES) ? SDFPRUNE_DEFAULT_SCENES : "";
}

// Path of a reference scene, or skips the calling test with a message when it is absent.
#define SDFPRUNE_REQUIRE_SCENE(var, file)                                                  \
    std::string var;                                                                       \
    do {                                                                                   \
        const std::string dir_ = ::sdfprune::test::scenes_dir();                           \
        if (dir_.empty() || !std::filesystem::exists(dir_ + "/" + (file)))                 \
            GTEST_SKIP() << "reference scene " << (file)                                   \
                         << " not found (set SDFPRUNE_SCENES or put ../shared beside the " \
                            "checkout)";                                                   \
        var = dir_ + "/" + (file);                                                         \
    } while (0)

struct CliResult {
    int status = -1;
    std::string out;  // stdout
    std::string err;  // stderr
};

// Runs the sdfprune CLI with `args` (shell-quoted by the caller) and captures its output;
// `env` is prefixed to the command (e.g. "VAR=value").
CliResult run_cli(const std::string& args, const std::string& env = "");

// How many pixels of two images of one size differ by more than `tolerance` in some channel.
size_t pixels_differing(const Image& a, const Image& b, int tolerance);

// Grains just above a floor (a box): at 128³, blocks of finest cells that hold the floor's face
// alone, and blocks that hold a grain too (the tracer's convex blocks, and the others).
Scene grains_on_floor();

}  // namespace sdfprune::test
