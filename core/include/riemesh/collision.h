// riemesh/collision.h: self-collision detection (paper 3.2, Fig. 2, eqs. 3-4).
//
// Pairs of non-neighbour vertices with d_R(u, w) <= lambda * zeta * delta. Since G >= I, d_R >= d_E,
// so a Euclidean spatial hash with cell = the search radius finds every candidate in O(n) expected
// time; the metric length then filters them.
#pragma once

#include "riemesh/metric.h"
#include "riemesh/topology.h"

#include <vector>

namespace riemesh {

struct CollisionOptions {
    double delta = 1.0; ///< shortest edge (metric length, world units)
    double zeta = 2.5;  ///< longest/shortest edge ratio
    double vmax = 0.5;  ///< largest displacement per iteration (world units)
    /// kappa: a pair (u, w) is on the same local sheet, hence no collision, when w is reachable
    /// from u by an edge path whose Euclidean length is <= kappa * collisionRadius (world units).
    /// The radius is ~0.97 zeta delta (Euclidean), so kappa = 2 would not even cover the 2-ring
    /// of a mesh whose edges are all near zeta delta (path 2 zeta delta, seen in a deflating box);
    /// 3 covers two rings of the longest edges and three of typical ones, and sharply curved sheets
    /// (geodesic <= pi/2 chord, times the zig-zag of mesh paths).
    double neighbourhoodFactor = 3.0;
};

/// The search radius lambda * zeta * delta (metric length, world units), lambda_E when
/// metric.isEuclidean() and lambda_R otherwise.
double collisionRadius(const MetricField& metric, const CollisionOptions& options);

/// lambda_E = sqrt(1 - 1/zeta + 1/zeta^2) + vmax/(2 zeta delta) (Euclidean, eq. 4) or
/// lambda_R = 1 + vmax/(2 zeta delta) (Riemannian).
double collisionLambda(bool euclidean, double zeta, double delta, double vmax);

/// Colliding vertex pairs (each pair once, closest first; distance = metric length, world units,
/// with the mean of the endpoints' tensors as for edges: from the VertexMetrics cache where it is
/// current, else sampled at each vertex).
/// A pair is reported when d_R(u, w) <= collisionRadius and w is not within u's mesh
/// neighbourhood: an edge path of length <= neighbourhoodFactor * collisionRadius that is also no
/// detour, i.e. <= 2 d_E(u, w) + delta / 2 (a longer path goes around a gap: two sheets joined by
/// a recent merge, or the two faces of a plate around its rim). Pairs whose vertex normals agree (n_u . n_w > 0.5)
/// and that lie nearly in each other's tangent planes are same-sheet pairs and skipped without a
/// search. The two sides of a convex crease (each behind the other's tangent plane, normals less
/// than 120 degrees apart) are never reported: at most contacts (below). Pairs of vertices tagged with the same cut id (the two sides of a tunnel cut, see
/// kCutIdProperty in topology.h) are never reported, so a fresh cut is not merged back at once.
/// Deleted vertices are ignored.
/// `contacts`, when given, receives the pairs within the radius that are close along the mesh
/// only by a detour (see above) away from a fresh merge, and the crease pairs not close along the
/// mesh: two sheets in contact that the model does not merge (a fold of the surface, a crease
/// sharpening into a fin) but must not let cross (Evolution holds them apart).
std::vector<CollisionPair> findCollisions(const Mesh& mesh, const MetricField& metric,
                                          const CollisionOptions& options = {},
                                          std::vector<CollisionPair>* contacts = nullptr);

} // namespace riemesh
