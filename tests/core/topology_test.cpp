#include "mesh_invariants.h"
#include "riemesh/collision.h"
#include "riemesh/primitives.h"
#include "riemesh/self_intersection.h"
#include "riemesh/topology.h"
#include "topology_fixtures.h"

#include <doctest/doctest.h>

#include <algorithm>
#include <map>
#include <random>
#include <set>

using namespace riemesh;
using namespace riemesh::fixtures;

namespace {

/// Garbage-collects, then requires the invariants and returns the topology.
MeshTopology compactAndCheck(Mesh& mesh)
{
    mesh.garbage_collection();
    REQUIRE_MESH_OK(mesh);
    return topologyOf(mesh);
}

/// Two regular icospheres whose facing vertices are `gap` apart along `dir`; returns the pair.
Mesh makeFacingSpheres(double gap, int subdivisions, VertexHandle& u, VertexHandle& w)
{
    Mesh mesh = makeRegularSphere(Vec3::Zero(), subdivisions, 1.0);
    const double r = (mesh.point(*mesh.vertices().begin()) - Mesh::Point(0, 0, 0)).norm();
    u = extremeVertex(mesh, Vec3(1, 0.1, 0.05));
    const Vec3 dir = position(mesh, u).normalized();
    Mesh b = makeRegularSphere((2 * r + gap) * dir, subdivisions, 1.0);
    // Icospheres are centrally symmetric: B's vertex farthest along -dir faces u.
    const VertexHandle wb = extremeVertex(b, -dir);
    w = VertexHandle(int(mesh.n_vertices()) + wb.idx());
    appendMesh(mesh, b);
    REQUIRE((position(mesh, w) - position(mesh, u)).norm() == doctest::Approx(gap));
    return mesh;
}

/// All the triangle loops of `mesh` (3-cycles of edges that are not faces), each once.
std::vector<TunnelCandidate> triangleLoops(const Mesh& mesh)
{
    std::vector<TunnelCandidate> loops;
    for (auto u : mesh.vertices())
        for (auto v : mesh.vv_range(u)) {
            if (v.idx() <= u.idx()) continue;
            for (auto w : mesh.vv_range(v)) {
                if (w.idx() <= v.idx() || !mesh.find_halfedge(w, u).is_valid()) continue;
                bool isFace = false;
                for (auto f : mesh.vf_range(u)) {
                    std::set<int> s;
                    for (auto x : mesh.fv_range(f)) s.insert(x.idx());
                    if (s.count(v.idx()) && s.count(w.idx())) isFace = true;
                }
                if (!isFace) loops.push_back({u, v, w});
            }
        }
    return loops;
}

} // namespace

TEST_CASE("merge: two spheres touching become one component (euler -2)")
{
    VertexHandle u, w;
    Mesh mesh = makeFacingSpheres(0.5, 2, u, w);
    const auto before = topologyOf(mesh);
    REQUIRE(before.components == 2);
    const double volume = signedVolume(mesh);
    REQUIRE(canMerge(mesh, u, w));
    REQUIRE(merge(mesh, u, w));
    const auto after = compactAndCheck(mesh);
    CHECK(after.euler == before.euler - 2);
    CHECK(after.components == 1);
    CHECK(after.genus == 0);
    CHECK(signedVolume(mesh) > 0.9 * volume);
}

TEST_CASE("merge: both sides of a thin plate open a handle (genus +1) and the volume stays positive")
{
    Mesh plate = makeBox(Vec3(0, 0, 0), Vec3(8, 8, 1.5), 1.0);
    const auto before = topologyOf(plate);
    auto closestTo = [&](const Vec3& p) {
        VertexHandle best;
        double bestD = 1e9;
        for (auto v : plate.vertices()) {
            const double d = (position(plate, v) - p).norm();
            if (d < bestD) { bestD = d; best = v; }
        }
        return best;
    };
    const VertexHandle topCenter = closestTo(Vec3(4, 4, 1.5)), bottom = closestTo(Vec3(4, 4, 0));
    REQUIRE(canMerge(plate, topCenter, bottom));
    REQUIRE(merge(plate, topCenter, bottom));
    const auto after = compactAndCheck(plate);
    CHECK(after.euler == before.euler - 2);
    CHECK(after.components == 1);
    CHECK(after.genus == 1);
    CHECK(signedVolume(plate) > 0);
    CHECK(signedVolume(plate) < 8 * 8 * 1.5);
}

