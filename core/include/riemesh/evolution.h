// riemesh/evolution.h: the order of the steps, and the loop to convergence (paper 3, 5).
//
// One iteration: forces -> integration -> regularity -> collision detection -> topology changes ->
// compaction. `evolve` runs to convergence (mean kinetic energy stabilised) or a cap;
// `Evolution::step()` advances one iteration for interactive use.
#pragma once

#include "riemesh/ccd.h"
#include "riemesh/forces.h"
#include "riemesh/image.h"
#include "riemesh/integration.h"
#include "riemesh/metric.h"
#include "riemesh/regularity.h"
#include "riemesh/topology.h"

#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace riemesh {

struct IterationStats {
    int iteration = 0;
    int level = 0;          ///< coarse-to-fine level evolved (0: the finest, delta as given)
    std::size_t vertices = 0;
    double meanKineticEnergy = 0;
    std::size_t moving = 0; ///< vertices still travelling (faster than half the free-flight speed)
    int splits = 0, collapses = 0, flips = 0, merges = 0, cuts = 0;
    int removedComponents = 0; ///< specks left by cuts and deleted (see removeSmallComponents)
    bool intersectionFree = false; ///< evolved with the guarantee (asked for, or after a tangle: untangledAt())
    std::size_t cutShort = 0;      ///< with the guarantee: vertices whose motion the collision-safe step cut short
    /// With the guarantee, on several threads: the regularity step, run beside the collision-safe
    /// step, was made again after it (the step came out cut short; see Evolution::step).
    bool regularityRedone = false;
    double milliseconds = 0;
    /// Where the milliseconds went: forces, integration, regularity (paper 3.1), collision
    /// detection (3.2), topology changes and housekeeping (holds, specks, compaction). With the
    /// guarantee on several threads the collision-safe step runs beside the regularity step: what
    /// it takes beyond it counts as regularity.
    struct Phases {
        double forces = 0, integration = 0, regularity = 0, collisions = 0, topology = 0;
    } phases;
};

enum class StopReason { Running, Converged, IterationCap, Interrupted, VertexCap };
const char* toString(StopReason reason);

