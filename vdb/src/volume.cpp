// The converter's pipeline behind an OpenVDB-free interface (volume.h).
#include "riemesh/vdb/volume.h"

#include "riemesh/vdb/io.h"
#include "riemesh/vdb/level_set.h"
#include "riemesh/vdb/metric_grid.h"
#include "riemesh/vdb/nano.h"
#include "riemesh/vdb/nifti.h"
#include "riemesh/vdb/phantom.h"
#include "riemesh/vdb/structure_tensor.h"

#include <tbb/global_control.h>
#include <tbb/info.h>

#include <algorithm>
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
    float lo = std::numeric_limits<float>::max(), hi = -lo;
    for (auto it = grid.tree().cbeginValueOn(); it; ++it) {
        lo = std::min(lo, *it);
        hi = std::max(hi, *it);
    }
    info.minValue = lo;
    info.maxValue = hi;
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

void Volume::smooth(double sigmaVoxels)
{
    if (sigmaVoxels <= 0) return;
    mImpl->image = gaussianSmooth(*mImpl->image, sigmaVoxels);
}

VolumeMetricStats Volume::computeMetric(const VolumeMetricOptions& options)
{
    const auto start = std::chrono::steady_clock::now();
    StructureTensorOptions t;
    t.sigma = options.sigma;
    t.rho = options.rho;
    MetricOptions m;
    m.muMax = options.muMax;
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

bool Volume::hasMetric() const { return bool(mImpl->diag); }
double Volume::metricMaxEigenvalue() const { return mImpl->muMax; }

NanoVolume Volume::nano() const
{
    return toNanoVolume(*mImpl->image, mImpl->diag.get(), mImpl->off.get());
}

void Volume::writeMetric(const std::string& path) const
{
    if (!hasMetric()) throw std::runtime_error("no metric to write");
    writeVdb(path, {mImpl->diag, mImpl->off});
}

void Volume::exportNanoVDB(const std::string& path) const
{
    writeNvdb(path, *mImpl->image, mImpl->diag.get(), mImpl->off.get());
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
    const auto e = surfaceError(mesh, *sdf);
    ReferenceError r;
    r.mean = e.meanVertexDistance;
    r.maxVertex = e.maxVertexDistance;
    r.maxSurface = e.maxSurfaceDistance;
    r.hausdorff = e.hausdorff;
    r.voxelSize = sdf->transform().voxelSize()[0];
    return r;
}

} // namespace riemesh::vdb
