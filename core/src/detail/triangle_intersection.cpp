// triangle_intersection.cpp: exact triangle-triangle tests from orientation predicates.
//
// Two non-coplanar closed triangles meet iff an edge of one meets the other (their common part
// is a segment on the line where the planes meet, and its ends lie on edges); coplanar ones are
// tested in the 2D projection that drops the dominant axis of the normal. Every decision is an
// orientation sign from detail/predicates.h, so the answers are exact for the double coordinates.
#include "detail/triangle_intersection.h"

#include "detail/predicates.h"
#include "riemesh/ccd.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace riemesh::detail {

namespace {

using Triangle = TriangleRef;

struct Point2 {
    double x, y;
};

Point2 project(const double* p, int axis) { return {p[(axis + 1) % 3], p[(axis + 2) % 3]}; }

int orient(const Point2& a, const Point2& b, const Point2& c) { return orient2d(a.x, a.y, b.x, b.y, c.x, c.y); }

bool mixedSigns(int a, int b, int c) { return (a > 0 || b > 0 || c > 0) && (a < 0 || b < 0 || c < 0); }

/// Collinear p on the closed segment [a, b] (coordinate-wise bounds: exact).
bool onSegment(const Point2& a, const Point2& b, const Point2& p)
{
    return std::min(a.x, b.x) <= p.x && p.x <= std::max(a.x, b.x) && std::min(a.y, b.y) <= p.y &&
           p.y <= std::max(a.y, b.y);
}

/// Closed segments [a, b] and [c, d] meet.
bool segmentsMeet(const Point2& a, const Point2& b, const Point2& c, const Point2& d)
{
    const int d1 = orient(c, d, a), d2 = orient(c, d, b), d3 = orient(a, b, c), d4 = orient(a, b, d);
    if (d1 * d2 < 0 && d3 * d4 < 0) return true;
    return (d1 == 0 && onSegment(c, d, a)) || (d2 == 0 && onSegment(c, d, b)) || (d3 == 0 && onSegment(a, b, c)) ||
           (d4 == 0 && onSegment(a, b, d));
}

/// p in the closed (non-degenerate) triangle t.
bool inTriangle(const Point2& p, const std::array<Point2, 3>& t)
{
    return !mixedSigns(orient(t[0], t[1], p), orient(t[1], t[2], p), orient(t[2], t[0], p));
}

std::array<Point2, 3> project(const Triangle& t, int axis)
{
    return {project(t.p[0], axis), project(t.p[1], axis), project(t.p[2], axis)};
}

/// Closed segment [a, b] and closed triangle t, all in one plane (projected).
bool segmentMeetsTriangle2d(const Point2& a, const Point2& b, const std::array<Point2, 3>& t)
{
    if (inTriangle(a, t) || inTriangle(b, t)) return true;
    for (int i = 0; i < 3; ++i)
        if (segmentsMeet(a, b, t[i], t[(i + 1) % 3])) return true;
    return false;
}

/// Closed coplanar triangles s and t meet (projected on `axis`).
bool trianglesMeet2d(const Triangle& s, const Triangle& t, int axis)
{
    const auto ps = project(s, axis), pt = project(t, axis);
    for (int i = 0; i < 3; ++i)
        if (segmentMeetsTriangle2d(ps[i], ps[(i + 1) % 3], pt)) return true;
    return inTriangle(pt[0], ps); // t inside s
}

/// Closed segment [a, b] meets closed triangle t; oa, ob = orient3d(t, a), orient3d(t, b).
bool segmentMeetsTriangle(const double* a, const double* b, int oa, int ob, const Triangle& t)
{
    if (oa * ob > 0) return false;
    if (oa == 0 && ob == 0) return segmentMeetsTriangle2d(project(a, t.axis), project(b, t.axis), project(t, t.axis));
    // The segment crosses the plane at one point; it lies in the closed triangle iff the line a-b
    // passes on the same side of the three edge lines (no two orientations of opposite sign).
    return !mixedSigns(orient3d(a, b, t.p[0], t.p[1]), orient3d(a, b, t.p[1], t.p[2]), orient3d(a, b, t.p[2], t.p[0]));
}

/// Sides of s's corners with respect to t's plane.
std::array<int, 3> sides(const Triangle& s, const Triangle& t)
{
    return {orient3d(t.p[0], t.p[1], t.p[2], s.p[0]), orient3d(t.p[0], t.p[1], t.p[2], s.p[1]),
            orient3d(t.p[0], t.p[1], t.p[2], s.p[2])};
}

bool allStrictlyOneSide(const std::array<int, 3>& o)
{
    return (o[0] > 0 && o[1] > 0 && o[2] > 0) || (o[0] < 0 && o[1] < 0 && o[2] < 0);
}

/// Two non-degenerate closed triangles with no shared vertex meet.
bool trianglesMeetImpl(const Triangle& s, const Triangle& t)
{
    const auto os = sides(s, t);
    if (allStrictlyOneSide(os)) return false;
    const auto ot = sides(t, s);
    if (allStrictlyOneSide(ot)) return false;
    if (os[0] == 0 && os[1] == 0 && os[2] == 0) return trianglesMeet2d(s, t, t.axis);
    for (int i = 0; i < 3; ++i) {
        const int j = (i + 1) % 3;
        if (segmentMeetsTriangle(s.p[i], s.p[j], os[i], os[j], t)) return true;
        if (segmentMeetsTriangle(t.p[i], t.p[j], ot[i], ot[j], s)) return true;
    }
    return false;
}

/// x (in the plane of s, c, d) lies in the closed cone of the corner s of triangle (s, c, d),
/// other than at s: the edge s-x and that triangle overlap beyond s.
bool inCorner(const double* s, const double* c, const double* d, const double* x, int axis)
{
    const Point2 ps = project(s, axis), pc = project(c, axis), pd = project(d, axis), px = project(x, axis);
    const int turn = orient(ps, pc, pd);
    return orient(ps, pc, px) * turn >= 0 && orient(ps, px, pd) * turn >= 0;
}

/// Triangles (s, a, b) and (s, c, d) sharing only the vertex s have a common point other than s.
/// Their common part is convex and contains s; its far end lies on the edge a-b or c-d, or is
/// reached along an edge from s that lies in the other triangle's plane and inside its corner.
bool sharedVertexFold(const Triangle& t1, const Triangle& t2)
{
    const double *s = t1.p[0], *a = t1.p[1], *b = t1.p[2], *c = t2.p[1], *d = t2.p[2];
    const int oa = orient3d(s, c, d, a), ob = orient3d(s, c, d, b);
    if (oa * ob > 0) return false; // t1 on one side of t2's plane: only s in common
    const int oc = orient3d(s, a, b, c), od = orient3d(s, a, b, d);
    if (oc * od > 0) return false;
    if (oa == 0 && ob == 0) // coplanar: the corners at s overlap iff a side of one is in the other
        return inCorner(s, c, d, a, t1.axis) || inCorner(s, c, d, b, t1.axis) || inCorner(s, a, b, c, t1.axis) ||
               inCorner(s, a, b, d, t1.axis);
    if (segmentMeetsTriangle(a, b, oa, ob, t2) || segmentMeetsTriangle(c, d, oc, od, t1)) return true;
    return (oa == 0 && inCorner(s, c, d, a, t2.axis)) || (ob == 0 && inCorner(s, c, d, b, t2.axis)) ||
           (oc == 0 && inCorner(s, a, b, c, t1.axis)) || (od == 0 && inCorner(s, a, b, d, t1.axis));
}

/// Triangles (a, b, c) and (a, b, d) sharing the edge a-b overlap beyond it: d exactly in the plane
/// of the first, on c's side of the edge.
bool sharedEdgeFold(const Triangle& t1, const double* d)
{
    const double *a = t1.p[0], *b = t1.p[1], *c = t1.p[2];
    if (orient3d(a, b, c, d) != 0) return false;
    const Point2 pa = project(a, t1.axis), pb = project(b, t1.axis);
    return orient(pa, pb, project(c, t1.axis)) * orient(pa, pb, project(d, t1.axis)) > 0;
}

} // namespace

