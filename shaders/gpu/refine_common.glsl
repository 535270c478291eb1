// refine_common.glsl — refinement's work on one cell (src/prune/prune_cell.cpp: refine_cell,
// then compact_tape), shared by prune_refine_lanes.comp (a lane per cell, its arrays private)
// and prune_refine.comp (a squad of lanes per cell, its arrays in shared memory). The includer
// says where a cell's arrays are, by defining before the include:
//   REFINE_WORD(i)        the tape's word i
//   REFINE_SEEN(i)        entry i's decisions over the sub-boxes so far (bit d: some decided d)
//   REFINE_SEE(i, bits)   adds decisions to REFINE_SEEN(i)
//   REFINE_LEFT(i)        entry i's left operand (an entry index)
//   REFINE_SET_LEFT(i, l) sets it
//   REFINE_FLAG(i)        the sweep's flags: bits 0-1 alive (0 dead, 1 kept, 2 skipped), bit 2
//                         negate; cleared before the sweep
//   REFINE_SET_FLAG(i, f) sets them
//   kRefineStack          the deepest evaluation stack of a tape it walks
// and may define REFINE_IS_PRIMITIVE(i), whether entry i is a primitive, known before the walks
// (else each use reads the entry's node): the walks then read a primitive's parameters beside
// its node, not after it (node order, scene.glsl), and the sweep and the write read no node.
// Include after prune_common.glsl.
#ifndef REFINE_IS_PRIMITIVE
#define REFINE_IS_PRIMITIVE(i) is_primitive(tape_node(REFINE_WORD(i)))
#endif

// REFINE_BATCH (default 1): how many sub-boxes one walk takes at once. The includer may set it
// before the include; the sub-boxes' order changes nothing (their decisions are or-ed, their
// ranges min- and max-ed).
#ifndef REFINE_BATCH
#define REFINE_BATCH 1
#endif

// A walk over the cell's tape of `len` words for REFINE_BATCH sub-boxes at once (centres p,
// evaluate_boxes in OperatorMode::kRefine): each entry's word, node and primitive read once for
// all of them, each operator's decisions added to REFINE_SEEN, its left operand recorded where
// `record`. Gives each sub-box's root range widened as the far-field test reads it
// (far_field_range; L: the root's Lipschitz bound).
void refine_sub_boxes(uint len, vec3 p[REFINE_BATCH], vec3 sub_half, float sub_R, bool interval,
                      float L, bool record, out vec2 range[REFINE_BATCH]) {
    // The stack's top slot (top − 1) is held in registers (tx, its entry t_entry), the slots
    // below it in the array: an operator's right operand is the top, and only a push spills it.
    vec3 st[kRefineStack * REFINE_BATCH];  // values and ranges: slot s, box j at s · B + j
    uint st_entry[kRefineStack];           // the entry in slot s (the same for every box)
    vec3 tx[REFINE_BATCH];
    uint t_entry = 0u;
    uint top = 0u;
    for (uint i = 0u; i < len; ++i) {
        uint w = REFINE_WORD(i);
        uint n = tape_node(w);
        Node nd = nodes[n];
        bool negated = tape_negated(w);
        if (REFINE_IS_PRIMITIVE(i)) {
            PrimitiveParams prm = params[n];
            vec4 b0 = extras[n].bound0;
            vec2 b1 = extras[n].bound1.xy;
            if (top > 0u) {
                for (uint j = 0u; j < REFINE_BATCH; ++j) st[(top - 1u) * REFINE_BATCH + j] = tx[j];
                st_entry[top - 1u] = t_entry;
            }
            for (uint j = 0u; j < REFINE_BATCH; ++j) {
                vec3 x = primitive_range_of(nd, prm, b0, b1, p[j], sub_half, sub_R, interval);
                tx[j] = negated ? negate_range(x) : x;
            }
            ++top;
        } else {
            --top;  // the left operand in slot top − 1, the right one the top
            uint seen = 0u;
            for (uint j = 0u; j < REFINE_BATCH; ++j) {
                uint decision;
                vec3 x = combine_operator(nd, sub_R, interval, true,
                                          st[(top - 1u) * REFINE_BATCH + j], tx[j], decision);
                seen |= 1u << decision;
                tx[j] = negated ? negate_range(x) : x;
            }
            REFINE_SEE(i, seen);
            if (record) REFINE_SET_LEFT(i, st_entry[top - 1u]);
        }
        t_entry = i;
    }
    for (uint j = 0u; j < REFINE_BATCH; ++j)
        range[j] = far_field_range(tx[j].x, tx[j].y, tx[j].z, L, sub_R);
}

