// regularity.cpp: restore delta <= d_R(u, v) <= zeta * delta on every edge (paper 3.1, Fig. 1).
//
// One pass = measure every edge once, split the long edges (Euclidean-longest first, new long
// edges are queued as they appear), collapse the short ones (shortest first, toward the midpoint; the
// endpoints are tried when the midpoint is refused), then one sweep of flips that lower the valence
// deviation from 6 (or, at equal deviation, restore the Delaunay-like angle condition measured in
// the metric). Passes repeat until one changes nothing or maxPasses is reached. Only the first pass
// looks at every edge: the later ones re-examine the edges of the faces around the vertices the
// previous pass changed (an edge away from every change keeps its length, its valences and its
// faces, so its verdict), which keeps a call O(n + changes) however many passes it takes.
// The first pass's measurements and flip tests run in parallel (detail/parallel.h); every edit
// stays sequential, in the order a serial pass would make it.
//
// A short edge u-v whose endpoints share an outside neighbour w is not collapsed (it would pinch
// the loop u-v-w). If one side of that loop holds only a few vertices (a dent or pimple of the
// sampling, typically a valence-3 vertex) those are collapsed away and u-v collapses normally;
// otherwise the loop is a real tunnel and goes to RegularityStats::tunnels for the topology step.
//
// On a mesh that is already regular one call costs one length evaluation and one flip test per
// edge, with no per-edge allocation.
#include "riemesh/regularity.h"

#include "riemesh/edge_ops.h"

#include "detail/edge_guards.h"
#include "detail/intersection_guard.h"
#include "detail/regularize.h"
#include "detail/parallel.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <tuple>

namespace riemesh {

namespace {

/// Collapses may make edges up to this fraction of zeta delta (see keepsEdgesShortEnough). 0.95 was
/// tried against the split/collapse churn along the creases of the 300^3 phantom at delta 9: it
/// converged there (162 iterations) only because the churn's travelling vertices happened to drop
/// from 3 to 2 (the convergence test allows 0.2% of 1,335); it still split and collapsed 3-5 edges
/// an iteration. The churn comes from a metric that grows by a large factor along one edge; the
/// collapses that feed it are refused by splitsIntoRegularHalves instead.
constexpr double kCollapseMargin = 1.0;
/// Collapses that would make an edge longer than this fraction of zeta delta check that the edge
/// could be split into regular halves once motion stretches it past zeta delta
/// (splitsIntoRegularHalves). 0.5: an edge no longer than the halves of a fresh split is far from
/// a split. (0 checks every edge made: 1,516 vertices on the 100^3 phantom instead of 1,493; 0.75
/// leaves the 300^3 phantom at delta 9 converging in 160 iterations instead of 118.)
constexpr double kUnsplittableCheck = 0.5;

/// An edge waiting in a split or collapse queue. An entry whose edge no longer has the metric
/// length it was queued with is stale and skipped: every edit re-queues the edges it changes.
struct QueuedEdge {
    double length;   ///< metric length when queued
    double priority; ///< heap key: Euclidean length for splits (world units), metric length for collapses
    int edge;        ///< edge idx()
};

/// Flips with equal valence deviation must beat the Delaunay-like condition by this much
/// (sum of the cotangents of the two opposite angles, measured in the metric).
constexpr double kDelaunayTolerance = 1e-2;
/// A regularity flip may not fold the surface: the new dihedral angle's cosine must reach
/// min(old cosine, kFlipFlatCosine) (about 26 degrees, or the old angle if that was sharper).
constexpr double kFlipFlatCosine = 0.9;

int squared(int x) { return x * x; }

/// Elements per parallel chunk.
constexpr std::size_t kGrain = 128;

/// A loop u-v-w that cuts off at most this many vertices is a cap (a dent or a pimple of the
/// sampling), dissolved by collapses; a loop with more on both sides is a tunnel.
constexpr int kMaxCapVertices = 8;

bool shorterFirst(const QueuedEdge& x, const QueuedEdge& y) { return x.priority > y.priority; }

class Regularizer {
public:
    /// With `made` (options.intersectionFree, the edits made without asking the guard, see
    /// enforceRegularity): the faces the collapses and flips made or moved are noted there (the
    /// vertices around which they all are, each once; each flip's two faces).
    Regularizer(Mesh& mesh, const MetricField& metric, const RegularityOptions& options, RegularityStats& stats,
                detail::GuardGrid* kept, detail::MadeFaces* made = nullptr)
        : mMesh(mesh), mMetric(metric), mVertexMetrics(mesh, metric), mStats(stats), mLo(options.delta),
          mHi(options.zeta * options.delta), mMade(made)
    {
        if (options.intersectionFree && !made)
            mGuard = std::make_unique<detail::IntersectionGuard>(mesh, options.minSeparation, kept);
        if (mMade) mMade->clear();
        mSpeculate = options.speculate;
    }

    /// Euclidean length of edge e (world units).
    double euclideanLength(EdgeHandle e) const
    {
        const HalfedgeHandle h = mMesh.halfedge_handle(e, 0);
        return (position(mMesh, mMesh.from_vertex_handle(h)) - position(mMesh, mMesh.to_vertex_handle(h))).norm();
    }

    /// Metric length of edge e.
    double length(EdgeHandle e) const
    {
        const HalfedgeHandle h = mMesh.halfedge_handle(e, 0);
        return lengthBetween(mMesh.from_vertex_handle(h), mMesh.to_vertex_handle(h));
    }

    /// G at vertex v: the mesh's VertexMetrics cache, sampled again only when the vertex moved (a
    /// collapse moves the kept vertex; splits add new ones). (Forced inline, as VertexMetrics::at:
    /// GCC 12 left both out of line once fec32b6 grew this class, phantom 100^3 unguarded
    /// 1,482.4 M -> 1,495.3 M instructions.)
    [[gnu::always_inline]] Mat3 vertexMetric(VertexHandle v) const { return mVertexMetrics.at(v); }

    /// Metric length between two vertices with G at the edge midpoint approximated by the mean of
    /// the endpoint tensors (second order in the edge length for a smooth metric; exact for a
    /// constant one), so that measuring an edge costs no metric lookup.
    double lengthBetween(VertexHandle a, VertexHandle b) const
    {
        const Vec3 d = position(mMesh, b) - position(mMesh, a);
        if (mMetric.isEuclidean()) return d.norm();
        return metricLength(vertexMetric(a), vertexMetric(b), d);
    }

