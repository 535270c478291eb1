// devices.cpp — hard-surface gadgets, mostly hard CSG with differences for slots, holes and
// recesses: "console" (a game console and its controller, 31 primitives), "gameboy" (a
// handheld with screen, d-pad and speaker slots, 33) and "camera" (a reflex camera with lens
// barrel, dials and grip, 60).
#include <array>

#include "generate_internal.hpp"

namespace sdfprune::gen {
namespace {

// A box seen from +z: width w (x), height h (y), depth d (z). Corner radii in the xy face:
// bottom-right, top-right, bottom-left, top-left; `round` rounds the front and back rims.
Shape panel(SceneBuilder& b, float w, float h, float d, vec4 corners = {}, float round = 0) {
    return face_z(b.box({w, d, h}, corners, round, round));
}
vec4 corners(float r) {
    return {r, r, r, r};
}

}  // namespace

Scene console(uint64_t seed) {
    Rng rng(seed);
    SceneBuilder b;
    const bool white = rng.uniform() < 0.5f;
    const vec3 shell = white ? vec3{0.92f, 0.92f, 0.9f} : vec3{0.1f, 0.1f, 0.11f};
    const vec3 trim = white ? vec3{0.12f, 0.12f, 0.14f} : vec3{0.3f, 0.3f, 0.32f};
    const vec3 glow = vary({0.2f, 0.55f, 1.0f}, 0.1f, rng);

    // The console: a rounded slab with a gently domed top (an intersection), a disc slot and
    // ports cut into the front, vents cut into the top, buttons, a light strip and a logo.
    Shape body = b.box({1.6f, 0.35f, 1.2f}, corners(0.08f), 0.04f, 0.02f)
                     .translated({0, 0.175f, 0})
                     .colored(shell);
    body =
        smooth_intersection(body, b.sphere(5.0f).translated({0, -4.65f, 0}).colored(shell), 0.02f);
    std::vector<Shape> cuts;
    cuts.push_back(b.box({0.55f, 0.025f, 0.2f}).translated({-0.1f, 0.22f, 0.6f}));  // disc slot
    for (int i = 0; i < 2; ++i)                                                     // USB ports
        cuts.push_back(
            b.box({0.08f, 0.03f, 0.08f}).translated({-0.6f + 0.13f * float(i), 0.13f, 0.6f}));
    for (int i = 0; i < 5; ++i)  // vents
        cuts.push_back(b.box({0.035f, 0.1f, 0.75f}, corners(0.015f))
                           .translated({0.22f + 0.1f * float(i), 0.36f, -0.12f}));
    body = body - union_all(cuts);
    std::vector<Shape> parts = {body};
    parts.push_back(b.box({1.3f, 0.016f, 0.03f}).translated({0, 0.07f, 0.59f}).colored(glow));
    for (float x : {0.45f, 0.6f})
        parts.push_back(
            face_z(b.cylinder(0.035f, 0.04f)).translated({x, 0.22f, 0.6f}).colored(trim));
    parts.push_back(b.torus(0.09f, 0.014f).translated({-0.45f, 0.33f, 0.15f}).colored(glow));
    Shape console_shape = union_all(parts);

    // The controller, lying in front: body and grips blended, d-pad, face buttons, sticks,
    // shoulder and option buttons, touch pad; its cable runs to the console.
    const vec3 pad = white ? vec3{0.94f, 0.94f, 0.93f} : vec3{0.13f, 0.13f, 0.15f};
    Shape ctrl = b.box({0.5f, 0.1f, 0.26f}, corners(0.1f), 0.04f, 0.04f)
                     .translated({0, 0.07f, 0})
                     .colored(pad);
    for (float s : {-1.0f, 1.0f})
        ctrl = smooth_union(
            ctrl,
            capsule_between(b, {s * 0.2f, 0.07f, 0.02f}, {s * 0.3f, 0.06f, 0.22f}, 0.08f)
                .colored(pad),
            0.06f);
    std::vector<Shape> controls;
    controls.push_back(b.box({0.1f, 0.03f, 0.032f}).translated({-0.17f, 0.12f, 0}).colored(trim));
    controls.push_back(b.box({0.032f, 0.03f, 0.1f}).translated({-0.17f, 0.12f, 0}).colored(trim));
    const std::array<vec3, 4> button_colors = {vec3{0.2f, 0.75f, 0.6f}, vec3{0.9f, 0.25f, 0.3f},
                                               vec3{0.3f, 0.5f, 0.95f}, vec3{0.9f, 0.5f, 0.8f}};
    const std::array<vec3, 4> button_at = {vec3{0.17f, 0.12f, -0.04f}, vec3{0.21f, 0.12f, 0},
                                           vec3{0.17f, 0.12f, 0.04f}, vec3{0.13f, 0.12f, 0}};
    for (size_t i = 0; i < 4; ++i)
        controls.push_back(b.sphere(0.02f).translated(button_at[i]).colored(button_colors[i]));
    for (float s : {-1.0f, 1.0f}) {
        controls.push_back(
            b.cylinder(0.036f, 0.05f).translated({s * 0.07f, 0.13f, 0.07f}).colored(trim));
        controls.push_back(
            face_x(b.capsule(0.025f, 0.1f)).translated({s * 0.17f, 0.09f, -0.13f}).colored(trim));
        controls.push_back(b.capsule(0.011f, 0.025f)
                               .rotated({1, 0, 0}, kPi / 2)
                               .translated({s * 0.1f, 0.118f, -0.07f})
                               .colored(trim));
    }
    controls.push_back(
        b.box({0.14f, 0.02f, 0.08f}, corners(0.01f)).translated({0, 0.115f, -0.05f}).colored(trim));
    ctrl = ctrl | union_all(controls);
    const float turn = rng.uniform(-0.35f, 0.35f);
    const vec3 at{rng.uniform(-0.15f, 0.15f), 0, 1.05f};
    ctrl = ctrl.rotated({0, 1, 0}, turn).translated(at);
    const vec3 plug = at + vec3{-0.14f * std::sin(turn), 0.06f, -0.14f * std::cos(turn)};
    Shape cable =
        capsule_between(b, plug, {0.3f, 0.12f, 0.6f}, 0.012f).colored({0.05f, 0.05f, 0.05f});
    return build_scene_of(b, console_shape | smooth_union(ctrl, cable, 0.02f));
}

Scene gameboy(uint64_t seed) {
    Rng rng(seed);
    SceneBuilder b;
    constexpr std::array<vec3, 5> kShells = {vec3{0.78f, 0.77f, 0.72f}, vec3{0.55f, 0.45f, 0.75f},
                                             vec3{0.95f, 0.82f, 0.2f}, vec3{0.25f, 0.6f, 0.4f},
                                             vec3{0.85f, 0.25f, 0.3f}};
    const vec3 shell = pick(kShells, rng);
    const vec3 dark{0.12f, 0.12f, 0.13f}, magenta{0.6f, 0.1f, 0.35f}, grey{0.55f, 0.55f, 0.58f};
    const vec3 lcd{0.6f, 0.68f, 0.25f}, pixel{0.18f, 0.26f, 0.1f};
    constexpr float kFront = 0.16f;  // z of the front face

    // The shell: the famous large bottom-right corner; a bezel plate; cuts for the screen,
    // button wells, speaker slots, top ridges, headphone jack and link port.
    Shape shell_shape =
        panel(b, 0.9f, 1.48f, 0.32f, {0.25f, 0.04f, 0.04f, 0.04f}, 0.03f).colored(shell);
    Shape bezel = panel(b, 0.76f, 0.62f, 0.03f, {0.12f, 0.03f, 0.03f, 0.03f})
                      .translated({0, 0.33f, kFront})
                      .colored({0.35f, 0.36f, 0.42f});
    shell_shape = shell_shape | bezel;
    shell_shape =
        shell_shape - panel(b, 0.48f, 0.43f, 0.06f).translated({0.02f, 0.33f, kFront + 0.01f});
    std::vector<Shape> cuts;
    auto well = [&](vec3 at, float r) { return face_z(b.cylinder(r, 0.04f)).translated(at); };
    cuts.push_back(well({-0.22f, -0.2f, kFront}, 0.14f));
    const vec3 a_at{0.3f, -0.14f, kFront}, b_at{0.12f, -0.23f, kFront};
    cuts.push_back(well(a_at, 0.08f));
    cuts.push_back(well(b_at, 0.08f));
    auto pill = [&](vec3 at, float r, float len) {
        return face_x(b.capsule(r, len)).rotated({0, 0, 1}, 0.45f).translated(at);
    };
    const vec3 select_at{-0.09f, -0.48f, kFront}, start_at{0.08f, -0.48f, kFront};
    cuts.push_back(pill(select_at, 0.03f, 0.09f));
    cuts.push_back(pill(start_at, 0.03f, 0.09f));
    for (int i = 0; i < 6; ++i)
        cuts.push_back(face_x(b.capsule(0.013f, 0.2f))
                           .rotated({0, 0, 1}, 1.0f)
                           .translated({0.2f + 0.05f * float(i), -0.56f, kFront + 0.01f}));
    for (int i = 0; i < 2; ++i)
        cuts.push_back(
            b.box({0.86f, 0.012f, 0.05f}).translated({0, 0.7f - 0.04f * float(i), kFront}));
    cuts.push_back(b.cylinder(0.03f, 0.12f).translated({-0.26f, -0.74f, 0}));
    cuts.push_back(b.box({0.06f, 0.1f, 0.08f}).translated({-0.45f, 0.32f, 0}));
    shell_shape = shell_shape - union_all(cuts);

    // What sits on it: LCD glass with a falling Tetris piece, power LED, d-pad cross, A and B,
    // start and select, power switch, cartridge, volume wheel.
    std::vector<Shape> parts;
    parts.push_back(
        panel(b, 0.46f, 0.41f, 0.02f).translated({0.02f, 0.33f, kFront - 0.01f}).colored(lcd));
    const int drop = uniform_int(rng, 0, 4);
    const std::array<vec3, 4> piece = {vec3{0, 0, 0}, vec3{0, 1, 0}, vec3{0, 2, 0}, vec3{1, 0, 0}};
    for (const vec3& c : piece)
        parts.push_back(b.box({0.05f, 0.05f, 0.01f})
                            .translated(vec3{-0.08f + 0.052f * c.x,
                                             0.2f + 0.052f * (c.y + float(drop)), kFront})
                            .colored(pixel));
    parts.push_back(
        b.sphere(0.02f).translated({-0.31f, 0.38f, kFront + 0.01f}).colored({0.95f, 0.1f, 0.1f}));
    parts.push_back(panel(b, 0.23f, 0.075f, 0.08f, corners(0.01f))
                        .translated({-0.22f, -0.2f, kFront})
                        .colored(dark));
    parts.push_back(panel(b, 0.075f, 0.23f, 0.08f, corners(0.01f))
                        .translated({-0.22f, -0.2f, kFront})
                        .colored(dark));
    for (const vec3& at : {a_at, b_at})
        parts.push_back(face_z(b.cylinder(0.065f, 0.07f)).translated(at).colored(magenta));
    for (const vec3& at : {select_at, start_at})
        parts.push_back(pill(at, 0.02f, 0.08f).colored(grey));
    parts.push_back(b.box({0.12f, 0.06f, 0.08f}).translated({-0.28f, 0.75f, 0.04f}).colored(grey));
    parts.push_back(
        b.box({0.56f, 0.14f, 0.07f}, corners(0.01f)).translated({0, 0.76f, -0.09f}).colored(grey));
    parts.push_back(face_x(b.cylinder(0.07f, 0.04f)).translated({0.45f, -0.02f, 0}).colored(grey));
    return build_scene_of(b, shell_shape | union_all(parts));
}

Scene camera(uint64_t seed) {
    Rng rng(seed);
    SceneBuilder b;
    const bool silver = rng.uniform() < 0.3f;
    const vec3 body_c = silver ? vec3{0.75f, 0.75f, 0.77f} : vec3{0.1f, 0.1f, 0.11f};
    const vec3 rubber{0.06f, 0.06f, 0.06f}, metal{0.7f, 0.7f, 0.72f}, black{0.03f, 0.03f, 0.035f};
    const vec3 glass{0.12f, 0.16f, 0.3f}, red{0.8f, 0.1f, 0.08f};
    constexpr float kAxisY = 0.45f;  // height of the lens axis

    // Body, grip and the pentaprism hump (a box intersected with a box turned 45°).
    Shape body = b.box({1.4f, 0.9f, 0.55f}, corners(0.1f), 0.07f, 0.05f)
                     .translated({0, 0.45f, 0})
                     .colored(body_c);
    body = smooth_union(
        body, b.capsule(0.2f, 0.42f).translated({-0.52f, 0.43f, 0.2f}).colored(body_c), 0.08f);
    body = body | b.box({0.32f, 0.6f, 0.12f}, corners(0.05f), 0.04f, 0.04f)
                      .translated({-0.52f, 0.42f, 0.33f})
                      .colored(rubber);
    Shape hump = b.box({0.5f, 0.34f, 0.42f}).translated({0, 1.0f, -0.03f}).colored(body_c);
    hump = hump & b.box({0.7f, 0.7f, 0.5f})
                      .rotated({0, 0, 1}, kPi / 4)
                      .translated({0, 0.78f, -0.03f})
                      .colored(body_c);
    body = smooth_union(body, hump, 0.04f);
    body = body | b.box({0.16f, 0.03f, 0.2f}).translated({0, 1.16f, -0.03f}).colored(metal);
    body = body | panel(b, 0.22f, 0.16f, 0.1f, corners(0.05f), 0.02f)
                      .translated({0, 0.98f, -0.3f})
                      .colored(rubber);

    // Lens: mount ring, barrel sections, zoom ring with ridges, focus ring, red ring, a hollow
    // front with domed glass (a sphere intersected with a cylinder).
    auto ring = [&](float z, float r, float minor, vec3 c) {
        return face_z(b.torus(r, minor)).translated({0, kAxisY, z}).colored(c);
    };
    auto tube = [&](float z, float r, float len, vec3 c) {
        return face_z(b.cylinder(r, len)).translated({0, kAxisY, z}).colored(c);
    };
    std::vector<Shape> lens = {ring(0.29f, 0.3f, 0.03f, metal), tube(0.38f, 0.3f, 0.2f, black),
                               tube(0.6f, 0.32f, 0.25f, rubber)};
    for (int i = 0; i < 6; ++i)
        lens.push_back(ring(0.5f + 0.04f * float(i), 0.32f, 0.012f, rubber));
    lens.push_back(tube(0.82f, 0.29f, 0.18f, black));
    lens.push_back(tube(0.97f, 0.31f, 0.12f, rubber));
    lens.push_back(ring(0.9f, 0.293f, 0.012f, red));
    Shape front = tube(1.08f, 0.33f, 0.1f, black) - tube(1.15f, 0.26f, 0.2f, black);
    lens.push_back(front);
    lens.push_back(b.sphere(0.45f).translated({0, kAxisY, 0.65f}).colored(glass) &
                   tube(1.0f, 0.26f, 0.2f, glass));
    lens.push_back(ring(1.13f, 0.295f, 0.01f, metal));
    Shape lens_shape = union_all(lens);

    // Top controls: knurled mode dial and control dial (notches cut out), shutter with collar,
    // top status panel.
    auto knurled = [&](vec3 at, float r, float h, int notches) {
        Shape dial = b.cylinder(r, h).translated(at).colored(body_c);
        std::vector<Shape> cut;
        for (int i = 0; i < notches; ++i) {
            const float a = 2 * kPi * float(i) / float(notches);
            cut.push_back(b.box({0.03f, h * 1.5f, 0.05f})
                              .translated({r, 0, 0})
                              .rotated({0, 1, 0}, a)
                              .translated(at));
        }
        return dial - union_all(cut);
    };
    std::vector<Shape> top = {knurled({0.45f, 0.94f, -0.05f}, 0.14f, 0.08f, 6),
                              knurled({-0.3f, 0.92f, -0.12f}, 0.11f, 0.05f, 4)};
    top.push_back(b.cylinder(0.05f, 0.06f).translated({-0.52f, 0.93f, 0.14f}).colored(metal));
    top.push_back(b.torus(0.065f, 0.016f).translated({-0.52f, 0.91f, 0.14f}).colored(body_c));
    top.push_back(b.box({0.24f, 0.02f, 0.18f}, corners(0.02f))
                      .translated({0.34f, 0.9f, 0.14f})
                      .colored(glass));

    // Front details, strap lugs; back screen (recessed), buttons, d-pad; side port doors and
    // microphone holes.
    std::vector<Shape> details;
    details.push_back(
        face_z(b.cylinder(0.045f, 0.04f)).translated({0.42f, 0.35f, 0.28f}).colored(metal));
    details.push_back(
        face_z(b.cylinder(0.03f, 0.04f)).translated({0.38f, 0.18f, 0.28f}).colored(body_c));
    details.push_back(
        b.sphere(0.035f).translated({-0.34f, 0.75f, 0.27f}).colored({0.9f, 0.45f, 0.1f}));
    details.push_back(b.sphere(0.03f).translated({-0.3f, 0.22f, 0.27f}).colored(black));
    details.push_back(
        panel(b, 0.3f, 0.06f, 0.04f, corners(0.01f)).translated({0, 0.96f, 0.18f}).colored(metal));
    details.push_back(panel(b, 0.34f, 0.1f, 0.02f).translated({0, 1.06f, 0.17f}).colored(black));
    for (float s : {-1.0f, 1.0f})
        details.push_back(
            face_x(b.torus(0.05f, 0.015f)).translated({s * 0.72f, 0.78f, 0}).colored(metal));
    std::vector<Shape> back = {
        panel(b, 0.7f, 0.46f, 0.02f).translated({-0.12f, 0.42f, -0.27f}).colored(glass)};
    for (int i = 0; i < 4; ++i)
        back.push_back(face_z(b.cylinder(0.035f, 0.04f))
                           .translated({0.42f, 0.72f - 0.12f * float(i), -0.28f})
                           .colored(black));
    back.push_back(face_z(b.torus(0.07f, 0.015f)).translated({0.5f, 0.2f, -0.28f}).colored(black));
    back.push_back(
        face_z(b.cylinder(0.035f, 0.04f)).translated({0.5f, 0.2f, -0.28f}).colored(metal));
    for (int i = 0; i < 2; ++i)
        details.push_back(panel(b, 0.04f, 0.18f, 0.3f, corners(0.015f), 0.01f)
                              .translated({0.7f, 0.6f - 0.25f * float(i), 0.02f})
                              .colored(rubber));
    std::vector<Shape> holes = {panel(b, 0.74f, 0.5f, 0.05f).translated({-0.12f, 0.42f, -0.275f}),
                                b.box({0.05f, 0.005f, 0.4f}).translated({-0.72f, 0.3f, 0}),
                                b.sphere(0.018f).translated({-0.15f, 1.12f, 0.1f}),
                                b.sphere(0.018f).translated({0.15f, 1.12f, 0.1f})};
    body = body - union_all(holes);

    Shape camera_shape = union_all(
        std::vector<Shape>{body, lens_shape, union_all(top), union_all(details), union_all(back)});
    const float yaw = rng.uniform(-0.5f, -0.2f);
    return build_scene_of(b, camera_shape.rotated({0, 1, 0}, yaw));
}

}  // namespace sdfprune::gen
