// extract.cpp — marching tetrahedra (DESIGN.md §6 "meshing") over the cubes of a regular grid
// that may hold the surface: those overlapping near-field cells of a pruned grid (Barbier et al.,
// EG 2025: a far-field cell has f != 0 everywhere in it), or every cube for the naive baseline.
//
// Grid corners live in 8³ bricks, allocated only where a cube needs them. Each brick keeps
// bit masks of its "candidate" cubes (a cube is named by its lowest corner) and of the corners
// to evaluate, the corner values, and which grid edges starting at each corner carry a vertex.
// The stages, each parallel over bricks (in brick order) and each deterministic:
//   1. mark candidate cubes (pruned: one walk over the near-field cells of the hierarchy,
//      plus the cubes where an inside far-field cell meets the AABB, which get a cap);
//   2. needed corners = the 8 corners of every candidate cube (bit operations on the masks);
//   3. evaluate every needed corner once;
//   4. vertices: one per sign-changing Kuhn edge used by a candidate cube, numbered in
//      (brick, corner, direction) order, so both methods and any thread count agree;
//   5. triangles from the 6 tetrahedra of every candidate cube, in (brick, cube, tet) order.

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <memory>

#include "../core/clock.hpp"
#include "../core/parallel.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/mesh.hpp"

namespace sdfprune {
namespace {

// ---- the tetrahedra of a cube ----------------------------------------------------------------
// Cube corner k = x + 2y + 4z (x, y, z in {0, 1}). The Kuhn triangulation: one tetrahedron per
// order of the axes, 0 -> e_a -> e_a + e_b -> (1,1,1). Any two of its corners are comparable
// (one's bits contain the other's), so every edge runs from a corner u to u + d with d in
// {0,1}³ \ {0}: the edge belongs to grid corner u, direction d (1..7).

// The surface inside one tetrahedron for one sign case: 0, 3 or 4 vertices, each on a tet edge
// given as (lower cube corner, upper cube corner), in counter-clockwise order seen from outside.
struct TetCase {
    uint8_t n = 0;
    uint8_t lo[4] = {}, hi[4] = {};
};
using TetTable = std::array<std::array<TetCase, 16>, 6>;
using TetVertices = std::array<std::array<uint8_t, 4>, 6>;

constexpr int det3(int a, int b, int c) {  // determinant of three corners as column vectors
    const auto v = [](int k, int i) { return (k >> i) & 1; };
    return v(a, 0) * (v(b, 1) * v(c, 2) - v(b, 2) * v(c, 1)) -
           v(b, 0) * (v(a, 1) * v(c, 2) - v(a, 2) * v(c, 1)) +
           v(c, 0) * (v(a, 1) * v(b, 2) - v(a, 2) * v(b, 1));
}

// The 6 tetrahedra as cube corners, each positively oriented: det(v1-v0, v2-v0, v3-v0) > 0.
constexpr TetVertices make_tet_vertices() {
    constexpr int axes[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
    TetVertices r{};
    for (int t = 0; t < 6; ++t) {
        int v[4] = {0, 1 << axes[t][0], (1 << axes[t][0]) | (1 << axes[t][1]), 7};
        if (det3(v[1], v[2], v[3]) < 0) std::swap(v[1], v[2]);  // odd order of the axes
        for (int i = 0; i < 4; ++i) r[t][i] = uint8_t(v[i]);
    }
    return r;
}
constexpr TetVertices kTetVertices = make_tet_vertices();

constexpr TetTable make_tet_table() {
    // The 12 even permutations of (0, 1, 2, 3): they keep a tetrahedron's orientation.
    std::array<std::array<int, 4>, 12> even{};
    int ne = 0;
    for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b)
            for (int c = 0; c < 4; ++c)
                for (int d = 0; d < 4; ++d) {
                    const int p[4] = {a, b, c, d};
                    bool distinct = true;
                    int inversions = 0;
                    for (int i = 0; i < 4; ++i)
                        for (int j = i + 1; j < 4; ++j) {
                            distinct = distinct && p[i] != p[j];
                            inversions += p[i] > p[j] ? 1 : 0;
                        }
                    if (distinct && inversions % 2 == 0) even[ne++] = {a, b, c, d};
                }
    // For a positively oriented (p0, p1, p2, p3), the section's vertices in outward order, as
    // edges (pi, pj):
    constexpr int kOneInside[3][2] = {{0, 1}, {0, 2}, {0, 3}};   // p0 alone inside: faces away
    constexpr int kOneOutside[3][2] = {{0, 1}, {0, 3}, {0, 2}};  // p0 alone outside: faces to
    constexpr int kTwoInside[4][2] = {{0, 2}, {0, 3}, {1, 3}, {1, 2}};  // p0, p1 inside
    TetTable table{};
    for (int t = 0; t < 6; ++t) {
        const auto& v = kTetVertices[t];
        for (int m = 0; m < 16; ++m) {  // bit i: tet vertex i is inside
            TetCase& tc = table[t][m];
            const int inside = (m & 1) + (m >> 1 & 1) + (m >> 2 & 1) + (m >> 3 & 1);
            if (inside == 0 || inside == 4) continue;
            for (const auto& p : even) {
                const auto in = [&](int i) { return ((m >> p[i]) & 1) != 0; };
                const int(*e)[2] = nullptr;
                if (inside == 1 && in(0)) {
                    tc.n = 3;
                    e = kOneInside;
                } else if (inside == 3 && !in(0)) {
                    tc.n = 3;
                    e = kOneOutside;
                } else if (inside == 2 && in(0) && in(1)) {
                    tc.n = 4;
                    e = kTwoInside;
                } else {
                    continue;
                }
                for (int i = 0; i < tc.n; ++i) {
                    const int a = v[p[e[i][0]]], b = v[p[e[i][1]]];
                    tc.lo[i] = uint8_t(a < b ? a : b);
                    tc.hi[i] = uint8_t(a < b ? b : a);
                }
                break;
            }
        }
    }
    return table;
}
constexpr TetTable kTets = make_tet_table();

// The surface inside a whole cube for one sign case (bit k: cube corner k is inside): its 6
// tetrahedra's sections in tetrahedron order, the empty ones left out.
struct CubeCase {
    uint8_t count = 0;           // sections (at most one per tetrahedron)
    uint8_t triangles = 0;       // triangles they make (a quad makes 2)
    std::array<TetCase, 6> tet;  // the sections, each with 3 or 4 vertices
};
constexpr std::array<CubeCase, 256> make_cube_table() {
    std::array<CubeCase, 256> table{};
    for (uint32_t inside = 0; inside < 256; ++inside) {
        CubeCase& cc = table[inside];
        for (uint32_t t = 0; t < 6; ++t) {
            uint32_t m = 0;
            for (uint32_t k = 0; k < 4; ++k) m |= ((inside >> kTetVertices[t][k]) & 1u) << k;
            if (kTets[t][m].n == 0) continue;
            cc.tet[cc.count++] = kTets[t][m];
            cc.triangles = uint8_t(cc.triangles + kTets[t][m].n - 2);
        }
    }
    return table;
}
constexpr std::array<CubeCase, 256> kCubes = make_cube_table();

// ---- bricks of grid corners ------------------------------------------------------------------

constexpr uint32_t kB = 8;  // corners per brick axis
constexpr uint32_t kBrickCorners = kB * kB * kB;
constexpr uint64_t kCol0 = 0x0101010101010101ull;  // x = 0 in every row of an xy layer word
constexpr uint64_t kCol7 = kCol0 << (kB - 1);      // x = 7

// Local index of a corner inside its brick: x + 8y + 64z; one uint64 word per z layer.
constexpr uint32_t local_index(uint32_t x, uint32_t y, uint32_t z) {
    return (x & 7u) | (y & 7u) << 3 | (z & 7u) << 6;
}
constexpr bool bit(const uint64_t* words, uint32_t l) {
    return (words[l >> 6] >> (l & 63)) & 1u;
}

// Bits set in a 7-bit edge mask, by table (std::popcount may be a library call without
// -mpopcnt).
constexpr std::array<uint8_t, 128> make_popcount7() {
    std::array<uint8_t, 128> t{};
    for (uint32_t m = 0; m < 128; ++m)
        for (uint32_t b = 0; b < 7; ++b) t[m] = uint8_t(t[m] + ((m >> b) & 1));
    return t;
}
constexpr std::array<uint8_t, 128> kPopcount7 = make_popcount7();

// 8³ grid corners, and the cubes having them as lowest corner. Arrays other than the masks are
// left uninitialized and written before being read.
struct Brick {
    uint32_t bx = 0, by = 0, bz = 0;   // brick coordinates
    uint32_t vbase = 0;                // the brick's first vertex
    uint64_t cand[kB] = {};            // candidate cubes, one word per z layer
    uint64_t need[kB] = {};            // corners to evaluate
    uint64_t inside[kB] = {};          // needed corners with f < 0 (capped on the AABB)
    uint64_t has_vertex[kB] = {};      // corners with a vertex on an edge from them
    uint64_t cross[kB] = {};           // candidate cubes whose corners differ in sign
    uint32_t tbase = 0;                // the brick's first triangle
    uint8_t cube_case[kBrickCorners];  // crossing cubes: bit k = cube corner k is inside
    // The bricks around this one: offset (dx, dy, dz) in {-1, 0, 1}³ at
    // (dx + 1) + 3 (dy + 1) + 9 (dz + 1), this brick at 13; null where none is allocated.
    std::array<const Brick*, 27> near{};
    float value[kBrickCorners];  // needed corners: f, capped on the AABB
    // Corners with a vertex (has_vertex): bit d-1 = the edge along d has a vertex; their first
    // vertex, relative to vbase.
    uint8_t vmask[kBrickCorners];
    uint16_t voff[kBrickCorners];
    // Candidate cubes, when the pruned grid's cells are unions of cubes: the cube's cell's tape
    // (its offset in the tape pool), or kNone for a far-field cell (a cap cube).
    std::unique_ptr<uint32_t[]> tape;
};

using BitField = uint64_t (Brick::*)[kB];

// The grid coordinates of corner l of brick b.
inline CellCoord corner_at(const Brick& b, uint32_t l) {
    return {b.bx * kB + (l & 7), b.by * kB + ((l >> 3) & 7), b.bz * kB + (l >> 6)};
}

constexpr uint32_t near_slot(int dx, int dy, int dz) {
    return uint32_t((dx + 1) + 3 * (dy + 1) + 9 * (dz + 1));
}

// Where corner (or cube) l of b lies after a move by (sx, sy, sz), each in {-1, 0, 1}: the
// brick (null if none) and the local index there.
struct CornerRef {
    const Brick* brick;
    uint32_t local;
};
inline CornerRef moved(const Brick& b, uint32_t l, int sx, int sy, int sz) {
    const int x = int(l & 7) + sx, y = int((l >> 3) & 7) + sy, z = int(l >> 6) + sz;
    const int dx = x < 0 ? -1 : x >= int(kB), dy = y < 0 ? -1 : y >= int(kB),
              dz = z < 0 ? -1 : z >= int(kB);
    return {b.near[near_slot(dx, dy, dz)], local_index(uint32_t(x), uint32_t(y), uint32_t(z))};
}

// The same for a move by k = x + 2y + 4z (a cube corner or an edge direction, all >= 0),
// quicker where the corner stays in the brick.
inline CornerRef moved_up(const Brick& b, uint32_t l, uint32_t k) {
    const uint32_t x = l & 7, y = (l >> 3) & 7, z = l >> 6;
    if (x < kB - 1 && y < kB - 1 && z < kB - 1)
        return {&b, l + (k & 1) + kB * ((k >> 1) & 1) + kB * kB * (k >> 2)};
    return moved(b, l, int(k & 1), int((k >> 1) & 1), int(k >> 2));
}

// Layer z of `field` moved by (sx, sy, sz), each in {-1, 0, 1}: bit (x, y) of the result is the
// field's bit at corner (x + sx, y + sy, z + sz), read from the neighbouring brick where that
// leaves b (0 where none is allocated). Every stage's neighbourhood test is a few of these.
inline uint64_t shifted(const Brick& b, BitField field, uint32_t z, int sx, int sy, int sz) {
    const int zz = int(z) + sz;
    const int dz = zz < 0 ? -1 : zz >= int(kB);
    const uint32_t layer = uint32_t(zz - int(kB) * dz);
    const auto word = [&](int dx, int dy) {
        const Brick* n = b.near[near_slot(dx, dy, dz)];
        return n ? (n->*field)[layer] : 0;
    };
    const auto along_x = [&](int dy) {  // the row's bits moved by sx
        const uint64_t w = word(0, dy);
        if (sx == 0) return w;
        const uint64_t next = word(sx, dy);
        return sx > 0 ? ((w >> 1) & ~kCol7) | ((next & kCol0) << (kB - 1))
                      : ((w << 1) & ~kCol0) | ((next & kCol7) >> (kB - 1));
    };
    const uint64_t here = along_x(0);
    if (sy == 0) return here;
    const uint64_t next = along_x(sy);
    return sy > 0 ? (here >> kB) | (next << (kB * (kB - 1)))
                  : (here << kB) | (next >> (kB * (kB - 1)));
}

class CornerBricks {
  public:
    CornerBricks(uint32_t n, bool with_tapes) : n_(n), nb_((n + kB) / kB), with_tapes_(with_tapes) {
        slot_of_.assign(size_t(nb_) * nb_ * nb_, kNone);
    }

