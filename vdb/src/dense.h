// Private helpers: dense blocks (x fastest) <-> OpenVDB grids whose every voxel in the block is active.
#pragma once

#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tree/LeafManager.h>

#include <cstddef>
#include <vector>

namespace riemesh::vdb::detail {

/// Index arithmetic of a dense block covering `box` (inclusive), x fastest.
struct DenseLayout {
    openvdb::CoordBBox box;
    int nx = 0, ny = 0, nz = 0;
    explicit DenseLayout(const openvdb::CoordBBox& b) : box(b)
    {
        const auto d = b.dim();
        nx = d.x();
        ny = d.y();
        nz = d.z();
    }
    std::size_t size() const { return std::size_t(nx) * ny * nz; }
    std::size_t index(int i, int j, int k) const
    {
        return (std::size_t(k - box.min().z()) * ny + (j - box.min().y())) * nx + (i - box.min().x());
    }
    std::size_t index(const openvdb::Coord& c) const { return index(c.x(), c.y(), c.z()); }
};

/// The values (active or not) of `grid` over `layout.box`, x fastest.
template<typename GridT>
std::vector<typename GridT::ValueType> gridToDense(const GridT& grid, const DenseLayout& layout)
{
    using ValueT = typename GridT::ValueType;
    std::vector<ValueT> data(layout.size());
    openvdb::tools::Dense<ValueT, openvdb::tools::LayoutXYZ> dense(layout.box, data.data());
    openvdb::tools::copyToDense(grid, dense);
    return data;
}

/// A grid with every voxel of `layout.box` active, values from `data` (x fastest); multithreaded.
template<typename GridT>
typename GridT::Ptr denseToGrid(const std::vector<typename GridT::ValueType>& data, const DenseLayout& layout,
                                const typename GridT::ValueType& background)
{
    auto grid = GridT::create(background);
    grid->tree().denseFill(layout.box, background, /*active=*/true);
    openvdb::tree::LeafManager<typename GridT::TreeType> leaves(grid->tree());
    leaves.foreach([&](typename GridT::TreeType::LeafNodeType& leaf, std::size_t) {
        for (auto it = leaf.beginValueOn(); it; ++it) it.setValue(data[layout.index(it.getCoord())]);
    });
    return grid;
}

} // namespace riemesh::vdb::detail
