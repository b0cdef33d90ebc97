// Self-intersection detection (issue 6): exact triangle-triangle tests and the BVH over a mesh.
#include "mesh_invariants.h"
#include "riemesh/primitives.h"
#include "riemesh/self_intersection.h"

#include <doctest/doctest.h>

#include <cmath>
#include <random>
#include <set>

using namespace riemesh;

namespace {

/// A mesh from shared vertex positions and index triples.
Mesh indexed(const std::vector<Vec3>& points, const std::vector<std::array<int, 3>>& faces)
{
    Mesh mesh;
    prepareMesh(mesh);
    std::vector<VertexHandle> v;
    for (const auto& p : points) {
        const Mesh::Point q(p.x(), p.y(), p.z());
        v.push_back(mesh.add_vertex(q));
    }
    for (const auto& f : faces) REQUIRE(mesh.add_face(v[f[0]], v[f[1]], v[f[2]]).is_valid());
    return mesh;
}

/// Brute force over every pair of faces that share no vertex, with the public triangle test.
std::size_t bruteForceCrossings(const Mesh& mesh)
{
    std::vector<std::array<VertexHandle, 3>> faces;
    for (auto f : mesh.faces()) {
        std::array<VertexHandle, 3> t;
        int i = 0;
        for (auto v : mesh.fv_range(f)) t[i++] = v;
        faces.push_back(t);
    }
    std::size_t count = 0;
    for (std::size_t i = 0; i < faces.size(); ++i)
        for (std::size_t j = i + 1; j < faces.size(); ++j) {
            bool shared = false;
            for (auto a : faces[i])
                for (auto b : faces[j]) shared |= a == b;
            if (shared) continue;
            const auto& s = faces[i];
            const auto& t = faces[j];
            count += trianglesIntersect(position(mesh, s[0]), position(mesh, s[1]), position(mesh, s[2]),
                                        position(mesh, t[0]), position(mesh, t[1]), position(mesh, t[2]));
        }
    return count;
}

} // namespace

TEST_CASE("trianglesIntersect: crossing, touching, separated and coplanar configurations")
{
    const Vec3 a(0, 0, 0), b(2, 0, 0), c(0, 2, 0);
    // A vertical triangle piercing the first one.
    CHECK(trianglesIntersect(a, b, c, Vec3(0.5, 0.5, -1), Vec3(0.5, 0.5, 1), Vec3(1.5, -1, 0)));
    // Parallel, just above: no.
    CHECK_FALSE(trianglesIntersect(a, b, c, Vec3(0, 0, 1e-12), Vec3(2, 0, 1e-12), Vec3(0, 2, 1e-12)));
    // A vertex resting on the interior, and on an edge: closed triangles touch.
    CHECK(trianglesIntersect(a, b, c, Vec3(0.5, 0.5, 0), Vec3(0.5, 0.5, 1), Vec3(1, 1, 1)));
    CHECK(trianglesIntersect(a, b, c, Vec3(1, 0, 0), Vec3(1, -1, 1), Vec3(1, 1, 1)));
    // The same just off the surface: no.
    CHECK_FALSE(trianglesIntersect(a, b, c, Vec3(0.5, 0.5, 1e-15), Vec3(0.5, 0.5, 1), Vec3(1, 1, 1)));
    // Coplanar: overlapping, one inside the other, sharing only a boundary point, apart.
    CHECK(trianglesIntersect(a, b, c, Vec3(1, 1, 0), Vec3(-1, 1, 0), Vec3(1, -1, 0)));
    CHECK(trianglesIntersect(a, b, c, Vec3(0.2, 0.2, 0), Vec3(0.5, 0.2, 0), Vec3(0.2, 0.5, 0)));
    CHECK(trianglesIntersect(Vec3(0.2, 0.2, 0), Vec3(0.5, 0.2, 0), Vec3(0.2, 0.5, 0), a, b, c));
    CHECK(trianglesIntersect(a, b, c, Vec3(1, 1, 0), Vec3(2, 2, 0), Vec3(3, 0, 0)));
    CHECK_FALSE(trianglesIntersect(a, b, c, Vec3(1.01, 1.01, 0), Vec3(2, 2, 0), Vec3(3, 0, 0)));
    // An edge lying in the other's plane and crossing it.
    CHECK(trianglesIntersect(a, b, c, Vec3(-1, 0.5, 0), Vec3(3, 0.5, 0), Vec3(1, 0.5, 2)));
    // Degenerate (collinear) triangles are never reported.
    CHECK_FALSE(trianglesIntersect(a, b, c, Vec3(0.5, 0.5, -1), Vec3(0.5, 0.5, 0), Vec3(0.5, 0.5, 1)));
}

