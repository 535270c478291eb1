// prune_order_model.cpp — a model of how long the Vulkan backend's finest pruning steps wait on
// their longest walk, computed on the CPU, so that a change of their job order can be judged
// without a GPU (issue 13). Three steps, each run by groups of lanes that take neighbouring
// jobs and walk as long as the group's longest tape:
//   - the finest level's octants step in teams: a workgroup's 8 teams take 8 blocks, each
//     walking its block's tape. In storage order, or sorted by class in windows of 256 (the
//     order pass, SDFPRUNE_VULKAN_TEAM_ORDER=1), or the whole step sorted;
//   - the finest level's cells step in teams (shaders/gpu/prune_team.glsl): a workgroup's 8
//     teams take 8 jobs, each the cells of one octant pruned from the octant's tape (none
//     where the octant is far-field). Block by block, the 8 octants of a block; in windows,
//     each window of 256 octants sorted by class of tape length (parent_class, the order
//     pass, SDFPRUNE_VULKAN_TEAM_ORDER=1); and, for comparison, the whole step sorted;
//   - refinement's lane pass (shaders/gpu/prune_refine_lanes.comp): a subgroup's 32 lanes take
//     32 cells, each walking its own tape (at most 32 words). Before: every near cell listed,
//     a lone primitive that cannot turn far-field copied (0); apart: the cells with nothing to
//     try (refine_need) copied apart; ordered: the others sorted by walk class.
// For each, the sum over the groups of the group's longest tape, and the ideal (the words over
// the group's lanes); and the critical path (critical_path): the longest a workgroup walks
// when the jobs are dealt out to an H100's resident teams as the kernels deal them, in rounds
// (stops 39-44) or in a snake (stop 45, the order sorted whole), or taken as workgroups come
// free (the team steps since stop 46: prune_team.glsl, take_jobs), against its floor (the
// longest tape, or the words over the teams); and the same where fewer workgroups fit the
// device at once than the plan's (critical_path_in_waves). The tapes are the CPU's, which the
// GPU's equal: the octants' pruned from their blocks' tapes (the coarse level's, kept), the
// cells' as the grid without refinement has them. The orders are the level's storage order, about
// the order the device lists the blocks and cells in (its atomics spread the cells further).
// And the octants steps of the levels between the top and the finest as wide steps
// (shaders/gpu/prune_wide.glsl), a workgroup of 256 lanes a job of a block's 8 octants, the
// jobs' parents each coarse level's near cells (only where the level has an octants step: a
// top level without octants takes 8 jobs a parent instead, and the finest level's octants run
// in teams, as above): their critical path on an H100's 1,056 resident workgroups of 256 when
// the jobs are dealt out in advance (workgroup w's are w, w + 1,056, ...) or taken as
// workgroups come free (take_part), each job's walk as plan_wide models it
// (src/gpu/device_layout.hpp: prune_wide_job_walk).
//
// Usage: sdfprune_order_model SCENE [GRID]
#include <algorithm>
#include <bit>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <functional>
#include <utility>
#include <vector>

#include "sdfprune/io.hpp"
#include "sdfprune/prune.hpp"
#include "src/gpu/device_layout.hpp"

using namespace sdfprune;

