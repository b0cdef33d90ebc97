// ccd.cpp: distances, Additive CCD and the collision-safe step (see riemesh/ccd.h); the broad
// phase is a hashed grid of swept boxes (detail/box_grid.h).
#include "riemesh/ccd.h"

#include "detail/box_grid.h"
#include "detail/parallel.h"
#include "detail/triangle_intersection.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace riemesh {

namespace {

using detail::Box6;

double clamp01(double x) { return x < 0 ? 0 : (x > 1 ? 1 : x); }

double pointSegmentDistanceSquared(const Vec3& p, const Vec3& a, const Vec3& b)
{
    const Vec3 ab = b - a;
    const double len2 = ab.squaredNorm();
    const double t = len2 > 0 ? clamp01((p - a).dot(ab) / len2) : 0.0;
    return (a + t * ab - p).squaredNorm();
}

/// ACCD's iterations give up (and report a contact at the time reached) after this many.
constexpr int kMaxAccdIterations = 2000;

/// Additive CCD (Li et al. 2021, Algorithm 1) over the four points x (start) moving by d: the first
/// `split` points form one primitive, the rest the other; `distance` gives their distance.
template <class Distance>
CcdResult additiveCcd(std::array<Vec3, 4> x, std::array<Vec3, 4> d, int split, double eta, double s, Distance distance)
{
    CcdResult result;
    const Vec3 mean = 0.25 * (d[0] + d[1] + d[2] + d[3]);
    double lp0 = 0, lp1 = 0;
    for (int i = 0; i < 4; ++i) {
        d[i] -= mean;
        (i < split ? lp0 : lp1) = std::max(i < split ? lp0 : lp1, d[i].norm());
    }
    const double lp = lp0 + lp1;
    if (!(lp > 0)) return result; // no relative motion (or not finite: nothing sensible to do)
    double dist = distance(x);
    if (!(dist > 0)) return {true, 0.0};
    // Closer than eta already (rounding, or an edit of the mesh left them so): they may close in
    // by 0.1% at most (pressed together for 3000 iterations, they keep 5% of their distance).
    const double xi = dist > eta ? eta : 0.999 * dist;
    const double gap = s * (dist - xi);
    double t = 0;
    double tl = (1 - s) * (dist - xi) / lp;
    for (int it = 0; it < kMaxAccdIterations; ++it) {
        for (int i = 0; i < 4; ++i) x[i] += tl * d[i];
        dist = distance(x);
        if (t > 0 && dist - xi < gap) return {true, t};
        t += tl;
        if (t > 1) return result;
        tl = 0.9 * (dist - xi) / lp;
    }
    return {true, t};
}

/// The vertex indices of face f, in its halfedge order.
std::array<int, 3> faceIds(const Mesh& mesh, FaceHandle f)
{
    const HalfedgeHandle h = mesh.halfedge_handle(f);
    return {mesh.from_vertex_handle(h).idx(), mesh.to_vertex_handle(h).idx(),
            mesh.to_vertex_handle(mesh.next_halfedge_handle(h)).idx()};
}

/// The vertex indices of edge e, from and to its first halfedge.
std::array<int, 2> edgeIds(const Mesh& mesh, EdgeHandle e)
{
    const HalfedgeHandle h = mesh.halfedge_handle(e, 0);
    return {mesh.from_vertex_handle(h).idx(), mesh.to_vertex_handle(h).idx()};
}

/// The vertex indices of every live face and edge, in index order.
void collectPrimitives(const Mesh& mesh, std::vector<std::array<int, 3>>& faces, std::vector<std::array<int, 2>>& edges)
{
    faces.clear();
    for (auto f : mesh.faces()) faces.push_back(faceIds(mesh, f));
    edges.clear();
    for (auto e : mesh.edges()) edges.push_back(edgeIds(mesh, e));
}

/// Queries per chunk of the broad phase (see findInChunks). Small: a cached step queries a few
/// hundred dirty vertices, faces and edges, which chunks of 512 left to one thread (phantom 100^3,
/// guarded, 2 threads: the steps' checks 74 -> 65 ms in all; the chunks' lists are appended in order, so
/// the candidates are the same for any chunk size).
constexpr std::size_t kQueryChunk = 64;

/// Elements per chunk of the per-element passes.
constexpr std::size_t kPassGrain = 2048;

/// detail::forLive in chunks of kPassGrain.
template <class Handle, class Fn>
void forLive(const Mesh& mesh, std::size_t count, Fn&& fn)
{
    detail::forLive<Handle>(mesh, count, kPassGrain, fn);
}

} // namespace

double pointTriangleDistanceSquared(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c)
{
    // Ericson, Real-Time Collision Detection 5.1.5, by Voronoi regions.
    const Vec3 ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) return ap.squaredNorm();
    const Vec3 bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) return bp.squaredNorm();
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        const double den = d1 - d3;
        const double v = den > 0 ? d1 / den : 0.0;
        return (a + v * ab - p).squaredNorm();
    }
    const Vec3 cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) return cp.squaredNorm();
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        const double den = d2 - d6;
        const double w = den > 0 ? d2 / den : 0.0;
        return (a + w * ac - p).squaredNorm();
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
        const double den = (d4 - d3) + (d5 - d6);
        const double w = den > 0 ? (d4 - d3) / den : 0.0;
        return (b + w * (c - b) - p).squaredNorm();
    }
    const double den = va + vb + vc;
    if (!(den > 0)) // a degenerate triangle: its edges
        return std::min({pointSegmentDistanceSquared(p, a, b), pointSegmentDistanceSquared(p, b, c),
                         pointSegmentDistanceSquared(p, c, a)});
    const double v = vb / den, w = vc / den;
    const double inside = (a + v * ab + w * ac - p).squaredNorm();
    // Round-off near a needle: never report more than the distance to an edge.
    return std::min({inside, pointSegmentDistanceSquared(p, a, b), pointSegmentDistanceSquared(p, b, c),
                     pointSegmentDistanceSquared(p, c, a)});
}

double segmentSegmentDistanceSquared(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1)
{
    // Ericson 5.1.9, with the parallel and degenerate cases.
    const Vec3 d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
    const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
    if (!(a > 0) && !(e > 0)) return r.squaredNorm();
    if (!(a > 0)) return pointSegmentDistanceSquared(p0, q0, q1);
    if (!(e > 0)) return pointSegmentDistanceSquared(q0, p0, p1);
    const double c = d1.dot(r), b = d1.dot(d2);
    const double denom = a * e - b * b;
    double s = denom > 1e-14 * a * e ? clamp01((b * f - c * e) / denom) : 0.0;
    double t = (b * s + f) / e;
    if (t < 0) {
        t = 0;
        s = clamp01(-c / a);
    } else if (t > 1) {
        t = 1;
        s = clamp01((b - c) / a);
    }
    const double closest = (p0 + s * d1 - (q0 + t * d2)).squaredNorm();
    if (denom > 1e-14 * a * e) return closest;
    // Nearly parallel: the closest pair may be at any endpoint.
    return std::min({closest, pointSegmentDistanceSquared(p0, q0, q1), pointSegmentDistanceSquared(p1, q0, q1),
                     pointSegmentDistanceSquared(q0, p0, p1), pointSegmentDistanceSquared(q1, p0, p1)});
}

CcdResult pointTriangleCcd(const Vec3& p0, const Vec3& a0, const Vec3& b0, const Vec3& c0, const Vec3& p1,
                           const Vec3& a1, const Vec3& b1, const Vec3& c1, double eta, double gapFraction)
{
    return additiveCcd({p0, a0, b0, c0}, {p1 - p0, a1 - a0, b1 - b0, c1 - c0}, 1, eta, gapFraction,
                       [](const std::array<Vec3, 4>& x) {
                           return std::sqrt(pointTriangleDistanceSquared(x[0], x[1], x[2], x[3]));
                       });
}

CcdResult edgeEdgeCcd(const Vec3& p0, const Vec3& q0, const Vec3& r0, const Vec3& s0, const Vec3& p1,
                      const Vec3& q1, const Vec3& r1, const Vec3& s1, double eta, double gapFraction)
{
    return additiveCcd({p0, q0, r0, s0}, {p1 - p0, q1 - q0, r1 - r0, s1 - s0}, 2, eta, gapFraction,
                       [](const std::array<Vec3, 4>& x) {
                           return std::sqrt(segmentSegmentDistanceSquared(x[0], x[1], x[2], x[3]));
                       });
}

namespace {

/// A candidate pair of the step: kind (0: vertex v[0] against face (v[1], v[2], v[3]); 1: edge
/// (v[0], v[1]) against edge (v[2], v[3])), then the four vertex indices.
using Quad = std::array<int, 5>;

/// What the pair tests of one step need: the positions at its start and end, how far each vertex
/// moves, and the minimal separation.
struct StepGeometry {
    const std::vector<Vec3>& start;
    const std::vector<Vec3>& end;
    const std::vector<double>& reach;
    double eta;

    /// The box swept by the k vertices v from start to end, grown by r.
    Box6 sweep(const int* v, int k, double r) const
    {
        constexpr double inf = std::numeric_limits<double>::infinity();
        Box6 b = {inf, inf, inf, -inf, -inf, -inf};
        for (int i = 0; i < k; ++i) {
            const Vec3& s = start[std::size_t(v[i])];
            const Vec3& e = end[std::size_t(v[i])];
            for (int c = 0; c < 3; ++c) {
                b[c] = std::min({b[c], s[c], e[c]});
                b[c + 3] = std::max({b[c + 3], s[c], e[c]});
            }
        }
        for (int c = 0; c < 3; ++c) b[c] -= r, b[c + 3] += r;
        return b;
    }
    Box6 vertexBox(int i) const { return sweep(&i, 1, 0.0); }
    Box6 faceBox(const std::array<int, 3>& t) const { return sweep(t.data(), 3, eta); }
    Box6 edgeBox(const std::array<int, 2>& x) const { return sweep(x.data(), 2, 0.5 * eta); }

