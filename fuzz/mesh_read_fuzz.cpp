// Fuzzes the mesh readers (core mesh_io: OBJ, PLY ascii and binary, OFF, STL ascii and binary).
// The first byte picks the format; the rest is the file. An accepted mesh must be closed, manifold
// and consistently oriented, as readMesh promises.
#include "fuzz_support.h"
#include "mesh_invariants.h"
#include "riemesh/mesh_io.h"

#include <limits>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    using namespace riemesh;
    if (size < 1) return 0;
    const MeshFormat formats[] = {MeshFormat::Obj, MeshFormat::Ply, MeshFormat::Off, MeshFormat::Stl};
    const MeshFormat format = formats[data[0] % 4];
    const std::string_view bytes(reinterpret_cast<const char*>(data + 1), size - 1);
    fuzz::expectCleanRefusal([&] {
        const Mesh mesh = readMeshFromBytes(bytes, format, "fuzz");
        testing::InvariantOptions options;
        options.requireOutward = false; // only the whole mesh is turned outward
        // The reader promises topology (closed, manifold, consistently oriented, no pillows), not
        // geometry: coincident points make zero-area faces, legal in a file (only NaN areas, from
        // overflowing coordinates, are still listed; they are ignored below too).
        options.minFaceArea = -std::numeric_limits<double>::infinity();
        const auto report = testing::checkInvariants(mesh, options);
        for (const auto& problem : report.problems)
            fuzz::require(problem.rfind("degenerate face", 0) == 0 || problem.rfind("...", 0) == 0,
                          "accepted mesh breaks invariants: " + problem);
    });
    return 0;
}