TEST_CASE("trianglesIntersect: exact near a tilted plane (answers do not depend on the corner order)")
{
    // Points rounded from a tilted plane lie a few ulps above or below it (or exactly on it). A spike
    // rising from such a point touches the triangle iff the point is on or below the plane. With
    // floating-point determinants the answer depends on which corner the differences are taken from
    // (in ~85% of these samples the three cyclic orders disagree); exact predicates agree always.
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const Vec3 a(0.1, 0.2, 0.3), b(1.7, 0.35, 0.9), c(0.45, 1.9, -0.7);
    const Vec3 n = (b - a).cross(c - a).normalized();
    const Vec3 t = (b - a).normalized();
    int above = 0, below = 0;
    for (int i = 0; i < 2000; ++i) {
        double u = unit(rng), v = unit(rng);
        if (u + v > 1) { u = 1 - u; v = 1 - v; }
        const Vec3 p = a + u * (b - a) + v * (c - a);
        const Vec3 up0 = p + n + 0.1 * t, up1 = p + n - 0.1 * t;
        const Vec3 down0 = p - n + 0.1 * t, down1 = p - n - 0.1 * t;
        const bool up = trianglesIntersect(a, b, c, p, up0, up1);
        const bool down = trianglesIntersect(a, b, c, p, down0, down1);
        INFO("sample " << i << " u " << u << " v " << v);
        CHECK((up || down)); // the point is on one side or on the plane
        CHECK(trianglesIntersect(b, c, a, p, up0, up1) == up);
        CHECK(trianglesIntersect(c, a, b, up1, p, up0) == up);
        CHECK(trianglesIntersect(p, up0, up1, c, b, a) == up);
        CHECK(trianglesIntersect(c, a, b, down0, down1, p) == down);
        above += !up;
        below += !down;
    }
    MESSAGE("points above the plane: " << above << ", below: " << below << " of 2000");
    CHECK(above > 100);
    CHECK(below > 100);
}

TEST_CASE("self-intersection: icosphere, torus and a flat-faced box have none")
{
    for (int s = 0; s <= 4; ++s) {
        const auto stats = findSelfIntersections(makeIcosphere(Vec3(0.3, -1, 2), 5.0, s));
        CHECK(stats.count() == 0);
        CHECK(stats.degenerateFaces == 0);
    }
    CHECK(findSelfIntersections(makeTorus(Vec3::Zero(), 3, 1, 48, 16)).count() == 0);
    CHECK(findSelfIntersections(makeTorus(Vec3::Zero(), 3, 2.9, 64, 24)).count() == 0);
    // Exactly coplanar neighbours everywhere: only exact predicates keep these at zero.
    const Mesh box = makeBox(Vec3(-1.1, -0.7, 0.3), Vec3(2.3, 1.9, 1.7), 0.1);
    const auto stats = findSelfIntersections(box);
    INFO("tested " << stats.testedPairs);
    CHECK(stats.count() == 0);
    CHECK(stats.testedPairs > box.n_faces());
}

