#include "../../core/src/detail/mesh_walk.h" // private to the core: included by path
#include "../../core/src/detail/spatial_hash.h"
#include "mesh_invariants.h"
#include "riemesh/collision.h"
#include "riemesh/primitives.h"
#include "topology_fixtures.h"

#include <doctest/doctest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <queue>
#include <random>
#include <set>
#include <string>
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


/// Brute-force O(n^2) reference for findCollisions: the documented predicate evaluated on every
/// pair of live vertices, with the same floating-point formulas (area-weighted normals summed face
/// by face, squared distances, a plain Dijkstra for the mesh neighbourhood).
std::vector<CollisionPair> referenceCollisions(const Mesh& mesh, const MetricField& metric, const CollisionOptions& o)
{
    const double radius = collisionRadius(metric, o);
    const std::size_t n = mesh.n_vertices();
    std::vector<Vec3> normal(n, Vec3::Zero());
    for (auto f : mesh.faces()) {
        const HalfedgeHandle h0 = mesh.halfedge_handle(f);
        const HalfedgeHandle h1 = mesh.next_halfedge_handle(h0);
        const VertexHandle a = mesh.from_vertex_handle(h0), b = mesh.to_vertex_handle(h0), c = mesh.to_vertex_handle(h1);
        const Vec3 pa = position(mesh, a);
        const Vec3 fn = (position(mesh, b) - pa).cross(position(mesh, c) - pa);
        normal[a.idx()] += fn;
        normal[b.idx()] += fn;
        normal[c.idx()] += fn;
    }
    for (Vec3& nv : normal) {
        const double len = nv.norm();
        nv *= len > 0 ? 1.0 / len : 0.0;
    }
    OpenMesh::VPropHandleT<int> cutId;
    const bool hasCutIds = mesh.get_property_handle(cutId, kCutIdProperty);
    OpenMesh::VPropHandleT<char> merged;
    const bool hasMerged = mesh.get_property_handle(merged, kMergedProperty);
    std::vector<VertexHandle> live;
    for (auto v : mesh.vertices()) live.push_back(v);

    // Plain Dijkstra: edge-path lengths from `source` (Euclidean), infinite beyond `bound`.
    auto within = [&](VertexHandle source, double bound) {
        std::vector<double> dist(n, std::numeric_limits<double>::infinity());
        std::vector<char> done(n, 0);
        using Item = std::pair<double, int>;
        std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
        dist[source.idx()] = 0;
        queue.emplace(0.0, source.idx());
        while (!queue.empty()) {
            const auto [d, i] = queue.top();
            queue.pop();
            if (done[i]) continue;
            done[i] = 1;
            const Mesh::Point& p = mesh.point(VertexHandle(i));
            for (auto h : mesh.voh_range(VertexHandle(i))) {
                const VertexHandle w = mesh.to_vertex_handle(h);
                if (mesh.status(w).deleted()) continue;
                const double dw = d + (mesh.point(w) - p).norm();
                if (dw <= bound && dw < dist[w.idx()]) {
                    dist[w.idx()] = dw;
                    queue.emplace(dw, w.idx());
                }
            }
        }
        for (std::size_t i = 0; i < n; ++i)
            if (!done[i]) dist[i] = std::numeric_limits<double>::infinity();
        return dist;
    };

    std::vector<CollisionPair> result;
    const double r2 = radius * radius;
    for (std::size_t i = 0; i < live.size(); ++i) {
        const VertexHandle u = live[i];
        const Vec3 pu = position(mesh, u), nu = normal[u.idx()];
        std::vector<double> path;
        for (std::size_t j = i + 1; j < live.size(); ++j) {
            const VertexHandle w = live[j];
            const Vec3 pw = position(mesh, w), nw = normal[w.idx()];
            const double dx = pw.x() - pu.x(), dy = pw.y() - pu.y(), dz = pw.z() - pu.z();
            const double d2 = dx * dx + dy * dy + dz * dz;
            if (!(d2 <= r2)) continue;
            const double agree = nu.x() * nw.x() + nu.y() * nw.y() + nu.z() * nw.z();
            const double hu = dx * nu.x() + dy * nu.y() + dz * nu.z();
            const double hw = dx * nw.x() + dy * nw.y() + dz * nw.z();
            const double limit = 0.25 * d2;
            if (agree > 0.5 && hu * hu <= limit && hw * hw <= limit) continue; // same sheet
            if (agree > -0.5 && hu < 0 && hw > 0) continue;                      // convex crease
            if (hasCutIds) {
                const int cu = mesh.property(cutId, u);
                if (cu != 0 && cu == mesh.property(cutId, w)) continue;
            }
            double distance = std::sqrt(d2);
            if (!metric.isEuclidean()) {
                distance = metricLength(metric.at(pu), metric.at(pw), pw - pu); // the endpoints' mean, as documented
                if (distance > radius) continue;
            }
            // Close along the mesh: a path within the bound, and near a merge no detour either
            // (<= 2 d_E + delta / 2).
            if (path.empty()) path = within(u, o.neighbourhoodFactor * radius);
            const bool nearMerge = hasMerged && (mesh.property(merged, u) || mesh.property(merged, w));
            if (path[w.idx()] < std::numeric_limits<double>::infinity() &&
                (!nearMerge || path[w.idx()] <= 2.0 * std::sqrt(d2) + 0.5 * o.delta))
                continue;
            result.push_back({VertexHandle(std::min(u.idx(), w.idx())), VertexHandle(std::max(u.idx(), w.idx())), distance});
        }
    }
    std::sort(result.begin(), result.end(), [](const CollisionPair& x, const CollisionPair& y) {
        if (x.distance != y.distance) return x.distance < y.distance;
        return x.u.idx() != y.u.idx() ? x.u.idx() < y.u.idx() : x.w.idx() < y.w.idx();
    });
    return result;
}

