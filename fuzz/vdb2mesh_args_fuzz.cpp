// Fuzzes vdb2mesh's command line (vdb/apps/vdb2mesh_args.cpp): the input, split at NUL bytes, is
// argv[1..]. Every rejection must be a BadInput (what main reports as exit 1); an accepted command
// line must hold values in their documented ranges. --init and output paths go through the same
// checks as in main. Nothing is read or run.
#include "cli.h"
#include "fuzz_support.h"
#include "vdb2mesh_args.h"

#include <cmath>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    using namespace riemesh::apps;
    std::vector<std::string> words(1, "vdb2mesh");
    std::string word;
    for (std::size_t i = 0; i < size; ++i) {
        if (data[i] == 0) {
            words.push_back(word);
            word.clear();
        } else {
            word += char(data[i]);
        }
    }
    words.push_back(word);
    if (words.size() > 64) return 0;
    std::vector<const char*> argv;
    for (const auto& w : words) argv.push_back(w.c_str());
    try {
        const Vdb2MeshArgs a = parseVdb2MeshArgs(int(argv.size()), argv.data());
        if (a.help) return 0;
        using riemesh::fuzz::require;
        require(a.delta > 0 && std::isfinite(a.delta), "delta accepted out of range");
        require(a.zeta >= 2 && std::isfinite(a.zeta), "zeta accepted out of range");
        require(a.muMax >= 1 && a.muMax <= 10000, "mu-max accepted out of range");
        require(a.sigma > 0 && a.rho > 0 && (a.smooth >= 0 || a.smooth == -1), "sigma/rho/smooth accepted out of range");
        require(a.maxIterations >= 1 && a.threads >= 0 && a.maxVertices >= 4, "count accepted out of range");
        if (a.init.rfind("sphere:", 0) == 0) {
            for (const auto& s : parseSpheres(a.init.substr(7)))
                require(s.second > 0 && s.first.allFinite(), "sphere accepted with a bad radius or centre");
        }
        checkOutputPath(a.output, {".obj", ".ply", ".off", ".stl", ".vdb"}, "output");
    } catch (const BadInput&) {
        // Refused with a message naming the flag: what main prints, exit 1.
    } catch (const std::exception& e) {
        std::fprintf(stderr, "fuzz: not a BadInput: %s\n", e.what());
        std::abort();
    }
    return 0;
}
