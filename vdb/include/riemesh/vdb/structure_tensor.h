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

#include <limits>
#include <vector>

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

/// Coarse images for a coarse-to-fine schedule (riemesh::EvolutionLevel), level 1 to `levels`
/// (<= 12): level l is the largest value of `image` (the smallest when `objectBrighter` is false:
/// level sets, dark objects) over blocks of 2^l voxels and a border of 2^(l-1) voxels around each
/// (windows of 4^3 cells of level l-1 at stride 2), on a grid of 2^l-voxel cells (the transform
/// says where). Its object thus holds the image's own object, grown by about half a block, so a
/// surface converged on a coarse level encloses the finer
/// levels' and the finest's objects (thin plates, narrow gaps and all). Sparse like the rest: leaf
/// nodes near the image's leaves are computed by bricks, constant tiles map to tiles. Named
/// riemesh::kLevelGridPrefix + l, the image's class and background.
///
/// With a finite `iso`, levels stop below the first one on which some part of the object (a
/// connected set of cells on the object's side of iso, not enclosed by another) is less than
/// `minObjectCells` cells long: a surface shrinking onto an object only a few edges across
/// collapses before it can wrap it, so such an object must first be met on a finer level. Returns
/// the levels kept (level 1 first; fewer than asked, possibly none).
///
/// With `objectBoxes` (and a finite iso): the world boxes of those parts of the object on the
/// coarsest level kept (with no level, on blocks of 2x2x2 voxels), before its dilation; each
/// holds a part of the image's object; no box lies inside another. Specks of one cell and slivers
/// against the image box have none (see the levels' rule above).
std::vector<openvdb::FloatGrid::Ptr> coarseLevels(const openvdb::FloatGrid& image, int levels, bool objectBrighter,
                                                  double iso = std::numeric_limits<double>::quiet_NaN(),
                                                  double minObjectCells = 0,
                                                  std::vector<openvdb::BBoxd>* objectBoxes = nullptr);

/// Structure tensor of `image`.
StructureTensorGrids structureTensor(const openvdb::FloatGrid& image, const StructureTensorOptions& options = {});

} // namespace riemesh::vdb
