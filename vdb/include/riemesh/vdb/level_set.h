// riemesh/vdb/level_set.h: meshes as OpenVDB level sets, and accuracy against a reference distance.
#pragma once

#include "riemesh/mesh.h"

#include <openvdb/openvdb.h>

#include <cstddef>
#include <vector>

namespace riemesh::vdb {

/// A narrow-band level set of the closed mesh `mesh` (world space) named "surface", class level set,
/// with `transform` (voxel size and origin; affine transforms are fine) and a band of `halfWidth`
/// voxels on each side (meshToLevelSet).
openvdb::FloatGrid::Ptr meshToSurfaceLevelSet(const Mesh& mesh, const openvdb::math::Transform& transform,
                                              float halfWidth = 3.0f);

/// Distances between a mesh and a reference surface given by its signed distance grid `sdf`
/// (e.g. a phantom's "sdf" grid), in world units.
struct SurfaceError {
    double meanVertexDistance = 0;   ///< mean over mesh vertices of |sdf| (mesh -> surface)
    double maxVertexDistance = 0;    ///< max over mesh vertices of |sdf|
    double maxSurfaceDistance = 0;   ///< max over reference surface points of the distance to the mesh
    double hausdorff = 0;            ///< max of the two one-sided maxima
    std::size_t samples = 0;         ///< reference surface points used
};
/// Reference surface points are the projections onto sdf = 0 of the voxels with |sdf| < voxel/2;
/// their distance to the mesh is read (trilinearly) from a signed distance grid of the closed mesh with
/// the sdf's transform and a band of 16 voxels (larger distances read as 16 voxels).
SurfaceError surfaceError(const Mesh& mesh, const openvdb::FloatGrid& sdf);
/// The same for any closed triangle mesh given as arrays (world-space points, vertex indices), such
/// as another mesher's output, so that every mesher is measured by the same code.
SurfaceError surfaceError(const std::vector<openvdb::Vec3d>& worldPoints, const std::vector<openvdb::Vec3I>& triangles,
                          const openvdb::FloatGrid& sdf);

} // namespace riemesh::vdb
