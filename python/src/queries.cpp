// queries.cpp (binding) — pruning and the queries on numpy arrays: evaluation at points (float32
// C-contiguous input read in place), discretization, meshing, rendering, and the writers. Work
// runs with the GIL released; results come back as numpy arrays that own the engine's buffers
// (no copy).
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>

#include "binding.hpp"
#include "sdfprune/discretize.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/mesh.hpp"
#include "sdfprune/npy.hpp"
#include "sdfprune/render.hpp"
#include "sdfprune/vdb.hpp"

namespace sdfprune::py_binding {

static_assert(sizeof(vec3) == 3 * sizeof(float), "points are read in place as vec3");

void Hook::report(double f) {
    if (cancel_.load()) return;
    py::gil_scoped_acquire gil;
    try {
        if (PyErr_CheckSignals() != 0) throw py::error_already_set();
        if (!callback_.is_none()) callback_(f);
    } catch (py::error_already_set& e) {
        error_.emplace(std::move(e));
        cancel_.store(true);
    }
}

void Hook::rethrow() {
    if (error_) {
        py::error_already_set e = std::move(*error_);
        error_.reset();
        throw e;
    }
}

namespace {

// A numpy array owning a heap vector (no copy).
template <typename T>
py::array_t<T> adopt(std::vector<T>&& v, std::vector<py::ssize_t> shape) {
    auto* owned = new std::vector<T>(std::move(v));
    py::capsule free_it(owned, [](void* p) { delete static_cast<std::vector<T>*>(p); });
    return py::array_t<T>(shape, owned->data(), free_it);
}

// Runs `work` without the GIL, under the hook; re-raises a Python error the hook caught
// (KeyboardInterrupt, the callback's own) in preference to the engine's cancellation.
template <typename F>
auto run_hooked(Hook& hook, F&& work) -> decltype(work()) {
    try {
        py::gil_scoped_release nogil;
        return work();
    } catch (...) {
        hook.rethrow();
        throw;
    }
}

PruneOptions prune_options(uint32_t grid, bool far_field, bool hierarchy, float far_field_c,
                           uint32_t refine, bool lipschitz_bounds, uint32_t factor, bool clearance,
                           int threads) {
    if (grid < 1 || grid > 4096) throw py::value_error("grid must be in 1..4096");
    if (factor < 2 || factor > 64) throw py::value_error("factor must be in 2..64");
    if (!(far_field_c >= 1 && far_field_c <= 1000))
        throw py::value_error("far_field_c must be in [1, 1000]");
    if (refine < 1 || refine > 8) throw py::value_error("refine must be in 1..8");
    if (threads < 0) throw py::value_error("threads must be >= 0");
    PruneOptions o;
    o.resolution = grid;
    o.far_field = far_field;
    o.hierarchy = hierarchy;
    o.far_field_c = far_field_c;
    o.refine = lipschitz_bounds ? 1 : refine;
    o.bounds = lipschitz_bounds ? CellBounds::kLipschitz : CellBounds::kInterval;
    o.clearance = clearance;
    o.factor = factor;
    o.threads = threads;
    return o;
}

py::dict stats_dict(const PruneStats& s, const PruneOptions& o, const Scene& sc) {
    std::string levels;
    for (uint32_t r : s.levels) levels += (levels.empty() ? "" : "x") + std::to_string(r);
    py::dict d;
    d["nodes"] = sc.size();
    d["grid"] = s.grid;
    d["levels"] = levels;
    d["bounds"] = o.bounds == CellBounds::kLipschitz ? "lipschitz" : "interval";
    d["far_field"] = o.far_field;
    d["hierarchy"] = o.hierarchy;
    d["farfield_c"] = o.far_field_c;
    d["refine"] = o.refine;
    d["clearance"] = o.clearance;
    d["cells"] = s.cells;
    d["near_field_cells"] = s.near_field_cells;
    d["active_avg"] = s.active_avg;
    d["active_std"] = s.active_std;
    d["active_max"] = s.active_max;
    d["near_field_active_avg"] = s.near_field_prims_avg;
    d["tape_avg"] = s.tape_avg;
    d["tape_max"] = s.tape_max;
    d["prune_ms"] = s.prune_ms;
    d["prune_peak_bytes"] = s.prune_peak_bytes;
    d["tape_bytes"] = s.tape_bytes;
    d["tape_words_visited"] = s.tape_words_visited;
    d["clearance_ms"] = s.clearance_ms;
    d["clearance_bytes"] = s.clearance_bytes;
    return d;
}

// The points of an (N, 3) array as float32 rows: in place when the array is float32 and
// C-contiguous, else converted slice by slice (no full copy).
struct Points {
    py::array array;
    size_t n = 0;
    const vec3* direct = nullptr;
    bool is_double = false;
};

Points points_of(const py::array& a) {
    Points p;
    p.array = a;
    if (a.ndim() != 2 || a.shape(1) != 3) throw py::value_error("points must be an (N, 3) array");
    p.n = size_t(a.shape(0));
    const bool f32 = py::isinstance<py::array_t<float>>(a);  // equivalent dtype, native order
    const bool f64 = py::isinstance<py::array_t<double>>(a);
    if (f32 && (a.flags() & py::array::c_style) == py::array::c_style &&
        reinterpret_cast<uintptr_t>(a.data()) % alignof(vec3) == 0) {
        p.direct = static_cast<const vec3*>(a.data());
    } else if (f32 || f64) {
        p.is_double = f64;
    } else {
        throw py::value_error("points must be float32 or float64");
    }
    return p;
}

// Reads rows [at, at + len) of a strided float32/float64 (N, 3) array into `buf`.
void gather(const Points& p, size_t at, size_t len, std::vector<vec3>& buf) {
    buf.resize(len);
    const char* base = static_cast<const char*>(p.array.data());
    const py::ssize_t s0 = p.array.strides(0), s1 = p.array.strides(1);
    for (size_t i = 0; i < len; ++i) {
        const char* row = base + py::ssize_t(at + i) * s0;
        for (int c = 0; c < 3; ++c) {
            const char* e = row + c * s1;
            if (p.is_double) {
                double v;
                std::memcpy(&v, e, sizeof v);
                buf[i][c] = float(v);
            } else {
                float v;
                std::memcpy(&v, e, sizeof v);
                buf[i][c] = v;
            }
        }
    }
}

// Evaluates `fn(points, out)` over slices (progress and Ctrl-C between slices).
template <typename F>
py::array_t<float> eval_sliced(const py::array& points, const py::object& out_obj, int threads,
                               const py::object& progress, F&& fn) {
    Points p = points_of(points);
    py::array_t<float> out;
    if (out_obj.is_none()) {
        out = py::array_t<float>(py::ssize_t(p.n));
    } else {
        // No conversion: results written to a converted copy would be lost.
        if (!py::isinstance<py::array_t<float>>(out_obj))
            throw py::value_error("out must be a float32 array");
        out = py::reinterpret_borrow<py::array_t<float>>(out_obj);
        if (out.ndim() != 1 || size_t(out.shape(0)) != p.n || !(out.flags() & py::array::c_style) ||
            !out.writeable())
            throw py::value_error(
                "out must be a writable C-contiguous float32 array of shape (N,)");
    }
    if (threads < 0) throw py::value_error("threads must be >= 0");
    float* dst = out.mutable_data();
    Hook hook(progress);
    run_hooked(hook, [&] {
        with_threads(threads, [&] {
            constexpr size_t kSlice = size_t(1) << 20;
            std::vector<vec3> buf;
            for (size_t at = 0; at < p.n && !hook.cancel()->load(); at += kSlice) {
                const size_t len = std::min(kSlice, p.n - at);
                std::span<const vec3> pts;
                if (p.direct) {
                    pts = {p.direct + at, len};
                } else {
                    gather(p, at, len, buf);
                    pts = buf;
                }
                fn(pts, std::span<float>(dst + at, len));
                if (p.n > kSlice) hook.report(double(at + len) / double(p.n));
            }
        });
    });
    hook.rethrow();
    return out;
}

py::tuple mesh_arrays(Mesh&& m) {
    const auto nv = py::ssize_t(m.vertices.size());
    const auto nt = py::ssize_t(m.triangle_count());
    // The vertices are read in place: a vec3 is three packed floats.
    static_assert(sizeof(vec3) == 3 * sizeof(float) && alignof(vec3) == alignof(float));
    auto* owned = new std::vector<vec3>(std::move(m.vertices));
    py::capsule free_it(owned, [](void* p) { delete static_cast<std::vector<vec3>*>(p); });
    py::array_t<float> vertices({nv, py::ssize_t(3)}, reinterpret_cast<const float*>(owned->data()),
                                free_it);
    return py::make_tuple(vertices, adopt(std::move(m.triangles), {nt, 3}));
}

Shading shading_of(const std::string& s) {
    if (s == "shaded") return Shading::kShaded;
    if (s == "normals") return Shading::kNormals;
    if (s == "heatmap") return Shading::kHeatmap;
    throw py::value_error("shading must be 'shaded', 'normals' or 'heatmap' (got '" + s + "')");
}

RenderOptions render_options(const Scene& sc, uint32_t width, uint32_t height, float yaw,
                             float pitch, float distance, float fov, const py::object& target,
                             const std::string& shading, bool shadows, int threads) {
    if (width < 1 || width > 16384 || height < 1 || height > 16384)
        throw py::value_error("width and height must be in 1..16384");
    if (!(pitch >= -89 && pitch <= 89)) throw py::value_error("pitch must be in [-89, 89]");
    if (!(fov >= 1 && fov <= 170)) throw py::value_error("fov must be in [1, 170]");
    if (!std::isfinite(yaw) || !std::isfinite(distance))
        throw py::value_error("yaw and distance must be finite");
    if (threads < 0) throw py::value_error("threads must be >= 0");
    RenderOptions ro;
    ro.width = width;
    ro.height = height;
    vec3 t;
    if (!target.is_none()) {
        const auto v = py::cast<std::vector<float>>(target);
        if (v.size() != 3) throw py::value_error("target needs 3 numbers");
        t = vec3(v[0], v[1], v[2]);
    }
    ro.camera = orbit_camera(sc.aabb, yaw, pitch, distance, fov, target.is_none() ? nullptr : &t);
    ro.shading = shading_of(shading);
    ro.shadows = shadows;
    ro.threads = threads;
    return ro;
}

py::array_t<uint8_t> image_array(Image&& img) {
    return adopt(std::move(img.rgb), {py::ssize_t(img.height), py::ssize_t(img.width), 3});
}

uint32_t check_res(uint32_t res) {
    if (res < 1 || res > kMaxMeshResolution)
        throw py::value_error("res must be in 1.." + std::to_string(kMaxMeshResolution));
    return res;
}

using GridPtr = std::shared_ptr<PrunedGrid>;
using GpuGridPtr = std::shared_ptr<GpuGrid>;

// The device every GPU grid alive shares, made where none is (binding.hpp: SharedDevice).
std::shared_ptr<SharedDevice> shared_device() {
    static std::mutex making;
    static std::weak_ptr<SharedDevice> current;
    const std::lock_guard<std::mutex> hold(making);
    std::shared_ptr<SharedDevice> d = current.lock();
    if (!d) {
        d = std::make_shared<SharedDevice>();
        current = d;
    }
    return d;
}

}  // namespace

void bind_queries(py::module_& m) {
    py::class_<PrunedGrid, GridPtr>(m, "Grid", "A pruned grid (CPU); keeps its scene alive.")
        .def_property_readonly("resolution", &PrunedGrid::resolution)
        .def("stats",
             [](const PrunedGrid& g) { return stats_dict(g.stats(), g.options(), g.scene()); });

    py::class_<GpuGrid, GpuGridPtr>(m, "GpuGrid", "A grid pruned on the Vulkan device.")
        .def_property_readonly("resolution", [](const GpuGrid& g) { return g.grid->stats().grid; })
        .def_property_readonly("device", [](const GpuGrid& g) { return g.device->device.name(); })
        .def("stats", [](const GpuGrid& g) {
            py::dict d = stats_dict(g.grid->stats(), {}, *g.scene);
            d["device"] = g.device->device.name();
            gpu::for_each_figure(g.grid->stats(), [&](const char* k, auto v) { d[k] = v; });
            py::list steps;
            for (const gpu::GpuStepShape& st : g.grid->stats().steps) {
                py::dict step;
                gpu::for_each_figure(st, [&](const char* k, auto v) { step[k] = v; });
                steps.append(step);
            }
            d["gpu_steps"] = steps;
            return d;
        });

    m.def("built_with_vulkan", &gpu::built_with_vulkan);

    m.def(
        "prune",
        [](ScenePtr scene, uint32_t grid, bool far_field, bool hierarchy, float c, uint32_t refine,
           bool lipschitz, uint32_t factor, bool clearance, int threads,
           const py::object& progress) {
            PruneOptions o = prune_options(grid, far_field, hierarchy, c, refine, lipschitz, factor,
                                           clearance, threads);
            Hook hook(progress);
            o.progress = hook.fn();
            o.cancel = hook.cancel();
            auto g = run_hooked(hook, [&] {
                return std::make_shared<PrunedGrid>(prune(std::shared_ptr<const Scene>(scene), o));
            });
            hook.rethrow();
            return g;
        },
        py::arg("scene"), py::arg("grid"), py::arg("far_field"), py::arg("hierarchy"),
        py::arg("far_field_c"), py::arg("refine"), py::arg("lipschitz_bounds"), py::arg("factor"),
        py::arg("clearance"), py::arg("threads"), py::arg("progress"));

    m.def(
        "prune_gpu",
        [](ScenePtr scene, uint32_t grid, bool far_field, bool hierarchy, float c, uint32_t refine,
           bool lipschitz, uint32_t factor, bool clearance) {
            if (!gpu::built_with_vulkan())
                throw gpu::GpuError(
                    "backend='vulkan': this sdfprune was built without the Vulkan backend "
                    "(install with SDFPRUNE_VULKAN=1 in the environment, or use backend='cpu')");
            const PruneOptions o = prune_options(grid, far_field, hierarchy, c, refine, lipschitz,
                                                 factor, clearance, 0);
            py::gil_scoped_release nogil;
            auto g = std::make_shared<GpuGrid>();
            g->scene = scene;
            g->device = shared_device();
            const std::lock_guard<std::mutex> hold(g->device->lock);
            g->grid.emplace(gpu::prune(g->device->device, *g->scene, o));
            return g;
        },
        py::arg("scene"), py::arg("grid"), py::arg("far_field"), py::arg("hierarchy"),
        py::arg("far_field_c"), py::arg("refine"), py::arg("lipschitz_bounds"), py::arg("factor"),
        py::arg("clearance"));

    m.def(
        "eval_grid",
        [](const GridPtr& g, const py::array& points, const py::object& out, int threads,
           const py::object& progress) {
            return eval_sliced(
                points, out, threads, progress,
                [&](std::span<const vec3> p, std::span<float> o) { g->eval_points(p, o); });
        },
        py::arg("grid"), py::arg("points"), py::arg("out") = py::none(), py::arg("threads") = 0,
        py::arg("progress") = py::none());
    m.def(
        "eval_scene",
        [](const ScenePtr& s, const py::array& points, const py::object& out, int threads,
           const py::object& progress) {
            return eval_sliced(points, out, threads, progress,
                               [&](std::span<const vec3> p, std::span<float> o) {
                                   eval_points(*s, p, o, {threads});
                               });
        },
        py::arg("scene"), py::arg("points"), py::arg("out") = py::none(), py::arg("threads") = 0,
        py::arg("progress") = py::none());

    m.def(
        "discretize_grid",
        [](const GridPtr& g, uint32_t n, int threads, const py::object& progress) {
            check_res(n);
            std::vector<float> v(size_t(n) * n * n);
            Hook hook(progress);
            run_hooked(hook, [&] {
                with_threads(threads, [&] { discretize_pruned(*g, n, v, hook.fn()); });
            });
            hook.rethrow();
            return adopt(std::move(v), {n, n, n});
        },
        py::arg("grid"), py::arg("res"), py::arg("threads") = 0, py::arg("progress") = py::none());
    m.def(
        "discretize_scene",
        [](const ScenePtr& s, uint32_t n, int threads, const py::object& progress) {
            check_res(n);
            std::vector<float> v(size_t(n) * n * n);
            Hook hook(progress);
            run_hooked(hook, [&] { discretize_naive(*s, n, v, threads, hook.fn()); });
            hook.rethrow();
            return adopt(std::move(v), {n, n, n});
        },
        py::arg("scene"), py::arg("res"), py::arg("threads") = 0, py::arg("progress") = py::none());
    m.def(
        "discretize_gpu",
        [](const GpuGridPtr& g, uint32_t n) {
            check_res(n);
            std::vector<float> v(size_t(n) * n * n);
            {
                py::gil_scoped_release nogil;
                const std::lock_guard<std::mutex> hold(g->device->lock);
                gpu::discretize(g->device->device, *g->grid, n, v);
            }
            return adopt(std::move(v), {n, n, n});
        },
        py::arg("grid"), py::arg("res"));

    auto mesh_with = [](auto&& source, uint32_t res, int threads, const py::object& progress,
                        const std::string& path) -> py::object {
        MeshOptions o;
        o.resolution = check_res(res);
        if (threads < 0) throw py::value_error("threads must be >= 0");
        o.threads = threads;
        Hook hook(progress);
        o.progress = hook.fn();
        o.cancel = hook.cancel();
        if (!path.empty()) check_writable(path), (void)mesh_format_of(path);
        Mesh msh = run_hooked(hook, [&] {
            Mesh r = mesh(source, o);
            if (!path.empty()) write_mesh(r, path);
            return r;
        });
        hook.rethrow();
        if (!path.empty()) return py::int_(msh.triangle_count());
        return mesh_arrays(std::move(msh));
    };
    m.def("default_mesh_grid", &default_mesh_grid, py::arg("res"),
          "The pruning grid that meshes at res cubes per axis fastest (res / 2 when even).");
    m.def(
        "mesh_grid",
        [mesh_with](const GridPtr& g, uint32_t res, int threads, const py::object& progress,
                    const std::string& path) {
            return mesh_with(*g, res, threads, progress, path);
        },
        py::arg("grid"), py::arg("res"), py::arg("threads") = 0, py::arg("progress") = py::none(),
        py::arg("path") = "");
    m.def(
        "mesh_scene",
        [mesh_with](const ScenePtr& s, uint32_t res, int threads, const py::object& progress,
                    const std::string& path) {
            return mesh_with(*s, res, threads, progress, path);
        },
        py::arg("scene"), py::arg("res"), py::arg("threads") = 0, py::arg("progress") = py::none(),
        py::arg("path") = "");

    m.def(
        "render",
        [](const py::object& source, uint32_t width, uint32_t height, float yaw, float pitch,
           float distance, float fov, const py::object& target, const std::string& shading,
           bool shadows, int threads, const py::object& progress) {
            Hook hook(progress);
            Image img;
            if (py::isinstance<GpuGrid>(source)) {
                const auto g = py::cast<GpuGridPtr>(source);
                RenderOptions ro = render_options(*g->scene, width, height, yaw, pitch, distance,
                                                  fov, target, shading, shadows, 0);
                py::gil_scoped_release nogil;
                const std::lock_guard<std::mutex> hold(g->device->lock);
                img = gpu::render(g->device->device, *g->grid, ro);
            } else if (py::isinstance<PrunedGrid>(source)) {
                const auto g = py::cast<GridPtr>(source);
                RenderOptions ro = render_options(g->scene(), width, height, yaw, pitch, distance,
                                                  fov, target, shading, shadows, threads);
                ro.progress = hook.fn();
                img = run_hooked(hook, [&] { return render(*g, ro); });
            } else {
                const auto s = py::cast<ScenePtr>(source);
                RenderOptions ro = render_options(*s, width, height, yaw, pitch, distance, fov,
                                                  target, shading, shadows, threads);
                ro.progress = hook.fn();
                img = run_hooked(hook, [&] { return render_naive(*s, ro); });
            }
            hook.rethrow();
            return image_array(std::move(img));
        },
        py::arg("source"), py::arg("width"), py::arg("height"), py::arg("yaw"), py::arg("pitch"),
        py::arg("distance"), py::arg("fov"), py::arg("target"), py::arg("shading"),
        py::arg("shadows"), py::arg("threads") = 0, py::arg("progress") = py::none());

    // Writers (atomic: a temporary file, then a rename; nothing is left on failure).
    m.def("check_writable", [](const std::string& path) { check_writable(path); });
    m.def(
        "write_npy",
        [](const std::string& path, const py::array_t<float, py::array::c_style>& a) {
            std::vector<uint64_t> shape(a.shape(), a.shape() + a.ndim());
            std::span<const float> data(a.data(), size_t(a.size()));
            py::gil_scoped_release nogil;
            write_npy(path, shape, data);
        },
        py::arg("path"), py::arg("values"));
    m.def(
        "write_vdb",
        [](const std::string& path, const ScenePtr& s,
           const py::array_t<float, py::array::c_style>& a) {
            if (a.ndim() != 3 || a.shape(0) != a.shape(1) || a.shape(1) != a.shape(2))
                throw py::value_error("values must be an (n, n, n) array");
            const auto n = uint32_t(a.shape(0));
            std::span<const float> data(a.data(), size_t(a.size()));
            py::gil_scoped_release nogil;
            const VdbStats st = write_vdb_level_set(path, s->aabb, n, data);
            return st.active_voxels;
        },
        py::arg("path"), py::arg("scene"), py::arg("values"));
    m.def(
        "write_png",
        [](const std::string& path, const py::array_t<uint8_t, py::array::c_style>& a) {
            if (a.ndim() != 3 || a.shape(2) != 3)
                throw py::value_error("an image must be an (H, W, 3) uint8 array");
            Image img;
            img.height = uint32_t(a.shape(0));
            img.width = uint32_t(a.shape(1));
            img.rgb.assign(a.data(), a.data() + a.size());
            py::gil_scoped_release nogil;
            write_png(img, path);
        },
        py::arg("path"), py::arg("image"));
    m.def(
        "write_mesh",
        [](const std::string& path, const py::array_t<float, py::array::c_style>& v,
           const py::array_t<uint32_t, py::array::c_style>& f) {
            if (v.ndim() != 2 || v.shape(1) != 3 || f.ndim() != 2 || f.shape(1) != 3)
                throw py::value_error("vertices must be (V, 3) and faces (F, 3)");
            Mesh msh;
            msh.vertices.resize(size_t(v.shape(0)));
            // vec3 is three floats (glsl_compat.hpp), so the rows copy as they are.
            static_assert(sizeof(vec3) == 3 * sizeof(float));
            std::memcpy(static_cast<void*>(msh.vertices.data()), v.data(),
                        size_t(v.size()) * sizeof(float));
            msh.triangles.assign(f.data(), f.data() + f.size());
            for (uint32_t i : msh.triangles)
                if (i >= msh.vertices.size()) throw py::value_error("face index out of range");
            py::gil_scoped_release nogil;
            write_mesh(msh, path);
        },
        py::arg("path"), py::arg("vertices"), py::arg("faces"));
}

}  // namespace sdfprune::py_binding
