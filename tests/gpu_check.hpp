// gpu_check.hpp — helpers of the Vulkan backend's tests (gpu_*test.cpp): the one device, devices
// made with environment settings, settings set for a scope, the checks that a device's grid is
// the CPU's (or another device grid's, or holds what every grid must), and deep chains.
#pragma once

#include <gtest/gtest.h>

#include <cstdint>
#include <initializer_list>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "sdfprune/builder.hpp"
#include "sdfprune/gpu.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune::test {

// ---- devices and environment settings -----------------------------------------------------------

// One device for the whole test binary; a build with Vulkan must find one (make setup installs
// lavapipe), a build without it skips.
gpu::Device* device(std::string& why);

#define SDFPRUNE_REQUIRE_DEVICE(var)                                                               \
    if (!::sdfprune::gpu::built_with_vulkan()) GTEST_SKIP() << "built without the Vulkan backend"; \
    std::string why_;                                                                              \
    ::sdfprune::gpu::Device* var = ::sdfprune::test::device(why_);                                 \
    ASSERT_NE(var, nullptr) << "no Vulkan device (install mesa-vulkan-drivers): " << why_

// Environment variables, each a name and a value.
using EnvSettings = std::initializer_list<std::pair<const char*, const char*>>;

// Environment variables set for a scope (settings the device reads as it is made, or the pruner
// as it runs), then put back as they were, last set first back: unset where they were unset,
// else their value before (a run may set some for all tests). A failed assertion that returns
// early puts them back too.
class ScopedEnv {
  public:
    explicit ScopedEnv(EnvSettings settings);
    ScopedEnv(const char* name, const char* value) : ScopedEnv({{name, value}}) {}
    ~ScopedEnv();
    ScopedEnv(const ScopedEnv&) = delete;
    ScopedEnv& operator=(const ScopedEnv&) = delete;

  private:
    std::vector<std::pair<std::string, std::optional<std::string>>> before_;  // name, value
};

// A pruning with the environment variables `settings` set for its duration.
gpu::Grid prune_with_env(gpu::Device& dev, const Scene& sc, const PruneOptions& o,
                         EnvSettings settings);
gpu::Grid prune_with_env(gpu::Device& dev, const Scene& sc, const PruneOptions& o, const char* name,
                         const char* value);

// A device made with environment variables set (for the figures it reads once); null, with a
// test failure, where none can be made.
std::unique_ptr<gpu::Device> device_with_envs(EnvSettings settings);
std::unique_ptr<gpu::Device> device_with_env(const char* name, const char* value);
// A device that plans its steps for an H100's or H200's resident lanes (132 SMs of 2,048), so
// that lavapipe takes the shapes a GPU takes.
std::unique_ptr<gpu::Device> device_planned_as_h100();

// ---- checks -------------------------------------------------------------------------------------

// Whether the device is Mesa's lavapipe (llvmpipe), the CPU's Vulkan driver.
bool is_lavapipe(const gpu::Device& dev);

// Whether the device should give the CPU's grids bit for bit: lavapipe (the same LLVM code
// generation rules as the CPU build, no fused multiply-add). Other drivers may round a centre
// or a bound differently and so decide a borderline operator or cell the other way; there the
// tests check what a grid must guarantee instead (expect_valid_cells). SDFPRUNE_GPU_EXACT=0 or
// 1 overrides the choice.
bool exact_device(const gpu::Device& dev);

// On an exact device the same statistics; elsewhere within 1 % (cells that flip near a
// decision's margin move the averages a little).
void expect_same_stats(const PruneStats& cpu, const PruneStats& gpu, const std::string& what,
                       bool exact = true);

// A step's walks as measured on `dev`: some, the longest within `slack` times the planned
// bound (twice: a team's lane may pass from one phase to the next within a step; a wide lane's
// bound counts its searches by the scene's mean steps, the jobs after a workgroup's first by
// their mean tape, and a chain's top-down pass round by round), and all workgroups' walks at
// least the longest and at most as if every workgroup walked as long. Where the workgroups
// took their jobs as they came free on a device without a loop limit (not lavapipe, which caps
// a workgroup's takes at its dealt share), twice that again: a workgroup that runs early may
// take more than its dealt share, up to as many times more as the planned workgroups
// outnumber those that fit the device at once (an H100 fits 2,376 of the team steps' 4,224);
// lavapipe planned as a GPU (SDFPRUNE_VULKAN_LOOP_LIMITED=0) is not held to the bound there.
void expect_walks_within_bound(const gpu::Device& dev, const gpu::GpuStepShape& st,
                               const std::string& what, uint64_t slack = 2);

// Whether a tape walk can run `tape`: every word names a node of the scene, each operator finds
// two values on the stack, which is at most scene.max_stack deep, and one value is left. (A
// broken kernel's tape must fail a test, not crash the test binary.)
bool runnable_tape(const Scene& sc, std::span<const uint32_t> tape);

// What every finest cell must guarantee, whichever device made it, at its centre and 8 points
// near its corners: a near-field cell's tape gives the full tree's value (within float
// rounding); a far-field constant has the value's sign and never overstates it (a lower bound of
// |f| over the cell).
void expect_valid_cells(const Scene& sc, const gpu::Grid& gpu, const std::string& what);

// Every finest cell: same kind, same far-field constant, same tape.
void expect_same_cells(const PrunedGrid& cpu, const gpu::Grid& gpu, const std::string& what);

// The GPU's grid against the CPU's: the statistics, and every finest cell bit for bit where the
// device rounds as the CPU does (lavapipe), else what every device must give.
void expect_matches_cpu(const Scene& sc, const PrunedGrid& cpu, const gpu::Grid& gpu,
                        const gpu::Device& dev, const std::string& what);

// Two grids of one device, cell by cell: the same far-field constants and tapes (every finest
// cell compared: the same kind, constant and tape).
void expect_same_device_cells(const gpu::Grid& a, const gpu::Grid& b, const std::string& what);

// Two grids of one scene whose plans may take other kernels for some steps (teams or wide,
// refinement's lanes or squads): on an exact device the same statistics and cells, bit for bit;
// elsewhere each kernel may round a bound differently, so the statistics agree within their
// tolerance and each grid holds what a grid guarantees.
void expect_same_grid_if_exact(const Scene& sc, const gpu::Grid& a, const gpu::Grid& b,
                               const gpu::Device& dev, const std::string& what);

// ---- scenes -------------------------------------------------------------------------------------

// A right-deep chain of `depth` smooth unions of small spheres on a helix: its evaluation
// stack is as deep as the chain, its tapes long.
Scene right_deep_chain(uint32_t depth);

// `base` grown into a left-deep chain by `ops` more operators, each with a small sphere on a
// helix around `centre`, their kinds in turn: smooth and hard unions, a smooth difference (a
// negated right operand), an intersection and a smooth intersection with large shapes, and a
// union with the chain as its right operand; every 16th operator subtracts the chain from a
// large sphere (the chain negated), the next 16th does so again.
Shape mixed_chain(SceneBuilder& b, Shape base, uint32_t ops, vec3 centre);

}  // namespace sdfprune::test
