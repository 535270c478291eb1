#version 450
// prune_refine.comp — refinement (mode 3): each finest near-field cell decided again over its
// refine³ sub-boxes (src/prune/prune_cell.cpp: refine_cell), from `cells` into the buffer of
// binding 5. A squad of kSquad lanes takes one cell: its tape sits in shared memory and every
// lane walks it in lockstep over its own sub-box (the next kSquad sub-boxes after each walk,
// while any are left), its evaluation stack in registers and the thread's local memory. The
// lanes' decisions meet in one shared word per entry, their far-field tests in one per lane;
// then one lane compacts the tape (the top-down sweep of compact_tape) and writes it to the
// level's pool. Job k takes cell refine_list[k], for k below refine_cells (the near-field cells
// the cells step listed); the far-field cells were copied to binding 5 before, as they are.
// Tapes longer than kRefineMaxTape, and a lone primitive that cannot clear the far field
// (refine_far_possible), have nothing to decide again: they are copied as they are, by all the
// squad's lanes.
#include "scene.glsl"

layout(local_size_x = 64) in;

#include "cells.glsl"
#include "prune_common.glsl"

const uint kSquad = 32u;                          // lanes per cell
const uint kSquads = 64u / kSquad;                // cells per workgroup
const uint kStackMax = kRefineMaxTape / 2u + 1u;  // the deepest stack of a tape it evaluates

// A squad's cell: its tape's words (the nodes are read where they are: every lane reads the
// same, and shared memory is kept for occupancy), per entry the decisions its lanes made (bit d:
// some sub-box decided d), the left operand, the sweep's flags (bits 0-1 alive: 0 dead, 1 kept,
// 2 skipped; bit 2 negate); per lane its sub-boxes' far-field flags (1: all clear above, 2:
// below) and lowest and highest root bounds; the new tape's place, and in a copy each lane's
// chunk's change of the stack depth (a primitive pushes, an operator pops two and pushes one)
// and the highest it reaches within.
shared uint s_word[kSquads][kRefineMaxTape];
shared uint s_seen[kSquads][kRefineMaxTape];
shared uint s_left[kSquads][kRefineMaxTape];
shared uint s_flag[kSquads][kRefineMaxTape];
shared uint s_far[kSquads][kSquad];
shared float s_lowest[kSquads][kSquad];
shared float s_highest[kSquads][kSquad];
shared uint s_at[kSquads];
shared int s_net[kSquads][kSquad], s_peak[kSquads][kSquad];

