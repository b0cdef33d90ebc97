// Edge operations: every split, collapse and flip keeps the mesh closed, oriented and manifold and
// leaves the Euler characteristic unchanged; the guards refuse the collapses and flips that would
// not (tetrahedra, valence-3 traps, tunnels).
#include "mesh_invariants.h"
#include "riemesh/edge_ops.h"
#include "riemesh/primitives.h"

#include <doctest/doctest.h>

#include <array>
#include <cmath>
#include <random>
#include <vector>

using namespace riemesh;

namespace {

Vec3 midpoint(const Mesh& mesh, EdgeHandle e)
{
    const auto h = mesh.halfedge_handle(e, 0);
    return 0.5 * (position(mesh, mesh.from_vertex_handle(h)) + position(mesh, mesh.to_vertex_handle(h)));
}

/// A mesh from explicit vertices and counter-clockwise (seen from outside) triangles.
Mesh meshFrom(const std::vector<Vec3>& points, const std::vector<std::array<int, 3>>& triangles)
{
    Mesh mesh;
    prepareMesh(mesh);
    std::vector<VertexHandle> vh;
    for (const auto& p : points) vh.push_back(mesh.add_vertex(toPoint(p)));
    for (const auto& t : triangles) mesh.add_face(vh[t[0]], vh[t[1]], vh[t[2]]);
    return mesh;
}

Mesh makeTetrahedron()
{
    return meshFrom({{1, 1, 1}, {1, -1, -1}, {-1, 1, -1}, {-1, -1, 1}}, {{0, 1, 2}, {0, 3, 1}, {0, 2, 3}, {1, 3, 2}});
}

/// Two apexes (valence 3) over an equilateral triangle (valence 4).
Mesh makeTriangularBipyramid()
{
    const double s = std::sqrt(3.0) / 2.0;
    return meshFrom({{1, 0, 0}, {-0.5, s, 0}, {-0.5, -s, 0}, {0, 0, 1.5}, {0, 0, -1.5}},
                    {{0, 1, 3}, {1, 2, 3}, {2, 0, 3}, {1, 0, 4}, {2, 1, 4}, {0, 2, 4}});
}

std::vector<EdgeHandle> liveEdges(const Mesh& mesh)
{
    std::vector<EdgeHandle> edges;
    for (auto e : mesh.edges()) edges.push_back(e);
    return edges;
}

std::array<int, 3> cornersOf(const Mesh& mesh, FaceHandle f)
{
    const auto v = faceVertices(mesh, f);
    return {v[0].idx(), v[1].idx(), v[2].idx()};
}

std::array<int, 2> endsOf(const Mesh& mesh, EdgeHandle e)
{
    const auto h = mesh.halfedge_handle(e, 0);
    return {mesh.from_vertex_handle(h).idx(), mesh.to_vertex_handle(h).idx()};
}

/// Random splits, collapses (toward the midpoint) and flips with the invariants checked after each.
/// The edit marks (kEditedProperty) are checked too: every face or edge that is new or whose
/// corners changed since the start has a marked corner (what SafeStepCache relies on).
void runRandomEdits(Mesh& mesh, unsigned seed, int steps)
{
    const int euler = topologyOf(mesh).euler;
    OpenMesh::VPropHandleT<char> edited;
    mesh.add_property(edited, kEditedProperty);
    for (auto v : mesh.all_vertices()) mesh.property(edited, v) = 0;
    std::vector<std::array<int, 3>> faces0;
    for (auto f : mesh.all_faces()) faces0.push_back(cornersOf(mesh, f));
    std::vector<std::array<int, 2>> edges0;
    for (auto e : mesh.all_edges()) edges0.push_back(endsOf(mesh, e));
    auto marked = [&](const auto& corners) {
        for (int v : corners)
            if (mesh.property(edited, VertexHandle(v))) return true;
        return false;
    };
    auto checkMarks = [&] {
        for (auto f : mesh.faces()) {
            const auto t = cornersOf(mesh, f);
            if (std::size_t(f.idx()) >= faces0.size() || t != faces0[std::size_t(f.idx())]) REQUIRE(marked(t));
        }
        for (auto e : mesh.edges()) {
            const auto x = endsOf(mesh, e);
            if (std::size_t(e.idx()) >= edges0.size() || x != edges0[std::size_t(e.idx())]) REQUIRE(marked(x));
        }
    };
    std::mt19937 rng(seed);
    int done[3] = {0, 0, 0};
    for (int step = 0; step < steps; ++step) {
        const auto edges = liveEdges(mesh);
        const EdgeHandle e = edges[std::uniform_int_distribution<std::size_t>(0, edges.size() - 1)(rng)];
        const int op = std::uniform_int_distribution<int>(0, 2)(rng);
        CAPTURE(step);
        CAPTURE(op);
        if (op == 0 && canSplit(mesh, e)) {
            REQUIRE(split(mesh, e, midpoint(mesh, e)).is_valid());
            ++done[0];
        } else if (op == 1) {
            const auto h = mesh.halfedge_handle(e, std::uniform_int_distribution<int>(0, 1)(rng));
            const Vec3 target = midpoint(mesh, e);
            if (!canCollapse(mesh, h, target)) continue;
            REQUIRE(collapse(mesh, h, target).is_valid());
            ++done[1];
        } else if (op == 2 && canFlip(mesh, e)) {
            flip(mesh, e);
            ++done[2];
        } else {
            continue;
        }
        REQUIRE_MESH_OK(mesh);
        REQUIRE(topologyOf(mesh).euler == euler);
        checkMarks();
    }
    // The sequence exercised every operation.
    CHECK(done[0] > steps / 10);
    CHECK(done[1] > steps / 10);
    CHECK(done[2] > steps / 10);
}

} // namespace

