// detail/edge_guards.h: the guards behind canCollapse/canFlip, split by cause so that the
// regularity step can tell a tunnel (handed to topology) from other refusals, and unchecked
// variants for callers that have just run the guard. Private to core/src.
#pragma once

#include "riemesh/mesh.h"

namespace riemesh::detail {

/// Faces whose unit normals have a smaller dot product before/after an edit count as flipped.
inline constexpr double kMinNormalCosine = 0.2;
/// Faces whose twice-area is below this (world units^2) are degenerate.
inline constexpr double kMinFaceDoubleArea = 1e-12;
/// Faces whose twice-area is below kMinSine * (longest side)^2 are degenerate (a needle or a cap).
inline constexpr double kMinSine = 1e-2;

using CollapseObstacles = unsigned;
inline constexpr CollapseObstacles kCollapseInvalid = 1u;     ///< deleted, or a boundary edge
inline constexpr CollapseObstacles kCollapseTunnel = 2u;      ///< shared outside neighbour (link condition)
inline constexpr CollapseObstacles kCollapseValence = 4u;     ///< a vertex would drop below valence 3
inline constexpr CollapseObstacles kCollapseTetrahedron = 8u; ///< the component is a tetrahedron
inline constexpr CollapseObstacles kCollapseGeometry = 16u;   ///< a surviving face flips or degenerates

bool isLiveEdge(const Mesh& mesh, EdgeHandle e);
bool isLiveHalfedge(const Mesh& mesh, HalfedgeHandle h);
bool isInteriorEdge(const Mesh& mesh, EdgeHandle e);
int valenceOf(const Mesh& mesh, VertexHandle v);

/// True when triangle (a, b, c) (world space) is not degenerate and its normal agrees with
/// `oldNormal` (any length; zero means "no reference": only non-degeneracy is checked).
bool isFaceAcceptable(const Vec3& oldNormal, const Vec3& a, const Vec3& b, const Vec3& c);

/// Every reason why collapsing h into `target` is refused (0 when canCollapse holds).
CollapseObstacles collapseObstacles(const Mesh& mesh, HalfedgeHandle h, const Vec3& target);
/// collapse() without the guard: the caller has checked collapseObstacles(...) == 0.
VertexHandle collapseUnchecked(Mesh& mesh, HalfedgeHandle h, const Vec3& target);

/// flip() without the guard: the caller has checked isFlipAcceptable(...).
void flipUnchecked(Mesh& mesh, EdgeHandle e);

/// canFlip with a configurable fold threshold: the two new unit face normals must have a dot
/// product above `minNewDihedralCosine` (0 for canFlip: no fold sharper than 90 degrees).
bool isFlipAcceptable(const Mesh& mesh, EdgeHandle e, double minNewDihedralCosine);

} // namespace riemesh::detail
