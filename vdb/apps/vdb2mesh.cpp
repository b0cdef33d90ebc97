// vdb2mesh INPUT OUTPUT [options]: an adaptive mesh of an isosurface with the Taton-Lachaud deformable
// model. Thin: parse and check everything, call riemesh::vdb and riemesh, report.
#include "riemesh/evolution.h"
#include "riemesh/mesh_io.h"
#include "riemesh/self_intersection.h"
#include "riemesh/vdb/volume.h"

#include "cli.h"

#include <atomic>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <optional>
#include <sstream>
#include <string>
#include <unistd.h>
#include <utility>
#include <vector>

namespace {

namespace fs = std::filesystem;

// Defaults (documented in --help).
constexpr double kDelta = 3.0;      // voxels
constexpr double kZeta = 2.5;
constexpr double kMuMax = 9.0;
constexpr double kSigma = 1.0;      // voxels
constexpr double kRho = 2.0;        // voxels
constexpr double kSmooth = 1.0;     // voxels
constexpr int kMaxIterations = 3000;

/// Bad input or parameters: exit 1.
using riemesh::apps::BadInput;
using riemesh::apps::parseCount;
using riemesh::apps::parseNumber;

volatile std::sig_atomic_t gInterrupted = 0;
extern "C" void onSigint(int)
{
    gInterrupted = 1;
    std::signal(SIGINT, SIG_DFL); // a second Ctrl-C kills at once
}

struct Args {
    std::string input, output;
    std::string grid;
    std::optional<double> iso;
    bool riemannian = true;
    double delta = kDelta, zeta = kZeta, muMax = kMuMax, sigma = kSigma, rho = kRho, smooth = kSmooth;
    int maxIterations = kMaxIterations;
    std::string init = "box";
    std::string exportNvdb, writeMetric, stats, reference;
    int threads = 0;
    bool quiet = false;
    bool openBorders = false;
    int downsample = 1;
};

void usage(std::FILE* out)
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
        "  --smooth S           Gaussian smoothing of the image the model fits, voxels (default %g; 0 = off)\n"
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
        "  --max-iterations N   iteration cap (default %d)\n"
        "  --init I             box (default: the image box inset by a voxel, deflating)\n"
        "                       sphere:X,Y,Z,R[;X,Y,Z,R...]  bubbles, world units, inflating\n"
        "                       mesh:FILE  a closed mesh (.obj .ply .off .stl), world units\n"
        "Outputs\n"
        "  --export-nvdb FILE   the image the model fits and the metric as NanoVDB (web viewer input)\n"
        "  --write-metric FILE  the metric grids metric_diag/metric_off to a .vdb (Houdini, vdb_view)\n"
        "  --stats FILE         per-iteration log and final summary as JSON\n"
        "  --reference FILE[:GRID]  report the distance to a reference signed distance grid (default\n"
        "                       grid \"sdf\", as written by vdbphantom): mean and Hausdorff, voxels\n"
        "Run\n"
        "  --threads N          worker threads for the volume stages (default: all cores)\n"
        "  -q, --quiet          no progress bar, no summary\n"
        "  -h, --help           this text\n"
        "\n"
        "A progress bar goes to stderr when it is a terminal; a one-line summary to stdout.\n"
        "Outputs are written to a temporary file beside the target and renamed: a failed or interrupted\n"
        "run leaves no partial file and an existing file untouched.\n"
        "Exit codes: 0 success, 1 bad input or parameters, 2 internal failure, 130 interrupted (Ctrl-C).\n",
        kSmooth, kDelta, kZeta, kMuMax, kSigma, kRho, kMaxIterations);
}

