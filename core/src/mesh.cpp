#include "riemesh/mesh.h"

#include <vector>

namespace riemesh {

OpenMesh::VPropHandleT<OpenMesh::Vec3d> velocityProperty(Mesh& mesh)
{
    OpenMesh::VPropHandleT<OpenMesh::Vec3d> prop;
    if (!mesh.get_property_handle(prop, kVelocityProperty)) {
        mesh.add_property(prop, kVelocityProperty);
        for (auto v : mesh.all_vertices()) mesh.property(prop, v) = OpenMesh::Vec3d(0, 0, 0);
    }
    return prop;
}

void prepareMesh(Mesh& mesh)
{
    mesh.request_vertex_status();
    mesh.request_edge_status();
    mesh.request_halfedge_status();
    mesh.request_face_status();
    velocityProperty(mesh);
}

std::vector<int> componentLabels(const Mesh& mesh, int* componentCount)
{
    std::vector<int> label(mesh.n_vertices(), -1);
    int count = 0;
    std::vector<VertexHandle> stack;
    for (auto seed : mesh.vertices()) {
        if (label[seed.idx()] >= 0) continue;
        label[seed.idx()] = count;
        stack.assign(1, seed);
        while (!stack.empty()) {
            VertexHandle v = stack.back();
            stack.pop_back();
            for (auto w : mesh.vv_range(v)) {
                if (label[w.idx()] < 0) {
                    label[w.idx()] = count;
                    stack.push_back(w);
                }
            }
        }
        ++count;
    }
    if (componentCount) *componentCount = count;
    return label;
}

MeshTopology topologyOf(const Mesh& mesh)
{
    MeshTopology t;
    for (auto v : mesh.vertices()) { (void)v; ++t.vertices; }
    for (auto e : mesh.edges()) { (void)e; ++t.edges; }
    for (auto f : mesh.faces()) { (void)f; ++t.faces; }
    componentLabels(mesh, &t.components);
    t.euler = int(t.vertices) - int(t.edges) + int(t.faces);
    t.genus = (2 * t.components - t.euler) / 2;
    return t;
}

double signedVolume(const Mesh& mesh)
{
    double volume = 0;
    for (auto f : mesh.faces()) {
        auto h = mesh.halfedge_handle(f);
        Vec3 a = position(mesh, mesh.from_vertex_handle(h));
        Vec3 b = position(mesh, mesh.to_vertex_handle(h));
        Vec3 c = position(mesh, mesh.to_vertex_handle(mesh.next_halfedge_handle(h)));
        volume += a.dot(b.cross(c));
    }
    return volume / 6.0;
}

Vec3 faceNormal(const Mesh& mesh, FaceHandle f)
{
    auto h = mesh.halfedge_handle(f);
    Vec3 a = position(mesh, mesh.from_vertex_handle(h));
    Vec3 b = position(mesh, mesh.to_vertex_handle(h));
    Vec3 c = position(mesh, mesh.to_vertex_handle(mesh.next_halfedge_handle(h)));
    Vec3 n = (b - a).cross(c - a);
    double len = n.norm();
    return len > 0 ? Vec3(n / len) : Vec3::Zero();
}

Vec3 vertexNormal(const Mesh& mesh, VertexHandle v)
{
    Vec3 n = Vec3::Zero();
    for (auto f : mesh.vf_range(v)) {
        auto h = mesh.halfedge_handle(f);
        Vec3 a = position(mesh, mesh.from_vertex_handle(h));
        Vec3 b = position(mesh, mesh.to_vertex_handle(h));
        Vec3 c = position(mesh, mesh.to_vertex_handle(mesh.next_halfedge_handle(h)));
        n += (b - a).cross(c - a);
    }
    double len = n.norm();
    return len > 0 ? Vec3(n / len) : Vec3::Zero();
}

void appendMesh(Mesh& dst, const Mesh& src)
{
    std::vector<VertexHandle> map(src.n_vertices());
    OpenMesh::VPropHandleT<OpenMesh::Vec3d> velocity;
    const bool hasVelocity = dst.get_property_handle(velocity, kVelocityProperty);
    for (auto v : src.vertices()) {
        map[v.idx()] = dst.add_vertex(src.point(v));
        if (hasVelocity) dst.property(velocity, map[v.idx()]) = OpenMesh::Vec3d(0, 0, 0);
    }
    std::vector<VertexHandle> face;
    for (auto f : src.faces()) {
        face.clear();
        for (auto v : src.fv_range(f)) face.push_back(map[v.idx()]);
        dst.add_face(face);
    }
}

} // namespace riemesh
