// collision.cpp: self-collision detection (paper 3.2, Fig. 2).
//
// One pass over the faces for vertex normals, one spatial-hash pass for Euclidean candidates
// (d_E <= d_R since G >= I), then cheap per-pair filters; the bounded mesh search that tells
// "close along the mesh" from "close across a gap" only runs for the few pairs that survive.
#include "riemesh/collision.h"

#include "detail/mesh_walk.h"
#include "detail/spatial_hash.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace riemesh {

namespace {

/// Same-sheet test without a search: normals agree (angle < 60 degrees) and each vertex lies
/// within 30 degrees of the other's tangent plane. On a sheet curved enough to turn the normal by
/// 60 degrees between u and w, the chord leaves the tangent plane by half that angle, so real
/// same-sheet pairs pass; two facing sheets (opposite normals) or stacked sheets (w in front of
/// u) do not.
constexpr double kNormalAgreement = 0.5;      // cos 60 degrees
constexpr double kSquaredTangentSlope = 0.25; // (sin 30 degrees)^2
/// Two sides of a convex crease (a box edge being rounded off) lie behind each other's tangent
/// planes; on a coarse mesh (edges up to zeta delta) their mesh path can exceed kappa * radius.
/// They cannot be colliding sheets unless the normals are nearly opposite (a thin plate, which
/// the paper does report under a coarse Euclidean metric).
constexpr double kCreaseAgreement = -0.5; // cos 120 degrees

} // namespace

double collisionLambda(bool euclidean, double zeta, double delta, double vmax)
{
    if (!(zeta > 1) || !(delta > 0) || !(vmax >= 0))
        throw std::invalid_argument("collisionLambda: need zeta > 1, delta > 0, vmax >= 0");
    const double motion = vmax / (2.0 * zeta * delta);
    if (euclidean) return std::sqrt(1.0 - 1.0 / zeta + 1.0 / (zeta * zeta)) + motion;
    return 1.0 + motion;
}

double collisionRadius(const MetricField& metric, const CollisionOptions& options)
{
    return collisionLambda(metric.isEuclidean(), options.zeta, options.delta, options.vmax) * options.zeta *
           options.delta;
}

