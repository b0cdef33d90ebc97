// Fuzzes the .vdb reader (vdb/src/io.cpp readVdbImage through OpenVDB's io::File) with a memory
// budget, then describes the image as the converter does (Volume::read). OpenVDB reads in a forked
// child (vdb/src/isolated_read.h), as in vdb2mesh: a child that crashes (a sanitizer report in it
// included) is a clean refusal here, so only this process's side can be a finding. The child's
// coverage is not seen by libFuzzer; fuzz_vdb_answer fuzzes what the parent reads back.
#include "fuzz_support.h"
#include "riemesh/vdb/io.h"
#include "riemesh/vdb/volume.h"

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    riemesh::vdb::initialize();
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    const std::string path = riemesh::fuzz::writeInput(data, size, ".vdb");
    riemesh::fuzz::expectCleanRefusal([&] {
        // 256 MB: the budget check, not the machine, refuses big boxes.
        (void)riemesh::vdb::Volume::read(path, {}, std::uint64_t(256) << 20);
    });
    return 0;
}
