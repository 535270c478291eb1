// refine_lanes.glsl — prune_refine_lanes.comp and prune_refine_lanes_long.comp: refinement
// (mode 3), its first pass: each finest near-field cell whose tape has at most pc.lane_tape
// words decided again over its refine³ sub-boxes by one lane alone (src/prune/prune_cell.cpp:
// refine_cell), in place: read from `cells`, written through binding 5, the same buffer.
// Most refined cells have tapes of a few words, and a lane per cell keeps as many cells in
// flight as the device has lanes: a cell's chain of dependent loads (the list, the cell, its
// block, its tape, the nodes) is waited for by 32 cells of a subgroup at once, where a squad
// (prune_refine.comp) waits for it alone. The lane's tape, left operands and stack are private
// arrays (which the device keeps in memory, cached); an entry's decisions and sweep flags are
// bits of registers, two a set (up to 64 entries). (Everything in registers and shared memory
// instead cost 18 registers and 13 KB of shared memory a workgroup, and ran 1.7× slower on an
// H100: BENCHMARKS.md, stop 30.) Cells with longer tapes are listed for the squads, in the long
// list (scratch[pc.list_start], counted in long_jobs). The host sets pc.lane_tape per slice
// (gpu_prune_plan.cpp: choose_lane_tape): 32, or 64 where the squads would otherwise take
// the longer tapes in several rounds. REFINE_LANES_LONG (prune_refine_lanes_long.comp): arrays
// of 64 entries, and sets of entry bits of two words (EntrySet), for that choice; without it
// (prune_refine_lanes.comp) 32 entries and one word, so that the lanes of the usual choice hold
// no more registers than they need.
// Job k takes refinement's job k (refine_job), for k below refine_cells + copy_cells (listed by
// the cells step): the cells to decide again, then those only copied, whose lanes copy alike;
// the far-field cells stay in binding 5 as they are.
// Built where the device has subgroup arithmetic and ballot: a subgroup's lanes take their
// tapes' room in the pool with one atomic (prune_common.glsl: PRUNE_SUBGROUPS). Elsewhere the
// squads refine every cell.
#define PRUNE_SUBGROUPS
#include "scene.glsl"

layout(local_size_x = 64) in;

#include "cells.glsl"
#include "prune_common.glsl"

// A set of a tape's entries, a bit each (entry i: bit i % 32 of word i / 32): mask_bit(m, i),
// mask_of(i) (the set of entry i alone), any_entry(m); its low and high words (the more list's).
#ifdef REFINE_LANES_LONG
const uint kLaneTape = kLaneTapeMax;  // the longest tape a lane refines
#define EntrySet uvec2
const uvec2 kNoEntries = uvec2(0u);
uint mask_bit(uvec2 m, uint i) { return (m[i >> 5] >> (i & 31u)) & 1u; }
uvec2 mask_of(uint i) { return i < 32u ? uvec2(1u << i, 0u) : uvec2(0u, 1u << (i - 32u)); }
bool any_entry(uvec2 m) { return any(notEqual(m, uvec2(0u))); }
uint low_word(uvec2 m) { return m.x; }
uint high_word(uvec2 m) { return m.y; }
uvec2 entry_set(uint low, uint high) { return uvec2(low, high); }
#else
const uint kLaneTape = kRefineLaneTape;
#define EntrySet uint
const uint kNoEntries = 0u;
uint mask_bit(uint m, uint i) { return (m >> i) & 1u; }
uint mask_of(uint i) { return 1u << i; }
bool any_entry(uint m) { return m != 0u; }
uint low_word(uint m) { return m; }
uint high_word(uint m) { return 0u; }
uint entry_set(uint low, uint high) { return low; }
#endif
EntrySet mask_set(EntrySet m, uint i, bool on) { return on ? m | mask_of(i) : m & ~mask_of(i); }

