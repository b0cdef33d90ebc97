// vdb2mesh's command line (vdb2mesh_args.h).
#include "vdb2mesh_args.h"

#include "cli.h"
#include "riemesh/vdb/volume.h"

#include <cctype>
#include <cmath>
#include <filesystem>
#include <sstream>

#include <unistd.h>

namespace riemesh::apps {

namespace fs = std::filesystem;

void printVdb2MeshUsage(std::FILE* out)
{
    std::fprintf(out,
        "usage: vdb2mesh INPUT OUTPUT [options]\n"
        "\n"
        "Extracts the isosurface of a 3D image as a closed, oriented triangle mesh with the adaptive\n"
        "deformable model of Taton & Lachaud (2003): the mesh deflates from the image box onto the object,\n"
        "changes topology by itself, and samples the surface regularly in a Riemannian metric built from\n"
        "the image structure tensor (fine at edges and corners, coarse on flat parts).\n"
        "\n"
        "INPUT   .vdb (a scalar float/double grid), .nvdb (written by --export-nvdb), .nii or .nii.gz\n"
        "OUTPUT  .obj .ply (binary) .off .stl: the mesh, outward normals; .vdb: its level set \"surface\".\n"
        "        World space: the grid's transform; for NIfTI, scanner space (RAS, millimetres).\n"
        "\n"
        "Image\n"
        "  --grid NAME          grid to read from a .vdb (default: the first scalar grid)\n"
        "  --iso V              isovalue, image intensity (default: 0.5 for fog volumes, 0 for level\n"
        "                       sets; required for other images, e.g. --iso 40 for a T1 head MRI)\n"
        "  --smooth S           Gaussian smoothing of the image the model fits, voxels (default %g for\n"
        "                       images, 0 for level sets; 0 = off)\n"
        "  --downsample F       average F^3 voxel blocks first (integer, default 1 = off): a quick preview\n"
        "  --open-borders       where the object touches the image box (a head cut at the neck), let the\n"
        "                       surface follow the cut slice into the object; by default the object is\n"
        "                       closed just beyond the border, its footprint's enclosed holes filled\n"
        "Model\n"
        "  --metric M           riemannian | euclidean (default riemannian)\n"
        "  --delta D            shortest edge, metric length, voxels (default %g)\n"
        "  --zeta Z             longest/shortest edge ratio, >= 2 (default %g)\n"
        "  --mu-max M           largest metric eigenvalue, >= 1: resolution at contours x sqrt(M) (default %g)\n"
        "  --sigma S            structure tensor pre-smoothing, voxels (default %g)\n"
        "  --rho R              structure tensor window, voxels (default %g)\n"
        "  --edge-gain G        boost of the metric along edges and corners of the image, >= 1: 1 = the\n"
        "                       structure tensor as is; higher refines creases more (default %g)\n"
        "  --max-iterations N   iteration cap (default %d)\n"
        "  --max-vertices N     vertex cap: a mesh growing past N vertices stops the run with an error\n"
        "                       and no output (default %llu)\n"
        "  --levels L           coarse-to-fine: converge first with delta x 2^L on 2^L-voxel blocks of the\n"
        "                       image (their maxima, grown by half a block: thin parts kept),\n"
        "                       then halve down to the image itself (a level that would only refine a\n"
        "                       surface already next to the object is left out); auto (default) leaves\n"
        "                       the coarsest level about 16 edges across the image; 0 = the image only\n"
        "  --intersection-free  no iteration may make faces cross: continuous collision detection of\n"
        "                       every step, collapses, flips and cuts refused where faces would cross\n"
        "                       (off by default: the evolution then takes about 2x as long; a\n"
        "                       surface that crosses itself without it is evolved again with it)\n"
        "  --no-sharpen         leave creases and corners as the smoothed image rounds them; by default\n"
        "                       they are put back where the filtered face normals and the image both\n"
        "                       turn sharply across an edge (vertices fitted to the faces' planes, at\n"
        "                       most 2.5 voxels; phantom: Hausdorff 2.5 -> 1.4 voxels); --sharpen,\n"
        "                       the default, is still accepted\n"
        "  --face-samples       the image force is sampled at the faces' centres too, so that the\n"
        "                       faces, not just their corners, lie on the isosurface (phantoms:\n"
        "                       errors 20-40%% lower; ~25%% more time per iteration; it keeps specks\n"
        "                       of noise a voxel or two wide: off by default for now)\n"
        "  --init I             box (default): a box around each separate part of the object (found on\n"
        "                       the coarsest level), deflating; the image box when no part is found\n"
        "                       sphere:X,Y,Z,R[;X,Y,Z,R...]  bubbles, world units, inflating\n"
        "                       mesh:FILE  a closed mesh (.obj .ply .off .stl), world units\n"
        "Outputs\n"
        "  --export-nvdb FILE   the image the model fits and the metric as NanoVDB (web viewer input)\n"
        "  --write-metric FILE  the metric grids metric_diag/metric_off to a .vdb (Houdini, vdb_view)\n"
        "  --stats FILE         per-iteration log and final summary as JSON\n"
        "  --reference FILE[:GRID]  report the distance to a reference signed distance grid (default\n"
        "                       grid \"sdf\", as written by vdbphantom), both ways from dense samples\n"
        "                       of both surfaces: means, maxima and Hausdorff, voxels, and where the\n"
        "                       Hausdorff is (world coordinates, on the mesh or on the reference)\n"
        "Run\n"
        "  --threads N          worker threads for the volume stages and the evolution (default: all\n"
        "                       cores); the output is the same for any N\n"
        "  --max-memory BYTES   memory budget, bytes with an optional K/M/G/T suffix (default: half the\n"
        "                       physical memory); an image whose bounding box would need more is refused\n"
        "                       before it is loaded\n"
        "  -q, --quiet          no progress bar, no summary\n"
        "  -h, --help           this text\n"
        "\n"
        "A progress bar goes to stderr when it is a terminal; a one-line summary to stdout.\n"
        "Outputs are written to a temporary file beside the target and renamed: a failed or interrupted\n"
        "run leaves no partial file and an existing file untouched.\n"
        "Where the kernel gives transparent huge pages only to memory that asks (mode \"madvise\"),\n"
        "vdb2mesh restarts itself once with GLIBC_TUNABLES=glibc.malloc.hugetlb=1 (large volumes\n"
        "about 25%% faster); RIEMESH_MALLOC_HUGEPAGES=0 turns this off.\n"
        "Exit codes: 0 success, 1 bad input or parameters (or a limit reached), 2 internal failure,\n"
        "130 interrupted (Ctrl-C).\n",
        kSmooth, kDelta, kZeta, kMuMax, kSigma, kRho, kTangentialGain, kMaxIterations, static_cast<unsigned long long>(kMaxVertices));
}

namespace {

double parseCount(const std::string& flag, const std::string& text, double lo, double hi)
{
    const double v = parseNumber(flag, text);
    if (v != std::floor(v) || v < lo || v > hi) {
        std::ostringstream msg;
        msg << flag << ": '" << text << "' must be an integer in [" << lo << ", " << hi << "]";
        throw BadInput(msg.str());
    }
    return v;
}

} // namespace

std::uint64_t parseByteCount(const std::string& flag, const std::string& text)
{
    std::string number = text;
    double unit = 1;
    if (!number.empty()) {
        switch (std::toupper(static_cast<unsigned char>(number.back()))) {
        case 'K': unit = 1024.0; break;
        case 'M': unit = 1024.0 * 1024; break;
        case 'G': unit = 1024.0 * 1024 * 1024; break;
        case 'T': unit = 1024.0 * 1024 * 1024 * 1024; break;
        }
        if (unit != 1) number.pop_back();
    }
    const double v = parseNumber(flag, number) * unit;
    // Below a megabyte nothing can run; above 2^60 the count no longer fits comfortably in 64 bits.
    if (!(v >= 1024.0 * 1024) || v > 1152921504606846976.0)
        throw BadInput(flag + ": '" + text + "' must be a byte count between 1M and 1048576T");
    return std::uint64_t(v);
}

Vdb2MeshArgs parseVdb2MeshArgs(int argc, const char* const* argv)
{
    Vdb2MeshArgs a;
    std::vector<std::string> positional;
    for (int i = 1; i < argc; ++i) {
        const std::string f = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) throw BadInput(f + ": missing value");
            return argv[++i];
        };
        auto positive = [&](double& out) {
            out = parseNumber(f, value());
            if (!(out > 0)) throw BadInput(f + ": must be > 0 (got " + argv[i] + ")");
        };
        if (f == "-h" || f == "--help") {
            a.help = true;
            return a;
        }
        else if (f == "--grid") a.grid = value();
        else if (f == "--iso") a.iso = parseNumber(f, value());
        else if (f == "--metric") {
            const std::string m = value();
            if (m == "riemannian") a.riemannian = true;
            else if (m == "euclidean") a.riemannian = false;
            else throw BadInput("--metric: '" + m + "' is not riemannian or euclidean");
        }
        else if (f == "--delta") positive(a.delta);
        else if (f == "--zeta") {
            a.zeta = parseNumber(f, value());
            if (!(a.zeta >= 2)) throw BadInput("--zeta: must be >= 2 so that both halves of a split edge stay >= delta (got " + std::string(argv[i]) + ")");
        }
        else if (f == "--mu-max") {
            a.muMax = parseNumber(f, value());
            if (!(a.muMax >= 1) || a.muMax > 10000) throw BadInput("--mu-max: must be in [1, 10000] (got " + std::string(argv[i]) + ")");
        }
        else if (f == "--sigma") positive(a.sigma);
        else if (f == "--rho") positive(a.rho);
        else if (f == "--edge-gain") {
            a.tangentialGain = parseNumber(f, value());
            if (!(a.tangentialGain >= 1) || a.tangentialGain > 1000)
                throw BadInput("--edge-gain: must be in [1, 1000] (got " + std::string(argv[i]) + ")");
        }
        else if (f == "--smooth") {
            a.smooth = parseNumber(f, value());
            if (!(a.smooth >= 0)) throw BadInput("--smooth: must be >= 0");
        }
        else if (f == "--max-iterations") a.maxIterations = int(parseCount(f, value(), 1, 1e9));
        else if (f == "--max-vertices") a.maxVertices = std::uint64_t(parseCount(f, value(), 4, 1e12));
        else if (f == "--max-memory") a.maxMemory = parseByteCount(f, value());
        else if (f == "--init") a.init = value();
        else if (f == "--export-nvdb") a.exportNvdb = value();
        else if (f == "--write-metric") a.writeMetric = value();
        else if (f == "--stats") a.stats = value();
        else if (f == "--reference") a.reference = value();
        else if (f == "--threads") a.threads = int(parseCount(f, value(), 1, 65536));
        else if (f == "-q" || f == "--quiet") a.quiet = true;
        else if (f == "--open-borders") a.openBorders = true;
        else if (f == "--intersection-free") a.intersectionFree = true;
        else if (f == "--sharpen") a.sharpen = true;
        else if (f == "--no-sharpen") a.sharpen = false;
        else if (f == "--face-samples") a.faceSamples = true;
        else if (f == "--downsample") a.downsample = int(parseCount(f, value(), 1, 64));
        else if (f == "--levels") {
            const std::string v = value();
            a.levels = v == "auto" ? -1 : int(parseCount(f, v, 0, 12));
        }
        else if (f.size() > 1 && f[0] == '-') throw BadInput("unknown option '" + f + "' (see --help)");
        else positional.push_back(f);
    }
    if (positional.size() != 2) throw BadInput("expected INPUT and OUTPUT (see --help)");
    a.input = positional[0];
    a.output = positional[1];
    return a;
}

void checkOutputPath(const std::string& path, const std::vector<std::string>& extensions, const char* what)
{
    const std::string ext = riemesh::vdb::fileExtension(path);
    bool ok = false;
    std::string list;
    for (const auto& e : extensions) {
        ok |= (ext == e);
        list += (list.empty() ? "" : " ") + e;
    }
    if (!ok)
        throw BadInput("'" + path + "': unknown " + what + " extension '" + ext + "' (expected " + list + ")");
    const fs::path p(path);
    const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) throw BadInput("'" + path + "': output folder '" + dir.string() + "' does not exist");
    if (fs::is_directory(p, ec)) throw BadInput("'" + path + "': is a directory");
    // Checked now, not after minutes of work; root passes this check whatever the permissions.
    if (::access(dir.c_str(), W_OK | X_OK) != 0)
        throw BadInput("'" + path + "': output folder '" + dir.string() + "' is not writable");
}

std::vector<std::pair<Vec3, double>> parseSpheres(const std::string& spec)
{
    try {
        return vdb::parseSpheres(spec);
    } catch (const vdb::PipelineInputError& e) {
        throw BadInput(e.what());
    }
}

} // namespace riemesh::apps
