#include "riemesh/image.h"

#include "detail/nano_stencil.h"
#include "detail/nano_validate.h"
#include "detail/thread_accessor.h"

#include <nanovdb/util/IO.h> // the file layout: nanovdb::io::Header and MetaData
#include <nanovdb/util/SampleFromVoxels.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <sstream>
#include <stdexcept>

namespace riemesh {

double isoDistance(const ScalarImage& image, const Vec3& x, double iso, double minGradient)
{
    double value;
    Vec3 gradient;
    image.sample(x, value, gradient);
    return (value - iso) / std::max(gradient.norm(), minGradient);
}

Vec3 ScalarImage::gradient(const Vec3& x) const
{
    const double h = 0.5 * voxelSize();
    Vec3 g;
    for (int a = 0; a < 3; ++a) {
        Vec3 p = x, m = x;
        p[a] += h;
        m[a] -= h;
        g[a] = (value(p) - value(m)) / (2 * h);
    }
    return g;
}

FunctionImage::FunctionImage(std::function<double(const Vec3&)> f, Box3 bounds, double voxelSize,
                             std::function<Vec3(const Vec3&)> gradient)
    : mF(std::move(f)), mGradient(std::move(gradient)), mBounds(bounds), mVoxelSize(voxelSize)
{
    if (!mF) throw std::invalid_argument("FunctionImage: empty function");
    if (!(voxelSize > 0)) throw std::invalid_argument("FunctionImage: voxel size must be > 0");
}

Vec3 FunctionImage::gradient(const Vec3& x) const
{
    return mGradient ? mGradient(x) : ScalarImage::gradient(x);
}

DenseImage::DenseImage(int nx, int ny, int nz, std::vector<float> data, Vec3 origin, double voxelSize,
                       double background)
    : mN{nx, ny, nz}, mData(std::move(data)), mOrigin(origin), mVoxelSize(voxelSize), mBackground(background)
{
    if (nx < 2 || ny < 2 || nz < 2) throw std::invalid_argument("DenseImage: need at least 2 voxels per axis");
    if (mData.size() != std::size_t(nx) * ny * nz) throw std::invalid_argument("DenseImage: data size mismatch");
    if (!(voxelSize > 0)) throw std::invalid_argument("DenseImage: voxel size must be > 0");
}

double DenseImage::value(const Vec3& x) const
{
    const Vec3 p = (x - mOrigin) / mVoxelSize;
    const int i = int(std::floor(p.x())), j = int(std::floor(p.y())), k = int(std::floor(p.z()));
    const double fx = p.x() - i, fy = p.y() - j, fz = p.z() - k;
    auto v = [&](int a, int b, int c) -> double {
        if (a < 0 || b < 0 || c < 0 || a >= mN[0] || b >= mN[1] || c >= mN[2]) return mBackground;
        return at(a, b, c);
    };
    const double c00 = v(i, j, k) * (1 - fx) + v(i + 1, j, k) * fx;
    const double c10 = v(i, j + 1, k) * (1 - fx) + v(i + 1, j + 1, k) * fx;
    const double c01 = v(i, j, k + 1) * (1 - fx) + v(i + 1, j, k + 1) * fx;
    const double c11 = v(i, j + 1, k + 1) * (1 - fx) + v(i + 1, j + 1, k + 1) * fx;
    return (c00 * (1 - fy) + c10 * fy) * (1 - fz) + (c01 * (1 - fy) + c11 * fy) * fz;
}

Vec3 DenseImage::gradient(const Vec3& x) const { return ScalarImage::gradient(x); }

Box3 DenseImage::bounds() const
{
    return Box3(mOrigin, mOrigin + mVoxelSize * Vec3(mN[0] - 1, mN[1] - 1, mN[2] - 1));
}

NanoImage::NanoImage(const nanovdb::FloatGrid* grid)
    : mGrid(grid ? grid : throw std::invalid_argument("NanoImage: null grid")), mOwner(detail::newAccessorOwner())
{
    mVoxelSize = grid->voxelSize()[0];
    const auto bbox = grid->worldBBox();
    mBounds = Box3(Vec3(bbox.min()[0], bbox.min()[1], bbox.min()[2]),
                   Vec3(bbox.max()[0], bbox.max()[1], bbox.max()[2]));
}

NanoImage::~NanoImage() = default;

double NanoImage::value(const Vec3& x) const
{
    detail::Stencil<float> st;
    detail::fetchStencil(detail::threadAccessor<0>(mOwner, mGrid), mGrid->worldToIndex(nanovdb::Vec3d(x.x(), x.y(), x.z())), st);
    return detail::trilinear(st);
}

Vec3 NanoImage::gradient(const Vec3& x) const
{
    double value;
    Vec3 g;
    sample(x, value, g);
    return g;
}

void NanoImage::sample(const Vec3& x, double& value, Vec3& gradient) const
{
    // Value and gradient of the trilinear interpolant from one 2x2x2 fetch; the gradient is mapped
    // from index to world space by the grid's transform.
    detail::Stencil<float> st;
    detail::fetchStencil(detail::threadAccessor<0>(mOwner, mGrid), mGrid->worldToIndex(nanovdb::Vec3d(x.x(), x.y(), x.z())), st);
    value = detail::trilinear(st);
    const nanovdb::Vec3d w = mGrid->indexToWorldGrad(detail::trilinearGradient(st));
    gradient = Vec3(w[0], w[1], w[2]);
}

Vec3 NanoImage::indexGradient(const Vec3& x) const
{
    detail::Stencil<float> st;
    detail::fetchStencil(detail::threadAccessor<0>(mOwner, mGrid), mGrid->worldToIndex(nanovdb::Vec3d(x.x(), x.y(), x.z())), st);
    const nanovdb::Vec3d g = detail::trilinearGradient(st);
    return Vec3(g[0], g[1], g[2]);
}

// ---- NanoVolume -------------------------------------------------------------------------------

NanoVolume::NanoVolume() = default;
NanoVolume::NanoVolume(NanoVolume&&) noexcept = default;
NanoVolume& NanoVolume::operator=(NanoVolume&&) noexcept = default;
NanoVolume::~NanoVolume() = default;

static double gershgorinBound(const nanovdb::Vec3fGrid* diag, const nanovdb::Vec3fGrid* off)
{
    // Largest eigenvalue <= max over voxels of max row sum |g_ii| + sum_j |g_ij| (Gershgorin);
    // the diagonal and off-diagonal maxima are taken separately, which only loosens the bound.
    double maxDiag = 1.0, maxOff = 0.0;
    auto scan = [](const nanovdb::Vec3fGrid* grid, double& out, bool sum) {
        const auto& tree = grid->tree();
        const auto* leaf = tree.getFirstNode<0>();
        for (uint32_t n = 0; n < tree.nodeCount(0); ++n, ++leaf) {
            for (uint32_t i = 0; i < 512; ++i) {
                const nanovdb::Vec3f v = leaf->getValue(i);
                if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]))
                    throw std::runtime_error("nvdb: the metric grids hold non-finite (NaN or infinite) values");
                double m = sum ? 2.0 * std::max({std::abs(v[0]), std::abs(v[1]), std::abs(v[2])})
                               : std::max({double(v[0]), double(v[1]), double(v[2])});
                out = std::max(out, m);
            }
        }
    };
    scan(diag, maxDiag, false);
    scan(off, maxOff, true);
    // Constant regions may be stored as tiles, which the leaf scan misses: the root statistics (the
    // longest vector, when the writer computed them) bound every component of every value.
    maxDiag = std::max(maxDiag, double(diag->tree().root().maximum().length()));
    maxOff = std::max(maxOff, 2.0 * double(off->tree().root().maximum().length()));
    return maxDiag + maxOff;
}

