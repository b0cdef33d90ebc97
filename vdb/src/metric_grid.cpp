// Structure tensor and metric (structure_tensor.h, metric_grid.h): dense separable Gaussian blurs on the
// image's active bounding box, multithreaded with TBB; the metric is written back sparse.
#include "riemesh/vdb/metric_grid.h"
#include "riemesh/vdb/structure_tensor.h"

#include "riemesh/image.h"
#include "riemesh/vdb/io.h"
#include "dense.h"

#include <Eigen/Eigenvalues>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

namespace riemesh::vdb {
namespace {

using detail::DenseLayout;
using Field = std::vector<float>;

constexpr std::size_t kMaxDenseVoxels = std::size_t(1) << 29; // 512M voxels: 2 GB per channel

std::vector<float> gaussianKernel(double sigma)
{
    const int radius = std::max(1, int(std::ceil(3.0 * sigma)));
    std::vector<float> w(2 * radius + 1);
    double sum = 0;
    for (int t = -radius; t <= radius; ++t) sum += (w[t + radius] = float(std::exp(-0.5 * t * t / (sigma * sigma))));
    for (auto& x : w) x = float(x / sum);
    return w;
}

/// In-place separable Gaussian blur of a dense block (edges clamped); `scratch` is resized as needed.
void blur(Field& f, const DenseLayout& L, double sigma, Field& scratch)
{
    if (!(sigma > 0)) return;
    const auto w = gaussianKernel(sigma);
    const int r = int(w.size() / 2);
    const int nx = L.nx, ny = L.ny, nz = L.nz;
    scratch.resize(f.size());
    auto clampi = [](int v, int n) { return v < 0 ? 0 : (v >= n ? n - 1 : v); };
    // x: contiguous lines.
    tbb::parallel_for(tbb::blocked_range<int>(0, ny * nz), [&](const tbb::blocked_range<int>& rg) {
        for (int line = rg.begin(); line != rg.end(); ++line) {
            const float* in = f.data() + std::size_t(line) * nx;
            float* out = scratch.data() + std::size_t(line) * nx;
            for (int i = 0; i < nx; ++i) {
                float s = 0;
                for (int t = -r; t <= r; ++t) s += w[t + r] * in[clampi(i + t, nx)];
                out[i] = s;
            }
        }
    });
    // y: per z slice, rows combined with contiguous inner loops.
    tbb::parallel_for(tbb::blocked_range<int>(0, nz), [&](const tbb::blocked_range<int>& rg) {
        for (int k = rg.begin(); k != rg.end(); ++k) {
            const float* in = scratch.data() + std::size_t(k) * nx * ny;
            float* out = f.data() + std::size_t(k) * nx * ny;
            for (int j = 0; j < ny; ++j) {
                float* o = out + std::size_t(j) * nx;
                std::fill(o, o + nx, 0.0f);
                for (int t = -r; t <= r; ++t) {
                    const float* src = in + std::size_t(clampi(j + t, ny)) * nx;
                    const float wt = w[t + r];
                    for (int i = 0; i < nx; ++i) o[i] += wt * src[i];
                }
            }
        }
    });
    // z: per y row, slices combined with contiguous inner loops.
    tbb::parallel_for(tbb::blocked_range<int>(0, ny), [&](const tbb::blocked_range<int>& rg) {
        for (int j = rg.begin(); j != rg.end(); ++j) {
            for (int k = 0; k < nz; ++k) {
                float* o = scratch.data() + (std::size_t(k) * ny + j) * nx;
                std::fill(o, o + nx, 0.0f);
                for (int t = -r; t <= r; ++t) {
                    const float* src = f.data() + (std::size_t(clampi(k + t, nz)) * ny + j) * nx;
                    const float wt = w[t + r];
                    for (int i = 0; i < nx; ++i) o[i] += wt * src[i];
                }
            }
        }
    });
    f.swap(scratch);
}

DenseLayout imageLayout(const openvdb::FloatGrid& image)
{
    const auto box = image.evalActiveVoxelBoundingBox();
    if (box.empty()) throw std::runtime_error("image grid '" + image.getName() + "' has no active voxels");
    DenseLayout L(box);
    if (L.size() > kMaxDenseVoxels)
        throw std::runtime_error("image box " + std::to_string(L.nx) + "x" + std::to_string(L.ny) + "x" +
                                 std::to_string(L.nz) + " is too large for the dense structure tensor");
    return L;
}

/// The six tensor channels Jxx Jyy Jzz Jxy Jxz Jyz (world space) on the image box.
struct DenseTensor {
    DenseLayout layout;
    std::array<Field, 6> c;
};

DenseTensor denseTensor(const openvdb::FloatGrid& image, const StructureTensorOptions& opt)
{
    if (!(opt.sigma >= 0) || !(opt.rho >= 0)) throw std::invalid_argument("structure tensor: sigma and rho must be >= 0");
    initialize();
    const DenseLayout L = imageLayout(image);
    Field I = detail::gridToDense(image, L), scratch;
    blur(I, L, opt.sigma, scratch);

    // Index-space gradient -> world-space gradient: g_w = A^-T g_i (inverse Jacobian transpose).
    const auto map = image.transform().baseMap();
    openvdb::Vec3d col[3];
    for (int a = 0; a < 3; ++a) {
        openvdb::Vec3d e(0.0);
        e[a] = 1.0;
        col[a] = map->applyIJT(e);
    }
    DenseTensor T{L, {}};
    for (auto& ch : T.c) ch.resize(L.size());
    const int nx = L.nx, ny = L.ny, nz = L.nz;
    tbb::parallel_for(tbb::blocked_range<int>(0, nz), [&](const tbb::blocked_range<int>& rg) {
        for (int k = rg.begin(); k != rg.end(); ++k)
            for (int j = 0; j < ny; ++j)
                for (int i = 0; i < nx; ++i) {
                    auto at = [&](int a, int b, int c) {
                        return I[(std::size_t(c) * ny + b) * nx + a];
                    };
                    auto diff = [](double span, float vlo, float vhi) { return (vhi - vlo) / span; };
                    const int i0 = std::max(i - 1, 0), i1 = std::min(i + 1, nx - 1);
                    const int j0 = std::max(j - 1, 0), j1 = std::min(j + 1, ny - 1);
                    const int k0 = std::max(k - 1, 0), k1 = std::min(k + 1, nz - 1);
                    const double gi = i1 > i0 ? diff(i1 - i0, at(i0, j, k), at(i1, j, k)) : 0.0;
                    const double gj = j1 > j0 ? diff(j1 - j0, at(i, j0, k), at(i, j1, k)) : 0.0;
                    const double gk = k1 > k0 ? diff(k1 - k0, at(i, j, k0), at(i, j, k1)) : 0.0;
                    const openvdb::Vec3d g = col[0] * gi + col[1] * gj + col[2] * gk;
                    const std::size_t n = (std::size_t(k) * ny + j) * nx + i;
                    T.c[0][n] = float(g[0] * g[0]);
                    T.c[1][n] = float(g[1] * g[1]);
                    T.c[2][n] = float(g[2] * g[2]);
                    T.c[3][n] = float(g[0] * g[1]);
                    T.c[4][n] = float(g[0] * g[2]);
                    T.c[5][n] = float(g[1] * g[2]);
                }
    });
    I.clear();
    I.shrink_to_fit();
    for (auto& ch : T.c) blur(ch, L, opt.rho, scratch);
    return T;
}

Eigen::Matrix3d tensorAt(const DenseTensor& T, std::size_t n)
{
    Eigen::Matrix3d J;
    J << T.c[0][n], T.c[3][n], T.c[4][n],
         T.c[3][n], T.c[1][n], T.c[5][n],
         T.c[4][n], T.c[5][n], T.c[2][n];
    return J;
}

MetricGrids metricFromDense(const DenseTensor& T, const openvdb::math::Transform& transform, const MetricOptions& opt)
{
    if (!(opt.muMax >= 1.0) || !std::isfinite(opt.muMax)) throw std::invalid_argument("metric: muMax must be >= 1");
    if (!(opt.referencePercentile > 0 && opt.referencePercentile <= 1))
        throw std::invalid_argument("metric: referencePercentile must be in (0, 1]");
    const DenseLayout& L = T.layout;
    const std::size_t n = L.size();

    // Robust scale: quantiles of xi_0 on a regular subsample (at most ~1M voxels).
    const std::size_t stride = std::max<std::size_t>(1, n / 1000000);
    std::vector<double> xi0((n + stride - 1) / stride);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, xi0.size()), [&](const tbb::blocked_range<std::size_t>& rg) {
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
        for (std::size_t s = rg.begin(); s != rg.end(); ++s) {
            es.computeDirect(tensorAt(T, s * stride), Eigen::EigenvaluesOnly);
            xi0[s] = std::max(0.0, es.eigenvalues()[2]);
        }
    });
    auto quantile = [&](double q) {
        const std::size_t k = std::min(xi0.size() - 1, std::size_t(q * double(xi0.size() - 1)));
        std::nth_element(xi0.begin(), xi0.begin() + std::ptrdiff_t(k), xi0.end());
        return xi0[k];
    };
    MetricGrids out;
    out.muMax = opt.muMax;
    out.totalVoxels = n;
    out.xiRef = quantile(opt.referencePercentile);
    const double median = quantile(0.5);
    out.threshold = std::min(0.95, std::max(opt.threshold, out.xiRef > 0 ? opt.noiseFactor * median / out.xiRef : 1.0));

