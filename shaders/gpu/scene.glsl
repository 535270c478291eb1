// scene.glsl — the scene and the tape pool as every kernel sees them (bindings 0–3), and the
// tape evaluators. The layouts match src/gpu/device_layout.hpp (checked by the GpuLayout
// tests); the math is sdf_math.h, the same file the CPU backend compiles.
#extension GL_GOOGLE_include_directive : require
#ifdef SDFPRUNE_ROUNDING_SALT
// A test build's stand-in for a GPU that rounds otherwise than the CPU (NVIDIA's square roots
// and divisions are not IEEE-exact in Vulkan): every primitive's and operator's value moves by
// -1, 0 or +1 in its last bit, by a hash of its bits and the salt (CMake:
// SDFPRUNE_SHADER_ROUNDING; one salt for every kernel, or one per kernel, as if each kernel's
// compile rounded its own way). Zero, infinities and NaN stay as they are.
float device_rounding(float x) {
    uint bits = floatBitsToUint(x);
    if (x == 0.0 || isinf(x) || isnan(x)) return x;
    uint h = (bits ^ (bits >> 15) ^ (uint(SDFPRUNE_ROUNDING_SALT) * 0x9e3779b9u)) * 0x85ebca6bu;
    h ^= h >> 13;
    return uintBitsToFloat(bits + (h % 3u) - 1u);
}
#define SDFPRUNE_DEVICE_ROUNDING(x) device_rounding(x)
#endif
#include "../shared/sdf_math.h"

struct Node {
    uint kind;       // kPrim* or kOp*
    uint primitive;  // primitives: index into params/extras, the node's own (node order)
    float blend;     // operators: k
    float lipschitz;
};
struct PrimitiveExtra {
    vec4 bound0;  // similarity bound: centre xyz, scale (<= 0: none)
    vec4 bound1;  // f0, rho
    vec4 color;   // rgb
};

// Node n's parameters and extras are params[n] and extras[n] (gpu_prune.cpp uploads them in
// node order; operators' records are unused), so that a kernel that knows an entry is a
// primitive may read them beside its node. `restrict` (as on the other read-only buffers a
// kernel is never given writable beside: the grid's cells and levels, the blocks, the wide
// kernels' node spans): the compiler may move their loads past the kernel's stores, to have
// them in flight sooner.
layout(std430, binding = 0) restrict readonly buffer Nodes { Node nodes[]; };
layout(std430, binding = 1) restrict readonly buffer Params { PrimitiveParams params[]; };
layout(std430, binding = 2) restrict readonly buffer Extras { PrimitiveExtra extras[]; };
// Tapes as [length, primitives, words...]; the full tree's tape is at offset 0.
layout(std430, binding = 3) buffer Pool { uint pool[]; };
const uint kFullTreeTape = 0u;

#define kInfinity uintBitsToFloat(0x7f800000u)

bool is_primitive(uint node) { return nodes[node].kind < kPrimitiveKindCount; }

#ifdef SCENE_STACK_BINDING
// Per-thread value stacks, slot j of thread t at ((j · stack_threads + t) · 4): the value, then
// the color channels.
layout(std430, binding = SCENE_STACK_BINDING) buffer Stack { float stack_values[]; };
#define SCENE_STACK stack_values

float eval_tape(uint tape, vec3 p, uint t, uint stack_threads) {
    uint len = pool[tape];
    uint top = 0u;
    for (uint i = 0u; i < len; ++i) {
        uint w = pool[tape + 2u + i];
        uint n = tape_node(w);
        uint kind = nodes[n].kind;
        float v;
        if (kind < kPrimitiveKindCount) {
            v = eval_primitive(kind, params[nodes[n].primitive], p);
        } else {
            float b = SCENE_STACK[((top - 1u) * stack_threads + t) * 4u];
            float a = SCENE_STACK[((top - 2u) * stack_threads + t) * 4u];
            top -= 2u;
            v = apply_operator(operator_s(kind), nodes[n].blend, a, b);
        }
        SCENE_STACK[(top * stack_threads + t) * 4u] = tape_negated(w) ? -v : v;
        ++top;
    }
    return SCENE_STACK[t * 4u];
}

vec3 eval_tape_color(uint tape, vec3 p, uint t, uint stack_threads) {
    uint len = pool[tape];
    uint top = 0u;
    for (uint i = 0u; i < len; ++i) {
        uint w = pool[tape + 2u + i];
        uint n = tape_node(w);
        uint kind = nodes[n].kind;
        float v;
        vec3 c;
        if (kind < kPrimitiveKindCount) {
            v = eval_primitive(kind, params[nodes[n].primitive], p);
            c = extras[nodes[n].primitive].color.xyz;
        } else {
            uint ib = ((top - 1u) * stack_threads + t) * 4u;
            uint ia = ((top - 2u) * stack_threads + t) * 4u;
            float b = SCENE_STACK[ib], a = SCENE_STACK[ia];
            float s = operator_s(kind);
            v = apply_operator(s, nodes[n].blend, a, b);
            float wb = operator_weight_b(s, nodes[n].blend, a, b);
            vec3 ca = vec3(SCENE_STACK[ia + 1u], SCENE_STACK[ia + 2u], SCENE_STACK[ia + 3u]);
            vec3 cb = vec3(SCENE_STACK[ib + 1u], SCENE_STACK[ib + 2u], SCENE_STACK[ib + 3u]);
            c = ca * (1.0 - wb) + cb * wb;
            top -= 2u;
        }
        uint io = (top * stack_threads + t) * 4u;
        SCENE_STACK[io] = tape_negated(w) ? -v : v;
        SCENE_STACK[io + 1u] = c.x;
        SCENE_STACK[io + 2u] = c.y;
        SCENE_STACK[io + 3u] = c.z;
        ++top;
    }
    return vec3(SCENE_STACK[t * 4u + 1u], SCENE_STACK[t * 4u + 2u], SCENE_STACK[t * 4u + 3u]);
}
#endif
