// prune_team.glsl — prune.comp and prune_refine.comp: one pruning step of a level, on teams of
// kTeam lanes: a team walks one parent
// tape in lockstep, each lane pruning one box from it. Mirrors src/prune/prune_cell.cpp stage for
// stage (evaluate_boxes over sibling lanes, is_near_field, compact_tape in each lane,
// refine_cell) and the octant split of src/prune/prune.cpp. A team's job:
//   mode 0: kTeam cells of a block, from the block's tape
//   mode 1: the 8 octants of a block, from the block's tape (not stored as cells)
//   mode 2: kTeam cells of an octant, from the octant's tape (or far-field from a far octant)
//   mode 3: one finest near-field cell decided again over its refine³ sub-boxes, kTeam at a time
//           (refine_cell), from `cells` into the buffer of binding 5; tapes longer than
//           kRefineMaxTape are evaluated once over the cell (which copies them to the main pool).
//           Job k takes cell refine_list[k], for k below refine_cells (the near-field cells the
//           cells step listed); the far-field cells were copied there before, as they are
// The kernel runs in steps, the same for every lane of a workgroup: at each step a team that
// evaluates stages the next kWindow entries of its tape (words and nodes) in shared memory, then
// every lane advances its phase by at most kWindow entries (evaluation from the window; the
// far-field test; the top-down sweep; the write of the compacted tape). During evaluation every
// lane of a team runs the same entry at the same step. Decisions and the sweep's flags are kept
// per lane and entry, interleaved so that a team's lanes touch adjacent words.
// New tapes are appended to the pool with an atomic counter; on overflow nothing is written
// (the box is stored as far-field) and the host grows the pool and runs the steps again.
//
// A job is resumable: its lanes' state lives in the team's scratch, and each dispatch (a
// "round") runs at most pc.budget steps of it. Devices without a loop limit use one round with
// an unlimited budget; lavapipe, which ends an invocation's loops after 65,535 iterations in
// all, gets as many jobs per team and dispatch as fit that, or one job over as many rounds as
// its steps need (gpu_prune.cpp counts them).
#include "scene.glsl"

layout(local_size_x = 64) in;

#include "cells.glsl"

const uint kTeams = 8u;    // teams per workgroup
const uint kWindow = 64u;  // tape entries a lane advances per step (gpu_prune.cpp: kPruneWindow)
// Batches of sub-boxes a step evaluates when the whole tape fits the window
// (gpu_prune.cpp: kPruneBatchesPerStep).
const uint kBatchesPerStep = 4u;

#include "prune_common.glsl"

// Per team (see team_words): the lanes' job state (kStateWords each), each parent-tape entry's
// left operand (one word, the same in every lane), each entry's decision and sweep flags (one
// word per lane), then 4 words per stack slot and lane (value, lo, hi, entry). Lane l's
// word of item k is at k · kTeam + l. In refinement a team's lanes read each other's decisions
// and far-field flags, written at earlier steps (a barrier between).

// The lanes' evaluation stacks, through a second view of the scratch buffer (binding 12, the
// same buffer as binding 8) without `coherent`: only the lane that writes a stack slot reads it
// (program order suffices; a job resumed in a later dispatch reads it after the dispatch's
// barrier), so its loads may be served from the SM's cache, where the coherent view's go to
// the device's. The two views never touch the same words.
layout(std430, binding = 12) buffer LaneScratch { uint lane_scratch[]; };