    /// Measures every edge once, queues the long and the short ones and counts the valences.
    /// The hot loop of an already-regular mesh: raw indices, no allocation, and with a Euclidean
    /// metric the squared length is compared with the squared bounds (the same classification as
    /// metricLength, without a call and a square root per edge).
    void measure()
    {
        mLong.clear();
        mShort.clear();
        const int edgeCount = int(mMesh.n_edges());
        const int vertexCount = int(mMesh.n_vertices());
        mValence.assign(std::size_t(vertexCount), 0);
        mClass.assign(std::size_t(edgeCount), kFits);
        // In parallel: G at every vertex first (so that measuring only reads the cache), then each
        // vertex's valence and each edge's class; the long and short edges are then queued in edge
        // order, as one pass over the edges would.
        mVertexMetrics.update();
        const bool vertexStatus = mMesh.has_vertex_status();
        int* const valence = mValence.data();
        detail::parallelFor(0, std::size_t(vertexCount), kGrain, [&](std::size_t i) {
            const VertexHandle v{int(i)};
            if (!(vertexStatus && mMesh.status(v).deleted())) valence[i] = int(mMesh.valence(v));
        });
        signed char* const edgeClass = mClass.data();
        detail::parallelFor(0, std::size_t(edgeCount), kGrain, [&](std::size_t i) {
            if (!mMesh.status(EdgeHandle(int(i))).deleted()) edgeClass[i] = measureClass(int(i));
        });
        for (int i = 0; i < edgeCount; ++i)
            if (edgeClass[i] != kFits) queue(i, edgeClass[i]);
        mEdges.clear();
        clearTouched();
    }

    /// Measures again only the edges of the faces around the vertices changed since the last
    /// measurement (collected in mEdges for the flip sweep); the other edges keep their class.
    /// Valences are kept up to date by the edits themselves.
    void measureTouched()
    {
        mLong.clear();
        mShort.clear();
        mEdges.clear();
        if (mEdgeSeen.size() < mMesh.n_edges()) mEdgeSeen.resize(mMesh.n_edges(), 0);
        if (mClass.size() < mMesh.n_edges()) mClass.resize(mMesh.n_edges(), kFits);
        for (const int t : mTouchedList) {
            const VertexHandle v(t);
            if (mMesh.status(v).deleted()) continue;
            for (auto f = mMesh.cvf_begin(v); f.is_valid(); ++f)
                for (auto fh = mMesh.cfh_begin(*f); fh.is_valid(); ++fh) {
                    const int i = mMesh.edge_handle(*fh).idx();
                    if (mEdgeSeen[std::size_t(i)]) continue;
                    mEdgeSeen[std::size_t(i)] = 1;
                    mEdges.push_back(i);
                }
        }
        for (const int i : mEdges) {
            mEdgeSeen[std::size_t(i)] = 0;
            classify(i);
        }
        clearTouched();
    }

    /// Edges still outside [delta, zeta*delta] after measuring what changed: (too long, too short).
    std::pair<int, int> countOutside()
    {
        measureTouched();
        std::atomic<int> tooLong{0}, tooShort{0};
        detail::parallelForChunks(0, mClass.size(), 4 * kGrain, [&](std::size_t begin, std::size_t end) {
            int longs = 0, shorts = 0;
            for (std::size_t i = begin; i < end; ++i) {
                if (mClass[i] == kFits || mMesh.status(EdgeHandle(int(i))).deleted()) continue;
                (mClass[i] == kLong ? longs : shorts) += 1;
            }
            tooLong += longs;
            tooShort += shorts;
        });
        return {tooLong.load(), tooShort.load()};
    }

    /// The class of edge i by its metric length (reads only: safe in parallel once every vertex's
    /// G is cached). With a Euclidean metric the squared length is compared with the squared
    /// bounds (the same classification as metricLength, without a call and a square root per edge).
    signed char measureClass(int i) const
    {
        const EdgeHandle e(i);
        if (mMetric.isEuclidean()) {
            const HalfedgeHandle h = mMesh.halfedge_handle(e, 0);
            const Mesh::Point* points = mMesh.points();
            const double l2 = (points[mMesh.to_vertex_handle(h).idx()] - points[mMesh.from_vertex_handle(h).idx()]).sqrnorm();
            return l2 > mHi * mHi ? kLong : l2 < mLo * mLo ? kShort : kFits;
        }
        const double l = length(e);
        return l > mHi ? kLong : l < mLo ? kShort : kFits;
    }

    /// Records edge i's class `c` (from measureClass) and queues it when it is too long or too short.
    void queue(int i, signed char c)
    {
        const EdgeHandle e(i);
        mClass[std::size_t(i)] = c;
        if (c == kFits) return;
        if (mMetric.isEuclidean()) {
            const HalfedgeHandle h = mMesh.halfedge_handle(e, 0);
            const Mesh::Point* points = mMesh.points();
            const double l2 = (points[mMesh.to_vertex_handle(h).idx()] - points[mMesh.from_vertex_handle(h).idx()]).sqrnorm();
            (c == kLong ? mLong : mShort).push_back({length(e), std::sqrt(l2), i});
        } else {
            const double l = length(e);
            if (c == kLong) mLong.push_back({l, euclideanLength(e), i});
            else mShort.push_back({l, l, i});
        }
    }

    /// Records edge i's class and queues it when it is too long or too short.
    void classify(int i) { queue(i, measureClass(i)); }

    /// Marks v as changed by this pass: the next pass re-examines the edges of its faces.
    void touch(VertexHandle v)
    {
        const std::size_t i = std::size_t(v.idx());
        if (i >= mTouched.size()) mTouched.resize(std::max(i + 1, std::size_t(mMesh.n_vertices())), 0);
        if (mTouched[i]) return;
        mTouched[i] = 1;
        mTouchedList.push_back(int(i));
    }