    out.diag = openvdb::Vec3fGrid::create(openvdb::Vec3f(1.0f));
    out.off = openvdb::Vec3fGrid::create(openvdb::Vec3f(0.0f));
    for (auto* g : {&out.diag, &out.off}) {
        (*g)->setTransform(transform.copy());
        (*g)->setGridClass(openvdb::GRID_UNKNOWN);
        (*g)->insertMeta(kMuMaxMetadata, openvdb::DoubleMetadata(opt.muMax));
        (*g)->setVectorType(openvdb::VEC_INVARIANT);
    }
    out.diag->setName(riemesh::kMetricDiagGrid);
    out.off->setName(riemesh::kMetricOffGrid);
    if (!(out.xiRef > 0) || opt.muMax == 1.0) return out; // flat image or Euclidean request: G = I

    // Per voxel G; identity voxels (the vast majority far from contours) are skipped cheaply:
    // xi_0 <= trace(J), so trace(J) <= t * xi_ref means every mu_i = 1.
    const double xiRef = out.xiRef, t = out.threshold, span = opt.muMax - 1.0;
    if (!(opt.tangentialGain >= 1.0) || !std::isfinite(opt.tangentialGain))
        throw std::invalid_argument("metric: tangentialGain must be >= 1");
    const double gain = opt.tangentialGain; // on xi_1, xi_2 (ev[1], ev[0]; ascending order)
    // The gain multiplies the excess over the noise threshold, not the eigenvalue itself: what noise
    // leaves below t stays Euclidean whatever the gain (a boosted raw xi_1 let noise through at high
    // noise and tangled the model).
    auto mu = [&](double xi, double g) {
        return 1.0 + span * std::clamp(g * (xi / xiRef - t) / (1.0 - t), 0.0, 1.0);
    };
    std::vector<openvdb::Vec3f> diag(n), off(n);
    std::vector<std::uint8_t> active(n, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& rg) {
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
        for (std::size_t v = rg.begin(); v != rg.end(); ++v) {
            const double trace = double(T.c[0][v]) + T.c[1][v] + T.c[2][v];
            if (trace <= t * xiRef) continue;
            es.computeDirect(tensorAt(T, v));
            const Eigen::Vector3d ev = es.eigenvalues(); // ascending: xi_2, xi_1, xi_0
            const Eigen::Vector3d m(mu(ev[0], gain), mu(ev[1], gain), mu(ev[2], 1.0));
            if (m.maxCoeff() - 1.0 < opt.activeTolerance) continue;
            const Eigen::Matrix3d V = es.eigenvectors();
            const Eigen::Matrix3d G = V * m.asDiagonal() * V.transpose();
            diag[v] = openvdb::Vec3f(float(G(0, 0)), float(G(1, 1)), float(G(2, 2)));
            off[v] = openvdb::Vec3f(float(G(0, 1)), float(G(0, 2)), float(G(1, 2)));
            active[v] = 1;
        }
    });
    auto diagAcc = out.diag->getAccessor();
    auto offAcc = out.off->getAccessor();
    for (int k = 0; k < L.nz; ++k)
        for (int j = 0; j < L.ny; ++j)
            for (int i = 0; i < L.nx; ++i) {
                const std::size_t v = (std::size_t(k) * L.ny + j) * L.nx + i;
                if (!active[v]) continue;
                const openvdb::Coord c = L.box.min() + openvdb::Coord(i, j, k);
                diagAcc.setValue(c, diag[v]);
                offAcc.setValue(c, off[v]);
                ++out.activeVoxels;
            }
    return out;
}

} // namespace

