// Synthetic volumes with exact signed distances (phantom.h).
#include "riemesh/vdb/phantom.h"

#include "riemesh/vdb/io.h"
#include "dense.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace riemesh::vdb {

using openvdb::Vec3d;

std::vector<std::string> phantomShapeNames()
{
    return {"cube-cavity", "ball", "torus", "two-spheres", "thin-plate", "notched-block"};
}

PhantomShape phantomShapeFromName(const std::string& name)
{
    const auto names = phantomShapeNames();
    for (std::size_t i = 0; i < names.size(); ++i)
        if (names[i] == name) return PhantomShape(i);
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
    throw std::invalid_argument("unknown shape '" + name + "' (shapes: " + list + ")");
}

namespace {

double boxDistance(const Vec3d& p, const Vec3d& centre, const Vec3d& half)
{
    const Vec3d q(std::abs(p.x() - centre.x()) - half.x(), std::abs(p.y() - centre.y()) - half.y(),
                  std::abs(p.z() - centre.z()) - half.z());
    const Vec3d outside(std::max(q.x(), 0.0), std::max(q.y(), 0.0), std::max(q.z(), 0.0));
    return outside.length() + std::min(std::max({q.x(), q.y(), q.z()}), 0.0);
}

/// The paper's phantom: cube minus (ball cavity U cylinder from the cavity centre up through the top face).
double cubeCavityDistance(const Vec3d& p, int size)
{
    const double n = size, cc = 0.5 * (n - 1);
    const Vec3d c(cc);
    const double h = 0.3 * n;     // cube half-size
    const double R = 0.18 * n;    // cavity radius
    const double rh = 0.06 * n;   // hole radius
    const double top = cc + h;    // the face with the hole
    const double zr = cc + std::sqrt(R * R - rh * rh); // where the hole meets the cavity

    const Vec3d d = p - c;
    const double rxy = std::sqrt(d.x() * d.x() + d.y() * d.y());

    // Distance to the six faces (the top one without the hole's disc).
    double dist = std::numeric_limits<double>::max();
    for (int axis = 0; axis < 3; ++axis)
        for (int side = -1; side <= 1; side += 2) {
            Vec3d q = p;
            q[axis] = cc + side * h;
            for (int b = 0; b < 3; ++b)
                if (b != axis) q[b] = std::clamp(p[b], cc - h, cc + h);
            if (axis == 2 && side == 1) {
                const double qx = q.x() - cc, qy = q.y() - cc, qr = std::sqrt(qx * qx + qy * qy);
                if (qr < rh) { // inside the hole's disc: the nearest face point is on its rim
                    if (qr > 0) {
                        q.x() = cc + qx * rh / qr;
                        q.y() = cc + qy * rh / qr;
                    } else {
                        q.x() = cc + rh;
                    }
                }
            }
            dist = std::min(dist, (p - q).length());
        }
    // Distance to the cavity's sphere without the cap the hole removes.
    {
        const double len = d.length();
        const Vec3d q = len > 0 ? c + d * (R / len) : c + Vec3d(0, 0, -R);
        const double qx = q.x() - cc, qy = q.y() - cc;
        if (std::sqrt(qx * qx + qy * qy) < rh && q.z() > cc) // in the removed cap: nearest is its rim
            dist = std::min(dist, std::hypot(rxy - rh, p.z() - zr));
        else
            dist = std::min(dist, (p - q).length());
    }
    // Distance to the hole's cylindrical wall between the cavity and the top face.
    {
        const double dz = std::max({zr - p.z(), 0.0, p.z() - top});
        dist = std::min(dist, std::hypot(rxy - rh, dz));
    }
    const bool inCube = std::abs(d.x()) < h && std::abs(d.y()) < h && std::abs(d.z()) < h;
    const bool inCavity = d.length() < R || (rxy < rh && p.z() > cc);
    return (inCube && !inCavity) ? -dist : dist;
}

/// Counter-based standard normal variate (splitmix64 + Box-Muller): the same for a (seed, index)
/// pair on every platform and thread count.
double normalVariate(std::uint64_t seed, std::uint64_t index)
{
    auto mix = [](std::uint64_t z) {
        z += 0x9E3779B97F4A7C15ull;
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return z ^ (z >> 31);
    };
    const std::uint64_t a = mix(seed * 0x632BE59BD9B4E019ull ^ mix(2 * index));
    const std::uint64_t b = mix(a ^ mix(2 * index + 1));
    const double u1 = (double(a >> 11) + 1.0) * 0x1.0p-53; // (0, 1]
    const double u2 = double(b >> 11) * 0x1.0p-53;         // [0, 1)
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
}

} // namespace

