// riemesh/vdb/structure_tensor.h: the image structure tensor (paper 4.3).
//
//   J_{rho,sigma} = G_rho * (grad_sigma I)(grad_sigma I)^T
//
// computed on the active bounding box of the image (a dense block; sparse inputs such as narrow-band
// level sets are filled with their inactive values), with separable Gaussian blurs and central
// differences, multithreaded with TBB. sigma and rho are in voxels (index space). The gradient is
// mapped to world space with the grid's transform (J_world = A^-T J_index A^-1 for the linear part A),
// so J's eigenvectors are world-space directions even for anisotropic or oblique (NIfTI) transforms.
#pragma once

#include <openvdb/openvdb.h>

namespace riemesh::vdb {

struct StructureTensorOptions {
    double sigma = 1.0; ///< pre-smoothing of the image before the gradient (voxels)
    double rho = 2.0;   ///< integration window of the gradient outer product (voxels)
};

/// The six components of J (world space, intensity^2 per world unit^2), on the image's active
/// bounding box, every voxel active: diag = (Jxx, Jyy, Jzz), off = (Jxy, Jxz, Jyz).
struct StructureTensorGrids {
    openvdb::Vec3fGrid::Ptr diag, off;
};

/// Gaussian smoothing with standard deviation `sigma` (voxels; 0 = copy) over the active bounding box
/// of `image`. The result has every voxel of that box active, the same transform, name and class.
openvdb::FloatGrid::Ptr gaussianSmooth(const openvdb::FloatGrid& image, double sigma);

/// Structure tensor of `image`.
StructureTensorGrids structureTensor(const openvdb::FloatGrid& image, const StructureTensorOptions& options = {});

} // namespace riemesh::vdb
