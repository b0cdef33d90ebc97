#include "riemesh/metric.h"

#include "detail/nano_stencil.h"
#include "detail/parallel.h"
#include "detail/thread_accessor.h"

#include <nanovdb/util/SampleFromVoxels.h>

#include <Eigen/Eigenvalues>

#include <atomic>
#include <cmath>
#include <stdexcept>

namespace riemesh {

double metricLength(const MetricField& metric, const Vec3& u, const Vec3& v)
{
    const Vec3 d = v - u;
    if (metric.isEuclidean()) return d.norm();
    return metricLength(metric.at(0.5 * (u + v)), d);
}

double metricLength(const MetricField& metric, const Mesh& mesh, EdgeHandle e)
{
    auto h = mesh.halfedge_handle(e, 0);
    const Vec3 u = position(mesh, mesh.from_vertex_handle(h)), v = position(mesh, mesh.to_vertex_handle(h));
    const Vec3 d = v - u;
    if (metric.isEuclidean()) return d.norm();
    return metricLength(metric.at(u), metric.at(v), d);
}

VertexMetrics::VertexMetrics(const Mesh& mesh, const MetricField& metric)
    : mMesh(mesh), mMetric(metric), mEuclidean(metric.isEuclidean())
{
    if (!mEuclidean) mHasCache = mesh.get_property_handle(mCache, kMetricCacheProperty);
}

VertexMetrics::VertexMetrics(Mesh& mesh, const MetricField& metric)
    : mMesh(mesh), mWritable(&mesh), mMetric(metric), mEuclidean(metric.isEuclidean())
{
    if (mEuclidean) return;
    if (!mesh.get_property_handle(mCache, kMetricCacheProperty)) mesh.add_property(mCache, kMetricCacheProperty);
    mHasCache = true;
}

void VertexMetrics::forget(Mesh& mesh)
{
    OpenMesh::VPropHandleT<VertexMetric> cache;
    if (!mesh.get_property_handle(cache, kMetricCacheProperty)) return;
    for (auto v : mesh.vertices()) mesh.property(cache, v).at = VertexMetric{}.at;
}

Mat3 VertexMetrics::sample(VertexHandle v) const
{
    const Mesh::Point& p = mMesh.point(v);
    if (!mHasCache || !mWritable) return mMetric.at(toVec3(p));
    VertexMetric& entry = mWritable->property(mCache, v);
    entry.g = mMetric.at(toVec3(p));
    entry.at = p;
    return entry.g;
}

std::size_t VertexMetrics::update()
{
    if (!mWritable || !mHasCache) return 0;
    // Every vertex in parallel: each writes only its own cache entry.
    const bool vertexStatus = mMesh.has_vertex_status();
    std::atomic<std::size_t> sampled{0};
    detail::parallelForChunks(0, mMesh.n_vertices(), 128, [&](std::size_t begin, std::size_t end) {
        std::size_t count = 0;
        for (std::size_t i = begin; i < end; ++i) {
            const VertexHandle v{int(i)};
            if (vertexStatus && mMesh.status(v).deleted()) continue;
            const Mesh::Point& p = mMesh.point(v);
            VertexMetric& entry = mWritable->property(mCache, v);
            if (entry.at == p) continue;
            entry.g = mMetric.at(toVec3(p));
            entry.at = p;
            ++count;
        }
        sampled += count;
    });
    return sampled;
}

ConstantMetric::ConstantMetric(const Mat3& g) : mG(g)
{
    if (!g.isApprox(g.transpose(), 1e-9)) throw std::invalid_argument("ConstantMetric: G is not symmetric");
    Eigen::SelfAdjointEigenSolver<Mat3> eig(g);
    if (eig.eigenvalues().minCoeff() < 1.0 - 1e-9)
        throw std::invalid_argument("ConstantMetric: eigenvalues of G must be >= 1");
    mMax = eig.eigenvalues().maxCoeff();
}

FunctionMetric::FunctionMetric(std::function<Mat3(const Vec3&)> g, double maxEigenvalue)
    : mG(std::move(g)), mMax(maxEigenvalue)
{
    if (!mG) throw std::invalid_argument("FunctionMetric: empty function");
    if (!(maxEigenvalue >= 1.0)) throw std::invalid_argument("FunctionMetric: maxEigenvalue must be >= 1");
}

DilatedMetric::DilatedMetric(const MetricField& base, double radius) : mBase(base), mRadius(radius)
{
    if (!(radius >= 0) || !std::isfinite(radius)) throw std::invalid_argument("DilatedMetric: radius must be finite and >= 0");
}

Mat3 DilatedMetric::at(const Vec3& x) const
{
    Mat3 best = mBase.at(x);
    if (mRadius == 0) return best;
    double trace = best.trace();
    for (int axis = 0; axis < 3; ++axis)
        for (const double side : {-1.0, 1.0}) {
            Vec3 y = x;
            y[axis] += side * mRadius;
            const Mat3 g = mBase.at(y);
            if (const double t = g.trace(); t > trace) best = g, trace = t;
        }
    return best;
}

Mat3 metricFromEigen(const Mat3& basis, const Vec3& eigenvalues)
{
    return basis * eigenvalues.asDiagonal() * basis.transpose();
}

struct NanoMetric::Impl {
    const nanovdb::Vec3fGrid* diag;
    const nanovdb::Vec3fGrid* off;
    std::uint64_t owner; ///< tells this metric's per-thread accessors apart
};

NanoMetric::NanoMetric(const nanovdb::Vec3fGrid* diag, const nanovdb::Vec3fGrid* off, double maxEigenvalue)
    : mMax(maxEigenvalue)
{
    if (!diag || !off) throw std::invalid_argument("NanoMetric: metric_diag and metric_off grids are required");
    mImpl.reset(new Impl{diag, off, detail::newAccessorOwner()});
}

NanoMetric::~NanoMetric() = default;

Mat3 NanoMetric::at(const Vec3& x) const
{
    // Both grids share one transform and one topology (written together by riemesh::vdb).
    const nanovdb::Vec3d ijk = mImpl->diag->worldToIndex(nanovdb::Vec3d(x.x(), x.y(), x.z()));
    detail::Stencil<nanovdb::Vec3f> sd, so;
    detail::fetchStencil(detail::threadAccessor<0>(mImpl->owner, mImpl->diag), ijk, sd);
    detail::fetchStencil(detail::threadAccessor<1>(mImpl->owner, mImpl->off), ijk, so);
    const nanovdb::Vec3f d = detail::trilinear(sd);
    const nanovdb::Vec3f o = detail::trilinear(so);
    Mat3 g;
    g << d[0], o[0], o[1],
         o[0], d[1], o[2],
         o[1], o[2], d[2];
    return g;
}

} // namespace riemesh
