// Intersection-free motion (issue 17): the CCD predicates, the collision-safe step, and the
// evolution keeping two surfaces driven into each other apart.
#include "../../core/src/detail/triangle_intersection.h" // private to the core: included by path
#include "mesh_invariants.h"
#include "riemesh/ccd.h"
#include "riemesh/edge_ops.h"
#include "riemesh/evolution.h"
#include "riemesh/primitives.h"
#include "riemesh/regularity.h"
#include "riemesh/self_intersection.h"

#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <random>

using namespace riemesh;

namespace {

const Vec3 kA(0, 0, 0), kB(1, 0, 0), kC(0, 1, 0); // a triangle in z = 0

} // namespace

TEST_CASE("ccd: distances from a point to a triangle and between segments, degenerate cases included")
{
    CHECK(pointTriangleDistanceSquared(Vec3(0.2, 0.2, 0.5), kA, kB, kC) == doctest::Approx(0.25));
    CHECK(pointTriangleDistanceSquared(Vec3(-1, 0, 0), kA, kB, kC) == doctest::Approx(1.0));
    CHECK(pointTriangleDistanceSquared(Vec3(1, 1, 0), kA, kB, kC) == doctest::Approx(0.5));
    // A flat triangle (collinear corners): the distance to its segment.
    CHECK(pointTriangleDistanceSquared(Vec3(0.5, 1, 0), kA, kB, Vec3(2, 0, 0)) == doctest::Approx(1.0));
    // Crossing, skew, parallel (overlapping and apart) and point-like segments.
    CHECK(segmentSegmentDistanceSquared(Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0, -1, 0), Vec3(0, 1, 0)) == doctest::Approx(0.0));
    CHECK(segmentSegmentDistanceSquared(Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0, -1, 2), Vec3(0, 1, 2)) == doctest::Approx(4.0));
    CHECK(segmentSegmentDistanceSquared(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 1, 0), Vec3(2, 1, 0)) == doctest::Approx(1.0));
    CHECK(segmentSegmentDistanceSquared(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(3, 0, 0), Vec3(4, 0, 0)) == doctest::Approx(4.0));
    CHECK(segmentSegmentDistanceSquared(Vec3(0, 0, 0), Vec3(0, 0, 0), Vec3(3, 0, 0), Vec3(3, 0, 0)) == doctest::Approx(9.0));
}

TEST_CASE("ccd: trianglesCloserThan answers as triangleSeparation < r, for pairs sharing 0 to 2 corners")
{
    // Random pairs: b's corners near a's (so that small r are met as well), some of them shared.
    std::mt19937 rng(1717);
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    auto jitter = [&](double s) { return Vec3(s * unit(rng), s * unit(rng), s * unit(rng)); };
    std::size_t closer = 0, farther = 0;
    for (int n = 0; n < 4000; ++n) {
        const std::array<Vec3, 3> a = {jitter(1), jitter(1), jitter(1)};
        const std::array<int, 3> ia = {0, 1, 2};
        const int shared = n % 3; // corners of b that are a's
        std::array<Vec3, 3> b;
        std::array<int, 3> ib;
        const double scale = std::pow(10.0, -double(n % 7)); // how near the others lie to a's corners
        for (int k = 0; k < 3; ++k) {
            const std::size_t i = std::size_t(k);
            if (k < shared) b[i] = a[i], ib[i] = k;
            else b[i] = a[(i + std::size_t(n)) % 3] + jitter(scale) + (k == 2 ? jitter(1) : Vec3::Zero()), ib[i] = 3 + k;
        }
        const double d = triangleSeparation(ia, a, ib, b);
        for (double r : {1e-9, 1e-6, 1e-4, 1e-2, 0.1, 0.5, 2.0}) {
            const bool expect = d < r;
            CHECK(trianglesCloserThan(ia, a, ib, b, r) == expect);
            CHECK(trianglesCloserThan(ib, b, ia, a, r) == expect);
            (expect ? closer : farther) += 1;
        }
        CHECK_FALSE(trianglesCloserThan(ia, a, ib, b, 0.0));
    }
    // Both answers were asked for, many times.
    CHECK(closer > 2000);
    CHECK(farther > 2000);
}

