// Regularity: after enforceRegularity every edge's metric length is within [delta, zeta*delta]
// (up to the few edges the guards refuse, which are counted), the mesh stays valid, and the
// sampling density follows the metric.
#include "mesh_invariants.h"
#include "riemesh/edge_ops.h"
#include "riemesh/primitives.h"
#include "riemesh/regularity.h"
#include "riemesh/self_intersection.h"

#include "detail/regularize.h" // private to the core (its directory is on this suite's include path)

#include <doctest/doctest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <random>
#include <stdexcept>
#include <thread>
#include <vector>

using namespace riemesh;

namespace {

/// Edges outside [delta, zeta*delta] in metric length, recounted independently of the stats.
struct OutOfRange {
    int tooShort = 0;
    int tooLong = 0;
    int edges = 0;
};

OutOfRange countOutOfRange(const Mesh& mesh, const MetricField& metric, const RegularityOptions& options)
{
    OutOfRange count;
    for (auto e : mesh.edges()) {
        const double l = metricLength(metric, mesh, e);
        ++count.edges;
        if (l < options.delta) ++count.tooShort;
        if (l > options.zeta * options.delta) ++count.tooLong;
    }
    return count;
}

/// Checks the result of a regularity call: valid mesh, same Euler characteristic, stats that match
/// a recount, and fewer than 1% of the edges left out of range.
void checkRegular(const Mesh& mesh, const MetricField& metric, const RegularityOptions& options,
                  const RegularityStats& stats, int euler)
{
    CHECK_MESH_OK(mesh);
    CHECK(topologyOf(mesh).euler == euler);
    const OutOfRange count = countOutOfRange(mesh, metric, options);
    CHECK(count.tooShort == stats.tooShort);
    CHECK(count.tooLong == stats.tooLong);
    CHECK(stats.tooLong == 0);
    CHECK(double(stats.tooShort + stats.tooLong) < 0.01 * count.edges);
}

/// The same vertices (positions, deleted or not) and the same faces (corners), handle for handle.
bool sameMesh(const Mesh& a, const Mesh& b)
{
    if (a.n_vertices() != b.n_vertices() || a.n_faces() != b.n_faces()) return false;
    for (auto v : a.all_vertices())
        if (a.point(v) != b.point(v) || a.status(v).deleted() != b.status(v).deleted()) return false;
    for (auto f : a.faces()) {
        if (b.status(f).deleted()) return false;
        auto fa = a.cfv_begin(f);
        auto fb = b.cfv_begin(f);
        for (int k = 0; k < 3; ++k, ++fa, ++fb)
            if (*fa != *fb) return false;
    }
    return true;
}

/// A sphere of radius 1 with its faces turned inward (a cavity) inside one of radius 1.02, both
/// icospheres of level 4: collapses on one cut chords toward the other, which a guard refuses.
Mesh sphereInSphere()
{
    Mesh a;
    const Mesh inner = makeIcosphere(Vec3(0, 0, 0), 1.0, 4);
    std::vector<VertexHandle> made;
    for (auto v : inner.vertices()) made.push_back(a.add_vertex(inner.point(v)));
    for (auto f : inner.faces()) {
        std::vector<VertexHandle> corners;
        for (auto v = inner.cfv_begin(f); v.is_valid(); ++v) corners.push_back(made[std::size_t(v->idx())]);
        a.add_face(corners[2], corners[1], corners[0]);
    }
    appendMesh(a, makeIcosphere(Vec3(0, 0, 0), 1.02, 4));
    return a;
}

/// The vertices of meshes[0] (a sphereInSphere, the others copies with the same handles) turned
/// about z by 0.4 (faces move out of the boxes a guard entered them with) and jittered about
/// their spheres (which never meet), alike in every mesh.
void turnAndJitter(std::mt19937& rng, std::initializer_list<Mesh*> meshes)
{
    std::normal_distribution<double> noise(0.0, 0.001);
    const double turn = 0.4, cs = std::cos(turn), sn = std::sin(turn);
    Mesh& a = **meshes.begin();
    for (auto v : a.vertices()) {
        const Vec3 p = position(a, v);
        const double radius = p.norm() < 1.01 ? 1.0 : 1.02;
        const Vec3 r(cs * p.x() - sn * p.y(), sn * p.x() + cs * p.y(), p.z());
        const Vec3 q = r.normalized() * radius + Vec3(noise(rng), noise(rng), noise(rng));
        for (Mesh* m : meshes) m->set_point(v, toPoint(q));
    }
}

/// Runs a job on another thread, as Evolution runs the work beside its regularity step; at once
/// where there are no threads (a WebAssembly build without them). join() waits for it.
struct BesideJob {
    std::thread thread;
    void run(std::function<void()> job)
    {
#if defined(__EMSCRIPTEN__) && !defined(__EMSCRIPTEN_PTHREADS__)
        job();
#else
        thread = std::thread(std::move(job));
#endif
    }
    void join()
    {
        if (thread.joinable()) thread.join();
    }
};

std::vector<Vec3> positions(const Mesh& mesh)
{
    std::vector<Vec3> p;
    for (auto v : mesh.vertices()) p.push_back(position(mesh, v));
    return p;
}

} // namespace