uint r_word[kLaneTape], r_left[kLaneTape];
// Entry i is in each if it was decided 0, 1, 2 in some sub-box; is kept, skipped, negated; is a
// primitive (set as the tape is read, before the walks).
EntrySet r_seen0, r_seen1, r_seen2, r_kept, r_skipped, r_negated, r_primitive;

uint refine_seen(uint i) {
    return mask_bit(r_seen0, i) | (mask_bit(r_seen1, i) << 1) | (mask_bit(r_seen2, i) << 2);
}
void refine_see(uint i, uint bits) {
    EntrySet b = mask_of(i);
    if ((bits & 1u) != 0u) r_seen0 |= b;
    if ((bits & 2u) != 0u) r_seen1 |= b;
    if ((bits & 4u) != 0u) r_seen2 |= b;
}
uint refine_flag(uint i) {
    return mask_bit(r_kept, i) | (mask_bit(r_skipped, i) << 1) | (mask_bit(r_negated, i) << 2);
}
void refine_set_flag(uint i, uint f) {
    r_kept = mask_set(r_kept, i, (f & 3u) == 1u);
    r_skipped = mask_set(r_skipped, i, (f & 3u) == 2u);
    r_negated = mask_set(r_negated, i, (f & 4u) != 0u);
}
#define REFINE_WORD(i) r_word[i]
#define REFINE_SEEN(i) refine_seen(i)
#define REFINE_SEE(i, bits) refine_see(i, bits)
#define REFINE_LEFT(i) r_left[i]
#define REFINE_SET_LEFT(i, l) r_left[i] = (l)
#define REFINE_FLAG(i) refine_flag(i)
#define REFINE_SET_FLAG(i, f) refine_set_flag(i, f)
#define REFINE_IS_PRIMITIVE(i) (mask_bit(r_primitive, i) != 0u)
const uint kRefineStack = kLaneTape / 2u + 1u;
// Sub-boxes a lane walks its tape for at once: a row of the default 3³, so that an entry's
// node and primitive are read once for three boxes. On an H200 (BENCHMARKS.md, stop 35) the
// lane pass took 10–20 % less time so (96 registers where one box a walk took 64); nine at once
// (72 registers, a larger private stack) was as fast on most scenes and 44 % slower on fluid.
#define REFINE_BATCH 3
#include "refine_common.glsl"

// Whether some operator is still open: decided alike (left, or right) in every sub-box so far,
// never kept whole, so that other sub-boxes may yet change its decision.
bool any_open_operator() { return any_entry((r_seen1 ^ r_seen2) & ~r_seen0); }

// The cell's sub-boxes in refine_cell's visiting order (prune_cell.cpp: sub_box_order), split
// in two: the first kFirstBoxes, the 8 corners and the middle, then the others. On the CPU's
// reference scenes two cells in three are decided by the first ones alone (no operator left that
// every sub-box so far decides alike, and no far-field test still open): the others cannot
// change their result. The first pass walks the first boxes for every cell and finishes those;
// it lists the others, with what it found, for a second pass over the other sub-boxes. A pass's
// lanes do the same walks, so a subgroup does not wait for its one cell that needs them all.
// With kStepRefineOnePass the first pass walks every sub-box and lists nothing (one pass, as
// before; SDFPRUNE_VULKAN_REFINE_SECOND_PASS=0, for comparisons).
// Sub-box k (< kFirstBoxes) of the first ones: corner k (bit 0: x, 1: y, 2: z at the far end),
// then the middle. Sub-box b of all, x fastest, is one of them where is_first_box(b).
uvec3 first_box(uint k, uint subs) {
    uint last = subs - 1u, mid = subs / 2u;
    if (k >= 8u) return uvec3(mid);
    return uvec3((k & 1u) != 0u ? last : 0u, (k & 2u) != 0u ? last : 0u,
                 (k & 4u) != 0u ? last : 0u);
}
uvec3 box_coord(uint b, uint subs) { return uvec3(b % subs, (b / subs) % subs, b / (subs * subs)); }
bool is_first_box(uvec3 c, uint subs) {
    uint last = subs - 1u, mid = subs / 2u;
    bvec3 end = bvec3(c.x == 0u || c.x == last, c.y == 0u || c.y == last,
                      c.z == 0u || c.z == last);
    return all(end) || all(equal(c, uvec3(mid)));
}
// Boxes of the first pass: the first ones there are (all of them where refine <= 2).
uint first_count(uint subs) {
    uint last = subs - 1u, mid = subs / 2u;
    bool mid_is_corner = (mid == 0u || mid == last);
    return min(subs * subs * subs, mid_is_corner ? 8u : kFirstBoxes);
}

