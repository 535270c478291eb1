// prune_team.glsl — prune.comp: one pruning step of a level, on teams of kTeam lanes: a team
// walks one parent tape in lockstep, each lane pruning one box from it. Mirrors
// src/prune/prune_cell.cpp stage for stage (evaluate_boxes over sibling lanes, is_near_field,
// compact_tape in each lane) and the octant split of src/prune/prune.cpp. A team's job:
//   mode 0: kTeam cells of a block, from the block's tape
//   mode 1: the 8 octants of a block, from the block's tape (not stored as cells)
//   mode 2: kTeam cells of an octant, from the octant's tape (or far-field from a far octant)
// (Refinement, mode 3, is prune_refine.comp's.) Mode 4 orders modes 1 and 2's jobs (below).
// The kernel runs in steps, the same for every lane of a workgroup: at each step a team that
// evaluates stages the next kWindow words of its tape in shared memory, then every lane advances
// its phase by at most kWindow entries (evaluation from the window; the far-field test; the
// top-down sweep; the write of the compacted tape). During evaluation every lane of a team runs
// the same entry at the same step. Decisions and the sweep's flags are kept per lane and entry,
// interleaved so that a team's lanes touch adjacent words. The entries' nodes are read from the
// scene's buffer, not staged: on an H100, staging them too (8 KB of shared memory a workgroup,
// 10 more registers) left less of the SM's memory to the cache that serves the scratch, and the
// finer levels' steps ran up to 2× slower (BENCHMARKS.md, stop 30).
// New tapes are appended to the pool with an atomic counter; on overflow nothing is written
// (the box is stored as far-field) and the host grows the pool and runs the steps again.
//
// A job is resumable: its lanes' state lives in the team's scratch, and each dispatch (a
// "round") runs at most pc.budget steps of it. Devices without a loop limit use one round with
// an unlimited budget; lavapipe, which ends an invocation's loops after 65,535 iterations in
// all, gets as many jobs per team and dispatch as fit that, or one job over as many rounds as
// its steps need (gpu_prune.cpp counts them).
#include "scene.glsl"
#include "prune_constants.h"

const uint kTeams = 8u;  // teams per workgroup
layout(local_size_x = kTeams * kTeam) in;

#include "cells.glsl"
#include "prune_common.glsl"

// Per team (team_words): the lanes' job state (kStateWords each) and 4 words per stack slot and
// lane (value, lo, hi, entry), then per entry of its job's parent tape (len words) the entry's
// left operand (one word, the same in every lane) and its decision and sweep flags
// (kEntryFlagWords: a word per lane, or with PRUNE_BYTE_FLAGS a byte, a third of the entry's
// scratch). Lane l's word (or byte) of item k is at k · kTeam + l. A team's entries are sized
// for the step's longest parent tape, or, where the jobs' tapes are known to sum to less
// (pc.claim_words > 0, gpu_prune_plan.cpp), each job claims room for its own tape's entries
// from the area past the teams' (claim_entries): molecule's level-3 octants, 31,556 jobs on as
// many teams, whose tapes reach 199 words but sum to 2.9 million, take 129 MB of scratch
// instead of 250 (planned as on an H100).

// The team's scratch, through a second view of the scratch buffer (binding 12, the same buffer
// as binding 8) without `coherent`: a lane reads only words it wrote itself (its state, its
// stack, its decisions and flags; an entry's left operand is written by every lane of the team,
// the same value), so program order suffices (a job resumed in a later dispatch reads them
// after the dispatch's barrier), and its loads may be served from the SM's cache, where the
// coherent view's go to the device's: on an H100 the team steps ran 2–33 % faster so
// (BENCHMARKS.md, stop 30). This kernel does not use the coherent view.
layout(std430, binding = 12) buffer LaneScratch { uint lane_scratch[]; };

