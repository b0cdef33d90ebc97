#include "riemesh/sharpen.h"

#include "riemesh/self_intersection.h"

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

/// The unit gradient of the image in its voxel coordinates (zero where it vanishes).
Vec3 unitIndexGradient(const ScalarImage& image, const Vec3& q)
{
    const Vec3 g = image.indexGradient(q);
    const double len = g.norm();
    return len > 0 ? Vec3(g / len) : Vec3::Zero();
}

/// The image's say, edge by edge (SharpenOptions::imageFeatureAngle): its own normals `step` (world
/// units) into either face from the edge's middle, each side's the mean of three samples along the
/// edge (the noise a single gradient carries, tens of degrees at noise 0.5, otherwise passes for a
/// crease now and then). Returns whether any edge is a crease.
bool markImageCreases(const Mesh& mesh, const std::vector<Vec3>& x, const FaceGeometry& geo, const SharpenOptions& o,
                      double step, std::vector<char>& crease)
{
    const double imageCos = cosOf(o.imageFeatureAngle);
    crease.assign(mesh.n_edges(), 0);
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
            for (int k = -1; k <= 1; ++k) sum += unitIndexGradient(*o.image, m + 0.25 * double(k) * along + step * t.normalized());
            const double len = sum.norm();
            return len > 0 ? Vec3(sum / len) : Vec3::Zero();
        };
        crease[e] = sideNormal(ta).dot(sideNormal(tb)) <= imageCos;
    });
    return std::find(crease.begin(), crease.end(), 1) != crease.end();
}

