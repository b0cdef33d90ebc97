#include "riemesh/evolution.h"

#include "riemesh/ccd.h"
#include "riemesh/collision.h"
#include "riemesh/primitives.h"
#include "riemesh/regularity.h"
#include "riemesh/self_intersection.h"
#include "riemesh/topology.h"

#include "detail/parallel.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace riemesh {

const char* toString(StopReason reason)
{
    switch (reason) {
    case StopReason::Running: return "running";
    case StopReason::Converged: return "converged";
    case StopReason::IterationCap: return "iteration-cap";
    case StopReason::Interrupted: return "interrupted";
    case StopReason::VertexCap: return "vertex-cap";
    }
    return "unknown";
}

namespace {

/// Meshes smaller than this are never renumbered (see step()): at ~250 bytes per vertex they fit
/// in a core's cache (1-2 MB here), and core_bench measured the gain only above it.
constexpr std::size_t kRenumberMinVertices = 16384;

/// A component of a coarse level with this many vertices or fewer has collapsed (see
/// updateConvergence()).
constexpr std::size_t kCollapsedComponent = 6;
/// Edits of the intersection-free evolution keep this fraction of its minimal separation between
/// their new faces and the rest (see step()).
constexpr double kEditSeparation = 1e-3;

/// Per-vertex memory of the topology changes around it (kTopologyHoldProperty): for how many more
/// iterations a merge is refused there after a cut, and how many changes (merges and cuts) have
/// touched it. See Evolution::holdTopology().
struct TopologyHold {
    std::uint16_t afterCut = 0;
    std::uint8_t changes = 0;
};
constexpr const char* kTopologyHoldProperty = "riemesh:topology_hold";
/// The first hold lasts kHoldIterations; each earlier change at a vertex doubles it, up to
/// 2^kMaxHoldDoublings times (10 x 256 = 2,560 iterations: the rest of any run).
constexpr int kHoldIterations = 10;
constexpr int kMaxHoldDoublings = 8;

/// The number of vertices of the smallest connected component (0 for an empty mesh).
std::size_t smallestComponent(const Mesh& mesh)
{
    int count = 0;
    const std::vector<int> label = componentLabels(mesh, &count);
    if (count == 0) return 0;
    std::vector<std::size_t> size(std::size_t(count), 0);
    for (int l : label)
        if (l >= 0) ++size[std::size_t(l)];
    return *std::min_element(size.begin(), size.end());
}

/// Deletes the components of at most kCollapsedComponent vertices that are inside out (see
/// step()); returns how many went.
int removeCollapsedComponents(Mesh& mesh)
{
    int count = 0;
    const std::vector<int> label = componentLabels(mesh, &count);
    std::vector<std::size_t> size(std::size_t(count), 0);
    for (int l : label)
        if (l >= 0) ++size[std::size_t(l)];
    if (std::none_of(size.begin(), size.end(), [](std::size_t n) { return n <= kCollapsedComponent; })) return 0;
    const std::vector<ComponentShape> shapes = componentShapes(mesh, label, count);
    std::vector<char> doomed(std::size_t(count), 0);
    int removed = 0;
    for (std::size_t i = 0; i < shapes.size(); ++i)
        if (shapes[i].vertices <= kCollapsedComponent && !shapes[i].outward()) doomed[i] = 1, ++removed;
    if (!removed) return 0;
    for (auto f : mesh.faces())
        if (doomed[std::size_t(label[mesh.fv_begin(f)->idx()])]) mesh.delete_face(f, true);
    return removed;
}

/// The box makeInitialBox() meshes: the image's bounds inset by a voxel, moved out by `grow`.
Box3 initialBoxBounds(const ScalarImage& image, double grow, const char* who)
{
    const Box3 b = image.bounds();
    const Vec3 inset = Vec3::Constant(image.voxelSize() - std::max(grow, 0.0));
    const Box3 box(b.min() + inset, b.max() - inset);
    if (!(box.max().array() > box.min().array()).all())
        throw std::invalid_argument(std::string(who) + ": the image is too small for an initial box (needs > 2 voxels per axis)");
    return box;
}

/// Where the image says the object is: +1 object, -1 background, 0 unclear (within `margin` of
/// the isovalue; see keepSettledPairsApart).
int imageSide(const ScalarImage& image, const ForceOptions& forces, const Vec3& x)
{
    const double object = (forces.objectBrighter ? 1.0 : -1.0) * (image.value(x) - forces.iso);
    return object > 0 ? 1 : object < 0 ? -1 : 0;
}

/// Colliding pairs whose two sheets already hold what the image says lies between them become
/// contacts (held apart, see step()) instead of merges. A merge removes what lies between the two
/// sheets near the pair: the mesh's inside when their normals point away from each other (a hole
/// through the enclosed volume), its outside when they face each other (the gap is filled). That
/// is right only across background, respectively object: the two faces of a plate thinner than
/// the collision radius must not merge through the plate, nor two objects closer than it join. A
/// 3-voxel plate at noise 0.8 otherwise merged and cut at its rim until the iteration cap. Pairs
/// whose image in between is unclear (three samples not all on one side) merge as the paper's
/// model would, except on the coarse levels of a schedule (`coarse`), where one of the three
/// showing what the merge would remove holds the pair: their cells are wider than the thin parts
/// that only the finest level sees, and their merges punched holes through a plate that the
/// sheets closing on it in free flight held at their middle sample only; the finer levels then
/// had to grow the holes shut (thin plate 400^3: a bite 40 voxels deep was left to the finest
/// level, 190 iterations and a Hausdorff distance of 6 voxels; now 92 iterations and 1.6). The
/// finest level decides the topology as the paper's model does.
void keepSettledPairsApart(const Mesh& mesh, const ScalarImage& image, const ForceOptions& forces, bool coarse,
                           std::vector<CollisionPair>& collisions, std::vector<CollisionPair>& contacts)
{
    std::size_t kept = 0;
    for (const CollisionPair& c : collisions) {
        const Vec3 u = position(mesh, c.u), e = position(mesh, c.w) - u;
        const double au = vertexNormal(mesh, c.u).dot(e), aw = vertexNormal(mesh, c.w).dot(e);
        const int between = au < 0 && aw > 0 ? 1 : au > 0 && aw < 0 ? -1 : 0; // inside between: 1
        int agree = 0; // samples in between that show what a merge would remove
        if (between != 0)
            for (double t : {0.25, 0.5, 0.75}) agree += imageSide(image, forces, u + t * e) == between;
        const bool held = agree == 3 || (coarse && agree > 0);
        if (held)
            contacts.push_back(c);
        else
            collisions[kept++] = c;
    }
    collisions.resize(kept);
}

/// Tunnel cuts (Fig. 3b) remove a neck of the enclosed volume: the disc the loop u, v, w spans lies
/// inside it. Where the image says that disc is object (its centre and the midpoints towards its
/// three corners), the neck is the object's own (a plate thinner than the model's edges, seen
/// edge-on): it stays, and the short edge with it.
void keepObjectNecks(const Mesh& mesh, const ScalarImage& image, const ForceOptions& forces,
                     std::vector<TunnelCandidate>& tunnels)
{
    std::size_t kept = 0;
    for (const TunnelCandidate& t : tunnels) {
        const Vec3 a = position(mesh, t.u), b = position(mesh, t.v), c = position(mesh, t.w);
        const Vec3 centre = (a + b + c) / 3.0;
        bool object = imageSide(image, forces, centre) > 0;
        for (const Vec3* corner : {&a, &b, &c})
            if (object && imageSide(image, forces, 0.5 * (centre + *corner)) <= 0) object = false;
        if (!object) tunnels[kept++] = t;
    }
    tunnels.resize(kept);
}

/// Copies into `to`, in its buffers, what the collision-safe step reads and writes of `from`:
/// connectivity and statuses, positions, velocities and edit marks (`to`'s other properties are
/// resized, not copied). Evolution::step copies the mesh so for the step it runs beside the
/// regularity step, and back over the mesh that step edited if the step was cut short: the
/// regularity step only adds elements (no garbage collection) and writes, of the other
/// properties, only the metric's samples (taken again where a vertex is not where its sample
/// was, see VertexMetrics) and the new vertices' travel anchors (those vertices go with the
/// copy), so the other properties of the elements `from` has are theirs again. The whole mesh
/// was copied before: head MRI, guarded, 2 threads, the 85 copies took 13.4 ms, these 3.8 ms
/// (phantom 100^3: 4.8 -> 1.3 ms).
void copySafeStepParts(const Mesh& from, Mesh& to)
{
    to.assign_connectivity(from); // (the statuses requested and sized, not copied)
    to.property(to.vertex_status_pph()).data_vector() = from.property(from.vertex_status_pph()).data_vector();
    to.property(to.halfedge_status_pph()).data_vector() = from.property(from.halfedge_status_pph()).data_vector();
    to.property(to.edge_status_pph()).data_vector() = from.property(from.edge_status_pph()).data_vector();
    to.property(to.face_status_pph()).data_vector() = from.property(from.face_status_pph()).data_vector();
    to.property(to.points_property_handle()).data_vector() = from.property(from.points_property_handle()).data_vector();
    OpenMesh::VPropHandleT<OpenMesh::Vec3d> fromVelocity;
    if (from.get_property_handle(fromVelocity, kVelocityProperty))
        to.property(velocityProperty(to)).data_vector() = from.property(fromVelocity).data_vector();
    OpenMesh::VPropHandleT<char> fromEdited, toEdited;
    if (from.get_property_handle(fromEdited, kEditedProperty)) {
        if (!to.get_property_handle(toEdited, kEditedProperty)) to.add_property(toEdited, kEditedProperty);
        to.property(toEdited).data_vector() = from.property(fromEdited).data_vector();
    }
}

/// Free flight at most this fraction of vmax (see step()).
constexpr double kCreaseRoom = 0.70710678118654752;

void validate(const EvolutionOptions& o)
{
    if (!(o.delta > 0) || !std::isfinite(o.delta)) throw std::invalid_argument("evolution: delta must be > 0");
    if (!(o.zeta >= 2.0) || !std::isfinite(o.zeta)) throw std::invalid_argument("evolution: zeta must be >= 2");
    if (!(o.vmaxFraction > 0 && o.vmaxFraction <= 1)) throw std::invalid_argument("evolution: vmaxFraction must be in (0, 1]");
    if (!(o.mass > 0) || !(o.damping >= 0)) throw std::invalid_argument("evolution: mass must be > 0 and damping >= 0");
    if (o.maxIterations < 0 || o.convergenceWindow < 1) throw std::invalid_argument("evolution: bad iteration limits");
    if (o.tangleCheckFirst < 1) throw std::invalid_argument("evolution: tangleCheckFirst must be >= 1");
    if (!(o.coarseMetricReach >= 0) || !std::isfinite(o.coarseMetricReach))
        throw std::invalid_argument("evolution: coarseMetricReach must be finite and >= 0");
}

} // namespace