    bool outOfReach(double distanceSquared, double motion) const
    {
        const double r = motion + eta;
        return distanceSquared > r * r * 1.0000001;
    }
    /// Can vertex i come within eta of face t during the step (i not a corner of t)? A pair whose
    /// distance at the start exceeds eta by more than the longest motions of both primitives
    /// together cannot, however its vertices' motions are shortened (most pairs: most vertices
    /// barely move).
    bool vertexFace(int i, const std::array<int, 3>& t) const
    {
        const double motion = reach[std::size_t(i)] + std::max({reach[std::size_t(t[0])], reach[std::size_t(t[1])],
                                                                 reach[std::size_t(t[2])]});
        if (motion == 0) return false;
        // A cheap lower bound first: the distance to the centroid less the farthest corner's.
        const Vec3& p = start[std::size_t(i)];
        const Vec3& a = start[std::size_t(t[0])];
        const Vec3& b = start[std::size_t(t[1])];
        const Vec3& c = start[std::size_t(t[2])];
        const Vec3 centroid = (a + b + c) / 3.0;
        const double radius = std::sqrt(std::max({(a - centroid).squaredNorm(), (b - centroid).squaredNorm(),
                                                  (c - centroid).squaredNorm()}));
        if ((p - centroid).norm() - radius > (motion + eta) * 1.0000001) return false;
        return !outOfReach(pointTriangleDistanceSquared(p, a, b, c), motion);
    }
    /// The same for edges x and y (sharing no vertex).
    bool edgeEdge(const std::array<int, 2>& x, const std::array<int, 2>& y) const
    {
        const double motion = std::max(reach[std::size_t(x[0])], reach[std::size_t(x[1])]) +
                              std::max(reach[std::size_t(y[0])], reach[std::size_t(y[1])]);
        if (motion == 0) return false;
        // A cheap lower bound first: the midpoints' distance less the half lengths.
        const Vec3& a0 = start[std::size_t(x[0])];
        const Vec3& a1 = start[std::size_t(x[1])];
        const Vec3& b0 = start[std::size_t(y[0])];
        const Vec3& b1 = start[std::size_t(y[1])];
        const double bound = 0.5 * ((a0 + a1 - b0 - b1).norm() - (a1 - a0).norm() - (b1 - b0).norm());
        if (bound > (motion + eta) * 1.0000001) return false;
        return !outOfReach(segmentSegmentDistanceSquared(a0, a1, b0, b1), motion);
    }
};

bool hasCorner(const std::array<int, 3>& t, int i) { return t[0] == i || t[1] == i || t[2] == i; }
bool shareVertex(const std::array<int, 2>& x, const std::array<int, 2>& y)
{
    return x[0] == y[0] || x[0] == y[1] || x[1] == y[0] || x[1] == y[1];
}
Quad vertexFaceQuad(int i, const std::array<int, 3>& t) { return {0, i, t[0], t[1], t[2]}; }
Quad edgeEdgeQuad(const std::array<int, 2>& x, const std::array<int, 2>& y) { return {1, x[0], x[1], y[0], y[1]}; }
/// The grids' cell size: the mean over `count` faces of their swept boxes' largest side
/// (`extents`, their sum).
double boxExtent(const Box6& b) { return std::max({b[3] - b[0], b[4] - b[1], b[5] - b[2]}); }
double cellSize(double extents, std::size_t count) { return std::max(extents / double(count), 1e-9); }

/// Runs query(i, found) for i in [0, count) in parallel, in fixed chunks of kQueryChunk indices,
/// each appending to its own list; the lists are then appended to `out` in chunk order, so that
/// `out` is the same, in the same order, for any thread count.
template <class T, class Query>
void findInChunks(std::size_t count, std::vector<std::vector<T>>& lists, std::vector<T>& out, Query&& query)
{
    const std::size_t chunks = (count + kQueryChunk - 1) / kQueryChunk;
    if (lists.size() < chunks) lists.resize(chunks);
    detail::parallelFor(0, chunks, 1, [&](std::size_t c) {
        std::vector<T>& found = lists[c];
        found.clear();
        for (std::size_t i = c * kQueryChunk, e = std::min(count, i + kQueryChunk); i < e; ++i) query(i, found);
    });
    for (std::size_t c = 0; c < chunks; ++c) out.insert(out.end(), lists[c].begin(), lists[c].end());
}

/// Builds the grids of the vertices', the faces' and the edges' boxes in one frame (cells of
/// `cell`, see PackedBoxGrid::frameFor), to be paired, each on a thread of its own when there
/// are several.
detail::PackedBoxGrid::Frame buildGridsToPair(const std::vector<Box6>& vertexBoxes, detail::PackedBoxGrid& vertexGrid,
                                              const std::vector<Box6>& faceBoxes, detail::PackedBoxGrid& faceGrid,
                                              const std::vector<Box6>& edgeBoxes, detail::PackedBoxGrid& edgeGrid,
                                              double cell)
{
    const auto frame = detail::PackedBoxGrid::frameFor({&vertexBoxes, &faceBoxes, &edgeBoxes}, cell);
    const std::array<std::pair<const std::vector<Box6>*, detail::PackedBoxGrid*>, 3> jobs = {
        {{&edgeBoxes, &edgeGrid}, {&faceBoxes, &faceGrid}, {&vertexBoxes, &vertexGrid}}};
    detail::parallelFor(0, jobs.size(), 1, [&](std::size_t k) { jobs[k].second->build(*jobs[k].first, frame); });
    return frame;
}

/// Grid entries per chunk of pairInChunks: the grids of a step from scratch and of an anchoring.
constexpr std::size_t kPairChunk = 1024;
/// The same for the few hundred to few thousand entries of a cached step's dirty primitives
/// (collect), which chunks of 1024 left to one thread: head MRI, guarded, 2 threads, the dirty
/// edges' pairs 13.8 -> 10.3 ms in all (the same pairs in the same order: see pairInChunks).
constexpr std::size_t kDirtyPairChunk = 128;

/// Runs pairs(e0, e1, found) over a grid's entries [0, entries) in parallel, in fixed chunks of
/// `chunk` entries, each appending to its own list; the lists are then appended to `out` in
/// chunk order (the same for any thread count or chunk size, as findInChunks).
template <class T, class Pairs>
void pairInChunks(std::size_t entries, std::vector<std::vector<T>>& lists, std::vector<T>& out, Pairs&& pairs,
                  std::size_t chunk = kPairChunk)
{
    const std::size_t chunks = (entries + chunk - 1) / chunk;
    if (lists.size() < chunks) lists.resize(chunks);
    detail::parallelFor(0, chunks, 1, [&](std::size_t c) {
        std::vector<T>& found = lists[c];
        found.clear();
        pairs(c * chunk, std::min(entries, (c + 1) * chunk), found);
    });
    for (std::size_t c = 0; c < chunks; ++c) out.insert(out.end(), lists[c].begin(), lists[c].end());
}

/// Every vertex-face pair of two grids and edge-edge pair of the third built to be paired
/// (buildGridsToPair) whose boxes overlap, large ones included: vertexFace(vertex item, face
/// item, list) and edgeEdge(edge item, later edge item, list), appending to `out` through lists
/// kept per chunk (pairInChunks).
template <class T, class VertexFace, class EdgeEdge>
void pairAll(const detail::PackedBoxGrid& vertexGrid, const detail::PackedBoxGrid& faceGrid,
             const detail::PackedBoxGrid& edgeGrid, std::vector<std::vector<T>>& lists, std::vector<T>& out,
             VertexFace&& vertexFace, EdgeEdge&& edgeEdge)
{
    pairInChunks(vertexGrid.entries(), lists, out, [&](std::size_t e0, std::size_t e1, std::vector<T>& found) {
        detail::PackedBoxGrid::pairsAcross(vertexGrid, faceGrid, e0, e1, [&](int k, int f) { vertexFace(k, f, found); });
    });
    pairInChunks(edgeGrid.entries(), lists, out, [&](std::size_t e0, std::size_t e1, std::vector<T>& found) {
        edgeGrid.pairsWithin(e0, e1, [&](int e, int h) { edgeEdge(e, h, found); });
    });
    detail::PackedBoxGrid::pairsWithLarge(vertexGrid, faceGrid, [&](int k, int f) { vertexFace(k, f, out); });
    edgeGrid.pairsWithLarge([&](int e, int h) { edgeEdge(e, h, out); });
}

/// The broad phase of one step from scratch: every vertex-face and edge-edge pair whose swept
/// boxes (the face's grown by eta, the edges' by eta / 2 each) overlap and that is within reach.
/// The pairs of boxes come from pairing the grids cell by cell (PackedBoxGrid::pairsAcross and
/// pairsWithin), not from a query per vertex and per edge (each cell's entries scanned by every
/// query meeting it).
/// Phantom 100^3, one thread: the edge-edge pairs of its 22 steps from scratch in 9.5 ms instead
/// of 15.9, the collision-safe steps in 415 M instructions instead of 518 M (with the same
/// pairing at the anchorings, SafeStepCache::Impl::rebuild).
void allCandidates(const StepGeometry& g, const std::vector<int>& live, const std::vector<std::array<int, 3>>& faces,
                   const std::vector<std::array<int, 2>>& edges, double cell, std::vector<Box6>& vertexBox,
                   std::vector<Box6>& faceBox, std::vector<Box6>& edgeBox, std::array<detail::PackedBoxGrid, 3>& grids,
                   std::vector<std::vector<Quad>>& lists, std::vector<Quad>& candidates)
{
    vertexBox.resize(live.size());
    detail::parallelFor(0, live.size(), kPassGrain, [&](std::size_t k) { vertexBox[k] = g.vertexBox(live[k]); });
    faceBox.resize(faces.size());
    detail::parallelFor(0, faces.size(), kPassGrain, [&](std::size_t f) { faceBox[f] = g.faceBox(faces[f]); });
    edgeBox.resize(edges.size());
    detail::parallelFor(0, edges.size(), kPassGrain, [&](std::size_t e) { edgeBox[e] = g.edgeBox(edges[e]); });
    detail::PackedBoxGrid& vertexGrid = grids[0];
    detail::PackedBoxGrid& faceGrid = grids[1];
    detail::PackedBoxGrid& edgeGrid = grids[2];
    buildGridsToPair(vertexBox, vertexGrid, faceBox, faceGrid, edgeBox, edgeGrid, cell);
    auto vertexFace = [&](int k, int f, std::vector<Quad>& found) {
        const int i = live[std::size_t(k)];
        const auto& t = faces[std::size_t(f)];
        // (the grid's float boxes are a little larger: the exact boxes decide)
        if (!hasCorner(t, i) && detail::boxesOverlap(vertexBox[std::size_t(k)], faceBox[std::size_t(f)]) &&
            g.vertexFace(i, t))
            found.push_back(vertexFaceQuad(i, t));
    };
    auto edgeEdge = [&](int e, int h, std::vector<Quad>& found) { // (e < h)
        const auto& x = edges[std::size_t(e)];
        const auto& y = edges[std::size_t(h)];
        if (!shareVertex(x, y) && detail::boxesOverlap(edgeBox[std::size_t(e)], edgeBox[std::size_t(h)]) && g.edgeEdge(x, y))
            found.push_back(edgeEdgeQuad(x, y));
    };
    pairAll(vertexGrid, faceGrid, edgeGrid, lists, candidates, vertexFace, edgeEdge);
}

} // namespace

