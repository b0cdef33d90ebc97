#include "mesh_invariants.h"
#include "riemesh/collision.h"
#include "riemesh/primitives.h"
#include "topology_fixtures.h"

#include <doctest/doctest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <set>
#include <utility>

using namespace riemesh;
using namespace riemesh::fixtures;

namespace {

/// Collision options for a mesh whose edges (world units) are in [delta, zeta delta].
CollisionOptions optionsFor(const Mesh& mesh)
{
    const EdgeStats s = edgeStats(mesh);
    CollisionOptions o;
    o.delta = s.min;
    o.zeta = std::max(2.5, s.max / s.min);
    o.vmax = 0.5 * o.delta;
    return o;
}

Mat3 rotationXYZ(double a, double b, double c)
{
    return (Eigen::AngleAxisd(a, Vec3::UnitX()) * Eigen::AngleAxisd(b, Vec3::UnitY()) *
            Eigen::AngleAxisd(c, Vec3::UnitZ()))
        .toRotationMatrix();
}

/// Metrics a regular mesh must not collide with itself under.
std::vector<std::unique_ptr<MetricField>> testMetrics()
{
    std::vector<std::unique_ptr<MetricField>> m;
    m.push_back(std::make_unique<EuclideanMetric>());
    m.push_back(std::make_unique<ConstantMetric>(Vec3(1, 1, 9).asDiagonal().toDenseMatrix()));
    m.push_back(std::make_unique<ConstantMetric>(metricFromEigen(rotationXYZ(0.3, 0.7, 1.1), Vec3(1, 2, 4))));
    m.push_back(std::make_unique<FunctionMetric>(
        [](const Vec3& x) { return Mat3(metricFromEigen(rotationXYZ(x.x(), 0.2, x.y()), Vec3(1, 1 + 0.5 * std::abs(std::sin(x.z())), 1.5))); },
        1.5));
    return m;
}

double timeFindCollisionsMs(const Mesh& mesh, const MetricField& metric, const CollisionOptions& o, std::size_t* pairs)
{
    double best = 1e30;
    for (int run = 0; run < 30; ++run) {
        const auto t0 = std::chrono::steady_clock::now();
        const auto found = findCollisions(mesh, metric, o);
        const auto t1 = std::chrono::steady_clock::now();
        best = std::min(best, std::chrono::duration<double, std::milli>(t1 - t0).count());
        if (pairs) *pairs = found.size();
    }
    return best;
}

} // namespace

TEST_CASE("collision: lambda follows eq. 4 (Euclidean) and the Riemannian bound")
{
    const double zeta = 2.5, delta = 1.0, vmax = 0.5;
    CHECK(collisionLambda(true, zeta, delta, vmax) == doctest::Approx(std::sqrt(1 - 0.4 + 0.16) + 0.1));
    CHECK(collisionLambda(false, zeta, delta, vmax) == doctest::Approx(1.1));
    CollisionOptions o;
    CHECK(collisionRadius(EuclideanMetric(), o) == doctest::Approx((std::sqrt(0.76) + 0.1) * 2.5));
    CHECK(collisionRadius(ConstantMetric(Mat3::Identity() * 2), o) == doctest::Approx(1.1 * 2.5));
    CHECK_THROWS(collisionLambda(true, 1.0, delta, vmax));
}

TEST_CASE("collision: a regular icosphere never collides with itself, at any resolution and metric")
{
    const auto metrics = testMetrics();
    for (int s = 0; s <= 5; ++s) {
        Mesh sphere = makeRegularSphere(Vec3(0.3, -0.2, 0.1), s, 1.0);
        const CollisionOptions o = optionsFor(sphere);
        for (const auto& metric : metrics) {
            INFO("subdivisions " << s << ", euclidean " << metric->isEuclidean());
            CHECK(findCollisions(sphere, *metric, o).empty());
        }
    }
}

