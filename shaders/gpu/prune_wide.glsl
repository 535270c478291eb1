// prune_wide.glsl — prune_wide.comp and prune_wide_subgroups.comp: one pruning step (modes 0–2
// of prune.comp) where a whole workgroup takes one team job: the kTeam boxes of one parent tape,
// its nodes spread over kWide lanes. For the top levels, where a few parents have long tapes: a
// team would walk every node of them in turn.
// The same stages as src/prune/prune_cell.cpp (evaluate_cell, is_near_field, compact_tape), the
// same float operations per node and box, in another order:
//   1. the tape's entries sorted by their node's height in the scene (a counting sort: the
//      counts, their prefix sums, the scatter), and each operator's left operand found (the
//      entry before its right operand's subtree, whose first node the scene gives);
//   2. evaluation height by height (the heights the tape has, in a round each): first every
//      primitive's value and range over every box, in parallel, then each height's operators
//      (their operands are lower), a barrier between;
//   3. the far-field test per box on the root's range;
//   4. the top-down pass round by round, from the root down (a parent before its operands);
//   5. compaction: each lane counts the kept entries of a slice of the tape, a workgroup prefix
//      sum gives each slice its place in the new tape, and the lanes write their slices.
// A chain of operators (a left-deep tree) still takes one height after another: the walk of
// a lane is at least twice the tape's number of distinct heights. But a run of rounds of one
// operator each (a chain's: for the reference molecule, a left-deep chain of 1,000 smooth
// unions, every round above the primitives') needs no barrier between its rounds: lane b
// walks box b of all of them alone (evaluate_run, sweep_run), then one barrier. gpu_prune.cpp
// picks this kernel by tape length and scene height, and sizes its dispatches under lavapipe's
// loop limit (a job is never resumed: it ends in the dispatch that starts it).
// PRUNE_WIDE_SUBGROUPS (prune_wide_subgroups.comp, for devices with subgroup arithmetic and
// ballot in compute shaders): the prefix sums and the pool appends on subgroup operations,
// else on shared memory and an atomic per box. PRUNE_WIDE_RUNS (prune_wide_runs.comp): long
// runs walked from shared memory (below).
#extension GL_EXT_shader_8bit_storage : require
#include "scene.glsl"
#include "prune_constants.h"
#ifdef PRUNE_WIDE_SUBGROUPS
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_ballot : require
#define PRUNE_SUBGROUPS  // the pool appends and refinement's list (prune_common.glsl)
#endif

const uint kSearchTurn = 37u;  // (stage 1: odd, so that a lane takes every place in turn)
layout(local_size_x = kWide) in;

#include "cells.glsl"
#include "prune_common.glsl"

// Per node: the first node of its subtree (post-order: a subtree is the nodes from it to the
// node) and its height (0 for primitives).
layout(std430, binding = 12) restrict readonly buffer NodeSpans { uvec2 node_span[]; };

// A workgroup's scratch (wide_words): per parent-tape entry its left operand and its place in
// the height order, per height its count, its entries placed so far and its first place, per
// round (a height the tape has) kRoundWords (below), the rounds in no run (breaks) in order,
// then per entry and box of the workgroup's the value and range (kWideValueWords, item
// (e · g_boxes + b − g_b0)), then each item's flags, a byte (8-bit storage: the wide kernels
// are built only where the device has it): 13 bytes an item instead of 16.
// The words of `items` items (device_layout.hpp: prune_wide_item_words).
uint item_words(uint items) { return items * kWideValueWords + (items + 3u) / 4u; }
// Scratch as bytes, for the items' flags.
layout(std430, binding = 8) coherent buffer ScratchBytes { uint8_t scratch_bytes[]; };
// Per round: its first place in the height order, its count of entries, and where it is in a
// run (rounds 1 and up of one entry each: a chain's operators), the run's first round and the
// round after its last (for any other round: itself and the next); in a run, its one entry's
// record (kRunEntry...): the entry, its left operand, its tape word, and the tape signs of its
// operands (1: the left's, 2: the right's). kRoundWords words a round, and kWideHeightWords per
// scene height (prune_constants.h).
const uint kRunEntry = 4u, kRunLeft = 5u, kRunWord = 6u, kRunSigns = 7u;
// Where the step's jobs claim their items (pc.claim_words > 0, gpu_prune_plan.cpp: their
// tapes sum to less than the longest tape per workgroup), a workgroup holds none, and each job
// claims its own tape's, past the workgroups' scratch (claim_items).
uint wide_words() {
    uint items = pc.claim_words != 0u ? 0u : item_words(pc.max_len * (kTeam / pc.wide_split));
    return pc.max_len * 2u + items + kWideHeightWords * (pc.max_stack + 1u);
}

// The workgroup's prefix sums.
shared uvec4 s_scan[kWide];
// Per box: 0 done, 1 near (swept and compacted), 2 writing its new tape; the new tape's place,
// its length, primitives and deepest stack, the box's value at its centre.
shared uint s_state[kTeam], s_at[kTeam], s_len[kTeam], s_prims[kTeam], s_depth[kTeam];
shared float s_value[kTeam];
shared uint s_rounds;  // the job's rounds: the heights its tape has
shared uint s_items;   // the first word of the job's items, where it claims them
shared uint s_breaks;  // its rounds that are in no run

#ifdef PRUNE_WIDE_SUBGROUPS
// Per subgroup its total, then its first sum; whether subgroups hold consecutive lanes.
shared uvec4 s_sub[kWide];
shared uint s_linear;
#endif

