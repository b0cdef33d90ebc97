#include "mesh_invariants.h"
#include "riemesh/edge_ops.h"
#include "riemesh/evolution.h"
#include "riemesh/primitives.h"

#include <doctest/doctest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

using namespace riemesh;

TEST_CASE("primitives: box is closed, oriented and genus 0")
{
    Mesh box = makeBox(Vec3(0, 0, 0), Vec3(4, 3, 2), 1.0);
    REQUIRE_MESH_OK(box);
    const auto t = topologyOf(box);
    CHECK(t.euler == 2);
    CHECK(t.components == 1);
    CHECK(signedVolume(box) == doctest::Approx(24.0));
}

TEST_CASE("primitives: icosphere is closed, oriented and genus 0")
{
    Mesh sphere = makeIcosphere(Vec3(1, 2, 3), 5.0, 3);
    REQUIRE_MESH_OK(sphere);
    CHECK(topologyOf(sphere).euler == 2);
    CHECK(sphere.n_faces() == 20u * 64u);
    CHECK(signedVolume(sphere) == doctest::Approx(4.0 / 3.0 * M_PI * 125.0).epsilon(0.02));
}

TEST_CASE("primitives: torus has genus 1")
{
    Mesh torus = makeTorus(Vec3::Zero(), 5.0, 2.0, 24, 12);
    REQUIRE_MESH_OK(torus);
    const auto t = topologyOf(torus);
    CHECK(t.euler == 0);
    CHECK(t.genus == 1);
    CHECK(signedVolume(torus) > 0);
}

TEST_CASE("mesh: appending a second sphere adds a component")
{
    Mesh a = makeIcosphere(Vec3::Zero(), 1.0, 2);
    appendMesh(a, makeIcosphere(Vec3(5, 0, 0), 1.0, 2));
    REQUIRE_MESH_OK(a);
    CHECK(topologyOf(a).components == 2);
    CHECK(topologyOf(a).euler == 4);
}

TEST_CASE("invariants: a mesh with a hole is reported as not closed")
{
    Mesh sphere = makeIcosphere(Vec3::Zero(), 1.0, 1);
    sphere.delete_face(*sphere.faces().begin(), false);
    sphere.garbage_collection();
    CHECK_FALSE(testing::checkInvariants(sphere).ok());
}

TEST_CASE("invariants: an inside-out sphere is reported as not oriented outward")
{
    Mesh sphere = makeIcosphere(Vec3::Zero(), 1.0, 1);
    Mesh flipped;
    prepareMesh(flipped);
    std::vector<VertexHandle> vh;
    for (auto v : sphere.vertices()) vh.push_back(flipped.add_vertex(sphere.point(v)));
    for (auto f : sphere.faces()) {
        std::vector<VertexHandle> face;
        for (auto v : sphere.fv_range(f)) face.push_back(vh[v.idx()]);
        std::reverse(face.begin(), face.end());
        flipped.add_face(face);
    }
    CHECK_FALSE(testing::checkInvariants(flipped).ok());
}

namespace {

/// Median |index(u) - index(v)| over the edges: how far apart in memory neighbours are.
int medianEdgeGap(const Mesh& mesh)
{
    std::vector<int> gaps;
    for (auto e : mesh.edges()) {
        const auto h = mesh.halfedge_handle(e, 0);
        gaps.push_back(std::abs(mesh.from_vertex_handle(h).idx() - mesh.to_vertex_handle(h).idx()));
    }
    std::nth_element(gaps.begin(), gaps.begin() + std::ptrdiff_t(gaps.size() / 2), gaps.end());
    return gaps[gaps.size() / 2];
}

/// The faces as lists of positions, each from its smallest point on (same winding), sorted: the
/// surface whatever the numbering.
std::vector<std::array<double, 9>> surfaceOf(const Mesh& mesh)
{
    std::vector<std::array<double, 9>> faces;
    for (auto f : mesh.faces()) {
        std::array<Mesh::Point, 3> p;
        int k = 0;
        for (auto v : mesh.fv_range(f)) p[std::size_t(k++)] = mesh.point(v);
        std::rotate(p.begin(), std::min_element(p.begin(), p.end()), p.end());
        std::array<double, 9> t{};
        for (int i = 0; i < 9; ++i) t[std::size_t(i)] = p[std::size_t(i / 3)][i % 3];
        faces.push_back(t);
    }
    std::sort(faces.begin(), faces.end());
    return faces;
}

} // namespace

