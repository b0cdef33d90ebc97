// detail/box_grid.h: a hashed uniform grid of axis-aligned boxes (world units), for the broad
// phase of continuous collision detection and of the intersection guards (ccd.cpp).
//
// Items (ints >= 0) are inserted with a box; each is entered in every cell its box overlaps (cubic
// cells of side cellSize, hashed into power-of-two buckets, chained). query(box, f) calls f(item)
// once for every item whose current box overlaps `box`: an item is reported only in the cell of the
// lower corner of the two boxes' intersection, so an item met in several cells is reported once.
// Inserting an item again (its box changed) adds entries for its new box; the old ones stay but
// are filtered by the item's current box (an item may then be reported twice: callers tolerate it).
// Deterministic: the order of the reports depends only on the insertions. Private to core/src.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace riemesh::detail {

/// lo xyz, hi xyz.
using Box6 = std::array<double, 6>;

inline bool boxesOverlap(const Box6& x, const Box6& y)
{
    return x[0] <= y[3] && y[0] <= x[3] && x[1] <= y[4] && y[1] <= x[4] && x[2] <= y[5] && y[2] <= x[5];
}

class BoxGrid {
public:
    /// Empties the grid; cells of side cellSize (world units, > 0), buckets for about `entries`.
    void reset(double cellSize, std::size_t entries)
    {
        mInvCell = 1.0 / cellSize;
        std::size_t buckets = 64;
        while (buckets < 2 * entries && buckets < (std::size_t(1) << 26)) buckets *= 2;
        mBits = 0;
        while ((std::size_t(1) << mBits) < buckets) ++mBits;
        mHead.assign(buckets, -1);
        mEntries.clear();
        mBox.clear();
        mIsLarge.clear();
        mLarge.clear();
    }

    /// Enters `item` with `box` (replaces the box it had).
    void insert(int item, const Box6& box)
    {
        if (std::size_t(item) >= mBox.size()) {
            mBox.resize(std::size_t(item) + 1, kEmpty);
            mIsLarge.resize(std::size_t(item) + 1, 0);
        }
        mBox[std::size_t(item)] = box;
        std::array<std::int64_t, 6> c{};
        mIsLarge[std::size_t(item)] = !cellRange(box, c);
        if (mIsLarge[std::size_t(item)]) {
            mLarge.push_back(item);
            return;
        }
        for (std::int64_t x = c[0]; x <= c[3]; ++x)
            for (std::int64_t y = c[1]; y <= c[4]; ++y)
                for (std::int64_t z = c[2]; z <= c[5]; ++z) {
                    const std::uint64_t key = pack(x, y, z);
                    std::int32_t& head = mHead[bucket(key)];
                    mEntries.push_back({key, item, head});
                    head = std::int32_t(mEntries.size() - 1);
                }
    }

    /// Forgets `item` (its entries stay, filtered out).
    void erase(int item)
    {
        if (std::size_t(item) >= mBox.size()) return;
        mBox[std::size_t(item)] = kEmpty;
        mIsLarge[std::size_t(item)] = 0;
    }

    /// The current box of `item`.
    const Box6& box(int item) const { return mBox[std::size_t(item)]; }

    /// Calls f(item) for every item whose box overlaps `q` (see the file comment).
    template <class F>
    void query(const Box6& q, F&& f) const
    {
        for (const int item : mLarge)
            if (mIsLarge[std::size_t(item)] && boxesOverlap(q, mBox[std::size_t(item)])) f(item);
        std::array<std::int64_t, 6> c{};
        if (!cellRange(q, c)) { // a query box too large for the cells: every item
            for (std::size_t i = 0; i < mBox.size(); ++i)
                if (!mIsLarge[i] && boxesOverlap(q, mBox[i])) f(int(i));
            return;
        }
        for (std::int64_t x = c[0]; x <= c[3]; ++x)
            for (std::int64_t y = c[1]; y <= c[4]; ++y)
                for (std::int64_t z = c[2]; z <= c[5]; ++z) {
                    const std::uint64_t key = pack(x, y, z);
                    for (std::int32_t e = mHead[bucket(key)]; e >= 0; e = mEntries[std::size_t(e)].next) {
                        const Entry& entry = mEntries[std::size_t(e)];
                        if (entry.key != key) continue;
                        const Box6& b = mBox[std::size_t(entry.item)];
                        if (!boxesOverlap(q, b) || mIsLarge[std::size_t(entry.item)]) continue;
                        // Report in the cell of the intersection's lower corner only.
                        if (cell(std::max(q[0], b[0])) != x || cell(std::max(q[1], b[1])) != y ||
                            cell(std::max(q[2], b[2])) != z)
                            continue;
                        f(entry.item);
                    }
                }
    }

private:
    struct Entry {
        std::uint64_t key;
        std::int32_t item;
        std::int32_t next;
    };
    static constexpr Box6 kEmpty = {1, 1, 1, -1, -1, -1}; // overlaps nothing
    /// Boxes spanning more cells than this on an axis are kept in mLarge, tested by every query.
    static constexpr std::int64_t kMaxSpan = 64;

