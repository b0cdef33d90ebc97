// Forces and integration: the force points toward the isosurface, vanishes on it, and every
// displacement is clamped to vmax.
#include "mesh_invariants.h"
#include "riemesh/forces.h"
#include "riemesh/integration.h"
#include "riemesh/primitives.h"

#include <doctest/doctest.h>

#include <cmath>

using namespace riemesh;

namespace {

FunctionImage ballImage(double radius)
{
    return FunctionImage([radius](const Vec3& x) { return 0.5 + 0.5 * std::tanh(radius - x.norm()); },
                         Box3(Vec3::Constant(-2 * radius), Vec3::Constant(2 * radius)), 1.0);
}

double meanRadialForce(const Mesh& mesh, const std::vector<Vec3>& forces)
{
    double sum = 0;
    for (auto v : mesh.vertices()) sum += forces[v.idx()].dot(position(mesh, v).normalized());
    return sum / double(mesh.n_vertices());
}

} // namespace

TEST_CASE("forces: a sphere outside the object is pushed inward, inside it is pushed outward")
{
    const auto image = ballImage(8.0);
    ForceOptions options;
    options.iso = 0.5;
    std::vector<Vec3> forces;
    Mesh outside = makeIcosphere(Vec3::Zero(), 11.0, 3);
    computeForces(outside, image, options, 1.0, forces);
    CHECK(meanRadialForce(outside, forces) < -0.1);
    Mesh inside = makeIcosphere(Vec3::Zero(), 5.0, 3);
    computeForces(inside, image, options, 1.0, forces);
    CHECK(meanRadialForce(inside, forces) > 0.05);
}

TEST_CASE("forces: on the isosurface the external force nearly vanishes")
{
    const auto image = ballImage(8.0);
    ForceOptions options;
    options.internalWeight = 0;
    options.curvatureWeight = 0;
    std::vector<Vec3> forces;
    Mesh onSurface = makeIcosphere(Vec3::Zero(), 8.0, 3);
    computeForces(onSurface, image, options, 1.0, forces);
    CHECK(std::abs(meanRadialForce(onSurface, forces)) < 0.02);
}

TEST_CASE("forces: with face samples, corners on a sphere are pushed out by their faces' sag")
{
    // A coarse icosphere (edges ~4.5) with its vertices on the isosurface: its faces lie inside the
    // ball (the centroid of a face by ~0.4), which the vertex samples cannot see and face samples do.
    const auto image = ballImage(8.0);
    ForceOptions options;
    options.internalWeight = 0;
    options.curvatureWeight = 0;
    std::vector<Vec3> forces;
    Mesh onSurface = makeIcosphere(Vec3::Zero(), 8.0, 1);
    // delta as long as the edges (the model keeps them within [delta, zeta delta]): the sag is then
    // within the pull's linear range, which ends at externalLimit * delta (0.56 here).
    const double delta = 4.5;
    computeForces(onSurface, image, options, delta, forces);
    const double cornersOnly = meanRadialForce(onSurface, forces);
    options.vertexShare = kFaceSampleVertexShare;
    computeForces(onSurface, image, options, delta, forces);
    const double withFaces = meanRadialForce(onSurface, forces);
    INFO("mean radial force: vertex samples " << cornersOnly << ", face samples " << withFaces);
    CHECK(std::abs(cornersOnly) < 0.05);
    CHECK(withFaces > cornersOnly + 0.1);
}

TEST_CASE("forces: far from the isosurface the push saturates at externalLimit * delta")
{
    const auto image = ballImage(4.0);
    ForceOptions options;
    options.internalWeight = 0;
    options.curvatureWeight = 0;
    options.freeCurvatureWeight = 0;
    std::vector<Vec3> forces;
    Mesh far = makeIcosphere(Vec3::Zero(), 14.0, 2);
    computeForces(far, image, options, 2.0, forces);
    for (auto v : far.vertices()) CHECK(forces[v.idx()].norm() == doctest::Approx(options.externalLimit * 2.0));
}

TEST_CASE("forces: free-flight smoothing acts on folding creases, not against an inflating bubble")
{
    // A bubble inside the object inflates: its curvature points against the push, so only the small
    // near-surface curvature weight applies and the bubble keeps growing.
    const auto image = ballImage(12.0);
    ForceOptions options;
    std::vector<Vec3> forces;
    Mesh bubble = makeIcosphere(Vec3::Zero(), 2.0, 1);
    computeForces(bubble, image, options, 1.0, forces);
    CHECK(meanRadialForce(bubble, forces) > 0.5 * options.externalLimit);
}

TEST_CASE("forces: a dark object (objectBrighter = false) reverses the push")
{
    const double radius = 8.0;
    FunctionImage dark([radius](const Vec3& x) { return 0.5 - 0.5 * std::tanh(radius - x.norm()); },
                       Box3(Vec3::Constant(-16), Vec3::Constant(16)), 1.0);
    ForceOptions options;
    options.objectBrighter = false;
    std::vector<Vec3> forces;
    Mesh outside = makeIcosphere(Vec3::Zero(), 11.0, 3);
    computeForces(outside, dark, options, 1.0, forces);
    CHECK(meanRadialForce(outside, forces) < -0.1);
}