// Stage 3 of a near cell (compact_tape): the top-down sweep from the root, an operator decided
// alike in every sub-box replaced by its winner; then the kept entries written to the level's
// pool, and the refined cell `cell` (c0 as it was, with its new tape) stored. Gives the entry
// the write started at: the sweep ends once it has reached every entry it kept (each has one
// parent), the entries below being dead, and the write starts at the last one it kept.
uint refine_write(uint cell, uint len, Cell c0) {
    REFINE_SET_FLAG(len - 1u, 1u | (tape_negated(REFINE_WORD(len - 1u)) ? 4u : 0u));
    uint out_len = 0u, prims = 0u;
    uint pending = 1u;  // entries kept and not yet reached: the root
    uint first_kept = 0u;
    for (uint i = len; i > 0u; --i) {
        uint e = i - 1u;
        uint fl = REFINE_FLAG(e);
        if ((fl & 3u) != 1u) continue;
        if (REFINE_IS_PRIMITIVE(e)) {
            ++out_len;
            ++prims;
            if (--pending == 0u && (pc.flags & kStepWholeSweeps) == 0u) {
                first_kept = e;
                break;
            }
            continue;
        }
        uint l = REFINE_LEFT(e), r = e - 1u;
        uint seen = REFINE_SEEN(e);
        uint d = bitCount(seen) == 1 ? uint(findLSB(seen)) : kKeepBoth;
        if (d == kKeepBoth) {
            ++out_len;
            ++pending;
            REFINE_SET_FLAG(l, 1u | (tape_negated(REFINE_WORD(l)) ? 4u : 0u));
            REFINE_SET_FLAG(r, 1u | (tape_negated(REFINE_WORD(r)) ? 4u : 0u));
            continue;
        }
        uint wn = d == kLeftWins ? l : r;
        uint neg = ((fl >> 2) & 1u) ^ (tape_negated(REFINE_WORD(wn)) ? 1u : 0u);
        REFINE_SET_FLAG(e, 2u | (fl & 4u));
        REFINE_SET_FLAG(wn, 1u | (neg << 2));
    }
    note_len(out_len);
    uint at = pool_allocate(false, out_len + 2u);
    if (at == kFarField) {
        store(cell, false, c0.value, 0.0, kFarField, 0u, c0);
        return first_kept;
    }
    tape_write(at, out_len);
    tape_write(at + 1u, prims);
    uint next = at + 2u, depth = 0u, depth_max = 0u;
    for (uint i = first_kept; i < len; ++i) {
        uint fl = REFINE_FLAG(i);
        if ((fl & 3u) != 1u) continue;
        uint node = tape_node(REFINE_WORD(i));
        tape_write(next++, tape_word(node, (fl & 4u) != 0u));
        depth = REFINE_IS_PRIMITIVE(i) ? depth + 1u : depth - 1u;
        depth_max = max(depth_max, depth);
    }
    note_depth(depth_max);
    store(cell, true, c0.value, 0.0, at, out_len, c0);
    return first_kept;
}

// A listed cell's centre (cell_centre: as the CPU computes it), from its block.
vec3 refine_cell_centre(uint cell) {
    uint f = pc.factor;
    uint per_block = f * f * f;
    uint bi = cell / per_block, local = cell % per_block;
    Block b = blocks[bi];
    uvec3 lc = uvec3(local % f, (local / f) % f, local / (f * f));
    return cell_centre(pc.origin.xyz, pc.csize.xyz, b.x + lc.x, b.y + lc.y, b.z + lc.z);
}

// A listed cell's tape (`len` words at `parent`) copied as it is into the level's pool by one
// lane, its deepest stack counted (a primitive pushes, an operator pops two and pushes one), and
// the cell `c0` stored with it (refinement's copies: list_near_cell).
void refine_copy(uint cell, uint parent, uint len, Cell c0) {
    uint at = pool_allocate(false, len + 2u);
    if (at == kFarField) {
        store(cell, false, c0.value, 0.0, kFarField, 0u, c0);
        return;
    }
    tape_write(at, len);
    tape_write(at + 1u, tape_read(parent, 1u));
    uint depth = 0u, depth_max = 0u;
    for (uint k = 0u; k < len; ++k) {
        uint w = tape_read(parent, 2u + k);
        tape_write(at + 2u + k, w);
        depth = is_primitive(tape_node(w)) ? depth + 1u : depth - 1u;
        depth_max = max(depth_max, depth);
    }
    note_len(len);
    note_depth(depth_max);
    store(cell, true, c0.value, 0.0, at, len, c0);
}