/// The projection axis of triangle (a, b, c): the largest normal component (checked exactly),
/// or -1 when the corners are exactly collinear.
int projectionAxis(const double* a, const double* b, const double* c)
{
    const Eigen::Vector3d pa(a[0], a[1], a[2]), pb(b[0], b[1], b[2]), pc(c[0], c[1], c[2]);
    const Eigen::Vector3d n = (pb - pa).cross(pc - pa);
    std::array<int, 3> axes = {0, 1, 2};
    std::sort(axes.begin(), axes.end(), [&](int i, int j) { return std::abs(n[i]) > std::abs(n[j]); });
    for (int axis : axes)
        if (orient(project(a, axis), project(b, axis), project(c, axis)) != 0) return axis;
    return -1;
}

bool trianglesMeet(const TriangleRef& a, const TriangleRef& b) { return trianglesMeetImpl(a, b); }

/// Classifies faces i and j by their shared vertices and runs the matching exact test.
TriangleContact classifyTriangles(const std::array<int, 3>& vi, const TriangleRef& ti, const std::array<int, 3>& vj,
                                  const TriangleRef& tj)
{
    int shared = 0, si = -1, sj = -1;
    for (int x = 0; x < 3; ++x)
        for (int y = 0; y < 3; ++y)
            if (vi[x] == vj[y]) {
                ++shared;
                si = x;
                sj = y;
            }
    if (shared == 0) return trianglesMeet(ti, tj) ? TriangleContact::Crossing : TriangleContact::None;
    if (shared == 3) return TriangleContact::EdgeFold; // two faces on the same corners
    // Rotate so that the shared vertex comes first (one shared), or the unshared one last (two).
    auto rotated = [](const Triangle& t, int first) {
        return Triangle{{t.p[first], t.p[(first + 1) % 3], t.p[(first + 2) % 3]}, t.axis};
    };
    if (shared == 1) return sharedVertexFold(rotated(ti, si), rotated(tj, sj)) ? TriangleContact::VertexFold : TriangleContact::None;
    int freeI = 0, freeJ = 0;
    for (int x = 0; x < 3; ++x) {
        if (std::find(vj.begin(), vj.end(), vi[x]) == vj.end()) freeI = x;
        if (std::find(vi.begin(), vi.end(), vj[x]) == vi.end()) freeJ = x;
    }
    return sharedEdgeFold(rotated(ti, (freeI + 1) % 3), tj.p[freeJ]) ? TriangleContact::EdgeFold : TriangleContact::None;
}

