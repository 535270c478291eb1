// prune_common.glsl — what the pruning kernels share: prune.comp (a team of kTeam lanes walks
// one parent tape, one lane per child box), prune_wide.comp (a whole workgroup takes one parent
// tape, its nodes spread over the lanes), prune_refine_lanes.comp (a lane per finest cell with a
// short tape) and prune_refine.comp (a squad of lanes per finest cell, a lane per sub-box): the
// step's buffers (bindings 4–11) and push constants, the tape pools, the boxes of a job
// (modes 0–2) and the store of a box's result.
// Include after scene.glsl and cells.glsl. The modes, flags and sizes the host plans with are
// prune_constants.h's.
// PRUNE_SUBGROUPS (prune_bytes.comp, prune_refine_lanes.comp; built only where the device has
// subgroup arithmetic and ballot): a subgroup's lanes that append to a pool or to refinement's
// list together take their places with one atomic (pool_allocate, list_near_cell).
#ifdef PRUNE_SUBGROUPS
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_ballot : require
// `place` = the counter as it was before the (active) lanes of the subgroup whose `take` holds
// added their number, plus the lane's rank among them: one atomic for all of them. (A macro: a
// buffer's member is no function argument in GLSL.)
#define SUBGROUP_APPEND(place, counter, take)                                              \
    {                                                                                      \
        uvec4 taking_ = subgroupBallot(take);                                              \
        uint first_ = 0u;                                                                  \
        if (subgroupElect() && subgroupBallotBitCount(taking_) != 0u)                      \
            first_ = atomicAdd(counter, subgroupBallotBitCount(taking_));                  \
        place = subgroupBroadcastFirst(first_) + subgroupBallotExclusiveBitCount(taking_); \
    }
#endif
// The bits of an entry's flags that say what it is, set with its decision (prune_team.glsl's
// entries, prune_wide.glsl's items): its tape word's sign, and whether it is a primitive.
const uint kFlagNegated = 64u, kFlagPrimitive = 128u;

#include "prune_constants.h"

layout(std430, binding = 4) restrict readonly buffer Blocks { Block blocks[]; };
layout(std430, binding = 5) buffer Octants { Cell octants[]; };
layout(std430, binding = 6) buffer Cells { Cell cells[]; };
#define COUNTERS_BINDING 7
#include "counters.glsl"
// The kernel's scratch (its layout is the kernel's own). Coherent: lanes read what other lanes
// of their workgroup wrote at earlier steps (a barrier between). In refinement, from
// pc.list_start, the long list: the cells its lane pass (prune_refine_lanes.comp) leaves to the
// squads that run after it (prune_refine.comp), long_jobs of them.
layout(std430, binding = 8) coherent buffer Scratch { uint scratch[]; };
// Octants' tapes (mode 1) live in a pool of their own, dropped after the level: a reference
// with kInOctantPool set points there. So do the finest cells' tapes that refinement (mode 3)
// replaces (kStepTransientTapes). Tapes for the main pool never share one of these: they copy it.
layout(std430, binding = 9) buffer OctantPool { uint octant_pool[]; };
const uint kInOctantPool = 0x80000000u;
// The finest near-field cells, the only ones refinement (mode 3) has work for: the step that
// makes the finest cells (kStepTransientTapes) lists each near one's index (list_near_cell); mode 3
// takes its jobs from here (refine_job; the far ones stay as they are: refinement rewrites the near
// ones in place).
layout(std430, binding = 10) buffer RefineList { uint refine_list[]; };
// The level's own pool, where its cells' tapes go; a main-pool reference read (tape_read) is a
// parent's, in the last level's pool (binding 3). The parents' pool is freed after the level, so
// a tape that outlives the level is never shared with its parent but copied (only transient
// tapes, in the octant pool, share their parents').
layout(std430, binding = 11) writeonly buffer LevelPool { uint level_pool[]; };