TEST_CASE("merge: across the tube of a torus adds a second handle (genus 2)")
{
    Mesh torus = makeRegularTorus(Vec3::Zero(), 6.0, 2.0, 1.0);
    const auto before = topologyOf(torus);
    // The top and bottom of the tube on its x > 0 side: the band runs through the tube's inside.
    const VertexHandle top = extremeVertex(torus, Vec3(0.3, 0.01, 1));
    const VertexHandle bottom = extremeVertex(torus, Vec3(0.3, 0.01, -1));
    REQUIRE(canMerge(torus, top, bottom));
    REQUIRE(merge(torus, top, bottom));
    const auto after = compactAndCheck(torus);
    CHECK(after.euler == before.euler - 2);
    CHECK(after.genus == 2);
}

TEST_CASE("merge: refused for neighbours, shared neighbours, existing loop edges and deleted vertices")
{
    Mesh sphere = makeRegularSphere(Vec3::Zero(), 2, 1.0);
    const VertexHandle u = *sphere.vertices().begin();
    const VertexHandle n1 = *sphere.vv_range(u).begin();
    CHECK_FALSE(canMerge(sphere, u, u));
    CHECK_FALSE(canMerge(sphere, u, n1)); // adjacent
    // Two rings away: the closed one-rings share a vertex.
    VertexHandle ring2;
    for (auto x : sphere.vv_range(n1))
        if (x != u && !sphere.find_halfedge(u, x).is_valid()) { ring2 = x; break; }
    REQUIRE(ring2.is_valid());
    CHECK_FALSE(canMerge(sphere, u, ring2));
    // Three rings away along an edge path: a loop-A vertex is adjacent to a loop-B vertex.
    VertexHandle ring3;
    for (auto x : sphere.vv_range(ring2)) {
        bool far = x != u && !sphere.find_halfedge(u, x).is_valid();
        for (auto y : sphere.vv_range(u)) if (y == x || sphere.find_halfedge(y, x).is_valid()) far = false;
        if (far) { ring3 = x; break; }
    }
    REQUIRE(ring3.is_valid());
    CHECK_FALSE(canMerge(sphere, u, ring3));
    CHECK_FALSE(merge(sphere, u, ring3));
    CHECK(topologyOf(sphere).euler == 2); // untouched
    // Far apart on the same sphere: allowed (it would add a handle).
    const VertexHandle far = extremeVertex(sphere, -position(sphere, u));
    CHECK(canMerge(sphere, u, far));
    sphere.delete_vertex(far, false);
    CHECK_FALSE(canMerge(sphere, u, far));
}

TEST_CASE("merge: the band orientation is forced by the loops, whatever the pair order")
{
    for (int order = 0; order < 2; ++order) {
        VertexHandle u, w;
        Mesh mesh = makeFacingSpheres(0.7, 2, u, w);
        const auto before = topologyOf(mesh);
        const bool merged = order == 0 ? merge(mesh, u, w) : merge(mesh, w, u);
        REQUIRE(merged);
        const auto after = compactAndCheck(mesh);
        CHECK(after.euler == before.euler - 2);
        CHECK(after.components == 1);
    }
}

