#version 450
// prune.comp — one pruning step of a level, one job (a cell or an octant) per iteration of a
// persistent thread; mirrors src/prune/prune_cell.cpp stage for stage (evaluate_cell,
// is_near_field, compact_tape) and the octant split of src/prune/prune.cpp.
//   mode 0: cells of a level from their block's tape (blocks[job / f³])
//   mode 1: the 8 octants of each block from the block's tape (not stored as cells)
//   mode 2: cells of a level from their octant's tape (or far-field from a far octant)
//   mode 3: finest near-field cells decided again over refine³ sub-boxes (refine_cell), from
//           `cells` into the buffer of binding 5; tapes longer than kRefineMaxTape are copied
// New tapes are appended to the pool with an atomic counter; on overflow nothing is written
// and the host grows the pool and runs the step again.
//
// A job is resumable: its state lives in the thread's scratch, and each dispatch (a "round")
// runs at most pc.budget loop iterations of it. Devices without a loop limit use one round with
// an unlimited budget; lavapipe, which ends an invocation's loops after 65,535 iterations in
// all, gets as many jobs per invocation as fit that, or one job over as many rounds as its
// parent tape needs.
#include "scene.glsl"

layout(local_size_x = 64) in;

#include "cells.glsl"

layout(std430, binding = 4) readonly buffer Blocks { Block blocks[]; };
layout(std430, binding = 5) buffer Octants { Cell octants[]; };
layout(std430, binding = 6) buffer Cells { Cell cells[]; };
layout(std430, binding = 7) buffer Counters {
    uint pool_used;
    uint pool_capacity;
    uint overflow;
    uint max_len;  // longest tape written or shared in this step
    uint near_jobs;  // near-field cells in this step
    uint next_blocks;
    uint max_depth;  // deepest evaluation stack of the tapes written or shared in this step
    uint octant_used;      // the octant pool, as pool_used, pool_capacity
    uint octant_capacity;
};
// Octants' tapes (mode 1) live in a pool of their own, dropped after the level: a reference
// with kInOctantPool set points there. So do the finest cells' tapes that refinement (mode 3)
// replaces (flag 4). Tapes for the main pool never share one of these: they copy it.
layout(std430, binding = 9) buffer OctantPool { uint octant_pool[]; };
const uint kInOctantPool = 0x80000000u;

uint tape_read(uint ref, uint k) {
    return (ref & kInOctantPool) != 0u ? octant_pool[(ref & ~kInOctantPool) + k] : pool[ref + k];
}
void tape_write(uint ref, uint value) {
    if ((ref & kInOctantPool) != 0u)
        octant_pool[ref & ~kInOctantPool] = value;
    else
        pool[ref] = value;
}
// Per thread: the job's state (kStateWords), 2 words per parent-tape entry (left operand;
// decision | alive << 2 | negate << 4), then 4 words per stack slot (value, lo, hi, entry).
layout(std430, binding = 8) buffer Scratch { uint scratch[]; };

layout(push_constant) uniform Push {
    vec4 origin;  // AABB min; w: Lipschitz bound of the root
    vec4 csize;   // cell size of this level; w: far-field C
    uint mode;
    uint factor;  // f: cells per axis of a block
    uint jobs;
    uint threads;
    uint max_len;    // longest parent tape (entry scratch per thread)
    uint max_stack;  // deepest evaluation stack of the parent tapes
    uint flags;      // 1: far field on; 2: interval bounds; 4: new tapes go to the octant pool
    uint pool_start;  // pool words in use before this step
    uint first_job;   // this dispatch's jobs: [first_job, jobs)
    uint round;       // 0: start the jobs; later rounds resume them
    uint budget;      // loop iterations per job and round
    uint refine;      // mode 3: sub-boxes per axis
    uint octant_start;  // octant pool words in use before this step
} pc;

// The state of a job between rounds, at the start of its thread's scratch.
const uint kStateWords = 16u;
const uint kPhaseEvaluate = 0u, kPhaseSweep = 1u, kPhaseWrite = 2u, kPhaseDone = 3u;
// Words: phase, i (next entry), top (stack size; in the write phase the next word), out_len,
// prims, at (tape offset), value, constant (float bits), the parent's stack depth, the new
// tape's stack depth now and at most, the sub-box, the far-field flags (1: every sub-box so far
// clears above, 2: below) and the lowest and highest root bounds so far (float bits).

