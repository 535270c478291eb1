#version 450
// prune_refine.comp — refinement (mode 3), its second pass: the finest near-field cells whose
// tapes are too long for a lane alone (prune_refine_lanes.comp lists them in the long list,
// scratch[pc.list_start], counted in long_jobs; without a lane pass, every listed near cell)
// decided again over their refine³ sub-boxes
// (src/prune/prune_cell.cpp: refine_cell), in place (written through binding 5, the cells' own
// buffer). A squad of kSquad
// lanes takes one cell: its tape sits in shared memory and every lane walks it in lockstep over
// its own sub-box (the next kSquad sub-boxes after each walk, while any are left), its
// evaluation stack in registers and the thread's local memory. The lanes' decisions meet in one
// shared word per entry, their far-field tests in one per lane; then one lane compacts the tape
// (the top-down sweep of compact_tape) and writes it to the level's pool. The cells listed as
// only copied (list_near_cell: tapes longer than kRefineMaxTape, or nothing that refinement might
// change) are copied as they are, by all the squad's lanes.
#include "scene.glsl"

layout(local_size_x = 64) in;

#include "cells.glsl"
#include "prune_common.glsl"

const uint kSquads = 64u / kSquad;  // cells per workgroup (kSquad lanes a cell)

// A squad's cell: its tape's words (the nodes are read where they are: every lane reads the
// same, and shared memory is kept for occupancy), per entry the decisions its lanes made, the
// left operand and the sweep's flags (refine_common.glsl); per lane its sub-boxes' far-field
// flags (1: all clear above, 2: below) and lowest and highest root bounds; the new tape's place,
// and in a copy each lane's chunk's change of the stack depth (a primitive pushes, an operator
// pops two and pushes one) and the highest it reaches within.
shared uint s_word[kSquads][kRefineMaxTape];
shared uint s_seen[kSquads][kRefineMaxTape];
shared uint s_left[kSquads][kRefineMaxTape];
shared uint s_flag[kSquads][kRefineMaxTape];
shared uint s_far[kSquads][kSquad];
shared float s_lowest[kSquads][kSquad];
shared float s_highest[kSquads][kSquad];
shared uint s_at[kSquads];
shared int s_net[kSquads][kSquad], s_peak[kSquads][kSquad];

uint q;  // the invocation's squad in its workgroup
#define REFINE_WORD(i) s_word[q][i]
#define REFINE_SEEN(i) s_seen[q][i]
#define REFINE_SEE(i, bits) atomicOr(s_seen[q][i], bits)
#define REFINE_LEFT(i) s_left[q][i]
#define REFINE_SET_LEFT(i, l) s_left[q][i] = (l)
#define REFINE_FLAG(i) s_flag[q][i]
#define REFINE_SET_FLAG(i, f) s_flag[q][i] = (f)
const uint kRefineStack = kRefineMaxTape / 2u + 1u;
#include "refine_common.glsl"

void main() {
    counts_begin();
    q = gl_LocalInvocationID.x / kSquad;
    uint lane = gl_LocalInvocationID.x % kSquad;
    uint squad = gl_WorkGroupID.x * kSquads + q;
    uint squads = pc.threads / kSquad;

    vec3 half_cell = pc.csize.xyz * 0.5;
    float radius = SDFPRUNE_DEVICE_ROUNDING(length(half_cell));
    bool interval = (pc.flags & kStepIntervalBounds) != 0u;
    bool far_field = (pc.flags & kStepFarField) != 0u;
    uint subs = pc.refine;
    uint nsub = subs * subs * subs;
    uint nbatch = (nsub + kSquad - 1u) / kSquad;
    vec3 sub_half = half_cell / float(subs);
    float sub_R = SDFPRUNE_DEVICE_ROUNDING(length(sub_half));

    // The host records the dispatches for every finest cell; the jobs are the cells the lanes
    // listed (kStepLongList), or without a lane pass every listed near cell (refine_job; the same
    // count in every lane: an earlier step wrote it). Every lane of a workgroup sees the same trip
    // count (barriers inside).
    bool listed = (pc.flags & kStepLongList) != 0u;
    uint jobs = min(pc.jobs, listed ? long_jobs : refine_cells + copy_cells);
    uint walked = 0u;  // tape entries this lane walked (note_walk)
    for (uint first = pc.first_job; first < jobs; first += squads) {
        uint job = first + squad;
        bool has_job = squad < squads && job < jobs;
        uint cell = 0u, parent = 0u, len = 0u;
        Cell c0 = Cell(kFarField, 0u, 0.0, 0.0);
        bool evaluate = false, copy = false;
        if (has_job) {
            uint entry = listed ? scratch[pc.list_start + job] : refine_job(job);
            cell = entry & kCellBits;
            c0 = cells[cell];
            if (c0.tape == kFarField) {
                // Only near cells are listed; were one not, it is copied as it is.
                if (lane == 0u) octants[cell] = c0;
            } else {
                parent = c0.tape;
                len = tape_read(parent, 0u);
                copy = (entry & kCopyOnly) != 0u || len > kRefineMaxTape;  // (the latter listed so)
                evaluate = !copy;
            }
        }

        barrier();  // the squads' last reads of the previous job's shared words are done
        if (evaluate)
            walked += (len + kSquad - 1u - lane) / kSquad + nbatch * len;  // staged, walks
        if (evaluate)
            for (uint k = lane; k < len; k += kSquad) {
                s_word[q][k] = tape_read(parent, 2u + k);
                s_seen[q][k] = 0u;
                s_flag[q][k] = 0u;
            }
        memoryBarrierShared();
        barrier();

        if (evaluate) {
            // Stage 1 over each sub-box, then stage 2: the far-field test of is_near_field on
            // the sub-box's root range against the whole cell's clearance.
            precise vec3 centre = refine_cell_centre(cell);
            float L = nodes[tape_node(s_word[q][len - 1u])].lipschitz;
            float clearance = far_field_clearance(pc.csize.w, L, radius);
            uint far_flags = far_field ? 3u : 0u;
            float lowest = kInfinity, highest = -kInfinity;
            for (uint batch = 0u; batch < nbatch; ++batch) {
                // Lanes past the last sub-box repeat it.
                uint sb = min(batch * kSquad + lane, nsub - 1u);
                uvec3 sc = uvec3(sb % subs, (sb / subs) % subs, sb / (subs * subs));
                precise vec3 p = centre - half_cell + vec3(2u * sc + 1u) * sub_half;
                vec3 ps[1] = vec3[1](p);
                vec2 ranges[1];
                refine_sub_boxes(len, ps, sub_half, sub_R, interval, L, lane == 0u && batch == 0u,
                                 ranges);
                vec2 range = ranges[0];
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
            walked += k1 - k0;
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
                walked += 2u * (len - refine_write(cell, len, c0));  // the sweep and the write
            }
        }
    }
    note_walk(walked);
    counts_end();
}