layout(push_constant) uniform Push {
    vec4 origin;  // AABB min; w: Lipschitz bound of the root
    vec4 csize;   // cell size of this level; w: far-field C
    uint mode;    // kMode* (prune_constants.h)
    uint factor;  // f: cells per axis of a block
    uint jobs;    // team jobs (see prune.comp)
    uint threads;  // lanes that take jobs (whole teams or workgroups)
    uint max_len;    // longest parent tape (scratch per team or workgroup)
    uint max_stack;  // prune.comp: deepest evaluation stack of the parent tapes;
                     // prune_wide.comp: the highest node's height (scene_height)
    uint flags;      // kStep* bits (prune_constants.h)
    uint pool_start;  // pool words in use before this step
    uint first_job;   // this dispatch's team jobs: [first_job, jobs)
    uint round;       // 0: start the jobs; later rounds resume them (prune.comp)
    uint budget;      // steps per job and round (prune.comp)
    uint refine;      // mode 3: sub-boxes per axis
    uint octant_start;  // octant pool words in use before this step
    uint list_start;    // mode 3: where the long list starts in scratch
    uint lane_tape;     // mode 3: the longest tape a lane refines alone
    uint wide_split;    // prune_wide.comp: workgroups per job (a share of its kTeam boxes each)
    uint more_start;    // prune_refine_lanes.comp: where its more list starts in scratch
    uint group_base;    // prune_wide.comp: the dispatch's first workgroup among the step's
    uint order_start;   // where the order list starts in scratch (kStepRefineOrderPass,
                        // kStepRefineOrdered, kStepTeamsOrdered; kModeOrderPlace)
    uint order_first;   // modes 1, 2 (kStepTeamsOrdered), 4, 5: the step's first parent (block,
                        // octant)
    uint claim_words;   // modes 0-2 in teams: the words its jobs may claim (0: no claims)
    uint walk_slot;     // the step's walk_words and walk_sum (kWalkSlots or more: none)
} pc;

// A job's claim of `words` of its step's claim area (pc.claim_words of them, past the teams'
// or workgroups' own scratch; prune_team.glsl: claim_entries, prune_wide.glsl: claim_items):
// their first word in the area, or kNoClaim where the claims would pass the host's bound on
// them (a bug: overflow bit 4 tells the host, which reports it).
const uint kNoClaim = 0xffffffffu;
uint claim_scratch(uint words) {
    if (words == 0u) return 0u;
    uint first = atomicAdd(scratch_claimed, words);
    if (first + words > pc.claim_words || first + words < first) {
        atomicOr(overflow, kOverflowClaim);
        return kNoClaim;
    }
    return first;
}

// The step's counters (near_jobs, near_words, max_len, max_depth, then walk_cells, then the
// workgroup's walk), summed and maxed first in shared memory by the workgroup's lanes, then
// added to the device's once per workgroup at its end: one atomic per workgroup instead of one
// per cell, on words that every workgroup of the device would otherwise queue on. Every lane
// calls counts_begin() first and counts_end() last, in uniform control flow.
const uint kWalkCount = 4u + kWalkClasses;  // s_counts' word of the workgroup's walk
const uint kCountWords = kWalkCount + 1u;
shared uint s_counts[kCountWords];
void counts_begin() {
    if (gl_LocalInvocationIndex < kCountWords) s_counts[gl_LocalInvocationIndex] = 0u;
    memoryBarrierShared();
    barrier();
}
// Lavapipe ends an invocation's loops, all of them together, after 65,535 iterations
// (Context::kLoopLimit), and the invocation goes on after them as if they had ended: so the
// host plans a step's work under that limit. Where it is wrong, the cells would come out wrong
// without a word; so there (pc.flags' probe count not 0) every invocation ends with a loop of
// that many iterations (a bound the compiler cannot know, so that the loop stays a loop), and
// one that runs fewer found the limit reached: overflow's kOverflowLoopLimit, which the host
// reports as an error.
void probe_loop_limit() {
    uint want = pc.flags >> kStepLoopProbeShift, ran = 0u;
    for (uint k = 0u; k < want; ++k) ++ran;
    if (ran != want) atomicOr(overflow, kOverflowLoopLimit);
}
void counts_end() {
    probe_loop_limit();
    memoryBarrierShared();
    barrier();
    uint k = gl_LocalInvocationIndex;
    if (k < kCountWords && s_counts[k] != 0u) {
        if (k == 0u) atomicAdd(near_jobs, s_counts[0]);
        if (k == 1u) atomicAdd(near_words, s_counts[1]);
        if (k == 2u) atomicMax(max_len, s_counts[2]);
        if (k == 3u) atomicMax(max_depth, s_counts[3]);
        if (k >= 4u && k < kWalkCount) atomicAdd(walk_cells[k - 4u], s_counts[k]);
        if (k == kWalkCount && pc.walk_slot < kWalkSlots) {
            atomicMax(walk_words[pc.walk_slot], s_counts[k]);
            atomicAdd(walk_sum[pc.walk_slot], s_counts[k]);
        }
    }
}
void note_len(uint len) { atomicMax(s_counts[2], len); }
void note_depth(uint depth) { atomicMax(s_counts[3], depth); }
// The workgroup's walk in this dispatch, in tape entries, where the step measures it
// (pc.walk_slot): the most any lane notes. The team kernel notes its workgroup's lockstep walk
// (the busiest lane of each of its steps, summed); refinement's lanes and squads each lane's
// own walk over its jobs (the tape staged, each walk over it, the sweep and the write).
void note_walk(uint words) {
    if (words != 0u) atomicMax(s_counts[kWalkCount], words);
}

