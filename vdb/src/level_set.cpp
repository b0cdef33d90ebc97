// Meshes as level sets, and two-sided distances between a mesh and a reference surface from dense
// samples of both (level_set.h).
//
// Mesh -> surface: points over every triangle (about 4 per square voxel, vertices and edges included),
// |signed distance| read from the reference, area-weighted mean. Surface -> mesh: points on the
// reference surface found by projecting a fine lattice (spacing voxel/3) of the band |d| < voxel onto
// d = 0 along the distance gradient. With an exact distance, lattice points outside a convex crease or a
// corner project onto the crease or the corner itself, and points inside a concave one onto it, so the
// samples hold the surface's edges and corners, which voxel centres projected one by one miss. The
// distance of each sample to the mesh is exact (closest point over the triangles of a uniform grid).
#include "riemesh/vdb/level_set.h"
#include "riemesh/vdb/io.h"
#include "riemesh/vdb/phantom.h"

#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/MeshToVolume.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <unordered_map>
#include <unordered_set>

namespace riemesh::vdb {

using openvdb::Vec3d;

void meshArrays(const Mesh& mesh, std::vector<Vec3d>& points, std::vector<openvdb::Vec3I>& triangles)
{
    std::vector<int> index(mesh.n_vertices(), -1);
    for (auto v : mesh.vertices()) {
        if (mesh.status(v).deleted()) continue;
        index[v.idx()] = int(points.size());
        const auto p = mesh.point(v);
        points.emplace_back(p[0], p[1], p[2]);
    }
    for (auto f : mesh.faces()) {
        if (mesh.status(f).deleted()) continue;
        openvdb::Vec3I t;
        int n = 0;
        for (auto v : mesh.fv_range(f)) t[n++] = openvdb::Index32(index[v.idx()]);
        if (n == 3) triangles.push_back(t);
    }
}

namespace {

/// World points to the index space that meshToVolume's adapter expects.
std::vector<openvdb::Vec3s> toIndexSpace(const std::vector<Vec3d>& world, const openvdb::math::Transform& xform)
{
    std::vector<openvdb::Vec3s> points;
    points.reserve(world.size());
    for (const auto& p : world) points.push_back(openvdb::Vec3s(xform.worldToIndex(p)));
    return points;
}

/// Closest point of triangle abc to p (Ericson, Real-Time Collision Detection 5.1.5).
Vec3d closestOnTriangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c)
{
    const Vec3d ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) return a;
    const Vec3d bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) return b;
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
    const Vec3d cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) return c;
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    const double denom = va + vb + vc;
    if (!(std::abs(denom) > 0)) return a; // degenerate triangle
    const double v = vb / denom, w = vc / denom;
    return a + ab * v + ac * w;
}