TEST_CASE("self-intersection: two overlapping spheres in one mesh cross along their common circle")
{
    // Unit spheres 1 apart meet in a circle of radius sqrt(3)/2 (length ~5.44). At 3 subdivisions
    // (edges ~0.15) the circle passes through ~5.44/0.15 ~ 36-72 faces of each sphere, and each
    // such face crosses one to a few faces of the other.
    Mesh mesh = makeIcosphere(Vec3::Zero(), 1.0, 3);
    const int firstB = int(mesh.n_faces());
    appendMesh(mesh, makeIcosphere(Vec3(1, 0, 0), 1.0, 3));
    SelfIntersectionOptions o;
    o.collectPairs = true;
    const auto stats = findSelfIntersections(mesh, o);
    INFO("crossings " << stats.crossings << " vertex folds " << stats.vertexFolds << " edge folds " << stats.edgeFolds);
    CHECK(stats.vertexFolds == 0);
    CHECK(stats.edgeFolds == 0);
    CHECK(stats.crossings >= 36);
    // Native builds find ~246 pairs (82 faces of each sphere), the WebAssembly build ~350 (90 faces):
    // an unexplained platform difference, open in the issue notes; both within this bound.
    CHECK(stats.crossings <= 400);
    REQUIRE(stats.pairs.size() == stats.crossings);
    std::set<int> facesA, facesB;
    for (const auto& [f, g] : stats.pairs) {
        // One face from each sphere, both near the plane x = 0.5 of the circle.
        CHECK(f.idx() < firstB);
        CHECK(g.idx() >= firstB);
        for (const FaceHandle h : {f, g}) {
            Vec3 centroid = Vec3::Zero();
            for (auto v : mesh.fv_range(h)) centroid += position(mesh, v) / 3;
            CHECK(std::abs(centroid.x() - 0.5) < 0.2);
        }
        facesA.insert(f.idx());
        facesB.insert(g.idx());
    }
    MESSAGE("crossing pairs " << stats.crossings << ", faces of A " << facesA.size() << ", of B " << facesB.size());
    CHECK(facesA.size() >= 36);
    CHECK(facesB.size() >= 36);
    CHECK(bruteForceCrossings(mesh) == stats.crossings);
}

TEST_CASE("self-intersection: the BVH finds exactly the crossings of a brute-force search (noisy spheres)")
{
    std::mt19937 rng(11);
    std::normal_distribution<double> noise(0.0, 0.08);
    for (int trial = 0; trial < 4; ++trial) {
        Mesh mesh = makeIcosphere(Vec3::Zero(), 1.0, 2);
        appendMesh(mesh, makeIcosphere(Vec3(0.9 + 0.2 * trial, 0.1, 0), 0.8, 2));
        for (auto v : mesh.vertices()) mesh.point(v) += OpenMesh::Vec3d(noise(rng), noise(rng), noise(rng));
        const auto stats = findSelfIntersections(mesh);
        INFO("trial " << trial << " crossings " << stats.crossings);
        CHECK(stats.crossings > 0);
        CHECK(stats.crossings == bruteForceCrossings(mesh));
        SelfIntersectionOptions leaves;
        leaves.leafSize = 1;
        CHECK(findSelfIntersections(mesh, leaves).crossings == stats.crossings);
    }
}

TEST_CASE("self-intersection: faces sharing one vertex fold when their interiors cross")
{
    const Vec3 s(0, 0, 0);
    // T1 in z = 0; T2 stands on s and cuts T1 along the segment s-(1, 0.5, 0): a fold.
    const Mesh fold = indexed({s, Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(1, 0.5, -0.5), Vec3(1, 0.5, 0.5)},
                              {{0, 1, 2}, {0, 3, 4}});
    auto stats = findSelfIntersections(fold);
    CHECK(stats.vertexFolds == 1);
    CHECK(stats.count() == 1);
    // The same beside T1 (cut segment outside it): only s in common.
    const Mesh apart = indexed({s, Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(1, -0.5, -0.5), Vec3(1, -0.5, 0.5)},
                               {{0, 1, 2}, {0, 3, 4}});
    CHECK(findSelfIntersections(apart).count() == 0);
    // Coplanar corners at s: overlapping (a fold), and side by side as in a flat fan (none).
    const Mesh flatFold = indexed({s, Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(1, 1, 0), Vec3(-1, 2, 0)},
                                  {{0, 1, 2}, {0, 3, 4}});
    CHECK(findSelfIntersections(flatFold).vertexFolds == 1);
    const Mesh flatFan = indexed({s, Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(-1, 1, 0), Vec3(-1, -0.1, 0)},
                                 {{0, 1, 2}, {0, 3, 4}});
    CHECK(findSelfIntersections(flatFan).count() == 0);
    // An edge from s lying inside the other triangle (in its plane): a fold along that edge.
    const Mesh alongEdge = indexed({s, Vec3(1, 0.5, 0), Vec3(1, 0.5, 1), Vec3(1, 0, 0), Vec3(1, 1, 0)},
                                   {{0, 1, 2}, {0, 3, 4}});
    CHECK(findSelfIntersections(alongEdge).vertexFolds == 1);
}

