// OpenVDB / NanoVDB file I/O and NanoVDB conversion (io.h, nano.h).
#include "riemesh/vdb/io.h"
#include "riemesh/vdb/level_set.h"
#include "riemesh/vdb/metric_grid.h"
#include "riemesh/vdb/nano.h"
#include "riemesh/vdb/nifti.h"
#include "riemesh/vdb/volume.h"

#include "isolated_read.h"

#include <openvdb/io/File.h>
#include <openvdb/tree/LeafManager.h>

#include <nanovdb/util/IO.h>
#include <nanovdb/util/NanoToOpenVDB.h>
#include <nanovdb/util/OpenToNanoVDB.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>

namespace fs = std::filesystem;

namespace riemesh::vdb {

void initialize()
{
    static std::once_flag once;
    std::call_once(once, [] { openvdb::initialize(); });
}

std::string gridClassName(const openvdb::GridBase& grid)
{
    switch (grid.getGridClass()) {
    case openvdb::GRID_FOG_VOLUME: return "fog";
    case openvdb::GRID_LEVEL_SET: return "levelset";
    default: return "unknown";
    }
}

ValueStats valueStats(const openvdb::FloatGrid& grid)
{
    // Leaf nodes in parallel (the bulk of any image), tiles after: each tile counts once.
    struct Partial {
        ValueStats s;
        void add(float v)
        {
            if (!std::isfinite(v)) {
                ++s.nonFinite;
                return;
            }
            ++s.finite;
            s.min = std::min(s.min, v);
            s.max = std::max(s.max, v);
        }
        void join(const Partial& o)
        {
            s.nonFinite += o.s.nonFinite;
            s.finite += o.s.finite;
            s.min = std::min(s.min, o.s.min);
            s.max = std::max(s.max, o.s.max);
        }
    };
    openvdb::tree::LeafManager<const openvdb::FloatTree> leaves(grid.tree());
    Partial total = tbb::parallel_reduce(
        leaves.leafRange(), Partial{},
        [](const openvdb::tree::LeafManager<const openvdb::FloatTree>::LeafRange& range, Partial p) {
            for (auto leaf = range.begin(); leaf; ++leaf)
                for (auto it = leaf->cbeginValueOn(); it; ++it) p.add(*it);
            return p;
        },
        [](Partial a, const Partial& b) {
            a.join(b);
            return a;
        });
    auto tile = grid.tree().cbeginValueOn();
    tile.setMaxDepth(openvdb::FloatTree::DEPTH - 2);
    for (; tile; ++tile) total.add(*tile);
    return total.s;
}

std::uint64_t countNonFinite(const openvdb::FloatGrid& grid) { return valueStats(grid).nonFinite; }

namespace {

std::runtime_error fileError(const std::string& path, const std::string& what)
{
    return std::runtime_error("'" + path + "': " + what);
}

void checkReadableFile(const std::string& path)
{
    std::error_code ec;
    if (!fs::exists(path, ec)) throw fileError(path, "no such file");
    if (fs::is_directory(path, ec)) throw fileError(path, "is a directory, not a file");
    if (fs::file_size(path, ec) == 0 || ec) throw fileError(path, "file is empty");
}

/// Why a VDB read failed, in words: OpenVDB's messages are terse ("IoError: ...").
std::string describeVdbFailure(const std::string& raw)
{
    // A corrupt file can put megabytes of garbage into OpenVDB's message (e.g. a grid type name read
    // from random bytes): keep it to one short printable line.
    std::string what;
    for (char c : raw) {
        const bool space = std::isspace(static_cast<unsigned char>(c)) || !std::isprint(static_cast<unsigned char>(c));
        if (space && (what.empty() || what.back() == ' ')) continue;
        what += space ? ' ' : c;
        if (what.size() > 160) {
            what += "...";
            break;
        }
    }
    std::string lower = what;
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
    if (lower.find("not a vdb file") != std::string::npos || lower.find("magic") != std::string::npos)
        return "not a VDB file";
    return "truncated or corrupt VDB file (" + what + ")";
}

std::string byteSize(double bytes)
{
    const char* units[] = {"bytes", "KB", "MB", "GB", "TB", "PB", "EB"};
    int u = 0;
    while (bytes >= 1024 && u < 6) bytes /= 1024, ++u;
    std::ostringstream s;
    s.precision(3);
    s << bytes << " " << units[u];
    return s.str();
}

openvdb::FloatGrid::Ptr checkedImage(openvdb::FloatGrid::Ptr grid, const std::string& path)
{
    const std::string name = grid->getName();
    if (grid->tree().activeVoxelCount() == 0)
        throw fileError(path, "grid '" + name + "' is empty (no active voxels)");
    if (const auto bad = countNonFinite(*grid))
        throw fileError(path, "grid '" + name + "' has " + std::to_string(bad) +
                                  " non-finite (NaN or infinite) voxel values");
    if (!std::isfinite(grid->background()))
        throw fileError(path, "grid '" + name + "' has a non-finite background value");
    return grid;
}

} // namespace

std::uint64_t estimatePipelineBytes(std::uint64_t imageBytes, bool levelSet)
{
    const double factor = levelSet ? kLevelSetBytesPerImageByte : kPipelineBytesPerImageByte;
    return std::uint64_t(std::min(kPipelineFixedBytes + factor * double(imageBytes), 1.8e19));
}

void checkMemoryBudget(const std::string& path, std::uint64_t imageBytes, bool levelSet, std::uint64_t budgetBytes)
{
    if (budgetBytes == 0) return;
    const double needed = double(estimatePipelineBytes(imageBytes, levelSet));
    if (needed <= double(budgetBytes)) return;
    throw fileError(path, "meshing this image needs about " + byteSize(needed) + " of memory (its grid takes " +
                              byteSize(double(imageBytes)) + "), more than the budget of " +
                              byteSize(double(budgetBytes)) + " (--max-memory)");
}

void checkMemoryBudget(const std::string& path, const VoxelDims& dims, std::uint64_t budgetBytes)
{
    if (budgetBytes == 0) return;
    // Every voxel active: leaf nodes of 512 floats and their masks, ~4.2 bytes per voxel.
    const double voxels = double(dims[0]) * double(dims[1]) * double(dims[2]);
    const double imageBytes = voxels * 4.2;
    const double needed = kPipelineFixedBytes + kPipelineBytesPerImageByte * imageBytes;
    if (needed <= double(budgetBytes)) return;
    throw fileError(path, "the image of " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                              std::to_string(dims[2]) + " voxels needs about " + byteSize(needed) +
                              " of memory, more than the budget of " + byteSize(double(budgetBytes)) + " (--max-memory)");
}

namespace {

/// The grid of a .vdb file that readVdbImage returns, as OpenVDB reads it (float or double, linear
/// transform, finite background): the part that runs in the isolated child (isolated_read.h), where
/// a file that corrupts OpenVDB's memory can only kill the child. No TBB here (see there).
openvdb::GridBase::ConstPtr readChosenVdbGrid(const std::string& path, const std::string& gridName,
                                              std::uint64_t memoryBudget)
{
    openvdb::io::File file(path);
    openvdb::GridPtrVecPtr metas;
    try {
        file.open(/*delayLoad=*/false);
        metas = file.readAllGridMetadata();
    } catch (const std::bad_alloc&) {
        throw; // the child's memory limit: reported as such
    } catch (const std::exception& e) {
        throw fileError(path, describeVdbFailure(e.what()));
    }
    if (!metas || metas->empty()) throw fileError(path, "the VDB file holds no grid");

    openvdb::GridBase::Ptr chosen;
    std::string names;
    for (const auto& g : *metas) {
        names += (names.empty() ? "" : ", ") + g->getName() + " (" + g->valueType() + ")";
        const bool scalar = g->isType<openvdb::FloatGrid>() || g->isType<openvdb::DoubleGrid>();
        if (gridName.empty() ? (scalar && !chosen) : (g->getName() == gridName && !chosen)) chosen = g;
    }
    if (!chosen) {
        if (gridName.empty()) throw fileError(path, "no scalar float or double grid (grids: " + names + ")");
        throw fileError(path, "no grid named '" + gridName + "' (grids: " + names + ")");
    }
    if (!(chosen->isType<openvdb::FloatGrid>() || chosen->isType<openvdb::DoubleGrid>()))
        throw fileError(path, "grid '" + chosen->getName() + "' holds " + chosen->valueType() +
                                  " values, not a scalar float or double grid");
    // The file's statistics give the grid's size in memory before any voxel is read.
    const bool levelSet = chosen->getGridClass() == openvdb::GRID_LEVEL_SET;
    if (const auto bytes = chosen->getMetadata<openvdb::Int64Metadata>(openvdb::GridBase::META_FILE_MEM_BYTES))
        if (bytes->value() > 0) checkMemoryBudget(path, std::uint64_t(bytes->value()), levelSet, memoryBudget);

    openvdb::GridBase::Ptr base;
    try {
        base = file.readGrid(chosen->getName());
        file.close();
    } catch (const std::bad_alloc&) {
        throw;
    } catch (const std::exception& e) {
        throw fileError(path, describeVdbFailure(e.what()));
    }
    if (!base) throw fileError(path, "could not read grid '" + chosen->getName() + "'");
    if (!base->transform().isLinear())
        throw fileError(path, "grid '" + base->getName() + "' has a non-linear (frustum) transform");
    const double background = base->isType<openvdb::FloatGrid>()
                                  ? double(openvdb::gridPtrCast<openvdb::FloatGrid>(base)->background())
                                  : openvdb::gridPtrCast<openvdb::DoubleGrid>(base)->background();
    if (!std::isfinite(background) || !std::isfinite(float(background)))
        throw fileError(path, "grid '" + base->getName() + "' has a non-finite background value");
    return base;
}

} // namespace

/// The least memory the isolated reader child gets, whatever the budget.
constexpr std::uint64_t kMinReaderBytes = std::uint64_t(16) << 20;

openvdb::FloatGrid::Ptr readVdbImage(const std::string& path, const std::string& gridName, std::uint64_t memoryBudget)
{
    initialize(); // before the fork: the child only reads
    checkReadableFile(path);
    // The child may use the budget, and at least what opening a file and reading its metadata
    // takes (so that a small --max-memory is refused by the budget's message, with the sizes).
    const std::uint64_t childLimit = std::max(memoryBudget ? memoryBudget : defaultMemoryBudget(), kMinReaderBytes);
    auto grid = detail::readGridInChild(path, childLimit, [&] { return readChosenVdbGrid(path, gridName, memoryBudget); });
    checkedImage(grid, path);
    checkMemoryBudget(path, grid->memUsage(), grid->getGridClass() == openvdb::GRID_LEVEL_SET, memoryBudget);
    return grid;
}

NanoFileGrids readNanoFile(const std::string& path, const std::string& gridName, std::uint64_t memoryBudget)
{
    initialize();
    checkReadableFile(path);
    NanoVolume volume;
    try {
        volume = NanoVolume::read(path);
    } catch (const std::exception& e) {
        throw std::runtime_error(e.what()); // names the file already
    }
    if (!gridName.empty() && volume.imageName() != gridName)
        throw fileError(path, "no image grid named '" + gridName + "' (image grid: '" + volume.imageName() + "')");
    // The NanoVDB grid takes about what its OpenVDB form will.
    checkMemoryBudget(path, volume.imageGrid()->gridSize(), volume.imageClass() == "levelset", memoryBudget);
    NanoFileGrids out;
    out.image = nanovdb::nanoToOpenVDB(*volume.imageGrid());
    out.image->setName(volume.imageName());
    const std::string cls = volume.imageClass();
    out.image->setGridClass(cls == "fog" ? openvdb::GRID_FOG_VOLUME
                                         : cls == "levelset" ? openvdb::GRID_LEVEL_SET : openvdb::GRID_UNKNOWN);
    checkedImage(out.image, path);
    if (volume.metricDiag() && volume.metricOff()) {
        out.metricDiag = nanovdb::nanoToOpenVDB(*volume.metricDiag());
        out.metricOff = nanovdb::nanoToOpenVDB(*volume.metricOff());
        out.metricDiag->setName(kMetricDiagGrid);
        out.metricOff->setName(kMetricOffGrid);
        out.muMax = volume.metricMaxEigenvalue();
    }
    return out;
}

openvdb::FloatGrid::Ptr readImage(const std::string& path, const std::string& gridName)
{
    const std::string ext = fileExtension(path);
    if (ext == ".vdb") return readVdbImage(path, gridName);
    if (ext == ".nvdb") return readNanoFile(path, gridName).image;
    if (ext == ".nii" || ext == ".nii.gz") return readNifti(path);
    throw fileError(path, "unknown input extension '" + ext + "' (expected .vdb, .nvdb, .nii or .nii.gz)");
}

void writeVdb(const std::string& path, const openvdb::GridCPtrVec& grids)
{
    initialize();
    writeFileAtomically(path, [&](const std::string& temp) {
        openvdb::io::File file(temp);
        file.write(grids);
        file.close();
    });
}

// ---- nano.h --------------------------------------------------------------------------------------

nanovdb::GridHandle<nanovdb::HostBuffer> toNano(const openvdb::FloatGrid& grid)
{
    // Images need no statistics in the core (only the metric's bound, below): the bounding boxes.
    return nanovdb::openToNanoVDB(grid, nanovdb::StatsMode::BBox);
}

nanovdb::GridHandle<nanovdb::HostBuffer> toNano(const openvdb::Vec3fGrid& grid)
{
    return nanovdb::openToNanoVDB(grid);
}

std::vector<nanovdb::GridHandle<nanovdb::HostBuffer>>
toNanoHandles(const openvdb::FloatGrid& image, const openvdb::Vec3fGrid* metricDiag, const openvdb::Vec3fGrid* metricOff,
              const FloatGrids& levels)
{
    if (bool(metricDiag) != bool(metricOff))
        throw std::invalid_argument("toNanoHandles: give both metric grids or neither");
    std::vector<nanovdb::GridHandle<nanovdb::HostBuffer>> handles;
    handles.push_back(toNano(image));
    if (metricDiag) {
        handles.push_back(toNano(*metricDiag));
        handles.push_back(toNano(*metricOff));
    }
    for (const auto& level : levels) handles.push_back(toNano(*level));
    return handles;
}

NanoVolume toNanoVolume(const openvdb::FloatGrid& image, const openvdb::Vec3fGrid* metricDiag,
                        const openvdb::Vec3fGrid* metricOff, const FloatGrids& levels)
{
    return NanoVolume::fromHandles(toNanoHandles(image, metricDiag, metricOff, levels));
}

void writeNvdb(const std::string& path, const openvdb::FloatGrid& image, const openvdb::Vec3fGrid* metricDiag,
               const openvdb::Vec3fGrid* metricOff, double iso, const FloatGrids& levels)
{
    auto handles = toNanoHandles(image, metricDiag, metricOff, levels);
    if (std::isfinite(iso)) {
        openvdb::FloatGrid isoGrid{float(iso)};
        isoGrid.setName(riemesh::kIsoGrid);
        isoGrid.tree().setValueOn(openvdb::Coord(0), float(iso));
        handles.push_back(toNano(isoGrid));
    }
    writeFileAtomically(path, [&](const std::string& temp) {
        nanovdb::io::writeGrids<nanovdb::HostBuffer, std::vector>(temp, handles);
    });
}

void writeNvdb(const std::string& path, const NanoVolume& volume, double iso)
{
    std::optional<nanovdb::GridHandle<nanovdb::HostBuffer>> isoHandle;
    if (std::isfinite(iso)) {
        openvdb::FloatGrid isoGrid{float(iso)};
        isoGrid.setName(riemesh::kIsoGrid);
        isoGrid.tree().setValueOn(openvdb::Coord(0), float(iso));
        isoHandle = toNano(isoGrid);
    }
    writeFileAtomically(path, [&](const std::string& temp) {
        // One segment per grid (a NanoVDB file may hold several), without copying the grids.
        std::ofstream out(temp, std::ios::binary);
        for (const auto& h : volume.handles()) {
            if (const auto* meta = h.gridMetaData(); meta && std::string(meta->shortGridName()) == riemesh::kIsoGrid) continue;
            nanovdb::io::writeGrid(out, h);
        }
        if (isoHandle) nanovdb::io::writeGrid(out, *isoHandle);
        out.close();
        if (!out) throw std::runtime_error("'" + path + "': write failed");
    });
}

} // namespace riemesh::vdb
