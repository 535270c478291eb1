// fuzz_entry.cpp — the fuzz targets' entry points (fuzz_entry.hpp): the scene loader, the .npy
// reader, and pruning + evaluation on small grids checked against the full tree.
#include "fuzz/fuzz_entry.hpp"

#include <cmath>
#include <string>
#include <string_view>
#include <vector>

#include "sdfprune/builtin.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/npy.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune::fuzz {
namespace {

std::string_view as_text(std::span<const uint8_t> data) {
    return {reinterpret_cast<const char*>(data.data()), data.size()};
}

[[noreturn]] void violation(const std::string& what) {
    throw FuzzPropertyViolation(what);
}

std::string str(vec3 p) {
    // Appended piece by piece: GCC 12 warns (-Wrestrict, falsely) on "(" + std::string.
    std::string s = "(";
    s += std::to_string(p.x);
    s += ", ";
    s += std::to_string(p.y);
    s += ", ";
    s += std::to_string(p.z);
    s += ")";
    return s;
}

// Values this large lose the relative precision the checks assume (and may overflow).
bool moderate(float f) {
    return std::isfinite(f) && std::fabs(f) < 1e6f;
}

PruneOptions options_from(std::span<const uint8_t> b) {
    PruneOptions o;
    o.resolution = 1 + b[0] % 16;
    o.factor = 2 + b[1] % 3;
    o.far_field = !(b[2] & 1);
    o.hierarchy = !(b[2] & 2);
    o.bounds = (b[2] & 4) ? CellBounds::kLipschitz : CellBounds::kInterval;
    o.coarse_tapes = (b[2] & 8) != 0;
    o.refine = 1 + b[3] % 3;
    o.far_field_c = 1.0f + float(b[4]) / 64.0f;
    o.threads = 1;
    return o;
}

// The checks of prune_eval at one point of the AABB.
void check_point(const PrunedGrid& g, vec3 p, std::vector<float>& stack) {
    const Scene& sc = g.scene();
    uint32_t ix, iy, iz;
    if (!g.cell_index(p, ix, iy, iz)) violation("cell_index false in the AABB at " + str(p));
    const float f = eval_tape(sc, sc.full_tape, p, stack.data());
    const CellView cv = g.cell(ix, iy, iz);
    const float ge = g.eval(p, stack.data());
    if (!moderate(f)) return;
    if (!cv.far_field) {
        const float v = eval_tape(sc, cv.tape, p, stack.data());
        if (!(std::fabs(double(v) - double(f)) <= 1e-6 * (1.0 + std::fabs(double(f)))))
            violation("near-field tape gives " + std::to_string(v) + ", full tree " +
                      std::to_string(f) + " at " + str(p));
        if (!(ge == v)) violation("PrunedGrid::eval differs from the cell's tape at " + str(p));
    } else {
        const float k = cv.constant;
        const bool ok = (f > 0 && k > 0 && k <= f) || (f < 0 && k < 0 && k >= f) || f == 0;
        if (!ok)
            violation("far-field constant " + std::to_string(k) +
                      " not conservative for f = " + std::to_string(f) + " at " + str(p));
        if (!(ge == k)) violation("PrunedGrid::eval differs from the far-field constant");
    }
}

}  // namespace

Outcome scene_loader(std::span<const uint8_t> data) {
    Scene sc;
    try {
        sc = parse_scene(as_text(data), "fuzz.json");
    } catch (const SceneError&) {
        return Outcome::kRejected;
    }
    const SceneInfo info = scene_info(sc);
    if (info.nodes != sc.size() || info.primitives + info.operators != sc.size())
        violation("scene_info counts do not add up");
    // Saving and loading again gives the same tree.
    Scene again;
    try {
        again = parse_scene(scene_to_json(sc), "saved.json");
    } catch (const SceneError& e) {
        violation(std::string("a saved scene does not load: ") + e.what());
    }
    if (again.kind != sc.kind || again.left != sc.left || again.full_tape != sc.full_tape)
        violation("save -> load changed the tree");
    return Outcome::kAccepted;
}

Outcome npy_reader(std::span<const uint8_t> data) {
    NpyArray a;
    try {
        a = parse_npy(as_text(data), "fuzz.npy");
    } catch (const IoError&) {
        return Outcome::kRejected;
    }
    uint64_t count = 1;
    for (uint64_t d : a.shape) count *= d;
    if (count != a.data.size()) violation("data size does not match the shape");
    return Outcome::kAccepted;
}

Outcome prune_eval(std::span<const uint8_t> data) {
    if (data.size() < kPruneOptionBytes) return Outcome::kRejected;
    const std::span<const uint8_t> opt = data.first(kPruneOptionBytes);
    Scene sc;
    try {
        sc = parse_scene(as_text(data.subspan(kPruneOptionBytes)), "fuzz.json");
    } catch (const SceneError&) {
        return Outcome::kRejected;
    }
    if (sc.size() > kPruneMaxNodes) return Outcome::kAccepted;
    const PruneOptions o = options_from(opt);
    const PrunedGrid g = prune(sc, o);
    if (g.resolution() != o.resolution) violation("wrong resolution");

    std::vector<float> stack(sc.max_stack + 1);
    Rng r(uint64_t(opt[5]) | uint64_t(opt[6]) << 8 | uint64_t(opt[7]) << 16);
    const Aabb& box = sc.aabb;
    const auto in_box = [&](vec3 lo, vec3 hi) {
        vec3 p;
        for (int a = 0; a < 3; ++a)
            p[a] = std::fmin(hi[a], std::fmax(lo[a], r.uniform(lo[a], hi[a])));
        return p;
    };
    // Points anywhere, the AABB's corners, and points in near-field cells.
    for (int i = 0; i < 16; ++i) check_point(g, in_box(box.min, box.max), stack);
    for (int c = 0; c < 8; ++c)
        check_point(g,
                    vec3((c & 1) ? box.max.x : box.min.x, (c & 2) ? box.max.y : box.min.y,
                         (c & 4) ? box.max.z : box.min.z),
                    stack);
    const uint32_t N = g.resolution();
    const vec3 cs = g.cell_size();
    if (!(std::isfinite(cs.x) && std::isfinite(cs.y) && std::isfinite(cs.z)))
        return Outcome::kAccepted;
    const float R = math::length(cs) * 0.5f;
    const float clearance = (o.far_field_c - 1.0f) * R;
    const auto index = [&] { return std::min(uint32_t(r.uniform() * float(N)), N - 1); };
    for (int i = 0; i < 32; ++i) {
        const uint32_t ix = index(), iy = index(), iz = index();
        const vec3 c = g.cell_center(ix, iy, iz);
        const CellView cv = g.cell(ix, iy, iz);
        if (!cv.far_field) {
            check_point(g, in_box(c - cs * 0.5f, c + cs * 0.5f), stack);
            continue;
        }
        // Cells the surface may cross are never culled (far_field_clearance).
        const float fc = eval_tape(sc, sc.full_tape, c, stack.data());
        if (moderate(fc) && std::isfinite(clearance) && std::fabs(fc) < clearance)
            violation("cell with |f(centre)| = " + std::to_string(std::fabs(fc)) + " < " +
                      std::to_string(clearance) + " is far-field");
    }
    return Outcome::kAccepted;
}

}  // namespace sdfprune::fuzz
