// The converter's pipeline behind an OpenVDB-free interface (volume.h).
#include "riemesh/vdb/volume.h"

#include "riemesh/vdb/io.h"
#include "riemesh/vdb/level_set.h"
#include "riemesh/vdb/metric_grid.h"
#include "riemesh/vdb/nano.h"
#include "riemesh/vdb/nifti.h"
#include "riemesh/vdb/phantom.h"
#include "riemesh/vdb/structure_tensor.h"

#include <nanovdb/util/NanoToOpenVDB.h>

#include <tbb/global_control.h>
#include <tbb/info.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <random>
#include <stdexcept>
#include <unistd.h>

namespace fs = std::filesystem;

namespace riemesh::vdb {

std::string fileExtension(const std::string& path)
{
    std::string name = fs::path(path).filename().string();
    std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return std::tolower(c); });
    if (name.size() > 7 && name.compare(name.size() - 7, 7, ".nii.gz") == 0) return ".nii.gz";
    const auto dot = name.rfind('.');
    return (dot == std::string::npos || dot == 0) ? std::string() : name.substr(dot);
}

void writeFileAtomically(const std::string& path, const std::function<void(const std::string&)>& write)
{
    const fs::path target(path);
    const fs::path dir = target.has_parent_path() ? target.parent_path() : fs::path(".");
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) throw std::runtime_error("'" + path + "': output folder '" + dir.string() + "' does not exist");
    std::random_device rd;
    const fs::path temp = dir / ("." + target.filename().string() + ".tmp" + std::to_string(::getpid()) + "-" +
                                 std::to_string(rd() & 0xffffff) + fs::path(path).extension().string());
    try {
        write(temp.string());
        if (!fs::exists(temp, ec) || fs::file_size(temp, ec) == 0)
            throw std::runtime_error("'" + path + "': writing produced no data");
        fs::rename(temp, target); // atomic on POSIX within one file system
    } catch (...) {
        fs::remove(temp, ec);
        throw;
    }
}

