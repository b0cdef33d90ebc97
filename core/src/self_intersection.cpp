// self_intersection.cpp: a BVH over the faces, then the exact triangle-triangle tests of
// detail/triangle_intersection.h on the pairs whose boxes overlap.
#include "riemesh/self_intersection.h"

#include "detail/parallel.h"
#include "detail/triangle_intersection.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

namespace riemesh {

namespace {

using detail::TriangleContact;
using detail::TriangleRef;

/// Faces as vertex indices, corners, boxes and projection axes (live faces only, compact).
struct FaceSet {
    std::vector<std::array<int, 3>> vertex;
    std::vector<TriangleRef> triangle;
    std::vector<std::array<double, 6>> box; // lo xyz, hi xyz
    std::vector<FaceHandle> handle;
};

/// A bounding-volume hierarchy over face boxes: median split along the longest axis of the
/// centroids; a leaf holds faces order[first, first + count), an inner node's children are
/// `first` and `first + 1` (count == 0).
struct Bvh {
    struct Node {
        std::array<double, 6> box;
        int first = 0, count = 0;
    };
    std::vector<Node> nodes;
    std::vector<int> order;
};

double extent(const std::array<double, 6>& b) { return std::max({b[3] - b[0], b[4] - b[1], b[5] - b[2]}); }

bool boxesOverlap(const std::array<double, 6>& x, const std::array<double, 6>& y)
{
    return x[0] <= y[3] && y[0] <= x[3] && x[1] <= y[4] && y[1] <= x[4] && x[2] <= y[5] && y[2] <= x[5];
}

void buildNode(Bvh& bvh, const FaceSet& faces, const std::vector<Vec3>& centroid, int node, int begin, int end,
               int leafSize)
{
    std::array<double, 6> box = faces.box[bvh.order[begin]];
    Vec3 lo = centroid[bvh.order[begin]], hi = lo;
    for (int i = begin + 1; i < end; ++i) {
        const auto& b = faces.box[bvh.order[i]];
        for (int k = 0; k < 3; ++k) {
            box[k] = std::min(box[k], b[k]);
            box[k + 3] = std::max(box[k + 3], b[k + 3]);
        }
        lo = lo.cwiseMin(centroid[bvh.order[i]]);
        hi = hi.cwiseMax(centroid[bvh.order[i]]);
    }
    bvh.nodes[node].box = box;
    if (end - begin <= leafSize) {
        bvh.nodes[node].first = begin;
        bvh.nodes[node].count = end - begin;
        return;
    }
    int axis = 0;
    (hi - lo).maxCoeff(&axis);
    const int mid = begin + (end - begin) / 2;
    std::nth_element(bvh.order.begin() + begin, bvh.order.begin() + mid, bvh.order.begin() + end,
                     [&](int x, int y) { return centroid[x][axis] < centroid[y][axis]; });
    const int left = int(bvh.nodes.size());
    bvh.nodes.emplace_back();
    bvh.nodes.emplace_back();
    bvh.nodes[node].first = left;
    bvh.nodes[node].count = 0;
    buildNode(bvh, faces, centroid, left, begin, mid, leafSize);
    buildNode(bvh, faces, centroid, left + 1, mid, end, leafSize);
}

Bvh buildBvh(const FaceSet& faces, int leafSize)
{
    Bvh bvh;
    const int n = int(faces.vertex.size());
    if (n == 0) return bvh;
    std::vector<Vec3> centroid(n);
    for (int i = 0; i < n; ++i) {
        const auto& b = faces.box[i];
        centroid[i] = Vec3(b[0] + b[3], b[1] + b[4], b[2] + b[5]) * 0.5;
    }
    bvh.order.resize(n);
    for (int i = 0; i < n; ++i) bvh.order[i] = i;
    bvh.nodes.reserve(std::size_t(4 * n / std::max(1, leafSize) + 2));
    bvh.nodes.emplace_back();
    buildNode(bvh, faces, centroid, 0, 0, n, std::max(1, leafSize));
    return bvh;
}

} // namespace

bool trianglesIntersect(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1, const Vec3& b2)
{
    const TriangleRef s = detail::makeTriangle(a0.data(), a1.data(), a2.data());
    const TriangleRef t = detail::makeTriangle(b0.data(), b1.data(), b2.data());
    if (s.axis < 0 || t.axis < 0) return false;
    return detail::trianglesMeet(s, t);
}

SelfIntersectionStats findSelfIntersections(const Mesh& mesh, const SelfIntersectionOptions& options)
{
    SelfIntersectionStats stats;
    if (mesh.n_vertices() == 0) return stats; // (points() is null then)
    FaceSet faces;
    const double* const xyz = mesh.points()[0].data();
    static_assert(sizeof(Mesh::Point) == 3 * sizeof(double), "points are 3 packed doubles");
    faces.vertex.reserve(mesh.n_faces());
    faces.triangle.reserve(mesh.n_faces());
    faces.box.reserve(mesh.n_faces());
    faces.handle.reserve(mesh.n_faces());
    for (auto f : mesh.faces()) {
        const HalfedgeHandle h = mesh.halfedge_handle(f);
        const std::array<int, 3> v = {mesh.from_vertex_handle(h).idx(), mesh.to_vertex_handle(h).idx(),
                                      mesh.to_vertex_handle(mesh.next_halfedge_handle(h)).idx()};
        const TriangleRef t = detail::makeTriangle(xyz + 3 * v[0], xyz + 3 * v[1], xyz + 3 * v[2]);
        if (t.axis < 0) {
            ++stats.degenerateFaces;
            continue;
        }
        std::array<double, 6> box;
        for (int k = 0; k < 3; ++k) {
            box[k] = std::min({t.p[0][k], t.p[1][k], t.p[2][k]});
            box[k + 3] = std::max({t.p[0][k], t.p[1][k], t.p[2][k]});
        }
        faces.vertex.push_back(v);
        faces.triangle.push_back(t);
        faces.box.push_back(box);
        faces.handle.push_back(f);
    }
    const Bvh bvh = buildBvh(faces, options.leafSize);
    if (bvh.nodes.empty()) return stats;

    // Self-traversal: a node against itself descends into (L, L), (R, R) and (L, R); two distinct
    // nodes are compared only when their boxes overlap, descending into the inner one. The first
    // levels are expanded here into a list of node pairs (tasks), whose traversals then run in
    // parallel, each into its own counts; tasks are summed in order and the pairs sorted, so the
    // result is the same for any thread count.
    struct Task {
        SelfIntersectionStats stats;
        std::vector<std::pair<int, int>> stack;
    };
    auto expand = [&](std::pair<int, int> xy, SelfIntersectionStats& out, std::vector<std::pair<int, int>>& stack,
                      bool descend) {
        auto test = [&](int i, int j) {
            if (!boxesOverlap(faces.box[i], faces.box[j])) return;
            ++out.testedPairs;
            const TriangleContact kind =
                detail::classifyTriangles(faces.vertex[i], faces.triangle[i], faces.vertex[j], faces.triangle[j]);
            if (kind == TriangleContact::None) return;
            if (kind == TriangleContact::Crossing) ++out.crossings;
            else if (kind == TriangleContact::VertexFold) ++out.vertexFolds;
            else ++out.edgeFolds;
            if (options.collectPairs && out.pairs.size() < options.maxPairs) {
                const FaceHandle a = faces.handle[i], b = faces.handle[j];
                out.pairs.emplace_back(a.idx() < b.idx() ? a : b, a.idx() < b.idx() ? b : a);
            }
        };
        const auto [x, y] = xy;
        const Bvh::Node& nx = bvh.nodes[x];
        const Bvh::Node& ny = bvh.nodes[y];
        if (x == y) {
            if (nx.count > 0) {
                if (!descend) return false;
                for (int i = nx.first; i < nx.first + nx.count; ++i)
                    for (int j = i + 1; j < nx.first + nx.count; ++j) test(bvh.order[i], bvh.order[j]);
            } else {
                stack.push_back({nx.first, nx.first});
                stack.push_back({nx.first + 1, nx.first + 1});
                stack.push_back({nx.first, nx.first + 1});
            }
            return true;
        }
        if (!boxesOverlap(nx.box, ny.box)) return true;
        if (nx.count > 0 && ny.count > 0) {
            if (!descend) return false;
            for (int i = nx.first; i < nx.first + nx.count; ++i)
                for (int j = ny.first; j < ny.first + ny.count; ++j) test(bvh.order[i], bvh.order[j]);
        } else if (ny.count > 0 || (nx.count == 0 && extent(nx.box) >= extent(ny.box))) {
            // descend into x: the only inner node, or the larger of two
            stack.push_back({nx.first, y});
            stack.push_back({nx.first + 1, y});
        } else {
            stack.push_back({x, ny.first});
            stack.push_back({x, ny.first + 1});
        }
        return true;
    };
    // Breadth first until there are enough tasks (leaf work is left to the tasks).
    constexpr std::size_t kTasks = 256;
    std::vector<std::pair<int, int>> frontier = {{0, 0}}, next, leaves;
    while (!frontier.empty() && frontier.size() + leaves.size() < kTasks) {
        next.clear();
        for (const auto& xy : frontier)
            if (!expand(xy, stats, next, false)) leaves.push_back(xy);
        frontier.swap(next);
    }
    frontier.insert(frontier.end(), leaves.begin(), leaves.end());
    std::vector<Task> tasks(frontier.size());
    detail::parallelFor(0, frontier.size(), 1, [&](std::size_t k) {
        Task& t = tasks[k];
        t.stack.push_back(frontier[k]);
        while (!t.stack.empty()) {
            const auto xy = t.stack.back();
            t.stack.pop_back();
            expand(xy, t.stats, t.stack, true);
        }
    });
    for (Task& t : tasks) {
        stats.testedPairs += t.stats.testedPairs;
        stats.crossings += t.stats.crossings;
        stats.vertexFolds += t.stats.vertexFolds;
        stats.edgeFolds += t.stats.edgeFolds;
        if (options.collectPairs) stats.pairs.insert(stats.pairs.end(), t.stats.pairs.begin(), t.stats.pairs.end());
    }
    if (options.collectPairs) {
        std::sort(stats.pairs.begin(), stats.pairs.end(), [](const auto& a, const auto& b) {
            return a.first.idx() != b.first.idx() ? a.first.idx() < b.first.idx() : a.second.idx() < b.second.idx();
        });
        if (stats.pairs.size() > options.maxPairs) stats.pairs.resize(options.maxPairs);
    }
    return stats;
}

} // namespace riemesh
