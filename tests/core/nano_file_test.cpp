// .nvdb files that lie: NanoVolume::fromBytes must refuse every truncated or corrupted file with a
// std::runtime_error (one message) instead of reading outside its buffers or allocating what a
// header claims. The files are written here with NanoVDB's GridBuilder and then damaged; the
// damages are the ones fuzz/nvdb_read_fuzz.cpp exercises at random.
#include "riemesh/image.h"

#include <nanovdb/util/GridBuilder.h>
#include <nanovdb/util/IO.h>

#include <doctest/doctest.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

using namespace riemesh;

namespace {

using Bytes = std::vector<std::uint8_t>;

/// An image (float, 24^3 so that it has several leaves) and a metric, as one .nvdb file's bytes.
Bytes validFile(float metricValue = 4.0f)
{
    nanovdb::GridBuilder<float> image(0.0f, nanovdb::GridClass::FogVolume);
    image([](const nanovdb::Coord& ijk) { return float(ijk[0] + ijk[1] - ijk[2]); },
          nanovdb::CoordBBox(nanovdb::Coord(0), nanovdb::Coord(23)));
    std::vector<nanovdb::GridHandle<>> handles;
    handles.push_back(image.getHandle<>(1.0, nanovdb::Vec3d(0), "density"));
    for (const char* name : {kMetricDiagGrid, kMetricOffGrid}) {
        nanovdb::GridBuilder<nanovdb::Vec3f> metric(nanovdb::Vec3f(name == kMetricDiagGrid ? 1.0f : 0.0f));
        metric([&](const nanovdb::Coord&) { return nanovdb::Vec3f(metricValue, 1, 1); },
               nanovdb::CoordBBox(nanovdb::Coord(0), nanovdb::Coord(9)));
        handles.push_back(metric.getHandle<>(1.0, nanovdb::Vec3d(0), name));
    }
    std::stringstream out(std::string(1 << 20, '\0'), std::ios::in | std::ios::out | std::ios::binary);
    nanovdb::io::writeGrids<nanovdb::HostBuffer, std::vector>(out, handles);
    const std::string s = out.str().substr(0, std::size_t(out.tellp()));
    return Bytes(s.begin(), s.end());
}

/// Where things are in a one-segment file: the grids' metadata and data.
struct Layout {
    std::vector<std::size_t> meta, grid;
};
Layout layoutOf(const Bytes& file)
{
    nanovdb::io::Header header;
    std::memcpy(&header, file.data(), sizeof(header));
    Layout l;
    std::size_t pos = sizeof(header);
    std::vector<nanovdb::io::MetaData> metas(header.gridCount);
    for (auto& m : metas) {
        l.meta.push_back(pos);
        std::memcpy(&m, file.data() + pos, sizeof(m));
        pos += sizeof(m) + m.nameSize;
    }
    for (const auto& m : metas) {
        l.grid.push_back(pos);
        pos += m.fileSize;
    }
    return l;
}

template<typename T>
void poke(Bytes& file, std::size_t at, T value)
{
    REQUIRE(at + sizeof(T) <= file.size());
    std::memcpy(file.data() + at, &value, sizeof(T));
}

std::string refusal(const Bytes& file)
{
    try {
        NanoVolume::fromBytes(file.data(), file.size());
    } catch (const std::runtime_error& e) {
        return e.what();
    }
    return "accepted";
}

} // namespace

TEST_CASE("nvdb reading: the valid file reads back (the damages below start from it)")
{
    const Bytes file = validFile();
    const NanoVolume v = NanoVolume::fromBytes(file.data(), file.size());
    REQUIRE(v.imageGrid());
    CHECK(v.metricDiag());
    CHECK(NanoImage(v.imageGrid()).value(Vec3(3, 2, 1)) == doctest::Approx(4.0));
}

TEST_CASE("nvdb reading: every truncation of a file is refused with a message")
{
    const Bytes file = validFile();
    const Layout l = layoutOf(file);
    // Every length through the headers, then a stride through the grids, then the last bytes.
    std::vector<std::size_t> lengths;
    for (std::size_t n = 0; n < l.grid[0] + 64; ++n) lengths.push_back(n);
    for (std::size_t n = l.grid[0] + 64; n < file.size(); n += 61) lengths.push_back(n);
    for (std::size_t n = file.size() - 8; n < file.size(); ++n) lengths.push_back(n);
    for (std::size_t n : lengths) {
        const Bytes cut(file.begin(), file.begin() + std::ptrdiff_t(n));
        INFO("length " << n << " of " << file.size());
        CHECK(refusal(cut) != "accepted");
    }
}