    // Stage 1, serial: marks cube (x, y, z) as a candidate and allocates the bricks holding its
    // corners. `tape` is stored when the bricks keep tapes.
    void add_candidate(uint32_t x, uint32_t y, uint32_t z, uint32_t tape = kNone) {
        const uint64_t one = 1;
        add_kept_cubes(x, y, z, 1, &one, tape);
    }
    // The same for some of the cubes [x0, x0 + m)³, within one brick (m divides kB, x0, y0, z0
    // are multiples of m): those of `keep`, bit x + m·y + m²·z for cube (x0 + x, y0 + y, z0 + z).
    void add_kept_cubes(uint32_t x0, uint32_t y0, uint32_t z0, uint32_t m, const uint64_t* keep,
                        uint32_t tape) {
        Brick* b = nullptr;
        const uint32_t lx = x0 % kB, ly = y0 % kB, lz = z0 % kB;
        uint32_t ex = 0, ey = 0, ez = 0;  // some cube touches the brick's +x, +y, +z face
        for (uint32_t w = 0; w < (m * m * m + 63) / 64; ++w)
            for (uint64_t bits = keep[w]; bits; bits &= bits - 1) {
                if (!b) b = &allocate(x0 / kB, y0 / kB, z0 / kB);
                const uint32_t i = w * 64 + uint32_t(std::countr_zero(bits));
                const uint32_t x = lx + i % m, y = ly + (i / m) % m, z = lz + i / (m * m);
                const uint32_t l = local_index(x, y, z);
                b->cand[l >> 6] |= 1ull << (l & 63);
                if (with_tapes_) b->tape[l] = tape;
                ex |= x == kB - 1;
                ey |= y == kB - 1;
                ez |= z == kB - 1;
            }
        if (ex | ey | ez)
            for (uint32_t dz = 0; dz <= ez; ++dz)
                for (uint32_t dy = 0; dy <= ey; ++dy)
                    for (uint32_t dx = 0; dx <= ex; ++dx)
                        allocate(x0 / kB + dx, y0 / kB + dy, z0 / kB + dz);
    }
    // Stage 1 for the naive method: every cube is a candidate.
    void add_all_cubes() {
        for (uint32_t bz = 0; bz < nb_; ++bz)
            for (uint32_t by = 0; by < nb_; ++by)
                for (uint32_t bx = 0; bx < nb_; ++bx) {
                    Brick& b = allocate(bx, by, bz);
                    uint64_t layer = 0;  // the cubes (x, y < n) of one xy layer of this brick
                    for (uint32_t y = 0; y < kB; ++y)
                        for (uint32_t x = 0; x < kB; ++x)
                            if (bx * kB + x < n_ && by * kB + y < n_) layer |= 1ull << (x + kB * y);
                    for (uint32_t z = 0; z < kB; ++z) b.cand[z] = bz * kB + z < n_ ? layer : 0;
                }
    }
    // Ends stage 1: the bricks in brick order (z-major), the order of every later stage, and
    // each brick's neighbours.
    void finish() {
        order_.clear();
        for (const uint32_t s : slot_of_)
            if (s != kNone) order_.push_back(bricks_[s].get());
        for (Brick* b : order_)
            for (int dz = -1; dz <= 1; ++dz)
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const int64_t x = int64_t(b->bx) + dx, y = int64_t(b->by) + dy,
                                      z = int64_t(b->bz) + dz;
                        const bool inside =
                            x >= 0 && y >= 0 && z >= 0 && x < nb_ && y < nb_ && z < nb_;
                        const uint32_t s =
                            inside ? slot_of_[brick_index(uint32_t(x), uint32_t(y), uint32_t(z))]
                                   : kNone;
                        b->near[near_slot(dx, dy, dz)] = s == kNone ? nullptr : bricks_[s].get();
                    }
    }
    uint32_t count() const { return uint32_t(order_.size()); }
    Brick& operator[](uint32_t i) const { return *order_[i]; }
    bool with_tapes() const { return with_tapes_; }

