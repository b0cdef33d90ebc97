#include "riemesh/integration.h"

#include "detail/parallel.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace riemesh {

namespace {
/// Vertices per parallel chunk.
constexpr std::size_t kGrain = 128;

/// Per-vertex figures of a step (kinetic energy, displacement, moving), in buffers kept between
/// calls (no allocation per iteration). Plain pointers: a thread_local named inside a parallel body
/// would be the worker's own.
struct PerVertex {
    double* energy;
    double* step;
    char* moving;
};
PerVertex perVertexBuffers(std::size_t n)
{
    static thread_local std::vector<double> energy, step;
    static thread_local std::vector<char> moving;
    energy.resize(n);
    step.resize(n);
    moving.resize(n);
    return {energy.data(), step.data(), moving.data()};
}

/// The step's statistics from per-vertex figures, summed in index order (the same for any thread
/// count).
IntegrationStats sumStats(const Mesh& mesh, const PerVertex& per)
{
    IntegrationStats stats;
    const bool vertexStatus = mesh.has_vertex_status();
    double energy = 0;
    std::size_t count = 0;
    for (std::size_t i = 0, n = mesh.n_vertices(); i < n; ++i) {
        if (vertexStatus && mesh.status(VertexHandle(int(i))).deleted()) continue;
        energy += per.energy[i];
        stats.maxDisplacement = std::max(stats.maxDisplacement, per.step[i]);
        stats.moving += std::size_t(per.moving[i]);
        ++count;
    }
    stats.meanKineticEnergy = count ? energy / double(count) : 0.0;
    return stats;
}
} // namespace

IntegrationStats integrate(Mesh& mesh, const std::vector<Vec3>& forces, const IntegrationOptions& options)
{
    const auto velocity = velocityProperty(mesh);
    OpenMesh::VPropHandleT<Drift> drift;
    if (!mesh.get_property_handle(drift, kDriftProperty)) mesh.add_property(drift, kDriftProperty);
    OpenMesh::VPropHandleT<Hold> hold;
    const bool holding = mesh.get_property_handle(hold, kHoldProperty);
    const double keep = options.driftDecay;
    const double dt = options.timeStep;
    const double invMass = 1.0 / options.mass;
    // Every vertex in parallel (each writes only its own properties); its kinetic energy goes to a
    // per-vertex array summed in index order afterwards, so the mean is the same for any thread count.
    const std::size_t n = mesh.n_vertices();
    const PerVertex per = perVertexBuffers(n);
    double* const vertexEnergy = per.energy;
    double* const maxStep = per.step;
    char* const moving = per.moving;
    const bool vertexStatus = mesh.has_vertex_status();
    auto deleted = [&](std::size_t i) { return vertexStatus && mesh.status(VertexHandle(int(i))).deleted(); };
    detail::parallelFor(0, n, kGrain, [&](std::size_t i) {
        const VertexHandle v{int(i)};
        if (deleted(i)) return;
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
        vertexEnergy[i] = 0.5 * options.mass * u.squaredNorm();
        maxStep[i] = d.norm();
        Drift& m = mesh.property(drift, v);
        m.x = keep * m.x + (1 - keep) * d.x();
        m.y = keep * m.y + (1 - keep) * d.y();
        m.z = keep * m.z + (1 - keep) * d.z();
        moving[i] = travelling(m, options.movingSpeed);
    });
    return sumStats(mesh, per);
}

IntegrationStats accountForShortenedStep(Mesh& mesh, const std::vector<Vec3>& start, const std::vector<Vec3>& intended,
                                         const IntegrationOptions& options)
{
    const auto velocity = velocityProperty(mesh);
    OpenMesh::VPropHandleT<Drift> drift;
    if (!mesh.get_property_handle(drift, kDriftProperty)) mesh.add_property(drift, kDriftProperty);
    const double share = 1 - options.driftDecay; // the weight integrate() gave this step's displacement
    const std::size_t n = mesh.n_vertices();
    if (start.size() < n || intended.size() < n)
        throw std::invalid_argument("accountForShortenedStep: need a start and an intended position per vertex");
    const PerVertex per = perVertexBuffers(n);
    double* const vertexEnergy = per.energy;
    double* const maxStep = per.step;
    char* const moving = per.moving;
    const bool vertexStatus = mesh.has_vertex_status();
    detail::parallelFor(0, n, kGrain, [&](std::size_t i) {
        const VertexHandle v{int(i)};
        if (vertexStatus && mesh.status(v).deleted()) return;
        const Vec3 now = position(mesh, v);
        Drift& m = mesh.property(drift, v);
        if (now != intended[i]) {
            const Vec3 lost = share * (intended[i] - now);
            m.x -= lost.x(), m.y -= lost.y(), m.z -= lost.z();
        }
        const auto& u = mesh.property(velocity, v);
        vertexEnergy[i] = 0.5 * options.mass * (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        maxStep[i] = (now - start[i]).norm();
        moving[i] = travelling(m, options.movingSpeed);
    });
    return sumStats(mesh, per);
}

} // namespace riemesh