TEST_CASE("mesh: renumbering for locality keeps the surface, its topology and the vertex properties")
{
    Mesh mesh = makeIcosphere(Vec3::Zero(), 10.0, 5); // subdivision appends midpoints: neighbours far apart
    appendMesh(mesh, makeTorus(Vec3(30, 0, 0), 6.0, 2.0, 48, 16));
    prepareMesh(mesh);
    // Deleted elements not yet compacted, as after a collapse in an iteration.
    const HalfedgeHandle h = mesh.halfedge_handle(EdgeHandle(7), 0);
    REQUIRE(collapse(mesh, h, position(mesh, mesh.to_vertex_handle(h))).is_valid());
    REQUIRE(mesh.n_vertices() > topologyOf(mesh).vertices);
    // Custom vertex properties, as an evolving mesh has.
    const auto velocity = velocityProperty(mesh);
    OpenMesh::VPropHandleT<int> tag;
    mesh.add_property(tag, "test:tag");
    for (auto v : mesh.vertices()) {
        mesh.property(velocity, v) = mesh.point(v) * 0.5;
        mesh.property(tag, v) = int(std::lround(mesh.point(v)[0] * 1000));
    }
    const auto before = topologyOf(mesh);
    const auto surface = surfaceOf(mesh);
    const double volume = signedVolume(mesh);
    const int gapBefore = medianEdgeGap(mesh);

    reorderForLocality(mesh);

    REQUIRE_MESH_OK(mesh);
    const auto after = topologyOf(mesh);
    CHECK(after.vertices == before.vertices);
    CHECK(after.edges == before.edges);
    CHECK(after.faces == before.faces);
    CHECK(after.components == before.components);
    CHECK(after.genus == before.genus);
    CHECK(mesh.n_vertices() == before.vertices); // compacted
    CHECK(signedVolume(mesh) == doctest::Approx(volume).epsilon(1e-12));
    CHECK(surfaceOf(mesh) == surface);
    int wrong = 0;
    for (auto v : mesh.vertices()) {
        wrong += mesh.property(velocity, v) != mesh.point(v) * 0.5;
        wrong += mesh.property(tag, v) != int(std::lround(mesh.point(v)[0] * 1000));
    }
    CHECK(wrong == 0);
    const int gapAfter = medianEdgeGap(mesh);
    MESSAGE("median index gap between edge endpoints: " << gapBefore << " -> " << gapAfter);
    CHECK(gapAfter * 4 < gapBefore);
}

TEST_CASE("evolution: a large mesh is renumbered for locality at the first step, unless told not to; each step's phases add up to its time")
{
    // A 40,962-vertex icosphere (over the 16k-vertex threshold) at rest on a ball's contour.
    const double radius = 30;
    const FunctionImage image([&](const Vec3& x) { return 0.5 + 0.5 * std::tanh(radius - x.norm()); },
                              Box3(Vec3::Constant(-40), Vec3::Constant(40)), 1.0);
    EuclideanMetric metric;
    int gaps[2];
    for (const bool renumber : {true, false}) {
        Mesh mesh = makeIcosphere(Vec3::Zero(), radius, 6);
        REQUIRE(mesh.n_vertices() > 16384u);
        EvolutionOptions o;
        o.delta = 0.45;
        o.renumber = renumber;
        Evolution evolution(mesh, image, metric, o);
        const IterationStats it = evolution.step();
        REQUIRE_MESH_OK(mesh);
        gaps[renumber ? 0 : 1] = medianEdgeGap(mesh);
        const auto& p = it.phases;
        CHECK(p.forces >= 0);
        CHECK(p.integration >= 0);
        CHECK(p.regularity >= 0);
        CHECK(p.collisions >= 0);
        CHECK(p.topology >= 0);
        CHECK(p.forces + p.integration + p.regularity + p.collisions + p.topology ==
              doctest::Approx(it.milliseconds).epsilon(1e-9));
        CHECK(it.milliseconds > 0);
    }
    MESSAGE("median index gap between edge endpoints after one step: " << gaps[0] << " renumbered, " << gaps[1]
                                                                      << " as is");
    CHECK(gaps[0] * 4 < gaps[1]);
}