TEST_CASE("cutTunnel: cutting the triangular tube of a torus removes the handle (genus 0, euler +2)")
{
    const int majorSegments = 16;
    Mesh torus = makeTorus(Vec3::Zero(), 5.0, 0.6, majorSegments, 3);
    const auto before = topologyOf(torus);
    REQUIRE(before.genus == 1);
    // makeTorus numbers vertices ring by ring: ring i is i*3 .. i*3+2.
    const VertexHandle u(12), v(13), w(14);
    CHECK_FALSE(canCutTunnel(torus, u, v, VertexHandle(15))); // 12-13-15 is not a loop of edges
    REQUIRE(canCutTunnel(torus, u, v, w));
    const std::size_t nBefore = torus.n_vertices();
    REQUIRE(cutTunnel(torus, u, v, w));
    CHECK(torus.n_vertices() == nBefore + 3);
    const auto after = compactAndCheck(torus);
    CHECK(after.euler == before.euler + 2);
    CHECK(after.components == 1);
    CHECK(after.genus == 0);
    CHECK(signedVolume(torus) > 0);
}

TEST_CASE("cutTunnel: either traversal direction of the loop works")
{
    Mesh torus = makeTorus(Vec3::Zero(), 5.0, 0.6, 12, 3);
    const auto before = topologyOf(torus);
    REQUIRE(cutTunnel(torus, VertexHandle(8), VertexHandle(7), VertexHandle(6)));
    const auto after = compactAndCheck(torus);
    CHECK(after.euler == before.euler + 2);
    CHECK(after.genus == 0);
}

TEST_CASE("cutTunnel: cutting the tube of a dumbbell splits it into two components")
{
    std::vector<std::array<VertexHandle, 3>> rings;
    Mesh dumbbell = makeDumbbell(3.0, 2, 3.0, 4, &rings);
    const auto before = compactAndCheck(dumbbell);
    REQUIRE(before.components == 1);
    REQUIRE(before.genus == 0);
    REQUIRE(rings.size() == 3);
    const auto& ring = rings[1];
    REQUIRE(canCutTunnel(dumbbell, ring[0], ring[1], ring[2]));
    REQUIRE(cutTunnel(dumbbell, ring[0], ring[1], ring[2]));
    const auto after = compactAndCheck(dumbbell);
    CHECK(after.euler == before.euler + 2);
    CHECK(after.components == 2);
    CHECK(after.genus == 0);
}

TEST_CASE("cutTunnel: the fresh caps are not reported as a collision, the rest of the model still is")
{
    std::vector<std::array<VertexHandle, 3>> rings;
    Mesh dumbbell = makeDumbbell(3.0, 2, 3.0, 4, &rings);
    const auto& ring = rings[1];
    REQUIRE(cutTunnel(dumbbell, ring[0], ring[1], ring[2]));
    dumbbell.garbage_collection();
    const EdgeStats s = edgeStats(dumbbell);
    CollisionOptions o;
    o.delta = s.min;
    o.zeta = std::max(2.5, s.max / s.min);
    CHECK(findCollisions(dumbbell, EuclideanMetric(), o).empty());
}

TEST_CASE("cutTunnel: refused for faces, missing edges and deleted vertices")
{
    Mesh sphere = makeRegularSphere(Vec3::Zero(), 2, 1.0);
    const FaceHandle f = *sphere.faces().begin();
    std::vector<VertexHandle> t;
    for (auto v : sphere.fv_range(f)) t.push_back(v);
    CHECK_FALSE(canCutTunnel(sphere, t[0], t[1], t[2]));
    CHECK_FALSE(cutTunnel(sphere, t[0], t[1], t[2]));
    CHECK(topologyOf(sphere).euler == 2);
    // A sphere has no triangle loop that is not a face except around valence-3 vertices (none here).
    CHECK(triangleLoops(sphere).empty());
    Mesh torus = makeTorus(Vec3::Zero(), 5.0, 0.6, 12, 3);
    torus.delete_vertex(VertexHandle(7), false);
    CHECK_FALSE(canCutTunnel(torus, VertexHandle(6), VertexHandle(7), VertexHandle(8)));
}

