#include "mesh_invariants.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <sstream>
#include <utility>

namespace riemesh::testing {

std::string InvariantReport::text() const
{
    std::ostringstream out;
    out << "V=" << topology.vertices << " E=" << topology.edges << " F=" << topology.faces
        << " components=" << topology.components << " euler=" << topology.euler << " genus=" << topology.genus;
    for (const auto& p : problems) out << "\n  - " << p;
    return out.str();
}

InvariantReport checkInvariants(const Mesh& mesh, const InvariantOptions& options)
{
    InvariantReport report;
    auto problem = [&](const std::string& s) {
        if (report.problems.size() < 20) report.problems.push_back(s);
        else if (report.problems.size() == 20) report.problems.push_back("... (more problems)");
    };
    report.topology = topologyOf(mesh);
    if (report.topology.faces == 0) problem("mesh has no faces");

    // Closed: every non-deleted halfedge has a face; every face is a triangle.
    for (auto h : mesh.halfedges())
        if (mesh.is_boundary(h)) { problem("boundary halfedge " + std::to_string(h.idx())); break; }
    for (auto f : mesh.faces())
        if (mesh.valence(f) != 3) problem("face " + std::to_string(f.idx()) + " is not a triangle");

    // Manifold vertices: the faces around v reached through one fan must be all faces at v, and
    // the number of outgoing halfedges with a face must equal the fan size. Also no isolated vertex.
    for (auto v : mesh.vertices()) {
        if (mesh.is_isolated(v)) { problem("isolated vertex " + std::to_string(v.idx())); continue; }
        std::size_t fan = 0, outgoing = 0;
        for (auto f : mesh.vf_range(v)) { (void)f; ++fan; }
        for (auto h : mesh.voh_range(v)) { (void)h; ++outgoing; }
        // On a closed manifold every outgoing halfedge has a face: the fan has one face per spoke.
        if (fan != outgoing) problem("vertex " + std::to_string(v.idx()) + " fan size differs from valence");
        if (outgoing < 3) problem("vertex " + std::to_string(v.idx()) + " has valence " + std::to_string(outgoing));
        if (!std::isfinite(mesh.point(v)[0]) || !std::isfinite(mesh.point(v)[1]) || !std::isfinite(mesh.point(v)[2]))
            problem("vertex " + std::to_string(v.idx()) + " has a non-finite position");
    }
    // A non-manifold vertex (two fans) shows up as a face whose corner is not reached by the fan
    // walk of that vertex: count face corners per vertex and compare with fan sizes.
    {
        std::vector<std::size_t> corners(mesh.n_vertices(), 0), fans(mesh.n_vertices(), 0);
        for (auto f : mesh.faces())
            for (auto v : mesh.fv_range(f)) ++corners[v.idx()];
        for (auto v : mesh.vertices()) {
            for (auto f : mesh.vf_range(v)) { (void)f; ++fans[v.idx()]; }
            if (corners[v.idx()] != fans[v.idx()])
                problem("vertex " + std::to_string(v.idx()) + " is non-manifold (" + std::to_string(corners[v.idx()]) +
                        " incident faces, fan of " + std::to_string(fans[v.idx()]) + ")");
        }
    }
    // No duplicate edges (two edges joining the same pair of vertices).
    {
        std::set<std::pair<int, int>> seen;
        for (auto e : mesh.edges()) {
            auto h = mesh.halfedge_handle(e, 0);
            int a = mesh.from_vertex_handle(h).idx(), b = mesh.to_vertex_handle(h).idx();
            if (a == b) problem("edge " + std::to_string(e.idx()) + " is a loop");
            if (!seen.insert(std::minmax(a, b)).second)
                problem("duplicate edge between vertices " + std::to_string(a) + " and " + std::to_string(b));
        }
    }
    // Consistent orientation: the two halfedges of an edge belong to different faces and point in
    // opposite directions (guaranteed by the halfedge structure; check the faces differ).
    for (auto e : mesh.edges()) {
        auto f0 = mesh.face_handle(mesh.halfedge_handle(e, 0));
        auto f1 = mesh.face_handle(mesh.halfedge_handle(e, 1));
        if (f0.is_valid() && f0 == f1) problem("edge " + std::to_string(e.idx()) + " has the same face on both sides");
    }
    // Two faces on the same three vertices (a "pillow") are degenerate too.
    {
        std::set<std::array<int, 3>> tris;
        for (auto f : mesh.faces()) {
            std::array<int, 3> key{};
            int i = 0;
            for (auto v : mesh.fv_range(f)) if (i < 3) key[i++] = v.idx();
            std::sort(key.begin(), key.end());
            if (!tris.insert(key).second) problem("two faces share the vertices of face " + std::to_string(f.idx()));
        }
    }
    // No degenerate faces.
    for (auto f : mesh.faces()) {
        auto h = mesh.halfedge_handle(f);
        Vec3 a = position(mesh, mesh.from_vertex_handle(h));
        Vec3 b = position(mesh, mesh.to_vertex_handle(h));
        Vec3 c = position(mesh, mesh.to_vertex_handle(mesh.next_halfedge_handle(h)));
        const double area = 0.5 * (b - a).cross(c - a).norm();
        if (!(area > options.minFaceArea)) problem("degenerate face " + std::to_string(f.idx()) + " (area " + std::to_string(area) + ")");
    }
    // Outward orientation: every solid encloses positive volume, every cavity's inner wall negative
    // volume inside a solid.
    if (options.requireOutward) {
        int count = 0;
        const auto label = componentLabels(mesh, &count);
        const auto shapes = componentShapes(mesh, label, count);
        for (std::size_t i = 0; i < shapes.size(); ++i)
            if (!shapes[i].outward())
                problem("component " + std::to_string(i) + " is not oriented outward: volume " +
                        std::to_string(shapes[i].volume) + ", enclosed by " + std::to_string(shapes[i].enclosure) +
                        " other components");
    }
    return report;
}

} // namespace riemesh::testing