TEST_CASE("edge_ops: split adds one vertex, keeps the mesh valid and averages the velocity")
{
    Mesh mesh = makeIcosphere(Vec3::Zero(), 1.0, 2);
    const auto velocity = velocityProperty(mesh);
    const auto before = topologyOf(mesh);
    const EdgeHandle e = *mesh.edges().begin();
    const auto h = mesh.halfedge_handle(e, 0);
    const VertexHandle u = mesh.from_vertex_handle(h), v = mesh.to_vertex_handle(h);
    mesh.property(velocity, u) = OpenMesh::Vec3d(1, 0, 0);
    mesh.property(velocity, v) = OpenMesh::Vec3d(0, 2, 0);
    REQUIRE(canSplit(mesh, e));
    const Vec3 mid = midpoint(mesh, e);
    const VertexHandle w = split(mesh, e, mid);
    REQUIRE(w.is_valid());
    CHECK_MESH_OK(mesh);
    const auto after = topologyOf(mesh);
    CHECK(after.euler == before.euler);
    CHECK(after.vertices == before.vertices + 1);
    CHECK(after.edges == before.edges + 3);
    CHECK(after.faces == before.faces + 2);
    CHECK(mesh.valence(w) == 4u);
    CHECK((position(mesh, w) - mid).norm() == doctest::Approx(0.0));
    CHECK((mesh.property(velocity, w) - OpenMesh::Vec3d(0.5, 1, 0)).norm() == doctest::Approx(0.0));
}