    uint64_t bytes() const {
        return slot_of_.size() * sizeof(uint32_t) + order_.size() * sizeof(Brick*) +
               bricks_.size() * (sizeof(Brick) + (with_tapes_ ? kBrickCorners * 4 : 0));
    }

  private:
    size_t brick_index(uint32_t bx, uint32_t by, uint32_t bz) const {
        return (size_t(bz) * nb_ + by) * nb_ + bx;
    }
    Brick& allocate(uint32_t bx, uint32_t by, uint32_t bz) {
        uint32_t& s = slot_of_[brick_index(bx, by, bz)];
        if (s == kNone) {
            s = uint32_t(bricks_.size());
            auto b = std::make_unique_for_overwrite<Brick>();
            b->bx = bx;
            b->by = by;
            b->bz = bz;
            if (with_tapes_) b->tape = std::make_unique_for_overwrite<uint32_t[]>(kBrickCorners);
            bricks_.push_back(std::move(b));
        }
        return *bricks_[s];
    }

    uint32_t n_, nb_;
    bool with_tapes_;
    std::vector<uint32_t> slot_of_;  // per brick index: its slot in bricks_, kNone if absent
    std::vector<std::unique_ptr<Brick>> bricks_;  // in allocation order
    std::vector<Brick*> order_;                   // in brick order
};

// Stage 2 for one brick: a corner is needed iff one of the (up to 8) cubes having it as a corner
// is a candidate: the candidate masks moved by every s in {0, -1}³.
void compute_needed(Brick& b) {
    for (uint32_t z = 0; z < kB; ++z) {
        uint64_t need = 0;
        for (uint32_t s = 0; s < 8; ++s)
            need |= shifted(b, &Brick::cand, z, -int(s & 1), -int((s >> 1) & 1), -int(s >> 2));
        b.need[z] = need;
    }
}

// Stage 4a for one brick: which edges from its needed corners carry a vertex (vmask), and each
// corner's first vertex (voff); returns the brick's vertex count. An edge from corner u along d
// carries one where both ends are needed, their signs differ, and a candidate cube uses it: a
// cube u - s for s a subset of the axes d does not move along.
uint32_t mark_vertex_edges(Brick& b) {
    uint64_t edges[7][kB];
    for (uint32_t z = 0; z < kB; ++z) {
        uint64_t cand_from[8];  // bit u: cube u - s is a candidate, s in {0, 1}³
        for (uint32_t s = 0; s < 8; ++s)
            cand_from[s] =
                shifted(b, &Brick::cand, z, -int(s & 1), -int((s >> 1) & 1), -int(s >> 2));
        for (uint32_t d = 1; d < 8; ++d) {
            const int sx = int(d & 1), sy = int((d >> 1) & 1), sz = int(d >> 2);
            const uint64_t both = b.need[z] & shifted(b, &Brick::need, z, sx, sy, sz);
            const uint64_t differ = b.inside[z] ^ shifted(b, &Brick::inside, z, sx, sy, sz);
            const uint32_t free = ~d & 7u;
            uint64_t used = 0;
            for (uint32_t s = 0;; s = (s - free) & free) {  // every subset of `free`
                used |= cand_from[s];
                if (s == free) break;
            }
            edges[d - 1][z] = both & differ & used;
        }
    }
    uint32_t vertices = 0;
    for (uint32_t word = 0; word < kB; ++word) {
        uint64_t any = 0;
        for (uint32_t d = 0; d < 7; ++d) any |= edges[d][word];
        b.has_vertex[word] = any;
        for (uint64_t bits = any; bits; bits &= bits - 1) {
            const uint32_t at = uint32_t(std::countr_zero(bits));
            uint32_t mask = 0;
            for (uint32_t d = 0; d < 7; ++d) mask |= uint32_t((edges[d][word] >> at) & 1) << d;
            const uint32_t l = word * 64 + at;
            b.vmask[l] = uint8_t(mask);
            b.voff[l] = uint16_t(vertices);
            vertices += kPopcount7[mask];
        }
    }
    return vertices;
}

// The vertex on the edge from corner `l` of brick `b` along d (1..7); it must exist.
inline uint32_t vertex(const Brick& b, uint32_t l, uint32_t d) {
    return b.vbase + b.voff[l] + kPopcount7[b.vmask[l] & ((1u << (d - 1)) - 1)];
}

// Runs fn(i) for i in [0, count) in parallel (one chunk per brick or triangle chunk); checks the
// cancel flag and reports progress in [lo, hi] from the calling thread.
template <class F>
void parallel_stage(uint32_t count, const MeshOptions& o, double lo, double hi, const F& fn) {
    parallel_for<MeshCancelled>(count, parallel_options(o, lo, hi),
                                [&](uint64_t i) { fn(uint32_t(i)); });
}

// Visits the grid's cells: near(ix, iy, iz, cell) for every near-field cell of the finest
// level, inside_far(level, cx, cy, cz) for every far-field cell with f < 0, at the level where
// it became far.
template <class Near, class InsideFar>
void for_each_cell(const PrunedGrid& g, const Near& near, const InsideFar& inside_far) {
    g.for_each_block([&](const PrunedGrid::Block& b) {
        const uint32_t f = g.level_factor(b.level);
        const PrunedCell* c = g.level_cells(b.level).data() + b.first;
        const bool finest = b.level + 1 == g.level_count();
        for (uint32_t z = 0; z < f; ++z)
            for (uint32_t y = 0; y < f; ++y)
                for (uint32_t x = 0; x < f; ++x, ++c) {
                    if (c->tape == PrunedCell::kFarField) {
                        if (c->bound < 0.0f)
                            inside_far(b.level, b.origin.x + x, b.origin.y + y, b.origin.z + z);
                    } else if (finest) {
                        near(b.origin.x + x, b.origin.y + y, b.origin.z + z, *c);
                    }
                }
    });
}

// The cubes (of n per axis) overlapping cells [j0, j1] (of g per axis) on one axis: [lo, hi].
void cube_range(uint32_t j0, uint32_t j1, uint32_t g, uint32_t n, uint32_t& lo, uint32_t& hi) {
    lo = uint32_t(uint64_t(j0) * n / g);
    hi = uint32_t((uint64_t(j1 + 1) * n + g - 1) / g) - 1;
    hi = std::min(hi, n - 1);
}

// The cells (of g per axis) holding corner i (of n + 1 per axis) on one axis: [lo, hi].
void cell_range(uint32_t i, uint32_t g, uint32_t n, uint32_t& lo, uint32_t& hi) {
    const uint64_t q = uint64_t(i) * g;
    hi = std::min(uint32_t(q / n), g - 1);
    lo = q % n == 0 && q > 0 ? uint32_t(q / n) - 1 : hi;
    lo = std::min(lo, hi);
}

// A near-field cell of the finest level, and (cells made of m³ cubes) which of its cubes may
// hold the surface: bit x + m·y + m²·z of `keep`.
struct NearCell {
    uint32_t x, y, z;
    uint32_t tape;
    std::array<uint64_t, 8> keep;
};

// Stage 1b for one near-field cell of m³ cubes (m a power of two from 2 to kB): drops the cubes
// where the cell's tape shows f != 0 everywhere, so that they cannot hold the surface. Boxes of
// (m/2)³ cubes first, then the halves of those kept, down to single cubes: a box whose centre
// value clears its Lipschitz reach (f's range over the box excludes 0, rounding included) is
// dropped, unless f < 0 there and the box touches the AABB, where the mesh caps the shape.
// Dropping them changes nothing in the mesh: their corners share one sign, and every edge and
// triangle the mesh has comes from a cube whose corners differ in sign.
void cull_cubes(const Scene& sc, const PrunedGrid& grid, uint32_t n, uint32_t m, vec3 origin,
                vec3 h, NearCell& cell, float* stack) {
    const std::span<const uint32_t> tape = grid.tape_at(cell.tape);
    const float L = sc.lipschitz[sc.root()];
    struct Box {
        uint32_t x, y, z;  // lowest cube, within the cell
    };
    Box boxes[kBrickCorners], next[kBrickCorners];
    uint32_t count = 0;
    for (uint32_t k = 0; k < 8; ++k)
        boxes[count++] = {(k & 1) * m / 2, ((k >> 1) & 1) * m / 2, (k >> 2) * m / 2};
    for (uint32_t size = m / 2;; size /= 2) {
        const float reach = math::far_field_reach(L, 0.5f * float(size) * math::length(h));
        uint32_t kept = 0;
        for (uint32_t first = 0; first < count; first += kEvalLanes) {
            const uint32_t lanes = std::min(kEvalLanes, count - first);
            PointLanes p;
            for (uint32_t i = 0; i < lanes; ++i) {
                const Box& bx = boxes[first + i];
                const vec3 c = origin + vec3(float(cell.x * m + bx.x) + 0.5f * float(size),
                                             float(cell.y * m + bx.y) + 0.5f * float(size),
                                             float(cell.z * m + bx.z) + 0.5f * float(size)) *
                                            h;
                p.x[i] = c.x;
                p.y[i] = c.y;
                p.z[i] = c.z;
            }
            float v[kEvalLanes];
            eval_tape_lanes(sc, tape, p, lanes, v, stack);
            for (uint32_t i = 0; i < lanes; ++i) {
                const Box& bx = boxes[first + i];
                const uint32_t x0 = cell.x * m + bx.x, y0 = cell.y * m + bx.y,
                               z0 = cell.z * m + bx.z;
                const bool on_aabb = x0 == 0 || y0 == 0 || z0 == 0 || x0 + size == n ||
                                     y0 + size == n || z0 + size == n;
                if (std::abs(v[i]) > reach && !(v[i] < 0.0f && on_aabb)) continue;
                if (size == 1) {
                    const uint32_t bit_index = bx.x + m * (bx.y + m * bx.z);
                    cell.keep[bit_index >> 6] |= 1ull << (bit_index & 63);
                    continue;
                }
                for (uint32_t k = 0; k < 8; ++k)
                    next[kept++] = {bx.x + (k & 1) * size / 2, bx.y + ((k >> 1) & 1) * size / 2,
                                    bx.z + (k >> 2) * size / 2};
            }
        }
        if (size == 1 || kept == 0) return;
        std::copy_n(next, kept, boxes);
        count = kept;
    }
}

// Stage 1 for a pruned grid: candidates are the cubes overlapping a near-field cell (where its
// cells are made of 2³ to 8³ cubes, only those that may hold the surface: cull_cubes), and the
// cubes on the AABB's boundary overlapping an inside far-field cell (the cap, where f < 0 meets
// the AABB: corners on the AABB count as outside). When the cells are unions of cubes (n a
// multiple of the grid's resolution), each candidate keeps its cell's tape.
void add_candidates(const PrunedGrid& grid, uint32_t n, CornerBricks& bricks,
                    const MeshOptions& o) {
    const Scene& sc = grid.scene();
    const uint32_t g = grid.resolution();
    const uint32_t m = n % g == 0 ? n / g : 0;  // cubes per cell and axis, 0: not a union
    const bool culled = m >= 2 && kB % m == 0;
    const auto cubes_of = [&](uint32_t cx, uint32_t cy, uint32_t cz, uint32_t span,
                              bool boundary_only, uint32_t tape) {
        uint32_t x0, x1, y0, y1, z0, z1;
        cube_range(cx * span, (cx + 1) * span - 1, g, n, x0, x1);
        cube_range(cy * span, (cy + 1) * span - 1, g, n, y0, y1);
        cube_range(cz * span, (cz + 1) * span - 1, g, n, z0, z1);
        for (uint32_t z = z0; z <= z1; ++z)
            for (uint32_t y = y0; y <= y1; ++y) {
                if (boundary_only && !(z == 0 || z == n - 1 || y == 0 || y == n - 1)) {
                    // Only the two ends of the row lie on the boundary.
                    if (x0 == 0) bricks.add_candidate(x0, y, z);
                    if (x1 == n - 1 && x1 != x0) bricks.add_candidate(x1, y, z);
                    continue;
                }
                for (uint32_t x = x0; x <= x1; ++x) bricks.add_candidate(x, y, z, tape);
            }
    };
    std::vector<NearCell> near;
    for_each_cell(
        grid,
        [&](uint32_t cx, uint32_t cy, uint32_t cz, const PrunedCell& c) {
            if (culled)
                near.push_back({cx, cy, cz, c.tape, {}});
            else if (m == 1)
                bricks.add_candidate(cx, cy, cz, c.tape);
            else
                cubes_of(cx, cy, cz, 1, false, c.tape);
        },
        [&](uint32_t level, uint32_t cx, uint32_t cy, uint32_t cz) {
            const uint32_t span = g / grid.level_resolution(level);
            const uint32_t last = grid.level_resolution(level) - 1;
            if (cx == 0 || cy == 0 || cz == 0 || cx == last || cy == last || cz == last)
                cubes_of(cx, cy, cz, span, true, kNone);
        });
    if (!culled) return;
    // Stage 1b in parallel, a fixed number of cells per chunk; then the kept cubes in cell order.
    constexpr uint32_t kChunkCells = 64;
    const vec3 origin = sc.aabb.min, h = (sc.aabb.max - sc.aabb.min) / float(n);
    const uint32_t chunks = uint32_t((near.size() + kChunkCells - 1) / kChunkCells);
    parallel_for<MeshCancelled>(chunks, parallel_options(o, 0.0, 0.04), [&](uint64_t c) {
        thread_local std::vector<float> stack;
        stack.resize(size_t(std::max(sc.max_stack, 1u)) * kEvalLanes);
        const size_t end = std::min(near.size(), size_t(c + 1) * kChunkCells);
        for (size_t i = size_t(c) * kChunkCells; i < end; ++i)
            cull_cubes(sc, grid, n, m, origin, h, near[i], stack.data());
    });
    for (const NearCell& cell : near)
        bricks.add_kept_cubes(cell.x * m, cell.y * m, cell.z * m, m, cell.keep.data(), cell.tape);
}

// A tape for a corner when the grid's cells are not unions of cubes: a near-field cell
// holding the corner, or (empty) the full tree.
std::span<const uint32_t> held_tape(const PrunedGrid& grid, uint32_t n, CellCoord corner) {
    const uint32_t g = grid.resolution();
    uint32_t x0, x1, y0, y1, z0, z1;
    cell_range(corner.x, g, n, x0, x1);
    cell_range(corner.y, g, n, y0, y1);
    cell_range(corner.z, g, n, z0, z1);
    for (uint32_t cz = z0; cz <= z1; ++cz)
        for (uint32_t cy = y0; cy <= y1; ++cy)
            for (uint32_t cx = x0; cx <= x1; ++cx) {
                const CellView c = grid.cell(cx, cy, cz);
                if (!c.far_field) return c.tape;
            }
    return {};
}

// Stage 3's batches: needed corners that share a tape, evaluated together in vector lanes.
class CornerBatch {
  public:
    CornerBatch(const Scene& sc, Brick& b, uint32_t n, vec3 origin, vec3 h)
        : sc_(sc),
          b_(b),
          n_(n),
          origin_(origin),
          h_(h),
          on_aabb_(b.bx == 0 || b.by == 0 || b.bz == 0 || (b.bx + 1) * kB > n ||
                   (b.by + 1) * kB > n || (b.bz + 1) * kB > n) {
        thread_local std::vector<float> stack;
        stack.resize(size_t(std::max(sc.max_stack, 1u)) * kEvalLanes);
        stack_ = stack.data();
    }
    ~CornerBatch() { flush(); }
    // Corner l of the brick, with `tape`; the batch is evaluated when full or when the tape
    // changes.
    void add(std::span<const uint32_t> tape, uint32_t l) {
        if (count_ > 0 &&
            (count_ == kEvalLanes || tape.data() != tape_.data() || tape.size() != tape_.size()))
            flush();
        tape_ = tape;
        const CellCoord c = corner_at(b_, l);
        const vec3 p = origin_ + vec3(float(c.x), float(c.y), float(c.z)) * h_;
        points_.x[count_] = p.x;
        points_.y[count_] = p.y;
        points_.z[count_] = p.z;
        local_[count_++] = l;
    }
    // A corner whose value is known (a cap corner's far-field constant).
    void set(uint32_t l, float v) { b_.value[l] = capped(l, v); }
    void flush() {
        if (count_ == 0) return;
        float v[kEvalLanes];
        eval_tape_lanes(sc_, tape_, points_, count_, v, stack_);
        for (uint32_t i = 0; i < count_; ++i) b_.value[local_[i]] = capped(local_[i], v[i]);
        evaluated_ += count_;
        count_ = 0;
    }
    uint64_t evaluated() const { return evaluated_; }