uint tape_read(uint ref, uint k) {
    return (ref & kInOctantPool) != 0u ? octant_pool[(ref & ~kInOctantPool) + k] : pool[ref + k];
}
void tape_write(uint ref, uint value) {
    if ((ref & kInOctantPool) != 0u)
        octant_pool[ref & ~kInOctantPool] = value;
    else
        level_pool[ref] = value;
}

// Room for a tape of `words` words (with its header) in the level's pool, or in the octant pool
// (`transient`): its reference (kInOctantPool set for the octant pool), or kFarField where the
// pool has no room. Then the overflow is flagged: the host grows the pool and runs the steps
// again, and until then the box is stored far-field, so that the steps after this one in the
// same submission read no garbage. `transient` is the same for every lane of a dispatch.
// With PRUNE_SUBGROUPS, the lanes of a subgroup that call it together (the active ones) sum
// their words and one of them adds the sum to the pool's counter; each takes its place by a
// prefix sum. Every near box of a step appends to one of two counters, and on a GPU atomics on
// one address queue one after another (molecule's finest cells step: some 700,000 appends):
// together they queue a subgroup's worth at once.
uint pool_allocate(bool transient, uint words) {
#ifdef PRUNE_SUBGROUPS
    uint offset = subgroupExclusiveAdd(words), sum = subgroupAdd(words);
    uint first = 0u;
    if (subgroupElect())
        first = transient ? atomicAdd(octant_used, sum) : atomicAdd(pool_used, sum);
    uint at = subgroupBroadcastFirst(first) + offset;
#else
    uint at = transient ? atomicAdd(octant_used, words) : atomicAdd(pool_used, words);
#endif
    uint start = transient ? pc.octant_start : pc.pool_start;
    uint capacity = transient ? octant_capacity : pool_capacity;
    if (at < start || at + words > capacity || at + words < at || at >= kInOctantPool) {
        atomicOr(overflow, transient ? kOverflowOctantPool : kOverflowPool);
        return kFarField;
    }
    return transient ? at | kInOctantPool : at;
}

// A pruning step's work on one tape entry over a box (evaluate_cell and refine_cell; the same
// float operations as the CPU backend), shared by the three pruning kernels. x: value, lo, hi.
// A tape sign on an entry: its value negated, its range flipped.
vec3 negate_range(vec3 x) { return vec3(-x.x, -x.z, -x.y); }

