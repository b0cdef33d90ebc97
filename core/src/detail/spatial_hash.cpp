#include "detail/spatial_hash.h"

#include <cmath>
#include <stdexcept>

namespace riemesh::detail {

namespace {

constexpr std::uint64_t packOffset(int dx, int dy, int dz)
{
    return (std::uint64_t(std::int64_t(dx)) << 42) + (std::uint64_t(std::int64_t(dy)) << 21) +
           std::uint64_t(std::int64_t(dz));
}

} // namespace

// The 13 neighbours lexicographically greater than (0, 0, 0): with the cell itself they form a
// half stencil that meets every neighbouring pair of cells exactly once.
const std::array<std::uint64_t, 13> SpatialHash::kForwardOffsets = {
    packOffset(1, -1, -1), packOffset(1, -1, 0), packOffset(1, -1, 1), packOffset(1, 0, -1), packOffset(1, 0, 0),
    packOffset(1, 0, 1),   packOffset(1, 1, -1), packOffset(1, 1, 0),  packOffset(1, 1, 1),  packOffset(0, 1, -1),
    packOffset(0, 1, 0),   packOffset(0, 1, 1),  packOffset(0, 0, 1),
};

void SpatialHash::build(const std::vector<Eigen::Vector3d>& points, const std::vector<int>& ids, double cellSize,
                        const std::vector<Eigen::Vector3d>& normals)
{
    if (!normals.empty() && normals.size() != points.size()) throw std::invalid_argument("SpatialHash: one normal per point");
    if (!(cellSize > 0)) throw std::invalid_argument("SpatialHash: cell size must be > 0");
    if (ids.size() != points.size()) throw std::invalid_argument("SpatialHash: one id per point");
    const std::size_t n = points.size();
    int bits = 4;
    while ((std::size_t(1) << bits) < 2 * n) ++bits;
    const std::size_t tableSize = std::size_t(1) << bits;
    mShift = 64 - bits;

    const double inv = 1.0 / cellSize;
    const double limit = double(kBias - 2);
    std::vector<std::uint64_t> keys(n);
    std::vector<std::uint32_t> bucket(n);
    mBucketStart.assign(tableSize + 1, 0);
    for (std::size_t i = 0; i < n; ++i) {
        std::uint64_t key = 0;
        for (int a = 0; a < 3; ++a) {
            const double c = std::floor(points[i][a] * inv);
            if (!(std::abs(c) < limit)) throw std::invalid_argument("SpatialHash: point too far from the origin for the cell size");
            key = (key << kBits) | std::uint64_t(std::int64_t(c) + kBias);
        }
        keys[i] = key;
        bucket[i] = bucketOf(key);
        ++mBucketStart[bucket[i] + 1];
    }
    mOccupied.assign((tableSize + 63) / 64, 0);
    for (std::size_t b = 0; b < tableSize; ++b) {
        if (mBucketStart[b + 1] > 0) mOccupied[b >> 6] |= std::uint64_t(1) << (b & 63);
        mBucketStart[b + 1] += mBucketStart[b];
    }

    // Counting sort by bucket, then insertion sort by key inside each (small) bucket.
    std::vector<std::uint32_t> order(n), slot(mBucketStart.begin(), mBucketStart.end() - 1);
    for (std::size_t i = 0; i < n; ++i) order[slot[bucket[i]]++] = std::uint32_t(i);
    for (std::size_t b = 0; b < tableSize; ++b) {
        const std::uint32_t begin = mBucketStart[b], end = mBucketStart[b + 1];
        for (std::uint32_t s = begin + 1; s < end; ++s) {
            const std::uint32_t x = order[s];
            std::uint32_t t = s;
            while (t > begin && keys[order[t - 1]] > keys[x]) {
                order[t] = order[t - 1];
                --t;
            }
            order[t] = x;
        }
    }
    mPoints.resize(n);
    mKeys.resize(n);
    mIds.resize(n);
    mNormals.resize(normals.empty() ? 0 : n);
    mCellStart.clear();
    for (std::size_t s = 0; s < n; ++s) {
        const std::uint32_t i = order[s];
        mPoints[s] = points[i];
        mKeys[s] = keys[i];
        mIds[s] = ids[i];
        if (!normals.empty()) mNormals[s] = normals[i];
        if (s == 0 || mKeys[s] != mKeys[s - 1]) mCellStart.push_back(std::uint32_t(s));
    }
    mCellStart.push_back(std::uint32_t(n));
}

} // namespace riemesh::detail