    /// Notes v among the vertices whose faces the edits made (see the constructor). A face made or
    /// moved by a collapse has a noted corner (the kept vertex), a face a flip made is noted itself
    /// (noteFlip), and a face made from either by later edits is noted again: a collapse notes the
    /// vertex its faces now end at, a flip its two faces, and a split of an edge of a noted face
    /// (or of a face with a noted corner) notes the new vertex, a corner of both halves (the
    /// halves of any other face lie in it, which the edits did not make). Only a flip's two faces
    /// are noted, not the faces around a corner of both: head MRI, guarded, a third of the faces
    /// checked after the flips (the rest of those stars are as they were).
    void noteMade(VertexHandle v)
    {
        if (!mMade) return;
        const std::size_t i = std::size_t(v.idx());
        if (i >= mIsMade.size()) mIsMade.resize(std::max(i + 1, std::size_t(mMesh.n_vertices())), 0);
        if (mIsMade[i]) return;
        mIsMade[i] = 1;
        mMade->vertices.push_back(v.idx());
    }
    bool isMade(VertexHandle v) const
    {
        const std::size_t i = std::size_t(v.idx());
        return i < mIsMade.size() && mIsMade[i];
    }
    /// Notes the two faces a flip made.
    void noteFlip(FaceHandle f, FaceHandle g)
    {
        if (!mMade) return;
        if (mIsMadeFace.size() < mMesh.n_faces()) mIsMadeFace.resize(mMesh.n_faces(), 0);
        mIsMadeFace[std::size_t(f.idx())] = mIsMadeFace[std::size_t(g.idx())] = 1;
        mMade->flipped.push_back({f.idx(), g.idx()});
    }
    bool isMade(FaceHandle f) const
    {
        const std::size_t i = std::size_t(f.idx());
        return f.is_valid() && i < mIsMadeFace.size() && mIsMadeFace[i];
    }

    void clearTouched()
    {
        for (const int i : mTouchedList) mTouched[std::size_t(i)] = 0;
        mTouchedList.clear();
    }

    /// After a split or a collapse around v: recounts the valences of v and its neighbours (the
    /// only ones an edit at v changes) and marks them changed.
    void updateRing(VertexHandle v)
    {
        if (mValence.size() < mMesh.n_vertices()) mValence.resize(mMesh.n_vertices(), 0);
        mValence[std::size_t(v.idx())] = int(mMesh.valence(v));
        if (mGuard) mGuard->update(v);
        touch(v);
        for (auto n = mMesh.cvv_begin(v); n.is_valid(); ++n) {
            mValence[std::size_t(n->idx())] = int(mMesh.valence(*n));
            touch(*n);
        }
        // During a speculating collapse pass (collapses add no vertex): the speculated verdicts this
        // edit may have changed (see speculateCollapses). v moved and the rings of v and its
        // neighbours changed, which the verdicts of every edge with an end within two edges of v read.
        if (mCollapseMarks.empty()) return;
        mCollapseMarks[std::size_t(v.idx())] = 1;
        for (auto n = mMesh.cvv_begin(v); n.is_valid(); ++n) {
            mCollapseMarks[std::size_t(n->idx())] = 1;
            for (auto m = mMesh.cvv_begin(*n); m.is_valid(); ++m) mCollapseMarks[std::size_t(m->idx())] = 1;
        }
    }

    /// Splits long edges at their midpoints until none is left (or a safety cap). Among the edges
    /// too long in metric length, the Euclidean-longest goes first: when a triangle's longest side
    /// is due for a split it is split before the others (Rivara's longest-edge bisection), which
    /// keeps triangles from degenerating even where the metric jumps.
    int splitLongEdges()
    {
        auto longerFirst = [](const QueuedEdge& x, const QueuedEdge& y) { return x.priority < y.priority; };
        std::make_heap(mLong.begin(), mLong.end(), longerFirst);
        // Longest-edge bisection terminates; the cap only guards against a pathological metric.
        const std::size_t cap = 64 * mMesh.n_edges() + 100000;
        int splits = 0;
        while (!mLong.empty() && std::size_t(splits) < cap) {
            std::pop_heap(mLong.begin(), mLong.end(), longerFirst);
            const QueuedEdge item = mLong.back();
            mLong.pop_back();
            const EdgeHandle e(item.edge);
            if (mMesh.status(e).deleted() || length(e) != item.length) continue; // stale
            const HalfedgeHandle h = mMesh.halfedge_handle(e, 0);
            const Vec3 mid = 0.5 * (position(mMesh, mMesh.from_vertex_handle(h)) +
                                    position(mMesh, mMesh.to_vertex_handle(h)));
            if (!splitKeepsFacesValid(h, mid)) continue; // stays long: counted in tooLong
            const HalfedgeHandle o = mMesh.opposite_halfedge_handle(h);
            const bool inMade = mMade && (isMade(mMesh.from_vertex_handle(h)) || isMade(mMesh.to_vertex_handle(h)) ||
                                          isMade(mMesh.to_vertex_handle(mMesh.next_halfedge_handle(h))) ||
                                          isMade(mMesh.to_vertex_handle(mMesh.next_halfedge_handle(o))) ||
                                          isMade(mMesh.face_handle(h)) || isMade(mMesh.face_handle(o)));
            const VertexHandle w = split(mMesh, e, mid);
            if (!w.is_valid()) continue;
            ++splits;
            if (inMade) noteMade(w);
            updateRing(w);
            for (auto oh = mMesh.cvoh_begin(w); oh.is_valid(); ++oh) {
                const EdgeHandle ne = mMesh.edge_handle(*oh);
                const double l = length(ne);
                if (l > mHi) {
                    mLong.push_back({l, euclideanLength(ne), ne.idx()});
                    std::push_heap(mLong.begin(), mLong.end(), longerFirst);
                } else if (l < mLo) {
                    mShort.push_back({l, l, ne.idx()}); // a short median: collapsed in the next stage
                }
            }
        }
        return splits;
    }

    /// Collapses short edges, shortest first; records tunnels instead of pinching them.
    int collapseShortEdges()
    {
        std::make_heap(mShort.begin(), mShort.end(), shorterFirst);
        if (mSpeculate) speculateCollapses();
        mCollapses = 0;
        while (!mShort.empty()) {
            std::pop_heap(mShort.begin(), mShort.end(), shorterFirst);
            const QueuedEdge item = mShort.back();
            mShort.pop_back();
            const EdgeHandle e(item.edge);
            if (mMesh.status(e).deleted() || length(e) != item.length) continue; // stale
            collapseShortEdge(e);
        }
        mCollapseMarks.clear(); // (the verdicts are spent: later edits mark nothing)
        return mCollapses;
    }

