#include "riemesh/mesh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
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

void markEdited(Mesh& mesh, std::initializer_list<VertexHandle> vertices)
{
    for (const char* name : {kEditedProperty, kGuardEditedProperty}) {
        OpenMesh::VPropHandleT<char> edited;
        if (!mesh.get_property_handle(edited, name)) continue;
        for (const VertexHandle v : vertices)
            if (v.is_valid()) mesh.property(edited, v) = 1;
    }
}

namespace {

/// Spreads the low 21 bits of x to every third bit (Morton interleaving).
std::uint64_t spreadBits(std::uint64_t x)
{
    x &= 0x1fffff;
    x = (x | x << 32) & 0x1f00000000ffffULL;
    x = (x | x << 16) & 0x1f0000ff0000ffULL;
    x = (x | x << 8) & 0x100f00f00f00f00fULL;
    x = (x | x << 4) & 0x10c30c30c30c30c3ULL;
    x = (x | x << 2) & 0x1249249249249249ULL;
    return x;
}

} // namespace

void reorderForLocality(Mesh& mesh)
{
    prepareMesh(mesh);
    Vec3 lo = Vec3::Constant(1e300), hi = Vec3::Constant(-1e300);
    for (auto v : mesh.vertices()) {
        lo = lo.cwiseMin(position(mesh, v));
        hi = hi.cwiseMax(position(mesh, v));
    }
    const double extent = (hi - lo).maxCoeff();
    constexpr double kCells = double((1 << 21) - 1);
    const double scale = extent > 0 && std::isfinite(extent) ? kCells / extent : 0.0;
    std::vector<std::pair<std::uint64_t, int>> order; // (Morton key, old vertex index)
    order.reserve(mesh.n_vertices());
    for (auto v : mesh.vertices()) {
        const Vec3 q = (position(mesh, v) - lo) * scale;
        std::uint64_t key = 0;
        for (int a = 0; a < 3; ++a) key |= spreadBits(std::uint64_t(std::clamp(q[a], 0.0, kCells))) << a;
        order.push_back({key, v.idx()});
    }
    std::sort(order.begin(), order.end());
    // New copies of the vertices in curve order (custom properties copied), then of the faces in
    // the order of their first vertex; the old elements are dropped by garbage collection.
    const std::size_t oldVertices = mesh.n_vertices(), oldEdges = mesh.n_edges(), oldFaces = mesh.n_faces();
    std::vector<int> renamed(oldVertices, -1);
    for (const auto& entry : order) {
        const Mesh::Point p = mesh.point(VertexHandle(entry.second)); // a copy: add_vertex may move the array
        const VertexHandle v = mesh.add_vertex(p);
        mesh.copy_all_properties(VertexHandle(entry.second), v);
        renamed[std::size_t(entry.second)] = v.idx();
    }
    std::vector<std::array<int, 3>> faces;
    faces.reserve(oldFaces);
    for (auto f : mesh.faces()) {
        std::array<int, 3> t{};
        int k = 0;
        for (auto v : mesh.fv_range(f)) t[std::size_t(k++ % 3)] = renamed[std::size_t(v.idx())];
        std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end()); // same winding
        faces.push_back(t);
    }
    std::sort(faces.begin(), faces.end());
    // The old elements share nothing with the new ones: marking them deleted is enough.
    for (std::size_t i = 0; i < oldVertices; ++i) mesh.status(VertexHandle(int(i))).set_deleted(true);
    for (std::size_t i = 0; i < oldEdges; ++i) {
        const EdgeHandle e{int(i)};
        mesh.status(e).set_deleted(true);
        mesh.status(mesh.halfedge_handle(e, 0)).set_deleted(true);
        mesh.status(mesh.halfedge_handle(e, 1)).set_deleted(true);
    }
    for (std::size_t i = 0; i < oldFaces; ++i) mesh.status(FaceHandle(int(i))).set_deleted(true);
    for (const auto& t : faces) mesh.add_face(VertexHandle(t[0]), VertexHandle(t[1]), VertexHandle(t[2]));
    mesh.garbage_collection();
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

double windingNumber(const Mesh& mesh, const Vec3& x, const std::vector<int>* label, int skip)
{
    double sum = 0;
    for (auto f : mesh.faces()) {
        const auto h = mesh.halfedge_handle(f);
        const VertexHandle va = mesh.from_vertex_handle(h);
        if (label && (*label)[std::size_t(va.idx())] == skip) continue;
        // Van Oosterom and Strackee: tan(omega / 2) = a.(b x c) / (|a||b||c| + (a.b)|c| + ...).
        const Vec3 a = position(mesh, va) - x, b = position(mesh, mesh.to_vertex_handle(h)) - x,
                   c = position(mesh, mesh.to_vertex_handle(mesh.next_halfedge_handle(h))) - x;
        const double la = a.norm(), lb = b.norm(), lc = c.norm();
        const double num = a.dot(b.cross(c));
        const double den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
        sum += 2 * std::atan2(num, den);
    }
    return sum / (4 * M_PI);
}

std::vector<ComponentShape> componentShapes(const Mesh& mesh, const std::vector<int>& label, int count)
{
    std::vector<ComponentShape> shapes(std::size_t(std::max(count, 0)));
    std::vector<Eigen::AlignedBox3d> bounds(shapes.size());
    std::vector<VertexHandle> sample(shapes.size());
    for (auto v : mesh.vertices()) {
        const std::size_t i = std::size_t(label[std::size_t(v.idx())]);
        ++shapes[i].vertices;
        bounds[i].extend(position(mesh, v));
        sample[i] = v;
    }
    for (auto f : mesh.faces()) {
        const auto h = mesh.halfedge_handle(f);
        const VertexHandle va = mesh.from_vertex_handle(h);
        const Vec3 a = position(mesh, va), b = position(mesh, mesh.to_vertex_handle(h)),
                   c = position(mesh, mesh.to_vertex_handle(mesh.next_halfedge_handle(h)));
        shapes[std::size_t(label[std::size_t(va.idx())])].volume += a.dot(b.cross(c)) / 6.0;
    }
    for (std::size_t i = 0; i < shapes.size(); ++i) {
        bool nested = false;
        for (std::size_t j = 0; j < shapes.size() && !nested; ++j) nested = j != i && bounds[j].contains(bounds[i]);
        if (nested)
            shapes[i].enclosure = int(std::lround(windingNumber(mesh, position(mesh, sample[i]), &label, int(i))));
    }
    return shapes;
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
