// gpu_render.cpp — sphere tracing and discretization on the device (gpu.hpp): trace.comp and
// discretize.comp over slices sized so that the per-thread stacks, deep enough for the grid's
// finest tapes, fit the scratch budget, and a second pass with full-depth stacks for the few
// items that need the full tree (slice.glsl); the host finishes images exactly as the CPU
// tracer does (background, heatmap, sRGB).
#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <stdexcept>
#include <string>

#include "../render/render_internal.hpp"
#include "device_grid.hpp"

namespace sdfprune::gpu {

namespace {

vec4 v4(vec3 v, float w) {
    return vec4(v.x, v.y, v.z, w);
}

template <class Params>
Buffer& upload_params(Context& ctx, LocalBuffers& local, const Params& p) {
    Buffer& b = local.create(sizeof(p));
    ctx.upload(b, &p, sizeof(p));
    return b;
}

// A value on a kernel's evaluation stack: 4 floats (the value, then a color).
constexpr uint64_t kStackSlotBytes = 16;
// Items the deferred list holds at first (slice.glsl): a chunk that defers more gets a longer
// list and runs again. SDFPRUNE_VULKAN_DEFERRED_LIST=N sets it (for tests).
uint64_t deferred_list_items() {
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_DEFERRED_LIST"))
        return std::max<uint64_t>(std::strtoull(env, nullptr, 10), 1);
    return uint64_t(1) << 16;
}

// What run_in_chunks did.
struct ChunkedRun {
    double gpu_ms = 0;
    uint64_t stack_words = 0;      // per thread, in the first pass
    uint64_t full_tree_items = 0;  // items evaluated again in the full-tree pass
    // An invocation reached the device's loop limit (slice.glsl: probe_loop_limit): the output
    // is wrong, and the run stopped at that chunk.
    bool loop_limit_reached = false;
};

// Threads for the full-tree pass over `items` items: as many as need it, within the scratch
// budget and one dispatch (no multiple of the workgroup size: a thread's stack may be
// megabytes). Throws GpuError when not even one full-depth stack fits.
uint32_t full_tree_threads(const Context& ctx, uint64_t items, uint64_t stack_bytes) {
    const uint64_t fit = ctx.scratch_budget_bytes() / stack_bytes;
    if (fit == 0)
        throw GpuError("Vulkan: " + std::to_string(items) +
                       " points need the full tree, whose evaluation stack (" +
                       std::to_string(stack_bytes) +
                       " bytes) exceeds the device's buffers; use --backend cpu");
    return uint32_t(std::min({items, fit, uint64_t(ctx.max_workgroups()) * kWorkgroupSize}));
}

// Runs `kernel` (trace.comp or discretize.comp) over items [0, total), one per thread, and
// downloads its output (`item_bytes` per item) to `host`: in chunks of at most `max_chunk`
// items whose output fits one storage buffer, each in two passes (slice.glsl). The first takes
// every item in dispatches of as many threads as stacks sized for the grid's finest tapes let
// share the scratch budget; the items that need the full tree are deferred to the second,
// which takes only them, with full-depth stacks. `check_full_tree` is called with the count of
// deferred items before the second pass runs (to refuse what the device cannot do). On a device
// that ends loops early, each pass's probe of that limit is read back, and the run stops where
// an invocation reached it.
ChunkedRun run_in_chunks(Context& ctx, KernelId kernel, const DeviceGrid& g, const Buffer& params,
                         uint64_t total, uint64_t item_bytes, uint64_t max_chunk, void* host,
                         const std::function<void(uint64_t)>& check_full_tree) {
    const uint64_t grid_depth = std::max(g.finest_stack_depth, 1u);
    const uint64_t full_depth = std::max(g.scene->max_stack, 1u);
    // A tree no deeper than the grid's tapes fits the first pass's stacks: nothing to defer.
    const bool full_tree_fits = full_depth <= grid_depth;
    const uint64_t stack_bytes = grid_depth * kStackSlotBytes;
    const uint64_t full_stack_bytes = full_depth * kStackSlotBytes;
    ChunkedRun run;
    run.stack_words = stack_bytes / 4;
    const uint32_t threads = ctx.threads_for(total, stack_bytes);
    LocalBuffers local(ctx);
    Buffer& stack = local.create(threads * stack_bytes);
    const uint64_t chunk = std::min({total, max_chunk, ctx.max_buffer_bytes() / item_bytes});
    Buffer& out = local.create(chunk * item_bytes);
    uint64_t deferred_capacity = std::min(chunk, deferred_list_items());
    // The deferred list: its count, the loop limit's flag, then the items (slice.glsl).
    constexpr uint64_t kDeferredHeaderBytes = 8;
    Buffer* deferred = &local.create(kDeferredHeaderBytes + deferred_capacity * 4);
    const bool probe = ctx.device_ends_loops();
    Buffer& full_stack = local.slot();  // made when an item first needs it
    uint32_t full_threads = 0;
    // One dispatch: `count` items from `first` (of the chunk from `base`, or of the deferred
    // list in the full-tree pass), over `stack_threads` threads' stacks in `stacks`.
    const auto dispatch = [&](uint64_t first, uint64_t count, uint32_t stack_threads, uint64_t base,
                              bool full_tree_pass, const Buffer& stacks) {
        SlicePush push{};
        push.first = uint32_t(first);
        push.count = uint32_t(count);
        push.stack_threads = stack_threads;
        push.base = uint32_t(base);
        push.full_tree_pass = full_tree_pass ? 1 : 0;
        push.full_tree_fits = full_tree_fits ? 1 : 0;
        push.deferred_capacity = uint32_t(deferred_capacity);
        push.loop_probe = probe ? kernel::kLoopProbeIterations : 0;
        ctx.dispatch(kernel,
                     {&g.nodes, &g.params, &g.extras, &g.pool, &g.cells, &g.levels, &params, &out,
                      &stacks, deferred},
                     &push, sizeof(push), ctx.groups_for(count));
    };
    uint32_t header[2] = {0, 0};  // the deferred list's count and loop limit flag, read back
    uint32_t& deferred_count = header[0];
    // Reads the header back after a pass: whether an invocation reached the loop limit.
    const auto limit_reached = [&] {
        ctx.download(*deferred, header, kDeferredHeaderBytes);
        return header[1] != 0;
    };
    for (uint64_t base = 0; base < total; base += chunk) {
        const uint64_t count = std::min(chunk, total - base);
        for (;;) {
            ctx.begin();
            ctx.fill(*deferred, 0, 0, kDeferredHeaderBytes);
            for (uint64_t done = 0; done < count; done += threads)
                dispatch(base + done, std::min<uint64_t>(threads, count - done), threads, base,
                         false, stack);
            run.gpu_ms += ctx.submit();
            if (limit_reached()) {
                run.loop_limit_reached = true;
                return run;
            }
            if (deferred_count <= deferred_capacity) break;
            // The list missed some: a list for all of them, and the chunk again (the same
            // items defer).
            deferred_capacity = deferred_count;
            ctx.destroy(*deferred);
            deferred = &local.create(kDeferredHeaderBytes + deferred_capacity * 4);
        }
        if (deferred_count > 0) {
            check_full_tree(deferred_count);
            const uint32_t want = full_tree_threads(ctx, deferred_count, full_stack_bytes);
            if (want > full_threads) {
                ctx.destroy(full_stack);
                full_stack = ctx.create_buffer(want * full_stack_bytes);
                full_threads = want;
            }
            ctx.begin();
            for (uint64_t done = 0; done < deferred_count; done += full_threads)
                dispatch(done, std::min<uint64_t>(full_threads, deferred_count - done),
                         full_threads, base, true, full_stack);
            run.gpu_ms += ctx.submit();
            run.full_tree_items += deferred_count;
            if (probe && limit_reached()) {
                run.loop_limit_reached = true;
                return run;
            }
        }
        ctx.download(out, static_cast<char*>(host) + base * item_bytes, count * item_bytes);
    }
    return run;
}

// On a device that ends an invocation's loops early (lavapipe), one evaluation of the longest
// finest tape must fit the limit: a grid with a longer tape is refused before any kernel runs
// (the probe, slice.glsl, would refuse its output after). The limit is the device's, whatever
// the pruning's plan (SDFPRUNE_VULKAN_LOOP_LIMITED plans lavapipe's steps as a GPU's, and
// changes nothing here).
void check_tape_loops(const Context& ctx, const DeviceGrid& g) {
    if (ctx.device_ends_loops() && uint64_t(g.stats.tape_max) + 64 >= Context::kLoopLimit)
        throw GpuError("tapes of " + std::to_string(g.stats.tape_max) +
                       " nodes exceed the loop limit of " + ctx.device_name() +
                       "; use --backend cpu or a GPU");
}

// An image or samples some of whose invocations reached the device's loop limit (their outputs
// are wrong): `what` needs more than the device allows.
[[noreturn]] void refuse_past_loop_limit(const Context& ctx, const char* what) {
    throw GpuError(std::string(what) + " than " + ctx.device_name() + " allows (" +
                   std::to_string(Context::kLoopLimit) + "); use --backend cpu or a GPU");
}

}  // namespace

Image render(Device& device, const Grid& grid, const RenderOptions& opt, RenderStats* stats) {
    const DeviceGrid& g = *grid.impl_;
    Context& ctx = device.context();
    const Scene& sc = *g.scene;
    const uint32_t W = opt.width, H = opt.height;
    if (W == 0 || H == 0) throw std::invalid_argument("image size must be positive");
    const uint64_t pixels = uint64_t(W) * H;
    if (pixels > 0xffffffffull) throw std::invalid_argument("image too large");
    check_tape_loops(ctx, g);
    const CameraFrame frame = camera_frame(sc, opt);
    TraceParams prm;
    prm.grid = g.grid_params();
    prm.march_min = v4(g.near_box.min, 0);
    prm.march_max = v4(g.near_box.max, 0);
    prm.eye = v4(opt.camera.eye, frame.tan_half);
    prm.forward = v4(frame.forward, frame.aspect);
    prm.right = v4(frame.right, frame.normal_h);
    prm.up = v4(frame.up, 0);
    prm.light = v4(frame.light, 0);
    prm.width = W;
    prm.height = H;
    prm.shading = opt.shading == Shading::kNormals ? 1u : 0u;
    prm.shadows = opt.shadows ? 1u : 0u;
    LocalBuffers local(ctx);
    const Buffer& params = upload_params(ctx, local, prm);
    std::vector<GpuPixel> host(pixels);
    const ChunkedRun run = run_in_chunks(ctx, KernelId::kTrace, g, params, pixels, sizeof(GpuPixel),
                                         pixels, host.data(), [](uint64_t) {});
    if (run.loop_limit_reached)
        refuse_past_loop_limit(ctx, "the image needs more loop iterations per pixel");

    std::vector<vec3> color(pixels);
    std::vector<uint32_t> evals(pixels);
    TraceTotals totals;
    totals.trace_ms = run.gpu_ms;
    for (uint64_t i = 0; i < pixels; ++i) {
        const GpuPixel& p = host[i];
        const float v = 1.0f - 2.0f * (float(i / W) + 0.5f) / float(H);
        color[i] = p.color.w > 0 ? p.color.xyz() : background(v);
        evals[i] = p.evals;
        totals.hits += p.color.w > 0 ? 1 : 0;
        totals.steps += p.steps;
        totals.evals += p.evals;
    }
    Image img = finish_image(opt, color, evals, totals, stats);
    if (stats) {
        stats->stack_words = run.stack_words;
        stats->full_tree_pixels = run.full_tree_items;
    }
    return img;
}

void discretize(Device& device, const Grid& grid, uint32_t n, std::span<float> out,
                DiscretizeStats* stats) {
    const DeviceGrid& g = *grid.impl_;
    Context& ctx = device.context();
    const Scene& sc = *g.scene;
    if (n == 0) throw std::invalid_argument("discretize: resolution must be >= 1");
    const uint64_t total = uint64_t(n) * n * n;
    if (out.size() != total) throw std::invalid_argument("discretize: output must hold n³ values");
    if (total > 0xffffffffull)  // the kernel indexes samples with 32 bits
        throw std::invalid_argument("discretize --backend vulkan: at most 1625³ samples");
    check_tape_loops(ctx, g);
    DiscretizeParams prm{};
    prm.grid = g.grid_params();
    const vec3 sample = (sc.aabb.max - sc.aabb.min) / float(n);
    prm.sample_size = v4(sample, 0);
    prm.n = n;
    LocalBuffers local(ctx);
    const Buffer& params = upload_params(ctx, local, prm);
    // A sample on the full tree walks all of it in one invocation.
    const auto check_full_tree = [&](uint64_t samples) {
        if (ctx.device_ends_loops() && uint64_t(sc.size()) + 64 >= Context::kLoopLimit)
            throw GpuError(std::to_string(samples) + " samples need the full tree of " +
                           std::to_string(sc.size()) + " nodes, beyond the loop limit of " +
                           ctx.device_name() + "; use --backend cpu or a GPU");
    };
    // At most 64 Mi values per chunk.
    const ChunkedRun run =
        run_in_chunks(ctx, KernelId::kDiscretize, g, params, total, sizeof(float),
                      uint64_t(1) << 26, out.data(), check_full_tree);
    if (run.loop_limit_reached)
        refuse_past_loop_limit(ctx, "the samples need more loop iterations per sample");
    if (stats) {
        stats->gpu_ms = run.gpu_ms;
        stats->stack_words = run.stack_words;
        stats->full_tree_samples = run.full_tree_items;
    }
}

}  // namespace sdfprune::gpu