    /// One sweep of flips over every edge (all = true) or over the edges of the last measureTouched().
    ///
    /// The sweep over every edge is the one serial pass over the whole mesh a call would otherwise
    /// make: the edges a flip would be wanted at are found in parallel first (on the mesh as it is
    /// before the sweep), then the sweep visits, in edge order, only those and the edges around
    /// every flip it makes (whose verdicts that flip may have changed). An edge it skips keeps the
    /// verdict it had before the sweep (no flip): the same flips as visiting every edge in order.
    int flipEdges(bool all)
    {
        int flips = 0;
        if (!all) {
            for (const int i : mEdges) flips += flipIfWanted(i);
            return flips;
        }
        const int edgeCount = int(mMesh.n_edges());
        mVertexMetrics.update(); // measuring then only reads the cache
        mWanted.assign(std::size_t(edgeCount), 0);
        char* const wanted = mWanted.data();
        detail::parallelFor(0, std::size_t(edgeCount), kGrain, [&](std::size_t i) {
            wanted[i] = isFlipWanted(EdgeHandle(int(i)));
        });
        mFlipQueue.clear(); // edges around the flips made, ahead of the sweep (a min-heap)
        const auto later = std::greater<int>();
        int cursor = -1;
        int next = 0; // the next edge wanted before the sweep
        for (;;) {
            while (next < edgeCount && (next <= cursor || !wanted[next])) ++next;
            while (!mFlipQueue.empty() && mFlipQueue.front() <= cursor) {
                std::pop_heap(mFlipQueue.begin(), mFlipQueue.end(), later);
                mFlipQueue.pop_back();
            }
            int i = next < edgeCount ? next : edgeCount;
            if (!mFlipQueue.empty()) i = std::min(i, mFlipQueue.front());
            if (i >= edgeCount) break;
            cursor = i;
            std::array<VertexHandle, 4> quad;
            if (!flipIfWanted(i, &quad)) continue;
            ++flips;
            // The flip changed the valences of its four vertices and the faces around them: every
            // edge of those faces still ahead is visited.
            for (const VertexHandle x : quad)
                for (auto f = mMesh.cvf_begin(x); f.is_valid(); ++f)
                    for (auto fh = mMesh.cfh_begin(*f); fh.is_valid(); ++fh) {
                        const int j = mMesh.edge_handle(*fh).idx();
                        if (j <= cursor) continue;
                        mFlipQueue.push_back(j);
                        std::push_heap(mFlipQueue.begin(), mFlipQueue.end(), later);
                    }
        }
        return flips;
    }

    /// True when edge e should be flipped now: lower valence deviation from 6 (or equal and
    /// Delaunay-like in the metric), an edge a-b within [delta, zeta*delta], and no fold. Reads
    /// only (safe in parallel once every vertex's G is cached).
    bool isFlipWanted(EdgeHandle e) const
    {
        if (mMesh.status(e).deleted()) return false;
        const HalfedgeHandle h = mMesh.halfedge_handle(e, 0), o = mMesh.halfedge_handle(e, 1);
        if (!mMesh.face_handle(h).is_valid() || !mMesh.face_handle(o).is_valid()) return false;
        const VertexHandle u = mMesh.from_vertex_handle(h), v = mMesh.to_vertex_handle(h);
        const VertexHandle a = mMesh.to_vertex_handle(mMesh.next_halfedge_handle(h));
        const VertexHandle b = mMesh.to_vertex_handle(mMesh.next_halfedge_handle(o));
        const int vu = mValence[u.idx()], vv = mValence[v.idx()], va = mValence[a.idx()], vb = mValence[b.idx()];
        if (vu <= 3 || vv <= 3 || a == b) return false;
        // Deviation of the four valences from the regular 6, before and after the flip.
        const int before = squared(vu - 6) + squared(vv - 6) + squared(va - 6) + squared(vb - 6);
        const int after = squared(vu - 7) + squared(vv - 7) + squared(va - 5) + squared(vb - 5);
        if (after > before) return false;
        const Vec3 pu = position(mMesh, u), pv = position(mMesh, v);
        const Vec3 pa = position(mMesh, a), pb = position(mMesh, b);
        if (after == before && !violatesDelaunay(u, v, pu, pv, pa, pb)) return false;
        const double newLength = lengthBetween(a, b);
        if (newLength < mLo || newLength > mHi) return false;
        // Do not fold the surface: the new dihedral may not be sharper than the old one (or ~26 deg).
        const Vec3 n1 = (pv - pu).cross(pa - pu), n2 = (pu - pv).cross(pb - pv);
        const double n1n2 = n1.norm() * n2.norm();
        const double oldCosine = n1n2 > 0 ? n1.dot(n2) / n1n2 : -1.0;
        return detail::isFlipAcceptable(mMesh, e, std::min(oldCosine, kFlipFlatCosine) - 1e-9);
    }

    /// Flips edge i if isFlipWanted (keeping the valences and the changed vertices up to date);
    /// `quad` receives the four vertices of the flip.
    bool flipIfWanted(int i, std::array<VertexHandle, 4>* quad = nullptr)
    {
        const EdgeHandle e(i);
        if (!isFlipWanted(e)) return false;
        if (mGuard && !mGuard->isFlipSafe(e)) return false; // would make faces cross
        const HalfedgeHandle h = mMesh.halfedge_handle(e, 0), o = mMesh.halfedge_handle(e, 1);
        const VertexHandle u = mMesh.from_vertex_handle(h), v = mMesh.to_vertex_handle(h);
        const VertexHandle a = mMesh.to_vertex_handle(mMesh.next_halfedge_handle(h));
        const VertexHandle b = mMesh.to_vertex_handle(mMesh.next_halfedge_handle(o));
        detail::flipUnchecked(mMesh, e);
        if (mGuard) mGuard->update(a);
        noteFlip(mMesh.face_handle(h), mMesh.face_handle(o));
        --mValence[u.idx()];
        --mValence[v.idx()];
        ++mValence[a.idx()];
        ++mValence[b.idx()];
        touch(u), touch(v), touch(a), touch(b);
        if (quad) *quad = {u, v, a, b};
        return true;
    }

