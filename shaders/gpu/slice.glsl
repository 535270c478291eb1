// slice.glsl — how trace.comp and discretize.comp take their items (pixels, samples), and the
// full-tree pass (src/gpu/gpu_render.cpp, run_in_chunks).
//
// Each thread's evaluation stack is sized for the deepest of the finest cells' tapes, the only
// pruned tapes these kernels evaluate: often tens of values where the full tree may need
// thousands (a right-deep chain of unions is as deep as it is long). A point that no near-field
// cell decides (outside the grid, or a hit point in a far-field cell; rare) needs the full tree,
// as on the CPU. In the first pass such an item is not evaluated but appended to the deferred
// list; the host then runs the same kernel over the listed items only, with stacks deep enough
// for the full tree and few threads (the full-tree pass). Every item's output is what one pass
// with full-depth stacks would give, bit for bit.
// Uses binding 9 (the deferred list); SlicePush in src/gpu/device_layout.hpp mirrors Push.

// Items [first, first + count) of a slice, output written from index `base` of the output
// buffer. full_tree_pass 0: item first + tid, stacks of `stack_threads` threads sized for the
// grid's tapes; the full tree's tape fits them only when full_tree_fits is 1, else an item that
// needs it is deferred (the list holds deferred_capacity items; the count may pass it: the host
// then makes the list longer and runs the chunk again). full_tree_pass 1: item
// deferred[2 + first + tid], stacks deep enough for the full tree. loop_probe: the iterations of
// the loop limit's probe (probe_loop_limit), 0 on a device without such a limit.
layout(push_constant) uniform Push {
    uint first, count, stack_threads, base;
    uint full_tree_pass, full_tree_fits, deferred_capacity, loop_probe;
} pc;

// [0]: items deferred so far (atomic, may pass the capacity); [1]: 1 where an invocation reached
// the device's loop limit (probe_loop_limit); [2 + i]: the i-th deferred item's index.
layout(std430, binding = 9) buffer Deferred { uint deferred[]; };

// The index of this thread's item (the caller has checked tid < pc.count).
uint slice_item(uint tid) {
    return pc.full_tree_pass != 0u ? deferred[2u + pc.first + tid] : pc.first + tid;
}

// Lavapipe ends an invocation's loops after 65,535 iterations in all, and the invocation goes on
// as if they had ended: its pixel or sample comes out wrong, and its counts too (a pixel's
// march ends early, as if it missed). So an invocation runs, before it writes its output, a loop
// of pc.loop_probe iterations (2 on such a device, else 0: a bound no compiler can know, so
// that the loop stays a loop); one that runs fewer found the limit reached, and sets
// deferred[1], which the host reports as an error (gpu_render.cpp). The pruning kernels probe
// the same way (prune_common.glsl).
void probe_loop_limit() {
    uint ran = 0u;
    for (uint k = 0u; k < pc.loop_probe; ++k) ++ran;
    if (ran != pc.loop_probe) atomicOr(deferred[1], 1u);
}

// Whether this thread's stack holds the evaluation of `tape`: the finest cells' tapes always
// fit; the full tree's only in the full-tree pass, or when it is no deeper than they are.
bool stack_holds(uint tape) {
    return tape != kFullTreeTape || pc.full_tree_pass != 0u || pc.full_tree_fits != 0u;
}

// Appends `item` to the deferred list, for the full-tree pass.
void defer_item(uint item) {
    uint at = atomicAdd(deferred[0], 1u);
    if (at < pc.deferred_capacity) deferred[2u + at] = item;
}
