// riemesh/vdb/structure_tensor.h: the image structure tensor (paper 4.3).
//
//   J_{rho,sigma} = G_rho * (grad_sigma I)(grad_sigma I)^T
//
// computed sparse: by bricks of 32^3 voxels within the filters' reach of the image's leaf nodes (each
// gathered with a halo into a small dense block: inactive voxels and tiles give their values, and
// samples beyond the active bounding box read its nearest voxel), with separable Gaussian blurs and
// central differences, multithreaded with TBB; the result does not depend on the thread count.
// Constant tiles and empty space cost nothing. sigma and rho are in voxels (index space). The gradient is
// mapped to world space with the grid's transform (J_world = A^-T J_index A^-1 for the linear part A),
// so J's eigenvectors are world-space directions even for anisotropic or oblique (NIfTI) transforms.
#pragma once

#include <openvdb/openvdb.h>

namespace riemesh::vdb {

struct StructureTensorOptions {
    double sigma = 1.0; ///< pre-smoothing of the image before the gradient (voxels)
    double rho = 2.0;   ///< integration window of the gradient outer product (voxels)
};

/// The six components of J (world space, intensity^2 per world unit^2), active on the voxels of the
/// image's active bounding box within the filters' reach of a leaf node (J = 0 elsewhere):
/// diag = (Jxx, Jyy, Jzz), off = (Jxy, Jxz, Jyz).
struct StructureTensorGrids {
    openvdb::Vec3fGrid::Ptr diag, off;
};

/// Gaussian smoothing with standard deviation `sigma` (voxels, <= 64; 0 = copy), sparse: the active
/// voxels of leaf nodes take their smoothed values, and voxels of the active bounding box that the
/// blur changes (within its reach of the active voxels) become active; constant active tiles keep
/// their value. Same transform, name and class.
openvdb::FloatGrid::Ptr gaussianSmooth(const openvdb::FloatGrid& image, double sigma);

/// Structure tensor of `image`.
StructureTensorGrids structureTensor(const openvdb::FloatGrid& image, const StructureTensorOptions& options = {});

} // namespace riemesh::vdb
