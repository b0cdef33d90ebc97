// vdbphantom SHAPE OUTPUT.vdb [--size N] [--noise S] [--seed K]: synthetic fog volumes with a known surface.
#include "riemesh/vdb/volume.h"

#include "cli.h"

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <string>
#include <vector>

namespace {

using riemesh::apps::BadInput;
using riemesh::apps::parseNumber;

void usage(std::FILE* out)
{
    std::string shapes;
    for (const auto& s : riemesh::vdb::phantomShapes()) shapes += (shapes.empty() ? "" : ", ") + s;
    std::fprintf(out,
        "usage: vdbphantom SHAPE OUTPUT.vdb [--size N] [--noise S] [--seed K]\n"
        "\n"
        "Writes a synthetic volume with a known surface: a fog volume \"density\" (1 inside, 0 outside,\n"
        "a one-voxel partial-volume ramp across the surface, plus Gaussian noise) and \"sdf\", the exact\n"
        "signed distance to the true surface (world units = voxels, negative inside), for accuracy checks.\n"
        "\n"
        "SHAPE          %s\n"
        "               cube-cavity is the paper's phantom: a cube with a spherical cavity that opens\n"
        "               through a small hole in its top (+z) face; notched-block is a cube with a\n"
        "               notch cut along one edge (two concave edges)\n"
        "--size N       voxels per axis of the cubic box (default 100; 16..1024)\n"
        "--noise S      standard deviation of the additive Gaussian noise, intensity units (default 0)\n"
        "--seed K       noise seed, a non-negative integer (default 1; same seed, same volume)\n"
        "-h, --help     this text\n"
        "\n"
        "Exit codes: 0 success, 1 bad input or parameters, 2 internal failure.\n",
        shapes.c_str());
}

} // namespace

int main(int argc, char** argv)
{
    std::string shape, output;
    int size = 100;
    double noise = 0;
    std::uint64_t seed = 1;
    try {
        std::vector<std::string> positional;
        for (int i = 1; i < argc; ++i) {
            const std::string a = argv[i];
            auto value = [&]() -> std::string {
                if (i + 1 >= argc) throw BadInput(a + ": missing value");
                return argv[++i];
            };
            if (a == "-h" || a == "--help") {
                usage(stdout);
                return 0;
            } else if (a == "--size") {
                const double v = parseNumber(a, value());
                if (v != std::floor(v) || v < 16 || v > 1024) throw BadInput("--size: must be an integer in [16, 1024]");
                size = int(v);
            } else if (a == "--noise") {
                noise = parseNumber(a, value());
                if (noise < 0) throw BadInput("--noise: must be >= 0");
            } else if (a == "--seed") {
                const std::string t = value();
                char* end = nullptr;
                errno = 0;
                const unsigned long long v = std::strtoull(t.c_str(), &end, 10);
                if (t.empty() || t[0] == '-' || *end != '\0' || errno == ERANGE)
                    throw BadInput("--seed: '" + t + "' is not a non-negative integer");
                seed = v;
            } else if (a.size() > 1 && a[0] == '-') {
                throw BadInput("unknown option '" + a + "' (see --help)");
            } else {
                positional.push_back(a);
            }
        }
        if (positional.size() != 2) throw BadInput("expected SHAPE and OUTPUT.vdb (see --help)");
        shape = positional[0];
        output = positional[1];
        const auto shapes = riemesh::vdb::phantomShapes();
        bool known = false;
        for (const auto& s : shapes) known |= (s == shape);
        if (!known) {
            std::string list;
            for (const auto& s : shapes) list += (list.empty() ? "" : ", ") + s;
            throw BadInput("unknown shape '" + shape + "' (shapes: " + list + ")");
        }
        if (riemesh::vdb::fileExtension(output) != ".vdb") throw BadInput("'" + output + "': output must be a .vdb file");
        const std::filesystem::path dir = std::filesystem::path(output).has_parent_path()
                                              ? std::filesystem::path(output).parent_path() : std::filesystem::path(".");
        if (!std::filesystem::is_directory(dir))
            throw BadInput("'" + output + "': output folder '" + dir.string() + "' does not exist");
    } catch (const std::exception& e) {
        std::fprintf(stderr, "vdbphantom: error: %s\n", e.what());
        return 1;
    }
    try {
        riemesh::vdb::writePhantom(shape, output, size, noise, seed);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "vdbphantom: error: %s\n", e.what());
        return 2;
    }
    return 0;
}