TEST_CASE("regularity: every edge ends within [delta, zeta*delta]")
{
    // Icosphere edges are ~5.5 world units; delta = 0.5 needs three to four halvings.
    Mesh mesh = makeIcosphere(Vec3::Zero(), 10.0, 1);
    const EuclideanMetric metric;
    RegularityOptions options;
    options.delta = 0.5;
    options.maxPasses = 8;
    const auto stats = enforceRegularity(mesh, metric, options);
    CHECK(stats.splits > 1000);
    CHECK(stats.tunnels.empty());
    checkRegular(mesh, metric, options, stats, 2);
    CHECK(topologyOf(mesh).vertices > 1000u);
    // Splits at edge midpoints stay on the original flat faces: the volume is that of the icosphere.
    CHECK(signedVolume(mesh) == doctest::Approx(signedVolume(makeIcosphere(Vec3::Zero(), 10.0, 1))).epsilon(0.01));
}

TEST_CASE("regularity: a fine icosphere with a large delta coarsens")
{
    Mesh mesh = makeIcosphere(Vec3::Zero(), 10.0, 5); // edges ~0.3 world units, 10242 vertices
    const EuclideanMetric metric;
    RegularityOptions options;
    options.delta = 1.0;
    options.maxPasses = 8;
    const auto before = topologyOf(mesh);
    const auto stats = enforceRegularity(mesh, metric, options);
    CHECK(stats.collapses > 5000);
    CHECK(stats.splits == 0);
    checkRegular(mesh, metric, options, stats, 2);
    CHECK(topologyOf(mesh).vertices * 5 < before.vertices);
    CHECK(signedVolume(mesh) == doctest::Approx(4.0 / 3.0 * M_PI * 1000.0).epsilon(0.05));
    // No compaction inside: removed vertices are only marked deleted, so handles stay valid.
    CHECK(mesh.n_vertices() == before.vertices);
    // A second call over the deleted elements, then one after compaction, find nothing to do.
    const auto again = enforceRegularity(mesh, metric, options);
    CHECK(again.splits + again.collapses + again.flips == 0);
    mesh.garbage_collection();
    CHECK_MESH_OK(mesh);
    const auto compacted = enforceRegularity(mesh, metric, options);
    CHECK(compacted.splits + compacted.collapses + compacted.flips == 0);
    CHECK(compacted.tooShort == stats.tooShort);
}

TEST_CASE("regularity: a non-positive delta or a zeta <= 1 is rejected")
{
    Mesh mesh = makeIcosphere(Vec3::Zero(), 1.0, 1);
    const EuclideanMetric metric;
    RegularityOptions options;
    options.delta = 0.0;
    CHECK_THROWS_AS(enforceRegularity(mesh, metric, options), std::invalid_argument);
    options.delta = 0.1;
    options.zeta = 1.0;
    CHECK_THROWS_AS(enforceRegularity(mesh, metric, options), std::invalid_argument);
}

TEST_CASE("regularity: a torus refines and coarsens without changing its genus")
{
    const EuclideanMetric metric;
    RegularityOptions options;
    options.maxPasses = 8;
    SUBCASE("refine")
    {
        Mesh mesh = makeTorus(Vec3::Zero(), 6.0, 2.0, 12, 6);
        options.delta = 0.4;
        const auto stats = enforceRegularity(mesh, metric, options);
        CHECK(stats.splits > 0);
        checkRegular(mesh, metric, options, stats, 0);
        CHECK(topologyOf(mesh).genus == 1);
        CHECK(stats.tunnels.empty());
    }
    SUBCASE("coarsen")
    {
        Mesh mesh = makeTorus(Vec3::Zero(), 6.0, 2.0, 120, 40);
        options.delta = 1.0;
        const auto stats = enforceRegularity(mesh, metric, options);
        CHECK(stats.collapses > 0);
        checkRegular(mesh, metric, options, stats, 0);
        CHECK(topologyOf(mesh).genus == 1);
        CHECK(stats.tunnels.empty());
    }
}

TEST_CASE("regularity: a box with sharp creases refines and stays valid")
{
    Mesh mesh = makeBox(Vec3(0, 0, 0), Vec3(4, 3, 2), 1.0);
    const EuclideanMetric metric;
    RegularityOptions options;
    options.delta = 0.25;
    options.maxPasses = 8;
    const auto stats = enforceRegularity(mesh, metric, options);
    CHECK(stats.splits > 0);
    checkRegular(mesh, metric, options, stats, 2);
    CHECK(signedVolume(mesh) == doctest::Approx(24.0).epsilon(0.05));
}