std::shared_ptr<void> limitThreads(int threads)
{
    if (threads <= 0) return nullptr;
    return std::make_shared<tbb::global_control>(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
}

struct Volume::Impl {
    ImageInfo info;
    openvdb::FloatGrid::Ptr image;
    openvdb::Vec3fGrid::Ptr diag, off;
    double muMax = 1.0;
    FloatGrids levels; ///< coarse images for the schedule, level 1 first
    std::vector<Box3> objectBoxes; ///< see Volume::objectBoxes()
    /// After releaseToNano(): the grids in NanoVDB form; `image` is then an empty grid that keeps the
    /// transform, name and class, and diag, off and levels are gone.
    std::shared_ptr<const NanoVolume> released;
    void checkVoxels(const char* what) const
    {
        if (released) throw std::logic_error(std::string("Volume::") + what + ": the voxels were released to NanoVDB");
    }
};

Volume::Volume() : mImpl(std::make_unique<Impl>()) {}
Volume::~Volume() = default;
Volume::Volume(Volume&&) noexcept = default;
Volume& Volume::operator=(Volume&&) noexcept = default;

const ImageInfo& Volume::info() const { return mImpl->info; }

namespace {

void describe(ImageInfo& info, const openvdb::FloatGrid& grid)
{
    info.gridName = grid.getName();
    info.gridClass = gridClassName(grid);
    const auto vs = grid.transform().voxelSize();
    info.voxelSize = std::max({vs[0], vs[1], vs[2]});
    const auto box = grid.evalActiveVoxelBoundingBox();
    info.dims[0] = box.dim().x();
    info.dims[1] = box.dim().y();
    info.dims[2] = box.dim().z();
    info.activeVoxels = grid.activeVoxelCount();
    const auto wb = grid.transform().indexToWorld(box);
    info.worldBounds = Box3(Vec3(wb.min().x(), wb.min().y(), wb.min().z()), Vec3(wb.max().x(), wb.max().y(), wb.max().z()));
    const ValueStats values = valueStats(grid);
    info.minValue = values.min;
    info.maxValue = values.max;
}

} // namespace

std::uint64_t defaultMemoryBudget()
{
    const long pages = ::sysconf(_SC_PHYS_PAGES), pageSize = ::sysconf(_SC_PAGE_SIZE);
    if (pages <= 0 || pageSize <= 0) return std::uint64_t(4) << 30; // unknown: 4 GB
    return std::uint64_t(pages) * std::uint64_t(pageSize) / 2;
}

Volume Volume::read(const std::string& path, const std::string& gridName, std::uint64_t memoryBudget)
{
    if (memoryBudget == 0) memoryBudget = defaultMemoryBudget();
    Volume v;
    auto& I = *v.mImpl;
    I.info.path = path;
    const std::string ext = fileExtension(path);
    if (ext == ".vdb") {
        I.info.format = "vdb";
        I.image = readVdbImage(path, gridName, memoryBudget);
        I.info.transformNote = "grid transform";
    } else if (ext == ".nvdb") {
        I.info.format = "nvdb";
        auto grids = readNanoFile(path, gridName, memoryBudget);
        I.image = grids.image;
        I.diag = grids.metricDiag;
        I.off = grids.metricOff;
        I.muMax = grids.muMax;
        I.info.transformNote = "grid transform";
    } else if (ext == ".nii" || ext == ".nii.gz") {
        I.info.format = "nifti";
        if (!gridName.empty()) throw std::runtime_error("'" + path + "': --grid does not apply to NIfTI files");
        NiftiHeaderInfo h;
        I.image = readNifti(path, &h, memoryBudget);
        I.info.transformNote = "NIfTI scanner space (RAS, mm) from the " + h.transformSource;
    } else {
        throw std::runtime_error("'" + path + "': unknown input extension '" + ext +
                                 "' (expected .vdb, .nvdb, .nii or .nii.gz)");
    }
    describe(I.info, *I.image);
    const auto b = I.info.worldBounds;
    if (I.info.dims[0] < 2 || I.info.dims[1] < 2 || I.info.dims[2] < 2)
        throw std::runtime_error("'" + path + "': grid '" + I.info.gridName + "' is flat (" +
                                 std::to_string(I.info.dims[0]) + "x" + std::to_string(I.info.dims[1]) + "x" +
                                 std::to_string(I.info.dims[2]) + " voxels); need a 3D block");
    (void)b;
    return v;
}

std::uint64_t Volume::closeBorders(double iso, bool objectBrighter)
{
    mImpl->checkVoxels("closeBorders");
    auto& grid = *mImpl->image;
    const openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
    if (box.empty()) return 0;
    const auto inside = [&](float v) { return objectBrighter ? v > iso : v < iso; };
    std::uint64_t added = 0;
    // All six slices are read before any padding is written, so the pads do not see each other.
    struct Pad {
        openvdb::Coord ijk;
        float value;
    };
    std::vector<Pad> pads;
    // Sparse: on each face, only the rectangle of the leaf nodes that touch it. Where a face lies in
    // constant tiles there is nothing to close: a tile has no holes, and the image drops to its
    // background just beyond the box, which closes the surface there.
    std::array<openvdb::CoordBBox, 6> touched; // per face: axis * 2 + side
    for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) {
        openvdb::CoordBBox b = leaf->getNodeBoundingBox();
        b.intersect(box);
        if (b.empty()) continue;
        for (int axis = 0; axis < 3; ++axis) {
            if (b.min()[axis] == box.min()[axis]) touched[2 * axis].expand(b);
            if (b.max()[axis] == box.max()[axis]) touched[2 * axis + 1].expand(b);
        }
    }
    for (int axis = 0; axis < 3; ++axis) {
        const int ua = (axis + 1) % 3, va = (axis + 2) % 3;
        for (int side = 0; side < 2; ++side) {
            const openvdb::CoordBBox& face = touched[2 * axis + side];
            if (face.empty()) continue;
            const int u0 = face.min()[ua], v0 = face.min()[va];
            const int nu = face.dim()[ua], nv = face.dim()[va];
            const int c = side ? box.max()[axis] : box.min()[axis];
            const auto at = [&](int u, int v) {
                openvdb::Coord ijk;
                ijk[axis] = c;
                ijk[ua] = u0 + u;
                ijk[va] = v0 + v;
                return ijk;
            };
            auto acc = grid.getConstAccessor();
            std::vector<float> value(std::size_t(nu) * nv);
            std::vector<char> in(value.size());
            double insideSum = 0;
            std::size_t insideCount = 0;
            for (int v = 0; v < nv; ++v)
                for (int u = 0; u < nu; ++u) {
                    const std::size_t k = std::size_t(v) * nu + u;
                    value[k] = acc.getValue(at(u, v));
                    in[k] = inside(value[k]);
                    if (in[k]) {
                        insideSum += value[k];
                        ++insideCount;
                    }
                }
            if (insideCount == 0) continue;
            // Outside of the footprint: what a 4-connected flood from the slice's rim reaches
            // through non-object pixels; everything else (object and enclosed holes) is footprint.
            std::vector<char> reached(value.size(), 0);
            std::vector<std::size_t> stack;
            const auto seed = [&](int u, int v) {
                const std::size_t k = std::size_t(v) * nu + u;
                if (!in[k] && !reached[k]) {
                    reached[k] = 1;
                    stack.push_back(k);
                }
            };
            for (int u = 0; u < nu; ++u) {
                seed(u, 0);
                seed(u, nv - 1);
            }
            for (int v = 0; v < nv; ++v) {
                seed(0, v);
                seed(nu - 1, v);
            }
            while (!stack.empty()) {
                const std::size_t k = stack.back();
                stack.pop_back();
                const int u = int(k % nu), v = int(k / nu);
                if (u > 0) seed(u - 1, v);
                if (u + 1 < nu) seed(u + 1, v);
                if (v > 0) seed(u, v - 1);
                if (v + 1 < nv) seed(u, v + 1);
            }
            const float fill = float(insideSum / double(insideCount));
            for (int v = 0; v < nv; ++v)
                for (int u = 0; u < nu; ++u) {
                    const std::size_t k = std::size_t(v) * nu + u;
                    if (reached[k]) continue;
                    // Two layers: the initial box (inset by one voxel from the image box) then
                    // starts on the cap, not on the cut slice where it would fall into its holes.
                    for (int layer = 1; layer <= 2; ++layer) {
                        openvdb::Coord ijk = at(u, v);
                        ijk[axis] += side ? layer : -layer;
                        pads.push_back({ijk, in[k] ? value[k] : fill});
                    }
                }
        }
    }
    auto acc = grid.getAccessor();
    for (const Pad& p : pads) {
        if (acc.isValueOn(p.ijk)) continue; // an edge voxel two faces both pad: keep the first
        acc.setValueOn(p.ijk, p.value);
        ++added;
    }
    return added;
}

