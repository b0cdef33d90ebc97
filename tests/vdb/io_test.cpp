// Reading and writing: NIfTI (Colin27 and a file written here with nifticlib), .vdb and .nvdb round
// trips, refusals with messages that name the problem, mesh level sets and accuracy against an sdf.
#include "riemesh/evolution.h"
#include "riemesh/primitives.h"
#include "riemesh/vdb/io.h"
#include "riemesh/vdb/level_set.h"
#include "riemesh/vdb/metric_grid.h"
#include "riemesh/vdb/nano.h"
#include "riemesh/vdb/nifti.h"
#include "riemesh/vdb/phantom.h"
#include "riemesh/vdb/pipeline.h"
#include "riemesh/vdb/volume.h"
#include "riemesh/vdb/volume_sources.h"

#include "corrupt_vdb.h"
#include "isolated_read.h"
#include "mesh_invariants.h"

#include <nifti2_io.h>

#include <openvdb/io/File.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <doctest/doctest.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <string>
#include <utility>
#include <vector>

using namespace riemesh::vdb;
using openvdb::Coord;
namespace fs = std::filesystem;

namespace {

struct TempDir {
    fs::path path;
    TempDir()
    {
        path = fs::temp_directory_path() / ("riemesh_io_test_" + std::to_string(::getpid()));
        fs::create_directories(path);
    }
    ~TempDir() { fs::remove_all(path); }
    std::string operator/(const std::string& name) const { return (path / name).string(); }
};

std::string messageOf(const std::function<void()>& f)
{
    try {
        f();
    } catch (const std::exception& e) {
        return e.what();
    }
    return "(no exception)";
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

/// Gives `nim` (from nifti_make_new_nim) the scanner-space sform S (rows of the 4x4 index -> mm
/// matrix, no qform), writes it to `path` and frees it.
void writeWithSform(nifti_image* nim, const std::string& path, const double (&S)[4][4])
{
    nim->sform_code = NIFTI_XFORM_SCANNER_ANAT;
    nim->qform_code = 0;
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) nim->sto_xyz.m[r][c] = S[r][c];
    REQUIRE(nifti_set_filenames(nim, path.c_str(), 0, 1) == 0);
    nifti_image_write(nim);
    nifti_image_free(nim);
}

} // namespace

TEST_CASE("nifti: Colin27 ch2.nii.gz reads as 181x217x181 voxels of 1 mm in scanner space")
{
    const std::string path = "/usr/share/mricron/templates/ch2.nii.gz";
    if (!fs::exists(path)) {
        MESSAGE("skipped: " << path << " is not installed (Debian mricron-data)");
        return;
    }
    NiftiHeaderInfo info;
    auto grid = readNifti(path, &info);
    CHECK(info.dims == std::array<long long, 3>{181, 217, 181});
    const auto box = grid->evalActiveVoxelBoundingBox();
    CHECK(box.min() == Coord(0));
    CHECK(box.max() == Coord(180, 216, 180));
    CHECK(grid->activeVoxelCount() == openvdb::Index64(181) * 217 * 181);
    const auto vs = grid->transform().voxelSize();
    CHECK(vs[0] == doctest::Approx(1.0));
    CHECK(vs[1] == doctest::Approx(1.0));
    CHECK(vs[2] == doctest::Approx(1.0));
    CHECK((info.transformSource == "sform" || info.transformSource == "qform"));
    // The header's own index -> world matrix, applied by nifticlib, agrees with the grid's transform.
    nifti_image* nim = nifti_image_read(path.c_str(), 0);
    REQUIRE(nim);
    const auto& M = info.transformSource == "sform" ? nim->sto_xyz : nim->qto_xyz;
    for (const Coord c : {Coord(0, 0, 0), Coord(90, 108, 90), Coord(180, 0, 37)}) {
        const openvdb::Vec3d w = grid->transform().indexToWorld(c);
        for (int r = 0; r < 3; ++r)
            CHECK(w[r] == doctest::Approx(M.m[r][0] * c.x() + M.m[r][1] * c.y() + M.m[r][2] * c.z() + M.m[r][3]));
    }
    nifti_image_free(nim);
    // A head: dark air in the corner, bright tissue in the middle.
    auto acc = grid->getConstAccessor();
    CHECK(acc.getValue(Coord(2, 2, 2)) < 20);
    double sum = 0;
    for (int k = 80; k < 100; ++k)
        for (int j = 98; j < 118; ++j)
            for (int i = 80; i < 100; ++i) sum += acc.getValue(Coord(i, j, k));
    CHECK(sum / 8000.0 > 40);
}

TEST_CASE("nifti: a file written with nifticlib reads back with its affine, slope/intercept and datatype")
{
    TempDir dir;
    const std::string path = dir / "small.nii.gz";
    const int64_t dims[8] = {3, 4, 5, 6, 1, 1, 1, 1};
    nifti_image* nim = nifti_make_new_nim(dims, NIFTI_TYPE_INT16, 1);
    REQUIRE(nim);
    auto* data = static_cast<int16_t*>(nim->data);
    for (int k = 0; k < 6; ++k)
        for (int j = 0; j < 5; ++j)
            for (int i = 0; i < 4; ++i) data[(k * 5 + j) * 4 + i] = int16_t(i + 10 * j + 100 * k);
    nim->scl_slope = 0.5;
    nim->scl_inter = -3.0;
    // sform: spacing (2, 1, 3) mm with a 90 degree rotation about z and an offset.
    writeWithSform(nim, path, {{0, -1, 0, 10}, {2, 0, 0, -20}, {0, 0, 3, 5}, {0, 0, 0, 1}});

    NiftiHeaderInfo info;
    auto grid = readNifti(path, &info);
    CHECK(info.transformSource == "sform");
    CHECK(info.datatype == NIFTI_TYPE_INT16);
    CHECK(info.dims == std::array<long long, 3>{4, 5, 6});
    auto acc = grid->getConstAccessor();
    CHECK(acc.getValue(Coord(3, 2, 1)) == doctest::Approx(0.5 * (3 + 20 + 100) - 3.0));
    CHECK(acc.getValue(Coord(0, 4, 5)) == doctest::Approx(0.5 * (40 + 500) - 3.0));
    const openvdb::Vec3d w = grid->transform().indexToWorld(openvdb::Vec3d(1, 2, 3));
    CHECK(w[0] == doctest::Approx(-2 + 10));
    CHECK(w[1] == doctest::Approx(2 - 20));
    CHECK(w[2] == doctest::Approx(9 + 5));
    CHECK(grid->getGridClass() == openvdb::GRID_UNKNOWN);
    // Through the facade: world box and a note saying which space.
    const Volume v = Volume::read(path);
    CHECK(contains(v.info().transformNote, "RAS"));
    CHECK(v.info().dims[0] == 4);
}

