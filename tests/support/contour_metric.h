// tests/support/contour_metric.h: a stand-in for the structure-tensor metric, shared by the core's
// tests (parallel_test) and bench/core_bench: sampled on a NanoVDB grid like the one vdb2mesh
// exports (the same NanoMetric code path), it multiplies lengths across the contour of an analytic
// sdf (along its gradient) by up to sqrt(muMax), within a Gaussian band around the surface.
#pragma once

#include "riemesh/image.h"
#include "riemesh/metric.h"
#include "riemesh/primitives.h"

#include <nanovdb/util/GridBuilder.h>

#include <cmath>
#include <functional>
#include <memory>

namespace riemesh::fixtures {

struct ContourMetric {
    nanovdb::GridHandle<> diag, off;
    std::unique_ptr<NanoMetric> metric;
};

/// The metric over the voxels of `bounds`: I + (muMax - 1) w g g^T, g the sdf's unit gradient
/// (central differences), w = exp(-sdf^2 / (2 bandSigma^2)) (the identity where w < 1e-3).
inline ContourMetric contourMetric(const std::function<double(const Vec3&)>& sdf, const Box3& bounds, double muMax,
                                   double bandSigma)
{
    const double twoSigma2 = 2.0 * bandSigma * bandSigma;
    auto tensor = [&](const nanovdb::Coord& ijk) {
        const Vec3 x(ijk[0], ijk[1], ijk[2]);
        const double d = sdf(x);
        const double w = std::exp(-d * d / twoSigma2);
        if (w < 1e-3) return Mat3(Mat3::Identity());
        Vec3 g;
        for (int a = 0; a < 3; ++a) {
            Vec3 e = Vec3::Zero();
            e[a] = 0.5;
            g[a] = sdf(x + e) - sdf(x - e);
        }
        if (!(g.norm() > 0)) return Mat3(Mat3::Identity());
        g.normalize();
        return Mat3(Mat3::Identity() + (muMax - 1.0) * w * g * g.transpose());
    };
    const nanovdb::CoordBBox box(nanovdb::Coord(int(bounds.min().x()), int(bounds.min().y()), int(bounds.min().z())),
                                 nanovdb::Coord(int(bounds.max().x()), int(bounds.max().y()), int(bounds.max().z())));
    nanovdb::GridBuilder<nanovdb::Vec3f> diag(nanovdb::Vec3f(1, 1, 1)), off(nanovdb::Vec3f(0, 0, 0));
    diag([&](const nanovdb::Coord& ijk) {
        const Mat3 g = tensor(ijk);
        return nanovdb::Vec3f(float(g(0, 0)), float(g(1, 1)), float(g(2, 2)));
    }, box);
    off([&](const nanovdb::Coord& ijk) {
        const Mat3 g = tensor(ijk);
        return nanovdb::Vec3f(float(g(0, 1)), float(g(0, 2)), float(g(1, 2)));
    }, box);
    ContourMetric grids;
    grids.diag = diag.getHandle<>(1.0, nanovdb::Vec3d(0), kMetricDiagGrid);
    grids.off = off.getHandle<>(1.0, nanovdb::Vec3d(0), kMetricOffGrid);
    grids.metric = std::make_unique<NanoMetric>(grids.diag.grid<nanovdb::Vec3f>(), grids.off.grid<nanovdb::Vec3f>(), muMax);
    return grids;
}

} // namespace riemesh::fixtures
