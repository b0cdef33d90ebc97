// NIfTI-1/2 reading through nifticlib (nifti.h).
#include "riemesh/vdb/nifti.h"

#include "riemesh/vdb/io.h"
#include "dense.h"

#include <nifti2_io.h>

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <vector>

namespace riemesh::vdb {

bool isNiftiPath(const std::string& path)
{
    std::string p = path;
    std::transform(p.begin(), p.end(), p.begin(), [](unsigned char c) { return std::tolower(c); });
    auto endsWith = [&](const std::string& s) { return p.size() >= s.size() && p.compare(p.size() - s.size(), s.size(), s) == 0; };
    return endsWith(".nii") || endsWith(".nii.gz");
}

namespace {

/// Silences stderr (fd 2) while it lives: nifticlib prints its own "** ERROR" lines whatever the
/// debug level, and a bad file must give the user one line, ours. Only the reading thread runs then.
class QuietStderr {
public:
    QuietStderr()
    {
        std::fflush(stderr);
        mSaved = ::dup(STDERR_FILENO);
        const int null = ::open("/dev/null", O_WRONLY);
        if (mSaved >= 0 && null >= 0) ::dup2(null, STDERR_FILENO);
        if (null >= 0) ::close(null);
    }
    ~QuietStderr()
    {
        std::fflush(stderr);
        if (mSaved >= 0) {
            ::dup2(mSaved, STDERR_FILENO);
            ::close(mSaved);
        }
    }
    QuietStderr(const QuietStderr&) = delete;
    QuietStderr& operator=(const QuietStderr&) = delete;
private:
    int mSaved = -1;
};

/// Non-finite values among the float voxels as stored in the file. nifticlib's loader silently
/// replaces them by 0, which would mesh a hole as background; we refuse the file instead.
std::uint64_t countNonFiniteStored(const nifti_image& nim)
{
    if (nim.datatype != NIFTI_TYPE_FLOAT32 && nim.datatype != NIFTI_TYPE_FLOAT64) return 0;
    znzFile fp = znzopen(nim.iname, "rb", nifti_is_gzfile(nim.iname));
    if (znz_isnull(fp)) return 0; // the load that follows reports the problem
    std::uint64_t bad = 0;
    if (znzseek(fp, long(nim.iname_offset), SEEK_SET) == 0) {
        const bool swap = nim.byteorder != nifti_short_order();
        std::vector<unsigned char> chunk(std::size_t(1) << 20);
        std::uint64_t left = std::uint64_t(nim.nvox) * std::uint64_t(nim.nbyper);
        while (left > 0) {
            const std::size_t want = std::size_t(std::min<std::uint64_t>(left, chunk.size()));
            const std::size_t got = znzread(chunk.data(), 1, want, fp);
            const std::size_t n = got / std::size_t(nim.nbyper);
            for (std::size_t i = 0; i < n; ++i) {
                unsigned char* v = chunk.data() + i * std::size_t(nim.nbyper);
                if (swap) std::reverse(v, v + nim.nbyper);
                if (nim.nbyper == 4) {
                    float f;
                    std::memcpy(&f, v, 4);
                    bad += !std::isfinite(f);
                } else {
                    double d;
                    std::memcpy(&d, v, 8);
                    bad += !std::isfinite(d);
                }
            }
            if (got < want) break; // short file: the load reports it
            left -= got;
        }
    }
    znzclose(fp);
    return bad;
}

template<typename T>
void convert(const void* raw, std::size_t n, double slope, double inter, std::vector<float>& out)
{
    const T* in = static_cast<const T*>(raw);
    for (std::size_t i = 0; i < n; ++i) out[i] = float(double(in[i]) * slope + inter);
}

} // namespace

openvdb::FloatGrid::Ptr readNifti(const std::string& path, NiftiHeaderInfo* info, std::uint64_t memoryBudget)
{
    initialize();
    auto fail = [&](const std::string& what) { return std::runtime_error("'" + path + "': " + what); };
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw fail("no such file");
    if (std::filesystem::file_size(path, ec) == 0 || ec) throw fail("file is empty");

    nifti_set_debug_level(0);
    std::unique_ptr<nifti_image, void (*)(nifti_image*)> nim(nullptr, nifti_image_free);
    {
        QuietStderr quiet;
        nim.reset(nifti_image_read(path.c_str(), /*read_data=*/0));
    }
    if (!nim) throw fail("not a readable NIfTI file (bad or missing header)");
    if (nim->nx < 2 || nim->ny < 2 || nim->nz < 2) throw fail("NIfTI image is not 3D (need at least 2 voxels along i, j and k)");
    // Everything the header claims is checked before a voxel is read: nifti_image_load allocates
    // what the header says, so a lying or merely huge header must stop here, not in an OOM kill.
    checkMemoryBudget(path, {nim->nx, nim->ny, nim->nz}, memoryBudget);
    constexpr std::int64_t kMaxAxis = std::int64_t(1) << 30; // OpenVDB coordinates are 32-bit
    if (nim->nx > kMaxAxis || nim->ny > kMaxAxis || nim->nz > kMaxAxis)
        throw fail("NIfTI image of " + std::to_string(nim->nx) + "x" + std::to_string(nim->ny) + "x" +
                   std::to_string(nim->nz) + " voxels is too large");
    const unsigned __int128 boxVoxels = (unsigned __int128)nim->nx * nim->ny * nim->nz;
    if (nim->nvox <= 0 || (unsigned __int128)nim->nvox != boxVoxels) {
        const double volumes = double(nim->nvox) / (double(nim->nx) * double(nim->ny) * double(nim->nz));
        throw fail("NIfTI file holds " + std::to_string(volumes) + " volumes; expected a single 3D volume");
    }
    switch (nim->datatype) {
    case NIFTI_TYPE_UINT8: case NIFTI_TYPE_INT8: case NIFTI_TYPE_INT16: case NIFTI_TYPE_UINT16:
    case NIFTI_TYPE_INT32: case NIFTI_TYPE_UINT32: case NIFTI_TYPE_INT64: case NIFTI_TYPE_UINT64:
    case NIFTI_TYPE_FLOAT32: case NIFTI_TYPE_FLOAT64: break;
    default:
        throw fail(std::string("unsupported NIfTI datatype ") + nifti_datatype_string(nim->datatype) +
                   " (need an integer or float scalar type)");
    }
    if (!nifti_is_gzfile(nim->iname)) {
        // Uncompressed: the file must hold the bytes the header declares (a gzip stream's length
        // is only known by decompressing it; nifticlib then reports a short read).
        const std::uint64_t declared = std::uint64_t(nim->nvox) * std::uint64_t(nim->nbyper);
        const std::uintmax_t size = std::filesystem::file_size(nim->iname, ec);
        if (ec || nim->iname_offset < 0 || size < std::uint64_t(nim->iname_offset) ||
            size - std::uint64_t(nim->iname_offset) < declared)
            throw fail("truncated NIfTI file (the header declares " + std::to_string(declared) +
                       " bytes of voxel data, the file holds " + std::to_string(size) + " bytes in all)");
    }
    if (const auto bad = countNonFiniteStored(*nim))
        throw fail("NIfTI image has " + std::to_string(bad) + " non-finite (NaN or infinite) voxel values");
    int loaded;
    {
        QuietStderr quiet;
        loaded = nifti_image_load(nim.get());
    }
    if (loaded != 0 || !nim->data) throw fail("truncated NIfTI file (cannot read the voxel data)");

    const double slope = (nim->scl_slope != 0 && std::isfinite(nim->scl_slope)) ? nim->scl_slope : 1.0;
    const double inter = (nim->scl_slope != 0 && std::isfinite(nim->scl_inter)) ? nim->scl_inter : 0.0;
    const std::size_t n = std::size_t(nim->nx) * nim->ny * nim->nz;
    std::vector<float> values(n);
    switch (nim->datatype) {
    case NIFTI_TYPE_UINT8: convert<std::uint8_t>(nim->data, n, slope, inter, values); break;
    case NIFTI_TYPE_INT8: convert<std::int8_t>(nim->data, n, slope, inter, values); break;
    case NIFTI_TYPE_INT16: convert<std::int16_t>(nim->data, n, slope, inter, values); break;
    case NIFTI_TYPE_UINT16: convert<std::uint16_t>(nim->data, n, slope, inter, values); break;
    case NIFTI_TYPE_INT32: convert<std::int32_t>(nim->data, n, slope, inter, values); break;
    case NIFTI_TYPE_UINT32: convert<std::uint32_t>(nim->data, n, slope, inter, values); break;
    case NIFTI_TYPE_INT64: convert<std::int64_t>(nim->data, n, slope, inter, values); break;
    case NIFTI_TYPE_UINT64: convert<std::uint64_t>(nim->data, n, slope, inter, values); break;
    case NIFTI_TYPE_FLOAT32: convert<float>(nim->data, n, slope, inter, values); break;
    case NIFTI_TYPE_FLOAT64: convert<double>(nim->data, n, slope, inter, values); break;
    }
    std::size_t bad = 0;
    for (float v : values) bad += !std::isfinite(v);
    if (bad) throw fail("NIfTI image has " + std::to_string(bad) + " non-finite (NaN or infinite) voxel values");

    // Index -> scanner space (RAS, mm): sform, else qform, else the voxel spacing (nifti1.h method 1).
    std::string source;
    double m[4][4] = {{0}};
    if (nim->sform_code > 0) {
        source = "sform";
        for (int r = 0; r < 4; ++r)
            for (int c = 0; c < 4; ++c) m[r][c] = nim->sto_xyz.m[r][c];
    } else if (nim->qform_code > 0) {
        source = "qform";
        for (int r = 0; r < 4; ++r)
            for (int c = 0; c < 4; ++c) m[r][c] = nim->qto_xyz.m[r][c];
    } else {
        source = "pixdim";
        m[0][0] = nim->dx > 0 ? nim->dx : 1.0;
        m[1][1] = nim->dy > 0 ? nim->dy : 1.0;
        m[2][2] = nim->dz > 0 ? nim->dz : 1.0;
        m[3][3] = 1.0;
    }
    // OpenVDB multiplies row vectors (world = index * M): transpose the column-vector NIfTI matrix.
    openvdb::math::Mat4d mat(openvdb::math::Mat4d::identity());
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 4; ++c) mat(c, r) = m[r][c];
    const openvdb::math::Mat3d linear = mat.getMat3();
    if (!(std::abs(linear.det()) > 1e-12) || !std::isfinite(linear.det()))
        throw fail("NIfTI " + source + " transform is singular");

    const int nz = int(nim->nz);
    const detail::DenseLayout layout(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(int(nim->nx) - 1,
                                                                                      int(nim->ny) - 1, nz - 1)));
    auto grid = detail::denseToGrid<openvdb::FloatGrid>(values, layout, 0.0f);
    try { // OpenVDB refuses near-zero axis scales that pass the determinant test (fuzzing found one)
        grid->setTransform(openvdb::math::Transform::createLinearTransform(mat));
    } catch (const openvdb::Exception& e) {
        throw fail("NIfTI " + source + " transform is unusable (" + e.what() + ")");
    }
    grid->setName(std::filesystem::path(path).filename().string());
    grid->setGridClass(openvdb::GRID_UNKNOWN);
    grid->insertMeta("riemesh:world_space", openvdb::StringMetadata("NIfTI scanner space (RAS, mm) from " + source));

    if (info) {
        info->dims = {nim->nx, nim->ny, nim->nz};
        info->spacing = {nim->dx, nim->dy, nim->dz};
        info->transformSource = source;
        info->datatype = nim->datatype;
        info->slope = slope;
        info->inter = inter;
    }
    return grid;
}

} // namespace riemesh::vdb
