// generate.cpp — the table of scene generators (the paper's Table 1 scenes and their node
// counts) and the dispatch that validates kind and count.
#include "sdfprune/generate.hpp"

#include "generate_internal.hpp"

namespace sdfprune {

const std::vector<GeneratorInfo>& generator_info() {
    // default_count = (paper_nodes + 1) / 2 primitives, rounded to what each subject builds.
    static const std::vector<GeneratorInfo> info = {
        {"character", 43, 22, false, 0,
         "a cartoon figure of capsules and spheres, smoothly blended"},
        {"raccoon", 53, 27, false, 0, "a raccoon: masked face, ringed tail, smooth blends"},
        {"console", 61, 31, false, 0,
         "a game console with vents and slot cut out, and its controller"},
        {"gameboy", 65, 33, false, 0,
         "a handheld game console: screen, d-pad, buttons, speaker slots"},
        {"car", 117, 59, false, 0,
         "a hatchback: window and wheel-arch cuts, spoked wheels, lights"},
        {"train-station", 119, 60, false, 0,
         "a platform under a curved canopy, a train and a passenger"},
        {"camera", 119, 60, false, 0,
         "a reflex camera: lens barrel with glass, dials, grip, back screen"},
        {"trees", 369, 185, false, 0,
         "a forest of low-poly trees and rocks on a ground slab (a chain)"},
        {"car-chase", 560, 280, false, 0, "police cars chasing a car down a street"},
        {"city", 691, 346, true, 10,
         "count = primitives: blocks of buildings with window bands, parks, streets"},
        {"crowd", 1989, 995, true, 16,
         "count = primitives: people (7-16 primitives each) on a plaza"},
        {"molecule", 1999, 1000, true, 1,
         "count = atoms (spheres): DNA rings, each a left-deep smooth chain"},
        {"monument", 6023, 3012, false, 0,
         "a domed, colonnaded monument: fluted columns, steps, balustrades, windows"},
        {"fluid", 27977, 13989, true, 100,
         "count = spheres: a splash crown in a tank, particles smoothly blended"},
    };
    return info;
}

std::vector<std::string> generator_kinds() {
    std::vector<std::string> kinds;
    for (const GeneratorInfo& g : generator_info()) kinds.push_back(g.kind);
    return kinds;
}

Scene generate_scene(const std::string& kind, uint64_t seed, uint32_t count) {
    const GeneratorInfo* g = nullptr;
    std::string known;
    for (const GeneratorInfo& i : generator_info()) {
        if (i.kind == kind) g = &i;
        known += (known.empty() ? "" : ", ") + i.kind;
    }
    if (!g) throw SceneError("unknown generator kind \"" + kind + "\" (known: " + known + ")");
    if (count != 0 && !g->scalable)
        throw SceneError(kind +
                         " has a fixed size; a count applies to city, crowd, molecule "
                         "and fluid only");
    if (count != 0 && (count < g->min_count || count > kMaxGeneratedPrimitives))
        throw SceneError("count for " + kind + " must be in [" + std::to_string(g->min_count) +
                         ", " + std::to_string(kMaxGeneratedPrimitives) + "] (got " +
                         std::to_string(count) + ")");
    const uint32_t n = count ? count : g->default_count;
    using namespace gen;
    if (kind == "character") return character(seed);
    if (kind == "raccoon") return raccoon(seed);
    if (kind == "console") return console(seed);
    if (kind == "gameboy") return gameboy(seed);
    if (kind == "car") return car(seed);
    if (kind == "train-station") return train_station(seed);
    if (kind == "camera") return camera(seed);
    if (kind == "trees") return trees(seed);
    if (kind == "car-chase") return car_chase(seed);
    if (kind == "city") return city(seed, n);
    if (kind == "crowd") return crowd(seed, n);
    if (kind == "molecule") return molecule(seed, n);
    if (kind == "monument") return monument(seed);
    return fluid(seed, n);
}

}  // namespace sdfprune
