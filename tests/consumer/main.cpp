// main.cpp — builds a scene with the installed headers, prunes it (the grid sharing the
// scene's ownership) and checks a value: exits 0 when the installed package works.
#include <cmath>
#include <cstdio>
#include <memory>

#include <sdfprune/builder.hpp>
#include <sdfprune/prune.hpp>

int main() {
    using namespace sdfprune;
    SceneBuilder b;
    auto scene = std::make_shared<const Scene>(b.build(b.sphere(1.0f) - b.box({1, 1, 1})));
    PrunedGrid grid = prune(scene, {.resolution = 32});
    scene.reset();  // the grid keeps it alive
    float stack[16];
    const float d = grid.eval({0.0f, 0.0f, 0.9f}, stack);  // inside the sphere, outside the box
    std::printf("consumer: f = %g, %u nodes\n", d, grid.scene().size());
    return std::fabs(d + 0.1f) < 1e-5f ? 0 : 1;
}
