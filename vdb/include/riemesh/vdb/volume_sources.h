// riemesh/vdb/volume_sources.h: Volumes made in memory rather than read from a file: from a strided 3D
// array (numpy's layout: any element type, any strides, read in place), and phantoms. No OpenVDB
// include.
#pragma once

#include "riemesh/vdb/volume.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

namespace riemesh::vdb {

enum class ArrayElement { Float32, Float64, Int8, UInt8, Int16, UInt16, Int32, UInt32, Int64, UInt64 };

/// A 3D array in memory that stays alive and unchanged while a Volume is made from it: element (i, j, k)
/// is at data + i*strides[0] + j*strides[1] + k*strides[2] (bytes, any sign).
struct ArrayView {
    const void* data = nullptr;
    ArrayElement element = ArrayElement::Float32;
    std::array<std::int64_t, 3> shape{0, 0, 0};
    std::array<std::int64_t, 3> strides{0, 0, 0};
};

struct ArrayPlacement {
    std::array<double, 3> spacing{1, 1, 1}; ///< world units per voxel along i, j, k (> 0)
    std::array<double, 3> origin{0, 0, 0};  ///< world position of element (0, 0, 0)
    std::string gridClass = "unknown";      ///< "fog", "levelset" (inside negative) or "unknown" (isovalue required)
    std::string name = "array";             ///< the image's name in messages and statistics
};

/// The array as a Volume: voxel (i, j, k) holds array[i, j, k] (converted to float) at world
/// origin + spacing * (i, j, k); every element is an active voxel, the background is 0. Reads the
/// elements where they are (no intermediate copy), in parallel. Throws std::invalid_argument naming
/// the problem: fewer than 2 elements along an axis, a shape beyond 2^30, non-finite values (with
/// their count), bad spacing, origin or class, or a box larger than `memoryBudget` allows (bytes, as
/// Volume::read; 0: defaultMemoryBudget()).
Volume volumeFromArray(const ArrayView& array, const ArrayPlacement& placement = {}, std::uint64_t memoryBudget = 0);

/// The phantom `shape` (phantom.h names) of size^3 voxels: its "density" fog volume (with the noise) or
/// its exact "sdf" level set. Throws std::invalid_argument for an unknown shape, grid or bad parameters.
Volume phantomVolume(const std::string& shape, int size, double noise, std::uint64_t seed,
                     const std::string& grid = "density");

} // namespace riemesh::vdb
