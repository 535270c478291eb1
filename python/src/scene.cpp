// scene.cpp (binding) — scenes for Python: the primitive table (primitives.hpp) as data, shapes
// checked field by field, a Python-built tree replayed into a SceneBuilder, and the reference
// JSON format (load, save, text).
#include <cmath>
#include <string>

#include "binding.hpp"
#include "sdfprune/builder.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/primitives.hpp"

namespace sdfprune::py_binding {

namespace {

// The table entry named `name`, or ValueError listing the known ones.
const PrimitiveKindInfo& kind_by_name(const std::string& name) {
    std::string known;
    for (const PrimitiveKindInfo& k : kPrimitiveTable) {
        if (name == k.name) return k;
        known += (known.empty() ? "" : ", ") + std::string(k.name);
    }
    throw py::value_error("unknown primitive '" + name + "' (known: " + known + ")");
}

// A primitive's fields, by their scene-format names, into a PrimitiveShape; checked with the
// table (the loader's checks and messages).
PrimitiveShape shape_from_fields(const PrimitiveKindInfo& k, const py::dict& fields) {
    PrimitiveShape s;
    for (auto item : fields) {
        const std::string key = py::str(item.first);
        const PrimitiveField* f = nullptr;
        for (uint32_t i = 0; i < k.field_count; ++i)
            if (key == k.fields[i].name) f = &k.fields[i];
        if (!f) {
            std::string names;
            for (uint32_t i = 0; i < k.field_count; ++i)
                names += (names.empty() ? "" : ", ") + std::string(k.fields[i].name);
            throw py::value_error(std::string(k.name) + ": unknown field '" + key +
                                  "' (fields: " + names + ")");
        }
        float* out = field_values(s, *f);
        py::handle v = item.second;
        if (f->count == 1) {
            out[0] = py::cast<float>(v);
        } else {
            const auto seq = py::cast<std::vector<float>>(v);
            if (seq.size() != f->count)
                throw py::value_error(std::string(k.name) + ": " + key + " needs " +
                                      std::to_string(f->count) + " numbers (got " +
                                      std::to_string(seq.size()) + ")");
            for (uint32_t i = 0; i < f->count; ++i) out[i] = seq[i];
        }
    }
    for (uint32_t i = 0; i < k.field_count; ++i)
        if (k.fields[i].required && !fields.contains(k.fields[i].name))
            throw py::value_error(std::string(k.name) + ": missing field '" + k.fields[i].name +
                                  "'");
    const std::string why = validate_primitive(k.kind, s);
    if (!why.empty()) throw py::value_error(std::string(k.name) + ": " + why);
    return s;
}

py::dict fields_of(uint32_t kind, const PrimitiveShape& s) {
    const PrimitiveKindInfo& k = primitive_info(kind);
    py::dict d;
    for (uint32_t i = 0; i < k.field_count; ++i) {
        const PrimitiveField& f = k.fields[i];
        const float* v = field_values(s, f);
        if (f.count == 1) {
            d[f.name] = v[0];
        } else {
            py::tuple t(f.count);
            for (uint32_t j = 0; j < f.count; ++j) t[j] = v[j];
            d[f.name] = t;
        }
    }
    return d;
}

vec3 to_vec3(const py::handle& h, const char* what) {
    const auto v = py::cast<std::vector<float>>(h);
    if (v.size() != 3) throw py::value_error(std::string(what) + " needs 3 numbers");
    return vec3(v[0], v[1], v[2]);
}

Affine to_affine(const py::handle& h) {
    const auto v = py::cast<std::vector<float>>(h);
    if (v.size() != 12) throw py::value_error("a placement needs 12 numbers (3x4, row-major)");
    Affine a;
    for (int i = 0; i < 12; ++i) {
        if (!std::isfinite(v[i])) throw py::value_error("transform is not finite");
        a.m[i] = v[i];
    }
    return a;
}

std::optional<Aabb> to_aabb(const py::object& bounds) {
    if (bounds.is_none()) return std::nullopt;
    const auto pair = py::cast<std::vector<py::object>>(bounds);
    if (pair.size() != 2) throw py::value_error("bounds must be ((x0, y0, z0), (x1, y1, z1))");
    Aabb b{to_vec3(pair[0], "bounds"), to_vec3(pair[1], "bounds")};
    for (int i = 0; i < 3; ++i)
        if (!(std::isfinite(b.min[i]) && std::isfinite(b.max[i]) && b.min[i] < b.max[i]))
            throw py::value_error("bounds must be finite with min < max on every axis");
    return b;
}

// Replays a tree described by Python (post-order list of steps, see python/sdfprune/_shape.py)
// into a SceneBuilder and builds it. Steps: ("prim", kind, fields, color | None),
// ("op", kind, left, right, k), ("place", child, affine12), ("color", child, rgb),
// ("scene", Scene). Children are indices of earlier steps.
ScenePtr build(const py::list& steps, const py::object& bounds) {
    SceneBuilder b;
    std::vector<Shape> made;
    made.reserve(steps.size());
    auto child = [&](const py::handle& h) {
        const auto i = py::cast<size_t>(h);
        if (i >= made.size()) throw py::value_error("bad step index");
        return made[i];
    };
    for (py::handle step : steps) {
        const auto t = py::cast<py::tuple>(step);
        const auto tag = py::cast<std::string>(t[0]);
        if (tag == "prim") {
            const auto kind = py::cast<uint32_t>(t[1]);
            if (kind >= math::kPrimitiveKindCount) throw py::value_error("unknown primitive");
            Shape s = b.primitive(
                kind, shape_from_fields(primitive_info(kind), py::cast<py::dict>(t[2])));
            if (!t[3].is_none()) s = s.colored(to_vec3(t[3], "color"));
            made.push_back(s);
        } else if (tag == "op") {
            const auto kind = py::cast<uint32_t>(t[1]);
            const float k = py::cast<float>(t[4]);
            if (!(std::isfinite(k) && k >= 0)) throw py::value_error("blend radius k must be >= 0");
            made.push_back(b.combine(kind, child(t[2]), child(t[3]), k));
        } else if (tag == "place") {
            made.push_back(child(t[1]).transformed(to_affine(t[2])));
        } else if (tag == "color") {
            made.push_back(child(t[1]).colored(to_vec3(t[2], "color")));
        } else if (tag == "scene") {
            made.push_back(b.scene(*py::cast<ScenePtr>(t[1])));
        } else {
            throw py::value_error("bad step '" + tag + "'");
        }
    }
    if (made.empty()) throw py::value_error("empty shape");
    const std::optional<Aabb> box = to_aabb(bounds);
    py::gil_scoped_release nogil;
    return std::make_shared<Scene>(box ? b.build(made.back(), *box) : b.build(made.back()));
}

py::tuple aabb_tuple(const Aabb& a) {
    return py::make_tuple(py::make_tuple(a.min.x, a.min.y, a.min.z),
                          py::make_tuple(a.max.x, a.max.y, a.max.z));
}

py::dict info_dict(const Scene& s) {
    const SceneInfo i = scene_info(s);
    py::dict d;
    d["nodes"] = i.nodes;
    d["primitives"] = i.primitives;
    d["operators"] = i.operators;
    d["depth"] = i.depth;
    d["max_lipschitz"] = i.max_lipschitz;
    py::dict per;
    for (uint32_t k = 0; k < math::kPrimitiveKindCount; ++k)
        if (i.per_primitive_kind[k]) per[primitive_kind_name(k)] = i.per_primitive_kind[k];
    d["primitive_kinds"] = per;
    d["unions"] = i.unions;
    d["intersections"] = i.intersections;
    d["differences"] = i.differences;
    d["smooth_operators"] = i.smooth_operators;
    d["aabb"] = aabb_tuple(s.aabb);
    return d;
}

}  // namespace

void bind_scene(py::module_& m) {
    py::class_<Scene, ScenePtr>(m, "Scene",
                                "An immutable, flattened CSG tree (the engine's Scene).")
        .def_property_readonly("nodes", &Scene::size)
        .def_property_readonly("primitives", &Scene::primitive_count)
        .def_property_readonly("aabb", [](const Scene& s) { return aabb_tuple(s.aabb); })
        .def("info", &info_dict, "Summary figures, as `sdfprune info --json`.")
        .def("to_json", &scene_to_json, "The scene in the reference JSON format.")
        .def(
            "with_aabb",
            [](const Scene& s, const py::object& bounds) {
                auto copy = std::make_shared<Scene>(s);
                copy->aabb = *to_aabb(bounds);
                return copy;
            },
            "A copy over other bounds.")
        .def(
            "save",
            [](const Scene& s, const std::string& path) {
                py::gil_scoped_release nogil;
                save_scene(s, path);
            },
            "Writes the reference JSON format atomically.")
        .def(
            "primitive_list",
            [](const Scene& s) {
                py::list out;
                for (uint32_t p = 0; p < s.primitive_count(); ++p) {
                    const uint32_t node = s.primitive_node[p];
                    out.append(py::make_tuple(
                        primitive_kind_name(s.kind[node]), fields_of(s.kind[node], s.shape[p]),
                        py::make_tuple(s.color[p].x, s.color[p].y, s.color[p].z)));
                }
                return out;
            },
            "Per primitive: (kind name, fields, color).");

    m.def("build_scene", &build, py::arg("steps"), py::arg("bounds") = py::none());
    m.def(
        "load_scene",
        [](const std::string& path) {
            py::gil_scoped_release nogil;
            // Reading first, so an unreadable file is an IoError (OSError), not a scene error.
            const std::string text = read_file(path);
            return std::make_shared<Scene>(parse_scene(text, path));
        },
        py::arg("path"));
    m.def(
        "parse_scene",
        [](const std::string& text, const std::string& name) {
            py::gil_scoped_release nogil;
            return std::make_shared<Scene>(parse_scene(text, name));
        },
        py::arg("text"), py::arg("name") = "<string>");
    m.def("primitive_table", [] {
        py::list out;
        for (const PrimitiveKindInfo& k : kPrimitiveTable) {
            py::list fields;
            for (uint32_t i = 0; i < k.field_count; ++i)
                fields.append(
                    py::make_tuple(k.fields[i].name, k.fields[i].count, k.fields[i].required));
            out.append(py::make_tuple(k.kind, k.name, k.summary, fields, k.bounded));
        }
        return out;
    });
    m.def(
        "check_primitive",
        [](const std::string& name, const py::dict& fields) {
            const PrimitiveKindInfo& k = kind_by_name(name);
            return py::make_tuple(k.kind, fields_of(k.kind, shape_from_fields(k, fields)));
        },
        py::arg("name"), py::arg("fields"));
    m.attr("OP_UNION") = math::kOpUnion;
    m.attr("OP_INTERSECTION") = math::kOpIntersection;
    m.attr("OP_DIFFERENCE") = math::kOpDifference;
}

}  // namespace sdfprune::py_binding
