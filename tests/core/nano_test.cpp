// NanoVDB-backed fields: NanoImage, NanoMetric and NanoVolume (.nvdb read), built here with
// NanoVDB's GridBuilder (no OpenVDB in core).
#include "riemesh/image.h"
#include "riemesh/metric.h"

#include <nanovdb/util/GridBuilder.h>
#include <nanovdb/util/IO.h>

#include <doctest/doctest.h>

#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

using namespace riemesh;

namespace {

nanovdb::GridHandle<> rampGrid(double voxelSize, const nanovdb::Vec3d& origin)
{
    nanovdb::GridBuilder<float> builder(0.0f, nanovdb::GridClass::FogVolume);
    builder([](const nanovdb::Coord& ijk) { return float(ijk[0] + 2 * ijk[1]) + 1.0f; },
            nanovdb::CoordBBox(nanovdb::Coord(0), nanovdb::Coord(15)));
    return builder.getHandle<>(voxelSize, origin, "density");
}

nanovdb::GridHandle<> metricGrid(const char* name, nanovdb::Vec3f background, nanovdb::Vec3f inside)
{
    nanovdb::GridBuilder<nanovdb::Vec3f> builder(background);
    builder([inside](const nanovdb::Coord&) { return inside; },
            nanovdb::CoordBBox(nanovdb::Coord(0), nanovdb::Coord(7)));
    return builder.getHandle<>(0.5, nanovdb::Vec3d(10, 0, 0), name);
}

std::string tempPath(const char* name) { return std::string("/tmp/riemesh_nano_test_") + name; }

} // namespace

TEST_CASE("nano image: values are trilinear in world space and the gradient is in intensity per world unit")
{
    auto handle = rampGrid(0.5, nanovdb::Vec3d(10, 0, 0));
    NanoImage image(handle.grid<float>());
    CHECK(image.voxelSize() == doctest::Approx(0.5));
    // voxel (2,3,4) sits at world (11, 1.5, 2): value 2 + 6 + 1.
    CHECK(image.value(Vec3(11, 1.5, 2)) == doctest::Approx(9.0));
    CHECK(image.value(Vec3(11.25, 1.5, 2)) == doctest::Approx(9.5));
    const Vec3 g = image.gradient(Vec3(12.1, 2.1, 2.1));
    CHECK(g.x() == doctest::Approx(2.0));
    CHECK(g.y() == doctest::Approx(4.0));
    CHECK(g.z() == doctest::Approx(0.0));
}

TEST_CASE("nano metric: identity outside the active region, the stored tensor inside")
{
    auto diag = metricGrid(kMetricDiagGrid, nanovdb::Vec3f(1, 1, 1), nanovdb::Vec3f(4, 1, 9));
    auto off = metricGrid(kMetricOffGrid, nanovdb::Vec3f(0, 0, 0), nanovdb::Vec3f(0.5f, 0, 0));
    NanoMetric metric(diag.grid<nanovdb::Vec3f>(), off.grid<nanovdb::Vec3f>(), 9.0);
    const Mat3 inside = metric.at(Vec3(11, 1, 1));
    CHECK(inside(0, 0) == doctest::Approx(4.0));
    CHECK(inside(2, 2) == doctest::Approx(9.0));
    CHECK(inside(0, 1) == doctest::Approx(0.5));
    CHECK(inside(1, 0) == doctest::Approx(0.5));
    CHECK(metric.at(Vec3(-50, 0, 0)).isApprox(Mat3::Identity()));
    CHECK(metricLength(metric, Vec3(11, 1, 1), Vec3(11, 1, 1.5)) == doctest::Approx(1.5));
}

TEST_CASE("nano volume: an .nvdb with image and metric reads back with its metric bound")
{
    std::vector<nanovdb::GridHandle<>> handles;
    handles.push_back(rampGrid(0.5, nanovdb::Vec3d(10, 0, 0)));
    handles.push_back(metricGrid(kMetricDiagGrid, nanovdb::Vec3f(1, 1, 1), nanovdb::Vec3f(4, 1, 9)));
    handles.push_back(metricGrid(kMetricOffGrid, nanovdb::Vec3f(0, 0, 0), nanovdb::Vec3f(0.5f, 0, 0)));
    const std::string path = tempPath("volume.nvdb");
    nanovdb::io::writeGrids<nanovdb::HostBuffer, std::vector>(path, handles);
    NanoVolume volume = NanoVolume::read(path);
    REQUIRE(volume.imageGrid() != nullptr);
    REQUIRE(volume.metricDiag() != nullptr);
    REQUIRE(volume.metricOff() != nullptr);
    CHECK(volume.imageName() == "density");
    CHECK(volume.imageClass() == "fog");
    CHECK(volume.metricMaxEigenvalue() >= 9.0);
    CHECK(volume.metricMaxEigenvalue() <= 11.0);

    std::ifstream in(path, std::ios::binary);
    std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    NanoVolume fromMemory = NanoVolume::fromBytes(bytes.data(), bytes.size());
    CHECK(NanoImage(fromMemory.imageGrid()).value(Vec3(11, 1.5, 2)) == doctest::Approx(9.0));
    std::remove(path.c_str());
}

TEST_CASE("nano volume: missing, garbage and image-less files are refused with a message")
{
    CHECK_THROWS_AS(NanoVolume::read(tempPath("does-not-exist.nvdb")), std::runtime_error);
    const std::string garbage = tempPath("garbage.nvdb");
    { std::ofstream out(garbage, std::ios::binary); out << "this is not a NanoVDB file at all, just text"; }
    CHECK_THROWS_AS(NanoVolume::read(garbage), std::runtime_error);
    std::remove(garbage.c_str());

    std::vector<nanovdb::GridHandle<>> handles;
    handles.push_back(metricGrid(kMetricDiagGrid, nanovdb::Vec3f(1, 1, 1), nanovdb::Vec3f(4, 1, 9)));
    const std::string onlyMetric = tempPath("only-metric.nvdb");
    nanovdb::io::writeGrids<nanovdb::HostBuffer, std::vector>(onlyMetric, handles);
    try {
        NanoVolume::read(onlyMetric);
        FAIL("expected an error");
    } catch (const std::runtime_error& e) {
        CHECK(std::string(e.what()).find("no float grid") != std::string::npos);
    }
    std::remove(onlyMetric.c_str());
}