// A team's window of its parent tape, staged for the step.
shared uint s_word[kTeams * kWindow];
shared Node s_node[kTeams * kWindow];
// Refinement of a tape that fits the window, in a dispatch that finishes its jobs (flag 8): per
// entry, bits 0-2 the decisions its lanes made over all their sub-boxes (1 << decision, OR-ed:
// the team's decision is the one seen, if it is the only one; team_decision's rule), bits 8-15
// lane 0's sweep flags (an entry's scratch word shifted, its decision bits unused), bits 16-23
// the entry's left operand. The sweep and the write then read no scratch, and the tape's words
// from the window: a refined cell's chain of loads stays in the SM.
// Only prune_refine.comp (PRUNE_REFINE_WINDOW), which runs refinement, has it: the shared
// memory and registers it takes cost the other steps' occupancy (on the H200, 20–30 % slower
// octant and cell steps).
#ifdef PRUNE_REFINE_WINDOW
shared uint s_meta[kTeams * kWindow];
#else
shared uint s_meta[1];
#endif
// Lanes still busy after a step, counted in one word while the other is reset.
shared uint s_busy[2];

const uint kStateWords = 16u;
const uint kPhaseEvaluate = 0u, kPhaseDecide = 1u, kPhaseSweep = 2u, kPhaseWrite = 3u,
           kPhaseDone = 4u;
// State words: phase, i (next entry), top (stack size; in the write phase the next word),
// out_len, prims, at (the new tape), value, constant (float bits), the parent's stack depth, the
// new tape's stack depth now and at most, the batch of sub-boxes, the far-field flags (1: every
// sub-box so far clears above, 2: below) and the lowest and highest root bounds (float bits).
const uint kStFar = 12u, kStLowest = 13u, kStHighest = 14u;
// An entry's word per lane: bits 0-1 its decision, then the sweep's flags: bits 2-3 alive (0
// dead, 1 kept, 2 skipped), bit 4 negate.

uint team_words() {
    return kStateWords * kTeam + pc.max_len * (1u + kTeam) + 4u * pc.max_stack * kTeam;
}

// Refinement: an entry's decision shared by the team's 8 lanes (every sub-box), else keep both.
uint team_decision(uint at) {
    uint d0 = scratch[at] & 3u, d1 = scratch[at + 1u] & 3u, d2 = scratch[at + 2u] & 3u;
    uint d3 = scratch[at + 3u] & 3u, d4 = scratch[at + 4u] & 3u, d5 = scratch[at + 5u] & 3u;
    uint d6 = scratch[at + 6u] & 3u, d7 = scratch[at + 7u] & 3u;
    uint differ = (d0 ^ d1) | (d0 ^ d2) | (d0 ^ d3) | (d0 ^ d4) | (d0 ^ d5) | (d0 ^ d6) | (d0 ^ d7);
    return differ == 0u ? d0 : kKeepBoth;
}

// The sweep's view of entry e of a team's tape (`at`: the entry's word of this lane in scratch),
// windowed (s_meta and the window: windowed refinement) or not: its flags (bits 2-4; from
// scratch, bits 0-1 hold the lane's decision), its tape word, and setting its flags (a
// scratch word keeps its decision bits).
uint sweep_flags(bool windowed, uint win, uint at, uint e) {
    return windowed ? (s_meta[win + e] >> 8) & 0xffu : scratch[at];
}
void set_sweep_flags(bool windowed, uint win, uint at, uint e, uint flags) {
    if (windowed)
        s_meta[win + e] = (s_meta[win + e] & ~0xff00u) | (flags << 8);
    else
        scratch[at] = (scratch[at] & 3u) | flags;
}
uint tape_entry(bool windowed, uint win, uint parent, uint e) {
    return windowed ? s_word[win + e] : tape_read(parent, 2u + e);
}
// The sweep's flags of a tape's root (its last entry, `len` words at `parent`): alive, with its
// own sign.
uint root_sweep_flags(uint parent, uint len) {
    uint root_neg = tape_negated(tape_read(parent, 2u + len - 1u)) ? 1u : 0u;
    return (1u << 2) | (root_neg << 4);
}
// Windowed refinement: the team's decision, the one its lanes saw if they saw only one.
uint window_decision(uint meta) {
    uint seen = meta & 7u;
    return bitCount(seen) == 1 ? uint(findLSB(seen)) : kKeepBoth;
}

