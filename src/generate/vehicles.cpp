// vehicles.cpp — cars and trains: "car" (a hatchback with sloped glass cut by intersections,
// window and wheel-arch differences, spoked wheels, 59 primitives), "car-chase" (police cars
// after a car down a street, 280) and "train-station" (a train at a platform under a vaulted
// roof, 60).
#include <array>

#include "generate_internal.hpp"

namespace sdfprune::gen {
namespace {

vec4 corners(float r) {
    return {r, r, r, r};
}

// A wheel in the xy plane at `at`: tyre (torus), rim with four holes, hub cap. 7 primitives.
Shape wheel(SceneBuilder& b, vec3 at, float side) {
    const vec3 tyre{0.08f, 0.08f, 0.09f}, alloy{0.72f, 0.73f, 0.76f};
    Shape rim = face_z(b.cylinder(0.22f, 0.18f)).colored(alloy);
    std::vector<Shape> holes;
    for (int i = 0; i < 4; ++i) {
        const float a = kPi / 4 + float(i) * kPi / 2;
        holes.push_back(face_z(b.cylinder(0.05f, 0.4f))
                            .translated({0.13f * std::cos(a), 0.13f * std::sin(a), 0}));
    }
    Shape w = face_z(b.torus(0.23f, 0.11f)).colored(tyre) | (rim - union_all(holes));
    w = w | b.sphere(0.07f).translated({0, 0, side * 0.07f}).colored(alloy);
    return w.translated(at);
}

}  // namespace

Shape car_shape(SceneBuilder& b, Rng& rng, vec3 paint, bool police) {
    const vec3 glass{0.08f, 0.1f, 0.14f}, chrome{0.75f, 0.75f, 0.78f}, trim{0.12f, 0.12f, 0.13f};
    const vec3 lamp{1.0f, 0.95f, 0.75f}, tail{0.85f, 0.08f, 0.06f}, plate{0.95f, 0.95f, 0.9f};

    // Lower body with wheel arches cut out of its sides.
    Shape body = b.box({4.0f, 0.62f, 1.8f}, corners(0.4f), 0.15f, 0.08f)
                     .translated({0, 0.66f, 0})
                     .colored(paint);
    std::vector<Shape> arches;
    for (float x : {-1.3f, 1.3f})
        for (float z : {-0.8f, 0.8f})
            arches.push_back(face_z(b.cylinder(0.42f, 0.5f)).translated({x, 0.34f, z}));

    // Cabin: a box cut to a sloped windscreen and hatch (intersections), side windows cut
    // through (differences) onto a dark interior, glass panels on the slopes.
    const vec3 wind_n = normalized({0.55f, 0.65f, 0}), hatch_n = normalized({-0.55f, 0.25f, 0});
    Shape cabin = b.box({2.5f, 0.62f, 1.62f}, corners(0.3f), 0.12f, 0)
                      .translated({-0.3f, 1.2f, 0})
                      .colored(paint);
    cabin = cabin & half_space(b, {0.95f, 0.95f, 0}, wind_n, 4).colored(paint);
    cabin = cabin & half_space(b, {-1.55f, 0.95f, 0}, hatch_n, 4).colored(paint);
    Shape windows = b.box({0.9f, 0.38f, 2.0f}).translated({-0.1f, 1.19f, 0}) |
                    b.box({0.6f, 0.38f, 2.0f}).translated({-0.95f, 1.19f, 0});
    cabin = (cabin - windows) |
            b.box({1.7f, 0.45f, 1.5f}).translated({-0.45f, 1.18f, 0}).colored(glass);
    auto pane = [&](vec3 mid, vec3 n, float length, float width) {
        return b.box({length, 0.02f, width}, corners(0.05f))
            .transformed(rotation_from_y(n))
            .translated(mid)
            .colored(glass);
    };
    cabin = cabin | pane(vec3{0.62f, 1.22f, 0} + wind_n * 0.005f, wind_n, 0.26f, 1.4f);
    cabin = cabin | pane(vec3{-1.43f, 1.22f, 0} + hatch_n * 0.005f, hatch_n, 0.4f, 1.3f);
    body = smooth_union(body - union_all(arches), cabin, 0.06f);

    // Front and back: grille recess with slats, lights, bumpers, plates, exhaust.
    body = body - b.box({0.12f, 0.16f, 0.8f}).translated({2.0f, 0.64f, 0});
    std::vector<Shape> parts = {body};
    for (float y : {0.6f, 0.68f})
        parts.push_back(b.box({0.05f, 0.025f, 0.78f}).translated({1.96f, y, 0}).colored(chrome));
    for (float z : {-0.6f, 0.6f}) {
        parts.push_back(b.sphere(0.13f).translated({1.9f, 0.76f, z}).colored(lamp));
        parts.push_back(b.box({0.06f, 0.12f, 0.32f}).translated({-1.99f, 0.8f, z}).colored(tail));
    }
    for (float x : {-2.02f, 2.02f}) {
        parts.push_back(b.capsule(0.1f, 1.4f)
                            .rotated({1, 0, 0}, kPi / 2)
                            .translated({x, 0.44f, 0})
                            .colored(trim));
        parts.push_back(b.box({0.02f, 0.12f, 0.45f})
                            .translated({x + (x > 0 ? 0.1f : -0.1f), 0.46f, 0})
                            .colored(plate));
    }
    parts.push_back(
        face_x(b.cylinder(0.05f, 0.25f)).translated({-2.05f, 0.3f, 0.5f}).colored(chrome) -
        face_x(b.cylinder(0.035f, 0.3f)).translated({-2.05f, 0.3f, 0.5f}));
    for (float z : {-0.92f, 0.92f})
        parts.push_back(
            b.box({0.15f, 0.1f, 0.12f}, corners(0.03f)).translated({0.7f, 1.0f, z}).colored(paint));

    // Wheels.
    for (float x : {-1.3f, 1.3f})
        for (float z : {-0.78f, 0.78f})
            parts.push_back(wheel(b, {x, 0.34f, z}, z > 0 ? 1.0f : -1.0f));

    // Roof: an antenna and door handles, or a police light bar in their place.
    if (police) {
        parts.push_back(b.box({0.3f, 0.08f, 1.1f}, corners(0.03f))
                            .translated({-0.35f, 1.55f, 0})
                            .colored(trim));
        parts.push_back(b.box({0.22f, 0.1f, 0.4f}, corners(0.03f))
                            .translated({-0.35f, 1.6f, -0.28f})
                            .colored({0.95f, 0.1f, 0.1f}));
        parts.push_back(b.box({0.22f, 0.1f, 0.4f}, corners(0.03f))
                            .translated({-0.35f, 1.6f, 0.28f})
                            .colored({0.1f, 0.3f, 1.0f}));
    } else {
        parts.push_back(
            capsule_between(b, {-1.2f, 1.45f, 0.3f}, {-1.35f, 1.85f, 0.3f}, 0.012f).colored(trim));
        for (float z : {-0.9f, 0.9f})
            parts.push_back(
                face_x(b.capsule(0.02f, 0.12f)).translated({0.1f, 0.88f, z}).colored(chrome));
    }
    (void)rng;
    return union_all(parts);
}

Scene car(uint64_t seed) {
    Rng rng(seed);
    constexpr std::array<vec3, 6> kPaint = {vec3{0.75f, 0.08f, 0.08f}, vec3{0.1f, 0.3f, 0.75f},
                                            vec3{0.95f, 0.75f, 0.1f},  vec3{0.15f, 0.5f, 0.25f},
                                            vec3{0.85f, 0.85f, 0.87f}, vec3{0.95f, 0.45f, 0.1f}};
    SceneBuilder b;
    const vec3 paint = vary(pick(kPaint, rng), 0.04f, rng);
    return build_scene_of(b, car_shape(b, rng, paint, false));
}

Scene car_chase(uint64_t seed) {
    Rng rng(seed);
    SceneBuilder b;
    const vec3 asphalt{0.22f, 0.22f, 0.24f}, curb{0.62f, 0.6f, 0.58f},
        paint_line{0.95f, 0.95f, 0.9f};
    constexpr float kLength = 24;
    std::vector<Shape> street;
    street.push_back(b.box({kLength, 0.2f, 9}).translated({0, -0.1f, 0}).colored(asphalt));
    for (float z : {-5.5f, 5.5f})
        street.push_back(b.box({kLength, 0.3f, 2}, {}, 0.05f).translated({0, 0, z}).colored(curb));
    for (int i = 0; i < 12; ++i)  // lane dashes
        street.push_back(b.box({1.0f, 0.02f, 0.15f})
                             .translated({-kLength / 2 + 1.0f + 2.0f * float(i), 0.005f, 0})
                             .colored(paint_line));

    // Buildings on the far side, window bands recessed into their fronts.
    for (int i = 0; i < 5; ++i) {
        const float w = 4.6f, h = rng.uniform(3.5f, 6.0f);
        const vec3 colour = vary({0.7f, 0.62f, 0.52f}, 0.12f, rng);
        const float x = -9.6f + 4.8f * float(i);
        Shape block = b.box({w, h, 4}, corners(0.1f)).translated({x, h / 2, -8.6f}).colored(colour);
        Shape bands = b.box({w - 0.8f, 0.6f, 1.0f}).translated({x, h * 0.35f, -6.6f}) |
                      b.box({w - 0.8f, 0.6f, 1.0f}).translated({x, h * 0.7f, -6.6f});
        street.push_back(block - bands);
    }
    // Street lamps on the near pavement, traffic cones (two knocked over by the chase).
    for (int i = 0; i < 4; ++i) {
        const float x = -8.4f + 5.6f * float(i);
        street.push_back(
            b.cylinder(0.08f, 5).translated({x, 2.5f, 5.2f}).colored({0.25f, 0.27f, 0.3f}));
        street.push_back(b.sphere(0.3f).translated({x, 5.1f, 5.0f}).colored({1.0f, 0.92f, 0.6f}));
    }
    for (int i = 0; i < 6; ++i) {
        Shape cone = b.cone(0.22f, 0.6f).colored({1.0f, 0.45f, 0.05f});
        if (i >= 4)
            cone = cone.rotated({1, 0, 0}, kPi / 2)
                       .rotated({0, 1, 0}, rng.uniform(0.0f, 2 * kPi))
                       .translated({0, 0.22f, 0});
        else
            cone = cone.translated({0, 0.3f, 0});
        street.push_back(cone.translated({3.0f + 0.9f * float(i), 0, 2.8f - 0.5f * float(i % 2)}));
    }

    // The chase: the getaway car ahead, two police cars after it (one drifting), and a car in
    // the other lane swerving out of the way.
    const vec3 getaway = vary({0.1f, 0.1f, 0.12f}, 0.05f, rng), police{0.95f, 0.95f, 0.96f};
    std::vector<Shape> cars;
    cars.push_back(car_shape(b, rng, getaway, false)
                       .rotated({0, 1, 0}, rng.uniform(-0.1f, 0.1f))
                       .translated({7, 0, 1.8f}));
    cars.push_back(car_shape(b, rng, police, true)
                       .rotated({0, 1, 0}, rng.uniform(0.25f, 0.4f))
                       .translated({0.5f, 0, 1.5f}));
    cars.push_back(car_shape(b, rng, police, true)
                       .rotated({0, 1, 0}, rng.uniform(-0.1f, 0.1f))
                       .translated({-6, 0, 2.4f}));
    cars.push_back(car_shape(b, rng, vary({0.2f, 0.45f, 0.8f}, 0.1f, rng), false)
                       .rotated({0, 1, 0}, kPi + rng.uniform(0.3f, 0.5f))
                       .translated({5, 0, -2.2f}));
    return build_scene_of(b, union_all(cars) | union_all(street));
}

Scene train_station(uint64_t seed) {
    Rng rng(seed);
    SceneBuilder b;
    const vec3 concrete{0.7f, 0.68f, 0.64f}, ballast{0.45f, 0.4f, 0.36f}, steel{0.55f, 0.56f, 0.6f};
    const vec3 wood{0.45f, 0.3f, 0.18f}, dark{0.1f, 0.1f, 0.12f}, glass{0.12f, 0.16f, 0.22f};
    const vec3 livery = vary({0.8f, 0.15f, 0.12f}, 0.1f, rng), stripe{0.95f, 0.95f, 0.9f};
    constexpr float kRail = 0.3f;  // top of the rails

    // Ground, platform with its yellow edge line, rails and a few sleepers.
    std::vector<Shape> site;
    site.push_back(b.box({18, 0.2f, 8}).translated({0, 0.0f, -0.5f}).colored(ballast));
    site.push_back(
        b.box({18, 1.0f, 2.8f}, {}, 0.03f).translated({0, 0.5f, -2.9f}).colored(concrete));
    site.push_back(
        b.box({18, 0.02f, 0.2f}).translated({0, 1.0f, -1.65f}).colored({0.95f, 0.8f, 0.1f}));
    for (float z : {-0.72f, 0.72f})
        site.push_back(b.box({18, 0.1f, 0.08f}).translated({0, kRail - 0.05f, z}).colored(steel));
    for (int i = 0; i < 5; ++i)
        site.push_back(b.box({0.25f, 0.1f, 2.2f})
                           .translated({-8.5f + 0.7f * float(i), 0.15f, 0})
                           .colored(wood));

    // A rail car: body with a vaulted roof (box ∩ cylinder), windows cut out, a stripe, wheels.
    auto rail_car = [&](float x0, float length, int windows, bool cab) {
        const float h = 2.4f, y = kRail + 0.35f + h / 2;
        Shape body = b.box({length, h, 2.6f}, corners(cab ? 0.5f : 0.15f), 0.05f)
                         .translated({x0, y, 0})
                         .colored(livery);
        body = body &
               face_x(b.cylinder(2.2f, length + 1)).translated({x0, y - 1.0f, 0}).colored(livery);
        std::vector<Shape> cuts;
        for (int i = 0; i < windows; ++i) {
            const float x = x0 - length / 2 + length * (float(i) + 0.5f) / float(windows);
            cuts.push_back(b.box({length / float(windows) * 0.6f, 0.7f, 3}, corners(0.1f))
                               .translated({x, y + 0.3f, 0}));
        }
        if (cab)
            cuts.push_back(
                b.box({1, 0.8f, 2.0f}, corners(0.1f)).translated({x0 + length / 2, y + 0.35f, 0}));
        body = (body - union_all(cuts)) |
               b.box({length - 0.4f, h - 0.5f, 2.4f}).translated({x0, y, 0}).colored(glass);
        body = body |
               b.box({length + 0.02f, 0.15f, 2.62f}).translated({x0, y - 0.55f, 0}).colored(stripe);
        std::vector<Shape> wheels;
        for (float dx : {-length * 0.32f, length * 0.32f})
            for (float z : {-0.72f, 0.72f})
                wheels.push_back(face_z(b.cylinder(0.4f, 0.12f))
                                     .translated({x0 + dx, kRail + 0.4f, z})
                                     .colored(dark));
        return body | union_all(wheels);
    };
    Shape loco = rail_car(3.2f, 5.5f, 1, true);
    loco = loco | b.sphere(0.18f).translated({5.95f, kRail + 1.3f, 0}).colored({1, 0.95f, 0.7f});
    loco = loco | (capsule_between(b, {2.6f, 3.3f, 0}, {3.2f, 3.8f, 0}, 0.04f).colored(dark) |
                   capsule_between(b, {3.8f, 3.3f, 0}, {3.2f, 3.8f, 0}, 0.04f).colored(dark));
    Shape coach = rail_car(-3.0f, 6.0f, 4, false);

    // The vaulted roof over platform and track (a shell: cylinder ∩ upper box − inner
    // cylinder) on four columns; a hanging clock; benches; a waiting passenger; a sign.
    const float roof_y = 3.6f, roof_z = -4.6f;
    Shape roof = face_x(b.cylinder(3.4f, 17)).translated({0, roof_y, roof_z}).colored(steel);
    roof =
        roof & b.box({18, 3.6f, 3.6f}).translated({0, roof_y + 1.8f, roof_z + 1.8f}).colored(steel);
    roof = roof - face_x(b.cylinder(3.25f, 18)).translated({0, roof_y, roof_z});
    std::vector<Shape> station = {roof};
    for (int i = 0; i < 4; ++i)
        station.push_back(cylinder_between(b, {-7.5f + 5 * float(i), 1.0f, -3.9f},
                                           {-7.5f + 5 * float(i), roof_y + 3.2f, -3.9f}, 0.15f)
                              .colored(steel));
    const vec3 clock_at{0, roof_y + 0.4f, -2.4f};
    station.push_back(
        face_z(b.cylinder(0.45f, 0.1f)).translated(clock_at).colored({0.97f, 0.97f, 0.95f}));
    const float hour = rng.uniform(0.0f, 2 * kPi);
    station.push_back(b.box({0.05f, 0.3f, 0.02f})
                          .translated({0, 0.13f, 0})
                          .rotated({0, 0, 1}, hour)
                          .translated(clock_at + vec3{0, 0, 0.06f})
                          .colored(dark));
    station.push_back(b.box({0.04f, 0.4f, 0.02f})
                          .translated({0, 0.18f, 0})
                          .rotated({0, 0, 1}, hour * 12)
                          .translated(clock_at + vec3{0, 0, 0.07f})
                          .colored(dark));
    station.push_back(
        cylinder_between(b, clock_at + vec3{0, 0.4f, 0}, clock_at + vec3{0, 2.8f, 0}, 0.03f)
            .colored(dark));
    for (float x : {-4.0f, 4.5f}) {
        station.push_back(b.box({1.6f, 0.08f, 0.5f}).translated({x, 1.45f, -3.8f}).colored(wood));
        station.push_back(b.box({1.6f, 0.5f, 0.08f}).translated({x, 1.75f, -4.08f}).colored(wood));
    }
    Shape sign = b.box({1.8f, 0.5f, 0.08f}, corners(0.04f))
                     .translated({-1.5f, 2.4f, -4.1f})
                     .colored({0.1f, 0.25f, 0.6f});
    for (float dx : {-0.7f, 0.7f})
        sign = sign | b.cylinder(0.04f, 1.6f).translated({-1.5f + dx, 1.8f, -4.1f}).colored(dark);
    station.push_back(sign);
    station.push_back(person(b, rng, 7)
                          .rotated({0, 1, 0}, rng.uniform(-0.4f, 0.4f))
                          .translated({1.5f, 1.0f, -2.6f}));
    return build_scene_of(b, union_all(site) | (loco | coach) | union_all(station));
}

}  // namespace sdfprune::gen
