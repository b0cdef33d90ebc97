// riemesh/vdb/io.h: reading scalar images from .vdb / .nvdb files and writing grids atomically.
//
// A riemesh image is an openvdb::FloatGrid in world space (the grid's transform). Double grids are
// converted to float. Every reader throws std::runtime_error with a one-line message that names the
// file and the problem (missing, empty, not a VDB file, truncated, no such grid, not scalar, empty,
// non-finite voxels with their count).
#pragma once

#include <openvdb/openvdb.h>

#include <array>
#include <cstdint>
#include <limits>
#include <string>

namespace riemesh::vdb {

/// Calls openvdb::initialize() once (thread-safe); every function here calls it as needed.
void initialize();

/// "fog", "levelset" or "unknown", from the grid class.
std::string gridClassName(const openvdb::GridBase& grid);

/// The active values (voxels and tiles, each tile once): range of the finite ones, count of the
/// others (NaN or infinite). One parallel pass over the leaf nodes.
struct ValueStats {
    float min = std::numeric_limits<float>::max(), max = -std::numeric_limits<float>::max();
    std::uint64_t finite = 0, nonFinite = 0;
};
ValueStats valueStats(const openvdb::FloatGrid& grid);

/// Number of NaN or infinite values among the active voxels and tiles (tiles count once).
std::uint64_t countNonFinite(const openvdb::FloatGrid& grid);

/// Bytes the converter needs per voxel of an image's active bounding box at its peak (the structure
/// tensor and metric stages work on that box as a dense block). Measured as vdb2mesh's peak resident
/// memory over box voxels: cube-cavity phantoms 64^3 / 128^3 / 192^3: 265 / 100 / 66 bytes (a fixed
/// ~45 MB dominates small boxes); the Colin27 head MRI (181x217x181): 109 bytes. Rounded up.
inline constexpr double kPipelineBytesPerVoxel = 128;

/// Throws std::runtime_error naming `path`, the box and both sizes when an image box of
/// `dims` voxels would need more than `budgetBytes` (kPipelineBytesPerVoxel each); 0 = no limit.
using VoxelDims = std::array<std::int64_t, 3>;
void checkMemoryBudget(const std::string& path, const VoxelDims& dims, std::uint64_t budgetBytes);

/// Reads the scalar grid named `gridName` (default: the first float or double grid) from a .vdb file,
/// as a FloatGrid. Checks: the file exists, is non-empty, is a complete VDB file, the grid exists and
/// is a scalar float/double grid, has active voxels, and all its active values are finite. With a
/// `memoryBudget` (bytes, 0 = none), a grid whose bounding box exceeds it is refused from the file's
/// statistics before its voxels are read (and from its real box after, for files without them).
openvdb::FloatGrid::Ptr readVdbImage(const std::string& path, const std::string& gridName = {},
                                     std::uint64_t memoryBudget = 0);

/// Grids of a riemesh .nvdb file (the image and, when present, the metric) converted back to OpenVDB.
struct NanoFileGrids {
    openvdb::FloatGrid::Ptr image;
    openvdb::Vec3fGrid::Ptr metricDiag, metricOff; ///< null when the file has no metric
    double muMax = 1.0;                            ///< bound on the metric's eigenvalues
};
/// Reads a .nvdb file through riemesh::NanoVolume; `gridName` must match the image grid when given.
/// `memoryBudget` as for readVdbImage (checked on the image's box before conversion).
NanoFileGrids readNanoFile(const std::string& path, const std::string& gridName = {}, std::uint64_t memoryBudget = 0);

/// Reads any supported image by extension: .vdb, .nvdb, .nii, .nii.gz.
openvdb::FloatGrid::Ptr readImage(const std::string& path, const std::string& gridName = {});

/// Writes `grids` to a .vdb file (Blosc or Zip compressed as available) through a temporary file
/// beside `path`, renamed on success: an existing file is replaced only by a complete one.
void writeVdb(const std::string& path, const openvdb::GridCPtrVec& grids);

} // namespace riemesh::vdb