TEST_CASE("resolveTopology: a sphere pair found by findCollisions merges once into one genus-0 component")
{
    VertexHandle u, w;
    Mesh probe = makeRegularSphere(Vec3::Zero(), 3, 1.0);
    const EdgeStats s = edgeStats(probe);
    CollisionOptions o;
    o.delta = s.min;
    o.zeta = std::max(2.5, s.max / s.min);
    o.vmax = 0.5 * o.delta;
    const double radius = collisionRadius(EuclideanMetric(), o);
    // The gap just closed below the radius, as after one iteration of a model moving at vmax.
    Mesh mesh = makeFacingSpheres(radius - 0.5 * o.vmax, 3, u, w);
    const auto collisions = findCollisions(mesh, EuclideanMetric(), o);
    REQUIRE_FALSE(collisions.empty());
    const auto before = topologyOf(mesh);
    TopologyOptions t;
    t.neighbourhoodRadius = o.neighbourhoodFactor * radius;
    const TopologyStats stats = resolveTopology(mesh, collisions, {}, t);
    CHECK(stats.merges == 1);
    CHECK(stats.cuts == 0);
    CHECK(stats.rejected == int(collisions.size()) - 1);
    const auto after = compactAndCheck(mesh);
    CHECK(after.euler == before.euler - 2);
    CHECK(after.components == 1);
    CHECK(after.genus == 0);
}

TEST_CASE("resolveTopology: cuts first, then merges; candidates touched by an earlier edit are skipped")
{
    Mesh torus = makeTorus(Vec3::Zero(), 5.0, 0.6, 16, 3);
    const auto before = topologyOf(torus);
    std::vector<TunnelCandidate> tunnels{{VertexHandle(12), VertexHandle(13), VertexHandle(14)},
                                         {VertexHandle(13), VertexHandle(14), VertexHandle(12)}, // same loop
                                         {VertexHandle(36), VertexHandle(37), VertexHandle(38)}};
    // A merge candidate whose vertex the first cut touched.
    std::vector<CollisionPair> collisions{{VertexHandle(15), VertexHandle(40), 0.1}};
    const TopologyStats stats = resolveTopology(torus, collisions, tunnels);
    CHECK(stats.cuts == 2);
    CHECK(stats.merges == 0);
    CHECK(stats.rejected == 2);
    const auto after = compactAndCheck(torus);
    CHECK(after.euler == before.euler + 4);
    CHECK(after.components == 2); // two cuts across one ring split it in two pieces
}