Evolution::Evolution(Mesh& mesh, const ScalarImage& image, const MetricField& metric, const EvolutionOptions& options)
    : Evolution(mesh, std::vector<EvolutionLevel>{{&image, 1.0}}, metric, options)
{
}

/// The collision-safe step of an iteration run beside its regularity step (see step()).
struct Evolution::Beside {
    detail::Background job;
    Mesh mesh;           ///< the mesh as integration left it, which the step limits (copySafeStepParts)
    SafeStepStats stats; ///< the step's
    int pause = 0;       ///< iterations left that limit the step first (after one that was cut short)
};

/// Iterations that limit the step before the regularity step after one whose step, run beside
/// it, was cut short (sheets pressed together cut many steps in a row: the brain-extracted MRI
/// ch2bet at iso 40 has 118 of its 162 steps cut short).
constexpr int kBesidePause = 8;

Evolution::~Evolution() = default; // (mBeside's job waits: it uses the members declared before it)

Evolution::Evolution(Mesh& mesh, std::vector<EvolutionLevel> levels, const MetricField& metric, const EvolutionOptions& options)
    : mMesh(mesh), mLevels(std::move(levels)), mMetric(metric), mOptions(options), mBeside(std::make_unique<Beside>())
{
    validate(mOptions);
    if (mLevels.empty()) throw std::invalid_argument("evolution: no level");
    for (const auto& l : mLevels)
        if (!l.image || !(l.scale >= 1.0) || !std::isfinite(l.scale))
            throw std::invalid_argument("evolution: every level needs an image and a scale >= 1");
    if (mOptions.coarseConvergenceWindow < 1 || mOptions.coarseMaxIterations < 1 || !(mOptions.coarseNetTravel >= 0) ||
        !std::isfinite(mOptions.coarseNetTravel) || !(mOptions.levelSkipReach >= 0) || !std::isfinite(mOptions.levelSkipReach))
        throw std::invalid_argument("evolution: bad coarse-level limits");
    if (!(mOptions.coarseExternalLimit >= 0) || !std::isfinite(mOptions.coarseExternalLimit) ||
        !(mOptions.coarseFreeCurvatureFactor >= 0) || !std::isfinite(mOptions.coarseFreeCurvatureFactor))
        throw std::invalid_argument("evolution: coarse-level forces must be finite and >= 0");
    prepareMesh(mMesh);
    // The coarse levels' metric reaches out to their surfaces (see coarseMetricReach).
    mLevelMetrics.resize(mLevels.size());
    if (mOptions.coarseMetricReach > 0 && !mMetric.isEuclidean())
        for (std::size_t l = 0; l + 1 < mLevels.size(); ++l)
            if (mLevels[l].scale > 1)
                mLevelMetrics[l] = std::make_unique<DilatedMetric>(
                    mMetric, mOptions.coarseMetricReach * mLevels[l].image->voxelSize());
    if (mLevels.size() > 1) mInitialMesh = mMesh;
    if (untangling()) mUntangleMesh = mMesh;
    mChurn = mMesh.n_vertices(); // a given mesh's numbering is unknown: renumbered at the first step
    OpenMesh::VPropHandleT<char> mergeZone; // zones left by an earlier run count down from the start
    if (mMesh.get_property_handle(mergeZone, kMergedProperty)) mLastMerge = 1;
    OpenMesh::VPropHandleT<int> cutId; // cut ids left by an earlier run are not fresh
    if (mMesh.get_property_handle(cutId, kCutIdProperty))
        for (auto v : mMesh.vertices()) mCutIdSeen = std::max(mCutIdSeen, mMesh.property(cutId, v));
    OpenMesh::VPropHandleT<TopologyHold> holds; // and holds count down from the start
    if (mMesh.get_property_handle(holds, kTopologyHoldProperty)) mHoldUntil = kHoldIterations << kMaxHoldDoublings;
}

