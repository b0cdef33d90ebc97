// The core's parallel loops (issue 15): the same mesh, bit for bit, for 1 and 2 threads. Each
// scenario (a ball, a torus, two bubbles merging, two balls pinching apart, a dumbbell cut at its
// tube, a thin plate under a coarse Euclidean and an anisotropic metric, NanoVDB image and metric)
// evolves once per thread count; the vertex positions (compared as bytes), the faces and every
// iteration's statistics must match, and the invariants hold at every tenth iteration.
#include "contour_metric.h"
#include "mesh_invariants.h"
#include "riemesh/collision.h"
#include "riemesh/evolution.h"
#include "riemesh/primitives.h"
#include "riemesh/threads.h"
#include "topology_fixtures.h"

#include <doctest/doctest.h>

#include <nanovdb/util/GridBuilder.h>

#include <array>
#include <cmath>
#include <cstring>
#include <functional>
#include <memory>
#include <vector>

using namespace riemesh;

namespace {

using fixtures::ballSdf;
using fixtures::ContourMetric;
using fixtures::contourMetric;
using fixtures::fogImage;
using fixtures::torusSdf;

/// Restores the default thread count (all cores) when a test case ends, however it ends.
struct ThreadCountGuard {
    ~ThreadCountGuard() { setThreadCount(0); }
};

/// What a run produced: live vertices and faces in index order, and its iterations.
struct Outcome {
    std::vector<std::array<double, 3>> points;
    std::vector<std::array<int, 3>> faces;
    std::vector<IterationStats> iterations;
    std::size_t checkedIterations = 0;
    int failures = 0;
};

Outcome outcome(Mesh& mesh, const EvolutionStats& stats, int failures)
{
    mesh.garbage_collection();
    Outcome o;
    for (auto v : mesh.vertices()) o.points.push_back({mesh.point(v)[0], mesh.point(v)[1], mesh.point(v)[2]});
    for (auto f : mesh.faces()) {
        std::array<int, 3> t{};
        int k = 0;
        for (auto v : mesh.fv_range(f)) t[std::size_t(k++ % 3)] = v.idx();
        o.faces.push_back(t);
    }
    o.iterations = stats.iterations;
    o.failures = failures;
    return o;
}

/// Evolves `start` on `threads` threads, checking the invariants every tenth iteration.
Outcome run(int threads, Mesh mesh, const ScalarImage& image, const MetricField& metric, EvolutionOptions options)
{
    setThreadCount(threads);
    if (isParallel()) REQUIRE(threadCount() == threads);
    int failures = 0;
    options.progress = [&](const IterationStats& it) {
        if (it.iteration % 10 == 0 && mesh.n_faces() > 0) {
            const auto report = testing::checkInvariants(mesh);
            if (!report.ok() && failures++ == 0) {
                INFO(threads << " thread(s), iteration " << it.iteration << ": " << report.text());
                CHECK(report.ok());
            }
        }
        return failures == 0;
    };
    const EvolutionStats stats = evolve(mesh, image, metric, options);
    if (mesh.n_faces() > 0) CHECK_MESH_OK(mesh);
    return outcome(mesh, stats, failures);
}

/// True when the two outcomes are the same mesh, bit for bit, reached through the same iterations.
bool identical(const Outcome& a, const Outcome& b)
{
    if (a.points.size() != b.points.size() || a.faces != b.faces || a.iterations.size() != b.iterations.size())
        return false;
    if (!a.points.empty() && std::memcmp(a.points.data(), b.points.data(), a.points.size() * sizeof(a.points[0])) != 0)
        return false;
    for (std::size_t i = 0; i < a.iterations.size(); ++i) {
        const IterationStats &x = a.iterations[i], &y = b.iterations[i];
        if (x.vertices != y.vertices || x.splits != y.splits || x.collapses != y.collapses || x.flips != y.flips ||
            x.merges != y.merges || x.cuts != y.cuts || x.moving != y.moving ||
            std::memcmp(&x.meanKineticEnergy, &y.meanKineticEnergy, sizeof(double)) != 0)
            return false;
    }
    return true;
}

/// Runs the scenario on 1 and on 2 threads and requires the same outcome; returns it (`onTwo`: the
/// iterations on 2 threads).
Outcome checkSameForOneAndTwoThreads(const Mesh& start, const ScalarImage& image, const MetricField& metric,
                                     const EvolutionOptions& options, std::vector<IterationStats>* onTwo = nullptr)
{
    ThreadCountGuard guard;
    const Outcome one = run(1, start, image, metric, options);
    const Outcome two = run(2, start, image, metric, options);
    if (onTwo) *onTwo = two.iterations;
    INFO("1 thread: " << one.points.size() << " vertices, " << one.iterations.size() << " iterations; 2 threads: "
                      << two.points.size() << " vertices, " << two.iterations.size() << " iterations");
    CHECK(one.failures == 0);
    CHECK(two.failures == 0);
    CHECK(identical(one, two));
    return one;
}

int merges(const Outcome& o)
{
    int n = 0;
    for (const auto& it : o.iterations) n += it.merges;
    return n;
}

int cuts(const Outcome& o)
{
    int n = 0;
    for (const auto& it : o.iterations) n += it.cuts;
    return n;
}

EvolutionOptions baseOptions(double delta, int maxIterations = 600)
{
    EvolutionOptions o;
    o.delta = delta;
    o.maxIterations = maxIterations;
    return o;
}

/// A NanoVDB float grid sampling `f` on the voxels of `bounds` (unit voxels), and its image.
struct NanoScene {
    nanovdb::GridHandle<> grid;
    std::unique_ptr<NanoImage> image;
};

NanoScene nanoImage(const std::function<double(const Vec3&)>& f, const Box3& bounds)
{
    nanovdb::GridBuilder<float> builder(0.0f);
    const nanovdb::CoordBBox box(nanovdb::Coord(int(bounds.min().x()), int(bounds.min().y()), int(bounds.min().z())),
                                 nanovdb::Coord(int(bounds.max().x()), int(bounds.max().y()), int(bounds.max().z())));
    builder([&](const nanovdb::Coord& ijk) { return float(f(Vec3(ijk[0], ijk[1], ijk[2]))); }, box);
    NanoScene s;
    s.grid = builder.getHandle<>(1.0, nanovdb::Vec3d(0), "image");
    s.image = std::make_unique<NanoImage>(s.grid.grid<float>());
    return s;
}


} // namespace