/// Moves every live vertex by a uniform random offset in [-amount, amount]^3 (world units).
void jitter(Mesh& mesh, double amount, std::mt19937& rng)
{
    std::uniform_real_distribution<double> u(-amount, amount);
    for (auto v : mesh.vertices()) mesh.point(v) += Mesh::Point(u(rng), u(rng), u(rng));
}

Mesh translated(Mesh mesh, const Vec3& t)
{
    for (auto v : mesh.vertices()) mesh.point(v) += toPoint(t);
    return mesh;
}

/// Checks findCollisions against the reference, pair by pair; returns the number of pairs.
std::size_t checkAgainstReference(const Mesh& mesh, const MetricField& metric, const CollisionOptions& o)
{
    const auto fast = findCollisions(mesh, metric, o);
    const auto slow = referenceCollisions(mesh, metric, o);
    REQUIRE(fast.size() == slow.size());
    for (std::size_t i = 0; i < fast.size(); ++i) {
        INFO("pair " << i << " of " << fast.size());
        CHECK(fast[i].u == slow[i].u);
        CHECK(fast[i].w == slow[i].w);
        CHECK(fast[i].distance == slow[i].distance);
    }
    return fast.size();
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

TEST_CASE("collision: same pairs as a brute-force reference on perturbed and folded meshes")
{
    std::mt19937 rng(20030);
    std::vector<std::pair<std::string, Mesh>> meshes;
    {
        Mesh m = makeRegularSphere(Vec3(0.3, -0.2, 0.1), 3, 1.0);
        jitter(m, 0.3, rng);
        meshes.emplace_back("perturbed sphere", std::move(m));
    }
    {
        // A sphere flattened into a pancake: its two faces are close across the gap, and meet
        // (close along the mesh too) at the rim.
        Mesh m = makeRegularSphere(Vec3(-2.5, 1.0, 0.5), 4, 1.0);
        const double r = (position(m, *m.vertices().begin()) - Vec3(-2.5, 1.0, 0.5)).norm();
        for (auto v : m.vertices()) m.point(v)[2] = 0.5 + (m.point(v)[2] - 0.5) * 1.6 / r;
        jitter(m, 0.1, rng);
        Mesh tagged = m;
        meshes.emplace_back("pancake", std::move(m));
        // The same pancake with its x > -2.5 half tagged as near a merge: there its two faces are
        // joined around the rim by a detour, and pair up (the stricter rule of kMergedProperty).
        OpenMesh::VPropHandleT<char> merged;
        tagged.add_property(merged, kMergedProperty);
        for (auto v : tagged.vertices()) tagged.property(merged, v) = position(tagged, v).x() > -2.5 ? 1 : 0;
        meshes.emplace_back("pancake half near a merge", std::move(tagged));
    }
    {
        Mesh m = makeRegularSphere(Vec3::Zero(), 3, 1.0);
        const double r = (m.point(*m.vertices().begin()) - Mesh::Point(0, 0, 0)).norm();
        appendMesh(m, makeRegularSphere(Vec3(2 * r + 1.2, 0.7, -0.4), 3, 1.0));
        jitter(m, 0.25, rng);
        meshes.emplace_back("two spheres close together", std::move(m));
    }
    {
        Mesh m = makeRegularTorus(Vec3(1, 2, 3), 4.0, 1.2, 0.8);
        jitter(m, 0.2, rng);
        meshes.emplace_back("perturbed torus", std::move(m));
    }
    {
        Mesh m = makeBox(Vec3(-3, -4, -1), Vec3(9, 7, 0.6), 1.0);
        jitter(m, 0.15, rng);
        meshes.emplace_back("thin plate", std::move(m));
    }
    {
        // Far from the origin and far apart: a sparse cell grid.
        Mesh m = translated(makeRegularSphere(Vec3::Zero(), 2, 1.0), Vec3(-1500, 20, 3));
        appendMesh(m, translated(makeRegularSphere(Vec3::Zero(), 2, 1.0), Vec3(2500, -700, 900)));
        appendMesh(m, translated(makeRegularSphere(Vec3::Zero(), 2, 1.0), Vec3(2504.5, -700, 900)));
        jitter(m, 0.3, rng);
        meshes.emplace_back("far apart", std::move(m));
    }
    {
        // Deleted vertices and cut ids: both must be ignored exactly as documented.
        Mesh m = makeRegularSphere(Vec3::Zero(), 2, 1.0);
        const double r = (m.point(*m.vertices().begin()) - Mesh::Point(0, 0, 0)).norm();
        const std::size_t nA = m.n_vertices();
        appendMesh(m, makeRegularSphere(Vec3(2 * r + 0.6, 0, 0), 2, 1.0));
        appendMesh(m, makeRegularSphere(Vec3(0, 2 * r + 0.6, 0), 2, 1.0));
        jitter(m, 0.2, rng);
        OpenMesh::VPropHandleT<int> cutId;
        m.add_property(cutId, kCutIdProperty);
        for (auto v : m.vertices()) m.property(cutId, v) = position(m, v).x() > 0.5 * r ? 7 : 0;
        std::vector<VertexHandle> doomed;
        for (auto v : m.vertices())
            if (std::size_t(v.idx()) >= nA && position(m, v).y() > 2 * r + 0.6) doomed.push_back(v);
        for (auto v : doomed) m.delete_vertex(v, false);
        meshes.emplace_back("deleted vertices and cut ids", std::move(m));
    }
    const auto metrics = testMetrics();
    std::size_t reported = 0;
    for (const auto& entry : meshes) {
        // not a structured binding: INFO captures `name` in a lambda (C++20; clang refuses it in C++17)
        const auto& name = entry.first;
        const auto& mesh = entry.second;
        for (double deltaScale : {1.0, 1.6}) {
            CollisionOptions o = optionsFor(mesh);
            o.delta *= deltaScale; // a larger radius: more candidates, more mesh searches
            for (const auto& metric : metrics) {
                INFO(name << ", delta x" << deltaScale << ", euclidean " << metric->isEuclidean());
                reported += checkAgainstReference(mesh, *metric, o);
            }
        }
    }
    CHECK(reported > 5000); // the fixtures do collide (pancake, plate, close spheres)
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
        std::vector<CollisionPair> contacts;
        CHECK(findCollisions(box, EuclideanMetric(), o, &contacts).empty());
        CHECK(contacts.empty()); // close along the mesh: not even held apart
        CHECK(findCollisions(box, ConstantMetric(Vec3(1, 1.5, 2).asDiagonal().toDenseMatrix()), o, &contacts).empty());
        CHECK(contacts.empty());
    }
}

