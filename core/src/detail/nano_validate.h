// detail/nano_validate.h: bounds checks on NanoVDB bytes from a file, before anything follows them.
//
// A NanoVDB grid is a flat buffer whose nodes find each other through stored byte offsets, and
// NanoVDB trusts every one of them (its own GridValidator only checks some, and computes a checksum
// over ranges taken from the same untrusted header). A corrupt or hostile .nvdb file would make the
// accessor, the leaf scans and nanoToOpenVDB read anywhere in memory. These checks walk the node
// arrays once (O(nodes)) and accept a grid only when every offset the library follows lands on a
// node of the right level inside the buffer; then reading it can go wrong only in its values.
#pragma once

#include <nanovdb/NanoVDB.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>

namespace riemesh::detail {

/// Empty when the grid header at `bytes` (a whole buffer of `size` bytes, 32-byte aligned) is sane:
/// magic, version, one grid of exactly `size` bytes, a terminated name, a valid class and type, a
/// finite invertible map. Otherwise the reason.
inline std::string nanoHeaderProblem(const std::uint8_t* bytes, std::size_t size)
{
    if (size < sizeof(nanovdb::GridData) + sizeof(nanovdb::TreeData<3>)) return "grid smaller than its header";
    const auto* g = reinterpret_cast<const nanovdb::GridData*>(bytes);
    if (g->mMagic != NANOVDB_MAGIC_NUMBER) return "bad grid magic number";
    if (g->mVersion.getMajor() != NANOVDB_MAJOR_VERSION_NUMBER) return "unsupported grid version";
    // getGrid() walks gridIndex/gridSize to find a grid: one grid per buffer keeps it in place.
    if (g->mGridIndex != 0 || g->mGridCount != 1 || g->mGridSize != size) return "inconsistent grid size or count";
    if (!std::memchr(g->mGridName, 0, sizeof(g->mGridName))) return "grid name is not terminated";
    if (g->mGridClass >= nanovdb::GridClass::End || g->mGridType >= nanovdb::GridType::End)
        return "unknown grid class or type";
    const double* m = g->mMap.mMatD;
    for (int i = 0; i < 9; ++i)
        if (!std::isfinite(m[i]) || !std::isfinite(g->mMap.mInvMatD[i])) return "non-finite grid transform";
    for (int i = 0; i < 3; ++i)
        if (!std::isfinite(g->mMap.mVecD[i]) || !(g->mVoxelSize[i] > 0) || !std::isfinite(g->mVoxelSize[i]))
            return "non-finite grid transform or voxel size";
    const double det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
                       m[2] * (m[3] * m[7] - m[4] * m[6]);
    if (!(std::abs(det) > 1e-300) || !std::isfinite(det)) return "singular grid transform";
    return {};
}

/// Empty when the tree of the NanoGrid<T> at `bytes` (header already checked, type T) only points
/// inside the buffer: root tile table, node arrays of the counts the tree declares, and every child
/// offset (root -> upper -> lower -> leaf) onto a node of the array of the level below.
template<typename T>
std::string nanoTreeProblem(const std::uint8_t* bytes, std::size_t size)
{
    using Root = nanovdb::NanoRoot<T>;
    using Upper = nanovdb::NanoUpper<T>;
    using Lower = nanovdb::NanoLower<T>;
    using Leaf = nanovdb::NanoLeaf<T>;
    using RootData = typename Root::DataType;
    const std::uint64_t treeAt = sizeof(nanovdb::GridData);
    const auto* tree = reinterpret_cast<const nanovdb::TreeData<3>*>(bytes + treeAt);

    // [start, start + count * stride) inside the buffer, 32-byte aligned (as NanoVDB lays it out).
    auto inside = [&](std::uint64_t start, std::uint64_t count, std::uint64_t stride) {
        return start % NANOVDB_DATA_ALIGNMENT == 0 && start <= size && count <= (size - start) / stride;
    };
    const std::uint64_t rootAt = treeAt + tree->mNodeOffset[3];
    if (tree->mNodeOffset[3] > size || !inside(rootAt, 1, sizeof(RootData))) return "root node outside the grid";
    const auto* root = reinterpret_cast<const RootData*>(bytes + rootAt);
    using Tile = typename RootData::Tile;
    if (!inside(rootAt + sizeof(RootData), root->mTableSize, sizeof(Tile))) return "root tile table outside the grid";

    std::uint64_t first[3];
    const std::uint64_t stride[3] = {sizeof(Leaf), sizeof(Lower), sizeof(Upper)};
    for (int level = 0; level < 3; ++level) {
        const std::uint64_t count = tree->mNodeCount[level];
        first[level] = treeAt + tree->mNodeOffset[level];
        if (count > 0 && (tree->mNodeOffset[level] > size || !inside(first[level], count, stride[level])))
            return "node array of level " + std::to_string(level) + " outside the grid";
    }
    // `from` + signed `offset` is node k < count of `level`'s array.
    auto isNode = [&](std::uint64_t from, std::int64_t offset, int level) {
        const std::uint64_t count = tree->mNodeCount[level];
        if (count == 0) return false;
        const std::uint64_t at = from + std::uint64_t(offset); // wraps like the pointer arithmetic
        if (at < first[level]) return false;
        const std::uint64_t rel = at - first[level];
        return rel % stride[level] == 0 && rel / stride[level] < count;
    };
    const auto* tiles = reinterpret_cast<const Tile*>(bytes + rootAt + sizeof(RootData));
    for (std::uint32_t i = 0; i < root->mTableSize; ++i)
        if (tiles[i].child != 0 && !isNode(rootAt, tiles[i].child, 2)) return "root child offset is invalid";
    auto checkChildren = [&](int level, auto* node) -> bool {
        using Node = std::remove_pointer_t<decltype(node)>;
        for (std::uint64_t k = 0; k < tree->mNodeCount[level]; ++k) {
            const std::uint64_t at = first[level] + k * sizeof(Node);
            const auto* data = reinterpret_cast<const typename Node::DataType*>(bytes + at);
            for (auto it = data->mChildMask.beginOn(); it; ++it)
                if (!isNode(at, data->mTable[*it].child, level - 1)) return false;
        }
        return true;
    };
    if (!checkChildren(2, static_cast<const Upper*>(nullptr))) return "upper node child offset is invalid";
    if (!checkChildren(1, static_cast<const Lower*>(nullptr))) return "lower node child offset is invalid";
    return {};
}

} // namespace riemesh::detail