struct EvolutionOptions {
    double delta = 1.0;          ///< shortest edge, metric length (world units)
    double zeta = 2.5;           ///< longest/shortest edge ratio
    double vmaxFraction = 0.5;   ///< vmax = vmaxFraction * delta (world units per iteration)
    ForceOptions forces;
    double mass = 1.0;
    double damping = 0.5;
    /// Renumber a large mesh (16k vertices and more) along a space-filling curve (reorderForLocality)
    /// at the first step and whenever splits have appended a quarter of it since: on large evolved
    /// meshes this makes an iteration about 1.5-2x faster (core_bench). Off: handles change only by
    /// compaction.
    bool renumber = true;
    int maxIterations = 3000;
    int minIterations = 20;
    /// Converged when no vertex is still travelling (drifting faster than half the free-flight speed,
    /// see Drift; at most movingFraction of them) over convergenceWindow iterations and either the mean kinetic energy,
    /// relative to delta^2, stays below energyThreshold, or it has stabilised (relative change over
    /// the window below relativeChange, no topology event, nearly constant vertex count).
    /// The mean alone is not enough: a few hundred vertices filling a cavity through a hole barely
    /// move the mean of a mesh at rest elsewhere. 1e-4 is a mean speed of about 1.4% of delta per
    /// iteration; at 1e-5 the finest level waited for the last of its energy to stop decaying
    /// (phantom 400^3: 55 iterations on the finest level instead of 26, the surface at rest within
    /// 0.005 voxel of mean error).
    double energyThreshold = 1e-4;
    int convergenceWindow = 25;
    double relativeChange = 0.02;
    double movingFraction = 0.002;
    std::size_t maxVertices = 4'000'000; ///< stop with VertexCap beyond this
    /// Coarse levels of a schedule (see EvolutionLevel) move on to the next level once no vertex
    /// has travelled (see movingFraction) for this many iterations: a coarse level only has to bring
    /// the surface near, its result is refined anyway; or after coarseMaxIterations.
    int coarseConvergenceWindow = 8;
    /// On a coarse level a travelling vertex (see movingFraction) counts only if it is also more
    /// than this many delta from where it was one to two windows (coarseConvergenceWindow) ago.
    /// A vertex can drift at speed without going anywhere: on the phantom 400^3 (noise seed 9) one
    /// slid 2 voxels an iteration along the cube's face and was collapsed back 4.3 voxels every
    /// other iteration, for 90 iterations, after the cavity had filled: level 2 waited for it (167
    /// iterations instead of 70-76 on seeds 1-8; 216 in all, 2.3 times the 100^3 count); now 123.
    /// A front going somewhere (the tube down the phantom's hole: 1.6 delta per window) still counts.
    double coarseNetTravel = 0.5;
    int coarseMaxIterations = 300;
    /// A coarse level that has arrived (not capped) and is not the last coarse one hands its
    /// surface straight to the level after the next when the next would only refine it: inward
    /// along the normal, the finest image's object lies within this many of the level's blocks
    /// (its scale, in voxels of the finest image) of all but movingFraction of the vertices. The
    /// level in between then costs its settling and window (12-21 iterations at 400^3) for a
    /// surface the finest level settles as fast from here. It stays where the surface is still far
    /// somewhere: a rim the coarse images thickened (a thin plate: 150 of 640 vertices at 400^3),
    /// a tube stopped over an opening (the noise-free phantom: 9 of 1,300), a gap the coarse
    /// images closed (two spheres 2 voxels apart: 3 of 640). 0: every level runs.
    double levelSkipReach = 2.0;
    /// On a coarse level, G at x is the largest (by trace) of the metric's samples at x and this many
    /// of the level's cells away along each axis (DilatedMetric); 0: the metric as it is. A coarse
    /// level's object is grown by about half a block and its image is blocky: its surface settles a
    /// few voxels outside the contours, where the image's metric is already the identity, so it
    /// sampled a hole, an edge or a corner as coarsely as a flat face. The phantom's hole at 400^3
    /// was spanned by three vertices on level 2 (a tube with edges of 22 voxels in a hole 40 across,
    /// which stopped a third of the way down); reaching one cell, 22-64 vertices go down it.
    double coarseMetricReach = 1.0;
    /// On the coarse levels of a schedule but the last (which hands the finest level its surface
    /// and keeps the finest level's forces, so that the finest level starts alike at any size):
    /// the push in free flight (ForceOptions::externalLimit, x delta; still capped so that creases
    /// keep up, see step()) and a factor on ForceOptions::freeCurvatureWeight. They only have to
    /// bring the surface near: a front travels 1.2 times as fast, and a membrane over a hole the
    /// level can just pass (the phantom's at 400^3 on level 2, four of its delta across) tunnels
    /// into it instead of resting over it until the level ends. Phantom 400^3, noise 0.5, seeds
    /// 1-5: 142, 181, 140 (seeds 1-3) iterations with the finest level's forces throughout (on seed
    /// 2 level 2 ended before the hole and level 1 filled the cavity at half the speed); 119, 127,
    /// 121, 124, 123 with these. Head MRI at iso 40: 99 -> 85 iterations. 100^3 has one coarse
    /// level: unchanged.
    double coarseExternalLimit = 0.15;
    double coarseFreeCurvatureFactor = 0.5;
    /// The finest level of a schedule starts next to its surface: its convergence window.
    int scheduledConvergenceWindow = 12;
    /// For this many iterations after a coarse level, the shortest edge is levelSettleFactor delta
    /// (the longest stays zeta delta): the surface of a coarse level encloses the finer level's and
    /// shrinks onto it, which compresses the edges just split from the coarse ones; collapsing them a
    /// little earlier while it settles gives the sampling a mesh deflating from the box would have
    /// (without it the head MRI ends with 24% more vertices). Head MRI, one level: 6,115 vertices;
    /// with the schedule at factor 1.1, 1.15, 1.17, 1.2, 1.22: 6,554, 6,387, 6,308, 6,208, 6,181
    /// (phantom 1,490-1,519 throughout); 1.25 = zeta / 2 stops the settling splits (7,881).
    int levelSettleIterations = 20;
    double levelSettleFactor = 1.2;
    /// Intersection-free evolution (issue 17): every step's motion is checked by continuous
    /// collision detection (limitStepToCollisionFree in riemesh/ccd.h) and shortened where a vertex
    /// and a face, or two edges, would come within minSeparation * delta of each other; collapses
    /// and flips that would make faces cross are refused (RegularityOptions::intersectionFree), as
    /// are tunnel cuts. An embedded initial surface then stays embedded. Off by default until its
    /// cost comes down: it makes the phantom's and the head's evolution 1.9-2.0x slower (issue 17; bench d3e260f).
    bool intersectionFree = false;
    double minSeparation = 1e-3; ///< eta, a fraction of delta
    /// Without intersectionFree the surface may cross itself: the collision search only sees two
    /// sheets that are far apart along the mesh, so two walls of a fold (the sides of a gyrus thinner
    /// than the image resolves) can pass through each other unmerged, and the crossing grows (the
    /// head MRI at iso 80: hundreds of crossing face pairs within 20 iterations of the finest
    /// level, then a balloon of 27,000 vertices that ends inside out after 4 minutes). So the
    /// surface is checked (findSelfIntersections) tangleCheckFirst iterations into each level, then
    /// at 2x, 4x ... that, and when the evolution ends (converged or capped). A surface with any
    /// crossing at its end, or at least max(tangleCrossings, 0.5% of its faces) at a check, or
    /// that lost a part of more than a handful of vertices for being inside out, is tangled: the
    /// evolution starts again from the initial surface with intersectionFree on, which keeps it
    /// embedded (untangledAt()). Off: untangle = false (a tangled result is then returned).
    bool untangle = true;
    int tangleCheckFirst = 32;
    std::size_t tangleCrossings = 64;
    /// Called after every iteration; return false to interrupt.
    std::function<bool(const IterationStats&)> progress;
};

