// riemesh/self_intersection.h: faces of a mesh that cross each other (issue 6, reliability).
//
// The model promises an embedded surface: collision detection (paper 3.2) merges sheets before
// they touch. This check is the independent judge: a bounding-volume hierarchy over the faces
// finds the pairs whose boxes overlap, then exact triangle-triangle tests (orientation predicates
// with a floating-point filter and an exact expansion-arithmetic fallback, coplanar cases
// included) decide. Triangles are closed sets: touching counts as intersecting.
//
// Pairs are classified by the vertices they share, since neighbours always touch:
//  - no shared vertex: any common point is an intersection (`crossings`);
//  - one shared vertex s: a fold when the triangles have a common point other than s, i.e. their
//    interiors or edges cross near or away from s (`vertexFolds`);
//  - a shared edge: two non-coplanar triangles meet only along that edge, so the only possible
//    overlap is a flat fold: the fourth vertex exactly in the first face's plane, on the same side
//    of the edge (`edgeFolds`, with faces on the same three vertices).
// Exactly degenerate faces (collinear corners) have no plane: they are counted and skipped.
#pragma once

#include "riemesh/mesh.h"

#include <cstddef>
#include <utility>
#include <vector>

namespace riemesh {

struct SelfIntersectionOptions {
    bool collectPairs = false;      ///< fill SelfIntersectionStats::pairs
    std::size_t maxPairs = 100000;  ///< at most this many pairs are stored (all are counted)
    int leafSize = 4;               ///< faces per BVH leaf
};

struct SelfIntersectionStats {
    std::size_t crossings = 0;   ///< intersecting pairs that share no vertex
    std::size_t vertexFolds = 0; ///< pairs sharing one vertex with another common point
    std::size_t edgeFolds = 0;   ///< pairs sharing an edge folded flat onto each other (or a duplicate face)
    std::size_t degenerateFaces = 0; ///< faces with exactly collinear corners, not tested
    std::size_t testedPairs = 0;     ///< face pairs whose boxes overlapped (triangle tests run)
    /// The offending pairs (first < second by index), when options.collectPairs.
    std::vector<std::pair<FaceHandle, FaceHandle>> pairs;
    /// Every kind of offence: an embedded surface has 0.
    std::size_t count() const { return crossings + vertexFolds + edgeFolds; }
};

/// Finds the face pairs of `mesh` (deleted faces ignored) that intersect, as classified above.
/// O(n log n) for the hierarchy plus the tests of the pairs whose boxes overlap.
SelfIntersectionStats findSelfIntersections(const Mesh& mesh, const SelfIntersectionOptions& options = {});

/// True when the closed triangles (a0, a1, a2) and (b0, b1, b2) (world space) have a common point.
/// Exact for any input; false when either triangle is degenerate (collinear corners).
bool trianglesIntersect(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1,
                        const Vec3& b2);

} // namespace riemesh
