// prune_level.cpp — the level step of the hierarchy (DESIGN.md §3–5): each child cell of a
// near-field parent evaluated at its centre (stage 1), culled to a constant if far from the
// surface (§4, stage 2) or given the tape compacted from its parent's (stage 3), optionally
// through the parent's octants first. The per-cell stages are in prune_cell.cpp.
#include "prune_level.hpp"

#include <algorithm>
#include <bit>
#include <cstdlib>
#include <stdexcept>
#include <vector>

namespace sdfprune {
namespace {

// FNV-1a over a tape's header and words: finds identical tapes within a call.
uint64_t tape_hash(std::span<const uint32_t> tape) {
    uint64_t h = 0xcbf29ce484222325ull;
    for (const uint32_t w : tape) h = (h ^ w) * 0x100000001b3ull;
    return h;
}

// The tapes stored by one call, by hash: open addressing in one flat array (a chunk stores up
// to a thousand tapes; a node-based map would allocate once per tape). Like a map from hash to
// the first tape stored with it: a tape whose hash is taken by a different tape is stored, not
// found again.
class StoredTapes {
  public:
    // The offset of the tape stored with hash `h`, or inserts `offset` for it and returns it.
    uint32_t find_or_insert(uint64_t h, uint32_t offset) {
        if (2 * (size_ + 1) > slots_.size()) grow();
        const size_t mask = slots_.size() - 1;
        for (size_t i = size_t(h) & mask;; i = (i + 1) & mask) {
            Slot& slot = slots_[i];
            if (slot.offset == kEmpty) {
                slot = {h, offset};
                ++size_;
                return offset;
            }
            if (slot.hash == h) return slot.offset;
        }
    }

  private:
    static constexpr uint32_t kEmpty = 0xffffffffu;
    struct Slot {
        uint64_t hash = 0;
        uint32_t offset = kEmpty;
    };
    void grow() {
        std::vector<Slot> old(std::max<size_t>(2 * slots_.size(), 256));
        old.swap(slots_);
        size_ = 0;
        for (const Slot& s : old)
            if (s.offset != kEmpty) find_or_insert(s.hash, s.offset);
    }
    std::vector<Slot> slots_;
    size_t size_ = 0;
};

// One call's state: the cells of a range pruned into one LevelChunk.
// Takes from `open` (bit i: item i) its lowest item and every other whose tape (tape_of(i)) is
// equal to that one's; writes them to `taken` in order and returns how many.
template <class TapeOf>
uint32_t take_equal_tapes(uint32_t& open, const TapeOf& tape_of, uint32_t* taken) {
    const std::span<const uint32_t> lead = tape_of(uint32_t(std::countr_zero(open)));
    uint32_t m = 0;
    for (uint32_t rest = open; rest != 0; rest &= rest - 1) {
        const uint32_t i = uint32_t(std::countr_zero(rest));
        const std::span<const uint32_t> t = tape_of(i);
        if (m > 0 && !std::equal(t.begin(), t.end(), lead.begin(), lead.end())) continue;
        taken[m++] = i;
        open &= ~(1u << i);
    }
    return m;
}

class StepPruner {
    // A cell's refinement, done with its group (refine_siblings).
    struct Refined {
        RefineResult result;
        std::vector<uint32_t> decisions;  // with result.decided: per entry of its tape
    };

  public:
    StepPruner(const Scene& sc, const PruneOptions& opt, const LevelGeometry& geo, CellScratch& s,
               LevelChunk& out)
        : sc_(sc), opt_(opt), geo_(geo), s_(s), out_(out) {
        proto_.half = geo.cell_size * 0.5f;
        proto_.radius = math::length(proto_.half);
    }

    CellBox cell_box(uint32_t x, uint32_t y, uint32_t z) const {
        CellBox box = proto_;
        box.centre = math::cell_centre(geo_.origin, geo_.cell_size, x, y, z);
        return box;
    }

