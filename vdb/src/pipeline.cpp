// The converter's pipeline after reading (pipeline.h): no OpenVDB include, everything goes through Volume.
#include "riemesh/vdb/pipeline.h"
#include "riemesh/sharpen.h"

#include "riemesh/mesh_io.h"
#include "riemesh/self_intersection.h"

#include <nlohmann/json.hpp>

#include <cerrno>
#include <chrono>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <sstream>

namespace riemesh::vdb {

namespace {

double secondsSince(std::chrono::steady_clock::time_point t)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

/// A number as the message shows it ("1.5", "1e+10").
std::string shown(double v)
{
    std::ostringstream s;
    s << v;
    return s.str();
}

/// The whole of `text` as a finite number, or PipelineInputError naming `what`.
double parseFinite(const std::string& what, const std::string& text)
{
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || *end != '\0' || errno == ERANGE || !std::isfinite(v))
        throw PipelineInputError(what + ": '" + text + "' is not a number");
    return v;
}

using Json = nlohmann::ordered_json;

/// `j` on one line with a space after every ':' and ',' (nlohmann's compact form has none).
void writeInline(std::string& out, const Json& j)
{
    if (j.is_object()) {
        out += '{';
        bool first = true;
        for (const auto& [key, value] : j.items()) {
            out += first ? "" : ", ";
            first = false;
            out += Json(key).dump() + ": ";
            writeInline(out, value);
        }
        out += '}';
    } else if (j.is_array()) {
        out += '[';
        for (std::size_t i = 0; i < j.size(); ++i) {
            out += i ? ", " : "";
            writeInline(out, j[i]);
        }
        out += ']';
    } else {
        out += j.dump(-1, ' ', false, Json::error_handler_t::replace);
    }
}

} // namespace

const char* toString(PipelineStage stage)
{
    switch (stage) {
    case PipelineStage::Borders: return "borders";
    case PipelineStage::Metric: return "metric";
    case PipelineStage::Smooth: return "smooth";
    case PipelineStage::Convert: return "convert";
    case PipelineStage::Evolve: return "evolve";
    }
    return "?";
}

std::vector<std::pair<Vec3, double>> parseSpheres(const std::string& spec)
{
    std::vector<std::pair<Vec3, double>> spheres;
    std::stringstream all(spec);
    std::string one;
    while (std::getline(all, one, ';')) {
        std::stringstream parts(one);
        std::string t;
        std::vector<double> v;
        while (std::getline(parts, t, ',')) v.push_back(parseFinite("--init sphere", t));
        if (v.size() != 4) throw PipelineInputError("--init sphere: '" + one + "' is not X,Y,Z,R");
        if (!(v[3] > 0)) throw PipelineInputError("--init sphere: radius must be > 0 in '" + one + "'");
        spheres.push_back({Vec3(v[0], v[1], v[2]), v[3]});
    }
    if (spheres.empty()) throw PipelineInputError("--init sphere: no sphere given");
    return spheres;
}

InitialSurface parseInitialSurface(const std::string& spec)
{
    InitialSurface init;
    init.spec = spec;
    if (spec == "box") {
        init.kind = InitialSurface::Kind::Box;
    } else if (spec.rfind("sphere:", 0) == 0) {
        init.kind = InitialSurface::Kind::Spheres;
        init.spheres = parseSpheres(spec.substr(7));
    } else if (spec.rfind("mesh:", 0) == 0) {
        const std::string file = spec.substr(5);
        init.kind = InitialSurface::Kind::Mesh;
        try {
            init.mesh = readMesh(file);
        } catch (const std::exception& e) {
            throw PipelineInputError(std::string("--init mesh: ") + e.what());
        }
        if (init.mesh.n_faces() == 0) throw PipelineInputError("--init mesh: '" + file + "' has no faces");
    } else {
        throw PipelineInputError("--init: '" + spec + "' is not box, sphere:X,Y,Z,R[;...] or mesh:FILE");
    }
    return init;
}

