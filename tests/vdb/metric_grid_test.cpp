// Structure tensor and metric: eigenvectors along the gradient, eigenvalue ordering, bounds, sparsity.
#include "riemesh/vdb/io.h"
#include "riemesh/vdb/metric_grid.h"
#include "riemesh/vdb/phantom.h"
#include "riemesh/vdb/structure_tensor.h"

#include <openvdb/tools/Interpolation.h>

#include <Eigen/Eigenvalues>

#include <doctest/doctest.h>

#include <cmath>
#include <functional>
#include <random>

using namespace riemesh::vdb;
using openvdb::Coord;

namespace {

openvdb::FloatGrid::Ptr denseImage(int n, const std::function<float(const openvdb::Vec3d&)>& f,
                                   openvdb::math::Transform::Ptr xform = nullptr)
{
    initialize();
    auto grid = openvdb::FloatGrid::create(0.0f);
    if (xform) grid->setTransform(xform);
    auto acc = grid->getAccessor();
    for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i)
                acc.setValue(Coord(i, j, k), f(grid->transform().indexToWorld(Coord(i, j, k))));
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    return grid;
}

Eigen::Matrix3d tensorAt(const StructureTensorGrids& t, const Coord& c)
{
    const auto d = t.diag->getConstAccessor().getValue(c);
    const auto o = t.off->getConstAccessor().getValue(c);
    Eigen::Matrix3d J;
    J << d[0], o[0], o[1], o[0], d[1], o[2], o[1], o[2], d[2];
    return J;
}

/// G at the centre of image voxel `c` (index space of `image`), interpolated from the metric's cells
/// as the core does (trilinear, the cells' own transform).
Eigen::Matrix3d metricAt(const MetricGrids& m, const openvdb::GridBase& image, const Coord& c)
{
    const openvdb::Vec3d world = image.transform().indexToWorld(c);
    const auto d = openvdb::tools::BoxSampler::sample(m.diag->tree(), m.diag->transform().worldToIndex(world));
    const auto o = openvdb::tools::BoxSampler::sample(m.off->tree(), m.off->transform().worldToIndex(world));
    Eigen::Matrix3d G;
    G << d[0], o[0], o[1], o[0], d[1], o[2], o[1], o[2], d[2];
    return G;
}

float smoothStep(double s) { return float(std::clamp(0.5 - s, 0.0, 1.0)); }

} // namespace

TEST_CASE("structure tensor: on a tilted plane, w0 is the gradient direction and xi1 = xi2 = 0")
{
    const openvdb::Vec3d nrm = openvdb::Vec3d(1, 2, 3).unit();
    const int n = 32;
    auto image = denseImage(n, [&](const openvdb::Vec3d& p) { return smoothStep(nrm.dot(p - openvdb::Vec3d(15.5))); });
    const auto t = structureTensor(*image, {1.0, 2.0});
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(tensorAt(t, Coord(16, 16, 15)));
    const Eigen::Vector3d xi = es.eigenvalues(); // ascending
    const Eigen::Vector3d w0 = es.eigenvectors().col(2);
    CHECK(xi[2] > 0.01);
    CHECK(xi[1] < 1e-3 * xi[2]);
    CHECK(std::abs(w0.dot(Eigen::Vector3d(nrm.x(), nrm.y(), nrm.z()))) > 0.999);
}

TEST_CASE("structure tensor: on a ball's surface, w0 is radial; at a corner all three eigenvalues are large")
{
    const int n = 40;
    const openvdb::Vec3d c(19.5);
    auto ball = denseImage(n, [&](const openvdb::Vec3d& p) { return smoothStep((p - c).length() - 10.0); });
    const auto t = structureTensor(*ball, {1.0, 2.0});
    const Coord onSurface(30, 20, 20); // (10.5, 0.5, 0.5) from the centre
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(tensorAt(t, onSurface));
    const Eigen::Vector3d xi = es.eigenvalues();
    CHECK(xi[2] >= xi[1]);
    CHECK(xi[1] >= xi[0]);
    const Eigen::Vector3d radial = Eigen::Vector3d(10.5, 0.5, 0.5).normalized();
    CHECK(std::abs(es.eigenvectors().col(2).dot(radial)) > 0.99);
    CHECK(xi[1] < 0.2 * xi[2]); // gently curved: mostly a flat contour at this scale

    // A cube corner: the gradient turns through three directions within the window.
    auto cube = denseImage(n, [&](const openvdb::Vec3d& p) {
        return smoothStep(std::max({std::abs(p.x() - c.x()), std::abs(p.y() - c.y()), std::abs(p.z() - c.z())}) - 10.0);
    });
    const auto tc = structureTensor(*cube, {1.0, 2.0});
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> corner(tensorAt(tc, Coord(30, 30, 30)));
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> face(tensorAt(tc, Coord(30, 20, 20)));
    CHECK(corner.eigenvalues()[0] > 0.2 * corner.eigenvalues()[2]);
    CHECK(face.eigenvalues()[1] < 0.05 * face.eigenvalues()[2]);
}