/// Every vertex's clearance at the last rebuild (positions "anchor"), and the grids of that time's
/// primitives, grown so that they still cover every primitive whose vertices have drifted less
/// than half the clearance radius since (see SafeStepCache in riemesh/ccd.h).
struct SafeStepCache::Impl {
    bool valid = false;
    /// The faces' mean extent at the rebuild (the grids' cells are SafeStepOptions::anchoredCell times it).
    double cell = 0;
    std::size_t vertices0 = 0, faces0 = 0, edges0 = 0; ///< element counts (with deleted ones) at the rebuild
    std::vector<Vec3> anchor;                          ///< positions at the rebuild, by vertex index
    std::vector<std::array<int, 3>> faceAt0;           ///< faces' corners at the rebuild, by face index
    std::vector<std::array<int, 2>> edgeAt0;
    /// By vertex index: how far it may drift from its anchor and stay clean (half its clearance
    /// less eta: the smallest distance, at the rebuild, of the vertex-face and edge-edge pairs it
    /// belongs to, at most C), squared.
    std::vector<double> allowed2;
    detail::PackedBoxGrid vertexGrid, faceGrid, edgeGrid;
    detail::PackedBoxGrid::Frame frame;        ///< theirs (a step's dirty primitives are paired with them)
    std::vector<int> vertexOf, faceOf, edgeOf; ///< grid item -> element index
    std::size_t rebuilds = 0;

    int chi0 = 0; ///< the Euler characteristic at the rebuild (kept until the next: see candidates)
    double radius = 0, eta = 0; ///< C and eta at the rebuild

    // Anchored again since the rebuild (settle): by element index, moved (its entry in the grids
    // above is stale; its current anchored box is in the overlay grid, by element index, if it is
    // registered), and how many faces and edges moved. A vertex whose anchor is a position:
    // anchored. faceAt0 / edgeAt0 hold {-1, ...} for an element not registered (never clean).
    std::vector<char> movedV, movedF, movedE, anchored;
    std::size_t movedFacesEdges = 0;
    detail::BoxGrid overVertexGrid, overFaceGrid, overEdgeGrid;
    std::vector<int> settleV, settleF, settleE;

    // This step's state. faceNow, edgeNow and the boxes are filled for every element at a rebuild
    // and for the dirty ones otherwise (the others' corners are faceAt0's, edgeAt0's).
    std::vector<std::array<int, 3>> faceNow; ///< corners by face index ({-1, -1, -1}: deleted)
    std::vector<std::array<int, 2>> edgeNow;
    std::vector<Box6> faceBox, edgeBox; ///< swept boxes by index (grown as in allCandidates)
    std::vector<char> cleanV;
    std::vector<int> dirtyV, dirtyF, dirtyE, seeds;
    std::size_t liveV = 0; ///< live vertices (classify's count)
    /// Stamps by face and edge index: looked at in this step's classify (seen), found dirty.
    std::vector<unsigned> seenF, seenE, dirtyAtF, dirtyAtE;
    unsigned stamp = 0;
    std::vector<Box6> dirtyBox;
    std::array<std::vector<Box6>, 3> anchoredBoxes; ///< the rebuild's boxes (vertices, faces, edges)
    detail::PackedBoxGrid dirtyGrid, dirtyVertexGrid; ///< (collect's, of this step's dirty primitives)
    struct Near { ///< a pair closer than C at the rebuild: its four vertices and distance
        std::array<int, 4> v;
        double d;
    };
    std::vector<std::vector<Near>> nearLists;
    std::vector<Near> near;
    std::vector<double> clearance;
    std::vector<std::vector<Quad>> lists;

    void candidates(Mesh& mesh, const StepGeometry& g, const SafeStepOptions& options, std::vector<Quad>& out,
                    SafeStepStats& stats);
    void anchorHere(Mesh& mesh, const StepGeometry& g, const SafeStepOptions& options);
    /// Anchors anew where the step leaves the vertices (see candidates()): what the rebuild
    /// reads is noted here, the rebuild runs beside the rest of the iteration.
    void anchorAfter(Mesh& mesh, const StepGeometry& g, const SafeStepOptions& options);
    /// Notes what a rebuild reads of the mesh (faceNow, edgeNow, liveVertices, the counts) and
    /// this step's swept face boxes; returns their mean extent (the cell, see rebuild).
    double noteForRebuild(const Mesh& mesh, const StepGeometry& g);
    /// Marks no vertex edited: the edits so far are in the rebuild's faceAt0 and edgeAt0.
    static void clearEdited(Mesh& mesh);
    void rebuild(const std::vector<Vec3>& anchors, double eta, double cell, double radiusFraction, double gridCell);
    std::vector<int> liveVertices;          ///< (noteForRebuild's)
    std::size_t notedV = 0, notedF = 0, notedE = 0; ///< element counts, deleted ones included (noteForRebuild's)
    bool rebuildAfter = false;              ///< this step anchors anew after it (see candidates())
    void classify(const Mesh& mesh, const StepGeometry& g);
    void collect(const Mesh& mesh, const StepGeometry& g, std::vector<Quad>& candidates);
    void settle(Mesh& mesh, const StepGeometry& g, double motion, const SafeStepOptions& options, SafeStepStats& stats);
    /// Sizes the per-element arrays for the mesh as it is now (elements made since the rebuild).
    void grow(const Mesh& mesh);
    /// Notes the faces and edges of the vertices settledNow, so that registering them again
    /// (anchorAgain) does not read the mesh; noteDeleted() notes which elements are deleted, for a
    /// measurement made while the mesh changes (measureAgain(nullptr)).
    void noteStars(const Mesh& mesh);
    void noteDeleted(const Mesh& mesh);
    /// Anchors the vertices settleV at settleAt and registers their faces and edges as noted
    /// (settleK: their places in settledNow); measureAgain() then measures their pairs again and
    /// lowers the allowed drifts to match (see settle), skipping the elements deleted in `mesh`
    /// (nullptr: in the notes).
    void anchorAgain();
    void measureAgain(const Mesh* mesh);
    /// Those of settledNow (just anchored ahead of their positions baseAt, by index) that their
    /// anchor leaves out of their allowed drift (a pair closer there than where they are: sheets
    /// pressed together, which a vertex cut short by a collision does not show): anchored again
    /// where they are (anchorAgain). Two spheres pressed together (ccd_test): anchored anew at 37
    /// of 80 steps without this, 23 with it, 27 with no anchor ahead.
    void withdrawAhead(const Mesh* mesh);
    std::vector<Vec3> settleAt, baseAt; ///< (scratch)
    std::vector<int> settledNow;        ///< (scratch)
    std::vector<std::size_t> settleK;   ///< (scratch)
    struct Star { ///< a vertex's faces and edges in starFaces and starEdges (noteStars)
        std::size_t f0 = 0, f1 = 0, e0 = 0, e1 = 0;
    };
    std::vector<Star> stars;
    std::vector<std::pair<int, std::array<int, 3>>> starFaces;
    std::vector<std::pair<int, std::array<int, 2>>> starEdges;
    std::vector<char> deadV, deadF, deadE;
    std::size_t notedFaces = 0, notedEdges = 0;
    /// Runs measureAgain() and withdrawAhead() beside the rest of the iteration (see settle);
    /// every other use of the cache waits for it first (finish()).
    detail::Background background;
    void finish() { background.wait(); }
    ~Impl() { finish(); } // (before any member the job uses goes)
    /// Where a vertex at `at` that has moved by `motion` in this step is anchored (see
    /// SafeStepOptions::anchorAhead): further along that motion, by at most `most` (world units).
    static Vec3 anchorAheadOf(const Vec3& at, const Vec3& motion, double most, const SafeStepOptions& options)
    {
        const double length = motion.norm();
        if (!(length > 0) || !(most > 0)) return at;
        return at + motion * std::min(options.anchorAhead, most / length);
    }
    std::vector<Vec3> ahead; ///< anchorHere's anchors (scratch)
    /// The allowed drift of a vertex with no pair closer than C: (C - eta) / 2, a hair less.
    double largestDrift() const { return 0.5 * (radius - eta) * (1 - 1e-9); }
    /// Clean: registered, is live, and no dirty or edited vertex is one of its corners.
    bool cleanFace(const Mesh& mesh, std::size_t f) const
    {
        return f < faceAt0.size() && faceAt0[f][0] >= 0 && dirtyAtF[f] != stamp &&
               !mesh.status(FaceHandle(int(f))).deleted();
    }
    bool cleanEdge(const Mesh& mesh, std::size_t e) const
    {
        return e < edgeAt0.size() && edgeAt0[e][0] >= 0 && dirtyAtE[e] != stamp &&
               !mesh.status(EdgeHandle(int(e))).deleted();
    }
    /// A stamp no element carries yet (classify's and settle's marks of this pass).
    void nextStamp()
    {
        if (++stamp != 0) return;
        // (wrapped: forget every stamp)
        std::fill(seenF.begin(), seenF.end(), 0u), std::fill(dirtyAtF.begin(), dirtyAtF.end(), 0u);
        std::fill(seenE.begin(), seenE.end(), 0u), std::fill(dirtyAtE.begin(), dirtyAtE.end(), 0u);
        stamp = 1;
    }
    /// The box around the anchors of the k vertices v, grown by `grow`.
    Box6 anchoredBox(const int* v, int k, double grow) const
    {
        constexpr double inf = std::numeric_limits<double>::infinity();
        Box6 b = {inf, inf, inf, -inf, -inf, -inf};
        for (int i = 0; i < k; ++i)
            for (int c = 0; c < 3; ++c) {
                b[c] = std::min(b[c], anchor[std::size_t(v[i])][c] - grow);
                b[c + 3] = std::max(b[c + 3], anchor[std::size_t(v[i])][c] + grow);
            }
        return b;
    }
    /// f(element) for every registered vertex, face or edge whose anchored box (grown as in the
    /// grids) overlaps q: the rebuild's grid less the moved elements, and the overlay.
    template <class F>
    static void queryAnchored(const detail::PackedBoxGrid& grid, const std::vector<int>& of,
                              const std::vector<char>& moved, const detail::BoxGrid& overlay, const Box6& q, F&& f)
    {
        grid.query(q, [&](int item) {
            const int x = of[std::size_t(item)];
            if (!moved[std::size_t(x)]) f(x);
        });
        overlay.query(q, f);
    }
    template <class F>
    void queryVertices(const Box6& q, F&& f) const { queryAnchored(vertexGrid, vertexOf, movedV, overVertexGrid, q, f); }
    template <class F>
    void queryFaces(const Box6& q, F&& f) const { queryAnchored(faceGrid, faceOf, movedF, overFaceGrid, q, f); }
    template <class F>
    void queryEdges(const Box6& q, F&& f) const { queryAnchored(edgeGrid, edgeOf, movedE, overEdgeGrid, q, f); }
};