    // Stages 1-3 on one box (box `box`) from `parent`: its centre value, whether it is
    // far-field (then its constant), else its compacted tape in `tape` (cleared first); returns
    // the tape's primitives.
    uint32_t prune_box(std::span<const uint32_t> parent, const CellBox& box, float& value,
                       bool& far, float& constant, std::vector<uint32_t>& tape) {
        CellScratch& s = s_;
        value = evaluate_cell(sc_, parent, box, opt_.bounds, s);
        constant = 0;
        far = opt_.far_field && !is_near_field(sc_, parent, box, opt_.far_field_c, s, constant);
        tape.clear();
        return far ? 0 : compact_tape(sc_, parent, s, tape);
    }

    // Prunes `cell` (box `box`) from `parent`, leaving far-field cells without a tape.
    void prune_cell(PrunedCell& cell, std::span<const uint32_t> parent, const CellBox& box) {
        float value, constant;
        bool far;
        const uint32_t prims = prune_box(parent, box, value, far, constant, s_.cell_tapes[0]);
        store_cell(cell, box, parent.size(), value, far, constant, s_.cell_tapes[0], prims, true);
    }

    // Prunes `count` <= kSiblingLanes cells of this level from one `parent` in one pass over
    // it: the same results as prune_cell on each, in the same order. With `evaluated`, stage 1
    // was done already, with other cells of the same parent tape (prune_split_block).
    void prune_siblings(PrunedCell* const* cells, const CellBox* boxes, uint32_t count,
                        std::span<const uint32_t> parent,
                        const CellScratch::SiblingLanes* evaluated = nullptr) {
        CellScratch& s = s_;
        if (parent.size() > kSiblingMaxTape) {
            for (uint32_t c = 0; c < count; ++c) prune_cell(*cells[c], parent, boxes[c]);
            return;
        }
        if (evaluated) {
            s.sib_at = *evaluated;
            link_tape(sc_, parent, s);
        } else {
            vec3 centres[kSiblingLanes];
            for (uint32_t c = 0; c < count; ++c) centres[c] = boxes[c].centre;
            evaluate_siblings(sc_, parent, centres, count, proto_.half, proto_.radius, opt_.bounds,
                              s);
        }
        float constant[kSiblingLanes];
        bool far[kSiblingLanes];
        uint32_t prims[kSiblingLanes];
        uint32_t near = 0;
        for (uint32_t c = 0; c < count; ++c) {
            constant[c] = 0;
            far[c] = opt_.far_field && !sibling_is_near_field(sc_, parent, c, proto_.radius,
                                                              opt_.far_field_c, s, constant[c]);
            s.cell_tapes[c].clear();
            near |= far[c] ? 0u : 1u << c;
        }
        uint32_t decidable = ~0u;
        compact_siblings(sc_, parent, near, s, s.cell_tapes, prims,
                         geo_.finest && opt_.refine > 1 ? &decidable : nullptr);
        bool refined[kSiblingLanes] = {};
        if (geo_.finest && opt_.refine > 1)
            refine_siblings(parent, boxes, count, near, decidable, refined);
        for (uint32_t c = 0; c < count; ++c)
            store_cell(*cells[c], boxes[c], parent.size(), sibling_value(s, parent, c), far[c],
                       constant[c], s.cell_tapes[c], prims[c], (decidable >> c & 1) != 0,
                       refined[c] ? &refined_[c] : nullptr);
    }

    // Stage 1 for `count` <= kSiblingGroupLanes cells of this level centred at `centres` from
    // `tape`, in one pass over it, kept in the sibling arrays past those in use (s.sib_used
    // moves past them) for prune_siblings: their lanes, lane c the cell at centres[c].
    CellScratch::SiblingLanes evaluate_kept(std::span<const uint32_t> tape, const vec3* centres,
                                            uint32_t count) {
        CellScratch& s = s_;
        evaluate_siblings(sc_, tape, centres, count, proto_.half, proto_.radius, opt_.bounds, s);
        s.sib_used = s.sib_at.offset + uint32_t(tape.size()) * s.sib_at.stride;
        return s.sib_at;
    }