void Volume::smooth(double sigmaVoxels)
{
    mImpl->checkVoxels("smooth");
    if (sigmaVoxels <= 0) return;
    mImpl->image = gaussianSmooth(*mImpl->image, sigmaVoxels);
    mImpl->levels.clear();
    mImpl->objectBoxes.clear();
}

int Volume::buildLevels(int levels, bool objectBrighter, double iso, double minObjectCells)
{
    mImpl->checkVoxels("buildLevels");
    std::vector<openvdb::BBoxd> boxes;
    mImpl->levels = coarseLevels(*mImpl->image, levels, objectBrighter, iso, minObjectCells, std::isfinite(iso) ? &boxes : nullptr);
    mImpl->objectBoxes.clear();
    for (const openvdb::BBoxd& b : boxes)
        mImpl->objectBoxes.emplace_back(Vec3(b.min().x(), b.min().y(), b.min().z()), Vec3(b.max().x(), b.max().y(), b.max().z()));
    return int(mImpl->levels.size());
}

int Volume::levelCount() const { return int(mImpl->levels.size()); }

const std::vector<Box3>& Volume::objectBoxes() const { return mImpl->objectBoxes; }

VolumeMetricStats Volume::computeMetric(const VolumeMetricOptions& options)
{
    mImpl->checkVoxels("computeMetric");
    const auto start = std::chrono::steady_clock::now();
    StructureTensorOptions t;
    t.sigma = options.sigma;
    t.rho = options.rho;
    MetricOptions m;
    m.muMax = options.muMax;
    m.tangentialGain = options.tangentialGain;
    auto grids = riemesh::vdb::computeMetric(*mImpl->image, t, m);
    mImpl->diag = grids.diag;
    mImpl->off = grids.off;
    mImpl->muMax = grids.muMax;
    VolumeMetricStats s;
    s.activeVoxels = grids.activeVoxels;
    s.totalVoxels = grids.totalVoxels;
    s.xiRef = grids.xiRef;
    s.threshold = grids.threshold;
    s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return s;
}

bool Volume::hasMetric() const { return mImpl->released ? mImpl->released->metricDiag() != nullptr : bool(mImpl->diag); }
double Volume::metricMaxEigenvalue() const { return mImpl->muMax; }

NanoVolume Volume::nano() const
{
    mImpl->checkVoxels("nano");
    return toNanoVolume(*mImpl->image, mImpl->diag.get(), mImpl->off.get(), mImpl->levels);
}