TEST_CASE("ccd: the edit guard's separating plane proves only what the exact tests find")
{
    // separatedBeyondShared is a shortcut before classifyTriangles and trianglesCloserThan: it may
    // say "don't know" (false), but when it says the pair is apart the exact tests must agree.
    // Random pairs sharing 0, 1 or 2 corners, from fans of a regular mesh (flat and creased, where
    // it should settle nearly every pair) to near-folds, crossings and tiny gaps.
    std::mt19937 rng(4242);
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    auto jitter = [&](double s) { return Vec3(s * unit(rng), s * unit(rng), s * unit(rng)); };
    auto corners = [](const std::array<Vec3, 3>& p) {
        return std::array<const double*, 3>{p[0].data(), p[1].data(), p[2].data()};
    };
    std::size_t settled = 0, asked = 0, unsafe = 0;
    for (int n = 0; n < 20000; ++n) {
        const int shared = n % 3;
        std::array<Vec3, 3> a, b;
        const std::array<int, 3> ia = {0, 1, 2};
        std::array<int, 3> ib = {3, 4, 5};
        if (n % 2 == 0) {
            // A fan around the origin (corners at unit distance, angles apart), bent by a random
            // crease angle along the shared corner or edge, then jittered by 10^-k.
            const double t0 = 0, t1 = 0.6 + 0.8 * std::abs(unit(rng));
            const double gap = shared == 2 ? 0.0 : 0.3 + 2.0 * std::abs(unit(rng));
            const double t2 = t1 + gap, t3 = t2 + 0.6 + 0.8 * std::abs(unit(rng));
            const double bend = 3.0 * unit(rng); // radians out of the plane for b's far corner
            auto on = [](double t, double z) { return Vec3(std::cos(t), std::sin(t), z); };
            a = {Vec3::Zero(), on(t0, 0), on(t1, 0)};
            if (shared == 2) b = {Vec3::Zero(), on(t1, 0), Vec3(std::cos(t3) * std::cos(bend), std::sin(t3) * std::cos(bend), std::sin(bend))};
            else b = {Vec3::Zero(), on(t2, std::sin(bend)), on(t3, std::sin(bend))};
            if (shared == 0) b[0] = Vec3(0, 0, 0.3 * unit(rng)) + jitter(0.2);
            const double s = std::pow(10.0, -double(n % 9));
            for (auto& p : a) p += jitter(s);
            for (int k = shared; k < 3; ++k) b[std::size_t(k)] += jitter(s);
            if (shared >= 1) b[0] = a[0], ib[0] = 0;
            if (shared == 2) b[1] = a[2], ib[1] = 2;
        } else {
            // Anything: b's free corners near a's, at scales down to 1e-8.
            a = {jitter(1), jitter(1), jitter(1)};
            const double s = std::pow(10.0, -double(n % 9));
            for (int k = 0; k < 3; ++k) {
                const std::size_t i = std::size_t(k);
                if (k < shared) b[i] = a[i], ib[i] = k;
                else b[i] = a[(i + std::size_t(n)) % 3] + jitter(s) + (k == 2 ? jitter(1) : Vec3::Zero());
            }
        }
        const detail::TriangleRef ra = detail::makeTriangle(a[0].data(), a[1].data(), a[2].data());
        const detail::TriangleRef rb = detail::makeTriangle(b[0].data(), b[1].data(), b[2].data());
        if (ra.axis < 0 || rb.axis < 0) continue; // (the guard skips degenerate faces)
        for (double r : {0.0, 1e-9, 1e-6, 1e-3, 0.05, 0.3}) {
            ++asked;
            const bool apart = detail::separatedBeyondShared(ia, corners(a).data(), ib, corners(b).data(), r);
            CHECK(apart == detail::separatedBeyondShared(ib, corners(b).data(), ia, corners(a).data(), r));
            const bool meet = detail::classifyTriangles(ia, ra, ib, rb) != detail::TriangleContact::None;
            const bool close = trianglesCloserThan(ia, a, ib, b, r);
            unsafe += meet || close;
            if (!apart) continue;
            ++settled;
            CHECK_FALSE(meet);
            CHECK_FALSE(close);
        }
    }
    // Two faces on a shared edge shorter than r, open flat: the edges from the free corners to the
    // edge's two ends come within its length of each other, however far the corners are from the
    // plane between the faces (the bound on those edges must give way to their distance); with r
    // well below the edge's length, the bound settles the pair.
    {
        const std::array<Vec3, 3> a = {Vec3(0, 0, 0), Vec3(0.01, 0, 0), Vec3(0.005, 1, 0)};
        const std::array<Vec3, 3> b = {Vec3(0, 0, 0), Vec3(0.01, 0, 0), Vec3(0.005, -1, 0)};
        const std::array<int, 3> ia = {0, 1, 2}, ib = {0, 1, 3};
        CHECK(trianglesCloserThan(ia, a, ib, b, 0.05));
        CHECK_FALSE(detail::separatedBeyondShared(ia, corners(a).data(), ib, corners(b).data(), 0.05));
        CHECK_FALSE(trianglesCloserThan(ia, a, ib, b, 1e-4));
        CHECK(detail::separatedBeyondShared(ia, corners(a).data(), ib, corners(b).data(), 1e-4));
    }
    // Both kinds were met many times, and the shortcut settled most pairs.
    MESSAGE("settled " << settled << " of " << asked << "; " << unsafe << " crossing or closer than r");
    CHECK(unsafe > asked / 20);
    CHECK(settled > asked / 2);
}