    // Prunes `count` <= kSiblingGroupLanes cells of one block from its tape `parent`: stage 1
    // for all of them in one pass over the tape where it is short (kSiblingGroupMaxTape words),
    // then the rest kSiblingLanes cells at a time (prune_siblings). The same results as
    // prune_cell on each, in the same order: each lane is computed alone.
    void prune_block_cells(PrunedCell* const* cells, const CellBox* boxes, uint32_t count,
                           std::span<const uint32_t> parent) {
        CellScratch& s = s_;
        const bool together = count > kSiblingLanes && parent.size() <= kSiblingGroupMaxTape;
        CellScratch::SiblingLanes evaluated;
        if (together) {
            vec3 centres[kSiblingGroupLanes];
            for (uint32_t c = 0; c < count; ++c) centres[c] = boxes[c].centre;
            s.sib_used = 0;
            evaluated = evaluate_kept(parent, centres, count);
        }
        for (uint32_t c0 = 0; c0 < count; c0 += kSiblingLanes) {
            CellScratch::SiblingLanes at = evaluated;
            at.first = c0;
            prune_siblings(cells + c0, boxes + c0, std::min(kSiblingLanes, count - c0), parent,
                           together ? &at : nullptr);
        }
        s.sib_used = 0;
    }

    // Refinement of the near cells (bits of `near`) that store_cell refines, by groups of cells
    // whose compacted tapes are equal (refine_cells: one pass over the tape per batch for the
    // group); each cell's result goes to refined_[c] (refined[c] set), for store_cell.
    void refine_siblings(std::span<const uint32_t> parent, const CellBox* boxes, uint32_t count,
                         uint32_t near, uint32_t decidable, bool* refined) {
        CellScratch& s = s_;
        uint32_t open = 0;  // cells to refine, not yet grouped
        for (uint32_t c = 0; c < count; ++c) {
            const std::vector<uint32_t>& tape = s.cell_tapes[c];
            if ((near >> c & 1) != 0 && !tape.empty() && tape.size() <= math::kRefineMaxTape)
                open |= 1u << c;
        }
        while (open != 0) {
            uint32_t group[kSiblingLanes];
            const uint32_t m = take_equal_tapes(
                open, [&](uint32_t c) -> std::span<const uint32_t> { return s.cell_tapes[c]; },
                group);
            const std::span<const uint32_t> tape = s.cell_tapes[group[0]];
            CellBox gboxes[kSiblingLanes];
            float values[kSiblingLanes];
            bool may_decide[kSiblingLanes];
            RefineResult results[kSiblingLanes];
            for (uint32_t j = 0; j < m; ++j) {
                gboxes[j] = boxes[group[j]];
                values[j] = sibling_value(s, parent, group[j]);
                may_decide[j] = (decidable >> group[j] & 1) != 0;
            }
            refine_cells(sc_, tape, gboxes, m, opt_.refine, opt_.bounds, opt_.far_field,
                         opt_.far_field_c, values, may_decide, s, results);
            for (uint32_t j = 0; j < m; ++j) {
                Refined& r = refined_[group[j]];
                r.result = results[j];
                if (results[j].decided)
                    r.decisions.assign(s.refine_decision.begin() + size_t(j) * tape.size(),
                                       s.refine_decision.begin() + size_t(j + 1) * tape.size());
                refined[group[j]] = true;
            }
        }
    }