// A team's window of its parent tape, staged for the step: each entry's tape word with bit 30
// set where its node is a primitive (kStagedPrimitive; node indices are below 2^28 on a device,
// gpu_prune.cpp). The staging reads the entries' nodes side by side, a lane taking every
// kTeam-th; the walk then knows a primitive from its word and reads the primitive's parameters
// (in node order, scene.glsl) beside its node, where it read them after the node.
shared uint s_word[kTeams * kWindow];
uint staged_node(uint w) { return w & (kStagedPrimitive - 1u); }
// Lanes still busy after a step, counted in one word while the other is reset.
shared uint s_busy[2];
// Per step (two, alternately), the workgroup's lanes still sweeping after it: a lane whose
// sweep has ended takes its new tape's place, lists its cell for refinement and writes from the
// step after the workgroup's last sweep ended. A lane's sweep ends where it has reached every
// entry it kept, and its write starts at the last one it kept (as low as the tape's first
// entry, or high in it): lanes whose sweeps ended apart would each run one phase's loop while
// the others run the other's, the workgroup running both loops in every such step (on the
// generated fluid, 3 % more steps than where every sweep passes over the whole tape), and
// their appends would take an atomic each. So the sweeps and the writes take no longer than
// the longest of the workgroup, less where every lane ends early, and the appends are made
// by all the lanes that have them at once.
shared uint s_sweeping[2];
// Per step (two, alternately) and phase (evaluation, sweep, write: s_walked[3 · parity +
// phase]), the most entries any lane of the workgroup took in it: the workgroup runs each
// phase's loop as long as that lane, one phase's loop after the other, and the sum over the
// steps and phases is how long it walked, in words (note_walk).
shared uint s_walked[2 * 3];

const uint kPhaseEvaluate = 0u, kPhaseSweep = 1u, kPhaseWrite = 2u, kPhaseDone = 3u;
// Swept: the lane's sweep has ended, but a lane of its workgroup still sweeps; it takes its new
// tape's place and writes once none does (s_sweeping).
const uint kPhaseSwept = 4u;
// State words: phase, i (next entry), top (stack size; in the sweep the kept entries it has not
// reached yet; in the write phase the next word),
// out_len, prims, at (the new tape), value, constant (float bits), the parent's stack depth, the
// new tape's stack depth now and at most, whether the sweep kept an operator that refinement
// might decide (list_near_cell), where the job's entries are (lbase), the new tape's root (its
// entry in the parent tape: the first the sweep kept).
// An entry's word per lane: bits 0-1 its decision, bit 5 whether its operands at the centre
// pass blend_may_decide (operators), bit 6 its tape word's sign, bit 7 whether it is a
// primitive, then the sweep's flags: bits 2-3 alive (0 dead, 1 kept, 2 skipped), bit 4 negate.
// Bits 6 and 7 are set with the decision, so that the sweep and the write read neither the
// tape word nor the node of an entry to know them: each was a dependent load of device memory
// in a serial walk.
const uint kEvaluationFlags = 3u | 32u | kFlagNegated | kFlagPrimitive;  // not the sweep's

// An entry's flags for lane `lane` (entry_flags), past the entries' left operands (dbase).
#ifdef PRUNE_BYTE_FLAGS
// prune_bytes.comp: a byte, through a third view of the scratch buffer (8-bit storage).
layout(std430, binding = 12) buffer LaneFlags { uint8_t lane_flags[]; };
const uint kEntryFlagWords = kTeam / 4u;
uint entry_flags(uint dbase, uint e, uint lane) {
    return uint(lane_flags[4u * dbase + e * kTeam + lane]);
}
void set_entry_flags(uint dbase, uint e, uint lane, uint flags) {
    lane_flags[4u * dbase + e * kTeam + lane] = uint8_t(flags);
}
#else
const uint kEntryFlagWords = kTeam;
uint entry_flags(uint dbase, uint e, uint lane) { return lane_scratch[dbase + e * kTeam + lane]; }
void set_entry_flags(uint dbase, uint e, uint lane, uint flags) {
    lane_scratch[dbase + e * kTeam + lane] = flags;
}
#endif
const uint kEntryWords = 1u + kEntryFlagWords;  // gpu_prune_plan.cpp: entry_bytes

uint team_fixed_words() { return kStateWords * kTeam + 4u * pc.max_stack * kTeam; }
uint team_words() {
    return team_fixed_words() + (pc.claim_words != 0u ? 0u : pc.max_len * kEntryWords);
}