void Evolution::setOptions(const EvolutionOptions& options)
{
    validate(options);
    mOptions = options;
    if (mReason == StopReason::Converged || mReason == StopReason::IterationCap) mReason = StopReason::Running;
    mLastTopologyEvent = int(mHistory.size());
}

const MetricField& Evolution::levelMetric() const
{
    return mLevelMetrics[std::size_t(mLevel)] ? *mLevelMetrics[std::size_t(mLevel)] : mMetric;
}

EvolutionOptions Evolution::levelOptions() const
{
    EvolutionOptions o = mOptions;
    o.delta *= mLevels[mLevel].scale;
    return o;
}

IterationStats Evolution::step()
{
    IterationStats it;
    if (done()) return it;
    const auto start = std::chrono::steady_clock::now();
    auto lap = start;
    auto phase = [&lap](double& ms) {
        const auto t = std::chrono::steady_clock::now();
        ms = std::chrono::duration<double, std::milli>(t - lap).count();
        lap = t;
    };
    const EvolutionOptions o = levelOptions();
    const ScalarImage& image = *mLevels[mLevel].image;
    const double vmax = o.vmaxFraction * o.delta;

    // G at every vertex once per position: the samples taken after the last integration serve the
    // regularity step and now the forces (only vertices created or moved since are sampled here).
    const MetricField& metric = levelMetric();
    VertexMetrics vertexMetrics(mMesh, metric);
    vertexMetrics.update();
    // Free flight runs at the terminal speed externalLimit delta / damping. A convex crease of the
    // front (a deflating box's edges) travels along its bisector, sqrt 2 times as far as the
    // faces beside it for a right angle: were the faces already at vmax, the clamp would hold the
    // crease back and it would sharpen into a fin whose sides cross. So the push is capped where
    // the faces would fly faster than vmax / sqrt 2 (never with the defaults: 0.25 vs 0.35 delta).
    ForceOptions forces = o.forces;
    if (mLevel + 2 < int(mLevels.size())) { // a coarse level but the last (see coarseExternalLimit)
        forces.externalLimit = o.coarseExternalLimit;
        forces.freeCurvatureWeight *= o.coarseFreeCurvatureFactor;
    }
    if (o.damping > 0) forces.externalLimit = std::min(forces.externalLimit, kCreaseRoom * o.damping * vmax / o.delta);
    computeForces(mMesh, image, forces, o.delta, mForces, &metric);
    phase(it.phases.forces);
    IntegrationOptions io;
    io.mass = o.mass;
    io.damping = o.damping;
    io.vmax = vmax;
    io.movingSpeed = 0.5 * forces.externalLimit * o.delta / std::max(o.damping, 1e-9); // half the terminal speed F/gamma
    if (o.intersectionFree) { // the start of the step, for its collision check
        mStepStart.resize(mMesh.n_vertices());
        for (auto v : mMesh.vertices()) mStepStart[std::size_t(v.idx())] = position(mMesh, v);
    }
    IntegrationStats is = integrate(mMesh, mForces, io);
    SafeStepOptions so;
    so.minSeparation = o.minSeparation * o.delta;
    // With the guarantee, the collision-safe step runs beside the regularity step (on another
    // thread, when the core's loops may use more than one), on a copy of the mesh as integration
    // left it, while the regularity step edits the mesh at the positions integration gave: the
    // regularity step is mostly sequential, and the step's search costs about as much. A step
    // that comes out cut short (a vertex moved back) makes the regularity step's edits void: the
    // mesh is then the copy, cut short, and the regularity step is made again, as if the step
    // had come first (the same mesh either way, and for any thread count). Edit marks
    // (kEditedProperty): the copy keeps those the step reads and clears, the mesh gets those of
    // the regularity step alone; merged after.
    OpenMesh::VPropHandleT<char> edited;
    RegularityCache::Mode regularityMode;
    Beside& beside = *mBeside;
    const bool besides = o.intersectionFree && beside.job.concurrent() && beside.pause == 0;
    struct Waiter { // (an exception before the wait below still waits for the job)
        detail::Background& job;
        ~Waiter()
        {
            try {
                job.wait();
            } catch (...) { // (the exception under way is the one to report)
            }
        }
    } waiter{beside.job};
    if (o.intersectionFree) {
        mStepEnd.resize(mMesh.n_vertices());
        for (auto v : mMesh.vertices()) mStepEnd[std::size_t(v.idx())] = position(mMesh, v);
        if (!besides) {
            if (beside.pause > 0) --beside.pause;
            const SafeStepStats ss = limitStepToCollisionFree(mMesh, mStepStart, so, &mSafeStepCache);
            it.cutShort = ss.shortened;
            if (ss.shortened > 0) is = accountForShortenedStep(mMesh, mStepStart, mStepEnd, io);
        }
    }
    vertexMetrics.update(); // every vertex that moved
    if (besides) { // (after the metric's samples, which use both threads)
        if (!mMesh.get_property_handle(edited, kEditedProperty)) mMesh.add_property(edited, kEditedProperty);
        copySafeStepParts(mMesh, beside.mesh);
        for (auto v : mMesh.all_vertices()) mMesh.property(edited, v) = 0;
        regularityMode = mRegularityCache.mode();
        // The edit guard's grid is brought up to date there too, first: a pass over the vertices
        // and the faces of those that moved entered again, sequential, was the regularity step's
        // work before. Its first guard waits for that if it has begun, else calls it off and does
        // it itself (see GuardGrid::beside).
        const bool guardBeside = mRegularityCache.handOver(mMesh, beside.mesh);
        beside.job.run([this, so, guardBeside] {
            if (guardBeside) mRegularityCache.bringUpToDate(mBeside->mesh);
            mBeside->stats = limitStepToCollisionFree(mBeside->mesh, mStepStart, so, &mSafeStepCache);
        });
    }
    phase(it.phases.integration);

    RegularityOptions ro;
    ro.delta = o.delta;
    ro.zeta = o.zeta;
    ro.intersectionFree = o.intersectionFree;
    // Edits leave their new faces a little apart from the rest (far above round-off, far below
    // what a merge bridges): left 1e-15 from a face, a vertex is on either side of it after the
    // next motion however the step is limited (stress case 7047475164732749801: a merge band).
    const double editSeparation = o.intersectionFree ? kEditSeparation * o.minSeparation * o.delta : 0.0;
    ro.minSeparation = editSeparation;
    if (mLevel > 0 && int(mHistory.size()) - mLevelStart < o.levelSettleIterations) {
        const double c = std::min(o.levelSettleFactor, 0.5 * o.zeta); // halves of a split edge stay >= c delta
        ro.delta = c * o.delta;
        ro.zeta = o.zeta / c;
    }
    RegularityStats rs;
    auto regularize = [&] {
        rs = enforceRegularity(mMesh, metric, ro, &mRegularityCache);
        keepObjectNecks(mMesh, image, o.forces, rs.tunnels);
        vertexMetrics.update(); // the vertices the edits made or moved: for the collision search, and the next step
    };
    regularize();
    phase(it.phases.regularity);

    CollisionOptions co;
    co.delta = o.delta;
    co.zeta = o.zeta;
    co.vmax = vmax;
    std::vector<CollisionPair> contacts, collisions;
    auto searchCollisions = [&] {
        contacts.clear();
        collisions = findCollisions(mMesh, metric, co, &contacts);
        keepSettledPairsApart(mMesh, image, o.forces, level() > 0, collisions, contacts);
    };
    searchCollisions();
    // The collision-safe step run beside is waited for only now: the collision search reads the
    // mesh and writes nothing but its metric samples, so it fills the time the step may still
    // take (and is made again with the regularity step after a step cut short). Its wait counts
    // in the collision phase.
    if (besides) {
        beside.job.wait();
        it.cutShort = beside.stats.shortened;
        if (beside.stats.shortened == 0) {
            OpenMesh::VPropHandleT<char> stepEdited; // (the step's marks, with the edits')
            if (beside.mesh.get_property_handle(stepEdited, kEditedProperty)) {
                const std::vector<char>& marks = beside.mesh.property(stepEdited).data_vector();
                std::vector<char>& into = mMesh.property(edited).data_vector();
                for (std::size_t i = 0; i < marks.size(); ++i) into[i] |= marks[i];
            }
        } else { // cut short: the regularity step and the collision search made again after it
            copySafeStepParts(beside.mesh, mMesh);
            is = accountForShortenedStep(mMesh, mStepStart, mStepEnd, io);
            vertexMetrics.update();
            mRegularityCache.invalidate(); // (its grid saw faces that are gone)
            mRegularityCache.setMode(regularityMode);
            regularize();
            searchCollisions();
            beside.pause = kBesidePause;
            it.regularityRedone = true;
        }
    }
    phase(it.phases.collisions);
    TopologyStats ts;
    holdTopology(collisions, contacts);
    if (!collisions.empty() || !rs.tunnels.empty()) {
        TopologyOptions to;
        to.neighbourhoodRadius = co.neighbourhoodFactor * collisionRadius(metric, co);
        to.minSeparation = editSeparation;
        ts = resolveTopology(mMesh, collisions, rs.tunnels, to);
    }
    if (!ts.unresolved.empty() || !contacts.empty()) { // before garbage collection: handles valid
        OpenMesh::VPropHandleT<Hold> hold;
        if (!mMesh.get_property_handle(hold, kHoldProperty)) mMesh.add_property(hold, kHoldProperty);
        for (const auto* pairs : {&ts.unresolved, &contacts})
            for (const CollisionPair& c : *pairs) {
                if (mMesh.status(c.u).deleted() || mMesh.status(c.w).deleted()) continue;
                const Vec3 e = position(mMesh, c.w) - position(mMesh, c.u);
                const double len = e.norm();
                if (!(len > 0)) continue;
                const Vec3 n = e / len;
                Hold& hu = mMesh.property(hold, c.u);
                Hold& hw = mMesh.property(hold, c.w);
                hu.x += n.x(), hu.y += n.y(), hu.z += n.z();
                hw.x -= n.x(), hw.y -= n.y(), hw.z -= n.z();
            }
    }
    const int iteration = int(mHistory.size()) + 1;
    if (ts.merges || ts.cuts) recordTopologyChanges(iteration);
    if (ts.cuts) mLastCut = iteration;
    if (ts.merges) mLastMerge = iteration;
    // Fresh-merge zones last kMergeZoneIterations: count them down (an O(n) pass, only while one may
    // still be alive).
    OpenMesh::VPropHandleT<char> mergeZone;
    if (mLastMerge > 0 && iteration - mLastMerge <= kMergeZoneIterations &&
        mMesh.get_property_handle(mergeZone, kMergedProperty))
        for (auto v : mMesh.vertices())
            if (char& left = mMesh.property(mergeZone, v); left > 0) --left;
    OpenMesh::VPropHandleT<TopologyHold> holds;
    if (iteration <= mHoldUntil && mMesh.get_property_handle(holds, kTopologyHoldProperty))
        for (auto v : mMesh.vertices()) {
            if (std::uint16_t& left = mMesh.property(holds, v).afterCut; left > 0) --left;
        }
    // Specks cut off from the surface have nothing to hold on to and shrink into degenerate faces:
    // remove components smaller than a few delta-sized triangles. Specks come only from cuts, so the
    // O(n) component pass runs only for a while after one.
    int removed = 0;
    if (mLastCut > 0 && iteration - mLastCut <= 60) {
        // On a coarse level a small object's surface (its coarse image holds it, grown by half a block)
        // may be as small as a few coarse edges allow: a speck by that level's measure, but a surface
        // the finer levels refine. Specks are judged by the finest level's delta.
        const bool coarse = level() > 0;
        const double fine = mOptions.delta * mLevels.back().scale;
        std::size_t inverted = 0;
        removed = removeSmallComponents(mMesh, coarse ? 4 : 6, 0.5 * fine * fine * fine, &inverted);
        if (untangling()) mInvertedPart = mInvertedPart || inverted > kCollapsedComponent; // a tangle's (checkTangle)
    }
    // A component that has shrunk to a handful of vertices on the finest level around nothing it
    // can hold on to (the initial box of a noise blob, an object below delta) is turned inside
    // out by the push and then balloons until it meets the rest: on the thin plate (seed 1,
    // --smooth 0.7) a blob's box at the image's corner was an inverted tetrahedron by iteration 4,
    // grew to 6,500 vertices and swallowed the plate, leaving an empty mesh. Delete it, as a cut's
    // specks are (a handful of vertices still enclosing a small object, outward, stays); a coarse
    // level starts again without itself instead (updateConvergence()). The component pass runs
    // only while some component may be that small: every iteration while the mesh has several
    // components, and for a lone one once it has a handful of vertices left.
    if (mLevel + 1 == int(mLevels.size()) && !removed) {
        if (mComponents < 0) componentLabels(mMesh, &mComponents);
        bool small = mComponents > 1;
        if (mComponents == 1) {
            std::size_t n = 0;
            for (auto v : mMesh.vertices()) { (void)v; if (++n > kCollapsedComponent) break; }
            small = n <= kCollapsedComponent;
        }
        if (small) removed = removeCollapsedComponents(mMesh);
    }
    if (ts.merges || ts.cuts || removed) mComponents = -1;

    // Compaction is O(n) and costly in OpenMesh: deleted elements are skipped by every iterator, so
    // compact only once they pile up (or after a topology edit, which deletes whole one-rings).
    std::size_t live = 0;
    for (auto v : mMesh.vertices()) { (void)v; ++live; }
    // Splits append vertices at the end of the arrays, and garbage collection fills each collapse's
    // hole with the last element, so neighbours drift apart in memory and every pass of an
    // iteration misses the cache more: once splits and collapses have churned an eighth of a large
    // mesh since the last time, renumber it along a space-filling curve (which compacts it as
    // well). A 109k-vertex sphere settling after a change of delta (60k collapses, no split):
    // 58 ms per settled iteration when only splits counted, 47 with collapses and a quarter, 46-50
    // with an eighth, 45 renumbered every 20 iterations. A mesh under kRenumberMinVertices fits in
    // a core's cache, where renumbering only costs (and changes the order edits are made in: the
    // stress runs' outcomes).
    mChurn += std::size_t(rs.splits) + std::size_t(rs.collapses);
    if (o.renumber && live >= kRenumberMinVertices && mChurn > live / 8) {
        reorderForLocality(mMesh);
        forgetGuaranteeCaches();
        mChurn = 0;
    } else if (ts.merges || ts.cuts || removed || mMesh.n_vertices() - live > mMesh.n_vertices() / 20) {
        mMesh.garbage_collection();
        forgetGuaranteeCaches();
    }

    const std::size_t travellers = level() > 0 ? countTravellers(o, iteration, io.movingSpeed) : 0;
    it.iteration = iteration;
    it.level = level();
    it.removedComponents = removed;
    it.intersectionFree = o.intersectionFree;
    it.vertices = live;
    it.meanKineticEnergy = is.meanKineticEnergy;
    it.moving = is.moving;
    it.splits = rs.splits;
    it.collapses = rs.collapses;
    it.flips = rs.flips;
    it.merges = ts.merges;
    it.cuts = ts.cuts;
    phase(it.phases.topology);
    it.milliseconds = std::chrono::duration<double, std::milli>(lap - start).count();
    mHistory.push_back(it);
    mTravellers.push_back(travellers);
    if (ts.merges || ts.cuts) mLastTopologyEvent = it.iteration;

    updateConvergence();
    checkTangle();
    if (o.progress && !o.progress(it) && mReason == StopReason::Running) mReason = StopReason::Interrupted;
    return it;
}