TEST_CASE("ccd: a point passing through a triangle in one step collides, one passing beside it does not")
{
    const double eta = 1e-3;
    // Straight through the interior, from 1 above to 1 below.
    const CcdResult through = pointTriangleCcd(Vec3(0.25, 0.25, 1), kA, kB, kC, Vec3(0.25, 0.25, -1), kA, kB, kC, eta);
    CHECK(through.collides);
    CHECK(through.toi < 0.5); // still above the plane at the reported time
    CHECK(through.toi >= 0.0);
    // Beside it (x + y > 1 all along): no collision.
    CHECK_FALSE(pointTriangleCcd(Vec3(1, 1, 1), kA, kB, kC, Vec3(1, 1, -1), kA, kB, kC, eta).collides);
    // The triangle moves through a resting point.
    CHECK(pointTriangleCcd(Vec3(0.2, 0.2, 0), kA + Vec3(0, 0, 1), kB + Vec3(0, 0, 1), kC + Vec3(0, 0, 1), Vec3(0.2, 0.2, 0),
                           kA - Vec3(0, 0, 1), kB - Vec3(0, 0, 1), kC - Vec3(0, 0, 1), eta)
              .collides);
    // Sliding parallel to the triangle at a distance: no collision; moving together: none either.
    CHECK_FALSE(pointTriangleCcd(Vec3(0.1, 0.1, 0.5), kA, kB, kC, Vec3(0.6, 0.1, 0.5), kA, kB, kC, eta).collides);
    const Vec3 shift(3, -2, 5);
    CHECK_FALSE(pointTriangleCcd(Vec3(0.2, 0.2, 0.01), kA, kB, kC, Vec3(0.2, 0.2, 0.01) + shift, kA + shift, kB + shift,
                                 kC + shift, eta)
                    .collides);
    // Ending just short of the plane, closer than eta: a collision.
    CHECK(pointTriangleCcd(Vec3(0.2, 0.2, 1), kA, kB, kC, Vec3(0.2, 0.2, 0.5 * eta), kA, kB, kC, eta).collides);
    // A flat (degenerate) triangle is its segments: a point crossing it still collides.
    CHECK(pointTriangleCcd(Vec3(0.5, 0, 1), kA, kB, Vec3(2, 0, 0), Vec3(0.5, 0, -1), kA, kB, Vec3(2, 0, 0), eta).collides);
}

