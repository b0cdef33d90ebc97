#include "detail/spatial_hash.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace riemesh::detail {

void CellGrid::build(const double* xyz, std::size_t n, double cellSize)
{
    if (!(cellSize > 0) || !std::isfinite(cellSize)) throw std::invalid_argument("CellGrid: cell size must be > 0");
    if (n >= std::numeric_limits<std::uint32_t>::max() / 2) throw std::invalid_argument("CellGrid: too many points");
    mOrder.resize(n);
    mCellKey.clear();
    mCellStart.clear();
    if (n == 0) {
        mCellKey.push_back(std::numeric_limits<std::uint64_t>::max());
        mCellStart.push_back(0);
        return;
    }

    // Cell coordinates and their bounding box.
    const double inv = 1.0 / cellSize;
    constexpr double kLimit = double(std::int64_t(1) << 40);
    mCoord.resize(3 * n);
    std::int64_t lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
        lo[a] = std::numeric_limits<std::int64_t>::max();
        hi[a] = std::numeric_limits<std::int64_t>::min();
    }
    for (std::size_t i = 0; i < 3 * n; i += 3) {
        for (int a = 0; a < 3; ++a) {
            const double c = xyz[i + a] * inv;
            if (!(std::abs(c) < kLimit)) throw std::invalid_argument("CellGrid: point not finite or too far for the cell size");
            std::int64_t k = std::int64_t(c); // floor: truncation, minus one below zero unless exact
            k -= c < double(k);
            mCoord[i + a] = k;
            lo[a] = std::min(lo[a], k);
            hi[a] = std::max(hi[a], k);
        }
    }
    // One cell of padding on each side, so that +-1 neighbours never wrap into another row.
    std::uint64_t extent[3];
    for (int a = 0; a < 3; ++a) {
        if (hi[a] - lo[a] > (std::int64_t(1) << 20)) throw std::invalid_argument("CellGrid: point cloud too wide for the cell size");
        extent[a] = std::uint64_t(hi[a] - lo[a]) + 3;
    }
    // The longest axis sweeps; the two others index rows (fewest rows).
    int s = 0;
    for (int a = 1; a < 3; ++a)
        if (extent[a] > extent[s]) s = a;
    mSweep = s;
    const int ra = (s + 1) % 3, rb = (s + 2) % 3;
    const std::uint64_t nb = extent[rb], ns = extent[s];
    const std::uint64_t rows = extent[ra] * nb;
    mRowStep[0] = ns;                // (0, +1)
    mRowStep[1] = (nb - 1) * ns;     // (+1, -1)
    mRowStep[2] = nb * ns;           // (+1, 0)
    mRowStep[3] = (nb + 1) * ns;     // (+1, +1)

    mRow.resize(n);
    mSweepCell.resize(n);
    mSortKey.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        const std::int64_t* c = &mCoord[3 * i];
        mRow[i] = std::uint64_t(c[ra] - lo[ra] + 1) * nb + std::uint64_t(c[rb] - lo[rb] + 1);
        mSweepCell[i] = std::uint32_t(c[s] - lo[s] + 1);
        mSortKey[i] = mRow[i] * ns + mSweepCell[i];
    }
    const std::uint64_t* key = mSortKey.data();
    const std::uint64_t dense = 4 * std::uint64_t(n) + 1024;
    if (rows <= dense && ns <= dense && n < (std::size_t(1) << 31)) {
        // LSD: counting sort by sweep cell, then a stable counting sort by row.
        mTmp.resize(n);
        mCount.assign(ns + 1, 0);
        for (std::size_t i = 0; i < n; ++i) ++mCount[mSweepCell[i] + 1];
        for (std::size_t b = 0; b < ns; ++b) mCount[b + 1] += mCount[b];
        for (std::size_t i = 0; i < n; ++i) mTmp[mCount[mSweepCell[i]]++] = std::uint32_t(i);
        mCount.assign(rows + 1, 0);
        for (std::size_t i = 0; i < n; ++i) ++mCount[mRow[i] + 1];
        for (std::size_t b = 0; b < rows; ++b) mCount[b + 1] += mCount[b];
        for (std::size_t j = 0; j < n; ++j) {
            const std::uint32_t i = mTmp[j];
            mOrder[mCount[mRow[i]]++] = i;
        }
    } else {
        // Sparse box: sort (key, index) pairs.
        for (std::size_t i = 0; i < n; ++i) mOrder[i] = std::uint32_t(i);
        std::sort(mOrder.begin(), mOrder.end(), [&](std::uint32_t x, std::uint32_t y) {
            return key[x] != key[y] ? key[x] < key[y] : x < y;
        });
    }
    // Inside each cell, by exact sweep coordinate (cells hold a few points: nearly sorted).
    for (std::size_t j = 1; j < n; ++j) {
        const std::uint32_t x = mOrder[j];
        const std::uint64_t kx = key[x];
        const double wx = xyz[3 * std::size_t(x) + s];
        std::size_t t = j;
        while (t > 0) {
            const std::uint32_t y = mOrder[t - 1];
            if (key[y] != kx || !(xyz[3 * std::size_t(y) + s] > wx)) break;
            mOrder[t] = y;
            --t;
        }
        mOrder[t] = x;
    }
    for (std::size_t j = 0; j < n; ++j) {
        const std::uint64_t k = key[mOrder[j]];
        if (j == 0 || k != mCellKey.back()) {
            mCellKey.push_back(k);
            mCellStart.push_back(std::uint32_t(j));
        }
    }
    mCellKey.push_back(std::numeric_limits<std::uint64_t>::max());
    mCellStart.push_back(std::uint32_t(n));
}

} // namespace riemesh::detail