void checkPipelineOptions(const PipelineOptions& o)
{
    const auto positive = [](const char* flag, double v) {
        if (!(v > 0) || !std::isfinite(v)) throw PipelineInputError(std::string(flag) + ": must be > 0 (got " + shown(v) + ")");
    };
    if (o.iso && !std::isfinite(*o.iso)) throw PipelineInputError("--iso: '" + shown(*o.iso) + "' is not a number");
    positive("--delta", o.delta);
    if (!(o.zeta >= 2) || !std::isfinite(o.zeta))
        throw PipelineInputError("--zeta: must be >= 2 so that both halves of a split edge stay >= delta (got " +
                                 shown(o.zeta) + ")");
    if (!(o.muMax >= 1) || o.muMax > 10000) throw PipelineInputError("--mu-max: must be in [1, 10000] (got " + shown(o.muMax) + ")");
    positive("--sigma", o.sigma);
    positive("--rho", o.rho);
    if (!(o.tangentialGain >= 1) || o.tangentialGain > 1000)
        throw PipelineInputError("--edge-gain: must be in [1, 1000] (got " + shown(o.tangentialGain) + ")");
    if (o.smooth && (!(*o.smooth >= 0) || !std::isfinite(*o.smooth))) throw PipelineInputError("--smooth: must be >= 0");
    const auto count = [](const char* flag, double v, double lo, double hi) {
        if (v < lo || v > hi) {
            std::ostringstream msg;
            msg << flag << ": '" << v << "' must be an integer in [" << lo << ", " << hi << "]";
            throw PipelineInputError(msg.str());
        }
    };
    count("--max-iterations", o.maxIterations, 1, 1e9);
    count("--max-vertices", double(o.maxVertices), 4, 1e12);
    count("--downsample", o.downsample, 1, 64);
    count("--levels", o.levels, -1, 12);
    if (o.threads != 0) count("--threads", o.threads, 1, 65536);
    for (const auto& s : o.init.spheres)
        if (!(s.second > 0) || !s.first.allFinite()) throw PipelineInputError("--init sphere: radius must be > 0 and the centre finite");
}

int autoLevels(double longestSideVoxels, double deltaVoxels)
{
    int levels = 0;
    while (levels < 12 && std::ldexp(deltaVoxels, levels + 1) * kCoarsestEdges <= longestSideVoxels) ++levels;
    return levels;
}

std::pair<double, bool> pipelineIso(const ImageInfo& info, const std::optional<double>& givenIso, const std::string& source)
{
    double iso = 0;
    if (givenIso) {
        iso = *givenIso;
    } else if (info.gridClass == "fog") {
        iso = 0.5;
    } else if (info.gridClass == "levelset") {
        iso = 0.0;
    } else {
        std::ostringstream msg;
        if (!source.empty()) msg << "'" << source << "': ";
        msg << "image '" << info.gridName << "' is neither a fog volume nor a level set: give --iso (its values range from "
            << info.minValue << " to " << info.maxValue << ")";
        throw PipelineInputError(msg.str());
    }
    const bool objectBrighter = info.gridClass != "levelset"; // level sets are negative inside
    if (!(iso > info.minValue && iso < info.maxValue)) {
        std::ostringstream msg;
        msg << "--iso " << iso << " is outside the values of image '" << info.gridName << "' (" << info.minValue << " to "
            << info.maxValue << "): there is no surface to extract";
        throw PipelineInputError(msg.str());
    }
    return {iso, objectBrighter};
}

