#include "riemesh/integration.h"

#include <algorithm>
#include <cmath>

namespace riemesh {

IntegrationStats integrate(Mesh& mesh, const std::vector<Vec3>& forces, const IntegrationOptions& options)
{
    IntegrationStats stats;
    const auto velocity = velocityProperty(mesh);
    OpenMesh::VPropHandleT<Drift> drift;
    if (!mesh.get_property_handle(drift, kDriftProperty)) mesh.add_property(drift, kDriftProperty);
    OpenMesh::VPropHandleT<Hold> hold;
    const bool holding = mesh.get_property_handle(hold, kHoldProperty);
    const double keep = options.driftDecay;
    const double dt = options.timeStep;
    const double invMass = 1.0 / options.mass;
    double energy = 0;
    std::size_t count = 0;
    for (auto v : mesh.vertices()) {
        const auto& vel = mesh.property(velocity, v);
        Vec3 u(vel[0], vel[1], vel[2]);
        const Vec3& f = forces[v.idx()];
        // Semi-implicit Euler on m x'' = -gamma x' + F.
        u += dt * invMass * (f - options.damping * u);
        Vec3 d = dt * u;
        const double len = d.norm();
        if (len > options.vmax) {
            d *= options.vmax / len;
            u = d / dt;
        }
        if (holding) {
            Hold& h = mesh.property(hold, v);
            const Vec3 toward(h.x, h.y, h.z);
            const double norm = toward.norm();
            if (norm > 0) {
                const Vec3 n = toward / norm;
                const double along = d.dot(n);
                if (along > 0) {
                    d -= along * n;
                    u -= std::max(0.0, u.dot(n)) * n;
                }
                h = Hold{};
            }
        }
        if (!std::isfinite(d.x()) || !std::isfinite(d.y()) || !std::isfinite(d.z())) {
            d.setZero();
            u.setZero();
        }
        mesh.point(v) += toPoint(d);
        mesh.property(velocity, v) = toPoint(u);
        energy += 0.5 * options.mass * u.squaredNorm();
        const double step = d.norm();
        stats.maxDisplacement = std::max(stats.maxDisplacement, step);
        Drift& m = mesh.property(drift, v);
        m.x = keep * m.x + (1 - keep) * d.x();
        m.y = keep * m.y + (1 - keep) * d.y();
        m.z = keep * m.z + (1 - keep) * d.z();
        if (m.x * m.x + m.y * m.y + m.z * m.z > options.movingSpeed * options.movingSpeed) ++stats.moving;
        ++count;
    }
    stats.meanKineticEnergy = count ? energy / double(count) : 0.0;
    return stats;
}

} // namespace riemesh