void Evolution::holdTopology(std::vector<CollisionPair>& collisions, std::vector<CollisionPair>& contacts) const
{
    OpenMesh::VPropHandleT<TopologyHold> holds;
    if (int(mHistory.size()) + 1 > mHoldUntil || !mMesh.get_property_handle(holds, kTopologyHoldProperty)) return;
    auto hold = [&](VertexHandle v) -> const TopologyHold& { return mMesh.property(holds, v); };
    std::size_t kept = 0;
    for (const CollisionPair& c : collisions) {
        if (hold(c.u).afterCut || hold(c.w).afterCut)
            contacts.push_back(c); // held apart instead of merged
        else
            collisions[kept++] = c;
    }
    collisions.resize(kept);
}

void Evolution::recordTopologyChanges(int iteration)
{
    // The zones the edits just tagged: a merge's band and two rings (kMergedProperty at its full
    // count), a cut's caps and two rings (a cut id above every earlier one).
    OpenMesh::VPropHandleT<char> merged;
    OpenMesh::VPropHandleT<int> cutId;
    const bool hasMerged = mMesh.get_property_handle(merged, kMergedProperty);
    const bool hasCut = mMesh.get_property_handle(cutId, kCutIdProperty);
    OpenMesh::VPropHandleT<TopologyHold> holds;
    if (!mMesh.get_property_handle(holds, kTopologyHoldProperty)) {
        mMesh.add_property(holds, kTopologyHoldProperty);
        for (auto v : mMesh.all_vertices()) mMesh.property(holds, v) = TopologyHold{};
    }
    int newest = mCutIdSeen;
    for (auto v : mMesh.vertices()) {
        const bool mergedHere = hasMerged && mMesh.property(merged, v) == char(kMergeZoneIterations);
        const int id = hasCut ? mMesh.property(cutId, v) : 0;
        const bool cutHere = id > mCutIdSeen;
        newest = std::max(newest, id);
        if (!mergedHere && !cutHere) continue;
        TopologyHold& h = mMesh.property(holds, v);
        const int length = kHoldIterations << std::min<int>(h.changes, kMaxHoldDoublings);
        if (h.changes < 255) ++h.changes;
        if (!cutHere) continue; // a merge only counts as a change
        h.afterCut = std::uint16_t(std::max<int>(h.afterCut, length));
        mHoldUntil = std::max(mHoldUntil, iteration + length);
    }
    mCutIdSeen = newest;
}