TEST_CASE("nifti: an sform that passes the determinant test but that OpenVDB cannot invert is refused (fuzz_nifti_read finding)")
{
    // Columns scaled from 1e-16 to 1e16: det 1.6e-10, above the reader's singularity bound, yet
    // OpenVDB's AffineMap throws ArithmeticError ("Inversion of singular 4x4 matrix"), which escaped
    // the reader before ad599a6 (vdb2mesh ended on an uncaught exception).
    TempDir dir;
    const std::string path = dir / "bad_sform.nii";
    const int64_t dims[8] = {3, 2, 2, 2, 1, 1, 1, 1};
    nifti_image* nim = nifti_make_new_nim(dims, NIFTI_TYPE_FLOAT32, 1);
    REQUIRE(nim);
    writeWithSform(nim, path, {{-9.46799e-16, -2.28356e-09, -4.07416e-16, 0},
                               {8.35615e-16, 3.08329e+16, -4.5909e-08, 0},
                               {-8.26083e-15, -3.73203e+12, 2.79116e-18, 0},
                               {0, 0, 0, 1}});
    const std::string message = messageOf([&] { readNifti(path); });
    CHECK(contains(message, "sform transform is unusable"));
}

TEST_CASE("vdb: round trip of an image, and double grids read as float")
{
    TempDir dir;
    PhantomOptions o;
    o.size = 20;
    o.noise = 0.1;
    const Phantom p = makePhantom(PhantomShape::Ball, o);
    const std::string path = dir / "p.vdb";
    writeVdb(path, {p.density, p.sdf});
    auto density = readVdbImage(path);
    CHECK(density->getName() == "density");
    CHECK(gridClassName(*density) == "fog");
    auto sdf = readVdbImage(path, "sdf");
    CHECK(gridClassName(*sdf) == "levelset");
    // The phantom's shape and size come through the isolated reader: --reference measures against
    // the exact distance (edges and corners), not the trilinear grid (lost from 4827400 to now).
    REQUIRE(bool(phantomReferenceDistance(*sdf)));
    CHECK(phantomReferenceDistance(*sdf)()(openvdb::Vec3d(3, 4, 5)) == phantomReferenceDistance(*p.sdf)()(openvdb::Vec3d(3, 4, 5)));
    auto a = density->getConstAccessor();
    for (auto it = p.density->cbeginValueOn(); it; ++it) CHECK(a.getValue(it.getCoord()) == *it);

    auto d = openvdb::DoubleGrid::create(0.0);
    d->setName("dbl");
    d->getAccessor().setValue(Coord(1, 2, 3), 0.25);
    d->getAccessor().setValue(Coord(2, 2, 3), 0.75);
    d->getAccessor().setValue(Coord(2, 3, 4), 0.5);
    writeVdb(dir / "d.vdb", {d});
    auto f = readVdbImage(dir / "d.vdb");
    CHECK(f->getConstAccessor().getValue(Coord(2, 2, 3)) == 0.75f);
    CHECK(f->activeVoxelCount() == 3);
}

namespace {

/// Every value of `a` (voxels and tiles, active or not) reads the same in `b`, with the same activity.
void checkSameValues(const openvdb::FloatGrid& a, const openvdb::FloatGrid& b)
{
    auto acc = b.getConstAccessor();
    std::size_t checked = 0, differ = 0;
    for (auto it = a.cbeginValueAll(); it; ++it) {
        const Coord c = it.getCoord();
        if (acc.getValue(c) != *it || acc.isValueOn(c) != it.isValueOn()) ++differ;
        ++checked;
    }
    CHECK(checked > 0);
    CHECK(differ == 0);
}

} // namespace

TEST_CASE("vdb: the isolated read hands back the grid unchanged (values, tiles, activity, name, class, background, transform)")
{
    TempDir dir;
    initialize();
    // A level set with a translated, anisotropic voxel; a fog with an active root tile, an inactive
    // tile of another value and a ball; a rotated (affine) one; a double grid.
    auto sphere = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(20.0f, openvdb::Vec3f(3, 4, 5), 0.5f, 3.0f);
    sphere->setName("sdf");
    sphere->setTransform(openvdb::math::Transform::createLinearTransform(0.5));
    sphere->transform().postTranslate(openvdb::Vec3d(0.25, -1.5, 7));
    auto fog = openvdb::FloatGrid::create(0.0f);
    fog->setName("fog");
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    fog->tree().fill(openvdb::CoordBBox(Coord(4096), Coord(8191)), 0.5f, true);
    fog->tree().addTile(1, Coord(-64, 0, 0), 0.25f, false);
    fog->tree().addTile(2, Coord(-4096, 0, 0), 0.75f, true);
    for (int i = 0; i < 40; ++i) fog->tree().setValueOn(Coord(i, i / 2, -i), 0.1f * float(i % 7));
    openvdb::math::Mat4d rotation = openvdb::math::Mat4d::identity();
    rotation.preRotate(openvdb::math::Z_AXIS, 0.3);
    rotation.preScale(openvdb::Vec3d(1, 2, 3));
    auto affine = fog->deepCopy();
    affine->setName("affine");
    affine->setTransform(openvdb::math::Transform::createLinearTransform(rotation));
    writeVdb(dir / "grids.vdb", {sphere, fog, affine});
    for (const auto& original : {sphere, fog, affine}) {
        INFO(original->getName());
        const auto read = readVdbImage(dir / "grids.vdb", original->getName());
        CHECK(read->getName() == original->getName());
        CHECK(read->getGridClass() == original->getGridClass());
        CHECK(read->background() == original->background());
        CHECK(read->transform() == original->transform());
        CHECK(read->transform().mapType() == original->transform().mapType());
        CHECK(read->activeVoxelCount() == original->activeVoxelCount());
        CHECK(read->tree().leafCount() == original->tree().leafCount());
        CHECK(read->tree().activeTileCount() == original->tree().activeTileCount());
        checkSameValues(*original, *read);
        checkSameValues(*read, *original);
    }
    auto d = openvdb::DoubleGrid::create(-2.0);
    d->setName("dbl");
    d->setGridClass(openvdb::GRID_LEVEL_SET);
    d->tree().addTile(1, Coord(8, 0, 0), 2.0, false);
    d->getAccessor().setValue(Coord(1, 2, 3), 0.1);
    writeVdb(dir / "d.vdb", {d});
    const auto f = readVdbImage(dir / "d.vdb");
    CHECK(f->background() == -2.0f);
    CHECK(f->getGridClass() == openvdb::GRID_LEVEL_SET);
    CHECK(f->getConstAccessor().getValue(Coord(1, 2, 3)) == 0.1f);
    CHECK(f->getConstAccessor().getValue(Coord(9, 0, 0)) == 2.0f);
    CHECK(f->activeVoxelCount() == 1);
}

