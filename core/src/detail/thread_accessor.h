// detail/thread_accessor.h: NanoVDB read accessors kept per thread, so that one NanoImage or
// NanoMetric can be sampled from every thread of a parallel loop at once.
//
// An accessor caches the path to the last leaf it read: shared between threads it would be a data
// race, built afresh per sample it would lose the cache (successive vertices are mostly in the same
// leaf). Each thread keeps the last owner's accessor; owners are told apart by an id that is never
// reused (an object destroyed and another built at its address do not share a stale cache).
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>

namespace riemesh::detail {

/// A new owner id (never 0, never reused in the process).
inline std::uint64_t newAccessorOwner()
{
    static std::atomic<std::uint64_t> next{1};
    return next.fetch_add(1, std::memory_order_relaxed);
}

/// The calling thread's accessor of `grid` for `owner` (Slot tells apart two grids of one type
/// that one owner samples together).
template <int Slot, class GridT>
inline auto& threadAccessor(std::uint64_t owner, const GridT* grid)
{
    using Accessor = decltype(grid->getAccessor());
    struct Entry {
        std::uint64_t owner = 0;
        std::optional<Accessor> accessor;
    };
    thread_local Entry entry;
    if (entry.owner != owner) {
        entry.accessor.emplace(grid->getAccessor());
        entry.owner = owner;
    }
    return *entry.accessor;
}

} // namespace riemesh::detail