/// Triangles bucketed in a uniform grid of cubic cells; exact distance from a point to the nearest.
class TriangleGrid {
public:
    TriangleGrid(const std::vector<Vec3d>& points, const std::vector<openvdb::Vec3I>& triangles, double cell)
        : mPoints(points), mTriangles(triangles), mCell(cell)
    {
        for (std::size_t t = 0; t < triangles.size(); ++t) {
            Vec3d lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
            for (int k = 0; k < 3; ++k) {
                lo = openvdb::math::minComponent(lo, points[triangles[t][k]]);
                hi = openvdb::math::maxComponent(hi, points[triangles[t][k]]);
            }
            const openvdb::Coord a = cellOf(lo), b = cellOf(hi);
            for (int i = a.x(); i <= b.x(); ++i)
                for (int j = a.y(); j <= b.y(); ++j)
                    for (int k = a.z(); k <= b.z(); ++k) mCells[key(openvdb::Coord(i, j, k))].push_back(int(t));
        }
    }
    /// Distance from p to the nearest triangle; `cap` when none lies within about cap.
    double distance(const Vec3d& p, double cap) const
    {
        const openvdb::Coord c = cellOf(p);
        double best = std::numeric_limits<double>::max();
        const int maxRing = std::max(1, int(std::ceil(cap / mCell)) + 1);
        for (int r = 0; r <= maxRing; ++r) {
            // Cells on the Chebyshev ring r around c; anything outside it is at least r cells away.
            for (int i = -r; i <= r; ++i)
                for (int j = -r; j <= r; ++j)
                    for (int k = -r; k <= r; ++k) {
                        if (std::max({std::abs(i), std::abs(j), std::abs(k)}) != r) continue;
                        const auto it = mCells.find(key(c.offsetBy(i, j, k)));
                        if (it == mCells.end()) continue;
                        for (int t : it->second) {
                            const auto& tri = mTriangles[t];
                            const Vec3d q = closestOnTriangle(p, mPoints[tri[0]], mPoints[tri[1]], mPoints[tri[2]]);
                            best = std::min(best, (p - q).length());
                        }
                    }
            if (best <= r * mCell) return best;
        }
        return std::min(best, cap);
    }

private:
    const std::vector<Vec3d>& mPoints;
    const std::vector<openvdb::Vec3I>& mTriangles;
    double mCell;
    std::unordered_map<std::uint64_t, std::vector<int>> mCells;
    openvdb::Coord cellOf(const Vec3d& p) const
    {
        return openvdb::Coord(int(std::floor(p.x() / mCell)), int(std::floor(p.y() / mCell)), int(std::floor(p.z() / mCell)));
    }
    static std::uint64_t key(const openvdb::Coord& c)
    {
        const auto u = [](int v) { return std::uint64_t(std::uint32_t(v) & 0x1FFFFFu); };
        return u(c.x()) | (u(c.y()) << 21) | (u(c.z()) << 42);
    }
};

/// Lattice points of one voxel (spacing voxel/3) in the band, projected onto the reference's zero set.
constexpr int kLattice = 3;

} // namespace

openvdb::FloatGrid::Ptr meshToSurfaceLevelSet(const Mesh& mesh, const openvdb::math::Transform& transform,
                                              float halfWidth)
{
    initialize();
    std::vector<Vec3d> world;
    std::vector<openvdb::Vec3I> triangles;
    meshArrays(mesh, world, triangles);
    const std::vector<openvdb::Vec3s> points = toIndexSpace(world, transform);
    // Points are in index space (what the adapter expects); distances come out in world units.
    openvdb::tools::QuadAndTriangleDataAdapter<openvdb::Vec3s, openvdb::Vec3I> adapter(points, triangles);
    auto grid = openvdb::tools::meshToVolume<openvdb::FloatGrid>(adapter, transform, halfWidth, halfWidth);
    grid->setTransform(transform.copy());
    grid->setName("surface");
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    return grid;
}

ReferenceDistance gridDistance(openvdb::FloatGrid::ConstPtr sdf)
{
    // GridSampler keeps pointers to its accessor and transform: both live beside it.
    struct Evaluator {
        openvdb::FloatGrid::ConstPtr grid;
        openvdb::FloatGrid::ConstAccessor accessor;
        openvdb::tools::GridSampler<openvdb::FloatGrid::ConstAccessor, openvdb::tools::BoxSampler> sampler;
        explicit Evaluator(openvdb::FloatGrid::ConstPtr g)
            : grid(std::move(g)), accessor(grid->getConstAccessor()), sampler(accessor, grid->transform())
        {}
    };
    return [sdf]() -> std::function<double(const Vec3d&)> {
        auto e = std::make_shared<Evaluator>(sdf);
        return [e](const Vec3d& p) { return double(e->sampler.wsSample(p)); };
    };
}