    std::int64_t cell(double x) const { return std::int64_t(std::floor(x * mInvCell)); }
    bool cellRange(const Box6& b, std::array<std::int64_t, 6>& c) const
    {
        for (int k = 0; k < 6; ++k) {
            const double s = b[k] * mInvCell;
            if (!(std::abs(s) < 1e15)) return false; // non-finite or absurd
            c[k] = std::int64_t(std::floor(s));
        }
        for (int k = 0; k < 3; ++k)
            if (c[k] > c[k + 3] || c[k + 3] - c[k] > kMaxSpan) return false;
        return true;
    }
    static std::uint64_t pack(std::int64_t x, std::int64_t y, std::int64_t z)
    {
        constexpr std::uint64_t m = (std::uint64_t(1) << 21) - 1;
        return ((std::uint64_t(x) & m) << 42) | ((std::uint64_t(y) & m) << 21) | (std::uint64_t(z) & m);
    }
    std::size_t bucket(std::uint64_t key) const
    {
        return std::size_t((key * 0x9E3779B97F4A7C15ull) >> (64 - mBits));
    }

    double mInvCell = 1.0;
    int mBits = 6;
    std::vector<std::int32_t> mHead;
    std::vector<Entry> mEntries;
    std::vector<Box6> mBox;
    std::vector<char> mIsLarge; ///< by item: its current box is in mLarge
    std::vector<int> mLarge; ///< items whose box spans too many cells: tested by every query
};

/// A BoxGrid built once from all its boxes, laid out for speed: the entries of a bucket are
/// contiguous and carry their item's box (in floats rounded outward: 40 bytes an entry), so that a
/// query reads memory in order (the collision-safe step queries it once per vertex and edge of the
/// mesh, every iteration). Reports every item whose box overlaps the query, once (the float boxes
/// are a little larger than the given ones: a few more reports, never fewer). Buffers are kept
/// between builds.
class PackedBoxGrid {
public:
    /// Items 0..boxes.size()-1 with those boxes; cells of side cellSize > 0 (world units).
    void build(const std::vector<Box6>& boxes, double cellSize)
    {
        mInvCell = 1.0 / cellSize;
        mLarge.clear();
        mTemp.clear();
        for (std::size_t i = 0; i < boxes.size(); ++i) {
            Entry e{0, std::int32_t(i), {}};
            for (int k = 0; k < 3; ++k) {
                e.box[k] = down(boxes[i][k]);
                e.box[k + 3] = up(boxes[i][k + 3]);
            }
            std::array<std::int64_t, 6> c{};
            if (!cellRange(e.box, c)) {
                mLarge.push_back(e);
                continue;
            }
            for (std::int64_t x = c[0]; x <= c[3]; ++x)
                for (std::int64_t y = c[1]; y <= c[4]; ++y)
                    for (std::int64_t z = c[2]; z <= c[5]; ++z) {
                        e.key = pack(x, y, z);
                        mTemp.push_back(e);
                    }
        }
        std::size_t buckets = 64;
        while (buckets < mTemp.size() && buckets < (std::size_t(1) << 26)) buckets *= 2;
        mBits = 0;
        while ((std::size_t(1) << mBits) < buckets) ++mBits;
        mStart.assign(buckets + 1, 0);
        mBucket.resize(mTemp.size());
        for (std::size_t t = 0; t < mTemp.size(); ++t) {
            mBucket[t] = std::uint32_t(bucket(mTemp[t].key));
            ++mStart[mBucket[t] + 1];
        }
        for (std::size_t b = 0; b < buckets; ++b) mStart[b + 1] += mStart[b];
        mEntries.resize(mTemp.size());
        mFill.assign(mStart.begin(), mStart.end() - 1);
        for (std::size_t t = 0; t < mTemp.size(); ++t) mEntries[mFill[mBucket[t]]++] = mTemp[t];
    }


