#include "riemesh/forces.h"

#include "detail/parallel.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

namespace riemesh {

namespace {

double clampUnit(double s) { return std::max(-1.0, std::min(1.0, s)); }

/// Elements per parallel chunk.
constexpr std::size_t kGrain = 128;

} // namespace

void computeForces(const Mesh& mesh, const ScalarImage& image, const ForceOptions& options, double delta,
                   std::vector<Vec3>& forces, const MetricField* metric)
{
    const std::size_t n = mesh.n_vertices();
    forces.assign(n, Vec3::Zero());

    // Area-weighted vertex normals and umbrella vectors. Per face and per edge in parallel, then
    // gathered per vertex around it (sorting each vertex's faces and edges by index, to sum as one
    // pass over the faces would, doubled the cost of an iteration at one thread).
    static thread_local std::vector<Vec3> normalBuffer, neighbourSumBuffer, faceNormalBuffer;
    static thread_local std::vector<double> weightSumBuffer, edgeWeightBuffer, faceDistanceBuffer;
    static thread_local std::vector<Mat3> tensorBuffer;
    // Plain pointers from here on: a thread_local named inside a parallel body would be the
    // worker's own buffer, not this one.
    normalBuffer.assign(n, Vec3::Zero());
    neighbourSumBuffer.assign(n, Vec3::Zero());
    weightSumBuffer.assign(n, 0.0);
    Vec3* const normal = normalBuffer.data();
    Vec3* const neighbourSum = neighbourSumBuffer.data();
    double* const weightSum = weightSumBuffer.data();
    const bool riemannian = metric && !metric->isEuclidean();
    const bool vertexStatus = mesh.has_vertex_status(), faceStatus = mesh.has_face_status(),
               edgeStatus = mesh.has_edge_status();
    auto deleted = [&](VertexHandle v) { return vertexStatus && mesh.status(v).deleted(); };
    if (riemannian) {
        tensorBuffer.resize(n);
        Mat3* const tensor = tensorBuffer.data();
        const VertexMetrics g(mesh, *metric); // the cache Evolution keeps, when there is one
        detail::parallelFor(0, n, kGrain, [&](std::size_t i) {
            const VertexHandle v{int(i)};
            if (!deleted(v)) tensor[i] = g.at(v);
        });
    }
    const Mat3* const tensor = tensorBuffer.data();
    // Signed distance to the isosurface estimated at a point (world units, > 0 inside).
    auto distanceAt = [&](const Vec3& x) {
        if (options.contrast > 0) return delta * (image.value(x) - options.iso) / options.contrast;
        return isoDistance(image, x, options.iso, 1e-12 / delta);
    };
    const std::size_t faceCount = mesh.n_faces(), edgeCount = mesh.n_edges();
    faceNormalBuffer.resize(faceCount);
    Vec3* const faceNormal = faceNormalBuffer.data();
    // With face samples, each face's centroid is sampled too (see ForceOptions::vertexShare).
    const bool faceSamples = options.vertexShare < 1.0;
    // Samples are blended as the pull sees them, saturated: the Newton estimate runs to any size
    // where the gradient is faint (a gyrus thinner than the blur, seen at iso 80), and one face's
    // estimate of thousands of voxels would set the sign of the whole blend, flipping it from one
    // iteration to the next as that face moved (the head MRI block at iso 80 jittered 0.8 voxel per
    // iteration and never converged).
    const double limit = options.externalLimit * delta; // the largest push
    const double saturation = options.externalWeight > 0 ? limit / options.externalWeight : std::numeric_limits<double>::infinity();
    auto saturated = [&](double d) { return std::max(-saturation, std::min(saturation, d)); };
    if (faceSamples) faceDistanceBuffer.resize(faceCount);
    double* const faceDistance = faceDistanceBuffer.data();
    detail::parallelFor(0, faceCount, kGrain, [&](std::size_t fi) {
        const FaceHandle f{int(fi)};
        if (faceStatus && mesh.status(f).deleted()) return;
        auto h0 = mesh.halfedge_handle(f);
        auto h1 = mesh.next_halfedge_handle(h0);
        const VertexHandle a = mesh.from_vertex_handle(h0), b = mesh.to_vertex_handle(h0),
                           c = mesh.to_vertex_handle(h1);
        const Vec3 pa = position(mesh, a), pb = position(mesh, b), pc = position(mesh, c);
        faceNormal[fi] = (pb - pa).cross(pc - pa);
        if (faceSamples) faceDistance[fi] = saturated(distanceAt((pa + pb + pc) / 3.0));
    });
    // Each edge contributes each end to the other's umbrella, weighted by its metric stretch.
    if (riemannian) edgeWeightBuffer.resize(edgeCount);
    double* const edgeWeight = edgeWeightBuffer.data();
    if (riemannian)
        detail::parallelFor(0, edgeCount, kGrain, [&](std::size_t ei) {
            const EdgeHandle e{int(ei)};
            if (edgeStatus && mesh.status(e).deleted()) return;
            const auto h = mesh.halfedge_handle(e, 0);
            const VertexHandle va = mesh.from_vertex_handle(h), vb = mesh.to_vertex_handle(h);
            const Vec3 d = position(mesh, vb) - position(mesh, va);
            const double euclid = d.norm();
            edgeWeight[ei] = euclid > 0 ? metricLength(tensor[va.idx()], tensor[vb.idx()], d) / euclid : 1.0;
        });
    detail::parallelFor(0, n, kGrain, [&](std::size_t i) {
        // One turn around each vertex: its faces, and its edges with the vertex across each, in the
        // circulator's order (the mesh's, not the threads': the same sums for any thread count).
        const VertexHandle v{int(i)};
        if (deleted(v)) return;
        for (auto h = mesh.cvoh_begin(v); h.is_valid(); ++h) {
            const FaceHandle f = mesh.face_handle(*h);
            if (f.is_valid()) normal[i] += faceNormal[f.idx()];
            const double w = riemannian ? edgeWeight[mesh.edge_handle(*h).idx()] : 1.0;
            neighbourSum[i] += w * position(mesh, mesh.to_vertex_handle(*h));
            weightSum[i] += w;
        }
    });

    const double sign = options.objectBrighter ? 1.0 : -1.0;
    const double gradientStep = 0.5 * image.voxelSize();
    Vec3* const force = forces.data();
    detail::parallelFor(0, n, kGrain, [&](std::size_t i) {
        const VertexHandle v{int(i)};
        if (deleted(v)) return;
        const Vec3 x = position(mesh, v);
        double len = normal[i].norm();
        if (!(len > 0) || !(weightSum[i] > 0)) return;
        const Vec3 nrm = normal[i] / len;

        // External: inflation/deflation toward I = iso along the normal. The signed distance to the
        // isosurface is estimated as (I - iso)/|grad I| (a Newton step) unless a fixed contrast is given;
        // the pull is stiff near the surface and saturates at externalLimit * delta.
        double distance = distanceAt(x); // estimated signed distance to the isosurface (world units), > 0 inside
        if (faceSamples) { // blended with its faces' (area-weighted, in the circulator's order)
            double sum = 0, area = 0;
            for (auto h = mesh.cvoh_begin(v); h.is_valid(); ++h) {
                const FaceHandle f = mesh.face_handle(*h);
                if (!f.is_valid()) continue;
                const double a = faceNormal[f.idx()].norm();
                sum += a * faceDistance[f.idx()];
                area += a;
            }
            if (area > 0) distance = options.vertexShare * saturated(distance) + (1 - options.vertexShare) * sum / area;
        }
        const double push = std::max(-limit, std::min(limit, options.externalWeight * sign * distance));
        // How free the flight is: 0 on the isosurface, 1 where the push saturates.
        const double freedom = limit > 0 ? std::abs(push) / limit : 0.0;

        // Internal: umbrella operator, split into tangential (sampling) and normal (curvature) parts.
        const Vec3 umbrella = neighbourSum[i] / weightSum[i] - x;
        const double un = umbrella.dot(nrm);
        // Free-flight smoothing only where the curvature points along the motion: the parts of a
        // moving front that would fold into a swallowtail (creases of a deflating box, concave parts of
        // an inflating bubble). Elsewhere (a convex bubble inflating) it would only fight the push.
        const bool folding = un * push > 0;
        const double curvature = folding
            ? options.curvatureWeight + freedom * (options.freeCurvatureWeight - options.curvatureWeight)
            : options.curvatureWeight;
        Vec3 f = options.internalWeight * (umbrella - un * nrm) + curvature * un * nrm + push * nrm;

        // Optional attraction toward high gradient magnitude, along the normal.
        if (options.gradientWeight != 0) {
            const double gp = image.gradient(x + gradientStep * nrm).norm();
            const double gm = image.gradient(x - gradientStep * nrm).norm();
            const double scale = std::max(gp, gm);
            if (scale > 0) f += options.gradientWeight * limit * clampUnit((gp - gm) / scale) * nrm;
        }
        force[i] = f;
    });
}

} // namespace riemesh
