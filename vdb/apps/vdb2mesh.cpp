// vdb2mesh INPUT OUTPUT [options]: an adaptive mesh of an isosurface with the Taton-Lachaud deformable
// model. Thin: parse and check everything, call riemesh::vdb and riemesh, report.
#include "riemesh/evolution.h"
#include "riemesh/mesh_io.h"
#include "riemesh/self_intersection.h"
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

        if (args.init == "box") {
        } else if (args.init.rfind("sphere:", 0) == 0) {
            spheres = apps::parseSpheres(args.init.substr(7));
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
            volume = vdb::Volume::read(args.input, args.grid, args.maxMemory);
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
            m.tangentialGain = args.tangentialGain;
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
        opt.maxVertices = args.maxVertices;
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
        if (evo.reason == StopReason::VertexCap) {
            // A runaway mesh (delta too small for the image, or noise it keeps resolving): not a
            // result worth writing. A limit the user set, so exit 1 like other parameters.
            std::fprintf(stderr,
                         "vdb2mesh: error: the mesh grew past the vertex cap of %llu vertices (--max-vertices) "
                         "after %zu iterations; no output written (raise --delta or the cap)\n",
                         static_cast<unsigned long long>(args.maxVertices), evo.iterations.size());
            return 1;
        }

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
              << ", \"mu_max\": " << args.muMax << ", \"edge_gain\": " << args.tangentialGain << ", \"sigma_voxels\": " << args.sigma << ", \"rho_voxels\": "
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