TEST_CASE("vdb: a reader's answer whose transform OpenVDB cannot build is refused as corrupt")
{
    // The CI fuzz finding of 2026-11-27 (fuzz_vdb_answer): an affine index-to-world matrix, the
    // identity translated by -5.16e120 along y. Its determinant is 1, but OpenVDB's Transform
    // simplifies it into a ScaleTranslateMap, whose constructor threw openvdb::ArithmeticError
    // ("Non-zero scale values required"), which no caller expects. It must end as the refusal
    // every malformed answer gets.
    initialize();
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName("density");
    grid->tree().setValueOn(Coord(1, 2, 3), 1.0f);
    std::string answer = riemesh::vdb::detail::childAnswerOf(*grid);
    // The header: magic (8 bytes), answer, class (4 each), three counts (8 each), then the
    // index-to-world Mat4d (row vectors: the translation is row 3) and the map kind (0: affine).
    constexpr std::size_t kMatrix = 40, kMapKind = kMatrix + 16 * sizeof(double);
    REQUIRE(answer.size() > kMapKind + 4);
    // (Unchanged, the answer is a grid: what follows fails only because of the patched matrix.)
    CHECK(riemesh::vdb::detail::gridFromChildAnswer(answer.data(), answer.size(), "x.vdb", std::uint64_t(256) << 20)
              ->activeVoxelCount() == 1);
    const double y = -5.164499756173817e+120;
    std::memcpy(&answer[kMatrix + 13 * sizeof(double)], &y, sizeof y);
    const std::uint32_t affine = 0;
    std::memcpy(&answer[kMapKind], &affine, sizeof affine);
    std::string message;
    try {
        riemesh::vdb::detail::gridFromChildAnswer(answer.data(), answer.size(), "x.vdb", std::uint64_t(256) << 20);
    } catch (const std::runtime_error& e) {
        message = e.what();
    }
    INFO(message);
    CHECK(message.find("'x.vdb'") != std::string::npos);
    CHECK(message.find("transform") != std::string::npos);
}

TEST_CASE("vdb: a file that overflows a heap buffer inside OpenVDB's reader is refused as corrupt, this process unharmed (issue 17)")
{
    TempDir dir;
    REQUIRE(riemesh::test::writeHeapOverflowVdb(dir / "overflow.vdb"));
    for (int i = 0; i < 3; ++i) { // the same again: nothing of the child's damage stays here
        const std::string message = messageOf([&] { readVdbImage(dir / "overflow.vdb"); });
        MESSAGE(message);
        CHECK(contains(message, "overflow.vdb"));
        // The overflow is undefined behaviour inside the child: most reads crash there ("the reader
        // crashed: signal 6/7/11"), but a few reach OpenVDB's own size check after the
        // overflow and throw (once in CI; 0 of 120 reads here). Either way: refused as corrupt, one line.
        const bool crashed = contains(message, "corrupt or unreadable VDB file (the reader crashed: signal ");
        const bool threw = contains(message, "truncated or corrupt VDB file (");
        CHECK((crashed || threw));
        CHECK(message.find('\n') == std::string::npos);
    }
    // This process reads good files as before.
    PhantomOptions o;
    o.size = 20;
    const Phantom p = makePhantom(PhantomShape::Ball, o);
    writeVdb(dir / "good.vdb", {p.density});
    CHECK(readVdbImage(dir / "good.vdb")->activeVoxelCount() == p.density->activeVoxelCount());
}

TEST_CASE("vdb: a file that keeps OpenVDB's reader busy for minutes is refused at the reader's time limit")
{
    // A root node claiming 2^31 tiles: OpenVDB reads them past the end of the file (15 s natively,
    // minutes under the sanitizers); the child stops at 4 processor seconds (a 1 KB file).
    TempDir dir;
    REQUIRE(riemesh::test::writeEndlessTilesVdb(dir / "endless.vdb"));
    const std::string message = messageOf([&] { readVdbImage(dir / "endless.vdb"); });
    MESSAGE(message);
    CHECK(contains(message, "endless.vdb"));
    CHECK(contains(message, "corrupt or unreadable VDB file (the reader ran past its 4 s time limit)"));
}

TEST_CASE("vdb: a reader stuck asleep (a lock the fork copied held) is started again once, then refused, never waited for")
{
    // TBB is not fork-safe: a child can inherit a lock a worker thread of the parent held at the
    // fork, and sleep on it forever (fuzz_vdb_read in CI: libFuzzer's 10 s timeout, the parent in
    // waitpid). A child asleep without using the processor for 2 s is killed and started again;
    // twice stuck, the read is refused. Here every child sleeps.
    TempDir dir;
    initialize();
    auto g = openvdb::FloatGrid::create(0.0f);
    g->setName("density");
    {
        openvdb::io::File file(dir / "small.vdb");
        file.write({g});
        file.close();
    }
    const auto start = std::chrono::steady_clock::now();
    const std::string message = messageOf([&] {
        detail::readGridInChild(dir / "small.vdb", std::uint64_t(64) << 20, [&]() -> openvdb::GridBase::ConstPtr {
            for (;;) ::pause(); // asleep, no processor time
        });
    });
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    MESSAGE(message << " (" << seconds << " s)");
    CHECK(contains(message, "small.vdb"));
    CHECK(contains(message, "corrupt or unreadable VDB file (the reader stalled twice: no progress for 2 s)"));
    CHECK(seconds > 4.0);  // two children, 2 s each
    CHECK(seconds < 30.0); // not waited for forever
}

TEST_CASE("vdb: a reader that runs past its memory limit is refused with the limit named")
{
    TempDir dir;
    initialize();
    // 64 MB of leaf nodes, written without the statistics that let the budget refuse it unread.
    auto g = openvdb::FloatGrid::create(0.0f);
    g->setName("dense");
    g->tree().fill(openvdb::CoordBBox(Coord(0), Coord(255)), 1.0f, true);
    g->tree().voxelizeActiveTiles();
    {
        openvdb::io::File file(dir / "dense.vdb");
        file.setGridStatsMetadataEnabled(false);
        file.write({g});
        file.close();
    }
    const std::string message = messageOf([&] { readVdbImage(dir / "dense.vdb", "", std::uint64_t(16) << 20); });
    MESSAGE(message);
    CHECK(contains(message, "dense.vdb"));
#if defined(__SANITIZE_ADDRESS__)
    // AddressSanitizer's allocator ends a process whose mmap fails instead of throwing bad_alloc.
    CHECK((contains(message, "ran out of the 16 MB memory limit") || contains(message, "the reader crashed")));
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
    CHECK((contains(message, "ran out of the 16 MB memory limit") || contains(message, "the reader crashed")));
#else
    CHECK(contains(message, "corrupt or unreadable VDB file (ran out of the 16 MB memory limit)"));
#endif
#else
    CHECK(contains(message, "corrupt or unreadable VDB file (ran out of the 16 MB memory limit)"));
#endif
}