TEST_CASE("topology: randomized collisions and tunnel cuts keep the mesh valid after every event")
{
    std::mt19937 rng(20030611);
    std::uniform_real_distribution<double> uniform(0.0, 1.0);
    int events = 0, merges = 0, cuts = 0;
    const EuclideanMetric euclidean;
    const ConstantMetric anisotropic(Vec3(1.0, 1.3, 1.6).asDiagonal().toDenseMatrix());
    for (int trial = 0; trial < 60; ++trial) {
        auto makeShape = [&](const Vec3& c) {
            const int kind = int(uniform(rng) * 3);
            if (kind == 0) return makeRegularSphere(c, 2 + int(uniform(rng) * 2), 1.0);
            if (kind == 1) return makeRegularTorus(c, 4.0 + 2 * uniform(rng), 1.2 + uniform(rng), 1.0);
            return makeTorus(c, 4.0 + uniform(rng), 0.55, 20 + int(uniform(rng) * 8), 3);
        };
        Mesh mesh = makeShape(Vec3::Zero());
        OpenMesh::VPropHandleT<int> moving;
        mesh.add_property(moving, "test:moving");
        for (auto v : mesh.vertices()) mesh.property(moving, v) = 0;
        const std::size_t nA = mesh.n_vertices();
        Vec3 dir(uniform(rng) - 0.5, uniform(rng) - 0.5, uniform(rng) - 0.5);
        dir.normalize();
        const Vec3 start = 16.0 * dir + Vec3(uniform(rng) - 0.5, uniform(rng) - 0.5, uniform(rng) - 0.5) * 4.0;
        appendMesh(mesh, makeShape(start));
        for (auto v : mesh.vertices()) mesh.property(moving, v) = std::size_t(v.idx()) >= nA ? 1 : 0;
        const MetricField& metric = trial % 3 == 2 ? static_cast<const MetricField&>(anisotropic) : euclidean;
        CollisionOptions o;
        o.delta = 0.9;
        o.zeta = 2.5;
        o.vmax = 0.45;
        // Approach at vmax per step until the first merge, as the model would; then keep detecting
        // and resolving without motion (the rest of the contact region, random tunnel cuts).
        bool merged = false;
        for (int step = 0, still = 0; step < 80 && still < 10; ++step) {
            if (merged) ++still;
            else
                for (auto v : mesh.vertices())
                    if (mesh.property(moving, v)) mesh.set_point(v, mesh.point(v) - toPoint(o.vmax * dir));
            const auto collisions = findCollisions(mesh, metric, o);
            std::vector<TunnelCandidate> tunnels;
            if (uniform(rng) < 0.15) {
                // A triangle loop of a thin triangular tube, as regularity would report it.
                auto loops = triangleLoops(mesh);
                loops.erase(std::remove_if(loops.begin(), loops.end(),
                                           [&](const TunnelCandidate& t) { return !canCutTunnel(mesh, t.u, t.v, t.w); }),
                            loops.end());
                if (!loops.empty()) tunnels.push_back(loops[std::size_t(uniform(rng) * loops.size()) % loops.size()]);
            }
            if (collisions.empty() && tunnels.empty()) continue;
            const auto before = topologyOf(mesh);
            const TopologyStats stats = resolveTopology(mesh, collisions, tunnels);
            INFO("trial " << trial << " step " << step);
            const auto after = compactAndCheck(mesh);
            CHECK(after.euler == before.euler - 2 * stats.merges + 2 * stats.cuts);
            events += stats.merges + stats.cuts;
            merged = merged || stats.merges > 0;
            merges += stats.merges;
            cuts += stats.cuts;
        }
    }
    MESSAGE("randomized topology events: " << events << " (" << merges << " merges, " << cuts << " cuts)");
    CHECK(merges > 50);
    CHECK(cuts > 10);
}

TEST_CASE("merge: the band never crosses itself or the surface, even between tilted and offset loops")
{
    // Two spheres at random offsets, merged between random nearby vertices whose one-rings face
    // each other at an angle (as when the two ends of a curved tube meet). Zipping from the closest
    // pair of loop vertices alone twisted such bands into crossing faces; merge must either build an
    // embedded band or refuse.
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    int merged = 0, refused = 0;
    for (int trial = 0; trial < 300; ++trial) {
        Mesh mesh = makeIcosphere(Vec3::Zero(), 1.0, 1 + trial % 2);
        const int firstB = int(mesh.n_vertices());
        const Vec3 direction = Vec3(unit(rng), unit(rng), unit(rng)).normalized();
        appendMesh(mesh, makeIcosphere(direction * (2.0 + 0.3 * (unit(rng) + 1)), 1.0, 1 + (trial / 2) % 2));
        prepareMesh(mesh);
        const VertexHandle u = fixtures::extremeVertex(mesh, direction); // on A, facing B (A's extreme)
        std::vector<VertexHandle> near;
        for (int i = firstB; i < int(mesh.n_vertices()); ++i)
            if ((position(mesh, VertexHandle(i)) - position(mesh, u)).norm() < 1.4) near.push_back(VertexHandle(i));
        if (near.empty()) continue;
        const VertexHandle w = near[std::size_t(rng() % near.size())];
        if (merge(mesh, u, w)) {
            ++merged;
            CHECK_MESH_OK(mesh);
            const auto self = findSelfIntersections(mesh);
            INFO("trial " << trial << ": crossings " << self.crossings << ", vertex folds " << self.vertexFolds);
            CHECK(self.count() == 0);
        } else {
            ++refused;
        }
    }
    MESSAGE("tilted merges: " << merged << " merged, " << refused << " refused");
    CHECK(merged > 50);
}

