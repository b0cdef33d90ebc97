#include "riemesh/metric.h"

#include "detail/nano_stencil.h"

#include <nanovdb/util/SampleFromVoxels.h>

#include <Eigen/Eigenvalues>

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

VertexMetrics::VertexMetrics(const Mesh& mesh, const MetricField& metric) : mMesh(mesh), mMetric(metric)
{
    if (!metric.isEuclidean()) mHasCache = mesh.get_property_handle(mCache, kMetricCacheProperty);
}

VertexMetrics::VertexMetrics(Mesh& mesh, const MetricField& metric) : mMesh(mesh), mWritable(&mesh), mMetric(metric)
{
    if (metric.isEuclidean()) return;
    if (!mesh.get_property_handle(mCache, kMetricCacheProperty)) mesh.add_property(mCache, kMetricCacheProperty);
    mHasCache = true;
}

Mat3 VertexMetrics::at(VertexHandle v) const
{
    if (mMetric.isEuclidean()) return Mat3::Identity();
    const Mesh::Point& p = mMesh.point(v);
    if (!mHasCache) return mMetric.at(toVec3(p));
    if (const VertexMetric& cached = mMesh.property(mCache, v); cached.at == p) return cached.g;
    if (!mWritable) return mMetric.at(toVec3(p));
    VertexMetric& entry = mWritable->property(mCache, v);
    entry.g = mMetric.at(toVec3(p));
    entry.at = p;
    return entry.g;
}

std::size_t VertexMetrics::update()
{
    if (!mWritable || !mHasCache) return 0;
    std::size_t sampled = 0;
    for (auto v : mMesh.vertices()) {
        if (mMesh.property(mCache, v).at == mMesh.point(v)) continue;
        at(v);
        ++sampled;
    }
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

Mat3 metricFromEigen(const Mat3& basis, const Vec3& eigenvalues)
{
    return basis * eigenvalues.asDiagonal() * basis.transpose();
}

struct NanoMetric::Impl {
    const nanovdb::Vec3fGrid* diag;
    const nanovdb::Vec3fGrid* off;
    nanovdb::DefaultReadAccessor<nanovdb::Vec3f> diagAccessor, offAccessor;
};

NanoMetric::NanoMetric(const nanovdb::Vec3fGrid* diag, const nanovdb::Vec3fGrid* off, double maxEigenvalue)
    : mMax(maxEigenvalue)
{
    if (!diag || !off) throw std::invalid_argument("NanoMetric: metric_diag and metric_off grids are required");
    mImpl.reset(new Impl{diag, off, diag->getAccessor(), off->getAccessor()});
}

NanoMetric::~NanoMetric() = default;

Mat3 NanoMetric::at(const Vec3& x) const
{
    // Both grids share one transform and one topology (written together by riemesh::vdb).
    const nanovdb::Vec3d ijk = mImpl->diag->worldToIndex(nanovdb::Vec3d(x.x(), x.y(), x.z()));
    detail::Stencil<nanovdb::Vec3f> sd, so;
    detail::fetchStencil(mImpl->diagAccessor, ijk, sd);
    detail::fetchStencil(mImpl->offAccessor, ijk, so);
    const nanovdb::Vec3f d = detail::trilinear(sd);
    const nanovdb::Vec3f o = detail::trilinear(so);
    Mat3 g;
    g << d[0], o[0], o[1],
         o[0], d[1], o[2],
         o[1], o[2], d[2];
    return g;
}

} // namespace riemesh