TEST_CASE("nvdb: image and metric survive the round trip through NanoVDB")
{
    TempDir dir;
    PhantomOptions o;
    o.size = 24;
    const Phantom p = makePhantom(PhantomShape::CubeCavity, o);
    const MetricGrids m = computeMetric(*p.density);
    const std::string path = dir / "p.nvdb";
    writeNvdb(path, *p.density, m.diag.get(), m.off.get());
    const NanoFileGrids back = readNanoFile(path);
    REQUIRE(back.image);
    REQUIRE(back.metricDiag);
    CHECK(back.image->getName() == "density");
    CHECK(gridClassName(*back.image) == "fog");
    CHECK(back.muMax >= m.muMax - 1e-6);
    auto a = back.image->getConstAccessor();
    for (auto it = p.density->cbeginValueOn(); it; ++it) CHECK(a.getValue(it.getCoord()) == *it);
    auto md = back.metricDiag->getConstAccessor();
    auto mo = back.metricOff->getConstAccessor();
    std::size_t n = 0;
    for (auto it = m.diag->cbeginValueOn(); it; ++it, ++n) {
        CHECK(md.getValue(it.getCoord()) == *it);
        CHECK(mo.getValue(it.getCoord()) == m.off->getConstAccessor().getValue(it.getCoord()));
    }
    CHECK(n == m.activeVoxels);
    // In memory, the same grids for the core.
    const riemesh::NanoVolume nv = toNanoVolume(*p.density, m.diag.get(), m.off.get());
    REQUIRE(nv.metricDiag());
    CHECK(nv.imageName() == "density");
    CHECK(nv.imageClass() == "fog");
}

TEST_CASE("io: bad files are refused with a message naming the problem")
{
    TempDir dir;
    initialize();
    CHECK(contains(messageOf([&] { readVdbImage(dir / "missing.vdb"); }), "no such file"));
    { std::ofstream(dir / "empty.vdb"); }
    CHECK(contains(messageOf([&] { readVdbImage(dir / "empty.vdb"); }), "empty"));
    { std::ofstream(dir / "text.vdb") << "hello, I am not a volume\n"; }
    CHECK(contains(messageOf([&] { readVdbImage(dir / "text.vdb"); }), "not a VDB file"));

    PhantomOptions o;
    o.size = 24;
    o.noise = 0.2;
    const Phantom p = makePhantom(PhantomShape::Ball, o);
    writeVdb(dir / "good.vdb", {p.density});
    {
        const auto size = fs::file_size(dir / "good.vdb");
        std::ifstream in(dir / "good.vdb", std::ios::binary);
        std::string bytes(size / 2, '\0');
        in.read(bytes.data(), std::streamsize(bytes.size()));
        std::ofstream(dir / "truncated.vdb", std::ios::binary) << bytes;
    }
    CHECK(contains(messageOf([&] { readVdbImage(dir / "truncated.vdb"); }), "truncated"));
    CHECK(contains(messageOf([&] { readVdbImage(dir / "good.vdb", "nope"); }), "no grid named 'nope'"));

    auto vec = openvdb::Vec3fGrid::create();
    vec->setName("velocity");
    vec->getAccessor().setValue(Coord(0), openvdb::Vec3f(1));
    writeVdb(dir / "vector.vdb", {vec});
    CHECK(contains(messageOf([&] { readVdbImage(dir / "vector.vdb"); }), "no scalar float or double grid"));
    CHECK(contains(messageOf([&] { readVdbImage(dir / "vector.vdb", "velocity"); }), "not a scalar"));

    auto empty = openvdb::FloatGrid::create();
    empty->setName("nothing");
    writeVdb(dir / "emptygrid.vdb", {empty});
    CHECK(contains(messageOf([&] { readVdbImage(dir / "emptygrid.vdb"); }), "no active voxels"));

    auto nan = p.density->deepCopy();
    nan->getAccessor().setValue(Coord(3, 3, 3), std::numeric_limits<float>::quiet_NaN());
    nan->getAccessor().setValue(Coord(4, 3, 3), std::numeric_limits<float>::infinity());
    writeVdb(dir / "nan.vdb", {nan});
    const std::string nanMessage = messageOf([&] { readVdbImage(dir / "nan.vdb"); });
    CHECK(contains(nanMessage, "2 non-finite"));

    CHECK(contains(messageOf([&] { readImage(dir / "image.png"); }), "unknown input extension"));
    CHECK(contains(messageOf([&] { readNifti(dir / "text.vdb"); }), "NIfTI"));
}

TEST_CASE("io: a failed write leaves an existing file untouched and no temporary behind")
{
    TempDir dir;
    const std::string target = dir / "out.txt";
    { std::ofstream(target) << "precious"; }
    CHECK_THROWS(writeFileAtomically(target, [](const std::string& temp) {
        std::ofstream(temp) << "partial";
        throw std::runtime_error("disk on fire");
    }));
    std::ifstream in(target);
    std::string content;
    in >> content;
    CHECK(content == "precious");
    CHECK(std::distance(fs::directory_iterator(dir.path), fs::directory_iterator()) == 1);
    CHECK_THROWS_WITH(writeFileAtomically(dir / "no/such/folder/x.vdb", [](const std::string&) {}),
                      doctest::Contains("does not exist"));
}

TEST_CASE("level set: a mesh becomes a 'surface' level set whose zero crossing is the mesh")
{
    const riemesh::Mesh sphere = riemesh::makeIcosphere(riemesh::Vec3(10, 10, 10), 6.0, 4);
    auto xform = openvdb::math::Transform::createLinearTransform(0.5);
    auto ls = meshToSurfaceLevelSet(sphere, *xform);
    CHECK(ls->getName() == "surface");
    CHECK(ls->getGridClass() == openvdb::GRID_LEVEL_SET);
    CHECK(ls->voxelSize()[0] == doctest::Approx(0.5));
    auto acc = ls->getConstAccessor();
    // World distance: inside negative, a point 0.5 outside the sphere reads about +0.5.
    CHECK(acc.getValue(xform->worldToIndexCellCentered(openvdb::Vec3d(10, 10, 10 + 5.5))) < 0);
    CHECK(acc.getValue(xform->worldToIndexCellCentered(openvdb::Vec3d(10, 10, 16.5))) == doctest::Approx(0.5).epsilon(0.15));
}