void Evolution::updateConvergence()
{
    const EvolutionOptions o = levelOptions();
    const int total = int(mHistory.size());
    // The live count (n_vertices() also counts deleted vertices not yet compacted away).
    if (total > 0 && mHistory[total - 1].vertices > o.maxVertices) { mReason = StopReason::VertexCap; return; }
    if (total - mAttemptStart >= o.maxIterations) { mReason = StopReason::IterationCap; return; }
    const bool coarse = level() > 0;
    const int inLevel = total - mLevelStart;
    if (!coarse && total > 0 && mHistory[total - 1].vertices == 0) { mReason = StopReason::Converged; return; } // nothing left
    if (!coarse) {
        const int w = mLevels.size() > 1 ? o.scheduledConvergenceWindow : o.convergenceWindow;
        if (inLevel >= std::max(mLevels.size() > 1 ? 0 : o.minIterations, 2 * w) && settled(o, w)) mReason = StopReason::Converged;
        return;
    }
    // A surface shrinking onto an object only a few of this level's edges across collapses into a
    // handful of vertices (then turns inside out and balloons): this level and the coarser ones
    // are too coarse for the image. Start again from the initial surface without them.
    if (smallestComponent(mMesh) <= kCollapsedComponent) {
        mLevels.erase(mLevels.begin(), mLevels.begin() + mLevel + 1);
        mLevelMetrics.erase(mLevelMetrics.begin(), mLevelMetrics.begin() + mLevel + 1);
        restartFrom(mInitialMesh, total);
        if (mLevels.size() == 1) mInitialMesh = Mesh();
        ++mRestarts;
        return;
    }
    // A coarse level has arrived once no vertex travels. A front filling a cavity through a hole is
    // a handful of vertices, which travel faster here than they would on the finer levels: the tip
    // of the tube going down the phantom's hole at 400^3 is one or two of them (letting two travel
    // ended level 2 there with the tube a third of the way down, and level 1 then took 141
    // iterations to fill the cavity; now level 2 fills it, in 86).
    const int w = o.coarseConvergenceWindow;
    bool arrived = inLevel >= w;
    for (int i = total - w; arrived && i < total; ++i) arrived = mTravellers[std::size_t(i)] == 0;
    if (arrived || inLevel >= o.coarseMaxIterations) {
        const double scale = mLevels[mLevel].scale / mLevels.back().scale;
        mPredictedVertices = std::size_t(double(mHistory[total - 1].vertices) * scale * scale);
        if (mPredictedVertices > o.maxVertices) {
            mReason = StopReason::VertexCap;
            return;
        }
        // The next, finer level starts from this surface; or the one after it, when the level in
        // between would only refine a surface that is already in place (see levelSkipReach).
        const int from = mLevel;
        mLevel += arrived && !nextLevelNeeded(o) ? 2 : 1;
        mSkippedLevels += mLevel - from - 1;
        if (mLevelMetrics[std::size_t(from)] || mLevelMetrics[std::size_t(mLevel)]) VertexMetrics::forget(mMesh);
        forgetGuaranteeCaches(); // (a new delta: new clearances)
        mLevelStart = total;
        mTravelBlockStart = -1; // (anchored again at the new level's first iteration)
    }
}

