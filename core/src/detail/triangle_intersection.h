// detail/triangle_intersection.h: exact tests between two triangles of a mesh, classified by the
// vertices they share (see riemesh/self_intersection.h for what counts). Used by
// findSelfIntersections and by merge, which checks the band it is about to add. Private to core/src.
#pragma once

#include <array>

namespace riemesh::detail {

/// A triangle's corners (3 doubles each, not owned) and the plane its coplanar tests project on:
/// coordinates (axis+1, axis+2) mod 3, where `axis` is a normal component that is exactly
/// non-zero; -1 for a degenerate triangle (exactly collinear corners).
struct TriangleRef {
    const double* p[3];
    int axis;
};

/// The projection axis of triangle (a, b, c), or -1 when it is degenerate.
int projectionAxis(const double* a, const double* b, const double* c);

/// A TriangleRef with its axis computed.
inline TriangleRef makeTriangle(const double* a, const double* b, const double* c)
{
    return {{a, b, c}, projectionAxis(a, b, c)};
}

enum class TriangleContact {
    None,       ///< disjoint, or touching only where they share vertices / an edge
    Crossing,   ///< no shared vertex and a common point
    VertexFold, ///< one shared vertex and another common point
    EdgeFold,   ///< a shared edge and folded flat onto each other, or the same three vertices
};

/// Two non-degenerate triangles with vertex ids `ia`, `ib` (equal ids = the same vertex, hence the
/// same position): how they meet beyond what they share. Exact.
TriangleContact classifyTriangles(const std::array<int, 3>& ia, const TriangleRef& a, const std::array<int, 3>& ib,
                                  const TriangleRef& b);

/// Closed non-degenerate triangles a and b (no shared vertex assumed) have a common point. Exact.
bool trianglesMeet(const TriangleRef& a, const TriangleRef& b);

/// A cheap proof that triangles a and b (corners 3 doubles each, vertex ids `ia`, `ib`; equal ids
/// = the same vertex) meet only in what they share and stay farther than `r` apart elsewhere: a
/// plane through what they share (their shared edge or vertex; between their centroids when they
/// share none) with every other corner of a beyond r on one side and every other corner of b
/// beyond r on the other. Then classifyTriangles says None (for non-degenerate triangles) and every
/// vertex-face and edge-edge pair of the two that shares no vertex is farther apart than r (points
/// of a triangle are convex combinations of its corners: none is nearer the plane than its nearest
/// corner), except, for a shared edge, the two pairs of edges that reach it at opposite ends: their
/// distances are measured. False proves nothing (the exact tests decide). The margins are measured
/// in floating point and required to exceed r by more than their rounding.
bool separatedBeyondShared(const std::array<int, 3>& ia, const double* const a[3], const std::array<int, 3>& ib,
                           const double* const b[3], double r);

} // namespace riemesh::detail
