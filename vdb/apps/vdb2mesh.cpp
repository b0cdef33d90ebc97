// vdb2mesh INPUT OUTPUT [options]: an adaptive mesh of an isosurface with the Taton-Lachaud deformable
// model. Thin: parse and check everything, call riemesh::vdb and riemesh, report.
#include "riemesh/mesh_io.h"
#include "riemesh/vdb/pipeline.h"
#include "riemesh/vdb/volume.h"

#include "cli.h"
#include "vdb2mesh_args.h"

#include <atomic>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <gnu/libc-version.h>
#include <unistd.h>
#include <utility>
#include <vector>

namespace {

namespace fs = std::filesystem;

/// Bad input or parameters: exit 1.
using riemesh::apps::BadInput;
using riemesh::apps::parseCount;
using riemesh::apps::parseNumber;
using Args = riemesh::apps::Vdb2MeshArgs;

volatile std::sig_atomic_t gInterrupted = 0;
extern "C" void onSigint(int)
{
    gInterrupted = 1;
    std::signal(SIGINT, SIG_DFL); // a second Ctrl-C kills at once
}

class ProgressBar {
public:
    ProgressBar(bool enabled, int maxIterations, bool intersectionFree)
        : mEnabled(enabled), mMax(maxIterations), mIntersectionFree(intersectionFree)
    {
    }
    void update(const riemesh::IterationStats& s)
    {
        if (!mEnabled) return;
        if (s.intersectionFree && !mIntersectionFree) { // the default mode tangled (EvolutionOptions::untangle)
            mIntersectionFree = true;
            std::fprintf(stderr, "\r%*s\rvdb2mesh: the surface tangled; evolving it again from the start with "
                                 "--intersection-free\n", 90, "");
        }
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
    bool mIntersectionFree; ///< the evolution runs (or was asked to run) with the guarantee
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

/// Starts this program again (same process, arguments, descriptors) with malloc advising its memory
/// for transparent huge pages, where that helps: the kernel gives huge pages only to advised
/// memory ("madvise", the mode of this VM and of many distributions), and glibc (>= 2.35) advises
/// malloc's memory only when the tunable is set before the program starts. The volume stages
/// allocate hundreds of thousands of small OpenVDB nodes; at about 15 us per 4 KB page fault on
/// the 2-core VM the benchmarks run on, the phantom 400^3 took 9-11 s with 318k page faults, and
/// 6.8-7.3 s with 46k once malloc used huge pages (peak memory +0.3-2%); the head MRI 1.35-1.59 s
/// against 0.94-1.23 s. The second start costs about 0.1 s (loading the shared libraries).
/// Not done when RIEMESH_MALLOC_HUGEPAGES=0, when the tunable is already set (or the restart did
/// not take), under valgrind (the restarted program would run outside it), when glibc is older or
/// the kernel's mode is not "madvise"; on any failure the program simply goes on as it is.
void restartWithHugePageMalloc(char** argv)
{
    if (const char* off = std::getenv("RIEMESH_MALLOC_HUGEPAGES"); off && std::strcmp(off, "0") == 0) return;
    const char* tunables = std::getenv("GLIBC_TUNABLES");
    if (tunables && std::strstr(tunables, "glibc.malloc.hugetlb")) return;
    if (const char* preload = std::getenv("LD_PRELOAD"); preload && std::strstr(preload, "vgpreload")) return;
    int major = 0, minor = 0;
    if (std::sscanf(gnu_get_libc_version(), "%d.%d", &major, &minor) != 2 || major < 2 || (major == 2 && minor < 35)) return;
    std::string mode;
    std::getline(std::ifstream("/sys/kernel/mm/transparent_hugepage/enabled"), mode);
    if (mode.find("[madvise]") == std::string::npos) return;
    const std::string tunable = riemesh::vdb::kHugePageMallocTunable;
    const std::string value = tunables && *tunables ? std::string(tunables) + ":" + tunable : tunable;
    if (::setenv("GLIBC_TUNABLES", value.c_str(), 1) != 0) return;
    std::fflush(nullptr);
    ::execv("/proc/self/exe", argv); // returns only on failure
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
    vdb::PipelineOptions options;
    std::string referencePath, referenceGrid = "sdf";
    double readSeconds = 0;
    try {
        args = apps::parseVdb2MeshArgs(argc, argv);
        if (args.help) {
            apps::printVdb2MeshUsage(stdout);
            return 0;
        }
        apps::checkOutputPath(args.output, {".obj", ".ply", ".off", ".stl", ".vdb"}, "output");
        if (!args.exportNvdb.empty()) apps::checkOutputPath(args.exportNvdb, {".nvdb"}, "--export-nvdb");
        if (!args.writeMetric.empty()) {
            apps::checkOutputPath(args.writeMetric, {".vdb"}, "--write-metric");
            if (!args.riemannian) throw BadInput("--write-metric: there is no metric with --metric euclidean");
        }
        if (!args.stats.empty()) apps::checkOutputPath(args.stats, {".json"}, "--stats");
        // The arguments are sound: from here on the work is long enough for malloc's huge pages to
        // pay for a second start (nothing has been read or written yet).
        restartWithHugePageMalloc(argv);

        options.iso = args.iso;
        options.riemannian = args.riemannian;
        options.delta = args.delta;
        options.zeta = args.zeta;
        options.muMax = args.muMax;
        options.sigma = args.sigma;
        options.rho = args.rho;
        options.tangentialGain = args.tangentialGain;
        if (args.smooth >= 0) options.smooth = args.smooth;
        options.maxIterations = args.maxIterations;
        options.maxVertices = args.maxVertices;
        options.openBorders = args.openBorders;
        options.intersectionFree = args.intersectionFree;
        options.sharpen = args.sharpen;
        options.faceSamples = args.faceSamples;
        options.downsample = args.downsample;
        options.levels = args.levels;
        options.threads = args.threads;
        options.init = vdb::parseInitialSurface(args.init); // reads an --init mesh now, before the image
        vdb::checkPipelineOptions(options);

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
            volume = vdb::Volume::read(args.input, args.grid, args.maxMemory);
        } catch (const std::exception& e) {
            throw BadInput(e.what());
        }
        readSeconds = secondsSince(readStart);
        if (args.downsample == 1) vdb::pipelineIso(volume.info(), args.iso, args.input); // else checked after it
    } catch (const std::exception& e) {
        std::fprintf(stderr, "vdb2mesh: error: %s\n", oneLine(e.what()).c_str());
        return 1;
    }

    // ---- Phase 2: the work (exit 2 on failure, 130 when interrupted; 1 for a limit reached). ----
    const bool tty = !args.quiet && ::isatty(STDERR_FILENO);
    const auto interrupted = [&]() {
        if (tty) std::fprintf(stderr, "\n");
        std::fprintf(stderr, "vdb2mesh: interrupted, no output written\n");
        return 130;
    };
    if (gInterrupted) return interrupted();
    ProgressBar bar(tty, args.maxIterations, options.intersectionFree);
    try {
        options.progress = [&](vdb::PipelineStage stage, const IterationStats* s) {
            if (s) {
                bar.update(*s);
            } else if (stage == vdb::PipelineStage::Borders) {
                const auto& info = volume.info();
                if (tty) std::fprintf(stderr, "vdb2mesh: %s '%s' %dx%dx%d, metric...", info.format.c_str(),
                                      info.gridName.c_str(), info.dims[0], info.dims[1], info.dims[2]);
            } else if (stage == vdb::PipelineStage::Evolve) {
                if (tty) std::fprintf(stderr, "\r%*s\r", 100, "");
                if (gInterrupted) return false;
                // The image the model fits and its metric, before the evolution (also when it fails).
                if (!args.writeMetric.empty()) volume.writeMetric(args.writeMetric);
                if (!args.exportNvdb.empty())
                    volume.exportNanoVDB(args.exportNvdb, vdb::pipelineIso(volume.info(), args.iso, args.input).first);
            }
            return gInterrupted == 0;
        };
        vdb::PipelineResult result;
        try {
            result = vdb::meshVolume(volume, options);
        } catch (const vdb::PipelineInputError& e) {
            bar.finish();
            std::fprintf(stderr, "vdb2mesh: error: %s\n", oneLine(e.what()).c_str());
            return 1;
        }
        bar.finish();
        if (gInterrupted || result.stop == StopReason::Interrupted) return interrupted();
        const Mesh& mesh = result.mesh;
        const auto& info = result.image;

        const auto writeStart = std::chrono::steady_clock::now();
        if (vdb::fileExtension(args.output) == ".vdb") {
            volume.writeSurfaceLevelSet(args.output, mesh);
        } else {
            writeMesh(args.output, mesh,
                      "riemesh vdb2mesh from " + fs::path(args.input).filename().string() + "; world space: " +
                          info.transformNote);
        }
        const double writeSeconds = secondsSince(writeStart);
        const MeshTopology& topo = result.topology;
        const std::size_t selfIntersections = result.selfIntersections;
        const EvolutionStats& evo = result.evolution;
        const double seconds = secondsSince(start);

        vdb::PipelineRecord record;
        record.input = args.input;
        record.output = args.output;
        record.readSeconds = readSeconds;
        record.writeSeconds = writeSeconds;
        record.totalSeconds = seconds;
        if (!referencePath.empty()) record.reference = vdb::compareToReference(mesh, referencePath, referenceGrid);
        const auto& ref = record.reference;

        if (!args.stats.empty()) {
            const std::string text = vdb::pipelineStatsJson(result, record);
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
                        result.seconds.metric, evo.seconds);
            if (ref)
                std::printf("; vs reference (voxels): mesh->surface mean %.3f max %.3f, surface->mesh mean %.3f "
                            "max %.3f, Hausdorff %.3f (%s, at %.4g %.4g %.4g)",
                            ref->meanMeshToSurface / ref->voxelSize, ref->maxMeshToSurface / ref->voxelSize,
                            ref->meanSurfaceToMesh / ref->voxelSize, ref->maxSurfaceToMesh / ref->voxelSize,
                            ref->hausdorff / ref->voxelSize, ref->hausdorffOnMesh ? "a mesh point" : "a reference point",
                            ref->hausdorffAt[0], ref->hausdorffAt[1], ref->hausdorffAt[2]);
            std::printf("\n");
            if (evo.untangledAt > 0)
                std::printf("note: after iteration %d the surface %s; it was evolved again from the start with "
                            "--intersection-free, which keeps it embedded (give --intersection-free to start that way)\n",
                            evo.untangledAt,
                            evo.tangleInverted ? "had a part turned inside out"
                                               : ("crossed itself (" + std::to_string(evo.tangleCrossings) + " crossing face pairs)").c_str());
        }
        return 0;
    } catch (const std::exception& e) {
        bar.finish();
        std::fprintf(stderr, "vdb2mesh: error: %s\n", oneLine(e.what()).c_str());
        return 2;
    }
}