TEST_CASE("structure tensor: eigenvectors are world-space directions under an anisotropic transform")
{
    // Voxels twice as long along z: a plane with world normal (0, 1, 1)/sqrt2.
    openvdb::math::Mat4d m = openvdb::math::Mat4d::identity();
    m(2, 2) = 2.0;
    auto xform = openvdb::math::Transform::createLinearTransform(m);
    const openvdb::Vec3d nrm = openvdb::Vec3d(0, 1, 1).unit();
    auto image = denseImage(32, [&](const openvdb::Vec3d& p) { return smoothStep(nrm.dot(p - openvdb::Vec3d(16, 16, 32))); },
                            xform);
    const auto t = structureTensor(*image, {1.0, 2.0});
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(tensorAt(t, Coord(16, 16, 16)));
    CHECK(std::abs(es.eigenvectors().col(2).dot(Eigen::Vector3d(0, 1, 1).normalized())) > 0.99);
}

TEST_CASE("metric: eigenvalues in [1, muMax], muMax along contour normals, identity away from contours")
{
    PhantomOptions o;
    o.size = 48;
    o.noise = 0.3;
    const Phantom p = makePhantom(PhantomShape::CubeCavity, o);
    MetricOptions mo;
    mo.muMax = 9.0;
    const MetricGrids m = computeMetric(*p.density, {1.0, 2.0}, mo);
    CHECK(m.diag->getName() == "metric_diag");
    CHECK(m.off->getName() == "metric_off");
    CHECK(m.diag->background() == openvdb::Vec3f(1.0f));
    CHECK(m.off->background() == openvdb::Vec3f(0.0f));
    CHECK(m.diag->metaValue<double>(kMuMaxMetadata) == 9.0);
    // The metric's cells are 2x2x2 voxels: cell (0, 0, 0) sits between voxels 0 and 1.
    CHECK(m.diag->voxelSize() == p.density->voxelSize() * 2.0);
    CHECK(m.diag->indexToWorld(Coord(0)) == p.density->indexToWorld(openvdb::Vec3d(0.5)));
    CHECK(m.activeVoxels == m.diag->activeVoxelCount());
    // Sparse: active only near the contours.
    CHECK(m.activeVoxels > 0);
    CHECK(double(m.activeVoxels) < 0.4 * double(m.totalVoxels));

    double maxMu = 0;
    for (auto it = m.diag->cbeginValueOn(); it; ++it) {
        const auto d = *it;
        const auto off = m.off->getConstAccessor().getValue(it.getCoord());
        Eigen::Matrix3d cell;
        cell << d[0], off[0], off[1], off[0], d[1], off[2], off[1], off[2], d[2];
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cell);
        CHECK(es.eigenvalues()[0] >= 1.0 - 1e-4);
        CHECK(es.eigenvalues()[2] <= 9.0 + 1e-3);
        maxMu = std::max(maxMu, es.eigenvalues()[2]);
    }
    CHECK(maxMu > 8.0);
    // Far from every contour (box corner, cavity centre, deep inside the wall) G = I and inactive.
    const int mid = (o.size - 1) / 2;
    for (const Coord c : {Coord(2, 2, 2), Coord(mid, mid, mid), Coord(o.size - 3, 2, o.size - 3)}) {
        CHECK_FALSE(m.diag->tree().isValueOn(c >> 1));
        CHECK(metricAt(m, *p.density, c).isApprox(Eigen::Matrix3d::Identity()));
    }
    // On a flat face: muMax along the face normal (x), small along the face.
    const Coord onFace(int(std::lround(0.5 * (o.size - 1) + 0.3 * o.size)), mid - 6, mid - 6);
    const Eigen::Matrix3d G = metricAt(m, *p.density, onFace);
    CHECK(G(0, 0) > 5.0);
    CHECK(G(1, 1) < 2.5);
    CHECK(G(2, 2) < 2.5);
}

TEST_CASE("metric: muMax = 1 and a constant image give the identity everywhere")
{
    auto flat = denseImage(16, [](const openvdb::Vec3d&) { return 0.25f; });
    const MetricGrids m = computeMetric(*flat);
    CHECK(m.activeVoxels == 0);
    PhantomOptions o;
    o.size = 24;
    const Phantom p = makePhantom(PhantomShape::Ball, o);
    MetricOptions mo;
    mo.muMax = 1.0;
    CHECK(computeMetric(*p.density, {}, mo).activeVoxels == 0);
}

