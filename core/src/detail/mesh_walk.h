// detail/mesh_walk.h: bounded shortest edge paths (Euclidean edge lengths, world units).
//
// Used to decide whether two vertices are close *along the mesh* (same local sheet) rather than
// across a gap: collision detection excludes pairs joined by a short edge path, and the topology
// step re-checks it after earlier edits of the same call.
#pragma once

#include "riemesh/mesh.h"

#include <utility>
#include <vector>

namespace riemesh::detail {

/// Reusable scratch for bounded Dijkstra searches over vertex indices. Arrays grow on demand and
/// are never cleared: a stamp per search marks which entries are current.
class BoundedPathSearch {
public:
    /// Runs Dijkstra from `source` over non-deleted edges, settling every vertex whose edge-path
    /// length from `source` is <= maxLength (world units). Returns the settled vertices.
    const std::vector<VertexHandle>& run(const Mesh& mesh, VertexHandle source, double maxLength);

    /// The same, stopping as soon as every one of the `count` vertices `targets` (distinct vertex
    /// indices) is settled: what reached() and distance() say of the targets is what the full run
    /// would say (settled distances are final), of other vertices not.
    void runUntil(const Mesh& mesh, VertexHandle source, double maxLength, const int* targets, std::size_t count);

    /// True when `v` was settled by the last run (its path length is <= the bound).
    bool reached(VertexHandle v) const
    {
        return std::size_t(v.idx()) < mStamp.size() && mStamp[v.idx()] == mCurrent && mSettled[v.idx()];
    }

    /// The edge-path length from the last run's source to `v` when reached(v).
    double distance(VertexHandle v) const { return mDistance[v.idx()]; }

    /// True when `to` is reachable from `from` by an edge path of length <= maxLength (world units).
    bool isWithin(const Mesh& mesh, VertexHandle from, VertexHandle to, double maxLength);

private:
    void search(const Mesh& mesh, VertexHandle source, double maxLength, const int* targets, std::size_t count);

    std::vector<unsigned> mStamp, mTarget;
    std::vector<double> mDistance;
    std::vector<char> mSettled;
    std::vector<std::pair<double, int>> mHeap;
    std::vector<VertexHandle> mReached;
    unsigned mCurrent = 0;
};

} // namespace riemesh::detail
