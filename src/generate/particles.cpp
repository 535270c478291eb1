// particles.cpp — scenes of many spheres, any number of them: "molecule" (rings of DNA, each a
// left-deep smooth-union chain of atoms like the reference molecule.json) and "fluid" (SPH-like
// particles of a splash crown in a tank, smoothly blended in a balanced tree).
#include <algorithm>
#include <array>

#include "generate_internal.hpp"

namespace sdfprune::gen {
namespace {

// ---- molecule --------------------------------------------------------------------------------

constexpr uint32_t kAtomsPerRing = 1000;
constexpr uint32_t kAtomsPerBasePair = 10;
constexpr float kRise = 0.034f;            // along the axis per base pair (0.34 nm at 1 nm = 0.1)
constexpr float kTwist = 2 * kPi / 10.5f;  // per base pair
constexpr float kHelixRadius = 0.11f;
constexpr float kMoleculeBlend = 0.026f;  // the reference molecule's k

// Appends `atoms` atoms of a DNA ring (a closed double helix) placed by `place` (local ->
// world), in chain order; returns the chain's root. Per base pair: on each strand a phosphate
// and a sugar (the backbones), and a rung of six base atoms between the sugars.
uint32_t dna_ring(Assembly& a, Rng& rng, uint32_t atoms, const Affine& place) {
    const vec3 backbone1{1.0f, 0.55f, 0.12f}, backbone2{0.9f, 0.2f, 0.25f};
    constexpr std::array<vec3, 4> kBases = {vec3{0.25f, 0.5f, 0.95f}, vec3{0.95f, 0.9f, 0.3f},
                                            vec3{0.3f, 0.8f, 0.4f}, vec3{0.7f, 0.4f, 0.9f}};
    const uint32_t pairs = (atoms + kAtomsPerBasePair - 1) / kAtomsPerBasePair;
    const float ring_radius = std::max(float(pairs) * kRise / (2 * kPi), 0.15f);
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
        atom(at(phi, kHelixRadius + 0.015f, -kRise / 2), 0.036f, backbone1);
        atom(s1, 0.032f, backbone1);
        for (float t : {0.17f, 0.33f, 0.48f}) atom(lerp(s1, s2, t), 0.026f, b1);
        for (float t : {0.52f, 0.67f, 0.83f}) atom(lerp(s1, s2, t), 0.026f, b2);
        atom(s2, 0.032f, backbone2);
        atom(at(phi2, kHelixRadius + 0.015f, kRise / 2), 0.036f, backbone2);
    }
    return a.chain(chain_atoms, math::kOpUnion, kMoleculeBlend);
}

// ---- fluid -----------------------------------------------------------------------------------

constexpr float kTank = 0.8f;  // the tank spans [-kTank, kTank] in x and z
constexpr float kFloor = -1.1f;
constexpr float kLevel = -0.3f;  // water level at rest
constexpr int kSpikes = 11;
constexpr float kDrop = 0.085f;   // radius of the falling drop
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
    float depth;   // below the nearest water surface, under-estimated; 0 in the thin splash
    float radius;  // at depth 0
};

// The water as particles: the pool on a lattice of spacing h, the splash above it on a finer
// one (jittered when collected; counted only when `out` is null). The pool is counted column
// by column without tests; only the splash's columns are tested point by point.
uint64_t lattice(const Splash& s, float h, Rng* rng, std::vector<Particle>* out) {
    uint64_t n = 0;
    auto keep = [&](vec3 p, float depth, float spacing) {
        ++n;
        if (out) out->push_back({p + uniform_vec3(*rng, -0.15f * spacing, 0.15f * spacing), depth, 0.8f * spacing});
    };
    const int cols = int(2 * kTank / h);
    for (int iz = 0; iz < cols; ++iz)
        for (int ix = 0; ix < cols; ++ix) {
            const float x = -kTank + (float(ix) + 0.5f) * h, z = -kTank + (float(iz) + 0.5f) * h;
            const float top = surface(std::sqrt(x * x + z * z));
            const int pool = std::max(int(std::floor((top - kFloor) / h + 0.5f)), 0);
            if (!out) {
                n += uint64_t(pool);
                continue;
            }
            const float side = kTank - std::max(std::fabs(x), std::fabs(z));
            for (int iy = 0; iy < pool; ++iy) {
                const float y = kFloor + (float(iy) + 0.5f) * h;
                // Vertical distance to the rippled top over-estimates on slopes: 0.9.
                keep({x, y, z}, std::max(0.0f, std::min({0.9f * (top - y), y - kFloor, side})), h);
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
                if (p.y > top && in_splash(s, p, r))
                    keep(p, std::max(0.0f, kDrop - math::length(p - s.drop)), hs);
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
            centre =
                vec3{float(i % side), float(i / side % side), float(i / (side * side))} * 1.35f;
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

    // Find the lattice spacing that fills the water with at least `spheres` points (the count
    // goes as h^-3; a few secant steps), then drop the surplus at random.
    float h = std::cbrt(2.2f / float(spheres));
    uint64_t got = lattice(s, h, nullptr, nullptr);
    for (int it = 0; it < 8 && (got < spheres || got > spheres + spheres / 100 + 8); ++it) {
        h *= std::cbrt(float(got) / (float(spheres) * 1.003f));
        got = lattice(s, h, nullptr, nullptr);
    }
    while (got < spheres) {
        h *= 0.995f;
        got = lattice(s, h, nullptr, nullptr);
    }
    std::vector<Particle> points;
    points.reserve(got);
    lattice(s, h, &rng, &points);
    std::vector<std::pair<uint64_t, uint32_t>> keep(points.size());
    for (size_t i = 0; i < points.size(); ++i) keep[i] = {rng.next_u64(), uint32_t(i)};
    std::nth_element(keep.begin(), keep.begin() + spheres, keep.end());
    std::vector<Particle> water(spheres);
    std::vector<vec3> centres(spheres);
    for (uint32_t i = 0; i < spheres; ++i) {
        water[i] = points[keep[i].second];
        centres[i] = water[i].p;
    }
    std::vector<Particle>().swap(points);

    // Particles in Morton order; a balanced smooth union. Like adaptive SPH, particles grow
    // with depth (half as fast, so they never reach the surface): the surface keeps its fine
    // particles while the inside becomes solid, deep water, which pruning culls as far field
    // instead of keeping every inner cell near the surface of some particle. Colour: deep blue
    // to white foam with height above the level.
    const std::vector<uint32_t> order = morton_order(centres);
    std::vector<vec3>().swap(centres);
    Assembly a;
    a.reserve(size_t(spheres) * 2);
    std::vector<uint32_t> leaves(spheres);
    const vec3 deep{0.08f, 0.28f, 0.62f}, foam{0.85f, 0.93f, 1.0f};
    for (uint32_t i = 0; i < spheres; ++i) {
        const Particle& w = water[order[i]];
        const float t = smoothstep(-0.05f, 0.2f, w.p.y - kLevel);
        const float radius = w.radius + 0.5f * std::max(0.0f, w.depth - 1.5f * h);
        leaves[i] = a.sphere(w.p, radius, lerp(deep, foam, t));
    }
    // Neighbours blend within groups of 8 (the lowest three levels), hard unions above.
    return a.build(a.balanced(leaves, math::kOpUnion, 0.5f * kSplashSpacing * h, 3));
}

}  // namespace sdfprune::gen
