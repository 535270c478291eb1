// refine_lanes_model.cpp — a model of the work of the Vulkan backend's refinement lane pass
// (shaders/gpu/prune_refine_lanes.comp), computed on the CPU, so that a change of its job
// order can be judged without a GPU (issue 13).
//
// A subgroup of 32 lanes takes 32 neighbouring jobs of refinement's list and walks as long as
// its longest tape. The model sums, over groups of 32 consecutive jobs, the longest tape of the
// group: the walk steps of the first pass per sub-box batch. It takes the finest near cells'
// tapes as the cells step makes them (the CPU's grid with refinement off: the same tapes) in
// the level's cell order (block after block, about the order the team kernel lists them in;
// the device's order is the atomics', spread wider), and reports
//   - before: every near cell of at most 32 words listed for the lanes, a lone primitive that
//     cannot turn far-field counting 0 (copied, no walk), the others their length;
//   - listed apart: the cells with nothing to try (refine_need) copied apart, the rest walked
//     in cell order;
//   - ordered: those sorted by walk class (prune_common.glsl: refine_walk_class), the longest
//     first, as the order pass does;
//   - ideal: the walked words over 32.
// Usage: sdfprune_refine_lanes_model SCENE [GRID]
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <vector>

#include "sdfprune/io.hpp"
#include "sdfprune/prune.hpp"

using namespace sdfprune;

namespace {

constexpr uint32_t kSubgroup = 32, kLaneTape = 32, kWalkClasses = 8;

uint32_t walk_class(uint32_t len) {
    return std::min((len - 1) / 4, kWalkClasses - 1);
}

// Sum over groups of kSubgroup consecutive jobs of the group's longest tape.
uint64_t subgroup_steps(const std::vector<uint32_t>& lengths) {
    uint64_t steps = 0;
    for (size_t i = 0; i < lengths.size(); i += kSubgroup) {
        const auto end = lengths.begin() + std::min(lengths.size(), i + kSubgroup);
        steps += *std::max_element(lengths.begin() + i, end);
    }
    return steps;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2 || argc > 3) {
        std::fprintf(stderr, "usage: %s SCENE [GRID]\n", argv[0]);
        return 2;
    }
    try {
        const Scene sc = load_scene(argv[1]);
        PruneOptions o;
        if (argc == 3) o.resolution = uint32_t(std::strtoul(argv[2], nullptr, 10));
        o.refine = 1;  // the cells' tapes before refinement
        const PrunedGrid grid = prune(sc, o);
        const uint32_t finest = grid.level_count() - 1, N = grid.resolution();
        const std::span<const PrunedCell> cells = grid.level_cells(finest);
        const vec3 cell_size = (sc.aabb.max - sc.aabb.min) / float(N), half = cell_size * 0.5f;
        // Per finest cell in storage order: its length before, and listed apart (-1: none).
        std::vector<int> before(cells.size(), -1), walked(cells.size(), -1);
        CellScratch s;
        for (uint32_t z = 0; z < N; ++z)
            for (uint32_t y = 0; y < N; ++y)
                for (uint32_t x = 0; x < N; ++x) {
                    const PrunedGrid::CellRef at = grid.descend(x, y, z, finest);
                    const PrunedCell& c = cells[at.index];
                    if (at.level != finest || c.tape == PrunedCell::kFarField) continue;
                    const std::span<const uint32_t> tape =
                        grid.tape_pool().subspan(c.tape + 2, grid.tape_pool()[c.tape]);
                    if (tape.size() > kLaneTape) continue;  // the squads'
                    const CellBox box{sc.aabb.min + vec3(x + 0.5f, y + 0.5f, z + 0.5f) * cell_size,
                                      half, math::length(half)};
                    evaluate_cell(sc, tape, box, o.bounds, s);
                    bool may_decide = false;
                    for (uint32_t e = 0; e < tape.size(); ++e) {
                        const uint32_t node = math::tape_node(tape[e]);
                        if (!sc.is_primitive(node))
                            may_decide = may_decide || math::blend_may_decide(s.value[s.left[e]],
                                                                              s.value[s.right[e]],
                                                                              sc.blend[node]);
                    }
                    const RefineNeed need =
                        refine_need(sc, tape, box, o.far_field, o.far_field_c, c.value, may_decide);
                    const int len = int(tape.size());
                    before[at.index] = len == 1 && !need.far ? 0 : len;
                    if (need.any) walked[at.index] = len;
                }
        const auto present = [](const std::vector<int>& v) {
            std::vector<uint32_t> out;
            for (const int x : v)
                if (x >= 0) out.push_back(uint32_t(x));
            return out;
        };
        const std::vector<uint32_t> all = present(before), apart = present(walked);
        std::vector<uint32_t> ordered = apart;
        std::stable_sort(ordered.begin(), ordered.end(),
                         [](uint32_t a, uint32_t b) { return walk_class(a) > walk_class(b); });
        uint64_t words = 0;
        for (const uint32_t len : apart) words += len;
        std::printf(
            "%s at %u³: %zu cells walked (%llu words) of %zu near cells of at most %u words; "
            "subgroup walk steps: before %llu, listed apart %llu, ordered %llu, ideal %llu\n",
            argv[1], N, apart.size(), (unsigned long long)words, all.size(), kLaneTape,
            (unsigned long long)subgroup_steps(all), (unsigned long long)subgroup_steps(apart),
            (unsigned long long)subgroup_steps(ordered),
            (unsigned long long)((words + kSubgroup - 1) / kSubgroup));
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "sdfprune_refine_lanes_model: %s\n", e.what());
        return 2;
    }
}