    /// Calls f(item) once for every item whose box overlaps `q`.
    template <class F>
    void query(const Box6& q, F&& f) const
    {
        for (const Entry& e : mLarge)
            if (overlaps(q, e.box)) f(int(e.item));
        std::array<std::int64_t, 6> c{};
        const std::array<float, 6> qf = {down(q[0]), down(q[1]), down(q[2]), up(q[3]), up(q[4]), up(q[5])};
        if (!cellRange(qf, c)) { // a query box too large for the cells: every entry, once per item
            for (const Entry& e : mEntries) {
                std::array<std::int64_t, 6> b{};
                cellRange(e.box, b);
                if (e.key == pack(b[0], b[1], b[2]) && overlaps(q, e.box)) f(int(e.item));
            }
            return;
        }
        for (std::int64_t x = c[0]; x <= c[3]; ++x)
            for (std::int64_t y = c[1]; y <= c[4]; ++y)
                for (std::int64_t z = c[2]; z <= c[5]; ++z) {
                    const std::uint64_t key = pack(x, y, z);
                    const std::size_t b = bucket(key);
                    for (std::uint32_t i = mStart[b], end = mStart[b + 1]; i < end; ++i) {
                        const Entry& e = mEntries[i];
                        if (e.key != key || !overlaps(q, e.box)) continue;
                        // Report in the cell of the intersection's lower corner only (the item's
                        // own lower cell matters only where the query starts before this cell).
                        if ((x != c[0] && cell(e.box[0]) != x) || (y != c[1] && cell(e.box[1]) != y) ||
                            (z != c[2] && cell(e.box[2]) != z))
                            continue;
                        f(int(e.item));
                    }
                }
    }

private:
    struct Entry {
        std::uint64_t key;
        std::int32_t item;
        std::array<float, 6> box; ///< lo xyz, hi xyz, rounded outward
    };
    static constexpr std::int64_t kMaxSpan = 64;
    static float down(double x)
    {
        float f = float(x);
        if (double(f) > x) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
        return f;
    }
    static float up(double x)
    {
        float f = float(x);
        if (double(f) < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
        return f;
    }
    static bool overlaps(const Box6& q, const std::array<float, 6>& b)
    {
        return q[0] <= b[3] && b[0] <= q[3] && q[1] <= b[4] && b[1] <= q[4] && q[2] <= b[5] && b[2] <= q[5];
    }
    std::int64_t cell(float x) const { return std::int64_t(std::floor(double(x) * mInvCell)); }
    bool cellRange(const std::array<float, 6>& b, std::array<std::int64_t, 6>& c) const
    {
        for (int k = 0; k < 6; ++k) {
            const double s = double(b[std::size_t(k)]) * mInvCell;
            if (!(std::abs(s) < 1e15)) return false; // non-finite or absurd
            c[std::size_t(k)] = std::int64_t(std::floor(s));
        }
        for (int k = 0; k < 3; ++k)
            if (c[std::size_t(k)] > c[std::size_t(k) + 3] || c[std::size_t(k) + 3] - c[std::size_t(k)] > kMaxSpan) return false;
        return true;
    }
    static std::uint64_t pack(std::int64_t x, std::int64_t y, std::int64_t z)
    {
        constexpr std::uint64_t m = (std::uint64_t(1) << 21) - 1;
        return ((std::uint64_t(x) & m) << 42) | ((std::uint64_t(y) & m) << 21) | (std::uint64_t(z) & m);
    }
    std::size_t bucket(std::uint64_t key) const { return std::size_t((key * 0x9E3779B97F4A7C15ull) >> (64 - mBits)); }

    double mInvCell = 1.0;
    int mBits = 6;
    std::vector<std::uint32_t> mStart, mFill, mBucket;
    std::vector<Entry> mEntries, mTemp, mLarge;
};

} // namespace riemesh::detail