TEST_CASE("regularity: an already regular mesh is left untouched")
{
    Mesh mesh = makeIcosphere(Vec3::Zero(), 10.0, 2);
    const EuclideanMetric metric;
    RegularityOptions options;
    options.delta = 0.5;
    options.maxPasses = 16;
    enforceRegularity(mesh, metric, options);
    const auto before = positions(mesh);
    const auto topologyBefore = topologyOf(mesh);
    const auto stats = enforceRegularity(mesh, metric, options);
    CHECK(stats.splits == 0);
    CHECK(stats.collapses == 0);
    CHECK(stats.flips == 0);
    CHECK(stats.tooLong == 0);
    const auto after = positions(mesh);
    REQUIRE(after.size() == before.size());
    for (std::size_t i = 0; i < after.size(); ++i) CHECK((after[i] - before[i]).norm() == 0.0);
    CHECK(topologyOf(mesh).edges == topologyBefore.edges);
}

TEST_CASE("regularity: where the metric doubles lengths the sampling gets twice as dense")
{
    // G = 4 I for x > 0 doubles metric lengths there: edges come out half as long in world units,
    // so that half holds about 4 times as many vertices as the other (same area).
    const FunctionMetric metric(
        [](const Vec3& x) { return x.x() > 0 ? Mat3(4.0 * Mat3::Identity()) : Mat3(Mat3::Identity()); }, 4.0);
    Mesh mesh = makeIcosphere(Vec3::Zero(), 10.0, 2);
    RegularityOptions options;
    options.delta = 0.8;
    options.maxPasses = 12;
    const auto stats = enforceRegularity(mesh, metric, options);
    checkRegular(mesh, metric, options, stats, 2);
    int positive = 0, negative = 0; // away from the jump at x = 0, where the halves mix
    for (auto v : mesh.vertices()) {
        const double x = mesh.point(v)[0];
        if (x > 1.0) ++positive;
        else if (x < -1.0) ++negative;
    }
    REQUIRE(negative > 0);
    const double ratio = double(positive) / negative;
    MESSAGE("vertices x > 1: " << positive << ", x < -1: " << negative << ", ratio " << ratio);
    CHECK(ratio > 2.5);
    CHECK(ratio < 6.0);
}

TEST_CASE("regularity: an anisotropic metric diag(1,1,4) makes edges shorter along z")
{
    Mat3 g = Mat3::Identity();
    g(2, 2) = 4.0; // lengths along z count double
    const ConstantMetric metric(g);
    Mesh mesh = makeIcosphere(Vec3::Zero(), 10.0, 2);
    RegularityOptions options;
    options.delta = 0.8;
    options.maxPasses = 12;
    const auto stats = enforceRegularity(mesh, metric, options);
    checkRegular(mesh, metric, options, stats, 2);
    // World-space lengths of the edges that run mostly along z and of those mostly across it.
    double alongZ = 0, acrossZ = 0;
    int nAlong = 0, nAcross = 0;
    Vec3 meanAbs = Vec3::Zero();
    int n = 0;
    for (auto e : mesh.edges()) {
        const auto h = mesh.halfedge_handle(e, 0);
        const Vec3 d = position(mesh, mesh.to_vertex_handle(h)) - position(mesh, mesh.from_vertex_handle(h));
        const double c = std::abs(d.z()) / d.norm();
        if (c > 0.8) { alongZ += d.norm(); ++nAlong; }
        else if (c < 0.2) { acrossZ += d.norm(); ++nAcross; }
        meanAbs += d.cwiseAbs();
        ++n;
    }
    REQUIRE(nAlong > 50);
    REQUIRE(nAcross > 50);
    meanAbs /= n;
    const double ratio = (alongZ / nAlong) / (acrossZ / nAcross);
    MESSAGE("mean length along z / across z: " << ratio << "; mean |dx| |dy| |dz|: " << meanAbs.transpose());
    CHECK(ratio > 0.35);
    CHECK(ratio < 0.75);
    CHECK(meanAbs.z() < 0.8 * meanAbs.x());
    CHECK(meanAbs.z() < 0.8 * meanAbs.y());
    CHECK(meanAbs.x() == doctest::Approx(meanAbs.y()).epsilon(0.15));
}

