// riemesh/evolution.h: the order of the steps, and the loop to convergence (paper 3, 5).
//
// One iteration: forces -> integration -> regularity -> collision detection -> topology changes ->
// compaction. `evolve` runs to convergence (mean kinetic energy stabilised) or a cap;
// `Evolution::step()` advances one iteration for interactive use.
#pragma once

#include "riemesh/forces.h"
#include "riemesh/image.h"
#include "riemesh/integration.h"
#include "riemesh/metric.h"

#include <cstddef>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace riemesh {

struct IterationStats {
    int iteration = 0;
    std::size_t vertices = 0;
    double meanKineticEnergy = 0;
    std::size_t moving = 0; ///< vertices still travelling (faster than half the free-flight speed)
    int splits = 0, collapses = 0, flips = 0, merges = 0, cuts = 0;
    int removedComponents = 0; ///< specks left by cuts and deleted (see removeSmallComponents)
    double milliseconds = 0;
    /// Where the milliseconds went: forces, integration, regularity (paper 3.1), collision
    /// detection (3.2), topology changes and housekeeping (holds, specks, compaction).
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
    /// move the mean of a mesh at rest elsewhere.
    double energyThreshold = 1e-5;
    int convergenceWindow = 25;
    double relativeChange = 0.02;
    double movingFraction = 0.002;
    std::size_t maxVertices = 4'000'000; ///< stop with VertexCap beyond this
    /// Called after every iteration; return false to interrupt.
    std::function<bool(const IterationStats&)> progress;
};

struct EvolutionStats {
    std::vector<IterationStats> iterations;
    StopReason reason = StopReason::Running;
    double seconds = 0;
    int splits = 0, collapses = 0, flips = 0, merges = 0, cuts = 0;
};

class Evolution {
public:
    /// Keeps references to mesh, image and metric: they must outlive this object.
    Evolution(Mesh& mesh, const ScalarImage& image, const MetricField& metric, const EvolutionOptions& options = {});
    /// One iteration; returns its statistics. Does nothing once done().
    IterationStats step();
    bool done() const { return mReason != StopReason::Running; }
    StopReason reason() const { return mReason; }
    const std::vector<IterationStats>& history() const { return mHistory; }
    const EvolutionOptions& options() const { return mOptions; }
    /// Changes parameters on the fly (viewer); clears a previous convergence.
    void setOptions(const EvolutionOptions& options);
    /// Marks the evolution interrupted.
    void interrupt() { mReason = StopReason::Interrupted; }

private:
    Mesh& mMesh;
    const ScalarImage& mImage;
    const MetricField& mMetric;
    EvolutionOptions mOptions;
    std::vector<IterationStats> mHistory;
    std::vector<Vec3> mForces;
    StopReason mReason = StopReason::Running;
    int mLastTopologyEvent = 0;
    int mLastCut = 0;   ///< iteration of the last tunnel cut (0: none)
    int mLastMerge = 0; ///< iteration of the last merge (0: none)
    std::size_t mChurn = 0; ///< splits and collapses since the mesh was last renumbered
    void updateConvergence();
};

/// Runs an Evolution until it stops.
EvolutionStats evolve(Mesh& mesh, const ScalarImage& image, const MetricField& metric,
                      const EvolutionOptions& options = {});

/// The default initialisation: the image's bounds() inset by one voxel, as a box mesh with edges of
/// about `edgeLength` (world units), that deflates onto the object.
Mesh makeInitialBox(const ScalarImage& image, double edgeLength);

/// Spheres ("bubbles", centre and radius in world units) that inflate inside the object.
Mesh makeBubbles(const std::vector<std::pair<Vec3, double>>& spheres, double edgeLength);

} // namespace riemesh
