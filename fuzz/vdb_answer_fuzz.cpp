// Fuzzes the parent's half of the isolated .vdb read (vdb/src/isolated_read.h gridFromChildAnswer):
// whatever a child that OpenVDB's reader corrupted writes back, the parent must refuse it cleanly or
// build a grid whose every node is where a FloatTree can hold it. fuzz_vdb_read drives the child,
// whose coverage libFuzzer does not see (it is another process): this target covers what the
// parent trusts.
#include "fuzz_support.h"
#include "isolated_read.h"

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    openvdb::initialize();
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    riemesh::fuzz::expectCleanRefusal([&] {
        const auto grid = riemesh::vdb::detail::gridFromChildAnswer(data, size, "fuzz.vdb", std::uint64_t(256) << 20);
        // What the reader does next with an accepted grid: count, bound and visit it.
        (void)grid->activeVoxelCount();
        (void)grid->evalActiveVoxelBoundingBox();
        (void)grid->memUsage();
        (void)grid->transform().indexToWorld(openvdb::Vec3d(1, 2, 3));
        for (auto it = grid->cbeginValueOn(); it; ++it) (void)*it;
    });
    return 0;
}
