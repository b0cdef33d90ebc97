// riemesh/image.h: the scalar image the model deforms in (paper 3.3, 5).
//
// All positions are world space. An image knows its voxel size (world units per voxel) and the
// world-space box of its data; `value` is trilinear for sampled images, `gradient` is in intensity
// per world unit.
#pragma once

#include "riemesh/mesh.h"

#include <nanovdb/NanoVDB.h>
#include <nanovdb/util/GridHandle.h>

#include <Eigen/Geometry>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace riemesh {

using Box3 = Eigen::AlignedBox3d;

/// Implementations must be safe to call from several threads at once (the core samples in parallel).
class ScalarImage {
public:
    virtual ~ScalarImage() = default;
    /// Intensity at a world-space point (outside the data: the background value).
    virtual double value(const Vec3& x) const = 0;
    /// Gradient (intensity per world unit); default: central differences with step voxelSize()/2.
    virtual Vec3 gradient(const Vec3& x) const;
    /// The gradient with respect to the image's own voxel coordinates (intensity per voxel; for a
    /// sampled image with anisotropic or oblique voxels, not a world-space direction): the shape as
    /// the image resolves it. Defaults to gradient(x) * voxelSize().
    virtual Vec3 indexGradient(const Vec3& x) const { return gradient(x) * voxelSize(); }
    /// World units per voxel (the unit users give delta, sigma and rho in).
    virtual double voxelSize() const = 0;
    /// World-space box of the data (for a sparse grid: its active voxels).
    virtual Box3 bounds() const = 0;
    /// Value and gradient at once (sampled images share the voxel lookups).
    virtual void sample(const Vec3& x, double& value, Vec3& gradient) const
    {
        value = this->value(x);
        gradient = this->gradient(x);
    }
};

/// The Newton estimate of the signed distance from `x` to the isosurface I = iso: (I(x) - iso) /
/// |grad I(x)| (world units, > 0 where the image is brighter), the gradient's norm taken at least
/// `minGradient` (where the image is flat the estimate is large, not infinite).
double isoDistance(const ScalarImage& image, const Vec3& x, double iso, double minGradient);

/// An analytic image: I(x) = f(x), with an optional exact gradient.
class FunctionImage final : public ScalarImage {
public:
    FunctionImage(std::function<double(const Vec3&)> f, Box3 bounds, double voxelSize = 1.0,
                  std::function<Vec3(const Vec3&)> gradient = {});
    double value(const Vec3& x) const override { return mF(x); }
    Vec3 gradient(const Vec3& x) const override;
    double voxelSize() const override { return mVoxelSize; }
    Box3 bounds() const override { return mBounds; }
private:
    std::function<double(const Vec3&)> mF;
    std::function<Vec3(const Vec3&)> mGradient;
    Box3 mBounds;
    double mVoxelSize;
};

/// A dense, axis-aligned grid: voxel (i,j,k) is at origin + voxelSize * (i,j,k), x fastest.
class DenseImage final : public ScalarImage {
public:
    DenseImage(int nx, int ny, int nz, std::vector<float> data, Vec3 origin = Vec3::Zero(),
               double voxelSize = 1.0, double background = 0.0);
    double value(const Vec3& x) const override;
    Vec3 gradient(const Vec3& x) const override;
    double voxelSize() const override { return mVoxelSize; }
    Box3 bounds() const override;
    int nx() const { return mN[0]; }
    int ny() const { return mN[1]; }
    int nz() const { return mN[2]; }
    float at(int i, int j, int k) const { return mData[(std::size_t(k) * mN[1] + j) * mN[0] + i]; }
private:
    int mN[3];
    std::vector<float> mData;
    Vec3 mOrigin;
    double mVoxelSize;
    double mBackground;
};