// Runs (a budget's worth of) pruning the tape at `parent` over the box; returns true in the
// round that finishes the job, with `near`, `value`, `constant` and `tape` (the new tape, or the parent's when
// nothing was pruned) set.
// With subs > 1 (mode 3) the tape is evaluated over each of the box's subs³ sub-boxes, an
// operator is decided only where all of them agree, and the far-field test asks every sub-box's
// root range to clear the box's margin (refine_cell in src/prune/prune_cell.cpp).
bool prune_box(uint parent, vec3 centre, vec3 half_size, float R, uint subs, out bool near,
               out float value, out float constant, out uint tape) {
    uint t = gl_GlobalInvocationID.x;
    uint base = t * (kStateWords + 2u * pc.max_len + 4u * pc.max_stack);
    uint ebase = base + kStateWords;
    uint sbase = ebase + 2u * pc.max_len;
    bool interval = (pc.flags & 2u) != 0u;
    uint len = tape_read(parent, 0u);
    if (pc.round == 0u) {
        for (uint k = 0u; k < kStateWords; ++k) scratch[base + k] = 0u;
        scratch[base + 12u] = (pc.flags & 1u) != 0u ? 3u : 0u;
        scratch[base + 13u] = floatBitsToUint(kInfinity);
        scratch[base + 14u] = floatBitsToUint(-kInfinity);
    }
    uint phase = scratch[base], i = scratch[base + 1u], top = scratch[base + 2u];
    if (phase == kPhaseDone) return false;  // finished in an earlier round
    uint out_len = scratch[base + 3u], prims = scratch[base + 4u], at = scratch[base + 5u];
    uint budget = pc.budget;
    near = true;
    tape = kFarField;
    uint nsub = subs * subs * subs;
    vec3 sub_half = subs == 1u ? half_size : half_size / float(subs);
    float sub_R = subs == 1u ? R : length(sub_half);
    uint sb = scratch[base + 11u];
    while (phase == kPhaseEvaluate && budget > 0u) {
        // Stage 1: values and ranges at the (sub-)box centre, decisions (evaluate_cell).
        uvec3 sc = uvec3(sb % subs, (sb / subs) % subs, sb / (subs * subs));
        precise vec3 sub_centre =
            subs == 1u ? centre : centre - half_size + vec3(2u * sc + 1u) * sub_half;
        for (; i < len && budget > 0u; ++i, --budget) {
            uint w = tape_read(parent, 2u + i);
            uint n = tape_node(w);
            uint kind = nodes[n].kind;
            float spread = nodes[n].lipschitz * sub_R;
            float v, lo, hi;
            uint decision = kKeepBoth;
            if (kind < kPrimitiveKindCount) {
                uint p = nodes[n].primitive;
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
                uint sr = sbase + (top - 1u) * 4u, sl = sbase + (top - 2u) * 4u;
                top -= 2u;
                float lv = uintBitsToFloat(scratch[sl]), llo = uintBitsToFloat(scratch[sl + 1u]),
                      lhi = uintBitsToFloat(scratch[sl + 2u]);
                float rv = uintBitsToFloat(scratch[sr]), rlo = uintBitsToFloat(scratch[sr + 1u]),
                      rhi = uintBitsToFloat(scratch[sr + 2u]);
                float sgn = operator_s(kind), k = nodes[n].blend;
                decision = prune_decision(sgn, k, llo, lhi, rlo, rhi);
                scratch[ebase + 2u * i] = scratch[sl + 3u];
                v = apply_operator(sgn, k, lv, rv);
                if (decision == kLeftWins) {
                    lo = llo;
                    hi = lhi;
                } else if (decision == kRightWins) {
                    lo = rlo;
                    hi = rhi;
                } else if (interval) {
                    vec2 r2 = operator_range(sgn, k, llo, lhi, rlo, rhi);
                    lo = max(v - spread, r2.x);
                    hi = min(v + spread, r2.y);
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
            // Flags cleared for stage 3; over sub-boxes, a decision all of them share.
            uint e = ebase + 2u * i + 1u;
            scratch[e] = sb == 0u || scratch[e] == decision ? decision : kKeepBoth;
            uint so = sbase + top * 4u;
            scratch[so] = floatBitsToUint(v);
            scratch[so + 1u] = floatBitsToUint(lo);
            scratch[so + 2u] = floatBitsToUint(hi);
            scratch[so + 3u] = i;
            ++top;
            scratch[base + 8u] = max(scratch[base + 8u], top);
        }
        if (i < len) break;  // out of budget: resume in the next round
        // Stage 2 for this sub-box: the far-field test on its root range against the box's
        // margin (is_near_field).
        float v = uintBitsToFloat(scratch[sbase]);
        if (sb == 0u) scratch[base + 6u] = floatBitsToUint(v);
        float L = nodes[tape_node(tape_read(parent, 2u + len - 1u))].lipschitz;
        float clearance = far_field_clearance(pc.csize.w, L, R);
        vec2 range = far_field_range(v, uintBitsToFloat(scratch[sbase + 1u]),
                                     uintBitsToFloat(scratch[sbase + 2u]), L, sub_R);
        float lo = range.x, hi = range.y;
        uint far_flags = scratch[base + 12u];
        if (!clears_above(lo, clearance)) far_flags &= ~1u;
        if (!clears_below(hi, clearance)) far_flags &= ~2u;
        scratch[base + 12u] = far_flags;
        scratch[base + 13u] = floatBitsToUint(min(uintBitsToFloat(scratch[base + 13u]), lo));
        scratch[base + 14u] = floatBitsToUint(max(uintBitsToFloat(scratch[base + 14u]), hi));
        ++sb;
        i = 0u;
        top = 0u;
        if (sb < nsub) continue;
        phase = kPhaseSweep;
        if ((far_flags & 1u) != 0u) {
            scratch[base + 7u] = scratch[base + 13u];
            phase = kPhaseDone;
            near = false;
        } else if ((far_flags & 2u) != 0u) {
            scratch[base + 7u] = scratch[base + 14u];
            phase = kPhaseDone;
            near = false;
        } else {
            uint root_neg = tape_negated(tape_read(parent, 2u + len - 1u)) ? 1u : 0u;
            scratch[ebase + 2u * (len - 1u) + 1u] |= (1u << 2) | (root_neg << 4);
            i = len;
        }
    }
    scratch[base + 11u] = sb;
    if (phase == kPhaseSweep) {
        // Stage 3: the top-down pass (compact_tape). Flags: alive (bits 2-3: 1 kept,
        // 2 skipped), negate (bit 4). An entry's flags are final when the reverse sweep reaches
        // it (parents come later), so the sweep also counts the kept entries.
        for (; i > 0u && budget > 0u; --i, --budget) {
            uint e = i - 1u;
            uint f = scratch[ebase + 2u * e + 1u];
            uint w = tape_read(parent, 2u + e);
            if (((f >> 2) & 3u) != 1u) continue;
            if (is_primitive(tape_node(w))) {
                ++out_len;
                ++prims;
                continue;
            }
            uint l = scratch[ebase + 2u * e], r = e - 1u;
            uint d = f & 3u;
            if (d == kKeepBoth) {
                ++out_len;
                uint nl = tape_negated(tape_read(parent, 2u + l)) ? 1u : 0u;
                uint nr = tape_negated(tape_read(parent, 2u + r)) ? 1u : 0u;
                scratch[ebase + 2u * l + 1u] =
                    (scratch[ebase + 2u * l + 1u] & 3u) | (1u << 2) | (nl << 4);
                scratch[ebase + 2u * r + 1u] =
                    (scratch[ebase + 2u * r + 1u] & 3u) | (1u << 2) | (nr << 4);
                continue;
            }
            uint win = d == kLeftWins ? l : r;
            uint neg = ((f >> 4) & 1u) ^ (tape_negated(tape_read(parent, 2u + win)) ? 1u : 0u);
            scratch[ebase + 2u * e + 1u] = (f & 3u) | (2u << 2) | (f & 16u);
            scratch[ebase + 2u * win + 1u] =
                (scratch[ebase + 2u * win + 1u] & 3u) | (1u << 2) | (neg << 4);
        }
        if (i == 0u) {
            atomicMax(max_len, out_len);
            bool transient = pc.mode == 1u || (pc.flags & 4u) != 0u;
            if (out_len == len && ((parent & kInOctantPool) == 0u || transient)) {
                at = parent;  // nothing pruned: share the parent's tape
                atomicMax(max_depth, scratch[base + 8u]);
                phase = kPhaseDone;
            } else {
                bool octant = transient;
                at = octant ? atomicAdd(octant_used, out_len + 2u)
                            : atomicAdd(pool_used, out_len + 2u);
                uint start = octant ? pc.octant_start : pc.pool_start;
                uint capacity = octant ? octant_capacity : pool_capacity;
                if (at < start || at + out_len + 2u > capacity || at + out_len + 2u < at ||
                    at >= kInOctantPool) {
                    overflow = 1u;
                    at = kFarField;
                    phase = kPhaseDone;
                } else {
                    if (octant) at |= kInOctantPool;
                    tape_write(at, out_len);
                    tape_write(at + 1u, prims);
                    phase = kPhaseWrite;
                    top = at + 2u;  // the next word to write
                }
            }
        }
    }
    if (phase == kPhaseWrite) {
        for (; i < len && budget > 0u; ++i, --budget) {
            uint f = scratch[ebase + 2u * i + 1u];
            if (((f >> 2) & 3u) != 1u) continue;
            uint node = tape_node(tape_read(parent, 2u + i));
            tape_write(top++, tape_word(node, ((f >> 4) & 1u) != 0u));
            // Stack depth of the new tape: a primitive pushes, an operator pops two, pushes one.
            uint depth = is_primitive(node) ? scratch[base + 9u] + 1u : scratch[base + 9u] - 1u;
            scratch[base + 9u] = depth;
            scratch[base + 10u] = max(scratch[base + 10u], depth);
        }
        if (i == len) {
            atomicMax(max_depth, scratch[base + 10u]);
            phase = kPhaseDone;
        }
    }
    scratch[base] = phase;
    scratch[base + 1u] = i;
    scratch[base + 2u] = top;
    scratch[base + 3u] = out_len;
    scratch[base + 4u] = prims;
    scratch[base + 5u] = at;
    value = uintBitsToFloat(scratch[base + 6u]);
    constant = uintBitsToFloat(scratch[base + 7u]);
    if (phase != kPhaseDone) return false;
    if (near) tape = at;
    return true;
}

void main() {
    uint f = pc.factor;
    uint per_block = f * f * f;
    vec3 origin = pc.origin.xyz;
    vec3 cs = pc.csize.xyz;
    vec3 half_cell = cs * 0.5;
    float radius = length(half_cell);
    uint hf = f / 2u;
    for (uint job = pc.first_job + gl_GlobalInvocationID.x; job < pc.jobs; job += pc.threads) {
        Cell result;
        result.children = 0u;
        bool near;
        if (pc.mode == 1u) {
            Block b = blocks[job / 8u];
            uint o = job % 8u;
            uvec3 oc = uvec3(b.x + (o & 1u) * hf, b.y + ((o >> 1) & 1u) * hf,
                             b.z + ((o >> 2) & 1u) * hf);
            precise vec3 centre = origin + (vec3(oc) + 0.5 * float(hf)) * cs;
            if (!prune_box(b.tape, centre, half_cell * float(hf), radius * float(hf), 1u, near,
                           result.value, result.bound, result.tape))
                continue;
            octants[job] = result;
            continue;
        }
        uint bi = job / per_block, local = job % per_block;
        Block b = blocks[bi];
        uvec3 lc = uvec3(local % f, (local / f) % f, local / (f * f));
        precise vec3 centre = origin + (vec3(b.x + lc.x, b.y + lc.y, b.z + lc.z) + 0.5) * cs;
        uint parent = b.tape;
        if (pc.mode == 3u) {
            // Reads `cells`, writes the refined cells to `octants` (binding 5): a step redone
            // after a pool overflow starts again from unchanged cells.
            // Long tapes are not refined (kRefineMaxTape); their one evaluation changes nothing
            // and copies them from the octant pool to the main pool.
            Cell c = cells[job];
            if (c.tape == kFarField) {
                if (pc.round == 0u) octants[job] = c;
                continue;
            }
            uint subs = tape_read(c.tape, 0u) > kRefineMaxTape ? 1u : pc.refine;
            float unused;
            if (!prune_box(c.tape, centre, half_cell, radius, subs, near, unused, result.bound,
                           result.tape))
                continue;
            if (!near) {
                c.tape = kFarField;
                c.bound = result.bound;
            } else {
                c.tape = result.tape;
            }
            octants[job] = c;
            continue;
        }
        if (pc.mode == 2u) {
            uint o = (lc.x >= hf ? 1u : 0u) | (lc.y >= hf ? 2u : 0u) | (lc.z >= hf ? 4u : 0u);
            Cell oct = octants[bi * 8u + o];
            if (oct.tape == kFarField) {
                if (pc.round != 0u) continue;
                // A far octant makes far cells (prune.cpp): its constant, and its centre value
                // moved conservatively to the cell's centre.
                uvec3 oc = uvec3(b.x + (o & 1u) * hf, b.y + ((o >> 1) & 1u) * hf,
                                 b.z + ((o >> 2) & 1u) * hf);
                precise vec3 ocentre = origin + (vec3(oc) + 0.5 * float(hf)) * cs;
                float reach = pc.origin.w * length(centre - ocentre);
                result.tape = kFarField;
                result.bound = oct.bound;
                result.value = oct.value > 0.0 ? max(oct.value - reach, oct.bound)
                                               : min(oct.value + reach, oct.bound);
                cells[job] = result;
                continue;
            }
            parent = oct.tape;
        }
        if (!prune_box(parent, centre, half_cell, radius, 1u, near, result.value, result.bound,
                       result.tape))
            continue;
        if (near) atomicAdd(near_jobs, 1u);
        cells[job] = result;
    }
}
