// parallel.hpp — the thread limit of the library's batch operations: every one of them (prune,
// render, discretize, mesh, eval_points) runs on oneTBB with at most its options' `threads`
// workers, and with_threads gives the same limit to a caller's own work (src/core/parallel.hpp
// holds the loop they share).
#pragma once

#include <functional>

namespace sdfprune {

// Runs fn() with at most `threads` oneTBB workers (0 = no limit).
void with_threads(int threads, const std::function<void()>& fn);

}  // namespace sdfprune
