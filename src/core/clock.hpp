// clock.hpp — the milliseconds since a point in time: how the library, the viewer and the CLI
// time what they report (prune_ms, trace_ms, wall_ms, ...).
#pragma once

#include <chrono>

namespace sdfprune {

// Milliseconds on the steady clock since t0.
inline double ms_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace sdfprune
