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

// ---- bricks of grid corners ------------------------------------------------------------------

constexpr uint32_t kB = 8;  // corners per brick axis
constexpr uint32_t kBrickCorners = kB * kB * kB;
constexpr uint64_t kCol0 = 0x0101010101010101ull;  // x = 0 in every row of an xy layer word

// Local index offset of cube corner k (x + 2y + 4z) from the cube's lowest corner, same brick.
constexpr uint32_t kCornerOffset[8] = {0,      1,          kB,          kB + 1,
                                       kB* kB, kB* kB + 1, kB* kB + kB, kB* kB + kB + 1};

// Local index of a corner inside its brick: x + 8y + 64z; one uint64 word per z layer.
constexpr uint32_t local_index(uint32_t x, uint32_t y, uint32_t z) {
    return (x & 7u) | (y & 7u) << 3 | (z & 7u) << 6;
}
constexpr bool bit(const uint64_t* words, uint32_t l) {
    return (words[l >> 6] >> (l & 63)) & 1u;
}
// Bits set in a 7-bit edge mask (std::popcount may be a library call without -mpopcnt).
constexpr uint32_t popcount7(uint32_t m) {
    return (m & 1) + (m >> 1 & 1) + (m >> 2 & 1) + (m >> 3 & 1) + (m >> 4 & 1) + (m >> 5 & 1) +
           (m >> 6 & 1);
}

// 8³ grid corners, and the cubes having them as lowest corner. Arrays other than the masks are
// left uninitialized and written before being read.
struct Brick {
    uint32_t bx = 0, by = 0, bz = 0;  // brick coordinates
    uint32_t vbase = 0;               // the brick's first vertex
    uint64_t cand[kB] = {};           // candidate cubes, one word per z layer
    uint64_t need[kB] = {};           // corners to evaluate
    float value[kBrickCorners];       // needed corners: f, capped on the AABB
    uint8_t vmask[kBrickCorners];     // needed corners: bit d-1 = the edge along d has a vertex
    uint16_t voff[kBrickCorners];     // needed corners: first vertex, relative to vbase
    // Candidate cubes, when cubes are the pruned grid's cells: the cell's tape (its offset in
    // the tape pool), or kNone for a far-field cell (a cap cube).
    std::unique_ptr<uint32_t[]> tape;
};

class CornerBricks {
  public:
    CornerBricks(uint32_t n, bool with_tapes) : n_(n), nb_((n + kB) / kB), with_tapes_(with_tapes) {
        slot_of_.assign(size_t(nb_) * nb_ * nb_, kNone);
    }