Args parseArgs(int argc, char** argv)
{
    Args a;
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
        if (f == "-h" || f == "--help") { usage(stdout); std::exit(0); }
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
        else if (f == "--smooth") {
            a.smooth = parseNumber(f, value());
            if (!(a.smooth >= 0)) throw BadInput("--smooth: must be >= 0");
        }
        else if (f == "--max-iterations") a.maxIterations = parseCount(f, value(), 1);
        else if (f == "--init") a.init = value();
        else if (f == "--export-nvdb") a.exportNvdb = value();
        else if (f == "--write-metric") a.writeMetric = value();
        else if (f == "--stats") a.stats = value();
        else if (f == "--reference") a.reference = value();
        else if (f == "--threads") a.threads = parseCount(f, value(), 1);
        else if (f == "-q" || f == "--quiet") a.quiet = true;
        else if (f == "--open-borders") a.openBorders = true;
        else if (f == "--downsample") a.downsample = parseCount(f, value(), 1);
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
}

std::vector<std::pair<riemesh::Vec3, double>> parseSpheres(const std::string& spec)
{
    std::vector<std::pair<riemesh::Vec3, double>> spheres;
    std::stringstream all(spec);
    std::string one;
    while (std::getline(all, one, ';')) {
        std::stringstream parts(one);
        std::string t;
        std::vector<double> v;
        while (std::getline(parts, t, ',')) v.push_back(parseNumber("--init sphere", t));
        if (v.size() != 4) throw BadInput("--init sphere: '" + one + "' is not X,Y,Z,R");
        if (!(v[3] > 0)) throw BadInput("--init sphere: radius must be > 0 in '" + one + "'");
        spheres.push_back({riemesh::Vec3(v[0], v[1], v[2]), v[3]});
    }
    if (spheres.empty()) throw BadInput("--init sphere: no sphere given");
    return spheres;
}

std::string jsonString(const std::string& s)
{
    std::string out = "\"";
    for (char c : s) {
        if (c == '"' || c == '\\') out += '\\', out += c;
        else if (c == '\n') out += "\\n";
        else if (static_cast<unsigned char>(c) < 0x20) out += ' ';
        else out += c;
    }
    return out + "\"";
}

class ProgressBar {
public:
    ProgressBar(bool enabled, int maxIterations) : mEnabled(enabled), mMax(maxIterations) {}
    void update(const riemesh::IterationStats& s)
    {
        if (!mEnabled) return;
        const auto now = std::chrono::steady_clock::now();
        if (now - mLast < std::chrono::milliseconds(100)) return;
        mLast = now;
        const int width = 30;
        const int filled = std::min(width, int(double(s.iteration) / mMax * width));
        std::fprintf(stderr, "\r[%s%s] iteration %d  %zu vertices  energy %.2e ", std::string(filled, '#').c_str(),
                     std::string(width - filled, '.').c_str(), s.iteration, s.vertices, s.meanKineticEnergy);
        std::fflush(stderr);
        mDrawn = true;
    }
    void finish()
    {
        if (mDrawn) std::fprintf(stderr, "\r%*s\r", 90, "");
        mDrawn = false;
    }
private:
    bool mEnabled;
    int mMax;
    bool mDrawn = false;
    std::chrono::steady_clock::time_point mLast{};
};

/// One printable line of at most ~300 characters, whatever an exception carried.
std::string oneLine(const std::string& raw)
{
    std::string s;
    for (char c : raw) {
        const bool space = std::isspace(static_cast<unsigned char>(c)) || !std::isprint(static_cast<unsigned char>(c));
        if (space && (s.empty() || s.back() == ' ')) continue;
        s += space ? ' ' : c;
        if (s.size() > 300) return s + "...";
    }
    return s;
}

double secondsSince(std::chrono::steady_clock::time_point t)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

} // namespace