TEST_CASE("edge_ops: collapse removes one vertex, keeps to_vertex at the target and averages the velocity")
{
    Mesh mesh = makeIcosphere(Vec3::Zero(), 1.0, 2);
    const auto velocity = velocityProperty(mesh);
    const auto before = topologyOf(mesh);
    const std::size_t allVertices = mesh.n_vertices();
    const EdgeHandle e = *mesh.edges().begin();
    const auto h = mesh.halfedge_handle(e, 0);
    const VertexHandle u = mesh.from_vertex_handle(h), v = mesh.to_vertex_handle(h);
    mesh.property(velocity, u) = OpenMesh::Vec3d(2, 0, 0);
    mesh.property(velocity, v) = OpenMesh::Vec3d(0, 0, 4);
    const Vec3 mid = midpoint(mesh, e);
    REQUIRE(canCollapse(mesh, h, mid));
    CHECK_FALSE(sharedOutsideNeighbour(mesh, h).is_valid());
    const VertexHandle kept = collapse(mesh, h, mid);
    CHECK(kept == v);
    CHECK(mesh.status(u).deleted());
    CHECK_MESH_OK(mesh);
    const auto after = topologyOf(mesh);
    CHECK(after.euler == before.euler);
    CHECK(after.vertices == before.vertices - 1);
    CHECK(after.faces == before.faces - 2);
    CHECK((position(mesh, kept) - mid).norm() == doctest::Approx(0.0));
    CHECK((mesh.property(velocity, kept) - OpenMesh::Vec3d(1, 0, 2)).norm() == doctest::Approx(0.0));
    // No compaction: handles taken before the collapse still index the same elements.
    CHECK(mesh.n_vertices() == allVertices);
}

TEST_CASE("edge_ops: flip joins the two opposite vertices and keeps the mesh valid")
{
    Mesh mesh = makeIcosphere(Vec3::Zero(), 1.0, 2);
    const auto before = topologyOf(mesh);
    int flipped = 0;
    for (auto e : liveEdges(mesh)) {
        if (!canFlip(mesh, e)) continue;
        const auto h = mesh.halfedge_handle(e, 0), o = mesh.halfedge_handle(e, 1);
        const VertexHandle a = mesh.to_vertex_handle(mesh.next_halfedge_handle(h));
        const VertexHandle b = mesh.to_vertex_handle(mesh.next_halfedge_handle(o));
        flip(mesh, e);
        const auto nh = mesh.halfedge_handle(e, 0);
        const VertexHandle x = mesh.from_vertex_handle(nh), y = mesh.to_vertex_handle(nh);
        CHECK(((x == a && y == b) || (x == b && y == a)));
        REQUIRE_MESH_OK(mesh);
        CHECK(topologyOf(mesh).euler == before.euler);
        if (++flipped == 20) break;
    }
    CHECK(flipped == 20);
    CHECK(topologyOf(mesh).vertices == before.vertices);
}

TEST_CASE("edge_ops: collapse and flip are refused on a tetrahedron")
{
    Mesh tet = makeTetrahedron();
    REQUIRE_MESH_OK(tet);
    for (auto e : tet.edges()) {
        for (int side = 0; side < 2; ++side) {
            const auto h = tet.halfedge_handle(e, side);
            CHECK_FALSE(canCollapse(tet, h, midpoint(tet, e)));
            CHECK_FALSE(collapse(tet, h, midpoint(tet, e)).is_valid());
        }
        CHECK_FALSE(canFlip(tet, e)); // the new edge exists already
        CHECK(canSplit(tet, e));
    }
    CHECK_MESH_OK(tet);
    CHECK(topologyOf(tet).vertices == 4u);
}

TEST_CASE("edge_ops: collapse is refused when a vertex opposite the edge has valence 3")
{
    Mesh mesh = makeTriangularBipyramid();
    REQUIRE_MESH_OK(mesh);
    int equatorEdges = 0, apexEdges = 0;
    for (auto e : mesh.edges()) {
        const auto h = mesh.halfedge_handle(e, 0);
        const bool equator = mesh.valence(mesh.from_vertex_handle(h)) == 4 && mesh.valence(mesh.to_vertex_handle(h)) == 4;
        if (equator) {
            // Both opposite vertices are apexes of valence 3: they would drop to valence 2.
            ++equatorEdges;
            CHECK_FALSE(canCollapse(mesh, h, midpoint(mesh, e)));
            CHECK_FALSE(canCollapse(mesh, mesh.opposite_halfedge_handle(h), midpoint(mesh, e)));
        } else {
            ++apexEdges;
        }
    }
    CHECK(equatorEdges == 3);
    CHECK(apexEdges == 6);
    // An apex edge may collapse: the bipyramid becomes a tetrahedron.
    for (auto e : mesh.edges()) {
        const auto h = mesh.halfedge_handle(e, 0);
        if (mesh.valence(mesh.from_vertex_handle(h)) != 3) continue;
        const Vec3 target = position(mesh, mesh.to_vertex_handle(h));
        REQUIRE(canCollapse(mesh, h, target));
        collapse(mesh, h, target);
        break;
    }
    CHECK_MESH_OK(mesh);
    CHECK(topologyOf(mesh).vertices == 4u);
    CHECK(topologyOf(mesh).euler == 2);
}