// Exclusive prefix sums over the workgroup, in the lanes' order; every lane of the workgroup
// calls it. After it, s_scan holds the inclusive sums. With subgroups: each subgroup's sums,
// then the subgroups' totals summed by the first subgroup (where subgroups hold consecutive
// lanes, as drivers make them; else the shared-memory way). Without: Hillis–Steele in shared
// memory.
uvec4 wg_exclusive_scan(uvec4 x) {
    uint id = gl_LocalInvocationID.x;
#ifdef PRUNE_WIDE_SUBGROUPS
    if (s_linear != 0u) {
        uvec4 inner = subgroupExclusiveAdd(x);
        uvec4 total = subgroupAdd(x);
        if (subgroupElect()) s_sub[gl_SubgroupID] = total;
        memoryBarrierShared();
        barrier();
        if (gl_SubgroupID == 0u) {
            uvec4 carry = uvec4(0u);
            for (uint j0 = 0u; j0 < gl_NumSubgroups; j0 += gl_SubgroupSize) {
                uint j = j0 + gl_SubgroupInvocationID;
                uvec4 t = j < gl_NumSubgroups ? s_sub[j] : uvec4(0u);
                uvec4 first = carry + subgroupExclusiveAdd(t);
                carry += subgroupAdd(t);
                if (j < gl_NumSubgroups) s_sub[j] = first;
            }
        }
        memoryBarrierShared();
        barrier();
        uvec4 before = s_sub[gl_SubgroupID] + inner;
        s_scan[id] = before + x;
        memoryBarrierShared();
        barrier();
        return before;
    }
#endif
    s_scan[id] = x;
    memoryBarrierShared();
    barrier();
    for (uint d = 1u; d < kWide; d <<= 1) {
        uvec4 add = id >= d ? s_scan[id - d] : uvec4(0u);
        memoryBarrierShared();
        barrier();
        s_scan[id] += add;
        memoryBarrierShared();
        barrier();
    }
    return s_scan[id] - x;
}

// The workgroup's walk (note_walk): each lane counts the entries, items, heights and rounds it
// takes between two barriers (g_walk: the loops' iterations, a binary search's steps); at each
// barrier the workgroup adds its busiest lane's count to its walk (g_group_walk, the same in
// every lane), a stage after another, as they run. (Not counted: the prefix sums' few steps,
// and a staged chunk's search of its rounds for their operands, in shared memory.)
uint g_walk = 0u, g_group_walk = 0u, g_syncs = 0u;
// Per barrier (three in turn), the busiest lane's count. After barrier k the workgroup reads
// word k % 3, and resets word (k + 2) % 3: read after barrier k − 1, counted into before
// barrier k + 2, a barrier from either.
shared uint s_stage_walk[3];

void sync_all() {
    uint turn = g_syncs % 3u;
    if (g_walk != 0u) atomicMax(s_stage_walk[turn], g_walk);
    g_walk = 0u;
    memoryBarrierBuffer();
    memoryBarrierShared();
    barrier();
    g_group_walk += s_stage_walk[turn];
    if (gl_LocalInvocationID.x == 0u) s_stage_walk[(turn + 2u) % 3u] = 0u;
    ++g_syncs;
}

// The boxes of its job a workgroup takes: [g_b0, g_b0 + g_boxes) (pc.wide_split workgroups per
// job, kTeam / pc.wide_split boxes each); the first byte of its items' flags.
uint g_b0, g_boxes, g_flags;

// The first word of the items of the workgroup's share of a job whose tape has `len` entries
// (g_boxes of its boxes), claimed (claim_scratch) past the step's `groups` workgroups'
// scratch, or kNoClaim. Every lane calls it.
uint claim_items(uint len, uint groups) {
    if (gl_LocalInvocationID.x == 0u) {
        uint first = claim_scratch(item_words(len * g_boxes));
        s_items = first == kNoClaim ? kNoClaim : groups * wide_words() + first;
    }
    sync_all();
    return s_items;
}

// Entry e's value and range (lo, hi) at box b (of the workgroup's, g_b0 and up): item
// (e · g_boxes + b − g_b0) of scratch; its decision and sweep flags at byte g_flags + the item
// (item_flags). A workgroup holds items for its own boxes only, so a job split over more
// workgroups takes less scratch in each.
uint item_at(uint vbase, uint e, uint b) {
    return vbase + (e * g_boxes + (b - g_b0)) * kWideValueWords;
}
uint item_flags(uint e, uint b) { return uint(scratch_bytes[g_flags + e * g_boxes + (b - g_b0)]); }
void set_item_flags(uint e, uint b, uint flags) {
    scratch_bytes[g_flags + e * g_boxes + (b - g_b0)] = uint8_t(flags);
}
// An item's flags: bits 0-1 its decision, bit 6 its entry's tape sign, bit 7 whether the entry
// is a primitive (set in stage 2, so that stages 4 and 5 read neither its tape word nor its
// node), then the sweep's: bits 2-3 alive (0 dead, 1 kept, 2 skipped), bit 4 negate.
const uint kEvaluationFlags = 3u | kFlagNegated | kFlagPrimitive;  // not the sweep's
// What stage 2 stores as an item's flags.
uint evaluation_flags(uint decision, uint word, bool primitive) {
    return decision | (tape_negated(word) ? kFlagNegated : 0u) | (primitive ? kFlagPrimitive : 0u);
}
// The flags an entry's operand gets from a kept operator above it, its evaluation flags kept.
void set_kept(uint e, uint b, uint flags) {
    set_item_flags(e, b, (item_flags(e, b) & kEvaluationFlags) | flags);
}
// Entry e kept, its sign its tape word's flipped where `flip`.
void keep_item(uint e, uint b, uint flip) {
    uint fl = item_flags(e, b);
    uint neg = ((fl & kFlagNegated) != 0u ? 1u : 0u) ^ flip;
    set_item_flags(e, b, (fl & kEvaluationFlags) | (1u << 2) | (neg << 4));
}
vec3 item_range(uint at) {
    return vec3(uintBitsToFloat(scratch[at]), uintBitsToFloat(scratch[at + 1u]),
                uintBitsToFloat(scratch[at + 2u]));
}
void store_item(uint vbase, uint e, uint b, vec3 x, uint flags) {
    uint at = item_at(vbase, e, b);
    scratch[at] = floatBitsToUint(x.x);
    scratch[at + 1u] = floatBitsToUint(x.y);
    scratch[at + 2u] = floatBitsToUint(x.z);
    set_item_flags(e, b, flags);  // the sweep's flags cleared
}
// Round q's record in a run: its entry, left operand, and `third` (kRunWord or kRunSigns).
uvec3 run_record(uint rbase, uint q, uint third) {
    uint at = rbase + kRoundWords * q;
    return uvec3(scratch[at + kRunEntry], scratch[at + kRunLeft], scratch[at + third]);
}
// Round q's entry in a run.
uint run_entry(uint rbase, uint q) { return scratch[rbase + kRoundWords * q + kRunEntry]; }

