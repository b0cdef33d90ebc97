// Private: the arithmetic of the sparse volume stage on one dense brick (no OpenVDB here).
//
// The volume stage (metric_grid.cpp) cuts the active region of a sparse grid into bricks of kBrick^3
// voxels, gathers each brick with a halo into a small dense block (x fastest), and runs these kernels
// on it: separable Gaussian passes that shrink the block by the kernel radius along their axis, the
// gradient, and the six channels of the structure tensor. The same source is compiled twice, once
// for any x86-64 and once with AVX2+FMA (where the CPU has them, brickKernels() picks that copy), so
// the loops the compiler vectorises run eight floats wide without making the binary need AVX2.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace riemesh::vdb::detail {

/// Normalised Gaussian taps w[0..2r] with r = max(1, ceil(3 sigma)) (sigma in voxels, > 0).
std::vector<float> gaussianTaps(double sigma);

/// A dense block, x fastest: value (i, j, k) at data[(k * ny + j) * nx + i].
struct BlockDims {
    int nx = 0, ny = 0, nz = 0;
    std::size_t size() const { return std::size_t(nx) * ny * nz; }
};

/// The mapping of the structure tensor's eigenvalues to the metric's (metric_grid.h):
/// mu_i = 1 + span * clamp(g_i (xi_i / xiRef - threshold) / (1 - threshold), 0, 1), g_0 = 1, g_1 = g_2 = gain.
struct MetricParams {
    double xiRef = 1, threshold = 0.1, span = 8, gain = 4, activeTolerance = 1e-3;
};

struct BrickKernels {
    /// out = in convolved with the 2r+1 taps w along x (resp. y, z); out has that axis shorter by 2r
    /// (only the outputs whose whole support lies in the block). `out` must not alias `in`.
    void (*blurX)(const float* in, BlockDims d, const float* w, int r, float* out);
    void (*blurY)(const float* in, BlockDims d, const float* w, int r, float* out);
    void (*blurZ)(const float* in, BlockDims d, const float* w, int r, float* out);
    /// The world-space gradient g = A^-T (central differences) on the block shrunk by one voxel on
    /// every side, and its outer products into six blocks of that size: xx yy zz xy xz yz.
    /// `toWorld` holds the three columns of A^-T (index-space unit steps to world gradient), row-major
    /// 3x3: g_w = toWorld * g_index.
    void (*tensorProducts)(const float* in, BlockDims d, const double* toWorld, float* const out[6]);
    /// tensorProducts followed by blurX with the 2r+1 taps w on each channel, fused row by row (the
    /// products never leave the cache): six blocks of (nx - 2 - 2r) x (ny - 2) x (nz - 2).
    void (*tensorBlurX)(const float* in, BlockDims d, const double* toWorld, const float* w, int r, float* const out[6]);
    /// tensorProducts averaged over 2x2x2 cells of the gradient domain (whose edges must be even):
    /// six blocks of ((nx - 2) / 2) x ((ny - 2) / 2) x ((nz - 2) / 2).
    void (*tensorProductsHalf)(const float* in, BlockDims d, const double* toWorld, float* const out[6]);
    /// The metric of n voxels (metric_grid.h) from their tensor channels: for each voxel whose G
    /// differs from the identity, appends its index to `index` and G's six entries (xx yy zz xy xz
    /// yz) to `g` (room for n of each); returns how many.
    /// With a `mask`, only voxels whose mask byte is non-zero are considered.
    std::size_t (*metricVoxels)(const float* const tensor[6], std::size_t n, const std::uint8_t* mask, const MetricParams& p,
                                std::uint32_t* index, float* g);
    /// The largest eigenvalue of J at the voxels index[0..n) into out.
    void (*largestEigenvalues)(const float* const tensor[6], const std::uint32_t* index, std::size_t n, float* out);
    const char* name; ///< "avx2" or "generic"
};

/// The kernels for this CPU.
const BrickKernels& brickKernels();

} // namespace riemesh::vdb::detail
