// riemesh/metric.h: the Riemannian metric G(x) (paper 3.1, 4).
//
// G(x) is a symmetric positive-definite 3x3 matrix with eigenvalues in [1, muMax]. The metric length
// of an edge (u, v) is sqrt((v-u)^T G(m) (v-u)) with G taken at the midpoint m (constant along the
// edge). Since the eigenvalues are >= 1, metric lengths are never shorter than Euclidean ones.
// Euclidean is the special case G = I and runs through the same code.
#pragma once

#include "riemesh/mesh.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <memory>

#include <nanovdb/NanoVDB.h>

namespace riemesh {

/// Implementations must be safe to call from several threads at once (the core samples in parallel).
class MetricField {
public:
    virtual ~MetricField() = default;
    /// G at a world-space point: SPD, eigenvalues in [1, maxEigenvalue()].
    virtual Mat3 at(const Vec3& x) const = 0;
    /// Upper bound of the eigenvalues of G over the whole domain (>= 1).
    virtual double maxEigenvalue() const = 0;
    /// True when G = I everywhere (callers may take the Euclidean fast path; results must not change).
    virtual bool isEuclidean() const { return false; }
};

/// Length of the displacement d (world units) under the constant tensor g: sqrt(d^T g d).
inline double metricLength(const Mat3& g, const Vec3& d) { return std::sqrt(std::max(0.0, d.dot(g * d))); }

/// Metric length of an edge d whose endpoints have tensors ga and gb: G is their mean (the edge rule
/// of regularity, the umbrella and the mesh overload below; second order in the edge length).
inline double metricLength(const Mat3& ga, const Mat3& gb, const Vec3& d)
{
    return metricLength(Mat3(0.5 * (ga + gb)), d);
}

/// Metric length of the segment u-v (world-space points), with G taken at the midpoint.
double metricLength(const MetricField& metric, const Vec3& u, const Vec3& v);

/// Metric length of edge e of `mesh`, with G at the midpoint approximated by the mean of G at the
/// two endpoints (second order in the edge length; exact for a constant metric). This is the
/// length the regularity step keeps within [delta, zeta*delta]: it samples G once per vertex
/// instead of once per edge measurement.
double metricLength(const MetricField& metric, const Mesh& mesh, EdgeHandle e);

/// Name of the per-vertex cache of G (VertexMetric), kept by VertexMetrics.
inline constexpr const char* kMetricCacheProperty = "riemesh:metric";

/// G at a vertex and the position it was sampled at: the entry is current only while the vertex
/// stays there (a new vertex has a NaN position, equal to none).
struct VertexMetric {
    Mat3 g = Mat3::Identity();
    Mesh::Point at{std::nan(""), std::nan(""), std::nan("")};
};

/// G at the mesh's vertices, sampled once per vertex position. Sampling a metric grid (two
/// trilinear lookups) is the costliest per-vertex read of an iteration, and the forces, the
/// regularity step and the next iteration's forces need G at the same positions: the samples live
/// in a vertex property (kMetricCacheProperty) that follows vertices through edits and garbage
/// collection, and an entry is used only while its vertex has not moved. With a Euclidean metric
/// nothing is stored and every call returns I.
class VertexMetrics {
public:
    /// Reads `mesh`'s cache if it has one (a vertex without a current entry is sampled each call).
    VertexMetrics(const Mesh& mesh, const MetricField& metric);
    /// Reads and fills `mesh`'s cache (created on first use).
    VertexMetrics(Mesh& mesh, const MetricField& metric);

    /// G at vertex v's current position. (Inline: the regularity step and the collision search
    /// read it about a million times on the 100^3 phantom; the cache hit is a compare and a copy.
    /// Forced: GCC 12 left it out of line once the regularity step grew.)
    [[gnu::always_inline]] Mat3 at(VertexHandle v) const
    {
        if (mEuclidean) return Mat3::Identity();
        if (mHasCache) {
            const VertexMetric& cached = mMesh.property(mCache, v);
            if (cached.at == mMesh.point(v)) return cached.g;
        }
        return sample(v);
    }
    /// Samples every vertex whose entry is not current; returns how many were sampled.
    std::size_t update();
    /// Marks every entry of `mesh`'s cache stale (the metric field changed: a coarse level's
    /// DilatedMetric and the image's are different fields at the same positions).
    static void forget(Mesh& mesh);

    const MetricField& field() const { return mMetric; }

private:
    const Mesh& mMesh;
    Mesh* mWritable = nullptr;
    const MetricField& mMetric;
    OpenMesh::VPropHandleT<VertexMetric> mCache;
    bool mHasCache = false;
    bool mEuclidean = false;
    Mat3 sample(VertexHandle v) const; ///< at() when the cache has no current entry
};

/// G = I.
class EuclideanMetric final : public MetricField {
public:
    Mat3 at(const Vec3&) const override { return Mat3::Identity(); }
    double maxEigenvalue() const override { return 1.0; }
    bool isEuclidean() const override { return true; }
};

/// The same G everywhere (anisotropic when its eigenvalues differ).
class ConstantMetric final : public MetricField {
public:
    /// `g` must be SPD with eigenvalues >= 1 (throws std::invalid_argument otherwise).
    explicit ConstantMetric(const Mat3& g);
    Mat3 at(const Vec3&) const override { return mG; }
    double maxEigenvalue() const override { return mMax; }
private:
    Mat3 mG;
    double mMax;
};

/// G given by a function of the world-space position (tests, analytic fields).
class FunctionMetric final : public MetricField {
public:
    /// `maxEigenvalue` must bound the eigenvalues of every value `g` returns.
    FunctionMetric(std::function<Mat3(const Vec3&)> g, double maxEigenvalue);
    Mat3 at(const Vec3& x) const override { return mG(x); }
    double maxEigenvalue() const override { return mMax; }
private:
    std::function<Mat3(const Vec3&)> mG;
    double mMax;
};

/// G of `base` reaching `radius` (world units) around each point: at x, the sample with the largest
/// trace among x and x +- radius along each axis (7 samples). For a coarse level of a
/// coarse-to-fine schedule, whose object is grown by about half a block: its surface settles that
/// far outside the contours, where the metric of the image (refined within a few voxels of them)
/// is already the identity, so without this a coarse level samples a narrow hole, an edge or a
/// corner as coarsely as a flat face. `base` must outlive this object.
class DilatedMetric final : public MetricField {
public:
    DilatedMetric(const MetricField& base, double radius);
    Mat3 at(const Vec3& x) const override;
    double maxEigenvalue() const override { return mBase.maxEigenvalue(); }
    bool isEuclidean() const override { return mBase.isEuclidean(); }

private:
    const MetricField& mBase;
    double mRadius;
};

/// G read from two NanoVDB Vec3f grids, trilinearly interpolated: `diag` = (gxx, gyy, gzz) with
/// background (1,1,1) and `off` = (gxy, gxz, gyz) with background (0,0,0) (identity where inactive).
/// The grids are not owned: keep their GridHandles alive as long as this object. Thread-safe: each
/// thread samples through its own cached accessors.
class NanoMetric final : public MetricField {
public:
    NanoMetric(const nanovdb::Vec3fGrid* diag, const nanovdb::Vec3fGrid* off, double maxEigenvalue);
    ~NanoMetric() override;
    Mat3 at(const Vec3& x) const override;
    double maxEigenvalue() const override { return mMax; }
private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
    double mMax;
};

/// Builds G from an orthonormal eigenbasis (columns of `basis`) and eigenvalues.
Mat3 metricFromEigen(const Mat3& basis, const Vec3& eigenvalues);

} // namespace riemesh
