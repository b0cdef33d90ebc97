#include "riemesh/sharpen.h"

#include "detail/parallel.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <limits>
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

/// Each face's neighbours: the faces around its three vertices (itself included), as offsets into
/// one array.
struct FaceRings {
    std::vector<std::size_t> first;
    std::vector<int> ring;
};

FaceRings faceRings(const Mesh& mesh)
{
    const std::size_t nf = mesh.n_faces();
    FaceRings r;
    r.first.assign(nf + 1, 0);
    r.ring.reserve(nf * 13);
    for (std::size_t fi = 0; fi < nf; ++fi) {
        const FaceHandle f{int(fi)};
        r.first[fi] = r.ring.size();
        if (mesh.status(f).deleted()) continue;
        const std::size_t begin = r.ring.size();
        for (auto v : mesh.fv_range(f))
            for (auto g : mesh.vf_range(v)) r.ring.push_back(g.idx());
        std::sort(r.ring.begin() + long(begin), r.ring.end());
        r.ring.erase(std::unique(r.ring.begin() + long(begin), r.ring.end()), r.ring.end());
    }
    r.first[nf] = r.ring.size();
    return r;
}

/// The face normals filtered bilaterally (spatial width meanEdge, range width sigmaNormal).
void filterNormals(const FaceGeometry& geo, const FaceRings& rings, double meanEdge, const SharpenOptions& o,
                   std::vector<Vec3>& filtered, std::vector<Vec3>& next)
{
    const std::size_t nf = geo.normal.size();
    const double s2 = 2.0 * meanEdge * meanEdge, r2 = 2.0 * o.sigmaNormal * o.sigmaNormal;
    filtered = geo.normal;
    next.resize(nf);
    for (int k = 0; k < o.normalIterations; ++k) {
        detail::parallelFor(0, nf, 256, [&](std::size_t f) {
            Vec3 m = Vec3::Zero();
            for (std::size_t j = rings.first[f]; j < rings.first[f + 1]; ++j) {
                const std::size_t g = std::size_t(rings.ring[j]);
                const double ds = (geo.centroid[f] - geo.centroid[g]).squaredNorm();
                const double dn = (filtered[f] - filtered[g]).squaredNorm();
                m += geo.area[g] * std::exp(-ds / s2 - dn / r2) * filtered[g];
            }
            const double len = m.norm();
            next[f] = len > 0 ? Vec3(m / len) : filtered[f];
        });
        std::swap(filtered, next);
    }
}

double cosOf(double degrees) { return degrees > 0 ? std::cos(degrees * 3.14159265358979323846 / 180.0) : 1.0; }

/// The image's say, edge by edge (SharpenOptions::imageFeatureAngle): its own normals `step` (world
/// units) into either face from the edge's middle, each side's the mean of three samples along the
/// edge (the noise a single gradient carries, tens of degrees at noise 0.5, otherwise passes for a
/// crease now and then). Returns whether any edge is a crease.
bool markImageCreases(const Mesh& mesh, const std::vector<Vec3>& x, const FaceGeometry& geo, const SharpenOptions& o,
                      double step, std::vector<char>& crease)
{
    const double imageCos = cosOf(o.imageFeatureAngle);
    crease.assign(mesh.n_edges(), 0);
    auto imageNormal = [&](const Vec3& q) {
        const Vec3 g = o.image->indexGradient(q);
        const double len = g.norm();
        return len > 0 ? Vec3(g / len) : Vec3::Zero();
    };
    detail::parallelFor(0, mesh.n_edges(), 1024, [&](std::size_t e) {
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
        auto sideNormal = [&](const Vec3& t) {
            Vec3 sum = Vec3::Zero();
            for (int k = -1; k <= 1; ++k) sum += imageNormal(m + 0.25 * double(k) * along + step * t.normalized());
            const double len = sum.norm();
            return len > 0 ? Vec3(sum / len) : Vec3::Zero();
        };
        crease[e] = sideNormal(ta).dot(sideNormal(tb)) <= imageCos;
    });
    return std::find(crease.begin(), crease.end(), 1) != crease.end();
}

double meanEdgeLength(const Mesh& mesh)
{
    double sum = 0;
    std::size_t count = 0;
    for (auto e : mesh.edges()) sum += mesh.calc_edge_length(e), ++count;
    return count ? sum / double(count) : 0.0;
}

