// vdbphantom volumes: shape and topology from the sign of the exact distance, noise, seeds.
#include "riemesh/vdb/phantom.h"

#include <doctest/doctest.h>

#include <cmath>
#include <queue>
#include <vector>

using namespace riemesh::vdb;
using openvdb::Coord;

namespace {

/// Connected components (6-neighbourhood) of the voxels of the box [0,n)^3 where `inside(c)` holds.
template<typename Pred>
int countComponents(int n, Pred inside)
{
    std::vector<char> seen(std::size_t(n) * n * n, 0);
    auto id = [n](int i, int j, int k) { return (std::size_t(k) * n + j) * n + i; };
    int components = 0;
    for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                if (seen[id(i, j, k)] || !inside(Coord(i, j, k))) continue;
                ++components;
                std::queue<Coord> q;
                q.push(Coord(i, j, k));
                seen[id(i, j, k)] = 1;
                while (!q.empty()) {
                    const Coord c = q.front();
                    q.pop();
                    for (int a = 0; a < 3; ++a)
                        for (int s = -1; s <= 1; s += 2) {
                            Coord d = c;
                            d[a] += s;
                            if (d[a] < 0 || d[a] >= n || seen[id(d.x(), d.y(), d.z())] || !inside(d)) continue;
                            seen[id(d.x(), d.y(), d.z())] = 1;
                            q.push(d);
                        }
                }
            }
    return components;
}

} // namespace

TEST_CASE("phantom: cube-cavity is one solid whose cavity opens to the outside (genus 0)")
{
    PhantomOptions o;
    o.size = 50;
    const Phantom p = makePhantom(PhantomShape::CubeCavity, o);
    auto acc = p.sdf->getConstAccessor();
    const int n = o.size;
    // One solid, and one outside region: the cavity is reached from the box corner through the hole.
    CHECK(countComponents(n, [&](const Coord& c) { return acc.getValue(c) < 0; }) == 1);
    CHECK(countComponents(n, [&](const Coord& c) { return acc.getValue(c) >= 0; }) == 1);
    const int mid = (n - 1) / 2;
    CHECK(acc.getValue(Coord(mid, mid, mid)) > 0);      // cavity centre: outside the solid
    CHECK(acc.getValue(Coord(mid, mid, int(0.25 * n))) < 0); // below the cavity: solid
    // Without the hole the cavity would be a second outside region: plug it and count again.
    const double topZ = 0.5 * (n - 1) + 0.3 * n;
    CHECK(countComponents(n, [&](const Coord& c) {
              const bool plug = std::abs(c.z() - topZ) < 2.0 && std::hypot(c.x() - 0.5 * (n - 1), c.y() - 0.5 * (n - 1)) < 0.1 * n;
              return acc.getValue(c) >= 0 && !plug;
          }) == 2);
}

TEST_CASE("phantom: the sdf is an exact distance (unit gradient, sign matches the density)")
{
    PhantomOptions o;
    o.size = 40;
    for (auto shape : {PhantomShape::CubeCavity, PhantomShape::Ball, PhantomShape::Torus, PhantomShape::TwoSpheres,
                       PhantomShape::ThinPlate}) {
        const Phantom p = makePhantom(shape, o);
        auto sdf = p.sdf->getConstAccessor();
        auto den = p.density->getConstAccessor();
        int unit = 0, total = 0;
        for (int k = 2; k < o.size - 2; k += 3)
            for (int j = 2; j < o.size - 2; j += 3)
                for (int i = 2; i < o.size - 2; i += 3) {
                    const Coord c(i, j, k);
                    const double d = sdf.getValue(c);
                    CHECK((den.getValue(c) > 0.5) == (d < 0));
                    // The distance is 1-Lipschitz along every axis ...
                    for (int a = 0; a < 3; ++a) {
                        Coord e = c;
                        e[a] += 1;
                        CHECK(std::abs(sdf.getValue(e) - d) <= 1.0 + 1e-4);
                    }
                    // ... and away from the medial axis its gradient has unit length.
                    const double gx = 0.5 * (sdf.getValue(c.offsetBy(1, 0, 0)) - sdf.getValue(c.offsetBy(-1, 0, 0)));
                    const double gy = 0.5 * (sdf.getValue(c.offsetBy(0, 1, 0)) - sdf.getValue(c.offsetBy(0, -1, 0)));
                    const double gz = 0.5 * (sdf.getValue(c.offsetBy(0, 0, 1)) - sdf.getValue(c.offsetBy(0, 0, -1)));
                    unit += std::abs(std::sqrt(gx * gx + gy * gy + gz * gz) - 1.0) < 0.05;
                    ++total;
                }
        CHECK(unit > 0.7 * total);
    }
}

TEST_CASE("phantom: torus has one component with a hole, two-spheres two components")
{
    PhantomOptions o;
    o.size = 40;
    {
        const Phantom p = makePhantom(PhantomShape::Torus, o);
        auto acc = p.sdf->getConstAccessor();
        CHECK(countComponents(o.size, [&](const Coord& c) { return acc.getValue(c) < 0; }) == 1);
        const int mid = (o.size - 1) / 2;
        CHECK(acc.getValue(Coord(mid, mid, mid)) > 0); // the hole
    }
    {
        const Phantom p = makePhantom(PhantomShape::TwoSpheres, o);
        auto acc = p.sdf->getConstAccessor();
        CHECK(countComponents(o.size, [&](const Coord& c) { return acc.getValue(c) < 0; }) == 2);
    }
}

