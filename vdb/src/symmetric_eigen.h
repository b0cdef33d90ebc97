// Private: eigenvalues and the two leading eigenvectors of a symmetric 3x3 matrix, closed form.
//
// What the metric needs per voxel, without an iterative solver: the eigenvalues by the trigonometric
// formula for the roots of the characteristic cubic (one acos, one cos), and the eigenvectors of the
// largest and the middle eigenvalue, the first from the cross products of the rows of A - xi_0 I,
// the second in the plane orthogonal to it (where the 2x2 problem is well posed even when the two
// smaller eigenvalues coincide). The matrix is scaled by its largest entry first.
#pragma once

#include <algorithm>
#include <cmath>

namespace riemesh::vdb::detail {

struct SymmetricEigen3 {
    double value[3];  ///< descending: xi_0 >= xi_1 >= xi_2
    double vector0[3]; ///< unit eigenvector of value[0]
    double vector1[3]; ///< unit eigenvector of value[1], orthogonal to vector0
};

/// The entries a = (xx, yy, zz, xy, xz, yz).
inline void symmetricEigenvalues3(const double a[6], double out[3])
{
    const double scale = std::max({std::abs(a[0]), std::abs(a[1]), std::abs(a[2]), std::abs(a[3]), std::abs(a[4]), std::abs(a[5])});
    if (!(scale > 0)) {
        out[0] = out[1] = out[2] = 0;
        return;
    }
    const double inv = 1.0 / scale;
    const double xx = a[0] * inv, yy = a[1] * inv, zz = a[2] * inv;
    const double xy = a[3] * inv, xz = a[4] * inv, yz = a[5] * inv;
    const double q = (xx + yy + zz) / 3.0;
    const double off = xy * xy + xz * xz + yz * yz;
    const double dx = xx - q, dy = yy - q, dz = zz - q;
    const double p2 = (dx * dx + dy * dy + dz * dz + 2.0 * off) / 6.0;
    if (!(p2 > 1e-30)) { // a multiple of the identity
        out[0] = out[1] = out[2] = q * scale;
        return;
    }
    const double p = std::sqrt(p2);
    // det((A - qI) / p) / 2, clamped to [-1, 1] against rounding.
    const double det = dx * (dy * dz - yz * yz) - xy * (xy * dz - yz * xz) + xz * (xy * yz - dy * xz);
    const double r = std::clamp(det / (2.0 * p2 * p), -1.0, 1.0);
    // Single precision for the angle (the metric needs eigenvalues to a few digits, and the float
    // functions cost a fraction of the double ones).
    const double c = std::cos(std::acos(float(r)) / 3.0f), s = std::sqrt(std::max(0.0, 1.0 - c * c));
    const double largest = q + 2.0 * p * c;
    const double smallest = q + 2.0 * p * (-0.5 * c - 0.8660254037844386 * s); // cos(phi + 2 pi / 3)
    out[0] = largest * scale;
    out[2] = smallest * scale;
    out[1] = (3.0 * q - largest - smallest) * scale;
}

namespace eigen3 {

inline void cross(const double u[3], const double v[3], double w[3])
{
    w[0] = u[1] * v[2] - u[2] * v[1];
    w[1] = u[2] * v[0] - u[0] * v[2];
    w[2] = u[0] * v[1] - u[1] * v[0];
}
inline double dot(const double u[3], const double v[3]) { return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]; }

/// A unit vector orthogonal to the unit vector u.
inline void orthogonal(const double u[3], double w[3])
{
    if (std::abs(u[0]) > std::abs(u[1])) {
        const double n = 1.0 / std::sqrt(u[0] * u[0] + u[2] * u[2]);
        w[0] = -u[2] * n, w[1] = 0, w[2] = u[0] * n;
    } else {
        const double n = 1.0 / std::sqrt(u[1] * u[1] + u[2] * u[2]);
        w[0] = 0, w[1] = u[2] * n, w[2] = -u[1] * n;
    }
}

} // namespace eigen3

/// The eigenvectors of e.value[0] and e.value[1] (from symmetricEigenvalues3) into e.
inline void symmetricEigenvectors3(const double a[6], SymmetricEigen3& e)
{
    using namespace eigen3;
    const double scale = std::max({std::abs(a[0]), std::abs(a[1]), std::abs(a[2]), std::abs(a[3]), std::abs(a[4]), std::abs(a[5])});
    const double s = scale > 0 ? 1.0 / scale : 1.0;
    const double xx = a[0] * s, yy = a[1] * s, zz = a[2] * s, xy = a[3] * s, xz = a[4] * s, yz = a[5] * s;
    // vector0: the largest cross product of two rows of A - xi_0 I (its null space).
    const double l0 = e.value[0] * s;
    const double r0[3] = {xx - l0, xy, xz}, r1[3] = {xy, yy - l0, yz}, r2[3] = {xz, yz, zz - l0};
    double c[3][3];
    cross(r0, r1, c[0]);
    cross(r0, r2, c[1]);
    cross(r1, r2, c[2]);
    int best = 0;
    double bestNorm = dot(c[0], c[0]);
    for (int i = 1; i < 3; ++i)
        if (const double n = dot(c[i], c[i]); n > bestNorm) best = i, bestNorm = n;
    if (bestNorm > 1e-300) {
        const double inv = 1.0 / std::sqrt(bestNorm);
        for (int k = 0; k < 3; ++k) e.vector0[k] = c[best][k] * inv;
    } else { // xi_0 is (nearly) triple: any direction
        e.vector0[0] = 1, e.vector0[1] = 0, e.vector0[2] = 0;
    }
    // vector1: in the plane (u, v) orthogonal to vector0, the null vector of the 2x2 restriction of
    // A - xi_1 I.
    double u[3], v[3];
    orthogonal(e.vector0, u);
    cross(e.vector0, u, v);
    const double l1 = e.value[1] * s;
    auto apply = [&](const double x[3], double y[3]) {
        y[0] = (xx - l1) * x[0] + xy * x[1] + xz * x[2];
        y[1] = xy * x[0] + (yy - l1) * x[1] + yz * x[2];
        y[2] = xz * x[0] + yz * x[1] + (zz - l1) * x[2];
    };
    double au[3], av[3];
    apply(u, au);
    apply(v, av);
    const double m00 = dot(u, au), m01 = dot(u, av), m11 = dot(v, av);
    // The null vector of [[m00, m01], [m01, m11]]: orthogonal to its larger row.
    double cu, cv;
    if (std::abs(m00) >= std::abs(m11)) {
        const double n2 = m00 * m00 + m01 * m01;
        if (n2 > 1e-300) {
            const double inv = 1.0 / std::sqrt(n2);
            cu = -m01 * inv, cv = m00 * inv;
        } else {
            cu = 1, cv = 0;
        }
    } else {
        const double inv = 1.0 / std::sqrt(m11 * m11 + m01 * m01);
        cu = m11 * inv, cv = -m01 * inv;
    }
    for (int k = 0; k < 3; ++k) e.vector1[k] = cu * u[k] + cv * v[k];
}

inline SymmetricEigen3 symmetricEigen3(const double a[6])
{
    SymmetricEigen3 e;
    symmetricEigenvalues3(a, e.value);
    symmetricEigenvectors3(a, e);
    return e;
}

} // namespace riemesh::vdb::detail
