// viewer/app.h: the viewer's state and user interface (Dear ImGui), without any GL.
//
// An App owns the volume (image + metric), the evolving mesh and its Evolution, the camera and the
// display settings. Each frame the main loop calls `frame()`: it advances the evolution for a bounded
// time, handles camera input and draws the ImGui panels; the renderer then reads `scene()`.
#pragma once

#include "riemesh/evolution.h"
#include "riemesh/image.h"
#include "riemesh/mesh.h"
#include "riemesh/metric.h"
#include "riemesh/sharpen.h"

#include <Eigen/Core>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace riemesh::viewer {

using Vec3f = Eigen::Vector3f;
using Mat4f = Eigen::Matrix4f;

/// Model parameters the user can change live; `defaults()` depends on the volume.
struct ModelParameters {
    double iso = 0.5;            ///< image intensity of the surface
    bool objectBrighter = true;  ///< object where I > iso
    double deltaVoxels = 3.0;    ///< shortest edge, metric length, voxels (as vdb2mesh)
    double zeta = 2.5;           ///< longest/shortest edge ratio
    double muScale = 1.0;        ///< metric eigenvalues become 1 + muScale * (mu - 1)
    bool riemannian = true;      ///< false: Euclidean metric (G = I)
    double externalWeight = 1.0; ///< inflation/deflation force
    double internalWeight = 0.3; ///< tangential umbrella
    double curvatureWeight = 0.05; ///< normal umbrella (smoothing)
    double gradientWeight = 0.0; ///< attraction to strong gradients
    int maxIterations = 3000;
    bool sharpen = true;         ///< creases and corners put back once converged (as vdb2mesh)
};

/// What colours the mesh.
enum class ColourMode { Shaded = 0, MetricEdgeLength = 1, LocalResolution = 2 };

/// Orbit camera around `target` (world space): yaw/pitch in radians, distance in world units.
struct Camera {
    Vec3f target = Vec3f::Zero();
    float yaw = 0.6f, pitch = 0.45f, distance = 100.f;
    float fovY = 0.8f; ///< radians
    Mat4f view() const;
    Mat4f projection(float aspect) const;
    Vec3f eye() const;
};

/// One axis-aligned slice of the image, as an RGBA8 texture spanning `corners` (world space).
struct SliceImage {
    int width = 0, height = 0;
    std::vector<std::uint8_t> rgba;
    Vec3f corners[4]; ///< (u0,v0) (u1,v0) (u1,v1) (u0,v1)
};

/// Everything the renderer draws, rebuilt by the App when something changed.
struct Scene {
    /// Mesh vertices: x y z nx ny nz r g b (world space, unit outward normal, colour in [0,1]).
    std::vector<float> vertices;
    /// Triangles (3 indices each) and edges (2 each) into `vertices`.
    std::vector<std::uint32_t> triangles, edges;
    /// The mesh's cross-section with the slice plane: per end x y z.
    std::vector<float> section;
    SliceImage slice;
    std::uint64_t meshVersion = 0, sliceVersion = 0;
    bool showMesh = true, wireframe = false, showSlice = true;
    /// Cut the mesh away on the eye's side of the slice (while the slice is shown), so that the
    /// image inside the surface can be seen with the cross-section on it.
    bool clipAtSlice = false;
    /// Mesh lighting: 0 automatic (per vertex when the mesh's edges are under 5 pixels on the screen,
    /// where it looks the same and costs software WebGL much less), 1 per pixel, 2 per vertex.
    int lighting = 0;
    Camera camera;
    Vec3f background{0.11f, 0.12f, 0.14f};
};

class App {
public:
    App();
    ~App();

    /// Loads a .nvdb volume (image + optional metric) and restarts on it. On failure the current state
    /// is kept and the message is shown in the UI; returns false.
    bool loadVolume(const std::string& path);
    /// The built-in analytic phantom (the paper's cube with a cavity opening through a hole), used
    /// when no .nvdb is available.
    void loadAnalyticPhantom();
    /// Restarts the evolution from the initial box with the current parameters.
    void reset();

    /// One frame: evolution (steps until `budgetMs` have passed, at least one), camera input, UI. `width`/`height` are the
    /// framebuffer size in pixels.
    void frame(double budgetMs, int width, int height);

    /// The main loop tells whether the frame it just finished was drawn (the page does not draw a
    /// frame that would show the same image as the last one): the panel's frame time is the interval
    /// between consecutive drawn frames, and "idle" when nothing has been drawn for a while.
    void frameShown(bool drawn);

    /// Runs without UI until the evolution stops (native `--headless`); returns the final stats line.
    std::string runToConvergence();

    /// A key went down (GLFW key code: 'F' frames the mesh, 'H' homes the camera, ' ' plays/pauses),
    /// handled by the next frame() unless ImGui has the keyboard.
    void keyPressed(int key) { mPendingKeys.push_back(key); }

    const Scene& scene() const { return mScene; }
    bool playing() const { return mPlaying; }
    void setPlaying(bool playing) { mPlaying = playing; }
    /// Set when the page should download `downloadPath()` (web) / has written it (native).
    std::optional<std::string> takeDownload();
    /// Writes the mesh as `extension` (".ply" or ".obj") for takeDownload(), named after the volume
    /// (phantom.nvdb: phantom.ply); what the Files panel's buttons do. False for another extension.
    bool exportMesh(const std::string& extension);
    const std::string& statusMessage() const { return mMessage; }

