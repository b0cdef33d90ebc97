// tests/support/mesh_invariants.h: the invariants every mesh operation must keep.
//
// closed (no boundary halfedge), 2-manifold (one fan per vertex, no duplicate edge), oriented
// (consistent winding; every component outward: a solid encloses positive volume, a cavity's inner
// wall negative volume inside a solid), no degenerate face, finite
// positions. Tests call CHECK_MESH_OK(mesh) after each operation.
#pragma once

#include "riemesh/mesh.h"

#include <string>
#include <vector>

namespace riemesh::testing {

struct InvariantReport {
    std::vector<std::string> problems;
    MeshTopology topology;
    bool ok() const { return problems.empty(); }
    std::string text() const;
};

struct InvariantOptions {
    double minFaceArea = 1e-12;        ///< faces with a smaller area (world units^2) are degenerate
    bool requireOutward = true; ///< every component oriented outward (ComponentShape::outward())
};

/// Checks every invariant and returns what is wrong (empty when all hold).
InvariantReport checkInvariants(const Mesh& mesh, const InvariantOptions& options = {});

} // namespace riemesh::testing

#define CHECK_MESH_OK(mesh)                                                                         \
    do {                                                                                            \
        const auto riemesh_report_ = ::riemesh::testing::checkInvariants(mesh);                    \
        INFO(riemesh_report_.text());                                                               \
        CHECK(riemesh_report_.ok());                                                                \
    } while (0)

#define REQUIRE_MESH_OK(mesh)                                                                       \
    do {                                                                                            \
        const auto riemesh_report_ = ::riemesh::testing::checkInvariants(mesh);                    \
        INFO(riemesh_report_.text());                                                               \
        REQUIRE(riemesh_report_.ok());                                                              \
    } while (0)
