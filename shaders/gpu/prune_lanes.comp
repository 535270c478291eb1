#version 450
// prune_lanes.comp — one pruning step of a level (modes 0–2, as prune_team.glsl), its first
// pass: a lane per box (cell or octant), walking the box's parent tape alone where that tape
// has at most pc.lane_tape words. The lane's arrays (the tape, the left operands, the
// decisions and the sweep's flags) are private, its evaluation stack too: no scratch in device
// memory, no barrier, and as many boxes in flight as the device has lanes. Most parent tapes
// below the top levels are a few words long. The team jobs (kTeam boxes of one parent tape,
// job_box) whose tapes are longer are listed for the teams (prune.comp, flag 8): from
// scratch[pc.list_start], counted in long_jobs. Mirrors src/prune/prune_cell.cpp stage for
// stage (evaluate_cell, is_near_field, compact_tape), as the team kernel does.
#include "scene.glsl"

layout(local_size_x = 64) in;

#include "cells.glsl"
#include "prune_common.glsl"

const uint kLaneTape = 32u;  // the longest tape a lane walks (device_layout.hpp)
const uint kLaneStack = kLaneTape / 2u + 1u;

// Per entry: the tape's word, its left operand, and its decision (bits 0-1) with the sweep's
// flags (bits 2-3 alive: 0 dead, 1 kept, 2 skipped; bit 4 negate).
uint l_word[kLaneTape], l_left[kLaneTape], l_flag[kLaneTape];

void main() {
    counts_begin();
    bool interval = (pc.flags & 2u) != 0u;
    bool transient = pc.mode == 1u || (pc.flags & 4u) != 0u;
    bool far_field = (pc.flags & 1u) != 0u;
    uint lane_tape = min(pc.lane_tape, kLaneTape);
    const Cell kNoCell = Cell(kFarField, 0u, 0.0, 0.0);  // store()'s, for refinement only

    // Box b is lane b % kTeam of team job b / kTeam.
    uint boxes = pc.jobs * kTeam;
    for (uint b = pc.first_job * kTeam + gl_GlobalInvocationID.x; b < boxes; b += pc.threads) {
        uint job = b / kTeam, lane = b % kTeam;
        vec3 box_centre, half_size;
        float R;
        uint parent, dest;
        bool valid;
        if (!job_box(job, lane, box_centre, half_size, R, parent, dest, valid)) continue;
        precise vec3 centre = box_centre;
        uint len = tape_read(parent, 0u);
        if (len > lane_tape) {
            // The team's, all its lanes' boxes.
            if (lane == 0u) scratch[pc.list_start + atomicAdd(long_jobs, 1u)] = job;
            continue;
        }

        // Stage 1: values and ranges at the box centre, decisions (evaluate_cell).
        vec3 st[kLaneStack];
        uint st_entry[kLaneStack];
        uint top = 0u, pdepth = 0u;
        for (uint i = 0u; i < len; ++i) {
            uint w = tape_read(parent, 2u + i);
            l_word[i] = w;
            Node nd = nodes[tape_node(w)];
            vec3 x;
            uint decision = kKeepBoth;
            if (nd.kind < kPrimitiveKindCount) {
                x = primitive_range(nd, centre, half_size, R, interval);
            } else {
                top -= 2u;
                l_left[i] = st_entry[top];
                x = combine_operator(nd, R, interval, false, st[top], st[top + 1u], decision);
            }
            if (tape_negated(w)) x = negate_range(x);
            l_flag[i] = decision;
            st[top] = x;
            st_entry[top] = i;
            ++top;
            pdepth = max(pdepth, top);
        }

        // Stage 2: the far-field test on the root range against the box's margin
        // (is_near_field).
        float value = st[0].x;
        float L = nodes[tape_node(l_word[len - 1u])].lipschitz;
        vec2 range = far_field_range(value, st[0].y, st[0].z, L, R);
        float clearance = far_field_clearance(pc.csize.w, L, R);
        bool above = far_field && clears_above(range.x, clearance);
        bool below = far_field && clears_below(range.y, clearance);
        if (above || below) {
            if (valid)
                store(dest, false, value, above ? range.x : range.y, kFarField, 0u, kNoCell);
            continue;
        }
        if (!valid) continue;  // a lane past the boxes

        // Stage 3: the top-down pass (compact_tape). An entry's flags are final when the
        // reverse sweep reaches it (parents come later), so the sweep also counts the kept
        // entries.
        l_flag[len - 1u] |= (1u << 2) | (tape_negated(l_word[len - 1u]) ? 16u : 0u);
        uint out_len = 0u, prims = 0u;
        for (uint i = len; i > 0u; --i) {
            uint e = i - 1u;
            uint fl = l_flag[e];
            if (((fl >> 2) & 3u) != 1u) continue;
            uint w = l_word[e];
            if (is_primitive(tape_node(w))) {
                ++out_len;
                ++prims;
                continue;
            }
            uint l = l_left[e], r = e - 1u;
            uint d = fl & 3u;
            if (d == kKeepBoth) {
                ++out_len;
                l_flag[l] |= (1u << 2) | (tape_negated(l_word[l]) ? 16u : 0u);
                l_flag[r] |= (1u << 2) | (tape_negated(l_word[r]) ? 16u : 0u);
                continue;
            }
            uint wn = d == kLeftWins ? l : r;
            uint neg = ((fl >> 4) & 1u) ^ (tape_negated(l_word[wn]) ? 1u : 0u);
            l_flag[e] = (fl & 3u) | (2u << 2) | (fl & 16u);
            l_flag[wn] |= (1u << 2) | (neg << 4);
        }
        note_len(out_len);
        if (out_len == len && transient) {
            // Nothing pruned, and a transient tape: share the parent's.
            note_depth(pdepth);
            store(dest, true, value, 0.0, parent, out_len, kNoCell);
            continue;
        }
        uint at = pool_allocate(transient, out_len + 2u);
        if (at == kFarField) {
            store(dest, false, value, 0.0, kFarField, 0u, kNoCell);
            continue;
        }
        tape_write(at, out_len);
        tape_write(at + 1u, prims);
        uint next = at + 2u, depth = 0u, depth_max = 0u;
        for (uint i = 0u; i < len; ++i) {
            uint fl = l_flag[i];
            if (((fl >> 2) & 3u) != 1u) continue;
            uint node = tape_node(l_word[i]);
            tape_write(next++, tape_word(node, ((fl >> 4) & 1u) != 0u));
            // Stack depth of the new tape: a primitive pushes, an operator pops two, pushes one.
            depth = is_primitive(node) ? depth + 1u : depth - 1u;
            depth_max = max(depth_max, depth);
        }
        note_depth(depth_max);
        store(dest, true, value, 0.0, at, out_len, kNoCell);
    }
    counts_end();
}