SafeStepCache::SafeStepCache() : mImpl(std::make_unique<Impl>()) {}
SafeStepCache::~SafeStepCache() = default;
SafeStepCache::SafeStepCache(SafeStepCache&&) noexcept = default;
SafeStepCache& SafeStepCache::operator=(SafeStepCache&&) noexcept = default;
void SafeStepCache::invalidate()
{
    mImpl->finish();
    mImpl->valid = false;
}
std::size_t SafeStepCache::rebuilds() const
{
    mImpl->finish();
    return mImpl->rebuilds;
}

void SafeStepCache::Impl::candidates(Mesh& mesh, const StepGeometry& g, const SafeStepOptions& options,
                                     std::vector<Quad>& out, SafeStepStats& stats)
{
    // First use, or renumbered (garbage collection: invalidate(), or noticed by the counts):
    // anchor here. Otherwise anchor again when the primitives out of their clearance are too many.
    OpenMesh::VPropHandleT<char> edited;
    bool rebuilt = false;
    if (!valid || mesh.n_vertices() < vertices0 || mesh.n_faces() < faces0 || mesh.n_edges() < edges0 ||
        !mesh.get_property_handle(edited, kEditedProperty)) {
        anchorHere(mesh, g, options);
        rebuilt = true;
    }
    classify(mesh, g);
    // The live faces and edges without a pass over them: split, collapse and flip keep the Euler
    // characteristic, and any other edit is followed by garbage collection and invalidate(); on
    // a closed triangle mesh E = 3 (V - chi) and F = 2 (V - chi).
    // (Or when options.reanchorFraction of them have been anchored again since, see settle.)
    const double liveFacesEdges = 5.0 * (double(liveV) - double(chi0));
    if (!rebuilt && double(dirtyF.size() + dirtyE.size()) > options.rebuildFraction * liveFacesEdges) {
        anchorHere(mesh, g, options);
        classify(mesh, g);
        rebuilt = true;
    }
    // Many anchored again (a surface at rest, its vertices leaving their drifts one by one):
    // this step is searched with the cache as it is, and the mesh anchored anew after it, beside
    // the rest of the iteration (the dirty primitives, few, do not make this step dearer). The
    // same candidates that can collide, so the same step. Head MRI, guarded, 2 threads: the three
    // rebuilds at rest made the regularity step wait for the collision-safe step 6.1-6.2 ms each.
    rebuildAfter = !rebuilt && double(movedFacesEdges) > options.reanchorFraction * liveFacesEdges;
    stats.rebuilt = rebuilt || rebuildAfter;
    stats.dirty = dirtyF.size() + dirtyE.size();
    collect(mesh, g, out);
}

double SafeStepCache::Impl::noteForRebuild(const Mesh& mesh, const StepGeometry& g)
{
    faceNow.assign(mesh.n_faces(), {-1, -1, -1});
    faceBox.resize(mesh.n_faces());
    forLive<FaceHandle>(mesh, mesh.n_faces(), [&](std::size_t i) {
        faceNow[i] = faceIds(mesh, FaceHandle(int(i)));
        faceBox[i] = g.faceBox(faceNow[i]);
    });
    edgeNow.assign(mesh.n_edges(), {-1, -1});
    forLive<EdgeHandle>(mesh, mesh.n_edges(), [&](std::size_t i) { edgeNow[i] = edgeIds(mesh, EdgeHandle(int(i))); });
    std::size_t liveFaces = 0;
    double extent = 0;
    for (std::size_t i = 0; i < faceNow.size(); ++i)
        if (faceNow[i][0] >= 0) {
            ++liveFaces;
            extent += boxExtent(faceBox[i]);
        }
    liveVertices.clear();
    for (auto v : mesh.vertices()) liveVertices.push_back(v.idx());
    notedV = mesh.n_vertices();
    notedF = mesh.n_faces();
    notedE = mesh.n_edges();
    return cellSize(extent, std::max<std::size_t>(liveFaces, 1));
}

void SafeStepCache::Impl::clearEdited(Mesh& mesh)
{
    OpenMesh::VPropHandleT<char> edited;
    if (!mesh.get_property_handle(edited, kEditedProperty)) mesh.add_property(edited, kEditedProperty);
    for (auto v : mesh.all_vertices()) mesh.property(edited, v) = 0;
}

void SafeStepCache::Impl::anchorHere(Mesh& mesh, const StepGeometry& g, const SafeStepOptions& options)
{
    const double cell = noteForRebuild(mesh, g);
    // The anchors: where the vertices start this step, ahead along their motion (see settle).
    const double most = options.anchorAheadFraction * 0.5 * (options.clearance * cell - g.eta);
    ahead.resize(mesh.n_vertices());
    forLive<VertexHandle>(mesh, mesh.n_vertices(), [&](std::size_t i) {
        ahead[i] = anchorAheadOf(g.start[i], g.end[i] - g.start[i], most, options);
    });
    rebuild(ahead, g.eta, cell, options.clearance, options.anchoredCell * cell);
    clearEdited(mesh);
}

void SafeStepCache::Impl::anchorAfter(Mesh& mesh, const StepGeometry& g, const SafeStepOptions& options)
{
    rebuildAfter = false;
    const double cell = noteForRebuild(mesh, g);
    // The anchors: where the step left the vertices, ahead along their motion unless it was cut
    // short (as settle anchors them again).
    const double most = options.anchorAheadFraction * 0.5 * (options.clearance * cell - g.eta);
    ahead.resize(mesh.n_vertices());
    forLive<VertexHandle>(mesh, mesh.n_vertices(), [&](std::size_t i) {
        const Vec3 at = position(mesh, VertexHandle(int(i)));
        ahead[i] = at == g.end[i] ? anchorAheadOf(at, at - g.start[i], most, options) : at;
    });
    clearEdited(mesh);
    const double eta = g.eta, radiusFraction = options.clearance, gridCell = options.anchoredCell * cell;
    background.run([this, eta, cell, radiusFraction, gridCell] { rebuild(ahead, eta, cell, radiusFraction, gridCell); });
}

void SafeStepCache::Impl::rebuild(const std::vector<Vec3>& anchors, double eta, double cell, double radiusFraction,
                                  double gridCell)
{
    ++rebuilds;
    valid = true;
    this->cell = cell;
    const double C = radiusFraction * cell; // the clearance radius: clearances are measured up to it
    // A vertex's clearance k is the smallest distance, here, of the vertex-face and edge-edge pairs
    // (sharing no vertex) it belongs to, or C if none is closer. While every vertex of a pair stays
    // within (k - eta) / 2 of its anchor, for its own k, the pair stays farther apart than eta: its
    // distance here is at least the larger k of its vertices, and each of its two primitives moves
    // away from where it was by at most the largest drift of its vertices (a point of a face or an
    // edge is a fixed combination of its vertices). So a pair of clean primitives needs no test.
    // The grids hold the anchored boxes grown by the largest drift (C / 2) and eta as
    // allCandidates grows them, so that they cover the swept boxes of every clean primitive.
    vertices0 = notedV;
    faces0 = notedF;
    edges0 = notedE;
    radius = C;
    this->eta = eta;
    anchor.assign(anchors.begin(), anchors.begin() + std::ptrdiff_t(vertices0));
    anchored.assign(vertices0, 1);
    faceAt0 = faceNow;
    edgeAt0 = edgeNow;
    movedV.assign(vertices0, 0);
    movedF.assign(faces0, 0);
    movedE.assign(edges0, 0);
    movedFacesEdges = 0;
    overVertexGrid.reset(gridCell, 1024, vertices0);
    overFaceGrid.reset(gridCell, 4096, faces0);
    overEdgeGrid.reset(gridCell, 4096, edges0);
    const double faceGrow = 0.5 * C + eta, edgeGrow = 0.5 * C + 0.5 * eta;
    vertexOf.clear();
    anchoredBoxes[0].clear();
    for (const int i : liveVertices) {
        vertexOf.push_back(i);
        anchoredBoxes[0].push_back(anchoredBox(&i, 1, 0.5 * C));
    }
    auto boxesOf = [&](const auto& corners, std::vector<int>& of, std::vector<Box6>& boxes, double grow) {
        of.clear();
        boxes.clear();
        for (std::size_t x = 0; x < corners.size(); ++x)
            if (corners[x][0] >= 0) { // (live)
                of.push_back(int(x));
                boxes.push_back(anchoredBox(corners[x].data(), int(corners[x].size()), grow));
            }
    };
    boxesOf(faceAt0, faceOf, anchoredBoxes[1], faceGrow);
    boxesOf(edgeAt0, edgeOf, anchoredBoxes[2], edgeGrow);
    frame = buildGridsToPair(anchoredBoxes[0], vertexGrid, anchoredBoxes[1], faceGrid, anchoredBoxes[2], edgeGrid,
                             gridCell);
    // The pairs closer than C: those whose boxes overlap (grown by C / 2 and eta, they meet
    // wherever the primitives are within C + eta), measured.
    const double C2 = C * C;
    near.clear();
    auto vertexFace = [&](int item, int faceItem, std::vector<Near>& found) {
        const int i = vertexOf[std::size_t(item)];
        const auto& t = faceAt0[std::size_t(faceOf[std::size_t(faceItem)])];
        if (hasCorner(t, i)) return;
        const double d2 = pointTriangleDistanceSquared(anchor[std::size_t(i)], anchor[std::size_t(t[0])],
                                                       anchor[std::size_t(t[1])], anchor[std::size_t(t[2])]);
        if (d2 < C2) found.push_back({{i, t[0], t[1], t[2]}, std::sqrt(d2)});
    };
    auto edgeEdge = [&](int item, int other, std::vector<Near>& found) {
        const auto& x = edgeAt0[std::size_t(edgeOf[std::size_t(item)])];
        const auto& y = edgeAt0[std::size_t(edgeOf[std::size_t(other)])];
        if (shareVertex(x, y)) return;
        const double d2 = segmentSegmentDistanceSquared(anchor[std::size_t(x[0])], anchor[std::size_t(x[1])],
                                                        anchor[std::size_t(y[0])], anchor[std::size_t(y[1])]);
        if (d2 < C2) found.push_back({{x[0], x[1], y[0], y[1]}, std::sqrt(d2)});
    };
    pairAll(vertexGrid, faceGrid, edgeGrid, nearLists, near, vertexFace, edgeEdge);
    clearance.assign(vertices0, C);
    for (const Near& n : near)
        for (int v : n.v) clearance[std::size_t(v)] = std::min(clearance[std::size_t(v)], n.d);
    allowed2.assign(vertices0, 0.0);
    for (std::size_t i = 0; i < vertices0; ++i) {
        const double drift = 0.5 * (clearance[i] - eta) * (1 - 1e-9);
        allowed2[i] = drift > 0 ? drift * drift : -1.0; // (-1: never clean)
    }
    chi0 = int(vertexOf.size()) - int(edgeOf.size()) + int(faceOf.size()); // (the grids hold the live elements)
}