PipelineResult meshVolume(Volume& volume, const PipelineOptions& options)
{
    checkPipelineOptions(options);
    PipelineResult r;
    r.options = options;
    r.options.progress = nullptr;
    const auto report = [&](PipelineStage stage, const IterationStats* s) {
        return !options.progress || options.progress(stage, s);
    };

    const auto downsampleStart = std::chrono::steady_clock::now();
    if (options.downsample > 1) volume.downsample(options.downsample);
    r.seconds.downsample = secondsSince(downsampleStart);
    r.image = volume.info();
    const auto [iso, objectBrighter] = pipelineIso(r.image, options.iso, r.image.path);
    r.iso = iso;
    r.objectBrighter = objectBrighter;

    auto threadLimit = limitThreads(options.threads);
    const double h = r.image.voxelSize;

    const auto interrupted = [&](PipelineStage stage) {
        if (report(stage, nullptr)) return false;
        r.stop = r.evolution.reason = StopReason::Interrupted;
        return true;
    };
    const auto metricStart = std::chrono::steady_clock::now();
    if (interrupted(PipelineStage::Borders)) return r;
    auto lap = metricStart;
    const auto split = [&](double& seconds) {
        const auto now = std::chrono::steady_clock::now();
        seconds = std::chrono::duration<double>(now - lap).count();
        lap = now;
    };
    r.borderVoxels = options.openBorders ? 0 : volume.closeBorders(iso, objectBrighter);
    split(r.seconds.borders);
    if (options.riemannian) {
        if (interrupted(PipelineStage::Metric)) return r;
        // The tensor is computed on the image as read (its own sigma); the forces see it smoothed.
        VolumeMetricOptions m;
        m.sigma = options.sigma;
        m.rho = options.rho;
        m.muMax = options.muMax;
        m.tangentialGain = options.tangentialGain;
        r.metric = volume.computeMetric(m);
    }
    split(r.seconds.tensor);
    if (interrupted(PipelineStage::Smooth)) return r;
    r.options.smooth = options.smooth ? *options.smooth : r.image.gridClass == "levelset" ? 0.0 : kSmooth;
    volume.smooth(*r.options.smooth);
    split(r.seconds.smooth);
    const int longest = std::max({r.image.dims[0], r.image.dims[1], r.image.dims[2]});
    if (options.levels >= 0) {
        r.levels = volume.buildLevels(options.levels, objectBrighter, iso); // as many as asked
    } else {
        // Automatic: no level on which some part of the object would be less than kMinObjectEdges
        // edges long (the shrinking surface would collapse on it).
        r.levels = volume.buildLevels(autoLevels(longest, options.delta), objectBrighter, iso, kMinObjectEdges * options.delta);
    }
    split(r.seconds.levels);
    if (interrupted(PipelineStage::Convert)) return r;
    const std::shared_ptr<const NanoVolume> nanoVolume = volume.releaseToNano();
    const NanoVolume& nano = *nanoVolume;
    split(r.seconds.convert);
    r.seconds.metric = secondsSince(metricStart);
    if (interrupted(PipelineStage::Evolve)) return r;

    NanoImage image(nano.imageGrid());
    // Coarsest first, the image itself last.
    std::vector<std::unique_ptr<NanoImage>> coarse;
    std::vector<EvolutionLevel> levels;
    for (int l = nano.levelCount(); l >= 1; --l) {
        coarse.push_back(std::make_unique<NanoImage>(nano.levelGrid(l)));
        levels.push_back({coarse.back().get(), std::ldexp(1.0, l)});
    }
    levels.push_back({&image, 1.0});
    EuclideanMetric euclidean;
    std::unique_ptr<NanoMetric> nanoMetric;
    if (options.riemannian && nano.metricDiag())
        nanoMetric = std::make_unique<NanoMetric>(nano.metricDiag(), nano.metricOff(), volume.metricMaxEigenvalue());
    const MetricField& metric = nanoMetric ? static_cast<const MetricField&>(*nanoMetric) : euclidean;

    EvolutionOptions opt;
    opt.delta = options.delta * h;
    opt.zeta = options.zeta;
    opt.maxIterations = options.maxIterations;
    opt.maxVertices = options.maxVertices;
    opt.intersectionFree = options.intersectionFree;
    opt.forces.iso = iso;
    opt.forces.objectBrighter = objectBrighter;
    if (options.faceSamples) opt.forces.vertexShare = kFaceSampleVertexShare;
    if (options.progress) opt.progress = [&](const IterationStats& s) { return report(PipelineStage::Evolve, &s); };

    // The initial surface is sampled for the level it starts on (the coarsest).
    const double initEdge = 0.5 * (1.0 + options.zeta) * opt.delta * levels.front().scale;
    switch (options.init.kind) {
    case InitialSurface::Kind::Box: {
        // A box around each part of the object (found on 2^L-voxel blocks, or 2-voxel ones without
        // levels), a coarsest cell beyond the coarsest image's object, which is grown by half of one.
        std::vector<Box3> parts = volume.objectBoxes();
        const double grow = levels.size() > 1 ? 2.0 * levels.front().scale * h : 0.0;
        if (levels.size() == 1)
            for (Box3& p : parts) p = Box3(p.min() - Vec3::Constant(2 * h), p.max() + Vec3::Constant(2 * h));
        r.mesh = makeInitialBoxes(image, std::move(parts), initEdge, grow);
        break;
    }
    case InitialSurface::Kind::Spheres: r.mesh = makeBubbles(options.init.spheres, initEdge); break;
    case InitialSurface::Kind::Mesh:
        r.mesh = options.init.mesh;
        prepareMesh(r.mesh);
        break;
    }

    r.evolution = evolve(r.mesh, levels, metric, opt);
    r.stop = r.evolution.reason;
    r.seconds.evolve = r.evolution.seconds;
    if (r.stop == StopReason::Interrupted) return r;
    if (r.stop == StopReason::VertexCap) {
        // A runaway mesh (delta too small for the image, or noise it keeps resolving): not a result
        // worth keeping. A limit the user set, so a bad parameter.
        const auto& last = r.evolution.iterations.back();
        if (last.level > 0 && r.evolution.predictedVertices > options.maxVertices)
            throw PipelineInputError("the surface would need about " + std::to_string(r.evolution.predictedVertices) +
                                     " vertices at this delta, past the vertex cap of " + std::to_string(options.maxVertices) +
                                     " (--max-vertices): found on coarse level " + std::to_string(last.level) + " after " +
                                     std::to_string(r.evolution.iterations.size()) +
                                     " iterations; no output written (raise --delta or the cap)");
        throw PipelineInputError("the mesh grew past the vertex cap of " + std::to_string(options.maxVertices) +
                                 " vertices (--max-vertices) after " + std::to_string(r.evolution.iterations.size()) +
                                 " iterations; no output written (raise --delta or the cap)");
    }

    if (r.mesh.faces().begin() == r.mesh.faces().end()) {
        // Every part shrank away (an object a few edges across at this delta collapses and is
        // deleted as a speck): an empty mesh is no extraction of a surface the image has.
        std::ostringstream msg;
        msg << "no surface left after " << r.evolution.iterations.size()
            << " iterations: every part of the model shrank below a few edges of delta " << shown(options.delta)
            << " voxels and was removed; no output written (lower --delta or --smooth)";
        throw PipelineInputError(msg.str());
    }
    if (options.sharpen) { // kept only if it adds no crossing (sharpenFeaturesEmbedded)
        const SharpenStats ss = sharpenFeaturesEmbedded(r.mesh, imageSharpenOptions(image, iso, objectBrighter));
        r.sharpened = ss.moved;
        r.rimSplits = ss.rimSplits;
        r.creaseVertices = ss.creaseVertices;
        r.creaseFlips = ss.creaseFlips;
    }
    analyseResult(r);
    return r;
}