TEST_CASE("accuracy: a mesh of the phantom's true surface is within a fraction of a voxel of its sdf")
{
    PhantomOptions o;
    o.size = 40;
    const Phantom p = makePhantom(PhantomShape::Ball, o);
    const double r = 0.3 * o.size, c = 0.5 * (o.size - 1);
    const riemesh::Mesh exact = riemesh::makeIcosphere(riemesh::Vec3(c, c, c), r, 5);
    for (const bool analytic : {false, true}) {
        CAPTURE(analytic);
        const ReferenceDistance distance = analytic ? phantomReferenceDistance(*p.sdf) : ReferenceDistance{};
        REQUIRE(bool(phantomReferenceDistance(*p.sdf)));
        const SurfaceError e = surfaceError(exact, *p.sdf, distance);
        CHECK(e.meanMeshToSurface < 0.02);
        CHECK(e.meanSurfaceToMesh < 0.02);
        CHECK(e.hausdorff < 0.1);
        // Both surfaces densely: ~4 samples per square voxel of a sphere of radius 12 (1,810 voxel^2).
        CHECK(e.surfaceSamples > 4000);
        CHECK(e.meshSamples > 4000);
        const riemesh::Mesh smaller = riemesh::makeIcosphere(riemesh::Vec3(c, c, c), r - 1.0, 5);
        const SurfaceError e2 = surfaceError(smaller, *p.sdf, distance);
        CHECK(e2.meanMeshToSurface == doctest::Approx(1.0).epsilon(0.05));
        CHECK(e2.meanSurfaceToMesh == doctest::Approx(1.0).epsilon(0.05));
        CHECK(e2.hausdorff == doctest::Approx(1.0).epsilon(0.1));
    }
}

TEST_CASE("accuracy: the two-sided measure sees rounded edges and corners of a box")
{
    // The thin plate is a box (28 x 28 x 3 voxels). Its exact mesh measures ~0; the same mesh with
    // its edges and corners rounded (radius 1.5) keeps every vertex within 0.42 r of the surface,
    // but the true corners are r (sqrt 3 - 1) = 1.10 voxels from it: only samples on the true
    // surface's corners see that.
    PhantomOptions o;
    o.size = 40;
    const Phantom p = makePhantom(PhantomShape::ThinPlate, o);
    const double c = 0.5 * (o.size - 1);
    const riemesh::Vec3 lo(c - 14, c - 14, c - 1.5), hi(c + 14, c + 14, c + 1.5);
    riemesh::Mesh box = riemesh::makeBox(lo, hi, 0.25);
    const ReferenceDistance exactDistance = phantomReferenceDistance(*p.sdf);
    const SurfaceError exact = surfaceError(box, *p.sdf, exactDistance);
    CHECK(exact.hausdorff < 0.05);
    CHECK(exact.meanSurfaceToMesh < 0.01);
    {
        // One vertex of the top face lifted by 2 voxels: the Hausdorff is there, on the mesh.
        riemesh::Mesh lifted = box;
        const riemesh::Vec3 target(c + 5, c - 3, hi.z());
        riemesh::VertexHandle best;
        for (auto v : lifted.vertices())
            if (!best.is_valid() || (riemesh::position(lifted, v) - target).norm() <
                                        (riemesh::position(lifted, best) - target).norm())
                best = v;
        const riemesh::Vec3 top = riemesh::position(lifted, best) + riemesh::Vec3(0, 0, 2);
        lifted.set_point(best, riemesh::toPoint(top));
        const SurfaceError l = surfaceError(lifted, *p.sdf, exactDistance);
        CHECK(l.hausdorff == doctest::Approx(2.0).epsilon(0.01));
        CHECK(l.hausdorffOnMesh);
        CHECK((riemesh::Vec3(l.hausdorffAt.x(), l.hausdorffAt.y(), l.hausdorffAt.z()) - top).norm() < 0.01);
    }
    const double r = 1.5;
    for (auto v : box.vertices()) {
        const riemesh::Vec3 q = riemesh::position(box, v);
        riemesh::Vec3 inner = q;
        for (int a = 0; a < 3; ++a) inner[a] = std::clamp(q[a], lo[a] + r, hi[a] - r);
        const riemesh::Vec3 d = q - inner;
        if (d.norm() > 0) box.set_point(v, riemesh::toPoint(inner + d * (r / d.norm())));
    }
    const SurfaceError e = surfaceError(box, *p.sdf, exactDistance);
    CHECK(e.maxMeshToSurface == doctest::Approx(r * (1 - 1 / std::sqrt(3.0))).epsilon(0.1));
    CHECK(e.maxSurfaceToMesh == doctest::Approx(r * (std::sqrt(3.0) - 1)).epsilon(0.05));
    CHECK(e.hausdorff == e.maxSurfaceToMesh);
    // ... and it is at one of the true corners, on the reference surface.
    CHECK_FALSE(e.hausdorffOnMesh);
    double nearestCorner = 1e300;
    for (int k = 0; k < 8; ++k) {
        const riemesh::Vec3 corner((k & 1) ? hi.x() : lo.x(), (k & 2) ? hi.y() : lo.y(), (k & 4) ? hi.z() : lo.z());
        nearestCorner = std::min(
            nearestCorner, (riemesh::Vec3(e.hausdorffAt.x(), e.hausdorffAt.y(), e.hausdorffAt.z()) - corner).norm());
    }
    CHECK(nearestCorner < 0.3);
    // Interpolating the grid instead rounds the true corners too (trilinear between voxel centres):
    // it sees the edges' 0.62 but not the corners' 1.10; hence the analytic distance for phantoms.
    const SurfaceError g = surfaceError(box, *p.sdf);
    CHECK(g.maxSurfaceToMesh > r * (std::sqrt(2.0) - 1) - 0.1);
    CHECK(g.maxSurfaceToMesh < e.maxSurfaceToMesh);
}

namespace {

// A half ball standing on the image's z = 0 face, cut by it, with a U-shaped tunnel that opens
// through the cut face at two holes: the isosurface of the image as cut goes through the tunnel
// (genus 1); the object as a user means it (continued beyond the field of view) is a solid half
// ball with a hidden void.
openvdb::FloatGrid::Ptr cutHalfBallWithTunnel()
{
    initialize();
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    grid->setName("density");
    auto acc = grid->getAccessor();
    const auto tube = [](double x, double y, double z) {
        const double r = 3.0;
        const double leg = std::min(std::hypot(x - 12, y - 20), std::hypot(x - 28, y - 20));
        const double legs = z <= 10 ? leg : std::hypot(leg, z - 10);
        const double across = (x >= 12 && x <= 28) ? std::hypot(y - 20, z - 10) : 1e9;
        return std::min(legs, across) - r; // > 0 outside the tube
    };
    for (int k = 0; k < 40; ++k)
        for (int j = 0; j < 40; ++j)
            for (int i = 0; i < 40; ++i) {
                const double ball = 18.0 - std::hypot(i - 20.0, j - 20.0, double(k)); // > 0 inside
                const double sd = std::min(ball, tube(i, j, k));                    // > 0 in the object
                acc.setValue(Coord(i, j, k), float(std::clamp(0.5 + sd, 0.0, 1.0)));
            }
    return grid;
}

} // namespace

