// detail/parallel.h: index-range loops on TBB when the core is built with it, serial otherwise.
//
// The body receives half-open chunks [begin, end) of the index range, each at least `grain` long
// (but the last); chunks may run in any order and on any thread, so a body must write only
// outputs owned by the indices of its chunk and read only what no chunk writes. TBB stays in
// parallel.cpp: this header is all the core's sources see.
#pragma once

#include <cstddef>
#include <functional>
#include <memory>

namespace riemesh::detail {

/// Calls fn(chunkBegin, chunkEnd) over [begin, end) in chunks of at least `grain` indices, in
/// parallel when TBB is available and more than one thread is allowed.
void parallelForChunks(std::size_t begin, std::size_t end, std::size_t grain,
                       const std::function<void(std::size_t, std::size_t)>& fn);

/// Calls fn(i) for every i in [begin, end), in parallel chunks of `grain` indices.
template <class Fn>
void parallelFor(std::size_t begin, std::size_t end, std::size_t grain, Fn&& fn)
{
    parallelForChunks(begin, end, grain, [&fn](std::size_t b, std::size_t e) {
        for (std::size_t i = b; i < e; ++i) fn(i);
    });
}

/// fn(i) for every index i in [0, count) whose mesh element Handle(i) is not deleted, in parallel
/// chunks of `grain` indices: fn may write only what index i owns.
template <class Handle, class MeshT, class Fn>
void forLive(const MeshT& mesh, std::size_t count, std::size_t grain, Fn&& fn)
{
    parallelFor(0, count, grain, [&](std::size_t i) {
        if (!mesh.status(Handle(int(i))).deleted()) fn(i);
    });
}

/// One job at a time run beside the caller: run(fn) starts fn on another thread when the core's
/// loops may use more than one (threadCount() > 1) and returns, else runs it at once; wait()
/// returns once it has finished (and rethrows what it threw). The job must touch nothing the
/// caller uses until wait(). The destructor waits.
class Background {
public:
    Background();
    ~Background();
    Background(const Background&) = delete;
    Background& operator=(const Background&) = delete;
    void run(std::function<void()> fn);
    void wait();
    /// run() would start its job on another thread.
    bool concurrent() const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace riemesh::detail