void main() {
    counts_begin();
    uint tl = gl_LocalInvocationID.x / kTeam, lane = gl_LocalInvocationID.x % kTeam;
    uint team = gl_WorkGroupID.x * kTeams + tl;
    uint teams = pc.threads / kTeam;
    uint tbase = team * team_words();
    uint st = tbase + lane;                    // state word k at st + k · kTeam
    uint lbase = tbase + kStateWords * kTeam;  // entry e's left operand at lbase + e
    uint dbase = lbase + pc.max_len;           // entry e's decision and flags at dbase + e · kTeam
    uint sbase = dbase + pc.max_len * kTeam;   // stack slot j, word c at sbase + (4j + c) · kTeam
    uint win = tl * kWindow;                   // the team's window in shared memory

    uint f = pc.factor;
    uint per_block = f * f * f;
    uint hf = f / 2u;
    vec3 origin = pc.origin.xyz;
    vec3 cs = pc.csize.xyz;
    vec3 half_cell = cs * 0.5;
    float radius = length(half_cell);
    bool interval = (pc.flags & 2u) != 0u;
    bool transient = pc.mode == 1u || (pc.flags & 4u) != 0u;

    // The host records refinement's dispatches for every finest cell; its jobs are the listed
    // ones only (the count is the same for every lane: the step before wrote it).
    uint jobs = pc.mode == 3u ? min(pc.jobs, refine_cells) : pc.jobs;
    // Every lane of a workgroup sees the same trip count (barriers inside); teams past
    // pc.threads / kTeam hold no scratch and take no jobs.
    for (uint first = pc.first_job; first < jobs; first += teams) {
        uint job = first + team;
        bool has_job = team < teams && job < jobs;
        // This lane's box and the team's parent tape; `valid`: the lane stores a result.
        bool valid = has_job, walk = has_job;
        uint parent = 0u, dest = 0u, subs = 1u, nbatch = 1u;
        precise vec3 centre = vec3(0.0);
        vec3 half_size = half_cell;
        float R = radius;
        Cell c0 = Cell(kFarField, 0u, 0.0, 0.0);
        bool lone = false;  // refinement: nothing to decide again (see below)
        if (has_job && pc.mode == 3u) {
            // Reads `cells`, writes the refined cells to `octants` (binding 5): a step
            // redone after a pool overflow starts again from unchanged cells. Lane 0
            // stores the cell; the others evaluate sub-boxes.
            uint cell = refine_list[job];
            uint bi = cell / per_block, local = cell % per_block;
            Block b = blocks[bi];
            uvec3 lc = uvec3(local % f, (local / f) % f, local / (f * f));
            centre = origin + (vec3(b.x + lc.x, b.y + lc.y, b.z + lc.z) + 0.5) * cs;
            dest = cell;
            c0 = cells[cell];
            valid = lane == 0u;
            if (c0.tape == kFarField) {
                // Only near cells are listed; were one not, it is copied as it is.
                walk = false;
                if (pc.round == 0u && valid) octants[cell] = c0;
            } else {
                parent = c0.tape;
                uint words = tape_read(parent, 0u);
                subs = words > kRefineMaxTape ? 1u : pc.refine;
                nbatch = (subs * subs * subs + kTeam - 1u) / kTeam;
                // A lone primitive in a cell that cannot clear the far field
                // (refine_far_possible: refine_cell's test, where the CPU returns at once too)
                // has nothing to decide again: its tape is copied as it is, unevaluated.
                if (words == 1u) {
                    Node lone_node = nodes[tape_node(tape_read(parent, 2u))];
                    float clearance = far_field_clearance(pc.csize.w, lone_node.lipschitz, radius);
                    float sigma = extras[lone_node.primitive].bound0.w;
                    lone = (pc.flags & 1u) == 0u ||
                           !refine_far_possible(c0.value, clearance, sigma, half_cell);
                }
            }
        } else if (has_job) {
            vec3 box_centre;
            walk = job_box(job, lane, box_centre, half_size, R, parent, dest, valid);
            centre = box_centre;
            valid = valid && walk;
        }

        // The lane's state: new, or from the previous round.
        uint len = walk ? tape_read(parent, 0u) : 0u;
        uint phase = kPhaseDone, i = 0u, top = 0u, out_len = 0u, prims = 0u, at = 0u;
        uint pdepth = 0u, depth = 0u, depth_max = 0u, batch = 0u;
        uint far_flags = (pc.flags & 1u) != 0u ? 3u : 0u;
        float value = 0.0, constant = 0.0, lowest = kInfinity, highest = -kInfinity;
        if (walk && pc.round == 0u && lone) {
            // Straight to the sweep, on the lane that stores the cell.
            phase = valid ? kPhaseSweep : kPhaseDone;
            i = len;
            // (its one entry is a primitive: no decision bits to keep)
            if (valid)
                set_sweep_flags(false, 0u, dbase + (len - 1u) * kTeam + lane, len - 1u,
                                root_sweep_flags(parent, len));
        } else if (walk && pc.round == 0u) {
            phase = kPhaseEvaluate;
        } else if (walk) {
            phase = scratch[st];
        }
        if (walk && pc.round != 0u && phase != kPhaseDone) {
            i = scratch[st + kTeam];
            top = scratch[st + 2u * kTeam];
            out_len = scratch[st + 3u * kTeam];
            prims = scratch[st + 4u * kTeam];
            at = scratch[st + 5u * kTeam];
            value = uintBitsToFloat(scratch[st + 6u * kTeam]);
            constant = uintBitsToFloat(scratch[st + 7u * kTeam]);
            pdepth = scratch[st + 8u * kTeam];
            depth = scratch[st + 9u * kTeam];
            depth_max = scratch[st + 10u * kTeam];
            batch = scratch[st + 11u * kTeam];
            far_flags = scratch[st + kStFar * kTeam];
            lowest = uintBitsToFloat(scratch[st + kStLowest * kTeam]);
            highest = uintBitsToFloat(scratch[st + kStHighest * kTeam]);
        }
        uint nsub = subs * subs * subs;
#ifdef PRUNE_REFINE_WINDOW
        bool windowed = pc.mode == 3u && !lone && len <= kWindow && (pc.flags & 8u) != 0u;
#else
        const bool windowed = false;
#endif
        vec3 sub_half = subs == 1u ? half_size : half_size / float(subs);
        float sub_R = subs == 1u ? R : length(sub_half);

        barrier();  // the previous job's last reads of s_busy are done
        if (gl_LocalInvocationID.x == 0u) {
            s_busy[0] = 0u;
            s_busy[1] = 0u;
        }
        for (uint s = 0u; s < pc.budget; ++s) {
            // The team's window, staged by its lanes together (every lane of a team evaluates
            // the same entries).
            uint w0 = i;
            if (phase == kPhaseEvaluate) {
                uint we = min(i + kWindow, len);
                for (uint k = i + lane; k < we; k += kTeam) {
                    uint w = tape_read(parent, 2u + k);
                    s_word[win + k - w0] = w;
                    s_node[win + k - w0] = nodes[tape_node(w)];
                    if (windowed && batch == 0u) s_meta[win + k] = 0u;
                }
            }
            memoryBarrierShared();
            barrier();
            // Stage 1: values and ranges at the (sub-)box centre, decisions (evaluate_cell);
            // over sub-boxes, per lane the decision all of its sub-boxes share. A tape that fits
            // the window is walked again for the next batches of sub-boxes in the same step.
            bool fresh = false;  // the evaluation ended in this step
            for (uint rep = 0u; rep < kBatchesPerStep && phase == kPhaseEvaluate; ++rep) {
                uint sb = min(batch * kTeam + lane, nsub - 1u);
                uvec3 sc = uvec3(sb % subs, (sb / subs) % subs, sb / (subs * subs));
                precise vec3 sub_centre =
                    subs == 1u ? centre : centre - half_size + vec3(2u * sc + 1u) * sub_half;
                uint we = min(i + kWindow, len);
                for (; i < we; ++i) {
                    uint w = s_word[win + i - w0];
                    Node nd = s_node[win + i - w0];
                    uint kind = nd.kind;
                    float spread = nd.lipschitz * sub_R;
                    float v, lo, hi;
                    uint decision = kKeepBoth;
                    if (kind < kPrimitiveKindCount) {
                        uint p = nd.primitive;
                        v = eval_primitive(kind, params[p], sub_centre);
                        lo = v - spread;
                        hi = v + spread;
                        vec4 b0 = extras[p].bound0;
                        if (interval && b0.w > 0.0) {
                            vec2 r = similarity_range(b0.xyz, b0.w, extras[p].bound1.x,
                                                      extras[p].bound1.y, sub_centre, sub_half);
                            lo = max(lo, r.x);
                            hi = min(hi, r.y);
                        }
                    } else {
                        uint sr = sbase + 4u * (top - 1u) * kTeam + lane;
                        uint sl = sbase + 4u * (top - 2u) * kTeam + lane;
                        top -= 2u;
                        float lv = uintBitsToFloat(lane_scratch[sl]);
                        float llo = uintBitsToFloat(lane_scratch[sl + kTeam]);
                        float lhi = uintBitsToFloat(lane_scratch[sl + 2u * kTeam]);
                        float rv = uintBitsToFloat(lane_scratch[sr]);
                        float rlo = uintBitsToFloat(lane_scratch[sr + kTeam]);
                        float rhi = uintBitsToFloat(lane_scratch[sr + 2u * kTeam]);
                        float sgn = operator_s(kind), k = nd.blend;
                        decision = prune_decision(sgn, k, llo, lhi, rlo, rhi);
                        // Written by every lane (the same value): a lane's sweep may follow in
                        // this very step, and reads its own write, with no barrier between.
                        uint left = lane_scratch[sl + 3u * kTeam];
                        if (windowed)
                            atomicOr(s_meta[win + i], (1u << decision) | (left << 16));
                        else
                            scratch[lbase + i] = left;
                        v = apply_operator(sgn, k, lv, rv);
                        if (decision == kLeftWins) {
                            lo = llo;
                            hi = lhi;
                        } else if (decision == kRightWins) {
                            lo = rlo;
                            hi = rhi;
                        } else if (interval) {
                            // Refinement: the operator's range alone (refine_cell's
                            // OperatorMode::kRefine, prune_cell.cpp), which holds the
                            // Lipschitz range up to rounding.
                            vec2 r2 = operator_range(sgn, k, llo, lhi, rlo, rhi);
                            bool refining = pc.mode == 3u;
                            lo = refining ? r2.x : max(v - spread, r2.x);
                            hi = refining ? r2.y : min(v + spread, r2.y);
                        } else {
                            lo = v - spread;
                            hi = v + spread;
                        }
                    }
                    if (tape_negated(w)) {
                        v = -v;
                        float tmp = lo;
                        lo = -hi;
                        hi = -tmp;
                    }
                    // Flags cleared for stage 3 (windowed: in s_meta, cleared when staged).
                    uint e = dbase + i * kTeam + lane;
                    if (!windowed)
                        scratch[e] =
                            batch == 0u || (scratch[e] & 3u) == decision ? decision : kKeepBoth;
                    uint so = sbase + 4u * top * kTeam + lane;
                    lane_scratch[so] = floatBitsToUint(v);
                    lane_scratch[so + kTeam] = floatBitsToUint(lo);
                    lane_scratch[so + 2u * kTeam] = floatBitsToUint(hi);
                    lane_scratch[so + 3u * kTeam] = i;
                    ++top;
                    pdepth = max(pdepth, top);
                }
                if (i == len) {
                    // Stage 2 for this sub-box: the far-field test on its root range against
                    // the box's margin (is_near_field); the root is in this window.
                    uint s0 = sbase + lane;
                    float v = uintBitsToFloat(lane_scratch[s0]);
                    if (batch == 0u) value = v;
                    float L = s_node[win + len - 1u - w0].lipschitz;
                    float clearance = far_field_clearance(pc.csize.w, L, R);
                    vec2 range = far_field_range(v, uintBitsToFloat(lane_scratch[s0 + kTeam]),
                                                 uintBitsToFloat(lane_scratch[s0 + 2u * kTeam]), L,
                                                 sub_R);
                    if (!clears_above(range.x, clearance)) far_flags &= ~1u;
                    if (!clears_below(range.y, clearance)) far_flags &= ~2u;
                    lowest = min(lowest, range.x);
                    highest = max(highest, range.y);
                    ++batch;
                    i = 0u;
                    top = 0u;
                    if (batch == nbatch) {
                        phase = kPhaseDecide;
                        fresh = true;
                        scratch[st + kStFar * kTeam] = far_flags;
                        scratch[st + kStLowest * kTeam] = floatBitsToUint(lowest);
                        scratch[st + kStHighest * kTeam] = floatBitsToUint(highest);
                    }
                }
                if (i != 0u || w0 != 0u || len > kWindow) break;  // the window holds no more
            }
            // The phases that follow run in the same step, each over at most kWindow entries.
            // Refinement's far-field test reads the other lanes' results: the next step.
            if (phase == kPhaseDecide && !(fresh && pc.mode == 3u)) {
                // Stage 2 for the box: over sub-boxes, every lane's sub-boxes must clear.
                if (pc.mode == 3u) {
                    uint t0 = tbase;
                    for (uint m = 0u; m < kTeam; ++m) {
                        far_flags &= scratch[t0 + kStFar * kTeam + m];
                        lowest = min(lowest, uintBitsToFloat(scratch[t0 + kStLowest * kTeam + m]));
                        highest =
                            max(highest, uintBitsToFloat(scratch[t0 + kStHighest * kTeam + m]));
                    }
                }
                if ((far_flags & 3u) != 0u) {
                    constant = (far_flags & 1u) != 0u ? lowest : highest;
                    phase = kPhaseDone;
                    if (valid) store(dest, false, value, constant, kFarField, 0u, c0);
                } else if (!valid) {
                    phase = kPhaseDone;  // a lane past the boxes, or a sub-box's helper
                } else {
                    set_sweep_flags(windowed, win, dbase + (len - 1u) * kTeam + lane, len - 1u,
                                    root_sweep_flags(parent, len));
                    i = len;
                    phase = kPhaseSweep;
                }
            }
            if (phase == kPhaseSweep) {
                // Stage 3: the top-down pass (compact_tape), kWindow entries a step. An entry's
                // flags are final when the reverse sweep reaches it (parents come later), so
                // the sweep also counts the kept entries.
                uint stop = i > kWindow ? i - kWindow : 0u;
                for (; i > stop; --i) {
                    uint e = i - 1u;
                    uint fe = dbase + e * kTeam + lane;
                    uint fl = sweep_flags(windowed, win, fe, e);
                    if (((fl >> 2) & 3u) != 1u) continue;
                    uint w = tape_entry(windowed, win, parent, e);
                    if (is_primitive(tape_node(w))) {
                        ++out_len;
                        ++prims;
                        continue;
                    }
                    uint l = windowed ? s_meta[win + e] >> 16 : scratch[lbase + e], r = e - 1u;
                    uint d = windowed        ? window_decision(s_meta[win + e])
                             : pc.mode == 3u ? team_decision(dbase + e * kTeam)
                                             : fl & 3u;
                    if (d == kKeepBoth) {
                        ++out_len;
                        uint nl = tape_negated(tape_entry(windowed, win, parent, l)) ? 1u : 0u;
                        uint nr = tape_negated(tape_entry(windowed, win, parent, r)) ? 1u : 0u;
                        set_sweep_flags(windowed, win, dbase + l * kTeam + lane, l,
                                        (1u << 2) | (nl << 4));
                        set_sweep_flags(windowed, win, dbase + r * kTeam + lane, r,
                                        (1u << 2) | (nr << 4));
                        continue;
                    }
                    uint wn = d == kLeftWins ? l : r;
                    uint neg = ((fl >> 4) & 1u) ^
                               (tape_negated(tape_entry(windowed, win, parent, wn)) ? 1u : 0u);
                    set_sweep_flags(windowed, win, fe, e, (2u << 2) | (fl & 16u));
                    set_sweep_flags(windowed, win, dbase + wn * kTeam + lane, wn,
                                    (1u << 2) | (neg << 4));
                }
                if (i == 0u) {
                    note_len(out_len);
                    if (out_len == len && transient) {
                        // Nothing pruned, and a transient tape: share the parent's.
                        note_depth(pdepth);
                        phase = kPhaseDone;
                        store(dest, true, value, constant, parent, out_len, c0);
                    } else {
                        at = transient ? atomicAdd(octant_used, out_len + 2u)
                                       : atomicAdd(pool_used, out_len + 2u);
                        uint start = transient ? pc.octant_start : pc.pool_start;
                        uint capacity = transient ? octant_capacity : pool_capacity;
                        if (at < start || at + out_len + 2u > capacity ||
                            at + out_len + 2u < at || at >= kInOctantPool) {
                            // The host grows the pool and redoes the level; until then
                            // the box reads as far-field, so the steps after this one in the
                            // same submission read no garbage.
                            atomicOr(overflow, transient ? 2u : 1u);
                            phase = kPhaseDone;
                            store(dest, false, value, constant, kFarField, 0u, c0);
                        } else {
                            if (transient) at |= kInOctantPool;
                            tape_write(at, out_len);
                            tape_write(at + 1u, prims);
                            phase = kPhaseWrite;
                            top = at + 2u;  // the next word to write
                        }
                    }
                }
            }
            if (phase == kPhaseWrite) {
                uint we = min(i + kWindow, len);
                for (; i < we; ++i) {
                    uint fl = sweep_flags(windowed, win, dbase + i * kTeam + lane, i);
                    if (((fl >> 2) & 3u) != 1u) continue;
                    uint node = tape_node(tape_entry(windowed, win, parent, i));
                    tape_write(top++, tape_word(node, ((fl >> 4) & 1u) != 0u));
                    // Stack depth of the new tape: a primitive pushes, an operator pops two,
                    // pushes one.
                    depth = is_primitive(node) ? depth + 1u : depth - 1u;
                    depth_max = max(depth_max, depth);
                }
                if (i == len) {
                    note_depth(depth_max);
                    phase = kPhaseDone;
                    store(dest, true, value, constant, at, out_len, c0);
                }
            }
            if (phase != kPhaseDone) atomicAdd(s_busy[s & 1u], 1u);
            memoryBarrierBuffer();
            memoryBarrierShared();
            barrier();
            bool busy = s_busy[s & 1u] != 0u;
            if (gl_LocalInvocationID.x == 0u) s_busy[(s + 1u) & 1u] = 0u;
            if (!busy) break;
        }
        if (walk) scratch[st] = phase;
        if (walk && phase != kPhaseDone) {
            scratch[st + kTeam] = i;
            scratch[st + 2u * kTeam] = top;
            scratch[st + 3u * kTeam] = out_len;
            scratch[st + 4u * kTeam] = prims;
            scratch[st + 5u * kTeam] = at;
            scratch[st + 6u * kTeam] = floatBitsToUint(value);
            scratch[st + 7u * kTeam] = floatBitsToUint(constant);
            scratch[st + 8u * kTeam] = pdepth;
            scratch[st + 9u * kTeam] = depth;
            scratch[st + 10u * kTeam] = depth_max;
            scratch[st + 11u * kTeam] = batch;
            scratch[st + kStFar * kTeam] = far_flags;
            scratch[st + kStLowest * kTeam] = floatBitsToUint(lowest);
            scratch[st + kStHighest * kTeam] = floatBitsToUint(highest);
        }
    }
    counts_end();
}
