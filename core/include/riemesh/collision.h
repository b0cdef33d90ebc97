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
};

/// lambda_E = sqrt(1 - 1/zeta + 1/zeta^2) + vmax/(2 zeta delta) (Euclidean, eq. 4) or
/// lambda_R = 1 + vmax/(2 zeta delta) (Riemannian).
double collisionLambda(bool euclidean, double zeta, double delta, double vmax);

/// Colliding vertex pairs (each pair once, closest first).
std::vector<CollisionPair> findCollisions(const Mesh& mesh, const MetricField& metric,
                                          const CollisionOptions& options = {});

} // namespace riemesh