TEST_CASE("regularity: short edges across a thin tunnel are reported once each, not collapsed")
{
    // A tube of 3 segments, radius 0.3: the ring edges (~0.52) are shorter than delta = 1, and
    // each ring is a triangle loop that bounds no face.
    const int major = 12, minor = 3;
    Mesh mesh = makeTorus(Vec3::Zero(), 4.0, 0.3, major, minor);
    const EuclideanMetric metric;
    RegularityOptions options;
    options.delta = 1.0;
    options.maxPasses = 4;
    const auto before = topologyOf(mesh);
    const auto stats = enforceRegularity(mesh, metric, options);
    CHECK_MESH_OK(mesh);
    CHECK(stats.collapses == 0);
    CHECK(topologyOf(mesh).vertices == before.vertices);
    CHECK(topologyOf(mesh).genus == 1);
    CHECK(stats.tooShort == major * minor);
    REQUIRE(stats.tunnels.size() == std::size_t(major));
    std::vector<int> ringsSeen;
    for (const auto& t : stats.tunnels) {
        // Vertex (i, j) of the torus has index i * minor + j: a tunnel is one ring i.
        const int ring = t.u.idx() / minor;
        CHECK(t.v.idx() / minor == ring);
        CHECK(t.w.idx() / minor == ring);
        CHECK(t.u != t.v);
        CHECK(t.v != t.w);
        CHECK(t.u != t.w);
        ringsSeen.push_back(ring);
    }
    std::sort(ringsSeen.begin(), ringsSeen.end());
    CHECK(std::unique(ringsSeen.begin(), ringsSeen.end()) == ringsSeen.end());
}

TEST_CASE("regularity: a short edge around a valence-3 dent is collapsed, not reported as a tunnel")
{
    // A vertex x inserted in face (u, v, w) makes u-v-w a loop that bounds no face, but it cuts
    // off only x: a dent of the sampling, not a tunnel.
    Mesh mesh = makeIcosphere(Vec3::Zero(), 10.0, 2); // edges ~2.5-3.2 world units
    const EuclideanMetric metric;
    RegularityOptions options;
    options.delta = 1.5;
    options.maxPasses = 8;
    const FaceHandle f = *mesh.faces().begin();
    const auto h = mesh.halfedge_handle(f);
    const VertexHandle u = mesh.from_vertex_handle(h), v = mesh.to_vertex_handle(h);
    const VertexHandle w = mesh.to_vertex_handle(mesh.next_halfedge_handle(h));
    const Vec3 centroid = (position(mesh, u) + position(mesh, v) + position(mesh, w)) / 3.0;
    const VertexHandle x = mesh.split(f, toPoint(0.98 * centroid)); // fixture: a slight dent
    // Pull v toward u: the edge u-v gets shorter than delta.
    mesh.set_point(v, toPoint(position(mesh, u) + 1.0 * (position(mesh, v) - position(mesh, u)).normalized()));
    REQUIRE_MESH_OK(mesh);
    REQUIRE(mesh.valence(x) == 3u);
    REQUIRE(sharedOutsideNeighbour(mesh, mesh.find_halfedge(u, v)) == w);
    const auto stats = enforceRegularity(mesh, metric, options);
    CHECK(stats.tunnels.empty());
    CHECK(stats.collapses >= 2);
    CHECK(mesh.status(x).deleted());
    checkRegular(mesh, metric, options, stats, 2);
}

TEST_CASE("regularity: a jittered surface stays valid and regular iteration after iteration")
{
    // Like the evolution: vertices move (here: noise and a swirl), then regularity, then compaction.
    Mat3 g = Mat3::Identity();
    g(2, 2) = 4.0;
    const ConstantMetric anisotropic(g);
    const EuclideanMetric euclidean;
    const MetricField* metrics[2] = {&euclidean, &anisotropic};
    for (const MetricField* metric : metrics) {
        Mesh mesh = makeTorus(Vec3::Zero(), 8.0, 3.0, 24, 12);
        std::mt19937 rng(2003);
        std::normal_distribution<double> noise(0.0, 1.0);
        RegularityOptions options;
        options.delta = 0.7;
        options.maxPasses = 2;
        for (int it = 0; it < 40; ++it) {
            const double swirl = 0.02 * std::sin(0.2 * it);
            for (auto v : mesh.vertices()) {
                const Vec3 p = position(mesh, v);
                const Vec3 jitter(noise(rng), noise(rng), noise(rng));
                mesh.set_point(v, toPoint(p + 0.05 * jitter + swirl * Vec3(p.y(), -p.x(), 0.3 * p.z())));
            }
            const auto stats = enforceRegularity(mesh, *metric, options);
            CAPTURE(it);
            REQUIRE_MESH_OK(mesh);
            REQUIRE(topologyOf(mesh).euler == 0);
            CHECK(stats.tunnels.empty()); // the tube is thick: no short edge closes a tunnel
            mesh.garbage_collection();
        }
        const auto stats = enforceRegularity(mesh, *metric, options);
        const OutOfRange count = countOutOfRange(mesh, *metric, options);
        CHECK(stats.tooLong == 0);
        CHECK(double(count.tooShort) < 0.05 * count.edges);
    }
}