openvdb::FloatGrid::Ptr gaussianSmooth(const openvdb::FloatGrid& image, double sigma)
{
    if (!(sigma >= 0)) throw std::invalid_argument("gaussianSmooth: sigma must be >= 0");
    initialize();
    const DenseLayout L = imageLayout(image);
    Field I = detail::gridToDense(image, L), scratch;
    blur(I, L, sigma, scratch);
    auto out = detail::denseToGrid<openvdb::FloatGrid>(I, L, image.background());
    out->setTransform(image.transform().copy());
    out->setName(image.getName());
    out->setGridClass(image.getGridClass());
    return out;
}

StructureTensorGrids structureTensor(const openvdb::FloatGrid& image, const StructureTensorOptions& options)
{
    const DenseTensor T = denseTensor(image, options);
    const DenseLayout& L = T.layout;
    std::vector<openvdb::Vec3f> d(L.size()), o(L.size());
    for (std::size_t v = 0; v < L.size(); ++v) {
        d[v] = openvdb::Vec3f(T.c[0][v], T.c[1][v], T.c[2][v]);
        o[v] = openvdb::Vec3f(T.c[3][v], T.c[4][v], T.c[5][v]);
    }
    StructureTensorGrids out;
    out.diag = detail::denseToGrid<openvdb::Vec3fGrid>(d, L, openvdb::Vec3f(0.0f));
    out.off = detail::denseToGrid<openvdb::Vec3fGrid>(o, L, openvdb::Vec3f(0.0f));
    for (auto* g : {&out.diag, &out.off}) (*g)->setTransform(image.transform().copy());
    out.diag->setName("tensor_diag");
    out.off->setName("tensor_off");
    return out;
}

MetricGrids metricFromStructureTensor(const StructureTensorGrids& tensor, const MetricOptions& options)
{
    if (!tensor.diag || !tensor.off) throw std::invalid_argument("metricFromStructureTensor: missing tensor grids");
    const auto box = tensor.diag->evalActiveVoxelBoundingBox();
    if (box.empty()) throw std::invalid_argument("metricFromStructureTensor: empty tensor grids");
    DenseTensor T{DenseLayout(box), {}};
    const auto d = detail::gridToDense(*tensor.diag, T.layout);
    const auto o = detail::gridToDense(*tensor.off, T.layout);
    for (auto& ch : T.c) ch.resize(T.layout.size());
    for (std::size_t v = 0; v < T.layout.size(); ++v)
        for (int a = 0; a < 3; ++a) {
            T.c[a][v] = d[v][a];
            T.c[3 + a][v] = o[v][a];
        }
    return metricFromDense(T, tensor.diag->transform(), options);
}

MetricGrids computeMetric(const openvdb::FloatGrid& image, const StructureTensorOptions& tensorOptions,
                          const MetricOptions& options)
{
    return metricFromDense(denseTensor(image, tensorOptions), image.transform(), options);
}

} // namespace riemesh::vdb