// A cell's refinement state between the passes, in the more list: the cell, its far-field flags
// and range, its entries' decisions (seen0, seen1, seen2: their low words, then where the lanes
// take tapes of more than 32 words their high words), kMoreWords words a cell, or 3 fewer
// (prune_constants.h).
uint more_words() { return refine_more_words(pc.lane_tape); }

// The first place of walk class c in a list of the cells to decide again sorted by class, the
// longest first (the order list, the more list): the cells of the longer classes.
uint class_start(uint c) {
    uint start = 0u;
    for (uint d = kWalkClasses - 1u; d > c; --d) start += walk_cells[d];
    return start;
}

// The order pass (kStepRefineOrderPass), before the first pass: the list's cells to decide again
// (refine_cells of them, each with its walk class) sorted by class into the order list
// (scratch[pc.order_start]), the longest walks first, so that the first pass's neighbouring
// jobs, which a subgroup's lanes take together, walk tapes of about one length: a subgroup
// walks as long as its longest lane's tape, and the lengths of refined tapes spread widely (on
// molecule at 256³ from 1 to 31 words, 8 on average). A counting sort: each class's count was
// summed as the cells were listed (walk_cells); a workgroup takes 64 entries at a time, counts
// their classes in shared memory, takes room for each class with one atomic (walk_placed),
// and writes every entry to its class's room. Within a class the order is the atomics': the
// cells and their results do not depend on it.
shared uint s_class_count[kWalkClasses], s_class_at[kWalkClasses];
void order_walks() {
    uint n = min(pc.jobs, refine_cells);
    uint lane = gl_LocalInvocationID.x;
    for (uint first = pc.first_job + gl_WorkGroupID.x * 64u; first < n;
         first += gl_NumWorkGroups.x * 64u) {
        if (lane < kWalkClasses) s_class_count[lane] = 0u;
        memoryBarrierShared();
        barrier();
        bool has = first + lane < n;
        uint entry = has ? refine_list[first + lane] : 0u;
        uint c = entry >> 28;  // (kWalkClasses: four bits)
        uint rank = has ? atomicAdd(s_class_count[c], 1u) : 0u;
        memoryBarrierShared();
        barrier();
        if (lane < kWalkClasses) {
            uint count = s_class_count[lane];
            s_class_at[lane] =
                count == 0u ? 0u : class_start(lane) + atomicAdd(walk_placed[lane], count);
        }
        memoryBarrierShared();
        barrier();
        if (has) scratch[pc.order_start + s_class_at[c] + rank] = entry;
        barrier();  // the counts read before the next entries reset them
    }
}

// The more list is sorted by walk class as the order list is, the longest tapes first: class c
// takes the places from class_start(c) on (room for all its cells to decide, more than it
// lists), so that the second pass's subgroups, which take neighbouring jobs, walk tapes of
// about one length, as the first pass's do. A subgroup's listing lanes take their places with
// an atomic per class among them (more_place). With kStepMoreAsListed, in the order they were
// listed instead (SDFPRUNE_VULKAN_REFINE_SORTED_MORE=0: as before stop 48, for comparisons),
// where a subgroup's cells come from several of the first pass's subgroups.
// The place of a cell of walk class `c` in the more list (all the subgroup's active lanes call
// it; each class among them adds its count to more_class once).
uint more_place(uint c) {
    for (;;) {
        uint first = subgroupBroadcastFirst(c);
        if (c == first) {
            uint placed;
            SUBGROUP_APPEND(placed, more_class[first], true);
            return class_start(first) + placed;
        }
    }
}
// The second pass's job k (below more_jobs): its place, its class's cells after the longer
// classes' listed ones.
uint more_job(uint k) {
    for (uint d = kWalkClasses; d > 0u; --d) {
        uint n = more_class[d - 1u];
        if (k < n) return class_start(d - 1u) + k;
        k -= n;
    }
    return 0u;  // (k is below more_jobs, the classes' sum)
}

