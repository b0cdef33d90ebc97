// collision.cpp: self-collision detection (paper 3.2, Fig. 2).
//
// One pass over the faces for vertex normals, one sorted-grid sweep for Euclidean candidates
// (d_E <= d_R since G >= I), then cheap per-pair filters; the bounded mesh search that tells
// "close along the mesh" from "close across a gap" only runs for the few pairs that survive.
// Per call, little is allocated once the threads' scratch buffers have grown to the mesh size.
#include "riemesh/collision.h"

#include "detail/mesh_walk.h"
#include "detail/parallel.h"
#include "detail/spatial_hash.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace riemesh {

namespace {

/// Same-sheet test without a search: normals agree (angle < 60 degrees) and each vertex lies
/// within 30 degrees of the other's tangent plane. On a sheet curved enough to turn the normal by
/// 60 degrees between u and w, the chord leaves the tangent plane by half that angle, so real
/// same-sheet pairs pass; two facing sheets (opposite normals) or stacked sheets (w in front of
/// u) do not.
constexpr double kNormalAgreement = 0.5;      // cos 60 degrees
constexpr double kSquaredTangentSlope = 0.25; // (sin 30 degrees)^2
/// Two sides of a convex crease (a box edge being rounded off) lie behind each other's tangent
/// planes; on a coarse mesh (edges up to zeta delta) their mesh path can exceed kappa * radius.
/// They cannot be colliding sheets unless the normals are nearly opposite (a thin plate, which
/// the paper does report under a coarse Euclidean metric): never merged. But a crease that
/// sharpens into a fin brings its sides within a step of each other, and they cross: such a pair,
/// unless close along the mesh, is a contact (held apart by Evolution). Stress soak (seed 4242,
/// 150 cases), broken + tangled runs: 9 + 2 when crease pairs were skipped, 1 + 2 as contacts;
/// seed 777, 100 cases: 2 + 3, then 1 + 1.
constexpr double kCreaseAgreement = -0.5; // cos 120 degrees
/// A pair joined by an edge path no longer than kDetour x their straight distance plus
/// kDetourSlack x delta is one sheet: mesh paths zig-zag, and a curved sheet's geodesic exceeds
/// its chord, by well under 2x; the slack absorbs vertices much closer than an edge is long
/// (across a sharp crease, e.g. a thin plate's rim: without it they pair up across the plate).
/// A longer path within the neighbourhood bound is a detour around a gap: two sheets joined by a
/// fresh merge's band that still approach each other (a collision: merged), or a fold of the
/// surface (a contact: held apart by Evolution, not merged; merging them gave the head MRI's skin
/// genus 14). Measured on the stress test (150 random cases, seed 4242), broken + tangled runs:
/// the plain neighbourhood bound 16 + 15; detour pairs as collisions everywhere 1 + 7 (but the
/// head's genus 14); near fresh merges only, contacts held apart elsewhere 9 + 3.
constexpr double kDetour = 2.0;
constexpr double kDetourSlack = 0.5;

/// Candidates that no cheap test rules out; ordered (u < w by index).
struct Candidate {
    int u, w;
    double distance; // metric length (world units)
    bool crease;     // across a convex crease: a contact at most, never merged
};

/// Per-thread buffers reused across calls (no allocation per call in steady state).
struct Scratch {
    std::vector<int> live;       ///< vertex index of each live vertex
    std::vector<double> soa;     ///< 6 arrays of `count` in slot order: x y z nx ny nz
    std::vector<int> id;         ///< vertex index of each slot
    std::vector<double> faceNormal; ///< 3 per face index: its area-weighted normal
    std::vector<std::vector<Candidate>> found; ///< candidates of each chunk of cells
    std::vector<Candidate> candidates;
    std::vector<char> verdict;      ///< per candidate: kNotColliding, kContact or kColliding
    std::vector<std::size_t> sources; ///< first candidate of each source vertex, then the end
    detail::CellGrid grid;
};

/// Elements per parallel chunk, and occupied cells per chunk of the candidate sweep.
constexpr std::size_t kGrain = 128;
constexpr std::size_t kCellsPerChunk = 32;
/// What the mesh search made of a candidate.
constexpr char kNotColliding = 0, kContact = 1, kColliding = 2;

Scratch& scratch()
{
    thread_local Scratch s;
    return s;
}

} // namespace

double collisionLambda(bool euclidean, double zeta, double delta, double vmax)
{
    if (!(zeta > 1) || !(delta > 0) || !(vmax >= 0))
        throw std::invalid_argument("collisionLambda: need zeta > 1, delta > 0, vmax >= 0");
    const double motion = vmax / (2.0 * zeta * delta);
    if (euclidean) return std::sqrt(1.0 - 1.0 / zeta + 1.0 / (zeta * zeta)) + motion;
    return 1.0 + motion;
}

