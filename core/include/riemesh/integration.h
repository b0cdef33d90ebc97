// riemesh/integration.h: explicit time stepping of m x'' = -gamma x' + F (paper 3.3, eq. 6).
#pragma once

#include "riemesh/mesh.h"

#include <vector>

namespace riemesh {

struct IntegrationOptions {
    double mass = 1.0;     ///< vertex mass m
    double damping = 0.5;  ///< gamma
    double timeStep = 1.0; ///< dt (iterations)
    double vmax = 0.5;     ///< largest displacement per iteration (world units); clamps every step
    double movingSpeed = 0; ///< displacements above this count as "moving" (world units per iteration)
};

struct IntegrationStats {
    double meanKineticEnergy = 0; ///< mean of m |v|^2 / 2 over vertices (world units^2 per iteration^2)
    double maxDisplacement = 0;   ///< largest displacement this step (world units), <= vmax
    std::size_t moving = 0;       ///< vertices displaced by more than movingSpeed
};

/// Updates velocities (the mesh's velocity property) and positions from `forces` (indexed by
/// vertex idx()), clamping each displacement to vmax.
IntegrationStats integrate(Mesh& mesh, const std::vector<Vec3>& forces, const IntegrationOptions& options);

} // namespace riemesh