/// A NanoVDB float grid, trilinear in index space, mapped to world space by the grid's transform.
/// The grid is not owned. Thread-safe: each thread samples through its own cached accessor.
class NanoImage final : public ScalarImage {
public:
    explicit NanoImage(const nanovdb::FloatGrid* grid);
    ~NanoImage() override;
    double value(const Vec3& x) const override;
    Vec3 gradient(const Vec3& x) const override;
    void sample(const Vec3& x, double& value, Vec3& gradient) const override;
    Vec3 indexGradient(const Vec3& x) const override;
    double voxelSize() const override { return mVoxelSize; }
    Box3 bounds() const override { return mBounds; }
    const nanovdb::FloatGrid* grid() const { return mGrid; }
private:
    const nanovdb::FloatGrid* mGrid;
    std::uint64_t mOwner; ///< tells this image's per-thread accessors apart (detail/thread_accessor.h)
    double mVoxelSize;
    Box3 mBounds;
};

/// Grid names in a riemesh .nvdb file.
inline constexpr const char* kMetricDiagGrid = "metric_diag";
inline constexpr const char* kMetricOffGrid = "metric_off";
/// Optional one-voxel float grid holding, at the origin, the isovalue the image was segmented at
/// (`vdb2mesh --iso 40 --export-nvdb`), so that a viewer opens the file at the same surface.
inline constexpr const char* kIsoGrid = "riemesh_iso";
/// Coarse images of a coarse-to-fine schedule in a .nvdb file: "riemesh_level_1", "riemesh_level_2",
/// ... (vdb::coarseLevels; EvolutionLevel).
inline constexpr const char* kLevelGridPrefix = "riemesh_level_";

/// An image and (optionally) its metric as NanoVDB grids, owning their buffers: what
/// `vdb2mesh --export-nvdb` writes and the viewer reads.
class NanoVolume {
public:
    /// Reads a .nvdb file. Throws std::runtime_error naming the problem (missing file, not NanoVDB,
    /// no float grid, metric grids of the wrong type).
    static NanoVolume read(const std::string& path);
    /// Same from bytes in memory.
    static NanoVolume fromBytes(const std::uint8_t* data, std::size_t size);
    /// From grids built in this process (e.g. by riemesh::vdb::toNanoHandles), without a copy: the
    /// grids are indexed as a file's would be, but their trees are trusted (not re-validated).
    static NanoVolume fromHandles(std::vector<nanovdb::GridHandle<nanovdb::HostBuffer>>&& handles);

    NanoVolume();
    NanoVolume(NanoVolume&&) noexcept;
    NanoVolume& operator=(NanoVolume&&) noexcept;
    ~NanoVolume();

    /// The first float grid (the image).
    const nanovdb::FloatGrid* imageGrid() const;
    /// metric_diag / metric_off, or nullptr when the file has no metric.
    const nanovdb::Vec3fGrid* metricDiag() const;
    const nanovdb::Vec3fGrid* metricOff() const;
    /// Largest eigenvalue bound stored with the metric (grid metadata), 1 without a metric.
    double metricMaxEigenvalue() const { return mMuMax; }
    /// Name of the image grid.
    std::string imageName() const;
    /// Grid class of the image ("fog", "levelset" or "unknown").
    std::string imageClass() const;
    /// Coarse images of a coarse-to-fine schedule (kLevelGridPrefix + l), level 1 (finest of them)
    /// to levelCount(); nullptr outside.
    int levelCount() const { return int(mLevels.size()); }
    const nanovdb::FloatGrid* levelGrid(int level) const;
    /// Every grid, in order (what NanoVolume::read would find in a file).
    const std::vector<nanovdb::GridHandle<nanovdb::HostBuffer>>& handles() const { return mHandles; }
    /// The isovalue stored with the image (kIsoGrid), if any.
    bool hasIso() const { return mIsoGrid >= 0; }
    double iso() const;

private:
    std::vector<nanovdb::GridHandle<nanovdb::HostBuffer>> mHandles;
    int mImage = -1, mDiag = -1, mOff = -1, mIsoGrid = -1;
    std::vector<int> mLevels; ///< handle index of level 1, 2, ...
    double mMuMax = 1.0;
    void index();
};

} // namespace riemesh