TEST_CASE("regularity: an already regular 5k-vertex mesh is left untouched, Euclidean or not")
{
    // Refine an icosphere to ~5,000 vertices, then call again: nothing to do. (Speed is measured in
    // bench/, not here.)
    Mesh mesh = makeIcosphere(Vec3::Zero(), 10.0, 3);
    RegularityOptions options;
    options.delta = 0.32;
    options.maxPasses = 16;
    const EuclideanMetric euclidean;
    enforceRegularity(mesh, euclidean, options);
    const auto vertices = topologyOf(mesh).vertices;
    CHECK(vertices > 4500u);
    CHECK(vertices < 5500u);
    const FunctionMetric function([](const Vec3&) { return Mat3(Mat3::Identity()); }, 1.0);
    for (const MetricField* metric : {static_cast<const MetricField*>(&euclidean), static_cast<const MetricField*>(&function)}) {
        const auto stats = enforceRegularity(mesh, *metric, options);
        CHECK(stats.splits + stats.collapses + stats.flips == 0);
    }
    CHECK_MESH_OK(mesh);
}

namespace {
/// G = s(x)^2 I with s rising from 1 to 4 across a few units of x: edges that a collapse would
/// stretch across the rise are refused by the check that they split into regular halves, so the
/// collapse pass refuses many queued edges, iteration after iteration, as on an image's contours.
class RampMetric final : public MetricField {
public:
    Mat3 at(const Vec3& p) const override
    {
        const double t = std::clamp(0.5 + p.x() / 6.0, 0.0, 1.0);
        const double s = 1.0 + 3.0 * t * t * (3.0 - 2.0 * t);
        return s * s * Mat3::Identity();
    }
    double maxEigenvalue() const override { return 16.0; }
};
} // namespace

TEST_CASE("regularity: collapses decided in parallel first make the same mesh as decided in turn")
{
    // Two copies of a torus, jittered and swirled alike, regularized with and without the
    // speculated collapse verdicts: at every call the same vertices, faces and stats.
    const RampMetric metric;
    Mesh a = makeTorus(Vec3::Zero(), 8.0, 3.0, 24, 12);
    Mesh b = a;
    std::mt19937 rng(2011);
    std::normal_distribution<double> noise(0.0, 1.0);
    RegularityOptions on, off;
    on.delta = off.delta = 0.9;
    on.maxPasses = off.maxPasses = 2;
    off.speculate = false;
    int collapses = 0, refused = 0;
    for (int it = 0; it < 30; ++it) {
        const double swirl = 0.02 * std::sin(0.2 * it);
        for (auto v : a.vertices()) {
            const Vec3 p = position(a, v);
            const Vec3 jitter(noise(rng), noise(rng), noise(rng));
            const Vec3 q = p + 0.08 * jitter + swirl * Vec3(p.y(), -p.x(), 0.3 * p.z());
            a.set_point(v, toPoint(q));
            b.set_point(v, toPoint(q));
        }
        const auto sa = enforceRegularity(a, metric, on);
        const auto sb = enforceRegularity(b, metric, off);
        CAPTURE(it);
        REQUIRE_MESH_OK(a);
        CHECK(sa.collapses == sb.collapses);
        CHECK(sa.splits == sb.splits);
        CHECK(sa.flips == sb.flips);
        CHECK(sa.tooShort == sb.tooShort);
        CHECK(sameMesh(a, b));
        collapses += sa.collapses;
        refused += sa.tooShort;
        a.garbage_collection();
        b.garbage_collection();
    }
    MESSAGE(collapses << " collapses, " << refused << " short edges left over the calls");
    CHECK(collapses > 100);
    CHECK(refused > 30); // (refusals to decide: the verdicts that must stay valid across collapses)
}