/// A thin rim's vertex: its faces make two fans (contiguous around it) whose filtered normals are
/// more than rimAngle apart; `a` and `b` those fans' mean normals, `vl`/`vr` the vertices across
/// the two edges between the fans.
struct Rim {
    VertexHandle v, vl, vr;
    Vec3 a, b;
};

/// The fans of `v`'s faces by the nearer of the normals `a` and `b` (`normal(f)` each face's): the
/// vertices across the two edges where the fans meet, or none if they are not two contiguous fans
/// of at least two faces each.
template <class NormalOf>
bool rimFans(const Mesh& mesh, VertexHandle v, const Vec3& a, const Vec3& b, NormalOf normal, VertexHandle& vl,
             VertexHandle& vr, int& countA)
{
    const Vec3 axis = a - b;
    int boundaries = 0, faces = 0;
    countA = 0;
    for (auto h : mesh.voh_range(v)) {
        const FaceHandle left = mesh.face_handle(h), right = mesh.face_handle(mesh.opposite_halfedge_handle(h));
        if (!left.is_valid() || !right.is_valid()) return false;
        const bool la = normal(left).dot(axis) >= 0, ra = normal(right).dot(axis) >= 0;
        ++faces;
        countA += la;
        if (la == ra) continue;
        if (++boundaries > 2) return false;
        (boundaries == 1 ? vl : vr) = mesh.to_vertex_handle(h);
    }
    return boundaries == 2 && countA >= 2 && faces - countA >= 2;
}

/// Splits the vertices of thin rims in two (SharpenOptions::rimAngle); returns how many.
std::size_t splitRims(Mesh& mesh, const SharpenOptions& o)
{
    const double rimCos = cosOf(o.rimAngle);
    const std::size_t nv = mesh.n_vertices(), nf = mesh.n_faces();
    std::vector<Vec3> x(nv);
    for (auto v : mesh.vertices()) x[std::size_t(v.idx())] = position(mesh, v);
    FaceGeometry geo;
    measureFaces(mesh, x, geo);
    const double meanEdge = meanEdgeLength(mesh);
    std::vector<Vec3> filtered, scratch;
    filterNormals(geo, faceRings(mesh), meanEdge, o, filtered, scratch);
    std::vector<char> imageCrease;
    const bool imageGated = o.image && cosOf(o.imageFeatureAngle) < 1;
    if (imageGated && !markImageCreases(mesh, x, geo, o, o.imageStep * o.image->voxelSize(), imageCrease)) return 0;

    // The candidates, on the surface as it is.
    auto filteredNormal = [&](FaceHandle f) -> const Vec3& { return filtered[std::size_t(f.idx())]; };
    std::vector<Rim> rims;
    for (auto v : mesh.vertices()) {
        // The two most opposed faces around v seed the fans.
        double lowest = 2;
        Vec3 a = Vec3::Zero(), b = Vec3::Zero();
        for (auto f : mesh.vf_range(v))
            for (auto g : mesh.vf_range(v))
                if (const double d = filteredNormal(f).dot(filteredNormal(g)); d < lowest) lowest = d, a = filteredNormal(f), b = filteredNormal(g);
        if (!(lowest < rimCos)) continue;
        Rim r{v, VertexHandle(), VertexHandle(), a, b};
        int countA = 0;
        if (!rimFans(mesh, v, a, b, filteredNormal, r.vl, r.vr, countA)) continue;
        // Each fan's mean normal; the fans must each be nearly flat and face apart.
        Vec3 ma = Vec3::Zero(), mb = Vec3::Zero();
        for (auto f : mesh.vf_range(v)) (filteredNormal(f).dot(a - b) >= 0 ? ma : mb) += geo.area[std::size_t(f.idx())] * filteredNormal(f);
        if (!(ma.norm() > 0) || !(mb.norm() > 0)) continue;
        r.a = ma.normalized(), r.b = mb.normalized();
        if (!(r.a.dot(r.b) < rimCos)) continue;
        if (imageGated) { // the image shows a crease across both edges between the fans
            const HalfedgeHandle hl = mesh.find_halfedge(v, r.vl), hr = mesh.find_halfedge(v, r.vr);
            if (!imageCrease[std::size_t(mesh.edge_handle(hl).idx())] || !imageCrease[std::size_t(mesh.edge_handle(hr).idx())]) continue;
        }
        rims.push_back(r);
    }

    // Split them one by one, each with its fans found again (a neighbour split before it has given
    // it a face across the rim): the new vertex takes one fan, the old one keeps the other, and the
    // two move a little apart across the rim, each toward its own side, for the fit to finish.
    std::size_t splits = 0;
    auto currentNormal = [&](FaceHandle f) -> Vec3 {
        if (std::size_t(f.idx()) < nf) return filtered[std::size_t(f.idx())];
        return faceNormal(mesh, f);
    };
    for (const Rim& r : rims) {
        VertexHandle vl, vr;
        int countA = 0;
        if (!rimFans(mesh, r.v, r.a, r.b, currentNormal, vl, vr, countA)) continue;
        const Vec3 p = position(mesh, r.v);
        double shortest = std::numeric_limits<double>::infinity();
        for (auto w : mesh.vv_range(r.v)) shortest = std::min(shortest, (position(mesh, w) - p).norm());
        const Vec3 across = (r.a - r.b).normalized() * (0.2 * shortest);
        const VertexHandle v0 = mesh.add_vertex(toPoint(p));
        mesh.vertex_split(v0, r.v, vl, vr);
        // Which fan the new vertex took: the old faces around it.
        int a = 0, b = 0;
        for (auto f : mesh.vf_range(v0))
            if (std::size_t(f.idx()) < nf) (filtered[std::size_t(f.idx())].dot(r.a - r.b) >= 0 ? a : b) += 1;
        const double side = a >= b ? 1.0 : -1.0;
        mesh.point(v0) = toPoint(p + side * across);
        mesh.point(r.v) = toPoint(p - side * across);
        ++splits;
    }
    return splits;
}

} // namespace

