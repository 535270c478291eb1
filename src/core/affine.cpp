// affine.cpp — 3x4 affine maps: composition, inverse, spectral norm (the Lipschitz factor of a
// primitive's world->local map, issue #2 §4).
#include <algorithm>
#include <cmath>
#include <numbers>

#include "sdfprune/scene.hpp"

namespace sdfprune {

Affine Affine::translation(vec3 t) {
    Affine a;
    a.m[3] = t.x;
    a.m[7] = t.y;
    a.m[11] = t.z;
    return a;
}

Affine Affine::scaling(vec3 s) {
    Affine a;
    a.m[0] = s.x;
    a.m[5] = s.y;
    a.m[10] = s.z;
    return a;
}

Affine Affine::rotation(vec3 axis, float radians) {
    double len =
        std::sqrt(double(axis.x) * axis.x + double(axis.y) * axis.y + double(axis.z) * axis.z);
    if (!(len > 0)) throw SceneError("rotation axis must be non-zero");
    double x = axis.x / len, y = axis.y / len, z = axis.z / len;
    double c = std::cos(radians), s = std::sin(radians), t = 1 - c;
    Affine a;
    const double r[9] = {t * x * x + c,     t * x * y - s * z, t * x * z + s * y,
                         t * x * y + s * z, t * y * y + c,     t * y * z - s * x,
                         t * x * z - s * y, t * y * z + s * x, t * z * z + c};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) a.m[4 * i + j] = float(r[3 * i + j]);
    return a;
}

vec3 Affine::apply(vec3 p) const {
    return {m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3],
            m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
            m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]};
}

Affine Affine::compose(const Affine& b) const {
    // Double accumulation: chains of 100,000 levels compose without drifting.
    Affine r;
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 4; ++j) {
            double s = j == 3 ? double(m[4 * i + 3]) : 0.0;
            for (int k = 0; k < 3; ++k) s += double(m[4 * i + k]) * double(b.m[4 * k + j]);
            r.m[4 * i + j] = float(s);
        }
    }
    return r;
}

Affine Affine::inverse() const {
    const double a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9],
                 i = m[10];
    const double det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g);
    double scale = 0;
    for (int k : {0, 1, 2, 4, 5, 6, 8, 9, 10}) scale = std::max(scale, std::fabs(double(m[k])));
    if (!(std::fabs(det) > 1e-12 * scale * scale * scale) || !std::isfinite(det))
        throw SceneError("matrix is singular");
    const double inv[9] = {(e * i - f * h) / det, (c * h - b * i) / det, (b * f - c * e) / det,
                           (f * g - d * i) / det, (a * i - c * g) / det, (c * d - a * f) / det,
                           (d * h - e * g) / det, (b * g - a * h) / det, (a * e - b * d) / det};
    Affine r;
    for (int row = 0; row < 3; ++row) {
        double t = 0;
        for (int k = 0; k < 3; ++k) {
            r.m[4 * row + k] = float(inv[3 * row + k]);
            t -= inv[3 * row + k] * double(m[4 * k + 3]);
        }
        r.m[4 * row + 3] = float(t);
    }
    return r;
}

float spectral_norm(const Affine& a) {
    // Largest eigenvalue of the symmetric matrix S = AᵀA, in closed form (trigonometric method).
    double A[3][3];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) A[i][j] = a.m[4 * i + j];
    double S[3][3];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            S[i][j] = 0;
            for (int k = 0; k < 3; ++k) S[i][j] += A[k][i] * A[k][j];
        }
    const double p1 = S[0][1] * S[0][1] + S[0][2] * S[0][2] + S[1][2] * S[1][2];
    const double q = (S[0][0] + S[1][1] + S[2][2]) / 3;
    double largest;
    if (p1 <= 1e-30 * (q * q + 1e-300)) {
        largest = std::max({S[0][0], S[1][1], S[2][2]});
    } else {
        const double p2 = (S[0][0] - q) * (S[0][0] - q) + (S[1][1] - q) * (S[1][1] - q) +
                          (S[2][2] - q) * (S[2][2] - q) + 2 * p1;
        const double p = std::sqrt(p2 / 6);
        double B[3][3];
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) B[i][j] = (S[i][j] - (i == j ? q : 0)) / p;
        const double detB = B[0][0] * (B[1][1] * B[2][2] - B[1][2] * B[2][1]) -
                            B[0][1] * (B[1][0] * B[2][2] - B[1][2] * B[2][0]) +
                            B[0][2] * (B[1][0] * B[2][1] - B[1][1] * B[2][0]);
        const double r = std::clamp(detB / 2, -1.0, 1.0);
        const double phi = std::acos(r) / 3;
        largest = q + 2 * p * std::cos(phi);
    }
    const double norm = std::sqrt(std::max(largest, 0.0));
    // Rigid maps stored in float are orthonormal only to ~1e-7: call them 1 (the pruning test's
    // relative margin covers the difference). Otherwise round up, never below the true norm.
    if (std::fabs(norm - 1) < 2e-6) return 1.0f;
    const float f = float(norm);
    return double(f) < norm ? std::nextafter(f, INFINITY) : f;
}

}  // namespace sdfprune
