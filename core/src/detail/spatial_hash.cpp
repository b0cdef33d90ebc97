#include "detail/spatial_hash.h"

#include "detail/parallel.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace riemesh::detail {

void CellGrid::build(const double* xyz, const int* index, std::size_t n, double cellSize)
{
    if (!(cellSize > 0) || !std::isfinite(cellSize)) throw std::invalid_argument("CellGrid: cell size must be > 0");
    if (n >= (std::size_t(1) << 31)) throw std::invalid_argument("CellGrid: too many points");
    mOrder.resize(n);
    mCellKey.clear();
    mCellStart.clear();
    if (n == 0) {
        mCellKey.push_back(std::numeric_limits<std::uint64_t>::max());
        mCellStart.push_back(0);
        return;
    }
    auto at = [&](std::size_t i) { return xyz + 3 * (index ? std::size_t(index[i]) : i); };

    // Bounding box; cells are counted from its low corner (any grid of this cell size finds the
    // same pairs), with one cell of padding on each side so that +-1 neighbours never wrap.
    // (In parallel chunks, each with its own bounds, then combined: min and max do not depend on
    // the order.)
    const std::size_t chunks = (n + kChunk - 1) / kChunk;
    mBounds.resize(chunks);
    parallelForChunks(0, chunks, 1, [&](std::size_t c0, std::size_t c1) {
        for (std::size_t c = c0; c < c1; ++c) {
            Bounds& b = mBounds[c];
            for (int a = 0; a < 3; ++a) b.lo[a] = b.hi[a] = at(c * kChunk)[a];
            b.numbers = true;
            for (std::size_t i = c * kChunk, end = std::min(n, (c + 1) * kChunk); i < end; ++i) {
                const double* p = at(i);
                for (int a = 0; a < 3; ++a) {
                    b.lo[a] = std::min(b.lo[a], p[a]);
                    b.hi[a] = std::max(b.hi[a], p[a]);
                    b.numbers &= p[a] == p[a];
                }
            }
        }
    });
    double lo[3], hi[3];
    for (int a = 0; a < 3; ++a) lo[a] = mBounds[0].lo[a], hi[a] = mBounds[0].hi[a];
    bool numbers = true; // no NaN (infinities fail the extent test below)
    for (const Bounds& b : mBounds)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], b.lo[a]);
            hi[a] = std::max(hi[a], b.hi[a]);
            numbers &= b.numbers;
        }
    const double inv = 1.0 / cellSize;
    std::uint64_t extent[3];
    for (int a = 0; a < 3; ++a) {
        const double cells = (hi[a] - lo[a]) * inv;
        if (!numbers || !(cells < double(1 << 20))) throw std::invalid_argument("CellGrid: points not finite or too far apart for the cell size");
        extent[a] = std::uint64_t(cells) + 3;
    }
    // The longest axis sweeps; the two others index rows (fewest rows).
    int s = 0;
    for (int a = 1; a < 3; ++a)
        if (extent[a] > extent[s]) s = a;
    const int ra = (s + 1) % 3, rb = (s + 2) % 3;
    const std::uint64_t nb = extent[rb], ns = extent[s];
    const std::uint64_t rows = extent[ra] * nb;
    mRowStep[0] = ns;            // (0, +1)
    mRowStep[1] = (nb - 1) * ns; // (+1, -1)
    mRowStep[2] = nb * ns;       // (+1, 0)
    mRowStep[3] = (nb + 1) * ns; // (+1, +1)
    auto cellOf = [&](const double* p, int a) { return std::uint64_t((p[a] - lo[a]) * inv) + 1; };

    const std::uint64_t dense = 4 * std::uint64_t(n) + 1024;
    if (rows <= dense && ns <= dense && rows < (std::uint64_t(1) << 32)) {
        // LSD: counting sort by sweep cell, then a stable counting sort by row.
        mRow.resize(n);
        mSweepCell.resize(n);
        mTmp.resize(n);
        parallelForChunks(0, n, kChunk, [&](std::size_t i0, std::size_t i1) {
            for (std::size_t i = i0; i < i1; ++i) {
                const double* p = at(i);
                mRow[i] = std::uint32_t(cellOf(p, ra) * nb + cellOf(p, rb));
                mSweepCell[i] = std::uint32_t(cellOf(p, s));
            }
        });
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
        for (std::size_t j = 0; j < n; ++j) {
            const std::uint32_t i = mOrder[j];
            const std::uint64_t k = std::uint64_t(mRow[i]) * ns + mSweepCell[i];
            if (j == 0 || k != mCellKey.back()) {
                mCellKey.push_back(k);
                mCellStart.push_back(std::uint32_t(j));
            }
        }
    } else {
        // Sparse box: sort (key, input position).
        mSortKey.resize(n);
        parallelForChunks(0, n, kChunk, [&](std::size_t i0, std::size_t i1) {
            for (std::size_t i = i0; i < i1; ++i) {
                const double* p = at(i);
                mSortKey[i] = (cellOf(p, ra) * nb + cellOf(p, rb)) * ns + cellOf(p, s);
                mOrder[i] = std::uint32_t(i);
            }
        });
        const std::uint64_t* key = mSortKey.data();
        std::sort(mOrder.begin(), mOrder.end(),
                  [key](std::uint32_t x, std::uint32_t y) { return key[x] != key[y] ? key[x] < key[y] : x < y; });
        for (std::size_t j = 0; j < n; ++j) {
            const std::uint64_t k = key[mOrder[j]];
            if (j == 0 || k != mCellKey.back()) {
                mCellKey.push_back(k);
                mCellStart.push_back(std::uint32_t(j));
            }
        }
    }
    mCellKey.push_back(std::numeric_limits<std::uint64_t>::max());
    mCellStart.push_back(std::uint32_t(n));
}

} // namespace riemesh::detail