namespace {

/// The sphere in a sphere, coarsened, turned and jittered call after call, guarded (edits asked
/// in turn, or checked together): with a RegularityCache and without, the same vertices and
/// faces at every call (the cache forgotten at each garbage collection, as Evolution does). With
/// `handOver`, before each call the guard's marks are handed over to a copy of the mesh
/// (RegularityCache::handOver), from which another thread brings the kept grid up to date
/// (bringUpToDate) while the call begins, as Evolution runs it beside the collision-safe step.
/// Without the guard the mesh differs: a collapse on the outer sphere cuts a chord toward the
/// inner one, which the guard refuses.
void checkCachedGuardMakesTheSameMesh(unsigned seed, bool together, bool handOver)
{
    const EuclideanMetric metric;
    Mesh a = sphereInSphere();
    Mesh b = a, c = a;
    std::mt19937 rng(seed);
    RegularityOptions guarded;
    guarded.delta = 0.05;
    guarded.maxPasses = 2;
    guarded.intersectionFree = true;
    guarded.minSeparation = 1e-4;
    guarded.checkEditsTogether = together;
    RegularityOptions plain = guarded;
    plain.intersectionFree = false;
    RegularityCache cache;
    bool guardMattered = false;
    int handed = 0;
    for (int it = 0; it < 40; ++it) {
        guarded.delta = plain.delta = 0.05 + 0.004 * it; // (coarsening: collapses, some across the gap)
        turnAndJitter(rng, {&a, &b, &c});
        Mesh snapshot;
        BesideJob beside;
        if (handOver) {
            snapshot = a;
            if (cache.handOver(a, snapshot)) ++handed, beside.run([&] { cache.bringUpToDate(snapshot); });
        }
        const auto sa = enforceRegularity(a, metric, guarded, &cache);
        beside.join();
        const auto sb = enforceRegularity(b, metric, guarded);
        const auto sc = enforceRegularity(c, metric, plain);
        CAPTURE(it);
        REQUIRE_MESH_OK(a);
        CHECK(sa.collapses == sb.collapses);
        CHECK(sa.flips == sb.flips);
        CHECK(sa.tooShort == sb.tooShort);
        CHECK(sameMesh(a, b));
        guardMattered = guardMattered || sa.collapses != sc.collapses || sa.flips != sc.flips || a.n_faces() != c.n_faces();
        if (it % 8 == 7) {
            a.garbage_collection();
            b.garbage_collection();
            cache.invalidate();
        }
        c = a; // (the unguarded copy starts each call from the guarded mesh)
    }
    if (handOver) CHECK(handed >= 35); // (all but the first call: the guard's marks exist from then on)
    CHECK(guardMattered);
}

} // namespace

TEST_CASE("regularity: the edit guard's grid kept from call to call makes the same mesh as one built at each call")
{
    // Faces entered again only once they leave their grown boxes, the grid compacted as entries
    // pile up. (Each edit asked in turn: with a cache, edits are checked together only after
    // calls with many edits, and not right after one that had to be made again; without,
    // always. That mode has its own test below.)
    checkCachedGuardMakesTheSameMesh(2027, false, false);
}

TEST_CASE("regularity: the edit guard's grid brought up to date on another thread makes the same mesh")
{
    // Its first guard waits for that thread (or calls it off), then enters only the faces its
    // own edits changed. Edits asked in turn, and checked together.
    for (const bool together : {false, true}) {
        CAPTURE(together);
        checkCachedGuardMakesTheSameMesh(2029, together, true);
    }
}

TEST_CASE("edit guard: a grid brought up to date on another thread holds every live face when first asked")
{
    // The invariant the guard's answers rest on: when it first looks at its grid in a call, every
    // live face lies within the box the grid holds for it. The sphere in a sphere turned and
    // jittered every other time (faces leave their boxes), edited at random before the copy is
    // taken (splits, collapses and flips: their marks go with the copy, see
    // detail::handOverMarks) and after (the call's own edits, marked in the mesh), the grid
    // brought up to date from the copy on another thread while the edits after are made (or
    // called off, if that thread has not begun when the guard first looks). Without entering the
    // faces of the marked vertices after, or without waiting for the other thread, some face
    // lies outside its box.
    Mesh mesh = sphereInSphere();
    std::mt19937 rng(31);
    detail::GuardGrid grid;
    detail::IntersectionGuard(mesh, 0.0, &grid).bringUpToDate(); // (built: the marks exist from now on)
    auto editAtRandom = [&](int count) {
        int made = 0;
        for (int tries = 0; made < count && tries < 50 * count; ++tries) {
            const EdgeHandle e(int(rng() % mesh.n_edges()));
            if (mesh.status(e).deleted()) continue;
            const HalfedgeHandle h = mesh.halfedge_handle(e, 0);
            const Vec3 mid = 0.5 * (position(mesh, mesh.from_vertex_handle(h)) + position(mesh, mesh.to_vertex_handle(h)));
            switch (rng() % 3) {
            case 0: made += split(mesh, e, mid).is_valid(); break;
            case 1:
                if (canCollapse(mesh, h, mid)) made += collapse(mesh, h, mid).is_valid();
                break;
            default:
                if (canFlip(mesh, e)) flip(mesh, e), ++made;
            }
        }
        return made;
    };
    int entered = 0;
    for (int it = 0; it < 30; ++it) {
        if (it % 2 == 0) turnAndJitter(rng, {&mesh}); // (between: only the edits' marks tell what changed)
        editAtRandom(20);
        Mesh snapshot = mesh;
        REQUIRE(detail::handOverMarks(mesh, snapshot, grid));
        const bool late = it % 3 == 2; // (the other thread begins after the guard's first look: called off)
        BesideJob beside;
        if (!late) beside.run([&] { detail::bringUpToDateFrom(snapshot, grid); });
        entered += editAtRandom(20);
        detail::IntersectionGuard guard(mesh, 0.0, &grid);
        CHECK(guard.facesAroundAreClear(detail::MadeFaces{})); // (its first look: waits, enters the marked)
        if (late) beside.run([&] { detail::bringUpToDateFrom(snapshot, grid); });
        beside.join();
        CAPTURE(it);
        std::size_t outside = 0;
        for (auto f : mesh.faces()) {
            const detail::Box6* box = grid.grid.boxOf(f.idx());
            bool inside = box != nullptr;
            for (auto v = mesh.cfv_begin(f); inside && v.is_valid(); ++v)
                for (int k = 0; k < 3; ++k)
                    inside = inside && (*box)[k] <= mesh.point(*v)[k] && mesh.point(*v)[k] <= (*box)[k + 3];
            outside += !inside;
        }
        CHECK(outside == 0);
        if (it % 10 == 9) {
            mesh.garbage_collection();
            grid.valid = false; // (renumbered: built anew, as RegularityCache::invalidate does)
        }
    }
    CHECK(entered > 300);
}

