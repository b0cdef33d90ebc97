// detail/spatial_hash.h: a uniform-grid broad phase for fixed-radius neighbour pairs.
//
// Points are binned into cubic cells of side `cellSize` (world units). Each cell gets a 64-bit key
// (three 21-bit coordinates); keys are hashed into a power-of-two table and the points are
// counting-sorted by bucket, then by key inside each bucket, into flat arrays (no per-cell
// containers, O(n) build), so every occupied cell is one contiguous run. Each pair closer than
// the cell size is enumerated exactly once from its cell's run by a half stencil of 14 cells (the
// cell itself and its 13 "forward" neighbours); hash collisions are resolved by comparing keys.
#pragma once

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <vector>

namespace riemesh::detail {

class SpatialHash {
public:
    /// Bins `points` (world space). `ids[i]` is reported for points[i]; `normals` (optional, empty
    /// or one per point) is stored beside the points so pair filters read contiguous memory.
    /// `cellSize` > 0 (world units); points must lie within 2^20 cells of the origin on each axis.
    void build(const std::vector<Eigen::Vector3d>& points, const std::vector<int>& ids, double cellSize,
               const std::vector<Eigen::Vector3d>& normals = {});

    /// Calls f(a0, a1, b0, b1) once for every pair of neighbouring occupied cells (the half
    /// stencil), with the slot ranges [a0, a1) and [b0, b1) of their points; for a cell paired
    /// with itself the two ranges are equal (pair slot s only with slots t > s then). Every pair
    /// of points closer than the cell size lies in exactly one such call.
    template <class F>
    void forEachCellPair(F&& f) const
    {
        for (std::size_t c = 0; c + 1 < mCellStart.size(); ++c) {
            const std::uint32_t s0 = mCellStart[c], s1 = mCellStart[c + 1];
            f(s0, s1, s0, s1);
            const std::uint64_t key = mKeys[s0];
            for (const std::uint64_t offset : kForwardOffsets) {
                std::uint32_t t0 = 0, t1 = 0;
                if (findCell(key + offset, t0, t1)) f(s0, s1, t0, t1);
            }
        }
    }

    /// Calls f(slotA, slotB, squaredDistance) once for every unordered pair of distinct points
    /// with squared Euclidean distance <= radius^2 (world units; radius <= the cell size). Slots
    /// index id(), point() and normal().
    template <class F>
    void forEachPairWithin(double radius, F&& f) const
    {
        const double r2 = radius * radius;
        forEachCellPair([&](std::uint32_t a0, std::uint32_t a1, std::uint32_t b0, std::uint32_t b1) {
            for (std::uint32_t s = a0; s < a1; ++s) {
                const Eigen::Vector3d& p = mPoints[s];
                for (std::uint32_t t = (a0 == b0 ? s + 1 : b0); t < b1; ++t) {
                    const double d2 = (mPoints[t] - p).squaredNorm();
                    if (d2 <= r2) f(s, t, d2);
                }
            }
        });
    }

    std::size_t size() const { return mPoints.size(); }
    int id(std::uint32_t slot) const { return mIds[slot]; }
    const Eigen::Vector3d& point(std::uint32_t slot) const { return mPoints[slot]; }
    const Eigen::Vector3d& normal(std::uint32_t slot) const { return mNormals[slot]; }

private:
    static constexpr int kBits = 21;
    static constexpr std::int64_t kBias = std::int64_t(1) << (kBits - 1);
    static const std::array<std::uint64_t, 13> kForwardOffsets;

    std::uint32_t bucketOf(std::uint64_t key) const
    {
        return std::uint32_t((key * 0x9E3779B97F4A7C15ull) >> mShift);
    }
    /// The run [t0, t1) of the points of cell `key`; false when the cell is empty.
    bool findCell(std::uint64_t key, std::uint32_t& t0, std::uint32_t& t1) const
    {
        const std::uint32_t b = bucketOf(key);
        if (!(mOccupied[b >> 6] >> (b & 63) & 1u)) return false; // most stencil cells are empty
        std::uint32_t t = mBucketStart[b];
        const std::uint32_t end = mBucketStart[b + 1];
        while (t < end && mKeys[t] < key) ++t;
        if (t == end || mKeys[t] != key) return false;
        t0 = t;
        while (t < end && mKeys[t] == key) ++t;
        t1 = t;
        return true;
    }

    int mShift = 60;
    std::vector<std::uint32_t> mBucketStart; ///< bucket b holds sorted slots [start[b], start[b+1])
    std::vector<std::uint64_t> mOccupied;    ///< one bit per bucket: non-empty (small, stays in cache)
    std::vector<std::uint32_t> mCellStart;   ///< occupied cell c holds slots [start[c], start[c+1])
    std::vector<Eigen::Vector3d> mPoints;    ///< positions in sorted order (world units)
    std::vector<std::uint64_t> mKeys;        ///< packed cell coordinates in sorted order
    std::vector<int> mIds;                   ///< caller ids in sorted order
    std::vector<Eigen::Vector3d> mNormals;   ///< caller normals in sorted order (may be empty)
};

} // namespace riemesh::detail
