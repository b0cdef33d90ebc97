// riemesh/vdb/volume.h: the converter's pipeline without OpenVDB types, for thin apps.
//
// Volume::read (any supported file, all checks) -> smooth (the image the forces see) ->
// computeMetric -> nano() for the core, writeMetric / exportNanoVDB on request; then
// writeSurfaceLevelSet for a .vdb output. Including this header does not include OpenVDB.
#pragma once

#include "riemesh/image.h"
#include "riemesh/mesh.h"

#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace riemesh::vdb {

struct ImageInfo {
    std::string path;
    std::string format;          ///< "vdb", "nvdb" or "nifti"
    std::string gridName;
    std::string gridClass;       ///< "fog", "levelset" or "unknown"
    double voxelSize = 1;        ///< world units per voxel (largest axis for anisotropic transforms)
    Box3 worldBounds;            ///< world box of the active voxels
    int dims[3] = {0, 0, 0};     ///< active bounding box, voxels
    std::uint64_t activeVoxels = 0;
    double minValue = 0, maxValue = 0;
    std::string transformNote;   ///< e.g. "NIfTI scanner space (RAS, mm) from sform"
};

struct VolumeMetricOptions {
    double sigma = 1.0;         ///< structure tensor pre-smoothing (voxels)
    double rho = 2.0;           ///< structure tensor window (voxels)
    double muMax = 9.0;         ///< largest metric eigenvalue
    double tangentialGain = 4.0;///< boost of the edge/corner eigenvalues (metric_grid.h)
};

struct VolumeMetricStats {
    std::uint64_t activeVoxels = 0, totalVoxels = 0;
    double xiRef = 0, threshold = 0, seconds = 0;
};

class Volume {
public:
    /// Reads .vdb (grid `gridName` or the first scalar grid), .nvdb (riemesh files, with their metric
    /// if any) or .nii/.nii.gz. Throws std::runtime_error with a one-line message naming the problem.
    /// An image whose bounding box needs more than `memoryBudget` bytes (0: defaultMemoryBudget())
    /// is refused, before its voxels are read where the file's header tells its size.
    static Volume read(const std::string& path, const std::string& gridName = {}, std::uint64_t memoryBudget = 0);

    Volume();
    ~Volume();
    Volume(Volume&&) noexcept;
    Volume& operator=(Volume&&) noexcept;

    const ImageInfo& info() const;

    /// Closes the object where the image cuts it (a head cut at the neck, an organ at the edge of the
    /// field of view): on each face of the image box, the object's footprint in the border slice
    /// (voxels on the object's side of `iso`, with the holes the slice encloses filled) is copied two
    /// voxels outward, so the isosurface closes just beyond the border instead of opening into the
    /// object through every cavity the cut slice shows. Returns the voxels added (0 when nothing
    /// touches the border). Call before computeMetric so the metric sees the closing cap too.
    std::uint64_t closeBorders(double iso, bool objectBrighter);

    /// Replaces the image by its Gaussian smoothing (sigma in voxels; 0 does nothing).
    void smooth(double sigmaVoxels);

    /// Coarse images of the current image for a coarse-to-fine schedule (vdb::coarseLevels: block
    /// extremes over 2^l voxels, grown by half a block, so that each holds the image's object),
    /// levels 1..`levels`; nano() and exportNanoVDB() carry them. 0 removes them; smooth() and
    /// downsample() drop them.
    /// With a finite `iso`, stops below a level where some part of the object is less than
    /// `minObjectCells` of its cells long (vdb::coarseLevels), and keeps objectBoxes(). Returns
    /// the levels built.
    int buildLevels(int levels, bool objectBrighter, double iso = std::numeric_limits<double>::quiet_NaN(),
                    double minObjectCells = 0);
    int levelCount() const;
    /// World boxes around the separate parts of the object found by the last buildLevels() with
    /// an iso (vdb::coarseLevels): where an initial surface per part can start. Empty otherwise.
    const std::vector<Box3>& objectBoxes() const;