struct EvolutionStats {
    std::vector<IterationStats> iterations;
    StopReason reason = StopReason::Running;
    std::size_t predictedVertices = 0; ///< Evolution::predictedVertices() at the end
    int restarts = 0;                  ///< Evolution::restarts()
    int skippedLevels = 0;             ///< Evolution::skippedLevels()
    int untangledAt = 0;               ///< Evolution::untangledAt()
    std::size_t tangleCrossings = 0;   ///< Evolution::tangleCrossings()
    bool tangleInverted = false;       ///< Evolution::tangleInverted()
    double seconds = 0;
    int splits = 0, collapses = 0, flips = 0, merges = 0, cuts = 0;
};

/// One level of a coarse-to-fine schedule: the image the forces see there and the factor on delta
/// (and so on vmax and every length of the model) relative to EvolutionOptions::delta.
///
/// A schedule runs its levels coarsest first; each starts from the surface the one before converged
/// to. For the result to be what the finest level alone would give, every coarse image should hold
/// the finest one's object inside its own (e.g. block maxima of a bright object, grown by half a block:
/// vdb::Volume::buildLevels), so that each level's surface still encloses the next one's and the
/// mesh keeps deflating onto it from outside, as from the initial box; thin parts and narrow gaps that
/// only the finest level resolves then come out as they do without a schedule.
struct EvolutionLevel {
    const ScalarImage* image = nullptr;
    double scale = 1.0; ///< delta factor (a power of two: 2^level); the last level has 1
};