// A run is walked by a lane a box (g_b0 + lane), each operand from scratch, made before the run
// or by the lane earlier in it. PRUNE_WIDE_RUNS (prune_wide_runs.comp): a run of kRunStaged
// rounds or more is walked kRunChunk rounds at a time. Before each chunk, every lane of the
// workgroup stages what the walk reads into shared memory, in parallel: per round its record
// and node and, for each of its operands, which round of the chunk it is the entry of, if any;
// per round and box what scratch holds of it. Then the walking lanes take the chunk from shared
// memory alone, and a barrier ends it. What the walk itself makes within the chunk (an
// operand's value, an entry's flags) it keeps in shared memory too, per round and box, and
// reads from there; what earlier chunks made is in scratch before the chunk is staged.
#ifdef PRUNE_WIDE_RUNS
// A run shorter than this is walked from scratch as it is: staging costs two barriers more.
const uint kRunStaged = 8u;
const uint kNotInChunk = 0xffu;
// Per round: entry, left operand, tape word (evaluation) or signs (sweep), and the chunk's
// rounds whose entries its operands are (bits 0-7 the left's, 8-15 the right's; kNotInChunk).
shared uvec4 s_run_rec[kRunChunk];
shared Node s_run_node[kRunChunk];  // (evaluation)
// Per round and box (item (q − c0) · kTeam + b): evaluation, its operands' values and ranges
// as staged and its own result; the sweep, its entry's flags and its operands' decisions.
shared vec4 s_run_left[kRunChunk * kTeam];
shared vec4 s_run_right[kRunChunk * kTeam];
shared uvec4 s_run_own[kRunChunk * kTeam];

// Stages a chunk's records (`third`: kRunWord or kRunSigns) and where its operands are made.
void stage_run_records(uint c0, uint c1, uint rbase, uint third, bool with_nodes) {
    uint id = gl_LocalInvocationID.x;
    for (uint q = c0 + id; q < c1; q += kWide) {
        ++g_walk;
        uvec3 rec = run_record(rbase, q, third);
        s_run_rec[q - c0] = uvec4(rec, 0u);
        if (with_nodes) s_run_node[q - c0] = nodes[tape_node(rec.z)];
    }
    sync_all();
    for (uint q = c0 + id; q < c1; q += kWide) {
        uvec4 rec = s_run_rec[q - c0];
        uint jl = kNotInChunk, jr = kNotInChunk;
        for (uint j = c0; j < c1; ++j) {
            uint e = s_run_rec[j - c0].x;
            if (e == rec.y) jl = j - c0;
            if (e == rec.x - 1u) jr = j - c0;
        }
        s_run_rec[q - c0].w = jl | (jr << 8);
    }
    sync_all();
}

#endif

// Whether the run of rounds [r0, end) is walked from scratch as it is (not staged).
bool run_walked_as_is(uint r0, uint end) {
#ifdef PRUNE_WIDE_RUNS
    return end - r0 < kRunStaged;
#else
    return true;
#endif
}

// Stage 2 over a run of rounds [r0, end), one operator each, for every box; every lane of the
// workgroup calls it.
void evaluate_run(uint r0, uint end, uint rbase, uint vbase, float spread_r, bool interval) {
    uint id = gl_LocalInvocationID.x, b = g_b0 + id;
    if (run_walked_as_is(r0, end)) {
        // Each operand from scratch: made before the run, or by this lane earlier in it.
        if (id < g_boxes)
            for (uint q = r0; q < end; ++q) {
                ++g_walk;
                uvec3 rec = run_record(rbase, q, kRunWord);
                uint decision;
                vec3 x = combine_operator(nodes[tape_node(rec.z)], spread_r, interval, false,
                                          item_range(item_at(vbase, rec.y, b)),
                                          item_range(item_at(vbase, rec.x - 1u, b)), decision);
                if (tape_negated(rec.z)) x = negate_range(x);
                store_item(vbase, rec.x, b, x, evaluation_flags(decision, rec.z, false));
            }
        sync_all();
        return;
    }
#ifdef PRUNE_WIDE_RUNS
    for (uint c0 = r0; c0 < end; c0 += kRunChunk) {
        uint c1 = min(c0 + kRunChunk, end);
        stage_run_records(c0, c1, rbase, kRunWord, true);
        for (uint k = id; k < (c1 - c0) * g_boxes; k += kWide) {
            ++g_walk;
            uvec4 rec = s_run_rec[k / g_boxes];
            uint box = g_b0 + k % g_boxes, at = (k / g_boxes) * kTeam + box;
            if ((rec.w & 0xffu) == kNotInChunk)
                s_run_left[at] = vec4(item_range(item_at(vbase, rec.y, box)), 0.0);
            if ((rec.w >> 8) == kNotInChunk)
                s_run_right[at] = vec4(item_range(item_at(vbase, rec.x - 1u, box)), 0.0);
        }
        sync_all();
        if (id < g_boxes)
            for (uint q = 0u; q < c1 - c0; ++q) {
                ++g_walk;
                uvec4 rec = s_run_rec[q];
                uint jl = rec.w & 0xffu, jr = rec.w >> 8;
                vec3 left = jl == kNotInChunk ? s_run_left[q * kTeam + b].xyz
                                              : uintBitsToFloat(s_run_own[jl * kTeam + b].xyz);
                vec3 right = jr == kNotInChunk ? s_run_right[q * kTeam + b].xyz
                                               : uintBitsToFloat(s_run_own[jr * kTeam + b].xyz);
                uint decision;
                vec3 x = combine_operator(s_run_node[q], spread_r, interval, false, left, right,
                                          decision);
                if (tape_negated(rec.z)) x = negate_range(x);
                store_item(vbase, rec.x, b, x, evaluation_flags(decision, rec.z, false));
                s_run_own[q * kTeam + b] = uvec4(floatBitsToUint(x), 0u);
            }
        sync_all();
    }
#endif
}

