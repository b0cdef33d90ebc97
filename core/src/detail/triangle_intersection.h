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

} // namespace riemesh::detail