void SafeStepCache::Impl::settle(Mesh& mesh, const StepGeometry& g, double motion, const SafeStepOptions& options,
                                 SafeStepStats& stats)
{
    // The vertices searched this step (out of their clearance, or edited) that have come to rest
    // are anchored again where they end (or ahead, see below), with their faces and edges as they
    // are now: they are clean from the next step on instead of until the next rebuild. Every pair
    // of a registered vertex and face, or of two registered edges, sharing no vertex, keeps a
    // distance at their anchors of at least eta + the largest allowed drift of each one's corners
    // (which is what makes a pair of clean elements safe, see rebuild). The pairs with an element
    // that changes here are measured again, and every corner of a pair closer than C has its
    // allowed drift lowered to match (the rest already allow no more than (C - eta) / 2).
    // Registering takes the mesh; measuring the pairs does not (it reads what was noted here), so
    // on several threads it runs beside the rest of the iteration (the regularity step, mostly
    // sequential) and is waited for at the next use of the cache. Head MRI, guarded, 2 threads,
    // four alternating runs: the integration phase 0.252-0.259 -> 0.234-0.243 s, the regularity
    // phase 0.253-0.261 -> 0.259-0.263 s (the two share the cores), the evolution 2% shorter.
    grow(mesh);
    settleV.clear();
    for (const int i : seeds) {
        const VertexHandle v(i);
        if (mesh.status(v).deleted() || (position(mesh, v) - g.start[std::size_t(i)]).squaredNorm() > motion * motion)
            continue;
        settleV.push_back(i);
    }
    stats.settled = settleV.size();
    if (settleV.empty()) return;
    // Ahead along this step's motion (SafeStepOptions::anchorAhead; not a vertex whose motion was
    // cut short, held against another sheet): slowly creeping vertices, most of those anchored
    // again on the head MRI at rest, leave their drift later.
    const double most = largestDrift();
    settleAt.clear();
    baseAt.resize(std::max(baseAt.size(), mesh.n_vertices()));
    for (const int i : settleV) {
        const Vec3 at = position(mesh, VertexHandle(i));
        baseAt[std::size_t(i)] = at;
        const bool whole = at == g.end[std::size_t(i)]; // (not cut short)
        settleAt.push_back(whole ? anchorAheadOf(at, at - g.start[std::size_t(i)], options.anchorAheadFraction * most, options)
                                 : at);
    }
    settledNow = settleV;
    noteStars(mesh);
    settleK.resize(settleV.size());
    for (std::size_t k = 0; k < settleK.size(); ++k) settleK[k] = k;
    OpenMesh::VPropHandleT<char> edited;
    if (mesh.get_property_handle(edited, kEditedProperty))
        for (const int i : settleV) mesh.property(edited, VertexHandle(i)) = 0; // (their faces and edges are registered)
    anchorAgain();
    if (!background.concurrent()) { // (on one thread: no notes of the deleted elements needed)
        measureAgain(&mesh);
        withdrawAhead(&mesh);
        return;
    }
    noteDeleted(mesh);
    background.run([this] {
        measureAgain(nullptr);
        withdrawAhead(nullptr);
    });
}

void SafeStepCache::Impl::noteStars(const Mesh& mesh)
{
    starFaces.clear();
    starEdges.clear();
    stars.clear();
    for (const int i : settledNow) {
        const VertexHandle v(i);
        Star star;
        star.f0 = starFaces.size();
        for (auto f = mesh.cvf_begin(v); f.is_valid(); ++f) starFaces.push_back({f->idx(), faceIds(mesh, *f)});
        star.f1 = starFaces.size();
        star.e0 = starEdges.size();
        for (auto e = mesh.cve_begin(v); e.is_valid(); ++e) starEdges.push_back({e->idx(), edgeIds(mesh, *e)});
        star.e1 = starEdges.size();
        stars.push_back(star);
    }
    notedFaces = mesh.n_faces();
    notedEdges = mesh.n_edges();
}

void SafeStepCache::Impl::noteDeleted(const Mesh& mesh)
{
    deadV.resize(mesh.n_vertices());
    for (std::size_t i = 0; i < deadV.size(); ++i) deadV[i] = mesh.status(VertexHandle(int(i))).deleted();
    deadF.resize(mesh.n_faces());
    for (std::size_t i = 0; i < deadF.size(); ++i) deadF[i] = mesh.status(FaceHandle(int(i))).deleted();
    deadE.resize(mesh.n_edges());
    for (std::size_t i = 0; i < deadE.size(); ++i) deadE[i] = mesh.status(EdgeHandle(int(i))).deleted();
}

void SafeStepCache::Impl::grow(const Mesh& mesh)
{
    const std::size_t nv = mesh.n_vertices(), nf = mesh.n_faces(), ne = mesh.n_edges();
    anchor.resize(std::max(anchor.size(), nv), Vec3::Zero());
    allowed2.resize(std::max(allowed2.size(), nv), -1.0);
    anchored.resize(std::max(anchored.size(), nv), 0);
    movedV.resize(std::max(movedV.size(), nv), 0);
    faceAt0.resize(std::max(faceAt0.size(), nf), {-1, -1, -1});
    movedF.resize(std::max(movedF.size(), nf), 0);
    edgeAt0.resize(std::max(edgeAt0.size(), ne), {-1, -1});
    movedE.resize(std::max(movedE.size(), ne), 0);
}

void SafeStepCache::Impl::withdrawAhead(const Mesh* mesh)
{
    settleV.clear();
    settleAt.clear();
    settleK.clear();
    for (std::size_t k = 0; k < settledNow.size(); ++k) {
        const std::size_t i = std::size_t(settledNow[k]);
        if (anchor[i] == baseAt[i]) continue;
        if ((baseAt[i] - anchor[i]).squaredNorm() < allowed2[i]) continue;
        settleV.push_back(int(i));
        settleAt.push_back(baseAt[i]);
        settleK.push_back(k);
    }
    if (settleV.empty()) return;
    anchorAgain();
    measureAgain(mesh);
}

void SafeStepCache::Impl::anchorAgain()
{
    const double most = largestDrift();
    for (std::size_t k = 0; k < settleV.size(); ++k) {
        const int i = settleV[k];
        anchor[std::size_t(i)] = settleAt[k];
        anchored[std::size_t(i)] = 1;
        allowed2[std::size_t(i)] = most > 0 ? most * most : -1.0;
        movedV[std::size_t(i)] = 1;
        overVertexGrid.insert(i, anchoredBox(&i, 1, 0.5 * radius));
    }
    // Their faces and edges, each once, registered as they were noted (unless a corner has no
    // anchor yet: then not registered, and so never clean, until it has).
    nextStamp();
    seenF.resize(std::max(seenF.size(), notedFaces), 0u);
    seenE.resize(std::max(seenE.size(), notedEdges), 0u);
    settleF.clear();
    settleE.clear();
    auto registrable = [&](const int* c, int k) {
        for (int j = 0; j < k; ++j)
            if (!anchored[std::size_t(c[j])]) return false;
        return true;
    };
    for (const std::size_t k : settleK) {
        const Star& star = stars[k];
        for (std::size_t s = star.f0; s < star.f1; ++s) {
            const std::size_t x = std::size_t(starFaces[s].first);
            const std::array<int, 3>& t = starFaces[s].second;
            if (seenF[x] == stamp) continue;
            seenF[x] = stamp;
            faceAt0[x] = registrable(t.data(), 3) ? t : std::array<int, 3>{-1, -1, -1};
            movedFacesEdges += !movedF[x];
            movedF[x] = 1;
            if (faceAt0[x][0] < 0) {
                overFaceGrid.erase(int(x));
                continue;
            }
            overFaceGrid.insert(int(x), anchoredBox(t.data(), 3, 0.5 * radius + eta));
            settleF.push_back(int(x));
        }
        for (std::size_t s = star.e0; s < star.e1; ++s) {
            const std::size_t x = std::size_t(starEdges[s].first);
            const std::array<int, 2>& c = starEdges[s].second;
            if (seenE[x] == stamp) continue;
            seenE[x] = stamp;
            edgeAt0[x] = registrable(c.data(), 2) ? c : std::array<int, 2>{-1, -1};
            movedFacesEdges += !movedE[x];
            movedE[x] = 1;
            if (edgeAt0[x][0] < 0) {
                overEdgeGrid.erase(int(x));
                continue;
            }
            overEdgeGrid.insert(int(x), anchoredBox(c.data(), 2, 0.5 * radius + 0.5 * eta));
            settleE.push_back(int(x));
        }
    }
}

