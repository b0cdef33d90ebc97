#include "mesh_invariants.h"
#include "riemesh/primitives.h"

#include <doctest/doctest.h>

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