TEST_CASE("gaussianSmooth: keeps constants and the transform, and reduces noise by the expected factor")
{
    PhantomOptions o;
    o.size = 32;
    const Phantom p = makePhantom(PhantomShape::Ball, o);
    auto s = gaussianSmooth(*p.density, 1.0);
    CHECK(s->transform() == p.density->transform());
    CHECK(s->getName() == "density");
    CHECK(s->getGridClass() == openvdb::GRID_FOG_VOLUME);
    CHECK(s->activeVoxelCount() == p.density->activeVoxelCount());
    auto c = gaussianSmooth(*denseImage(16, [](const openvdb::Vec3d&) { return 3.0f; }), 2.0);
    for (auto it = c->cbeginValueOn(); it; ++it) CHECK(*it == doctest::Approx(3.0f));
    // White noise of std 1 blurred by sigma = 1 has std (2 sqrt(pi))^-3/2 ~ 0.150.
    std::mt19937 rng(3);
    std::normal_distribution<float> normal(0.0f, 1.0f);
    auto noise = denseImage(40, [&](const openvdb::Vec3d&) { return normal(rng); });
    auto sn = gaussianSmooth(*noise, 1.0);
    auto acc = sn->getConstAccessor();
    double sum2 = 0;
    int n = 0;
    for (int k = 5; k < 35; ++k)
        for (int j = 5; j < 35; ++j)
            for (int i = 5; i < 35; ++i, ++n) sum2 += double(acc.getValue(Coord(i, j, k))) * acc.getValue(Coord(i, j, k));
    CHECK(std::sqrt(sum2 / n) == doctest::Approx(0.150).epsilon(0.08));
}

TEST_CASE("metric: the edge gain refines across a cube's edges and leaves its faces coarse")
{
    const int n = 40;
    const openvdb::Vec3d c(19.5);
    auto cube = denseImage(n, [&](const openvdb::Vec3d& p) {
        return smoothStep(std::max({std::abs(p.x() - c.x()), std::abs(p.y() - c.y()), std::abs(p.z() - c.z())}) - 10.0);
    });
    const Coord edge(30, 30, 20), face(30, 20, 20); // on the x = y edge mid-way; a face centre
    auto tangential = [&](double gain, const Coord& at) {
        MetricOptions o;
        o.tangentialGain = gain;
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(metricAt(computeMetric(*cube, {1.0, 2.0}, o), *cube, at));
        return es.eigenvalues()[1]; // the middle eigenvalue: across the edge, tangent to both faces
    };
    const double plain = tangential(1.0, edge), boosted = tangential(4.0, edge);
    MESSAGE("mu across the edge: gain 1 -> " << plain << ", gain 4 -> " << boosted);
    CHECK(boosted > 3.0);            // edges across it ~2x shorter than on a face (muMax 9)
    // The cells' metric (2x2x2 voxels) is a little smoother than a voxel one, which raises the plain
    // value near the edge (1.86 vs 3.34 boosted; a per-voxel metric gave more than 2x).
    CHECK(boosted > 1.6 * plain);
    CHECK(tangential(4.0, face) < 1.5); // flat face: tangential directions stay ~Euclidean
    CHECK_THROWS(tangential(0.5, edge));
}

TEST_CASE("metric: the reference fraction refines a thin plate's corners as much as its faces")
{
    // The thin-plate phantom (3 voxels thick): at its corners the structure tensor's xi_0 is about a
    // quarter of its faces', so with xi_ref at the faces' level the corners stayed nearly Euclidean
    // (and came out cut by 5 voxels). With the default fraction they reach most of muMax.
    PhantomOptions po;
    po.size = 60;
    const Phantom p = makePhantom(PhantomShape::ThinPlate, po);
    const double cc = 0.5 * (po.size - 1), half = 0.35 * po.size;
    // One voxel inside the corner at (+x, -y), mid-thickness; and the middle of the top face.
    const Coord corner(int(std::lround(cc + half - 1)), int(std::lround(cc - half + 1)), int(std::lround(cc)));
    const Coord face(int(std::lround(cc)), int(std::lround(cc)), int(std::lround(cc + 1.5)));
    auto largest = [&](double fraction, const Coord& at) {
        MetricOptions o;
        o.referenceFraction = fraction;
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(metricAt(computeMetric(*p.density, {1.0, 2.0}, o), *p.density, at));
        return es.eigenvalues()[2];
    };
    const double before = largest(1.0, corner), now = largest(MetricOptions{}.referenceFraction, corner);
    MESSAGE("largest mu at the plate's corner: fraction 1 -> " << before << ", default -> " << now);
    CHECK(MetricOptions{}.referenceFraction < 1.0);
    CHECK(now > 6.0);
    CHECK(now > before + 2.0);
    CHECK(largest(MetricOptions{}.referenceFraction, face) > 8.0); // the faces stay saturated
    CHECK_THROWS(largest(0.0, corner));
    CHECK_THROWS(largest(1.5, corner));
}
