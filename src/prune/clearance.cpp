// clearance.cpp — far-field clearances (prune.hpp, set_clearance): for every far-field cell and
// each of the eight octants, how far a box of cells of its level reaching from it into that
// octant stays clear of near-field finest cells, so that a tracer in the cell heading that way
// may go on from the exit of the whole box (src/render/trace.cpp, shaders/gpu/trace.comp). Not
// in the paper: its tracer steps one far-field cell at a time.
//
// Per level and octant, the side S(p) of the largest clear cube with corner p reaching into the
// octant is the classic maximal-square recurrence in 3D: S = 0 on a cell holding a near-field
// cell, else 1 + the least S of the 7 neighbours p + u, u ∈ {0, 1}³ \ {0} (the octant's way),
// capped. It runs plane by plane against the octant's z (two planes of bytes), row by row
// against its y; along x the dependence S(x) = min(S0(x), S(x + 1) + 1) is closed in four
// doubling passes so that every pass runs on whole rows. Octants run in parallel.
#include <algorithm>
#include <array>
#include <cstring>
#include <vector>

#include "../core/parallel.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune {
namespace {

// The cells of a box of a level (nx · ny · nz, local coordinates) that hold a near-field
// finest cell: one bit per cell, each row along x in `words` words.
struct CellSet {
    uint32_t nx = 0, ny = 0, nz = 0, words = 0;
    std::vector<uint64_t> bits;
    CellSet(uint32_t x, uint32_t y, uint32_t z)
        : nx(x), ny(y), nz(z), words((x + 63) / 64), bits(size_t(y) * z * words) {}
    const uint64_t* row(uint32_t y, uint32_t z) const {
        return bits.data() + (size_t(z) * ny + y) * words;
    }
    void set(uint32_t x, uint32_t y, uint32_t z) {
        bits[(size_t(z) * ny + y) * words + x / 64] |= uint64_t(1) << (x % 64);
    }
};

// S of a cell whose cube may grow past the cap (the grid's outside, too): clearance
// kMaxClearance.
constexpr uint8_t kOpen = kMaxClearance + 1;
// Bytes on either side of a row: a doubling pass reads up to 8 cells past it.
constexpr uint32_t kPad = 16;

// Eight cells' S0 limits (0 on a near cell, else kOpen) from their eight bits, as the bytes
// of a little-endian word.
constexpr auto kLimits = [] {
    std::array<uint64_t, 256> t{};
    for (uint32_t b = 0; b < 256; ++b)
        for (uint32_t i = 0; i < 8; ++i)
            if (!(b >> i & 1)) t[b] |= uint64_t(kOpen) << (8 * i);
    return t;
}();

// A far-field cell waiting for its clearances: its index in its level, its coordinates in the
// box of its level's CellSet.
struct Pending {
    uint32_t index;
    uint16_t x, y, z;
};

// Sixteen bytes in one SIMD register (GCC/Clang vector extension, any target), for whole rows.
using u8x16 = uint8_t __attribute__((vector_size(16)));
u8x16 load16(const uint8_t* p) {
    u8x16 v;
    std::memcpy(&v, p, 16);
    return v;
}
void store16(uint8_t* p, u8x16 v) {
    std::memcpy(p, &v, 16);
}
u8x16 min16(u8x16 a, u8x16 b) {
    return a < b ? a : b;
}

// The clearances in `octant` of the cells `pending` (sorted by z: those of plane z are
// [first[z], first[z + 1])), into out[0, pending.size()).
void octant_clearances(const CellSet& near, uint32_t octant, std::span<const Pending> pending,
                       std::span<const uint32_t> first, uint8_t* out) {
    // Rows of r cells are computed in 16-byte pieces up to r16; past r, where the octant heads
    // up along x, they come out kOpen like the pads (the grid's outside); where it heads down,
    // nothing reads them.
    const uint32_t r = near.nx, r16 = (r + 15) / 16 * 16, stride = r16 + 2 * kPad;
    const uint32_t ny = near.ny, nz = near.nz;
    const bool up_x = octant & 1, up_y = octant & 2, up_z = octant & 4;
    const int sx = up_x ? 1 : -1;
    // Two planes of ny + 2 rows (a row of kOpen past each end) of padded rows.
    std::vector<uint8_t> planes(2 * size_t(ny + 2) * stride, kOpen);
    const auto row = [&](uint32_t plane, int y) {
        return planes.data() + (plane * size_t(ny + 2) + size_t(y + 1)) * stride + kPad;
    };
    std::vector<uint8_t> tmp(2 * size_t(stride), kOpen);  // two rows; pads never written
    uint8_t* const u = tmp.data() + kPad;
    uint8_t* const v = tmp.data() + stride + kPad;
    std::vector<uint8_t> limit(std::max(64 * size_t(near.words), size_t(r16)));
    uint32_t prev = 0, cur = 1;  // planes z + sz (at first: outside) and z
    // Per plane row: whether it is all kOpen (those of the pad rows and of the first plane
    // are): a row whose three inputs are, with no near cell, is too (most rows away from the
    // surface), and needs no work. (Past r, where the octant heads down along x, a row may hold
    // other values: nothing reads them.)
    std::vector<uint8_t> open(2 * size_t(ny + 2), 1);
    const auto is_open = [&](uint32_t plane, int y) -> uint8_t& {
        return open[plane * size_t(ny + 2) + size_t(y + 1)];
    };
    const u8x16 one = u8x16{} + 1, open16 = u8x16{} + kOpen;
    for (uint32_t i = 0; i < nz; ++i) {
        const uint32_t z = up_z ? nz - 1 - i : i;
        for (uint32_t j = 0; j < ny; ++j) {
            const int y = int(up_y ? ny - 1 - j : j), y1 = up_y ? y + 1 : y - 1;
            // 0 on a near cell, else kOpen
            const uint64_t* bits = near.row(uint32_t(y), z);
            if (is_open(prev, y) && is_open(prev, y1) && is_open(cur, y1) &&
                std::all_of(bits, bits + near.words, [](uint64_t w) { return w == 0; })) {
                if (!is_open(cur, y)) std::fill_n(row(cur, y), r16, kOpen);
                is_open(cur, y) = 1;
                continue;
            }
            is_open(cur, y) = 0;
            for (uint32_t w = 0; w < 8 * near.words; ++w) {
                const uint64_t eight = kLimits[bits[w / 8] >> (8 * (w % 8)) & 255];
                std::memcpy(limit.data() + 8 * w, &eight, 8);
            }
            // N(x) = min of S over (x, y + sy, z), (x, y, z + sz), (x, y + sy, z + sz)
            const uint8_t *a = row(prev, y), *b = row(prev, y1), *c = row(cur, y1);
            for (uint32_t x = 0; x < r16; x += 16)
                store16(u + x, min16(min16(load16(a + x), load16(b + x)), load16(c + x)));
            // S0(x) = min(limit, 1 + min(N(x), N(x + sx))): S(x + sx) left to the closure
            for (uint32_t x = 0; x < r16; x += 16)
                store16(v + x, min16(load16(limit.data() + x),
                                     one + min16(load16(u + x), load16(u + x + sx))));
            // closure S(x) = min over k >= 0 of S0(x + k·sx) + k: steps 1, 2, 4, 8
            uint8_t *from = v, *to = u;
            for (int k = 1; k <= 8; k *= 2) {
                uint8_t* out = k == 8 ? row(cur, y) : to;
                const u8x16 kk = u8x16{} + uint8_t(k);
                for (uint32_t x = 0; x < r16; x += 16)
                    store16(out + x, min16(load16(from + x), load16(from + int(x) + sx * k) + kk));
                std::swap(from, to);
            }
            // all kOpen again (past the surface's reach): later rows may skip it
            const uint8_t* done = row(cur, y);
            u8x16 differ{};
            uint32_t x = 0;
            for (; x + 16 <= r; x += 16) differ |= u8x16(load16(done + x) != open16);
            uint64_t halves[2];
            std::memcpy(halves, &differ, 16);
            bool open_row = (halves[0] | halves[1]) == 0;
            for (; x < r; ++x) open_row = open_row && done[x] == kOpen;
            is_open(cur, y) = open_row;
        }
        for (uint32_t p = first[z]; p < first[z + 1]; ++p) {
            const Pending& q = pending[p];
            // a far-field cell holds no near-field one: S >= 1
            out[p] = uint8_t(row(cur, q.y)[q.x] - 1);
        }
        std::swap(prev, cur);
    }
}

}  // namespace