TEST_CASE("collision: regular boxes and tori never collide with themselves")
{
    const auto metrics = testMetrics();
    std::vector<Mesh> meshes;
    meshes.push_back(makeBox(Vec3(0, 0, 0), Vec3(3, 3, 3), 1.0));
    meshes.push_back(makeBox(Vec3(-1, 0, 0), Vec3(9, 7, 4), 1.0));
    meshes.push_back(makeBox(Vec3(0, 0, 0), Vec3(20, 12, 6), 1.0));
    meshes.push_back(makeRegularTorus(Vec3::Zero(), 6.0, 2.0, 1.0));
    meshes.push_back(makeRegularTorus(Vec3::Zero(), 5.0, 0.6, 1.0)); // thin tube, 4 minor segments
    meshes.push_back(makeTorus(Vec3::Zero(), 5.0, 0.5, 30, 3));       // triangular tube
    meshes.push_back(makeRegularTorus(Vec3(1, 2, 3), 12.0, 4.0, 1.0));
    for (std::size_t i = 0; i < meshes.size(); ++i) {
        const CollisionOptions o = optionsFor(meshes[i]);
        for (const auto& metric : metrics) {
            INFO("mesh " << i << ", euclidean " << metric->isEuclidean());
            const auto found = findCollisions(meshes[i], *metric, o);
            CHECK(found.empty());
        }
    }
}

TEST_CASE("collision: two approaching spheres collide once the gap is within the radius, facing pairs first")
{
    const double edge = 1.0;
    Mesh probe = makeRegularSphere(Vec3::Zero(), 3, edge);
    const CollisionOptions o = optionsFor(probe);
    const EuclideanMetric metric;
    const double radius = collisionRadius(metric, o);
    const double sphereRadius = (probe.point(*probe.vertices().begin()) - Mesh::Point(0, 0, 0)).norm();
    // Icospheres are centrally symmetric: the +dir vertex of A faces the -dir vertex of B.
    const Vec3 dir = position(probe, extremeVertex(probe, Vec3(1, 0.1, 0.05))).normalized();
    for (double gap : {0.3 * radius, 0.9 * radius, 0.999 * radius, 1.01 * radius, 1.5 * radius}) {
        Mesh mesh = makeRegularSphere(Vec3::Zero(), 3, edge);
        const std::size_t nA = mesh.n_vertices();
        appendMesh(mesh, makeRegularSphere((2 * sphereRadius + gap) * dir, 3, edge));
        const auto found = findCollisions(mesh, metric, o);
        INFO("gap / radius = " << gap / radius);
        if (gap <= radius) {
            REQUIRE_FALSE(found.empty());
            CHECK(found.front().distance == doctest::Approx(gap).epsilon(1e-6));
            for (std::size_t i = 0; i < found.size(); ++i) {
                const auto& c = found[i];
                CHECK(((std::size_t(c.u.idx()) < nA) != (std::size_t(c.w.idx()) < nA))); // across the gap
                CHECK(c.distance <= radius + 1e-12);
                if (i > 0) CHECK(found[i - 1].distance <= c.distance);
            }
            std::set<std::pair<int, int>> unique;
            for (const auto& c : found) unique.insert(std::minmax(c.u.idx(), c.w.idx()));
            CHECK(unique.size() == found.size());
        } else {
            CHECK(found.empty());
        }
    }
}

TEST_CASE("collision: a metric that overestimates lengths across a thin gap prevents the collision")
{
    // Two plates 3 thick stacked along z with a 1.5 gap: closer than the Euclidean radius (2.43),
    // but G = diag(1, 1, 9) measures the gap as 4.5 > lambda_R zeta delta = 2.75 (paper, sect. 5).
    Mesh plates = makeBox(Vec3(0, 0, 0), Vec3(8, 8, 3), 1.0);
    appendMesh(plates, makeBox(Vec3(0, 0, 4.5), Vec3(8, 8, 7.5), 1.0));
    CollisionOptions o;
    o.delta = 1.0;
    o.zeta = 2.5;
    o.vmax = 0.5;
    const auto euclidean = findCollisions(plates, EuclideanMetric(), o);
    REQUIRE_FALSE(euclidean.empty());
    CHECK(euclidean.front().distance == doctest::Approx(1.5));
    for (const auto& c : euclidean) {
        const double zu = plates.point(c.u)[2], zw = plates.point(c.w)[2];
        CHECK(std::min(zu, zw) == doctest::Approx(3.0));
        CHECK(std::max(zu, zw) == doctest::Approx(4.5));
    }
    const ConstantMetric across(Vec3(1, 1, 9).asDiagonal().toDenseMatrix());
    CHECK(findCollisions(plates, across, o).empty());
    // ... while a metric that stretches along the plates only does not hide the gap.
    const ConstantMetric along(Vec3(1.2, 1.2, 1).asDiagonal().toDenseMatrix());
    CHECK_FALSE(findCollisions(plates, along, o).empty());
}