double phantomDistance(PhantomShape shape, int size, const Vec3d& p)
{
    const double n = size, cc = 0.5 * (n - 1);
    const Vec3d c(cc);
    switch (shape) {
    case PhantomShape::CubeCavity: return cubeCavityDistance(p, size);
    case PhantomShape::Ball: return (p - c).length() - 0.3 * n;
    case PhantomShape::Torus: {
        const Vec3d d = p - c;
        return std::hypot(std::hypot(d.x(), d.y()) - 0.28 * n, d.z()) - 0.1 * n;
    }
    case PhantomShape::TwoSpheres: {
        const double r = 0.2 * n, off = r + 1.5; // gap of 3 voxels
        return std::min((p - (c + Vec3d(off, 0, 0))).length(), (p - (c - Vec3d(off, 0, 0))).length()) - r;
    }
    case PhantomShape::ThinPlate: return boxDistance(p, c, Vec3d(0.35 * n, 0.35 * n, 1.5));
    case PhantomShape::NotchedBlock: {
        // The cube A less the notch B (x and z beyond s from the centre, through in y). Inside, the
        // distance to the boundary is min(depth in A, distance to B); outside, the distance to the
        // solid, which is the union of the cube's part x <= s and its part x >= s, z <= s.
        const double h = 0.3 * n, s = 0.05 * n;
        const double inA = boxDistance(p, c, Vec3d(h));
        const double far = 2 * h; // the notch box reaches past the cube
        const Vec3d notchLo(cc + s, cc - far, cc + s), notchHi(cc + far, cc + far, cc + far);
        const double toB = boxDistance(p, 0.5 * (notchLo + notchHi), 0.5 * (notchHi - notchLo));
        if (inA < 0 && toB > 0) return std::max(inA, -toB);
        const Vec3d loX(cc - h, cc - h, cc - h), hiX(cc + s, cc + h, cc + h);  // x <= s
        const Vec3d loZ(cc + s, cc - h, cc - h), hiZ(cc + h, cc + h, cc + s);  // x >= s, z <= s
        return std::min(boxDistance(p, 0.5 * (loX + hiX), 0.5 * (hiX - loX)),
                        boxDistance(p, 0.5 * (loZ + hiZ), 0.5 * (hiZ - loZ)));
    }
    }
    return 0;
}

Phantom makePhantom(PhantomShape shape, const PhantomOptions& options)
{
    if (options.size < 16 || options.size > 1024) throw std::invalid_argument("phantom size must be in [16, 1024] voxels");
    if (!(options.noise >= 0) || !std::isfinite(options.noise)) throw std::invalid_argument("phantom noise must be >= 0");
    initialize();
    const int n = options.size;
    const detail::DenseLayout layout(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(n - 1)));
    std::vector<float> sdf(layout.size()), density(layout.size());
    tbb::parallel_for(tbb::blocked_range<int>(0, n), [&](const tbb::blocked_range<int>& rg) {
        for (int k = rg.begin(); k != rg.end(); ++k)
            for (int j = 0; j < n; ++j)
                for (int i = 0; i < n; ++i) {
                    const std::size_t v = layout.index(i, j, k);
                    const double d = phantomDistance(shape, n, Vec3d(i, j, k));
                    sdf[v] = float(d);
                    double value = std::clamp(0.5 - d, 0.0, 1.0);
                    if (options.noise > 0) value += options.noise * normalVariate(options.seed, v);
                    density[v] = float(value);
                }
    });
    Phantom out;
    out.density = detail::denseToGrid<openvdb::FloatGrid>(density, layout, 0.0f);
    out.density->setName("density");
    out.density->setGridClass(openvdb::GRID_FOG_VOLUME);
    out.sdf = detail::denseToGrid<openvdb::FloatGrid>(sdf, layout, float(n));
    out.sdf->setName("sdf");
    out.sdf->setGridClass(openvdb::GRID_LEVEL_SET);
    const auto transform = openvdb::math::Transform::createLinearTransform(1.0);
    out.density->setTransform(transform);
    out.sdf->setTransform(transform->copy());
    out.density->insertMeta("riemesh:noise", openvdb::DoubleMetadata(options.noise));
    out.density->insertMeta("riemesh:seed", openvdb::Int64Metadata(std::int64_t(options.seed)));
    // The shape and size on both grids: a reference measure (level_set.h, phantomReferenceDistance)
    // then evaluates the analytic distance, exact at edges and corners, instead of interpolating.
    for (const auto& grid : {out.density, out.sdf}) {
        grid->insertMeta("riemesh:phantom", openvdb::StringMetadata(phantomShapeNames()[int(shape)]));
        grid->insertMeta("riemesh:size", openvdb::Int32Metadata(n));
    }
    return out;
}

} // namespace riemesh::vdb
