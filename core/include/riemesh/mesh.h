// riemesh/mesh.h: the deformable surface.
//
// A closed, oriented (normals out, counter-clockwise faces seen from outside), 2-manifold triangle
// mesh in world space, with any number of connected components. Positions are double precision.
// Per-vertex dynamic state (velocity) lives in an OpenMesh property so that it follows the vertex
// through splits, collapses and garbage collection.
#pragma once

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstddef>
#include <initializer_list>
#include <string>
#include <vector>

namespace riemesh {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

struct MeshTraits : public OpenMesh::DefaultTraits {
    using Point = OpenMesh::Vec3d;
    using Normal = OpenMesh::Vec3d;
    VertexAttributes(OpenMesh::Attributes::Status);
    EdgeAttributes(OpenMesh::Attributes::Status);
    HalfedgeAttributes(OpenMesh::Attributes::PrevHalfedge | OpenMesh::Attributes::Status);
    FaceAttributes(OpenMesh::Attributes::Status);
};

using Mesh = OpenMesh::TriMesh_ArrayKernelT<MeshTraits>;
using VertexHandle = OpenMesh::VertexHandle;
using HalfedgeHandle = OpenMesh::HalfedgeHandle;
using EdgeHandle = OpenMesh::EdgeHandle;
using FaceHandle = OpenMesh::FaceHandle;

inline Vec3 toVec3(const Mesh::Point& p) { return Vec3(p[0], p[1], p[2]); }
inline Mesh::Point toPoint(const Vec3& v) { return Mesh::Point(v.x(), v.y(), v.z()); }
inline Vec3 position(const Mesh& mesh, VertexHandle v) { return toVec3(mesh.point(v)); }

/// The three corners of triangle `f`, in its winding order.
inline std::array<VertexHandle, 3> faceVertices(const Mesh& mesh, FaceHandle f)
{
    const HalfedgeHandle h = mesh.halfedge_handle(f);
    return {mesh.from_vertex_handle(h), mesh.to_vertex_handle(h), mesh.to_vertex_handle(mesh.next_halfedge_handle(h))};
}

/// Name of the per-vertex velocity property (world units per iteration), OpenMesh::Vec3d.
inline constexpr const char* kVelocityProperty = "riemesh:velocity";

/// The velocity property of `mesh`, created (zero-initialised) if missing.
OpenMesh::VPropHandleT<OpenMesh::Vec3d> velocityProperty(Mesh& mesh);

/// Name of the per-vertex edit mark (char). When a mesh has it, split, collapse and flip
/// (riemesh/edge_ops.h) set it on every vertex whose faces or edges they change (a face or an
/// edge whose corners changed has a marked corner). SafeStepCache (riemesh/ccd.h) adds it and
/// clears it whenever it anchors the mesh (and on the vertices it anchors again), to find the
/// edited faces without comparing them all.
/// Any other edit of the connectivity must either mark its vertices or be followed by
/// garbage_collection() and SafeStepCache::invalidate().
inline constexpr const char* kEditedProperty = "riemesh:edited";

/// The same marks for the regularity step's intersection guard (RegularityCache in
/// riemesh/regularity.h), which adds this property and clears the marks it has seen: set by
/// split, collapse and flip (markEdited) beside kEditedProperty, cleared by their own reader.
/// The same rule: any other edit of the connectivity marks its vertices or is followed by
/// garbage_collection() and RegularityCache::invalidate().
inline constexpr const char* kGuardEditedProperty = "riemesh:guard-edited";

/// Sets the edit mark on `vertices` (see kEditedProperty) if the mesh has it.
void markEdited(Mesh& mesh, std::initializer_list<VertexHandle> vertices);

/// Counts that describe the topology of a closed mesh (deleted elements are ignored).
struct MeshTopology {
    std::size_t vertices = 0;
    std::size_t edges = 0;
    std::size_t faces = 0;
    int components = 0;      ///< connected components (through edges)
    int euler = 0;           ///< V - E + F
    int genus = 0;           ///< (2 * components - euler) / 2 for a closed orientable surface
};

/// Vertices, edges, faces, components, Euler characteristic and genus of `mesh`.
MeshTopology topologyOf(const Mesh& mesh);

/// Signed volume enclosed by `mesh` (world units cubed): positive when the normals point outward.
double signedVolume(const Mesh& mesh);

/// Per-vertex component labels (0..components-1), indexed by vertex idx(); -1 for deleted vertices.
std::vector<int> componentLabels(const Mesh& mesh, int* componentCount = nullptr);

/// Generalised winding number of the faces of `mesh` around `x`: the solid angle they subtend,
/// over 4 pi. 1 inside a closed outward-oriented component, 0 outside, -1 inside an inside-out
/// one; fractional near a tangle. With `label` (componentLabels()), the faces of component `skip`
/// are left out. O(faces).
double windingNumber(const Mesh& mesh, const Vec3& x, const std::vector<int>* label = nullptr, int skip = -1);

/// One connected component, in componentLabels()' numbering.
struct ComponentShape {
    std::size_t vertices = 0;
    double volume = 0;  ///< signed volume: positive for a solid, negative for a cavity's wall
    int enclosure = 0;  ///< the other components' winding number around it, rounded (0 unless one
                        ///< of their bounding boxes contains its own)
    /// Orientation consistent with nesting: a solid (volume > 0) enclosed by nothing, or a cavity's
    /// inner wall (volume < 0) enclosed by exactly one solid. A component turned inside out (or a
    /// solid inside a solid) fails.
    bool outward() const { return volume > 0 ? enclosure == 0 : volume < 0 && enclosure == 1; }
};

/// Vertex count, signed volume and enclosure of every component (`label` and `count` from
/// componentLabels()). The winding numbers are computed only where boxes nest.
std::vector<ComponentShape> componentShapes(const Mesh& mesh, const std::vector<int>& label, int count);

/// Unit area-weighted vertex normal (outward for a correctly oriented mesh).
Vec3 vertexNormal(const Mesh& mesh, VertexHandle v);

/// Unit face normal (zero for a degenerate face).
Vec3 faceNormal(const Mesh& mesh, FaceHandle f);

/// Appends a copy of `src` to `dst` as new component(s).
void appendMesh(Mesh& dst, const Mesh& src);

/// Renumbers the live vertices along a space-filling (Morton) curve, and the faces, edges and
/// halfedges after them, then compacts the mesh: neighbours end up close in memory, which keeps
/// every per-iteration pass cache-friendly (splits append vertices at the end of the arrays and
/// collapses leave holes, so an evolved mesh's neighbours are scattered). Geometry, connectivity and
/// every custom vertex property (velocity, ...) are kept; handles change as with garbage_collection().
void reorderForLocality(Mesh& mesh);

/// Requests the status attributes needed by delete/collapse and the velocity property.
void prepareMesh(Mesh& mesh);

} // namespace riemesh