class Evolution {
public:
    /// Keeps references to mesh, image and metric: they must outlive this object.
    Evolution(Mesh& mesh, const ScalarImage& image, const MetricField& metric, const EvolutionOptions& options = {});
    /// A coarse-to-fine schedule, coarsest level first (see EvolutionLevel); the images must outlive
    /// this object. Convergence (and done()) is that of the last level; options.maxIterations caps
    /// the iterations of all levels together.
    Evolution(Mesh& mesh, std::vector<EvolutionLevel> levels, const MetricField& metric, const EvolutionOptions& options = {});
    ~Evolution();
    Evolution(const Evolution&) = delete;
    Evolution& operator=(const Evolution&) = delete;
    /// One iteration; returns its statistics. Does nothing once done().
    IterationStats step();
    bool done() const { return mReason != StopReason::Running; }
    StopReason reason() const { return mReason; }
    /// When a coarse level ends, the vertices the finest level should need: each halving of delta
    /// about quadruples a surface's vertices. Past options.maxVertices the schedule stops there
    /// with VertexCap (a runaway found at the cost of a coarse mesh). 0 before the first level ends.
    std::size_t predictedVertices() const { return mPredictedVertices; }
    /// Times a coarse level gave up on an object too small for it (see step()): the schedule then
    /// started again from the initial surface without that level and the coarser ones.
    int restarts() const { return mRestarts; }
    /// Levels the schedule left out so far (see EvolutionOptions::levelSkipReach).
    int skippedLevels() const { return mSkippedLevels; }
    /// The iteration after which a tangled surface (see EvolutionOptions::untangle) was replaced by
    /// the initial one and the evolution started again with intersectionFree on; 0 if it was not.
    /// tangleCrossings(): the offending face pairs it had then (findSelfIntersections().count()).
    /// tangleInverted(): a part of more than a handful of vertices had turned inside out.
    int untangledAt() const { return mUntangledAt; }
    std::size_t tangleCrossings() const { return mTangleCrossings; }
    bool tangleInverted() const { return mUntangledAt > 0 && mInvertedPart; }
    const std::vector<IterationStats>& history() const { return mHistory; }
    const EvolutionOptions& options() const { return mOptions; }
    /// The level being evolved, counted from the finest (0) up; levels() in all.
    int level() const { return int(mLevels.size()) - 1 - mLevel; }
    int levels() const { return int(mLevels.size()); }
    /// Changes parameters on the fly (viewer); clears a previous convergence.
    void setOptions(const EvolutionOptions& options);
    /// Marks the evolution interrupted.
    void interrupt() { mReason = StopReason::Interrupted; }

private:
    Mesh& mMesh;
    std::vector<EvolutionLevel> mLevels;
    int mLevel = 0;          ///< index into mLevels
    int mLevelStart = 0;     ///< iterations before the current level started
    std::size_t mPredictedVertices = 0;
    int mRestarts = 0;
    Mesh mInitialMesh; ///< kept while coarse levels remain, for a restart
    Mesh mUntangleMesh; ///< the initial surface, kept while a tangle may still restart from it
    int mAttemptStart = 0;   ///< iterations before the current attempt (0, or untangledAt())
    int mNextTangleCheck = 0; ///< iterations into the level of the next tangle check
    int mTangleLevelStart = -1; ///< mLevelStart of the level mNextTangleCheck counts in
    int mUntangledAt = 0;
    std::size_t mTangleCrossings = 0;
    /// Before any restart: a part turned inside out was deleted (removeSmallComponents).
    bool mInvertedPart = false;
    bool untangling() const { return mOptions.untangle && !mOptions.intersectionFree && mUntangledAt == 0; }
    void checkTangle();
    /// Replaces the mesh by `initial` and starts the first level over at iteration `total`.
    void restartFrom(const Mesh& initial, int total);
    const MetricField& mMetric;
    std::vector<std::unique_ptr<DilatedMetric>> mLevelMetrics; ///< by level: the coarse levels' (null: mMetric)
    const MetricField& levelMetric() const;
    EvolutionOptions mOptions;
    std::vector<IterationStats> mHistory;
    std::vector<Vec3> mForces;
    std::vector<Vec3> mStepStart; ///< positions before integration (intersectionFree)
    std::vector<Vec3> mStepEnd;   ///< where integration meant them to go (intersectionFree)
    SafeStepCache mSafeStepCache; ///< the collision-safe step's clearances (intersectionFree)
    RegularityCache mRegularityCache; ///< the edit guard's grid of the faces (intersectionFree)
    struct Beside; ///< the collision-safe step run beside the regularity step (see step())
    std::unique_ptr<Beside> mBeside;
    StopReason mReason = StopReason::Running;
    int mLastTopologyEvent = 0;
    int mLastCut = 0;   ///< iteration of the last tunnel cut (0: none)
    int mLastMerge = 0; ///< iteration of the last merge (0: none)
    int mComponents = -1; ///< connected components of the mesh on the finest level (-1: to count)
    int mCutIdSeen = 0;  ///< the largest cut id (kCutIdProperty) seen after the last cuts
    int mHoldUntil = 0;  ///< last iteration a topology hold may still be active
    /// Topology hysteresis: a collision pair next to a fresh tunnel cut becomes a contact (held
    /// apart) instead of a merge, for 10 iterations doubled by every change the vertex has already
    /// seen (recordTopologyChanges). The head MRI at iso 80 with the guarantee merged and cut in
    /// turn at the same places every iteration (2,280 merges, 2,205 cuts, 3,000-iteration cap); it
    /// now converges in 1,312 iterations (433 merges, 388 cuts on its finest level). Skipping tunnel
    /// cuts next to a fresh merge as well cut the events further but lost the torus (the uncut band
    /// turned inside out).
    void holdTopology(std::vector<CollisionPair>& collisions, std::vector<CollisionPair>& contacts) const;
    void recordTopologyChanges(int iteration);
    std::size_t mChurn = 0; ///< splits and collapses since the mesh was last renumbered
    /// Per iteration (as mHistory): the travelling vertices that went somewhere (coarse levels,
    /// see EvolutionOptions::coarseNetTravel and countTravellers()).
    std::vector<std::size_t> mTravellers;
    int mTravelBlockStart = -1; ///< iteration of the travel check's last block boundary (-1: none)
    int mSkippedLevels = 0;
    /// At the end of a coarse level: false when the level after it may be left out (see
    /// EvolutionOptions::levelSkipReach).
    bool nextLevelNeeded(const EvolutionOptions& o) const;
    void updateConvergence();
    /// The mesh was renumbered or replaced, or the level changed: the intersection-free caches
    /// (the safe step's clearances, the edit guard's grid) start again.
    void forgetGuaranteeCaches();
    EvolutionOptions levelOptions() const; ///< mOptions with the current level's scale
    bool settled(const EvolutionOptions& o, int window) const; ///< the convergence test over the last 2 windows
    /// On a coarse level: the vertices whose drift exceeds movingSpeed and which are more than
    /// coarseNetTravel delta from their position at the block boundary before last; moves the
    /// anchors on at a boundary (every coarseConvergenceWindow iterations of the level).
    std::size_t countTravellers(const EvolutionOptions& o, int iteration, double movingSpeed);
};