ReferenceDistance phantomReferenceDistance(const openvdb::GridBase& grid)
{
    const auto shapeMeta = grid.getMetadata<openvdb::StringMetadata>("riemesh:phantom");
    const auto sizeMeta = grid.getMetadata<openvdb::Int32Metadata>("riemesh:size");
    if (!shapeMeta || !sizeMeta) return {};
    const PhantomShape shape = phantomShapeFromName(shapeMeta->value());
    const int size = sizeMeta->value();
    const openvdb::math::Transform::ConstPtr xform = grid.transform().copy();
    return [shape, size, xform]() -> std::function<double(const Vec3d&)> {
        return [shape, size, xform](const Vec3d& p) {
            // Phantom distances are in index units, world = index * voxel size.
            return phantomDistance(shape, size, xform->worldToIndex(p)) * xform->voxelSize()[0];
        };
    };
}

SurfaceError surfaceError(const Mesh& mesh, const openvdb::FloatGrid& sdf, const ReferenceDistance& exact)
{
    std::vector<Vec3d> points;
    std::vector<openvdb::Vec3I> triangles;
    meshArrays(mesh, points, triangles);
    return surfaceError(points, triangles, sdf, exact);
}

SurfaceError surfaceError(const std::vector<Vec3d>& worldPoints, const std::vector<openvdb::Vec3I>& triangles,
                          const openvdb::FloatGrid& sdf, const ReferenceDistance& exact)
{
    initialize();
    SurfaceError err;
    const double h = sdf.transform().voxelSize()[0];
    const ReferenceDistance distance = exact ? exact : gridDistance(openvdb::FloatGrid::ConstPtr(sdf.copy()));
    // Exact distances have exact gradients at any step; a trilinear one is differentiated across a voxel.
    const double step = exact ? 1e-4 * h : 0.5 * h;
    // One step along an exact distance's gradient lands on the nearest surface point; a trilinear
    // distance needs a few.
    const int newtonSteps = exact ? 1 : 3;
    const double cap = 16 * h; // farther than this reads as this: a missed part

    // Mesh -> surface: about 4 samples per square voxel on every triangle, area-weighted.
    {
        std::vector<double> sum(triangles.size(), 0.0), worst(triangles.size(), 0.0);
        std::vector<Vec3d> worstAt(triangles.size(), Vec3d(0.0));
        std::vector<std::size_t> count(triangles.size(), 0);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, triangles.size(), 256), [&](const auto& range) {
            const auto d = distance();
            for (std::size_t t = range.begin(); t != range.end(); ++t) {
                const Vec3d a = worldPoints[triangles[t][0]], b = worldPoints[triangles[t][1]], c = worldPoints[triangles[t][2]];
                const double longest = std::max({(b - a).length(), (c - b).length(), (a - c).length()});
                const int n = std::clamp(int(std::ceil(longest / (0.5 * h))), 1, 256);
                double s = 0, m = 0;
                Vec3d at = a;
                std::size_t k = 0;
                for (int i = 0; i <= n; ++i)
                    for (int j = 0; i + j <= n; ++j) {
                        const Vec3d p = a + (b - a) * (double(i) / n) + (c - a) * (double(j) / n);
                        const double e = std::min(std::abs(d(p)), cap);
                        s += e;
                        if (e > m) m = e, at = p;
                        ++k;
                    }
                worstAt[t] = at;
                const double area = 0.5 * (b - a).cross(c - a).length();
                sum[t] = area * s / double(k);
                worst[t] = m;
                count[t] = k;
            }
        });
        double area = 0, total = 0;
        for (std::size_t t = 0; t < triangles.size(); ++t) {
            const Vec3d a = worldPoints[triangles[t][0]], b = worldPoints[triangles[t][1]], c = worldPoints[triangles[t][2]];
            area += 0.5 * (b - a).cross(c - a).length();
            total += sum[t];
            if (worst[t] > err.maxMeshToSurface || t == 0) {
                err.maxMeshToSurface = worst[t];
                err.hausdorffAt = worstAt[t];
                err.hausdorffOnMesh = true;
            }
            err.meshSamples += count[t];
        }
        err.meanMeshToSurface = area > 0 ? total / area : 0.0;
    }

    // Surface samples: the band's voxels, a voxel/3 lattice in each, projected onto d = 0.
    std::vector<Vec3d> samples;
    {
        std::vector<openvdb::Coord> band;
        for (auto it = sdf.tree().cbeginValueOn(); it; ++it)
            if (it.isVoxelValue() && std::abs(*it) < h) band.push_back(it.getCoord());
        constexpr int perVoxel = kLattice * kLattice * kLattice;
        std::vector<Vec3d> projected(band.size() * perVoxel);
        std::vector<char> valid(projected.size(), 0);
        const auto& xform = sdf.transform();
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, band.size(), 64), [&](const auto& range) {
            const auto d = distance();
            const auto gradient = [&](const Vec3d& p) {
                Vec3d g;
                for (int a = 0; a < 3; ++a) {
                    Vec3d e(0);
                    e[a] = step;
                    g[a] = (d(p + e) - d(p - e)) / (2 * step);
                }
                return g;
            };
            for (std::size_t v = range.begin(); v != range.end(); ++v) {
                const Vec3d centre = xform.indexToWorld(band[v]);
                int slot = 0;
                for (int i = 0; i < kLattice; ++i)
                    for (int j = 0; j < kLattice; ++j)
                        for (int k = 0; k < kLattice; ++k, ++slot) {
                            const auto offset = [](int x) { return (double(x) - 0.5 * (kLattice - 1)) / kLattice; };
                            Vec3d q = centre + Vec3d(offset(i), offset(j), offset(k)) * h;
                            if (std::abs(d(q)) >= 0.75 * h) continue;
                            for (int it = 0; it < newtonSteps; ++it) {
                                Vec3d g = gradient(q);
                                if (!(g.length() > 1e-6)) break;
                                g.normalize();
                                q -= g * d(q);
                            }
                            if (std::abs(d(q)) < 0.02 * h) {
                                projected[v * perVoxel + slot] = q;
                                valid[v * perVoxel + slot] = 1;
                            }
                        }
            }
        });
        // One sample per cell of half a voxel: about 4 per square voxel, edges and corners kept.
        std::unordered_set<std::uint64_t> seen;
        const double cell = 0.5 * h;
        for (std::size_t i = 0; i < projected.size(); ++i) {
            if (!valid[i]) continue;
            const Vec3d& q = projected[i];
            const auto u = [&](double x) { return std::uint64_t(std::uint32_t(int(std::floor(x / cell))) & 0x1FFFFFu); };
            if (seen.insert(u(q.x()) | (u(q.y()) << 21) | (u(q.z()) << 42)).second) samples.push_back(q);
        }
    }

    // Surface -> mesh: exact distance to the nearest triangle.
    {
        double meanEdge = 0;
        for (const auto& t : triangles) meanEdge += (worldPoints[t[1]] - worldPoints[t[0]]).length();
        meanEdge = triangles.empty() ? h : meanEdge / double(triangles.size());
        const TriangleGrid grid(worldPoints, triangles, std::max(2 * h, 1.5 * meanEdge));
        std::vector<double> dist(samples.size(), cap);
        if (!triangles.empty())
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, samples.size(), 256), [&](const auto& range) {
                for (std::size_t i = range.begin(); i != range.end(); ++i) dist[i] = grid.distance(samples[i], cap);
            });
        double total = 0;
        std::size_t farthest = 0;
        for (std::size_t i = 0; i < dist.size(); ++i) {
            total += dist[i];
            if (dist[i] > dist[farthest]) farthest = i;
        }
        if (!dist.empty()) err.maxSurfaceToMesh = dist[farthest];
        if (!dist.empty() && (err.maxSurfaceToMesh > err.maxMeshToSurface || triangles.empty())) {
            err.hausdorffAt = samples[farthest];
            err.hausdorffOnMesh = false;
        }
        err.surfaceSamples = samples.size();
        err.meanSurfaceToMesh = samples.empty() ? 0.0 : total / double(samples.size());
    }
    err.hausdorff = std::max(err.maxMeshToSurface, err.maxSurfaceToMesh);
    return err;
}

} // namespace riemesh::vdb