void NanoVolume::index()
{
    mImage = mDiag = mOff = mIsoGrid = -1;
    mLevels.clear();
    std::vector<std::pair<int, int>> levels; // (level, handle)
    for (int i = 0; i < int(mHandles.size()); ++i) {
        const auto* meta = mHandles[i].gridMetaData();
        if (!meta) continue;
        const std::string name = meta->shortGridName();
        const std::string prefix = kLevelGridPrefix;
        if (name.compare(0, prefix.size(), prefix) == 0) {
            const std::string digits = name.substr(prefix.size());
            if (digits.empty() || digits.size() > 2 || digits.find_first_not_of("0123456789") != std::string::npos)
                throw std::runtime_error("nvdb: grid '" + name + "' is not a level (" + prefix + "1, 2, ...)");
            if (!mHandles[i].grid<float>()) throw std::runtime_error("nvdb: level grid '" + name + "' is not a float grid");
            levels.emplace_back(std::stoi(digits), i);
        } else if (name == kMetricDiagGrid) {
            if (!mHandles[i].grid<nanovdb::Vec3f>())
                throw std::runtime_error("nvdb: grid 'metric_diag' is not a Vec3f grid");
            mDiag = i;
        } else if (name == kMetricOffGrid) {
            if (!mHandles[i].grid<nanovdb::Vec3f>())
                throw std::runtime_error("nvdb: grid 'metric_off' is not a Vec3f grid");
            mOff = i;
        } else if (name == kIsoGrid) {
            const auto* grid = mHandles[i].grid<float>();
            if (!grid) throw std::runtime_error(std::string("nvdb: grid '") + kIsoGrid + "' is not a float grid");
            if (!std::isfinite(grid->tree().getValue(nanovdb::Coord(0))))
                throw std::runtime_error(std::string("nvdb: grid '") + kIsoGrid + "' holds no finite isovalue");
            mIsoGrid = i;
        } else if (mImage < 0 && mHandles[i].grid<float>()) {
            mImage = i;
        }
    }
    if (mImage < 0) throw std::runtime_error("nvdb: the file holds no float grid to segment");
    std::sort(levels.begin(), levels.end());
    for (std::size_t k = 0; k < levels.size(); ++k) {
        if (levels[k].first != int(k) + 1)
            throw std::runtime_error("nvdb: the level grids are not numbered 1, 2, ... without a gap");
        mLevels.push_back(levels[k].second);
    }
    if ((mDiag < 0) != (mOff < 0))
        throw std::runtime_error("nvdb: the metric needs both 'metric_diag' and 'metric_off' grids");
    mMuMax = (mDiag >= 0) ? gershgorinBound(metricDiag(), metricOff()) : 1.0;
}