// Entry e kept by the sweep, its sign its tape word's flipped where `flip` (1: the operator
// above it was decided for it, and negated); its evaluation flags kept.
void keep_entry(uint dbase, uint e, uint lane, uint flip) {
    uint fl = entry_flags(dbase, e, lane);
    uint neg = ((fl & kFlagNegated) != 0u ? 1u : 0u) ^ flip;
    set_entry_flags(dbase, e, lane, (fl & kEvaluationFlags) | (1u << 2) | (neg << 4));
}

// Each team's claim (claim_entries): its job's entries' words, then their first word.
shared uint s_claim[kTeams];
// The first word of the entries of this team's job (round 0), whose tape has `len` words (0
// where it walks none; `lead`: the team's first lane): claimed for the workgroup's 8 teams at
// once (claim_scratch), past the teams' scratch (pc.threads / kTeam of them), or kNoClaim.
// Every lane calls it.
uint claim_entries(uint tl, bool lead, uint len) {
    if (lead) s_claim[tl] = len * kEntryWords;
    memoryBarrierShared();
    barrier();
    if (gl_LocalInvocationID.x == 0u) {
        uint sum = 0u;
        for (uint t = 0u; t < kTeams; ++t) {
            uint need = s_claim[t];
            s_claim[t] = sum;
            sum += need;
        }
        uint first = claim_scratch(sum);
        uint base = (pc.threads / kTeam) * team_fixed_words() + first;
        for (uint t = 0u; t < kTeams; ++t)
            s_claim[t] = first == kNoClaim ? kNoClaim : base + s_claim[t];
    }
    memoryBarrierShared();
    barrier();
    return s_claim[tl];
}

// A stack slot's words (value, lo, hi, entry) at `at`, `at` + kTeam, ... (one lane's).
vec3 slot_range(uint at) {
    return vec3(uintBitsToFloat(lane_scratch[at]), uintBitsToFloat(lane_scratch[at + kTeam]),
                uintBitsToFloat(lane_scratch[at + 2u * kTeam]));
}
void store_slot(uint at, vec3 x, uint entry) {
    lane_scratch[at] = floatBitsToUint(x.x);
    lane_scratch[at + kTeam] = floatBitsToUint(x.y);
    lane_scratch[at + 2u * kTeam] = floatBitsToUint(x.z);
    lane_scratch[at + 3u * kTeam] = entry;
}