    // Stores a cell pruned from a parent tape of `parent_size` words: its centre value, its
    // far-field test, and its compacted tape, which the finest level refines first.
    // `may_decide`: refine_cell's hint, whether some operator of the tape might be decided.
    void store_cell(PrunedCell& cell, const CellBox& box, size_t parent_size, float value, bool far,
                    float constant, std::span<const uint32_t> compacted, uint32_t prims,
                    bool may_decide, const Refined* refined = nullptr) {
        CellScratch& s = s_;
        LevelChunk& out = out_;
        cell.value = value;
        out.words_visited += parent_size;
        ++out.pruned;
        if (far) {
            cell.tape = PrunedCell::kFarField;
            cell.bound = constant;
            return;
        }
        const size_t at = out.words.size();
        out.words.push_back(0);
        out.words.push_back(0);
        if (geo_.finest && opt_.refine > 1 && compacted.size() <= math::kRefineMaxTape) {
            // Decided again over the cell's sub-boxes, from the tape just made (here, unless
            // refine_siblings did with the cell's group).
            RefineResult r;
            std::span<const uint32_t> decisions;
            if (refined) {
                r = refined->result;
                decisions = refined->decisions;
            } else {
                refine_cells(sc_, compacted, &box, 1, opt_.refine, opt_.bounds, opt_.far_field,
                             opt_.far_field_c, &value, &may_decide, s, &r);
                decisions = std::span<const uint32_t>(s.refine_decision).first(compacted.size());
            }
            if (!r.near) {
                out.words.resize(at);
                cell.tape = PrunedCell::kFarField;
                cell.bound = r.constant;
                return;
            }
            // Compacted again only where some operator was decided over every sub-box: with
            // none, compaction would give back the tape word for word (most cells).
            if (r.decided) {
                std::copy(decisions.begin(), decisions.end(), s.decision.begin());
                link_tape(sc_, compacted, s);
                prims = compact_tape(sc_, compacted, s, out.words);
            } else {
                out.words.insert(out.words.end(), compacted.begin(), compacted.end());
            }
        } else {
            out.words.insert(out.words.end(), compacted.begin(), compacted.end());
        }
        const uint32_t len = uint32_t(out.words.size() - at - 2);
        out.words[at] = len;
        out.words[at + 1] = prims;
        const std::span<const uint32_t> tape(out.words.data() + at, len + 2);
        const uint32_t same = stored_.find_or_insert(tape_hash(tape), uint32_t(at));
        if (same != at && out.words[same] == len &&
            std::equal(tape.begin(), tape.end(), out.words.begin() + same)) {
            out.words.resize(at);
            cell.tape = same;
        } else {
            cell.tape = uint32_t(at);
        }
        if (geo_.finest) {
            ++out.near;
            out.tape_sum += len;
            out.tape_max = std::max(out.tape_max, len);
            out.prim_sum += prims;
            out.prim_sq_sum += uint64_t(prims) * prims;
            out.prim_max = std::max(out.prim_max, prims);
        }
    }