    /// Drops the tunnel candidates that later edits of this call undid: a vertex was removed, the
    /// edge u-v or the loop through w is gone, or u-v is no longer shorter than delta.
    void pruneTunnels()
    {
        auto& tunnels = mStats.tunnels;
        tunnels.erase(std::remove_if(tunnels.begin(), tunnels.end(),
                                     [&](const TunnelCandidate& t) {
                                         if (mMesh.status(t.u).deleted() || mMesh.status(t.v).deleted() ||
                                             mMesh.status(t.w).deleted())
                                             return true;
                                         const HalfedgeHandle h = mMesh.find_halfedge(t.u, t.v);
                                         if (!h.is_valid() || !mMesh.find_halfedge(t.u, t.w).is_valid() ||
                                             !mMesh.find_halfedge(t.v, t.w).is_valid())
                                             return true;
                                         // w must still lie outside the two faces of u-v.
                                         const HalfedgeHandle o = mMesh.opposite_halfedge_handle(h);
                                         if (mMesh.to_vertex_handle(mMesh.next_halfedge_handle(h)) == t.w ||
                                             mMesh.to_vertex_handle(mMesh.next_halfedge_handle(o)) == t.w)
                                             return true;
                                         return !(length(mMesh.edge_handle(h)) < mLo);
                                     }),
                      tunnels.end());
    }

    int longCount() const { return int(mLong.size()); }
    int shortCount() const { return int(mShort.size()); }

private:
    /// Collapses e toward its midpoint (or, when the midpoint is refused for geometric reasons,
    /// into one of its endpoints). When its endpoints share an outside neighbour w, the loop u-v-w
    /// either cuts off a small cap (a few vertices, e.g. a valence-3 dent) that is dissolved first,
    /// or it is a real tunnel, recorded for the topology step.
    void collapseShortEdge(EdgeHandle e)
    {
        HalfedgeHandle h = mMesh.halfedge_handle(e, 0);
        const VertexHandle u = mMesh.from_vertex_handle(h), v = mMesh.to_vertex_handle(h);
        bool capped = false;
        for (int attempt = 0;; ++attempt) {
            const VertexHandle w = sharedOutsideNeighbour(mMesh, h);
            if (!w.is_valid()) break;
            capped = true;
            const CapResult cap = dissolveSmallCap(h, w);
            if (cap == CapResult::NotACap) recordTunnel(u, v, w);
            if (cap != CapResult::Dissolved || attempt == 2) return;
            // The cap's collapses may have replaced the edge u-v by a merged twin: find it again.
            h = mMesh.find_halfedge(u, v);
            if (!h.is_valid()) return;
            if (!(length(mMesh.edge_handle(h)) < mLo)) return;
        }
        const auto options = collapseOptions(h);
        const std::array<Verdict, 3>* known = capped ? nullptr : speculated(e, u, v);
        for (std::size_t k = 0; k < options.size(); ++k) {
            const auto& [hh, target] = options[k];
            Verdict verdict = known ? (*known)[k] : Verdict::Unknown;
            if (verdict == Verdict::Unknown) verdict = collapseVerdict(u, v, hh, target);
            // Topological obstacles do not depend on the target: give up at once.
            if (verdict == Verdict::Abort) return;
            if (verdict == Verdict::Skip) continue;
            if (mGuard && !mGuard->isCollapseSafe(hh, target)) continue;
            collapseAndRequeue(hh, target);
            return;
        }
    }

    /// What collapseShortEdge makes of one of its options before the intersection guard.
    enum class Verdict : std::int8_t { Unknown, Abort, Skip, Pass };

    /// The collapses of edge u-v (h from u to v) collapseShortEdge tries, in order, as (halfedge to
    /// collapse, target): into the midpoint, into v kept in place, into u kept in place.
    std::array<std::pair<HalfedgeHandle, Vec3>, 3> collapseOptions(HalfedgeHandle h) const
    {
        const Vec3 pu = position(mMesh, mMesh.from_vertex_handle(h)), pv = position(mMesh, mMesh.to_vertex_handle(h));
        return {{{h, Vec3(0.5 * (pu + pv))}, {h, pv}, {mMesh.opposite_halfedge_handle(h), pu}}};
    }

    /// Abort: a topological obstacle (no target can help); Skip: this target folds or degenerates a
    /// face, or makes an edge too long; Pass: only the intersection guard is left to ask. Reads
    /// u, v, their neighbours and the neighbours' valences, nothing else of the mesh.
    Verdict collapseVerdict(VertexHandle u, VertexHandle v, HalfedgeHandle hh, const Vec3& target) const
    {
        const detail::CollapseObstacles obstacles = detail::collapseObstacles(mMesh, hh, target);
        if (obstacles & ~detail::kCollapseGeometry) return Verdict::Abort;
        if (obstacles || !keepsEdgesShortEnough(u, v, target)) return Verdict::Skip;
        return Verdict::Pass;
    }

    /// The verdicts of the queued collapses, in parallel, on the mesh as the collapse pass finds it
    /// (most queued edges are refused, many of them at every iteration, and the verdicts are most
    /// of the pass's work). The pass then takes an edge's verdicts as long as no collapse has
    /// changed what they read: collapses mark the two rings around the vertex they keep (see
    /// updateRing), and the verdicts of edge u-v read only u, v and their neighbours' positions and
    /// rings, so they stand while neither u nor v is marked. The same collapses as deciding each
    /// edge in turn, for any thread count. Each edge's options are decided up to the first that
    /// passes or aborts (the rest stay Unknown, decided in turn if the guard refuses it).
    void speculateCollapses()
    {
        ++mSpeculation;
        mSpeculatedAt.resize(mMesh.n_edges(), 0);
        mVerdicts.resize(mMesh.n_edges());
        mCollapseMarks.assign(mMesh.n_vertices(), 0);
        mSpeculated.clear();
        for (const QueuedEdge& item : mShort) {
            const std::size_t i = std::size_t(item.edge);
            if (mMesh.status(EdgeHandle(item.edge)).deleted() || mSpeculatedAt[i] == mSpeculation) continue;
            mSpeculatedAt[i] = mSpeculation;
            mSpeculated.push_back(item.edge);
        }
        detail::parallelFor(0, mSpeculated.size(), kGrain / 4, [&](std::size_t k) {
            const EdgeHandle e(mSpeculated[k]);
            const HalfedgeHandle h = mMesh.halfedge_handle(e, 0);
            const VertexHandle u = mMesh.from_vertex_handle(h), v = mMesh.to_vertex_handle(h);
            std::array<Verdict, 3>& verdicts = mVerdicts[std::size_t(e.idx())];
            verdicts.fill(Verdict::Unknown);
            if (sharedOutsideNeighbour(mMesh, h).is_valid()) return; // (a cap or a tunnel: decided in turn)
            const auto options = collapseOptions(h);
            for (std::size_t i = 0; i < options.size(); ++i) {
                verdicts[i] = collapseVerdict(u, v, options[i].first, options[i].second);
                if (verdicts[i] != Verdict::Skip) break;
            }
        });
    }

