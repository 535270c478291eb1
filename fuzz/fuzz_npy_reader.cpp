// fuzz_npy_reader.cpp — libFuzzer target: sdfprune::fuzz::npy_reader (fuzz_entry.hpp).
#include "fuzz/fuzz_entry.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    sdfprune::fuzz::npy_reader({data, size});
    return 0;
}