/// Runs an Evolution until it stops.
EvolutionStats evolve(Mesh& mesh, const ScalarImage& image, const MetricField& metric,
                      const EvolutionOptions& options = {});
/// The same through a coarse-to-fine schedule (levels coarsest first).
EvolutionStats evolve(Mesh& mesh, const std::vector<EvolutionLevel>& levels, const MetricField& metric,
                      const EvolutionOptions& options = {});

/// The default initialisation: the image's bounds() inset by one voxel, as a box mesh with edges of
/// about `edgeLength` (world units), that deflates onto the object. `grow` (world units) moves its
/// faces out: a schedule's coarse images hold the object grown by up to two of their voxels, so a
/// schedule starts 2^(levels + 1) voxels further out, where every level's object is inside the box.
Mesh makeInitialBox(const ScalarImage& image, double edgeLength, double grow = 0.0);

/// One box per part of the object: `parts` (world boxes, each holding a part, e.g. from
/// vdb::Volume::objectBoxes()) grown by `grow`, clipped to makeInitialBox's box, and merged while
/// any two come closer than two edges (a box around both replaces them), so that no two start
/// touching. A small object in a large, mostly empty image is then met in a few iterations instead
/// of after the whole box has shrunk onto it. Empty `parts`, or more than kMaxInitialBoxes of
/// them, give makeInitialBox().
Mesh makeInitialBoxes(const ScalarImage& image, std::vector<Box3> parts, double edgeLength, double grow = 0.0);
inline constexpr std::size_t kMaxInitialBoxes = 4096;

/// Spheres ("bubbles", centre and radius in world units) that inflate inside the object.
Mesh makeBubbles(const std::vector<std::pair<Vec3, double>>& spheres, double edgeLength);

} // namespace riemesh
