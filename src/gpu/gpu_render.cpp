// gpu_render.cpp — sphere tracing and discretization on the device (gpu.hpp): trace.comp and
// discretize.comp over slices sized so that the per-thread stacks fit the scratch budget; the
// host finishes images exactly as the CPU tracer does (background, heatmap, sRGB).
#include <algorithm>
#include <cstring>
#include <stdexcept>

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

// Runs `kernel` (trace.comp or discretize.comp) over items [0, total), one per thread, and
// downloads its output (`item_bytes` per item) to `host`: in chunks of at most `max_chunk`
// items whose output fits one storage buffer, each in dispatches of as many threads as the
// per-thread stacks let share the scratch budget. Returns the GPU time.
double run_in_chunks(Context& ctx, KernelId kernel, const DeviceGrid& g, const Buffer& params,
                     uint64_t total, uint64_t item_bytes, uint64_t max_chunk, void* host) {
    const uint64_t stack_bytes = uint64_t(g.scene->max_stack) * 16;
    const uint32_t threads = ctx.threads_for(total, stack_bytes);
    LocalBuffers local(ctx);
    Buffer& stack = local.create(threads * stack_bytes);
    const uint64_t chunk = std::min({total, max_chunk, ctx.max_buffer_bytes() / item_bytes});
    Buffer& out = local.create(chunk * item_bytes);
    double ms = 0;
    for (uint64_t base = 0; base < total; base += chunk) {
        const uint64_t count = std::min(chunk, total - base);
        ctx.begin();
        for (uint64_t done = 0; done < count; done += threads) {
            const SlicePush push{uint32_t(base + done),
                                 uint32_t(std::min<uint64_t>(threads, count - done)), threads,
                                 uint32_t(base)};
            ctx.dispatch(kernel,
                         {&g.nodes, &g.params, &g.extras, &g.pool, &g.cells, &g.levels, &params,
                          &out, &stack},
                         &push, sizeof(push), ctx.groups_for(push.count));
        }
        ms += ctx.submit();
        ctx.download(out, static_cast<char*>(host) + base * item_bytes, count * item_bytes);
    }
    return ms;
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
    const CameraFrame frame = camera_frame(sc, opt);
    TraceParams prm;
    prm.grid = g.grid_params();
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
    const double gpu_ms = run_in_chunks(ctx, KernelId::kTrace, g, params, pixels, sizeof(GpuPixel),
                                        pixels, host.data());
    if (ctx.loop_limited()) {
        // Loop iterations of each pixel's invocation, bounded from above: tape words evaluated,
        // and per step the level walk and the few fixed loops.
        const uint64_t per_step = g.level_info.size() + 8;
        for (const GpuPixel& p : host)
            if (p.evals + (uint64_t(p.steps) + 8) * per_step >= Context::kLoopLimit)
                throw GpuError("the image needs more loop iterations per pixel than " +
                               ctx.device_name() + " allows (" +
                               std::to_string(Context::kLoopLimit) +
                               "); use --backend cpu or a GPU");
    }

    std::vector<vec3> color(pixels);
    std::vector<uint32_t> evals(pixels);
    TraceTotals totals;
    totals.trace_ms = gpu_ms;
    for (uint64_t i = 0; i < pixels; ++i) {
        const GpuPixel& p = host[i];
        const float v = 1.0f - 2.0f * (float(i / W) + 0.5f) / float(H);
        color[i] = p.color.w > 0 ? p.color.xyz() : background(v);
        evals[i] = p.evals;
        totals.hits += p.color.w > 0 ? 1 : 0;
        totals.steps += p.steps;
        totals.evals += p.evals;
    }
    return finish_image(opt, color, evals, totals, stats);
}

void discretize(Device& device, const Grid& grid, uint32_t n, std::span<float> out,
                double* gpu_ms) {
    const DeviceGrid& g = *grid.impl_;
    Context& ctx = device.context();
    const Scene& sc = *g.scene;
    if (n == 0) throw std::invalid_argument("discretize: resolution must be >= 1");
    const uint64_t total = uint64_t(n) * n * n;
    if (out.size() != total) throw std::invalid_argument("discretize: output must hold n³ values");
    if (total > 0xffffffffull)  // the kernel indexes samples with 32 bits
        throw std::invalid_argument("discretize --backend vulkan: at most 1625³ samples");
    if (ctx.loop_limited() && uint64_t(g.stats.tape_max) + 64 >= Context::kLoopLimit)
        throw GpuError("tapes of " + std::to_string(g.stats.tape_max) +
                       " nodes exceed the loop "
                       "limit of " +
                       ctx.device_name() + "; use --backend cpu or a GPU");
    DiscretizeParams prm{};
    prm.grid = g.grid_params();
    const vec3 sample = (sc.aabb.max - sc.aabb.min) / float(n);
    prm.sample_size = v4(sample, 0);
    prm.n = n;
    LocalBuffers local(ctx);
    const Buffer& params = upload_params(ctx, local, prm);
    // At most 64 Mi values per chunk.
    const double ms = run_in_chunks(ctx, KernelId::kDiscretize, g, params, total, sizeof(float),
                                    uint64_t(1) << 26, out.data());
    if (gpu_ms) *gpu_ms = ms;
}

}  // namespace sdfprune::gpu