    // Block `b`'s f³ cells in two steps: its 8 octants are pruned first (not stored), then each
    // cell from its octant's tape. Shorter parent tapes for the cells, same guarantees: a tape
    // valid in an octant is valid in every cell inside it. The octants are pruned together, and
    // so are the cells of an octant, kSiblingLanes at a time.
    void prune_split_block(const ParentBlock& b, std::span<PrunedCell> cells) {
        CellScratch& s = s_;
        const uint32_t f = geo_.factor, hf = f / 2;
        const std::span<const uint32_t> parent = b.tape();
        const float lipschitz = sc_.lipschitz[sc_.root()];
        const vec3 ohalf = proto_.half * float(hf);
        const float oradius = proto_.radius * float(hf);
        vec3 ocentre[8];
        for (uint32_t o = 0; o < 8; ++o) {
            const uint32_t ox = (o & 1) * hf, oy = ((o >> 1) & 1) * hf, oz = ((o >> 2) & 1) * hf;
            ocentre[o] = geo_.origin + vec3(float(b.origin.x + ox) + 0.5f * float(hf),
                                            float(b.origin.y + oy) + 0.5f * float(hf),
                                            float(b.origin.z + oz) + 0.5f * float(hf)) *
                                           geo_.cell_size;
        }
        out_.words_visited += 8 * parent.size();
        float ov[8], oconst[8];
        bool ofar[8];
        if (parent.size() > kSiblingMaxTape) {
            for (uint32_t o = 0; o < 8; ++o)
                prune_box(parent, {ocentre[o], ohalf, oradius}, ov[o], ofar[o], oconst[o],
                          s.octants[o]);
        } else {
            evaluate_siblings(sc_, parent, ocentre, 8, ohalf, oradius, opt_.bounds, s);
            uint32_t onear = 0, oprims[8];
            for (uint32_t o = 0; o < 8; ++o) {
                ov[o] = sibling_value(s, parent, o);
                oconst[o] = 0;
                ofar[o] = opt_.far_field && !sibling_is_near_field(sc_, parent, o, oradius,
                                                                   opt_.far_field_c, s, oconst[o]);
                s.octants[o].clear();
                onear |= ofar[o] ? 0u : 1u << o;
            }
            compact_siblings(sc_, parent, onear, s, s.octants, oprims);
        }
        const auto octant_tape = [&](uint32_t o) {
            return s.octants[o].size() < parent.size() ? std::span<const uint32_t>(s.octants[o])
                                                       : parent;
        };
        const auto octant_cell = [&](uint32_t o, uint32_t c) {
            const uint32_t ox = (o & 1) * hf, oy = ((o >> 1) & 1) * hf, oz = ((o >> 2) & 1) * hf;
            return cell_box(b.origin.x + ox + c % hf, b.origin.y + oy + c / hf % hf,
                            b.origin.z + oz + c / (hf * hf));
        };
        // Octants of 2×2×2 cells (factor 4) whose tapes are equal: their cells' stage 1 in one
        // pass over the tape, 8 lanes per octant, before the octants are finished one by one in
        // order. The same results: each lane is computed alone.
        CellScratch::SiblingLanes evaluated[8];
        bool grouped[8] = {};
        s.sib_used = 0;
        uint32_t open = 0;
        if (hf == 2)
            for (uint32_t o = 0; o < 8; ++o)
                if (!ofar[o] && octant_tape(o).size() <= kSiblingGroupMaxTape) open |= 1u << o;
        while (open != 0) {
            uint32_t members[8];
            const uint32_t m = take_equal_tapes(open, octant_tape, members);
            if (m < 2) continue;
            const std::span<const uint32_t> tape = octant_tape(members[0]);
            vec3 centres[kSiblingGroupLanes];
            for (uint32_t j = 0; j < m; ++j)
                for (uint32_t c = 0; c < kSiblingLanes; ++c)
                    centres[j * kSiblingLanes + c] = octant_cell(members[j], c).centre;
            const CellScratch::SiblingLanes lanes = evaluate_kept(tape, centres, m * kSiblingLanes);
            for (uint32_t j = 0; j < m; ++j) {
                evaluated[members[j]] = lanes;
                evaluated[members[j]].first = j * kSiblingLanes;
                grouped[members[j]] = true;
            }
        }
        for (uint32_t o = 0; o < 8; ++o) {
            const uint32_t ox = (o & 1) * hf, oy = ((o >> 1) & 1) * hf, oz = ((o >> 2) & 1) * hf;
            const std::span<const uint32_t> otape = octant_tape(o);
            const CellScratch::SiblingLanes* pre = grouped[o] ? &evaluated[o] : nullptr;
            PrunedCell* group[kSiblingLanes];
            CellBox boxes[kSiblingLanes];
            uint32_t count = 0;
            for (uint32_t lz = oz; lz < oz + hf; ++lz)
                for (uint32_t ly = oy; ly < oy + hf; ++ly)
                    for (uint32_t lx = ox; lx < ox + hf; ++lx) {
                        PrunedCell& cell = cells[(lz * f + ly) * f + lx];
                        const CellBox box =
                            cell_box(b.origin.x + lx, b.origin.y + ly, b.origin.z + lz);
                        if (!ofar[o]) {
                            group[count] = &cell;
                            boxes[count] = box;
                            if (++count == kSiblingLanes) {
                                prune_siblings(group, boxes, count, otape, pre);
                                count = 0;
                            }
                            continue;
                        }
                        // A far octant makes far cells: its constant holds in each; the
                        // centre value is a conservative stand-in (same sign, never larger in
                        // magnitude) moved from the octant centre.
                        const float reach = lipschitz * math::length(box.centre - ocentre[o]);
                        cell.tape = PrunedCell::kFarField;
                        cell.bound = oconst[o];
                        cell.value = ov[o] > 0 ? std::max(ov[o] - reach, oconst[o])
                                               : std::min(ov[o] + reach, oconst[o]);
                    }
            if (count > 0) prune_siblings(group, boxes, count, otape, pre);
        }
        s.sib_used = 0;
    }