const uint kNoEntry = 0xffffffffu;
// Stage 4 at a kept operator of a run, its flags `fl` and its sign `neg`, its operands' tape
// signs in `signs` (its record's: bit 0 the left's, bit 1 the right's): its own flags (kept, or
// skipped where one operand wins), and the sweep's flags it gives its left and its right
// operand (0: none, for one that loses), their evaluation flags aside.
uvec3 swept_operator(uint fl, uint neg, uint signs) {
    uint d = fl & 3u, nl = signs & 1u, nr = (signs >> 1) & 1u;
    uint own = (fl & kEvaluationFlags) | ((d == kKeepBoth ? 1u : 2u) << 2) | (neg << 4);
    if (d == kKeepBoth) return uvec3(own, (1u << 2) | (nl << 4), (1u << 2) | (nr << 4));
    bool left = d == kLeftWins;
    uint winner = (1u << 2) | ((neg ^ (left ? nl : nr)) << 4);
    return uvec3(own, left ? winner : 0u, left ? 0u : winner);
}
// Stage 4 for a kept operator of a run (its record `rec`: entry, left operand, tape signs), box
// b, its flags `fl` and its sign `neg` (swept_operator): its own flags and its kept operands',
// all but `below` (kNoEntry: none), whose flags are written by its own round.
void sweep_operator(uvec3 rec, uint b, uint fl, uint neg, uint below) {
    uint e = rec.x, l = rec.y, r = e - 1u;
    uvec3 swept = swept_operator(fl, neg, rec.z);
    // (Its own flags are written already where the round above set them.)
    if (swept.x != fl) set_item_flags(e, b, swept.x);
    if (swept.y != 0u && l != below) set_kept(l, b, swept.y);
    if (swept.z != 0u && r != below) set_kept(r, b, swept.z);
}
// Stage 4 for round q of a run, box b, from scratch as it is: an entry's flags were set above
// the run, or by the round above it in the run.
void sweep_round(uint rbase, uint q, uint b) {
    ++g_walk;
    uvec3 rec = run_record(rbase, q, kRunSigns);
    uint fl = item_flags(rec.x, b);
    if (((fl >> 2) & 3u) == 1u) sweep_operator(rec, b, fl, (fl >> 4) & 1u, kNoEntry);
}

// A long run's top-down pass as a scan. Where each round's operator is an operand of the round
// above it (a chain), the pass hands one state down the path: whether the operator is kept and
// its sign. Each operator maps its state to its path operand's by a map of three bits (kPass:
// kept stays kept, unless the other operand wins; kSign: the sign passes on, where the
// operator is skipped; kFlip: then flipped by the operand's tape sign, or set to it), and maps
// compose. So the rounds are shared out among a box's kWide / g_boxes lanes, kScanRounds each
// from the top: each lane composes its rounds' maps, a scan over the lanes gives each the map
// from the chunk's top to its first round, and each lane then walks its rounds again with its
// state, writing every flag the serial pass writes: its operators' own, and those of operands
// off the path or below the chunk. A chunk where some round's operator is not an operand of
// the one above (a pruned tape's heights can skip) is swept round by round as before.
const uint kScanRounds = 8u;
// Runs of at least this many rounds are swept so (shorter ones: a scan's barriers cost more
// than the rounds).
const uint kRunScanned = 64u;
const uint kPass = 1u, kSign = 2u, kFlip = 4u, kSameState = kPass | kSign;
// The map of `upper` then `lower`.
uint compose_maps(uint upper, uint lower) {
    bool flip = ((upper & kFlip) != 0u && (lower & kSign) != 0u) != ((lower & kFlip) != 0u);
    return (upper & lower & kSameState) | (flip ? kFlip : 0u);
}
// A state (kPass: kept, kFlip: negated) through a map.
uint map_state(uint map, uint state) {
    bool negated = ((state & kFlip) != 0u && (map & kSign) != 0u) != ((map & kFlip) != 0u);
    return (state & map & kPass) | (negated ? kFlip : 0u);
}
// The map of an operator with decision d, whose path operand is its left one or not, with
// the operands' tape signs nl and nr.
uint path_map(uint d, bool left, uint nl, uint nr) {
    bool pass = d == kKeepBoth || d == (left ? kLeftWins : kRightWins);
    return (pass ? kPass : 0u) | (d != kKeepBoth ? kSign : 0u) |
           ((left ? nl : nr) != 0u ? kFlip : 0u);
}
shared uint s_unlinked;  // a round of the chunk not linked to the one above it

