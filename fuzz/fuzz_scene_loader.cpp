// fuzz_scene_loader.cpp — libFuzzer target: sdfprune::fuzz::scene_loader (fuzz_entry.hpp).
#include "fuzz/fuzz_entry.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    sdfprune::fuzz::scene_loader({data, size});
    return 0;
}