void main() {
    if ((pc.flags & kStepRefineOrderPass) != 0u) {
        order_walks();
        return;
    }
    counts_begin();
    vec3 half_cell = pc.csize.xyz * 0.5;
    float radius = SDFPRUNE_DEVICE_ROUNDING(length(half_cell));
    bool interval = (pc.flags & kStepIntervalBounds) != 0u;
    bool far_field = (pc.flags & kStepFarField) != 0u;
    bool second = (pc.flags & kStepRefineSecondPass) != 0u;
    uint subs = pc.refine;
    uint nsub = subs * subs * subs;
    uint nfirst = first_count(subs);
    // The pass's sub-boxes in visiting order: [k0, k1).
    uint k0 = second ? nfirst : 0u;
    uint k1 = second || (pc.flags & kStepRefineOnePass) != 0u ? nsub : nfirst;
    vec3 sub_half = half_cell / float(subs);
    float sub_R = SDFPRUNE_DEVICE_ROUNDING(length(sub_half));
    uint lane_tape = min(pc.lane_tape, kLaneTape);

    // The host records the dispatches for every finest cell; the jobs are the listed ones only
    // (the second pass's: the more list's).
    uint jobs = min(pc.jobs, second ? more_jobs : refine_cells + copy_cells);
    uint walked = 0u;  // tape entries this lane walked (note_walk)
    for (uint j = pc.first_job + gl_GlobalInvocationID.x; j < jobs; j += pc.threads) {
        // In order (kStepRefineOrdered), the jobs dealt in a snake: on an H100's lanes molecule's
        // critical path goes from 38 to 31 words (tools/prune_order_model.cpp).
        bool sorted_more = (pc.flags & kStepMoreAsListed) == 0u;
        bool in_order = (!second || sorted_more) && (pc.flags & kStepRefineOrdered) != 0u;
        uint job = in_order ? snake_deal(j, pc.first_job, pc.threads, jobs) : j;
        uint cell;
        bool copy = false;
        uint far_flags = far_field ? 3u : 0u;
        float lowest = kInfinity, highest = -kInfinity;
        r_seen0 = r_seen1 = r_seen2 = r_kept = r_skipped = r_negated = r_primitive = kNoEntries;
        if (second) {
            uint at = pc.more_start + (sorted_more ? more_job(job) : job) * more_words();
            cell = scratch[at];
            far_flags = scratch[at + 1u];
            lowest = uintBitsToFloat(scratch[at + 2u]);
            highest = uintBitsToFloat(scratch[at + 3u]);
            uvec3 high = more_words() == kMoreWords
                             ? uvec3(scratch[at + 7u], scratch[at + 8u], scratch[at + 9u])
                             : uvec3(0u);
            r_seen0 = entry_set(scratch[at + 4u], high.x);
            r_seen1 = entry_set(scratch[at + 5u], high.y);
            r_seen2 = entry_set(scratch[at + 6u], high.z);
        } else {
            uint entry = refine_job(job);
            copy = (entry & kCopyOnly) != 0u;
            cell = entry & kCellBits;
        }
        Cell c0 = cells[cell];
        if (c0.tape == kFarField) {
            octants[cell] = c0;  // only near cells are listed; were one not, it is copied
            continue;
        }
        uint parent = c0.tape;
        uint len = tape_read(parent, 0u);
        if (!second && len > lane_tape) {
            scratch[pc.list_start + atomicAdd(long_jobs, 1u)] = cell | (copy ? kCopyOnly : 0u);
            continue;
        }
        if (copy) {
            refine_copy(cell, parent, len, c0);
            walked += len;
            continue;
        }
        for (uint k = 0u; k < len; ++k) {
            uint w = tape_read(parent, 2u + k);
            r_word[k] = w;
            if (is_primitive(tape_node(w))) r_primitive |= mask_of(k);
        }
        // Stage 1 over each sub-box, then stage 2: the far-field test of is_near_field on the
        // sub-box's root range against the whole cell's clearance. The sub-boxes in visiting
        // order: the first ones, then the others b by b (x fastest), the first ones skipped.
        precise vec3 centre = refine_cell_centre(cell);
        float L = nodes[tape_node(r_word[len - 1u])].lipschitz;
        float clearance = far_field_clearance(pc.csize.w, L, radius);
        uint b = 0u;  // the next sub-box of all, past the first ones
        uvec3 sc = uvec3(0u);
        walked += len;  // staged
        for (uint k = k0; k < k1; k += REFINE_BATCH) {
            // A batch past the last sub-box repeats it.
            vec3 p[REFINE_BATCH];
            for (uint j = 0u; j < REFINE_BATCH; ++j) {
                if (k + j < min(nfirst, k1)) {
                    sc = first_box(k + j, subs);
                } else if (k + j < k1) {
                    while (is_first_box(box_coord(b, subs), subs)) ++b;
                    sc = box_coord(b++, subs);
                }
                precise vec3 pj = centre - half_cell + vec3(2u * sc + 1u) * sub_half;
                p[j] = pj;
            }
            vec2 range[REFINE_BATCH];
            refine_sub_boxes(len, p, sub_half, sub_R, interval, L, k == k0, range);
            walked += len;
            for (uint j = 0u; j < REFINE_BATCH; ++j) {
                if (!clears_above(range[j].x, clearance)) far_flags &= ~1u;
                if (!clears_below(range[j].y, clearance)) far_flags &= ~2u;
                lowest = min(lowest, range[j].x);
                highest = max(highest, range[j].y);
            }
            // A cell with no operator still open and its far-field test closed is done: the
            // other sub-boxes change nothing (as refine_cells stops).
            if (far_flags == 0u && !any_open_operator()) break;
        }
        // After the first boxes: an operator that every one decided alike (left, or right,
        // never both kept) may still be decided for the cell, and a far-field test still open
        // needs every sub-box. Otherwise the other sub-boxes change nothing.
        if (k1 < nsub && (any_open_operator() || far_flags != 0u)) {
            // The lanes that list a cell together count it with one atomic.
            uint listed;
            SUBGROUP_APPEND(listed, more_jobs, true);
            if (sorted_more) listed = more_place(refine_walk_class(len));
            uint at = pc.more_start + listed * more_words();
            scratch[at] = cell;
            scratch[at + 1u] = far_flags;
            scratch[at + 2u] = floatBitsToUint(lowest);
            scratch[at + 3u] = floatBitsToUint(highest);
            scratch[at + 4u] = low_word(r_seen0);
            scratch[at + 5u] = low_word(r_seen1);
            scratch[at + 6u] = low_word(r_seen2);
            if (more_words() == kMoreWords) {
                scratch[at + 7u] = high_word(r_seen0);
                scratch[at + 8u] = high_word(r_seen1);
                scratch[at + 9u] = high_word(r_seen2);
            }
            continue;
        }
        if (far_flags != 0u)
            store(cell, false, c0.value, (far_flags & 1u) != 0u ? lowest : highest, kFarField, 0u,
                  c0);
        else
            walked += 2u * (len - refine_write(cell, len, c0));  // the sweep and the write
    }
    note_walk(walked);
    counts_end();
}