    /// Edge e's verdicts if they still stand (see speculateCollapses), else nullptr.
    const std::array<Verdict, 3>* speculated(EdgeHandle e, VertexHandle u, VertexHandle v) const
    {
        const std::size_t i = std::size_t(e.idx());
        if (i >= mSpeculatedAt.size() || mSpeculatedAt[i] != mSpeculation) return nullptr;
        if (mCollapseMarks[std::size_t(u.idx())] || mCollapseMarks[std::size_t(v.idx())]) return nullptr;
        return &mVerdicts[i];
    }

    /// Collapses hh into `target` (guards already checked) and queues the short edges it made.
    void collapseAndRequeue(HalfedgeHandle hh, const Vec3& target)
    {
        const VertexHandle kept = detail::collapseUnchecked(mMesh, hh, target);
        ++mCollapses;
        noteMade(kept);
        updateRing(kept);
        for (auto oh = mMesh.cvoh_begin(kept); oh.is_valid(); ++oh) {
            const EdgeHandle ne = mMesh.edge_handle(*oh);
            const double l = length(ne);
            if (l < mLo) {
                mShort.push_back({l, l, ne.idx()});
                std::push_heap(mShort.begin(), mShort.end(), shorterFirst);
            }
        }
    }

    enum class CapResult { NotACap, Dissolved, Stuck };

    /// The loop u-v-w (u-v = h's edge, w a shared outside neighbour) bounds no face. If one side of
    /// it holds at most kMaxCapVertices vertices it is a small cap, not a tunnel: its vertices are
    /// collapsed one by one into their neighbours (kept in place) until the loop bounds a face.
    CapResult dissolveSmallCap(HalfedgeHandle h, VertexHandle w)
    {
        const VertexHandle u = mMesh.from_vertex_handle(h), v = mMesh.to_vertex_handle(h);
        const VertexHandle a = mMesh.to_vertex_handle(mMesh.next_halfedge_handle(h));
        const VertexHandle b = mMesh.to_vertex_handle(mMesh.next_halfedge_handle(mMesh.opposite_halfedge_handle(h)));
        if (!collectCap(a, u, v, w) && !collectCap(b, u, v, w)) return CapResult::NotACap;
        while (!mCap.empty()) {
            bool progress = false;
            for (std::size_t i = 0; i < mCap.size() && !progress; ++i) {
                const VertexHandle x = mCap[i];
                for (auto oh = mMesh.cvoh_begin(x); oh.is_valid(); ++oh) {
                    const Vec3 target = position(mMesh, mMesh.to_vertex_handle(*oh)); // the neighbour stays
                    if (detail::collapseObstacles(mMesh, *oh, target) != 0) continue;
                    if (!keepsEdgesShortEnough(x, mMesh.to_vertex_handle(*oh), target)) continue;
                    if (mGuard && !mGuard->isCollapseSafe(*oh, target)) continue;
                    collapseAndRequeue(*oh, target);
                    mCap.erase(mCap.begin() + std::ptrdiff_t(i));
                    progress = true;
                    break;
                }
            }
            if (!progress) return CapResult::Stuck;
        }
        return CapResult::Dissolved;
    }

    /// Collects into mCap the vertices reachable from `seed` without crossing u, v or w. Returns
    /// false (a large side: a tunnel or a real separation) once more than kMaxCapVertices are found.
    bool collectCap(VertexHandle seed, VertexHandle u, VertexHandle v, VertexHandle w)
    {
        mCap.clear();
        mCap.push_back(seed);
        for (std::size_t i = 0; i < mCap.size(); ++i) {
            for (auto n = mMesh.cvv_begin(mCap[i]); n.is_valid(); ++n) {
                const VertexHandle y = *n;
                if (y == u || y == v || y == w || std::find(mCap.begin(), mCap.end(), y) != mCap.end()) continue;
                if (mCap.size() == std::size_t(kMaxCapVertices)) return false;
                mCap.push_back(y);
            }
        }
        return true;
    }

    /// True when splitting h's edge at `mid` (world space) leaves no degenerate face. With a metric
    /// that jumps across a surface, bisecting the metric-longest edges can shrink a triangle toward a
    /// needle indefinitely; this stops it before the faces degenerate.
    bool splitKeepsFacesValid(HalfedgeHandle h, const Vec3& mid) const
    {
        const HalfedgeHandle sides[2] = {h, mMesh.opposite_halfedge_handle(h)};
        for (const HalfedgeHandle s : sides) {
            const Vec3 pu = position(mMesh, mMesh.from_vertex_handle(s)), pv = position(mMesh, mMesh.to_vertex_handle(s));
            const Vec3 pa = position(mMesh, mMesh.to_vertex_handle(mMesh.next_halfedge_handle(s)));
            if (!detail::isFaceAcceptable(Vec3::Zero(), pu, mid, pa) || !detail::isFaceAcceptable(Vec3::Zero(), mid, pv, pa))
                return false;
        }
        return true;
    }

