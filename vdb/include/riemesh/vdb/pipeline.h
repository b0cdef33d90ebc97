// riemesh/vdb/pipeline.h: everything vdb2mesh does between reading an image and writing the mesh, as one
// call shared by the CLI and the Python module: close the borders, the structure-tensor metric, the
// smoothed image the forces see, NanoVDB conversion, the initial surface, the evolution, then the
// topology and self-intersection counts of the result. Works through Volume (volume.h): including this
// header does not include OpenVDB.
//
//   vdb::Volume volume = vdb::Volume::read("phantom.vdb");
//   vdb::PipelineOptions options;                 // vdb2mesh's defaults
//   vdb::PipelineResult result = vdb::meshVolume(volume, options);
//   writeMesh("phantom.ply", result.mesh);
#pragma once

#include "riemesh/sharpen.h"

#include "riemesh/evolution.h"
#include "riemesh/mesh.h"
#include "riemesh/vdb/volume.h"

#include <cstdint>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace riemesh::vdb {

// Defaults of PipelineOptions (and of vdb2mesh's flags, which document them in --help).
inline constexpr double kDelta = 3.0;      // voxels
inline constexpr double kZeta = 2.5;
inline constexpr double kMuMax = 9.0;
inline constexpr double kSigma = 1.0;      // voxels
inline constexpr double kRho = 2.0;        // voxels
inline constexpr double kTangentialGain = 4.0;
/// The glibc tunable that has malloc advise its memory for transparent huge pages: vdb2mesh
/// restarts itself with it (see vdb/apps/vdb2mesh.cpp), the stats say whether it was in effect.
inline constexpr const char* kHugePageMallocTunable = "glibc.malloc.hugetlb=1";
inline constexpr double kSmooth = 1.0;     // voxels, images (level sets: 0)
inline constexpr int kMaxIterations = 3000;
inline constexpr std::uint64_t kMaxVertices = 4'000'000;

/// Bad parameters or an image they do not fit (vdb2mesh exits 1, Python raises ValueError). Other
/// std::exceptions from meshVolume are internal failures.
struct PipelineInputError : std::invalid_argument {
    using std::invalid_argument::invalid_argument;
};

/// Where the model starts: vdb2mesh's --init.
struct InitialSurface {
    enum class Kind { Box, Spheres, Mesh };
    Kind kind = Kind::Box;          ///< Box: the image box inset by a voxel, deflating
    std::vector<std::pair<Vec3, double>> spheres; ///< Spheres: centres and radii, world units, inflating
    Mesh mesh;                      ///< Mesh: a closed mesh, world units
    std::string spec = "box";       ///< as given (box, sphere:..., mesh:FILE), for the statistics
};

/// "sphere:" specs X,Y,Z,R[;X,Y,Z,R...] (world units), each radius > 0. Throws PipelineInputError
/// naming --init sphere.
std::vector<std::pair<Vec3, double>> parseSpheres(const std::string& spec);

/// vdb2mesh's --init: box | sphere:X,Y,Z,R[;...] | mesh:FILE (the file is read here). Throws
/// PipelineInputError naming --init.
InitialSurface parseInitialSurface(const std::string& spec);

/// Steps of meshVolume, in order, as reported to PipelineOptions::progress.
enum class PipelineStage {
    Borders, ///< closing the object where the image box cuts it
    Metric,  ///< structure tensor and metric (Riemannian only)
    Smooth,  ///< the smoothed image the forces see, and its coarse levels
    Convert, ///< NanoVDB conversion for the core
    Evolve,  ///< the deformable model (reported again after every iteration)
};
const char* toString(PipelineStage stage);

/// Every vdb2mesh option that is not a file path, under the same name and default.
struct PipelineOptions {
    std::optional<double> iso;      ///< image intensity; default 0.5 for fog volumes, 0 for level sets
                                    ///< (then inside = negative), required for other images
    bool riemannian = true;         ///< --metric riemannian | euclidean
    double delta = kDelta;          ///< shortest edge, metric length, voxels
    double zeta = kZeta;            ///< longest/shortest edge ratio, >= 2
    double muMax = kMuMax;          ///< largest metric eigenvalue, [1, 10000]
    double sigma = kSigma;          ///< structure tensor pre-smoothing, voxels, > 0
    double rho = kRho;              ///< structure tensor window, voxels, > 0
    double tangentialGain = kTangentialGain; ///< --edge-gain, [1, 1000]
    /// Gaussian smoothing of the image the model fits, voxels, >= 0. Unset: kSmooth for images, 0 for
    /// level sets (a signed distance is smooth already: smoothing would only cost time and round
    /// its sharp edges). meshVolume's result holds the value used.
    std::optional<double> smooth;
    int maxIterations = kMaxIterations;      ///< >= 1
    std::uint64_t maxVertices = kMaxVertices; ///< past it the run fails (PipelineInputError), >= 4
    bool openBorders = false;       ///< do not close objects cut by the image box
    /// Intersection-free evolution (EvolutionOptions::intersectionFree); --intersection-free sets it.
    bool intersectionFree = false;
    /// Put creases and corners back on the converged surface (riemesh/sharpen.h; --no-sharpen turns
    /// it off): only the vertices on a crease or a corner move (SharpenOptions::featureAngle), so that
    /// the rounded relief of organic shapes stays. A vertex moves at most kSharpenMaxMoveVoxels voxels;
    /// the result is kept only if it crosses itself no more than before.
    bool sharpen = true;
    /// The external force samples the image at the faces' centroids as well as at the vertices
    /// (ForceOptions::vertexShare = kFaceSampleVertexShare, --face-samples): the faces, not only their
    /// corners, come to lie on the isosurface, and each vertex averages more of the noise. Off by
    /// default while it is evaluated: it costs ~25% more per iteration, and it keeps objects of a
    /// voxel or two (noise specks) that the vertex samples alone let shrink away.
    bool faceSamples = false;
    int downsample = 1;             ///< block-average F^3 voxels first, [1, 64]
    /// Coarse-to-fine levels below the finest (--levels): the model converges first with delta 2^L
    /// on an image of 2^L-voxel blocks, then with half of it, ..., then the image as it is. -1: as
    /// many as leave the coarsest level about kCoarsestEdges edges across the image (autoLevels);
    /// 0: the finest level only. [-1, 12].
    int levels = -1;
    int threads = 0;                ///< worker threads for the volume stages and the evolution (0: all cores)
    InitialSurface init;            ///< --init
    /// Called when a stage starts (`iteration` null) and after every iteration of the evolution (stage
    /// Evolve, that iteration's statistics); return false to interrupt: meshVolume then returns at
    /// once with `stop` Interrupted. May be empty.
    std::function<bool(PipelineStage stage, const IterationStats* iteration)> progress;
};