// A primitive's value at the box's centre p and its range over the box (half sizes h, radius
// spread_r): v ± L·R, with interval bounds narrowed by its similarity bound.
// primitive_range_of takes the primitive's parameters and similarity bound (b0: extras' bound0,
// b1: bound1's f0 and rho) as read, for a caller that evaluates several boxes from one read.
vec3 primitive_range_of(Node nd, PrimitiveParams prm, vec4 b0, vec2 b1, vec3 p, vec3 h,
                        float spread_r, bool interval) {
    float v = eval_primitive(nd.kind, prm, p);
    vec2 r = primitive_box_range(v, nd.lipschitz * spread_r, primitive_narrows(interval, b0.w),
                                 b0.xyz, b0.w, b1.x, b1.y, p, h);
    return vec3(v, r.x, r.y);
}
// primitive_range: of node n (nd: nodes[n]), whose parameters are at n (node order), so that
// they may be read beside the node.
vec3 primitive_range(uint n, Node nd, vec3 p, vec3 h, float spread_r, bool interval) {
    return primitive_range_of(nd, params[n], extras[n].bound0, extras[n].bound1.xy, p, h,
                              spread_r, interval);
}

// An operator's value and range and its decision, from its operands'. An undecided operator's
// range with interval bounds: the operator's range over its operands' ranges, narrowed by
// v ± L·R; in refinement (`refining`) that range alone (OperatorMode::kRefine), which holds the
// Lipschitz range up to rounding.
vec3 combine_operator(Node nd, float spread_r, bool interval, bool refining, vec3 left,
                      vec3 right, out uint decision) {
    float sgn = operator_s(nd.kind), k2 = nd.blend;
    decision = prune_decision(sgn, k2, left.y, left.z, right.y, right.z);
    float v = apply_operator(sgn, k2, left.x, right.x);
    vec2 r = operator_box_range(decision, sgn, k2, v, nd.lipschitz * spread_r, interval,
                                !refining, left.y, left.z, right.y, right.z);
    return vec3(v, r.x, r.y);
}

// Stores a finished box's result: `tape` of `words` words (near), or the far-field constant.
// Mode 3 writes the refined cell `c` (to binding 5, the cells' own buffer, bound twice: a job
// reads its cell from binding 6 before it writes it, and no other job touches it).
void store(uint dest, bool near, float value, float constant, uint tape, uint words, Cell c) {
    if (pc.mode == kModeRefine) {
        if (near) {
            c.tape = tape;
        } else {
            c.tape = kFarField;
            c.bound = constant;
        }
        octants[dest] = c;
        return;
    }
    Cell result = Cell(near ? tape : kFarField, 0u, value, constant);
    if (pc.mode == kModeOctants) {
        // The near octants and their tape words (shared ones too), which bound their cells'
        // (gpu_prune.cpp: the cells to list for refinement, their tapes' words).
        if (near) {
            atomicAdd(s_counts[0], 1u);
            atomicAdd(s_counts[1], words + 2u);
        }
        octants[dest] = result;
        return;
    }
    if (near) {
        atomicAdd(s_counts[0], 1u);
        atomicAdd(s_counts[1], words + 2u);
    }
    cells[dest] = result;
}

// Whether refinement's far-field test might pass for a finest near cell whose tape (`len` words,
// its root `root_node`) is worth `value` at the centre (refine_need in
// src/prune/prune_cell.cpp: the far field on, and refine_far_possible, with a lone primitive's
// similarity scale).
bool refine_far_may_pass(uint root_node, uint len, float value) {
    if ((pc.flags & kStepFarField) == 0u) return false;
    vec3 half_cell = pc.csize.xyz * 0.5;
    Node root = nodes[root_node];
    float R = SDFPRUNE_DEVICE_ROUNDING(length(half_cell));
    float clearance = far_field_clearance(pc.csize.w, root.lipschitz, R);
    float sigma = len == 1u ? extras[root.primitive].bound0.w : 0.0;
    return refine_far_possible(value, clearance, sigma, half_cell);
}