bool separatedBeyondShared(const std::array<int, 3>& ia, const double* const a[3], const std::array<int, 3>& ib,
                           const double* const b[3], double r)
{
    using V = Eigen::Vector3d;
    auto at = [](const double* p) { return V(p[0], p[1], p[2]); };
    // Which corners are shared: sa[i] = the corner of b equal to a's corner i, or -1.
    int sa[3] = {-1, -1, -1}, shared = 0;
    bool inB[3] = {false, false, false};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            if (ia[std::size_t(i)] == ib[std::size_t(j)]) sa[i] = j, inB[j] = true, ++shared;
    if (shared == 3) return false;
    // The plane: through `origin`, normal m (unit); a's free corners must be beyond r on the side
    // m points to, b's on the other.
    V origin, m;
    int free = 0, freeB = 0; // with a shared edge: the corner of a, and of b, off it
    if (shared == 2) {
        while (sa[free] >= 0) ++free;
        while (inB[freeB]) ++freeB;
    }
    double scale = 0; // the coordinates' magnitude, for the rounding bound
    for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) scale = std::max(scale, std::max(std::abs(a[i][k]), std::abs(b[i][k])));
    if (shared == 0) {
        const V ca = (at(a[0]) + at(a[1]) + at(a[2])) / 3.0, cb = (at(b[0]) + at(b[1]) + at(b[2])) / 3.0;
        m = ca - cb;
        origin = 0.5 * (ca + cb);
    } else if (shared == 1) {
        int s = 0;
        while (sa[s] < 0) ++s;
        origin = at(a[s]);
        // Away from b's free corners, toward a's: the difference of the unit directions from the
        // shared corner to the midpoints of the free edges.
        const V ua = (0.5 * (at(a[(s + 1) % 3]) + at(a[(s + 2) % 3])) - origin).normalized();
        V mb = V::Zero();
        for (int j = 0; j < 3; ++j)
            if (!inB[j]) mb += 0.5 * at(b[j]);
        const V ub = (mb - origin).normalized();
        m = ua - ub;
    } else {
        const int e0 = (free + 1) % 3;
        origin = at(a[e0]);
        const V e = at(a[(free + 2) % 3]) - origin;
        const double e2 = e.squaredNorm();
        if (!(e2 > 0)) return false;
        // Each free corner's direction from the shared edge, orthogonal to it; the plane contains
        // the edge and bisects the two.
        auto across = [&](const V& p) {
            const V d = p - origin;
            return V(d - (d.dot(e) / e2) * e).normalized();
        };
        m = across(at(a[free])) - across(at(b[freeB]));
    }
    const double len = m.norm();
    if (!(len > 0) || !std::isfinite(len)) return false;
    // Rounding of the margins (a few operations on coordinates of magnitude `scale`), with room.
    // The margins along m as it is, against need times its length (m is not made unit).
    const double need = r * (1 + 1e-9) + 1e-12 * (scale + 1), needLen = need * len;
    double height[3] = {0, 0, 0}; // (a's free corners' margins, in units of len: for the edges below)
    for (int i = 0; i < 3; ++i)
        if (sa[i] < 0 && !((height[i] = m.dot(at(a[i]) - origin)) > needLen)) return false;
    double heightB = 0;
    for (int j = 0; j < 3; ++j)
        if (!inB[j] && !((heightB = -m.dot(at(b[j]) - origin)) > needLen)) return false;
    if (shared == 2) {
        // Each edge from a free corner to one end of the shared edge, against the one from the
        // other free corner to the other end: they share no vertex, and both reach the plane (at
        // different points). A point of the first at a fraction t of the way from its end on the
        // plane is t ha from the plane (ha: the free corner's margin), one of the second s hb:
        // closer than `need` only where t < need / ha and s < need / hb, hence at least
        // L - need (la / ha + lb / hb) apart (L: the shared edge's length; la, lb: the edges').
        // That bound (halved, for its rounding) settles most; the others are measured.
        const double L = (at(a[(free + 1) % 3]) - at(a[(free + 2) % 3])).norm();
        for (int k = 1; k <= 2; ++k) {
            const int ea = (free + k) % 3;       // a's corner at one end of the shared edge
            const int eb = (free + 3 - k) % 3;   // a's corner at the other end: b's corner sa[eb]
            const double la = (at(a[free]) - at(a[ea])).norm(), lb = (at(b[freeB]) - at(b[sa[eb]])).norm();
            if (0.5 * L > need * (1 + len * (la / height[free] + lb / heightB))) continue;
            const double d2 = segmentSegmentDistanceSquared(at(a[free]), at(a[ea]), at(b[freeB]), at(b[sa[eb]]));
            if (!(std::sqrt(d2) > need)) return false;
        }
    }
    return true;
}

} // namespace riemesh::detail