TEST_CASE("regularity: edits checked together make the same mesh as checked in turn, or one without crossings")
{
    // The guard's two ways on the coarsening sphere in a sphere: the collapses and flips made
    // without asking and their faces checked at the end (the default), and each asked in turn.
    // Where the check finds a crossing the call is made again in turn: the same mesh as in turn.
    // Otherwise the same mesh too, unless an edit the guard refuses in turn was undone by a later
    // one (never the case here: checked). Either way no two faces cross after a call if none did
    // before (from delta 0.18 on, the jittered spheres' chords cross each other by themselves).
    const EuclideanMetric metric;
    Mesh a = sphereInSphere();
    Mesh b = a;
    std::mt19937 rng(2029);
    RegularityOptions together;
    together.maxPasses = 2;
    together.intersectionFree = true;
    together.minSeparation = 1e-4;
    RegularityOptions inTurn = together;
    inTurn.checkEditsTogether = false;
    int redone = 0, kept = 0;
    for (int it = 0; it < 40; ++it) {
        together.delta = inTurn.delta = 0.05 + 0.004 * it;
        turnAndJitter(rng, {&a, &b});
        const bool clean = findSelfIntersections(a).count() == 0;
        const auto sa = enforceRegularity(a, metric, together);
        const auto sb = enforceRegularity(b, metric, inTurn);
        CAPTURE(it);
        REQUIRE_MESH_OK(a);
        if (clean) {
            CHECK(findSelfIntersections(a).count() == 0);
            (sa.editsRedone ? redone : kept) += 1;
        }
        CHECK(!sb.editsRedone);
        CHECK(sa.collapses == sb.collapses);
        CHECK(sa.flips == sb.flips);
        CHECK(sameMesh(a, b));
        if (it % 8 == 7) a.garbage_collection(), b.garbage_collection();
        b = a;
    }
    MESSAGE(redone << " calls made again in turn, " << kept << " kept as made together (of those without a crossing before)");
    CHECK(redone > 0); // (the guard refuses edits here: the check must find them)
    CHECK(kept > 0);
}

TEST_CASE("regularity: with a cache, the calls right after one made again ask each edit in turn")
{
    // The same coarsening sphere in a sphere, with a RegularityCache: a call whose edits, checked
    // together, had to be made again is followed by calls that ask each edit in turn (they can
    // never have to be made again), for a few calls; a valid mesh without crossings after any
    // call that started without one.
    const EuclideanMetric metric;
    Mesh a = sphereInSphere();
    std::mt19937 rng(2029);
    RegularityOptions options;
    options.maxPasses = 2;
    options.intersectionFree = true;
    options.minSeparation = 1e-4;
    RegularityCache cache;
    std::vector<int> redoneAt;
    for (int it = 0; it < 40; ++it) {
        options.delta = 0.05 + 0.004 * it;
        turnAndJitter(rng, {&a});
        const bool clean = findSelfIntersections(a).count() == 0;
        const auto stats = enforceRegularity(a, metric, options, &cache);
        CAPTURE(it);
        if (clean) { // (from delta 0.18 on, the jittered spheres may cross each other by themselves)
            REQUIRE_MESH_OK(a);
            CHECK(findSelfIntersections(a).count() == 0);
        }
        if (stats.editsRedone) redoneAt.push_back(it);
    }
    REQUIRE(!redoneAt.empty());
    for (std::size_t k = 1; k < redoneAt.size(); ++k) CHECK(redoneAt[k] - redoneAt[k - 1] > 8);
}