TEST_CASE("closeBorders: the footprint of an object cut by the image box, holes filled, is copied two voxels out")
{
    TempDir dir;
    const std::string path = dir / "cut.vdb";
    writeVdb(path, {cutHalfBallWithTunnel()});
    Volume volume = Volume::read(path);
    const std::uint64_t added = volume.closeBorders(0.5, true);
    // The z = 0 disc of radius 18 (~pi 18^2 = 1018 voxels) including both tunnel holes; nothing
    // else touches the box.
    CHECK(added > 2 * 950);
    CHECK(added < 2 * 1100);
    const riemesh::NanoVolume nano = volume.nano();
    riemesh::NanoImage image(nano.imageGrid());
    double v;
    riemesh::Vec3 g;
    image.sample(riemesh::Vec3(20, 20, -1), v, g); // under the solid centre
    CHECK(v > 0.5);
    image.sample(riemesh::Vec3(12, 20, -1), v, g); // under a tunnel hole: filled
    CHECK(v > 0.5);
    image.sample(riemesh::Vec3(2, 2, -1), v, g); // outside the footprint
    CHECK(v < 0.5);
    image.sample(riemesh::Vec3(20, 20, 41), v, g); // the top face has no object: nothing added
    CHECK(v < 0.5);
}

TEST_CASE("closeBorders: a deflating box keeps the cut object's topology (genus 0) instead of tunnelling in")
{
    TempDir dir;
    const std::string path = dir / "cut.vdb";
    writeVdb(path, {cutHalfBallWithTunnel()});
    for (const bool close : {false, true}) {
        CAPTURE(close);
        Volume volume = Volume::read(path);
        if (close) volume.closeBorders(0.5, true);
        const riemesh::NanoVolume nano = volume.nano();
        riemesh::NanoImage image(nano.imageGrid());
        riemesh::EuclideanMetric metric;
        riemesh::EvolutionOptions opt;
        opt.delta = 1.2;
        opt.zeta = 2.5;
        opt.maxIterations = 1500;
        riemesh::Mesh mesh = riemesh::makeInitialBox(image, 0.5 * (1 + opt.zeta) * opt.delta);
        const auto stats = riemesh::evolve(mesh, image, metric, opt);
        CHECK(std::string(riemesh::toString(stats.reason)) == "converged");
        const auto topo = riemesh::topologyOf(mesh);
        CHECK(topo.components == 1);
        // Open borders: the tunnel's two holes on the cut face make a handle.
        CHECK(topo.genus == (close ? 0 : 1));
    }
}

TEST_CASE("nvdb: the isovalue given to the export travels with the file; files without one have none")
{
    TempDir dir;
    PhantomOptions o;
    o.size = 16;
    const Phantom p = makePhantom(PhantomShape::Ball, o);
    writeNvdb(dir / "with.nvdb", *p.density, nullptr, nullptr, 0.25);
    writeNvdb(dir / "without.nvdb", *p.density);
    const riemesh::NanoVolume with = riemesh::NanoVolume::read(dir / "with.nvdb");
    REQUIRE(with.hasIso());
    CHECK(with.iso() == doctest::Approx(0.25));
    CHECK(with.imageName() == "density"); // the iso grid is not taken for the image
    CHECK_FALSE(riemesh::NanoVolume::read(dir / "without.nvdb").hasIso());
}

TEST_CASE("downsample: block averages keep the image's world placement and values")
{
    TempDir dir;
    initialize();
    // A linear ramp v = x + 2y + 3z (world = index + 0.5 offset, voxel 1.5): the mean over a block
    // is the ramp at the block centre, so every output voxel must read the ramp at its own centre.
    auto grid = openvdb::FloatGrid::create(0.0f);
    auto xform = openvdb::math::Transform::createLinearTransform(1.5);
    xform->postTranslate(openvdb::Vec3d(0.5, -1.0, 2.0));
    grid->setTransform(xform);
    grid->setName("ramp");
    auto acc = grid->getAccessor();
    for (int k = 0; k < 12; ++k)
        for (int j = 0; j < 12; ++j)
            for (int i = 0; i < 12; ++i) {
                const auto w = grid->indexToWorld(Coord(i, j, k));
                acc.setValue(Coord(i, j, k), float(w.x() + 2 * w.y() + 3 * w.z()));
            }
    writeVdb(dir / "ramp.vdb", {grid});
    Volume v = Volume::read(dir / "ramp.vdb", "ramp");
    v.downsample(3);
    CHECK(v.info().dims[0] == 4);
    CHECK(v.info().voxelSize == doctest::Approx(4.5));
    const riemesh::NanoVolume nano = v.nano();
    riemesh::NanoImage image(nano.imageGrid());
    for (const riemesh::Vec3& x : {riemesh::Vec3(5, 3, 9), riemesh::Vec3(9.2, 8.1, 12.3)}) {
        double value;
        riemesh::Vec3 g;
        image.sample(x, value, g);
        CHECK(value == doctest::Approx(x.x() + 2 * x.y() + 3 * x.z()).epsilon(1e-4));
    }
    CHECK_THROWS(v.downsample(0));
}

