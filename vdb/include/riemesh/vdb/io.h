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

/// The peak memory of meshing an image whose grid takes `imageBytes` in memory (its leaf nodes and
/// tiles: openvdb memUsage, or the file's "file_mem_bytes"): the volume stage is sparse, so the
/// peak follows the grid, not its bounding box. Measured as vdb2mesh's peak resident memory (with
/// its defaults) over the grid's bytes: cube-cavity phantoms 100^3 / 200^3 / 400^3 (dense fog):
/// 20 / 4.7 / 4.0 (a fixed ~60 MB dominates small images: the program, the mesh); level-set spheres
/// r = 60 / 125 / 250: ... / ... / 9.9 (the smoothing widens the band, the metric fills it).
/// Rounded up: kPipelineFixedBytes + factor x imageBytes.
inline constexpr double kPipelineFixedBytes = 96.0 * 1024 * 1024;
inline constexpr double kPipelineBytesPerImageByte = 5.0;
inline constexpr double kLevelSetBytesPerImageByte = 12.0;
std::uint64_t estimatePipelineBytes(std::uint64_t imageBytes, bool levelSet);

/// Throws std::runtime_error naming `path`, the image and both sizes when meshing an image whose
/// grid takes `imageBytes` (estimatePipelineBytes) would need more than `budgetBytes`; 0 = no limit.
void checkMemoryBudget(const std::string& path, std::uint64_t imageBytes, bool levelSet, std::uint64_t budgetBytes);
/// The same for a dense image of `dims` voxels (NIfTI files, arrays: every voxel active).
using VoxelDims = std::array<std::int64_t, 3>;
void checkMemoryBudget(const std::string& path, const VoxelDims& dims, std::uint64_t budgetBytes);

/// Reads the scalar grid named `gridName` (default: the first float or double grid) from a .vdb file,
/// as a FloatGrid. Checks: the file exists, is non-empty, is a complete VDB file, the grid exists and
/// is a scalar float/double grid, has active voxels, and all its active values are finite. With a
/// `memoryBudget` (bytes, 0 = none), a grid whose bounding box exceeds it is refused from the file's
/// statistics before its voxels are read (and from its real box after, for files without them).
/// OpenVDB reads the file in a forked child process limited to the budget (at least 16 MB; no
/// budget: half the physical memory), which hands the grid back as a flat buffer that this process
/// checks before it builds the grid: a file that makes OpenVDB crash or corrupt its memory (10.0.1
/// overflows a heap buffer on some corrupt Blosc blocks) is refused as "corrupt or unreadable VDB
/// file (the reader crashed: signal N...)", one that makes it exceed the limit as "(ran out of the
/// N MB memory limit)".
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