  private:
    // Corners on the AABB count as outside: shapes cut by it are capped.
    float capped(uint32_t l, float v) const {
        if (!on_aabb_) return v;
        const CellCoord c = corner_at(b_, l);
        const bool on_aabb =
            c.x == 0 || c.y == 0 || c.z == 0 || c.x == n_ || c.y == n_ || c.z == n_;
        return on_aabb ? std::max(v, 0.0f) : v;
    }

    const Scene& sc_;
    Brick& b_;
    uint32_t n_;
    vec3 origin_, h_;
    bool on_aabb_;  // the brick holds corners on the AABB
    float* stack_;
    PointLanes points_;
    uint32_t local_[kEvalLanes];
    std::span<const uint32_t> tape_;
    uint32_t count_ = 0;
    uint64_t evaluated_ = 0;
};

// Stage 4a for one brick, after its corners' signs are known: its crossing cubes (candidates
// whose corners differ in sign) and their sign cases; returns the triangles they make.
uint32_t classify_cubes(Brick& b) {
    uint32_t triangles = 0;
    for (uint32_t z = 0; z < kB; ++z) {
        b.cross[z] = 0;
        if (b.cand[z] == 0) continue;
        uint64_t corner_in[8];  // bit l: corner k of cube l is inside
        uint64_t all = ~0ull, any = 0;
        for (uint32_t k = 0; k < 8; ++k) {
            corner_in[k] =
                shifted(b, &Brick::inside, z, int(k & 1), int((k >> 1) & 1), int(k >> 2));
            all &= corner_in[k];
            any |= corner_in[k];
        }
        b.cross[z] = b.cand[z] & any & ~all;
        for (uint64_t bits = b.cross[z]; bits; bits &= bits - 1) {
            const uint32_t at = uint32_t(std::countr_zero(bits));
            uint32_t inside = 0;
            for (uint32_t k = 0; k < 8; ++k) inside |= uint32_t((corner_in[k] >> at) & 1) << k;
            b.cube_case[z * 64 + at] = uint8_t(inside);
            triangles += kCubes[inside].triangles;
        }
    }
    return triangles;
}

// Stage 5 for one brick: the triangles of its crossing cubes, written from `out` on.
void polygonize_brick(const Brick& b, const std::vector<vec3>& vertices, uint32_t* out) {
    for (uint32_t z = 0; z < kB; ++z) {
        for (uint64_t bits = b.cross[z]; bits; bits &= bits - 1) {
            const uint32_t l = z * 64 + uint32_t(std::countr_zero(bits));
            CornerRef c[8];
            for (uint32_t k = 0; k < 8; ++k) c[k] = moved_up(b, l, k);
            const CubeCase& cc = kCubes[b.cube_case[l]];
            for (uint32_t t = 0; t < cc.count; ++t) {
                const TetCase& tc = cc.tet[t];
                uint32_t q[4] = {};
                for (uint32_t k = 0; k < tc.n; ++k) {
                    const uint8_t lo = tc.lo[k];
                    q[k] = vertex(*c[lo].brick, c[lo].local, uint32_t(lo ^ tc.hi[k]));
                }
                if (tc.n == 3) {
                    out[0] = q[0], out[1] = q[1], out[2] = q[2];
                    out += 3;
                    continue;
                }
                // A quad: split along its shorter diagonal.
                const auto dist2 = [&](uint32_t a, uint32_t b) {
                    const vec3 e = vertices[a] - vertices[b];
                    return math::dot(e, e);
                };
                if (dist2(q[0], q[2]) <= dist2(q[1], q[3]))
                    out[0] = q[0], out[1] = q[1], out[2] = q[2], out[3] = q[0], out[4] = q[2],
                    out[5] = q[3];
                else
                    out[0] = q[0], out[1] = q[1], out[2] = q[3], out[3] = q[1], out[4] = q[2],
                    out[5] = q[3];
                out += 6;
            }
        }
    }
}

Mesh extract(const Scene& sc, const PrunedGrid* grid, const MeshOptions& o, MeshStats* stats) {
    const auto t0 = std::chrono::steady_clock::now();
    const uint32_t n = o.resolution;
    if (n < 1 || n > kMaxMeshResolution)
        throw std::invalid_argument("mesh resolution must be in 1.." +
                                    std::to_string(kMaxMeshResolution) + " (got " +
                                    std::to_string(n) + ")");
    const vec3 origin = sc.aabb.min;
    const vec3 h = (sc.aabb.max - sc.aabb.min) / float(n);
    const auto corner = [&](uint32_t x, uint32_t y, uint32_t z) {
        return origin + vec3(float(x), float(y), float(z)) * h;
    };

    // Stage 1: candidate cubes. When the grid's cells are unions of cubes, each keeps its
    // cell's tape.
    const uint32_t g = grid ? grid->resolution() : 0;
    CornerBricks bricks(n, grid && n % g == 0);
    if (grid)
        add_candidates(*grid, n, bricks, o);
    else
        bricks.add_all_cubes();
    bricks.finish();
    const uint32_t count = bricks.count();
    // Stage 3 takes a cell's own cubes together where cells tile the bricks (cell_step cubes
    // per axis); elsewhere one cube at a time.
    const uint32_t cubes_per_cell = bricks.with_tapes() ? n / g : 1;
    const uint32_t cell_step = kB % cubes_per_cell == 0 ? cubes_per_cell : 1;
    uint64_t cell_square = 0;  // a cell's cubes in the layer word, at x = y = 0
    for (uint32_t y = 0; y < cell_step; ++y) cell_square |= ((1ull << cell_step) - 1) << (kB * y);

    Mesh mesh;
    std::atomic<uint64_t> evaluated{0};

    {
        // Stage 2: needed corners.
        parallel_stage(count, o, 0.04, 0.05, [&](uint32_t i) { compute_needed(bricks[i]); });

        // Stage 3: every needed corner evaluated once, in batches sharing a tape.
        parallel_stage(count, o, 0.05, 0.8, [&](uint32_t i) {
            Brick& b = bricks[i];
            {
                CornerBatch batch(sc, b, n, origin, h);
                if (!grid) {
                    for (uint32_t word = 0; word < kB; ++word)
                        for (uint64_t bits = b.need[word]; bits; bits &= bits - 1)
                            batch.add(sc.full_tape, word * 64 + uint32_t(std::countr_zero(bits)));
                } else if (!bricks.with_tapes()) {
                    for (uint32_t word = 0; word < kB; ++word)
                        for (uint64_t bits = b.need[word]; bits; bits &= bits - 1) {
                            const uint32_t l = word * 64 + uint32_t(std::countr_zero(bits));
                            const std::span<const uint32_t> t =
                                held_tape(*grid, n, corner_at(b, l));
                            batch.add(t.empty() ? std::span<const uint32_t>(sc.full_tape) : t, l);
                        }
                } else {
                    // The corners of each near-field cell's own cubes first, cell by cell (a
                    // cube is named by its lowest corner); then the others, held by cubes of
                    // other bricks or by cap cubes only. A corner of the cap only, when the
                    // cells are the cubes: f has the sign of their constant on all of them, so
                    // every Kuhn edge from it crosses only towards a capped AABB corner (value
                    // 0), where t = 0 or 1 whatever this corner's magnitude: the constant gives
                    // the naive mesh. Otherwise the full tree.
                    uint64_t rest[kB];
                    std::copy_n(b.need, kB, rest);
                    const auto own = [&](uint32_t l) {
                        if (b.tape[l] == kNone) return;  // a cap cube
                        batch.add(grid->tape_at(b.tape[l]), l);
                        rest[l >> 6] &= ~(1ull << (l & 63));
                    };
                    if (cell_step == 1) {
                        for (uint32_t z = 0; z < kB; ++z)
                            for (uint64_t bits = b.cand[z]; bits; bits &= bits - 1)
                                own(z * 64 + uint32_t(std::countr_zero(bits)));
                    } else {
                        for (uint32_t cz = 0; cz < kB; cz += cell_step)
                            for (uint32_t cy = 0; cy < kB; cy += cell_step)
                                for (uint32_t cx = 0; cx < kB; cx += cell_step) {
                                    const uint64_t square = cell_square << (cx + kB * cy);
                                    for (uint32_t z = cz; z < cz + cell_step; ++z)
                                        for (uint64_t bits = b.cand[z] & square; bits;
                                             bits &= bits - 1)
                                            own(z * 64 + uint32_t(std::countr_zero(bits)));
                                }
                    }
                    // A corner held by cube u - s (s in {0, 1}³ \ {0}), the first s as in
                    // corner_tape; taken a direction at a time, so that a cell's corners stay
                    // together.
                    for (uint32_t s = 1; s < 8; ++s) {
                        const int sx = -int(s & 1), sy = -int((s >> 1) & 1), sz = -int(s >> 2);
                        for (uint32_t z = 0; z < kB; ++z) {
                            if (rest[z] == 0) continue;
                            uint64_t held = rest[z] & shifted(b, &Brick::cand, z, sx, sy, sz);
                            for (; held; held &= held - 1) {
                                const uint32_t l = z * 64 + uint32_t(std::countr_zero(held));
                                const CornerRef c = moved(b, l, sx, sy, sz);
                                if (c.brick->tape[c.local] == kNone) continue;  // a cap cube
                                batch.add(grid->tape_at(c.brick->tape[c.local]), l);
                                rest[z] &= ~(1ull << (l & 63));
                            }
                        }
                    }
                    // Corners of cap cubes only.
                    for (uint32_t word = 0; word < kB; ++word)
                        for (uint64_t bits = rest[word]; bits; bits &= bits - 1) {
                            const uint32_t l = word * 64 + uint32_t(std::countr_zero(bits));
                            if (cubes_per_cell != 1) {
                                batch.add(sc.full_tape, l);
                                continue;
                            }
                            const CellCoord c = corner_at(b, l);
                            batch.set(l, grid->cell(std::min(c.x, n - 1), std::min(c.y, n - 1),
                                                    std::min(c.z, n - 1))
                                             .constant);
                        }
                }
                batch.flush();
                evaluated += batch.evaluated();
            }
            for (uint32_t z = 0; z < kB; ++z) {
                uint64_t in = 0;
                for (uint64_t bits = b.need[z]; bits; bits &= bits - 1) {
                    const uint32_t at = uint32_t(std::countr_zero(bits));
                    if (b.value[z * 64 + at] < 0.0f) in |= 1ull << at;
                }
                b.inside[z] = in;
            }
        });

        // Stage 4a: which edges carry a vertex, numbered within each brick; which cubes cross
        // the surface, and the triangles they make.
        std::vector<uint32_t> tri_count(count);
        parallel_stage(count, o, 0.8, 0.85, [&](uint32_t i) {
            bricks[i].vbase = mark_vertex_edges(bricks[i]);
            tri_count[i] = classify_cubes(bricks[i]);
        });
        uint64_t total = 0, total_tris = 0;
        for (uint32_t i = 0; i < count; ++i) {
            const uint64_t c = bricks[i].vbase;
            bricks[i].vbase = uint32_t(total);
            total += c;
            if (total > 0xffffffffull) throw std::length_error("mesh has more than 2^32 vertices");
            bricks[i].tbase = uint32_t(total_tris);
            total_tris += tri_count[i];
            if (total_tris * 3 > 0xffffffffull)
                throw std::length_error("mesh has more than 2^32 triangle indices");
        }
        mesh.vertices.resize(total);
        mesh.triangles.resize(total_tris * 3);

        // Stage 4b: vertex positions, where f's linear interpolation along the edge is zero.
        parallel_stage(count, o, 0.85, 0.9, [&](uint32_t i) {
            const Brick& b = bricks[i];
            for (uint32_t word = 0; word < kB; ++word) {
                for (uint64_t bits = b.has_vertex[word]; bits; bits &= bits - 1) {
                    const uint32_t l = word * 64 + uint32_t(std::countr_zero(bits));
                    const CellCoord c = corner_at(b, l);
                    const float fu = b.value[l];
                    const vec3 pu = corner(c.x, c.y, c.z);
                    uint32_t id = b.vbase + b.voff[l];
                    for (uint32_t mask = b.vmask[l]; mask; mask &= mask - 1) {
                        const uint32_t d = uint32_t(std::countr_zero(mask)) + 1;
                        const CornerRef v = moved_up(b, l, d);
                        const float fv = v.brick->value[v.local];
                        const float t =
                            std::clamp(fu / (fu - fv), kMinEdgeFraction, 1.0f - kMinEdgeFraction);
                        const vec3 pv = corner(c.x + (d & 1), c.y + ((d >> 1) & 1), c.z + (d >> 2));
                        mesh.vertices[id++] = pu + (pv - pu) * t;
                    }
                }
            }
        });

        // Stage 5: triangles, each brick's at its place.
        parallel_stage(count, o, 0.9, 0.99, [&](uint32_t i) {
            polygonize_brick(bricks[i], mesh.vertices,
                             mesh.triangles.data() + size_t(bricks[i].tbase) * 3);
        });
    }
    if (o.progress) o.progress(1.0);
    if (stats) {
        uint64_t cubes = 0;  // the candidates
        for (uint32_t i = 0; i < count; ++i)
            for (const uint64_t w : bricks[i].cand) cubes += uint64_t(std::popcount(w));
        stats->resolution = n;
        stats->cubes_visited = cubes;
        stats->corners_evaluated = evaluated;
        stats->brick_bytes = bricks.bytes();
        stats->ms = ms_since(t0);
    }
    return mesh;
}

}  // namespace

Mesh mesh(const PrunedGrid& grid, const MeshOptions& options, MeshStats* stats) {
    return extract(grid.scene(), &grid, options, stats);
}

Mesh mesh(const Scene& scene, const MeshOptions& options, MeshStats* stats) {
    return extract(scene, nullptr, options, stats);
}

}  // namespace sdfprune
