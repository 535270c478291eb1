// binding.hpp — what the Python binding's files share: the module's classes (a built Scene and
// pruned grids, CPU or GPU, both holding their scene alive), errors mapped to Python exceptions
// and the progress/interrupt hook. The binding is a thin layer over include/sdfprune: it holds
// no engine logic; the modelling sugar is pure Python (python/sdfprune/).
#pragma once

#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>

#include "sdfprune/gpu.hpp"
#include "sdfprune/prune.hpp"
#include "sdfprune/scene.hpp"

namespace sdfprune::py_binding {

namespace py = pybind11;

using ScenePtr = std::shared_ptr<Scene>;  // immutable once built; Python shares it

// The process's Vulkan device, shared by its GPU grids: made at the first GPU pruning (which
// takes hundreds of milliseconds: its kernels are built and its memory reserve allocated) and
// gone with the last grid that holds it (queries.cpp: shared_device). One thread at a time
// uses a device: every call on it (pruning, rendering, discretizing, a grid's end) holds
// `lock`, and none takes the GIL while it does.
struct SharedDevice {
    std::mutex lock;
    gpu::Device device;
};

// A grid pruned on the Vulkan device: the device and scene are kept alive by the grid holder
// (gpu::Grid refers to both; declared last, so it is destroyed first, its buffers given back
// to the device under its lock).
struct GpuGrid {
    ScenePtr scene;
    std::shared_ptr<SharedDevice> device;
    std::optional<gpu::Grid> grid;
    GpuGrid() = default;
    GpuGrid(const GpuGrid&) = delete;
    GpuGrid& operator=(const GpuGrid&) = delete;
    ~GpuGrid() {
        if (!grid) return;
        const std::lock_guard<std::mutex> hold(device->lock);
        grid.reset();
    }
};

// Progress reports and Ctrl-C during long work run with the GIL released. The engine calls
// progress from the calling thread; the hook takes the GIL there, calls the user's callback
// (if any), and checks for signals. A Python exception (KeyboardInterrupt included) sets the
// cancel flag, which work that can stop (prune, mesh) honours; it is re-raised afterwards.
class Hook {
  public:
    explicit Hook(py::object callback) : callback_(std::move(callback)) {}
    std::function<void(double)> fn() {
        return [this](double f) { report(f); };
    }
    const std::atomic<bool>* cancel() const { return &cancel_; }
    void report(double f);
    // Raises the saved Python error, if any (with the GIL held).
    void rethrow();
    bool failed() const { return error_.has_value(); }

  private:
    py::object callback_;
    std::atomic<bool> cancel_{false};
    std::optional<py::error_already_set> error_;
};

void bind_scene(py::module_& m);
void bind_queries(py::module_& m);

}  // namespace sdfprune::py_binding