    /// The state as JSON (the page's JS API and tests): iteration, vertices, components, genus,
    /// playing, state ("evolving", "paused", "converged", ...), computeSeconds, frameMs (frame interval,
    /// smoothed, between consecutive drawn frames), cpuMs (the last frame's model + UI time on the main thread), volume.
    std::string stateJson() const;
    /// Sets a model parameter by name (iso, delta, zeta, mu_scale, riemannian, inflation, umbrella,
    /// curvature, gradient) or a display setting (colour: 0 shaded, 1 metric edge length, 2 local
    /// resolution; wireframe, show_mesh, show_slice: 0/1; slice_axis: 0..2; slice_position: 0..1;
    /// camera_yaw: radians; lighting: 0 automatic, 1 per pixel, 2 per vertex) as
    /// if changed in the UI; false for an unknown name.
    bool setParameter(const std::string& name, double value);

private:
    // the data
    std::string mVolumeName;
    std::unique_ptr<NanoVolume> mVolume;
    std::unique_ptr<ScalarImage> mImage;
    /// The coarse-to-fine levels the volume carries (riemesh_level_<l> grids), coarsest first.
    std::vector<std::unique_ptr<ScalarImage>> mCoarse;
    std::unique_ptr<MetricField> mVolumeMetric;   ///< as read (nullptr: none in the file)
    std::unique_ptr<MetricField> mMetric;         ///< what the evolution uses (scaled / Euclidean)
    double mImageMin = 0, mImageMax = 1;
    // the model
    ModelParameters mParams, mDefaults;
    Mesh mMesh;
    /// The converged mesh with its creases and corners put back (sharpenFeatures, as vdb2mesh does),
    /// shown, counted and exported instead of mMesh until the model evolves again.
    Mesh mSharpened;
    bool mShowSharpened = false;
    SharpenStats mSharpenStats;
    const Mesh& shownMesh() const { return mShowSharpened ? mSharpened : mMesh; }
    void sharpenConverged();
    void setSharpen(bool on); ///< the option, applied at once to a converged model
    std::unique_ptr<Evolution> mEvolution;
    bool mPlaying = true;
    bool mReported = false;
    double mComputeSeconds = 0;
    double mWallStart = 0;
    MeshTopology mTopology;
    int mTopologyEvents = 0, mTopologyCountdown = 0; ///< see updateTopology()
    int mMerges = 0, mCuts = 0;
    int mIterationBase = 0;            ///< iterations of previous Evolution objects (metric changes)
    int mIteration = 0;
    std::vector<float> mEnergyLog;     ///< log10 mean kinetic energy / delta^2 per iteration
    std::vector<float> mHistogram;     ///< edge metric length / delta, binned
    float mHistogramMax = 0;
    // display
    Scene mScene;
    // rebuildMeshGeometry()'s per-vertex work arrays, kept to reuse their memory
    std::vector<Vec3> mScratchPositions, mScratchNormals;
    std::vector<Mat3> mScratchMetric;
    std::vector<double> mScratchValues;
    std::vector<int> mScratchCounts;
    std::vector<std::uint32_t> mScratchIndex;
    ColourMode mColour = ColourMode::MetricEdgeLength;
    int mSliceAxis = 2;
    float mSlicePosition = 0.5f;       ///< fraction of the bounds along the axis
    float mWindow = 1.f, mLevel = 0.5f;
    bool mSliceDirty = true, mMeshDirty = true;
    bool mGeometryAtRest = false; ///< the scene's mesh was built while the model was not evolving
    int mStatsCountdown = 0;
    std::vector<int> mPendingKeys;
    std::string mMessage;
    std::optional<std::string> mDownload;
    double mLastFrameMs = 0;
    double mLastDrawnAt = -1, mFrameInterval = 0; ///< seconds; between consecutive drawn frames, smoothed
    double mDrawingAt = -1;  ///< when the last of two consecutive frames was drawn (seconds)
    bool mLastDrawn = false; ///< the last frame was drawn
    double mShownAt = -1, mShownIntervalMs = 0, mShownFrameMs = 0; ///< the figures the panel shows
    /// The model's figures the panel shows, refreshed at most every 0.2 s while the model evolves
    /// (see drawPanels()) and at every frame otherwise.
    struct PanelFigures {
        int iteration = 0, merges = 0, cuts = 0;
        int level = 0, levels = 1; ///< coarse-to-fine level being evolved (0: the finest) of levels
        int untangledAt = 0;       ///< Evolution::untangledAt(): evolved again with the guarantee after
        MeshTopology topology;
        double computeSeconds = 0;
        int energyCount = 0; ///< entries of mEnergyLog plotted
        std::vector<float> histogram;
        float histogramMax = 0;
    } mPanel;
    double mPanelAt = -1;

    void installVolume(std::unique_ptr<NanoVolume> volume, std::unique_ptr<ScalarImage> image,
                       std::unique_ptr<MetricField> metric, const std::string& name);
    void rebuildMetric();
    EvolutionOptions evolutionOptions() const;
    /// The schedule: the coarse levels, then the image itself.
    std::vector<EvolutionLevel> schedule() const;
    void advance(double budgetMs);
    void onStopped();
    void homeCamera();
    void frameCamera();
    void handleCameraInput(int width, int height);
    void rebuildMeshGeometry();
    void rebuildSlice();
    void updateTopology();
    void updateStatistics();
    void drawPanels();
    void applyParameters(bool metricChanged);
    const char* stateName() const;
};

/// Seconds on a monotonic clock (performance.now() in the browser).
double nowSeconds();

} // namespace riemesh::viewer
