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
    double movingSpeed = 0; ///< drifts above this count as "moving" (world units per iteration)
    double driftDecay = 0.9; ///< drift = driftDecay * drift + (1 - driftDecay) * displacement
};

struct IntegrationStats {
    double meanKineticEnergy = 0; ///< mean of m |v|^2 / 2 over vertices (world units^2 per iteration^2)
    double maxDisplacement = 0;   ///< largest displacement this step (world units), <= vmax
    std::size_t moving = 0;       ///< vertices whose drift exceeds movingSpeed: still travelling
};

/// Per-vertex drift: the displacement per iteration averaged over the last iterations (an
/// exponential moving average). A travelling vertex drifts at its speed; a vertex jittering in
/// noise at rest does not. Zero for new vertices (the type's constructor), unlike a plain Vec3d.
struct Drift {
    double x = 0, y = 0, z = 0;
};
inline constexpr const char* kDriftProperty = "riemesh:drift";
/// A vertex whose drift exceeds `movingSpeed` (world units per iteration) is travelling.
inline bool travelling(const Drift& d, double movingSpeed)
{
    return d.x * d.x + d.y * d.y + d.z * d.z > movingSpeed * movingSpeed;
}

/// Per-vertex positions at the last two block boundaries of the evolution's travel check (see
/// EvolutionOptions::coarseNetTravel): `now` at the last one, `before` at the one before. A split
/// gives its new vertex the means of its edge's ends (a front's new vertices have come as far as
/// their parents); a collapse keeps the survivor's own. Invalid for new vertices otherwise.
struct TravelAnchors {
    double now[3] = {0, 0, 0};
    double before[3] = {0, 0, 0};
    bool nowValid = false, beforeValid = false;
};
inline constexpr const char* kTravelAnchorsProperty = "riemesh:travel-anchors";

/// Per-vertex contact (Hold, zero = none): the sum of unit directions from the vertex toward
/// the vertices it must not approach this iteration. Evolution sets it for the collision pairs the
/// topology step could not merge and for the sheets in contact that collision detection does not
/// merge (findCollisions' contacts): paper 3.2 assumes every detected pair is merged at once, and
/// its radius lambda zeta delta only guarantees a crossing is seen, not that it is handled. The
/// next integrate() removes the part of the vertex's displacement (and velocity) along that
/// direction, so the sheets may slide but not close in, and clears it.
/// Zero for new vertices (the type's constructor), like Drift: a plain Vec3d property entry added
/// by a split would hold an uninitialised direction.
struct Hold {
    double x = 0, y = 0, z = 0;
};
inline constexpr const char* kHoldProperty = "riemesh:contact";

/// Updates velocities (the mesh's velocity property) and positions from `forces` (indexed by
/// vertex idx()), clamping each displacement to vmax. A vertex with a kHoldProperty direction does
/// not move along it (and the direction is cleared).
IntegrationStats integrate(Mesh& mesh, const std::vector<Vec3>& forces, const IntegrationOptions& options);

/// After limitStepToCollisionFree shortened the step of some vertices (and scaled their
/// velocities): their drift counts how far they moved, not how far integrate() meant them to, and
/// the statistics are measured again, so that a vertex held back against another sheet does not
/// count as travelling forever (an --intersection-free run then never converged: a head MRI block,
/// 19 such vertices until the 3,000-iteration cap). `start`: the positions before integrate();
/// `intended`: the positions it left.
IntegrationStats accountForShortenedStep(Mesh& mesh, const std::vector<Vec3>& start, const std::vector<Vec3>& intended,
                                         const IntegrationOptions& options);

} // namespace riemesh