SharpenStats sharpenFeatures(Mesh& mesh, const SharpenOptions& o)
{
    SharpenStats stats;
    if (mesh.n_vertices() == 0 || mesh.n_faces() == 0) return stats;
    if (o.rimAngle < 180) stats.rimSplits = splitRims(mesh, o);
    const std::size_t nv = mesh.n_vertices(), nf = mesh.n_faces();
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

    const FaceRings rings = faceRings(mesh);

    FaceGeometry geo;
    const double featureCos = cosOf(o.featureAngle);
    std::vector<Vec3> filtered, next, moved(nv), anchor;
    std::vector<char> keep(nv), feature(nv);
    const bool imageGated = o.image && cosOf(o.imageFeatureAngle) < 1;
    const double step = imageGated ? o.imageStep * o.image->voxelSize() : 0.0; // world units
    std::vector<char> imageCrease;
    for (int round = 0; round < o.rounds; ++round) {
        measureFaces(mesh, x, geo);
        // The image's say first, as it is cheap: where it shows no crease, nothing moves, and a
        // surface without one is left as it is without filtering its normals.
        if (imageGated && !markImageCreases(mesh, x, geo, o, step, imageCrease)) break;
        filterNormals(geo, rings, meanEdge, o, filtered, next);
        // Each face's plane: through where the image's isosurface crosses the line along its
        // filtered normal from its centroid (SharpenOptions::planeSearch), or the centroid.
        anchor = geo.centroid;
        if (o.image && o.planeSearch > 0) {
            const double h = 0.25 * o.image->voxelSize(), reach = o.planeSearch * o.image->voxelSize();
            const double sign = o.objectBrighter ? 1.0 : -1.0;
            detail::parallelFor(0, nf, 256, [&](std::size_t f) {
                const Vec3& n = filtered[f];
                const Vec3& c = geo.centroid[f];
                if (!(n.squaredNorm() > 0)) return;
                auto inside = [&](double t) { return sign * (o.image->value(c + t * n) - o.iso); };
                // The nearest crossing, outward or inward, at quarter-voxel steps, interpolated.
                for (double t = h; t <= reach + 1e-9 * h; t += h)
                    for (const double dir : {1.0, -1.0}) {
                        const double before = inside(dir * (t - h)), now = inside(dir * t);
                        if ((before > 0) == (now > 0)) continue;
                        anchor[f] = c + dir * (t - h + h * before / (before - now)) * n;
                        return;
                    }
            });
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
        // face's anchor), with a weak pull to where it is: along a crease only that pull holds
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
                rhs += n * n.dot(anchor[fi]);
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