uint64_t set_clearance(std::span<const LevelCells> levels, int threads, const CellRange* changed) {
    const uint32_t L = uint32_t(levels.size());
    if (L == 0) return 0;
    const uint32_t N = levels.back().res;
    // Per level: the cells to set (`set`, within reach of a change), and the box the recurrence
    // runs on (`run`: the cells their clearances depend on); levels too wide keep clearance 0.
    struct Range {
        uint32_t lo[3], hi[3];
        bool holds(CellCoord c) const {
            return c.x >= lo[0] && c.x < hi[0] && c.y >= lo[1] && c.y < hi[1] && c.z >= lo[2] &&
                   c.z < hi[2];
        }
    };
    std::vector<Range> set(L), run(L);
    std::vector<CellSet> near;
    for (uint32_t k = 0; k < L; ++k) {
        const uint32_t res = levels[k].res, s = N / res;
        const uint32_t c_lo[3] = {changed ? changed->lo.x : 0, changed ? changed->lo.y : 0,
                                  changed ? changed->lo.z : 0};
        const uint32_t c_hi[3] = {changed ? changed->hi.x : N, changed ? changed->hi.y : N,
                                  changed ? changed->hi.z : N};
        for (int a = 0; a < 3; ++a) {
            const uint32_t lo = c_lo[a] / s, hi = std::min(res, (c_hi[a] + s - 1) / s);
            const auto grown = [&](uint32_t by, uint32_t& out_lo, uint32_t& out_hi) {
                out_lo = lo > by ? lo - by : 0;
                out_hi = std::min(res, hi + by);
            };
            grown(kMaxClearance, set[k].lo[a], set[k].hi[a]);
            grown(2 * kMaxClearance, run[k].lo[a], run[k].hi[a]);
        }
        const bool fits = res <= kClearanceMaxRes;
        near.emplace_back(fits ? run[k].hi[0] - run[k].lo[0] : 0,
                          fits ? run[k].hi[1] - run[k].lo[1] : 0,
                          fits ? run[k].hi[2] - run[k].lo[2] : 0);
    }
    std::vector<std::vector<Pending>> pending(L);
    // Every block, children first (whether a cell holds a near-field finest cell is known once
    // its children are): marks the cells of the `run` boxes that hold one, and collects the
    // far-field cells of the `set` boxes. Returns whether the block holds one.
    const auto visit = [&](const auto& self, uint32_t level, uint32_t first,
                           CellCoord origin) -> bool {
        const LevelCells& l = levels[level];
        const bool finest = level + 1 == L;
        const uint32_t f = l.factor, nf = finest ? 0 : levels[level + 1].factor;
        const Range &to_set = set[level], &r = run[level];
        CellSet& n = near[level];
        bool any = false;
        uint32_t local = 0;
        for (uint32_t dz = 0; dz < f; ++dz)
            for (uint32_t dy = 0; dy < f; ++dy)
                for (uint32_t dx = 0; dx < f; ++dx, ++local) {
                    PrunedCell& c = l.cells[first + local];
                    const CellCoord at{origin.x + dx, origin.y + dy, origin.z + dz};
                    bool holds = true;
                    if (c.tape == PrunedCell::kFarField) {
                        holds = false;
                        if (to_set.holds(at)) {
                            c.children = 0;
                            if (n.nx)
                                pending[level].push_back({first + local, uint16_t(at.x - r.lo[0]),
                                                          uint16_t(at.y - r.lo[1]),
                                                          uint16_t(at.z - r.lo[2])});
                        }
                    } else if (!finest) {
                        holds =
                            self(self, level + 1, c.children, {at.x * nf, at.y * nf, at.z * nf});
                    }
                    if (holds && n.nx && r.holds(at))
                        n.set(at.x - r.lo[0], at.y - r.lo[1], at.z - r.lo[2]);
                    any |= holds;
                }
        return any;
    };
    visit(visit, 0, 0, {});
    uint64_t bytes = 0, peak = 0;
    for (uint32_t k = 0; k < L; ++k)
        bytes += near[k].bits.size() * 8 + pending[k].capacity() * sizeof(Pending);
    ParallelOptions po;
    po.threads = threads;
    for (uint32_t k = 0; k < L; ++k) {
        if (pending[k].empty()) continue;
        const uint32_t nz = near[k].nz;
        // pending by plane (counting sort on z)
        std::vector<uint32_t> first(nz + 1, 0);
        for (const Pending& p : pending[k]) ++first[p.z + 1];
        for (uint32_t z = 0; z < nz; ++z) first[z + 1] += first[z];
        std::vector<Pending> sorted(pending[k].size());
        std::vector<uint32_t> at(first.begin(), first.end() - 1);
        for (const Pending& p : pending[k]) sorted[at[p.z]++] = p;
        std::vector<Pending>().swap(pending[k]);
        // per octant: two planes, three rows
        const uint64_t octant_bytes =
            (2 * uint64_t(near[k].ny + 2) + 3) * (near[k].nx + 16 + 2 * kPad);
        const size_t n = sorted.size();
        std::vector<uint8_t> out(8 * n);  // per octant, per pending cell
        peak = std::max(peak, bytes + n * (sizeof(Pending) + 8) + 8 * octant_bytes);
        parallel_for<NotCancellable>(8, po, [&](uint64_t octant) {
            octant_clearances(near[k], uint32_t(octant), sorted, first, out.data() + octant * n);
        });
        constexpr uint64_t kChunk = 1 << 14;
        parallel_for<NotCancellable>((n + kChunk - 1) / kChunk, po, [&](uint64_t c) {
            for (size_t i = c * kChunk; i < std::min(n, size_t(c + 1) * kChunk); ++i) {
                uint32_t word = 0;
                for (uint32_t o = 0; o < 8; ++o) word |= uint32_t(out[o * n + i]) << (4 * o);
                levels[k].cells[sorted[i].index].children = word;
            }
        });
    }
    return std::max(peak, bytes);
}

}  // namespace sdfprune