    /// Computes the structure-tensor metric of the current image (replacing any metric read from a
    /// .nvdb file).
    VolumeMetricStats computeMetric(const VolumeMetricOptions& options);
    bool hasMetric() const;
    double metricMaxEigenvalue() const;

    /// The image, metric (when present) and coarse levels as NanoVDB grids for the core.
    NanoVolume nano() const;
    /// The same, converting one grid at a time and freeing its OpenVDB form right after, so that the
    /// peak memory holds one grid twice, not all of them (what meshVolume does). The volume then keeps
    /// the NanoVDB copy (returned), from which writeMetric, exportNanoVDB, writeSurfaceLevelSet,
    /// placement and info still work; the operations on voxels (smooth, computeMetric, closeBorders,
    /// buildLevels, downsample, nano) throw std::logic_error. Calling it again returns the same copy.
    std::shared_ptr<const NanoVolume> releaseToNano();

    /// metric_diag + metric_off to a .vdb file (for Houdini / vdb_view), atomically. Needs a metric.
    void writeMetric(const std::string& path) const;
    /// Image + metric (+ the isovalue, when finite) to a .nvdb file (the web viewer's input), atomically.
    void exportNanoVDB(const std::string& path, double iso = std::numeric_limits<double>::quiet_NaN()) const;

    /// Replaces the image by its block average over factor^3 voxels (factor >= 1; 1 does nothing),
    /// keeping its world placement (voxel size x factor); drops a computed metric. For previews and
    /// small web demos.
    void downsample(int factor);

    /// The mesh as a level set "surface" with this image's transform, to a .vdb file, atomically.
    void writeSurfaceLevelSet(const std::string& path, const Mesh& mesh) const;

    /// A deep copy (image and metric): meshVolume changes the volume it is given.
    Volume copy() const;
    /// The same info and transform without voxels: enough for writeSurfaceLevelSet, kept beside a mesh.
    Volume placement() const;

private:
    friend struct VolumeGrids; // volume_grids.h: the OpenVDB grids behind a Volume
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

/// Accuracy of `mesh` against a reference signed distance grid (default grid "sdf") in a .vdb file,
/// in world units, both ways from dense samples of both surfaces (level_set.h: surfaceError). A
/// phantom's sdf grid (vdbphantom) is measured against the phantom's analytic distance.
struct ReferenceError {
    double meanMeshToSurface = 0, maxMeshToSurface = 0; ///< mesh samples to the reference surface
    double meanSurfaceToMesh = 0, maxSurfaceToMesh = 0; ///< reference surface samples to the mesh
    double hausdorff = 0, voxelSize = 1;
    /// Where the Hausdorff distance is (world units, as the mesh's points): on the mesh (the sample
    /// farthest from the reference surface) or on the reference surface (the farthest from the mesh).
    double hausdorffAt[3] = {0, 0, 0};
    bool hausdorffOnMesh = false;
    bool analytic = false; ///< measured against a phantom's analytic distance (else the grid's, trilinear)
};
ReferenceError compareToReference(const Mesh& mesh, const std::string& path, const std::string& gridName = "sdf");

/// Makes the phantom `shape` (see phantom.h: "cube-cavity", "ball", "torus", "two-spheres",
/// "thin-plate") and writes its "density" and "sdf" grids to a .vdb file atomically. Throws
/// std::invalid_argument for an unknown shape or bad parameters.
void writePhantom(const std::string& shape, const std::string& path, int size, double noise, std::uint64_t seed);
/// The valid phantom shape names.
std::vector<std::string> phantomShapes();

/// Half the physical memory, in bytes (the default budget of Volume::read).
std::uint64_t defaultMemoryBudget();

/// Limits TBB to `threads` threads for the lifetime of the returned object (0: all cores).
std::shared_ptr<void> limitThreads(int threads);

/// Writes a file through a temporary file beside `path` that `write` fills, renamed on success; on
/// any exception the temporary is removed and the exception rethrown (an existing file is untouched).
void writeFileAtomically(const std::string& path, const std::function<void(const std::string& tempPath)>& write);

/// Lowercase extension including the dot, ".nii.gz" recognised as one ("" when none).
std::string fileExtension(const std::string& path);

} // namespace riemesh::vdb
