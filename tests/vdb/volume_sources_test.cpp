// Volumes made in memory (riemesh/vdb/volume_sources.h): a strided array is read in any layout and
// element type to the same image (the same mesh as the phantom it copies), placed at
// origin + spacing * index; bad arrays are refused with the problem named.
#include "riemesh/vdb/pipeline.h"
#include "riemesh/vdb/volume_sources.h"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

using namespace riemesh;
using namespace riemesh::vdb;

namespace {

constexpr int kN = 32;

/// The noiseless ball phantom's density (phantom.cpp's formula), element (i, j, k) at [i][j][k].
template<typename T>
std::vector<T> ballValues(double scale = 1)
{
    std::vector<T> v(std::size_t(kN) * kN * kN);
    const double c = 0.5 * (kN - 1);
    for (int i = 0; i < kN; ++i)
        for (int j = 0; j < kN; ++j)
            for (int k = 0; k < kN; ++k) {
                const double d = std::sqrt((i - c) * (i - c) + (j - c) * (j - c) + (k - c) * (k - c)) - 0.3 * kN;
                v[(std::size_t(i) * kN + j) * kN + k] = T(float(std::clamp(0.5 - d, 0.0, 1.0)) * scale);
            }
    return v;
}

template<typename T>
ArrayView view(const std::vector<T>& v, ArrayElement e)
{
    ArrayView a;
    a.data = v.data();
    a.element = e;
    a.shape = {kN, kN, kN};
    a.strides = {std::int64_t(sizeof(T)) * kN * kN, std::int64_t(sizeof(T)) * kN, std::int64_t(sizeof(T))};
    return a;
}

std::vector<Vec3> meshPoints(Volume volume, double iso)
{
    PipelineOptions o;
    o.iso = iso;
    const PipelineResult r = meshVolume(volume, o);
    std::vector<Vec3> points;
    for (auto v : r.mesh.vertices()) points.push_back(position(r.mesh, v));
    return points;
}

std::string refusal(const ArrayView& a, const ArrayPlacement& p = {}, std::uint64_t budget = 0)
{
    try {
        volumeFromArray(a, p, budget);
    } catch (const std::invalid_argument& e) {
        return e.what();
    } catch (const std::runtime_error& e) {
        return e.what();
    }
    return "accepted";
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

} // namespace

TEST_CASE("volume sources: an array of the phantom's values meshes exactly like the phantom, in any layout and type")
{
    const std::vector<Vec3> phantom = meshPoints(phantomVolume("ball", kN, 0.0, 1), 0.5);
    REQUIRE(phantom.size() > 50);

    const auto c = ballValues<float>();
    CHECK(meshPoints(volumeFromArray(view(c, ArrayElement::Float32)), 0.5) == phantom);
    const auto d = ballValues<double>();
    CHECK(meshPoints(volumeFromArray(view(d, ArrayElement::Float64)), 0.5) == phantom);

    // Fortran order: the same elements, i fastest.
    std::vector<float> f(c.size());
    for (int i = 0; i < kN; ++i)
        for (int j = 0; j < kN; ++j)
            for (int k = 0; k < kN; ++k) f[(std::size_t(k) * kN + j) * kN + i] = c[(std::size_t(i) * kN + j) * kN + k];
    ArrayView fv = view(f, ArrayElement::Float32);
    fv.strides = {4, 4 * kN, 4 * kN * kN};
    CHECK(meshPoints(volumeFromArray(fv), 0.5) == phantom);

    // Negative strides: element (i, j, k) read backwards from the end of a reversed copy.
    std::vector<float> r(c.rbegin(), c.rend());
    ArrayView rv = view(r, ArrayElement::Float32);
    rv.data = r.data() + r.size() - 1;
    rv.strides = {-4 * kN * kN, -4 * kN, -4};
    CHECK(meshPoints(volumeFromArray(rv), 0.5) == phantom);

    // Integers: the ball scaled to 0..200 as uint8 meshes at 100 like the float ball at 0.5 (same
    // surface up to the rounding of the ramp's values).
    const auto u = ballValues<std::uint8_t>(200);
    const Volume uv = volumeFromArray(view(u, ArrayElement::UInt8));
    CHECK(uv.info().minValue == 0);
    CHECK(uv.info().maxValue == 200);
    CHECK(meshPoints(uv.copy(), 100).size() == doctest::Approx(double(phantom.size())).epsilon(0.1));
}

TEST_CASE("volume sources: voxel (i, j, k) sits at origin + spacing * (i, j, k); the class sets the isovalue default")
{
    const auto c = ballValues<float>();
    ArrayPlacement p;
    p.spacing = {0.5, 1.0, 2.0};
    p.origin = {10, -20, 30};
    p.gridClass = "fog";
    p.name = "ball";
    const Volume v = volumeFromArray(view(c, ArrayElement::Float32), p);
    const auto& info = v.info();
    CHECK(info.gridName == "ball");
    CHECK(info.gridClass == "fog");
    CHECK(info.format == "array");
    CHECK(info.voxelSize == 2.0);
    CHECK(info.activeVoxels == std::uint64_t(kN) * kN * kN);
    CHECK(info.worldBounds.min().isApprox(Vec3(10, -20, 30)));
    CHECK(info.worldBounds.max().isApprox(Vec3(10 + 0.5 * (kN - 1), -20 + (kN - 1), 30 + 2.0 * (kN - 1))));
    CHECK(pipelineIso(info, std::nullopt, "").first == 0.5);
}

TEST_CASE("volume sources: flat arrays, non-finite values, bad placements and budgets are refused naming the problem")
{
    auto c = ballValues<float>();
    ArrayView flat = view(c, ArrayElement::Float32);
    flat.shape = {kN, 1, kN};
    CHECK(contains(refusal(flat), "shape (32, 1, 32) is not a 3D block"));
    c[5] = std::numeric_limits<float>::quiet_NaN();
    c[7] = std::numeric_limits<float>::infinity();
    CHECK(contains(refusal(view(c, ArrayElement::Float32)), "the array has 2 non-finite (NaN or infinite) values"));
    c[5] = c[7] = 0;
    ArrayPlacement p;
    p.spacing = {1, 0, 1};
    CHECK(contains(refusal(view(c, ArrayElement::Float32), p), "spacing: must be > 0"));
    p = {};
    p.gridClass = "smoke";
    CHECK(contains(refusal(view(c, ArrayElement::Float32), p), "grid_class: 'smoke' is not fog, levelset or unknown"));
    ArrayView huge = view(c, ArrayElement::Float32);
    huge.shape = {4000, 4000, 4000};
    CHECK(contains(refusal(huge, {}, std::uint64_t(1) << 30), "needs about"));
    CHECK(contains([] {
        try {
            phantomVolume("ball", 32, 0, 1, "velocity");
        } catch (const std::invalid_argument& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    }(), "phantom grid: 'velocity' is not density or sdf"));
}