NanoVolume NanoVolume::read(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error("cannot read NanoVDB file '" + path + "': cannot open it");
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) throw std::runtime_error("cannot read NanoVDB file '" + path + "': read error");
    try {
        return fromBytes(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
    } catch (const std::exception& e) {
        throw std::runtime_error("NanoVDB file '" + path + "': " + e.what());
    }
}

namespace {

/// The grids of a NanoVDB file image, parsed here rather than by nanovdb::io::readGrids: that
/// trusts the file's name and grid sizes (allocating whatever they say, reading a name up to a
/// NUL that may not be there). Here every size is checked against the bytes that remain before
/// anything is allocated, and each grid's offsets before it is used (detail/nano_validate.h).
/// Layout per segment: io::Header, gridCount x (io::MetaData, name), then the grids' bytes.
std::vector<nanovdb::GridHandle<nanovdb::HostBuffer>> parseNanoFile(const std::uint8_t* data, std::size_t size)
{
    std::vector<nanovdb::GridHandle<nanovdb::HostBuffer>> handles;
    std::size_t pos = 0;
    auto take = [&](void* out, std::size_t n, const char* what) {
        if (size - pos < n) throw std::runtime_error(std::string("truncated (") + what + ")");
        std::memcpy(out, data + pos, n);
        pos += n;
    };
    while (pos < size) {
        nanovdb::io::Header header;
        take(&header, sizeof(header), "segment header");
        if (header.magic != NANOVDB_MAGIC_NUMBER) throw std::runtime_error("not a NanoVDB file (bad magic number)");
        if (header.version.getMajor() != NANOVDB_MAJOR_VERSION_NUMBER)
            // Not version.c_str(): NanoVDB returns a malloc'd string the caller must free.
            throw std::runtime_error("NanoVDB major version " + std::to_string(header.version.getMajor()) +
                                     " is not supported (expected " + std::to_string(NANOVDB_MAJOR_VERSION_NUMBER) + ")");
        if (header.codec != nanovdb::io::Codec::NONE)
            throw std::runtime_error("compressed NanoVDB files are not supported (riemesh writes them uncompressed)");
        if (header.gridCount == 0) throw std::runtime_error("a segment holds no grid");
        std::vector<nanovdb::io::MetaData> metas(header.gridCount);
        for (auto& meta : metas) {
            take(&meta, sizeof(meta), "grid metadata");
            if (meta.nameSize > size - pos) throw std::runtime_error("truncated (grid name)");
            pos += meta.nameSize; // the name is read from the grid itself
        }
        for (const auto& meta : metas) {
            if (meta.fileSize != meta.gridSize) throw std::runtime_error("grid size and stored size differ");
            if (meta.gridSize > size - pos) throw std::runtime_error("truncated (grid data)");
            auto buffer = nanovdb::HostBuffer::create(meta.gridSize);
            std::memcpy(buffer.data(), data + pos, meta.gridSize);
            pos += meta.gridSize;
            const auto* bytes = static_cast<const std::uint8_t*>(buffer.data());
            std::string problem = detail::nanoHeaderProblem(bytes, meta.gridSize);
            if (problem.empty()) {
                // Only the float and Vec3f grids are ever traversed; others are skipped by index().
                const auto type = reinterpret_cast<const nanovdb::GridData*>(bytes)->mGridType;
                if (type == nanovdb::GridType::Float) problem = detail::nanoTreeProblem<float>(bytes, meta.gridSize);
                else if (type == nanovdb::GridType::Vec3f)
                    problem = detail::nanoTreeProblem<nanovdb::Vec3f>(bytes, meta.gridSize);
            }
            if (!problem.empty())
                throw std::runtime_error("corrupt grid " + std::to_string(handles.size()) + ": " + problem);
            handles.emplace_back(std::move(buffer));
        }
    }
    return handles;
}

} // namespace

