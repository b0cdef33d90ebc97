#include "detail/intersection_guard.h"

#include "riemesh/ccd.h"

#include "detail/parallel.h"
#include "detail/triangle_intersection.h"

#include <algorithm>
#include <cmath>
#include <atomic>
#include <limits>
#include <thread>

namespace riemesh::detail {

namespace {
/// GuardGrid's margin, in mean face extents. Phantom 100^3 and head MRI, guarded: the faces
/// entered again per regularity step (see RegularityCache in riemesh/regularity.h).
constexpr double kGuardMargin = 0.1;

/// `inner` lies within `outer` (closed).
bool contains(const Box6& outer, const Box6& inner)
{
    return outer[0] <= inner[0] && outer[1] <= inner[1] && outer[2] <= inner[2] && inner[3] <= outer[3] &&
           inner[4] <= outer[4] && inner[5] <= outer[5];
}

/// p within `margin` of its reference r on every axis (false for a NaN reference: none yet).
bool withinReference(const Vec3& p, const Vec3& r, double margin)
{
    return std::abs(p.x() - r.x()) <= margin && std::abs(p.y() - r.y()) <= margin && std::abs(p.z() - r.z()) <= margin;
}

Box6 grownBy(Box6 box, double margin)
{
    for (int k = 0; k < 3; ++k) box[k] -= margin, box[k + 3] += margin;
    return box;
}
} // namespace

Box6 IntersectionGuard::faceBox(FaceHandle f) const
{
    const HalfedgeHandle h = mMesh.halfedge_handle(f);
    const Mesh::Point& a = mMesh.point(mMesh.from_vertex_handle(h));
    const Mesh::Point& b = mMesh.point(mMesh.to_vertex_handle(h));
    const Mesh::Point& c = mMesh.point(mMesh.to_vertex_handle(mMesh.next_halfedge_handle(h)));
    Box6 box;
    for (int k = 0; k < 3; ++k) {
        box[k] = std::min({a[k], b[k], c[k]});
        box[k + 3] = std::max({a[k], b[k], c[k]});
    }
    return box;
}

void IntersectionGuard::enter(FaceHandle f)
{
    GuardGrid& g = *mKept;
    const std::size_t i = std::size_t(f.idx());
    const HalfedgeHandle h = mMesh.halfedge_handle(f);
    const std::array<int, 3> c = {mMesh.from_vertex_handle(h).idx(), mMesh.to_vertex_handle(h).idx(),
                                  mMesh.to_vertex_handle(mMesh.next_halfedge_handle(h)).idx()};
    for (const int x : c) // (a vertex made since the references were given: its own now)
        if (std::size_t(x) >= g.ref.size() || std::isnan(g.ref[std::size_t(x)].x())) renewReference(VertexHandle(x));
    Box6 box;
    for (int k = 0; k < 3; ++k) {
        const double x0 = g.ref[std::size_t(c[0])][k], x1 = g.ref[std::size_t(c[1])][k], x2 = g.ref[std::size_t(c[2])][k];
        box[k] = std::min({x0, x1, x2}) - g.margin;
        box[k + 3] = std::max({x0, x1, x2}) + g.margin;
    }
    if (const Box6* entered = g.grid.boxOf(int(i)); entered && contains(*entered, box)) return;
    g.grid.insert(int(i), box);
}

bool IntersectionGuard::renewReference(VertexHandle v)
{
    GuardGrid& g = *mKept;
    const std::size_t i = std::size_t(v.idx());
    constexpr double none = std::numeric_limits<double>::quiet_NaN();
    if (i >= g.ref.size()) g.ref.resize(i + 1, Vec3::Constant(none));
    const Vec3 p = position(mMesh, v);
    if (withinReference(p, g.ref[i], g.margin)) return false;
    g.ref[i] = p;
    return true;
}

bool GuardGrid::takeBeside()
{
    int state = kPending;
    if (beside.compare_exchange_strong(state, kNone, std::memory_order_acq_rel)) return false; // (called off)
    if (state == kNone) return false;
    while (state == kRunning) { // (a fraction of a millisecond)
        std::this_thread::yield();
        state = beside.load(std::memory_order_acquire);
    }
    beside.store(kNone, std::memory_order_relaxed);
    return true;
}

void IntersectionGuard::build()
{
    mBuilt = true;
    if (mKept->takeBeside() && enterMarked()) return;
    bringUpToDate();
}

bool IntersectionGuard::enterMarked()
{
    GuardGrid& g = *mKept;
    OpenMesh::VPropHandleT<char> marks;
    const std::size_t nv = mMesh.n_vertices(), nf = mMesh.n_faces();
    if (!g.valid || !mMesh.get_property_handle(marks, kGuardEditedProperty) || nv < g.ref.size() || nf < g.faces)
        return false;
    // Brought up to date from the mesh as the regularity step found it: since, only the step's
    // edits have moved vertices or changed faces, and they marked their vertices. (The marks from
    // before, which the copy had, are here too: their faces, entered beside, are found in place.)
    std::vector<char>& marked = mMesh.property(marks).data_vector();
    g.ref.resize(nv, Vec3::Constant(std::numeric_limits<double>::quiet_NaN()));
    g.flagged.clear();
    for (std::size_t i = 0; i < nv; ++i)
        if (marked[i] && !mMesh.status(VertexHandle(int(i))).deleted()) g.flagged.push_back(int(i));
    enterFlagged(marked);
    return true;
}

void IntersectionGuard::enterFlagged(std::vector<char>& marked)
{
    GuardGrid& g = *mKept;
    const std::size_t nf = mMesh.n_faces();
    // Every new reference first, then the faces (a face entered before one of its corners had its
    // new reference would keep a box around the old one).
    for (const int i : g.flagged) {
        g.ref[std::size_t(i)] = position(mMesh, VertexHandle(i));
        marked[std::size_t(i)] = 0;
    }
    g.faces = nf;
    g.seen.resize(nf, 0u);
    if (++g.stamp == 0) std::fill(g.seen.begin(), g.seen.end(), 0u), g.stamp = 1;
    for (const int i : g.flagged)
        for (auto f = mMesh.cvf_begin(VertexHandle(i)); f.is_valid(); ++f) {
            unsigned& seen = g.seen[std::size_t(f->idx())];
            if (seen == g.stamp) continue;
            seen = g.stamp;
            enter(*f);
        }
}

void IntersectionGuard::bringUpToDate()
{
    mBuilt = true;
    GuardGrid& g = *mKept;
    OpenMesh::VPropHandleT<char> marks;
    if (!mMesh.get_property_handle(marks, kGuardEditedProperty)) {
        mMesh.add_property(marks, kGuardEditedProperty);
        g.valid = false; // (edits made before are not marked)
    }
    std::vector<char>& marked = mMesh.property(marks).data_vector();
    constexpr double none = std::numeric_limits<double>::quiet_NaN();
    // Kept from an earlier step: the vertices that left their references or whose faces an edit
    // changed are given new references (a pass over the vertices, in parallel), then their faces
    // are entered again (in index order: the grid is not thread-safe). Built anew when the mesh
    // has grown or shrunk twofold since (the cells were sized for its faces then).
    const std::size_t nv = mMesh.n_vertices(), nf = mMesh.n_faces();
    if (g.valid && nv >= g.ref.size() && nf >= g.faces) { // (fewer: renumbered, see RegularityCache)
        g.ref.resize(nv, Vec3::Constant(none));
        g.moved.assign(nv, 0);
        forLive<VertexHandle>(mMesh, nv, 2048, [&](std::size_t i) {
            g.moved[i] = marked[i] || !withinReference(position(mMesh, VertexHandle(int(i))), g.ref[i], g.margin);
        });
        std::size_t live = 0;
        g.flagged.clear();
        for (std::size_t i = 0; i < nv; ++i) {
            if (mMesh.status(VertexHandle(int(i))).deleted()) continue;
            ++live;
            if (g.moved[i]) g.flagged.push_back(int(i));
        }
        if (2 * live >= g.vertices && live <= 2 * g.vertices) {
            enterFlagged(marked);
            return;
        }
    }
    // The boxes in parallel, their extents summed in face order.
    mBoxes.assign(nf, Box6{});
    forLive<FaceHandle>(mMesh, nf, 2048, [&](std::size_t i) { mBoxes[i] = faceBox(FaceHandle(int(i))); });
    double extent = 0;
    std::size_t count = 0;
    for (auto f : mMesh.faces()) {
        const Box6& b = mBoxes[std::size_t(f.idx())];
        extent += std::max({b[3] - b[0], b[4] - b[1], b[5] - b[2]});
        ++count;
    }
    // Cells of twice the faces' mean extent: few faces are wider than 0.9 cell (those are tested by
    // every query), and a query visits about 3 cells per axis. Head MRI, guarded, 1 thread: the
    // edit guard's instructions 1.11 G with a BoxGrid (each face in every cell its box meets,
    // cells of the mean extent) -> 0.61 G (cells of 1.5 / 3 mean extents: 0.75 / 0.66 G).
    // Faces entered with their boxes grown by a tenth of the mean extent (see GuardGrid): most
    // vertices of a surface at rest stay that close to their references for many steps.
    const double mean = count ? extent / double(count) : 0.5;
    g.grid.reset(count ? std::max(2.0 * mean, 1e-9) : 1.0, nf);
    g.margin = kGuardMargin * mean;
    g.valid = true;
    g.ref.assign(nv, Vec3::Constant(none));
    g.vertices = 0;
    for (auto v : mMesh.vertices()) {
        g.ref[std::size_t(v.idx())] = position(mMesh, v);
        ++g.vertices;
    }
    std::fill(marked.begin(), marked.end(), 0);
    g.faces = nf;
    for (auto f : mMesh.faces()) g.grid.insert(f.idx(), grownBy(mBoxes[std::size_t(f.idx())], g.margin));
}

void IntersectionGuard::update(VertexHandle v)
{
    if (!mBuilt) return; // built (or brought up to date) from the current mesh when first needed
    renewReference(v);
    for (auto f = mMesh.cvf_begin(v); f.is_valid(); ++f) enter(*f);
}

IntersectionGuard::Triangle IntersectionGuard::triangle(FaceHandle f) const
{
    const HalfedgeHandle h = mMesh.halfedge_handle(f);
    const VertexHandle a = mMesh.from_vertex_handle(h), b = mMesh.to_vertex_handle(h);
    const VertexHandle c = mMesh.to_vertex_handle(mMesh.next_halfedge_handle(h));
    return {{a.idx(), b.idx(), c.idx()}, {position(mMesh, a), position(mMesh, b), position(mMesh, c)}};
}

template <class Skip>
bool IntersectionGuard::crosses(const std::vector<Triangle>& made, Scratch& scratch, Skip&& skip) const
{
    std::vector<TriangleRef> refs;
    refs.reserve(made.size());
    for (const Triangle& t : made) {
        refs.push_back(makeTriangle(t.p[0].data(), t.p[1].data(), t.p[2].data()));
        if (refs.back().axis < 0) return true; // a flat triangle: refuse
    }
    auto tooClose = [&](const std::array<int, 3>& ia, const std::array<Vec3, 3>& a, const std::array<int, 3>& ib,
                        const std::array<Vec3, 3>& b) {
        return trianglesCloserThan(ia, a, ib, b, mMinSeparation);
    };
    // Most pairs (neighbours around the edit: on the phantom 95% of the faces met share a corner
    // or an edge with the new face) are settled by a plane through what they share; the exact
    // tests decide the others.
    auto corners = [](const std::array<Vec3, 3>& p) {
        return std::array<const double*, 3>{p[0].data(), p[1].data(), p[2].data()};
    };
    for (std::size_t i = 0; i < made.size(); ++i)
        for (std::size_t j = i + 1; j < made.size(); ++j) {
            if (separatedBeyondShared(made[i].ids, corners(made[i].p).data(), made[j].ids, corners(made[j].p).data(),
                                      mMinSeparation))
                continue;
            if (classifyTriangles(made[i].ids, refs[i], made[j].ids, refs[j]) != TriangleContact::None ||
                tooClose(made[i].ids, made[i].p, made[j].ids, made[j].p))
                return true;
        }
    // The faces near any of them, from one query with the box around them all (each face is
    // looked up once, where a query per new triangle met most of them several times), then each
    // against the new triangles whose boxes (grown by the separation) overlap its own.
    std::vector<Box6>& boxes = scratch.boxes;
    boxes.resize(made.size());
    constexpr double inf = std::numeric_limits<double>::infinity();
    Box6 all = {inf, inf, inf, -inf, -inf, -inf};
    for (std::size_t i = 0; i < made.size(); ++i) {
        const Triangle& t = made[i];
        for (int k = 0; k < 3; ++k) {
            boxes[i][k] = std::min({t.p[0][k], t.p[1][k], t.p[2][k]}) - mMinSeparation;
            boxes[i][k + 3] = std::max({t.p[0][k], t.p[1][k], t.p[2][k]}) + mMinSeparation;
            all[k] = std::min(all[k], boxes[i][k]);
            all[k + 3] = std::max(all[k + 3], boxes[i][k + 3]);
        }
    }
    std::vector<int>& near = scratch.near;
    near.clear();
    mKept->grid.query(all, [&](int fi) { near.push_back(fi); });
    for (const int fi : near) {
        if (std::size_t(fi) >= mMesh.n_faces()) continue;
        const FaceHandle f(fi);
        if (mMesh.status(f).deleted()) continue;
        const HalfedgeHandle h = mMesh.halfedge_handle(f);
        const std::array<int, 3> ids = {mMesh.from_vertex_handle(h).idx(), mMesh.to_vertex_handle(h).idx(),
                                        mMesh.to_vertex_handle(mMesh.next_halfedge_handle(h)).idx()};
        if (skip(fi, ids)) continue;
        const std::array<const double*, 3> q = {mMesh.point(VertexHandle(ids[0])).data(),
                                                mMesh.point(VertexHandle(ids[1])).data(),
                                                mMesh.point(VertexHandle(ids[2])).data()};
        Box6 box;
        for (int k = 0; k < 3; ++k) {
            box[k] = std::min({q[0][k], q[1][k], q[2][k]});
            box[k + 3] = std::max({q[0][k], q[1][k], q[2][k]});
        }
        TriangleRef ref{};
        bool haveRef = false;
        for (std::size_t i = 0; i < made.size(); ++i) {
            const Triangle& t = made[i];
            if (!boxesOverlap(boxes[i], box)) continue;
            if (separatedBeyondShared(t.ids, corners(t.p).data(), ids, q.data(), mMinSeparation)) continue;
            if (!haveRef) ref = makeTriangle(q[0], q[1], q[2]), haveRef = true;
            if (ref.axis < 0) break; // a degenerate face: nothing to cross
            if (classifyTriangles(t.ids, refs[i], ids, ref) != TriangleContact::None) return true;
            if (mMinSeparation > 0) {
                const std::array<Vec3, 3> p = {position(mMesh, VertexHandle(ids[0])), position(mMesh, VertexHandle(ids[1])),
                                               position(mMesh, VertexHandle(ids[2]))};
                if (tooClose(t.ids, t.p, ids, p)) return true;
            }
        }
    }
    return false;
}

bool IntersectionGuard::facesAroundAreClear(const MadeFaces& made)
{
    if (!mBuilt) build();
    // Each live face once, owned by the first group it belongs to: the faces around each vertex of
    // made.vertices, then each pair of made.flipped (the group k's faces: mOwned[mStart[k],
    // mStart[k + 1])).
    const std::vector<int>& around = made.vertices;
    const std::size_t groups = around.size() + made.flipped.size();
    mOwner.assign(mMesh.n_faces(), -1);
    mStart.assign(groups + 1, 0);
    mOwned.clear();
    auto own = [&](int f, std::size_t k) {
        int& owner = mOwner[std::size_t(f)];
        if (owner >= 0) return;
        owner = int(k);
        mOwned.push_back(f);
    };
    for (std::size_t k = 0; k < around.size(); ++k) {
        mStart[k] = mOwned.size();
        const VertexHandle v(around[k]);
        if (std::size_t(around[k]) >= mMesh.n_vertices() || mMesh.status(v).deleted()) continue;
        for (auto f = mMesh.cvf_begin(v); f.is_valid(); ++f) own(f->idx(), k);
    }
    for (std::size_t j = 0; j < made.flipped.size(); ++j) {
        const std::size_t k = around.size() + j;
        mStart[k] = mOwned.size();
        for (const int f : made.flipped[j])
            if (std::size_t(f) < mMesh.n_faces() && !mMesh.status(FaceHandle(f)).deleted()) own(f, k);
    }
    mStart[groups] = mOwned.size();
    // Each group's faces as the made triangles of an edit: against each other, and against the
    // faces near them but their own and those of a group before it (that one tested the pair).
    std::atomic<bool> crossing{false};
    detail::parallelForChunks(0, groups, 16, [&](std::size_t k0, std::size_t k1) {
        static thread_local std::vector<Triangle> triangles; // (the group's faces)
        static thread_local Scratch scratch;
        for (std::size_t k = k0; k < k1 && !crossing.load(std::memory_order_relaxed); ++k) {
            if (mStart[k] == mStart[k + 1]) continue;
            triangles.clear();
            for (std::size_t i = mStart[k]; i < mStart[k + 1]; ++i) triangles.push_back(triangle(FaceHandle(mOwned[i])));
            const int self = int(k);
            if (crosses(triangles, scratch, [&](int fi, const std::array<int, 3>&) {
                    const int owner = mOwner[std::size_t(fi)];
                    return owner >= 0 && owner <= self;
                }))
                crossing = true;
        }
    });
    return !crossing;
}

bool IntersectionGuard::isCollapseSafe(HalfedgeHandle h, const Vec3& target)
{
    const VertexHandle u = mMesh.from_vertex_handle(h), v = mMesh.to_vertex_handle(h);
    const FaceHandle left = mMesh.face_handle(h), right = mMesh.face_handle(mMesh.opposite_halfedge_handle(h));
    mMade.clear();
    for (const VertexHandle x : {u, v})
        for (auto f = mMesh.cvf_begin(x); f.is_valid(); ++f) {
            if (*f == left || *f == right) continue;
            Triangle t;
            int k = 0;
            for (auto w = mMesh.cfv_begin(*f); w.is_valid(); ++w, ++k) {
                const bool moved = *w == u || *w == v;
                t.ids[std::size_t(k)] = moved ? v.idx() : w->idx();
                t.p[std::size_t(k)] = moved ? target : position(mMesh, *w);
            }
            mMade.push_back(t);
        }
    if (!mBuilt) build();
    const int gone[2] = {u.idx(), v.idx()};
    return !crosses(mMade, mScratch, [&](int, const std::array<int, 3>& ids) {
        return std::any_of(ids.begin(), ids.end(), [&](int x) { return x == gone[0] || x == gone[1]; });
    });
}

bool IntersectionGuard::isFlipSafe(EdgeHandle e)
{
    const HalfedgeHandle h = mMesh.halfedge_handle(e, 0), o = mMesh.halfedge_handle(e, 1);
    const VertexHandle u = mMesh.from_vertex_handle(h), v = mMesh.to_vertex_handle(h);
    const VertexHandle a = mMesh.to_vertex_handle(mMesh.next_halfedge_handle(h));
    const VertexHandle b = mMesh.to_vertex_handle(mMesh.next_halfedge_handle(o));
    mMade.clear();
    mMade.push_back({{u.idx(), b.idx(), a.idx()}, {position(mMesh, u), position(mMesh, b), position(mMesh, a)}});
    mMade.push_back({{v.idx(), a.idx(), b.idx()}, {position(mMesh, v), position(mMesh, a), position(mMesh, b)}});
    if (!mBuilt) build();
    const int goneFaces[2] = {mMesh.face_handle(h).idx(), mMesh.face_handle(o).idx()};
    return !crosses(mMade, mScratch, [&](int fi, const std::array<int, 3>&) { return fi == goneFaces[0] || fi == goneFaces[1]; });
}

bool handOverMarks(Mesh& mesh, Mesh& snapshot, GuardGrid& g)
{
    OpenMesh::VPropHandleT<char> from, to;
    if (!mesh.get_property_handle(from, kGuardEditedProperty)) return false;
    if (!snapshot.get_property_handle(to, kGuardEditedProperty)) snapshot.add_property(to, kGuardEditedProperty);
    snapshot.property(to).data_vector() = mesh.property(from).data_vector();
    g.beside.store(GuardGrid::kPending, std::memory_order_release);
    return true;
}

void bringUpToDateFrom(Mesh& snapshot, GuardGrid& g)
{
    int state = GuardGrid::kPending;
    if (!g.beside.compare_exchange_strong(state, GuardGrid::kRunning, std::memory_order_acq_rel)) return; // (called off)
    try {
        IntersectionGuard(snapshot, 0.0, &g).bringUpToDate();
    } catch (...) {
        g.valid = false; // (built anew where it is waited for)
        g.beside.store(GuardGrid::kReady, std::memory_order_release);
        throw;
    }
    g.beside.store(GuardGrid::kReady, std::memory_order_release);
}

} // namespace riemesh::detail
