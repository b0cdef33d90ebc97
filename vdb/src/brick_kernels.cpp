// Private: the brick kernels of brick_filters.h. Compiled twice (vdb/CMakeLists.txt): with
// RIEMESH_KERNEL_NS=generic for any x86-64, and with RIEMESH_KERNEL_NS=avx2 and -mavx2 -mfma; plain
// loops over contiguous x that the compiler vectorises in both.
#include "brick_filters.h"
#include "symmetric_eigen.h"

#include <algorithm>

#include <vector>

#ifndef RIEMESH_KERNEL_NS
#error "compile with -DRIEMESH_KERNEL_NS=name"
#endif

namespace riemesh::vdb::detail::RIEMESH_KERNEL_NS {

namespace {

/// One row: out[i] = sum_t w[t] in[i + t], i < n (in has n + 2r values).
inline void convolveRow(const float* __restrict in, int n, const float* __restrict w, int r, float* __restrict out)
{
    for (int i = 0; i < n; ++i) out[i] = w[0] * in[i];
    for (int t = 1; t <= 2 * r; ++t) {
        const float wt = w[t];
        const float* src = in + t;
        for (int i = 0; i < n; ++i) out[i] += wt * src[i];
    }
}

/// out[i] = sum_t w[t] rows[t][i], i < n: the y and z passes combine whole rows.
inline void combineRows(const float* __restrict in, std::size_t rowStride, int n, const float* __restrict w, int r,
                        float* __restrict out)
{
    const float w0 = w[0];
    for (int i = 0; i < n; ++i) out[i] = w0 * in[i];
    for (int t = 1; t <= 2 * r; ++t) {
        const float wt = w[t];
        const float* src = in + std::size_t(t) * rowStride;
        for (int i = 0; i < n; ++i) out[i] += wt * src[i];
    }
}

/// Radii known at compile time: the taps loop unrolls and each output is summed in a register
/// (x: eight outputs of a row at once; y, z: eight columns at once).
template<int R>
void blurXFixed(const float* __restrict in, BlockDims d, const float* __restrict w, float* __restrict out)
{
    const int ox = d.nx - 2 * R;
    const std::size_t rows = std::size_t(d.ny) * d.nz;
    float wt[2 * R + 1];
    for (int t = 0; t <= 2 * R; ++t) wt[t] = w[t];
    for (std::size_t row = 0; row < rows; ++row) {
        const float* __restrict src = in + row * d.nx;
        float* __restrict dst = out + row * ox;
        for (int i = 0; i < ox; ++i) {
            float acc = wt[0] * src[i];
            for (int t = 1; t <= 2 * R; ++t) acc += wt[t] * src[i + t];
            dst[i] = acc;
        }
    }
}

template<int R>
void combineFixed(const float* __restrict in, std::size_t stride, int n, const float* __restrict wt, float* __restrict out)
{
    for (int i = 0; i < n; ++i) {
        float acc = wt[0] * in[i];
        for (int t = 1; t <= 2 * R; ++t) acc += wt[t] * in[i + std::size_t(t) * stride];
        out[i] = acc;
    }
}

template<int R>
void blurYFixed(const float* in, BlockDims d, const float* w, float* out)
{
    const int oy = d.ny - 2 * R;
    float wt[2 * R + 1];
    for (int t = 0; t <= 2 * R; ++t) wt[t] = w[t];
    for (int k = 0; k < d.nz; ++k)
        for (int j = 0; j < oy; ++j)
            combineFixed<R>(in + (std::size_t(k) * d.ny + j) * d.nx, std::size_t(d.nx), d.nx, wt,
                            out + (std::size_t(k) * oy + j) * d.nx);
}

template<int R>
void blurZFixed(const float* in, BlockDims d, const float* w, float* out)
{
    const int oz = d.nz - 2 * R;
    const std::size_t slice = std::size_t(d.nx) * d.ny;
    float wt[2 * R + 1];
    for (int t = 0; t <= 2 * R; ++t) wt[t] = w[t];
    // Whole slices at once: the combination is the same for every (i, j) of a slice.
    for (int k = 0; k < oz; ++k) combineFixed<R>(in + std::size_t(k) * slice, slice, int(slice), wt, out + std::size_t(k) * slice);
}

#define RIEMESH_DISPATCH(fn, ...)                                                                                   \
    switch (r) {                                                                                                   \
    case 1: return fn##Fixed<1>(__VA_ARGS__);                                                                      \
    case 2: return fn##Fixed<2>(__VA_ARGS__);                                                                      \
    case 3: return fn##Fixed<3>(__VA_ARGS__);                                                                      \
    case 4: return fn##Fixed<4>(__VA_ARGS__);                                                                      \
    case 5: return fn##Fixed<5>(__VA_ARGS__);                                                                      \
    case 6: return fn##Fixed<6>(__VA_ARGS__);                                                                      \
    case 9: return fn##Fixed<9>(__VA_ARGS__);                                                                      \
    default: break;                                                                                                \
    }

void blurX(const float* in, BlockDims d, const float* w, int r, float* out)
{
    RIEMESH_DISPATCH(blurX, in, d, w, out)
    const int ox = d.nx - 2 * r;
    const std::size_t rows = std::size_t(d.ny) * d.nz;
    for (std::size_t row = 0; row < rows; ++row) convolveRow(in + row * d.nx, ox, w, r, out + row * ox);
}

void blurY(const float* in, BlockDims d, const float* w, int r, float* out)
{
    RIEMESH_DISPATCH(blurY, in, d, w, out)
    const int oy = d.ny - 2 * r;
    for (int k = 0; k < d.nz; ++k)
        for (int j = 0; j < oy; ++j)
            combineRows(in + (std::size_t(k) * d.ny + j) * d.nx, std::size_t(d.nx), d.nx, w, r,
                        out + (std::size_t(k) * oy + j) * d.nx);
}

void blurZ(const float* in, BlockDims d, const float* w, int r, float* out)
{
    RIEMESH_DISPATCH(blurZ, in, d, w, out)
    const int oz = d.nz - 2 * r;
    const std::size_t slice = std::size_t(d.nx) * d.ny;
    for (int k = 0; k < oz; ++k) combineRows(in + std::size_t(k) * slice, slice, int(slice), w, r, out + std::size_t(k) * slice);
}

/// The tensor products of one row of gradients (length n) into six row buffers.
inline void productRow(const float* __restrict c, std::ptrdiff_t sy, std::ptrdiff_t sz, int n, const float* m, float* const rows[6])
{
    const float m00 = m[0], m01 = m[1], m02 = m[2], m10 = m[3], m11 = m[4], m12 = m[5], m20 = m[6], m21 = m[7], m22 = m[8];
    float* __restrict xx = rows[0];
    float* __restrict yy = rows[1];
    float* __restrict zz = rows[2];
    float* __restrict xy = rows[3];
    float* __restrict xz = rows[4];
    float* __restrict yz = rows[5];
    for (int i = 0; i < n; ++i) {
        const float gi = 0.5f * (c[i + 1] - c[i - 1]);
        const float gj = 0.5f * (c[i + sy] - c[i - sy]);
        const float gk = 0.5f * (c[i + sz] - c[i - sz]);
        const float gx = m00 * gi + m01 * gj + m02 * gk;
        const float gy = m10 * gi + m11 * gj + m12 * gk;
        const float gz = m20 * gi + m21 * gj + m22 * gk;
        xx[i] = gx * gx;
        yy[i] = gy * gy;
        zz[i] = gz * gz;
        xy[i] = gx * gy;
        xz[i] = gx * gz;
        yz[i] = gy * gz;
    }
}

void tensorProducts(const float* in, BlockDims d, const double* m, float* const out[6])
{
    const int ox = d.nx - 2, oy = d.ny - 2, oz = d.nz - 2;
    const std::size_t sy = std::size_t(d.nx), sz = std::size_t(d.nx) * d.ny;
    float mf[9];
    for (int i = 0; i < 9; ++i) mf[i] = float(m[i]);
    std::size_t o = 0;
    for (int k = 0; k < oz; ++k)
        for (int j = 0; j < oy; ++j, o += std::size_t(ox)) {
            float* rows[6];
            for (int c = 0; c < 6; ++c) rows[c] = out[c] + o;
            productRow(in + (k + 1) * sz + (j + 1) * sy + 1, std::ptrdiff_t(sy), std::ptrdiff_t(sz), ox, mf, rows);
        }
}


/// The tensor products averaged over 2x2x2 cells: out[c] has ((nx - 2) / 2)^3-style dimensions
/// (each axis of the gradient domain halved), cell (i, j, k) the mean of the gradient-domain voxels
/// 2(i, j, k) + {0, 1}^3.
void tensorProductsHalf(const float* in, BlockDims d, const double* toWorld, float* const out[6])
{
    float m[9];
    for (int i = 0; i < 9; ++i) m[i] = float(toWorld[i]);
    const int gx = d.nx - 2, hx = gx / 2, hy = (d.ny - 2) / 2, hz = (d.nz - 2) / 2;
    const std::size_t sy = std::size_t(d.nx), sz = std::size_t(d.nx) * d.ny;
    std::vector<float> buffer(6 * std::size_t(gx));
    float* rows[6];
    for (int c = 0; c < 6; ++c) rows[c] = buffer.data() + c * std::size_t(gx);
    std::size_t o = 0;
    for (int k = 0; k < hz; ++k)
        for (int j = 0; j < hy; ++j, o += std::size_t(hx)) {
            for (int c = 0; c < 6; ++c) std::fill_n(out[c] + o, hx, 0.0f);
            for (int b = 0; b < 2; ++b)
                for (int a = 0; a < 2; ++a) {
                    productRow(in + (2 * k + b + 1) * sz + (2 * j + a + 1) * sy + 1, std::ptrdiff_t(sy), std::ptrdiff_t(sz), gx, m, rows);
                    for (int c = 0; c < 6; ++c) {
                        float* __restrict dst = out[c] + o;
                        const float* __restrict src = rows[c];
                        for (int i = 0; i < hx; ++i) dst[i] += 0.125f * (src[2 * i] + src[2 * i + 1]);
                    }
                }
        }
}

template<int R>
inline void convolveRowFixed(const float* __restrict src, int n, const float* __restrict wt, float* __restrict dst)
{
    for (int i = 0; i < n; ++i) {
        float acc = wt[0] * src[i];
        for (int t = 1; t <= 2 * R; ++t) acc += wt[t] * src[i + t];
        dst[i] = acc;
    }
}

template<int R>
void tensorBlurXFixed(const float* in, BlockDims d, const float* m, const float* w, float* const out[6])
{
    const int gx = d.nx - 2, gy = d.ny - 2, gz = d.nz - 2, ox = gx - 2 * R;
    const std::size_t sy = std::size_t(d.nx), sz = std::size_t(d.nx) * d.ny;
    float wt[2 * R + 1];
    for (int t = 0; t <= 2 * R; ++t) wt[t] = w[t];
    std::vector<float> buffer(6 * std::size_t(gx));
    float* rows[6];
    for (int c = 0; c < 6; ++c) rows[c] = buffer.data() + c * std::size_t(gx);
    std::size_t o = 0;
    for (int k = 0; k < gz; ++k)
        for (int j = 0; j < gy; ++j, o += std::size_t(ox)) {
            productRow(in + (k + 1) * sz + (j + 1) * sy + 1, std::ptrdiff_t(sy), std::ptrdiff_t(sz), gx, m, rows);
            for (int c = 0; c < 6; ++c) convolveRowFixed<R>(rows[c], ox, wt, out[c] + o);
        }
}

void tensorBlurX(const float* in, BlockDims d, const double* toWorld, const float* w, int r, float* const out[6])
{
    float m[9];
    for (int i = 0; i < 9; ++i) m[i] = float(toWorld[i]);
    RIEMESH_DISPATCH(tensorBlurX, in, d, m, w, out)
    // Any other radius: products first, then the generic x pass.
    const int gx = d.nx - 2, gy = d.ny - 2, gz = d.nz - 2;
    std::vector<float> products(6 * std::size_t(gx) * gy * gz);
    float* p[6];
    for (int c = 0; c < 6; ++c) p[c] = products.data() + c * std::size_t(gx) * gy * gz;
    tensorProducts(in, d, toWorld, p);
    for (int c = 0; c < 6; ++c) blurX(p[c], BlockDims{gx, gy, gz}, w, r, out[c]);
}
std::size_t metricVoxels(const float* const J[6], std::size_t n, const std::uint8_t* mask, const MetricParams& p,
                         std::uint32_t* index, float* g)
{
    // Identity voxels (the vast majority far from contours) are skipped cheaply: xi_0 <= trace(J),
    // so trace(J) <= t * xi_ref means every mu_i = 1.
    const double floorTrace = p.threshold * p.xiRef, scale = 1.0 / (p.xiRef * (1.0 - p.threshold));
    const double offset = p.threshold / (1.0 - p.threshold);
    auto mu = [&](double xi, double gain) { return 1.0 + p.span * std::clamp(gain * (xi * scale - offset), 0.0, 1.0); };
    std::size_t count = 0;
    for (std::size_t v = 0; v < n; ++v) {
        if (mask && !mask[v]) continue;
        if (!(double(J[0][v]) + J[1][v] + J[2][v] > floorTrace)) continue;
        const double a[6] = {J[0][v], J[1][v], J[2][v], J[3][v], J[4][v], J[5][v]};
        SymmetricEigen3 e;
        symmetricEigenvalues3(a, e.value);
        const double m0 = mu(e.value[0], 1.0), m1 = mu(e.value[1], p.gain), m2 = mu(e.value[2], p.gain);
        if (m0 - 1.0 < p.activeTolerance) continue; // m0 >= m1 >= m2
        symmetricEigenvectors3(a, e);
        // G = sum mu_i w_i w_i^T = m2 I + (m0 - m2) w0 w0^T + (m1 - m2) w1 w1^T.
        const double* w0 = e.vector0;
        const double* w1 = e.vector1;
        const double a0 = m0 - m2, a1 = m1 - m2;
        auto entry = [&](int i, int j) { return float(a0 * w0[i] * w0[j] + a1 * w1[i] * w1[j] + (i == j ? m2 : 0.0)); };
        float* out = g + 6 * count;
        out[0] = entry(0, 0), out[1] = entry(1, 1), out[2] = entry(2, 2);
        out[3] = entry(0, 1), out[4] = entry(0, 2), out[5] = entry(1, 2);
        index[count++] = std::uint32_t(v);
    }
    return count;
}

void largestEigenvalues(const float* const J[6], const std::uint32_t* index, std::size_t n, float* out)
{
    for (std::size_t i = 0; i < n; ++i) {
        const std::size_t v = index[i];
        const double a[6] = {J[0][v], J[1][v], J[2][v], J[3][v], J[4][v], J[5][v]};
        double xi[3];
        symmetricEigenvalues3(a, xi);
        out[i] = float(std::max(0.0, xi[0]));
    }
}

} // namespace

#define RIEMESH_STR2(x) #x
#define RIEMESH_STR(x) RIEMESH_STR2(x)
extern const BrickKernels kKernels{blurX, blurY, blurZ, tensorProducts, tensorBlurX, tensorProductsHalf, metricVoxels, largestEigenvalues, RIEMESH_STR(RIEMESH_KERNEL_NS)};

} // namespace riemesh::vdb::detail::RIEMESH_KERNEL_NS