namespace {

// A team step's workgroup: 8 teams (prune_team.glsl: kTeams). NVIDIA's subgroups: 32 lanes.
// The kernels' sizes are device_layout.hpp's (shaders/gpu/prune_constants.h).
constexpr uint32_t kTeams = 8, kSubgroup = 32;
constexpr uint32_t kLaneTape = gpu::kRefineLaneTape, kOrderWindow = gpu::kPruneOrderWindow;

// prune_team.glsl: parent_class (0: far-field); prune_common.glsl: refine_walk_class.
uint32_t parent_class(uint32_t len) {
    if (len == 0) return 0;
    const uint32_t k = uint32_t(std::bit_width(len)) - 1;
    const uint32_t upper = k > 0 && len >= (3u << (k - 1)) ? 1 : 0;
    return std::min(1 + 2 * k + upper, 31u);
}
uint32_t walk_class(uint32_t len) {
    return std::min((len - 1) / 4, 15u);
}

// Sum over groups of `group` consecutive jobs of the group's longest tape.
uint64_t group_steps(const std::vector<uint32_t>& lengths, uint32_t group) {
    uint64_t steps = 0;
    for (size_t i = 0; i < lengths.size(); i += group)
        steps += *std::max_element(lengths.begin() + i,
                                   lengths.begin() + std::min(lengths.size(), i + group));
    return steps;
}

// `lengths` sorted by class, the highest first, each window of `window` apart (0: all at once).
template <class Class>
std::vector<uint32_t> ordered(std::vector<uint32_t> lengths, Class cls, size_t window = 0) {
    if (window == 0) window = std::max<size_t>(lengths.size(), 1);
    for (size_t i = 0; i < lengths.size(); i += window)
        std::stable_sort(lengths.begin() + i,
                         lengths.begin() + std::min(lengths.size(), i + window),
                         [&](uint32_t a, uint32_t b) { return cls(a) > cls(b); });
    return lengths;
}

// The step's critical path when its jobs are dealt out as the kernels deal them: `teams`
// teams (a team or subgroup per job; resident threads / lanes per job), job j to team j mod
// teams in round j / teams, and `per_group` teams a workgroup (or 1), which walk a round as long
// as their longest tape. Returned: the largest sum over a workgroup's rounds. `snake`: odd
// rounds deal the jobs out from the last team to the first.
std::vector<uint64_t> dealt_loads(const std::vector<uint32_t>& ranked, uint32_t teams,
                                  uint32_t per_group, bool snake) {
    const uint32_t groups = teams / per_group;
    std::vector<uint64_t> load(groups, 0);
    for (size_t r0 = 0, round = 0; r0 < ranked.size(); r0 += teams, ++round)
        for (uint32_t g = 0; g < groups; ++g) {
            uint32_t longest = 0;
            for (uint32_t k = 0; k < per_group; ++k) {
                const uint32_t team = g * per_group + k;
                const size_t j = r0 + (snake && round % 2 == 1 ? teams - 1 - team : team);
                if (j < ranked.size()) longest = std::max(longest, ranked[j]);
            }
            load[g] += longest;
        }
    return load;
}
uint64_t critical_path(const std::vector<uint32_t>& ranked, uint32_t teams, uint32_t per_group,
                       bool snake) {
    const std::vector<uint64_t> load = dealt_loads(ranked, teams, per_group, snake);
    return *std::max_element(load.begin(), load.end());
}

// When the last of `works` ends, each started in order on whichever of `slots` comes free
// first (the device's workgroup slots).
uint64_t end_on_slots(const std::vector<uint64_t>& works, size_t slots) {
    std::vector<uint64_t> free_at(std::max<size_t>(std::min(slots, works.size()), 1), 0);
    uint64_t end = 0;  // free_at: a min-heap
    for (const uint64_t w : works) {
        std::pop_heap(free_at.begin(), free_at.end(), std::greater<>());
        free_at.back() += w;
        end = std::max(end, free_at.back());
        std::push_heap(free_at.begin(), free_at.end(), std::greater<>());
    }
    return end;
}

// The same where only `resident` of the workgroups fit the device at once (their registers):
// the others start in order as resident ones end, each with the jobs dealt to it.
uint64_t critical_path_in_waves(const std::vector<uint32_t>& ranked, uint32_t teams,
                                uint32_t per_group, bool snake, uint32_t resident) {
    return end_on_slots(dealt_loads(ranked, teams, per_group, snake), resident);
}

// The same with the jobs taken as workgroups come free (a counter each takes its next
// per_group jobs from), the workgroups all resident.
uint64_t critical_path_taken(const std::vector<uint32_t>& ranked, uint32_t teams,
                             uint32_t per_group) {
    std::vector<uint64_t> takes;  // each take's walk: its per_group jobs' longest
    for (size_t j = 0; j < ranked.size(); j += per_group)
        takes.push_back(*std::max_element(ranked.begin() + j,
                                          ranked.begin() + std::min(ranked.size(), j + per_group)));
    return end_on_slots(takes, teams / per_group);
}

uint64_t ideal(const std::vector<uint32_t>& lengths, uint32_t group) {
    uint64_t words = 0;
    for (const uint32_t len : lengths) words += len;
    return (words + group - 1) / group;
}

std::span<const uint32_t> tape_of(const PrunedGrid& grid, const PrunedCell& c) {
    return grid.tape_pool().subspan(c.tape + 2, grid.tape_pool()[c.tape]);
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
        o.refine = 1;           // the cells' tapes before refinement
        o.coarse_tapes = true;  // the blocks' tapes
        const PrunedGrid grid = prune(sc, o);
        const uint32_t finest = grid.level_count() - 1, N = grid.resolution();
        if (finest == 0 || grid.level_factor(finest - 1) % 2 != 0) {
            std::fprintf(stderr, "the grid's finest level is not split in octants\n");
            return 2;
        }
        const uint32_t f = grid.level_factor(finest - 1), hf = f / 2;
        const vec3 cell_size = (sc.aabb.max - sc.aabb.min) / float(N), half = cell_size * 0.5f;
        CellScratch s;
        std::vector<uint32_t> scratch_tape;

        // The finest level's blocks (its parents' near cells) in storage order, and their
        // octants' tape lengths.
        std::vector<std::pair<uint32_t, uint32_t>> blocks;  // (storage index, finest origin)
        const uint32_t P = grid.level_resolution(finest - 1);
        std::vector<uint32_t> origin_of(grid.level_cells(finest - 1).size(), ~0u);
        for (uint32_t z = 0; z < P; ++z)
            for (uint32_t y = 0; y < P; ++y)
                for (uint32_t x = 0; x < P; ++x) {
                    const PrunedGrid::CellRef at = grid.descend(x * f, y * f, z * f, finest - 1);
                    if (at.level == finest - 1 &&
                        grid.level_cells(at.level)[at.index].tape != PrunedCell::kFarField)
                        origin_of[at.index] = (z * P + y) * P + x;
                }
        std::vector<uint32_t> octants, block_lengths;
        for (uint32_t i = 0; i < origin_of.size(); ++i) {
            if (origin_of[i] == ~0u) continue;
            const uint32_t x = origin_of[i] % P * f, y = origin_of[i] / P % P * f,
                           z = origin_of[i] / (P * P) * f;
            const std::span<const uint32_t> parent = tape_of(grid, grid.level_cells(finest - 1)[i]);
            block_lengths.push_back(uint32_t(parent.size()));
            for (uint32_t oc = 0; oc < 8; ++oc) {
                const vec3 corner(float(x + (oc & 1) * hf), float(y + (oc >> 1 & 1) * hf),
                                  float(z + (oc >> 2 & 1) * hf));
                const CellBox box{sc.aabb.min + (corner + vec3(0.5f * float(hf))) * cell_size,
                                  half * float(hf), math::length(half) * float(hf)};
                evaluate_cell(sc, parent, box, o.bounds, s);
                float constant = 0;
                if (o.far_field && !is_near_field(sc, parent, box, o.far_field_c, s, constant)) {
                    octants.push_back(0);
                    continue;
                }
                scratch_tape.clear();
                compact_tape(sc, parent, s, scratch_tape);
                octants.push_back(uint32_t(std::min(scratch_tape.size(), parent.size())));
            }
        }

        // Refinement's cells of at most kLaneTape words, in storage order.
        std::vector<int> before(grid.level_cells(finest).size(), -1), walked(before);
        for (uint32_t z = 0; z < N; ++z)
            for (uint32_t y = 0; y < N; ++y)
                for (uint32_t x = 0; x < N; ++x) {
                    const PrunedGrid::CellRef at = grid.descend(x, y, z, finest);
                    const PrunedCell& c = grid.level_cells(at.level)[at.index];
                    if (at.level != finest || c.tape == PrunedCell::kFarField) continue;
                    const std::span<const uint32_t> tape = tape_of(grid, c);
                    if (tape.size() > kLaneTape) continue;  // the squads'
                    const CellBox box{sc.aabb.min + vec3(x + 0.5f, y + 0.5f, z + 0.5f) * cell_size,
                                      half, math::length(half)};
                    const RefineNeed need = refine_need_of_tape(sc, tape, box, o, c.value, s);
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

        std::printf("%s at %u³\n", argv[1], N);
        std::printf(
            "  octants step (teams, %zu blocks): group walk steps: in storage order %llu, in "
            "windows %llu, sorted whole %llu, ideal %llu\n",
            block_lengths.size(), (unsigned long long)group_steps(block_lengths, kTeams),
            (unsigned long long)group_steps(ordered(block_lengths, parent_class, kOrderWindow),
                                            kTeams),
            (unsigned long long)group_steps(ordered(block_lengths, parent_class), kTeams),
            (unsigned long long)ideal(block_lengths, kTeams));
        std::printf(
            "  cells step (teams, %zu octants of %zu blocks): group walk steps: block by block "
            "%llu, in windows %llu, sorted whole %llu, ideal %llu\n",
            octants.size(), octants.size() / 8, (unsigned long long)group_steps(octants, kTeams),
            (unsigned long long)group_steps(ordered(octants, parent_class, kOrderWindow), kTeams),
            (unsigned long long)group_steps(ordered(octants, parent_class), kTeams),
            (unsigned long long)ideal(octants, kTeams));
        std::printf(
            "  refinement's lane pass (%zu cells walked of %zu near cells of at most %u "
            "words): subgroup walk steps: before %llu, listed apart %llu, ordered %llu, ideal "
            "%llu\n",
            apart.size(), all.size(), kLaneTape, (unsigned long long)group_steps(all, kSubgroup),
            (unsigned long long)group_steps(apart, kSubgroup),
            (unsigned long long)group_steps(ordered(apart, walk_class), kSubgroup),
            (unsigned long long)ideal(apart, kSubgroup));
        // The critical path (critical_path) with the H100's and H200's 270,336 resident threads
        // (132 SMs of 2,048): the teams steps' 33,792 teams, 8 a workgroup; the lane pass's
        // 270,336 lanes in subgroups of 32. Its floor: the longest tape, or the words over the
        // teams.
        constexpr uint32_t kResident = 270336, kResidentTeams = kResident / gpu::kPruneTeam;
        const auto paths = [&](const char* what, const std::vector<uint32_t>& lengths,
                               const char* order_name, const std::vector<uint32_t>& order,
                               uint32_t teams, uint32_t per_group) {
            const uint64_t longest =
                lengths.empty() ? 0 : *std::max_element(lengths.begin(), lengths.end());
            const std::vector<uint32_t> sorted = ordered(lengths, parent_class);
            std::printf(
                "  %s, critical path (words, %u teams): in storage order %llu, %s %llu, the same "
                "dealt in a snake %llu, sorted whole in a snake %llu, taken as workgroups come "
                "free: %s %llu, sorted whole %llu; floor %llu\n",
                what, teams, (unsigned long long)critical_path(lengths, teams, per_group, false),
                order_name, (unsigned long long)critical_path(order, teams, per_group, false),
                (unsigned long long)critical_path(order, teams, per_group, true),
                (unsigned long long)critical_path(sorted, teams, per_group, true), order_name,
                (unsigned long long)critical_path_taken(order, teams, per_group),
                (unsigned long long)critical_path_taken(sorted, teams, per_group),
                (unsigned long long)std::max(longest, ideal(lengths, teams)));
        };
        paths("octants step", block_lengths, "in windows",
              ordered(block_lengths, parent_class, kOrderWindow), kResidentTeams, kTeams);
        paths("cells step", octants, "in windows", ordered(octants, parent_class, kOrderWindow),
              kResidentTeams, kTeams);
        // The team kernel's workgroups that fit an SM at once, by its registers: 56 a lane
        // (BENCHMARKS.md, stop 36) leave room for 18 workgroups of 64 lanes of the 32 planned
        // for, 2,376 of the 4,224 on an H100's 132 SMs. Dealt jobs then wait for the
        // workgroups that start late; taken ones go to the workgroups that run.
        constexpr uint32_t kResidentGroups = 132 * 18;
        const auto waves = [&](const char* what, const std::vector<uint32_t>& order) {
            std::printf(
                "  %s, critical path with %u workgroups resident (words): in windows dealt in a "
                "snake %llu, taken as workgroups come free %llu\n",
                what, kResidentGroups,
                (unsigned long long)critical_path_in_waves(order, kResidentTeams, kTeams, true,
                                                           kResidentGroups),
                (unsigned long long)critical_path_taken(order, kResidentGroups * kTeams, kTeams));
        };
        waves("octants step", ordered(block_lengths, parent_class, kOrderWindow));
        waves("cells step", ordered(octants, parent_class, kOrderWindow));
        paths("lane pass", apart, "by walk class", ordered(apart, walk_class), kResident,
              kSubgroup);

        // The wide steps: the scene's heights and search steps as gpu_prune.cpp counts them.
        const gpu::WideSceneShape wide = gpu::wide_scene_shape(sc);
        const uint64_t rounds = uint64_t(wide.height) + 1, search = wide.search_steps;
        constexpr uint32_t kWideGroups = kResident / gpu::kPruneWide;
        // Only the levels above the finest that have an octants step, as gpu_prune.cpp splits
        // them.
        for (uint32_t l = 0; l + 1 < finest; ++l) {
            const uint32_t res = grid.level_resolution(l + 1);
            if (!gpu::level_splits_into_octants(sc, o, res, res / grid.level_resolution(l)))
                continue;
            std::vector<uint64_t> walks;
            for (const PrunedCell& c : grid.level_cells(l))
                if (c.tape != PrunedCell::kFarField)
                    walks.push_back(gpu::prune_wide_job_walk(tape_of(grid, c).size(), rounds,
                                                             gpu::kPruneTeam, search));
            if (walks.empty()) continue;
            const size_t groups = std::min<size_t>(kWideGroups, walks.size());
            std::vector<uint64_t> dealt(groups, 0);
            uint64_t longest = 0, words = 0;
            for (size_t j = 0; j < walks.size(); ++j) {
                dealt[j % groups] += walks[j];
                longest = std::max(longest, walks[j]);
                words += walks[j];
            }
            std::printf(
                "  level %u's octants step, wide (%zu jobs: level %u's near cells), critical path "
                "(words, %u workgroups): dealt %llu, taken as workgroups come free %llu; floor "
                "%llu\n",
                l + 1, walks.size(), l, kWideGroups,
                (unsigned long long)*std::max_element(dealt.begin(), dealt.end()),
                (unsigned long long)end_on_slots(walks, groups),
                (unsigned long long)std::max(longest, (words + kWideGroups - 1) / kWideGroups));
        }
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "sdfprune_order_model: %s\n", e.what());
        return 2;
    }
}