  private:
    const Scene& sc_;
    const PruneOptions& opt_;
    const LevelGeometry& geo_;
    CellScratch& s_;
    LevelChunk& out_;
    CellBox proto_;
    // This call's tapes by hash: a tape equal to one already stored is not stored again.
    StoredTapes stored_;
    Refined refined_[kSiblingLanes];  // refine_siblings' results, per sibling cell
};

}  // namespace

LevelGeometry level_geometry(const Scene& sc, const PruneOptions& opt, uint32_t res,
                             uint32_t factor, bool finest, uint32_t chunk_cells) {
    LevelGeometry geo;
    geo.origin = sc.aabb.min;
    geo.cell_size = (sc.aabb.max - sc.aabb.min) / float(res);
    geo.factor = factor;
    geo.finest = finest;
    const uint64_t per_block = uint64_t(factor) * factor * factor;
    geo.split = splits_into_octants(sc, opt, res, factor) && chunk_cells % per_block == 0;
    return geo;
}

bool splits_into_octants(const Scene& sc, const PruneOptions& opt, uint32_t res, uint32_t factor) {
    if (!opt.hierarchy || factor < 4 || factor % 2 != 0) return false;
    static const uint64_t max_cell_words = [] {
        const char* env = std::getenv("SDFPRUNE_DIRECT_CELL_WORDS");
        return env && *env ? std::strtoull(env, nullptr, 10) : kDirectMaxCellWords;
    }();
    const uint64_t parents_per_axis = res / factor, cells = uint64_t(res) * res * res;
    return parents_per_axis * parents_per_axis * parents_per_axis > kDirectMaxParents ||
           cells * sc.full_tape.size() > max_cell_words;
}

void add_chunk_stats(const LevelChunk& o, PruneStats& st) {
    st.near_field_cells += o.near;
    st.tape_avg += double(o.tape_sum);
    st.tape_max = std::max(st.tape_max, o.tape_max);
    st.active_avg += double(o.prim_sum);
    st.active_std += double(o.prim_sq_sum);
    st.active_max = std::max(st.active_max, o.prim_max);
    st.cells_pruned += o.pruned;
    st.tape_words_visited += o.words_visited;
}

void prune_level_step(const Scene& sc, const PruneOptions& opt, const LevelGeometry& geo,
                      std::span<const ParentBlock> blocks, uint64_t begin, uint64_t end,
                      std::span<PrunedCell> cells, CellScratch& s, LevelChunk& out) {
    const uint32_t f = geo.factor;
    const uint64_t per_block = uint64_t(f) * f * f;
    if (end < begin || end > blocks.size() * per_block || cells.size() < end - begin)
        throw std::invalid_argument("prune_level_step: range outside the blocks or the cells");
    StepPruner step(sc, opt, geo, s, out);
    if (!geo.split) {
        // The cells of a block kSiblingGroupLanes at a time (prune_block_cells).
        PrunedCell* group[kSiblingGroupLanes];
        CellBox boxes[kSiblingGroupLanes];
        uint32_t count = 0;
        uint64_t group_block = 0;
        for (uint64_t i = begin; i < end; ++i) {
            const uint64_t bi = i / per_block;
            if (count == kSiblingGroupLanes || (count > 0 && bi != group_block)) {
                step.prune_block_cells(group, boxes, count, blocks[group_block].tape());
                count = 0;
            }
            const CellCoord at = block_cell(blocks[bi].origin, f, uint32_t(i % per_block));
            group[count] = &cells[i - begin];
            boxes[count] = step.cell_box(at.x, at.y, at.z);
            group_block = bi;
            ++count;
        }
        if (count > 0) step.prune_block_cells(group, boxes, count, blocks[group_block].tape());
        return;
    }
    if (begin % per_block != 0 || end % per_block != 0)
        throw std::invalid_argument("prune_level_step: a split level needs whole blocks");
    for (uint64_t bi = begin / per_block; bi < end / per_block; ++bi)
        step.prune_split_block(blocks[bi], cells.subspan(bi * per_block - begin, per_block));
}

}  // namespace sdfprune
