// detail/parallel.h: index-range loops on TBB when the core is built with it, serial otherwise.
//
// The body receives half-open chunks [begin, end) of the index range, each at least `grain` long
// (but the last); chunks may run in any order and on any thread, so a body must write only
// outputs owned by the indices of its chunk and read only what no chunk writes. TBB stays in
// parallel.cpp: this header is all the core's sources see.
#pragma once

#include <cstddef>
#include <functional>

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

} // namespace riemesh::detail