// Lists a near cell that the step making the finest cells (kStepTransientTapes, modes 0 and 2)
// stores, with its tape's length and root node and its centre value, for refinement (which runs
// after the step: the tape may be written after it is listed). From the list's front
// (refine_cells), the cells it decides again; from its back, the last entry first
// (copy_cells), those it only copies into the level's pool: where it has nothing to try
// (refine_need), no operator of the tape that a sub-box might decide (`may_decide`: the compaction
// found a kept operator whose operands at the centre pass blend_may_decide) and no far-field
// test that might pass, or a tape too long to refine. Refinement's lanes then take the walks in
// runs of neighbouring jobs and the copies in others, instead of copies beside walks in every
// subgroup, where a subgroup takes as long as its longest lane.
// A cell to decide again goes to the list with its walk class (bits 28-31, counted in
// walk_cells), which refinement's order pass sorts the list by.
const uint kCellBits = 0x0fffffffu;  // a list entry's cell (below 2^28: 16-byte cells in a buffer)
// Set on refine_job's entries of cells only copied (its entries of cells to decide again are
// the cell alone, their class taken off).
const uint kCopyOnly = 0x80000000u;
uint refine_walk_class(uint len) { return min((len - 1u) / 4u, kWalkClasses - 1u); }
// With PRUNE_SUBGROUPS, the lanes of a subgroup that list cells together take their places in
// both lists with one atomic each (as pool_allocate).
void list_near_cell(uint dest, uint root_node, uint len, float value, bool may_decide) {
    if ((pc.flags & kStepTransientTapes) == 0u || pc.mode == kModeOctants) return;
    bool decide =
        len <= kRefineMaxTape && (may_decide || refine_far_may_pass(root_node, len, value));
#ifdef PRUNE_SUBGROUPS
    uint at_front, at_back;
    SUBGROUP_APPEND(at_front, refine_cells, decide);
    SUBGROUP_APPEND(at_back, copy_cells, !decide);
#else
    uint at_front = decide ? atomicAdd(refine_cells, 1u) : 0u;
    uint at_back = decide ? 0u : atomicAdd(copy_cells, 1u);
#endif
    if (decide) {
        uint c = refine_walk_class(len);
        refine_list[at_front] = dest | (c << 28);
        atomicAdd(s_counts[4u + c], 1u);
    } else {
        refine_list[uint(refine_list.length()) - 1u - at_back] = dest;
    }
}

// A workgroup's take from the step's counter (jobs_taken, zeroed before each dispatch; push
// kStepTakeJobs: prune_team.glsl's take_jobs, prune_wide.glsl's take_part): the first of the next
// `count` of [first, end), the same for every lane, or `end` where none is left or the
// workgroup may not take (`may_take`, its lane 0's). Called by every lane of the workgroup.
shared uint s_taken;
uint take_from_counter(bool may_take, uint count, uint first, uint end) {
    barrier();  // every lane has read the workgroup's last take
    if (gl_LocalInvocationID.x == 0u) {
        uint next = end;
        if (may_take) {
            uint k = atomicAdd(jobs_taken, count);
            if (k < end - first) next = first + k;
        }
        s_taken = next;
    }
    memoryBarrierShared();
    barrier();
    return s_taken;
}

// Jobs dealt out in a snake: takers (teams, lanes) 0 .. width − 1 take the jobs [first, end) in
// rounds of `width` (taker t's are first + t + k · width), the odd rounds from the last taker to
// the first (a round short of takers: from its last job). Job j of that deal is the one this
// gives. With the jobs in order, longest first, no taker takes the longest of every round.
// Push kStepDealInRounds (SDFPRUNE_VULKAN_SNAKE=0): every round from the first taker, to compare.
uint snake_deal(uint j, uint first, uint width, uint end) {
    if ((pc.flags & kStepDealInRounds) != 0u) return j;
    uint r = (j - first) / width, r0 = first + r * width;
    return (r & 1u) != 0u ? r0 + (min(width, end - r0) - 1u) - (j - r0) : j;
}

// Refinement's job k, below refine_cells + copy_cells: its cell, with kCopyOnly set where the
// cell is only copied (list_near_cell). The cells to decide again come first, in the order
// pass's order where it ran (kStepRefineOrdered), longest walks first.
uint refine_job(uint k) {
    if (k < refine_cells) {
        bool ordered = (pc.flags & kStepRefineOrdered) != 0u;
        uint entry = ordered ? scratch[pc.order_start + k] : refine_list[k];
        return entry & kCellBits;
    }
    return refine_list[uint(refine_list.length()) - 1u - (k - refine_cells)] | kCopyOnly;
}

