// detail/spatial_hash.h: a uniform-grid broad phase for fixed-radius neighbour pairs.
//
// Points are binned into cubic cells of side `cellSize` (world units) and sorted by cell, with no
// hash table: the grid's longest axis is the "sweep" axis, the other two index rows of cells.
// Slots are ordered by row, then by the cell's sweep coordinate, then (inside a cell) by the
// point's exact sweep coordinate. Every pair of points closer than the cell size lies in one cell
// pair of the half stencil (the cell itself, its +1 sweep neighbour, and the 3 cells nearest to it
// in each of 4 forward rows), and each such group is one contiguous run of slots sorted by sweep
// coordinate. Since cell keys increase along the slots, the start of each forward row's run is
// found by a pointer that only moves forward (a merge, O(1) amortised per cell). The build is two
// counting sorts (sweep cell, then row) and one insertion pass (points inside a cell), O(n),
// falling back to a comparison sort when the occupied box is sparse (cells >> points).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace riemesh::detail {

class CellGrid {
public:
    /// Bins `n` points given as interleaved coordinates (x0 y0 z0 x1 ...; world units) into cells
    /// of side `cellSize` > 0. Throws std::invalid_argument for a bad size, non-finite points or a
    /// grid wider than 2^20 cells on an axis. Buffers are kept for the next build.
    void build(const double* xyz, std::size_t n, double cellSize);

    std::size_t size() const { return mOrder.size(); }
    /// The input index of slot s.
    std::uint32_t index(std::uint32_t s) const { return mOrder[s]; }
    /// The sweep axis (0, 1, 2): each run passed by forEachCellRange is sorted by this coordinate.
    int sweepAxis() const { return mSweep; }

    /// For every occupied cell with slots [a0, a1): calls f(a0, a1, a0, b1) once, where [a0, b1)
    /// covers the cell and its +1 neighbour along the sweep axis (pair slot s with t in (s, b1)),
    /// and f(a0, a1, b0, b1) for each forward row with occupied cells near it ([b0, b1): the
    /// three cells of the row at sweep offsets -1, 0, +1; pair every s with every t). Every pair
    /// of points closer than the cell size meets in exactly one call; all ranges are sorted by the
    /// sweep coordinate.
    template <class F>
    void forEachCellRange(F&& f) const
    {
        const std::size_t cells = mCellStart.size() - 1;
        if (cells == 0) return;
        const std::uint64_t* key = mCellKey.data(); // key[cells] is a sentinel above every key
        const std::uint32_t* start = mCellStart.data();
        std::size_t lo[4] = {0, 0, 0, 0}, hi[4] = {0, 0, 0, 0};
        for (std::size_t c = 0; c < cells; ++c) {
            const std::uint64_t k = key[c];
            const std::uint32_t a0 = start[c], a1 = start[c + 1];
            f(a0, a1, a0, key[c + 1] == k + 1 ? start[c + 2] : a1);
            for (int r = 0; r < 4; ++r) {
                const std::uint64_t first = k + mRowStep[r] - 1, last = first + 2;
                std::size_t l = lo[r];
                while (key[l] < first) ++l;
                lo[r] = l;
                std::size_t h = hi[r] > l ? hi[r] : l;
                while (key[h] <= last) ++h;
                hi[r] = h;
                if (h > l) f(a0, a1, start[l], start[h]);
            }
        }
    }

private:
    int mSweep = 2;
    std::uint64_t mRowStep[4] = {0, 0, 0, 0}; ///< key offsets of the 4 forward rows (same sweep cell)
    std::vector<std::uint64_t> mCellKey;      ///< occupied cells in increasing key order, then a sentinel
    std::vector<std::uint32_t> mCellStart;    ///< cell c holds slots [start[c], start[c+1])
    std::vector<std::uint32_t> mOrder;        ///< slot -> input index
    // Scratch, kept between builds.
    std::vector<std::int64_t> mCoord;         ///< 3 cell coordinates per point
    std::vector<std::uint64_t> mRow, mSortKey;
    std::vector<std::uint32_t> mSweepCell, mCount, mTmp;
};

} // namespace riemesh::detail
