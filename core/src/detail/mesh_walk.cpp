#include "detail/mesh_walk.h"

#include <algorithm>
#include <functional>

namespace riemesh::detail {

const std::vector<VertexHandle>& BoundedPathSearch::run(const Mesh& mesh, VertexHandle source, double maxLength)
{
    search(mesh, source, maxLength, nullptr, 0);
    return mReached;
}

void BoundedPathSearch::runUntil(const Mesh& mesh, VertexHandle source, double maxLength, const int* targets,
                                 std::size_t count)
{
    search(mesh, source, maxLength, targets, count);
}

void BoundedPathSearch::search(const Mesh& mesh, VertexHandle source, double maxLength, const int* targets,
                               std::size_t count)
{
    const std::size_t n = mesh.n_vertices();
    if (mStamp.size() < n) {
        mStamp.resize(n, 0);
        mDistance.resize(n, 0.0);
        mSettled.resize(n, 0);
    }
    if (++mCurrent == 0) { // wrapped around: reset every stamp once
        std::fill(mStamp.begin(), mStamp.end(), 0u);
        std::fill(mTarget.begin(), mTarget.end(), 0u);
        mCurrent = 1;
    }
    mReached.clear();
    mHeap.clear();
    auto touch = [&](int i, double d) {
        if (mStamp[i] != mCurrent) {
            mStamp[i] = mCurrent;
            mSettled[i] = 0;
            mDistance[i] = d;
            return true;
        }
        if (!mSettled[i] && d < mDistance[i]) {
            mDistance[i] = d;
            return true;
        }
        return false;
    };
    // The targets are marked with the stamp of the search after this one: a settled target meets
    // its mark first (the stamp is only compared for equality with the current one).
    if (count > 0 && mTarget.size() < n) mTarget.resize(n, 0);
    for (std::size_t k = 0; k < count; ++k) mTarget[std::size_t(targets[k])] = mCurrent;
    std::size_t targetsLeft = count;
    const auto later = std::greater<std::pair<double, int>>();
    touch(source.idx(), 0.0);
    mHeap.emplace_back(0.0, source.idx());
    while (!mHeap.empty()) {
        std::pop_heap(mHeap.begin(), mHeap.end(), later);
        const auto [d, i] = mHeap.back();
        mHeap.pop_back();
        if (mSettled[i] || d > mDistance[i]) continue;
        mSettled[i] = 1;
        const VertexHandle v(i);
        mReached.push_back(v);
        if (targetsLeft > 0 && mTarget[std::size_t(i)] == mCurrent) {
            mTarget[std::size_t(i)] = 0;
            if (--targetsLeft == 0) break;
        }
        const Mesh::Point& p = mesh.point(v);
        for (auto h : mesh.voh_range(v)) {
            const VertexHandle w = mesh.to_vertex_handle(h);
            if (mesh.status(w).deleted()) continue;
            const double dw = d + (mesh.point(w) - p).norm();
            if (dw > maxLength) continue;
            if (touch(w.idx(), dw)) {
                mHeap.emplace_back(dw, w.idx());
                std::push_heap(mHeap.begin(), mHeap.end(), later);
            }
        }
    }
}

bool BoundedPathSearch::isWithin(const Mesh& mesh, VertexHandle from, VertexHandle to, double maxLength)
{
    run(mesh, from, maxLength);
    return reached(to);
}

} // namespace riemesh::detail
