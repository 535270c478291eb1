// bench_eval.cpp — micro-benchmarks of the tape evaluator (the naive full-tree baseline).
#include <benchmark/benchmark.h>

#include "sdfprune/builtin.hpp"
#include "sdfprune/eval.hpp"

namespace {

void BM_EvalFullTreeDemo(benchmark::State& state) {
    const sdfprune::Scene sc = sdfprune::builtin_scene("demo");
    std::vector<float> stack(sc.max_stack);
    sdfprune::Rng rng(1);
    float sum = 0;
    for (auto _ : state) {
        const sdfprune::vec3 p(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1));
        sum += sdfprune::eval_tape(sc, sc.full_tape, p, stack.data());
    }
    benchmark::DoNotOptimize(sum);
    state.counters["nodes"] = sc.size();
    state.counters["node_evals/s"] =
        benchmark::Counter(double(state.iterations()) * sc.size(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_EvalFullTreeDemo);

}  // namespace

BENCHMARK_MAIN();