TEST_CASE("parallel: the thread count is a process-wide setting, 0 lifts the limit")
{
    ThreadCountGuard guard;
    CHECK_THROWS_AS(setThreadCount(-1), std::invalid_argument);
    setThreadCount(1);
    CHECK(threadCount() == 1);
    setThreadCount(2);
    CHECK(threadCount() == (isParallel() ? 2 : 1));
    setThreadCount(0);
    CHECK(threadCount() >= 1);
}

TEST_CASE("parallel: a box deflating onto a ball gives the same mesh on 1 and 2 threads")
{
    const auto image = fogImage([](const Vec3& x) { return ballSdf(x, Vec3::Zero(), 10); },
                                Box3(Vec3::Constant(-13), Vec3::Constant(13)));
    const Outcome o = checkSameForOneAndTwoThreads(makeInitialBox(image, 1.6), image, EuclideanMetric(), baseOptions(0.8));
    CHECK(o.points.size() > 1000); // large enough for several chunks per loop
}

TEST_CASE("parallel: the comparison tells apart runs whose starts differ by one ulp in one coordinate")
{
    // The check above is no tautology: the evolution amplifies the smallest difference (as a
    // different summation order would make), and the comparison sees it.
    ThreadCountGuard guard;
    const auto image = fogImage([](const Vec3& x) { return ballSdf(x, Vec3::Zero(), 10); },
                                Box3(Vec3::Constant(-13), Vec3::Constant(13)));
    const Mesh start = makeInitialBox(image, 1.6);
    Mesh nudged = start;
    const VertexHandle v(7);
    nudged.point(v)[0] = std::nextafter(nudged.point(v)[0], 1e9);
    const Outcome a = run(2, start, image, EuclideanMetric(), baseOptions(0.8, 100));
    const Outcome b = run(2, nudged, image, EuclideanMetric(), baseOptions(0.8, 100));
    CHECK_FALSE(identical(a, b));
}