void analyseResult(PipelineResult& r)
{
    const auto start = std::chrono::steady_clock::now();
    r.topology = topologyOf(r.mesh);
    r.selfIntersections = findSelfIntersections(r.mesh).count(); // 0 for an embedded surface
    r.seconds.analysis = secondsSince(start);
}

/// Whether malloc advises its memory for transparent huge pages (kHugePageMallocTunable in effect).
static bool mallocHugePages()
{
    const char* t = std::getenv("GLIBC_TUNABLES");
    return t && std::strstr(t, kHugePageMallocTunable);
}

std::string pipelineStatsJson(const PipelineResult& r, const PipelineRecord& record)
{
    const auto& info = r.image;
    const auto& o = r.options;
    const auto orNull = [](const std::optional<std::string>& s) { return s ? Json(*s) : Json(nullptr); };
    Json j;
    j["input"] = orNull(record.input);
    j["output"] = orNull(record.output);
    j["image"] = {{"grid", info.gridName},
                  {"class", info.gridClass},
                  {"dims", {info.dims[0], info.dims[1], info.dims[2]}},
                  {"voxel_size", info.voxelSize},
                  {"world_space", info.transformNote}};
    j["parameters"] = {{"metric", o.riemannian ? "riemannian" : "euclidean"},
                       {"iso", r.iso},
                       {"delta_voxels", o.delta},
                       {"zeta", o.zeta},
                       {"mu_max", o.muMax},
                       {"edge_gain", o.tangentialGain},
                       {"sigma_voxels", o.sigma},
                       {"rho_voxels", o.rho},
                       {"smooth_voxels", o.smooth.value_or(kSmooth)},
                       {"max_iterations", o.maxIterations},
                       {"init", o.init.spec},
                       {"open_borders", o.openBorders},
                       {"intersection_free", o.intersectionFree},
                       {"sharpen", o.sharpen},
                       {"face_samples", o.faceSamples},
                       {"border_voxels_added", r.borderVoxels},
                       {"downsample", o.downsample},
                       {"levels", r.levels},
                       {"level_restarts", r.evolution.restarts},
                       {"levels_skipped", r.evolution.skippedLevels}};
    if (o.riemannian)
        j["metric"] = {{"active_voxels", r.metric.activeVoxels},
                       {"total_voxels", r.metric.totalVoxels},
                       {"xi_ref", r.metric.xiRef},
                       {"threshold", r.metric.threshold}};
    Json iterations = Json::array();
    for (const auto& s : r.evolution.iterations)
        iterations.push_back({{"iteration", s.iteration},
                              {"level", s.level},
                              {"vertices", s.vertices},
                              {"mean_kinetic_energy", s.meanKineticEnergy},
                              {"splits", s.splits},
                              {"collapses", s.collapses},
                              {"flips", s.flips},
                              {"merges", s.merges},
                              {"cuts", s.cuts},
                              {"removed_components", s.removedComponents},
                              {"travelling", s.moving},
                              {"intersection_free", s.intersectionFree},
                              {"cut_short", s.cutShort},
                              {"regularity_redone", s.regularityRedone},
                              {"ms", s.milliseconds}});
    j["iterations"] = std::move(iterations);
    const auto& e = r.evolution;
    IterationStats::Phases phases; // where the evolution's time went, summed over the iterations
    for (const auto& s : e.iterations) {
        phases.forces += s.phases.forces;
        phases.integration += s.phases.integration;
        phases.regularity += s.phases.regularity;
        phases.collisions += s.phases.collisions;
        phases.topology += s.phases.topology;
    }
    j["summary"] = {{"vertices", r.topology.vertices},
                    {"faces", r.topology.faces},
                    {"components", r.topology.components},
                    {"genus", r.topology.genus},
                    {"euler", r.topology.euler},
                    {"self_intersections", r.selfIntersections},
                    {"iterations", e.iterations.size()},
                    {"stop", toString(r.stop)},
                    // A tangled surface evolved again from the start with the guarantee (0: none).
                    {"untangled_at_iteration", e.untangledAt},
                    {"tangle_crossings", e.tangleCrossings},
                    {"tangle_inverted", e.tangleInverted},
                    {"seconds", record.totalSeconds},
                    {"read_seconds", record.readSeconds + r.seconds.downsample},
                    {"metric_seconds", r.seconds.metric},
                    {"stage_seconds", {{"borders", r.seconds.borders}, {"metric", r.seconds.tensor},
                                       {"smooth", r.seconds.smooth}, {"levels", r.seconds.levels},
                                       {"convert", r.seconds.convert}}},
                    {"evolve_seconds", r.seconds.evolve},
                    {"evolve_phase_seconds", {{"forces", 1e-3 * phases.forces},
                                              {"integration", 1e-3 * phases.integration},
                                              {"regularity", 1e-3 * phases.regularity},
                                              {"collisions", 1e-3 * phases.collisions},
                                              {"topology", 1e-3 * phases.topology}}},
                    {"write_seconds", record.writeSeconds},
                    {"malloc_huge_pages", mallocHugePages()},
                    {"sharpened_vertices", r.sharpened},
                    {"rim_splits", r.rimSplits},
                    {"crease_vertices", r.creaseVertices},
                    {"crease_flips", r.creaseFlips},
                    {"splits", e.splits},
                    {"collapses", e.collapses},
                    {"flips", e.flips},
                    {"merges", e.merges},
                    {"cuts", e.cuts}};
    if (record.reference) {
        const auto& ref = *record.reference;
        // mean_voxels: mesh -> surface (the figure every table has shown); both ways beside it.
        j["reference"] = {{"mean_voxels", ref.meanMeshToSurface / ref.voxelSize},
                          {"max_mesh_to_surface_voxels", ref.maxMeshToSurface / ref.voxelSize},
                          {"mean_surface_to_mesh_voxels", ref.meanSurfaceToMesh / ref.voxelSize},
                          {"max_surface_to_mesh_voxels", ref.maxSurfaceToMesh / ref.voxelSize},
                          {"analytic", ref.analytic},
                          {"hausdorff_voxels", ref.hausdorff / ref.voxelSize},
                          {"hausdorff_at", {ref.hausdorffAt[0], ref.hausdorffAt[1], ref.hausdorffAt[2]}},
                          {"hausdorff_on", ref.hausdorffOnMesh ? "mesh" : "reference"}};
    }
    // One line per section and per iteration, as vdb2mesh has always written it.
    std::string out = "{";
    bool first = true;
    for (const auto& [key, value] : j.items()) {
        out += first ? "\n  " : ",\n  ";
        first = false;
        out += Json(key).dump() + ": ";
        if (key == "iterations") {
            out += '[';
            for (std::size_t i = 0; i < value.size(); ++i) {
                out += i ? ",\n    " : "\n    ";
                writeInline(out, value[i]);
            }
            out += "\n  ]";
        } else {
            writeInline(out, value);
        }
    }
    return out + "\n}\n";
}

} // namespace riemesh::vdb
