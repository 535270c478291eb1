// fuzz_entry.hpp — the entry points of the fuzz targets (fuzz/fuzz_*.cpp), shared with the
// regression test (tests/fuzz_regression_test.cpp) so both feed inputs through the same code.
//
// Each function takes arbitrary bytes and either returns (the input was accepted or refused
// with the library's documented error type, which it catches) or throws FuzzPropertyViolation
// when a guaranteed property fails. Any other exception, a crash, a hang or a huge allocation
// is a finding: the fuzz targets let it escape so libFuzzer reports it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>

namespace sdfprune::fuzz {

// What an entry point made of its input.
enum class Outcome : uint8_t {
    kAccepted,  // parsed (and, for prune_eval, pruned and checked)
    kRejected,  // refused with the documented error (SceneError, IoError)
};

// A guaranteed property of the library does not hold for this input.
struct FuzzPropertyViolation : std::logic_error {
    using std::logic_error::logic_error;
};

// JSON text → Scene (parse_scene); on success also checks that scene_to_json reads back to a
// scene of the same size. Rejections: SceneError.
Outcome scene_loader(std::span<const uint8_t> data);

// .npy bytes → NpyArray (parse_npy); on success checks data.size() == product(shape).
// Rejections: IoError.
Outcome npy_reader(std::span<const uint8_t> data);

// The first kPruneOptionBytes bytes choose the pruning options (resolution 1–16, factor 2–4,
// far field, hierarchy, bounds, refine 1–3, C in [1, 5], coarse tapes) and the sample points'
// seed; the rest is a scene (JSON text). Prunes the scene and checks at points of the AABB:
// a near-field cell's tape gives the full tree's value (within 1e-6·(1 + |f|)), a far-field
// constant has f's sign and |c| <= |f|, PrunedGrid::eval agrees with both, and a cell whose
// centre value satisfies |f| < (C − 1)·R is near-field. Scenes over kPruneMaxNodes nodes are
// only loaded (pruning them on every input would starve the fuzzer). Rejections: SceneError.
inline constexpr size_t kPruneOptionBytes = 8;
inline constexpr uint32_t kPruneMaxNodes = 512;
Outcome prune_eval(std::span<const uint8_t> data);

}  // namespace sdfprune::fuzz
