// primitives.cpp — what the primitive table (primitives.hpp) drives in the core: parameter
// slots, local bounds and validation, the same code for every kind.
#include "sdfprune/primitives.hpp"

#include <cmath>
#include <cstring>

namespace sdfprune {
namespace {

// Every field name must mean the same member and count in every kind: the loader stores a
// field before it knows the node's kind.
constexpr bool field_names_consistent() {
    for (const PrimitiveKindInfo& a : kPrimitiveTable)
        for (uint32_t i = 0; i < a.field_count; ++i)
            for (const PrimitiveKindInfo& b : kPrimitiveTable)
                for (uint32_t j = 0; j < b.field_count; ++j) {
                    const PrimitiveField &f = a.fields[i], &g = b.fields[j];
                    if (std::string_view(f.name) == g.name &&
                        (f.offset != g.offset || f.count != g.count))
                        return false;
                }
    return true;
}
static_assert(field_names_consistent(), "a field name must mean one PrimitiveShape member");

constexpr bool kinds_in_order() {
    for (uint32_t k = 0; k < math::kPrimitiveKindCount; ++k)
        if (kPrimitiveTable[k].kind != k) return false;
    return true;
}
static_assert(kinds_in_order(), "kPrimitiveTable[k] must describe kind k");

std::string value_error(const PrimitiveField& f, uint32_t i, float v) {
    std::string name(f.name);
    if (f.count > 1) name.append("[").append(std::to_string(i)).append("]");
    const char* rule = nullptr;
    if (!std::isfinite(v)) return name.append(" must be finite");
    if (f.check == FieldCheck::kPositive && !(v > 0)) rule = " must be > 0 (got ";
    if (f.check == FieldCheck::kNonNegative && !(v >= 0)) rule = " must be >= 0 (got ";
    if (!rule) return {};
    return name.append(rule).append(std::to_string(v)).append(")");
}

}  // namespace

void primitive_slots(uint32_t kind, const PrimitiveShape& shape, vec4& a, vec4& b, vec4& c) {
    vec4* slots[3] = {&a, &b, &c};
    const PrimitiveKindInfo& info = primitive_info(kind);
    for (uint32_t i = 0; i < info.field_count; ++i) {
        const PrimitiveField& f = info.fields[i];
        if (f.slot < 0) continue;
        const float* v = field_values(shape, f);
        for (uint32_t j = 0; j < f.count; ++j) {
            const int slot = f.slot + int(j);
            (*slots[slot / 4])[slot % 4] = f.scale == 1.0f ? v[j] : v[j] * f.scale;
        }
    }
}

vec3 primitive_half_extents(uint32_t kind, const PrimitiveShape& shape) {
    const PrimitiveKindInfo& info = primitive_info(kind);
    return info.half_extents ? info.half_extents(shape) : vec3(INFINITY);
}

float primitive_bounding_radius(uint32_t kind, const PrimitiveShape& shape) {
    const PrimitiveKindInfo& info = primitive_info(kind);
    if (!info.bounded) return INFINITY;
    return info.bounding_radius ? info.bounding_radius(shape)
                                : math::length(primitive_half_extents(kind, shape));
}

std::string validate_primitive(uint32_t kind, const PrimitiveShape& shape) {
    if (kind >= math::kPrimitiveKindCount) return "unknown primitive";
    const PrimitiveKindInfo& info = primitive_info(kind);
    for (uint32_t i = 0; i < info.field_count; ++i) {
        const PrimitiveField& f = info.fields[i];
        const float* v = field_values(shape, f);
        for (uint32_t j = 0; j < f.count; ++j)
            if (std::string e = value_error(f, j, v[j]); !e.empty()) return e;
    }
    return info.check ? info.check(shape) : std::string();
}

}  // namespace sdfprune