    // Stage 1, serial: marks cube (x, y, z) as a candidate and allocates the bricks holding its
    // corners. `tape` is stored when the bricks keep tapes.
    void add_candidate(uint32_t x, uint32_t y, uint32_t z, uint32_t tape = kNone) {
        Brick& b = allocate(x / kB, y / kB, z / kB);
        const uint32_t l = local_index(x, y, z);
        b.cand[l >> 6] |= 1ull << (l & 63);
        if (with_tapes_) b.tape[l] = tape;
        const uint32_t ex = x % kB == kB - 1, ey = y % kB == kB - 1, ez = z % kB == kB - 1;
        if (ex | ey | ez)
            for (uint32_t dz = 0; dz <= ez; ++dz)
                for (uint32_t dy = 0; dy <= ey; ++dy)
                    for (uint32_t dx = 0; dx <= ex; ++dx)
                        allocate(x / kB + dx, y / kB + dy, z / kB + dz);
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
    // Ends stage 1: the bricks in brick order (z-major), the order of every later stage.
    void finish() {
        order_.clear();
        for (const uint32_t s : slot_of_)
            if (s != kNone) order_.push_back(bricks_[s].get());
    }
    uint32_t count() const { return uint32_t(order_.size()); }
    Brick& operator[](uint32_t i) const { return *order_[i]; }

    // Stage 2 for one brick: a corner is needed iff one of the (up to 8) cubes having it as a
    // corner is a candidate: the candidate masks dilated by one towards +x, +y, +z.
    void compute_needed(Brick& b) const {
        const int bx = int(b.bx), by = int(b.by), bz = int(b.bz);
        for (uint32_t z = 0; z < kB; ++z)
            b.need[z] = dilate_xy(bx, by, bz, z) |
                        (z > 0 ? dilate_xy(bx, by, bz, z - 1) : dilate_xy(bx, by, bz - 1, kB - 1));
    }

    // The brick holding corner (x, y, z) (coordinates <= n), or null.
    const Brick* find(uint32_t x, uint32_t y, uint32_t z) const {
        const uint32_t s = slot_of_[brick_index(x / kB, y / kB, z / kB)];
        return s == kNone ? nullptr : bricks_[s].get();
    }
    // The tape stored with cube (x, y, z) (any integers; bricks keeping tapes): kNone when it is
    // not a candidate or its cell is far-field.
    uint32_t cube_tape(int64_t x, int64_t y, int64_t z) const {
        if (x < 0 || y < 0 || z < 0 || x >= n_ || y >= n_ || z >= n_) return kNone;
        const Brick* b = find(uint32_t(x), uint32_t(y), uint32_t(z));
        const uint32_t l = local_index(uint32_t(x), uint32_t(y), uint32_t(z));
        return b && bit(b->cand, l) ? b->tape[l] : kNone;
    }
    // Whether cube (x, y, z) (any integers) is a candidate.
    bool candidate(int64_t x, int64_t y, int64_t z) const {
        if (x < 0 || y < 0 || z < 0 || x >= n_ || y >= n_ || z >= n_) return false;
        const Brick* b = find(uint32_t(x), uint32_t(y), uint32_t(z));
        return b && bit(b->cand, local_index(uint32_t(x), uint32_t(y), uint32_t(z)));
    }
    // Where the 8 corners of cube (x, y, z) are stored, corner k as in kCornerOffset.
    void cube_corners(uint32_t x, uint32_t y, uint32_t z, const Brick* brick[8],
                      uint32_t local[8]) const {
        if (x % kB < kB - 1 && y % kB < kB - 1 && z % kB < kB - 1) {
            const Brick* b = find(x, y, z);
            const uint32_t l = local_index(x, y, z);
            for (uint32_t k = 0; k < 8; ++k) {
                brick[k] = b;
                local[k] = l + kCornerOffset[k];
            }
            return;
        }
        for (uint32_t k = 0; k < 8; ++k) {
            const uint32_t cx = x + (k & 1), cy = y + ((k >> 1) & 1), cz = z + (k >> 2);
            brick[k] = find(cx, cy, cz);
            local[k] = local_index(cx, cy, cz);
        }
    }
    // The vertex on the edge from corner `l` of brick `b` along d (1..7); it must exist.
    static uint32_t vertex(const Brick& b, uint32_t l, uint32_t d) {
        return b.vbase + b.voff[l] + popcount7(b.vmask[l] & ((1u << (d - 1)) - 1));
    }

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
    uint64_t cand_word(int bx, int by, int bz, uint32_t z) const {
        if (bx < 0 || by < 0 || bz < 0) return 0;
        const uint32_t s = slot_of_[brick_index(uint32_t(bx), uint32_t(by), uint32_t(bz))];
        return s == kNone ? 0 : bricks_[s]->cand[z];
    }
    // Corners (x, y) of layer z of brick (bx, by, bz) that are a corner of a candidate cube of
    // that same layer: cubes (x, y), (x-1, y), (x, y-1), (x-1, y-1), reaching into the -x/-y
    // neighbour bricks.
    uint64_t dilate_xy(int bx, int by, int bz, uint32_t z) const {
        const uint64_t w00 = cand_word(bx, by, bz, z), w10 = cand_word(bx - 1, by, bz, z);
        const uint64_t w01 = cand_word(bx, by - 1, bz, z), w11 = cand_word(bx - 1, by - 1, bz, z);
        const auto sx = [](uint64_t a, uint64_t b) {  // x - 1 -> x, b = the -x neighbour
            return ((a << 1) & ~kCol0) | ((b >> (kB - 1)) & kCol0);
        };
        const auto sy = [](uint64_t a, uint64_t b) {  // y - 1 -> y, b = the -y neighbour
            return (a << kB) | (b >> (kB * (kB - 1)));
        };
        const uint64_t x0 = sx(w00, w10), x1 = sx(w01, w11);
        return w00 | x0 | sy(w00, w01) | sy(x0, x1);
    }

    uint32_t n_, nb_;
    bool with_tapes_;
    std::vector<uint32_t> slot_of_;  // per brick index: its slot in bricks_, kNone if absent
    std::vector<std::unique_ptr<Brick>> bricks_;  // in allocation order
    std::vector<Brick*> order_;                   // in brick order
};

// Runs fn(i) for i in [0, count) in parallel (one chunk per brick or triangle chunk); checks the
// cancel flag and reports progress in [lo, hi] from the calling thread.
template <class F>
void parallel_stage(uint32_t count, const MeshOptions& o, double lo, double hi, const F& fn) {
    parallel_for<MeshCancelled>(count, parallel_options(o, lo, hi),
                                [&](uint64_t i) { fn(uint32_t(i)); });
}

// Visits the grid's cells: near(ix, iy, iz, cell) for every near-field cell of the finest
// level, far(level, cx, cy, cz, cell) for every far-field cell, at the level where it became
// far.
template <class Near, class Far>
void for_each_cell(const PrunedGrid& g, const Near& near, const Far& far) {
    g.for_each_block([&](const PrunedGrid::Block& b) {
        const uint32_t f = g.level_factor(b.level);
        const PrunedCell* cells = g.level_cells(b.level).data() + b.first;
        const bool finest = b.level + 1 == g.level_count();
        for (uint32_t local = 0; local < f * f * f; ++local) {
            const PrunedCell& c = cells[local];
            const CellCoord at = block_cell(b.origin, f, local);
            if (c.tape == PrunedCell::kFarField)
                far(b.level, at.x, at.y, at.z, c);
            else if (finest)
                near(at.x, at.y, at.z, c);
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

// Stage 1 for a pruned grid: candidates are the cubes overlapping a near-field cell, and the
// cubes on the AABB's boundary overlapping an inside far-field cell (the cap, where f < 0
// meets the AABB: corners on the AABB count as outside).
void add_candidates(const PrunedGrid& grid, uint32_t n, CornerBricks& bricks) {
    const uint32_t g = grid.resolution();
    const auto cubes_of = [&](uint32_t cx, uint32_t cy, uint32_t cz, uint32_t span,
                              bool boundary_only) {
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
                for (uint32_t x = x0; x <= x1; ++x) bricks.add_candidate(x, y, z);
            }
    };
    for_each_cell(
        grid,
        [&](uint32_t cx, uint32_t cy, uint32_t cz, const PrunedCell& c) {
            if (g == n)
                bricks.add_candidate(cx, cy, cz, c.tape);
            else
                cubes_of(cx, cy, cz, 1, false);
        },
        [&](uint32_t level, uint32_t cx, uint32_t cy, uint32_t cz, const PrunedCell& c) {
            if (!(c.bound < 0.0f)) return;
            const uint32_t span = g / grid.level_resolution(level);
            const uint32_t last = grid.level_resolution(level) - 1;
            if (cx == 0 || cy == 0 || cz == 0 || cx == last || cy == last || cz == last)
                cubes_of(cx, cy, cz, span, true);
        });
}

// How the pruned version gets a corner's value.
struct CornerSource {
    std::span<const uint32_t> tape;  // a near-field cell's tape; empty: the full tree
    bool far_field = false;          // use `constant` instead of evaluating
    float constant = 0;
};

// The tape of a near-field cell holding corner (x, y, z): all of them give the full tree's value
// bit for bit. When none does and the cells are the cubes, the corner is a corner of the cap:
// f has the sign of their constant on all of them, so every Kuhn edge from it crosses only
// towards a capped AABB corner (value 0), where t = 0 or 1 whatever this corner's magnitude:
// the constant gives the naive mesh. Otherwise the full tree.
CornerSource corner_source(const PrunedGrid& grid, const CornerBricks& bricks, uint32_t n,
                           uint32_t x, uint32_t y, uint32_t z) {
    CornerSource src;
    const uint32_t g = grid.resolution();
    if (g == n) {
        // The holding cells are the cubes having the corner; the near-field ones are the
        // candidates with a tape.
        for (uint32_t s = 0; s < 8; ++s) {
            const uint32_t t = bricks.cube_tape(int64_t(x) - (s & 1), int64_t(y) - (s >> 1 & 1),
                                                int64_t(z) - (s >> 2));
            if (t != kNone) {
                src.tape = grid.tape_at(t);
                return src;
            }
        }
        src.far_field = true;
        src.constant =
            grid.cell(std::min(x, n - 1), std::min(y, n - 1), std::min(z, n - 1)).constant;
        return src;
    }
    uint32_t x0, x1, y0, y1, z0, z1;
    cell_range(x, g, n, x0, x1);
    cell_range(y, g, n, y0, y1);
    cell_range(z, g, n, z0, z1);
    for (uint32_t cz = z0; cz <= z1; ++cz)
        for (uint32_t cy = y0; cy <= y1; ++cy)
            for (uint32_t cx = x0; cx <= x1; ++cx) {
                const CellView c = grid.cell(cx, cy, cz);
                if (!c.far_field) {
                    src.tape = c.tape;
                    return src;
                }
            }
    return src;
}

// Stage 5 for one cube: appends the triangles of its 6 tetrahedra to `out`.
void polygonize_cube(const CornerBricks& bricks, uint32_t x, uint32_t y, uint32_t z,
                     const std::vector<vec3>& vertices, std::vector<uint32_t>& out) {
    const Brick* cb[8];
    uint32_t cl[8];
    bricks.cube_corners(x, y, z, cb, cl);
    uint32_t inside = 0;  // bit k: cube corner k is inside
    for (uint32_t k = 0; k < 8; ++k)
        if (cb[k]->value[cl[k]] < 0.0f) inside |= 1u << k;
    if (inside == 0 || inside == 0xff) return;
    for (uint32_t t = 0; t < 6; ++t) {
        uint32_t m = 0;
        for (uint32_t k = 0; k < 4; ++k) m |= ((inside >> kTetVertices[t][k]) & 1u) << k;
        const TetCase& tc = kTets[t][m];
        if (tc.n == 0) continue;
        uint32_t q[4] = {};
        for (uint32_t k = 0; k < tc.n; ++k) {
            const uint8_t lo = tc.lo[k];
            q[k] = CornerBricks::vertex(*cb[lo], cl[lo], uint32_t(lo ^ tc.hi[k]));
        }
        if (tc.n == 3) {
            out.insert(out.end(), {q[0], q[1], q[2]});
            continue;
        }
        // A quad: split along its shorter diagonal.
        const auto dist2 = [&](uint32_t a, uint32_t b) {
            const vec3 e = vertices[a] - vertices[b];
            return math::dot(e, e);
        };
        if (dist2(q[0], q[2]) <= dist2(q[1], q[3]))
            out.insert(out.end(), {q[0], q[1], q[2], q[0], q[2], q[3]});
        else
            out.insert(out.end(), {q[0], q[1], q[3], q[1], q[2], q[3]});
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
    // Corners on the AABB count as outside: shapes cut by it are capped.
    const auto cap = [n](uint32_t x, uint32_t y, uint32_t z, float v) {
        return x == 0 || y == 0 || z == 0 || x == n || y == n || z == n ? std::max(v, 0.0f) : v;
    };

    // Stage 1: candidate cubes. When they are the grid's cells, each keeps its cell's tape.
    CornerBricks bricks(n, grid && grid->resolution() == n);
    if (grid)
        add_candidates(*grid, n, bricks);
    else
        bricks.add_all_cubes();
    bricks.finish();
    const uint32_t count = bricks.count();

    Mesh mesh;
    std::vector<std::vector<uint32_t>> tri_chunks;
    constexpr uint32_t kChunkBricks = 8;  // bricks per triangle chunk: fixed, for determinism
    std::atomic<uint64_t> cubes{0}, evaluated{0};

    {
        // Stages 2 and 3: needed corners, each evaluated once.
        parallel_stage(count, o, 0.0, 0.85, [&](uint32_t i) {
            Brick& b = bricks[i];
            bricks.compute_needed(b);
            thread_local std::vector<float> stack;
            stack.resize(sc.max_stack);
            uint64_t done = 0;
            for (uint32_t word = 0; word < kB; ++word) {
                for (uint64_t bits = b.need[word]; bits; bits &= bits - 1) {
                    const uint32_t l = word * 64 + uint32_t(std::countr_zero(bits));
                    const uint32_t x = b.bx * kB + (l & 7), y = b.by * kB + ((l >> 3) & 7),
                                   z = b.bz * kB + (l >> 6);
                    std::span<const uint32_t> tape = sc.full_tape;
                    if (grid) {
                        const CornerSource src = corner_source(*grid, bricks, n, x, y, z);
                        if (src.far_field) {
                            b.value[l] = cap(x, y, z, src.constant);
                            continue;
                        }
                        if (!src.tape.empty()) tape = src.tape;
                    }
                    b.value[l] = cap(x, y, z, eval_tape(sc, tape, corner(x, y, z), stack.data()));
                    ++done;
                }
            }
            evaluated += done;
        });

        // Stage 4a: which edges carry a vertex, numbered within each brick.
        parallel_stage(count, o, 0.85, 0.9, [&](uint32_t i) {
            Brick& b = bricks[i];
            uint32_t vertices = 0;
            for (uint32_t word = 0; word < kB; ++word) {
                for (uint64_t bits = b.need[word]; bits; bits &= bits - 1) {
                    const uint32_t l = word * 64 + uint32_t(std::countr_zero(bits));
                    const uint32_t x = b.bx * kB + (l & 7), y = b.by * kB + ((l >> 3) & 7),
                                   z = b.bz * kB + (l >> 6);
                    const bool in = b.value[l] < 0.0f;
                    const bool inner = (l & 7) < kB - 1 && ((l >> 3) & 7) < kB - 1 &&
                                       (l >> 6) < kB - 1;  // its +1 neighbours in this brick
                    uint8_t mask = 0;
                    for (uint32_t d = 1; d < 8; ++d) {
                        const Brick* vb = &b;
                        uint32_t vl = l + kCornerOffset[d];
                        if (!inner) {
                            const uint32_t vx = x + (d & 1), vy = y + ((d >> 1) & 1),
                                           vz = z + (d >> 2);
                            if (vx > n || vy > n || vz > n) continue;
                            vb = bricks.find(vx, vy, vz);
                            if (!vb) continue;
                            vl = local_index(vx, vy, vz);
                        }
                        if (!bit(vb->need, vl) || (vb->value[vl] < 0.0f) == in) continue;
                        // Used by a candidate cube? Those holding the edge: (x, y, z) minus
                        // any subset of the axes the edge does not move along.
                        const uint32_t free = ~d & 7u;
                        bool used = false;
                        for (uint32_t s = 0;; s = (s - free) & free) {
                            used =
                                bricks.candidate(int64_t(x) - (s & 1), int64_t(y) - ((s >> 1) & 1),
                                                 int64_t(z) - (s >> 2));
                            if (used || s == free) break;
                        }
                        if (used) mask |= uint8_t(1u << (d - 1));
                    }
                    b.vmask[l] = mask;
                    b.voff[l] = uint16_t(vertices);
                    vertices += popcount7(mask);
                }
            }
            b.vbase = vertices;  // the count, until the prefix sum below
        });
        uint64_t total = 0;
        for (uint32_t i = 0; i < count; ++i) {
            const uint64_t c = bricks[i].vbase;
            bricks[i].vbase = uint32_t(total);
            total += c;
            if (total > 0xffffffffull) throw std::length_error("mesh has more than 2^32 vertices");
        }
        mesh.vertices.resize(total);

        // Stage 4b: vertex positions, where f's linear interpolation along the edge is zero.
        parallel_stage(count, o, 0.9, 0.92, [&](uint32_t i) {
            const Brick& b = bricks[i];
            for (uint32_t word = 0; word < kB; ++word) {
                for (uint64_t bits = b.need[word]; bits; bits &= bits - 1) {
                    const uint32_t l = word * 64 + uint32_t(std::countr_zero(bits));
                    if (!b.vmask[l]) continue;
                    const uint32_t x = b.bx * kB + (l & 7), y = b.by * kB + ((l >> 3) & 7),
                                   z = b.bz * kB + (l >> 6);
                    const float fu = b.value[l];
                    const vec3 pu = corner(x, y, z);
                    uint32_t id = b.vbase + b.voff[l];
                    for (uint32_t d = 1; d < 8; ++d) {
                        if (!(b.vmask[l] >> (d - 1) & 1)) continue;
                        const uint32_t vx = x + (d & 1), vy = y + ((d >> 1) & 1), vz = z + (d >> 2);
                        const float fv = bricks.find(vx, vy, vz)->value[local_index(vx, vy, vz)];
                        const float t =
                            std::clamp(fu / (fu - fv), kMinEdgeFraction, 1.0f - kMinEdgeFraction);
                        const vec3 pv = corner(vx, vy, vz);
                        mesh.vertices[id++] = pu + (pv - pu) * t;
                    }
                }
            }
        });

        // Stage 5: triangles, per fixed chunk of bricks, concatenated in order.
        const uint32_t chunks = (count + kChunkBricks - 1) / kChunkBricks;
        tri_chunks.resize(chunks);
        parallel_stage(chunks, o, 0.92, 0.99, [&](uint32_t c) {
            std::vector<uint32_t>& out = tri_chunks[c];
            uint64_t visited = 0;
            for (uint32_t i = c * kChunkBricks; i < std::min(count, (c + 1) * kChunkBricks); ++i) {
                const Brick& b = bricks[i];
                for (uint32_t word = 0; word < kB; ++word) {
                    for (uint64_t bits = b.cand[word]; bits; bits &= bits - 1) {
                        const uint32_t l = word * 64 + uint32_t(std::countr_zero(bits));
                        const uint32_t x = b.bx * kB + (l & 7), y = b.by * kB + ((l >> 3) & 7),
                                       z = b.bz * kB + (l >> 6);
                        ++visited;
                        polygonize_cube(bricks, x, y, z, mesh.vertices, out);
                    }
                }
            }
            cubes += visited;
        });
    }

    size_t tri_words = 0;
    for (const auto& c : tri_chunks) tri_words += c.size();
    mesh.triangles.reserve(tri_words);
    for (auto& c : tri_chunks) {
        mesh.triangles.insert(mesh.triangles.end(), c.begin(), c.end());
        std::vector<uint32_t>().swap(c);
    }
    if (o.progress) o.progress(1.0);
    if (stats) {
        stats->resolution = n;
        stats->cubes_visited = cubes;
        stats->corners_evaluated = evaluated;
        stats->brick_bytes = bricks.bytes();
        stats->ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                        .count();
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