TEST_CASE("collision: near a merge, two sheets joined by a detour around a rim are collisions")
{
    // A pancake: its two faces 1.6 apart, joined around the rim. Untagged, the rim path (within
    // the neighbourhood bound) hides many across pairs; tagged as near a merge (kMergedProperty),
    // a path longer than 2 d_E + delta / 2 no longer does.
    Mesh m = makeRegularSphere(Vec3::Zero(), 4, 1.0);
    const double r = (position(m, *m.vertices().begin())).norm();
    for (auto v : m.vertices()) m.point(v)[2] *= 0.8 / r;
    const CollisionOptions o = optionsFor(m);
    auto across = [&](const Mesh& mesh) {
        int n = 0;
        for (const auto& p : findCollisions(mesh, EuclideanMetric(), o))
            n += position(mesh, p.u).z() * position(mesh, p.w).z() < 0;
        return n;
    };
    const int plain = across(m);
    OpenMesh::VPropHandleT<char> merged;
    m.add_property(merged, kMergedProperty);
    for (auto v : m.vertices()) m.property(merged, v) = 1;
    const int tagged = across(m);
    INFO("across pairs: untagged " << plain << ", near a merge " << tagged);
    CHECK(tagged > plain);
    CHECK(tagged > 100);
}

TEST_CASE("bounded path search: stopping at the targets gives the targets' full-run answers")
{
    // runUntil stops once its targets are settled (findCollisions' exclusion of pairs close along
    // the mesh); reached() and distance() of every target must be the full run's, bit for bit.
    const Mesh torus = makeRegularTorus(Vec3(0, 0, 0), 4.0, 1.5, 0.6);
    const int n = int(torus.n_vertices());
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> pick(0, n - 1);
    detail::BoundedPathSearch full, early;
    int partial = 0; // runs that stopped before the full run's last settled vertex
    for (int trial = 0; trial < 200; ++trial) {
        const VertexHandle source(pick(rng));
        const double bound = 1.0 + 0.1 * (trial % 60);
        const std::vector<VertexHandle> reached = full.run(torus, source, bound);
        const std::size_t settled = reached.size();
        // Targets among the reached vertices (what findCollisions mostly asks), and every third
        // trial one anywhere (perhaps beyond the bound: then the search runs to the end).
        std::vector<int> targets;
        std::uniform_int_distribution<std::size_t> among(0, settled - 1);
        for (int k = 0; k < 1 + trial % 5; ++k) {
            const int t = trial % 3 == 0 && k == 0 ? pick(rng) : reached[among(rng)].idx();
            if (t != source.idx() && std::find(targets.begin(), targets.end(), t) == targets.end()) targets.push_back(t);
        }
        early.runUntil(torus, source, bound, targets.data(), targets.size());
        bool allReached = true;
        for (int t : targets) {
            const VertexHandle v(t);
            CHECK(early.reached(v) == full.reached(v));
            if (full.reached(v)) CHECK(early.distance(v) == full.distance(v));
            allReached = allReached && full.reached(v);
        }
        // With every target reached the search may stop early: count the runs that did (the test
        // would see nothing if runUntil always ran to the bound).
        std::size_t earlyCount = 0;
        for (auto v : torus.vertices()) earlyCount += early.reached(v);
        partial += allReached && earlyCount < settled;
    }
    CHECK(partial > 50);
}

