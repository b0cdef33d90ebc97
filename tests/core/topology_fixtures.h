// tests/core/topology_fixtures.h: procedural fixtures for the collision, topology and evolution suites
// (analytic fog images of balls and tori, regular spheres and tori, a dumbbell with a triangular-prism
// tube, turned-over copies, edge statistics).
#pragma once

#include "riemesh/image.h"
#include "riemesh/mesh.h"
#include "riemesh/primitives.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <vector>

namespace riemesh::fixtures {

/// A fog-like analytic image: 1 inside, 0 outside, a smooth (tanh) transition one voxel wide
/// centred on the surface sdf = 0 (sdf > 0 inside). The isosurface I = 0.5 is exactly sdf = 0.
inline FunctionImage fogImage(std::function<double(const Vec3&)> sdf, const Box3& bounds)
{
    return FunctionImage([sdf](const Vec3& x) { return 0.5 + 0.5 * std::tanh(sdf(x)); }, bounds, 1.0);
}

inline double ballSdf(const Vec3& x, const Vec3& c, double r) { return r - (x - c).norm(); }

inline double torusSdf(const Vec3& x, double major, double minor)
{
    const double q = std::hypot(x.x(), x.y()) - major;
    return minor - std::hypot(q, x.z());
}


struct EdgeStats {
    double min = std::numeric_limits<double>::infinity();
    double max = 0;
    double mean = 0;
};

/// `mesh` with every face turned over: the same surface oriented inward (a cavity's wall, or a
/// component turned inside out).
inline Mesh turnedOver(const Mesh& mesh)
{
    Mesh out;
    for (auto v : mesh.vertices()) out.add_vertex(mesh.point(v));
    for (auto f : mesh.faces()) {
        std::vector<VertexHandle> corners;
        for (auto v : mesh.fv_range(f)) corners.insert(corners.begin(), v);
        out.add_face(corners);
    }
    return out;
}

inline EdgeStats edgeStats(const Mesh& mesh)
{
    EdgeStats s;
    int count = 0;
    for (auto e : mesh.edges()) {
        const auto h = mesh.halfedge_handle(e, 0);
        const double l = (mesh.point(mesh.to_vertex_handle(h)) - mesh.point(mesh.from_vertex_handle(h))).norm();
        s.min = std::min(s.min, l);
        s.max = std::max(s.max, l);
        s.mean += l;
        ++count;
    }
    if (count) s.mean /= count;
    return s;
}

/// Icosphere whose shortest edge is `edge` (world units).
inline Mesh makeRegularSphere(const Vec3& center, int subdivisions, double edge)
{
    const double unitMin = edgeStats(makeIcosphere(Vec3::Zero(), 1.0, subdivisions)).min;
    return makeIcosphere(center, edge / unitMin, subdivisions);
}

/// Torus around z whose quads are about `edge` on a side (world units), at least 3 minor segments.
inline Mesh makeRegularTorus(const Vec3& center, double major, double minor, double edge)
{
    const int majorSegments = std::max(3, int(std::lround(2 * M_PI * (major - minor) / edge)));
    const int minorSegments = std::max(3, int(std::lround(2 * M_PI * minor / edge)));
    return makeTorus(center, major, minor, majorSegments, minorSegments);
}

/// The vertex of `mesh` farthest along `direction`.
inline VertexHandle extremeVertex(const Mesh& mesh, const Vec3& direction)
{
    VertexHandle best;
    double bestDot = -std::numeric_limits<double>::infinity();
    for (auto v : mesh.vertices()) {
        const double d = position(mesh, v).dot(direction);
        if (d > bestDot) { bestDot = d; best = v; }
    }
    return best;
}

/// Two icospheres (radius `radius`) on the x axis joined by a thin tube of triangular cross-section:
/// the tube starts at the face of the left sphere that faces +x and ends at the face of the right
/// sphere that faces -x, with `tubeSegments` segments. `ring` receives the tube's inner rings
/// (3 vertices each, in a consistent order), `tubeSegments - 1` of them.
inline Mesh makeDumbbell(double radius, int subdivisions, double gap, int tubeSegments,
                         std::vector<std::array<VertexHandle, 3>>* rings = nullptr)
{
    const Mesh a = makeIcosphere(Vec3::Zero(), radius, subdivisions);
    const Vec3 offset(2 * radius + gap, 0, 0);
    const Mesh b = makeIcosphere(offset, radius, subdivisions);
    auto extremeFace = [](const Mesh& m, double sign) {
        FaceHandle best;
        double bestX = -std::numeric_limits<double>::infinity();
        for (auto f : m.faces()) {
            Vec3 c = Vec3::Zero();
            for (auto v : m.fv_range(f)) c += position(m, v);
            if (sign * c.x() > bestX) { bestX = sign * c.x(); best = f; }
        }
        return best;
    };
    const FaceHandle fa = extremeFace(a, +1), fb = extremeFace(b, -1);

    Mesh mesh;
    prepareMesh(mesh);
    std::vector<VertexHandle> mapA, mapB;
    for (auto v : a.vertices()) mapA.push_back(mesh.add_vertex(a.point(v)));
    for (auto v : b.vertices()) mapB.push_back(mesh.add_vertex(b.point(v)));
    for (auto f : a.faces()) {
        if (f == fa) continue;
        std::vector<VertexHandle> t;
        for (auto v : a.fv_range(f)) t.push_back(mapA[v.idx()]);
        mesh.add_face(t);
    }
    for (auto f : b.faces()) {
        if (f == fb) continue;
        std::vector<VertexHandle> t;
        for (auto v : b.fv_range(f)) t.push_back(mapB[v.idx()]);
        mesh.add_face(t);
    }
    // End rings sorted by angle around the x axis.
    auto ringOf = [&](const Mesh& m, FaceHandle f, const std::vector<VertexHandle>& map) {
        std::array<VertexHandle, 3> r;
        int i = 0;
        for (auto v : m.fv_range(f)) r[i++] = map[v.idx()];
        Vec3 c = Vec3::Zero();
        for (auto v : r) c += position(mesh, v);
        c /= 3;
        std::sort(r.begin(), r.end(), [&](VertexHandle x, VertexHandle y) {
            const Vec3 px = position(mesh, x) - c, py = position(mesh, y) - c;
            return std::atan2(px.z(), px.y()) < std::atan2(py.z(), py.y());
        });
        return r;
    };
    const auto r0 = ringOf(a, fa, mapA);
    auto rK = ringOf(b, fb, mapB);
    int shift = 0;
    double bestCost = std::numeric_limits<double>::infinity();
    for (int s = 0; s < 3; ++s) {
        double cost = 0;
        for (int i = 0; i < 3; ++i) {
            const Vec3 d = position(mesh, r0[i]) - position(mesh, rK[(i + s) % 3]);
            cost += std::hypot(d.y(), d.z());
        }
        if (cost < bestCost) { bestCost = cost; shift = s; }
    }
    std::rotate(rK.begin(), rK.begin() + shift, rK.end());
    std::vector<std::array<VertexHandle, 3>> all{r0};
    for (int k = 1; k < tubeSegments; ++k) {
        const double t = double(k) / tubeSegments;
        std::array<VertexHandle, 3> r;
        for (int i = 0; i < 3; ++i)
            r[i] = mesh.add_vertex(toPoint((1 - t) * position(mesh, r0[i]) + t * position(mesh, rK[i])));
        all.push_back(r);
    }
    all.push_back(rK);
    auto centroidOf = [&](const std::array<VertexHandle, 3>& r) {
        return Vec3((position(mesh, r[0]) + position(mesh, r[1]) + position(mesh, r[2])) / 3);
    };
    const Vec3 axis0 = centroidOf(r0), axisDir = (centroidOf(rK) - axis0).normalized();
    auto addOutward = [&](VertexHandle x, VertexHandle y, VertexHandle z) {
        const Vec3 px = position(mesh, x), py = position(mesh, y), pz = position(mesh, z);
        const Vec3 c = (px + py + pz) / 3;
        const Vec3 n = (py - px).cross(pz - px);
        const Vec3 along = axis0 + (c - axis0).dot(axisDir) * axisDir;
        const Vec3 radial = c - along; // away from the tube axis
        if (n.dot(radial) >= 0) mesh.add_face(x, y, z);
        else mesh.add_face(x, z, y);
    };
    for (int k = 0; k < tubeSegments; ++k)
        for (int i = 0; i < 3; ++i) {
            const int j = (i + 1) % 3;
            addOutward(all[k][i], all[k][j], all[k + 1][j]);
            addOutward(all[k][i], all[k + 1][j], all[k + 1][i]);
        }
    if (rings) rings->assign(all.begin() + 1, all.end() - 1);
    return mesh;
}

} // namespace riemesh::fixtures