TEST_CASE("componentShapes: a cavity's wall is outward, a component turned inside out or a solid inside a solid is not")
{
    Mesh shell = makeIcosphere(Vec3::Zero(), 5.0, 3);
    appendMesh(shell, turnedOver(makeIcosphere(Vec3(0.5, 0, 0), 2.0, 2))); // the cavity
    appendMesh(shell, makeIcosphere(Vec3(0.5, 0, 0), 1.0, 2));              // a solid in the cavity
    int count = 0;
    auto label = componentLabels(shell, &count);
    REQUIRE(count == 3);
    auto shapes = componentShapes(shell, label, count);
    CHECK(shapes[0].volume > 0);
    CHECK(shapes[0].enclosure == 0);
    CHECK(shapes[1].volume < 0);
    CHECK(shapes[1].enclosure == 1);
    CHECK(shapes[2].volume > 0);
    CHECK(shapes[2].enclosure == 0); // inside the solid (+1) and inside the cavity (-1)
    for (const auto& s : shapes) CHECK(s.outward());
    CHECK_MESH_OK(shell);

    Mesh alone = turnedOver(makeIcosphere(Vec3::Zero(), 2.0, 2)); // inside out, enclosed by nothing
    label = componentLabels(alone, &count);
    shapes = componentShapes(alone, label, count);
    CHECK(shapes[0].enclosure == 0);
    CHECK_FALSE(shapes[0].outward());
    CHECK_FALSE(testing::checkInvariants(alone).ok());

    Mesh nested = makeIcosphere(Vec3::Zero(), 5.0, 3); // a solid inside a solid
    appendMesh(nested, makeIcosphere(Vec3(1, 0, 0), 2.0, 2));
    label = componentLabels(nested, &count);
    shapes = componentShapes(nested, label, count);
    CHECK(shapes[0].outward());
    CHECK(shapes[1].enclosure == 1);
    CHECK_FALSE(shapes[1].outward());
    CHECK(windingNumber(nested, Vec3(1, 0, 0)) == doctest::Approx(2.0).epsilon(1e-9));
    CHECK(windingNumber(nested, Vec3(0, 0, 9)) == doctest::Approx(0.0).scale(1.0).epsilon(1e-9));
}

TEST_CASE("removeSmallComponents: keeps a cavity's wall, deletes specks of either sign and components turned inside out")
{
    Mesh mesh = makeIcosphere(Vec3::Zero(), 6.0, 3);                             // a solid
    appendMesh(mesh, turnedOver(makeIcosphere(Vec3::Zero(), 3.0, 2)));           // its cavity
    appendMesh(mesh, turnedOver(makeIcosphere(Vec3(20, 0, 0), 3.0, 2)));         // inside out, alone
    appendMesh(mesh, makeIcosphere(Vec3(-20, 0, 0), 0.3, 1));                   // a speck
    appendMesh(mesh, turnedOver(makeIcosphere(Vec3(0, 20, 0), 0.3, 1)));         // an inside-out speck
    prepareMesh(mesh);
    REQUIRE(topologyOf(mesh).components == 5);
    const double delta = 1.0;
    CHECK(removeSmallComponents(mesh, 6, 0.5 * delta * delta * delta) == 3);
    mesh.garbage_collection();
    CHECK_MESH_OK(mesh);
    const auto t = topologyOf(mesh);
    CHECK(t.components == 2);
    CHECK(t.genus == 0);
    // What is left is the solid and its cavity: 4/3 pi (6^3 - 3^3) ~ 792 (a bit less on the facets).
    CHECK(signedVolume(mesh) == doctest::Approx(4.0 / 3.0 * M_PI * (216 - 27)).epsilon(0.06));
}
