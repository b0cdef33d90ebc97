// riemesh/vdb/level_set.h: meshes as OpenVDB level sets, and accuracy against a reference distance.
#pragma once

#include "riemesh/mesh.h"

#include <openvdb/openvdb.h>

#include <cstddef>
#include <functional>
#include <vector>

namespace riemesh::vdb {

/// The live vertices (world space) and faces of `mesh` appended to index arrays (vertices
/// renumbered without the deleted ones), as surfaceError's array form and OpenVDB's mesh tools
/// take them.
void meshArrays(const Mesh& mesh, std::vector<openvdb::Vec3d>& points, std::vector<openvdb::Vec3I>& triangles);

/// A narrow-band level set of the closed mesh `mesh` (world space) named "surface", class level set,
/// with `transform` (voxel size and origin; affine transforms are fine) and a band of `halfWidth`
/// voxels on each side (meshToLevelSet).
openvdb::FloatGrid::Ptr meshToSurfaceLevelSet(const Mesh& mesh, const openvdb::math::Transform& transform,
                                              float halfWidth = 3.0f);

/// A reference surface's signed distance (world units, negative inside) as a factory of evaluators:
/// each call returns an evaluator for one thread (grid samplers cache nodes and are not shared).
using ReferenceDistance = std::function<std::function<double(const openvdb::Vec3d&)>()>;
/// Trilinear interpolation of a signed distance grid.
ReferenceDistance gridDistance(openvdb::FloatGrid::ConstPtr sdf);
/// The analytic distance of a phantom (phantom.h) when `grid` carries the metadata vdbphantom writes
/// ("riemesh:phantom", "riemesh:size"), exact at creases and corners; empty otherwise.
ReferenceDistance phantomReferenceDistance(const openvdb::GridBase& grid);

/// Two-sided distances between a mesh and a reference surface, world units, from dense samples of
/// both surfaces (see surface_error.cpp):
/// - mesh -> surface: about 4 points per square voxel over every triangle (vertices, edges and
///   interiors), |distance| from the reference, mean weighted by area;
/// - surface -> mesh: points on the reference surface, its creases and corners included (a voxel/3
///   lattice in the band |sdf| < 1 voxel projected onto sdf = 0, one point per half-voxel cell),
///   exact distance to the nearest triangle.
/// Distances beyond 16 voxels read as 16 voxels (a missed part).
struct SurfaceError {
    double meanMeshToSurface = 0;  ///< area-weighted mean over the mesh's samples
    double maxMeshToSurface = 0;
    double meanSurfaceToMesh = 0;  ///< mean over the reference surface's samples
    double maxSurfaceToMesh = 0;
    double hausdorff = 0;          ///< max of the two one-sided maxima
    /// Where the Hausdorff distance is (world): the mesh's sample farthest from the surface, or
    /// the surface's sample farthest from the mesh, whichever is farther (hausdorffOnMesh).
    openvdb::Vec3d hausdorffAt{0.0};
    bool hausdorffOnMesh = false;
    std::size_t meshSamples = 0, surfaceSamples = 0;
};
/// `sdf` seeds the surface samples (its voxels with |value| < 1 voxel) and gives the distance unless
/// `exact` is given (e.g. phantomReferenceDistance), which then gives every distance. Interpolated
/// between voxel centres, a grid's distance rounds the reference's own corners (a box's by ~0.5
/// voxel): only an exact distance puts samples on them.
SurfaceError surfaceError(const Mesh& mesh, const openvdb::FloatGrid& sdf, const ReferenceDistance& exact = {});
/// The same for any closed triangle mesh given as arrays (world-space points, vertex indices), such
/// as another mesher's output, so that every mesher is measured by the same code.
SurfaceError surfaceError(const std::vector<openvdb::Vec3d>& worldPoints, const std::vector<openvdb::Vec3I>& triangles,
                          const openvdb::FloatGrid& sdf, const ReferenceDistance& exact = {});

} // namespace riemesh::vdb