void SafeStepCache::Impl::measureAgain(const Mesh* mesh)
{
    // The pairs closer than C with a vertex, face or edge registered here (some twice: the lower
    // drift is the same).
    const double C = radius, C2 = C * C;
    // Deleted elements: from the mesh, or from the notes taken before the iteration went on.
    auto dead = [&](auto handle, const std::vector<char>& noted) {
        const std::size_t x = std::size_t(handle.idx());
        return mesh ? mesh->status(handle).deleted() : x < noted.size() && noted[x];
    };
    near.clear();
    findInChunks(settleV.size(), nearLists, near, [&](std::size_t k, std::vector<Near>& found) {
        const int i = settleV[k];
        const Vec3& p = anchor[std::size_t(i)];
        queryFaces(anchoredBox(&i, 1, std::max(0.0, 0.5 * C - eta)), [&](int f) {
            const auto& t = faceAt0[std::size_t(f)];
            if (t[0] < 0 || hasCorner(t, i) || dead(FaceHandle(f), deadF)) return;
            const double d2 = pointTriangleDistanceSquared(p, anchor[std::size_t(t[0])], anchor[std::size_t(t[1])],
                                                           anchor[std::size_t(t[2])]);
            if (d2 < C2) found.push_back({{i, t[0], t[1], t[2]}, std::sqrt(d2)});
        });
    });
    findInChunks(settleF.size(), nearLists, near, [&](std::size_t k, std::vector<Near>& found) {
        const auto& t = faceAt0[std::size_t(settleF[k])];
        queryVertices(anchoredBox(t.data(), 3, 0.5 * C), [&](int i) {
            if (hasCorner(t, i) || !anchored[std::size_t(i)] || dead(VertexHandle(i), deadV)) return;
            const double d2 = pointTriangleDistanceSquared(anchor[std::size_t(i)], anchor[std::size_t(t[0])],
                                                           anchor[std::size_t(t[1])], anchor[std::size_t(t[2])]);
            if (d2 < C2) found.push_back({{i, t[0], t[1], t[2]}, std::sqrt(d2)});
        });
    });
    findInChunks(settleE.size(), nearLists, near, [&](std::size_t k, std::vector<Near>& found) {
        const auto& x = edgeAt0[std::size_t(settleE[k])];
        queryEdges(anchoredBox(x.data(), 2, std::max(0.0, 0.5 * C - 0.5 * eta)), [&](int h) {
            const auto& y = edgeAt0[std::size_t(h)];
            if (y[0] < 0 || shareVertex(x, y) || dead(EdgeHandle(h), deadE)) return;
            const double d2 = segmentSegmentDistanceSquared(anchor[std::size_t(x[0])], anchor[std::size_t(x[1])],
                                                            anchor[std::size_t(y[0])], anchor[std::size_t(y[1])]);
            if (d2 < C2) found.push_back({{x[0], x[1], y[0], y[1]}, std::sqrt(d2)});
        });
    });
    for (const Near& n : near) {
        const double drift = 0.5 * (n.d - eta) * (1 - 1e-9);
        const double d2 = drift > 0 ? drift * drift : -1.0;
        for (const int v : n.v) allowed2[std::size_t(v)] = std::min(allowed2[std::size_t(v)], d2);
    }
}

void SafeStepCache::Impl::classify(const Mesh& mesh, const StepGeometry& g)
{
    nextStamp();
    // The vertices' flags in parallel, then the dirty ones in index order.
    cleanV.assign(mesh.n_vertices(), 0);
    forLive<VertexHandle>(mesh, mesh.n_vertices(), [&](std::size_t i) {
        cleanV[i] = i < allowed2.size() && (g.start[i] - anchor[i]).squaredNorm() < allowed2[i] &&
                    (g.end[i] - anchor[i]).squaredNorm() < allowed2[i];
    });
    OpenMesh::VPropHandleT<char> edited;
    const bool marks = mesh.get_property_handle(edited, kEditedProperty);
    dirtyV.clear();
    seeds.clear();
    liveV = 0;
    for (std::size_t i = 0; i < cleanV.size(); ++i) {
        const VertexHandle v{int(i)};
        if (mesh.status(v).deleted()) continue;
        ++liveV;
        if (!cleanV[i]) dirtyV.push_back(int(i));
        if (!cleanV[i] || (marks && mesh.property(edited, v))) seeds.push_back(int(i));
    }
    // Faces and edges: clean when they existed at the rebuild with the same corners, all clean.
    // Only those around a dirty or an edited vertex can be anything else (kEditedProperty): they
    // are looked at, each once, in the order of their first such corner, then sorted.
    const std::size_t nf = mesh.n_faces(), ne = mesh.n_edges();
    for (auto* x : {&seenF, &dirtyAtF}) x->resize(std::max(x->size(), nf), 0u);
    for (auto* x : {&seenE, &dirtyAtE}) x->resize(std::max(x->size(), ne), 0u);
    faceNow.resize(std::max(faceNow.size(), nf)); // (each its own: a rebuild sizes some of them)
    edgeNow.resize(std::max(edgeNow.size(), ne));
    movedF.resize(std::max(movedF.size(), nf), 0);
    movedE.resize(std::max(movedE.size(), ne), 0);
    faceBox.resize(std::max(faceBox.size(), nf));
    edgeBox.resize(std::max(edgeBox.size(), ne));
    auto clean = [&](const int* v, int k) {
        for (int i = 0; i < k; ++i)
            if (!cleanV[std::size_t(v[i])]) return false;
        return true;
    };
    dirtyF.clear();
    dirtyE.clear();
    auto lookAtFace = [&](FaceHandle fh) {
        const std::size_t f = std::size_t(fh.idx());
        if (seenF[f] == stamp || mesh.status(fh).deleted()) return;
        seenF[f] = stamp;
        const std::array<int, 3> t = faceIds(mesh, fh);
        if (f < faceAt0.size() && faceAt0[f][0] >= 0) {
            if (t == faceAt0[f]) {
                if (clean(t.data(), 3)) return;
            } else { // edited: no longer registered (its pairs are measured again when it is, see settle)
                faceAt0[f] = {-1, -1, -1};
                movedFacesEdges += !movedF[f];
                movedF[f] = 1;
                overFaceGrid.erase(int(f));
            }
        }
        dirtyAtF[f] = stamp;
        faceNow[f] = t;
        dirtyF.push_back(int(f));
    };
    auto lookAtEdge = [&](EdgeHandle eh) {
        const std::size_t e = std::size_t(eh.idx());
        if (seenE[e] == stamp || mesh.status(eh).deleted()) return;
        seenE[e] = stamp;
        const std::array<int, 2> x = edgeIds(mesh, eh);
        if (e < edgeAt0.size() && edgeAt0[e][0] >= 0) {
            if (x == edgeAt0[e]) {
                if (clean(x.data(), 2)) return;
            } else {
                edgeAt0[e] = {-1, -1};
                movedFacesEdges += !movedE[e];
                movedE[e] = 1;
                overEdgeGrid.erase(int(e));
            }
        }
        dirtyAtE[e] = stamp;
        edgeNow[e] = x;
        dirtyE.push_back(int(e));
    };
    for (int i : seeds) {
        const VertexHandle v(i);
        for (auto f = mesh.cvf_begin(v); f.is_valid(); ++f) lookAtFace(*f);
        for (auto e = mesh.cve_begin(v); e.is_valid(); ++e) lookAtEdge(*e);
    }
    for (std::size_t f = faces0; f < nf; ++f) lookAtFace(FaceHandle(int(f))); // (new ones: all have a new corner)
    for (std::size_t e = edges0; e < ne; ++e) lookAtEdge(EdgeHandle(int(e)));
    std::sort(dirtyF.begin(), dirtyF.end());
    std::sort(dirtyE.begin(), dirtyE.end());
    for (int f : dirtyF) faceBox[std::size_t(f)] = g.faceBox(faceNow[std::size_t(f)]);
    for (int e : dirtyE) edgeBox[std::size_t(e)] = g.edgeBox(edgeNow[std::size_t(e)]);
}

