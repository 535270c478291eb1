// builtin.cpp — the scenes built into the tool (make run's default scene needs no file).
#include "sdfprune/builtin.hpp"

#include <cmath>
#include <numbers>

#include "sdfprune/builder.hpp"
#include "sdfprune/generate.hpp"

namespace sdfprune {

std::vector<std::string> builtin_scene_names() {
    return {"demo", "sphere"};
}

namespace {

Scene demo_scene() {
    SceneBuilder b;
    Rng rng(7);
    // A random walk of atoms winding round a helix, smoothly blended as a left-deep chain.
    Shape cluster;
    vec3 p(0.0f, 0.0f, 0.0f);
    for (int i = 0; i < 300; ++i) {
        const float t = float(i) * 0.07f;
        const vec3 helix(0.55f * std::cos(t), -0.45f + 0.003f * float(i), 0.55f * std::sin(t));
        const vec3 jitter(rng.uniform(-0.12f, 0.12f), rng.uniform(-0.12f, 0.12f),
                          rng.uniform(-0.12f, 0.12f));
        p = helix + jitter;
        const float r = rng.uniform(0.05f, 0.11f);
        const vec3 color = i % 3 == 0   ? vec3(0.85f, 0.25f, 0.2f)
                           : i % 3 == 1 ? vec3(0.9f, 0.9f, 0.92f)
                                        : vec3(0.25f, 0.45f, 0.85f);
        Shape atom = b.sphere(r).translated(p).colored(color);
        cluster = i == 0 ? atom : smooth_union(cluster, atom, 0.03f);
    }
    // A hole drilled through the cluster and a hard cut of its top.
    Shape drill = b.cylinder(0.18f, 3.0f).rotated({1, 0, 0}, std::numbers::pi_v<float> / 2);
    cluster = smooth_difference(cluster, drill, 0.04f);
    cluster = cluster & b.box({3.0f, 1.25f, 3.0f}).translated({0, -0.1f, 0});
    // A plinth: bevelled box with rounded rims, a torus round it, capsule posts and a cone.
    Shape plinth = b.box({1.8f, 0.2f, 1.8f}, {0.3f, 0.3f, 0.3f, 0.3f}, 0.05f, 0.02f)
                       .translated({0, -0.75f, 0})
                       .colored({0.55f, 0.5f, 0.45f});
    Shape ring = b.torus(0.85f, 0.05f).translated({0, -0.62f, 0}).colored({0.8f, 0.65f, 0.2f});
    Shape base = smooth_union(plinth, ring, 0.05f);
    for (int i = 0; i < 4; ++i) {
        const float a = float(i) * std::numbers::pi_v<float> / 2 + 0.785f;
        Shape post = b.capsule(0.05f, 0.5f)
                         .translated({0.72f * std::cos(a), -0.45f, 0.72f * std::sin(a)})
                         .colored({0.7f, 0.7f, 0.75f});
        base = base | post;
    }
    Shape spire = b.cone(0.12f, 0.4f).translated({0, 0.75f, 0}).colored({0.9f, 0.75f, 0.3f});
    Shape scene = smooth_union(smooth_union(cluster, spire, 0.05f), base, 0.06f);
    return b.build(scene, {vec3(-1.1f, -1.0f, -1.1f), vec3(1.1f, 1.1f, 1.1f)});
}

}  // namespace

Scene builtin_scene(const std::string& name) {
    if (name == "demo") return demo_scene();
    if (name == "sphere") {
        SceneBuilder b;
        return b.build(b.sphere(1.0f), {vec3(-2.0f), vec3(2.0f)});
    }
    for (const std::string& k : generator_kinds())
        if (name == k) return generate_scene(k, 1, 0);
    std::string known;
    for (const std::string& n : builtin_scene_names()) known += (known.empty() ? "" : ", ") + n;
    throw SceneError("unknown built-in scene \"" + name + "\" (known: " + known + ")");
}

}  // namespace sdfprune