    /// True when no edge from `target` to a neighbour of u or v would exceed kCollapseMargin zeta
    /// delta (metric length), nor be an edge that could not be split into regular halves
    /// (splitsIntoRegularHalves): refusing those collapses avoids split/collapse oscillation.
    ///
    /// The second condition is the one that matters where the metric grows by a large factor along
    /// an edge (a vertex on a face next to one on a crease, G ~4.5x larger along the edge at the
    /// crease end on the 300^3 phantom at delta 9). The mean of the end tensors then overestimates
    /// the edge: once the forces' rest position makes it longer than zeta delta it is split at its
    /// midpoint, the half on the face side comes out shorter than delta (0.7-0.9 delta), the
    /// collapse of that half moves the face vertex a quarter of the way toward the crease and makes
    /// the edge again (0.85-0.99 zeta delta), and the forces pull the vertex back: 3-8 splits and as
    /// many collapses every iteration, and the vertices pulled back count as travelling, so the run
    /// never converges (3,000 iterations). A margin on the first condition cannot stop it (the
    /// forces' rest position is past zeta delta whatever the margin): keeping the short half can.
    bool keepsEdgesShortEnough(VertexHandle u, VertexHandle v, const Vec3& target) const
    {
        const bool euclidean = mMetric.isEuclidean();
        const Mat3 gTarget = euclidean ? Mat3(Mat3::Identity()) : mMetric.at(target);
        const double checkFrom2 = kUnsplittableCheck * kUnsplittableCheck * mHi * mHi;
        const VertexHandle ends[2] = {u, v};
        for (const VertexHandle end : ends) {
            for (auto n = mMesh.cvv_begin(end); n.is_valid(); ++n) {
                if (*n == u || *n == v) continue;
                const Vec3 pn = position(mMesh, *n);
                const Vec3 d = pn - target;
                const double l2 = euclidean ? d.squaredNorm() : d.dot((0.5 * (gTarget + vertexMetric(*n))) * d);
                if (l2 > kCollapseMargin * kCollapseMargin * mHi * mHi) return false;
                // A Euclidean edge always halves (and zeta > 2 keeps the halves at least delta).
                if (!euclidean && l2 > checkFrom2 && !splitsIntoRegularHalves(target, gTarget, pn, vertexMetric(*n), std::sqrt(l2)))
                    return false;
            }
        }
        return true;
    }

    /// True when the edge a-b (metric length l, G at its ends ga and gb), stretched to zeta delta,
    /// would split at its midpoint into two halves of at least delta: the shorter half, measured
    /// with G sampled at the midpoint as a split measures it, is at least l / zeta. With a constant
    /// metric the halves are l / 2 and this holds for every zeta >= 2; it fails where G grows by a
    /// large factor between the midpoint and one end (see keepsEdgesShortEnough). With zeta < 2 no
    /// split leaves regular halves and there is nothing to protect: true.
    bool splitsIntoRegularHalves(const Vec3& a, const Mat3& ga, const Vec3& b, const Mat3& gb, double l) const
    {
        if (mHi < 2.0 * mLo) return true;
        const Vec3 mid = 0.5 * (a + b);
        const Mat3 gm = mMetric.at(mid);
        const double shorter = std::min(metricLength(ga, gm, mid - a), metricLength(gm, gb, b - mid));
        return shorter * mHi >= (1.0 - 1e-9) * mLo * l; // equality: zeta = 2 with a constant metric
    }

    /// Records the tunnel u-v-w once (whichever of its edges found it).
    void recordTunnel(VertexHandle u, VertexHandle v, VertexHandle w)
    {
        std::array<int, 3> key = {u.idx(), v.idx(), w.idx()};
        std::sort(key.begin(), key.end());
        for (const auto& t : mStats.tunnels) {
            std::array<int, 3> seen = {t.u.idx(), t.v.idx(), t.w.idx()};
            std::sort(seen.begin(), seen.end());
            if (seen == key) return;
        }
        mStats.tunnels.push_back({u, v, w});
    }

    /// True when the angles opposite edge u-v (at a and b), measured with G at the edge midpoint,
    /// sum to more than pi by a margin: flipping to a-b makes the pair Delaunay-like.
    bool violatesDelaunay(VertexHandle u, VertexHandle v, const Vec3& pu, const Vec3& pv, const Vec3& pa,
                          const Vec3& pb) const
    {
        Mat3 g;
        const bool euclidean = mMetric.isEuclidean();
        if (!euclidean) g = 0.5 * (vertexMetric(u) + vertexMetric(v));
        auto dot = [&](const Vec3& x, const Vec3& y) { return euclidean ? x.dot(y) : x.dot(g * y); };
        // cot of the angle between x and y: <x,y> / sqrt(|x|^2 |y|^2 - <x,y>^2) (Gram determinant).
        auto cot = [&](const Vec3& x, const Vec3& y) {
            const double xy = dot(x, y), gram = dot(x, x) * dot(y, y) - xy * xy;
            return gram > 0 ? xy / std::sqrt(gram) : 1e300;
        };
        return cot(pu - pa, pv - pa) + cot(pu - pb, pv - pb) < -kDelaunayTolerance;
    }