void Evolution::forgetGuaranteeCaches()
{
    mSafeStepCache.invalidate();
    mRegularityCache.invalidate();
}

bool Evolution::nextLevelNeeded(const EvolutionOptions& o) const
{
    if (!(o.levelSkipReach > 0) || mLevel + 2 >= int(mLevels.size())) return true;
    // Inward along each vertex's normal, is the finest image's object within reach? A surface
    // that has arrived lies just outside the object, by the grown half block of its image and
    // the blur (phantom 400^3, level 2: 4-8 voxels); a front stopped over an opening (a tube
    // short of the bottom of a cavity) or a rim the coarse images thickened lies farther.
    const ScalarImage& finest = *mLevels.back().image;
    const double h = finest.voxelSize();
    const double reach = o.levelSkipReach * mLevels[std::size_t(mLevel)].scale / mLevels.back().scale * h;
    std::size_t far = 0, live = 0;
    for (auto v : mMesh.vertices()) {
        ++live;
        const Vec3 p = position(mMesh, v), n = vertexNormal(mMesh, v);
        bool found = false;
        for (double t = 0; t <= reach && !found; t += 0.5 * h) found = imageSide(finest, o.forces, p - t * n) > 0;
        far += !found;
    }
    return double(far) > o.movingFraction * double(live);
}