TEST_CASE("regularity: the edits made without asking the guard note every face they made or moved")
{
    // The check of edits together (intersection-free, see enforceRegularity) tests only the faces
    // the edits noted: those around the vertices collapses kept (and splits of noted faces made),
    // and the two faces of each flip. Every other face after the call must be one of before (the
    // same corners in the same places) or lie in one (a half of a split face no edit made). The
    // sphere in a sphere refined and coarsened at random, three passes a call: splits after the
    // flips and collapses of earlier passes, on their faces too. Euclidean and anisotropic metrics
    // in turn. (A split of an edge of a face a flip made, in a later pass of the same call, is
    // reached by none of these calls: that rule of noteMade is not tested here.)
    const EuclideanMetric euclidean;
    const ConstantMetric flat(Vec3(1, 1, 9).asDiagonal().toDenseMatrix());
    const ConstantMetric tilted(metricFromEigen(Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix(),
                                                Vec3(1, 4, 16)));
    const MetricField* metrics[3] = {&euclidean, &flat, &tilted};
    Mesh mesh = sphereInSphere();
    std::mt19937 rng(2031);
    std::uniform_real_distribution<double> pick(0.0, 1.0);
    RegularityOptions options;
    options.maxPasses = 3;
    options.intersectionFree = true;
    options.minSeparation = 1e-4;
    struct Face {
        std::array<int, 3> ids;
        std::array<Vec3, 3> p;
    };
    auto faceOf = [&](FaceHandle f) {
        Face x;
        int k = 0;
        for (auto v = mesh.cfv_begin(f); v.is_valid(); ++v, ++k) {
            x.ids[std::size_t(k)] = v->idx();
            x.p[std::size_t(k)] = position(mesh, *v);
        }
        return x;
    };
    // q lies in triangle t (within round-off of its plane and its sides).
    auto inTriangle = [](const Vec3& q, const std::array<Vec3, 3>& t) {
        const Vec3 n = (t[1] - t[0]).cross(t[2] - t[0]);
        const double area2 = n.squaredNorm();
        if (!(area2 > 0) || std::abs(n.dot(q - t[0])) > 1e-9 * std::sqrt(area2)) return false;
        for (int k = 0; k < 3; ++k) {
            const Vec3& a = t[std::size_t(k)];
            const Vec3& b = t[std::size_t((k + 1) % 3)];
            if ((b - a).cross(q - a).dot(n) < -1e-9 * area2) return false;
        }
        return true;
    };
    std::size_t flips = 0, splits = 0, collapses = 0, inOld = 0, noted = 0;
    for (int it = 0; it < 60; ++it) {
        const MetricField& metric = *metrics[it % 3];
        options.delta = (0.03 + 0.15 * pick(rng)) * (it % 3 == 0 ? 1.0 : 2.5);
        turnAndJitter(rng, {&mesh});
        std::vector<Face> before;
        std::vector<std::vector<std::size_t>> facesAt(mesh.n_vertices());
        for (auto f : mesh.faces()) {
            before.push_back(faceOf(f));
            for (const int id : before.back().ids) facesAt[std::size_t(id)].push_back(before.size() - 1);
        }
        detail::MadeFaces made;
        detail::GuardGrid kept;
        const RegularityStats stats = detail::regularizeNotingEdits(mesh, metric, options, &kept, made);
        flips += std::size_t(stats.flips);
        splits += std::size_t(stats.splits);
        collapses += std::size_t(stats.collapses);
        CHECK(made.flipped.size() == std::size_t(stats.flips));
        std::vector<char> around(mesh.n_vertices(), 0), flipped(mesh.n_faces(), 0);
        for (const int v : made.vertices) around[std::size_t(v)] = 1;
        for (const auto& pair : made.flipped)
            for (const int f : pair) flipped[std::size_t(f)] = 1;
        CAPTURE(it);
        for (auto f : mesh.faces()) {
            const Face x = faceOf(f);
            if (flipped[std::size_t(f.idx())] ||
                std::any_of(x.ids.begin(), x.ids.end(), [&](int v) { return around[std::size_t(v)] != 0; })) {
                ++noted;
                continue;
            }
            // Held by a face of before: one at a corner of it, or any (splits of splits: no corner
            // of before).
            auto holds = [&](std::size_t g) {
                return std::all_of(x.p.begin(), x.p.end(), [&](const Vec3& q) { return inTriangle(q, before[g].p); });
            };
            bool held = false, oldCorner = false;
            for (const int id : x.ids)
                if (std::size_t(id) < facesAt.size()) {
                    oldCorner = true;
                    for (const std::size_t g : facesAt[std::size_t(id)]) held = held || holds(g);
                }
            for (std::size_t g = 0; !oldCorner && !held && g < before.size(); ++g) held = holds(g);
            CHECK(held);
            inOld += held;
        }
        // (No mesh check: the edits, made without asking, may cut chords through the other sphere.)
        if (it % 8 == 7) mesh.garbage_collection();
    }
    MESSAGE(splits << " splits, " << collapses << " collapses, " << flips << " flips; faces after: " << noted << " noted, "
                   << inOld << " in a face of before");
    CHECK(splits > 1000);
    CHECK(collapses > 1000);
    CHECK(flips > 1000);
}
