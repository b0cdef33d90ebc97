#include "riemesh/forces.h"

#include <algorithm>
#include <cmath>

namespace riemesh {

namespace {

double clampUnit(double s) { return std::max(-1.0, std::min(1.0, s)); }

} // namespace

void computeForces(const Mesh& mesh, const ScalarImage& image, const ForceOptions& options, double delta,
                   std::vector<Vec3>& forces, const MetricField* metric)
{
    const std::size_t n = mesh.n_vertices();
    forces.assign(n, Vec3::Zero());

    // Area-weighted vertex normals and umbrella vectors in one pass over faces / halfedges.
    static thread_local std::vector<Vec3> normal, neighbourSum;
    static thread_local std::vector<double> weightSum;
    static thread_local std::vector<Mat3> tensor;
    normal.assign(n, Vec3::Zero());
    neighbourSum.assign(n, Vec3::Zero());
    weightSum.assign(n, 0.0);
    const bool riemannian = metric && !metric->isEuclidean();
    if (riemannian) {
        tensor.resize(n);
        const VertexMetrics g(mesh, *metric); // the cache Evolution keeps, when there is one
        for (auto v : mesh.vertices()) tensor[v.idx()] = g.at(v);
    }
    for (auto f : mesh.faces()) {
        auto h0 = mesh.halfedge_handle(f);
        auto h1 = mesh.next_halfedge_handle(h0);
        const VertexHandle a = mesh.from_vertex_handle(h0), b = mesh.to_vertex_handle(h0),
                           c = mesh.to_vertex_handle(h1);
        const Vec3 pa = position(mesh, a), pb = position(mesh, b), pc = position(mesh, c);
        const Vec3 fn = (pb - pa).cross(pc - pa);
        normal[a.idx()] += fn;
        normal[b.idx()] += fn;
        normal[c.idx()] += fn;
    }
    for (auto e : mesh.edges()) {
        // each edge contributes each end to the other's umbrella, weighted by its metric stretch
        const auto h = mesh.halfedge_handle(e, 0);
        const VertexHandle va = mesh.from_vertex_handle(h), vb = mesh.to_vertex_handle(h);
        const int a = va.idx(), b = vb.idx();
        const Vec3 pa = position(mesh, va), pb = position(mesh, vb);
        double w = 1.0;
        if (riemannian) {
            const Vec3 d = pb - pa;
            const double euclid = d.norm();
            if (euclid > 0) w = metricLength(tensor[a], tensor[b], d) / euclid;
        }
        neighbourSum[a] += w * pb;
        neighbourSum[b] += w * pa;
        weightSum[a] += w;
        weightSum[b] += w;
    }

    const double sign = options.objectBrighter ? 1.0 : -1.0;
    const double gradientStep = 0.5 * image.voxelSize();
    for (auto v : mesh.vertices()) {
        const int i = v.idx();
        const Vec3 x = position(mesh, v);
        double len = normal[i].norm();
        if (!(len > 0) || !(weightSum[i] > 0)) continue;
        const Vec3 nrm = normal[i] / len;

        // External: inflation/deflation toward I = iso along the normal. The signed distance to the
        // isosurface is estimated as (I - iso)/|grad I| (a Newton step) unless a fixed contrast is given;
        // the pull is stiff near the surface and saturates at externalLimit * delta.
        double value;
        double distance; // estimated signed distance to the isosurface (world units), > 0 inside
        if (options.contrast > 0) {
            value = image.value(x);
            distance = delta * (value - options.iso) / options.contrast;
        } else {
            Vec3 gradient;
            image.sample(x, value, gradient);
            distance = (value - options.iso) / std::max(gradient.norm(), 1e-12 / delta);
        }
        const double limit = options.externalLimit * delta;
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
        forces[i] = f;
    }
}

} // namespace riemesh
