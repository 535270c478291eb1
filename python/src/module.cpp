// module.cpp (binding) — the extension module sdfprune._sdfprune: the engine's errors as Python
// exceptions with the CLI's one-line messages (ValueError for a bad scene or argument, OSError
// for files), then the scene and query bindings (scene.cpp, queries.cpp).
#include "binding.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/mesh.hpp"

PYBIND11_MODULE(_sdfprune, m) {
    namespace py = pybind11;
    using namespace sdfprune;
    m.doc() = "sdfprune's engine (C++); use the sdfprune package, not this module directly.";
    m.attr("__version__") = SDFPRUNE_VERSION;
    static py::exception<gpu::GpuError> gpu_error(m, "GpuError", PyExc_RuntimeError);
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const IoError& e) {
            PyErr_SetString(PyExc_OSError, e.what());
        } catch (const SceneError& e) {
            PyErr_SetString(PyExc_ValueError, e.what());
        } catch (const std::invalid_argument& e) {
            PyErr_SetString(PyExc_ValueError, e.what());
        } catch (const std::length_error& e) {
            PyErr_SetString(PyExc_ValueError, e.what());
        } catch (const gpu::GpuError& e) {
            gpu_error(e.what());
        } catch (const PruneCancelled& e) {
            PyErr_SetString(PyExc_KeyboardInterrupt, e.what());
        } catch (const MeshCancelled& e) {
            PyErr_SetString(PyExc_KeyboardInterrupt, e.what());
        }
    });
    sdfprune::py_binding::bind_scene(m);
    sdfprune::py_binding::bind_queries(m);
}