void Evolution::checkTangle()
{
    if (!untangling()) return;
    const int total = int(mHistory.size());
    const bool ended = mReason == StopReason::Converged || mReason == StopReason::IterationCap;
    if (mReason != StopReason::Running && !ended) return;
    if (mTangleLevelStart != mLevelStart) { // a new level (or a restart): checks from its start again
        mTangleLevelStart = mLevelStart;
        mNextTangleCheck = mOptions.tangleCheckFirst;
    }
    const int inLevel = total - mLevelStart;
    if (!ended && !mInvertedPart && inLevel < mNextTangleCheck) return;
    if (!ended && inLevel >= mNextTangleCheck) mNextTangleCheck *= 2;
    const std::size_t crossings = findSelfIntersections(mMesh).count();
    std::size_t faces = 0;
    for (auto f : mMesh.faces()) { (void)f; ++faces; }
    const std::size_t limit = ended ? 1 : std::max(mOptions.tangleCrossings, faces / 200);
    // A part of the surface deleted for being inside out (more than a collapsed speck) is a tangle
    // too, whatever is left: the default mode's torus in stress case 8797090675329720181 vanished so.
    if (crossings < limit && !mInvertedPart) return;
    // Tangled: start again from the initial surface, every level, with the guarantee.
    restartFrom(mUntangleMesh, total); // (mInitialMesh, kept while coarse levels remain, is the same)
    mUntangleMesh = Mesh();
    mOptions.intersectionFree = true;
    mUntangledAt = total;
    mTangleCrossings = crossings;
    mReason = StopReason::Running;
    mAttemptStart = total;
    mPredictedVertices = 0;
}

void Evolution::restartFrom(const Mesh& initial, int total)
{
    mMesh = initial;
    VertexMetrics::forget(mMesh); // (sampled in another level's metric, if any)
    forgetGuaranteeCaches();
    mLevel = 0;
    mLevelStart = total;
    mTravelBlockStart = -1;
    mLastTopologyEvent = total;
    mLastCut = mLastMerge = 0;
    mComponents = -1;
    mCutIdSeen = mHoldUntil = 0;
    mChurn = mMesh.n_vertices();
}

std::size_t Evolution::countTravellers(const EvolutionOptions& o, int iteration, double movingSpeed)
{
    OpenMesh::VPropHandleT<TravelAnchors> anchors;
    if (!mMesh.get_property_handle(anchors, kTravelAnchorsProperty)) mMesh.add_property(anchors, kTravelAnchorsProperty);
    OpenMesh::VPropHandleT<Drift> drift;
    const bool haveDrift = mMesh.get_property_handle(drift, kDriftProperty);
    const bool start = mTravelBlockStart < 0;
    if (start) mTravelBlockStart = iteration;
    const bool boundary = (iteration - mTravelBlockStart) % o.coarseConvergenceWindow == 0;
    const double reach = o.coarseNetTravel * o.delta;
    std::size_t count = 0;
    for (auto v : mMesh.vertices()) {
        TravelAnchors& a = mMesh.property(anchors, v);
        const Vec3 p = position(mMesh, v);
        if (!start && haveDrift) {
            if (travelling(mMesh.property(drift, v), movingSpeed)) {
                const Vec3 before(a.before[0], a.before[1], a.before[2]);
                // (a vertex with no position that far back is new since: a front's, counted)
                if (!a.beforeValid || (p - before).squaredNorm() > reach * reach) ++count;
            }
        }
        if (start) {
            for (int k = 0; k < 3; ++k) a.before[k] = a.now[k] = p[k];
            a.beforeValid = a.nowValid = true;
        } else if (boundary) {
            for (int k = 0; k < 3; ++k) a.before[k] = a.now[k], a.now[k] = p[k];
            a.beforeValid = a.nowValid;
            a.nowValid = true;
        }
    }
    return count;
}

