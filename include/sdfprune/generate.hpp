// generate.hpp — procedural stand-ins for the paper's scenes (Barbier et al. 2025, Table 1):
// the scenes the paper measured but did not publish, made in code with the same node counts
// (within 5 %), each shaped like its name and built with the operators its subject implies
// (smooth blends for organic shapes, differences for windows and holes, intersections, hard and
// smooth CSG mixed, balanced trees for large scenes and left-deep chains where the subject is a
// chain).
//
//   Scene city = generate_scene("city", 7, 0);          // the paper's size: 691 nodes
//   Scene fluid = generate_scene("fluid", 1, 1000000);  // 1,000,000 spheres
//
// Output is a pure function of (kind, seed, count): the same arguments give the same scene,
// node for node, on every run (the random stream is sdfprune::Rng; no std:: distributions).
// Every scene has colors on all primitives and an AABB that holds it with a small margin.
//
// Thread-safety: the functions are reentrant; calls may run concurrently.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "scene.hpp"

namespace sdfprune {

// What generate_scene() can make, in order of the paper's node counts.
struct GeneratorInfo {
    std::string kind;          // "character", "city", ...
    uint32_t paper_nodes = 0;  // #N of the paper's scene (Table 1)
    // Primitives of the default scene (count = 0); its node count is 2·primitives − 1.
    uint32_t default_count = 0;
    // Scalable kinds accept a count: the exact number of primitives to make, in
    // [min_count, kMaxGeneratedPrimitives]. Fixed kinds accept only count = 0.
    bool scalable = false;
    uint32_t min_count = 0;
    std::string summary;  // one line: what it looks like and what count scales
};

// Upper bound on a scalable kind's count (2^24 primitives: about 2^25 nodes).
inline constexpr uint32_t kMaxGeneratedPrimitives = 1u << 24;

const std::vector<GeneratorInfo>& generator_info();
// The kinds, in generator_info() order: character, raccoon, console, gameboy, car,
// train-station, camera, trees, car-chase, city, crowd, molecule, monument, fluid.
std::vector<std::string> generator_kinds();

// Makes the scene `kind` from `seed`. count = 0 gives the paper's size. For the scalable kinds
// count is the exact number of primitives:
//   fluid     spheres: adaptive SPH-like particles of a splash crown in a tank (fine at the
//             surface, large and overlapping deep inside, so the inside prunes as far field);
//             the spacing shrinks as count grows, so the shape stays the same. A balanced
//             union in Morton order, smooth only between neighbours (the lowest two levels);
//   molecule  atoms: DNA rings of up to 1000 atoms each, every ring a left-deep smooth-union
//             chain (k = 0.026, like the reference molecule), rings joined by a balanced tree;
//   crowd     primitives of a crowd of people (7–16 primitives each) on a ground slab;
//   city      primitives of a city of blocks, buildings and parks on a street grid.
// Large scenes are built straight into node descriptions (no SceneBuilder arena): 1,000,000
// fluid spheres take a few seconds and well under 1 GB.
// Throws SceneError for an unknown kind, a count given to a fixed kind, or a count out of range.
Scene generate_scene(const std::string& kind, uint64_t seed, uint32_t count = 0);

}  // namespace sdfprune
