// particles.cpp — scenes of many spheres, any number of them: "molecule" (rings of DNA, each a
// left-deep smooth-union chain of atoms like the reference molecule.json) and "fluid" (adaptive
// SPH-like particles of a splash crown in a tank, in a balanced tree blended between neighbours).
#include <algorithm>
#include <array>

#include "generate_internal.hpp"

namespace sdfprune::gen {
namespace {

// ---- molecule --------------------------------------------------------------------------------

constexpr uint32_t kAtomsPerRing = 1000;
constexpr uint32_t kAtomsPerBasePair = 10;
// Lengths at 1 nm = 0.23, which spaces the atoms as in the reference molecule.json (nearest
// neighbour about 0.05 apart for atoms of radius 0.026–0.036, k = 0.026); at 1 nm = 0.1 they
// would overlap far more than any real scene's and few operators could be pruned.
constexpr float kRise = 0.078f;            // along the axis per base pair (0.34 nm)
constexpr float kTwist = 2 * kPi / 10.5f;  // per base pair
constexpr float kHelixRadius = 0.25f;      // to the backbone (1.1 nm)
constexpr float kPhosphateOut = 0.035f;    // phosphates beyond the sugars
// Rings on a lattice this far apart: 2.5 radii of a full ring (kAtomsPerRing atoms).
constexpr float kRingSpacing = 2.5f * kAtomsPerRing / kAtomsPerBasePair * kRise / (2 * kPi);
constexpr float kMoleculeBlend = 0.026f;  // the reference molecule's k

// Appends `atoms` atoms of a DNA ring (a closed double helix) placed by `place` (local ->
// world), chained in random order; returns the chain's root. Per base pair: on each strand a
// phosphate and a sugar (the backbones), and a rung of six base atoms between the sugars.
uint32_t dna_ring(Assembly& a, Rng& rng, uint32_t atoms, const Affine& place) {
    const vec3 backbone1{1.0f, 0.55f, 0.12f}, backbone2{0.9f, 0.2f, 0.25f};
    constexpr std::array<vec3, 4> kBases = {vec3{0.25f, 0.5f, 0.95f}, vec3{0.95f, 0.9f, 0.3f},
                                            vec3{0.3f, 0.8f, 0.4f}, vec3{0.7f, 0.4f, 0.9f}};
    const uint32_t pairs = (atoms + kAtomsPerBasePair - 1) / kAtomsPerBasePair;
    const float ring_radius = std::max(float(pairs) * kRise / (2 * kPi), 1.5f * kHelixRadius);
    const float wobble = rng.uniform(0.0f, 0.08f) * ring_radius;  // gentle supercoiling
    const float phase = rng.uniform(0.0f, 2 * kPi);
    std::vector<uint32_t> chain_atoms;
    chain_atoms.reserve(atoms);
    auto atom = [&](vec3 local, float r, vec3 c) {
        if (chain_atoms.size() < atoms) chain_atoms.push_back(a.sphere(place.apply(local), r, c));
    };
    for (uint32_t i = 0; i < pairs; ++i) {
        const float theta = 2 * kPi * float(i) / float(pairs);
        const vec3 radial{std::cos(theta), 0, std::sin(theta)};
        const vec3 tangent{-std::sin(theta), 0, std::cos(theta)};
        const vec3 up{0, 1, 0};
        const vec3 axis = radial * ring_radius + up * (wobble * std::sin(3 * theta + phase));
        const float phi = kTwist * float(i);
        auto at = [&](float angle, float r, float along) {
            return axis + (radial * std::cos(angle) + up * std::sin(angle)) * r + tangent * along;
        };
        const float phi2 = phi + 2.3f;  // the second strand, across the minor groove
        const vec3 s1 = at(phi + 0.3f, kHelixRadius, 0), s2 = at(phi2 - 0.3f, kHelixRadius, 0);
        const bool at_pair = rng.uniform() < 0.5f;  // A-T or G-C
        const bool flip = rng.uniform() < 0.5f;
        const vec3 b1 = kBases[(at_pair ? 0 : 2) + (flip ? 1 : 0)];
        const vec3 b2 = kBases[(at_pair ? 0 : 2) + (flip ? 0 : 1)];
        atom(at(phi, kHelixRadius + kPhosphateOut, -kRise / 2), 0.036f, backbone1);
        atom(s1, 0.032f, backbone1);
        for (float t : {0.17f, 0.33f, 0.48f}) atom(lerp(s1, s2, t), 0.026f, b1);
        for (float t : {0.52f, 0.67f, 0.83f}) atom(lerp(s1, s2, t), 0.026f, b2);
        atom(s2, 0.032f, backbone2);
        atom(at(phi2, kHelixRadius + kPhosphateOut, kRise / 2), 0.036f, backbone2);
    }
    // The chain in no spatial order, as in the reference (consecutive atoms there lie 0.8
    // apart in a scene 2 across). Chained along the helix instead, the atoms would approach
    // any cell gradually, and no operator could drop the chain before the nearest atom.
    for (size_t i = chain_atoms.size(); i > 1; --i)
        std::swap(chain_atoms[i - 1], chain_atoms[rng.next_u64() % i]);
    return a.chain(chain_atoms, math::kOpUnion, kMoleculeBlend);
}

// ---- fluid -----------------------------------------------------------------------------------

constexpr float kTank = 0.8f;  // the tank spans [-kTank, kTank] in x and z
constexpr float kFloor = -1.5f;
constexpr float kLevel = -0.3f;  // water level at rest
constexpr int kSpikes = 11;
constexpr float kDrop = 0.085f;  // radius of the falling drop
// The thin splash is sampled finer than the pool: spacing kSplashSpacing·h.
constexpr float kSplashSpacing = 0.6f;

struct Splash {
    vec3 spike_base[kSpikes], spike_tip[kSpikes], droplet[kSpikes];
    vec3 drop;  // centre of the falling drop
};

Splash make_splash(Rng& rng) {
    Splash s;
    for (int i = 0; i < kSpikes; ++i) {
        const float a = 2 * kPi * (float(i) + rng.uniform(-0.3f, 0.3f)) / float(kSpikes);
        const float top = 0.15f + rng.uniform(0.04f, 0.11f);
        const vec3 dir{std::cos(a), 0, std::sin(a)};
        s.spike_base[i] = dir * (0.3f + 0.35f * 0.12f) + vec3{0, kLevel + 0.12f, 0};
        s.spike_tip[i] = dir * (0.3f + 0.35f * top) + vec3{0, kLevel + top, 0};
        s.droplet[i] = s.spike_tip[i] + dir * 0.03f + vec3{0, 0.07f, 0};
    }
    const float dx = rng.uniform(-0.05f, 0.05f);
    const float dy = rng.uniform(0.38f, 0.45f);
    const float dz = rng.uniform(-0.05f, 0.05f);
    s.drop = {dx, kLevel + dy, dz};
    return s;
}

// Height of the disturbed surface at radius r from the impact: a crater and ripples.
float surface(float r) {
    const float crater = -0.07f * std::exp(-(r * r) / (0.22f * 0.22f));
    const float ripple = 0.02f * std::sin(20 * r - 1.5f) * std::exp(-2.5f * (r - 0.35f)) *
                         smoothstep(0.34f, 0.45f, r);
    return kLevel + crater + ripple;
}

// Whether p, above the pool's surface, lies in the splash: the crown sheet flaring out as it
// rises, the fingers on its rim with a droplet flying above each, the falling drop.
bool in_splash(const Splash& s, vec3 p, float r) {
    const float h = p.y - kLevel;
    const float rc = 0.3f + 0.35f * std::max(h, 0.0f);
    if (h > -0.08f && h < 0.17f && std::fabs(r - rc) < 0.032f - 0.06f * std::max(h, 0.0f))
        return true;
    for (int i = 0; i < kSpikes; ++i) {
        const vec3 ab = s.spike_tip[i] - s.spike_base[i], ap = p - s.spike_base[i];
        const float t = std::clamp(math::dot(ap, ab) / math::dot(ab, ab), 0.0f, 1.0f);
        if (math::length(ap - ab * t) < 0.028f - 0.012f * t) return true;
        if (math::length(p - s.droplet[i]) < 0.03f) return true;
    }
    return math::length(p - s.drop) < kDrop;
}

struct Particle {
    vec3 p;
    float radius;
    bool fine;  // at the surface (or in the splash): never dropped
};

// Depth below the pool's nearest face (top, floor, tank sides), under-estimated; < 0 outside.
float pool_depth(vec3 p) {
    const float top = surface(std::sqrt(p.x * p.x + p.z * p.z));
    // Vertical distance to the rippled top over-estimates on slopes: 0.9.
    return std::min(
        {0.9f * (top - p.y), p.y - kFloor, kTank - std::fabs(p.x), kTank - std::fabs(p.z)});
}

// The water as particles, adaptively like adaptive SPH: the pool as an octree of cubes, split
// down to spacing h near its faces, each leaf one particle (radius 0.8·h at the surface; deep
// leaves of side c ≤ depth / 2.5 get radius 1.8·c, overlapping their neighbours so that the
// inside is solid and deep — pruning culls it as far field even on coarse grids — yet never
// closer than 0.7·c to the surface); the thin splash on its own
// lattice of spacing kSplashSpacing·h. Counts only when `out` is null; jitters fine particles.
uint64_t sample_water(const Splash& s, float h, Rng* rng, std::vector<Particle>* out) {
    uint64_t n = 0;
    auto emit = [&](vec3 p, float radius, bool fine, float jitter) {
        ++n;
        if (out) {
            if (fine) p = p + uniform_vec3(*rng, -jitter, jitter);
            out->push_back({p, radius, fine});
        }
    };
    // Iterative octree descent from top cubes of side h·2^K (about 0.2).
    float top_side = h;
    while (top_side * 2 <= 0.4f) top_side *= 2;
    const float y_top = kLevel + 0.03f;
    const int nxz = int(std::ceil(2 * kTank / top_side)),
              ny = int(std::ceil((y_top - kFloor) / top_side));
    struct Cube {
        vec3 centre;
        float side;
    };
    std::vector<Cube> stack;
    for (int iz = 0; iz < nxz; ++iz)
        for (int iy = 0; iy < ny; ++iy)
            for (int ix = 0; ix < nxz; ++ix) {
                stack.push_back(
                    {vec3{-kTank, kFloor, -kTank} +
                         vec3{float(ix) + 0.5f, float(iy) + 0.5f, float(iz) + 0.5f} * top_side,
                     top_side});
                while (!stack.empty()) {
                    const Cube c = stack.back();
                    stack.pop_back();
                    const float d = pool_depth(c.centre);
                    if (c.side < 1.5f * h) {
                        if (d >= 0) emit(c.centre, 0.8f * h, true, 0.15f * h);
                    } else if (d >= 2.5f * c.side) {
                        emit(c.centre, 1.8f * c.side, false, 0);
                    } else if (d > -0.87f * c.side) {
                        const float q = c.side / 4;
                        for (int o = 7; o >= 0; --o)
                            stack.push_back(
                                {c.centre + vec3{o & 1 ? q : -q, o & 2 ? q : -q, o & 4 ? q : -q},
                                 c.side / 2});
                    }
                }
            }
    const float hs = kSplashSpacing * h, reach = 0.5f;
    const int splash_cols = int(2 * reach / hs), rows = int((0.3f - kFloor) / hs);
    for (int iz = 0; iz < splash_cols; ++iz)
        for (int ix = 0; ix < splash_cols; ++ix) {
            const float x = -reach + (float(ix) + 0.5f) * hs, z = -reach + (float(iz) + 0.5f) * hs;
            const float r = std::sqrt(x * x + z * z);
            if ((r < 0.2f || r > reach) && std::hypot(x - s.drop.x, z - s.drop.z) > kDrop) continue;
            const float top = surface(r);
            for (int iy = 0; iy < rows; ++iy) {
                const vec3 p{x, kFloor + (float(iy) + 0.5f) * hs, z};
                if (p.y > top && in_splash(s, p, r)) emit(p, 0.8f * hs, true, 0.15f * hs);
            }
        }
    return n;
}

}  // namespace

Scene molecule(uint64_t seed, uint32_t atoms) {
    Rng rng(seed);
    const uint32_t rings = (atoms + kAtomsPerRing - 1) / kAtomsPerRing;
    uint32_t side = 1;
    while (side * side * side < rings) ++side;
    Assembly a;
    a.reserve(size_t(atoms) * 2);
    std::vector<uint32_t> roots;
    std::vector<vec3> centres;
    for (uint32_t i = 0; i < rings; ++i) {
        const uint32_t n = atoms / rings + (i < atoms % rings ? 1 : 0);
        // One ring tilted towards the viewer; many rings on a lattice, each turned at random.
        Affine place = Affine::rotation({1, 0, 0.3f}, 0.45f);
        vec3 centre{0, 0, 0};
        if (rings > 1) {
            const vec3 axis = uniform_vec3(rng, -1, 1) + vec3{0, 0, 1e-3f};
            place = Affine::rotation(axis, rng.uniform(0.0f, kPi));
            centre = vec3{float(i % side), float(i / side % side), float(i / (side * side))} *
                     kRingSpacing;
        }
        roots.push_back(dna_ring(a, rng, n, Affine::translation(centre).compose(place)));
        centres.push_back(centre);
    }
    const std::vector<uint32_t> order = morton_order(centres);
    std::vector<uint32_t> sorted;
    for (uint32_t i : order) sorted.push_back(roots[i]);
    return a.build(a.balanced(sorted, math::kOpUnion, 0));
}

Scene fluid(uint64_t seed, uint32_t spheres) {
    Rng rng(seed);
    const Splash s = make_splash(rng);

    // Find the spacing h that makes at least `spheres` particles: secant steps on log(count)
    // against log(h) (most particles lie at the surface: count ~ h^-2 at first), then drop the
    // surplus among deep particles.
    const float want = float(spheres) * 1.003f;
    float h = std::sqrt(60.0f / float(spheres)), slope = -2;
    uint64_t got = sample_water(s, h, nullptr, nullptr);
    for (int it = 0; it < 12 && (got < spheres || got > spheres + spheres / 100 + 8); ++it) {
        const float h_next = h * std::exp(std::log(want / float(got)) / slope);
        const uint64_t got_next = sample_water(s, h_next, nullptr, nullptr);
        if (got_next != got && h_next != h)
            slope = std::clamp(std::log(float(got_next) / float(got)) / std::log(h_next / h), -3.5f,
                               -1.5f);
        h = h_next;
        got = got_next;
    }
    while (got < spheres) {
        h *= 0.995f;
        got = sample_water(s, h, nullptr, nullptr);
    }
    std::vector<Particle> points;
    points.reserve(got);
    sample_water(s, h, &rng, &points);
    const uint64_t deep = uint64_t(
        std::count_if(points.begin(), points.end(), [](const Particle& p) { return !p.fine; }));
    const bool deep_only = points.size() - spheres <= deep;
    std::vector<std::pair<uint64_t, uint32_t>> keep(points.size());
    for (size_t i = 0; i < points.size(); ++i) {
        const uint64_t key = rng.next_u64() >> 1;
        keep[i] = {deep_only && points[i].fine ? key : key | (1ull << 63), uint32_t(i)};
    }
    std::nth_element(keep.begin(), keep.begin() + spheres, keep.end());
    std::vector<Particle> water(spheres);
    std::vector<vec3> centres(spheres);
    for (uint32_t i = 0; i < spheres; ++i) {
        water[i] = points[keep[i].second];
        centres[i] = water[i].p;
    }
    std::vector<Particle>().swap(points);

    // Particles in Morton order; a balanced union, blending neighbours within groups of 4
    // (the lowest two levels) and hard above: a balanced tree of smooth unions lowers the
    // field by up to k/4 per level where many operands are close, which bloats the shape and
    // defeats pruning. Colour: deep blue to white foam with height above the level.
    const std::vector<uint32_t> order = morton_order(centres);
    std::vector<vec3>().swap(centres);
    Assembly a;
    a.reserve(size_t(spheres) * 2);
    std::vector<uint32_t> leaves(spheres);
    const vec3 deep_blue{0.08f, 0.28f, 0.62f}, foam{0.85f, 0.93f, 1.0f};
    for (uint32_t i = 0; i < spheres; ++i) {
        const Particle& w = water[order[i]];
        const float t = smoothstep(-0.05f, 0.2f, w.p.y - kLevel);
        leaves[i] = a.sphere(w.p, w.radius, lerp(deep_blue, foam, t));
    }
    return a.build(a.balanced(leaves, math::kOpUnion, 0.5f * kSplashSpacing * h, 2));
}

}  // namespace sdfprune::gen