TEST_CASE("forces: the tangential umbrella evens out a perturbed sampling without moving the surface")
{
    Mesh sphere = makeIcosphere(Vec3::Zero(), 8.0, 3);
    FunctionImage flat([](const Vec3&) { return 0.5; }, Box3(Vec3::Constant(-16), Vec3::Constant(16)), 1.0);
    ForceOptions options;
    options.externalWeight = 0;
    options.curvatureWeight = 0;
    std::vector<Vec3> forces;
    computeForces(sphere, flat, options, 1.0, forces);
    for (auto v : sphere.vertices()) {
        CHECK(std::abs(forces[v.idx()].dot(vertexNormal(sphere, v))) < 1e-9);
    }
}

TEST_CASE("integration: displacements never exceed vmax and the kinetic energy is reported")
{
    Mesh sphere = makeIcosphere(Vec3::Zero(), 8.0, 2);
    std::vector<Vec3> forces(sphere.n_vertices(), Vec3(100, 0, 0));
    IntegrationOptions options;
    options.vmax = 0.25;
    std::vector<Vec3> before;
    for (auto v : sphere.vertices()) before.push_back(position(sphere, v));
    const auto stats = integrate(sphere, forces, options);
    for (auto v : sphere.vertices()) CHECK((position(sphere, v) - before[v.idx()]).norm() <= 0.25 + 1e-12);
    CHECK(stats.maxDisplacement == doctest::Approx(0.25));
    CHECK(stats.meanKineticEnergy == doctest::Approx(0.5 * 0.25 * 0.25));
    CHECK_MESH_OK(sphere);
}

TEST_CASE("integration: a vertex whose step is taken back stops counting as travelling")
{
    // What an --intersection-free step does to a vertex pressed against another sheet: integrate()
    // moves it at full speed, the collision check puts it back (and scales its velocity). Its drift
    // must follow what it did, else it travels forever and the evolution never converges.
    Mesh sphere = makeIcosphere(Vec3::Zero(), 8.0, 1);
    std::vector<Vec3> forces(sphere.n_vertices(), Vec3(1, 0, 0));
    IntegrationOptions options;
    options.vmax = 0.25;
    options.movingSpeed = 0.1;
    const VertexHandle held = *sphere.vertices().begin();
    std::vector<Vec3> start(sphere.n_vertices()), intended(sphere.n_vertices());
    IntegrationStats stats;
    for (int i = 0; i < 40; ++i) {
        for (auto v : sphere.vertices()) start[std::size_t(v.idx())] = position(sphere, v);
        stats = integrate(sphere, forces, options);
        for (auto v : sphere.vertices()) intended[std::size_t(v.idx())] = position(sphere, v);
        sphere.set_point(held, toPoint(start[std::size_t(held.idx())])); // held back, velocity zeroed
        sphere.property(velocityProperty(sphere), held) = OpenMesh::Vec3d(0, 0, 0);
        stats = accountForShortenedStep(sphere, start, intended, options);
    }
    CHECK(stats.moving == sphere.n_vertices() - 1); // the others fly at vmax, above movingSpeed
    OpenMesh::VPropHandleT<Drift> drift;
    REQUIRE(sphere.get_property_handle(drift, kDriftProperty));
    const Drift& d = sphere.property(drift, held);
    CHECK(std::abs(d.x) + std::abs(d.y) + std::abs(d.z) < 1e-12);
    CHECK(stats.maxDisplacement == doctest::Approx(0.25));
    // Mean kinetic energy: from the velocities as they are after the check.
    const double free = 0.5 * 0.25 * 0.25;
    CHECK(stats.meanKineticEnergy == doctest::Approx(free * double(sphere.n_vertices() - 1) / double(sphere.n_vertices())));
    CHECK_MESH_OK(sphere);
}

TEST_CASE("integration: a damped vertex under a spring force comes to rest at the spring's zero")
{
    Mesh sphere = makeIcosphere(Vec3::Zero(), 1.0, 0);
    IntegrationOptions options;
    options.vmax = 10;
    std::vector<Vec3> forces(sphere.n_vertices());
    const VertexHandle v0 = *sphere.vertices().begin();
    const Vec3 rest = position(sphere, v0) + Vec3(0.3, 0, 0);
    double energy = 1;
    for (int i = 0; i < 60; ++i) {
        for (auto v : sphere.vertices()) forces[v.idx()] = Vec3::Zero();
        forces[v0.idx()] = 0.5 * (rest - position(sphere, v0));
        energy = integrate(sphere, forces, options).meanKineticEnergy;
    }
    CHECK((position(sphere, v0) - rest).norm() < 1e-4);
    CHECK(energy < 1e-8);
}
