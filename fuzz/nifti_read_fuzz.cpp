// Fuzzes the NIfTI reader (vdb/src/nifti.cpp through nifticlib) with a memory budget. Inputs that
// start with the gzip magic are read as .nii.gz, others as .nii.
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
    const bool gz = size >= 2 && data[0] == 0x1f && data[1] == 0x8b;
    const std::string path = riemesh::fuzz::writeInput(data, size, gz ? ".nii.gz" : ".nii");
    riemesh::fuzz::expectCleanRefusal([&] {
        (void)riemesh::vdb::Volume::read(path, {}, std::uint64_t(256) << 20);
    });
    return 0;
}
