// tests/vdb/corrupt_vdb.h: .vdb files that OpenVDB 10.0.1's reader mishandles (issue 17): one
// corrupts its memory (the finding scripts/fuzz used to report as advisory), one keeps it reading
// for minutes; made from fresh files so that they cannot rot.
#pragma once

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <random>
#include <string>

namespace riemesh::test {

/// Writes `grid` to `path` as OpenVDB does; returns the file's bytes.
inline std::string writtenBytes(const std::string& path, const openvdb::FloatGrid::Ptr& grid)
{
    {
        openvdb::io::File file(path);
        file.write({grid});
        file.close();
    }
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// Writes to `path` a float grid "density": four marked voxels in the leaf at the origin, then a
/// 16^3 block of random values, Blosc-compressed as OpenVDB writes by default; then turns the byte
/// count of the first leaf's value block into an "uncompressed" count of all the bytes after it.
/// io::bloscFromStream reads that many bytes into the leaf's 16-byte buffer before it checks the
/// count: a heap overflow of ~16 KB (natively "munmap_chunk(): invalid pointer" or "double free or
/// corruption", exit 134). Returns false when the block is not where this layout puts it.
inline bool writeHeapOverflowVdb(const std::string& path)
{
    openvdb::initialize();
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName("density");
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    const float marks[4] = {1234.5f, 2345.5f, 3456.5f, 4567.5f};
    auto acc = grid->getAccessor();
    for (int i = 0; i < 4; ++i) acc.setValueOn(openvdb::Coord(i, i, 2 * i), marks[i]);
    std::mt19937 random(1);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    for (int x = 64; x < 80; ++x)
        for (int y = 0; y < 16; ++y)
            for (int z = 0; z < 16; ++z) acc.setValueOn(openvdb::Coord(x, y, z), unit(random));
    std::string bytes = writtenBytes(path, grid);
    const std::size_t values = bytes.find(std::string(reinterpret_cast<const char*>(marks), sizeof marks));
    if (values == std::string::npos || values < 24) return false;
    // The count sits before the values (-16: stored raw) or before Blosc's 16-byte header (32).
    for (const std::size_t at : {values - 8, values - 24}) {
        std::int64_t count;
        std::memcpy(&count, bytes.data() + at, 8);
        if (count != -16 && count != 32) continue;
        const std::int64_t overflow = -std::int64_t(bytes.size() - at - 8);
        std::memcpy(&bytes[at], &overflow, 8);
        std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
        return true;
    }
    return false;
}

/// Writes to `path` a float grid "density" of one voxel whose root node claims 2^31 - 1 tiles (the
/// count after its background value in the topology): OpenVDB 10.0.1 reads that many tiles past the
/// end of the file, for minutes (the fuzz_vdb_read finding of 2026-11-26). Returns false when the
/// count is not where this layout puts it.
inline bool writeEndlessTilesVdb(const std::string& path)
{
    openvdb::initialize();
    const float background = 1234.25f; // a value found nowhere else in the file
    auto grid = openvdb::FloatGrid::create(background);
    grid->setName("density");
    grid->getAccessor().setValueOn(openvdb::Coord(1, 2, 3), 0.5f);
    std::string bytes = writtenBytes(path, grid);
    // Background, then the tile count (0) and the child count (1), 32-bit each.
    std::string pattern(reinterpret_cast<const char*>(&background), sizeof background);
    const std::uint32_t counts[2] = {0, 1};
    pattern.append(reinterpret_cast<const char*>(counts), sizeof counts);
    const std::size_t at = bytes.find(pattern);
    if (at == std::string::npos || bytes.find(pattern, at + 1) != std::string::npos) return false;
    const std::uint32_t endless = 0x7fffffff;
    std::memcpy(&bytes[at + sizeof background], &endless, sizeof endless);
    std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
    return true;
}

} // namespace riemesh::test
