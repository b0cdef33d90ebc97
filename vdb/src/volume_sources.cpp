// Volumes made in memory (volume_sources.h): from strided arrays, and phantoms.
#include "riemesh/vdb/volume_sources.h"

#include "riemesh/vdb/io.h"
#include "riemesh/vdb/phantom.h"
#include "riemesh/vdb/volume_grids.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace riemesh::vdb {

namespace {

using Leaf = openvdb::FloatTree::LeafNodeType;

template<typename T>
float elementAt(const char* p)
{
    T v;
    std::memcpy(&v, p, sizeof(T)); // any alignment (numpy views can be unaligned)
    return float(v);
}

/// Leaves of `tree` covering the array's box, every voxel active, filled in parallel from the elements
/// where they are. Returns the number of non-finite values met.
template<typename T>
std::uint64_t fillLeaves(const ArrayView& a, openvdb::FloatTree& tree)
{
    const auto dim = Leaf::DIM;
    std::vector<openvdb::Coord> origins;
    for (std::int64_t i = 0; i < a.shape[0]; i += dim)
        for (std::int64_t j = 0; j < a.shape[1]; j += dim)
            for (std::int64_t k = 0; k < a.shape[2]; k += dim) origins.emplace_back(int(i), int(j), int(k));
    std::vector<Leaf*> leaves(origins.size(), nullptr);
    std::atomic<std::uint64_t> nonFinite{0};
    const char* base = static_cast<const char*>(a.data);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, origins.size()), [&](const tbb::blocked_range<std::size_t>& r) {
        std::uint64_t bad = 0;
        for (std::size_t n = r.begin(); n != r.end(); ++n) {
            const openvdb::Coord o = origins[n];
            auto leaf = std::make_unique<Leaf>(o, 0.0f, false);
            const int ni = int(std::min<std::int64_t>(dim, a.shape[0] - o.x()));
            const int nj = int(std::min<std::int64_t>(dim, a.shape[1] - o.y()));
            const int nk = int(std::min<std::int64_t>(dim, a.shape[2] - o.z()));
            for (int i = 0; i < ni; ++i)
                for (int j = 0; j < nj; ++j) {
                    const char* row = base + (o.x() + i) * a.strides[0] + (o.y() + j) * a.strides[1] + o.z() * a.strides[2];
                    for (int k = 0; k < nk; ++k) {
                        const float v = elementAt<T>(row + k * a.strides[2]);
                        bad += !std::isfinite(v);
                        leaf->setValueOn(Leaf::coordToOffset(openvdb::Coord(o.x() + i, o.y() + j, o.z() + k)), v);
                    }
                }
            leaves[n] = leaf.release();
        }
        nonFinite += bad;
    });
    for (Leaf* leaf : leaves) tree.addLeaf(leaf); // the tree owns them now
    return nonFinite;
}

std::string shapeText(const std::array<std::int64_t, 3>& s)
{
    return "(" + std::to_string(s[0]) + ", " + std::to_string(s[1]) + ", " + std::to_string(s[2]) + ")";
}

} // namespace

