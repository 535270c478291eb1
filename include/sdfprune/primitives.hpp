// primitives.hpp — the primitive table: one entry per primitive kind (DESIGN.md §1) giving its
// name in scene files, its JSON fields and how each is checked and stored in the kind's
// parameter slots, whether the shape is bounded and a local box and ball that hold it. The JSON
// loader and writer, validation, parameter baking, bounding boxes, `info` and the Python
// bindings all read this table; the distance itself is `math::eval_primitive_local` in
// shaders/shared/sdf_math.h (CPU and GPU), which also defines the kind ids.
//
// Adding a primitive: a kind id and an sd_* function in sdf_math.h (one more line in
// eval_primitive_local), any new PrimitiveShape member in scene.hpp, one entry below, a builder
// method, and a generator in tests/prune_check.hpp (random_primitive): the range test
// (tests/primitive_range_test.cpp), the JSON round trip and the property tests then cover it;
// its analytic test goes beside the others (tests/primitives_exact_test.cpp).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "scene.hpp"

namespace sdfprune {

// How a field's values are checked (every value must also be finite).
enum class FieldCheck : uint8_t { kFinite, kPositive, kNonNegative };

// One JSON field of a primitive: `count` floats of PrimitiveShape starting at `offset` (a number
// when count = 1, else an array of exactly `count` numbers). Parameter slot `slot + i` (0–3:
// PrimitiveParams::a.xyzw, 4–7: b, 8–11: c; -1: not stored) receives value i times `scale`.
// A field name means the same PrimitiveShape member with the same count in every kind.
struct PrimitiveField {
    const char* name;
    uint16_t offset;
    uint8_t count;
    FieldCheck check;
    bool required;
    int8_t slot;
    float scale;
};

inline constexpr uint32_t kMaxPrimitiveFields = 4;

struct PrimitiveKindInfo {
    uint32_t kind;                               // math::kPrim*
    const char* name;                            // primitiveType in scene files
    const char* summary;                         // one line, for help texts and bindings
    PrimitiveField fields[kMaxPrimitiveFields];  // in the order they are written
    uint32_t field_count;
    // false: the shape is unbounded (a half-space); it gets no similarity bound, no local box,
    // and a scene needs an explicit AABB unless bounded shapes cut it (see bounding_box).
    bool bounded;
    // Half extents of a local box about the origin holding the shape (bounded kinds).
    vec3 (*half_extents)(const PrimitiveShape&);
    // Radius of a local ball about the origin holding the shape (bounded kinds).
    float (*bounding_radius)(const PrimitiveShape&);
    // Constraints between fields, after each field passed its own check: "" or the reason.
    std::string (*check)(const PrimitiveShape&);
};

namespace table_detail {
constexpr FieldCheck kPos = FieldCheck::kPositive;
constexpr FieldCheck kNonNeg = FieldCheck::kNonNegative;
constexpr FieldCheck kAny = FieldCheck::kFinite;
// A required / optional field of `count` floats at PrimitiveShape byte offset `at`.
constexpr PrimitiveField req(const char* name, size_t at, uint8_t count, FieldCheck check,
                             int8_t slot, float scale = 1.0f) {
    return {name, uint16_t(at), count, check, true, slot, scale};
}
constexpr PrimitiveField opt(const char* name, size_t at, uint8_t count, FieldCheck check,
                             int8_t slot, float scale = 1.0f) {
    return {name, uint16_t(at), count, check, false, slot, scale};
}
}  // namespace table_detail

#define SDFPRUNE_AT(member) offsetof(PrimitiveShape, member)
// clang-format off
inline constexpr PrimitiveKindInfo kPrimitiveTable[math::kPrimitiveKindCount] = {
    {math::kPrimSphere, "sphere", "ball of `radius` about the origin",
     {table_detail::req("radius", SDFPRUNE_AT(radius), 1, table_detail::kPos, 0)}, 1, true,
     [](const PrimitiveShape& s) { return vec3(s.radius); },
     [](const PrimitiveShape& s) { return s.radius; }, nullptr},
    {math::kPrimBox, "box",
     "box of full `sides`; optional xz corner radii `bevel`, rims rounded by `round_x` (top) and `round_y` (bottom)",
     {table_detail::req("sides", SDFPRUNE_AT(sides), 3, table_detail::kPos, 0, 0.5f),
      table_detail::opt("bevel", SDFPRUNE_AT(bevel), 4, table_detail::kNonNeg, 4),
      table_detail::opt("round_x", SDFPRUNE_AT(round_x), 1, table_detail::kNonNeg, 8),
      table_detail::opt("round_y", SDFPRUNE_AT(round_y), 1, table_detail::kNonNeg, 9)}, 4, true,
     [](const PrimitiveShape& s) { return s.sides * 0.5f; }, nullptr, nullptr},
    {math::kPrimCylinder, "cylinder", "cylinder along y of full `height` and `radius`, centred",
     {table_detail::req("height", SDFPRUNE_AT(height), 1, table_detail::kPos, 0, 0.5f),
      table_detail::req("radius", SDFPRUNE_AT(radius), 1, table_detail::kPos, 1)}, 2, true,
     [](const PrimitiveShape& s) { return vec3(s.radius, s.height / 2, s.radius); }, nullptr,
     nullptr},
    {math::kPrimCone, "cone",
     "cone along y of full `height`: base `radius` at y = -height/2, apex at y = +height/2",
     {table_detail::req("height", SDFPRUNE_AT(height), 1, table_detail::kPos, 1, 0.5f),
      table_detail::req("radius", SDFPRUNE_AT(radius), 1, table_detail::kPos, 0)}, 2, true,
     [](const PrimitiveShape& s) { return vec3(s.radius, s.height / 2, s.radius); }, nullptr,
     nullptr},
    {math::kPrimCapsule, "capsule", "`radius` about a segment of length `height` along y, centred",
     {table_detail::req("height", SDFPRUNE_AT(height), 1, table_detail::kNonNeg, 0, 0.5f),
      table_detail::req("radius", SDFPRUNE_AT(radius), 1, table_detail::kPos, 1)}, 2, true,
     [](const PrimitiveShape& s) { return vec3(s.radius, s.height / 2 + s.radius, s.radius); },
     [](const PrimitiveShape& s) { return s.height / 2 + s.radius; }, nullptr},
    {math::kPrimTorus, "torus", "torus in the xz plane of `major_radius` and `minor_radius`",
     {table_detail::req("major_radius", SDFPRUNE_AT(major_radius), 1, table_detail::kPos, 0),
      table_detail::req("minor_radius", SDFPRUNE_AT(minor_radius), 1, table_detail::kPos, 1)}, 2,
     true,
     [](const PrimitiveShape& s) {
         const float r = s.major_radius + s.minor_radius;
         return vec3(r, s.minor_radius, r);
     },
     [](const PrimitiveShape& s) { return s.major_radius + s.minor_radius; }, nullptr},
    {math::kPrimRoundedCylinder, "rounded_cylinder",
     "cylinder along y of full `height` and `radius`, both rims rounded by `rounding`",
     {table_detail::req("height", SDFPRUNE_AT(height), 1, table_detail::kPos, 0, 0.5f),
      table_detail::req("radius", SDFPRUNE_AT(radius), 1, table_detail::kPos, 1),
      table_detail::req("rounding", SDFPRUNE_AT(rounding), 1, table_detail::kNonNeg, 2)}, 3, true,
     [](const PrimitiveShape& s) { return vec3(s.radius, s.height / 2, s.radius); },
     [](const PrimitiveShape& s) { return std::sqrt(s.radius * s.radius + s.height * s.height / 4); },
     [](const PrimitiveShape& s) {
         // The distance is exact only while the rounded rims fit the cylinder.
         if (s.rounding > s.radius || s.rounding > s.height / 2)
             return std::string("rounding must be <= radius and <= height/2");
         return std::string();
     }},
    {math::kPrimCappedCone, "capped_cone",
     "cone frustum along y of full `height`: `radius` at y = -height/2, `top_radius` at +height/2",
     {table_detail::req("height", SDFPRUNE_AT(height), 1, table_detail::kPos, 0, 0.5f),
      table_detail::req("radius", SDFPRUNE_AT(radius), 1, table_detail::kNonNeg, 1),
      table_detail::req("top_radius", SDFPRUNE_AT(top_radius), 1, table_detail::kNonNeg, 2)}, 3,
     true,
     [](const PrimitiveShape& s) {
         const float r = std::max(s.radius, s.top_radius);
         return vec3(r, s.height / 2, r);
     },
     [](const PrimitiveShape& s) {
         const float r = std::max(s.radius, s.top_radius);
         return std::sqrt(r * r + s.height * s.height / 4);
     },
     [](const PrimitiveShape& s) {
         if (!(std::max(s.radius, s.top_radius) > 0))
             return std::string("radius or top_radius must be > 0");
         return std::string();
     }},
    {math::kPrimHexPrism, "hex_prism",
     "hexagonal prism along y of full `height`; `radius` = the hexagon's circumradius (vertices at x = ±radius)",
     {table_detail::req("height", SDFPRUNE_AT(height), 1, table_detail::kPos, 1, 0.5f),
      table_detail::req("radius", SDFPRUNE_AT(radius), 1, table_detail::kPos, 0, 0.8660254f)}, 2,
     true,
     [](const PrimitiveShape& s) { return vec3(s.radius, s.height / 2, s.radius * 0.8660254f); },
     [](const PrimitiveShape& s) { return std::sqrt(s.radius * s.radius + s.height * s.height / 4); },
     nullptr},
    {math::kPrimOctahedron, "octahedron", "regular octahedron |x| + |y| + |z| <= `radius`",
     {table_detail::req("radius", SDFPRUNE_AT(radius), 1, table_detail::kPos, 0)}, 1, true,
     [](const PrimitiveShape& s) { return vec3(s.radius); },
     [](const PrimitiveShape& s) { return s.radius; }, nullptr},
    {math::kPrimPlane, "plane",
     "half-space dot(p, normal) <= offset·|normal| (unbounded: see bounding_box)",
     {table_detail::req("normal", SDFPRUNE_AT(normal), 3, table_detail::kAny, 0),
      table_detail::opt("offset", SDFPRUNE_AT(offset), 1, table_detail::kAny, 3)}, 2, false,
     nullptr, nullptr,
     [](const PrimitiveShape& s) {
         if (!(math::length(s.normal) > 1e-20f)) return std::string("normal must not be zero");
         return std::string();
     }},
};
// clang-format on
#undef SDFPRUNE_AT

// The entry of `kind` (< math::kPrimitiveKindCount).
inline const PrimitiveKindInfo& primitive_info(uint32_t kind) {
    return kPrimitiveTable[kind];
}

// The field's values inside a shape.
inline float* field_values(PrimitiveShape& s, const PrimitiveField& f) {
    return reinterpret_cast<float*>(reinterpret_cast<char*>(&s) + f.offset);
}
inline const float* field_values(const PrimitiveShape& s, const PrimitiveField& f) {
    return reinterpret_cast<const float*>(reinterpret_cast<const char*>(&s) + f.offset);
}

// The primitive's parameter slots (a, b, c of math::PrimitiveParams) from its shape.
void primitive_slots(uint32_t kind, const PrimitiveShape& shape, vec4& a, vec4& b, vec4& c);

// Local half extents / bounding radius (bounded kinds; the radius defaults to the half
// extents' length when the entry gives none).
vec3 primitive_half_extents(uint32_t kind, const PrimitiveShape& shape);
float primitive_bounding_radius(uint32_t kind, const PrimitiveShape& shape);

// Checks a primitive's fields (finite, sign) and the kind's constraints; "" when valid.
std::string validate_primitive(uint32_t kind, const PrimitiveShape& shape);

}  // namespace sdfprune
