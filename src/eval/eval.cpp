// eval.cpp — the tape evaluator shared by the naive baseline and the pruned grid: one pass over
// the post-order words with a value stack, the primitive and operator math from sdf_math.h.
#include "sdfprune/eval.hpp"

#include <stdexcept>
#include <vector>

#include "../core/parallel.hpp"

namespace sdfprune {

float eval_tape(const Scene& sc, std::span<const uint32_t> tape, vec3 p, float* stack) {
    const uint32_t* kind = sc.kind.data();
    const uint32_t* prim = sc.primitive.data();
    const float* blend = sc.blend.data();
    const math::PrimitiveParams* params = sc.params.data();
    // A tape of one word is one primitive (an operator needs two operands before it): most
    // near-field cells of a pruned grid hold one, and a tracer evaluates them at every step.
    // The loop's result without the loop.
    if (tape.size() == 1) {
        const uint32_t n = math::tape_node(tape[0]);
        const float v = math::eval_primitive(kind[n], params[prim[n]], p);
        return math::tape_negated(tape[0]) ? -v : v;
    }
    uint32_t top = 0;
    for (const uint32_t w : tape) {
        const uint32_t n = math::tape_node(w);
        const uint32_t k = kind[n];
        float v;
        if (k < math::kPrimitiveKindCount) {
            v = math::eval_primitive(k, params[prim[n]], p);
        } else {
            const float b = stack[--top];
            const float a = stack[--top];
            v = math::apply_operator(math::operator_s(k), blend[n], a, b);
        }
        stack[top++] = math::tape_negated(w) ? -v : v;
    }
    return stack[0];
}

vec3 eval_tape_color(const Scene& sc, std::span<const uint32_t> tape, vec3 p, float* stack,
                     vec3* color_stack) {
    // (one primitive: its colour, whatever its value; most near-field cells' tapes)
    if (tape.size() == 1) return sc.color[sc.primitive[math::tape_node(tape[0])]];
    uint32_t top = 0;
    for (const uint32_t w : tape) {
        const uint32_t n = math::tape_node(w);
        const uint32_t k = sc.kind[n];
        float v;
        vec3 c;
        if (k < math::kPrimitiveKindCount) {
            v = math::eval_primitive(k, sc.params[sc.primitive[n]], p);
            c = sc.color[sc.primitive[n]];
        } else {
            --top;
            const float b = stack[top], a = stack[top - 1];
            const float s = math::operator_s(k);
            v = math::apply_operator(s, sc.blend[n], a, b);
            const float wb = math::operator_weight_b(s, sc.blend[n], a, b);
            c = color_stack[top - 1] * (1.0f - wb) + color_stack[top] * wb;
            --top;
        }
        stack[top] = math::tape_negated(w) ? -v : v;
        color_stack[top++] = c;
    }
    return color_stack[0];
}

uint32_t eval_tape_winner(const Scene& sc, std::span<const uint32_t> tape, vec3 p, float* stack,
                          uint32_t* winner_stack) {
    uint32_t top = 0;
    for (const uint32_t w : tape) {
        const uint32_t n = math::tape_node(w);
        const uint32_t k = sc.kind[n];
        float v;
        uint32_t winner;
        if (k < math::kPrimitiveKindCount) {
            v = math::eval_primitive(k, sc.params[sc.primitive[n]], p);
            winner = sc.primitive[n];
        } else {
            --top;
            const float b = stack[top], a = stack[top - 1];
            const float s = math::operator_s(k);
            v = math::apply_operator(s, sc.blend[n], a, b);
            winner = math::operator_weight_b(s, sc.blend[n], a, b) > 0.5f ? winner_stack[top]
                                                                          : winner_stack[top - 1];
            --top;
        }
        stack[top] = math::tape_negated(w) ? -v : v;
        winner_stack[top++] = winner;
    }
    return winner_stack[0];
}

float eval_point(const Scene& sc, vec3 p) {
    std::vector<float> stack(sc.max_stack);
    return eval_tape(sc, sc.full_tape, p, stack.data());
}

void eval_points(const Scene& sc, std::span<const vec3> points, std::span<float> out,
                 const EvalOptions& options) {
    if (out.size() != points.size()) throw std::invalid_argument("eval_points: size mismatch");
    parallel_points(points.size(), options.threads, [&](size_t begin, size_t end) {
        std::vector<float> stack(sc.max_stack);
        for (size_t i = begin; i != end; ++i)
            out[i] = eval_tape(sc, sc.full_tape, points[i], stack.data());
    });
}

}  // namespace sdfprune