int main(int argc, char** argv)
{
    using namespace riemesh;
    const auto start = std::chrono::steady_clock::now();
    // From the start, so that Ctrl-C while the input is read also ends cleanly (exit 130, a message).
    std::signal(SIGINT, onSigint);

    // ---- Phase 1: everything that can be wrong with the input, before any long work (exit 1). ----
    Args args;
    vdb::Volume volume;
    Mesh initMesh;
    bool haveInitMesh = false;
    std::vector<std::pair<Vec3, double>> spheres;
    double iso = 0;
    bool objectBrighter = true;
    std::string referencePath, referenceGrid = "sdf";
    double readSeconds = 0;
    try {
        args = parseArgs(argc, argv);
        checkOutputPath(args.output, {".obj", ".ply", ".off", ".stl", ".vdb"}, "output");
        if (!args.exportNvdb.empty()) checkOutputPath(args.exportNvdb, {".nvdb"}, "--export-nvdb");
        if (!args.writeMetric.empty()) {
            checkOutputPath(args.writeMetric, {".vdb"}, "--write-metric");
            if (!args.riemannian) throw BadInput("--write-metric: there is no metric with --metric euclidean");
        }
        if (!args.stats.empty()) checkOutputPath(args.stats, {".json"}, "--stats");

        if (args.init == "box") {
        } else if (args.init.rfind("sphere:", 0) == 0) {
            spheres = parseSpheres(args.init.substr(7));
        } else if (args.init.rfind("mesh:", 0) == 0) {
            const std::string file = args.init.substr(5);
            try {
                initMesh = readMesh(file);
            } catch (const std::exception& e) {
                throw BadInput(std::string("--init mesh: ") + e.what());
            }
            if (initMesh.n_faces() == 0) throw BadInput("--init mesh: '" + file + "' has no faces");
            haveInitMesh = true;
        } else {
            throw BadInput("--init: '" + args.init + "' is not box, sphere:X,Y,Z,R[;...] or mesh:FILE");
        }

        if (!args.reference.empty()) {
            referencePath = args.reference;
            const auto colon = referencePath.rfind(':');
            if (colon != std::string::npos && colon + 1 < referencePath.size() &&
                vdb::fileExtension(referencePath.substr(0, colon)) == ".vdb") {
                referenceGrid = referencePath.substr(colon + 1);
                referencePath = referencePath.substr(0, colon);
            }
            if (!fs::is_regular_file(referencePath)) throw BadInput("--reference: '" + referencePath + "': no such file");
        }

        const auto readStart = std::chrono::steady_clock::now();
        try {
            volume = vdb::Volume::read(args.input, args.grid);
        } catch (const std::exception& e) {
            throw BadInput(e.what());
        }
        if (args.downsample > 1) volume.downsample(args.downsample);
        readSeconds = secondsSince(readStart);
        const auto& info = volume.info();
        if (args.iso) {
            iso = *args.iso;
        } else if (info.gridClass == "fog") {
            iso = 0.5;
        } else if (info.gridClass == "levelset") {
            iso = 0.0;
        } else {
            std::ostringstream msg;
            msg << "'" << args.input << "': image '" << info.gridName
                << "' is neither a fog volume nor a level set: give --iso (its values range from " << info.minValue
                << " to " << info.maxValue << ")";
            throw BadInput(msg.str());
        }
        objectBrighter = info.gridClass != "levelset"; // level sets are negative inside
        if (!(iso > info.minValue && iso < info.maxValue)) {
            std::ostringstream msg;
            msg << "--iso " << iso << " is outside the values of image '" << info.gridName << "' (" << info.minValue
                << " to " << info.maxValue << "): there is no surface to extract";
            throw BadInput(msg.str());
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "vdb2mesh: error: %s\n", oneLine(e.what()).c_str());
        return 1;
    }

    // ---- Phase 2: the work (exit 2 on failure, 130 when interrupted). ----
    const bool tty = !args.quiet && ::isatty(STDERR_FILENO);
    const auto interrupted = [&]() {
        if (tty) std::fprintf(stderr, "\n");
        std::fprintf(stderr, "vdb2mesh: interrupted, no output written\n");
        return 130;
    };
    if (gInterrupted) return interrupted();
    try {
        auto threadLimit = vdb::limitThreads(args.threads);
        const auto& info = volume.info();
        const double h = info.voxelSize;

        const auto metricStart = std::chrono::steady_clock::now();
        if (tty) std::fprintf(stderr, "vdb2mesh: %s '%s' %dx%dx%d, metric...", info.format.c_str(),
                              info.gridName.c_str(), info.dims[0], info.dims[1], info.dims[2]);
        const std::uint64_t borderVoxels = args.openBorders ? 0 : volume.closeBorders(iso, objectBrighter);
        vdb::VolumeMetricStats metricStats;
        if (args.riemannian) {
            // The tensor is computed on the image as read (its own sigma); the forces see it smoothed.
            vdb::VolumeMetricOptions m;
            m.sigma = args.sigma;
            m.rho = args.rho;
            m.muMax = args.muMax;
            metricStats = volume.computeMetric(m);
        }
        volume.smooth(args.smooth);
        const NanoVolume nano = volume.nano();
        const double metricSeconds = secondsSince(metricStart);
        if (tty) std::fprintf(stderr, "\r%*s\r", 100, "");
        if (gInterrupted) return interrupted();

        if (!args.writeMetric.empty()) volume.writeMetric(args.writeMetric);
        if (!args.exportNvdb.empty()) volume.exportNanoVDB(args.exportNvdb, iso);

        NanoImage image(nano.imageGrid());
        EuclideanMetric euclidean;
        std::unique_ptr<NanoMetric> nanoMetric;
        if (args.riemannian && nano.metricDiag())
            nanoMetric = std::make_unique<NanoMetric>(nano.metricDiag(), nano.metricOff(), volume.metricMaxEigenvalue());
        const MetricField& metric = nanoMetric ? static_cast<const MetricField&>(*nanoMetric) : euclidean;

        EvolutionOptions opt;
        opt.delta = args.delta * h;
        opt.zeta = args.zeta;
        opt.maxIterations = args.maxIterations;
        opt.forces.iso = iso;
        opt.forces.objectBrighter = objectBrighter;
        ProgressBar bar(tty, args.maxIterations);
        opt.progress = [&](const IterationStats& s) {
            bar.update(s);
            return gInterrupted == 0;
        };

        const double initEdge = 0.5 * (1.0 + args.zeta) * opt.delta;
        Mesh mesh = haveInitMesh ? std::move(initMesh)
                    : spheres.empty() ? makeInitialBox(image, initEdge) : makeBubbles(spheres, initEdge);
        if (haveInitMesh) prepareMesh(mesh);

        const EvolutionStats evo = evolve(mesh, image, metric, opt);
        bar.finish();
        if (gInterrupted || evo.reason == StopReason::Interrupted) return interrupted();

        const auto writeStart = std::chrono::steady_clock::now();
        if (vdb::fileExtension(args.output) == ".vdb") {
            volume.writeSurfaceLevelSet(args.output, mesh);
        } else {
            writeMesh(args.output, mesh,
                      "riemesh vdb2mesh from " + fs::path(args.input).filename().string() + "; world space: " +
                          info.transformNote);
        }
        const double writeSeconds = secondsSince(writeStart);
        const MeshTopology topo = topologyOf(mesh);
        const std::size_t selfIntersections = findSelfIntersections(mesh).count(); // 0 for an embedded surface
        const double seconds = secondsSince(start);

        std::optional<vdb::ReferenceError> ref;
        if (!referencePath.empty()) ref = vdb::compareToReference(mesh, referencePath, referenceGrid);

        if (!args.stats.empty()) {
            std::ostringstream j;
            j << std::setprecision(9);
            j << "{\n  \"input\": " << jsonString(args.input) << ",\n  \"output\": " << jsonString(args.output)
              << ",\n  \"image\": {\"grid\": " << jsonString(info.gridName) << ", \"class\": " << jsonString(info.gridClass)
              << ", \"dims\": [" << info.dims[0] << ", " << info.dims[1] << ", " << info.dims[2]
              << "], \"voxel_size\": " << h << ", \"world_space\": " << jsonString(info.transformNote) << "},\n"
              << "  \"parameters\": {\"metric\": \"" << (args.riemannian ? "riemannian" : "euclidean")
              << "\", \"iso\": " << iso << ", \"delta_voxels\": " << args.delta << ", \"zeta\": " << args.zeta
              << ", \"mu_max\": " << args.muMax << ", \"sigma_voxels\": " << args.sigma << ", \"rho_voxels\": "
              << args.rho << ", \"smooth_voxels\": " << args.smooth << ", \"max_iterations\": " << args.maxIterations
              << ", \"init\": " << jsonString(args.init) << ", \"open_borders\": " << (args.openBorders ? "true" : "false")
              << ", \"border_voxels_added\": " << borderVoxels << ", \"downsample\": " << args.downsample << "},\n";
            if (args.riemannian)
                j << "  \"metric\": {\"active_voxels\": " << metricStats.activeVoxels << ", \"total_voxels\": "
                  << metricStats.totalVoxels << ", \"xi_ref\": " << metricStats.xiRef << ", \"threshold\": "
                  << metricStats.threshold << "},\n";
            j << "  \"iterations\": [";
            for (std::size_t i = 0; i < evo.iterations.size(); ++i) {
                const auto& s = evo.iterations[i];
                j << (i ? ",\n    " : "\n    ") << "{\"iteration\": " << s.iteration << ", \"vertices\": " << s.vertices
                  << ", \"mean_kinetic_energy\": " << s.meanKineticEnergy << ", \"splits\": " << s.splits
                  << ", \"collapses\": " << s.collapses << ", \"flips\": " << s.flips << ", \"merges\": " << s.merges
                  << ", \"cuts\": " << s.cuts << ", \"removed_components\": " << s.removedComponents
                  << ", \"travelling\": " << s.moving << ", \"ms\": " << s.milliseconds << "}";
            }
            j << "\n  ],\n  \"summary\": {\"vertices\": " << topo.vertices << ", \"faces\": " << topo.faces
              << ", \"components\": " << topo.components << ", \"genus\": " << topo.genus << ", \"euler\": " << topo.euler
              << ", \"self_intersections\": " << selfIntersections
              << ", \"iterations\": " << evo.iterations.size() << ", \"stop\": " << jsonString(toString(evo.reason))
              << ", \"seconds\": " << seconds << ", \"read_seconds\": " << readSeconds << ", \"metric_seconds\": "
              << metricSeconds << ", \"evolve_seconds\": " << evo.seconds << ", \"write_seconds\": " << writeSeconds
              << ", \"splits\": " << evo.splits << ", \"collapses\": " << evo.collapses << ", \"flips\": " << evo.flips
              << ", \"merges\": " << evo.merges << ", \"cuts\": " << evo.cuts << "}";
            if (ref)
                j << ",\n  \"reference\": {\"mean_voxels\": " << ref->mean / ref->voxelSize << ", \"max_vertex_voxels\": "
                  << ref->maxVertex / ref->voxelSize << ", \"max_surface_voxels\": " << ref->maxSurface / ref->voxelSize
                  << ", \"hausdorff_voxels\": " << ref->hausdorff / ref->voxelSize << "}";
            j << "\n}\n";
            const std::string text = j.str();
            vdb::writeFileAtomically(args.stats, [&](const std::string& temp) {
                std::ofstream out(temp, std::ios::binary);
                out << text;
                out.close();
                if (!out) throw std::runtime_error("'" + args.stats + "': write failed");
            });
        }

        if (!args.quiet) {
            std::printf("%s: %zu vertices, %zu faces, %d component%s, genus %d, %zu self-intersections, %zu iterations "
                        "(%s), %.2f s (metric %.2f, evolve %.2f)",
                        args.output.c_str(), topo.vertices, topo.faces, topo.components, topo.components == 1 ? "" : "s",
                        topo.genus, selfIntersections, evo.iterations.size(), toString(evo.reason), seconds,
                        metricSeconds, evo.seconds);
            if (ref)
                std::printf("; vs reference: mean %.3f, Hausdorff %.3f voxels", ref->mean / ref->voxelSize,
                            ref->hausdorff / ref->voxelSize);
            std::printf("\n");
        }
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "vdb2mesh: error: %s\n", oneLine(e.what()).c_str());
        return 2;
    }
}
