// riemesh/vdb/nifti.h: NIfTI-1/NIfTI-2 images (.nii, .nii.gz) through nifticlib.
//
// World coordinates are NIfTI *scanner space* in millimetres, RAS+ (+x toward the subject's Right,
// +y Anterior, +z Superior), given by the sform when sform_code > 0, else
// by the qform when qform_code > 0, else by the voxel sizes alone (method 1 of nifti1.h). The voxel index
// (i,j,k) of the file is the OpenVDB index coordinate, and the index-to-world map is the full affine
// matrix (rotation, shear, anisotropic spacing), stored as an OpenVDB affine transform.
#pragma once

#include <openvdb/openvdb.h>

#include <array>
#include <string>

namespace riemesh::vdb {

struct NiftiHeaderInfo {
    std::array<long long, 3> dims{};   ///< voxels along i, j, k
    std::array<double, 3> spacing{};   ///< pixdim 1..3 (millimetres)
    std::string transformSource;       ///< "sform", "qform" or "pixdim"
    int datatype = 0;                  ///< NIFTI_TYPE_* of the file
    double slope = 1, inter = 0;       ///< scl_slope / scl_inter applied to the voxel values
};

/// Reads a 3D NIfTI image (a 4D file must have a single volume) of any integer or float datatype,
/// applies scl_slope/scl_inter (when slope != 0), and returns a FloatGrid whose voxels are all active
/// over the image box, named after the file, class "unknown" (an intensity image: give --iso), with an
/// affine transform from voxel index to scanner space. Throws std::runtime_error naming the problem.
/// The header is checked before any voxel is read: an uncompressed file must hold the voxel bytes it
/// declares, and with a `memoryBudget` (bytes, 0 = none) a box that exceeds it is refused.
openvdb::FloatGrid::Ptr readNifti(const std::string& path, NiftiHeaderInfo* info = nullptr,
                                  std::uint64_t memoryBudget = 0);

/// True for .nii and .nii.gz (case-insensitive).
bool isNiftiPath(const std::string& path);

} // namespace riemesh::vdb