    Mesh& mMesh;
    const MetricField& mMetric;
    VertexMetrics mVertexMetrics;
    RegularityStats& mStats;
    double mLo; ///< delta (metric length)
    double mHi; ///< zeta * delta (metric length)
    std::vector<QueuedEdge> mLong, mShort;
    std::vector<int> mValence; ///< by vertex idx(), kept up to date by every edit
    static constexpr signed char kFits = 0, kLong = 1, kShort = -1;
    std::vector<signed char> mClass;  ///< by edge idx(): the class of its last measurement
    std::vector<char> mTouched;       ///< by vertex idx(): changed since the last measurement
    std::vector<int> mTouchedList;    ///< the vertices marked in mTouched
    std::vector<int> mEdges;          ///< the edges re-measured by measureTouched()
    std::vector<char> mEdgeSeen;      ///< by edge idx(): scratch of measureTouched()
    std::vector<char> mWanted;        ///< by edge idx(): isFlipWanted before a full flip sweep
    std::vector<int> mFlipQueue;      ///< edges around the flips of a sweep, ahead of it (min-heap)
    int mCollapses = 0;             ///< collapses of the current collapse stage
    std::vector<VertexHandle> mCap; ///< the vertices of a small cap being dissolved
    // speculateCollapses: by edge idx(), the verdicts and the speculation they belong to; by
    // vertex idx(), marked by the collapses since (empty outside a speculating collapse pass).
    std::vector<std::array<Verdict, 3>> mVerdicts;
    std::vector<std::uint32_t> mSpeculatedAt;
    std::uint32_t mSpeculation = 0;
    std::vector<char> mCollapseMarks;
    std::vector<int> mSpeculated;
    bool mSpeculate = true;
    std::unique_ptr<detail::IntersectionGuard> mGuard; ///< options.intersectionFree, edits asked in turn
    detail::MadeFaces* mMade = nullptr;                ///< (see the constructor)
    std::vector<char> mIsMade;                         ///< by vertex idx(): in mMade
    std::vector<char> mIsMadeFace;                     ///< by face idx(): noted by a flip (noteFlip)
};

} // namespace

struct RegularityCache::Impl {
    detail::GuardGrid guard;
    Mesh before;            ///< (checkEditsTogether's copy of the mesh, kept for its buffers)
    std::size_t lastEdits = std::size_t(-1); ///< the collapses and flips of the last call (none yet: many)
    int pause = 0; ///< calls left that ask edit by edit after a call checked together had to be made again
};

RegularityCache::RegularityCache() : mImpl(std::make_unique<Impl>()) {}
RegularityCache::~RegularityCache() = default;
RegularityCache::RegularityCache(RegularityCache&&) noexcept = default;
RegularityCache& RegularityCache::operator=(RegularityCache&&) noexcept = default;
RegularityCache::Mode RegularityCache::mode() const { return {mImpl->lastEdits, mImpl->pause}; }
void RegularityCache::setMode(const Mode& mode)
{
    mImpl->lastEdits = mode.lastEdits;
    mImpl->pause = mode.pause;
}
bool RegularityCache::handOver(Mesh& mesh, Mesh& snapshot) { return detail::handOverMarks(mesh, snapshot, mImpl->guard); }
void RegularityCache::bringUpToDate(Mesh& snapshot) { detail::bringUpToDateFrom(snapshot, mImpl->guard); }

void RegularityCache::invalidate()
{
    mImpl->guard.valid = false;
    mImpl->lastEdits = std::size_t(-1);
    mImpl->pause = 0;
}

namespace {

/// Calls that ask edit by edit after one whose edits, checked together, had to be made again:
/// where sheets press together, the next steps' edits would likely be made twice too
/// (brain-extracted MRI ch2bet at iso 40, guarded, 2 threads: 16 calls made again and a
/// regularity phase of 2.45 s without a pause; 5 and 2.15 s with 4 calls, 4 and 2.18 s with 16;
/// the same mesh).
constexpr int kPauseAfterRedone = 8;

/// The split, collapse and flip passes (see enforceRegularity), the collapses and flips asked of
/// the guard in turn, or, with `made`, made without asking and the faces they made noted there
/// (see detail::MadeFaces).
RegularityStats regularize(Mesh& mesh, const MetricField& metric, const RegularityOptions& options,
                           detail::GuardGrid* kept, detail::MadeFaces* made)
{
    RegularityStats stats;
    Regularizer regularizer(mesh, metric, options, stats, kept, made);
    for (int pass = 0; pass < options.maxPasses; ++pass) {
        if (pass == 0) regularizer.measure();
        else regularizer.measureTouched();
        int changes = 0;
        if (regularizer.longCount() > 0) {
            const int n = regularizer.splitLongEdges();
            stats.splits += n;
            changes += n;
        }
        if (regularizer.shortCount() > 0) { // includes short medians queued by the splits
            const int n = regularizer.collapseShortEdges();
            stats.collapses += n;
            changes += n;
        }
        if (options.flips) {
            const int n = regularizer.flipEdges(pass == 0);
            stats.flips += n;
            changes += n;
        }
        if (changes == 0) break;
    }
    std::tie(stats.tooLong, stats.tooShort) = regularizer.countOutside();
    regularizer.pruneTunnels();
    return stats;
}

} // namespace

RegularityStats detail::regularizeNotingEdits(Mesh& mesh, const MetricField& metric, const RegularityOptions& options,
                                              GuardGrid* kept, MadeFaces& made)
{
    return regularize(mesh, metric, options, kept, &made);
}

RegularityStats enforceRegularity(Mesh& mesh, const MetricField& metric, const RegularityOptions& options,
                                  RegularityCache* cache)
{
    if (!(options.delta > 0.0)) throw std::invalid_argument("enforceRegularity: delta must be > 0");
    if (!(options.zeta > 1.0)) throw std::invalid_argument("enforceRegularity: zeta must be > 1");
    detail::GuardGrid own;
    detail::GuardGrid* kept = cache ? &cache->impl().guard : &own;
    // Brought up to date beside this call (RegularityCache::handOver): taken by the first guard
    // (waited for, or called off), or here at the end if none asked (the grid then holds the
    // faces as the call found them, or as before, and the marks of its edits are left for the
    // next).
    struct Settle {
        detail::GuardGrid& g;
        ~Settle() { g.takeBeside(); }
    } settle{*kept};
    if (!options.intersectionFree) return regularize(mesh, metric, options, kept, nullptr);
    // Together when the last call made many edits and none of the last kPauseAfterRedone calls had
    // to be made again (or with no cache): the copy of the mesh costs about as much as what
    // checking together saves on an edit per 128 vertices (head MRI, 6,600 vertices: the copy
    // 0.19 ms; a guard question about 8 us, an edit checked together 4.5 us on two threads).
    std::size_t vertices = 0;
    for (auto v : mesh.vertices()) (void)v, ++vertices;
    const int paused = cache ? cache->impl().pause : 0;
    if (paused > 0) --cache->impl().pause;
    const bool together =
        options.checkEditsTogether && paused == 0 && (!cache || cache->impl().lastEdits > vertices / 128);
    if (!together) {
        RegularityStats stats = regularize(mesh, metric, options, kept, nullptr);
        if (cache) cache->impl().lastEdits = std::size_t(stats.collapses + stats.flips);
        return stats;
    }
    // The edits made without asking, then the faces they made checked together (in parallel);
    // if any would cross or come too close, the mesh as it was and the edits made again, each
    // asked in turn.
    std::unique_ptr<Mesh> ownBefore;
    Mesh& before = cache ? cache->impl().before : *(ownBefore = std::make_unique<Mesh>());
    before = mesh;
    detail::MadeFaces made;
    RegularityStats stats = detail::regularizeNotingEdits(mesh, metric, options, kept, made);
    const bool clear = detail::IntersectionGuard(mesh, options.minSeparation, kept).facesAroundAreClear(made);
    if (cache) cache->impl().lastEdits = std::size_t(stats.collapses + stats.flips);
    if (clear) return stats;
    mesh = before;
    kept->valid = false; // (the grid saw the edits undone here)
    stats = regularize(mesh, metric, options, kept, nullptr);
    stats.editsRedone = true;
    if (cache) cache->impl().pause = kPauseAfterRedone;
    return stats;
}

} // namespace riemesh