// Jobs in order (kStepTeamsOrdered, modes 1 and 2): a workgroup's 8 teams run as long as their
// longest walk, and in block order they take the 8 octants of one block (mode 2), whose tapes
// differ widely in length (molecule's finest level: from 1 word to 597, or none where the
// octant is far-field), or 8 neighbouring blocks (mode 1). A pass before the step sorts the
// step's parents (octants; blocks with kStepOrderBlocks) by class of tape length, the longest first
// (class 0: far-field, last), into the order list (pc.order_start in scratch, rank 0 the
// first): by default (kStepOrderWindows) each window of kOrderWindow parents (32 neighbouring
// blocks' octants: a workgroup's teams read nearby nodes) apart, in mode 5; else the whole step,
// mode 4 counting each class (order_count) and mode 5 placing each parent after the longer classes
// and the parents of its class placed before it (order_placed). Within a class the order is
// the atomics': the cells do not depend on it. The step's jobs then take the parents in that
// order, dealt out in a snake (ordered_job), so that no team takes the longest parent of every
// round: on an H100's 33,792 teams, molecule's finest cells step at 256³ has a critical path
// of 376 words in windows (578 dealt in rounds), 183 sorted whole (floor: 151, its longest
// tape; tools/prune_order_model.cpp). A parent's class: 0 far-field, else 1 + 2k (+ 1 in the
// upper half of the octave) for a tape of 2^k to 2^(k+1) − 1 words.
uint parent_class(uint parent) {
    uint tape = (pc.flags & kStepOrderBlocks) != 0u ? blocks[parent].tape : octants[parent].tape;
    if (tape == kFarField) return 0u;
    uint len = tape_read(tape, 0u);
    uint k = uint(findMSB(len));
    uint upper = k > 0u && len >= (3u << (k - 1u)) ? 1u : 0u;
    return min(1u + 2u * k + upper, kOrderClasses - 1u);
}
shared uint s_order_count[kOrderClasses];
// Modes 4 and 5: the parents [pc.order_first, pc.order_first + pc.jobs), a window a workgroup
// at a time (kOrderWindow / 64 parents a lane), counted by class in shared memory.
void order_parents() {
    const uint kPerLane = kOrderWindow / 64u;
    uint lane = gl_LocalInvocationID.x;
    // The octants step's order (kStepOrderBlocks) and the cells step's count apart: both may run in
    // one submission.
    uint which = (pc.flags & kStepOrderBlocks) != 0u ? 0u : kOrderClasses;
    for (uint w0 = pc.first_job + gl_WorkGroupID.x * kOrderWindow; w0 < pc.jobs;
         w0 += gl_NumWorkGroups.x * kOrderWindow) {
        if (lane < kOrderClasses) s_order_count[lane] = 0u;
        memoryBarrierShared();
        barrier();
        uint cls[kPerLane], rank[kPerLane];
        for (uint k = 0u; k < kPerLane; ++k) {
            uint i = w0 + k * 64u + lane;
            cls[k] = i < pc.jobs ? parent_class(pc.order_first + i) : 0u;
            rank[k] = i < pc.jobs ? atomicAdd(s_order_count[cls[k]], 1u) : 0u;
        }
        memoryBarrierShared();
        barrier();
        // Each class's first place: in windows (kStepOrderWindows, SDFPRUNE_VULKAN_TEAM_ORDER=1),
        // past the window's longer classes in the window's places; else past every longer class's
        // parents of the step and this class's placed so far.
        uint first_place = 0u;
        if (lane < kOrderClasses) {
            uint count = s_order_count[lane];
            if (pc.mode == kModeOrderCount) {
                if (count != 0u) atomicAdd(order_count[which + lane], count);
            } else if ((pc.flags & kStepOrderWindows) != 0u) {
                first_place = w0;
                for (uint c = lane + 1u; c < kOrderClasses; ++c) first_place += s_order_count[c];
            } else {
                for (uint c = lane + 1u; c < kOrderClasses; ++c)
                    first_place += order_count[which + c];
                if (count != 0u) first_place += atomicAdd(order_placed[which + lane], count);
            }
        }
        memoryBarrierShared();
        barrier();  // every lane's counts read before they are replaced
        if (lane < kOrderClasses) s_order_count[lane] = first_place;
        memoryBarrierShared();
        barrier();
        if (pc.mode == kModeOrderPlace)
            for (uint k = 0u; k < kPerLane; ++k) {
                uint i = w0 + k * 64u + lane;
                if (i < pc.jobs)
                    lane_scratch[pc.order_start + s_order_count[cls[k]] + rank[k]] =
                        pc.order_first + i;
            }
        barrier();  // the places read before the next window resets them
    }
}
// Team job j under kStepTeamsOrdered: dealt in a snake to the teams (snake_deal over this
// dispatch's jobs [first_job, jobs)), then the job at the same place of its parent (in mode 2 a
// team takes kTeam of an octant's cells; in mode 1 a block is one job) of the parent of that rank /
// per_team in the order list.
// Jobs taken as workgroups come free (kStepTakeJobs, take_jobs) take the order list as it is.
uint ordered_job(uint j, uint teams) {
    if ((pc.flags & kStepTakeJobs) == 0u) j = snake_deal(j, pc.first_job, teams, pc.jobs);
    uint hf = pc.factor / 2u;
    uint per_team = pc.mode == kModeOctantCells ? (hf * hf * hf + kTeam - 1u) / kTeam : 1u;
    uint parent = lane_scratch[pc.order_start + j / per_team - pc.order_first];
    return parent * per_team + j % per_team;
}