TEST_CASE("ccd: edges crossing in one step collide; parallel and separating ones do not")
{
    const double eta = 1e-3;
    // Edge along x at z = 1 moving to z = -1 through an edge along y at z = 0.
    CHECK(edgeEdgeCcd(Vec3(-1, 0, 1), Vec3(1, 0, 1), Vec3(0, -1, 0), Vec3(0, 1, 0), Vec3(-1, 0, -1), Vec3(1, 0, -1),
                      Vec3(0, -1, 0), Vec3(0, 1, 0), eta)
              .collides);
    // The same motion beside the other edge's end (x in [2, 4]): no collision.
    CHECK_FALSE(edgeEdgeCcd(Vec3(2, 0, 1), Vec3(4, 0, 1), Vec3(0, -1, 0), Vec3(0, 1, 0), Vec3(2, 0, -1), Vec3(4, 0, -1),
                            Vec3(0, -1, 0), Vec3(0, 1, 0), eta)
                    .collides);
    // Parallel edges sliding along each other at distance 0.5: none; moving onto each other: one.
    CHECK_FALSE(edgeEdgeCcd(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 0.5, 0), Vec3(1, 0.5, 0), Vec3(0.7, 0, 0), Vec3(1.7, 0, 0),
                            Vec3(0, 0.5, 0), Vec3(1, 0.5, 0), eta)
                    .collides);
    CHECK(edgeEdgeCcd(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 0.5, 0), Vec3(1, 0.5, 0), Vec3(0, 1, 0), Vec3(1, 1, 0),
                      Vec3(0, 0.5, 0), Vec3(1, 0.5, 0), eta)
              .collides);
    // Moving apart: none. No motion at all: none.
    CHECK_FALSE(edgeEdgeCcd(Vec3(-1, 0, 0.1), Vec3(1, 0, 0.1), Vec3(0, -1, 0), Vec3(0, 1, 0), Vec3(-1, 0, 1), Vec3(1, 0, 1),
                            Vec3(0, -1, 0), Vec3(0, 1, 0), eta)
                    .collides);
    CHECK_FALSE(edgeEdgeCcd(Vec3(-1, 0, 0.1), Vec3(1, 0, 0.1), Vec3(0, -1, 0), Vec3(0, 1, 0), Vec3(-1, 0, 0.1),
                            Vec3(1, 0, 0.1), Vec3(0, -1, 0), Vec3(0, 1, 0), eta)
                    .collides);
    // A degenerate (zero-length) edge is a point: crossing the other edge still collides.
    CHECK(edgeEdgeCcd(Vec3(0, 0, 1), Vec3(0, 0, 1), Vec3(0, -1, 0), Vec3(0, 1, 0), Vec3(0, 0, -1), Vec3(0, 0, -1),
                      Vec3(0, -1, 0), Vec3(0, 1, 0), eta)
              .collides);
}

TEST_CASE("ccd: a sphere driven into another in one big step stops before the faces cross")
{
    // Two unit spheres 0.05 apart (edges ~0.3); the second jumps half an edge to the left in one
    // step (the model's largest step, vmax, is at most an edge): 0.1 deep into the first.
    Mesh mesh = makeIcosphere(Vec3(0, 0, 0), 1.0, 3);
    const Mesh other = makeIcosphere(Vec3(2.05, 0, 0), 1.0, 3);
    appendMesh(mesh, other);
    REQUIRE(findSelfIntersections(mesh).count() == 0);
    std::vector<Vec3> start(mesh.n_vertices());
    for (auto v : mesh.vertices()) start[std::size_t(v.idx())] = position(mesh, v);
    const std::size_t firstMoved = mesh.n_vertices() - other.n_vertices();
    for (auto v : mesh.vertices())
        if (std::size_t(v.idx()) >= firstMoved) mesh.set_point(v, mesh.point(v) + Mesh::Point(-0.15, 0, 0));
    CHECK(findSelfIntersections(mesh).count() > 0); // unchecked, the step makes them cross

    SafeStepOptions so;
    so.minSeparation = 1e-3;
    const SafeStepStats stats = limitStepToCollisionFree(mesh, start, so);
    CHECK(stats.collisions > 0);
    CHECK(stats.shortened > 0);
    CHECK(findSelfIntersections(mesh).count() == 0);
    CHECK(minimumSeparation(mesh, 0.01) >= so.minSeparation); // never closer than eta
    // The far side moved the whole step; the near side was held back, still to the right of the
    // first sphere.
    double leftmost = 1e9, rightmost = -1e9;
    for (auto v : mesh.vertices())
        if (std::size_t(v.idx()) >= firstMoved) {
            leftmost = std::min(leftmost, mesh.point(v)[0]);
            rightmost = std::max(rightmost, mesh.point(v)[0]);
        }
    CHECK(rightmost == doctest::Approx(2.9));
    CHECK(leftmost > 1.0);
    MESSAGE(stats.candidates << " candidates, " << stats.collisions << " collisions, " << stats.shortened
                             << " vertices shortened (" << stats.stopped << " stopped), " << stats.rounds << " rounds");
    REQUIRE_MESH_OK(mesh);
}