TEST_CASE("vdb: bytes cut out of a file's middle are refused as corrupt (fuzz_vdb_read finding)")
{
    // The seed fuzz_vdb_read started from (fuzz/make_seeds.cpp: a double grid of four voxels). With
    // bytes [5723, 8806) erased, OpenVDB read a Blosc chunk size of ~140 TB from the shifted bytes
    // and allocated it: std::bad_alloc, which readVdbImage must report as a corrupt file (under
    // ASan the vdb suite links fuzz/bounded_new.cpp so that such sizes throw there too). The same
    // for erasures swept across the file.
    TempDir dir;
    auto d = openvdb::DoubleGrid::create(0.0);
    d->setName("double");
    for (int i = 0; i < 4; ++i) d->tree().setValue(openvdb::Coord(i, i, 2 * i), 1.0 + i);
    writeVdb(dir / "d.vdb", {d});
    std::string bytes;
    {
        std::ifstream in(dir / "d.vdb", std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    std::vector<std::pair<std::size_t, std::size_t>> cuts; // [begin, end) to erase
    if (bytes.size() == 10064) cuts.push_back({5723, 8806}); // the finding, for this file layout
    for (std::size_t at = 0; at + 64 < bytes.size(); at += 397) cuts.push_back({at, at + 64});
    int refused = 0;
    for (const auto& range : cuts) { // no structured binding: INFO's lambda captures (C++20 only)
        const std::size_t begin = range.first, end = range.second;
        std::string cut = bytes;
        cut.erase(begin, end - begin);
        { std::ofstream(dir / "cut.vdb", std::ios::binary) << cut; }
        try {
            (void)readVdbImage(dir / "cut.vdb");
        } catch (const std::runtime_error& e) {
            ++refused;
            INFO("erased [" << begin << ", " << end << "): " << e.what());
            CHECK(std::string(e.what()).find("cut.vdb") != std::string::npos);
        }
    }
    MESSAGE(refused << " of " << cuts.size() << " cut files refused (the rest erase only metadata padding)");
    CHECK(refused > 0);
}

namespace {

void writeGrid(const openvdb::FloatGrid::Ptr& grid, const std::string& path)
{
    openvdb::io::File file(path);
    file.write({grid});
    file.close();
}

} // namespace

TEST_CASE("sparse: two small level-set spheres at opposite corners of a 10^9-voxel box mesh as two spheres, unsmoothed")
{
    openvdb::initialize();
    TempDir dir;
    const float r = 12;
    auto a = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(r, openvdb::Vec3f(0, 0, 0), 1.0f, 3.0f);
    auto b = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(r, openvdb::Vec3f(1000, 1000, 1000), 1.0f, 3.0f);
    openvdb::tools::csgUnion(*a, *b);
    a->setName("ls");
    REQUIRE(a->evalActiveVoxelBoundingBox().volume() > 1'000'000'000ull);
    writeGrid(a, dir / "far.vdb");
    Volume volume = Volume::read(dir / "far.vdb");
    const PipelineResult result = meshVolume(volume, PipelineOptions{});
    CHECK_MESH_OK(result.mesh);
    CHECK((result.stop == riemesh::StopReason::Converged));
    CHECK(result.topology.components == 2);
    CHECK(result.topology.genus == 0);
    CHECK(result.options.smooth == 0.0); // a level set is not smoothed by default
    CHECK(result.evolution.iterations.size() < 200);
    double worst = 0;
    for (auto v : result.mesh.vertices()) {
        const riemesh::Vec3 p = riemesh::position(result.mesh, v);
        const double toA = std::abs(p.norm() - r), toB = std::abs((p - riemesh::Vec3::Constant(1000)).norm() - r);
        worst = std::max(worst, std::min(toA, toB));
    }
    CHECK(worst < 0.5);
}

TEST_CASE("sparse: a fog volume whose root holds a 4096^3 constant tile meshes its small object; a tile-sized object is refused early")
{
    openvdb::initialize();
    TempDir dir;
    const auto ball = [](openvdb::FloatGrid& g, float inside, float outside) {
        auto acc = g.getAccessor();
        for (int x = 2000; x <= 2040; ++x)
            for (int y = 2000; y <= 2040; ++y)
                for (int z = 2000; z <= 2040; ++z) {
                    const double d = std::sqrt(double((x - 2020) * (x - 2020) + (y - 2020) * (y - 2020) + (z - 2020) * (z - 2020)));
                    const double t = std::clamp(20.5 - d, 0.0, 1.0); // 1 inside the ball
                    if (t > 0) acc.setValueOn(Coord(x, y, z), float(outside + (inside - outside) * t));
                }
    };
    SUBCASE("a ball in a tile of background value")
    {
        auto g = openvdb::FloatGrid::create(0.0f);
        g->setName("fog");
        g->setGridClass(openvdb::GRID_FOG_VOLUME);
        g->tree().fill(openvdb::CoordBBox(Coord(0), Coord(4095)), 0.0f, true);
        ball(*g, 1.0f, 0.0f);
        writeGrid(g, dir / "tile.vdb");
        Volume volume = Volume::read(dir / "tile.vdb");
        const PipelineResult result = meshVolume(volume, PipelineOptions{});
        CHECK_MESH_OK(result.mesh);
        CHECK(result.topology.components == 1);
        CHECK(result.topology.genus == 0);
        CHECK(result.options.smooth == kSmooth);
        for (auto v : result.mesh.vertices())
            CHECK(std::abs((riemesh::position(result.mesh, v) - riemesh::Vec3::Constant(2020)).norm() - 20.5) < 1.0);
    }
    SUBCASE("the object is the tile: its surface needs more vertices than the cap, found on the coarsest level")
    {
        auto g = openvdb::FloatGrid::create(0.0f);
        g->setName("fog");
        g->setGridClass(openvdb::GRID_FOG_VOLUME);
        g->tree().fill(openvdb::CoordBBox(Coord(0), Coord(4095)), 1.0f, true);
        ball(*g, 0.0f, 1.0f); // a cavity
        writeGrid(g, dir / "tile.vdb");
        Volume volume = Volume::read(dir / "tile.vdb");
        PipelineOptions options;
        options.maxVertices = 200'000; // the cube's ~4 million are found on the coarsest level
        const std::string message = messageOf([&] { meshVolume(volume, options); });
        CHECK(contains(message, "would need about"));
        CHECK(contains(message, "--max-vertices"));
    }
}

/// A 64 x 64 x 58 block of the head MRI (the nibabel crop an earlier issue's note names), written
/// as a NIfTI file of its own (its first voxel at index 0, as the crop's) and read back.
static Volume headBlock(const TempDir& dir)
{
    const std::string path = "/usr/share/mricron/templates/ch2.nii.gz";
    REQUIRE_MESSAGE(fs::exists(path), "install mricron-data (scripts/setup)");
    nifti_image* head = nifti_image_read(path.c_str(), 1);
    REQUIRE(head);
    REQUIRE(head->datatype == NIFTI_TYPE_UINT8);
    const int lo[3] = {58, 153, 0};
    const int64_t dims[8] = {3, 64, 64, 58, 1, 1, 1, 1};
    nifti_image* block = nifti_make_new_nim(dims, NIFTI_TYPE_UINT8, 1);
    REQUIRE(block);
    const auto* from = static_cast<const std::uint8_t*>(head->data);
    auto* to = static_cast<std::uint8_t*>(block->data);
    for (int k = 0; k < 58; ++k)
        for (int j = 0; j < 64; ++j)
            for (int i = 0; i < 64; ++i)
                to[i + 64 * (j + 64 * k)] = from[(lo[0] + i) + head->nx * ((lo[1] + j) + head->ny * std::int64_t(lo[2] + k))];
    double S[4][4];
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) S[r][c] = head->sto_xyz.m[r][c];
    for (int r = 0; r < 3; ++r) S[r][3] += S[r][0] * lo[0] + S[r][1] * lo[1] + S[r][2] * lo[2];
    nifti_image_free(head);
    writeWithSform(block, dir / "block.nii.gz", S);
    return Volume::read(dir / "block.nii.gz");
}

TEST_CASE("untangle: a block of the head MRI at iso 80 crosses itself without the guarantee and comes out embedded")
{
    // The grey/white-matter boundary folds into gyri thinner than the image resolves: two walls of
    // such a fold are near each other along the mesh, which the collision search takes for one sheet,
    // so they pass through each other unmerged. On this 64 x 64 x 58 block (the nibabel crop the
    // issue's note names, ending 3-4 crossing face pairs without the fallback) the default evolution
    // ends tangled, and the surface is evolved again from the start with the guarantee.
    TempDir dir;
    Volume volume = headBlock(dir);
    PipelineOptions options;
    options.iso = 80;
    // Built for the sanitizers (other rounding), the evolution after the restart once ran to the cap:
    // the vertices the guarantee held back counted as travelling (fixed in accountForShortenedStep).
    options.maxIterations = 1500;
    const PipelineResult r = meshVolume(volume, options);
    INFO("iterations " << r.evolution.iterations.size() << ", restarted after " << r.evolution.untangledAt);
    CHECK_MESH_OK(r.mesh);
    CHECK((r.stop == riemesh::StopReason::Converged));
    CHECK(r.evolution.untangledAt > 0);
    CHECK(r.evolution.tangleCrossings > 0);
    CHECK(r.selfIntersections == 0);
}

TEST_CASE("face samples: the head MRI block at iso 80 converges, with and without the guarantee")
{
    // Where the gradient is faint (a gyrus thinner than the blur), the Newton estimate of a face's
    // distance runs to any size; blended unsaturated, one such face set the sign of its corners'
    // pull and flipped it every iteration: both runs reached the cap (the guaranteed one jittering
    // 0.8 voxel per iteration after 3,000 iterations; the default one tangled at iteration 35 and
    // its restart did the same).
    for (const bool intersectionFree : {false, true}) {
        CAPTURE(intersectionFree);
        TempDir dir;
        Volume volume = headBlock(dir); // (meshVolume releases its voxels)
        PipelineOptions options;
        options.iso = 80;
        options.faceSamples = true;
        options.intersectionFree = intersectionFree;
        options.maxIterations = 1500;
        const PipelineResult r = meshVolume(volume, options);
        INFO("iterations " << r.evolution.iterations.size() << ", restarted after " << r.evolution.untangledAt);
        CHECK_MESH_OK(r.mesh);
        CHECK((r.stop == riemesh::StopReason::Converged));
        CHECK(r.evolution.iterations.size() < 800);
        CHECK(r.selfIntersections == 0);
    }
}

/// The pipeline's mesh of a 100^3 phantom at noise 0.5, and its distances to the exact surface.
struct PhantomMesh {
    PipelineResult result;
    SurfaceError error;
};
PhantomMesh meshPhantom(PhantomShape shape, const char* name, int seed, bool sharpen)
{
    Volume volume = phantomVolume(name, 100, 0.5, seed);
    PhantomOptions po;
    po.noise = 0.5;
    po.seed = seed;
    const Phantom p = makePhantom(shape, po);
    const ReferenceDistance distance = phantomReferenceDistance(*p.sdf);
    REQUIRE(bool(distance));
    PipelineOptions options;
    options.sharpen = sharpen;
    PhantomMesh m{meshVolume(volume, options), {}};
    CHECK_MESH_OK(m.result.mesh);
    CHECK(m.result.selfIntersections == 0);
    m.error = surfaceError(m.result.mesh, *p.sdf, distance);
    return m;
}

TEST_CASE("sharpen: a thin plate's rim grows no fin beyond where the image puts the plate")
{
    // The plate's 3-voxel rim is thinner than the model's faces: the vertices along it take the top
    // and bottom faces' planes, and the fit pushed them out where those planes meet, up to its
    // 2.5-voxel bound (mesh->true 2.33 here). Moves the smoothed image puts more than
    // kSharpenMaxOutsideVoxels outside its isosurface are held back (1.47); the cube's corners (blurred
    // ~1.4 voxels in) still come out.
    const PhantomMesh m = meshPhantom(PhantomShape::ThinPlate, "thin-plate", 2, true);
    CHECK(m.result.sharpened > 0);
    INFO("mesh->true max " << m.error.maxMeshToSurface << ", mean " << m.error.meanMeshToSurface);
    CHECK(m.error.maxMeshToSurface < 1.8);
}

TEST_CASE("sharpen: no vertex goes into the object where the hole's wall meets the cavity")
{
    // The hole's wall is a concave cylinder: near the crease where it meets the cavity, a vertex's
    // faces' planes meet behind the wall, and the fit put vertices there 2-2.8 voxels into the
    // cube (seed 5: mesh->true max 2.62, the image's isosurface 2.6 voxels away). Moves the
    // smoothed image puts more than kSharpenMaxInsideVoxels inside its isosurface are held back.
    const PhantomMesh m = meshPhantom(PhantomShape::CubeCavity, "cube-cavity", 5, true);
    CHECK(m.result.sharpened > 0);
    INFO("mesh->true max " << m.error.maxMeshToSurface << ", Hausdorff " << m.error.hausdorff);
    CHECK(m.error.maxMeshToSurface < 1.6);
}

TEST_CASE("sharpen (on by default): the phantom cube's corners come back; a noisy ball and a torus keep their round shape")
{
    // Creases and corners are sharpened where the filtered normals and the image both turn sharply
    // across an edge (SharpenOptions::featureAngle, imageFeatureAngle). Measured (seed 1): cube
    // Hausdorff 2.50 -> 1.44, true->mesh mean 0.187 -> 0.144; ball and torus: no vertex moved.
    CHECK(PipelineOptions{}.sharpen);
    const PhantomMesh sharpened = meshPhantom(PhantomShape::CubeCavity, "cube-cavity", 1, true);
    const PhantomMesh rounded = meshPhantom(PhantomShape::CubeCavity, "cube-cavity", 1, false);
    const SurfaceError& cube = sharpened.error;
    const SurfaceError& cubeBefore = rounded.error;
    INFO("cube: Hausdorff " << cubeBefore.hausdorff << " -> " << cube.hausdorff << ", true->mesh "
                            << cubeBefore.meanSurfaceToMesh << " -> " << cube.meanSurfaceToMesh << " ("
                            << sharpened.result.sharpened << " vertices moved)");
    CHECK(rounded.result.sharpened == 0);
    CHECK(cubeBefore.hausdorff > 2.0);
    CHECK(cube.hausdorff < 1.6);
    CHECK(cube.meanSurfaceToMesh < 0.85 * cubeBefore.meanSurfaceToMesh);
    CHECK(cube.meanMeshToSurface < cubeBefore.meanMeshToSurface);
    // Round shapes: a few vertices at most pass the gate, and they stay close. (With single image
    // samples at 45 degrees, the sanitizer build's torus, evolved a little differently by clang,
    // had 2 vertices moved out: Hausdorff 0.68 -> 1.13. Here 0 move on seeds 1-6.)
    for (const auto& roundShape : {std::make_pair(PhantomShape::Ball, "ball"), std::make_pair(PhantomShape::Torus, "torus")}) {
        const PhantomShape shape = roundShape.first; // (no structured binding: clang 14's INFO cannot capture one)
        const std::string name = roundShape.second;
        const PhantomMesh round = meshPhantom(shape, name.c_str(), 1, false);
        const PhantomMesh gated = meshPhantom(shape, name.c_str(), 1, true);
        const std::size_t moved = gated.result.sharpened;
        const double before = round.error.hausdorff, after = gated.error.hausdorff;
        const double meanBefore = round.error.meanMeshToSurface, meanAfter = gated.error.meanMeshToSurface;
        INFO(name << ": " << moved << " vertices moved, Hausdorff " << before << " -> " << after << ", mesh->true "
                  << meanBefore << " -> " << meanAfter);
        CHECK(moved < 10);
        CHECK(after < before + 0.4);
        CHECK(meanAfter < meanBefore + 0.005);
    }
}
