// gpu_prune_plan.cpp — the shape of each pruning step on the device (gpu_prune.hpp): how many
// teams, squads, lanes or workgroups take its jobs, their scratch, their push constants and,
// under lavapipe's loop limit, how many jobs a dispatch takes; and which kernel runs it (teams,
// wide, refinement's lanes and squads). gpu_prune.cpp runs what is planned here.
#include <algorithm>
#include <bit>
#include <string>

#include "gpu_prune.hpp"

namespace sdfprune::gpu::pruning {

// Which steps run wide (prune_wide.comp): those with parent tapes of kWideMinTape words or
// more where the modelled cost is less than twice a team's longest walk. The cost is the wide
// walk with every round (a height of the tape, a workgroup barrier and a chain of global loads)
// counted kWideRoundCost times. Both constants fit the per-step GPU times measured on an NVIDIA
// H200 (stop 23: 18 steps of six scenes at levels 2 and 3, where the two kernels were timed
// against each other): a team's word costs up to twice a wide lane's, its scratch per lane
// being larger, and a round costs about four words. Any number of team jobs may run wide (a
// workgroup each, in a grid-stride loop): the generated fluid's level-2 octants, 3,518 team
// jobs, take 3.0 ms wide against 12.5 ms in teams. SDFPRUNE_VULKAN_WIDE=0 never, =1 wherever
// the kernel fits (for tests).
// A round in a run (a chain's operators, one a round, walked with no barrier between them)
// counts kWideRunRoundCost times instead: on an H200 molecule's four top steps, about 3,450
// such rounds, took 2.14 ms (stop 28), about 620 ns a round against 485-672 ns a team's word
// (stop 36), so a run's round costs about what a team's word does, twice a wide lane's word.
// (A run walked as it is, from scratch, costs more: on the same steps 3.18 ms; plan_wide then
// takes prune_wide_runs.comp for steps whose rounds are mostly in runs.)
// SDFPRUNE_VULKAN_WIDE_CHAINS=0 counts every round as a barrier's (before stop 50).
constexpr uint64_t kWideMinTape = 128, kWideRoundCost = 4, kWideRunRoundCost = 2;
constexpr uint64_t kWideSplitGroups = 64;  // plan_wide
// plan_wide splits a step's jobs further where the modelled cost falls to this share or less.
constexpr struct { uint64_t num, den; } kWideSplitGain{3, 4};
// Wide steps of at most kWideRunsJobs jobs over tapes of kWideRunsRounds heights or more run
// prune_wide_runs.comp (long runs walked from shared memory): on an H200 molecule's four top
// steps went from 3.18 to 2.14 ms, but its staging arrays slowed the steps of many jobs and
// short runs that shared the kernel (monument's level-2 cells 1.24 -> 1.97 ms; stop 28). So
// do steps of more jobs whose rounds are mostly in runs (plan_wide: a chain's).
constexpr uint64_t kWideRunsJobs = 512, kWideRunsRounds = 64;

// A step over the blocks [first_block, first_block + blocks), `jobs` cells or octants (or in
// refinement, mode 3, cells), `transient`: new tapes go to the octant pool (the finest cells'
// tapes before refinement): in teams (or wide). Refinement runs first a lane per cell
// (plan_refine_lanes; its second pass, plan_refine_more, over the cells its first listed),
// then, unless the cells' longest tape is short enough for the lanes, the squads over the cells
// the lanes listed (the long list, in scratch); without a lane pass (its setting 0, or no room
// for the list), squads alone.
std::vector<Step> Pruner::plan_step(const Level& lv, uint32_t mode, uint64_t first_block,
                                    uint64_t blocks, uint64_t jobs, const Buffer& octants,
                                    const Buffer& cells, bool transient) {
    Step teams = plan_teams(lv, mode, first_block, blocks, jobs, octants, cells, transient);
    // Workgroups take the jobs as they come free (prune_team.glsl: take_jobs), where a job is
    // done in one round (under a loop limit a job resumed over rounds keeps its team).
    if (take_jobs && mode <= kernel::kModeOctantCells && !teams.wide && teams.rounds == 1) {
        teams.push.flags |= kernel::kStepTakeJobs;
        teams.shape.taken = true;
    }
    if ((mode == kernel::kModeOctants || mode == kernel::kModeOctantCells) && !teams.wide &&
        team_order) {
        // The jobs in order of their parents' tape lengths (the blocks', the octants'), listed
        // past the teams' scratch by a pass before them (prune_team.glsl: order_parents), where
        // it fits.
        const uint64_t parents = mode == kernel::kModeOctants ? blocks : blocks * 8,
                       at = teams.scratch_words;
        if (parents > 0 && 4 * (at + parents) <= ctx.max_buffer_bytes()) {
            hold(scratch, 4 * (at + parents));
            teams.push.flags |=
                kernel::kStepTeamsOrdered | (snake ? 0u : kernel::kStepDealInRounds);
            teams.push.order_start = uint32_t(at);
            teams.push.order_first =
                uint32_t(mode == kernel::kModeOctants ? first_block : first_block * 8);
            if (team_order == 1) {  // each window of parents apart: the places alone
                Step place = plan_job_order(teams, parents, kernel::kModeOrderPlace);
                place.push.flags |= kernel::kStepOrderWindows;
                return {place, teams};
            }
            // The whole step: the classes counted, then the places.
            return {plan_job_order(teams, parents, kernel::kModeOrderCount),
                    plan_job_order(teams, parents, kernel::kModeOrderPlace), teams};
        }
    }
    if (mode != kernel::kModeRefine || lane_tape == 0 ||
        4 * teams.team_jobs > ctx.max_buffer_bytes())
        return {teams};
    // Scratch: the long list (a word a cell), then the more list (refine_more_words a listed
    // near cell), where the lane pass takes two passes: unless set off, or the lists would not
    // fit a buffer; then the order list (a word a listed near cell), unless set off or it would
    // not fit.
    const uint64_t more_bytes = 4 * refine_more_words(lane_tape) * uint64_t(lv.listed_cells);
    const bool more = refine_second_pass &&
                      uint64_t(opt.refine) * opt.refine * opt.refine > kRefineFirstBoxes &&
                      4 * teams.team_jobs + more_bytes <= ctx.max_buffer_bytes();
    const uint64_t order_at = teams.team_jobs + (more ? more_bytes / 4 : 0);
    const bool order = refine_order && lv.listed_cells > 0 &&
                       4 * (order_at + lv.listed_cells) <= ctx.max_buffer_bytes();
    Step lanes = plan_refine_lanes(teams, more);
    hold(scratch, 4 * (order ? order_at + lv.listed_cells : order_at));
    std::vector<Step> steps;
    if (order) {
        lanes.push.order_start = uint32_t(order_at);
        lanes.push.flags |= kernel::kStepRefineOrdered | (snake ? 0u : kernel::kStepDealInRounds);
        steps.push_back(plan_refine_order(lanes, lv.listed_cells));
    }
    steps.push_back(lanes);
    if (more) steps.push_back(plan_refine_more(lanes));
    if (max_len <= lane_tape) return steps;
    teams.listed = true;
    teams.push.flags |= kernel::kStepLongList;
    teams.shape.jobs = 0;  // the lanes' (one shape, add_shape)
    steps.push_back(teams);
    return steps;
}

// A step's jobs in teams (or wide, plan_wide), or in refinement squads (plan_squads).
Step Pruner::plan_teams(const Level& lv, uint32_t mode, uint64_t first_block, uint64_t blocks,
                        uint64_t jobs, const Buffer& octants, const Buffer& cells, bool transient) {
    const uint64_t hf = lv.f / 2;
    const auto teams_for = [](uint64_t boxes) { return ceil_div(boxes, kPruneTeam); };
    Step s;
    s.octants = &octants;
    s.cells = &cells;
    // Team jobs run block by block in every mode (prune_common.glsl: job_box).
    const uint64_t per_block_jobs = mode == kernel::kModeCells         ? teams_for(lv.per_block)
                                    : mode == kernel::kModeOctants     ? 1
                                    : mode == kernel::kModeOctantCells ? 8 * teams_for(hf * hf * hf)
                                                                       : lv.per_block;
    s.first_team_job = first_block * per_block_jobs;
    s.team_jobs = blocks * per_block_jobs;
    // Refinement takes the slice's listed near cells (a list a run, from 0).
    if (mode == kernel::kModeRefine) s.first_team_job = 0;
    if (s.first_team_job + s.team_jobs > 0xfffffffeull)
        throw std::length_error("too many cells in one level");
    if (mode == kernel::kModeRefine) {
        plan_squads(lv, s);
        return s;
    }
    // A team's scratch: its lanes' state, per stack slot and lane 4 words, per parent-tape
    // entry a left operand and the lanes' decision and sweep flags: a word per lane, or a byte
    // (prune_bytes.comp, where the device has 8-bit storage).
    s.kernel = byte_flags ? KernelId::kPruneBytes : KernelId::kPrune;
    const uint64_t flag_bytes = byte_flags ? 1 : 4;
    const uint64_t fixed_bytes = (kPruneStateWords + 4ull * max_depth) * kPruneTeam * 4;
    const uint64_t entry_bytes = 4 + kPruneTeam * flag_bytes;
    const uint64_t team_bytes = fixed_bytes + uint64_t(max_len) * entry_bytes;
    // Teams in flight: as many as have jobs, their scratch fits the budget and the device runs
    // at once (more would only queue, their scratch held for nothing; the teams take the jobs
    // in a grid-stride loop). Only teams with jobs hold scratch, so one parent tape as long as
    // the budget allows can be pruned (the root's, the full tree, at level 0) even where a
    // workgroup's 8 teams could not.
    const uint64_t fit = ctx.prune_scratch_budget_bytes() / team_bytes;
    if (fit == 0)
        throw GpuError("Vulkan: pruning a tape of " + std::to_string(max_len) + " words needs " +
                       std::to_string(team_bytes) +
                       " bytes of scratch, more than the device's buffers allow; use "
                       "--backend cpu");
    const uint64_t unlimited =
        std::min({std::max<uint64_t>(s.team_jobs, 1),
                  uint64_t(ctx.max_workgroups()) * (kWorkgroupSize / kPruneTeam),
                  std::max<uint64_t>(ctx.resident_threads() / kPruneTeam, 1)});
    s.teams = std::min(unlimited, fit);
    s.threads = uint32_t(s.teams * kPruneTeam);
    s.groups = uint32_t(ceil_div(s.threads, kWorkgroupSize));
    // Steps of a job: the evaluation window by window, the sweep and the write window by
    // window (and one to spare).
    const uint64_t per_job = 3 * ceil_div(max_len, kPruneWindow) + 2;
    // Under a loop limit (lavapipe), as many jobs per team and dispatch as fit the limit, or
    // one job resumed over as many rounds as its steps need; elsewhere one unlimited round. A
    // step's loops: staging the window, evaluating it, the sweep, the write; each over at most
    // the longest tape.
    const bool limited = ctx.loop_limited();
    const uint64_t step_len = std::min<uint64_t>(max_len, kPruneWindow);
    const uint64_t step_loops = kPruneWindow / kPruneTeam + 3 * step_len + 8;
    const uint64_t max_steps = (Context::kLoopLimit - 1024) / step_loops;
    s.rounds = limited ? ceil_div(per_job, max_steps) : 1;
    const uint32_t budget = !limited ? 0xffffffffu : uint32_t(s.rounds > 1 ? max_steps : per_job);
    s.per_dispatch = limited ? s.teams * std::max<uint64_t>(1, max_steps / per_job)
                             : std::max<uint64_t>(s.team_jobs, 1);
    s.push = push_for(lv, mode, s.threads, flags | (transient ? kernel::kStepTransientTapes : 0u),
                      budget);
    s.shape.level = lv.index;
    s.shape.mode = mode;
    s.shape.jobs = jobs;
    s.shape.lanes_per_tape = uint32_t(kPruneTeam);
    s.shape.lanes = std::min<uint64_t>(s.team_jobs, s.teams) * kPruneTeam;
    // A lane's walk per job: the evaluation, the sweep and the write.
    s.job_walk = 3 * max_len;
    s.shape.longest_walk_words = s.team_jobs == 0 ? 0 : ceil_div(s.team_jobs, s.teams) * s.job_walk;
    s.wide = false;
    // Each job's entries claimed for its own tape (prune_team.glsl: claim_entries), past the
    // teams' state and stacks, where the jobs' tapes sum to less than a longest tape per team:
    // the finer levels', where most teams take one job and most tapes are far shorter than the
    // longest.
    const uint64_t parent_jobs = mode == kernel::kModeOctants       ? 1
                                 : mode == kernel::kModeOctantCells ? teams_for(hf * hf * hf)
                                                                    : teams_for(lv.per_block);
    const uint64_t claimable_words = parent_jobs * lv.parent_tape_words;
    const uint64_t claim_bytes = claimable_words * entry_bytes;
    if (claims && lv.parent_tape_words > 0 && claim_bytes / 4 <= 0xffffffffull &&
        s.teams * fixed_bytes + claim_bytes < s.teams * team_bytes)
        s.push.claim_words = uint32_t(claim_bytes / 4);
    const auto teams_scratch = [&](const Step& t) {
        return t.push.claim_words != 0 ? t.teams * fixed_bytes + claim_bytes : t.teams * team_bytes;
    };
    uint64_t scratch_bytes = teams_scratch(s);
    const Step teams = s;
    if (wide_override != 0 && ctx.can_run(KernelId::kPruneWide))
        plan_wide(s, scratch_bytes, claimable_words);
    hold(scratch, scratch_bytes);
    // A wide step's further scratch buffers (those it does not take are given back: only the
    // top levels' steps spread, and the finer levels need the memory). Where the device has
    // no memory left for them (a small GPU, a large scene), the pruning goes on with one
    // buffer from then on.
    for (size_t b = s.scratch_buffers; b <= more_scratch.size(); ++b)
        ctx.destroy(*more_scratch[b - 1]);
    try {
        while (more_scratch.size() + 1 < s.scratch_buffers) more_scratch.push_back(&local.slot());
        for (uint32_t b = 1; b < s.scratch_buffers; ++b) hold(*more_scratch[b - 1], scratch_bytes);
    } catch (const GpuError&) {
        for (Buffer* b : more_scratch) ctx.destroy(*b);
        scratch_buffers_cap = 1;
        s = teams;
        scratch_bytes = teams_scratch(s);
        plan_wide(s, scratch_bytes, claimable_words);
        hold(scratch, scratch_bytes);
    }
    s.scratch_words = ceil_div(scratch_bytes, 4);
    s.shape.scratch_bytes = scratch_bytes * s.scratch_buffers;
    return s;
}

// An order pass before `step` (its kernel's, with the push constants the caller then sets): a
// counting sort of `items` entries, `per_group` a workgroup at a time, one such tile a
// workgroup and dispatch under a loop limit (lavapipe). It walks no tape; its time and
// dispatches are the step's (one shape).
Step Pruner::plan_order_pass(const Step& step, uint64_t items, uint64_t per_group) const {
    Step s = step;
    s.push.flags &= ~kernel::kStepTakeJobs;
    s.shape.taken = false;
    s.first_team_job = 0;
    s.team_jobs = items;
    s.groups = uint32_t(std::min<uint64_t>(ceil_div(items, per_group), ctx.max_workgroups()));
    s.threads = s.groups * kWorkgroupSize;
    s.push.threads = s.threads;
    s.teams = s.threads;
    s.rounds = 1;
    s.per_dispatch = ctx.loop_limited() ? uint64_t(s.groups) * per_group : items;
    s.job_walk = 0;
    s.shape.jobs = 0;
    s.shape.lanes = 0;
    s.shape.longest_walk_words = 0;
    return s;
}

// An order pass of a step in teams (prune_team.glsl: order_parents; `mode` 4 counts the
// parents by class, 5 places them; kStepOrderBlocks for the octants step's blocks): its `parents`,
// a window of kPruneOrderWindow a workgroup at a time.
Step Pruner::plan_job_order(const Step& step, uint64_t parents, uint32_t mode) const {
    Step s = plan_order_pass(step, parents, kPruneOrderWindow);
    if (step.push.mode == kernel::kModeOctants) s.push.flags |= kernel::kStepOrderBlocks;
    s.push.mode = mode;
    return s;
}

// A step's push constants (prune_common.glsl: Push): the level's, the parents' longest tape and
// deepest stack; record_step sets the pools' starts and each dispatch's jobs.
PrunePush Pruner::push_for(const Level& lv, uint32_t mode, uint32_t threads, uint32_t step_flags,
                           uint32_t budget) const {
    return PrunePush{vec4(origin.x, origin.y, origin.z, L),
                     vec4(lv.csize.x, lv.csize.y, lv.csize.z, opt.far_field_c),
                     mode,
                     lv.f,
                     0,
                     threads,
                     max_len,
                     max_depth,
                     step_flags,
                     0,
                     0,
                     0,
                     budget,
                     opt.refine,
                     0,
                     0,
                     0,
                     1,
                     0,
                     0,
                     0,
                     0,
                     0,
                     kPruneWalkSlots};
}

// The longest tape refinement's lanes take alone in the current slice (`lv`'s listed cells, by
// walk class). A squad refines a cell sooner than a lane (its lanes walk the sub-boxes at
// once), as long as the squads of the cells with longer tapes all run at once. Where they
// would take more than one round of the lanes the device runs at once, a lane a cell spreads
// them over more of the device instead. So the lanes take tapes of up to kRefineLaneTape
// words, and up to refine_lane_tape (kLaneTapeMax) where the cells of the walk classes past
// kRefineLaneTape (refine_walk_class: 4 words a class) would fill the device's lanes as
// squads more than once (at 256³ planned as on an H100, 270,336 lanes: trees' 40,033 such
// cells would take 1.28 M lanes; molecule's 3,861, 124 k).
uint32_t Pruner::choose_lane_tape(const Level& lv) const {
    if (lane_tape_fixed || refine_lane_tape <= kRefineLaneTape) return refine_lane_tape;
    uint64_t longer = 0;
    for (uint32_t c = kRefineLaneTape / 4; c < kRefineWalkClasses; ++c) longer += lv.walk_cells[c];
    return longer * kRefineSquad > ctx.resident_threads() ? refine_lane_tape : kRefineLaneTape;
}

// Refinement's lane pass (prune_refine_lanes.comp): a lane per listed cell, as many lanes as
// the device runs at once in a grid-stride loop, each refining its cell alone where its tape
// has at most lane_tape words, and listing it for the squads where not (from scratch
// word 0), and with `second_pass` walking only the first sub-boxes of each cell, listing the
// cells that need the others for its second pass (the more list, past the long list). Under a
// loop limit (lavapipe), as many cells per lane and dispatch as its loops allow: per cell, the
// tape staged, one walk per sub-box (every one, at most), the sweep and the write.
Step Pruner::plan_refine_lanes(const Step& squads, bool second_pass) const {
    Step s = squads;
    const uint64_t len = std::min<uint64_t>(max_len, lane_tape);
    const uint64_t subs = uint64_t(opt.refine) * opt.refine * opt.refine;
    const uint64_t walk = (second_pass ? std::min(subs, kRefineFirstBoxes) : subs) * len;
    const uint64_t per_cell = subs * len + subs + 3 * len + 8;
    const uint64_t cells = s.team_jobs;
    const uint64_t lanes =
        std::min({std::max<uint64_t>(cells, 1), uint64_t(ctx.max_workgroups()) * kWorkgroupSize,
                  std::max<uint64_t>(ctx.resident_threads(), 1)});
    s.kernel =
        lane_tape > kRefineLaneTape ? KernelId::kPruneRefineLanesLong : KernelId::kPruneRefineLanes;
    s.listed = false;
    s.teams = lanes;
    s.threads = uint32_t(ceil_div(lanes, kWorkgroupSize) * kWorkgroupSize);
    s.groups = uint32_t(s.threads / kWorkgroupSize);
    s.per_dispatch =
        ctx.loop_limited()
            ? s.threads * std::max<uint64_t>(1, (Context::kLoopLimit - 1024) / per_cell)
            : std::max<uint64_t>(cells, 1);
    s.push.threads = s.threads;
    s.push.list_start = 0;
    s.push.more_start = uint32_t(s.team_jobs);  // past the long list
    if (!second_pass) s.push.flags |= kernel::kStepRefineOnePass;
    if (!refine_sorted_more) s.push.flags |= kernel::kStepMoreAsListed;
    s.push.lane_tape = lane_tape;
    s.shape.lane_tape = lane_tape;
    s.job_walk = walk;
    s.shape.lanes_per_tape = 1;
    s.shape.lanes = lanes;
    s.shape.longest_walk_words = ceil_div(cells, lanes) * walk;
    return s;
}

// The lane pass's order pass (prune_refine_lanes.comp, kStepRefineOrderPass): the `listed` cells to
// decide again sorted by walk class into the order list, 64 a workgroup at a time.
Step Pruner::plan_refine_order(const Step& lanes, uint64_t listed) const {
    Step s = plan_order_pass(lanes, listed, kWorkgroupSize);
    s.order_pass = true;
    s.push.flags = (s.push.flags & ~kernel::kStepRefineOrdered) | kernel::kStepRefineOrderPass;
    return s;
}

// The lane pass's second pass (prune_refine_lanes.comp, kStepRefineSecondPass): the cells its first
// pass listed, decided over their other sub-boxes than the first kRefineFirstBoxes. Its jobs'
// count is the device's (more_jobs): its dispatches are recorded for all the first pass's.
Step Pruner::plan_refine_more(const Step& lanes) const {
    Step s = lanes;
    const uint64_t len = std::min<uint64_t>(max_len, lane_tape);
    const uint64_t subs = uint64_t(opt.refine) * opt.refine * opt.refine;
    s.second_pass = true;
    s.push.flags |= kernel::kStepRefineSecondPass;
    s.job_walk = (subs - kRefineFirstBoxes) * len;
    s.shape.jobs = 0;                // the first pass's (one shape, add_shape)
    s.shape.longest_walk_words = 0;  // counted once the list is known (run_steps)
    return s;
}

// Refinement's squads (prune_refine.comp): a squad of kRefineSquad lanes a listed cell, its
// sub-boxes a lane each, as many squads as the device runs at once, in a grid-stride loop over
// the list. Its jobs' count is the device's (refine_cells, or after a lane pass long_jobs):
// the dispatches are recorded for all the slice's cells. A lane's loops per job: staging the
// tape, one walk per batch of kRefineSquad sub-boxes over at most kRefineMaxTape words, the
// far-field test over the squad, the sweep and the write (one lane), or a chunk of a copied
// tape and the chunks' depths.
void Pruner::plan_squads(const Level& lv, Step& s) {
    const uint64_t len = max_len, walked = std::min<uint64_t>(len, math::kRefineMaxTape);
    const uint64_t subs = uint64_t(opt.refine) * opt.refine * opt.refine;
    const uint64_t batches = ceil_div(subs, kRefineSquad);
    const uint64_t per_job =
        2 * ceil_div(len, kRefineSquad) + batches * walked + 2 * walked + 2 * kRefineSquad + 8;
    const uint64_t squads =
        std::min({std::max<uint64_t>(s.team_jobs, 1),
                  uint64_t(ctx.max_workgroups()) * (kWorkgroupSize / kRefineSquad),
                  std::max<uint64_t>(ctx.resident_threads() / kRefineSquad, 1)});
    s.kernel = KernelId::kPruneRefine;
    s.teams = squads;
    s.threads = uint32_t(squads * kRefineSquad);
    s.groups = uint32_t(ceil_div(s.threads, kWorkgroupSize));
    s.rounds = 1;
    s.per_dispatch = ctx.loop_limited()
                         ? squads * std::max<uint64_t>(1, (Context::kLoopLimit - 1024) / per_job)
                         : std::max<uint64_t>(s.team_jobs, 1);
    s.push = push_for(lv, kernel::kModeRefine, s.threads, flags, 0);
    s.job_walk = batches * walked;
    s.wide = false;
    s.shape.level = lv.index;
    s.shape.mode = kernel::kModeRefine;
    s.shape.jobs = s.team_jobs;  // until the device's count is read back
    s.shape.lanes_per_tape = uint32_t(kRefineSquad);
    s.shape.lanes = std::min<uint64_t>(s.team_jobs, squads) * kRefineSquad;
    s.shape.longest_walk_words = ceil_div(s.team_jobs, squads) * s.job_walk;
}

// The wide kernel instead of teams, where it fits and its modelled cost wins (kWideRoundCost).
// Per job the tape entries a lane takes one after another (prune_wide.comp): its share of the
// entries counted, then placed (with a binary search for an operator's left operand: the
// scene's wide_search_steps on average, at most the tape's bit width under a loop limit), in the
// evaluation and the top-down pass its share of each round's entries and kPruneTeam boxes (at
// most one more than an even share per round: a round per height the tape has, no more than
// its operators plus one), and the compaction's two passes over a slice. A run of rounds of
// one operator each (a chain) is walked by kPruneTeam lanes, a step a round as before, but
// with no barrier between its rounds, kPruneWideRunChunk rounds at a time, each chunk staged in
// shared memory by the whole workgroup first (and a search of the chunk's rounds for its
// operands' entries). Its loops add the heights cleared and summed, the rounds (and the runs
// found among them) themselves and the prefix sums' steps: a job ends in the dispatch
// that starts it, within lavapipe's loop limit; only where twice that count fits (a deep chain
// near the limit came out wrong on lavapipe: the count is taken as approximate).
void Pruner::plan_wide(Step& s, uint64_t& scratch_bytes, uint64_t claimable_words) {
    const uint64_t len = max_len, heights = uint64_t(scene_height) + 1;
    const uint64_t rounds = std::min<uint64_t>(heights, len / 2 + 1);
    // The rounds that end at a barrier (in stages 2 and 4 each), at most: a round of more than
    // one entry (at a height the scene's operators share, or the primitives'), a run's last
    // round (runs lie between those), and in a long run one round a chunk (staged, or
    // scanned); the others are in runs. A job's rounds cost, beyond their walked words:
    const uint64_t barrier_rounds =
        !wide_chains ? rounds
                     : std::min(rounds, 2 * uint64_t(shared_heights) + 3 +
                                            ceil_div(rounds, kPruneWideRunChunk));
    const uint64_t round_cost = 2 * ((kWideRoundCost - 1) * barrier_rounds +
                                     (kWideRunRoundCost - 1) * (rounds - barrier_rounds));
    const uint64_t resident_groups = std::max<uint64_t>(ctx.resident_threads() / kPruneWide, 1);
    // Workgroups whose scratch fits a buffer, and all the buffers a step may spread over.
    const uint64_t buffers = std::min(ctx.prune_scratch_buffers(), scratch_buffers_cap);
    const bool limited = ctx.loop_limited();
    // A workgroup's scratch with `split` workgroups per job: per tape entry two words, and the
    // items of its own kPruneTeam / split boxes.
    const auto group_bytes_for = [&](uint64_t split) {
        return (len * 2 + prune_wide_item_words(len * (kPruneTeam / split)) +
                kPruneWideHeightWords * heights) *
               4;
    };
    const auto fitting = [&](uint64_t split) {
        return buffers * (ctx.prune_scratch_budget_bytes() / group_bytes_for(split));
    };
    // The step's shape and modelled cost with `split` workgroups per job: how many workgroups
    // fit, how they spread over buffers, the jobs each takes one after another, its walk.
    struct Shape {
        uint64_t split, group_bytes, per_job, spread, dispatch_groups, groups, walk, cost;
        bool fits;
    };
    const auto shape_for = [&](uint64_t split) {
        Shape w{};
        w.split = split;
        const uint64_t boxes = kPruneTeam / split;
        w.group_bytes = group_bytes_for(split);
        // A job's walk over a tape of `n` entries, `search` steps a search.
        const auto job_walk = [&](uint64_t n, uint64_t search) {
            return prune_wide_job_walk(n, rounds, boxes, search);
        };
        const uint64_t walk_job = job_walk(len, wide_search_steps);
        // (Under a loop limit, with every search as long as the whole tape's.)
        w.per_job = job_walk(len, std::max<uint64_t>(std::bit_width(len), wide_search_steps)) +
                    3 * ceil_div(heights, kPruneWide) + ceil_div(rounds, kPruneWide) + 2 * rounds +
                    2 * ceil_div(rounds, kPruneWideRunChunk) * (kPruneWideRunChunk + 4) +
                    4 * std::bit_width(kPruneWide);
        const uint64_t buffer_groups = ctx.prune_scratch_budget_bytes() / w.group_bytes;
        w.fits = buffer_groups > 0 && !(limited && 2 * w.per_job + 1024 > Context::kLoopLimit);
        if (!w.fits) return w;
        const uint64_t parts = s.team_jobs * split;
        const uint64_t unlimited_groups = std::min(
            {std::max<uint64_t>(parts, 1), uint64_t(ctx.max_workgroups()), resident_groups});
        // As few buffers as hold the workgroups, as many workgroups in each.
        w.spread = std::min(buffers, ceil_div(unlimited_groups, buffer_groups));
        w.dispatch_groups = std::min(buffer_groups, ceil_div(unlimited_groups, w.spread));
        w.groups = w.spread * w.dispatch_groups;
        const uint64_t group_jobs = ceil_div(parts, w.groups);
        // A workgroup of several jobs walks their tapes one after another: the longest, and
        // the jobs' mean tape for each of the others (`claimable_words`: the jobs' tapes
        // summed, a bound).
        const uint64_t mean = s.team_jobs == 0 ? 0 : ceil_div(claimable_words, s.team_jobs);
        w.walk = s.team_jobs == 0 ? 0
                 : !wide_mean || mean >= len
                     ? group_jobs * walk_job
                     : walk_job + (group_jobs - 1) * job_walk(mean, wide_search_steps);
        w.cost = w.walk + group_jobs * round_cost;
        return w;
    };
    // Workgroups per job (wide_split): where a step has very few jobs (level 0: the root's 64
    // cells are 8; split into octants, one, then 8), a job's boxes are shared out among up to
    // kPruneTeam workgroups, each walking the tape for its share (all of them sort it), up to
    // kWideSplitGroups workgroups in all. On an H200, level 0 of the generated fluid (then its
    // octants, then its cells) went from 2.47 and 3.32 ms to 0.74 and 1.11 ms; level 1's steps
    // (63 and 504 jobs) ran slower split than not (stop 28).
    uint64_t split = 1;
    while (split < kPruneTeam && std::max<uint64_t>(s.team_jobs, 1) * split * 2 <=
                                     std::min(kWideSplitGroups, resident_groups))
        split *= 2;
    // Where scratch holds the step to fewer workgroups than it has jobs and the device runs
    // (the million-sphere fluid's top levels: parent tapes of a million words and more), the
    // jobs are split further, as long as more workgroups then fit: a workgroup of 1 box in 8
    // needs 5.25 words an entry instead of 28.
    while (split < kPruneTeam && fitting(split) < std::min(s.team_jobs * split, resident_groups) &&
           fitting(2 * split) > fitting(split))
        split *= 2;
    // Split further where the modelled cost falls to kWideSplitGain of the best so far or
    // less: where the jobs' tapes are wide (not a chain, whose rounds no split shortens) and
    // more workgroups still run at once. Planned as on an H100, the generated fluid's level-1
    // octants (64 team jobs) walk 743 words split 8 against 3,402 whole, and its level-1 cells
    // (512) 1,385 split 2 against 2,489 (measured on lavapipe); molecule's chains stay whole.
    Shape w = shape_for(split);
    if (w.fits && wide_split_by_cost)
        for (uint64_t more = split * 2; more <= kPruneTeam; more *= 2)
            if (const Shape m = shape_for(more);
                m.fits && m.cost * kWideSplitGain.den < w.cost * kWideSplitGain.num)
                w = m;
    if (wide_split > 0) w = shape_for(wide_split);
    if (!w.fits) return;
    split = w.split;
    const uint64_t group_bytes = w.group_bytes, per_job = w.per_job, spread = w.spread;
    const uint64_t dispatch_groups = w.dispatch_groups, groups = w.groups;
    const uint64_t parts = s.team_jobs * split, walk = w.walk, cost = w.cost;
    const bool pick =
        wide_override == 1 || (len >= kWideMinTape && cost < 2 * s.shape.longest_walk_words);
    if (!pick) return;
    s.wide = true;
    s.teams = groups;
    s.groups = uint32_t(dispatch_groups);
    s.scratch_buffers = uint32_t(spread);
    s.threads = uint32_t(groups * kPruneWide);
    s.rounds = 1;
    s.per_dispatch =
        limited
            ? std::max<uint64_t>(
                  1, groups * std::max<uint64_t>(1, (Context::kLoopLimit - 1024) / (2 * per_job)) /
                         split)
            : std::max<uint64_t>(s.team_jobs, 1);
    s.push.threads = s.threads;
    s.push.max_stack = scene_height;
    s.push.wide_split = uint32_t(split);
    // Parts taken as workgroups come free (prune_wide.glsl: take_part), as the team steps take
    // their jobs; under a loop limit (push budget other than 0xffffffff) each workgroup takes
    // at most the parts it would be dealt.
    s.shape.taken = wide_take;
    if (wide_take) s.push.flags |= kernel::kStepTakeJobs;
    s.push.budget = limited ? 1u : 0xffffffffu;
    if (!wide_scan) s.push.flags |= kernel::kStepWideNoScan;
    // (Or any number of jobs where at most a quarter of the rounds end at a barrier: a chain's
    // steps, whose runs are long, as molecule's level-2 octants, 1,675 jobs. The staged walk
    // is what kWideRunRoundCost was measured on.)
    // (Never without the chains' model, whose barrier rounds are then all the rounds.)
    const bool mostly_runs = 4 * barrier_rounds <= rounds;
    const bool runs =
        wide_runs_override == 1 || (wide_runs_override != 0 && rounds >= kWideRunsRounds &&
                                    (s.team_jobs <= kWideRunsJobs || mostly_runs));
    s.kernel = runs && ctx.can_run(KernelId::kPruneWideRuns) ? KernelId::kPruneWideRuns
               : ctx.can_run(KernelId::kPruneWideSubgroups)  ? KernelId::kPruneWideSubgroups
                                                             : KernelId::kPruneWide;
    s.shape.wide = true;
    s.shape.wide_runs = s.kernel == KernelId::kPruneWideRuns;
    s.shape.lanes_per_tape = uint32_t(kPruneWide * split);
    s.shape.lanes = std::min<uint64_t>(parts, groups) * kPruneWide;
    s.shape.longest_walk_words = walk;
    scratch_bytes = dispatch_groups * group_bytes;  // in each buffer
    // Each job's items claimed for its own tape (prune_wide.glsl: claim_items) where the jobs'
    // tapes (`claimable_words` at most, all jobs' shares together) sum to less than the
    // longest tape per workgroup, in one buffer: the same workgroups, their scratch without
    // items. The generated fluid's level-1 cells (512 jobs of 8 cells, a workgroup each, over
    // parent tapes of up to 5,000 words summing to 4.5 million) then take 0.66 GB instead of
    // 1.4 (planned as on an H100).
    // (Each of a job's `split` workgroups claims the items of its boxes: all of them together
    // at most the items of all boxes at once and a word each for their flags' last bytes.)
    const uint64_t items_bytes = prune_wide_item_words(len * (kPruneTeam / split)) * 4;
    const uint64_t claim_bytes =
        (prune_wide_item_words(claimable_words * kPruneTeam) + s.team_jobs * split) * 4;
    s.push.claim_words = 0;
    if (claims && spread == 1 && claimable_words > 0 && claim_bytes / 4 <= 0xffffffffull &&
        groups * (group_bytes - items_bytes) + claim_bytes < scratch_bytes) {
        s.push.claim_words = uint32_t(claim_bytes / 4);
        scratch_bytes = groups * (group_bytes - items_bytes) + claim_bytes;
    }
}

}  // namespace sdfprune::gpu::pruning