TEST_CASE("phantom: density is dense over the box, a fog volume, with the documented noise")
{
    PhantomOptions o;
    o.size = 40;
    o.noise = 0.5;
    o.seed = 7;
    const Phantom noisy = makePhantom(PhantomShape::Ball, o);
    o.noise = 0;
    const Phantom clean = makePhantom(PhantomShape::Ball, o);
    CHECK(noisy.density->getName() == "density");
    CHECK(noisy.sdf->getName() == "sdf");
    CHECK(noisy.density->getGridClass() == openvdb::GRID_FOG_VOLUME);
    CHECK(noisy.density->activeVoxelCount() == openvdb::Index64(40 * 40 * 40));
    auto a = noisy.density->getConstAccessor();
    auto b = clean.density->getConstAccessor();
    double sum = 0, sum2 = 0;
    std::size_t n = 0;
    for (auto it = clean.density->cbeginValueOn(); it; ++it) {
        const double e = a.getValue(it.getCoord()) - *it;
        sum += e;
        sum2 += e * e;
        ++n;
    }
    const double mean = sum / double(n), sd = std::sqrt(sum2 / double(n) - mean * mean);
    CHECK(std::abs(mean) < 0.01);
    CHECK(sd == doctest::Approx(0.5).epsilon(0.02));
    (void)b;
}

TEST_CASE("phantom: the same seed gives the same volume, another seed another one")
{
    PhantomOptions o;
    o.size = 24;
    o.noise = 0.3;
    o.seed = 42;
    const Phantom p1 = makePhantom(PhantomShape::CubeCavity, o);
    const Phantom p2 = makePhantom(PhantomShape::CubeCavity, o);
    o.seed = 43;
    const Phantom p3 = makePhantom(PhantomShape::CubeCavity, o);
    auto a2 = p2.density->getConstAccessor();
    auto a3 = p3.density->getConstAccessor();
    bool same = true, differs = false;
    for (auto it = p1.density->cbeginValueOn(); it; ++it) {
        same &= (a2.getValue(it.getCoord()) == *it);
        differs |= (a3.getValue(it.getCoord()) != *it);
    }
    CHECK(same);
    CHECK(differs);
}

TEST_CASE("phantom: notched-block is one solid with a notch along an edge; its distance is exact")
{
    PhantomOptions o;
    o.size = 40;
    const Phantom p = makePhantom(PhantomShape::NotchedBlock, o);
    auto acc = p.sdf->getConstAccessor();
    const int n = o.size;
    CHECK(countComponents(n, [&](const Coord& c) { return acc.getValue(c) < 0; }) == 1);
    CHECK(countComponents(n, [&](const Coord& c) { return acc.getValue(c) >= 0; }) == 1);
    const double cc = 0.5 * (n - 1), h = 0.3 * n, s = 0.05 * n;
    auto d = [&](double x, double y, double z) { return phantomDistance(PhantomShape::NotchedBlock, n, openvdb::Vec3d(cc + x, cc + y, cc + z)); };
    CHECK(d(0, 0, 0) == doctest::Approx(-s * std::sqrt(2.0))); // centre: nearest is the concave edge
    CHECK(d(-h + 1, 0, -s) == doctest::Approx(-1));     // a voxel inside the -x face
    CHECK(d(s + 4, 0, s + 4) == doctest::Approx(4));    // in the notch, 4 from both walls: 4 from the edge
    CHECK(d(h - 1, 0, h - 1) == doctest::Approx(h - 1 - s)); // deep in the notch: its walls, not its far end
    CHECK(d(h + 3, 0, -h - 4) == doctest::Approx(5));   // outside a convex edge
    // Against brute force: the distance to the solid's voxel-centre samples bounds it from above.
    for (const auto& q : {openvdb::Vec3d(3, 1, 9), openvdb::Vec3d(-9, 4, 2), openvdb::Vec3d(9, -2, 9)}) {
        const double exact = d(q.x(), q.y(), q.z());
        double nearest = 1e300;
        for (double x = -h; x <= h; x += 0.25)
            for (double z = -h; z <= h; z += 0.25) {
                if (x > s && z > s) continue; // the notch
                for (const double y : {q.y()})
                    if (exact > 0) nearest = std::min(nearest, std::hypot(x - q.x(), z - q.z()) + std::abs(y - q.y()));
            }
        if (exact > 0) CHECK(exact <= nearest + 1e-9);
        if (exact > 0) CHECK(exact >= nearest - 0.36); // (the samples' spacing)
    }
}

TEST_CASE("phantom: unknown shape names and bad sizes are refused")
{
    CHECK_THROWS_AS(phantomShapeFromName("cube"), std::invalid_argument);
    CHECK(phantomShapeFromName("thin-plate") == PhantomShape::ThinPlate);
    CHECK(phantomShapeFromName("notched-block") == PhantomShape::NotchedBlock);
    PhantomOptions o;
    o.size = 4;
    CHECK_THROWS_AS(makePhantom(PhantomShape::Ball, o), std::invalid_argument);
}