// Jobs taken as workgroups come free (kStepTakeJobs): a workgroup that is done with its jobs
// takes the next one for each of its teams (`group_teams`) from the step's counter
// (jobs_taken, zeroed before each dispatch), instead of the jobs dealt out in advance (team t's
// are first_job + t + k · teams). With the jobs in order, longest first, no workgroup waits
// for one that drew long jobs round after round: on an H100's 33,792 teams molecule's finest
// cells step has a critical path of 197 words in windows (376 dealt in a snake;
// tools/prune_order_model.cpp). Gives the first of the workgroup's jobs, the same for all its
// lanes, or pc.jobs where none is left or the workgroup has taken `cap` times (under a loop
// limit: the jobs a team takes at most when dealt, so that every job is taken and none passes
// the limit). Called by every lane of the workgroup.
uint take_jobs(uint group_teams, uint taken, uint cap) {
    return take_from_counter(taken < cap, group_teams, pc.first_job, pc.jobs);
}

void main() {
    if (pc.mode >= kModeOrderCount) {
        order_parents();
        probe_loop_limit();
        return;
    }
    counts_begin();
    uint tl = gl_LocalInvocationID.x / kTeam, lane = gl_LocalInvocationID.x % kTeam;
    uint team = gl_WorkGroupID.x * kTeams + tl;
    uint teams = pc.threads / kTeam;
    uint tbase = team * team_words();
    uint st = tbase + lane;                    // state word k at st + k · kTeam
    uint sbase = tbase + kStateWords * kTeam;  // stack slot j, word c at sbase + (4j + c) · kTeam
    uint win = tl * kWindow;                   // the team's window in shared memory
    bool interval = (pc.flags & kStepIntervalBounds) != 0u;
    bool transient = pc.mode == kModeOctants || (pc.flags & kStepTransientTapes) != 0u;
    // The step lists its near cells for refinement (list_near_cell), which reads bit 5.
    bool lists = pc.mode != kModeOctants && (pc.flags & kStepTransientTapes) != 0u;
    const Cell kNoCell = Cell(kFarField, 0u, 0.0, 0.0);  // store()'s, for refinement only

    // Every lane of a workgroup sees the same trip count (barriers inside); teams past
    // pc.threads / kTeam hold no scratch and take no jobs. Jobs dealt out in advance (team t's
    // are first + t, first = first_job + k · teams) or taken (take_jobs: the workgroup's teams
    // take first + tl).
    bool taking = (pc.flags & kStepTakeJobs) != 0u;
    uint group_teams = min(kTeams, teams - min(teams, gl_WorkGroupID.x * kTeams));
    uint cap = pc.budget == 0xffffffffu ? 0xffffffffu
                                        : (pc.jobs - pc.first_job + teams - 1u) / teams;
    uint taken = 0u;
    uint group_walked = 0u;  // the workgroup's walk in this dispatch (s_walked), every lane's
    for (uint first = pc.first_job;; first += teams) {
        if (taking) first = take_jobs(group_teams, taken++, cap);
        if (first >= pc.jobs) break;
        uint job = first + (taking ? tl : team);
        bool has_job = (taking ? tl < group_teams : team < teams) && job < pc.jobs;
        if (has_job && (pc.flags & kStepTeamsOrdered) != 0u) job = ordered_job(job, teams);
        // This lane's box and the team's parent tape; `valid`: the lane stores a result.
        bool valid = has_job, walk = has_job;
        uint parent = 0u, dest = 0u;
        precise vec3 centre = vec3(0.0);
        vec3 half_size = vec3(0.0);
        float R = 0.0;
        if (has_job) {
            vec3 box_centre;
            walk = job_box(job, lane, box_centre, half_size, R, parent, dest, valid);
            centre = box_centre;
            valid = valid && walk;
        }

        // The lane's state: new, or from the previous round.
        uint len = walk ? tape_read(parent, 0u) : 0u;
        // The entries: entry e's left operand at lbase + e, its decision and flags at dbase +
        // e · kTeam (past the team's stack, or claimed).
        uint lbase = sbase + 4u * pc.max_stack * kTeam;
        if (pc.claim_words != 0u) {
            lbase = pc.round == 0u ? claim_entries(tl, lane == 0u, len)
                    : walk         ? lane_scratch[st + 12u * kTeam]
                                   : 0u;
            if (lbase == kNoClaim) walk = valid = false;  // (the host reports it)
        }
        uint dbase = lbase + len;
        uint phase = kPhaseDone, i = 0u, top = 0u, out_len = 0u, prims = 0u, at = 0u;
        uint pdepth = 0u, depth = 0u, depth_max = 0u;
        uint root = 0u;  // the new tape's root: the entry of the parent tape that stands there
        float value = 0.0, constant = 0.0;
        bool may_decide = false;
        if (walk && pc.round == 0u) {
            phase = kPhaseEvaluate;
        } else if (walk) {
            phase = lane_scratch[st];
        }
        if (walk && pc.round != 0u && phase != kPhaseDone) {
            i = lane_scratch[st + kTeam];
            top = lane_scratch[st + 2u * kTeam];
            out_len = lane_scratch[st + 3u * kTeam];
            prims = lane_scratch[st + 4u * kTeam];
            at = lane_scratch[st + 5u * kTeam];
            value = uintBitsToFloat(lane_scratch[st + 6u * kTeam]);
            constant = uintBitsToFloat(lane_scratch[st + 7u * kTeam]);
            pdepth = lane_scratch[st + 8u * kTeam];
            depth = lane_scratch[st + 9u * kTeam];
            depth_max = lane_scratch[st + 10u * kTeam];
            may_decide = lane_scratch[st + 11u * kTeam] != 0u;
            root = lane_scratch[st + 13u * kTeam];
        }

        barrier();  // the previous job's last reads of s_busy and s_walked are done
        if (gl_LocalInvocationID.x == 0u) {
            s_busy[0] = s_busy[1] = 0u;
            for (uint k = 0u; k < 6u; ++k) s_walked[k] = 0u;
            s_sweeping[0] = s_sweeping[1] = 0u;
        }
        for (uint s = 0u; s < pc.budget; ++s) {
            // The team's window, staged by its lanes together (every lane of a team evaluates
            // the same entries).
            uint w0 = i;
            uvec3 walked = uvec3(0u);  // the entries this lane takes in this step, per phase
            if (phase == kPhaseEvaluate) {
                uint we = min(i + kWindow, len);
                for (uint k = i + lane; k < we; k += kTeam) {
                    uint w = tape_read(parent, 2u + k);
                    s_word[win + k - w0] = is_primitive(tape_node(w)) ? w | kStagedPrimitive : w;
                }
            }
            memoryBarrierShared();
            barrier();
            // Stage 1: values and ranges at the box centre, decisions (evaluate_cell). The
            // stack's top slot (top − 1) is held in registers during the step (tx, its entry
            // t_entry), the slots below it in scratch: an operator's right operand is the top,
            // and only a push spills the top before it.
            if (phase == kPhaseEvaluate) {
                uint we = min(i + kWindow, len);
                vec3 tx = vec3(0.0);
                uint t_entry = 0u;
                if (top > 0u) {
                    uint so = sbase + 4u * (top - 1u) * kTeam + lane;
                    tx = slot_range(so);
                    t_entry = lane_scratch[so + 3u * kTeam];
                }
                for (; i < we; ++i) {
                    uint w = s_word[win + i - w0];
                    uint n = staged_node(w);
                    Node nd = nodes[n];
                    vec3 x;
                    uint decision = kKeepBoth;
                    if ((w & kStagedPrimitive) != 0u) {
                        decision |= kFlagPrimitive;
                        x = primitive_range(n, nd, centre, half_size, R, interval);
                        if (top > 0u)
                            store_slot(sbase + 4u * (top - 1u) * kTeam + lane, tx, t_entry);
                        ++top;
                    } else {
                        uint sl = sbase + 4u * (top - 2u) * kTeam + lane;
                        --top;
                        vec3 left = slot_range(sl);
                        // Written by every lane (the same value): a lane's sweep may follow in
                        // this very step, and reads its own write, with no barrier between.
                        lane_scratch[lbase + i] = lane_scratch[sl + 3u * kTeam];
                        x = combine_operator(nd, R, interval, false, left, tx, decision);
                        if (lists && blend_may_decide(left.x, tx.x, nd.blend)) decision |= 32u;
                    }
                    if (tape_negated(w)) {
                        x = negate_range(x);
                        decision |= kFlagNegated;
                    }
                    // The decision and what the entry is, its sweep flags cleared for stage 3.
                    set_entry_flags(dbase, i, lane, decision);
                    tx = x;
                    t_entry = i;
                    pdepth = max(pdepth, top);
                }
                walked.x = i - w0;
                // The top back to scratch for the next step; after the last entry it is the
                // root, which stage 2 reads from the registers.
                if (i < len && top > 0u)
                    store_slot(sbase + 4u * (top - 1u) * kTeam + lane, tx, t_entry);
                if (i == len) {
                    // Stage 2: the far-field test on the root range against the box's margin
                    // (is_near_field); the root is in this window.
                    value = tx.x;
                    float L = nodes[staged_node(s_word[win + len - 1u - w0])].lipschitz;
                    vec2 range = far_field_range(value, tx.y, tx.z, L, R);
                    float clearance = far_field_clearance(pc.csize.w, L, R);
                    bool far_field = (pc.flags & kStepFarField) != 0u;
                    bool above = far_field && clears_above(range.x, clearance);
                    bool below = far_field && clears_below(range.y, clearance);
                    if (above || below) {
                        constant = above ? range.x : range.y;
                        phase = kPhaseDone;
                        if (valid) store(dest, false, value, constant, kFarField, 0u, kNoCell);
                    } else if (!valid) {
                        phase = kPhaseDone;  // a lane past the boxes
                    } else {
                        keep_entry(dbase, len - 1u, lane, 0u);  // the root, with its own sign
                        phase = kPhaseSweep;
                        top = 1u;  // the root, kept and not yet reached
                    }
                }
            }
            if (phase == kPhaseSweep) {
                // Stage 3: the top-down pass (compact_tape), kWindow entries a step. An entry's
                // flags are final when the reverse sweep reaches it (parents come later), so
                // the sweep also counts the kept entries. Each entry has one parent: once the
                // sweep has reached every entry kept so far (`top` of them were not), the
                // entries below are dead, and the sweep ends there, the write starting at the
                // last one it kept (`first_kept`): a cell near a few primitives low in a long
                // chain (molecule's) need not pass over the chain's bottom twice more.
                uint stop = i > kWindow ? i - kWindow : 0u;
                uint from = i, first_kept = 0u;
                bool ended = false;
                for (; i > stop; --i) {
                    uint e = i - 1u;
                    uint fl = entry_flags(dbase, e, lane);
                    if (((fl >> 2) & 3u) != 1u) continue;
                    if (out_len == 0u) root = e;  // the first entry it keeps
                    if ((fl & kFlagPrimitive) != 0u) {
                        ++out_len;
                        ++prims;
                        if (--top == 0u && (pc.flags & kStepWholeSweeps) == 0u) {
                            first_kept = e;
                            ended = true;
                            break;
                        }
                        continue;
                    }
                    uint l = lane_scratch[lbase + e], r = e - 1u;
                    uint d = fl & 3u;
                    if (d == kKeepBoth) {
                        ++out_len;
                        ++top;  // it is reached, its two operands kept
                        may_decide = may_decide || (fl & 32u) != 0u;
                        keep_entry(dbase, l, lane, 0u);
                        keep_entry(dbase, r, lane, 0u);
                        continue;
                    }
                    uint skipped = (fl & kEvaluationFlags) | (2u << 2) | (fl & 16u);
                    set_entry_flags(dbase, e, lane, skipped);
                    keep_entry(dbase, d == kLeftWins ? l : r, lane, (fl >> 4) & 1u);
                }
                walked.y = from - (ended ? first_kept : i);
                if (ended || i == 0u) {
                    note_len(out_len);
                    phase = kPhaseSwept;  // the rest once the workgroup's sweeps have ended
                    i = first_kept;       // the write's first entry: the entries before are dead
                }
            }
            if (phase == kPhaseWrite) {
                uint we = min(i + kWindow, len);
                walked.z = we - i;
                for (; i < we; ++i) {
                    uint fl = entry_flags(dbase, i, lane);
                    if (((fl >> 2) & 3u) != 1u) continue;
                    uint node = tape_node(tape_read(parent, 2u + i));
                    tape_write(top++, tape_word(node, ((fl >> 4) & 1u) != 0u));
                    // Stack depth of the new tape: a primitive pushes, an operator pops two,
                    // pushes one.
                    depth = (fl & kFlagPrimitive) != 0u ? depth + 1u : depth - 1u;
                    depth_max = max(depth_max, depth);
                }
                if (i == len) {
                    note_depth(depth_max);
                    phase = kPhaseDone;
                    store(dest, true, value, constant, at, out_len, kNoCell);
                }
            }
            if (phase != kPhaseDone) atomicAdd(s_busy[s & 1u], 1u);
            if (phase == kPhaseSweep) atomicAdd(s_sweeping[s & 1u], 1u);
            uint parity = 3u * (s & 1u);
            for (uint k = 0u; k < 3u; ++k)
                if (walked[k] != 0u) atomicMax(s_walked[parity + k], walked[k]);
            memoryBarrierBuffer();
            memoryBarrierShared();
            barrier();
            bool busy = s_busy[s & 1u] != 0u;
            group_walked += s_walked[parity] + s_walked[parity + 1u] + s_walked[parity + 2u];
            if (phase == kPhaseSwept && s_sweeping[s & 1u] == 0u) {
                // Every lane of the workgroup whose sweep has ended, at once: their appends to
                // the pool and to refinement's list take one atomic per subgroup. The new
                // tape's root node is read from the parent tape (the new one is not written).
                uint root_node = tape_node(tape_read(parent, 2u + root));
                if (out_len == len && transient) {
                    // Nothing pruned, and a transient tape: share the parent's.
                    note_depth(pdepth);
                    phase = kPhaseDone;
                    store(dest, true, value, constant, parent, out_len, kNoCell);
                    list_near_cell(dest, root_node, out_len, value, may_decide);
                } else {
                    at = pool_allocate(transient, out_len + 2u);
                    if (at == kFarField) {
                        phase = kPhaseDone;
                        store(dest, false, value, constant, kFarField, 0u, kNoCell);
                    } else {
                        tape_write(at, out_len);
                        tape_write(at + 1u, prims);
                        list_near_cell(dest, root_node, out_len, value, may_decide);
                        phase = kPhaseWrite;
                        top = at + 2u;  // the next word to write
                    }
                }
            }
            if (gl_LocalInvocationID.x == 0u) {
                s_busy[(s + 1u) & 1u] = 0u;
                uint next = 3u - parity;  // the next step's words
                for (uint k = 0u; k < 3u; ++k) s_walked[next + k] = 0u;
                s_sweeping[(s + 1u) & 1u] = 0u;
            }
            if (!busy) break;
        }
        if (walk) lane_scratch[st] = phase;
        if (walk && phase != kPhaseDone) {
            lane_scratch[st + kTeam] = i;
            lane_scratch[st + 2u * kTeam] = top;
            lane_scratch[st + 3u * kTeam] = out_len;
            lane_scratch[st + 4u * kTeam] = prims;
            lane_scratch[st + 5u * kTeam] = at;
            lane_scratch[st + 6u * kTeam] = floatBitsToUint(value);
            lane_scratch[st + 7u * kTeam] = floatBitsToUint(constant);
            lane_scratch[st + 8u * kTeam] = pdepth;
            lane_scratch[st + 9u * kTeam] = depth;
            lane_scratch[st + 10u * kTeam] = depth_max;
            lane_scratch[st + 11u * kTeam] = may_decide ? 1u : 0u;
            lane_scratch[st + 12u * kTeam] = lbase;
            lane_scratch[st + 13u * kTeam] = root;
        }
    }
    // The step's walks, measured: the most any workgroup walked in one dispatch, and their sum.
    if (gl_LocalInvocationID.x == 0u) note_walk(group_walked);
    counts_end();
}
