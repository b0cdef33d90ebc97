#include "riemesh/sharpen.h"

#include "detail/parallel.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <vector>

namespace riemesh {

namespace {

struct FaceGeometry {
    std::vector<Vec3> centroid, normal; // unit normals
    std::vector<double> area;
};

void measureFaces(const Mesh& mesh, const std::vector<Vec3>& x, FaceGeometry& g)
{
    const std::size_t nf = mesh.n_faces();
    g.centroid.assign(nf, Vec3::Zero());
    g.normal.assign(nf, Vec3::Zero());
    g.area.assign(nf, 0.0);
    for (auto f : mesh.faces()) {
        const auto [va, vb, vc] = faceVertices(mesh, f);
        const Vec3& a = x[std::size_t(va.idx())];
        const Vec3& b = x[std::size_t(vb.idx())];
        const Vec3& c = x[std::size_t(vc.idx())];
        const Vec3 n = (b - a).cross(c - a);
        const double len = n.norm();
        const std::size_t i = std::size_t(f.idx());
        g.centroid[i] = (a + b + c) / 3.0;
        g.area[i] = 0.5 * len;
        g.normal[i] = len > 0 ? Vec3(n / len) : Vec3::Zero();
    }
}

} // namespace

SharpenStats sharpenFeatures(Mesh& mesh, const SharpenOptions& o)
{
    SharpenStats stats;
    const std::size_t nv = mesh.n_vertices(), nf = mesh.n_faces();
    if (nv == 0 || nf == 0) return stats;
    std::vector<Vec3> x(nv);
    for (auto v : mesh.vertices()) x[std::size_t(v.idx())] = position(mesh, v);
    const std::vector<Vec3> start = x;

    // Mean edge length: the spatial width of the filter; per vertex: the move bound.
    double edgeSum = 0;
    std::size_t edgeCount = 0;
    std::vector<double> vertexEdge(nv, 0.0);
    std::vector<int> vertexEdges(nv, 0);
    for (auto e : mesh.edges()) {
        const auto h = mesh.halfedge_handle(e, 0);
        const std::size_t a = std::size_t(mesh.from_vertex_handle(h).idx()), b = std::size_t(mesh.to_vertex_handle(h).idx());
        const double len = (x[a] - x[b]).norm();
        edgeSum += len;
        ++edgeCount;
        vertexEdge[a] += len, vertexEdge[b] += len;
        ++vertexEdges[a], ++vertexEdges[b];
    }
    if (edgeCount == 0) return stats;
    const double meanEdge = edgeSum / double(edgeCount);
    for (std::size_t i = 0; i < nv; ++i)
        vertexEdge[i] = vertexEdges[i] > 0 ? vertexEdge[i] / vertexEdges[i] : meanEdge;

    // Each face's neighbours: the faces around its three vertices (itself included), as offsets
    // into one array.
    std::vector<std::size_t> first(nf + 1, 0);
    std::vector<int> ring;
    ring.reserve(nf * 13);
    for (std::size_t fi = 0; fi < nf; ++fi) {
        const FaceHandle f{int(fi)};
        first[fi] = ring.size();
        if (mesh.status(f).deleted()) continue;
        const std::size_t begin = ring.size();
        for (auto v : mesh.fv_range(f))
            for (auto g : mesh.vf_range(v)) ring.push_back(g.idx());
        std::sort(ring.begin() + long(begin), ring.end());
        ring.erase(std::unique(ring.begin() + long(begin), ring.end()), ring.end());
    }
    first[nf] = ring.size();

    FaceGeometry geo;
    const double s2 = 2.0 * meanEdge * meanEdge, r2 = 2.0 * o.sigmaNormal * o.sigmaNormal;
    auto cosOf = [](double degrees) { return degrees > 0 ? std::cos(degrees * 3.14159265358979323846 / 180.0) : 1.0; };
    const double featureCos = cosOf(o.featureAngle), imageCos = cosOf(o.imageFeatureAngle);
    std::vector<Vec3> filtered, next(nf), moved(nv);
    std::vector<char> keep(nv), feature(nv);
    const bool imageGated = o.image && imageCos < 1;
    const double step = imageGated ? o.imageStep * o.image->voxelSize() : 0.0; // world units
    std::vector<char> imageCrease(imageGated ? mesh.n_edges() : 0);
    auto imageNormal = [&](const Vec3& q) {
        const Vec3 g = o.image->indexGradient(q);
        const double len = g.norm();
        return len > 0 ? Vec3(g / len) : Vec3::Zero();
    };
    for (int round = 0; round < o.rounds; ++round) {
        measureFaces(mesh, x, geo);
        // The image's say, edge by edge: its own normals a little way into either face from the
        // edge's middle (first, as it is cheap: where the image shows no crease, nothing moves, and
        // a surface without one is left as it is without filtering its normals).
        if (imageGated) {
            detail::parallelFor(0, mesh.n_edges(), 1024, [&](std::size_t e) {
                imageCrease[e] = 0;
                const EdgeHandle edge{int(e)};
                if (mesh.status(edge).deleted()) return;
                const HalfedgeHandle h = mesh.halfedge_handle(edge, 0);
                const FaceHandle f = mesh.face_handle(h), g = mesh.face_handle(mesh.opposite_halfedge_handle(h));
                if (!f.is_valid() || !g.is_valid()) return;
                const Vec3& p0 = x[std::size_t(mesh.from_vertex_handle(h).idx())];
                const Vec3& p1 = x[std::size_t(mesh.to_vertex_handle(h).idx())];
                const Vec3 m = 0.5 * (p0 + p1), along = p1 - p0;
                const Vec3 ta = geo.centroid[std::size_t(f.idx())] - m, tb = geo.centroid[std::size_t(g.idx())] - m;
                if (!(ta.norm() > 0) || !(tb.norm() > 0)) return;
                // Each side's normal from three samples along the edge: the noise a single gradient
                // carries (tens of degrees at noise 0.5) otherwise passes for a crease now and then.
                auto sideNormal = [&](const Vec3& t) {
                    Vec3 sum = Vec3::Zero();
                    for (int k = -1; k <= 1; ++k) sum += imageNormal(m + 0.25 * double(k) * along + step * t.normalized());
                    const double len = sum.norm();
                    return len > 0 ? Vec3(sum / len) : Vec3::Zero();
                };
                imageCrease[e] = sideNormal(ta).dot(sideNormal(tb)) <= imageCos;
            });
            if (std::find(imageCrease.begin(), imageCrease.end(), 1) == imageCrease.end()) break;
        }
        filtered = geo.normal;
        for (int k = 0; k < o.normalIterations; ++k) {
            detail::parallelFor(0, nf, 256, [&](std::size_t f) {
                Vec3 m = Vec3::Zero();
                for (std::size_t j = first[f]; j < first[f + 1]; ++j) {
                    const std::size_t g = std::size_t(ring[j]);
                    const double ds = (geo.centroid[f] - geo.centroid[g]).squaredNorm();
                    const double dn = (filtered[f] - filtered[g]).squaredNorm();
                    m += geo.area[g] * std::exp(-ds / s2 - dn / r2) * filtered[g];
                }
                const double len = m.norm();
                next[f] = len > 0 ? Vec3(m / len) : filtered[f];
            });
            std::swap(filtered, next);
        }

        // The vertices on a crease or a corner: at an edge of theirs, the filtered normals of the
        // two faces differ by more than the feature angle, and so do the image's own normals on
        // either side (SharpenOptions::featureAngle, imageFeatureAngle).
        const bool gated = featureCos < 1 || imageGated;
        feature.assign(nv, gated ? 0 : 1);
        auto crease = [&](HalfedgeHandle h) {
            const FaceHandle f = mesh.face_handle(h), g = mesh.face_handle(mesh.opposite_halfedge_handle(h));
            if (!f.is_valid() || !g.is_valid()) return false;
            return filtered[std::size_t(f.idx())].dot(filtered[std::size_t(g.idx())]) <= featureCos &&
                   (!imageGated || imageCrease[std::size_t(mesh.edge_handle(h).idx())]);
        };
        if (gated)
            for (auto v : mesh.vertices())
                for (auto h : mesh.voh_range(v))
                    if (crease(h)) {
                        feature[std::size_t(v.idx())] = 1;
                        break;
                    }
        // Each of those to the point nearest the planes of its faces (filtered normal, through the
        // face's centroid), with a weak pull to where it is: along a crease only that pull holds
        // it. The planes stay put during a round (updates through moving centroids would shrink
        // curved parts as Laplacian smoothing does).
        for (auto v : mesh.vertices()) {
            const std::size_t i = std::size_t(v.idx());
            if (!feature[i]) { // left where the evolution put it
                moved[i] = x[i];
                continue;
            }
            Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
            Vec3 rhs = Vec3::Zero();
            int count = 0;
            for (auto f : mesh.vf_range(v)) {
                const std::size_t fi = std::size_t(f.idx());
                const Vec3& n = filtered[fi];
                A += n * n.transpose();
                rhs += n * n.dot(geo.centroid[fi]);
                ++count;
            }
            const double lambda = o.pull * count;
            A += lambda * Eigen::Matrix3d::Identity();
            rhs += lambda * x[i];
            Vec3 y = count > 0 ? Vec3(A.ldlt().solve(rhs)) : x[i];
            if (!std::isfinite(y.x()) || !std::isfinite(y.y()) || !std::isfinite(y.z())) y = x[i];
            const Vec3 off = y - start[i];
            const double limit = std::min(o.maxMove, o.maxMoveEdges * vertexEdge[i]);
            if (off.norm() > limit) y = start[i] + off * (limit / off.norm());
            if (o.image) { // back toward where the round started, while the image says far outside
                auto outside = [&](const Vec3& p) {
                    return (o.objectBrighter ? 1.0 : -1.0) * isoDistance(*o.image, p, o.iso, 1e-12) < -o.maxOutside;
                };
                for (int k = 0; k < 4 && outside(y); ++k) y = x[i] + 0.5 * (y - x[i]);
                if (outside(y)) y = x[i];
            }
            moved[i] = y;
        }

        // A face that would flip against its filtered normal, or collapse, keeps its vertices where
        // they were this round (checked again with them kept, until no face is bad).
        std::fill(keep.begin(), keep.end(), 0);
        for (bool changed = true; changed;) {
            changed = false;
            auto at = [&](std::size_t i) -> const Vec3& { return keep[i] ? x[i] : moved[i]; };
            for (auto f : mesh.faces()) {
                const auto [va, vb, vc] = faceVertices(mesh, f);
                const std::size_t a = std::size_t(va.idx()), b = std::size_t(vb.idx()), c = std::size_t(vc.idx());
                if (keep[a] && keep[b] && keep[c]) continue;
                const Vec3 pa = at(a), pb = at(b), pc = at(c);
                const Vec3 n = (pb - pa).cross(pc - pa);
                const double len = n.norm();
                const double longest = std::max({(pb - pa).norm(), (pc - pb).norm(), (pa - pc).norm()});
                const bool bad = !(len > 0.02 * longest * longest) || n.dot(filtered[std::size_t(f.idx())]) < 0.2 * len;
                if (bad) {
                    keep[a] = keep[b] = keep[c] = 1;
                    changed = true;
                }
            }
        }
        for (std::size_t i = 0; i < nv; ++i) {
            if (keep[i]) {
                ++stats.refused;
                continue;
            }
            x[i] = moved[i];
        }
    }
    for (auto v : mesh.vertices()) {
        const std::size_t i = std::size_t(v.idx());
        const double move = (x[i] - start[i]).norm();
        if (move > 1e-6 * meanEdge) ++stats.moved;
        stats.largestMove = std::max(stats.largestMove, move);
        mesh.point(v) = toPoint(x[i]);
    }
    return stats;
}

} // namespace riemesh