/// Each face's plane point: where the line along its filtered normal from its centroid first
/// crosses the image's isosurface within planeSearch voxels (SharpenOptions::planeSearch), else
/// the centroid.
void faceAnchors(const FaceGeometry& geo, const std::vector<Vec3>& filtered, const SharpenOptions& o, std::vector<Vec3>& anchor)
{
    anchor = geo.centroid;
    if (!o.image || !(o.planeSearch > 0)) return;
    const double h = 0.25 * o.image->voxelSize(), reach = o.planeSearch * o.image->voxelSize();
    const double sign = o.objectBrighter ? 1.0 : -1.0;
    detail::parallelFor(0, anchor.size(), 256, [&](std::size_t f) {
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
             VertexHandle& vr)
{
    const Vec3 axis = a - b;
    int boundaries = 0, faces = 0, countA = 0;
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
    std::vector<char> imageCrease; // first: where the image shows no crease, there is nothing to do
    const bool imageGated = o.image && cosOf(o.imageFeatureAngle) < 1;
    if (imageGated && !markImageCreases(mesh, x, geo, o, o.imageStep * o.image->voxelSize(), imageCrease)) return 0;
    const double meanEdge = meanEdgeLength(mesh);
    std::vector<Vec3> filtered, scratch;
    filterNormals(geo, faceRings(mesh), meanEdge, o, filtered, scratch);

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
        if (!rimFans(mesh, v, a, b, filteredNormal, r.vl, r.vr)) continue;
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
        if (!rimFans(mesh, r.v, r.a, r.b, currentNormal, vl, vr)) continue;
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

/// From `from` (inside the object), along +-dir up to `reach`, at steps of `h`: the nearer point
/// where the image says outside (interpolated) and the direction taken there; false if neither
/// way reaches one, or `from` is not inside.
bool creaseEnd(const ScalarImage& image, double iso, bool objectBrighter, const Vec3& from, const Vec3& dir, double reach,
               double h, Vec3& end, Vec3& across)
{
    const double sign = objectBrighter ? 1.0 : -1.0;
    auto inside = [&](const Vec3& q) { return sign * (image.value(q) - iso); };
    if (!(inside(from) > 0)) return false;
    double best = std::numeric_limits<double>::infinity();
    for (const double way : {1.0, -1.0}) {
        double before = inside(from);
        for (double t = h; t <= reach + 1e-9 * h && t < best; t += h) {
            const double now = inside(from + way * t * dir);
            if (now > 0) {
                before = now;
                continue;
            }
            best = t - h + h * before / (before - now);
            end = from + way * best * dir;
            across = way * dir;
            break;
        }
    }
    return std::isfinite(best);
}

/// Chamfers cut across a crease (SharpenOptions::insertCreases): a face whose neighbours' filtered
/// normals make two planes more than twice featureAngle apart, which lies on neither (its own
/// normal more than chamferAngle from both) and whose crease, the planes' intersection, passes over
/// it at least chamferDepth voxels away, gets a vertex on the crease (a 1-to-3 split). With an
/// image, its normals a little way into either plane from that point must be imageFeatureAngle
/// apart. Returns the vertices added.
std::vector<VertexHandle> insertCreaseVertices(Mesh& mesh, const SharpenOptions& o)
{
    std::vector<VertexHandle> added;
    const std::size_t nv = mesh.n_vertices(), nf = mesh.n_faces();
    std::vector<Vec3> x(nv);
    for (auto v : mesh.vertices()) x[std::size_t(v.idx())] = position(mesh, v);
    FaceGeometry geo;
    measureFaces(mesh, x, geo);
    const double meanEdge = meanEdgeLength(mesh);
    const bool imageGated = o.image && cosOf(o.imageFeatureAngle) < 1;
    const double voxel = o.image ? o.image->voxelSize() : meanEdge;
    const double imageCos = cosOf(o.imageFeatureAngle), step = o.imageStep * voxel;
    if (imageGated) { // where the image shows no crease, there is nothing to do
        std::vector<char> imageCrease;
        if (!markImageCreases(mesh, x, geo, o, step, imageCrease)) return added;
    }
    const FaceRings rings = faceRings(mesh);
    std::vector<Vec3> filtered, scratch, anchor;
    filterNormals(geo, rings, meanEdge, o, filtered, scratch);
    faceAnchors(geo, filtered, o, anchor);
    const double clusterCos = cosOf(2 * o.featureAngle), chamferCos = cosOf(o.chamferAngle);
    const double ownCos = std::min(chamferCos, cosOf(o.ownPlaneAngle));

    struct Candidate {
        FaceHandle f;
        Vec3 p;
        double depth;
    };
    std::vector<Candidate> found;
    for (std::size_t fi = 0; fi < nf; ++fi) {
        const FaceHandle f{int(fi)};
        if (mesh.status(f).deleted() || !(geo.area[fi] > 0)) continue;
        const std::size_t begin = rings.first[fi], end = rings.first[fi + 1];
        // The planes around the face: its neighbours' filtered normals clustered about seeds at
        // least twice featureAngle apart, each seed the normal farthest from those before (the
        // first two the most opposed pair), up to four (a thin plate's corner: top, bottom and two
        // sides); each plane the clusters' area-weighted mean normal and plane point.
        double lowest = 2;
        Vec3 seeds[4];
        int count = 0;
        for (std::size_t j = begin; j < end; ++j)
            for (std::size_t k = j + 1; k < end; ++k) {
                const Vec3& nj = filtered[std::size_t(rings.ring[j])];
                const Vec3& nk = filtered[std::size_t(rings.ring[k])];
                if (const double d = nj.dot(nk); d < lowest) lowest = d, seeds[0] = nj, seeds[1] = nk;
            }
        if (!(lowest < clusterCos)) continue;
        count = 2;
        while (count < 4) {
            double farthest = 2; // the largest cosine to the nearest seed, minimised
            Vec3 next = Vec3::Zero();
            for (std::size_t j = begin; j < end; ++j) {
                const Vec3& nj = filtered[std::size_t(rings.ring[j])];
                double nearest = -2;
                for (int i = 0; i < count; ++i) nearest = std::max(nearest, nj.dot(seeds[i]));
                if (nearest < farthest) farthest = nearest, next = nj;
            }
            if (!(farthest < clusterCos)) break;
            seeds[count++] = next;
        }
        Vec3 normal[4], point[4];
        double weight[4] = {0, 0, 0, 0};
        for (int i = 0; i < count; ++i) normal[i] = point[i] = Vec3::Zero();
        for (std::size_t j = begin; j < end; ++j) {
            const std::size_t g = std::size_t(rings.ring[j]);
            int best = 0;
            for (int i = 1; i < count; ++i)
                if (filtered[g].dot(seeds[i]) > filtered[g].dot(seeds[best])) best = i;
            normal[best] += geo.area[g] * filtered[g], point[best] += geo.area[g] * anchor[g], weight[best] += geo.area[g];
        }
        const Vec3& n = geo.normal[fi];
        const Vec3& c = geo.centroid[fi];
        // The planes the face cuts across: those it faces (within ~80 degrees), none of which it
        // lies on; two make a crease, three a corner.
        int used[3], planes = 0;
        bool onPlane = false;
        for (int i = 0; i < count; ++i) {
            if (!(weight[i] > 0) || !(normal[i].norm() > 0)) continue;
            normal[i].normalize(), point[i] /= weight[i];
            // A plane of the face's own orientation is one it lies on, or one it is parallel to (a
            // chamfer's own cluster: its plane is anchored outside it, at the image's isosurface,
            // and crossing it with the others put the crease within a fraction of a voxel of the
            // face, so a plate's corner was never found); never one it cuts across
            // (ownPlaneAngle).
            if (n.dot(normal[i]) > chamferCos && std::abs(normal[i].dot(c - point[i])) < 0.5 * o.chamferDepth * voxel)
                onPlane = true;
            if (n.dot(normal[i]) > ownCos) continue;
            if (n.dot(normal[i]) > 0.2 && planes < 3) used[planes++] = i;
        }
        if (onPlane || planes < 2) continue;
        Eigen::Matrix3d M;
        Vec3 rhs;
        Vec3 dir = Vec3::Zero();
        for (int r = 0; r < planes; ++r) M.row(r) = normal[used[r]].transpose(), rhs[r] = normal[used[r]].dot(point[used[r]]);
        if (planes == 2) { // the crease's point nearest the centroid
            dir = normal[used[0]].cross(normal[used[1]]);
            if (!(dir.norm() > 0.5)) continue;
            dir.normalize();
            M.row(2) = dir.transpose(), rhs[2] = dir.dot(c);
        } else if (std::abs(M.determinant()) < 0.3) { // three planes meeting well in one point
            continue;
        }
        Vec3 p = M.colPivHouseholderQr().solve(rhs);
        if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) continue;
        // Over the face: its projection inside the triangle.
        const auto [va, vb, vc] = faceVertices(mesh, f);
        const Vec3 &A = x[std::size_t(va.idx())], &B = x[std::size_t(vb.idx())], &C = x[std::size_t(vc.idx())];
        const double area2 = (B - A).cross(C - A).dot(n);
        auto over = [&](const Vec3& y) {
            const Vec3 q = y - n.dot(y - c) * n;
            const double u = (C - B).cross(q - B).dot(n) / area2, v = (A - C).cross(q - C).dot(n) / area2;
            return u >= 0 && v >= 0 && u + v <= 1;
        };
        if (planes == 2 && o.image && o.cornerInset > 0) { // where the crease ends, if it ends over the face
            Vec3 end = Vec3::Zero(), across = Vec3::Zero();
            if (creaseEnd(*o.image, o.iso, o.objectBrighter, p - o.cornerInset * voxel * (normal[used[0]] + normal[used[1]]).normalized(),
                          dir, meanEdge, 0.25 * voxel, end, across)) {
                M.row(2) = across.transpose(), rhs[2] = across.dot(end);
                const Vec3 corner = M.colPivHouseholderQr().solve(rhs);
                if (corner.allFinite() && over(corner) && n.dot(corner - c) >= o.chamferDepth * voxel &&
                    (corner - c).norm() <= meanEdge)
                    p = corner;
            }
        }
        const double depth = n.dot(p - c);
        if (!(depth >= o.chamferDepth * voxel) || (p - c).norm() > meanEdge) continue; // convex creases only (see insertCreases)
        const Vec3 na = normal[used[0]], nb = normal[used[1]];
        if (planes == 3) dir = na.cross(nb).normalized();
        if (!over(p)) continue;
        if (imageGated) { // the image's normals a little way into either plane from p
            auto into = [&](const Vec3& nPlane) {
                const Vec3 t = nPlane.cross(dir).normalized();
                const Vec3 n1 = unitIndexGradient(*o.image, p + step * t), n2 = unitIndexGradient(*o.image, p - step * t);
                const double sign = o.objectBrighter ? -1.0 : 1.0; // the gradient points inward for a bright object
                return (sign * n1).dot(nPlane) >= (sign * n2).dot(nPlane) ? Vec3(sign * n1) : Vec3(sign * n2);
            };
            if (!(into(na).dot(into(nb)) <= imageCos)) continue;
        }
        found.push_back({f, p, depth});
    }
    // Deepest first; none within half a mean edge of another.
    std::sort(found.begin(), found.end(), [](const Candidate& l, const Candidate& r) { return l.depth > r.depth; });
    std::vector<Vec3> placed;
    for (const Candidate& k : found) {
        bool near = false;
        for (const Vec3& q : placed) near |= (q - k.p).norm() < 0.5 * meanEdge;
        if (near) continue;
        added.push_back(mesh.split(k.f, toPoint(k.p)));
        placed.push_back(k.p);
    }
    return added;
}

/// SharpenOptions::alignCreases: the edges of the faces around `seeds` flipped, in sweeps, while a
/// flip lowers the sum of length x |dihedral angle| over the edges of its two faces. A flip is
/// made only if its faces keep their orientation (each new normal within 90 degrees of the old
/// faces' mean), do not fold onto each other (dihedral under 120 degrees) and have no angle under
/// half the smallest of the old faces' (nor under 10 degrees). Returns the flips made.
std::size_t alignCreaseEdges(Mesh& mesh, const std::vector<VertexHandle>& seeds)
{
    std::vector<EdgeHandle> edges;
    for (VertexHandle v : seeds)
        for (auto f : mesh.vf_range(v))
            for (auto e : mesh.fe_range(f)) edges.push_back(e);
    std::sort(edges.begin(), edges.end(), [](EdgeHandle l, EdgeHandle r) { return l.idx() < r.idx(); });
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    const double scale = meanEdgeLength(mesh);
    auto at = [&](VertexHandle v) { return position(mesh, v); };
    auto normalOf = [](const Vec3& a, const Vec3& b, const Vec3& c) {
        const Vec3 n = (b - a).cross(c - a);
        const double len = n.norm();
        return len > 0 ? Vec3(n / len) : Vec3(Vec3::Zero());
    };
    auto bend = [](const Vec3& n, const Vec3& m) { return std::acos(std::clamp(n.dot(m), -1.0, 1.0)); };
    auto smallestAngle = [](const Vec3& a, const Vec3& b, const Vec3& c) {
        const Vec3 p[3] = {a, b, c};
        double smallest = M_PI;
        for (int k = 0; k < 3; ++k) {
            const Vec3 u = p[(k + 1) % 3] - p[k], w = p[(k + 2) % 3] - p[k];
            const double denominator = u.norm() * w.norm();
            smallest = std::min(smallest, denominator > 0 ? std::acos(std::clamp(u.dot(w) / denominator, -1.0, 1.0)) : 0.0);
        }
        return smallest;
    };
    // The normal of the face across the halfedge h's edge from h's face (zero at a boundary).
    auto outerNormal = [&](HalfedgeHandle h) {
        const FaceHandle g = mesh.face_handle(mesh.opposite_halfedge_handle(h));
        return g.is_valid() ? faceNormal(mesh, g) : Vec3(Vec3::Zero());
    };
    std::size_t flips = 0;
    for (int sweep = 0; sweep < 8; ++sweep) {
        std::size_t flipped = 0;
        for (EdgeHandle e : edges) {
            if (mesh.status(e).deleted() || mesh.is_boundary(e) || !mesh.is_flip_ok(e)) continue;
            const HalfedgeHandle h = mesh.halfedge_handle(e, 0), o = mesh.opposite_halfedge_handle(h);
            const HalfedgeHandle hbc = mesh.next_halfedge_handle(h), hca = mesh.next_halfedge_handle(hbc);
            const HalfedgeHandle had = mesh.next_halfedge_handle(o), hdb = mesh.next_halfedge_handle(had);
            const VertexHandle va = mesh.from_vertex_handle(h), vb = mesh.to_vertex_handle(h);
            const VertexHandle vc = mesh.to_vertex_handle(hbc), vd = mesh.to_vertex_handle(had);
            const Vec3 a = at(va), b = at(vb), c = at(vc), d = at(vd);
            const Vec3 nf = normalOf(a, b, c), ng = normalOf(b, a, d);      // now: (a, b, c), (b, a, d)
            const Vec3 nf2 = normalOf(c, a, d), ng2 = normalOf(d, b, c);    // flipped: (c, a, d), (d, b, c)
            if (nf.isZero() || ng.isZero() || nf2.isZero() || ng2.isZero()) continue;
            const Vec3 mean = (nf + ng).normalized();
            if (!(nf2.dot(mean) > 0) || !(ng2.dot(mean) > 0) || !(nf2.dot(ng2) > -0.5)) continue;
            const double oldAngle = std::min(smallestAngle(a, b, c), smallestAngle(b, a, d));
            const double newAngle = std::min(smallestAngle(c, a, d), smallestAngle(d, b, c));
            if (newAngle < std::min(0.5 * oldAngle, 10 * M_PI / 180)) continue;
            const Vec3 obc = outerNormal(hbc), oca = outerNormal(hca), oad = outerNormal(had), odb = outerNormal(hdb);
            const double lbc = (c - b).norm(), lca = (a - c).norm(), lad = (d - a).norm(), ldb = (b - d).norm();
            const double before = (b - a).norm() * bend(nf, ng) + lbc * bend(nf, obc) + lca * bend(nf, oca) +
                                  lad * bend(ng, oad) + ldb * bend(ng, odb);
            const double after = (d - c).norm() * bend(nf2, ng2) + lbc * bend(ng2, obc) + lca * bend(nf2, oca) +
                                 lad * bend(nf2, oad) + ldb * bend(ng2, odb);
            if (!(after < before - 1e-3 * scale)) continue;
            mesh.flip(e);
            ++flipped;
        }
        flips += flipped;
        if (!flipped) break;
    }
    return flips;
}

/// One pass: thin rims split, then the vertices on creases and corners fitted (see the file
/// comment); `stats` gets the splits and the refusals.
void sharpenPass(Mesh& mesh, const SharpenOptions& o, SharpenStats& stats)
{
    if (o.rimAngle < 180) stats.rimSplits += splitRims(mesh, o);
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
    if (edgeCount == 0) return;
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
        faceAnchors(geo, filtered, o, anchor);
        // Each plane's offset: from its neighbours on the same plane (SharpenOptions::samePlaneAngle)
        // as well as its own anchor, each weighted by how well the image's normal there agrees with
        // the plane's (SharpenOptions::anchorAgreement): near a rounded crease or corner it does
        // not, and those anchors lie inside it.
        std::vector<double> offset(nf);
        {
            const double power = o.anchorAgreement;
            std::vector<double> reliability(nf, 1.0);
            if (o.image && power > 0)
                detail::parallelFor(0, nf, 256, [&](std::size_t g) {
                    const Vec3 m = (o.objectBrighter ? -1.0 : 1.0) * unitIndexGradient(*o.image, anchor[g]);
                    reliability[g] = std::pow(std::max(0.0, m.dot(filtered[g])), power);
                });
            const double same = cosOf(o.samePlaneAngle);
            detail::parallelFor(0, nf, 256, [&](std::size_t f) {
                double sum = 0, weight = 0;
                if (power > 0)
                    for (std::size_t j = rings.first[f]; j < rings.first[f + 1]; ++j) {
                        const std::size_t g = std::size_t(rings.ring[j]);
                        if (filtered[g].dot(filtered[f]) < same) continue;
                        const double w = geo.area[g] * reliability[g];
                        sum += w * filtered[f].dot(anchor[g]), weight += w;
                    }
                offset[f] = weight > 0 ? sum / weight : filtered[f].dot(anchor[f]);
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
                rhs += n * offset[fi];
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
            if (o.image) { // back toward where the round started, while the image says too far out or in
                auto astray = [&](const Vec3& p) {
                    const double d = (o.objectBrighter ? 1.0 : -1.0) * isoDistance(*o.image, p, o.iso, 1e-12);
                    return d < -o.maxOutside || d > o.maxInside;
                };
                for (int k = 0; k < 4 && astray(y); ++k) y = x[i] + 0.5 * (y - x[i]);
                if (astray(y)) y = x[i];
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
    for (auto v : mesh.vertices()) mesh.point(v) = toPoint(x[std::size_t(v.idx())]);
}

} // namespace

SharpenStats sharpenFeatures(Mesh& mesh, const SharpenOptions& o)
{
    SharpenStats stats;
    if (mesh.n_vertices() == 0 || mesh.n_faces() == 0) return stats;
    const std::size_t before = mesh.n_vertices();
    std::vector<Vec3> start(before);
    for (auto v : mesh.vertices()) start[std::size_t(v.idx())] = position(mesh, v);
    if (o.image && cosOf(o.imageFeatureAngle) < 1) { // a surface where the image shows no crease is left as it is
        FaceGeometry geo;
        measureFaces(mesh, start, geo);
        std::vector<char> imageCrease;
        if (!markImageCreases(mesh, start, geo, o, o.imageStep * o.image->voxelSize(), imageCrease)) return stats;
    }
    for (int pass = 0; pass < o.passes; ++pass) sharpenPass(mesh, o, stats);
    std::vector<VertexHandle> added;
    for (int pass = 0; o.insertCreases && pass < o.insertPasses; ++pass) {
        const std::vector<VertexHandle> more = insertCreaseVertices(mesh, o);
        if (more.empty()) break;
        added.insert(added.end(), more.begin(), more.end());
    }
    stats.creaseVertices = added.size();
    if (o.alignCreases && !added.empty()) stats.creaseFlips = alignCreaseEdges(mesh, added);
    const double meanEdge = meanEdgeLength(mesh);
    for (auto v : mesh.vertices()) {
        const std::size_t i = std::size_t(v.idx());
        if (i >= before) { // added by a split or on a crease
            ++stats.moved;
            continue;
        }
        const double move = (position(mesh, v) - start[i]).norm();
        if (move > 1e-6 * meanEdge) ++stats.moved;
        stats.largestMove = std::max(stats.largestMove, move);
    }
    return stats;
}

SharpenOptions imageSharpenOptions(const ScalarImage& image, double iso, bool objectBrighter)
{
    SharpenOptions o;
    const double h = image.voxelSize();
    o.image = &image;
    o.iso = iso;
    o.objectBrighter = objectBrighter;
    o.maxMove = kSharpenMaxMoveVoxels * h;
    o.maxOutside = kSharpenMaxOutsideVoxels * h;
    o.maxInside = kSharpenMaxInsideVoxels * h;
    return o;
}

SharpenStats sharpenFeaturesEmbedded(Mesh& mesh, const SharpenOptions& options)
{
    Mesh before = mesh; // (sharpening may split vertices and faces)
    const SharpenStats stats = sharpenFeatures(mesh, options);
    const bool changed = stats.largestMove > 0 || stats.rimSplits > 0 || stats.creaseVertices > 0;
    const std::size_t after = changed ? findSelfIntersections(mesh).count() : 0;
    if (after == 0 || after <= findSelfIntersections(before).count()) return stats;
    mesh = std::move(before); // a crossing added: the surface as it was
    return {};
}

} // namespace riemesh