void sweep_run_scanned(uint r0, uint end, uint rbase) {
    uint id = gl_LocalInvocationID.x, per_box = kWide / g_boxes;
    uint b = g_b0 + id / per_box, lane = id % per_box;
    bool mine = s_state[b] == 1u;
    for (uint c1 = end; c1 > r0;) {
        uint c0 = c1 - min(per_box * kScanRounds, c1 - r0);
        // This lane's rounds [q0, q1), the highest first.
        uint q1 = c1 - min(c1 - c0, lane * kScanRounds);
        uint q0 = q1 - min(q1 - c0, kScanRounds);
        if (id == 0u) s_unlinked = 0u;
        memoryBarrierShared();
        barrier();
        // The chunk's top operator's state, as the rounds above left it.
        uint top = item_flags(run_entry(rbase, c1 - 1u), b);
        uint top_state = (((top >> 2) & 3u) == 1u ? kPass : 0u) | ((top & 16u) != 0u ? kFlip : 0u);
        uint map = kSameState;
        // (The chunk's lowest round's map is not needed.)
        for (uint q = q1; mine && q > q0 && q - 1u > c0; --q) {
            ++g_walk;
            uvec3 rec = run_record(rbase, q - 1u, kRunSigns);
            uint below = run_entry(rbase, q - 2u);
            bool left = below == rec.y;
            if (!left && below != rec.x - 1u) s_unlinked = 1u;
            uint d = item_flags(rec.x, b) & 3u;
            map = compose_maps(map, path_map(d, left, rec.z & 1u, (rec.z >> 1) & 1u));
        }
        s_scan[id].x = map;
        sync_all();
        if (s_unlinked != 0u) {
            if (id < g_boxes && s_state[g_b0 + id] == 1u)
                for (uint q = c1; q > c0; --q) sweep_round(rbase, q - 1u, g_b0 + id);
            sync_all();
            c1 = c0;
            continue;
        }
        // An inclusive scan of the maps over the box's lanes, from the top.
        for (uint k = 1u; k < per_box; k <<= 1) {
            ++g_walk;
            uint above = lane >= k ? s_scan[id - k].x : kSameState;
            memoryBarrierShared();
            barrier();
            s_scan[id].x = compose_maps(above, s_scan[id].x);
            memoryBarrierShared();
            barrier();
        }
        uint state = map_state(lane == 0u ? kSameState : s_scan[id - 1u].x, top_state);
        for (uint q = q1; mine && q > q0; --q) {
            ++g_walk;
            uvec3 rec = run_record(rbase, q - 1u, kRunSigns);
            // The operand whose flags the round below writes, if it is in the chunk.
            uint below = q - 1u > c0 ? run_entry(rbase, q - 2u) : kNoEntry;
            uint fl = item_flags(rec.x, b);
            if ((state & kPass) != 0u)
                sweep_operator(rec, b, fl, (state & kFlip) != 0u ? 1u : 0u, below);
            if (below == kNoEntry) break;
            state = map_state(path_map(fl & 3u, below == rec.y, rec.z & 1u, (rec.z >> 1) & 1u),
                              state);
        }
        sync_all();
        c1 = c0;
    }
}

// Stage 4 over a run of rounds [r0, end), one operator each, for every box whose tape is being
// compacted (s_state 1), from the highest round down; every lane of the workgroup calls it. The
// flags an entry of the chunk gets from a round above it in the chunk are kept in its item;
// its operands' decisions (the low two bits of their flags) do not change in this stage.
void sweep_run(uint r0, uint end, uint rbase, uint vbase) {
    uint id = gl_LocalInvocationID.x, b = g_b0 + id;
    if (end - r0 >= kRunScanned && (pc.flags & kStepWideNoScan) == 0u) {
        sweep_run_scanned(r0, end, rbase);
        return;
    }
    if (run_walked_as_is(r0, end)) {
        // Each entry's flags from scratch: set above the run, or by this lane earlier in it.
        if (id < g_boxes && s_state[b] == 1u)
            for (uint q = end; q > r0; --q) sweep_round(rbase, q - 1u, b);
        sync_all();
        return;
    }
#ifdef PRUNE_WIDE_RUNS
    for (uint c1 = end; c1 > r0;) {
        uint c0 = c1 - min(kRunChunk, c1 - r0);
        stage_run_records(c0, c1, rbase, kRunSigns, false);
        for (uint k = id; k < (c1 - c0) * g_boxes; k += kWide) {
            ++g_walk;
            uvec4 rec = s_run_rec[k / g_boxes];
            uint box = g_b0 + k % g_boxes;
            s_run_own[(k / g_boxes) * kTeam + box] =
                uvec4(item_flags(rec.x, box), item_flags(rec.y, box) & kEvaluationFlags,
                      item_flags(rec.x - 1u, box) & kEvaluationFlags, 0u);
        }
        sync_all();
        if (id < g_boxes && s_state[b] == 1u)
            for (uint q = c1 - c0; q > 0u; --q) {
                ++g_walk;
                uvec4 rec = s_run_rec[q - 1u];
                uvec4 own = s_run_own[(q - 1u) * kTeam + b];
                uint e = rec.x, l = rec.y, r = e - 1u, fl = own.x;
                if (((fl >> 2) & 3u) != 1u) continue;
                uint jl = rec.w & 0xffu, jr = rec.w >> 8;
                uvec3 swept = swept_operator(fl, (fl >> 4) & 1u, rec.z);
                if (swept.x != fl) set_item_flags(e, b, swept.x);
                // Each kept operand's flags, in scratch and, where the chunk has it, in its own.
                if (swept.y != 0u) {
                    set_item_flags(l, b, own.y | swept.y);
                    if (jl != kNotInChunk) s_run_own[jl * kTeam + b].x = own.y | swept.y;
                }
                if (swept.z != 0u) {
                    set_item_flags(r, b, own.z | swept.z);
                    if (jr != kNotInChunk) s_run_own[jr * kTeam + b].x = own.z | swept.z;
                }
            }
        sync_all();
        c1 = c0;
    }
#endif
}

