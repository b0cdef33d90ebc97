// riemesh/vdb/volume_grids.h: the OpenVDB grid behind a Volume, for code that has a grid in memory (the
// Python module's pyopenvdb input, phantoms, arrays). Includes OpenVDB.
#pragma once

#include "riemesh/vdb/volume.h"

#include <openvdb/openvdb.h>

#include <string>

namespace riemesh::vdb {

struct VolumeGrids {
    /// A Volume whose image is `image` itself (shared, not copied: meshVolume will change it; pass a
    /// deepCopy() to keep the original). `format` and `transformNote` go to its info. Checks what
    /// Volume::read checks: active voxels, finite values and background, a linear transform, at least
    /// 2 voxels along each axis; throws std::invalid_argument with a one-line message otherwise.
    static Volume fromImage(openvdb::FloatGrid::Ptr image, const std::string& format, const std::string& transformNote);

    /// The image grid of `volume` (null for a default-constructed Volume).
    static openvdb::FloatGrid::ConstPtr image(const Volume& volume);
};

} // namespace riemesh::vdb
