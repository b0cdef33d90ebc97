#include "riemesh/image.h"
#include "riemesh/metric.h"
#include "riemesh/primitives.h"

#include <doctest/doctest.h>

#include <cmath>
#include <stdexcept>

using namespace riemesh;

TEST_CASE("metric: Euclidean length equals the Euclidean distance")
{
    EuclideanMetric g;
    CHECK(metricLength(g, Vec3(0, 0, 0), Vec3(3, 4, 0)) == doctest::Approx(5.0));
}

TEST_CASE("metric: a constant anisotropic metric scales lengths by sqrt(mu) along its axis")
{
    Mat3 g = Mat3::Identity();
    g(2, 2) = 4.0;
    ConstantMetric m(g);
    CHECK(metricLength(m, Vec3(0, 0, 0), Vec3(0, 0, 1)) == doctest::Approx(2.0));
    CHECK(metricLength(m, Vec3(0, 0, 0), Vec3(1, 0, 0)) == doctest::Approx(1.0));
    CHECK(m.maxEigenvalue() == doctest::Approx(4.0));
}

TEST_CASE("metric: eigenvalues below 1 are refused")
{
    Mat3 g = Mat3::Identity() * 0.5;
    CHECK_THROWS_AS(ConstantMetric{g}, std::invalid_argument);
}

TEST_CASE("metric: a function metric is evaluated at the edge midpoint")
{
    FunctionMetric m([](const Vec3& x) { return x.x() > 0 ? Mat3(Mat3::Identity() * 4.0) : Mat3(Mat3::Identity()); }, 4.0);
    CHECK(metricLength(m, Vec3(-1, 0, 0), Vec3(-0.5, 0, 0)) == doctest::Approx(0.5));
    CHECK(metricLength(m, Vec3(0.5, 0, 0), Vec3(1, 0, 0)) == doctest::Approx(1.0));
}

TEST_CASE("metric: a dilated metric takes the largest of the samples within its radius along the axes")
{
    // A refined slab |z - 5| < 1 (mu 9 across it) in a Euclidean space.
    const FunctionMetric slab(
        [](const Vec3& x) {
            Mat3 g = Mat3::Identity();
            if (std::abs(x.z() - 5) < 1) g(2, 2) = 9;
            return g;
        },
        9.0);
    const DilatedMetric reach(slab, 3.0), none(slab, 0.0);
    CHECK(reach.maxEigenvalue() == 9.0);
    CHECK_FALSE(reach.isEuclidean());
    CHECK(reach.at(Vec3(0, 0, 8.5))(2, 2) == 9.0); // 3 below is in the slab
    CHECK(reach.at(Vec3(0, 0, 1.5))(2, 2) == 9.0); // 3 above
    CHECK(reach.at(Vec3(0, 0, 9.5))(2, 2) == 1.0); // out of reach
    CHECK(reach.at(Vec3(0, 0, 0.5))(2, 2) == 1.0);
    CHECK(reach.at(Vec3(7, -2, 5))(2, 2) == 9.0); // in it
    CHECK(none.at(Vec3(0, 0, 8.5))(2, 2) == 1.0); // radius 0: the metric itself
    // Lengths never shrink: the chosen sample has the largest trace, and each is SPD with
    // eigenvalues in [1, 9].
    CHECK(metricLength(reach, Vec3(0, 0, 7), Vec3(0, 0, 8)) == doctest::Approx(3.0));
    CHECK_THROWS_AS(DilatedMetric(slab, -1.0), std::invalid_argument);
    const EuclideanMetric euclidean;
    const DilatedMetric flat(euclidean, 2.0);
    CHECK(flat.isEuclidean());
}

TEST_CASE("metric: built from an eigenbasis it has those eigenvalues")
{
    Mat3 basis = Eigen::AngleAxisd(0.3, Vec3(1, 1, 0).normalized()).toRotationMatrix();
    Mat3 g = metricFromEigen(basis, Vec3(1, 2, 9));
    CHECK((g * basis.col(2) - 9.0 * basis.col(2)).norm() < 1e-12);
}

TEST_CASE("image: dense image interpolates trilinearly and its gradient follows a linear ramp")
{
    std::vector<float> data(4 * 4 * 4);
    for (int k = 0; k < 4; ++k)
        for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i) data[(k * 4 + j) * 4 + i] = float(2 * i + j);
    DenseImage img(4, 4, 4, data, Vec3(10, 0, 0), 0.5);
    CHECK(img.value(Vec3(10.25, 0.5, 0.5)) == doctest::Approx(2 * 0.5 + 1));
    const Vec3 g = img.gradient(Vec3(10.6, 0.6, 0.6));
    CHECK(g.x() == doctest::Approx(4.0));
    CHECK(g.y() == doctest::Approx(2.0));
}

TEST_CASE("image: function image uses its exact gradient when given")
{
    FunctionImage img([](const Vec3& x) { return x.squaredNorm(); }, Box3(Vec3(-1, -1, -1), Vec3(1, 1, 1)), 1.0,
                      [](const Vec3& x) { return Vec3(2 * x); });
    CHECK(img.gradient(Vec3(1, 2, 3)).isApprox(Vec3(2, 4, 6)));
}

TEST_CASE("metric: a mesh edge is measured with the mean of the endpoint tensors")
{
    FunctionMetric m([](const Vec3& x) { return x.x() > 0 ? Mat3(Mat3::Identity() * 4.0) : Mat3(Mat3::Identity()); }, 4.0);
    Mesh mesh;
    const auto a = mesh.add_vertex(Mesh::Point(-1, 0, 0));
    const auto b = mesh.add_vertex(Mesh::Point(1, 0, 0));
    const auto c = mesh.add_vertex(Mesh::Point(0, 1, 0));
    mesh.add_face(a, b, c);
    const auto e = mesh.edge_handle(mesh.find_halfedge(a, b));
    CHECK(metricLength(m, mesh, e) == doctest::Approx(2.0 * std::sqrt(2.5)));
}

TEST_CASE("metric: VertexMetrics samples G once per vertex position and again when a vertex moves")
{
    using namespace riemesh;
    int calls = 0;
    FunctionMetric metric([&calls](const Vec3& x) {
        ++calls;
        return Mat3(Mat3::Identity() * (1.0 + x.squaredNorm()));
    }, 1e6);
    Mesh mesh = makeIcosphere(Vec3::Zero(), 2.0, 1);
    prepareMesh(mesh);
    const int n = int(mesh.n_vertices());
    VertexMetrics cache(mesh, metric);
    CHECK(cache.update() == std::size_t(n));
    CHECK(calls == n);
    CHECK(cache.update() == 0); // nothing moved
    const VertexHandle v(3);
    const Mat3 before = cache.at(v);
    CHECK(calls == n);
    CHECK(before.isApprox(metric.at(position(mesh, v))));
    --calls; // the direct call above
    mesh.point(v) *= 1.5;
    const VertexMetrics reader(static_cast<const Mesh&>(mesh), metric); // read-only: samples, stores nothing
    CHECK(reader.at(v).isApprox(Mat3::Identity() * (1.0 + position(mesh, v).squaredNorm())));
    CHECK(calls == n + 1);
    CHECK(cache.update() == 1); // only the moved vertex
    CHECK(calls == n + 2);
    CHECK(reader.at(v).isApprox(Mat3::Identity() * (1.0 + position(mesh, v).squaredNorm())));
    CHECK(calls == n + 2); // now cached
    EuclideanMetric euclidean;
    VertexMetrics none(mesh, euclidean);
    CHECK(none.update() == 0);
    CHECK(none.at(v).isIdentity());
}
