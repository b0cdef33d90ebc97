// detail/predicates.h: exact orientation predicates on double coordinates (Shewchuk's approach).
//
// Each predicate first evaluates its determinant in floating point and returns the sign when it
// exceeds a proven error bound (Shewchuk 1997, ccwerrboundA / o3derrboundA); otherwise it
// re-evaluates the determinant exactly with expansion arithmetic (sums of non-overlapping
// doubles). Exact signs matter where the mesh is flat: the faces of a box lie exactly in one plane
// and a plain floating-point determinant gives them random signs. Private to core/src.
//
// The exact path relies on IEEE round-to-nearest without fused multiply-adds: predicates.cpp is
// compiled with -ffp-contract=off (see cmake/riemesh/02_core.cmake).
#pragma once

namespace riemesh::detail {

/// Sign (-1, 0, +1) of det[b - a, c - a] for 2D points (x, y): +1 when a, b, c turn
/// counter-clockwise.
int orient2d(double ax, double ay, double bx, double by, double cx, double cy);

/// Sign (-1, 0, +1) of ((b - a) x (c - a)) . (d - a) for 3D points given as 3 doubles each: +1
/// when d lies on the side the normal of the counter-clockwise triangle (a, b, c) points to.
int orient3d(const double* a, const double* b, const double* c, const double* d);

} // namespace riemesh::detail
