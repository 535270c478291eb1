// organic.cpp — living things, smoothly blended: "character" (a cartoon figure of capsules and
// spheres, 22 primitives), "raccoon" (masked face, ringed tail, 27 primitives), the `person`
// used by crowds and stations, and "crowd" (people on a plaza, any number of primitives).
#include <algorithm>
#include <array>

#include "generate_internal.hpp"

namespace sdfprune::gen {
namespace {

constexpr std::array<vec3, 5> kSkin = {vec3{0.96f, 0.80f, 0.66f}, vec3{0.87f, 0.66f, 0.50f},
                                       vec3{0.70f, 0.49f, 0.34f}, vec3{0.50f, 0.33f, 0.22f},
                                       vec3{0.36f, 0.24f, 0.17f}};
constexpr std::array<vec3, 8> kCloth = {vec3{0.80f, 0.16f, 0.16f}, vec3{0.16f, 0.36f, 0.78f},
                                        vec3{0.20f, 0.60f, 0.30f}, vec3{0.95f, 0.75f, 0.15f},
                                        vec3{0.55f, 0.25f, 0.65f}, vec3{0.95f, 0.95f, 0.92f},
                                        vec3{0.20f, 0.20f, 0.22f}, vec3{0.95f, 0.50f, 0.20f}};
constexpr std::array<vec3, 4> kTrousers = {vec3{0.15f, 0.20f, 0.40f}, vec3{0.18f, 0.18f, 0.20f},
                                           vec3{0.45f, 0.38f, 0.28f}, vec3{0.30f, 0.30f, 0.34f}};
constexpr std::array<vec3, 4> kHair = {vec3{0.10f, 0.07f, 0.05f}, vec3{0.35f, 0.20f, 0.08f},
                                       vec3{0.80f, 0.62f, 0.30f}, vec3{0.55f, 0.55f, 0.55f}};

}  // namespace

Scene character(uint64_t seed) {
    Rng rng(seed);
    SceneBuilder b;
    const vec3 skin = pick(kSkin, rng);
    const vec3 shirt = vary(pick(kCloth, rng), 0.05f, rng);
    const vec3 pants = pick(kTrousers, rng);
    const vec3 shoes{0.25f, 0.15f, 0.10f};
    const float wave = rng.uniform(0.0f, 0.5f);  // how high the right hand is raised

    // Head: sphere, ears and nose blended in; eyes (white and pupil) stay hard.
    const vec3 head_c{0, 1.72f, 0};
    Shape head = b.sphere(0.25f).translated(head_c).colored(skin);
    for (float s : {-1.0f, 1.0f})
        head = smooth_union(
            head, b.sphere(0.075f).translated(head_c + vec3{s * 0.245f, 0, 0}).colored(skin),
            0.04f);
    head = smooth_union(
        head, b.sphere(0.055f).translated(head_c + vec3{0, -0.03f, 0.245f}).colored(skin), 0.03f);
    for (float s : {-1.0f, 1.0f}) {
        const vec3 e = head_c + vec3{s * 0.09f, 0.07f, 0.19f};
        Shape eye =
            b.sphere(0.065f).translated(e).colored({0.97f, 0.97f, 0.97f}) |
            b.sphere(0.032f).translated(e + vec3{0, 0, 0.052f}).colored({0.05f, 0.05f, 0.08f});
        head = head | eye;
    }

    // Trunk: a capsule over a hip sphere.
    Shape trunk =
        smooth_union(capsule_between(b, {0, 1.02f, 0}, {0, 1.36f, 0}, 0.21f).colored(shirt),
                     b.sphere(0.19f).translated({0, 0.95f, 0}).colored(pants), 0.08f);

    // Limbs: two capsules and a hand or foot each, smoothly chained.
    auto limb = [&](vec3 a, vec3 j, vec3 e, float r, vec3 c_upper, vec3 c_lower, Shape end) {
        Shape upper = capsule_between(b, a, j, r).colored(c_upper);
        Shape lower = capsule_between(b, j, e, r * 0.9f).colored(c_lower);
        return smooth_union(smooth_union(upper, lower, 0.03f), end, 0.03f);
    };
    const vec3 wrist_l{0.47f, 0.88f, 0.1f};
    const vec3 wrist_r{-0.52f, 1.62f + wave * 0.4f, 0.06f};
    Shape arm_l =
        limb({0.24f, 1.42f, 0}, {0.4f, 1.14f, 0.02f}, wrist_l, 0.07f, shirt, skin,
             b.sphere(0.085f).translated(wrist_l + vec3{0.02f, -0.05f, 0.02f}).colored(skin));
    Shape arm_r = limb({-0.24f, 1.42f, 0}, {-0.46f, 1.3f, 0.02f}, wrist_r, 0.07f, shirt, skin,
                       b.sphere(0.085f).translated(wrist_r + vec3{-0.02f, 0.07f, 0}).colored(skin));
    Shape legs[2];
    for (int i = 0; i < 2; ++i) {
        const float s = i ? -1.0f : 1.0f;
        const vec3 ankle{s * 0.12f, 0.1f, 0};
        Shape foot =
            capsule_between(b, {s * 0.12f, 0.07f, -0.02f}, {s * 0.13f, 0.07f, 0.16f}, 0.07f)
                .colored(shoes);
        legs[i] =
            limb({s * 0.1f, 0.9f, 0}, {s * 0.12f, 0.5f, 0.04f}, ankle, 0.085f, pants, pants, foot);
    }
    const Shape body_parts[] = {trunk, arm_l, arm_r, legs[0], legs[1]};
    Shape body = chain(body_parts, 0.05f);
    return build_scene_of(b, smooth_union(body, head, 0.07f));
}

Scene raccoon(uint64_t seed) {
    Rng rng(seed);
    SceneBuilder b;
    const vec3 fur = vary({0.5f, 0.47f, 0.43f}, 0.04f, rng);
    const vec3 dark{0.09f, 0.08f, 0.08f};
    const vec3 light{0.90f, 0.89f, 0.86f};
    const float head_turn = rng.uniform(-0.3f, 0.3f);
    constexpr float kY = 0.56f;  // height of the back's axis

    // Body: a capsule between rump and chest, facing +x.
    Shape body = capsule_between(b, {-0.3f, kY - 0.02f, 0}, {0.25f, kY, 0}, 0.22f).colored(fur);
    body =
        smooth_union(body, b.sphere(0.28f).translated({-0.36f, kY + 0.06f, 0}).colored(fur), 0.08f);
    body = smooth_union(
        body, b.sphere(0.21f).translated({0.3f, kY, 0}).colored(vary(fur, 0.03f, rng)), 0.08f);

    // Head, built at the origin facing +x then turned and placed: snout cone, black nose,
    // ears, the black mask over the eyes and the white brows above it.
    Shape head = b.sphere(0.2f).colored(fur);
    Shape snout = b.cone(0.11f, 0.22f)
                      .transformed(rotation_from_y({1, 0, 0}))
                      .translated({0.2f, -0.06f, 0})
                      .colored(light);
    head = smooth_union(head, snout, 0.06f);
    head = smooth_union(head, b.sphere(0.04f).translated({0.32f, -0.05f, 0}).colored(dark), 0.015f);
    for (float s : {-1.0f, 1.0f}) {
        Shape ear = b.cone(0.075f, 0.13f)
                        .rotated({1, 0, 0}, s * 0.35f)
                        .translated({-0.03f, 0.2f, s * 0.11f})
                        .colored(dark);
        head = smooth_union(head, ear, 0.03f);
    }
    for (float s : {-1.0f, 1.0f}) {
        Shape mask = b.sphere(0.085f).translated({0.12f, 0.04f, s * 0.09f}).colored(dark);
        Shape brow = b.sphere(0.06f).translated({0.12f, 0.11f, s * 0.075f}).colored(light);
        head = smooth_union(head, smooth_union(mask, brow, 0.02f), 0.025f);
    }
    head = head.rotated({0, 1, 0}, head_turn).translated({0.6f, kY + 0.22f, 0});

    // Legs: dark capsules with paws.
    std::vector<Shape> legs;
    for (float x : {0.3f, -0.35f})
        for (float z : {-0.13f, 0.13f}) {
            const float step = rng.uniform(-0.06f, 0.06f);
            Shape leg =
                capsule_between(b, {x, kY - 0.05f, z}, {x + step, 0.08f, z}, 0.065f).colored(dark);
            Shape paw = b.sphere(0.075f).translated({x + step + 0.03f, 0.06f, z}).colored(dark);
            legs.push_back(smooth_union(leg, paw, 0.03f));
        }

    // The bushy ringed tail: alternating light and dark spheres along a rising curve (a chain).
    std::vector<Shape> tail;
    const float sway = rng.uniform(-0.25f, 0.25f);
    for (int i = 0; i < 7; ++i) {
        const float t = float(i) / 6.0f;
        const vec3 p{-0.6f - 0.66f * t, kY + 0.08f + 0.3f * t * t, sway * t * t};
        tail.push_back(b.sphere(0.14f + 0.03f * std::sin(kPi * t) - 0.05f * t)
                           .translated(p)
                           .colored(i % 2 ? dark : fur));
    }
    Shape tail_shape = chain(tail, 0.05f);

    Shape animal = smooth_union(body, head, 0.06f);
    animal = smooth_union(animal, union_all(legs, 0.03f), 0.06f);
    // Turned three-quarters towards the default view, so the masked face shows.
    return build_scene_of(b, smooth_union(animal, tail_shape, 0.05f).rotated({0, 1, 0}, -0.4f));
}

Shape person(SceneBuilder& b, Rng& rng, uint32_t primitives) {
    const vec3 skin = pick(kSkin, rng);
    const vec3 shirt = vary(pick(kCloth, rng), 0.06f, rng);
    const vec3 pants = pick(kTrousers, rng);
    const vec3 hair = pick(kHair, rng);
    const float stride = rng.uniform(-0.25f, 0.25f);  // leg and arm swing, walking

    // The 7 every person has: legs, torso, arms, head, hair.
    std::vector<Shape> body;
    for (float s : {-1.0f, 1.0f})
        body.push_back(
            capsule_between(b, {s * 0.1f, 0.9f, 0}, {s * 0.11f, 0.1f, s * stride}, 0.075f)
                .colored(pants));
    body.push_back(capsule_between(b, {0, 1.0f, 0}, {0, 1.36f, 0}, 0.17f).colored(shirt));
    for (float s : {-1.0f, 1.0f})
        body.push_back(
            capsule_between(b, {s * 0.22f, 1.4f, 0}, {s * 0.29f, 0.88f, -s * stride * 0.8f}, 0.055f)
                .colored(shirt));
    Shape figure = union_all(body, 0.04f);
    Shape head = b.sphere(0.13f).translated({0, 1.6f, 0}).colored(skin);
    head = head | b.sphere(0.132f).translated({0, 1.64f, -0.03f}).colored(hair);

    // Extras to reach exactly `primitives`: singles (nose, backpack, skirt) and pairs (feet,
    // hands, eyes, hat), as many singles as the parity needs.
    const int extra = int(primitives) - 7;
    int singles_lo = std::max(extra - 8, 0), singles_hi = std::min(extra, 3);
    if ((extra - singles_lo) % 2) ++singles_lo;
    if ((extra - singles_hi) % 2) --singles_hi;
    int singles = singles_lo + 2 * uniform_int(rng, 0, (singles_hi - singles_lo) / 2);
    int pairs = (extra - singles) / 2;
    std::array<int, 3> single_order = {0, 1, 2};
    std::array<int, 4> pair_order = {0, 1, 2, 3};
    for (int i = 2; i > 0; --i)
        std::swap(single_order[size_t(i)], single_order[size_t(uniform_int(rng, 0, i))]);
    for (int i = 3; i > 0; --i)
        std::swap(pair_order[size_t(i)], pair_order[size_t(uniform_int(rng, 0, i))]);
    for (int i = 0; i < singles; ++i) {
        switch (single_order[size_t(i)]) {
            case 0:
                head = head | b.sphere(0.03f).translated({0, 1.59f, 0.13f}).colored(skin);
                break;
            case 1:
                figure = figure | b.box({0.28f, 0.36f, 0.14f}, vec4(0.04f, 0.04f, 0.04f, 0.04f),
                                        0.04f, 0.04f)
                                      .translated({0, 1.2f, -0.22f})
                                      .colored(vary(pick(kCloth, rng), 0.05f, rng));
                break;
            default:
                figure = smooth_union(
                    figure, b.cone(0.3f, 0.6f).translated({0, 0.98f, 0}).colored(shirt), 0.03f);
                break;
        }
    }
    for (int i = 0; i < pairs; ++i) {
        const int what = pair_order[size_t(i)];
        if (what == 3) {  // hat: brim and crown
            const vec3 c = vary({0.25f, 0.2f, 0.15f}, 0.1f, rng);
            head = head | (b.cylinder(0.2f, 0.02f).translated({0, 1.71f, 0}).colored(c) |
                           b.cylinder(0.12f, 0.16f).translated({0, 1.79f, 0}).colored(c));
            continue;
        }
        for (float s : {-1.0f, 1.0f}) {
            if (what == 0)  // feet
                figure = smooth_union(figure,
                                      capsule_between(b, {s * 0.11f, 0.06f, s * stride - 0.03f},
                                                      {s * 0.11f, 0.06f, s * stride + 0.1f}, 0.05f)
                                          .colored({0.15f, 0.12f, 0.1f}),
                                      0.03f);
            else if (what == 1)  // hands
                figure = smooth_union(figure,
                                      b.sphere(0.06f)
                                          .translated({s * 0.3f, 0.84f, -s * stride * 0.85f})
                                          .colored(skin),
                                      0.03f);
            else  // eyes
                head = head | b.sphere(0.024f)
                                  .translated({s * 0.045f, 1.64f, 0.115f})
                                  .colored({0.05f, 0.05f, 0.05f});
        }
    }
    return smooth_union(figure, head, 0.05f);
}

Scene crowd(uint64_t seed, uint32_t primitives) {
    Rng rng(seed);
    // One primitive for the plaza, the rest for people of 7..16 primitives each.
    const std::vector<uint32_t> budgets = split_budget(primitives - 1, 7, 16, rng);
    const uint32_t n = uint32_t(budgets.size());
    uint32_t cols, rows;
    grid_shape(n, cols, rows);
    const float spacing = 0.95f;
    const vec3 origin{-0.5f * spacing * float(cols - 1), 0, -0.5f * spacing * float(rows - 1)};

    std::vector<vec3> where(n);
    std::vector<uint32_t> roots(n);
    Assembly a;
    a.reserve(size_t(primitives) * 2);
    for (uint32_t i = 0; i < n; ++i) {
        const float jx = rng.uniform(-0.25f, 0.25f);
        const float jz = rng.uniform(-0.25f, 0.25f);
        where[i] =
            origin + vec3{(float(i % cols) + jx) * spacing, 0, (float(i / cols) + jz) * spacing};
        // Mostly facing the camera side (+z), some turned to chat; a few children.
        const float turn = rng.uniform() < 0.8f ? rng.uniform(-0.7f, 0.7f) : rng.uniform(-kPi, kPi);
        const float size =
            rng.uniform() < 0.1f ? rng.uniform(0.6f, 0.75f) : rng.uniform(0.92f, 1.08f);
        SceneBuilder b;
        Shape p =
            person(b, rng, budgets[i]).scaled(size).rotated({0, 1, 0}, turn).translated(where[i]);
        roots[i] = a.add(b, p);
    }
    // People in Morton order, so subtrees of the balanced union are compact neighbourhoods.
    const std::vector<uint32_t> order = morton_order(where);
    std::vector<uint32_t> sorted(n);
    for (uint32_t i = 0; i < n; ++i) sorted[i] = roots[order[i]];
    const uint32_t people = a.balanced(sorted, math::kOpUnion, 0);

    PrimitiveShape plaza;
    plaza.sides = {spacing * float(cols) + 1.0f, 0.1f, spacing * float(rows) + 1.0f};
    plaza.bevel = vec4(0.4f, 0.4f, 0.4f, 0.4f);
    plaza.round_x = 0.03f;
    const uint32_t ground = a.add_primitive(
        math::kPrimBox, plaza, Affine::translation({0, 0.05f, 0}), {0.62f, 0.6f, 0.56f});
    return a.build(a.combine(math::kOpUnion, ground, people, 0));
}

}  // namespace sdfprune::gen
