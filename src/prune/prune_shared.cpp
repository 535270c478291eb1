// prune_shared.cpp — prune() with shared ownership of the scene (prune.hpp): the grid holds the
// scene's shared_ptr so callers that cannot order lifetimes (the Python binding) need not.
#include <stdexcept>

#include "sdfprune/prune.hpp"

namespace sdfprune {

PrunedGrid prune(std::shared_ptr<const Scene> scene, const PruneOptions& options) {
    if (!scene) throw std::invalid_argument("prune: null scene");
    PrunedGrid grid = prune(*scene, options);
    grid.owner_ = std::move(scene);
    return grid;
}

}  // namespace sdfprune
