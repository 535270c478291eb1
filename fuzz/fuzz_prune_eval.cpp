// fuzz_prune_eval.cpp — libFuzzer target: sdfprune::fuzz::prune_eval (fuzz_entry.hpp).
#include "fuzz/fuzz_entry.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    sdfprune::fuzz::prune_eval({data, size});
    return 0;
}