Volume volumeFromArray(const ArrayView& a, const ArrayPlacement& placement, std::uint64_t memoryBudget)
{
    initialize();
    constexpr std::int64_t kMaxAxis = std::int64_t(1) << 30; // OpenVDB coordinates are 32-bit
    for (int axis = 0; axis < 3; ++axis)
        if (a.shape[axis] < 2 || a.shape[axis] > kMaxAxis)
            throw std::invalid_argument("volume: an array of shape " + shapeText(a.shape) +
                                        " is not a 3D block (need 2 to 2^30 elements along each axis)");
    if (!a.data) throw std::invalid_argument("volume: no data");
    for (int axis = 0; axis < 3; ++axis) {
        const double s = placement.spacing[axis], o = placement.origin[axis];
        if (!(s > 0) || !std::isfinite(s)) {
            std::ostringstream msg;
            msg << "spacing: must be > 0 along each axis (got " << placement.spacing[0] << ", " << placement.spacing[1]
                << ", " << placement.spacing[2] << ")";
            throw std::invalid_argument(msg.str());
        }
        if (!std::isfinite(o)) throw std::invalid_argument("origin: must be finite");
    }
    openvdb::GridClass gridClass;
    if (placement.gridClass == "fog") gridClass = openvdb::GRID_FOG_VOLUME;
    else if (placement.gridClass == "levelset") gridClass = openvdb::GRID_LEVEL_SET;
    else if (placement.gridClass == "unknown") gridClass = openvdb::GRID_UNKNOWN;
    else throw std::invalid_argument("grid_class: '" + placement.gridClass + "' is not fog, levelset or unknown");
    checkMemoryBudget(placement.name, {a.shape[0], a.shape[1], a.shape[2]},
                      memoryBudget ? memoryBudget : defaultMemoryBudget());

    auto grid = openvdb::FloatGrid::create(0.0f);
    std::uint64_t bad = 0;
    switch (a.element) {
    case ArrayElement::Float32: bad = fillLeaves<float>(a, grid->tree()); break;
    case ArrayElement::Float64: bad = fillLeaves<double>(a, grid->tree()); break;
    case ArrayElement::Int8: bad = fillLeaves<std::int8_t>(a, grid->tree()); break;
    case ArrayElement::UInt8: bad = fillLeaves<std::uint8_t>(a, grid->tree()); break;
    case ArrayElement::Int16: bad = fillLeaves<std::int16_t>(a, grid->tree()); break;
    case ArrayElement::UInt16: bad = fillLeaves<std::uint16_t>(a, grid->tree()); break;
    case ArrayElement::Int32: bad = fillLeaves<std::int32_t>(a, grid->tree()); break;
    case ArrayElement::UInt32: bad = fillLeaves<std::uint32_t>(a, grid->tree()); break;
    case ArrayElement::Int64: bad = fillLeaves<std::int64_t>(a, grid->tree()); break;
    case ArrayElement::UInt64: bad = fillLeaves<std::uint64_t>(a, grid->tree()); break;
    }
    if (bad) throw std::invalid_argument("volume: the array has " + std::to_string(bad) + " non-finite (NaN or infinite) values");

    const auto& s = placement.spacing;
    const auto& o = placement.origin;
    openvdb::math::Transform::Ptr transform;
    if (s[0] == s[1] && s[1] == s[2]) {
        transform = openvdb::math::Transform::createLinearTransform(s[0]);
    } else {
        openvdb::math::Mat4d m(openvdb::math::Mat4d::identity());
        m.setToScale(openvdb::Vec3d(s[0], s[1], s[2]));
        transform = openvdb::math::Transform::createLinearTransform(m);
    }
    if (o[0] != 0 || o[1] != 0 || o[2] != 0) transform->postTranslate(openvdb::Vec3d(o[0], o[1], o[2]));
    grid->setTransform(transform);
    grid->setName(placement.name);
    grid->setGridClass(gridClass);
    std::ostringstream note;
    note.precision(17);
    note << "array index (i, j, k) * spacing (" << s[0] << ", " << s[1] << ", " << s[2] << ") + origin (" << o[0] << ", "
         << o[1] << ", " << o[2] << ")";
    return VolumeGrids::fromImage(grid, "array", note.str());
}

Volume phantomVolume(const std::string& shape, int size, double noise, std::uint64_t seed, const std::string& grid)
{
    if (grid != "density" && grid != "sdf") throw std::invalid_argument("phantom grid: '" + grid + "' is not density or sdf");
    PhantomOptions o;
    o.size = size;
    o.noise = noise;
    o.seed = seed;
    const Phantom p = makePhantom(phantomShapeFromName(shape), o);
    return VolumeGrids::fromImage(grid == "sdf" ? p.sdf : p.density, "phantom", "grid transform");
}

} // namespace riemesh::vdb
