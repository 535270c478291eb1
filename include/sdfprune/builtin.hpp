// builtin.hpp — scenes made in code, so the tool works without any scene file.
#pragma once

#include <string>
#include <vector>

#include "scene.hpp"

namespace sdfprune {

// Names accepted by builtin_scene().
std::vector<std::string> builtin_scene_names();

// "demo": a smooth molecule-like cluster of ~300 spheres with a drilled hole, on a bevelled
// plinth with a torus, capsules and a cone (about 650 nodes, every primitive and operator kind).
// "sphere": one unit sphere (analytic checks).
// Throws SceneError for an unknown name.
Scene builtin_scene(const std::string& name);

// A deterministic stream of uniform floats in [0, 1) for generators (same on every platform).
class Rng {
  public:
    explicit Rng(uint64_t seed) : state_(seed * 0x9E3779B97F4A7C15ull + 0x632BE59BD9B4E019ull) {}
    uint64_t next_u64() {
        uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return z ^ (z >> 31);
    }
    float uniform() { return float(next_u64() >> 40) * (1.0f / 16777216.0f); }
    float uniform(float lo, float hi) { return lo + (hi - lo) * uniform(); }

  private:
    uint64_t state_;
};

}  // namespace sdfprune