double collisionRadius(const MetricField& metric, const CollisionOptions& options)
{
    return collisionLambda(metric.isEuclidean(), options.zeta, options.delta, options.vmax) * options.zeta *
           options.delta;
}

std::vector<CollisionPair> findCollisions(const Mesh& mesh, const MetricField& metric, const CollisionOptions& options,
                                          std::vector<CollisionPair>* contacts)
{
    if (contacts) contacts->clear();
    std::vector<CollisionPair> result;
    if (!mesh.has_vertex_status() || !mesh.has_face_status())
        throw std::invalid_argument("findCollisions: call prepareMesh() first (status attributes)");
    const double radius = collisionRadius(metric, options);
    const std::size_t n = mesh.n_vertices();
    Scratch& S = scratch();

    // Area-weighted vertex normals: each face's in parallel here, summed per vertex around it (the
    // mesh's order: the same sums for any thread count) where the vertices are copied in slot order
    // below (one parallel pass less: on 2 threads a short pass costs the worker's wake-up).
    const Mesh::Point* const point = mesh.points();
    const std::size_t faceCount = mesh.n_faces();
    S.faceNormal.resize(3 * faceCount);
    double* const faceNormal = S.faceNormal.data();
    detail::parallelFor(0, faceCount, kGrain, [&](std::size_t fi) {
        const FaceHandle f{int(fi)};
        if (mesh.status(f).deleted()) return;
        const HalfedgeHandle h0 = mesh.halfedge_handle(f);
        const HalfedgeHandle h1 = mesh.next_halfedge_handle(h0);
        const int a = mesh.from_vertex_handle(h0).idx(), b = mesh.to_vertex_handle(h0).idx(),
                  c = mesh.to_vertex_handle(h1).idx();
        const Mesh::Point& pa = point[a];
        const double ex = point[b][0] - pa[0], ey = point[b][1] - pa[1], ez = point[b][2] - pa[2];
        const double gx = point[c][0] - pa[0], gy = point[c][1] - pa[1], gz = point[c][2] - pa[2];
        double* const fn = faceNormal + 3 * fi;
        fn[0] = ey * gz - ez * gy, fn[1] = ez * gx - ex * gz, fn[2] = ex * gy - ey * gx;
    });

    // Live vertices: straight from the mesh's point array unless some are deleted.
    static_assert(sizeof(Mesh::Point) == 3 * sizeof(double), "points are 3 packed doubles");
    S.live.resize(n);
    std::size_t count = 0;
    for (std::size_t i = 0; i < n; ++i) {
        S.live[count] = int(i);
        count += !mesh.status(VertexHandle(int(i))).deleted();
    }
    if (count == 0) return result;
    const double* const xyz = point[0].data();
    const int* const live = count < n ? S.live.data() : nullptr;

    OpenMesh::VPropHandleT<int> cutId;
    const bool hasCutIds = mesh.get_property_handle(cutId, kCutIdProperty);

    detail::CellGrid& grid = S.grid;
    grid.build(xyz, live, count, radius);

    // Structure-of-arrays copies in slot order (unit normals; zero for isolated vertices).
    S.soa.resize(6 * count);
    S.id.resize(count);
    double* const qx = S.soa.data();
    double* const qy = qx + count;
    double* const qz = qy + count;
    double* const mx = qz + count;
    double* const my = mx + count;
    double* const mz = my + count;
    int* const ids = S.id.data();
    detail::parallelFor(0, count, kGrain, [&](std::size_t slot) {
        const std::uint32_t s = std::uint32_t(slot);
        const std::uint32_t i = grid.index(s);
        const int v = live ? live[i] : int(i);
        ids[s] = v;
        qx[s] = xyz[3 * v];
        qy[s] = xyz[3 * v + 1];
        qz[s] = xyz[3 * v + 2];
        double nx = 0, ny = 0, nz = 0;
        for (auto f = mesh.cvf_begin(VertexHandle(v)); f.is_valid(); ++f) {
            const double* const fn = faceNormal + 3 * std::size_t(f->idx());
            nx += fn[0], ny += fn[1], nz += fn[2];
        }
        const double len = std::sqrt(nx * nx + ny * ny + nz * nz);
        const double inv = len > 0 ? 1.0 / len : 0.0;
        mx[s] = nx * inv;
        my[s] = ny * inv;
        mz[s] = nz * inv;
    });

    const double r2 = radius * radius;
    const bool euclidean = metric.isEuclidean();
    const VertexMetrics vertexMetrics(mesh, metric); // read only: the cache, else a sample per vertex
    // The cells are swept in parallel chunks, each into its own candidate list (concatenated in
    // chunk order, then sorted: the same list for any thread count).
    const std::size_t cells = grid.cellCount();
    const std::size_t chunks = (cells + kCellsPerChunk - 1) / kCellsPerChunk;
    if (S.found.size() < chunks) S.found.resize(chunks);
    detail::parallelFor(0, chunks, 1, [&](std::size_t chunk) {
        std::vector<Candidate>& found = S.found[chunk];
        found.clear();
        // Per-thread buffers sized to the mesh (a cell's stencil may hold every vertex).
        thread_local std::vector<std::uint32_t> nearBuffer;
        thread_local std::vector<double> gatherBuffer;
        if (nearBuffer.size() < count) nearBuffer.resize(count);
        if (gatherBuffer.size() < 5 * count) gatherBuffer.resize(5 * count);
        std::uint32_t* const near = nearBuffer.data();
        auto consider = [&](std::uint32_t sa, std::uint32_t sb, double d2, bool crease) {
            const int a = ids[sa], b = ids[sb];
            if (hasCutIds) {
                const int ca = mesh.property(cutId, VertexHandle(a));
                if (ca != 0 && ca == mesh.property(cutId, VertexHandle(b))) return;
            }
            const int u = std::min(a, b), w = std::max(a, b);
            double dR = std::sqrt(d2);
            if (!euclidean) {
                // The mean of the endpoints' tensors, as the regularity step measures edges: from
                // the per-vertex cache Evolution keeps current, not a metric sample per pair
                // (on the phantom 207k pairs, 180k of them then dropped: 15% of the evolution).
                const VertexHandle vu(u), vw(w);
                dR = metricLength(vertexMetrics.at(vu), vertexMetrics.at(vw), position(mesh, vw) - position(mesh, vu));
                if (dR > radius) return;
            }
            found.push_back({u, w, dR, crease});
        };
        // Per cell, the positions of its half stencil are gathered into short contiguous arrays
        // (own cell first), so each vertex runs one loop over its candidates: squared distances
        // (vectorisable), then the sheet tests only for the few within reach.
        double* const gx = gatherBuffer.data();
        double* const gy = gx + count;
        double* const gz = gy + count;
        double* const gd = gz + count;
        std::uint32_t* const gs = reinterpret_cast<std::uint32_t*>(gd + count);
        const std::size_t firstCell = chunk * kCellsPerChunk;
        auto sweepCell = [&](std::uint32_t a0, std::uint32_t a1, const std::uint32_t(*range)[2], int ranges) {
            std::uint32_t m = 0;
            for (int r = 0; r < ranges; ++r) {
                for (std::uint32_t t = range[r][0]; t < range[r][1]; ++t, ++m) {
                    gx[m] = qx[t];
                    gy[m] = qy[t];
                    gz[m] = qz[t];
                    gs[m] = t;
                }
            }
            for (std::uint32_t s = a0; s < a1; ++s) {
                const std::uint32_t first = s - a0 + 1;
                const double x = qx[s], y = qy[s], z = qz[s];
                for (std::uint32_t j = first; j < m; ++j) {
                    const double dx = gx[j] - x, dy = gy[j] - y, dz = gz[j] - z;
                    gd[j] = dx * dx + dy * dy + dz * dz;
                }
                std::uint32_t k = 0;
                for (std::uint32_t j = first; j < m; ++j) {
                    near[k] = gs[j];
                    k += gd[j] <= r2;
                }
                if (k == 0) continue;
                const double ux = mx[s], uy = my[s], uz = mz[s];
                for (std::uint32_t j = 0; j < k; ++j) {
                    const std::uint32_t t = near[j];
                    const double dx = qx[t] - x, dy = qy[t] - y, dz = qz[t] - z;
                    const double d2 = dx * dx + dy * dy + dz * dz;
                    const double agree = ux * mx[t] + uy * my[t] + uz * mz[t];
                    const double hu = dx * ux + dy * uy + dz * uz;
                    const double hw = dx * mx[t] + dy * my[t] + dz * mz[t];
                    const double limit = kSquaredTangentSlope * d2;
                    const bool flat = (agree > kNormalAgreement) & (hu * hu <= limit) & (hw * hw <= limit);
                    // Convex crease: each vertex behind the other's tangent plane and the normals
                    // less than 120 degrees apart (a thin plate has opposite normals and stays in).
                    const bool crease = (agree > kCreaseAgreement) & (hu < 0) & (hw > 0);
                    if (!flat) consider(s, t, d2, crease);
                }
            }
        };
        grid.forEachCell(firstCell, firstCell + kCellsPerChunk, sweepCell);
    });
    std::vector<Candidate>& candidates = S.candidates;
    candidates.clear();
    for (std::size_t chunk = 0; chunk < chunks; ++chunk)
        candidates.insert(candidates.end(), S.found[chunk].begin(), S.found[chunk].end());
    if (candidates.empty()) return result;

    // Exclude pairs close along the mesh: one bounded search per distinct source vertex.
    std::sort(candidates.begin(), candidates.end(),
              [](const Candidate& x, const Candidate& y) { return x.u != y.u ? x.u < y.u : x.w < y.w; });
    const double pathBound = options.neighbourhoodFactor * radius;
    const double detourSlack = kDetourSlack * options.delta;
    OpenMesh::VPropHandleT<char> merged;
    const bool hasMerged = mesh.get_property_handle(merged, kMergedProperty);
    auto euclideanDistance = [&](int a, int b) {
        const double* p = xyz + 3 * a;
        const double* q = xyz + 3 * b;
        return std::sqrt((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) + (p[2] - q[2]) * (p[2] - q[2]));
    };
    // A crease pair is usually joined through the crease by a two-edge path, checked first;
    // otherwise it, like any pair, asks the source's bounded search (run once per source, and for a
    // source with crease pairs alone only as far as their detour limit: a deflating box's creases
    // make many such sources).
    auto closeByTwoEdges = [&](int u, int w, double limit) {
        const Mesh::Point& pu = point[u];
        for (auto h : mesh.voh_range(VertexHandle(u))) {
            const VertexHandle x = mesh.to_vertex_handle(h);
            if (x.idx() == w) return true;
            const double ux = (mesh.point(x) - pu).norm();
            if (ux >= limit) continue;
            for (auto g : mesh.voh_range(x))
                if (mesh.to_vertex_handle(g).idx() == w && ux + (point[w] - mesh.point(x)).norm() <= limit) return true;
        }
        return false;
    };
    // Longest edge path between a candidate's ends that is no detour around a gap (see kDetour).
    auto detourLimit = [&](const Candidate& c) { return kDetour * euclideanDistance(c.u, c.w) + detourSlack; };
    // Each source vertex's candidates in parallel (one bounded search per source and thread), each
    // candidate's verdict in its own slot; the pairs are then listed in candidate order.
    std::vector<std::size_t>& sources = S.sources;
    sources.clear();
    for (std::size_t k = 0; k < candidates.size(); ++k)
        if (k == 0 || candidates[k].u != candidates[k - 1].u) sources.push_back(k);
    sources.push_back(candidates.size());
    S.verdict.assign(candidates.size(), kNotColliding);
    char* const verdict = S.verdict.data();
    detail::parallelFor(0, sources.size() - 1, 8, [&](std::size_t g) {
        thread_local detail::BoundedPathSearch search;
        thread_local std::vector<int> targets;
        const std::size_t end = sources[g + 1];
        bool searched = false;
        for (std::size_t k = sources[g]; k < end; ++k) {
            const Candidate& c = candidates[k];
            if (c.crease && closeByTwoEdges(c.u, c.w, detourLimit(c))) continue;
            if (!searched) { // up to the farthest this source's candidates ask, or until all are settled
                searched = true;
                double bound = 0;
                targets.clear();
                for (std::size_t j = k; j < end; ++j) {
                    bound = std::max(bound, candidates[j].crease ? detourLimit(candidates[j]) : pathBound);
                    targets.push_back(candidates[j].w);
                }
                search.runUntil(mesh, VertexHandle(c.u), std::min(bound, pathBound), targets.data(), targets.size());
            }
            // Close along the mesh: a short edge path that is no detour around a gap.
            const bool reached = search.reached(VertexHandle(c.w));
            if (reached && search.distance(VertexHandle(c.w)) <= detourLimit(c)) continue;
            if (c.crease) {
                verdict[k] = kContact;
                continue;
            }
            if (reached) {
                const bool nearMerge =
                    hasMerged && (mesh.property(merged, VertexHandle(c.u)) || mesh.property(merged, VertexHandle(c.w)));
                if (!nearMerge) {
                    verdict[k] = kContact;
                    continue;
                }
            }
            verdict[k] = kColliding;
        }
    });
    for (std::size_t k = 0; k < candidates.size(); ++k) {
        const Candidate& c = candidates[k];
        if (verdict[k] == kColliding) result.push_back({VertexHandle(c.u), VertexHandle(c.w), c.distance});
        else if (verdict[k] == kContact && contacts) contacts->push_back({VertexHandle(c.u), VertexHandle(c.w), c.distance});
    }
    std::sort(result.begin(), result.end(), [](const CollisionPair& x, const CollisionPair& y) {
        if (x.distance != y.distance) return x.distance < y.distance;
        return x.u.idx() != y.u.idx() ? x.u.idx() < y.u.idx() : x.w.idx() < y.w.idx();
    });
    return result;
}

} // namespace riemesh
