// detail/spatial_hash.h: a uniform-grid broad phase for fixed-radius neighbour pairs.
//
// Points are binned into cubic cells of side `cellSize` (world units) and sorted by cell, with no
// hash table: the grid's longest axis is the "sweep" axis, the other two index rows of cells, and
// slots are ordered by row, then by the cell's sweep coordinate (ties keep the input order). Every
// pair of points closer than the cell size lies in one cell pair of the half stencil (the cell
// itself, its +1 sweep neighbour, and the 3 cells nearest to it in each of 4 forward rows), and
// each such group of cells is one contiguous run of slots. Since cell keys increase along the
// slots, the start of each forward row's run is found by a pointer that only moves forward (a
// merge, O(1) amortised per cell). The build is two counting sorts (sweep cell, then row), O(n),
// falling back to a comparison sort when the occupied box is sparse (many more cells than points).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace riemesh::detail {

class CellGrid {
public:
    /// Bins `n` points into cells of side `cellSize` > 0 (world units). Point i is the three
    /// coordinates at xyz + 3 * (index ? index[i] : i). Throws std::invalid_argument for a bad
    /// size, non-finite points or a grid wider than 2^20 cells on an axis. Buffers are kept for
    /// the next build (no allocation once they have grown).
    void build(const double* xyz, const int* index, std::size_t n, double cellSize);

    std::size_t size() const { return mOrder.size(); }
    /// The input position i (0 <= i < n) of slot s.
    std::uint32_t index(std::uint32_t s) const { return mOrder[s]; }

    /// For every occupied cell with slots [a0, a1): calls f(a0, a1, range, count) with the slot
    /// ranges range[0..count) (count <= 5, pairs [begin, end)) of its half stencil: range[0] =
    /// [a0, b1) covers the cell and its +1 neighbour along the sweep axis (pair slot s with
    /// t > s only), the others are the forward rows with occupied cells near it (the three cells
    /// of the row at sweep offsets -1, 0, +1; pair every s with every t). Every pair of points
    /// closer than the cell size meets in exactly one call.
    template <class F>
    void forEachCell(F&& f) const
    {
        forEachCell(0, cellCount(), f);
    }

    /// The number of occupied cells.
    std::size_t cellCount() const { return mCellStart.empty() ? 0 : mCellStart.size() - 1; }

    /// forEachCell() for the occupied cells [cellBegin, cellEnd) only (in increasing order): disjoint
    /// ranges of cells can be swept by different threads.
    template <class F>
    void forEachCell(std::size_t cellBegin, std::size_t cellEnd, F&& f) const
    {
        const std::size_t cells = cellCount();
        if (cellEnd > cells) cellEnd = cells;
        if (cellBegin >= cellEnd) return;
        const std::uint64_t* key = mCellKey.data(); // key[cells] is a sentinel above every key
        const std::uint32_t* start = mCellStart.data();
        // The forward rows' pointers start at the first cell of each row at or after the first
        // cell's stencil (found by bisection); from there they only move forward.
        std::size_t lo[4], hi[4];
        for (int r = 0; r < 4; ++r) {
            const std::uint64_t target = key[cellBegin] + mRowStep[r] - 1;
            lo[r] = hi[r] = std::size_t(std::lower_bound(key, key + cells, target) - key);
        }
        std::uint32_t range[5][2];
        for (std::size_t c = cellBegin; c < cellEnd; ++c) {
            const std::uint64_t k = key[c];
            const std::uint32_t a0 = start[c], a1 = start[c + 1];
            range[0][0] = a0;
            range[0][1] = key[c + 1] == k + 1 ? start[c + 2] : a1;
            int count = 1;
            for (int r = 0; r < 4; ++r) {
                const std::uint64_t first = k + mRowStep[r] - 1, last = first + 2;
                std::size_t l = lo[r];
                while (key[l] < first) ++l;
                lo[r] = l;
                std::size_t h = hi[r] > l ? hi[r] : l;
                while (key[h] <= last) ++h;
                hi[r] = h;
                range[count][0] = start[l];
                range[count][1] = start[h];
                count += h > l;
            }
            f(a0, a1, range, count);
        }
    }

private:
    std::uint64_t mRowStep[4] = {0, 0, 0, 0}; ///< key offsets of the 4 forward rows (same sweep cell)
    std::vector<std::uint64_t> mCellKey;      ///< occupied cells in increasing key order, then a sentinel
    std::vector<std::uint32_t> mCellStart;    ///< cell c holds slots [start[c], start[c+1])
    std::vector<std::uint32_t> mOrder;        ///< slot -> input position
    // Scratch, kept between builds.
    std::vector<std::uint32_t> mRow, mSweepCell, mCount, mTmp;
    std::vector<std::uint64_t> mSortKey;
    /// The O(n) passes over the points run in parallel chunks of kChunk points.
    static constexpr std::size_t kChunk = 4096;
    struct Bounds {
        double lo[3], hi[3];
        bool numbers;
    };
    std::vector<Bounds> mBounds; ///< per chunk
};

} // namespace riemesh::detail