std::vector<CollisionPair> findCollisions(const Mesh& mesh, const MetricField& metric, const CollisionOptions& options)
{
    std::vector<CollisionPair> result;
    if (!mesh.has_vertex_status() || !mesh.has_face_status())
        throw std::invalid_argument("findCollisions: call prepareMesh() first (status attributes)");
    const double radius = collisionRadius(metric, options);
    const std::size_t n = mesh.n_vertices();

    // Area-weighted vertex normals in one pass over the faces.
    std::vector<Vec3> normal(n, Vec3::Zero());
    for (auto f : mesh.faces()) {
        const HalfedgeHandle h0 = mesh.halfedge_handle(f);
        const HalfedgeHandle h1 = mesh.next_halfedge_handle(h0);
        const VertexHandle a = mesh.from_vertex_handle(h0), b = mesh.to_vertex_handle(h0),
                           c = mesh.to_vertex_handle(h1);
        const Vec3 pa = position(mesh, a);
        const Vec3 fn = (position(mesh, b) - pa).cross(position(mesh, c) - pa);
        normal[a.idx()] += fn;
        normal[b.idx()] += fn;
        normal[c.idx()] += fn;
    }

    std::vector<Vec3> points;
    std::vector<int> ids;
    points.reserve(n);
    ids.reserve(n);
    for (auto v : mesh.vertices()) {
        points.push_back(position(mesh, v));
        ids.push_back(v.idx());
    }
    if (points.empty()) return result;

    OpenMesh::VPropHandleT<int> cutId;
    const bool hasCutIds = mesh.get_property_handle(cutId, kCutIdProperty);

    detail::SpatialHash hash;
    hash.build(points, ids, radius);

    // Candidates that no cheap test rules out; ordered (u < w by index).
    struct Candidate {
        int u, w;
        double distance; // metric length (world units)
    };
    std::vector<Candidate> candidates;

    // Structure-of-arrays copies in slot order, so that the pair loop below is branch-free except
    // for the (rare) pairs that survive the cheap tests.
    const std::size_t count = hash.size();
    std::vector<double> px(count), py(count), pz(count), nx(count), ny(count), nz(count);
    for (std::uint32_t s = 0; s < count; ++s) {
        const Vec3& p = hash.point(s);
        const Vec3& nv = normal[hash.id(s)];
        const double len = nv.norm();
        const double inv = len > 0 ? 1.0 / len : 0.0; // unit normal (zero for isolated vertices)
        px[s] = p.x(); py[s] = p.y(); pz[s] = p.z();
        nx[s] = nv.x() * inv; ny[s] = nv.y() * inv; nz[s] = nv.z() * inv;
    }
    const double r2 = radius * radius;
    auto consider = [&](std::uint32_t sa, std::uint32_t sb, double d2) {
        const int a = hash.id(sa), b = hash.id(sb);
        const VertexHandle va(a), vb(b);
        if (hasCutIds) {
            const int ca = mesh.property(cutId, va);
            if (ca != 0 && ca == mesh.property(cutId, vb)) return;
        }
        double dR = std::sqrt(d2);
        if (!metric.isEuclidean()) {
            dR = metricLength(metric, hash.point(sa), hash.point(sb));
            if (dR > radius) return;
        }
        candidates.push_back({std::min(a, b), std::max(a, b), dR});
    };
    const double* const qx = px.data(); // raw pointers: no reload after a candidate push_back
    const double* const qy = py.data();
    const double* const qz = pz.data();
    const double* const mx = nx.data();
    const double* const my = ny.data();
    const double* const mz = nz.data();
    hash.forEachCellPair([&](std::uint32_t a0, std::uint32_t a1, std::uint32_t b0, std::uint32_t b1) {
        for (std::uint32_t s = a0; s < a1; ++s) {
            const double x = qx[s], y = qy[s], z = qz[s], ux = mx[s], uy = my[s], uz = mz[s];
            for (std::uint32_t t = (a0 == b0 ? s + 1 : b0); t < b1; ++t) {
                const double dx = qx[t] - x, dy = qy[t] - y, dz = qz[t] - z;
                const double d2 = dx * dx + dy * dy + dz * dz;
                const double agree = ux * mx[t] + uy * my[t] + uz * mz[t];
                const double hu = dx * ux + dy * uy + dz * uz;
                const double hw = dx * mx[t] + dy * my[t] + dz * mz[t];
                const double limit = kSquaredTangentSlope * d2;
                const bool flat = (agree > kNormalAgreement) & (hu * hu <= limit) & (hw * hw <= limit);
                // Convex crease: each vertex behind the other's tangent plane and the normals
                // less than 120 degrees apart (a thin plate has opposite normals and stays in).
                const bool crease = (agree > kCreaseAgreement) & (hu < 0) & (hw > 0);
                const bool sameSheet = flat | crease;
                if ((d2 <= r2) & !sameSheet) consider(s, t, d2);
            }
        }
    });
    if (candidates.empty()) return result;

    // Exclude pairs close along the mesh: one bounded search per distinct source vertex.
    std::sort(candidates.begin(), candidates.end(),
              [](const Candidate& x, const Candidate& y) { return x.u != y.u ? x.u < y.u : x.w < y.w; });
    const double pathBound = options.neighbourhoodFactor * radius;
    detail::BoundedPathSearch search;
    int source = -1;
    for (const Candidate& c : candidates) {
        if (c.u != source) {
            source = c.u;
            search.run(mesh, VertexHandle(source), pathBound);
        }
        if (search.reached(VertexHandle(c.w))) continue;
        result.push_back({VertexHandle(c.u), VertexHandle(c.w), c.distance});
    }
    std::sort(result.begin(), result.end(), [](const CollisionPair& x, const CollisionPair& y) {
        if (x.distance != y.distance) return x.distance < y.distance;
        return x.u.idx() != y.u.idx() ? x.u.idx() < y.u.idx() : x.w.idx() < y.w.idx();
    });
    return result;
}

} // namespace riemesh