/// Edges across the image's longest side at the coarsest level chosen by autoLevels.
inline constexpr double kCoarsestEdges = 16.0;
/// Automatic levels stop below the first on which some part of the object is less than this many
/// edges long (vdb::coarseLevels); and a level on which a component still collapses is dropped
/// (Evolution::restarts()).
inline constexpr double kMinObjectEdges = 3.0;
/// The levels for an image `longestSideVoxels` long meshed with edges of `deltaVoxels`: the largest
/// L with 2^L delta kCoarsestEdges <= the side (0 for images up to ~96 voxels at delta 3).
int autoLevels(double longestSideVoxels, double deltaVoxels);

/// Throws PipelineInputError naming the option (vdb2mesh's flag) when a value is out of its range.
void checkPipelineOptions(const PipelineOptions& options);

/// The isovalue and side meshVolume uses for `image` (fog 0.5, level set 0 and inside negative, else
/// options.iso, required), checked to lie strictly between the image's values. Throws
/// PipelineInputError otherwise; `source` names the image in messages (its path).
std::pair<double, bool> pipelineIso(const ImageInfo& image, const std::optional<double>& iso,
                                    const std::string& source);

struct PipelineTimings {
    double downsample = 0; ///< seconds
    double metric = 0;     ///< border closing, metric, smoothing, NanoVDB conversion (Borders to Convert)
    double borders = 0, tensor = 0, smooth = 0, levels = 0, convert = 0; ///< the parts of `metric`
    double evolve = 0;     ///< the evolution (EvolutionStats::seconds)
    double analysis = 0;   ///< topology and self-intersection counts
};

struct PipelineResult {
    Mesh mesh;                          ///< world units, outward
    EvolutionStats evolution;           ///< per-iteration statistics and why it stopped
    StopReason stop = StopReason::Running; ///< Converged, IterationCap or Interrupted
    MeshTopology topology;              ///< of `mesh` (not computed when interrupted)
    std::size_t selfIntersections = 0;  ///< intersecting face pairs (0 for an embedded surface)
    double iso = 0;                     ///< the isovalue used
    bool objectBrighter = true;         ///< inside is above iso (false for level sets)
    std::uint64_t borderVoxels = 0;     ///< voxels added by border closing
    std::size_t sharpened = 0;          ///< vertices moved by --sharpen (0 when off or undone)
    std::size_t rimSplits = 0;          ///< thin-rim vertices split in two by the sharpening (SharpenStats)
    std::size_t creaseVertices = 0;     ///< vertices the sharpening added on creases (SharpenStats)
    std::size_t creaseFlips = 0;        ///< edges it flipped to run along creases
    int levels = 0;                     ///< coarse-to-fine levels used below the finest
    VolumeMetricStats metric;           ///< zero with the Euclidean metric
    ImageInfo image;                    ///< the image meshed (after downsampling)
    PipelineOptions options;            ///< the options used (without the progress callback)
    PipelineTimings seconds;
};

/// Meshes `volume` (which it changes: border closing, metric, smoothing; afterwards it holds the
/// image the model fitted and its metric, for Volume::writeMetric / exportNanoVDB). Throws
/// PipelineInputError for bad options, an iso outside the image's values, or a mesh past
/// options.maxVertices.
PipelineResult meshVolume(Volume& volume, const PipelineOptions& options);

/// Fills result.topology, selfIntersections and seconds.analysis from result.mesh: meshVolume does it
/// unless interrupted; call it to keep a mesh whose evolution was stopped early.
void analyseResult(PipelineResult& result);

/// What the caller adds to the statistics: its files, and the time it spent reading and writing.
struct PipelineRecord {
    std::optional<std::string> input, output; ///< file paths (null in the JSON when absent)
    double readSeconds = 0, writeSeconds = 0, totalSeconds = 0;
    std::optional<ReferenceError> reference; ///< compareToReference, when measured
};

/// vdb2mesh's --stats document as JSON text: input, output, image, parameters, metric (Riemannian
/// only), iterations (one object per iteration), summary (topology, stop reason, timings, operation
/// counts), reference (when measured).
std::string pipelineStatsJson(const PipelineResult& result, const PipelineRecord& record);

} // namespace riemesh::vdb