void SafeStepCache::Impl::collect(const Mesh& mesh, const StepGeometry& g, std::vector<Quad>& candidates)
{
    // Clean against clean: nothing to test (see rebuild). The rest from grids of this step's
    // dirty primitives, in the anchored grids' frame, paired with the anchored grids and with
    // each other (PackedBoxGrid::pairsAcross, a grid query per dirty primitive before: phantom
    // 100^3, collect 113.5 M -> 81.6 M instructions), and from queries of the overlay.
    // f(k, element) for the pairs of the sparse grid's item k and an anchored element still in
    // the anchored grid (not anchored again since).
    auto withAnchored = [&](const detail::PackedBoxGrid& sparse, const detail::PackedBoxGrid& anchored,
                            const std::vector<int>& of, const std::vector<char>& moved, auto&& f) {
        auto pair = [&](int k, int item, std::vector<Quad>& found) {
            const int x = of[std::size_t(item)];
            if (!moved[std::size_t(x)]) f(k, x, found);
        };
        pairInChunks(sparse.entries(), lists, candidates, [&](std::size_t e0, std::size_t e1, std::vector<Quad>& found) {
            detail::PackedBoxGrid::pairsAcross(sparse, anchored, e0, e1, [&](int k, int item) { pair(k, item, found); });
        }, kDirtyPairChunk);
        detail::PackedBoxGrid::pairsWithLarge(sparse, anchored, [&](int k, int item) { pair(k, item, candidates); });
    };

    // Dirty vertices against clean faces and dirty faces; clean vertices against dirty faces.
    auto vertexFace = [&](int i, const std::array<int, 3>& t, const Box6& box, std::vector<Quad>& found) {
        if (!hasCorner(t, i) && detail::boxesOverlap(g.vertexBox(i), box) && g.vertexFace(i, t))
            found.push_back(vertexFaceQuad(i, t));
    };
    auto dirtyWithClean = [&](int k, int f, std::vector<Quad>& found) { // (dirty vertex k, face f)
        if (!cleanFace(mesh, std::size_t(f))) return;
        const auto& t = faceAt0[std::size_t(f)];
        vertexFace(dirtyV[std::size_t(k)], t, g.faceBox(t), found);
    };
    auto dirtyWithDirty = [&](int k, int j, std::vector<Quad>& found) { // (dirty vertex k, dirty face j)
        const std::size_t f = std::size_t(dirtyF[std::size_t(j)]);
        vertexFace(dirtyV[std::size_t(k)], faceNow[f], faceBox[f], found);
    };
    auto cleanWithDirty = [&](int j, int i, std::vector<Quad>& found) { // (dirty face j, vertex i)
        if (std::size_t(i) >= cleanV.size() || !cleanV[std::size_t(i)]) return;
        const std::size_t f = std::size_t(dirtyF[std::size_t(j)]);
        vertexFace(i, faceNow[f], faceBox[f], found);
    };
    dirtyBox.clear();
    for (int i : dirtyV) dirtyBox.push_back(g.vertexBox(i));
    dirtyVertexGrid.buildSparse(dirtyBox, frame);
    dirtyBox.clear();
    for (int f : dirtyF) dirtyBox.push_back(faceBox[std::size_t(f)]);
    dirtyGrid.buildSparse(dirtyBox, frame);
    withAnchored(dirtyVertexGrid, faceGrid, faceOf, movedF, dirtyWithClean);
    pairInChunks(dirtyVertexGrid.entries(), lists, candidates, [&](std::size_t e0, std::size_t e1, std::vector<Quad>& found) {
        detail::PackedBoxGrid::pairsAcross(dirtyVertexGrid, dirtyGrid, e0, e1,
                                           [&](int k, int j) { dirtyWithDirty(k, j, found); });
    }, kDirtyPairChunk);
    detail::PackedBoxGrid::pairsWithLarge(dirtyVertexGrid, dirtyGrid,
                                          [&](int k, int j) { dirtyWithDirty(k, j, candidates); });
    withAnchored(dirtyGrid, vertexGrid, vertexOf, movedV, cleanWithDirty);
    findInChunks(dirtyV.size(), lists, candidates, [&](std::size_t k, std::vector<Quad>& found) {
        overFaceGrid.query(g.vertexBox(dirtyV[k]), [&](int f) { dirtyWithClean(int(k), f, found); });
    });
    findInChunks(dirtyF.size(), lists, candidates, [&](std::size_t j, std::vector<Quad>& found) {
        overVertexGrid.query(faceBox[std::size_t(dirtyF[j])], [&](int i) { cleanWithDirty(int(j), i, found); });
    });

    // Dirty edges against clean edges, and against dirty edges (each pair once).
    auto edgeEdge = [&](std::size_t e, std::size_t h, const std::array<int, 2>& y, const Box6& box,
                        std::vector<Quad>& found) {
        const auto& x = edgeNow[e];
        if (!shareVertex(x, y) && detail::boxesOverlap(edgeBox[e], box) &&
            (e < h ? g.edgeEdge(x, y) : g.edgeEdge(y, x)))
            found.push_back(e < h ? edgeEdgeQuad(x, y) : edgeEdgeQuad(y, x)); // (in index order, as from scratch)
    };
    auto withClean = [&](int k, int h, std::vector<Quad>& found) { // (dirty edge k, edge h)
        if (!cleanEdge(mesh, std::size_t(h))) return;
        const auto& y = edgeAt0[std::size_t(h)];
        edgeEdge(std::size_t(dirtyE[std::size_t(k)]), std::size_t(h), y, g.edgeBox(y), found);
    };
    auto withDirty = [&](int k, int j, std::vector<Quad>& found) { // (dirty edges k < j)
        const std::size_t h = std::size_t(dirtyE[std::size_t(j)]);
        edgeEdge(std::size_t(dirtyE[std::size_t(k)]), h, edgeNow[h], edgeBox[h], found);
    };
    dirtyBox.clear();
    for (int e : dirtyE) dirtyBox.push_back(edgeBox[std::size_t(e)]);
    dirtyGrid.buildSparse(dirtyBox, frame);
    withAnchored(dirtyGrid, edgeGrid, edgeOf, movedE, withClean);
    pairInChunks(dirtyGrid.entries(), lists, candidates, [&](std::size_t e0, std::size_t e1, std::vector<Quad>& found) {
        dirtyGrid.pairsWithin(e0, e1, [&](int k, int j) { withDirty(k, j, found); });
    }, kDirtyPairChunk);
    dirtyGrid.pairsWithLarge([&](int k, int j) { withDirty(k, j, candidates); });
    findInChunks(dirtyE.size(), lists, candidates, [&](std::size_t k, std::vector<Quad>& found) {
        overEdgeGrid.query(edgeBox[std::size_t(dirtyE[k])], [&](int h) { withClean(int(k), h, found); });
    });
}

SafeStepStats limitStepToCollisionFree(Mesh& mesh, const std::vector<Vec3>& start, const SafeStepOptions& options,
                                       SafeStepCache* cache)
{
    SafeStepStats stats;
    if (cache) cache->impl().finish(); // (the last step's pairs, measured meanwhile: see settle)
    const std::size_t n = mesh.n_vertices();
    if (n == 0 || start.size() < n) return stats;
    const double eta = options.minSeparation;
    // Buffers kept for the next step (no allocation once they have grown).
    struct Scratch {
        std::vector<Vec3> end;
        std::vector<char> moves, changed;
        std::vector<std::array<int, 3>> faces;
        std::vector<std::array<int, 2>> edges;
        std::vector<Box6> vertexBox, faceBox, edgeBox;
        std::vector<double> reach, alpha, factor, extents;
        std::vector<int> touched;
        std::vector<Quad> candidates;
        std::vector<std::vector<Quad>> lists;
        std::vector<int> live;
        std::array<detail::PackedBoxGrid, 3> grids;
    };
    static thread_local Scratch scratch;
    std::vector<Vec3>& end = scratch.end;
    std::vector<char>& moves = scratch.moves;
    std::vector<double>& reach = scratch.reach; // how far each live vertex moves
    std::vector<int>& live = scratch.live;
    end.resize(n);
    moves.assign(n, 0);
    reach.assign(n, 0.0);
    forLive<VertexHandle>(mesh, n, [&](std::size_t i) {
        end[i] = position(mesh, VertexHandle(int(i)));
        moves[i] = end[i] != start[i];
        if (moves[i]) reach[i] = (end[i] - start[i]).norm();
    });
    live.clear();
    bool any = false;
    for (std::size_t i = 0; i < n; ++i)
        if (!mesh.status(VertexHandle(int(i))).deleted()) {
            live.push_back(int(i));
            any = any || moves[i];
        }
    if (!any) return stats;
    const StepGeometry g{start, end, reach, eta};

    std::vector<Quad>& candidates = scratch.candidates;
    candidates.clear();
    // The grids' cells: the faces' mean extent (swept boxes of this step; summed in index order).
    // While the cache is anchored, it measures them itself, from the boxes it makes anyway: the
    // choice of the path below takes its anchoring's (an O(n) pass over the faces less per step).
    double cell = cache && cache->impl().valid ? cache->impl().cell : 0.0;
    if (!(cell > 0)) {
        std::vector<double>& extents = scratch.extents;
        extents.assign(mesh.n_faces(), -1.0);
        forLive<FaceHandle>(mesh, mesh.n_faces(), [&](std::size_t f) {
            extents[f] = boxExtent(g.faceBox(faceIds(mesh, FaceHandle(int(f)))));
        });
        double extent = 0;
        std::size_t faceCount = 0;
        for (const double x : extents)
            if (x >= 0) extent += x, ++faceCount;
        if (faceCount == 0) return stats;
        cell = cellSize(extent, faceCount);
    }
    // A step in which many vertices move far (a front travelling, a new level settling) would
    // leave them out of their clearance however they were anchored: it is searched from scratch,
    // and the mesh anchored later.
    std::size_t far = 0;
    bool cached = false;
    if (cache) {
        const double farMotion = options.farMotion * cell;
        for (int i : live) far += reach[std::size_t(i)] > farMotion;
    }
    if (!cache || double(far) > 0.5 * options.rebuildFraction * double(live.size())) {
        if (cache) cache->invalidate();
        collectPrimitives(mesh, scratch.faces, scratch.edges);
        allCandidates(g, live, scratch.faces, scratch.edges, options.scratchCell * cell, scratch.vertexBox,
                      scratch.faceBox, scratch.edgeBox, scratch.grids, scratch.lists, candidates);
    } else {
        cache->impl().candidates(mesh, g, options, candidates, stats);
        cached = true;
    }
    stats.candidates = candidates.size();

    // Rounds: test (again) the pairs with a vertex whose motion changed, shorten the colliding ones.
    std::vector<double>& alpha = scratch.alpha;
    std::vector<double>& factor = scratch.factor;
    std::vector<char>& changed = scratch.changed;
    std::vector<int>& touched = scratch.touched;
    alpha.assign(n, 1.0);
    factor.assign(n, 1.0);
    changed.assign(n, 1);
    touched.clear();
    auto at = [&](int v) -> Vec3 {
        const std::size_t i = std::size_t(v);
        return alpha[i] == 1.0 ? end[i] : Vec3(start[i] + alpha[i] * (end[i] - start[i]));
    };
    for (int round = 0;; ++round) {
        stats.rounds = round + 1;
        bool hit = false;
        const double shorten = round < options.shortenRounds ? options.shorten : 0.0;
        for (const Quad& c : candidates) {
            const std::array<int, 4> v = {c[1], c[2], c[3], c[4]};
            if (!changed[std::size_t(v[0])] && !changed[std::size_t(v[1])] && !changed[std::size_t(v[2])] &&
                !changed[std::size_t(v[3])])
                continue;
            const Vec3& s0 = start[std::size_t(v[0])];
            const Vec3& s1 = start[std::size_t(v[1])];
            const Vec3& s2 = start[std::size_t(v[2])];
            const Vec3& s3 = start[std::size_t(v[3])];
            const CcdResult r =
                c[0] == 0 ? pointTriangleCcd(s0, s1, s2, s3, at(v[0]), at(v[1]), at(v[2]), at(v[3]), eta, options.gapFraction)
                          : edgeEdgeCcd(s0, s1, s2, s3, at(v[0]), at(v[1]), at(v[2]), at(v[3]), eta, options.gapFraction);
            if (!r.collides) continue;
            hit = true;
            ++stats.collisions;
            for (int w : v) {
                double& f = factor[std::size_t(w)];
                if (alpha[std::size_t(w)] > 0 && moves[std::size_t(w)]) {
                    if (f == 1.0) touched.push_back(w);
                    f = std::min(f, shorten * r.toi);
                }
            }
        }
        std::fill(changed.begin(), changed.end(), 0);
        if (!hit) break;
        for (int w : touched) {
            alpha[std::size_t(w)] *= factor[std::size_t(w)];
            factor[std::size_t(w)] = 1.0;
            changed[std::size_t(w)] = 1;
        }
        touched.clear();
    }

    OpenMesh::VPropHandleT<OpenMesh::Vec3d> velocity;
    const bool hasVelocity = mesh.get_property_handle(velocity, kVelocityProperty);
    for (auto v : mesh.vertices()) {
        const std::size_t i = std::size_t(v.idx());
        if (alpha[i] == 1.0) continue;
        ++stats.shortened;
        stats.stopped += alpha[i] == 0.0;
        mesh.set_point(v, toPoint(at(v.idx())));
        if (hasVelocity) mesh.property(velocity, v) *= alpha[i];
    }
    if (cached && cache->impl().rebuildAfter) cache->impl().anchorAfter(mesh, g, options);
    else if (cached) cache->impl().settle(mesh, g, options.farMotion * cell, options, stats);
    return stats;
}