TEST_CASE("edge_ops: a collapse across a thin tunnel is refused and reports the shared neighbour")
{
    // A tube of 3 segments: every cross-section is a triangle loop that bounds no face.
    const int major = 12, minor = 3;
    Mesh torus = makeTorus(Vec3::Zero(), 4.0, 0.3, major, minor);
    REQUIRE_MESH_OK(torus);
    // Vertex (i, j) was added as index i * minor + j.
    auto ring = [&](VertexHandle x) { return x.idx() / minor; };
    int tunnelEdges = 0, otherEdges = 0;
    for (auto e : torus.edges()) {
        const auto h = torus.halfedge_handle(e, 0);
        const VertexHandle u = torus.from_vertex_handle(h), v = torus.to_vertex_handle(h);
        const VertexHandle w = sharedOutsideNeighbour(torus, h);
        if (ring(u) == ring(v)) {
            ++tunnelEdges;
            REQUIRE(w.is_valid());
            CHECK(ring(w) == ring(u));
            CHECK(w != u);
            CHECK(w != v);
            CHECK(sharedOutsideNeighbour(torus, torus.opposite_halfedge_handle(h)) == w);
            CHECK_FALSE(canCollapse(torus, h, midpoint(torus, e)));
            CHECK_FALSE(canCollapse(torus, torus.opposite_halfedge_handle(h), position(torus, u)));
        } else {
            ++otherEdges;
            CHECK_FALSE(w.is_valid());
        }
    }
    CHECK(tunnelEdges == major * minor);
    CHECK(otherEdges == 2 * major * minor);
}

TEST_CASE("edge_ops: collapse is refused when a surviving face would flip")
{
    Mesh mesh = makeIcosphere(Vec3::Zero(), 1.0, 2);
    const EdgeHandle e = *mesh.edges().begin();
    const auto h = mesh.halfedge_handle(e, 0);
    const Vec3 u = position(mesh, mesh.from_vertex_handle(h)), v = position(mesh, mesh.to_vertex_handle(h));
    // Far past v along the edge: the faces around v on the far side fold over.
    const Vec3 beyond = v + 3.0 * (v - u);
    CHECK_FALSE(canCollapse(mesh, h, beyond));
    // Deep inside the sphere: the faces around the kept vertex turn inside out.
    CHECK_FALSE(canCollapse(mesh, h, Vec3::Zero()));
    CHECK(canCollapse(mesh, h, 0.5 * (u + v)));
}

TEST_CASE("edge_ops: random splits, collapses and flips on an icosphere keep every invariant")
{
    Mesh mesh = makeIcosphere(Vec3(0.5, -1, 2), 3.0, 2);
    runRandomEdits(mesh, 12345u, 400);
}

TEST_CASE("edge_ops: random splits, collapses and flips on a torus keep every invariant")
{
    Mesh mesh = makeTorus(Vec3::Zero(), 5.0, 2.0, 20, 10);
    runRandomEdits(mesh, 777u, 400);
    CHECK(topologyOf(mesh).genus == 1);
}

TEST_CASE("edge_ops: random edits on a box keep every invariant")
{
    Mesh mesh = makeBox(Vec3(0, 0, 0), Vec3(3, 2, 1), 0.5);
    runRandomEdits(mesh, 4242u, 300);
}
