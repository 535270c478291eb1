// architecture.cpp — buildings and landscapes: "city" (street grid of blocks with towers whose
// ribbon windows are cut out, round towers made by intersections, gabled houses and parks; any
// number of primitives), "monument" (a domed, colonnaded capitol: fluted columns, pediments,
// balustrades, windows; 3012 primitives) and "trees" (a forest of low-poly trees and rocks on a
// ground slab, a left-deep smooth chain like the reference trees.json; 185 primitives).
#include <algorithm>
#include <array>

#include "generate_internal.hpp"

namespace sdfprune::gen {
namespace {

vec4 corners(float r) {
    return {r, r, r, r};
}

// ---- city ------------------------------------------------------------------------------------

constexpr float kBlock = 12;  // block side, metres
constexpr float kStreet = 6;  // street width
constexpr vec3 kWindowGlass{0.1f, 0.14f, 0.2f};
constexpr std::array<vec3, 6> kFacades = {vec3{0.78f, 0.76f, 0.72f}, vec3{0.62f, 0.35f, 0.28f},
                                          vec3{0.85f, 0.82f, 0.7f},  vec3{0.45f, 0.5f, 0.55f},
                                          vec3{0.9f, 0.9f, 0.92f},   vec3{0.7f, 0.6f, 0.45f}};

// A building of exactly `n` (>= 3) primitives on a footprint w × d centred at the origin.
// Towers: floor slabs between window bands cut through the body onto a dark glass core.
Shape building(SceneBuilder& b, Rng& rng, uint32_t n, float w, float d, float height) {
    const vec3 facade = vary(pick(kFacades, rng), 0.05f, rng);
    const float r = rng.uniform();
    if (n >= 4 && r < 0.25f) {
        // Round tower: a cylinder cut flat on two sides (intersection), glass core, bands,
        // a cone spire.
        const float rad = 0.5f * std::max(w, d);
        const float h = height * 1.1f;
        Shape body = b.cylinder(rad, h).translated({0, h / 2, 0}).colored(facade) &
                     b.box({w, h + 1, d}).translated({0, h / 2, 0}).colored(facade);
        const uint32_t bands = n - 4;
        std::vector<Shape> cuts;
        for (uint32_t i = 0; i < bands; ++i)
            cuts.push_back(b.box({w + 2, 0.45f * h / float(bands + 1), d + 2})
                               .translated({0, h * (float(i) + 0.6f) / float(bands + 1), 0}));
        if (!cuts.empty()) body = body - union_all(cuts);
        body =
            body | b.cylinder(rad - 0.4f, h - 0.2f).translated({0, h / 2, 0}).colored(kWindowGlass);
        return body | b.cone(rad * 0.5f, h * 0.25f)
                          .translated({0, h * 1.125f, 0})
                          .colored({0.7f, 0.72f, 0.75f});
    }
    if (height < 12 && r < 0.5f) {
        // Gabled house: a box with a roof made of a box turned 45° cut by the footprint
        // (intersection) and windows cut through onto a dark core.
        const float h = std::min(height, 8.0f);
        const float roof = 0.5f * d;
        const vec3 tiles{0.55f, 0.2f, 0.15f};
        Shape body = b.box({w, h, d}).translated({0, h / 2, 0}).colored(facade);
        Shape gable =
            b.box({w * 1.02f, roof * 1.414f, roof * 1.414f})
                .rotated({1, 0, 0}, kPi / 4)
                .translated({0, h, 0})
                .colored(tiles) &
            b.box({w * 1.04f, roof, d * 1.02f}).translated({0, h + roof / 2, 0}).colored(tiles);
        const uint32_t extra = n - 3;  // a door, or windows cut onto a dark core
        if (extra == 1)
            body = body | b.box({w * 0.2f, h * 0.4f, 0.2f})
                              .translated({0, h * 0.2f, d / 2})
                              .colored(kWindowGlass);
        if (extra >= 2) {
            std::vector<Shape> cuts;
            for (uint32_t i = 0; i + 1 < extra; ++i) {
                const float x = -w / 2 + w * (float(i) + 0.5f) / float(extra - 1);
                cuts.push_back(b.box({0.5f * w / float(extra - 1), 0.4f * h, d + 1})
                                   .translated({x, h * 0.5f, 0}));
            }
            body = (body - union_all(cuts)) | b.box({w - 0.6f, h - 0.4f, d - 0.6f})
                                                  .translated({0, h / 2, 0})
                                                  .colored(kWindowGlass);
        }
        return body | gable;
    }
    // Ribbon-window tower with an optional rooftop unit.
    const bool roof_unit = n >= 4 && rng.uniform() < 0.6f;
    const uint32_t bands = n - 2 - (roof_unit ? 1 : 0);
    const float h = height;
    Shape body = b.box({w, h, d}, corners(rng.uniform() < 0.3f ? 0.8f : 0.0f))
                     .translated({0, h / 2, 0})
                     .colored(facade);
    std::vector<Shape> cuts;
    for (uint32_t i = 0; i < bands; ++i)
        cuts.push_back(b.box({w + 2, 0.5f * h / float(bands + 1), d + 2})
                           .translated({0, h * (float(i) + 0.75f) / float(bands + 1), 0}));
    body = (body - union_all(cuts)) |
           b.box({w - 0.7f, h - 0.2f, d - 0.7f}).translated({0, h / 2, 0}).colored(kWindowGlass);
    if (roof_unit) {
        Shape unit = rng.uniform() < 0.5f
                         ? b.box({w * 0.4f, 2.0f, d * 0.4f}).translated({0, h + 1.0f, 0})
                         : b.cylinder(std::min(w, d) * 0.18f, 2.5f)
                               .translated({w * 0.2f, h + 1.25f, d * 0.15f});
        body = body | unit.colored({0.55f, 0.55f, 0.57f});
    }
    return body;
}

// A park: a green slab, trees (trunk and crown blended), bushes; exactly `n` primitives.
Shape park(SceneBuilder& b, Rng& rng, uint32_t n) {
    std::vector<Shape> parts = {b.box({kBlock + 1, 0.3f, kBlock + 1}, corners(1), 0.1f)
                                    .translated({0, 0.15f, 0})
                                    .colored({0.3f, 0.55f, 0.25f})};
    uint32_t left = n - 1;
    while (left > 0) {
        const float x = rng.uniform(-5, 5), z = rng.uniform(-5, 5), s = rng.uniform(0.7f, 1.3f);
        const vec3 leaf = vary({0.2f, 0.5f, 0.18f}, 0.08f, rng);
        if (left >= 2) {
            Shape trunk = b.cylinder(0.2f * s, 3 * s)
                              .translated({x, 1.5f * s, z})
                              .colored({0.4f, 0.28f, 0.15f});
            parts.push_back(smooth_union(
                trunk, b.sphere(1.5f * s).translated({x, 3.6f * s, z}).colored(leaf), 0.3f));
            left -= 2;
        } else {
            parts.push_back(b.sphere(0.8f * s).translated({x, 0.3f, z}).colored(leaf));
            left -= 1;
        }
    }
    return union_all(parts);
}

// ---- monument --------------------------------------------------------------------------------

constexpr vec3 kMarble{0.9f, 0.88f, 0.82f};
constexpr vec3 kStone{0.78f, 0.75f, 0.68f};
constexpr uint32_t kFlutes = 12;
constexpr uint32_t kColumnPrimitives = 5 + kFlutes;

// A fluted column standing on `at`: plinth, base torus, shaft with flutes cut out, echinus
// torus, abacus. kColumnPrimitives primitives.
Shape column(SceneBuilder& b, vec3 at, float height, float radius) {
    const float shaft_h = height - 2.2f * radius;
    Shape shaft = b.cylinder(radius, shaft_h)
                      .translated({0, 0.8f * radius + shaft_h / 2, 0})
                      .colored(kMarble);
    std::vector<Shape> flutes;
    for (uint32_t i = 0; i < kFlutes; ++i) {
        const float a = 2 * kPi * float(i) / float(kFlutes);
        flutes.push_back(b.capsule(radius * 0.16f, shaft_h * 0.8f)
                             .translated({radius * 1.04f * std::cos(a), 0.8f * radius + shaft_h / 2,
                                          radius * 1.04f * std::sin(a)}));
    }
    Shape c = shaft - union_all(flutes);
    c = c | b.box({2.6f * radius, 0.4f * radius, 2.6f * radius})
                .translated({0, 0.2f * radius, 0})
                .colored(kStone);
    c = smooth_union(
        c,
        b.torus(radius * 1.05f, radius * 0.2f).translated({0, 0.55f * radius, 0}).colored(kMarble),
        0.1f * radius);
    c = smooth_union(c,
                     b.torus(radius * 1.0f, radius * 0.25f)
                         .translated({0, height - 1.2f * radius, 0})
                         .colored(kMarble),
                     0.1f * radius);
    c = c | b.box({2.5f * radius, 0.5f * radius, 2.5f * radius})
                .translated({0, height - 0.25f * radius, 0})
                .colored(kStone);
    return c.translated(at);
}

// A triangular pediment over (x0..x1) at z0..z1 from height y: a slab cut by two slopes.
// 3 primitives.
Shape pediment(SceneBuilder& b, float cx, float width, float y, float z, float depth) {
    const float rise = width * 0.14f;
    Shape slab = b.box({width, rise, depth}).translated({cx, y + rise / 2, z}).colored(kMarble);
    slab =
        slab & half_space(b, {cx, y + rise, z}, {rise, width / 2, 0}, 2 * width).colored(kMarble);
    return slab &
           half_space(b, {cx, y + rise, z}, {-rise, width / 2, 0}, 2 * width).colored(kMarble);
}

}  // namespace

Scene city(uint64_t seed, uint32_t primitives) {
    Rng rng(seed);
    // One primitive for the street slab, the rest split into blocks of 4..26 primitives.
    const std::vector<uint32_t> budgets = split_budget(primitives - 1, 4, 26, rng);
    const uint32_t n = uint32_t(budgets.size());
    uint32_t cols, rows;
    grid_shape(n, cols, rows);
    const float pitch = kBlock + kStreet;
    const vec3 origin{-0.5f * pitch * float(cols - 1), 0, -0.5f * pitch * float(rows - 1)};
    const float radius = 0.5f * pitch * float(std::max(cols, rows));

    Assembly a;
    a.reserve(size_t(primitives) * 2);
    std::vector<uint32_t> roots(n);
    std::vector<vec3> where(n);
    for (uint32_t i = 0; i < n; ++i) {
        where[i] = origin + vec3{float(i % cols), 0, float(i / cols)} * pitch;
        SceneBuilder b;
        const float centrality = std::exp(-math::dot(where[i], where[i]) / (radius * radius));
        Shape block;
        if (rng.uniform() < 0.12f) {
            block = park(b, rng, budgets[i]);
        } else {
            // A pavement slab and 1..n buildings on a grid of lots.
            std::vector<Shape> parts = {b.box({kBlock + 1, 0.3f, kBlock + 1}, corners(0.6f))
                                            .translated({0, 0.15f, 0})
                                            .colored({0.6f, 0.6f, 0.58f})};
            const std::vector<uint32_t> houses = split_budget(budgets[i] - 1, 3, 12, rng);
            const uint32_t lots = uint32_t(houses.size());
            const uint32_t lot_rows = lots > 1 ? 2 : 1, lot_cols = (lots + 1) / lot_rows;
            const float lw = kBlock / float(lot_cols), ld = kBlock / float(lot_rows);
            for (uint32_t j = 0; j < lots; ++j) {
                const float fill = rng.uniform(0.7f, 0.9f);
                const float tall = rng.uniform();
                const float height = 5 + 45 * centrality * tall * tall + rng.uniform(0.0f, 4.0f);
                const vec3 lot{-kBlock / 2 + lw * (float(j % lot_cols) + 0.5f), 0.3f,
                               -kBlock / 2 + ld * (float(j / lot_cols) + 0.5f)};
                parts.push_back(
                    building(b, rng, houses[j], lw * fill, ld * fill, height).translated(lot));
            }
            block = union_all(parts);
        }
        roots[i] = a.add(b, block.translated(where[i]));
    }
    const std::vector<uint32_t> order = morton_order(where);
    std::vector<uint32_t> sorted(n);
    for (uint32_t i = 0; i < n; ++i) sorted[i] = roots[order[i]];
    const uint32_t blocks = a.balanced(sorted, math::kOpUnion, 0);

    PrimitiveShape street;
    street.sides = {pitch * float(cols) + kStreet, 0.2f, pitch * float(rows) + kStreet};
    const vec3 centre =
        origin + vec3{0.5f * pitch * float(cols - 1), -0.1f, 0.5f * pitch * float(rows - 1)};
    const uint32_t ground = a.add_primitive(math::kPrimBox, street, Affine::translation(-centre),
                                            {0.25f, 0.25f, 0.27f});
    return a.build(a.combine(math::kOpUnion, ground, blocks, 0));
}

Scene monument(uint64_t seed) {
    constexpr uint32_t kTotal = 3012;
    Rng rng(seed);
    SceneBuilder b;
    std::vector<Shape> parts;
    uint32_t used = 0;
    auto add = [&](Shape s, uint32_t primitives) {
        parts.push_back(s);
        used += primitives;
    };
    const float roof_hue = rng.uniform(0.0f, 1.0f);
    const vec3 dome_c =
        lerp({0.45f, 0.62f, 0.55f}, {0.75f, 0.72f, 0.68f}, roof_hue);  // copper or lead

    // Podium of three tiers and a grand stair in front.
    for (int i = 0; i < 3; ++i)
        add(b.box({90 - 4 * float(i), 1, 48 - 4 * float(i)})
                .translated({0, 0.5f + float(i), 0})
                .colored(kStone),
            1);
    for (int i = 0; i < 10; ++i)
        add(b.box({30, 0.3f * float(i + 1), 1.2f})
                .translated({0, 0.15f * float(i + 1), 29.4f - 1.2f * float(i)})
                .colored(kStone),
            1);

    // Windows: boxes cut through a wall onto a dark core (one core per hall).
    auto hall = [&](vec3 c, vec3 size, int rows, int per_front, int per_side, bool back) {
        Shape body = b.box(size).translated(c + vec3{0, size.y / 2, 0}).colored(kMarble);
        std::vector<Shape> cuts;
        for (int r = 0; r < rows; ++r) {
            const float y = c.y + size.y * (0.3f + 0.4f * float(r));
            for (int i = 0; i < per_front; ++i) {
                const float x = c.x - size.x / 2 + size.x * (float(i) + 0.5f) / float(per_front);
                for (float zs : {-1.0f, 1.0f})
                    if (back || zs > 0)
                        cuts.push_back(b.box({size.x / float(per_front) * 0.4f, size.y * 0.22f, 2})
                                           .translated({x, y, c.z + zs * size.z / 2}));
            }
            for (int i = 0; i < per_side; ++i) {
                const float z = c.z - size.z / 2 + size.z * (float(i) + 0.5f) / float(per_side);
                for (float xs : {-1.0f, 1.0f})
                    cuts.push_back(b.box({2, size.y * 0.22f, size.z / float(per_side) * 0.4f})
                                       .translated({c.x + xs * size.x / 2, y, z}));
            }
        }
        const uint32_t n = uint32_t(cuts.size()) + 2;
        Shape core = b.box(size - vec3{1.2f, 0.6f, 1.2f})
                         .translated(c + vec3{0, size.y / 2, 0})
                         .colored(kWindowGlass);
        add((body - union_all(cuts)) | core, n);
    };
    hall({0, 3, -2}, {36, 14, 26}, 2, 7, 6, true);
    for (float s : {-1.0f, 1.0f}) hall({s * 28, 3, -2}, {20, 11, 20}, 2, 5, 4, true);

    // Porticoes: colonnades of fluted columns under an entablature and a pediment, with
    // statues on the pediment's corners and apex.
    auto portico = [&](float cx, float wall_z, float z_front, int columns, int rows, float height,
                       float radius, float spacing) {
        std::vector<Shape> cs;
        const float width = spacing * float(columns - 1);
        for (int r = 0; r < rows; ++r)
            for (int i = 0; i < columns; ++i)
                cs.push_back(
                    column(b, {cx - width / 2 + spacing * float(i), 3, z_front - 3.5f * float(r)},
                           height, radius));
        const float front = z_front + 1.5f * radius + 0.5f;  // the roof reaches back to the wall
        const float depth = front - wall_z, zc = (front + wall_z) / 2;
        cs.push_back(b.box({width + 4 * radius, 1.6f, depth})
                         .translated({cx, 3 + height + 0.8f, zc})
                         .colored(kMarble));
        cs.push_back(pediment(b, cx, width + 4 * radius, 3 + height + 1.6f, zc, depth));
        const float top = 3 + height + 1.6f, rise = (width + 4 * radius) * 0.14f;
        for (float dx : {-0.5f, 0.0f, 0.5f}) {
            const float y = top + (dx == 0 ? rise : 0);
            const vec3 at{cx + dx * (width + 2 * radius), y, zc + depth / 2 - 0.8f};
            cs.push_back(smooth_union(
                b.cylinder(0.5f, 1.6f).translated(at + vec3{0, 0.8f, 0}).colored(kStone),
                b.sphere(0.5f).translated(at + vec3{0, 1.9f, 0}).colored(kStone), 0.2f));
        }
        add(union_all(cs), uint32_t(columns * rows) * kColumnPrimitives + 1 + 3 + 6);
    };
    portico(0, 11, 18, 8, 2, 12, 0.75f, 4.2f);
    for (float s : {-1.0f, 1.0f}) portico(s * 28, 8, 10.5f, 6, 1, 9.5f, 0.55f, 3.2f);

    // Drum with a peristyle and windows, attic, ribbed dome with dormers, lantern.
    const vec3 axis{0, 17, -2};
    {
        Shape drum = b.cylinder(9, 8).translated(axis + vec3{0, 4, 0}).colored(kMarble);
        std::vector<Shape> windows, cols;
        for (int i = 0; i < 24; ++i) {
            const float a = 2 * kPi * (float(i) + 0.5f) / 24;
            windows.push_back(b.box({1.2f, 4, 3})
                                  .translated({9, 0, 0})
                                  .rotated({0, 1, 0}, a)
                                  .translated(axis + vec3{0, 4, 0}));
            const float ca = 2 * kPi * float(i) / 24;
            cols.push_back(
                column(b, axis + vec3{10 * std::cos(ca), 0, 10 * std::sin(ca)}, 7, 0.45f));
        }
        drum = (drum - union_all(windows)) |
               b.cylinder(8.4f, 7.8f).translated(axis + vec3{0, 4, 0}).colored(kWindowGlass);
        Shape ring = b.cylinder(10.8f, 1.2f).translated(axis + vec3{0, 7.6f, 0}).colored(kStone);
        Shape attic = b.cylinder(8.6f, 2).translated(axis + vec3{0, 9, 0}).colored(kMarble);
        add(drum | union_all(cols) | ring | attic, 2 + 24 + 24 * kColumnPrimitives + 2);
    }
    const vec3 dome_o = axis + vec3{0, 10, 0};
    {
        Shape dome = b.sphere(8.5f).translated(dome_o).colored(dome_c) &
                     b.box({18, 9, 18}).translated(dome_o + vec3{0, 4.5f, 0}).colored(dome_c);
        std::vector<Shape> ribs, dormers;
        for (int i = 0; i < 16; ++i) {
            const float a = kPi * float(i) / 16;
            ribs.push_back(b.torus(8.5f, 0.22f)
                               .rotated({1, 0, 0}, kPi / 2)
                               .rotated({0, 1, 0}, a)
                               .translated(dome_o)
                               .colored(kMarble));
        }
        for (int i = 0; i < 12; ++i) {
            const float a = 2 * kPi * float(i) / 12;
            dormers.push_back(b.sphere(0.9f).translated(
                dome_o + vec3{6.9f * std::cos(a), 4.8f, 6.9f * std::sin(a)}));
        }
        Shape rib_cage = union_all(ribs) &
                         b.box({18, 9, 18}).translated(dome_o + vec3{0, 4.5f, 0}).colored(kMarble);
        add(smooth_union(dome - union_all(dormers), rib_cage, 0.15f), 2 + 16 + 1 + 12);
    }
    {
        const vec3 base = dome_o + vec3{0, 8.3f, 0};
        std::vector<Shape> l = {
            b.cylinder(1.5f, 3).translated(base + vec3{0, 1.5f, 0}).colored(kMarble)};
        for (int i = 0; i < 8; ++i) {
            const float a = 2 * kPi * float(i) / 8;
            l.push_back(b.cylinder(0.15f, 3)
                            .translated(base + vec3{1.75f * std::cos(a), 1.5f, 1.75f * std::sin(a)})
                            .colored(kMarble));
        }
        l.push_back(b.sphere(1.9f).translated(base + vec3{0, 3, 0}).colored(dome_c) &
                    b.box({4, 2, 4}).translated(base + vec3{0, 4, 0}).colored(dome_c));
        l.push_back(
            b.cone(0.4f, 3).translated(base + vec3{0, 6.2f, 0}).colored({0.8f, 0.65f, 0.25f}));
        l.push_back(
            b.sphere(0.35f).translated(base + vec3{0, 7.9f, 0}).colored({0.9f, 0.75f, 0.3f}));
        add(union_all(l), 13);
    }

    // Balustrades fill the rest: rails along roof edges and the podium, balusters spaced
    // evenly over their total length.
    struct Run {
        vec3 from, to;
    };
    std::vector<Run> runs;
    auto rectangle = [&](vec3 c, float w, float d, bool skip_front) {
        const vec3 p[4] = {c + vec3{-w / 2, 0, -d / 2}, c + vec3{w / 2, 0, -d / 2},
                           c + vec3{w / 2, 0, d / 2}, c + vec3{-w / 2, 0, d / 2}};
        for (int i = 0; i < 4; ++i)
            if (!(skip_front && i == 2)) runs.push_back({p[i], p[(i + 1) % 4]});
    };
    rectangle({0, 17, -2}, 35.4f, 25.4f, false);
    for (float s : {-1.0f, 1.0f}) rectangle({s * 28, 14, -2}, 19.4f, 19.4f, false);
    rectangle({0, 3, 0}, 81, 39, true);
    float total = 0;
    for (const Run& r : runs) total += math::length(r.to - r.from);
    const uint32_t rails = uint32_t(runs.size());
    const uint32_t balusters = kTotal - used - rails;
    std::vector<Shape> balustrade;
    uint32_t placed = 0;
    float walked = 0;
    for (size_t k = 0; k < runs.size(); ++k) {
        const Run& r = runs[k];
        const float len = math::length(r.to - r.from);
        walked += len;
        const uint32_t upto =
            k + 1 == runs.size() ? balusters : uint32_t(float(balusters) * walked / total);
        balustrade.push_back(
            b.box({std::fabs(r.to.x - r.from.x) + 0.3f, 0.2f, std::fabs(r.to.z - r.from.z) + 0.3f})
                .translated((r.from + r.to) * 0.5f + vec3{0, 0.8f, 0})
                .colored(kStone));
        const uint32_t here = upto - placed;
        for (uint32_t i = 0; i < here; ++i)
            balustrade.push_back(
                b.capsule(0.08f, 0.55f)
                    .translated(lerp(r.from, r.to, (float(i) + 0.5f) / float(here)) +
                                vec3{0, 0.4f, 0})
                    .colored(kMarble));
        placed = upto;
    }
    parts.push_back(union_all(balustrade));
    return build_scene_of(b, union_all(parts));
}

Scene trees(uint64_t seed) {
    constexpr uint32_t kTotal = 185;
    Rng rng(seed);
    SceneBuilder b;
    const vec3 bark{0.42f, 0.28f, 0.16f}, rock{0.55f, 0.54f, 0.52f};

    // Decide the items first (pine 4, round tree 5, low-poly tree 3, rock 2, bush 1), so the
    // layout grid fits them; the ground slab is the first primitive.
    std::vector<int> items;
    uint32_t left = kTotal - 1;
    constexpr uint32_t kSize[5] = {4, 5, 3, 2, 1};
    while (left > 0) {
        int kind = uniform_int(rng, 0, 9);
        kind = kind < 3 ? 0 : kind < 5 ? 1 : kind < 7 ? 2 : kind < 9 ? 3 : 4;
        while (kSize[kind] > left) ++kind;
        items.push_back(kind);
        left -= kSize[kind];
    }
    uint32_t cols, rows;
    grid_shape(uint32_t(items.size()), cols, rows);
    const float cell = 0.75f;
    const float w = cell * float(cols), d = cell * float(rows);
    std::vector<Shape> chain_items = {b.box({w + 0.4f, 0.2f, d + 0.4f}, corners(0.3f), 0.05f, 0)
                                          .translated({0, -0.1f, 0})
                                          .colored({0.42f, 0.55f, 0.28f})};
    for (size_t i = 0; i < items.size(); ++i) {
        const float jx = rng.uniform(-0.22f, 0.22f), jz = rng.uniform(-0.22f, 0.22f);
        const vec3 at{-w / 2 + cell * (float(i % cols) + 0.5f + jx), 0,
                      -d / 2 + cell * (float(i / cols) + 0.5f + jz)};
        const float s = rng.uniform(0.75f, 1.25f);
        const vec3 leaf =
            vary(items[i] == 0 ? vec3{0.12f, 0.38f, 0.2f} : vec3{0.35f, 0.62f, 0.22f}, 0.07f, rng);
        Shape item;
        switch (items[i]) {
            case 0: {  // pine: trunk and three cones
                item = b.cylinder(0.05f, 0.4f).translated({0, 0.2f, 0}).colored(bark);
                for (int k = 0; k < 3; ++k)
                    item = smooth_union(item,
                                        b.cone(0.34f - 0.08f * float(k), 0.5f - 0.06f * float(k))
                                            .translated({0, 0.5f + 0.28f * float(k), 0})
                                            .colored(leaf),
                                        0.03f);
                break;
            }
            case 1: {  // round tree: trunk and four blended spheres
                item = capsule_between(b, {0, 0, 0}, {0, 0.55f, 0}, 0.05f).colored(bark);
                item = smooth_union(item, b.sphere(0.25f).translated({0, 0.75f, 0}).colored(leaf),
                                    0.05f);
                for (int k = 0; k < 3; ++k) {
                    const float a = 2 * kPi * float(k) / 3 + rng.uniform(0.0f, 1.0f);
                    item = smooth_union(
                        item,
                        b.sphere(0.17f)
                            .translated({0.18f * std::cos(a), 0.68f, 0.18f * std::sin(a)})
                            .colored(vary(leaf, 0.04f, rng)),
                        0.08f);
                }
                break;
            }
            case 2: {  // low-poly tree: a box trunk and two bevelled boxes
                item = b.box({0.08f, 0.5f, 0.08f}).translated({0, 0.25f, 0}).colored(bark);
                const float turn = rng.uniform(0.0f, kPi);
                item = smooth_union(item,
                                    b.box({0.45f, 0.35f, 0.45f}, corners(0.08f), 0.06f, 0.06f)
                                        .rotated({0, 1, 0}, turn)
                                        .translated({0, 0.6f, 0})
                                        .colored(leaf),
                                    0.02f);
                item = smooth_union(item,
                                    b.box({0.3f, 0.25f, 0.3f}, corners(0.06f), 0.05f, 0.05f)
                                        .rotated({0, 1, 0}, turn + 0.5f)
                                        .translated({0, 0.88f, 0})
                                        .colored(leaf),
                                    0.02f);
                break;
            }
            case 3: {  // rock: a sphere cut by a turned box
                const vec3 axis = uniform_vec3(rng, -1, 1) + vec3{0, 0, 0.01f};
                item = b.sphere(0.16f).colored(rock) & b.box(vec3(0.24f), corners(0.02f))
                                                           .rotated(axis, rng.uniform(0.0f, kPi))
                                                           .colored(rock);
                item = item.translated({0, 0.05f, 0});
                break;
            }
            default:  // bush
                item = b.sphere(0.12f).translated({0, 0.04f, 0}).colored(leaf);
                break;
        }
        chain_items.push_back(
            item.scaled(s).rotated({0, 1, 0}, rng.uniform(0.0f, 2 * kPi)).translated(at));
    }
    return build_scene_of(b, chain(chain_items, 0.02f));
}

}  // namespace sdfprune::gen