double triangleSeparation(const std::array<int, 3>& ia, const std::array<Vec3, 3>& a, const std::array<int, 3>& ib,
                          const std::array<Vec3, 3>& b)
{
    auto in = [](int v, const std::array<int, 3>& ids) { return v == ids[0] || v == ids[1] || v == ids[2]; };
    double best = std::numeric_limits<double>::infinity();
    for (int i = 0; i < 3; ++i) {
        if (!in(ia[std::size_t(i)], ib)) best = std::min(best, pointTriangleDistanceSquared(a[std::size_t(i)], b[0], b[1], b[2]));
        if (!in(ib[std::size_t(i)], ia)) best = std::min(best, pointTriangleDistanceSquared(b[std::size_t(i)], a[0], a[1], a[2]));
    }
    for (std::size_t i = 0; i < 3; ++i)
        for (std::size_t j = 0; j < 3; ++j) {
            const std::size_t i1 = (i + 1) % 3, j1 = (j + 1) % 3;
            if (ia[i] == ib[j] || ia[i] == ib[j1] || ia[i1] == ib[j] || ia[i1] == ib[j1]) continue;
            best = std::min(best, segmentSegmentDistanceSquared(a[i], a[i1], b[j], b[j1]));
        }
    return std::sqrt(best);
}

bool trianglesCloserThan(const std::array<int, 3>& ia, const std::array<Vec3, 3>& a, const std::array<int, 3>& ib,
                         const std::array<Vec3, 3>& b, double r)
{
    if (!(r > 0)) return false;
    // Each distance is measured only where the primitives' boxes come within r of each other on
    // every axis (a gap wider than r on one axis is a distance wider than r): with r far below the
    // edges' lengths, as for the edits' separation, most pairs of neighbouring faces stop there.
    auto boxOf = [](const Vec3* p, int k) {
        Box6 box = {p[0][0], p[0][1], p[0][2], p[0][0], p[0][1], p[0][2]};
        for (int i = 1; i < k; ++i)
            for (int c = 0; c < 3; ++c) {
                box[std::size_t(c)] = std::min(box[std::size_t(c)], p[i][c]);
                box[std::size_t(c) + 3] = std::max(box[std::size_t(c) + 3], p[i][c]);
            }
        return box;
    };
    const double reach = r * (1 + 1e-9);
    auto near = [reach](const Box6& x, const Box6& y) {
        for (std::size_t c = 0; c < 3; ++c)
            if (x[c] - y[c + 3] > reach || y[c] - x[c + 3] > reach) return false;
        return true;
    };
    auto in = [](int v, const std::array<int, 3>& ids) { return v == ids[0] || v == ids[1] || v == ids[2]; };
    const Box6 boxA = boxOf(a.data(), 3), boxB = boxOf(b.data(), 3);
    if (!near(boxA, boxB)) return false;
    auto closer = [r](double d2) { return std::sqrt(d2) < r; }; // (as triangleSeparation(...) < r)
    for (std::size_t i = 0; i < 3; ++i) {
        if (!in(ia[i], ib) && near(boxOf(&a[i], 1), boxB) && closer(pointTriangleDistanceSquared(a[i], b[0], b[1], b[2])))
            return true;
        if (!in(ib[i], ia) && near(boxOf(&b[i], 1), boxA) && closer(pointTriangleDistanceSquared(b[i], a[0], a[1], a[2])))
            return true;
    }
    for (std::size_t i = 0; i < 3; ++i) {
        const std::size_t i1 = (i + 1) % 3;
        const Vec3 x[2] = {a[i], a[i1]};
        const Box6 boxX = boxOf(x, 2);
        if (!near(boxX, boxB)) continue;
        for (std::size_t j = 0; j < 3; ++j) {
            const std::size_t j1 = (j + 1) % 3;
            if (ia[i] == ib[j] || ia[i] == ib[j1] || ia[i1] == ib[j] || ia[i1] == ib[j1]) continue;
            const Vec3 y[2] = {b[j], b[j1]};
            if (near(boxX, boxOf(y, 2)) && closer(segmentSegmentDistanceSquared(a[i], a[i1], b[j], b[j1]))) return true;
        }
    }
    return false;
}

bool facesMeetMesh(const Mesh& mesh, const std::vector<FaceHandle>& faces, double minSeparation)
{
    struct Face {
        std::array<int, 3> ids;
        std::array<Vec3, 3> p;
        detail::TriangleRef ref;
        Box6 box;
    };
    auto makeFace = [&](FaceHandle f) {
        Face x;
        x.ids = faceIds(mesh, f);
        const double* p[3];
        for (int i = 0; i < 3; ++i) {
            p[i] = mesh.point(VertexHandle(x.ids[std::size_t(i)])).data();
            x.p[std::size_t(i)] = Vec3(p[i][0], p[i][1], p[i][2]);
        }
        x.ref = detail::makeTriangle(p[0], p[1], p[2]);
        for (int k = 0; k < 3; ++k) { // grown by the separation: a closer face's box overlaps
            x.box[k] = std::min({p[0][k], p[1][k], p[2][k]}) - 0.5 * minSeparation;
            x.box[k + 3] = std::max({p[0][k], p[1][k], p[2][k]}) + 0.5 * minSeparation;
        }
        return x;
    };
    std::vector<Face> mine;
    constexpr double inf = std::numeric_limits<double>::infinity();
    Box6 all = {inf, inf, inf, -inf, -inf, -inf};
    for (FaceHandle f : faces) {
        if (!f.is_valid() || mesh.status(f).deleted()) continue;
        mine.push_back(makeFace(f));
        if (mine.back().ref.axis < 0) return true; // a flat face: refuse
        for (int k = 0; k < 3; ++k) {
            all[k] = std::min(all[k], mine.back().box[k]);
            all[k + 3] = std::max(all[k + 3], mine.back().box[k + 3]);
        }
    }
    auto meet = [minSeparation](const Face& x, const Face& y) {
        return detail::boxesOverlap(x.box, y.box) &&
               (detail::classifyTriangles(x.ids, x.ref, y.ids, y.ref) != detail::TriangleContact::None ||
                trianglesCloserThan(x.ids, x.p, y.ids, y.p, minSeparation));
    };
    for (std::size_t i = 0; i < mine.size(); ++i)
        for (std::size_t j = i + 1; j < mine.size(); ++j)
            if (meet(mine[i], mine[j])) return true;
    for (auto f : mesh.faces()) {
        if (std::find(faces.begin(), faces.end(), f) != faces.end()) continue;
        const Face x = makeFace(f);
        if (x.ref.axis < 0 || !detail::boxesOverlap(x.box, all)) continue;
        for (const Face& y : mine)
            if (meet(x, y)) return true;
    }
    return false;
}

double minimumSeparation(const Mesh& mesh, double radius)
{
    std::vector<Vec3> start(mesh.n_vertices());
    for (auto v : mesh.vertices()) start[std::size_t(v.idx())] = position(mesh, v);
    double best = radius;
    detail::BoxGrid grid;
    std::vector<std::array<int, 3>> faces;
    std::vector<std::array<int, 2>> edges;
    collectPrimitives(mesh, faces, edges);
    auto boxOf = [&](const int* v, int k) {
        Box6 b = {1e300, 1e300, 1e300, -1e300, -1e300, -1e300};
        for (int i = 0; i < k; ++i)
            for (int c = 0; c < 3; ++c) {
                b[c] = std::min(b[c], start[std::size_t(v[i])][c] - radius);
                b[c + 3] = std::max(b[c + 3], start[std::size_t(v[i])][c] + radius);
            }
        return b;
    };
    grid.reset(4 * radius + 1e-9, 4 * faces.size() + 64, faces.size());
    for (std::size_t f = 0; f < faces.size(); ++f) grid.insert(int(f), boxOf(faces[f].data(), 3));
    for (auto v : mesh.vertices()) {
        const int i = v.idx();
        Box6 b = boxOf(&i, 1);
        grid.query(b, [&](int f) {
            const auto& t = faces[std::size_t(f)];
            if (t[0] == i || t[1] == i || t[2] == i) return;
            best = std::min(best, std::sqrt(pointTriangleDistanceSquared(start[i], start[t[0]], start[t[1]], start[t[2]])));
        });
    }
    grid.reset(4 * radius + 1e-9, 4 * edges.size() + 64, edges.size());
    for (std::size_t e = 0; e < edges.size(); ++e) grid.insert(int(e), boxOf(edges[e].data(), 2));
    for (std::size_t e = 0; e < edges.size(); ++e) {
        const auto& x = edges[e];
        grid.query(boxOf(x.data(), 2), [&](int g) {
            const auto& y = edges[std::size_t(g)];
            if (x[0] == y[0] || x[0] == y[1] || x[1] == y[0] || x[1] == y[1]) return;
            best = std::min(best, std::sqrt(segmentSegmentDistanceSquared(start[x[0]], start[x[1]], start[y[0]], start[y[1]])));
        });
    }
    return best;
}

} // namespace riemesh