std::shared_ptr<const NanoVolume> Volume::releaseToNano()
{
    auto& I = *mImpl;
    if (I.released) return I.released;
    std::vector<nanovdb::GridHandle<nanovdb::HostBuffer>> handles;
    handles.push_back(toNano(*I.image));
    I.image = I.image->copyWithNewTree(); // the transform, name, class and metadata, no voxels
    if (I.diag && I.off) {
        handles.push_back(toNano(*I.diag));
        I.diag.reset();
        handles.push_back(toNano(*I.off));
        I.off.reset();
    }
    for (auto& level : I.levels) {
        handles.push_back(toNano(*level));
        level.reset();
    }
    I.levels.clear();
    I.released = std::make_shared<const NanoVolume>(NanoVolume::fromHandles(std::move(handles)));
    return I.released;
}

void Volume::writeMetric(const std::string& path) const
{
    if (!hasMetric()) throw std::runtime_error("no metric to write");
    if (const auto& nano = mImpl->released) {
        openvdb::Vec3fGrid::Ptr diag = nanovdb::nanoToOpenVDB(*nano->metricDiag());
        openvdb::Vec3fGrid::Ptr off = nanovdb::nanoToOpenVDB(*nano->metricOff());
        diag->setName(kMetricDiagGrid);
        off->setName(kMetricOffGrid);
        for (auto* g : {&diag, &off}) {
            (*g)->insertMeta(kMuMaxMetadata, openvdb::DoubleMetadata(mImpl->muMax));
            (*g)->setVectorType(openvdb::VEC_INVARIANT);
        }
        writeVdb(path, {diag, off});
        return;
    }
    writeVdb(path, {mImpl->diag, mImpl->off});
}

void Volume::exportNanoVDB(const std::string& path, double iso) const
{
    if (const auto& nano = mImpl->released) {
        writeNvdb(path, *nano, iso);
        return;
    }
    writeNvdb(path, *mImpl->image, mImpl->diag.get(), mImpl->off.get(), iso, mImpl->levels);
}

void Volume::downsample(int factor)
{
    mImpl->checkVoxels("downsample");
    if (factor < 1) throw std::invalid_argument("downsample: factor must be >= 1");
    if (factor == 1) return;
    const auto& in = *mImpl->image;
    const openvdb::CoordBBox box = in.evalActiveVoxelBoundingBox();
    auto out = openvdb::FloatGrid::create(in.background());
    out->setName(in.getName());
    out->setGridClass(in.getGridClass());
    // Output voxel c covers input voxels box.min + f*c + [0, f)^3; its centre is at f*c + (f-1)/2 in
    // the input's index space (relative to box.min).
    auto xform = in.transform().copy();
    xform->preTranslate(openvdb::Vec3d(box.min().asVec3d()) + openvdb::Vec3d(0.5 * (factor - 1)));
    xform->preScale(double(factor));
    out->setTransform(xform);
    // Sparse: the active voxels of leaf nodes add to their block's sum and count; constant tiles fill
    // the blocks they cover whole (a block a tile covers only in part averages its leaf voxels).
    const auto block = [&](const openvdb::Coord& ijk) {
        const openvdb::Coord r = ijk - box.min();
        return openvdb::Coord(r.x() / factor, r.y() / factor, r.z() / factor);
    };
    {
        auto tile = in.tree().cbeginValueOn();
        tile.setMaxDepth(openvdb::FloatTree::DEPTH - 2);
        for (; tile; ++tile) {
            openvdb::CoordBBox t;
            tile.getBoundingBox(t);
            t.intersect(box);
            if (t.empty()) continue;
            const openvdb::Coord lo = block(t.min().offsetBy(factor - 1)), hi = block(t.max().offsetBy(1)).offsetBy(-1);
            if (lo.x() <= hi.x() && lo.y() <= hi.y() && lo.z() <= hi.z())
                out->tree().fill(openvdb::CoordBBox(lo, hi), *tile, true);
        }
    }
    openvdb::DoubleGrid sums(0.0);
    openvdb::Int32Grid counts(0);
    {
        auto sum = sums.getAccessor();
        auto count = counts.getAccessor();
        for (auto leaf = in.tree().cbeginLeaf(); leaf; ++leaf)
            for (auto it = leaf->cbeginValueOn(); it; ++it) {
                const openvdb::Coord b = block(it.getCoord());
                sum.setValue(b, sum.getValue(b) + double(*it));
                count.setValue(b, count.getValue(b) + 1);
            }
    }
    auto dst = out->getAccessor();
    auto sum = sums.getConstAccessor();
    for (auto it = counts.cbeginValueOn(); it; ++it) dst.setValue(it.getCoord(), float(sum.getValue(it.getCoord()) / *it));
    mImpl->image = out;
    mImpl->diag.reset();
    mImpl->off.reset();
    mImpl->muMax = 1.0;
    mImpl->levels.clear();
    mImpl->objectBoxes.clear();
    describe(mImpl->info, *out);
}

