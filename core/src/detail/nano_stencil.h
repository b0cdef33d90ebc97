// detail/nano_stencil.h: the 2x2x2 voxel values around a point of a NanoVDB grid, read with one
// tree traversal when the block lies inside one leaf (7 times in 8 per axis), for trilinear value
// and gradient. NanoVDB's sampler does eight cached accessor lookups per sample; the model samples
// every vertex every iteration, so this is on the hot path.
#pragma once

#include <nanovdb/NanoVDB.h>

#include <cmath>

namespace riemesh::detail {

template<typename ValueT>
struct Stencil {
    ValueT v[8];   ///< v[(di << 2) | (dj << 1) | dk] = value at (i+di, j+dj, k+dk)
    double fx, fy, fz; ///< fractional position inside the cell, in [0, 1)
};

/// Fills `s` for the index-space point `p`, through `acc` (a ReadAccessor of the grid; it caches
/// the path to the last leaf, and successive mesh vertices are mostly close to each other).
template<typename ValueT, typename AccessorT>
inline void fetchStencil(const AccessorT& acc, const nanovdb::Vec3d& p, Stencil<ValueT>& s)
{
    // Index coordinates beyond +-2^30 (or NaN; a far point, or a file's extreme transform) are
    // clamped there: converting them to int would be undefined (found by fuzz_nvdb_read), and no
    // grid reaches that far, so they read the background either way.
    auto cell = [](double x, double& frac) {
        constexpr double kFar = 1073741824.0;
        const double f = std::floor(x);
        if (!(std::abs(f) < kFar)) {
            frac = 0;
            return x > 0 ? int(kFar) : -int(kFar);
        }
        frac = x - f;
        return int(f);
    };
    const nanovdb::Coord ijk{cell(p[0], s.fx), cell(p[1], s.fy), cell(p[2], s.fz)};
    if ((ijk[0] & 7) != 7 && (ijk[1] & 7) != 7 && (ijk[2] & 7) != 7) {
        const auto* leaf = acc.probeLeaf(ijk);
        if (!leaf) { // a tile or the background: the whole block has one value
            const ValueT value = acc.getValue(ijk);
            for (auto& x : s.v) x = value;
            return;
        }
        const uint32_t base = leaf->CoordToOffset(ijk);
        for (int n = 0; n < 8; ++n)
            s.v[n] = leaf->getValue(base + (uint32_t((n >> 2) & 1) << 6) + (uint32_t((n >> 1) & 1) << 3) + uint32_t(n & 1));
        return;
    }
    for (int n = 0; n < 8; ++n)
        s.v[n] = acc.getValue(ijk.offsetBy((n >> 2) & 1, (n >> 1) & 1, n & 1));
}

/// Trilinear interpolation of the stencil (works for scalars and nanovdb::Vec3f).
template<typename ValueT>
inline ValueT trilinear(const Stencil<ValueT>& s)
{
    const float fx = float(s.fx), fy = float(s.fy), fz = float(s.fz);
    auto lerp = [](const ValueT& a, const ValueT& b, float t) { return a + (b - a) * t; };
    const ValueT x00 = lerp(s.v[0], s.v[4], fx), x01 = lerp(s.v[1], s.v[5], fx);
    const ValueT x10 = lerp(s.v[2], s.v[6], fx), x11 = lerp(s.v[3], s.v[7], fx);
    return lerp(lerp(x00, x01, fz), lerp(x10, x11, fz), fy);
}

/// Gradient of the trilinear interpolant of a scalar stencil, in index space.
inline nanovdb::Vec3d trilinearGradient(const Stencil<float>& s)
{
    const double fx = s.fx, fy = s.fy, fz = s.fz;
    const float* v = s.v;
    // d/dx: difference along i of the bilinear (j, k) interpolants, etc.
    auto bilerp = [](double a, double b, double c, double d, double t, double u) {
        return (a * (1 - u) + b * u) * (1 - t) + (c * (1 - u) + d * u) * t;
    };
    const double gx = bilerp(v[4], v[5], v[6], v[7], fy, fz) - bilerp(v[0], v[1], v[2], v[3], fy, fz);
    const double gy = bilerp(v[2], v[3], v[6], v[7], fx, fz) - bilerp(v[0], v[1], v[4], v[5], fx, fz);
    const double gz = bilerp(v[1], v[3], v[5], v[7], fx, fy) - bilerp(v[0], v[2], v[4], v[6], fx, fy);
    return nanovdb::Vec3d(gx, gy, gz);
}

} // namespace riemesh::detail