void main() {
    counts_begin();
    uint q = gl_LocalInvocationID.x / kSquad, lane = gl_LocalInvocationID.x % kSquad;
    uint squad = gl_WorkGroupID.x * kSquads + q;
    uint squads = pc.threads / kSquad;

    uint f = pc.factor;
    uint per_block = f * f * f;
    vec3 origin = pc.origin.xyz;
    vec3 cs = pc.csize.xyz;
    vec3 half_cell = cs * 0.5;
    float radius = length(half_cell);
    bool interval = (pc.flags & 2u) != 0u;
    bool far_field = (pc.flags & 1u) != 0u;
    uint subs = pc.refine;
    uint nsub = subs * subs * subs;
    uint nbatch = (nsub + kSquad - 1u) / kSquad;
    vec3 sub_half = half_cell / float(subs);
    float sub_R = length(sub_half);

    // The host records the dispatches for every finest cell; the jobs are the listed ones only
    // (the same count in every lane: the step before wrote it). Every lane of a workgroup sees
    // the same trip count (barriers inside).
    uint jobs = min(pc.jobs, refine_cells);
    for (uint first = pc.first_job; first < jobs; first += squads) {
        uint job = first + squad;
        bool has_job = squad < squads && job < jobs;
        uint cell = 0u, parent = 0u, len = 0u;
        Cell c0 = Cell(kFarField, 0u, 0.0, 0.0);
        precise vec3 centre = vec3(0.0);
        bool evaluate = false, copy = false;
        if (has_job) {
            cell = refine_list[job];
            uint bi = cell / per_block, local = cell % per_block;
            Block b = blocks[bi];
            uvec3 lc = uvec3(local % f, (local / f) % f, local / (f * f));
            centre = origin + (vec3(b.x + lc.x, b.y + lc.y, b.z + lc.z) + 0.5) * cs;
            c0 = cells[cell];
            if (c0.tape == kFarField) {
                // Only near cells are listed; were one not, it is copied as it is.
                if (lane == 0u) octants[cell] = c0;
            } else {
                parent = c0.tape;
                len = tape_read(parent, 0u);
                copy = len > kRefineMaxTape;
                if (len == 1u) {
                    Node lone = nodes[tape_node(tape_read(parent, 2u))];
                    float clearance = far_field_clearance(pc.csize.w, lone.lipschitz, radius);
                    float sigma = extras[lone.primitive].bound0.w;
                    copy = !far_field || !refine_far_possible(c0.value, clearance, sigma, half_cell);
                }
                evaluate = !copy;
            }
        }

        barrier();  // the squads' last reads of the previous job's shared words are done
        if (evaluate)
            for (uint k = lane; k < len; k += kSquad) {
                uint w = tape_read(parent, 2u + k);
                s_word[q][k] = w;
                s_seen[q][k] = 0u;
                s_flag[q][k] = 0u;
            }
        memoryBarrierShared();
        barrier();

        if (evaluate) {
            // Stage 1 over each sub-box: values, ranges and decisions (evaluate_boxes in
            // OperatorMode::kRefine), then stage 2, the far-field test of is_near_field on the
            // sub-box's root range against the whole cell's clearance.
            float L = nodes[tape_node(s_word[q][len - 1u])].lipschitz;
            float clearance = far_field_clearance(pc.csize.w, L, radius);
            uint far_flags = far_field ? 3u : 0u;
            float lowest = kInfinity, highest = -kInfinity;
            vec3 st[kStackMax];  // the stack's values and ranges
            uint st_entry[kStackMax];
            for (uint batch = 0u; batch < nbatch; ++batch) {
                // Lanes past the last sub-box repeat it.
                uint sb = min(batch * kSquad + lane, nsub - 1u);
                uvec3 sc = uvec3(sb % subs, (sb / subs) % subs, sb / (subs * subs));
                precise vec3 p = centre - half_cell + vec3(2u * sc + 1u) * sub_half;
                uint top = 0u;
                for (uint i = 0u; i < len; ++i) {
                    uint w = s_word[q][i];
                    Node nd = nodes[tape_node(w)];
                    vec3 x;
                    if (nd.kind < kPrimitiveKindCount) {
                        x = primitive_range(nd, p, sub_half, sub_R, interval);
                    } else {
                        top -= 2u;
                        uint decision;
                        x = combine_operator(nd, sub_R, interval, true, st[top], st[top + 1u],
                                             decision);
                        atomicOr(s_seen[q][i], 1u << decision);
                        if (lane == 0u && batch == 0u) s_left[q][i] = st_entry[top];
                    }
                    if (tape_negated(w)) x = negate_range(x);
                    st[top] = x;
                    st_entry[top] = i;
                    ++top;
                }
                vec2 range = far_field_range(st[0].x, st[0].y, st[0].z, L, sub_R);
                if (!clears_above(range.x, clearance)) far_flags &= ~1u;
                if (!clears_below(range.y, clearance)) far_flags &= ~2u;
                lowest = min(lowest, range.x);
                highest = max(highest, range.y);
            }
            s_far[q][lane] = far_flags;
            s_lowest[q][lane] = lowest;
            s_highest[q][lane] = highest;
        }
        if (copy && lane == 0u) {
            uint at = pool_allocate(false, len + 2u);
            if (at == kFarField) {
                store(cell, false, c0.value, 0.0, kFarField, 0u, c0);
            } else {
                tape_write(at, len);
                tape_write(at + 1u, tape_read(parent, 1u));
            }
            s_at[q] = at;
        }
        memoryBarrierShared();
        barrier();

        if (copy && s_at[q] != kFarField) {
            // Copied word for word, a chunk a lane; each chunk's change of the stack depth and
            // the highest it reaches within give the tape's deepest stack.
            uint at = s_at[q];
            uint chunk = (len + kSquad - 1u) / kSquad;
            uint k0 = min(lane * chunk, len), k1 = min(k0 + chunk, len);
            int depth = 0, peak = 0;
            for (uint k = k0; k < k1; ++k) {
                uint w = tape_read(parent, 2u + k);
                tape_write(at + 2u + k, w);
                depth += is_primitive(tape_node(w)) ? 1 : -1;
                peak = max(peak, depth);
            }
            s_net[q][lane] = depth;
            s_peak[q][lane] = peak;
        }
        memoryBarrierShared();
        barrier();

        if (copy && lane == 0u && s_at[q] != kFarField) {
            int depth = 0, depth_max = 0;
            for (uint m = 0u; m < kSquad; ++m) {
                depth_max = max(depth_max, depth + s_peak[q][m]);
                depth += s_net[q][m];
            }
            note_len(len);
            note_depth(uint(depth_max));
            store(cell, true, c0.value, 0.0, s_at[q], len, c0);
        }
        if (evaluate && lane == 0u) {
            uint far_flags = 3u;
            float lowest = kInfinity, highest = -kInfinity;
            for (uint m = 0u; m < kSquad; ++m) {
                far_flags &= s_far[q][m];
                lowest = min(lowest, s_lowest[q][m]);
                highest = max(highest, s_highest[q][m]);
            }
            if (far_flags != 0u) {
                store(cell, false, c0.value, (far_flags & 1u) != 0u ? lowest : highest,
                      kFarField, 0u, c0);
            } else {
                // Stage 3, compact_tape: the top-down sweep from the root, an operator decided
                // alike in every sub-box replaced by its winner.
                s_flag[q][len - 1u] = 1u | (tape_negated(s_word[q][len - 1u]) ? 4u : 0u);
                uint out_len = 0u, prims = 0u;
                for (uint i = len; i > 0u; --i) {
                    uint e = i - 1u;
                    uint fl = s_flag[q][e];
                    if ((fl & 3u) != 1u) continue;
                    uint w = s_word[q][e];
                    if (is_primitive(tape_node(w))) {
                        ++out_len;
                        ++prims;
                        continue;
                    }
                    uint l = s_left[q][e], r = e - 1u;
                    uint seen = s_seen[q][e];
                    uint d = bitCount(seen) == 1 ? uint(findLSB(seen)) : kKeepBoth;
                    if (d == kKeepBoth) {
                        ++out_len;
                        s_flag[q][l] = 1u | (tape_negated(s_word[q][l]) ? 4u : 0u);
                        s_flag[q][r] = 1u | (tape_negated(s_word[q][r]) ? 4u : 0u);
                        continue;
                    }
                    uint wn = d == kLeftWins ? l : r;
                    uint neg = ((fl >> 2) & 1u) ^ (tape_negated(s_word[q][wn]) ? 1u : 0u);
                    s_flag[q][e] = 2u | (fl & 4u);
                    s_flag[q][wn] = 1u | (neg << 2);
                }
                note_len(out_len);
                uint at = pool_allocate(false, out_len + 2u);
                if (at == kFarField) {
                    store(cell, false, c0.value, 0.0, kFarField, 0u, c0);
                } else {
                    tape_write(at, out_len);
                    tape_write(at + 1u, prims);
                    uint next = at + 2u, depth = 0u, depth_max = 0u;
                    for (uint i = 0u; i < len; ++i) {
                        uint fl = s_flag[q][i];
                        if ((fl & 3u) != 1u) continue;
                        uint node = tape_node(s_word[q][i]);
                        tape_write(next++, tape_word(node, (fl & 4u) != 0u));
                        depth = is_primitive(node) ? depth + 1u : depth - 1u;
                        depth_max = max(depth_max, depth);
                    }
                    note_depth(depth_max);
                    store(cell, true, c0.value, 0.0, at, out_len, c0);
                }
            }
        }
    }
    counts_end();
}