TEST_CASE("collision: a thin plate collides with itself under the Euclidean metric but not across a strong metric")
{
    Mesh plate = makeBox(Vec3(0, 0, 0), Vec3(12, 12, 1.5), 1.0);
    CollisionOptions o;
    const auto euclidean = findCollisions(plate, EuclideanMetric(), o);
    CHECK_FALSE(euclidean.empty()); // the coarse Euclidean model punches holes (paper, Fig. 4d)
    for (const auto& c : euclidean) CHECK(std::abs(plate.point(c.u)[2] - plate.point(c.w)[2]) == doctest::Approx(1.5));
    CHECK(findCollisions(plate, ConstantMetric(Vec3(1, 1, 4).asDiagonal().toDenseMatrix()), o).empty());
}

TEST_CASE("collision: deleted vertices are ignored")
{
    Mesh mesh = makeRegularSphere(Vec3::Zero(), 2, 1.0);
    const double r = (mesh.point(*mesh.vertices().begin()) - Mesh::Point(0, 0, 0)).norm();
    const std::size_t nA = mesh.n_vertices();
    appendMesh(mesh, makeRegularSphere(Vec3(2 * r + 0.5, 0, 0), 2, 1.0));
    const CollisionOptions o = optionsFor(mesh);
    const auto before = findCollisions(mesh, EuclideanMetric(), o);
    REQUIRE_FALSE(before.empty());
    for (auto v : mesh.vertices())
        if (std::size_t(v.idx()) >= nA) mesh.delete_vertex(v, false);
    CHECK(findCollisions(mesh, EuclideanMetric(), o).empty());
}

TEST_CASE("collision: timing on icospheres with edge ~ delta and no collisions")
{
    for (int s : {4, 5}) {
        Mesh sphere = makeRegularSphere(Vec3::Zero(), s, 1.0);
        CollisionOptions o = optionsFor(sphere);
        std::size_t pairsE = 1, pairsR = 1;
        const double euclidean = timeFindCollisionsMs(sphere, EuclideanMetric(), o, &pairsE);
        const ConstantMetric aniso(metricFromEigen(rotationXYZ(0.3, 0.7, 1.1), Vec3(1, 1.5, 2)));
        const double anisotropic = timeFindCollisionsMs(sphere, aniso, o, &pairsR);
        MESSAGE("findCollisions on " << sphere.n_vertices() << " vertices: euclidean " << euclidean
                                     << " ms, anisotropic " << anisotropic << " ms (best of 30)");
        CHECK(pairsE == 0);
        CHECK(pairsR == 0);
        // Loose bound (shared CI machines): about 0.1 us per vertex is expected in Release.
        CHECK(euclidean < 2e-3 * double(sphere.n_vertices()));
    }
}

TEST_CASE("collision: a coarse box (edges near zeta delta) and its sharp edges never collide with themselves")
{
    // Edges of up to 2.4 delta: the 2-ring is up to ~4.8 delta away along the mesh, more than
    // 2 x the Euclidean radius; the box's 90-degree creases put vertices of two faces within the
    // radius with perpendicular normals.
    CollisionOptions o; // delta 1, zeta 2.5
    for (double edge : {1.6, 2.0, 2.4}) {
        const Mesh box = makeBox(Vec3(-7.5, -7.5, -7.5), Vec3(7.5, 7.5, 7.5), edge);
        INFO("edge " << edge);
        CHECK(findCollisions(box, EuclideanMetric(), o).empty());
        CHECK(findCollisions(box, ConstantMetric(Vec3(1, 1.5, 2).asDiagonal().toDenseMatrix()), o).empty());
    }
}