// Box `lane` of team job `job` in modes 0–2: mode 0, kTeam cells of a block from the block's
// tape; mode 1, the 8 octants of a block; mode 2, kTeam cells of an octant from the octant's
// tape. Gives the box's centre (exact: `precise`, as the CPU computes it), half size and radius,
// the parent tape, where the result goes, and whether the lane stores one (a lane past a
// block's or octant's cells does not). Returns false where there is nothing to walk: the
// octant is far-field, and its cells are then stored far-field here (in round 0).
bool job_box(uint job, uint lane, out vec3 centre_out, out vec3 half_size, out float R,
             out uint parent, out uint dest, out bool valid) {
    uint f = pc.factor;
    uint per_block = f * f * f;
    uint hf = f / 2u;
    vec3 origin = pc.origin.xyz;
    vec3 cs = pc.csize.xyz;
    vec3 half_cell = cs * 0.5;
    float radius = SDFPRUNE_DEVICE_ROUNDING(length(half_cell));
    precise vec3 centre;
    valid = true;
    half_size = half_cell;
    R = radius;
    if (pc.mode == kModeOctants) {
        Block b = blocks[job];
        uint o = lane;
        uvec3 oc = uvec3(b.x + (o & 1u) * hf, b.y + ((o >> 1) & 1u) * hf,
                         b.z + ((o >> 2) & 1u) * hf);
        centre = origin + (vec3(oc) + 0.5 * float(hf)) * cs;
        centre_out = centre;
        half_size = half_cell * float(hf);
        R = radius * float(hf);
        parent = b.tape;
        dest = job * 8u + o;
        return true;
    }
    uint bi, local;
    if (pc.mode == kModeCells) {
        uint per_team = (per_block + kTeam - 1u) / kTeam;
        bi = job / per_team;
        local = (job % per_team) * kTeam + lane;
        valid = local < per_block;
        local = min(local, per_block - 1u);
    } else {
        // Mode 2: the octant's cells, kTeam at a time.
        uint per_octant = hf * hf * hf;
        uint per_team = (per_octant + kTeam - 1u) / kTeam;
        bi = job / (8u * per_team);
        uint o = (job / per_team) % 8u;
        uint q = (job % per_team) * kTeam + lane;
        valid = q < per_octant;
        q = min(q, per_octant - 1u);
        uvec3 l3 = uvec3((o & 1u) * hf + q % hf, ((o >> 1) & 1u) * hf + (q / hf) % hf,
                         ((o >> 2) & 1u) * hf + q / (hf * hf));
        local = (l3.z * f + l3.y) * f + l3.x;
    }
    Block b = blocks[bi];
    uvec3 lc = uvec3(local % f, (local / f) % f, local / (f * f));
    centre = cell_centre(origin, cs, b.x + lc.x, b.y + lc.y, b.z + lc.z);
    centre_out = centre;
    dest = bi * per_block + local;
    parent = b.tape;
    if (pc.mode == kModeOctantCells) {
        uint o = (lc.x >= hf ? 1u : 0u) | (lc.y >= hf ? 2u : 0u) | (lc.z >= hf ? 4u : 0u);
        Cell oct = octants[bi * 8u + o];
        if (oct.tape == kFarField) {
            // A far octant makes far cells (prune.cpp): its constant, and its centre
            // value moved conservatively to the cell's centre.
            if (pc.round == 0u && valid) {
                uvec3 oc = uvec3(b.x + (o & 1u) * hf, b.y + ((o >> 1) & 1u) * hf,
                                 b.z + ((o >> 2) & 1u) * hf);
                precise vec3 ocentre = origin + (vec3(oc) + 0.5 * float(hf)) * cs;
                float reach = pc.origin.w * SDFPRUNE_DEVICE_ROUNDING(length(centre - ocentre));
                cells[dest] = Cell(kFarField, 0u,
                                   oct.value > 0.0 ? max(oct.value - reach, oct.bound)
                                                   : min(oct.value + reach, oct.bound),
                                   oct.bound);
            }
            return false;
        }
        parent = oct.tape;
    }
    return true;
}
