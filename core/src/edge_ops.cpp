// edge_ops.cpp: split, collapse and flip with the guards that keep a closed triangle mesh closed,
// oriented and 2-manifold (paper Fig. 1). No garbage_collection() here: deleted elements stay
// until the evolution compacts the mesh.
#include "riemesh/edge_ops.h"

#include "detail/edge_guards.h"
#include "riemesh/integration.h"

#include <algorithm>
#include <cmath>

namespace riemesh {

namespace detail {

bool isLiveEdge(const Mesh& mesh, EdgeHandle e)
{
    return e.is_valid() && std::size_t(e.idx()) < mesh.n_edges() && !mesh.status(e).deleted();
}

bool isLiveHalfedge(const Mesh& mesh, HalfedgeHandle h)
{
    return h.is_valid() && std::size_t(h.idx()) < mesh.n_halfedges() && !mesh.status(mesh.edge_handle(h)).deleted();
}

bool isInteriorEdge(const Mesh& mesh, EdgeHandle e)
{
    return !mesh.is_boundary(mesh.halfedge_handle(e, 0)) && !mesh.is_boundary(mesh.halfedge_handle(e, 1));
}

int valenceOf(const Mesh& mesh, VertexHandle v)
{
    int n = 0;
    for (auto h = mesh.cvoh_begin(v); h.is_valid(); ++h) ++n;
    return n;
}

namespace {

/// True when a triangle with these corners (world space) and twice-area `twiceArea` is degenerate:
/// tiny area, or a smallest angle with sine below kMinSine (conservatively: 2A <= kMinSine * longest^2).
bool isDegenerateTriangle(const Vec3& a, const Vec3& b, const Vec3& c, double twiceArea)
{
    if (!(twiceArea > kMinFaceDoubleArea)) return true;
    const double longest2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
    return !(twiceArea > kMinSine * longest2);
}

} // namespace

bool isFaceAcceptable(const Vec3& oldNormal, const Vec3& a, const Vec3& b, const Vec3& c)
{
    const Vec3 n = (b - a).cross(c - a);
    const double len = n.norm();
    if (isDegenerateTriangle(a, b, c, len)) return false;
    const double oldLen = oldNormal.norm();
    if (oldLen == 0.0) return true; // the old face was degenerate: any valid new one is an improvement
    return oldNormal.dot(n) > kMinNormalCosine * oldLen * len;
}

CollapseObstacles collapseObstacles(const Mesh& mesh, HalfedgeHandle h, const Vec3& target)
{
    CollapseObstacles obstacles = 0;
    if (!isLiveHalfedge(mesh, h) || !isInteriorEdge(mesh, mesh.edge_handle(h))) return kCollapseInvalid;
    const VertexHandle u = mesh.from_vertex_handle(h), v = mesh.to_vertex_handle(h);
    const VertexHandle a = mesh.to_vertex_handle(mesh.next_halfedge_handle(h));
    const HalfedgeHandle o = mesh.opposite_halfedge_handle(h);
    const VertexHandle b = mesh.to_vertex_handle(mesh.next_halfedge_handle(o));
    if (a == b || u == v) return kCollapseInvalid;

    // Link condition on a closed mesh: the only common neighbours of u and v are a and b.
    if (sharedOutsideNeighbour(mesh, h).is_valid()) obstacles |= kCollapseTunnel;

    // Valences: a and b lose one edge each, the kept vertex gets val(u) + val(v) - 4. A
    // tetrahedron component (all valences 3) is caught here as well: a would drop to 2.
    const int valU = valenceOf(mesh, u), valV = valenceOf(mesh, v);
    if (valenceOf(mesh, a) <= 3 || valenceOf(mesh, b) <= 3 || valU + valV - 4 < 3)
        obstacles |= kCollapseValence;
    if (valU == 3 && valV == 3) obstacles |= kCollapseTetrahedron; // with a, b of valence 3: a tetrahedron

    // Geometry: every face that survives around u or v, with u and v moved to `target`, keeps its
    // orientation (unit normals agree to kMinNormalCosine) and stays non-degenerate.
    const VertexHandle ends[2] = {u, v};
    for (int k = 0; k < 2; ++k) {
        const VertexHandle moved = ends[k], other = ends[1 - k];
        const Vec3 p = position(mesh, moved);
        for (auto oh = mesh.cvoh_begin(moved); oh.is_valid(); ++oh) {
            const HalfedgeHandle hh = *oh;
            if (!mesh.face_handle(hh).is_valid()) continue;
            const VertexHandle p1 = mesh.to_vertex_handle(hh);
            const VertexHandle p2 = mesh.to_vertex_handle(mesh.next_halfedge_handle(hh));
            if (p1 == other || p2 == other) continue; // one of the two faces that disappear
            const Vec3 q1 = position(mesh, p1), q2 = position(mesh, p2);
            const Vec3 oldNormal = (q1 - p).cross(q2 - p);
            if (!isFaceAcceptable(oldNormal, target, q1, q2)) {
                obstacles |= kCollapseGeometry;
                return obstacles;
            }
        }
    }
    return obstacles;
}

VertexHandle collapseUnchecked(Mesh& mesh, HalfedgeHandle h, const Vec3& target)
{
    const VertexHandle u = mesh.from_vertex_handle(h), v = mesh.to_vertex_handle(h);
    const auto velocity = velocityProperty(mesh);
    mesh.property(velocity, v) = 0.5 * (mesh.property(velocity, u) + mesh.property(velocity, v));
    mesh.collapse(h);
    mesh.set_point(v, toPoint(target));
    markEdited(mesh, {v}); // (u's faces and edges now end at v)
    return v;
}

bool isFlipAcceptable(const Mesh& mesh, EdgeHandle e, double minNewDihedralCosine)
{
    if (!isLiveEdge(mesh, e) || !isInteriorEdge(mesh, e)) return false;
    if (!mesh.is_flip_ok(e)) return false; // a != b and the edge a-b does not exist yet
    const HalfedgeHandle h = mesh.halfedge_handle(e, 0), o = mesh.halfedge_handle(e, 1);
    const VertexHandle u = mesh.from_vertex_handle(h), v = mesh.to_vertex_handle(h);
    const VertexHandle a = mesh.to_vertex_handle(mesh.next_halfedge_handle(h));
    const VertexHandle b = mesh.to_vertex_handle(mesh.next_halfedge_handle(o));
    if (valenceOf(mesh, u) <= 3 || valenceOf(mesh, v) <= 3) return false;
    const Vec3 pu = position(mesh, u), pv = position(mesh, v), pa = position(mesh, a), pb = position(mesh, b);
    // Old faces (u, v, a), (v, u, b); new faces (u, b, a), (b, v, a).
    const Vec3 oldSum = (pv - pu).cross(pa - pu) + (pu - pv).cross(pb - pv);
    const Vec3 n1 = (pb - pu).cross(pa - pu);
    const Vec3 n2 = (pv - pb).cross(pa - pb);
    const double l1 = n1.norm(), l2 = n2.norm();
    if (isDegenerateTriangle(pu, pb, pa, l1) || isDegenerateTriangle(pb, pv, pa, l2)) return false;
    // Folded: the new faces disagree with each other or with the old surface orientation.
    if (!(n1.dot(n2) > minNewDihedralCosine * l1 * l2)) return false;
    if (!(n1.dot(oldSum) > 0.0) || !(n2.dot(oldSum) > 0.0)) return false;
    return true;
}

void flipUnchecked(Mesh& mesh, EdgeHandle e)
{
    const HalfedgeHandle h = mesh.halfedge_handle(e, 0), o = mesh.halfedge_handle(e, 1);
    markEdited(mesh, {mesh.from_vertex_handle(h), mesh.to_vertex_handle(h), mesh.to_vertex_handle(mesh.next_halfedge_handle(h)),
                      mesh.to_vertex_handle(mesh.next_halfedge_handle(o))});
    mesh.flip(e);
}

} // namespace detail

bool canSplit(const Mesh& mesh, EdgeHandle e)
{
    return detail::isLiveEdge(mesh, e) && detail::isInteriorEdge(mesh, e);
}

VertexHandle split(Mesh& mesh, EdgeHandle e, const Vec3& position)
{
    if (!canSplit(mesh, e)) return VertexHandle();
    const HalfedgeHandle h = mesh.halfedge_handle(e, 0);
    const VertexHandle u = mesh.from_vertex_handle(h), v = mesh.to_vertex_handle(h);
    const auto velocity = velocityProperty(mesh);
    const OpenMesh::Vec3d mean = 0.5 * (mesh.property(velocity, u) + mesh.property(velocity, v));
    const VertexHandle w = mesh.add_vertex(toPoint(position));
    mesh.property(velocity, w) = mean;
    OpenMesh::VPropHandleT<TravelAnchors> anchors;
    if (mesh.get_property_handle(anchors, kTravelAnchorsProperty)) {
        const TravelAnchors a = mesh.property(anchors, u), b = mesh.property(anchors, v);
        TravelAnchors& c = mesh.property(anchors, w);
        c = TravelAnchors{};
        c.nowValid = a.nowValid && b.nowValid;
        c.beforeValid = a.beforeValid && b.beforeValid;
        for (int k = 0; k < 3; ++k) {
            c.now[k] = 0.5 * (a.now[k] + b.now[k]);
            c.before[k] = 0.5 * (a.before[k] + b.before[k]);
        }
    }
    mesh.split(e, w);
    markEdited(mesh, {u, v, w});
    return w;
}

VertexHandle sharedOutsideNeighbour(const Mesh& mesh, HalfedgeHandle h)
{
    if (!detail::isLiveHalfedge(mesh, h)) return VertexHandle();
    const VertexHandle u = mesh.from_vertex_handle(h), v = mesh.to_vertex_handle(h);
    const HalfedgeHandle o = mesh.opposite_halfedge_handle(h);
    const VertexHandle a =
        mesh.face_handle(h).is_valid() ? mesh.to_vertex_handle(mesh.next_halfedge_handle(h)) : VertexHandle();
    const VertexHandle b =
        mesh.face_handle(o).is_valid() ? mesh.to_vertex_handle(mesh.next_halfedge_handle(o)) : VertexHandle();
    // Valences are ~6: the nested walk is a few dozen steps and allocates nothing.
    for (auto wu = mesh.cvv_begin(u); wu.is_valid(); ++wu) {
        const VertexHandle w = *wu;
        if (w == v || w == a || w == b) continue;
        for (auto wv = mesh.cvv_begin(v); wv.is_valid(); ++wv)
            if (*wv == w) return w;
    }
    return VertexHandle();
}

bool canCollapse(const Mesh& mesh, HalfedgeHandle h, const Vec3& target)
{
    return detail::collapseObstacles(mesh, h, target) == 0;
}

VertexHandle collapse(Mesh& mesh, HalfedgeHandle h, const Vec3& target)
{
    if (!canCollapse(mesh, h, target)) return VertexHandle();
    return detail::collapseUnchecked(mesh, h, target);
}

bool canFlip(const Mesh& mesh, EdgeHandle e)
{
    return detail::isFlipAcceptable(mesh, e, 0.0);
}

void flip(Mesh& mesh, EdgeHandle e)
{
    if (!canFlip(mesh, e)) return;
    detail::flipUnchecked(mesh, e);
}

} // namespace riemesh
