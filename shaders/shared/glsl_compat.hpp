// glsl_compat.hpp — the small part of GLSL's vector language that sdf_math.h uses, for C++.
// With it, the SDF math is one source for the CPU backend and the Vulkan shaders.
#pragma once

#include <cmath>
#include <cstdint>

namespace sdfprune::glsl {

using uint = std::uint32_t;

struct vec2 {
    float x = 0, y = 0;
    constexpr vec2() = default;
    constexpr vec2(float a, float b) : x(a), y(b) {}
    constexpr explicit vec2(float a) : x(a), y(a) {}
};

struct vec3 {
    float x = 0, y = 0, z = 0;
    constexpr vec3() = default;
    constexpr vec3(float a, float b, float c) : x(a), y(b), z(c) {}
    constexpr explicit vec3(float a) : x(a), y(a), z(a) {}
    constexpr float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
    constexpr float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
    constexpr vec2 xz() const { return {x, z}; }
    constexpr bool operator==(const vec3&) const = default;
};

// 16-byte aligned like GLSL's std430 vec4, so shared structs have one layout on both sides.
struct alignas(16) vec4 {
    float x = 0, y = 0, z = 0, w = 0;
    constexpr vec4() = default;
    constexpr vec4(float a, float b, float c, float d) : x(a), y(b), z(c), w(d) {}
    constexpr vec3 xyz() const { return {x, y, z}; }
    constexpr float operator[](int i) const { return i == 0 ? x : i == 1 ? y : i == 2 ? z : w; }
    constexpr float& operator[](int i) { return i == 0 ? x : i == 1 ? y : i == 2 ? z : w; }
    constexpr bool operator==(const vec4&) const = default;
};

// clang-format off
constexpr vec2 operator+(vec2 a, vec2 b) { return {a.x + b.x, a.y + b.y}; }
constexpr vec2 operator-(vec2 a, vec2 b) { return {a.x - b.x, a.y - b.y}; }
constexpr vec2 operator*(vec2 a, float s) { return {a.x * s, a.y * s}; }
constexpr vec2 operator*(float s, vec2 a) { return a * s; }
constexpr vec2 operator+(vec2 a, float s) { return {a.x + s, a.y + s}; }
constexpr vec2 operator-(vec2 a, float s) { return {a.x - s, a.y - s}; }
constexpr vec3 operator+(vec3 a, vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
constexpr vec3 operator-(vec3 a, vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
constexpr vec3 operator*(vec3 a, vec3 b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
constexpr vec3 operator*(vec3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
constexpr vec3 operator*(float s, vec3 a) { return a * s; }
constexpr vec3 operator/(vec3 a, float s) { return {a.x / s, a.y / s, a.z / s}; }
constexpr vec3 operator-(vec3 a) { return {-a.x, -a.y, -a.z}; }
constexpr vec3 operator+(vec3 a, float s) { return {a.x + s, a.y + s, a.z + s}; }
constexpr vec3 operator-(vec3 a, float s) { return {a.x - s, a.y - s, a.z - s}; }

inline float abs(float a) { return std::fabs(a); }
inline float min(float a, float b) { return a < b ? a : b; }
inline float max(float a, float b) { return a > b ? a : b; }
inline uint min(uint a, uint b) { return a < b ? a : b; }
inline float clamp(float a, float lo, float hi) { return min(max(a, lo), hi); }
inline float sqrt(float a) { return std::sqrt(a); }
inline vec2 abs(vec2 a) { return {std::fabs(a.x), std::fabs(a.y)}; }
inline vec2 max(vec2 a, float s) { return {max(a.x, s), max(a.y, s)}; }
inline vec3 abs(vec3 a) { return {std::fabs(a.x), std::fabs(a.y), std::fabs(a.z)}; }
inline vec3 max(vec3 a, float s) { return {max(a.x, s), max(a.y, s), max(a.z, s)}; }
inline vec3 max(vec3 a, vec3 b) { return {max(a.x, b.x), max(a.y, b.y), max(a.z, b.z)}; }
inline vec3 min(vec3 a, vec3 b) { return {min(a.x, b.x), min(a.y, b.y), min(a.z, b.z)}; }
inline float dot(vec2 a, vec2 b) { return a.x * b.x + a.y * b.y; }
inline float dot(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline float length(vec2 a) { return std::sqrt(dot(a, a)); }
inline float length(vec3 a) { return std::sqrt(dot(a, a)); }
// clang-format on

}  // namespace sdfprune::glsl