void Volume::writeSurfaceLevelSet(const std::string& path, const Mesh& mesh) const
{
    auto grid = meshToSurfaceLevelSet(mesh, mImpl->image->transform());
    writeVdb(path, {grid});
}

void writePhantom(const std::string& shape, const std::string& path, int size, double noise, std::uint64_t seed)
{
    const PhantomShape s = phantomShapeFromName(shape);
    PhantomOptions o;
    o.size = size;
    o.noise = noise;
    o.seed = seed;
    const Phantom p = makePhantom(s, o);
    writeVdb(path, {p.density, p.sdf});
}

std::vector<std::string> phantomShapes() { return phantomShapeNames(); }

ReferenceError compareToReference(const Mesh& mesh, const std::string& path, const std::string& gridName)
{
    auto sdf = readVdbImage(path, gridName);
    const ReferenceDistance exact = phantomReferenceDistance(*sdf);
    const auto e = surfaceError(mesh, *sdf, exact);
    ReferenceError r;
    r.meanMeshToSurface = e.meanMeshToSurface;
    r.maxMeshToSurface = e.maxMeshToSurface;
    r.meanSurfaceToMesh = e.meanSurfaceToMesh;
    r.maxSurfaceToMesh = e.maxSurfaceToMesh;
    r.hausdorff = e.hausdorff;
    for (int k = 0; k < 3; ++k) r.hausdorffAt[k] = e.hausdorffAt[k];
    r.hausdorffOnMesh = e.hausdorffOnMesh;
    r.analytic = bool(exact);
    r.voxelSize = sdf->transform().voxelSize()[0];
    return r;
}

} // namespace riemesh::vdb

// ---- Additions for in-memory sources (volume_grids.h, volume_sources.h) ----------------------------

#include "riemesh/vdb/volume_grids.h"

#include <cmath>

namespace riemesh::vdb {

Volume Volume::copy() const
{
    mImpl->checkVoxels("copy");
    Volume v;
    *v.mImpl = *mImpl;
    if (mImpl->image) v.mImpl->image = mImpl->image->deepCopy();
    if (mImpl->diag) v.mImpl->diag = mImpl->diag->deepCopy();
    if (mImpl->off) v.mImpl->off = mImpl->off->deepCopy();
    return v;
}

Volume Volume::placement() const
{
    Volume v;
    v.mImpl->info = mImpl->info;
    if (mImpl->image) v.mImpl->image = mImpl->image->copyWithNewTree();
    return v;
}

Volume VolumeGrids::fromImage(openvdb::FloatGrid::Ptr image, const std::string& format, const std::string& transformNote)
{
    if (!image) throw std::invalid_argument("no grid");
    const std::string name = "grid '" + image->getName() + "'";
    if (image->activeVoxelCount() == 0) throw std::invalid_argument(name + " is empty (no active voxels)");
    if (const auto bad = countNonFinite(*image))
        throw std::invalid_argument(name + " has " + std::to_string(bad) + " non-finite (NaN or infinite) voxel values");
    if (!std::isfinite(image->background())) throw std::invalid_argument(name + " has a non-finite background value");
    if (!image->transform().isLinear()) throw std::invalid_argument(name + " has a non-linear (frustum) transform");
    Volume v;
    auto& I = *v.mImpl;
    I.info.format = format;
    I.info.transformNote = transformNote;
    I.image = std::move(image);
    describe(I.info, *I.image);
    if (I.info.dims[0] < 2 || I.info.dims[1] < 2 || I.info.dims[2] < 2)
        throw std::invalid_argument(name + " is flat (" + std::to_string(I.info.dims[0]) + "x" +
                                    std::to_string(I.info.dims[1]) + "x" + std::to_string(I.info.dims[2]) +
                                    " voxels); need a 3D block");
    return v;
}

openvdb::FloatGrid::ConstPtr VolumeGrids::image(const Volume& volume) { return volume.mImpl->image; }

} // namespace riemesh::vdb