TEST_CASE("ccd: a step with no vertex near another surface is left alone")
{
    Mesh mesh = makeIcosphere(Vec3(0, 0, 0), 1.0, 2);
    appendMesh(mesh, makeIcosphere(Vec3(5, 0, 0), 1.0, 2));
    std::vector<Vec3> start(mesh.n_vertices());
    for (auto v : mesh.vertices()) start[std::size_t(v.idx())] = position(mesh, v);
    for (auto v : mesh.vertices()) mesh.set_point(v, mesh.point(v) * 1.1); // every vertex moves out
    const Mesh expected = mesh;
    const SafeStepStats stats = limitStepToCollisionFree(mesh, start);
    CHECK(stats.collisions == 0);
    CHECK(stats.shortened == 0);
    for (auto v : mesh.vertices()) CHECK(mesh.point(v) == expected.point(v));
}

TEST_CASE("ccd: two bubbles inflating into each other at vmax = delta never cross, and still merge")
{
    // Inside one ball, two bubbles grow toward each other at the largest step the model allows:
    // no iteration may leave crossing faces, and the model's merge (paper 3.2) still joins them.
    const Box3 bounds(Vec3::Constant(-12), Vec3::Constant(12));
    FunctionImage image([](const Vec3& x) { return 0.5 + 0.5 * std::tanh(9.0 - x.norm()); }, bounds, 1.0);
    EuclideanMetric metric;
    Mesh mesh = makeBubbles({{Vec3(-4, 0, 0), 2.0}, {Vec3(4, 0, 0), 2.0}}, 1.5);
    EvolutionOptions o;
    o.intersectionFree = true;
    o.delta = 1.0;
    o.vmaxFraction = 1.0;
    o.maxIterations = 400;
    int crossed = 0;
    o.progress = [&](const IterationStats&) {
        crossed += int(findSelfIntersections(mesh).count() > 0);
        return true;
    };
    const EvolutionStats stats = evolve(mesh, image, metric, o);
    CHECK(crossed == 0);
    CHECK(stats.merges >= 1);
    CHECK(topologyOf(mesh).components == 1);
    REQUIRE_MESH_OK(mesh);
}