TEST_CASE("self-intersection: faces sharing an edge count only when folded flat onto each other")
{
    const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
    // (a, b, c) and (b, a, d): d on c's side of a-b, exactly in the plane: folded flat.
    CHECK(findSelfIntersections(indexed({a, b, c, Vec3(0.5, 0.5, 0)}, {{0, 1, 2}, {1, 0, 3}})).edgeFolds == 1);
    // A sharp crease (d slightly above the plane) meets the first face only along the edge.
    CHECK(findSelfIntersections(indexed({a, b, c, Vec3(0.5, 0.5, 1e-9)}, {{0, 1, 2}, {1, 0, 3}})).count() == 0);
    // Flat and unfolded (d on the other side): an ordinary flat pair.
    CHECK(findSelfIntersections(indexed({a, b, c, Vec3(0.5, -0.5, 0)}, {{0, 1, 2}, {1, 0, 3}})).count() == 0);
}

TEST_CASE("self-intersection: one vertex pushed through the surface is detected")
{
    const Mesh sphere = makeIcosphere(Vec3::Zero(), 1.0, 3);
    REQUIRE(findSelfIntersections(sphere).count() == 0);
    const VertexHandle v(0);
    {
        // Through the far side: the vertex's fan crosses the faces around the antipode.
        Mesh mesh = sphere;
        mesh.set_point(v, -1.2 * mesh.point(v));
        const auto stats = findSelfIntersections(mesh);
        INFO("crossings " << stats.crossings << " vertex folds " << stats.vertexFolds);
        CHECK(stats.crossings > 0);
    }
    {
        // A dent (pushed inward past its one-ring, not through anything) is still embedded.
        Mesh mesh = sphere;
        mesh.set_point(v, 0.8 * mesh.point(v));
        CHECK(findSelfIntersections(mesh).count() == 0);
    }
    {
        // Pushed sideways over a neighbour: its fan folds over the neighbour's faces.
        Mesh mesh = sphere;
        const VertexHandle w = *mesh.vv_begin(v);
        const Vec3 over = position(mesh, w) + 0.6 * (position(mesh, w) - position(mesh, v));
        mesh.set_point(v, toPoint(over.normalized()));
        const auto stats = findSelfIntersections(mesh);
        INFO("crossings " << stats.crossings << " vertex folds " << stats.vertexFolds << " edge folds " << stats.edgeFolds);
        CHECK(stats.count() > 0);
        CHECK(stats.vertexFolds > 0);
    }
}

TEST_CASE("self-intersection: a 80k-face sphere and a fine torus are embedded")
{
    const Mesh sphere = makeIcosphere(Vec3(1, 2, 3), 10.0, 6);
    REQUIRE(sphere.n_faces() == 81920u);
    const auto stats = findSelfIntersections(sphere);
    CHECK(stats.count() == 0);
    CHECK(stats.testedPairs >= sphere.n_faces() * 6); // each face's 12 vertex neighbours, each pair once
    CHECK(findSelfIntersections(makeTorus(Vec3::Zero(), 5, 1, 400, 80)).count() == 0);
}

TEST_CASE("self-intersections: an empty mesh (a model that vanished) has none")
{
    Mesh mesh;
    prepareMesh(mesh);
    SelfIntersectionOptions options;
    options.collectPairs = true;
    const auto stats = findSelfIntersections(mesh, options);
    CHECK(stats.count() == 0);
    CHECK(stats.testedPairs == 0);
    CHECK(stats.pairs.empty());
}