NanoVolume NanoVolume::fromBytes(const std::uint8_t* data, std::size_t size)
{
    NanoVolume volume;
    if (size == 0) throw std::runtime_error("NanoVDB data is empty");
    volume.mHandles = parseNanoFile(data, size);
    if (volume.mHandles.empty()) throw std::runtime_error("NanoVDB data holds no grid");
    volume.index();
    return volume;
}

NanoVolume NanoVolume::fromHandles(std::vector<nanovdb::GridHandle<nanovdb::HostBuffer>>&& handles)
{
    NanoVolume volume;
    volume.mHandles = std::move(handles);
    if (volume.mHandles.empty()) throw std::runtime_error("NanoVolume: no grid");
    volume.index();
    return volume;
}

double NanoVolume::iso() const
{
    if (mIsoGrid < 0) throw std::logic_error("NanoVolume::iso: the volume stores no isovalue");
    return mHandles[mIsoGrid].grid<float>()->tree().getValue(nanovdb::Coord(0));
}

const nanovdb::FloatGrid* NanoVolume::imageGrid() const
{
    return mImage >= 0 ? mHandles[mImage].grid<float>() : nullptr;
}
const nanovdb::FloatGrid* NanoVolume::levelGrid(int level) const
{
    return level >= 1 && level <= int(mLevels.size()) ? mHandles[mLevels[level - 1]].grid<float>() : nullptr;
}
const nanovdb::Vec3fGrid* NanoVolume::metricDiag() const
{
    return mDiag >= 0 ? mHandles[mDiag].grid<nanovdb::Vec3f>() : nullptr;
}
const nanovdb::Vec3fGrid* NanoVolume::metricOff() const
{
    return mOff >= 0 ? mHandles[mOff].grid<nanovdb::Vec3f>() : nullptr;
}
std::string NanoVolume::imageName() const
{
    return mImage >= 0 ? std::string(mHandles[mImage].gridMetaData()->shortGridName()) : std::string();
}
std::string NanoVolume::imageClass() const
{
    if (mImage < 0) return "unknown";
    switch (mHandles[mImage].gridMetaData()->gridClass()) {
    case nanovdb::GridClass::FogVolume: return "fog";
    case nanovdb::GridClass::LevelSet: return "levelset";
    default: return "unknown";
    }
}

} // namespace riemesh