TEST_CASE("parallel: a box deflating onto a torus gives the same genus-1 mesh on 1 and 2 threads")
{
    const auto image = fogImage([](const Vec3& x) { return torusSdf(x, 8, 3); }, Box3(Vec3(-13, -13, -6), Vec3(13, 13, 6)));
    const Outcome o = checkSameForOneAndTwoThreads(makeInitialBox(image, 1.6), image, EuclideanMetric(), baseOptions(0.8));
    CHECK(o.points.size() > 500);
}

TEST_CASE("parallel: two bubbles merging inside a ball give the same mesh on 1 and 2 threads")
{
    const auto image = fogImage([](const Vec3& x) { return ballSdf(x, Vec3::Zero(), 9); },
                                Box3(Vec3::Constant(-12), Vec3::Constant(12)));
    const Mesh start = makeBubbles({{Vec3(-4, 0, 0), 2.0}, {Vec3(4, 0, 0), 2.0}}, 1.2);
    const Outcome o = checkSameForOneAndTwoThreads(start, image, EuclideanMetric(), baseOptions(0.8));
    CHECK(merges(o) >= 1);
}

TEST_CASE("parallel: a box pinching apart onto two balls gives the same meshes on 1 and 2 threads")
{
    const auto image = fogImage(
        [](const Vec3& x) { return std::max(ballSdf(x, Vec3(-7, 0, 0), 5), ballSdf(x, Vec3(7, 0, 0), 5)); },
        Box3(Vec3(-15, -8, -8), Vec3(15, 8, 8)));
    const Outcome o = checkSameForOneAndTwoThreads(makeInitialBox(image, 1.6), image, EuclideanMetric(), baseOptions(0.8));
    CHECK(cuts(o) >= 1);
}

TEST_CASE("parallel: the intersection-free evolution gives the same meshes on 1 and 2 threads")
{
    // On 2 threads the collision-safe step measures the pairs of the vertices it anchors again
    // while the regularity step edits the mesh (SafeStepCache), and the step itself runs beside
    // the regularity step, which is made again when the step comes out cut short (Evolution::
    // step); on 1 thread each comes before. Two bubbles merging inside a ball, and a box pinching
    // apart onto two balls: merges, cuts and the garbage collections after them while a
    // measurement may be under way, and a step cut short.
    EvolutionOptions options = baseOptions(0.8);
    options.intersectionFree = true;
    const auto ball = fogImage([](const Vec3& x) { return ballSdf(x, Vec3::Zero(), 9); },
                               Box3(Vec3::Constant(-12), Vec3::Constant(12)));
    const Outcome merged = checkSameForOneAndTwoThreads(makeBubbles({{Vec3(-4, 0, 0), 2.0}, {Vec3(4, 0, 0), 2.0}}, 1.2),
                                                        ball, EuclideanMetric(), options);
    CHECK(merges(merged) >= 1);
    const auto balls = fogImage(
        [](const Vec3& x) { return std::max(ballSdf(x, Vec3(-7, 0, 0), 5), ballSdf(x, Vec3(7, 0, 0), 5)); },
        Box3(Vec3(-15, -8, -8), Vec3(15, 8, 8)));
    std::vector<IterationStats> onTwo;
    const Outcome cut = checkSameForOneAndTwoThreads(makeInitialBox(balls, 1.6), balls, EuclideanMetric(), options, &onTwo);
    CHECK(cuts(cut) >= 1);
    int cutShort = 0, redoneOnOne = 0, redoneOnTwo = 0;
    for (const IterationStats& it : cut.iterations) cutShort += it.cutShort > 0, redoneOnOne += it.regularityRedone;
    for (const IterationStats& it : onTwo) redoneOnTwo += it.regularityRedone;
    CHECK(cutShort >= 1);
    CHECK(redoneOnOne == 0);
    if (isParallel()) CHECK(redoneOnTwo >= 1); // (the regularity step made again, and the same mesh)
}