TEST_CASE("ccd: the clearances kept between steps skip only pairs that stay apart")
{
    // Two spheres drifting into each other with jitter, edited between steps (splits, flips,
    // collapses, a garbage collection now and then), stepped with a SafeStepCache. At every step
    // a copy searches the same step from scratch: the cache's candidates are never more (pairs of
    // clean primitives are skipped). The step as the cache limits it
    // is checked apart: at 17 instants of it, and at its end, no vertex-face or edge-edge pair
    // sharing no vertex is closer than eta, and no faces cross. The cache rebuilds at only some
    // of the steps (else it was never used).
    Mesh a = makeIcosphere(Vec3(0, 0, 0), 1.0, 3);
    appendMesh(a, makeIcosphere(Vec3(2.03, 0, 0), 1.0, 3));
    SafeStepCache cache;
    SafeStepOptions so;
    so.minSeparation = 1e-3;
    so.reanchorFraction = 0.5; // (every vertex drifts: anchored anew less often, the cache is used more)
    std::mt19937 rng(11);
    std::normal_distribution<double> jitter(0.0, 0.0005);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::size_t steps = 0, collisions = 0, rebuilt = 0, edits = 0, cached = 0, scratch = 0, closeSteps = 0;
    double closest = std::numeric_limits<double>::infinity();
    // Each vertex drifts toward the other sphere at its own speed, so that vertices leave their
    // clearance at different steps: clean and dirty primitives meet in the contact.
    std::vector<double> speed(4 * a.n_vertices());
    for (double& x : speed) x = 0.002 * (0.2 + 1.3 * unit(rng));
    for (int step = 0; step < 80; ++step) {
        // Edits, the same on both copies (same mesh, same handles).
        for (int k = 0; k < 4; ++k) {
            const EdgeHandle e(int(unit(rng) * double(a.n_edges())));
            const double what = unit(rng);
            if (a.status(e).deleted()) continue;
            const HalfedgeHandle h = a.halfedge_handle(e, 0);
            const Vec3 mid = 0.5 * (position(a, a.from_vertex_handle(h)) + position(a, a.to_vertex_handle(h)));
            if (what < 0.4 && canSplit(a, e)) {
                split(a, e, mid);
            } else if (what < 0.7 && canFlip(a, e)) {
                flip(a, e);
            } else if (canCollapse(a, h, mid)) {
                collapse(a, h, mid);
            } else {
                continue;
            }
            ++edits;
        }
        if (step % 25 == 24) { // renumbered: the cache must be told
            a.garbage_collection();
            cache.invalidate();
        }
        std::vector<Vec3> start(a.n_vertices());
        for (auto v : a.vertices()) start[std::size_t(v.idx())] = position(a, v);
        for (auto v : a.vertices()) {
            // Every vertex drifts and jitters; now and then one jumps (out of its skin).
            Vec3 d(jitter(rng), jitter(rng), jitter(rng));
            const double drift = (step % 20 == 10 ? 10.0 : 1.0) * speed[std::size_t(v.idx()) % speed.size()];
            d.x() += position(a, v).x() > 1.015 ? -drift : drift; // (a fast step: searched from scratch)
            if (unit(rng) < 0.003) d *= 20.0;
            const Mesh::Point p = a.point(v) + Mesh::Point(d.x(), d.y(), d.z());
            a.set_point(v, p);
        }
        Mesh b = a; // the same step, searched from scratch
        const SafeStepStats sa = limitStepToCollisionFree(a, start, so, &cache);
        const SafeStepStats sb = limitStepToCollisionFree(b, start, so);
        CHECK(sa.candidates <= sb.candidates);
        cached += sa.candidates;
        scratch += sb.candidates;
        // The step as limited, at 17 instants. (The edits may leave pairs closer than eta: such a
        // pair may not come closer than 0.999 of where it starts.)
        double least = std::numeric_limits<double>::infinity(), atStart = 0;
        for (int k = 0; k <= 16; ++k) {
            const double t = k / 16.0;
            for (auto v : b.vertices()) {
                const Vec3 p = start[std::size_t(v.idx())] + t * (position(a, v) - start[std::size_t(v.idx())]);
                b.set_point(v, Mesh::Point(p.x(), p.y(), p.z()));
            }
            least = std::min(least, minimumSeparation(b, 0.05));
            if (k == 0) atStart = least;
        }
        CHECK(least >= std::min(so.minSeparation, 0.999 * atStart) * (1 - 1e-9));
        CHECK(findSelfIntersections(a).count() == 0);
        closest = std::min(closest, least);
        closeSteps += least < 0.01;
        ++steps;
        collisions += sa.collisions;
        rebuilt += sa.rebuilt;
    }
    MESSAGE(steps << " steps, " << edits << " edits, " << collisions << " collisions, rebuilt at " << rebuilt
                  << " steps (" << cache.rebuilds() << " rebuilds), candidates " << cached << " (from scratch "
                  << scratch << "), closest " << closest << ", " << closeSteps << " steps closer than 10 eta");
    CHECK(collisions > 0);
    CHECK(closeSteps > steps / 4); // (the contact is tight: the checks above can fail)
    CHECK(edits > 100);
    CHECK(rebuilt > 0);
    CHECK(rebuilt < steps / 2);
}