TEST_CASE("cell grid: the pairs closer than the cell size, for point sets spanning many build chunks")
{
    // The build's passes over the points run in parallel chunks (bounds, cell keys): sets of
    // several chunks, dense and sparse boxes, against all pairs; a NaN anywhere is refused.
    std::mt19937 rng(4096);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    for (const double spread : {30.0, 3000.0}) { // a dense box, then a sparse one (far more cells than points)
        const std::size_t n = 9000;
        std::vector<double> xyz(3 * n);
        for (double& x : xyz) x = spread * unit(rng) - 7.0;
        std::vector<int> index(n - 100); // a subset, through an index array as findCollisions uses it
        for (std::size_t i = 0; i < index.size(); ++i) index[i] = int(i + 100);
        const double cell = 1.0;
        detail::CellGrid grid;
        for (const bool indexed : {false, true}) {
            INFO("spread " << spread << ", indexed " << indexed);
            const std::size_t count = indexed ? index.size() : n;
            grid.build(xyz.data(), indexed ? index.data() : nullptr, count, cell);
            auto point = [&](std::size_t i) { return xyz.data() + 3 * (indexed ? std::size_t(index[i]) : i); };
            auto close = [&](std::size_t i, std::size_t j) {
                const double* p = point(i);
                const double* q = point(j);
                const double d2 = (p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) + (p[2] - q[2]) * (p[2] - q[2]);
                return d2 < cell * cell;
            };
            std::set<std::pair<std::uint32_t, std::uint32_t>> found;
            grid.forEachCell([&](std::uint32_t a0, std::uint32_t a1, const std::uint32_t(*range)[2], int ranges) {
                for (std::uint32_t s = a0; s < a1; ++s)
                    for (int r = 0; r < ranges; ++r)
                        for (std::uint32_t t = r == 0 ? s + 1 : range[r][0]; t < range[r][1]; ++t) {
                            const std::uint32_t i = grid.index(s), j = grid.index(t);
                            if (close(i, j)) found.insert({std::min(i, j), std::max(i, j)});
                        }
            });
            std::set<std::pair<std::uint32_t, std::uint32_t>> expected;
            for (std::size_t i = 0; i < count; ++i)
                for (std::size_t j = i + 1; j < count; ++j)
                    if (close(i, j)) expected.insert({std::uint32_t(i), std::uint32_t(j)});
            CHECK(found.size() == expected.size());
            CHECK(found == expected);
            if (spread < 100) CHECK(expected.size() > 1000); // the dense box does have close pairs
        }
        xyz[3 * (n - 5) + 1] = std::numeric_limits<double>::quiet_NaN(); // in the last chunk
        CHECK_THROWS_AS(grid.build(xyz.data(), nullptr, n, cell), std::invalid_argument);
    }
}