TEST_CASE("parallel: a dumbbell whose tube is cut gives the same meshes on 1 and 2 threads")
{
    // The dumbbell fixture (two spheres of radius 4, 3 apart, a thin tube between them) on an
    // image of the two balls alone: the tube thins into a tunnel and is cut.
    const Mesh start = fixtures::makeDumbbell(4.0, 3, 3.0, 4);
    const auto image = fogImage(
        [](const Vec3& x) { return std::max(ballSdf(x, Vec3(0, 0, 0), 3.5), ballSdf(x, Vec3(11, 0, 0), 3.5)); },
        Box3(Vec3(-6, -6, -6), Vec3(17, 6, 6)));
    const Outcome o = checkSameForOneAndTwoThreads(start, image, EuclideanMetric(), baseOptions(0.6));
    CHECK(cuts(o) >= 1);
}

TEST_CASE("parallel: a thin plate, coarse Euclidean (punched) and anisotropic, the same on 1 and 2 threads")
{
    auto plate = [](const Vec3& x) { return std::min({1.5 - std::abs(x.z()), 20 - std::abs(x.x()), 20 - std::abs(x.y())}); };
    const auto image = fogImage(plate, Box3(Vec3(-24, -24, -8), Vec3(24, 24, 8)));
    const Outcome punched = checkSameForOneAndTwoThreads(makeInitialBox(image, 4.0), image, EuclideanMetric(), baseOptions(3.0, 200));
    CHECK(merges(punched) > 0);
    Mat3 g = Mat3::Identity();
    g(2, 2) = 9.0;
    checkSameForOneAndTwoThreads(makeInitialBox(image, 4.0), image, ConstantMetric(g), baseOptions(3.0, 200));
}

TEST_CASE("parallel: a NanoVDB image and contour metric give the same mesh on 1 and 2 threads")
{
    // Per-thread accessors: both grids are sampled from every thread at once.
    auto sdf = [](const Vec3& x) { return ballSdf(x, Vec3(16, 16, 16), 10); };
    const Box3 bounds(Vec3::Zero(), Vec3::Constant(32));
    const NanoScene scene = nanoImage([&](const Vec3& x) { return 0.5 + 0.5 * std::tanh(sdf(x)); }, bounds);
    const ContourMetric grids = contourMetric(sdf, bounds, 4.0, 2.0);
    const Outcome o = checkSameForOneAndTwoThreads(makeInitialBox(*scene.image, 2.4), *scene.image, *grids.metric,
                                                   baseOptions(1.2));
    CHECK(o.points.size() > 500);
}

TEST_CASE("parallel: findCollisions lists the same pairs in the same order on 1 and 2 threads")
{
    // Two spheres on a collision course, one step apart, and a torus close to itself.
    ThreadCountGuard guard;
    Mesh mesh = fixtures::makeRegularSphere(Vec3::Zero(), 4, 0.5);
    appendMesh(mesh, fixtures::makeRegularSphere(Vec3(2 * mesh.point(fixtures::extremeVertex(mesh, Vec3::UnitX()))[0] + 0.4, 0, 0), 4, 0.5));
    prepareMesh(mesh);
    CollisionOptions co;
    co.delta = 0.5;
    co.zeta = 2.5;
    co.vmax = 0.25;
    std::vector<CollisionPair> contacts1, contacts2;
    setThreadCount(1);
    const auto one = findCollisions(mesh, EuclideanMetric(), co, &contacts1);
    setThreadCount(2);
    const auto two = findCollisions(mesh, EuclideanMetric(), co, &contacts2);
    REQUIRE(!one.empty());
    REQUIRE(one.size() == two.size());
    for (std::size_t i = 0; i < one.size(); ++i) {
        CHECK(one[i].u == two[i].u);
        CHECK(one[i].w == two[i].w);
        CHECK(std::memcmp(&one[i].distance, &two[i].distance, sizeof(double)) == 0);
    }
    CHECK(contacts1.size() == contacts2.size());
}
