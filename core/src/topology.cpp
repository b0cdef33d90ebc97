// topology.cpp: automated topology changes (paper 3.2, Fig. 3).
//
// merge (Fig. 3a) and cutTunnel (Fig. 3b) delete a small patch and re-add faces with OpenMesh
// add_face. Every precondition that decides the outcome is checked by canMerge / canCutTunnel
// before anything is touched. As a last line of defence, each operation keeps a copy of the mesh
// and restores it if OpenMesh ever refuses a face (it never has in the tests; the copy costs O(n)
// per topology change, which are rare events).
#include "riemesh/topology.h"

#include "riemesh/ccd.h"

#include "detail/mesh_walk.h"
#include "detail/triangle_intersection.h"

#include <algorithm>
#include <array>
#include <limits>

namespace riemesh {

namespace {

bool isAlive(const Mesh& mesh, VertexHandle v)
{
    return v.is_valid() && std::size_t(v.idx()) < mesh.n_vertices() && !mesh.status(v).deleted();
}

bool contains(const std::vector<VertexHandle>& list, VertexHandle v)
{
    return std::find(list.begin(), list.end(), v) != list.end();
}

/// The one-ring of v as a loop a_0..a_{n-1} such that a_i -> a_{i+1} is the halfedge of the face
/// (v, a_i, a_{i+1}): once v's faces are gone, exactly these halfedges are the boundary. False when
/// v is a boundary vertex or the ring does not close.
bool collectLoop(const Mesh& mesh, VertexHandle v, std::vector<VertexHandle>& loop)
{
    loop.clear();
    if (mesh.is_boundary(v) || mesh.is_isolated(v)) return false;
    const HalfedgeHandle start = mesh.halfedge_handle(v);
    HalfedgeHandle h = start;
    const std::size_t limit = mesh.n_halfedges();
    do {
        if (!mesh.face_handle(h).is_valid() || loop.size() > limit) return false;
        loop.push_back(mesh.to_vertex_handle(h));
        h = mesh.opposite_halfedge_handle(mesh.next_halfedge_handle(mesh.next_halfedge_handle(h)));
    } while (h != start);
    return true;
}

double distance(const Mesh& mesh, VertexHandle a, VertexHandle b)
{
    return (mesh.point(a) - mesh.point(b)).norm();
}

double meanEdgeLengthAround(const Mesh& mesh, VertexHandle v)
{
    double sum = 0;
    int count = 0;
    for (auto w : mesh.vv_range(v)) {
        sum += distance(mesh, v, w);
        ++count;
    }
    return count ? sum / count : 0.0;
}

/// The faces around a tunnel loop u -> v -> w, split into the side left of the loop (the faces of
/// u->v, v->w, w->u) and the side right of it, each in flood-fill order.
struct TunnelSides {
    std::vector<FaceHandle> left, right;
};

bool partitionTunnelSides(const Mesh& mesh, VertexHandle u, VertexHandle v, VertexHandle w, TunnelSides& sides)
{
    const std::array<VertexHandle, 3> loop{u, v, w};
    std::array<HalfedgeHandle, 3> forward, backward; // u->v, v->w, w->u and their opposites
    for (int i = 0; i < 3; ++i) {
        forward[i] = mesh.find_halfedge(loop[i], loop[(i + 1) % 3]);
        if (!forward[i].is_valid()) return false;
        backward[i] = mesh.opposite_halfedge_handle(forward[i]);
        if (!mesh.face_handle(forward[i]).is_valid() || !mesh.face_handle(backward[i]).is_valid()) return false;
    }
    // (u, v, w) must not be a face, in either orientation.
    for (int i = 0; i < 3; ++i) {
        const VertexHandle opposite = loop[(i + 2) % 3];
        if (mesh.to_vertex_handle(mesh.next_halfedge_handle(forward[i])) == opposite) return false;
        if (mesh.to_vertex_handle(mesh.next_halfedge_handle(backward[i])) == opposite) return false;
    }
    std::vector<FaceHandle> around;
    for (auto x : loop)
        for (auto f : mesh.vf_range(x))
            if (std::find(around.begin(), around.end(), f) == around.end()) around.push_back(f);
    std::vector<int> side(around.size(), -1);
    auto slot = [&](FaceHandle f) {
        const auto it = std::find(around.begin(), around.end(), f);
        return it == around.end() ? -1 : int(it - around.begin());
    };
    auto isLoopEdge = [&](EdgeHandle e) {
        for (int i = 0; i < 3; ++i)
            if (mesh.edge_handle(forward[i]) == e) return true;
        return false;
    };
    auto flood = [&](FaceHandle seed, int label, std::vector<FaceHandle>& order) {
        const int s = slot(seed);
        if (s < 0 || side[s] >= 0) return false;
        side[s] = label;
        order.assign(1, seed);
        for (std::size_t next = 0; next < order.size(); ++next) {
            for (auto h : mesh.fh_range(order[next])) {
                if (isLoopEdge(mesh.edge_handle(h))) continue;
                const FaceHandle g = mesh.face_handle(mesh.opposite_halfedge_handle(h));
                const int t = g.is_valid() ? slot(g) : -1;
                if (t < 0) continue;
                if (side[t] >= 0) {
                    if (side[t] != label) return false; // the loop does not separate the sides
                    continue;
                }
                side[t] = label;
                order.push_back(g);
            }
        }
        return true;
    };
    if (!flood(mesh.face_handle(forward[0]), 0, sides.left)) return false;
    if (!flood(mesh.face_handle(backward[0]), 1, sides.right)) return false;
    for (int s : side)
        if (s < 0) return false;
    for (int i = 0; i < 3; ++i) {
        if (side[slot(mesh.face_handle(forward[i]))] != 0) return false;
        if (side[slot(mesh.face_handle(backward[i]))] != 1) return false;
    }
    // Each loop vertex keeps at least two faces on each side (valence >= 3 once capped).
    for (auto x : loop) {
        int count[2] = {0, 0};
        for (auto f : mesh.vf_range(x)) ++count[side[slot(f)]];
        if (count[0] < 2 || count[1] < 2) return false;
    }
    // A side that closes up on its own with its cap (e.g. the three faces around a valence-3
    // vertex whose neighbours form the loop) is a pinch, not a tunnel: cutting it would split
    // off a tetrahedron-sized component. Regularity removes such a vertex instead.
    for (const auto* side_ : {&sides.left, &sides.right}) {
        bool closesUp = true;
        for (const FaceHandle f : *side_)
            for (auto x : mesh.fv_range(f)) {
                if (x == u || x == v || x == w) continue;
                for (auto g : mesh.vf_range(x))
                    if (std::find(side_->begin(), side_->end(), g) == side_->end()) closesUp = false;
            }
        if (closesUp) return false;
    }
    // A vertex off the loop loses its faces around the loop and gets them back; keep the removed
    // faces one contiguous arc of its fan so that re-adding them never meets a split fan.
    for (const FaceHandle f : around) {
        for (auto x : mesh.fv_range(f)) {
            if (x == u || x == v || x == w) continue;
            int transitions = 0;
            for (auto h : mesh.voh_range(x)) {
                const FaceHandle a = mesh.face_handle(h);
                const FaceHandle b = mesh.face_handle(mesh.opposite_halfedge_handle(h));
                if ((slot(a) >= 0) != (slot(b) >= 0)) ++transitions;
            }
            if (transitions > 2) return false;
            bool allRemoved = true;
            for (auto g : mesh.vf_range(x))
                if (slot(g) < 0) allRemoved = false;
            if (allRemoved) return false; // x would be rebuilt from nothing: a tiny component
        }
    }
    return true;
}

OpenMesh::VPropHandleT<int> cutIdProperty(Mesh& mesh)
{
    OpenMesh::VPropHandleT<int> prop;
    if (!mesh.get_property_handle(prop, kCutIdProperty)) {
        mesh.add_property(prop, kCutIdProperty);
        for (auto v : mesh.all_vertices()) mesh.property(prop, v) = 0;
    }
    return prop;
}

/// Sets property `prop` to `value` on `seeds` and on every vertex within `rings` edges of them
/// (a breadth-first spread that stops at vertices already holding `value`).
template <typename T>
void tagRings(Mesh& mesh, OpenMesh::VPropHandleT<T> prop, T value, const std::vector<VertexHandle>& seeds, int rings)
{
    std::vector<VertexHandle> frontier, next;
    for (auto v : seeds)
        if (mesh.property(prop, v) != value) {
            mesh.property(prop, v) = value;
            frontier.push_back(v);
        }
    for (int r = 0; r < rings; ++r) {
        next.clear();
        for (auto v : frontier)
            for (auto x : mesh.vv_range(v))
                if (mesh.property(prop, x) != value) {
                    mesh.property(prop, x) = value;
                    next.push_back(x);
                }
        frontier.swap(next);
    }
}

/// Tags `seeds` and every vertex within `rings` edges of them with a fresh cut id.
void tagCut(Mesh& mesh, const std::vector<VertexHandle>& seeds, int rings)
{
    const auto prop = cutIdProperty(mesh);
    int id = 0;
    for (auto v : mesh.vertices()) id = std::max(id, mesh.property(prop, v));
    tagRings(mesh, prop, id + 1, seeds, rings);
}

using Triangle = std::array<VertexHandle, 3>;

/// Tags the band's vertices and every vertex within `rings` edges of them (kMergedProperty,
/// kMergeZoneIterations).
void tagMerge(Mesh& mesh, const std::vector<Triangle>& band, int rings)
{
    OpenMesh::VPropHandleT<char> prop;
    if (!mesh.get_property_handle(prop, kMergedProperty)) {
        mesh.add_property(prop, kMergedProperty);
        for (auto v : mesh.all_vertices()) mesh.property(prop, v) = 0;
    }
    std::vector<VertexHandle> seeds;
    for (const Triangle& t : band) seeds.insert(seeds.end(), t.begin(), t.end());
    tagRings(mesh, prop, char(kMergeZoneIterations), seeds, rings);
}

/// The band of merge (Fig. 3a) that zips loop `a` (forward) with loop `b` (backward) starting from
/// the cross edge a[i0]-b[j0]. State (i, k): the current cross edge joins A(i) and B(-k); an A step
/// adds (A(i), A(i+1), B(-k)) over the boundary halfedge A(i)->A(i+1), a B step adds
/// (B(-k-1), B(-k), A(i)) over B(-k-1)->B(-k). The band is an annulus only if no cross edge appears
/// twice: states equal modulo (n, m) are joined by the same edge, so a step into an already visited
/// state is refused (except the final (n, m) = (0, 0)). At most one of the two steps is ever
/// refused, and the shorter new cross edge wins otherwise. `length` receives the summed length of
/// the cross edges (world units). False when the zip gets stuck.
bool zipBand(const Mesh& mesh, const std::vector<VertexHandle>& a, const std::vector<VertexHandle>& b, int i0, int j0,
             std::vector<Triangle>& band, double& length)
{
    const int n = int(a.size()), m = int(b.size());
    auto A = [&](int i) { return a[(((i0 + i) % n) + n) % n]; };
    auto B = [&](int j) { return b[(((j0 + j) % m) + m) % m]; };
    band.clear();
    length = distance(mesh, A(0), B(0));
    std::vector<char> visited(std::size_t(n) * m, 0);
    auto isVisited = [&](int i, int k) { return visited[std::size_t(i % n) * m + (k % m)] != 0; };
    visited[0] = 1;
    int i = 0, k = 0;
    while (i < n || k < m) {
        const bool closing = (i + 1 == n && k == m) || (i == n && k + 1 == m);
        const bool canA = i < n && (closing || !isVisited(i + 1, k));
        const bool canB = k < m && (closing || !isVisited(i, k + 1));
        if (!canA && !canB) return false;
        const double lengthA = distance(mesh, A(i + 1), B(-k)), lengthB = distance(mesh, A(i), B(-k - 1));
        const bool stepA = !canB || (canA && lengthA <= lengthB);
        if (stepA) {
            band.push_back({A(i), A(i + 1), B(-k)});
            ++i;
        } else {
            band.push_back({B(-k - 1), B(-k), A(i)});
            ++k;
        }
        if (!closing) length += stepA ? lengthA : lengthB;
        visited[std::size_t(i % n) * m + (k % m)] = 1;
    }
    return true;
}

/// True when the band faces meet neither each other nor any face of the mesh that stays (all but
/// the one-rings of u and w), beyond the vertices and edges they share (exact tests, see
/// riemesh/self_intersection.h). A band that folds or twists, or cuts through a nearby sheet,
/// would leave the surface self-intersecting. With minSeparation > 0, a band face may come no
/// closer than that to a face it shares no vertex with (trianglesCloserThan, riemesh/ccd.h).
bool isBandEmbedded(const Mesh& mesh, const std::vector<FaceHandle>& nearby, const std::vector<Triangle>& band,
                    double minSeparation)
{
    using detail::TriangleRef;
    auto corners = [&](const Triangle& t) {
        return detail::makeTriangle(mesh.point(t[0]).data(), mesh.point(t[1]).data(), mesh.point(t[2]).data());
    };
    auto ids = [](const Triangle& t) { return std::array<int, 3>{t[0].idx(), t[1].idx(), t[2].idx()}; };
    auto points = [&](const Triangle& t) {
        return std::array<Vec3, 3>{position(mesh, t[0]), position(mesh, t[1]), position(mesh, t[2])};
    };
    auto tooClose = [&](const Triangle& x, const Triangle& y) {
        return trianglesCloserThan(ids(x), points(x), ids(y), points(y), minSeparation);
    };
    Eigen::AlignedBox3d box;
    std::vector<TriangleRef> refs;
    for (const Triangle& t : band) {
        refs.push_back(corners(t));
        if (refs.back().axis < 0) return false; // a flat band face
        // A nearly flat one too (height under 1e-8 of its longest edge): the loops of a pair that
        // met at vmax ~ delta held collinear corners up to round-off, and the band face's area was
        // 2e-16 (stress case 145331693200290732).
        const Vec3 p = position(mesh, t[0]), q = position(mesh, t[1]), r = position(mesh, t[2]);
        const double longest = std::max({(q - p).squaredNorm(), (r - q).squaredNorm(), (p - r).squaredNorm()});
        if (!((q - p).cross(r - p).squaredNorm() > 1e-16 * longest * longest)) return false;
        for (auto v : t) box.extend(position(mesh, v));
    }
    for (std::size_t i = 0; i < band.size(); ++i)
        for (std::size_t j = i + 1; j < band.size(); ++j)
            if (detail::classifyTriangles(ids(band[i]), refs[i], ids(band[j]), refs[j]) != detail::TriangleContact::None ||
                tooClose(band[i], band[j]))
                return false;
    // The faces that stay, near the band.
    for (const FaceHandle f : nearby) {
        const Triangle t = faceVertices(mesh, f);
        Eigen::AlignedBox3d faceBox;
        for (auto v : t) faceBox.extend(position(mesh, v));
        faceBox.extend(faceBox.min() - Vec3::Constant(minSeparation));
        faceBox.extend(faceBox.max() + Vec3::Constant(minSeparation));
        if (!box.intersects(faceBox)) continue;
        const TriangleRef ref = corners(t);
        if (ref.axis < 0) continue; // a degenerate face of the surface: nothing to cross
        for (std::size_t i = 0; i < band.size(); ++i)
            if (detail::classifyTriangles(ids(band[i]), refs[i], ids(t), ref) != detail::TriangleContact::None ||
                tooClose(band[i], t))
                return false;
    }
    return true;
}

/// The band merge(u, w) adds: of the zips from every pair of loop vertices, the one with the
/// shortest cross edges in total that is embedded. Starting at the closest pair alone twists the
/// band when the two loops are tilted or offset against each other (seen when the two ends of a
/// tube meet at an angle), and a twisted band crosses itself. False when no zip is embedded.
bool chooseBand(const Mesh& mesh, VertexHandle u, VertexHandle w, std::vector<Triangle>& band, double minSeparation)
{
    std::vector<VertexHandle> a, b;
    if (!collectLoop(mesh, u, a) || !collectLoop(mesh, w, b)) return false;
    struct Zip {
        double length;
        int i0, j0;
    };
    std::vector<Zip> zips;
    std::vector<Triangle> faces;
    for (int i0 = 0; i0 < int(a.size()); ++i0)
        for (int j0 = 0; j0 < int(b.size()); ++j0) {
            double length = 0;
            if (zipBand(mesh, a, b, i0, j0, faces, length)) zips.push_back({length, i0, j0});
        }
    std::sort(zips.begin(), zips.end(), [](const Zip& x, const Zip& y) {
        return x.length != y.length ? x.length < y.length : std::make_pair(x.i0, x.j0) < std::make_pair(y.i0, y.j0);
    });
    // Every zip's band joins vertices of the two loops: the faces that stay and could cross one lie
    // in the loops' bounding box, found in one pass over the faces (not one per zip: a tangled
    // surface has high-valence loops and tries hundreds of zips).
    Eigen::AlignedBox3d loops;
    for (const auto* loop : {&a, &b})
        for (const VertexHandle v : *loop) loops.extend(position(mesh, v));
    std::vector<FaceHandle> nearby;
    if (!zips.empty())
        for (auto f : mesh.faces()) {
            const Triangle t = faceVertices(mesh, f);
            if (std::find(t.begin(), t.end(), u) != t.end() || std::find(t.begin(), t.end(), w) != t.end()) continue;
            Eigen::AlignedBox3d faceBox;
            for (auto v : t) faceBox.extend(position(mesh, v));
            faceBox.extend(faceBox.min() - Vec3::Constant(minSeparation));
            faceBox.extend(faceBox.max() + Vec3::Constant(minSeparation));
            if (loops.intersects(faceBox)) nearby.push_back(f);
        }
    for (const Zip& z : zips) {
        double length = 0;
        zipBand(mesh, a, b, z.i0, z.j0, band, length);
        if (isBandEmbedded(mesh, nearby, band, minSeparation)) return true;
    }
    band.clear();
    return false;
}

/// canMerge(), with the band merge() adds when true.
bool findMergeBand(const Mesh& mesh, VertexHandle u, VertexHandle w, double minSeparation, std::vector<Triangle>& band)
{
    band.clear();
    if (!mesh.has_vertex_status() || !mesh.has_face_status() || !mesh.has_edge_status()) return false;
    if (!isAlive(mesh, u) || !isAlive(mesh, w) || u == w) return false;
    std::vector<VertexHandle> a, b;
    if (!collectLoop(mesh, u, a) || !collectLoop(mesh, w, b)) return false;
    if (a.size() < 3 || b.size() < 3) return false;
    // Closed one-rings disjoint (also rules out u, w adjacent); loops simple.
    for (std::size_t i = 0; i < a.size(); ++i) {
        if (a[i] == w || contains(b, a[i])) return false;
        if (std::find(a.begin() + i + 1, a.end(), a[i]) != a.end()) return false;
    }
    for (std::size_t j = 0; j < b.size(); ++j) {
        if (b[j] == u) return false;
        if (std::find(b.begin() + j + 1, b.end(), b[j]) != b.end()) return false;
    }
    // The band adds edges between loop A and loop B: none may exist already.
    for (auto x : a)
        for (auto y : mesh.vv_range(x))
            if (contains(b, y)) return false;
    return chooseBand(mesh, u, w, band, minSeparation);
}

/// merge() with the band findMergeBand() chose for (u, w) on this very mesh.
bool mergeWithBand(Mesh& mesh, VertexHandle u, VertexHandle w, const std::vector<Triangle>& band)
{
    const Mesh backup = mesh;
    mesh.delete_vertex(u, false);
    mesh.delete_vertex(w, false);
    for (const Triangle& t : band) {
        if (!mesh.add_face(t[0], t[1], t[2]).is_valid()) {
            mesh = backup;
            return false;
        }
    }
    tagMerge(mesh, band, 2);
    return true;
}

} // namespace

bool canMerge(const Mesh& mesh, VertexHandle u, VertexHandle w, double minSeparation)
{
    std::vector<Triangle> band;
    return findMergeBand(mesh, u, w, minSeparation, band);
}

bool merge(Mesh& mesh, VertexHandle u, VertexHandle w, double minSeparation)
{
    // One band search serves the checks and the merge (resolveTopology keeps the band it checked).
    std::vector<Triangle> band;
    return findMergeBand(mesh, u, w, minSeparation, band) && mergeWithBand(mesh, u, w, band);
}

bool canCutTunnel(const Mesh& mesh, VertexHandle u, VertexHandle v, VertexHandle w)
{
    if (!mesh.has_vertex_status() || !mesh.has_face_status() || !mesh.has_edge_status()) return false;
    if (!isAlive(mesh, u) || !isAlive(mesh, v) || !isAlive(mesh, w)) return false;
    if (u == v || v == w || w == u) return false;
    TunnelSides sides;
    return partitionTunnelSides(mesh, u, v, w, sides);
}

bool cutTunnel(Mesh& mesh, VertexHandle u, VertexHandle v, VertexHandle w, double minSeparation)
{
    if (!canCutTunnel(mesh, u, v, w)) return false;
    TunnelSides sides;
    partitionTunnelSides(mesh, u, v, w, sides);

    std::vector<std::array<VertexHandle, 3>> leftFaces, rightFaces;
    for (auto f : sides.left) leftFaces.push_back(faceVertices(mesh, f));
    for (auto f : sides.right) rightFaces.push_back(faceVertices(mesh, f));

    const Mesh backup = mesh;
    for (auto f : sides.left) mesh.delete_face(f, false);
    for (auto f : sides.right) mesh.delete_face(f, false);

    const auto velocity = velocityProperty(mesh);
    const std::array<VertexHandle, 3> loop{u, v, w};
    std::array<VertexHandle, 3> copy;
    for (int i = 0; i < 3; ++i) {
        // A copy, not mesh.point()'s reference: add_vertex may grow the point array it refers into
        // (heap-use-after-free found by the ASan suite).
        const Mesh::Point p = mesh.point(loop[i]);
        copy[i] = mesh.add_vertex(p);
        mesh.copy_all_properties(loop[i], copy[i]); // velocity and any caller property (not status)
        mesh.property(velocity, copy[i]) = mesh.property(velocity, loop[i]);
    }
    auto onRight = [&](VertexHandle x) {
        for (int i = 0; i < 3; ++i)
            if (x == loop[i]) return copy[i];
        return x;
    };

    bool ok = true;
    for (const auto& t : leftFaces)
        if (ok) ok = mesh.add_face(t[0], t[1], t[2]).is_valid();
    if (ok) ok = mesh.add_face(v, u, w).is_valid(); // left cap: halfedges v->u, u->w, w->v
    for (const auto& t : rightFaces)
        if (ok) ok = mesh.add_face(onRight(t[0]), onRight(t[1]), onRight(t[2])).is_valid();
    if (ok) ok = mesh.add_face(copy[0], copy[1], copy[2]).is_valid(); // right cap, reversed
    if (!ok) {
        mesh = backup;
        return false;
    }

    // Pull each cap a quarter of the way into its own side so the caps no longer coincide; less
    // when that would make faces cross (issue 17), and no cut when even a small pull would.
    const std::array<VertexHandle, 6> moved{u, v, w, copy[0], copy[1], copy[2]};
    std::array<Mesh::Point, 6> origin, centroid;
    for (int i = 0; i < 6; ++i) {
        origin[i] = centroid[i] = mesh.point(moved[i]);
        Mesh::Point sum(0, 0, 0);
        int count = 0;
        for (auto x : mesh.vv_range(moved[i])) {
            if (std::find(moved.begin(), moved.end(), x) != moved.end()) continue;
            sum += mesh.point(x);
            ++count;
        }
        if (count) centroid[i] = sum / count;
    }
    std::vector<FaceHandle> pulled;
    for (const VertexHandle x : moved)
        for (auto f : mesh.vf_range(x))
            if (std::find(pulled.begin(), pulled.end(), f) == pulled.end()) pulled.push_back(f);
    bool embedded = false;
    for (const double pull : {0.25, 0.1, 0.03}) {
        for (int i = 0; i < 6; ++i) mesh.set_point(moved[i], origin[i] + pull * (centroid[i] - origin[i]));
        if (!facesMeetMesh(mesh, pulled, minSeparation)) {
            embedded = true;
            break;
        }
    }
    if (!embedded) {
        mesh = backup;
        return false;
    }

    tagCut(mesh, std::vector<VertexHandle>(moved.begin(), moved.end()), 2);
    return true;
}

TopologyStats resolveTopology(Mesh& mesh, const std::vector<CollisionPair>& collisions,
                              const std::vector<TunnelCandidate>& tunnels, const TopologyOptions& options)
{
    TopologyStats stats;
    std::vector<char> touched(mesh.n_vertices(), 0);
    auto isTouched = [&](VertexHandle x) { return std::size_t(x.idx()) < touched.size() && touched[x.idx()]; };
    auto markTouched = [&](VertexHandle x) {
        if (std::size_t(x.idx()) >= touched.size()) touched.resize(mesh.n_vertices(), 0);
        touched[x.idx()] = 1;
    };
    auto isUsable = [&](VertexHandle x) { return isAlive(mesh, x) && !isTouched(x); };

    for (const TunnelCandidate& t : tunnels) {
        if (!isUsable(t.u) || !isUsable(t.v) || !isUsable(t.w)) { ++stats.rejected; continue; }
        const std::size_t before = mesh.n_vertices();
        if (!cutTunnel(mesh, t.u, t.v, t.w, options.minSeparation)) { ++stats.rejected; continue; }
        ++stats.cuts;
        std::vector<VertexHandle> changed{t.u, t.v, t.w};
        for (std::size_t i = before; i < mesh.n_vertices(); ++i) changed.push_back(VertexHandle(int(i)));
        for (auto x : changed) {
            markTouched(x);
            for (auto y : mesh.vv_range(x)) markTouched(y);
        }
    }

    std::vector<CollisionPair> order = collisions;
    std::stable_sort(order.begin(), order.end(),
                     [](const CollisionPair& x, const CollisionPair& y) { return x.distance < y.distance; });
    detail::BoundedPathSearch search;
    std::vector<VertexHandle> a, b;
    auto reject = [&](const CollisionPair& c) {
        ++stats.rejected;
        if (isAlive(mesh, c.u) && isAlive(mesh, c.w)) stats.unresolved.push_back(c);
    };
    std::vector<Triangle> band;
    for (const CollisionPair& c : order) {
        if (!isUsable(c.u) || !isUsable(c.w) || !findMergeBand(mesh, c.u, c.w, options.minSeparation, band)) {
            reject(c);
            continue;
        }
        if (stats.merges + stats.cuts > 0) {
            const double bound = options.neighbourhoodRadius > 0
                                     ? options.neighbourhoodRadius
                                     : 1.5 * (meanEdgeLengthAround(mesh, c.u) + meanEdgeLengthAround(mesh, c.w));
            if (search.isWithin(mesh, c.u, c.w, bound)) { reject(c); continue; }
        }
        collectLoop(mesh, c.u, a);
        collectLoop(mesh, c.w, b);
        if (!mergeWithBand(mesh, c.u, c.w, band)) { reject(c); continue; } // (the mesh is as the band found it)
        ++stats.merges;
        markTouched(c.u);
        markTouched(c.w);
        for (auto x : a) markTouched(x);
        for (auto x : b) markTouched(x);
    }
    return stats;
}

int removeSmallComponents(Mesh& mesh, std::size_t minVertices, double minVolume, std::size_t* largestInverted)
{
    if (largestInverted) *largestInverted = 0;
    int count = 0;
    const std::vector<int> label = componentLabels(mesh, &count);
    if (count <= 1 && minVertices <= 4 && minVolume <= 0) return 0;
    const std::vector<ComponentShape> shapes = componentShapes(mesh, label, count);
    std::vector<char> doomed(std::size_t(count), 0);
    int removed = 0;
    for (std::size_t i = 0; i < shapes.size(); ++i) {
        const ComponentShape& c = shapes[i];
        const bool small = c.vertices < minVertices || std::abs(c.volume) < minVolume;
        if (small || !c.outward()) {
            doomed[i] = 1;
            ++removed;
            if (!small && largestInverted) *largestInverted = std::max(*largestInverted, c.vertices);
        }
    }
    if (!removed) return 0;
    for (auto f : mesh.faces()) {
        if (doomed[label[faceVertices(mesh, f)[0].idx()]]) mesh.delete_face(f, true);
    }
    return removed;
}

} // namespace riemesh