TEST_CASE("nvdb reading: headers that claim more than the file holds are refused before allocating")
{
    const Bytes good = validFile();
    const Layout l = layoutOf(good);
    const auto metaField = [&](std::size_t grid, std::size_t offset) { return l.meta[grid] + offset; };
    struct Damage {
        const char* what;
        std::function<void(Bytes&)> apply;
        const char* expect;
    };
    const std::size_t gridSizeAt = offsetof(nanovdb::io::MetaData, gridSize);
    const std::size_t fileSizeAt = offsetof(nanovdb::io::MetaData, fileSize);
    const std::size_t nameSizeAt = offsetof(nanovdb::io::MetaData, nameSize);
    const std::size_t treeAt = sizeof(nanovdb::GridData);
    const Damage damages[] = {
        {"a 4 GB grid name", [&](Bytes& f) { poke<std::uint32_t>(f, metaField(0, nameSizeAt), 0xffffffffu); }, "truncated"},
        {"a 2^62-byte grid", [&](Bytes& f) {
             poke<std::uint64_t>(f, metaField(0, gridSizeAt), std::uint64_t(1) << 62);
             poke<std::uint64_t>(f, metaField(0, fileSizeAt), std::uint64_t(1) << 62);
         }, "truncated"},
        {"stored and grid sizes differ", [&](Bytes& f) { poke<std::uint64_t>(f, metaField(1, fileSizeAt), 64); }, "differ"},
        {"zip codec", [&](Bytes& f) { poke<std::uint16_t>(f, 14, 1); }, "compressed"},
        {"wrong magic", [&](Bytes& f) { f[0] ^= 0xff; }, "not a NanoVDB file"},
        // Found by fuzz_nvdb_read: the message used NanoVDB's Version::c_str(), which leaks.
        {"file version 31", [&](Bytes& f) { poke<std::uint32_t>(f, 8, 31u << 21); }, "major version 31"},
        {"grid magic", [&](Bytes& f) { f[l.grid[0]] ^= 0xff; }, "magic"},
        {"grid index 1", [&](Bytes& f) { poke<std::uint32_t>(f, l.grid[0] + offsetof(nanovdb::GridData, mGridIndex), 1); }, "count"},
        {"unterminated grid name", [&](Bytes& f) {
             std::memset(f.data() + l.grid[0] + offsetof(nanovdb::GridData, mGridName), 'x', nanovdb::GridData::MaxNameSize);
         }, "name"},
        {"NaN transform", [&](Bytes& f) {
             poke<double>(f, l.grid[0] + offsetof(nanovdb::GridData, mMap) + offsetof(nanovdb::Map, mMatD),
                          std::numeric_limits<double>::quiet_NaN());
         }, "transform"},
        {"root beyond the end", [&](Bytes& f) { poke<std::uint64_t>(f, l.grid[0] + treeAt + 24, std::uint64_t(1) << 40); }, "root"},
        {"root tile table of 2^32-1 tiles", [&](Bytes& f) {
             std::uint64_t rootOffset;
             std::memcpy(&rootOffset, f.data() + l.grid[0] + treeAt + 24, 8);
             poke<std::uint32_t>(f, l.grid[0] + treeAt + rootOffset + 24, 0xffffffffu);
         }, "tile table"},
        {"leaf count beyond the end", [&](Bytes& f) { poke<std::uint32_t>(f, l.grid[0] + treeAt + 32, 1u << 30); }, "level 0"},
        {"metric NaN", [&](Bytes& f) { f = validFile(std::numeric_limits<float>::quiet_NaN()); }, "non-finite"},
    };
    for (const auto& d : damages) {
        Bytes f = good;
        d.apply(f);
        const std::string message = refusal(f);
        INFO(d.what << ": " << message);
        CHECK(message.find(d.expect) != std::string::npos);
    }
}

TEST_CASE("nvdb reading: a child offset pointing anywhere but a node of the level below is refused")
{
    const Bytes good = validFile();
    const Layout l = layoutOf(good);
    const std::size_t tree = l.grid[0] + sizeof(nanovdb::GridData);
    std::uint64_t offsets[4];
    std::memcpy(offsets, good.data() + tree, sizeof(offsets));
    // Root tile 0 (the image has one upper node): its child offset, relative to the root data.
    using RootData = nanovdb::NanoRoot<float>::DataType;
    const std::size_t tile0 = tree + offsets[3] + sizeof(RootData);
    const std::size_t childAt = tile0 + offsetof(RootData::Tile, child);
    for (std::int64_t bad : {std::int64_t(8), std::int64_t(-4096), std::int64_t(1) << 40, -(std::int64_t(1) << 40)}) {
        Bytes f = good;
        std::int64_t child;
        std::memcpy(&child, f.data() + childAt, 8);
        REQUIRE(child != 0);
        poke<std::int64_t>(f, childAt, child + bad);
        CHECK(refusal(f).find("root child offset") != std::string::npos);
    }
    // First lower node's first child (a leaf): shifted by half a leaf.
    using LowerData = nanovdb::NanoLower<float>::DataType;
    const std::size_t lower0 = tree + offsets[1];
    decltype(LowerData::mChildMask) mask; // copied: the vector's bytes need not be aligned
    std::memcpy(static_cast<void*>(&mask), good.data() + lower0 + offsetof(LowerData, mChildMask), sizeof(mask));
    const std::uint32_t n = *mask.beginOn();
    Bytes f = good;
    const std::size_t slot = lower0 + offsetof(LowerData, mTable) + n * sizeof(LowerData::Tile);
    std::int64_t child;
    std::memcpy(&child, f.data() + slot, 8);
    poke<std::int64_t>(f, slot, child + std::int64_t(sizeof(nanovdb::NanoLeaf<float>) / 2));
    CHECK(refusal(f).find("lower node child offset") != std::string::npos);
}

TEST_CASE("nano image: a point beyond int index range (or NaN) reads the background, no overflow")
{
    // Found by fuzz_nvdb_read: sampling a file whose transform puts the box at ~1e304 converted
    // the index coordinate to int (undefined behaviour; the ASan/UBSan suite checks this case).
    const Bytes file = validFile();
    const NanoVolume v = NanoVolume::fromBytes(file.data(), file.size());
    const NanoImage image(v.imageGrid());
    CHECK(image.value(Vec3(1e300, -1e300, 5)) == 0.0);
    CHECK(image.value(Vec3(std::numeric_limits<double>::quiet_NaN(), 1, 1)) == 0.0);
    double value;
    Vec3 gradient;
    image.sample(Vec3(-3e9, 4e9, 1e20), value, gradient);
    CHECK(value == 0.0);
    CHECK(gradient.norm() == 0.0);
}
