// riemesh/regularity.h: keep every edge's metric length within [delta, zeta*delta] (paper 3.1, Fig. 1).
#pragma once

#include "riemesh/metric.h"
#include "riemesh/topology.h"

#include <memory>
#include <vector>

namespace riemesh {

struct RegularityOptions {
    double delta = 1.0;  ///< shortest allowed edge (metric length, world units measured with G)
    double zeta = 2.5;   ///< ratio longest/shortest; >= 2.5 keeps halves of a split edge >= delta
    int maxPasses = 4;   ///< split/collapse/flip sweeps per call
    bool flips = true;   ///< flip edges to improve valences and angles
    /// Refuse the collapses and flips that would make two faces cross (exact tests against the
    /// faces nearby, issue 17). Splits at an edge's midpoint keep the surface where it is.
    bool intersectionFree = false;
    /// With intersectionFree: the new faces of a collapse or flip keep at least this distance
    /// (world units) from the faces they share no vertex with.
    double minSeparation = 0.0;
    /// With intersectionFree: the collapses and flips are made without asking, and the faces they
    /// made (or moved) are checked together at the end, in parallel, with the same tests. If any
    /// would cross a face or come too close, the mesh is put back as it was and the edits made
    /// again, each checked in turn (RegularityStats::editsRedone). Either way no face of the
    /// result crosses another; when no edit is refused, the same mesh as checking each in turn.
    /// With a RegularityCache, only after a call with many edits, and not in the few calls after
    /// one that had to be made again.
    bool checkEditsTogether = true;
    /// Decide the queued collapses' checks in parallel before the collapse pass, which then reuses
    /// each edge's verdict while no collapse has changed what it read. The same mesh either way
    /// (tested); false decides each edge in turn.
    bool speculate = true;
};

struct RegularityStats {
    int splits = 0;
    int collapses = 0;
    int flips = 0;
    int tooShort = 0;  ///< edges still shorter than delta at the end (guards refused the collapse)
    int tooLong = 0;   ///< edges still longer than zeta*delta at the end
    bool editsRedone = false; ///< checkEditsTogether found a crossing: the edits were made again, each checked
    /// Short edges whose collapse would pinch a tunnel: handed to the topology step.
    std::vector<TunnelCandidate> tunnels;
};

/// What enforceRegularity keeps from one call to the next with intersectionFree: the grid of the
/// faces its intersection guard looks up, instead of a grid of every face built anew at each
/// call. Each vertex has a reference position and each face is entered with the box of its
/// corners' references grown by a tenth of the mean face size; a call gives the vertices that
/// moved farther than that from their references (or whose faces split, collapse or flip changed:
/// kGuardEditedProperty in riemesh/mesh.h) new ones and enters their faces again: a pass over the
/// vertices, not over the faces. The same edits either way. Call invalidate() when the mesh is
/// renumbered (garbage collection), replaced (a mesh with fewer vertices or faces than before is
/// noticed) or its connectivity changed otherwise than by those edits.
class RegularityCache {
public:
    RegularityCache();
    ~RegularityCache();
    RegularityCache(RegularityCache&&) noexcept;
    RegularityCache& operator=(RegularityCache&&) noexcept;
    void invalidate();
    /// What decides how the next call checks its edits, together or one by one (see
    /// RegularityOptions::checkEditsTogether): kept by Evolution across a regularity step it
    /// makes again (see Evolution::step), so that the call made again decides as the first did.
    struct Mode {
        std::size_t lastEdits = 0;
        int pause = 0;
    };
    Mode mode() const;
    void setMode(const Mode& mode);
    /// The guard's grid brought up to date on another thread while the next call begins (the
    /// work of its first guard question: a pass over the vertices, the faces of those that moved
    /// entered again), from `snapshot`, a copy of `mesh` as that call will find it (points,
    /// connectivity and statuses, as Evolution::step copies them for the collision-safe step):
    /// handOver() (on the caller's thread) copies the guard's edit marks of `mesh` to `snapshot`
    /// and returns false if there is nothing to hand over (no marks: the call then builds its
    /// grid itself); bringUpToDate(snapshot) then runs on the other thread. The call waits for it
    /// where it first needs the grid if it has begun, else calls it off and does that work
    /// itself. Nothing may edit `mesh` between the two but that call.
    bool handOver(Mesh& mesh, Mesh& snapshot);
    void bringUpToDate(Mesh& snapshot);

    struct Impl;
    Impl& impl() { return *mImpl; } ///< (regularity.cpp's)

private:
    std::unique_ptr<Impl> mImpl;
};

/// Edge lengths are metric lengths with G at the edge midpoint approximated by the mean of the
/// endpoint tensors (G is sampled once per vertex per call).
/// Splits long edges, collapses short ones and flips for valence/angle quality, until every edge
/// is within [delta, zeta*delta] (metric length) or maxPasses is reached.
RegularityStats enforceRegularity(Mesh& mesh, const MetricField& metric, const RegularityOptions& options = {},
                                  RegularityCache* cache = nullptr);

} // namespace riemesh
