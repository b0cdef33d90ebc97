#include "app.h"

#include "riemesh/mesh_io.h"

#include <imgui.h>

#include <algorithm>
#include <chrono>
#include <cfloat>
#include <cmath>
#include <cstdio>
#include <exception>
#include <fstream>

namespace riemesh::viewer {

double nowSeconds()
{
    using Clock = std::chrono::steady_clock;
    static const Clock::time_point start = Clock::now();
    return std::chrono::duration<double>(Clock::now() - start).count();
}

namespace {

/// G' = I + scale (G - I): eigenvalues 1 + scale (mu - 1), so the metric stays SPD with eigenvalues
/// >= 1 for any scale >= 0 (0: Euclidean, 1: the metric as computed).
class ScaledMetric final : public MetricField {
public:
    ScaledMetric(const MetricField& base, double scale) : mBase(base), mScale(scale) {}
    Mat3 at(const Vec3& x) const override
    {
        const Mat3 g = mBase.at(x);
        return Mat3::Identity() + mScale * (g - Mat3::Identity());
    }
    double maxEigenvalue() const override { return 1.0 + mScale * (mBase.maxEigenvalue() - 1.0); }

private:
    const MetricField& mBase;
    double mScale;
};

/// The paper's phantom as an analytic fog image, N = 100 unit voxels: a cube with a spherical cavity
/// opening through a small hole in its top (+z) face; 1 inside the object, 0 outside, a one-voxel
/// ramp across the surface (its 0.5 isosurface is the surface).
double phantomDistance(const Vec3& p)
{
    const Vec3 c(49.5, 49.5, 49.5);
    const Vec3 q = (p - c).cwiseAbs() - Vec3::Constant(30.0);
    const double cube = q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
    const double cavity = (p - c).norm() - 20.0;
    const double r = std::hypot(p.x() - c.x(), p.y() - c.y());
    const double hole = std::max(r - 5.0, c.z() - p.z()); // a half-infinite cylinder going up
    return std::max(cube, -std::min(cavity, hole));
}

/// A perceptual-ish blue-to-yellow colour map (viridis-like), t in [0,1].
Vec3f colourMap(float t)
{
    t = std::clamp(t, 0.f, 1.f);
    static const Vec3f stops[5] = {{0.267f, 0.005f, 0.329f}, {0.230f, 0.322f, 0.546f}, {0.128f, 0.567f, 0.551f},
                                   {0.369f, 0.789f, 0.383f}, {0.993f, 0.906f, 0.144f}};
    const float x = t * 4.f;
    const int i = std::min(3, int(x));
    const float f = x - float(i);
    return stops[i] * (1.f - f) + stops[i + 1] * f;
}

/// Reorders the scene's triangles along a Morton curve of their centroids and renumbers the vertices
/// in the order the triangles first use them: neighbouring triangles then share recently shaded
/// vertices (the vertex cache of SwiftShader, Chromium's software WebGL, is a direct-mapped one of 64
/// entries per batch of triangles), where OpenMesh's order after many splits and collapses is
/// scattered. Same triangles, same winding, same edges: the image does not change.
void reorderForLocality(Scene& s)
{
    const std::size_t nt = s.triangles.size() / 3, nv = s.vertices.size() / 9;
    if (nt == 0) return;
    float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
    for (std::size_t i = 0; i < nv; ++i)
        for (int k = 0; k < 3; ++k) {
            lo[k] = std::min(lo[k], s.vertices[9 * i + k]);
            hi[k] = std::max(hi[k], s.vertices[9 * i + k]);
        }
    auto spread = [](std::uint32_t x) {
        x &= 0x3ff;
        x = (x | (x << 16)) & 0x030000ff;
        x = (x | (x << 8)) & 0x0300f00f;
        x = (x | (x << 4)) & 0x030c30c3;
        x = (x | (x << 2)) & 0x09249249;
        return x;
    };
    std::vector<std::uint64_t> keyed(nt);
    for (std::size_t t = 0; t < nt; ++t) {
        std::uint32_t code = 0;
        for (int k = 0; k < 3; ++k) {
            float c = 0;
            for (int j = 0; j < 3; ++j) c += s.vertices[9 * s.triangles[3 * t + j] + k];
            const float u = (c / 3 - lo[k]) / std::max(hi[k] - lo[k], 1e-9f);
            code |= spread(std::uint32_t(std::clamp(u, 0.f, 1.f) * 1023.f)) << k;
        }
        keyed[t] = (std::uint64_t(code) << 32) | t;
    }
    std::sort(keyed.begin(), keyed.end());
    std::vector<std::uint32_t> remap(nv, ~0u), tris(3 * nt);
    std::uint32_t next = 0;
    for (std::size_t i = 0; i < nt; ++i) {
        const std::size_t t = keyed[i] & 0xffffffffu;
        for (int j = 0; j < 3; ++j) {
            std::uint32_t& r = remap[s.triangles[3 * t + j]];
            if (r == ~0u) r = next++;
            tris[3 * i + j] = r;
        }
    }
    for (auto& r : remap) if (r == ~0u) r = next++;
    std::vector<float> verts(s.vertices.size());
    for (std::size_t i = 0; i < nv; ++i) std::copy_n(&s.vertices[9 * i], 9, &verts[9 * remap[i]]);
    s.vertices.swap(verts);
    s.triangles.swap(tris);
    for (auto& e : s.edges) e = remap[e];
}

/// Greyed text wrapped at the panel's width.
void textDisabledWrapped(const char* text)
{
    ImGui::PushStyleColor(ImGuiCol_Text, ImGui::GetStyleColorVec4(ImGuiCol_TextDisabled));
    ImGui::TextWrapped("%s", text);
    ImGui::PopStyleColor();
}

const char* kColourNames[] = {"shaded", "metric edge length", "local resolution"};
const char* kAxisNames[] = {"x", "y", "z"};

} // namespace

Vec3f Camera::eye() const
{
    const Vec3f dir(std::cos(pitch) * std::cos(yaw), std::cos(pitch) * std::sin(yaw), std::sin(pitch));
    return target + distance * dir;
}

Mat4f Camera::view() const
{
    const Vec3f e = eye();
    const Vec3f f = (target - e).normalized();
    const Vec3f s = f.cross(Vec3f(0, 0, 1)).normalized();
    const Vec3f u = s.cross(f);
    Mat4f m = Mat4f::Identity();
    m.block<1, 3>(0, 0) = s.transpose();
    m.block<1, 3>(1, 0) = u.transpose();
    m.block<1, 3>(2, 0) = -f.transpose();
    m(0, 3) = -s.dot(e);
    m(1, 3) = -u.dot(e);
    m(2, 3) = f.dot(e);
    return m;
}

Mat4f Camera::projection(float aspect) const
{
    const float n = distance * 0.01f, fa = distance * 10.f;
    const float t = 1.f / std::tan(fovY / 2);
    Mat4f m = Mat4f::Zero();
    m(0, 0) = t / aspect;
    m(1, 1) = t;
    m(2, 2) = (fa + n) / (n - fa);
    m(2, 3) = 2 * fa * n / (n - fa);
    m(3, 2) = -1;
    return m;
}

App::App() = default;
App::~App() = default;

void App::installVolume(std::unique_ptr<NanoVolume> volume, std::unique_ptr<ScalarImage> image,
                        std::unique_ptr<MetricField> metric, const std::string& name)
{
    mEvolution.reset(); // holds references to the old image and metric
    mVolume = std::move(volume);
    mImage = std::move(image);
    mCoarse.clear();
    if (mVolume)
        for (int l = mVolume->levelCount(); l >= 1; --l) mCoarse.push_back(std::make_unique<NanoImage>(mVolume->levelGrid(l)));
    mVolumeMetric = std::move(metric);
    mVolumeName = name;

    // Intensity range from a coarse sampling of the box (window/level defaults).
    const Box3 b = mImage->bounds();
    mImageMin = 1e300;
    mImageMax = -1e300;
    const int n = 24;
    for (int k = 0; k <= n; ++k)
        for (int j = 0; j <= n; ++j)
            for (int i = 0; i <= n; ++i) {
                const Vec3 t(double(i) / n, double(j) / n, double(k) / n);
                const double v = mImage->value(b.min() + t.cwiseProduct(b.sizes()));
                mImageMin = std::min(mImageMin, v);
                mImageMax = std::max(mImageMax, v);
            }
    if (!(mImageMax > mImageMin)) mImageMax = mImageMin + 1;
    mWindow = float(mImageMax - mImageMin);
    mLevel = float(0.5 * (mImageMax + mImageMin));

    ModelParameters d;
    const std::string cls = mVolume ? mVolume->imageClass() : "fog";
    if (cls == "levelset") {
        d.iso = 0.0;
        d.objectBrighter = false; // inside is negative
    } else if (cls == "fog") {
        d.iso = 0.5;
    } else {
        d.iso = 0.5 * (mImageMin + mImageMax);
    }
    if (mVolume && mVolume->hasIso()) d.iso = mVolume->iso(); // vdb2mesh --iso V --export-nvdb
    d.riemannian = mVolumeMetric != nullptr;
    mDefaults = d;
    mParams = d;
    mSlicePosition = 0.5f;
    homeCamera();
    reset();
}

bool App::loadVolume(const std::string& path)
{
    try {
        auto volume = std::make_unique<NanoVolume>(NanoVolume::read(path));
        auto image = std::make_unique<NanoImage>(volume->imageGrid());
        std::unique_ptr<MetricField> metric;
        if (volume->metricDiag())
            metric = std::make_unique<NanoMetric>(volume->metricDiag(), volume->metricOff(),
                                                  volume->metricMaxEigenvalue());
        const std::string name = path.substr(path.find_last_of('/') + 1);
        installVolume(std::move(volume), std::move(image), std::move(metric), name);
        mMessage.clear();
        std::printf("riemesh: loaded %s (%s, grid '%s'%s)\n", name.c_str(), mVolume->imageClass().c_str(),
                    mVolume->imageName().c_str(), mVolumeMetric ? ", with metric" : ", no metric");
        return true;
    } catch (const std::exception& e) {
        // Named as the user knows the file: a dropped file's place in the page's file system
        // (/.glfw_dropped_files/...) means nothing to them.
        const std::string name = path.substr(path.find_last_of('/') + 1);
        std::string why = e.what();
        for (std::size_t at; (at = why.find(path)) != std::string::npos;) why.replace(at, path.size(), name);
        mMessage = "Cannot open " + name + ": " + why;
        std::fprintf(stderr, "riemesh: %s\n", mMessage.c_str());
        return false;
    }
}

void App::loadAnalyticPhantom()
{
    auto image = std::make_unique<FunctionImage>(
        [](const Vec3& p) { return std::clamp(0.5 - phantomDistance(p), 0.0, 1.0); },
        Box3(Vec3::Zero(), Vec3::Constant(99.0)), 1.0);
    installVolume(nullptr, std::move(image), nullptr, "analytic phantom (no .nvdb found)");
}

void App::rebuildMetric()
{
    if (mParams.riemannian && mVolumeMetric) {
        if (mParams.muScale == 1.0)
            mMetric = std::make_unique<ScaledMetric>(*mVolumeMetric, 1.0);
        else
            mMetric = std::make_unique<ScaledMetric>(*mVolumeMetric, std::max(0.0, mParams.muScale));
    } else {
        mMetric = std::make_unique<EuclideanMetric>();
    }
}

EvolutionOptions App::evolutionOptions() const
{
    EvolutionOptions o;
    o.delta = mParams.deltaVoxels * mImage->voxelSize();
    o.zeta = mParams.zeta;
    o.maxIterations = mParams.maxIterations;
    o.forces.iso = mParams.iso;
    o.forces.objectBrighter = mParams.objectBrighter;
    o.forces.externalWeight = mParams.externalWeight;
    o.forces.internalWeight = mParams.internalWeight;
    o.forces.curvatureWeight = mParams.curvatureWeight;
    o.forces.gradientWeight = mParams.gradientWeight;
    return o;
}

std::vector<EvolutionLevel> App::schedule() const
{
    std::vector<EvolutionLevel> levels;
    const int n = int(mCoarse.size());
    for (int i = 0; i < n; ++i) levels.push_back({mCoarse[i].get(), std::ldexp(1.0, n - i)});
    levels.push_back({mImage.get(), 1.0});
    return levels;
}

void App::reset()
{
    if (!mImage) return;
    mEvolution.reset();
    rebuildMetric();
    const EvolutionOptions o = evolutionOptions();
    try {
        const double scale = schedule().front().scale;
        mMesh = makeInitialBox(*mImage, 0.5 * (1.0 + o.zeta) * o.delta * scale, scale > 1 ? 2.0 * scale * mImage->voxelSize() : 0.0);
    } catch (const std::exception& e) {
        mMessage = std::string("Cannot initialise: ") + e.what();
        mMesh = Mesh();
        return;
    }
    mShowSharpened = false;
    mEvolution = std::make_unique<Evolution>(mMesh, schedule(), *mMetric, o);
    mIterationBase = 0;
    mIteration = 0;
    mComputeSeconds = 0;
    mWallStart = nowSeconds();
    mReported = false;
    mMerges = mCuts = 0;
    mEnergyLog.clear();
    mMeshDirty = mSliceDirty = true;
    mStatsCountdown = 0;
    mTopology = topologyOf(mMesh);
    updateStatistics();
}

void App::advance(double budgetMs)
{
    if (!mEvolution || !mPlaying || mEvolution->done()) return;
    mShowSharpened = false; // evolving again: the model's own mesh
    const double start = nowSeconds();
    do {
        const IterationStats s = mEvolution->step();
        mIteration = mIterationBase + int(mEvolution->history().size());
        mComputeSeconds += s.milliseconds * 1e-3;
        mMerges += s.merges;
        mCuts += s.cuts;
        const double delta2 = std::pow(evolutionOptions().delta, 2);
        mEnergyLog.push_back(float(std::log10(s.meanKineticEnergy / delta2 + 1e-12)));
        mMeshDirty = true;
    } while (!mEvolution->done() && (nowSeconds() - start) * 1e3 < budgetMs);
    if (mEvolution->done()) onStopped();
}

void App::onStopped()
{
    if (mReported) return;
    mReported = true;
    const MeshTopology t = topologyOf(mMesh);
    const StopReason r = mEvolution->reason();
    if (r == StopReason::Converged) {
        std::printf("riemesh: converged iterations=%d vertices=%zu seconds=%.3f\n", mIteration, t.vertices,
                    mComputeSeconds);
    } else {
        std::printf("riemesh: stopped (%s) iterations=%d vertices=%zu seconds=%.3f\n", toString(r), mIteration,
                    t.vertices, mComputeSeconds);
    }
    std::printf("riemesh: components=%d genus=%d merges=%d cuts=%d wall_seconds=%.3f\n", t.components, t.genus,
                mMerges, mCuts, nowSeconds() - mWallStart);
    if (r == StopReason::Converged && mParams.sharpen) sharpenConverged();
    std::fflush(stdout);
}

void App::setSharpen(bool on)
{
    mParams.sharpen = on;
    const bool converged = mEvolution && mEvolution->reason() == StopReason::Converged;
    if (on && converged && !mShowSharpened) {
        sharpenConverged();
    } else if (!on && mShowSharpened) {
        mShowSharpened = false;
        mMeshDirty = true;
        mTopology = topologyOf(mMesh);
    }
}

void App::sharpenConverged()
{
    // As vdb2mesh does: on a copy, kept only if it adds no crossing of the surface.
    mSharpened = mMesh;
    mSharpened.garbage_collection(); // (the evolution's deleted elements: counted by n_vertices())
    const double start = nowSeconds();
    mSharpenStats = sharpenFeaturesEmbedded(mSharpened, imageSharpenOptions(*mImage, mParams.iso, mParams.objectBrighter));
    mShowSharpened = mSharpenStats.moved > 0;
    mMeshDirty = true;
    mTopology = topologyOf(shownMesh());
    std::printf("riemesh: sharpened moved=%zu rim_splits=%zu crease_vertices=%zu vertices=%zu seconds=%.3f\n",
                mSharpenStats.moved, mSharpenStats.rimSplits, mSharpenStats.creaseVertices, mTopology.vertices,
                nowSeconds() - start);
}

std::string App::runToConvergence()
{
    mPlaying = true;
    while (mEvolution && !mEvolution->done()) advance(1e9);
    return mEvolution ? toString(mEvolution->reason()) : "no model";
}

void App::homeCamera()
{
    if (!mImage) return;
    const Box3 b = mImage->bounds();
    mScene.camera.target = b.center().cast<float>();
    mScene.camera.distance = float(1.6 * b.diagonal().norm());
    mScene.camera.yaw = -1.1f;
    mScene.camera.pitch = 0.5f;
}

void App::frameCamera()
{
    const Mesh& mesh = shownMesh();
    if (mesh.n_vertices() == 0) return homeCamera();
    Box3 b;
    for (auto v : mesh.vertices()) b.extend(position(mesh, v));
    mScene.camera.target = b.center().cast<float>();
    mScene.camera.distance = float(std::max(1.0, 1.5 * b.diagonal().norm()));
}

void App::handleCameraInput(int width, int height)
{
    ImGuiIO& io = ImGui::GetIO();
    Camera& c = mScene.camera;
    if (!io.WantCaptureMouse) {
        const ImVec2 d = io.MouseDelta;
        if (ImGui::IsMouseDown(ImGuiMouseButton_Left) && !io.KeyShift) {
            c.yaw -= d.x * 0.008f;
            c.pitch = std::clamp(c.pitch + d.y * 0.008f, -1.55f, 1.55f);
        } else if (ImGui::IsMouseDown(ImGuiMouseButton_Right) || ImGui::IsMouseDown(ImGuiMouseButton_Middle) ||
                   (ImGui::IsMouseDown(ImGuiMouseButton_Left) && io.KeyShift)) {
            const Mat4f v = c.view();
            const Vec3f right = v.block<1, 3>(0, 0).transpose(), up = v.block<1, 3>(1, 0).transpose();
            const float scale = 2.f * c.distance * std::tan(c.fovY / 2) / float(std::max(1, height));
            c.target += (-d.x * right + d.y * up) * scale;
        }
        if (io.MouseWheel != 0) c.distance *= std::pow(0.88f, io.MouseWheel);
    }
    // Shortcuts from the queued key presses (keyPressed()), not from ImGui's key state: a press and
    // release between two frames (a quick tap, or an idle page that does not draw) leave no trace in
    // ImGui 1.86's KeysDown.
    for (const int key : mPendingKeys) {
        if (io.WantCaptureKeyboard) break;
        if (key == 'F') frameCamera();
        else if (key == 'H') homeCamera();
        else if (key == ' ') mPlaying = !mPlaying;
    }
    mPendingKeys.clear();
    (void)width;
}

void App::rebuildMeshGeometry()
{
    // One pass over the faces (triangles, area-weighted normals, cross-section) and one over the edges
    // (edge lengths for the colour), instead of circulating around every vertex: the same values as
    // vertexNormal() and the per-vertex means of before, for a fraction of the time (12 -> 4.5 ms per
    // rebuild at 20k vertices in WebAssembly), which matters since it runs every frame while evolving.
    Scene& s = mScene;
    const Mesh& mesh = shownMesh();
    const std::size_t nv = mesh.n_vertices();
    auto& pos = mScratchPositions;
    auto& nrm = mScratchNormals;
    auto& value = mScratchValues;
    auto& count = mScratchCounts;
    auto& index = mScratchIndex;
    pos.resize(nv);
    nrm.assign(nv, Vec3::Zero());
    index.assign(nv, 0);
    std::uint32_t n = 0;
    for (auto v : mesh.vertices()) {
        index[v.idx()] = n++;
        pos[v.idx()] = position(mesh, v);
    }

    s.triangles.resize(std::size_t(3) * mesh.n_faces());
    s.section.clear();
    const Box3 bounds = mImage->bounds();
    const double plane = bounds.min()[mSliceAxis] + mSlicePosition * bounds.sizes()[mSliceAxis];
    std::size_t t = 0;
    for (auto f : mesh.faces()) {
        // fv_range order: to(h), to(next h), to(next next h) = from(h), with h the face's halfedge.
        const auto h0 = mesh.halfedge_handle(f);
        const auto h1 = mesh.next_halfedge_handle(h0);
        const int iv[3] = {mesh.to_vertex_handle(h0).idx(), mesh.to_vertex_handle(h1).idx(),
                           mesh.from_vertex_handle(h0).idx()};
        const Vec3 p[3] = {pos[iv[0]], pos[iv[1]], pos[iv[2]]};
        // vertexNormal(): sum of (b - a) x (c - a) with a = from(h), b = to(h), c = to(next h).
        const Vec3 fn = (p[0] - p[2]).cross(p[1] - p[2]);
        for (int k = 0; k < 3; ++k) {
            nrm[iv[k]] += fn;
            s.triangles[t++] = index[iv[k]];
        }
        // Cross-section with the slice plane.
        const double d[3] = {p[0][mSliceAxis] - plane, p[1][mSliceAxis] - plane, p[2][mSliceAxis] - plane};
        const std::size_t before = s.section.size();
        for (int i = 0; i < 3; ++i) {
            const int j = (i + 1) % 3;
            if ((d[i] < 0) != (d[j] < 0)) {
                const Vec3 x = p[i] + (d[i] / (d[i] - d[j])) * (p[j] - p[i]);
                s.section.insert(s.section.end(), {float(x.x()), float(x.y()), float(x.z())});
            }
        }
        if (s.section.size() - before == 3) s.section.resize(before); // a vertex on the plane
    }
    s.triangles.resize(t);

    // Mean length of the edges around each vertex, measured with the metric at the vertex (metric edge
    // length) or Euclidean (local resolution), over delta.
    s.edges.resize(std::size_t(2) * mesh.n_edges());
    std::size_t k = 0;
    const bool coloured = mColour != ColourMode::Shaded;
    if (coloured) {
        value.assign(nv, 0.0);
        count.assign(nv, 0);
        if (mColour == ColourMode::MetricEdgeLength) {
            mScratchMetric.resize(nv);
            for (auto v : mesh.vertices()) mScratchMetric[v.idx()] = mMetric->at(pos[v.idx()]);
        }
    }
    for (auto e : mesh.edges()) {
        const auto h = mesh.halfedge_handle(e, 0);
        const int a = mesh.from_vertex_handle(h).idx(), b = mesh.to_vertex_handle(h).idx();
        s.edges[k++] = index[a];
        s.edges[k++] = index[b];
        if (!coloured) continue;
        const Vec3 d = pos[b] - pos[a];
        if (mColour == ColourMode::MetricEdgeLength) {
            value[a] += std::sqrt(d.dot(mScratchMetric[a] * d));
            value[b] += std::sqrt(d.dot(mScratchMetric[b] * d));
        } else {
            const double l = std::sqrt(d.dot(d));
            value[a] += l;
            value[b] += l;
        }
        ++count[a];
        ++count[b];
    }
    s.edges.resize(k);
    const double delta = evolutionOptions().delta;
    float lo = 1e30f, hi = -1e30f;
    if (coloured)
        for (auto v : mesh.vertices()) {
            const int i = v.idx();
            const float x = count[i] ? float(value[i] / count[i] / delta) : 0.f;
            value[i] = x;
            lo = std::min(lo, x);
            hi = std::max(hi, x);
        }
    // Metric edge length: fixed scale [1, zeta] (the regularity band); local resolution: the mesh's range.
    float a = 1.f, b = float(mParams.zeta);
    if (mColour == ColourMode::LocalResolution) {
        a = lo;
        b = std::max(hi, lo + 1e-6f);
    }
    s.vertices.resize(std::size_t(n) * 9);
    float* out = s.vertices.data();
    for (auto v : mesh.vertices()) {
        const int i = v.idx();
        const Vec3& p = pos[i];
        const double len = nrm[i].norm();
        const Vec3 u = len > 0 ? Vec3(nrm[i] / len) : Vec3::Zero();
        const Vec3f col = coloured ? colourMap((float(value[i]) - a) / (b - a)) : Vec3f(0.85f, 0.72f, 0.55f);
        const float f[9] = {float(p.x()), float(p.y()), float(p.z()), float(u.x()), float(u.y()),
                            float(u.z()), col.x(), col.y(), col.z()};
        std::copy(f, f + 9, out);
        out += 9;
    }
    // A mesh at rest is drawn again and again (camera moves, UI): worth ordering it for the vertex
    // cache (-10% draw time at 19.5k vertices in software WebGL); while evolving it is drawn once
    // per rebuild and the sort would cost about what it saves.
    mGeometryAtRest = !(mPlaying && mEvolution && !mEvolution->done());
    if (mGeometryAtRest) reorderForLocality(s);
    ++s.meshVersion;
    mMeshDirty = false;
}

void App::rebuildSlice()
{
    SliceImage& sl = mScene.slice;
    const Box3 b = mImage->bounds();
    const int ua = (mSliceAxis + 1) % 3, va = (mSliceAxis + 2) % 3;
    const double h = mImage->voxelSize();
    sl.width = std::clamp(int(b.sizes()[ua] / h) + 1, 2, 256);
    sl.height = std::clamp(int(b.sizes()[va] / h) + 1, 2, 256);
    sl.rgba.resize(std::size_t(sl.width) * sl.height * 4);
    const double w = b.min()[mSliceAxis] + mSlicePosition * b.sizes()[mSliceAxis];
    const float lo = mLevel - 0.5f * mWindow, span = std::max(1e-12f, mWindow);
    for (int j = 0; j < sl.height; ++j)
        for (int i = 0; i < sl.width; ++i) {
            Vec3 p;
            p[mSliceAxis] = w;
            p[ua] = b.min()[ua] + b.sizes()[ua] * (double(i) / (sl.width - 1));
            p[va] = b.min()[va] + b.sizes()[va] * (double(j) / (sl.height - 1));
            const float t = std::clamp((float(mImage->value(p)) - lo) / span, 0.f, 1.f);
            const auto g = std::uint8_t(std::lround(255 * t));
            std::uint8_t* px = &sl.rgba[(std::size_t(j) * sl.width + i) * 4];
            px[0] = px[1] = px[2] = g;
            px[3] = 255;
        }
    auto corner = [&](double u, double v) {
        Vec3 p;
        p[mSliceAxis] = w;
        p[ua] = u;
        p[va] = v;
        return Vec3f(p.cast<float>());
    };
    sl.corners[0] = corner(b.min()[ua], b.min()[va]);
    sl.corners[1] = corner(b.max()[ua], b.min()[va]);
    sl.corners[2] = corner(b.max()[ua], b.max()[va]);
    sl.corners[3] = corner(b.min()[ua], b.max()[va]);
    ++mScene.sliceVersion;
    mSliceDirty = false;
}

void App::updateTopology()
{
    // Components need a traversal of the mesh (~2 ms at 20k vertices in WebAssembly). Only merges and
    // cuts change them (the other operations keep the topology), so while evolving they are counted
    // again after such an event, every 10th rebuild and whenever the model stops; in between the
    // counts come from the geometry just rebuilt and the genus from the Euler characteristic.
    const int events = mMerges + mCuts;
    const bool running = mPlaying && mEvolution && !mEvolution->done();
    if (!running || events != mTopologyEvents || --mTopologyCountdown <= 0) {
        mTopology = topologyOf(shownMesh());
        mTopologyEvents = events;
        mTopologyCountdown = 10;
        return;
    }
    MeshTopology& t = mTopology;
    t.vertices = mScene.vertices.size() / 9;
    t.edges = mScene.edges.size() / 2;
    t.faces = mScene.triangles.size() / 3;
    t.euler = int(t.vertices) - int(t.edges) + int(t.faces);
    t.genus = (2 * t.components - t.euler) / 2;
}

void App::updateStatistics()
{
    // Histogram of metric edge lengths / delta over [0, 1.5 zeta].
    const int bins = 40;
    mHistogram.assign(bins, 0.f);
    const Mesh& mesh = shownMesh();
    if (!mMetric || mesh.n_edges() == 0) return;
    const double delta = evolutionOptions().delta, top = 1.5 * mParams.zeta;
    for (auto e : mesh.edges()) {
        const double l = metricLength(*mMetric, mesh, e) / delta;
        const int bin = std::clamp(int(l / top * bins), 0, bins - 1);
        mHistogram[bin] += 1.f;
    }
    mHistogramMax = *std::max_element(mHistogram.begin(), mHistogram.end());
}

std::optional<std::string> App::takeDownload()
{
    auto d = std::move(mDownload);
    mDownload.reset();
    return d;
}

bool App::exportMesh(const std::string& extension)
{
    if (extension != ".ply" && extension != ".obj") return false;
    // Named after the volume (phantom.nvdb: phantom.ply), or riemesh-mesh for the analytic phantom.
    std::string stem = mVolume ? mVolumeName.substr(0, mVolumeName.find_last_of('.')) : std::string();
    for (char& c : stem)
        if (c == '/' || c == '\\' || c == '"') c = '_';
    if (stem.empty()) stem = "riemesh-mesh";
#ifdef __EMSCRIPTEN__
    const std::string path = "/tmp/" + stem + extension;
#else
    const std::string path = stem + extension;
#endif
    try {
        writeMesh(path, shownMesh(), "riemesh viewer, " + mVolumeName);
        mDownload = path;
        mMessage = "Wrote " + path;
    } catch (const std::exception& e) {
        mMessage = std::string("Cannot write the mesh: ") + e.what();
    }
    return true;
}

void App::drawPanels()
{
    // The panel fits its content as sections open and close (up to the window's height, then it
    // scrolls), 340 pixels wide.
    ImGui::SetNextWindowPos(ImVec2(8, 8), ImGuiCond_FirstUseEver);
    const float tallest = std::max(120.f, ImGui::GetIO().DisplaySize.y - 16.f);
    ImGui::SetNextWindowSizeConstraints(ImVec2(340, 0), ImVec2(340, tallest));
    ImGui::Begin("riemesh", nullptr, ImGuiWindowFlags_AlwaysAutoResize);
    ImGui::TextWrapped("%s", mVolumeName.c_str());
    if (!mMessage.empty()) {
        ImGui::PushStyleColor(ImGuiCol_Text, ImVec4(1.f, 0.45f, 0.35f, 1.f));
        ImGui::TextWrapped("%s", mMessage.c_str());
        ImGui::PopStyleColor();
    }

    // --- run controls
    if (ImGui::Button(mPlaying ? "Pause" : "Play", ImVec2(60, 0))) mPlaying = !mPlaying;
    ImGui::SameLine();
    if (ImGui::Button("Step", ImVec2(60, 0)) && mEvolution) {
        // Step pauses: one iteration, then wait.
        mPlaying = true;
        if (mEvolution->done()) mEvolution->setOptions(evolutionOptions());
        advance(0.0);
        mPlaying = false;
    }
    ImGui::SameLine();
    if (ImGui::Button("Reset", ImVec2(60, 0))) reset();

    // While the model evolves its figures and plots change at every step: shown as they are every
    // 0.2 s, so that the panel's image stays the same in between and the frames in between draw it
    // from its layer (main.cpp) instead of redrawing its glyphs.
    const bool evolving = mPlaying && mEvolution && !mEvolution->done();
    if (!evolving || nowSeconds() - mPanelAt >= 0.2) {
        mPanelAt = nowSeconds();
        mPanel.iteration = mIteration;
        mPanel.level = mEvolution ? mEvolution->level() : 0;
        mPanel.levels = mEvolution ? mEvolution->levels() : 1;
        mPanel.untangledAt = mEvolution ? mEvolution->untangledAt() : 0;
        mPanel.merges = mMerges;
        mPanel.cuts = mCuts;
        mPanel.topology = mTopology;
        mPanel.computeSeconds = mComputeSeconds;
        mPanel.energyCount = int(mEnergyLog.size());
        mPanel.histogram = mHistogram;
        mPanel.histogramMax = mHistogramMax;
    }
    const PanelFigures& p = mPanel;
    if (p.levels > 1)
        ImGui::Text("iteration %d  level %d of %d  (%s)", p.iteration, p.levels - p.level, p.levels, stateName());
    else
        ImGui::Text("iteration %d  (%s)", p.iteration, stateName());
    if (p.untangledAt > 0) ImGui::Text("tangled at %d: again, intersection-free", p.untangledAt);
    ImGui::Text("vertices %zu  faces %zu", p.topology.vertices, p.topology.faces);
    ImGui::Text("components %d  genus %d", p.topology.components, p.topology.genus);
    ImGui::Text("merges %d  cuts %d  compute %.2f s", p.merges, p.cuts, p.computeSeconds);
    if (mShowSharpened)
        ImGui::Text("sharpened: %zu vertices moved, %zu added", mSharpenStats.moved,
                    mSharpenStats.rimSplits + mSharpenStats.creaseVertices);
    // Refreshed twice a second: a number that changes every frame would make every frame a new image
    // (the page does not draw a frame that shows the same image as the last one).
    if (nowSeconds() - mShownAt >= 0.5) {
        mShownAt = nowSeconds();
        mShownIntervalMs = mFrameInterval * 1e3;
        mShownFrameMs = mLastFrameMs;
    }
    // The interval between drawn frames while frames are drawn; an idle page draws nothing (the
    // interval between its rare redraws would say nothing about the time a frame takes).
    if (nowSeconds() - mDrawingAt < 0.5)
        ImGui::Text("frame %.0f ms (model + UI %.0f ms)", mShownIntervalMs, mShownFrameMs);
    else
        ImGui::Text("frame: idle (model + UI %.0f ms)", mShownFrameMs);
    if (mColour == ColourMode::MetricEdgeLength)
        textDisabledWrapped("colour: metric edge length / delta, 1 (purple) .. zeta (yellow)");
    else if (mColour == ColourMode::LocalResolution)
        textDisabledWrapped("colour: edge length in voxels, fine (purple) .. coarse (yellow)");

    // --- plots
    if (ImGui::CollapsingHeader("Plots", ImGuiTreeNodeFlags_DefaultOpen)) {
        const int n = std::min(p.energyCount, int(mEnergyLog.size()));
        const int shown = std::min(n, 400);
        char overlay[64];
        std::snprintf(overlay, sizeof overlay, "log10 E/delta^2 = %.2f", n ? mEnergyLog[n - 1] : 0.f);
        const float plotWidth = ImGui::GetWindowWidth() - 2 * ImGui::GetStyle().WindowPadding.x;
        ImGui::PlotLines("##energy", mEnergyLog.data() + (n - shown), shown, 0, overlay, FLT_MAX, FLT_MAX, ImVec2(plotWidth, 60));
        ImGui::TextDisabled("mean kinetic energy per iteration");
        ImGui::PlotHistogram("##lengths", p.histogram.data(), int(p.histogram.size()), 0, "edge length / delta",
                             0.f, p.histogramMax * 1.1f, ImVec2(plotWidth, 50));
        textDisabledWrapped("0 .. 1.5 zeta; the band [1, zeta] is the regular one");
    }

    // --- parameters
    bool changed = false, metricChanged = false;
    // Closed at first: a shorter panel costs less to put over every frame in software WebGL.
    if (ImGui::CollapsingHeader("Model")) {
        const double isoLo = mImageMin, isoHi = mImageMax;
        changed |= ImGui::SliderScalar("iso", ImGuiDataType_Double, &mParams.iso, &isoLo, &isoHi, "%.3f");
        const double dLo = 0.5, dHi = 8, zLo = 2.0, zHi = 5.0, mLo = 0, mHi = 2, wLo = 0, wHi = 2, cHi = 0.5;
        changed |= ImGui::SliderScalar("delta (voxels)", ImGuiDataType_Double, &mParams.deltaVoxels, &dLo, &dHi, "%.2f");
        changed |= ImGui::SliderScalar("zeta", ImGuiDataType_Double, &mParams.zeta, &zLo, &zHi, "%.2f");
        if (!mVolumeMetric) ImGui::BeginDisabled();
        metricChanged |= ImGui::Checkbox("Riemannian metric", &mParams.riemannian);
        metricChanged |= ImGui::SliderScalar("mu_max scale", ImGuiDataType_Double, &mParams.muScale, &mLo, &mHi, "%.2f");
        if (!mVolumeMetric) ImGui::EndDisabled();
        changed |= ImGui::SliderScalar("inflation", ImGuiDataType_Double, &mParams.externalWeight, &wLo, &wHi, "%.2f");
        changed |= ImGui::SliderScalar("umbrella", ImGuiDataType_Double, &mParams.internalWeight, &wLo, &wHi, "%.2f");
        changed |= ImGui::SliderScalar("curvature", ImGuiDataType_Double, &mParams.curvatureWeight, &wLo, &cHi, "%.3f");
        changed |= ImGui::SliderScalar("gradient", ImGuiDataType_Double, &mParams.gradientWeight, &wLo, &wHi, "%.2f");
        changed |= ImGui::Checkbox("object brighter than iso", &mParams.objectBrighter);
        // Applies to the converged mesh as it is: no evolution again.
        bool sharpen = mParams.sharpen;
        if (ImGui::Checkbox("sharpen creases when converged", &sharpen)) setSharpen(sharpen);
        if (mShowSharpened)
            textDisabledWrapped((std::to_string(mSharpenStats.moved) + " vertices sharpened (" +
                                 std::to_string(mSharpenStats.rimSplits) + " rim splits, " +
                                 std::to_string(mSharpenStats.creaseVertices) + " on creases)")
                                    .c_str());
        if (ImGui::Button("Defaults")) {
            metricChanged |= mParams.riemannian != mDefaults.riemannian || mParams.muScale != mDefaults.muScale;
            mParams = mDefaults;
            changed = true;
        }
    }
    if (metricChanged || changed) applyParameters(metricChanged);

    // --- display
    if (ImGui::CollapsingHeader("Display")) {
        int colour = int(mColour);
        if (ImGui::Combo("colour", &colour, kColourNames, 3)) {
            mColour = ColourMode(colour);
            mMeshDirty = true;
        }
        ImGui::Checkbox("mesh", &mScene.showMesh);
        ImGui::SameLine();
        ImGui::Checkbox("wireframe", &mScene.wireframe);
        ImGui::SameLine();
        ImGui::Checkbox("slice", &mScene.showSlice);
        ImGui::Checkbox("cut the mesh at the slice", &mScene.clipAtSlice);
        bool slice = ImGui::Combo("slice axis", &mSliceAxis, kAxisNames, 3);
        slice |= ImGui::SliderFloat("slice position", &mSlicePosition, 0.f, 1.f, "%.2f");
        const float range = float(mImageMax - mImageMin);
        slice |= ImGui::DragFloat("window", &mWindow, range * 0.005f, range * 0.001f, range * 4.f, "%.3f");
        slice |= ImGui::DragFloat("level", &mLevel, range * 0.005f, float(mImageMin) - range, float(mImageMax) + range, "%.3f");
        if (slice) mSliceDirty = mMeshDirty = true;
        if (ImGui::Button("Frame (F)")) frameCamera();
        ImGui::SameLine();
        if (ImGui::Button("Home (H)")) homeCamera();
        textDisabledWrapped("drag: orbit  right/shift-drag: pan  wheel: zoom");
    }

    // --- files
    if (ImGui::CollapsingHeader("Files")) {
        ImGui::TextWrapped("Drop a .nvdb made by `vdb2mesh --export-nvdb` on the window to segment it.");
        if (ImGui::Button("Download PLY")) exportMesh(".ply");
        ImGui::SameLine();
        if (ImGui::Button("Download OBJ")) exportMesh(".obj");
    }
    ImGui::End();
}

void App::applyParameters(bool metricChanged)
{
    if (!mEvolution) return;
    if (metricChanged) {
        // The Evolution keeps a reference to the metric: continue on the same mesh with a new one.
        mIterationBase = mIteration;
        mEvolution.reset();
        rebuildMetric();
        mShowSharpened = false;
        mEvolution = std::make_unique<Evolution>(mMesh, *mImage, *mMetric, evolutionOptions());
    } else {
        mEvolution->setOptions(evolutionOptions());
    }
    mReported = false;
    mMeshDirty = true;
}

const char* App::stateName() const
{
    if (!mEvolution) return "no model";
    if (!mEvolution->done()) return mPlaying ? "evolving" : "paused";
    return toString(mEvolution->reason());
}

std::string App::stateJson() const
{
    std::string name;
    for (char c : mVolumeName) name += (c == '"' || c == '\\') ? '_' : c;
    char buffer[768];
    std::snprintf(buffer, sizeof buffer,
                  "{\"iteration\": %d, \"level\": %d, \"levels\": %d, \"vertices\": %zu, \"components\": %d, \"genus\": %d, \"playing\": %s, "
                  "\"state\": \"%s\", \"computeSeconds\": %.4f, \"frameMs\": %.2f, \"cpuMs\": %.2f, \"merges\": %d, \"cuts\": %d, \"sharpened\": %zu, \"volume\": \"%s\"}",
                  mIteration, mEvolution ? mEvolution->level() : 0, mEvolution ? mEvolution->levels() : 1,
                  mTopology.vertices, mTopology.components, mTopology.genus, mPlaying ? "true" : "false",
                  stateName(), mComputeSeconds, mFrameInterval * 1e3, mLastFrameMs, mMerges, mCuts,
                  mShowSharpened ? mSharpenStats.moved : std::size_t(0), name.c_str());
    return buffer;
}

bool App::setParameter(const std::string& name, double value)
{
    // Sharpening applies to the converged mesh as it is (the Model panel's checkbox).
    if (name == "sharpen") {
        setSharpen(value != 0);
        return true;
    }
    // Display settings (as in the Display panel): they do not touch the model.
    if (name == "colour") {
        mColour = ColourMode(std::clamp(int(value), 0, 2));
        mMeshDirty = true;
        return true;
    }
    if (name == "camera_yaw") { mScene.camera.yaw = float(value); return true; }
    if (name == "wireframe") { mScene.wireframe = value != 0; return true; }
    if (name == "lighting") { mScene.lighting = std::clamp(int(value), 0, 2); return true; }
    if (name == "show_mesh") { mScene.showMesh = value != 0; return true; }
    if (name == "show_slice") { mScene.showSlice = value != 0; return true; }
    if (name == "clip") { mScene.clipAtSlice = value != 0; return true; }
    if (name == "slice_axis" || name == "slice_position") {
        if (name == "slice_axis") mSliceAxis = std::clamp(int(value), 0, 2);
        else mSlicePosition = float(std::clamp(value, 0.0, 1.0));
        mSliceDirty = mMeshDirty = true;
        return true;
    }
    bool metric = false;
    if (name == "iso") mParams.iso = value;
    else if (name == "delta") mParams.deltaVoxels = value;
    else if (name == "zeta") mParams.zeta = value;
    else if (name == "mu_scale") { mParams.muScale = value; metric = true; }
    else if (name == "riemannian") { mParams.riemannian = value != 0; metric = true; }
    else if (name == "inflation") mParams.externalWeight = value;
    else if (name == "umbrella") mParams.internalWeight = value;
    else if (name == "curvature") mParams.curvatureWeight = value;
    else if (name == "gradient") mParams.gradientWeight = value;
    else return false;
    applyParameters(metric);
    return true;
}

void App::frame(double budgetMs, int width, int height)
{
    const double start = nowSeconds();
    advance(budgetMs);
    handleCameraInput(width, height);
    drawPanels();
    if (mSliceDirty && mImage) rebuildSlice();
    if (!mGeometryAtRest && !(mPlaying && mEvolution && !mEvolution->done())) mMeshDirty = true; // paused
    if (mMeshDirty) {
        rebuildMeshGeometry();
        updateTopology();
        // Statistics cost a metric evaluation per edge: every few frames while evolving.
        if (--mStatsCountdown <= 0 || !mPlaying || (mEvolution && mEvolution->done())) {
            updateStatistics();
            mStatsCountdown = 10;
        }
    }
    mLastFrameMs = (nowSeconds() - start) * 1e3;
}

void App::frameShown(bool drawn)
{
    const double now = nowSeconds();
    if (drawn && mLastDrawn) {
        const double dt = now - mLastDrawnAt;
        mFrameInterval = mFrameInterval > 0 ? 0.9 * mFrameInterval + 0.1 * dt : dt;
        mDrawingAt = now;
    }
    if (drawn) mLastDrawnAt = now;
    mLastDrawn = drawn;
}

} // namespace riemesh::viewer