// Parts taken as workgroups come free (kStepTakeJobs, as the team steps' take_jobs): a
// workgroup that is done with a part takes the next from the step's counter (jobs_taken, zeroed
// before each dispatch, shared by a step's dispatches side by side), in order, instead of the
// parts dealt out in advance (workgroup w's are w, w + groups, ...): one that drew long tapes
// no longer keeps the step waiting while others stand idle. Under a loop limit (lavapipe: push
// budget other than 0xffffffff) a workgroup takes at most as many as it would be dealt, so that
// every part is taken and none passes the limit. Gives the part, the same for all lanes, or
// `end` where none is left. Called by every lane of the workgroup.
uint take_part(uint taken, uint first, uint end, uint groups) {
    bool may_take = pc.budget == 0xffffffffu || taken < (end - first + groups - 1u) / groups;
    return take_from_counter(may_take, 1u, first, end);
}

void main() {
    if (gl_LocalInvocationID.x < 3u) s_stage_walk[gl_LocalInvocationID.x] = 0u;
    counts_begin();  // (its barrier orders the reset before any count)
    uint id = gl_LocalInvocationID.x;
#ifdef PRUNE_WIDE_SUBGROUPS
    if (id == 0u) s_linear = 1u;
    memoryBarrierShared();
    barrier();
    if (id != gl_SubgroupID * gl_SubgroupSize + gl_SubgroupInvocationID) s_linear = 0u;
    memoryBarrierShared();
    barrier();
#endif
    uint groups = pc.threads / kWide;
    uint split = pc.wide_split;
    g_boxes = kTeam / split;
    // The lanes' slices of a box's tape in the compaction.
    uint slices = kWide / g_boxes;
    uint base = gl_WorkGroupID.x * wide_words();
    uint lbase = base;                      // entry e's left operand
    uint obase = lbase + pc.max_len;        // the height order: entries
    uint hbase = obase + pc.max_len;        // per height: count, placed, first place
    uint rbase = hbase + 3u * (pc.max_stack + 1u);  // per round: kRoundWords
    uint bbase = rbase + kRoundWords * (pc.max_stack + 1u);  // the rounds in no run, in order
    uint own_items = bbase + (pc.max_stack + 1u);  // items (item_at): v, lo, hi; then flags
    bool interval = (pc.flags & kStepIntervalBounds) != 0u;
    bool transient = pc.mode == kModeOctants || (pc.flags & kStepTransientTapes) != 0u;

    // Every lane of a workgroup sees the same trip count and the same job (and boxes).
    // (A step whose scratch is spread over several buffers runs as several dispatches side by
    // side, one a buffer: the dispatch's workgroups are the step's from pc.group_base on, its
    // scratch its own buffer's.)
    bool taking = (pc.flags & kStepTakeJobs) != 0u;
    uint first_part = pc.first_job * split, end = pc.jobs * split, taken = 0u;
    for (uint part = taking ? take_part(taken++, first_part, end, groups)
                            : first_part + pc.group_base + gl_WorkGroupID.x;
         part < end; part = taking ? take_part(taken++, first_part, end, groups) : part + groups) {
        uint job = part / split;
        g_b0 = (part % split) * g_boxes;
        uint box = g_b0 + id % g_boxes;  // the box of this lane in stages 1–4
        vec3 centre, half_size;
        float R;
        uint parent, dest;
        bool valid;
        bool walk = job_box(job, box, centre, half_size, R, parent, dest, valid);
        // Every box of a job shares its parent: far or not, all together.
        if (!walk) continue;
        uint len = tape_read(parent, 0u);
        uint root_word = tape_read(parent, 1u + len);
        uint H = node_span[tape_node(root_word)].y;
        // The job's items: the workgroup's own, or claimed.
        uint vbase = pc.claim_words != 0u ? claim_items(len, groups) : own_items;
        if (vbase == kNoClaim) continue;  // (the host reports it)
        g_flags = 4u * (vbase + len * g_boxes * kWideValueWords);

        // Stage 1: the counting sort by height, and the left operands.
        for (uint h = id; h <= H; h += kWide) {
            ++g_walk;
            scratch[hbase + 3u * h] = 0u;
            scratch[hbase + 3u * h + 1u] = 0u;
        }
        sync_all();
        for (uint e = id; e < len; e += kWide) {
            ++g_walk;
            atomicAdd(scratch[hbase + 3u * node_span[tape_node(tape_read(parent, 2u + e))].y], 1u);
        }
        sync_all();
        // Each lane sums a slice of the heights (entries, heights with any, and those of them
        // in no run: with other than one entry, or the primitives'), a prefix sum places the
        // slices: each height's first place, each round's, and each break's in the list of
        // breaks. A round in a run keeps, until the runs are found, the breaks before it.
        uint hs = (H + kWide) / kWide;
        uint h0 = min(id * hs, H + 1u), h1 = min(h0 + hs, H + 1u);
        uint sum = 0u, present = 0u, breaks = 0u;
        g_walk += 2u * (h1 - h0);  // (this loop and the next)
        for (uint h = h0; h < h1; ++h) {
            uint count = scratch[hbase + 3u * h];
            sum += count;
            present += count != 0u ? 1u : 0u;
            breaks += count != 0u && (count != 1u || h == 0u) ? 1u : 0u;
        }
        uvec4 places = wg_exclusive_scan(uvec4(sum, present, breaks, 0u));
        if (id == 0u) {
            s_rounds = s_scan[kWide - 1u].y;
            s_breaks = s_scan[kWide - 1u].z;
        }
        uint place = places.x, rank = places.y, brk = places.z;
        for (uint h = h0; h < h1; ++h) {
            uint count = scratch[hbase + 3u * h];
            scratch[hbase + 3u * h + 2u] = place;
            if (count != 0u) {
                uint at = rbase + kRoundWords * rank;
                scratch[at] = place;
                scratch[at + 1u] = count;
                if (count == 1u && h != 0u) {
                    scratch[at + 2u] = brk;
                } else {
                    scratch[at + 2u] = rank;
                    scratch[at + 3u] = rank + 1u;
                    scratch[bbase + brk] = rank;
                    ++brk;
                }
                ++rank;
            }
            place += count;
        }
        sync_all();
        uint rounds = s_rounds, round_breaks = s_breaks;
        // Each lane takes an entry of every kWide in turn, at a place that moves by
        // kSearchTurn from one kWide to the next: the searches' lengths follow the tape's
        // shape, which repeats (a balanced tree's highest operators, with the longest
        // searches, lie kWide and a power of two apart), and a lane that took the same place
        // each time took every long one. The workgroup's loads are still of adjacent words.
        for (uint e0 = 0u, turn = 0u; e0 < len; e0 += kWide, turn += kSearchTurn) {
            uint e = e0 + (id + turn) % kWide;
            if (e >= len) continue;
            ++g_walk;
            uint w = tape_read(parent, 2u + e);
            uint n = tape_node(w);
            uint h = node_span[n].y;
            uint place = scratch[hbase + 3u * h + 2u] + atomicAdd(scratch[hbase + 3u * h + 1u], 1u);
            scratch[obase + place] = e;
            if (h == 0u) continue;
            // The left operand ends just before the right operand's subtree: the entries of
            // a subtree are those of its scene subtree's nodes, in the same order. So the
            // subtree's entries are at most its nodes, and the search starts that far back: a
            // step per level of the right operand's subtree, not per level of the whole tape.
            uint right = tape_node(tape_read(parent, 1u + e));
            uint first = node_span[right].x;
            uint hi = e - 1u, lo = hi - min(hi, right - first);
            while (lo < hi) {
                ++g_walk;
                uint mid = (lo + hi) / 2u;
                if (tape_node(tape_read(parent, 2u + mid)) >= first)
                    hi = mid;
                else
                    lo = mid + 1u;
            }
            scratch[lbase + e] = lo - 1u;
        }
        sync_all();
        // The runs: a round in one lies between the breaks before and after it (round 0, the
        // primitives', is a break), and its entry is the first in its place. Its record, so
        // that the serial walks start from one load a round.
        for (uint r = id; r < rounds; r += kWide) {
            ++g_walk;
            uint at = rbase + kRoundWords * r;
            if (scratch[at + 1u] != 1u || r == 0u) continue;
            uint before = scratch[at + 2u];
            scratch[at + 2u] = scratch[bbase + before - 1u] + 1u;
            scratch[at + 3u] = before < round_breaks ? scratch[bbase + before] : rounds;
            uint e = scratch[obase + scratch[at]], l = scratch[lbase + e];
            scratch[at + kRunEntry] = e;
            scratch[at + kRunLeft] = l;
            scratch[at + kRunWord] = tape_read(parent, 2u + e);
            scratch[at + kRunSigns] = (tape_negated(tape_read(parent, 2u + l)) ? 1u : 0u) |
                                      (tape_negated(tape_read(parent, 1u + e)) ? 2u : 0u);
        }
        sync_all();

        // Stage 2: values and ranges at the boxes' centres, decisions (evaluate_cell), round by
        // round. Item k of a round: its entry k / g_boxes, box g_b0 + k % g_boxes (this lane's
        // box). A run of rounds (one operator each) is walked by a lane a box (evaluate_run).
        float spread_r = R;
        for (uint r = 0u; r < rounds;) {
            uint at = rbase + kRoundWords * r;
            uint first_place = scratch[at], count = scratch[at + 1u], next = scratch[at + 3u];
            if (next > r + 1u) {
                evaluate_run(r, next, rbase, vbase, spread_r, interval);
                r = next;
                continue;
            }
            for (uint k = id; k < count * g_boxes; k += kWide) {
                ++g_walk;
                uint e = scratch[obase + first_place + k / g_boxes];
                uint w = tape_read(parent, 2u + e);
                Node nd = nodes[tape_node(w)];
                uint kind = nd.kind;
                vec3 x;
                uint decision = kKeepBoth;
                if (kind < kPrimitiveKindCount) {
                    x = primitive_range(tape_node(w), nd, centre, half_size, spread_r, interval);
                } else {
                    vec3 left = item_range(item_at(vbase, scratch[lbase + e], box));
                    vec3 right = item_range(item_at(vbase, e - 1u, box));
                    x = combine_operator(nd, spread_r, interval, false, left, right, decision);
                }
                if (tape_negated(w)) x = negate_range(x);
                store_item(vbase, e, box, x,
                           evaluation_flags(decision, w, kind < kPrimitiveKindCount));
            }
            sync_all();
            ++r;
        }

        // Stage 3: the far-field test on each box's root range (is_near_field).
        if (id < g_boxes) {
            uint s0 = item_at(vbase, len - 1u, box);
            float v = uintBitsToFloat(scratch[s0]);
            float L = nodes[tape_node(root_word)].lipschitz;
            float clearance = far_field_clearance(pc.csize.w, L, R);
            vec2 range = far_field_range(v, uintBitsToFloat(scratch[s0 + 1u]),
                                         uintBitsToFloat(scratch[s0 + 2u]), L, R);
            uint far_flags = (pc.flags & kStepFarField) != 0u ? 3u : 0u;
            if (!clears_above(range.x, clearance)) far_flags &= ~1u;
            if (!clears_below(range.y, clearance)) far_flags &= ~2u;
            float lowest = min(kInfinity, range.x), highest = max(-kInfinity, range.y);
            s_value[box] = v;
            s_state[box] = 0u;
            if ((far_flags & 3u) != 0u) {
                float constant = (far_flags & 1u) != 0u ? lowest : highest;
                if (valid) store(dest, false, v, constant, kFarField, 0u, Cell(0u, 0u, 0.0, 0.0));
            } else if (valid) {
                keep_item(len - 1u, box, 0u);  // the root, with its own sign
                s_state[box] = 1u;
            }
        }
        sync_all();

        // Stage 4: the top-down pass (compact_tape), from the highest operators down: an
        // entry's flags are final when its round is reached. (Round 0: the primitives.)
        // A run is walked by a lane a box, from its highest round down (sweep_run).
        for (uint r = rounds - 1u; r >= 1u;) {
            uint at = rbase + kRoundWords * r;
            uint first_place = scratch[at], count = scratch[at + 1u], start = scratch[at + 2u];
            if (start < r) {
                sweep_run(start, r + 1u, rbase, vbase);
                r = start - 1u;
                continue;
            }
            for (uint k = id; k < count * g_boxes; k += kWide) {
                ++g_walk;
                if (s_state[box] != 1u) continue;
                uint e = scratch[obase + first_place + k / g_boxes];
                uint fl = item_flags(e, box);
                if (((fl >> 2) & 3u) != 1u) continue;
                uint l = scratch[lbase + e], r = e - 1u;
                uint d = fl & 3u;
                if (d == kKeepBoth) {
                    keep_item(l, box, 0u);
                    keep_item(r, box, 0u);
                    continue;
                }
                set_item_flags(e, box, (fl & kEvaluationFlags) | (2u << 2) | (fl & 16u));
                keep_item(d == kLeftWins ? l : r, box, (fl >> 4) & 1u);
            }
            sync_all();
            --r;
        }

        // Stage 5: compaction. Box g_b0 + b's kept entries in `slices` slices of the tape, one
        // a lane (lanes b · slices ...): counted (entries, primitives, the stack's change and
        // its highest point in the slice), placed by a prefix sum, then written.
        uint cbox = g_b0 + id / slices, slice = id % slices;
        uint per = (len + slices - 1u) / slices;
        uint e0 = min(slice * per, len), e1 = min(e0 + per, len);
        bool mine = s_state[cbox] == 1u;
        uint kept = 0u, kept_prims = 0u;
        int depth = 0, depth_peak = 0;  // the stack's change from the slice's start, its peak
        for (uint e = e0; mine && e < e1; ++e) {
            ++g_walk;
            uint fl = item_flags(e, cbox);
            if (((fl >> 2) & 3u) != 1u) continue;
            bool prim = (fl & kFlagPrimitive) != 0u;
            if (prim) ++kept_prims;
            depth += prim ? 1 : -1;
            depth_peak = kept == 0u ? depth : max(depth_peak, depth);
            ++kept;
        }
        // (The stack's changes sum as uints: two's complement.)
        uvec4 before = wg_exclusive_scan(uvec4(kept, kept_prims, uint(depth), 0u));
        uint cfirst = (id / slices) * slices;  // the box's first lane
        uvec4 box_first = cfirst == 0u ? uvec4(0u) : s_scan[cfirst - 1u];
        uvec4 box_total = s_scan[cfirst + slices - 1u] - box_first;
        before -= box_first;
        // The stack depth at the slice's start plus its highest point within it.
        uint peak = kept == 0u ? 0u : uint(int(before.z) + depth_peak);
        if (slice == 0u) {
            s_len[cbox] = box_total.x;
            s_prims[cbox] = box_total.y;
            s_depth[cbox] = 0u;
        }
        sync_all();
        if (mine) atomicMax(s_depth[cbox], peak);
        sync_all();
        if (id < g_boxes && s_state[box] == 1u) {
            uint out_len = s_len[box];
            note_len(out_len);
            if (out_len == len && transient) {
                // Nothing pruned, and a transient tape: share the parent's (as deep a stack).
                note_depth(s_depth[box]);
                s_state[box] = 0u;
                store(dest, true, s_value[box], 0.0, parent, out_len, Cell(0u, 0u, 0.0, 0.0));
                list_near_cell(dest, tape_node(root_word), out_len, s_value[box], true);
            } else {
                // (With subgroups, one append per subgroup.) On overflow the host grows the
                // pool and redoes the level (see prune.comp).
                uint at = pool_allocate(transient, out_len + 2u);
                if (at == kFarField) {
                    s_state[box] = 0u;
                    store(dest, false, s_value[box], 0.0, kFarField, 0u, Cell(0u, 0u, 0.0, 0.0));
                } else {
                    tape_write(at, out_len);
                    tape_write(at + 1u, s_prims[box]);
                    s_at[box] = at;
                    s_state[box] = 2u;
                }
            }
        }
        sync_all();
        if (s_state[cbox] == 2u) {
            uint to = s_at[cbox] + 2u + before.x;
            for (uint e = e0; e < e1; ++e) {
                ++g_walk;
                uint fl = item_flags(e, cbox);
                if (((fl >> 2) & 3u) != 1u) continue;
                uint node = tape_node(tape_read(parent, 2u + e));
                tape_write(to++, tape_word(node, ((fl >> 4) & 1u) != 0u));
            }
        }
        sync_all();
        if (id < g_boxes && s_state[box] == 2u) {
            note_depth(s_depth[box]);
            store(dest, true, s_value[box], 0.0, s_at[box], s_len[box], Cell(0u, 0u, 0.0, 0.0));
            // (Every tape refined: this kernel does not look for operators refinement might
            // decide, which only saves work.)
            list_near_cell(dest, tape_node(tape_read(s_at[box], 1u + s_len[box])), s_len[box],
                           s_value[box], true);
        }
        sync_all();
    }
    // The step's walks, measured: the most any workgroup walked in one dispatch, and their sum.
    if (id == 0u) note_walk(g_group_walk);
    counts_end();
}