bool Evolution::settled(const EvolutionOptions& o, int w) const
{
    const int n = int(mHistory.size());
    const double scale = o.delta * o.delta;
    // Mean and spread of the relative kinetic energy (KE / delta^2) over the last two windows.
    double recent = 0, previous = 0, peak = 0;
    for (int i = n - w; i < n; ++i) {
        recent += mHistory[i].meanKineticEnergy / scale;
        peak = std::max(peak, mHistory[i].meanKineticEnergy / scale);
    }
    for (int i = n - 2 * w; i < n - w; ++i) previous += mHistory[i].meanKineticEnergy / scale;
    recent /= w;
    previous /= w;
    // Still travelling somewhere (a front filling a cavity through a hole barely moves the mean of a
    // mesh at rest elsewhere): not converged. Travelling is judged on the drift, which noise jitter
    // does not build up.
    for (int i = n - w; i < n; ++i)
        if (double(mHistory[i].moving) > o.movingFraction * double(mHistory[i].vertices)) return false;
    if (peak < o.energyThreshold) return true;
    // Stabilised: low energy (well below free-flight speed), no topology change and a nearly constant
    // vertex count over the last window, and energy no longer decreasing.
    const double moving = 0.5 * std::pow(0.1 * o.vmaxFraction, 2); // mean speed < 10% of vmax
    const bool quiet = recent < moving && n - mLastTopologyEvent >= w;
    const double dv = std::abs(double(mHistory[n - 1].vertices) - double(mHistory[n - w].vertices));
    const bool steadyCount = dv <= 0.01 * double(mHistory[n - 1].vertices);
    const bool flat = std::abs(recent - previous) <= o.relativeChange * std::max(previous, 1e-30) || recent > previous;
    return quiet && steadyCount && flat;
}

EvolutionStats evolve(Mesh& mesh, const ScalarImage& image, const MetricField& metric, const EvolutionOptions& options)
{
    return evolve(mesh, std::vector<EvolutionLevel>{{&image, 1.0}}, metric, options);
}

EvolutionStats evolve(Mesh& mesh, const std::vector<EvolutionLevel>& levels, const MetricField& metric,
                      const EvolutionOptions& options)
{
    const auto start = std::chrono::steady_clock::now();
    Evolution evolution(mesh, levels, metric, options);
    while (!evolution.done()) evolution.step();
    EvolutionStats stats;
    stats.iterations = evolution.history();
    stats.reason = evolution.reason();
    stats.predictedVertices = evolution.predictedVertices();
    stats.restarts = evolution.restarts();
    stats.skippedLevels = evolution.skippedLevels();
    stats.untangledAt = evolution.untangledAt();
    stats.tangleCrossings = evolution.tangleCrossings();
    stats.tangleInverted = evolution.tangleInverted();
    for (const auto& it : stats.iterations) {
        stats.splits += it.splits;
        stats.collapses += it.collapses;
        stats.flips += it.flips;
        stats.merges += it.merges;
        stats.cuts += it.cuts;
    }
    stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return stats;
}

Mesh makeInitialBox(const ScalarImage& image, double edgeLength, double grow)
{
    const Box3 box = initialBoxBounds(image, grow, "makeInitialBox");
    return makeBox(box.min(), box.max(), edgeLength);
}

Mesh makeInitialBoxes(const ScalarImage& image, std::vector<Box3> parts, double edgeLength, double grow)
{
    if (parts.empty() || parts.size() > kMaxInitialBoxes) return makeInitialBox(image, edgeLength, grow);
    if (!(edgeLength > 0)) throw std::invalid_argument("makeInitialBoxes: edge length must be > 0");
    const Box3 outer = initialBoxBounds(image, grow, "makeInitialBoxes");
    for (Box3& p : parts) {
        p = Box3(p.min() - Vec3::Constant(grow), p.max() + Vec3::Constant(grow)).intersection(outer);
        // At least about two edges wide on every axis, still inside the outer box.
        for (int a = 0; a < 3 && !p.isEmpty(); ++a) {
            const double need = 2.0 * edgeLength - p.sizes()[a];
            if (need > 0) {
                p.min()[a] = std::max(outer.min()[a], p.min()[a] - 0.5 * need);
                p.max()[a] = std::min(outer.max()[a], p.max()[a] + 0.5 * need);
            }
        }
    }
    parts.erase(std::remove_if(parts.begin(), parts.end(), [](const Box3& p) { return !(p.max().array() > p.min().array()).all(); }),
                parts.end());
    if (parts.empty()) return makeInitialBox(image, edgeLength, grow);
    // Merge boxes closer than two edges until none are (each merge shrinks the list: ends).
    const Vec3 gap = Vec3::Constant(edgeLength);
    for (bool merged = true; merged;) {
        merged = false;
        for (std::size_t i = 0; i < parts.size() && !merged; ++i)
            for (std::size_t j = i + 1; j < parts.size() && !merged; ++j) {
                const Box3 a(parts[i].min() - gap, parts[i].max() + gap);
                const Box3 c(parts[j].min() - gap, parts[j].max() + gap);
                if (a.intersects(c)) {
                    parts[i].extend(parts[j]);
                    parts.erase(parts.begin() + std::ptrdiff_t(j));
                    merged = true;
                }
            }
    }
    Mesh mesh;
    prepareMesh(mesh);
    for (const Box3& p : parts) appendMesh(mesh, makeBox(p.min(), p.max(), edgeLength));
    return mesh;
}

Mesh makeBubbles(const std::vector<std::pair<Vec3, double>>& spheres, double edgeLength)
{
    if (spheres.empty()) throw std::invalid_argument("makeBubbles: no sphere given");
    if (!(edgeLength > 0)) throw std::invalid_argument("makeBubbles: edge length must be > 0");
    Mesh mesh;
    prepareMesh(mesh);
    for (const auto& [center, radius] : spheres) {
        if (!(radius > 0)) throw std::invalid_argument("makeBubbles: radius must be > 0");
        // icosphere edge ~ 1.1 * radius / 2^s
        int s = 0;
        while (s < 6 && 1.1 * radius / double(1 << s) > edgeLength) ++s;
        appendMesh(mesh, makeIcosphere(center, radius, s));
    }
    return mesh;
}

} // namespace riemesh
