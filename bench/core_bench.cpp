// core_bench: speed of the portable core on analytic images (no OpenVDB).
//
//   core_bench [--quick] [--scaling-only | --parallel-only]
//   core_bench --instructions   (the scaling sizes in instructions, under callgrind: see instructions())
//
// 1. Cost per iteration against the vertex count (1k, 5k, 20k, 80k vertices on a converged
//    sphere): one full iteration = forces, integration, regularity, collision, topology.
// 1b. The same step on 1 and on 2 threads at 20k and 80k vertices (Euclidean and a NanoVDB metric),
//    and the speed-up.
// 2. Full runs: a ball and the paper's phantom (a cube with a spherical cavity opening through a
//    hole in one face), Euclidean and Riemannian (an analytic metric that stretches lengths across
//    the contour), at a few resolutions: vertices, iterations, ms per iteration, total seconds,
//    topology.
// Prints one table per part; --quick runs a small subset (CI, through ctest: it fails only when a
// run does not end as one converged genus-0 surface; times are printed, never checked).
#include "contour_metric.h"
#include "riemesh/evolution.h"
#include "riemesh/primitives.h"
#include "riemesh/self_intersection.h"
#include "riemesh/threads.h"

#if __has_include(<valgrind/callgrind.h>)
#include <valgrind/callgrind.h>
#define RIEMESH_CALLGRIND 1
#endif

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#ifdef __linux__
#include <sched.h>
#endif

using namespace riemesh;

namespace {

double ballSdf(const Vec3& x, const Vec3& c, double r) { return r - (x - c).norm(); }

/// The paper's phantom in a 100^3 image (voxel units): a cube [20,80]^3 with a spherical cavity of
/// radius 20 at its centre, opened to the outside by a cylindrical hole of radius 4 along +z.
/// sdf > 0 inside the solid.
double phantomSdf(const Vec3& x, double scale)
{
    const Vec3 p = x / scale;
    const Vec3 c(50, 50, 50);
    const Vec3 d = (p - c).cwiseAbs() - Vec3::Constant(30);
    const double outside = d.cwiseMax(0.0).norm() + std::min(d.maxCoeff(), 0.0);
    const double cube = -outside;
    const double cavity = (p - c).norm() - 20;
    const double hole = p.z() > 50 ? std::hypot(p.x() - 50, p.y() - 50) - 4 : 1e9;
    return scale * std::min({cube, cavity, hole});
}

struct Scene {
    std::string name;
    std::function<double(const Vec3&)> sdf;
    Box3 bounds;
};

FunctionImage fog(const Scene& s)
{
    auto sdf = s.sdf;
    // Exact gradient of 0.5 + 0.5 tanh(sdf): 0.5 (1 - tanh^2) grad sdf, grad sdf by central differences.
    return FunctionImage([sdf](const Vec3& x) { return 0.5 + 0.5 * std::tanh(sdf(x)); }, s.bounds, 1.0,
                         [sdf](const Vec3& x) {
                             const double t = std::tanh(sdf(x));
                             Vec3 g;
                             for (int a = 0; a < 3; ++a) {
                                 Vec3 e = Vec3::Zero();
                                 e[a] = 0.25;
                                 g[a] = (sdf(x + e) - sdf(x - e)) / 0.5;
                             }
                             return Vec3(0.5 * (1 - t * t) * g);
                         });
}

using fixtures::ContourMetric;

/// The contour metric of the bench's scenes: a Gaussian band of sigma 3 voxels around the surface.
ContourMetric contourMetric(const std::function<double(const Vec3&)>& sdf, const Box3& bounds, double muMax)
{
    return fixtures::contourMetric(sdf, bounds, muMax, 3.0);
}

double now()
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// Processor time of the whole process (every thread), seconds.
double processorSeconds()
{
    timespec t{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

/// One size of the scaling table: a sphere settled at about `target` vertices whose evolution never
/// stops (every step a full iteration), with what its timed steps measured.
struct ScalingCase {
    int target = 0;
    std::unique_ptr<FunctionImage> image;
    std::unique_ptr<Mesh> mesh;
    EvolutionOptions options;
    std::unique_ptr<Evolution> evolution;
    int stepsPerRound = 1;
    std::vector<double> ms; ///< every timed step
    IterationStats::Phases sum;
    /// The peer: OpenMesh's own update_normals() (face normals, then each vertex's one ring) on a
    /// copy of the settled mesh, a plain linear pass timed in the same turns.
    std::unique_ptr<Mesh> peer;
    std::vector<double> peerMs;
};

/// The sizes 1k, 5k, 20k and 80k (1k and 5k when quick), settled, and a peer of the 80k row
/// without renumbering (EvolutionOptions::renumber off).
std::vector<ScalingCase> makeScalingCases(bool quick, const MetricField& metric,
                                          const std::vector<int>& targets = {1000, 5000, 20000, 80000, -80000})
{
    std::vector<ScalingCase> cases;
    for (int signedTarget : targets) {
        const int target = std::abs(signedTarget);
        if (quick && target > 5000) break;
        ScalingCase c;
        c.target = target;
        const double radius = 30;
        // Area per vertex on a regular mesh with edges ~1.6 delta: ~ 2.2 delta^2.
        const double delta = std::sqrt(4 * M_PI * radius * radius / (2.2 * target));
        Scene s{"ball", [radius](const Vec3& x) { return ballSdf(x, Vec3::Zero(), radius); },
                Box3(Vec3::Constant(-40), Vec3::Constant(40))};
        c.image = std::make_unique<FunctionImage>(fog(s));
        int sub = 0;
        while (20.0 * std::pow(4.0, sub) < 2.0 * target && sub < 8) ++sub;
        c.mesh = std::make_unique<Mesh>(makeIcosphere(Vec3::Zero(), radius, sub));
        EvolutionOptions& o = c.options;
        o.delta = delta;
        o.maxIterations = 1000000;
        o.minIterations = 1000000; // never converged: every timed step is a full iteration
        o.renumber = signedTarget > 0;
        c.evolution = std::make_unique<Evolution>(*c.mesh, *c.image, metric, o);
        for (int i = 0; i < 40; ++i) c.evolution->step(); // settle the sampling
        // The area per vertex is only roughly known: delta is corrected (area ~ 1/delta^2) until the
        // settled count is within 10% of the target.
        for (int round = 0; round < 4; ++round) {
            const double ratio = double(c.evolution->history().back().vertices) / target;
            if (std::abs(ratio - 1) < 0.1) break;
            o.delta *= std::sqrt(ratio);
            c.evolution->setOptions(o);
            for (int i = 0; i < 40; ++i) c.evolution->step();
        }
        // About 60 ms of steps per round (0.5 us per vertex and step as a first guess).
        c.stepsPerRound = std::clamp(int(60e3 / (0.5 * double(c.mesh->n_vertices()))), 2, 200);
        c.peer = std::make_unique<Mesh>(*c.mesh);
        c.peer->request_face_normals();
        c.peer->request_vertex_normals();
        cases.push_back(std::move(c));
    }
    return cases;
}

void scaling(bool quick)
{
    std::printf("\n# cost per iteration against vertex count (ball image, Euclidean, converged sphere)\n");
    // "growth": the exponent k of ms ~ vertices^k from the row above (1 = linear).
    EuclideanMetric metric;
    std::vector<ScalingCase> cases = makeScalingCases(quick, metric);
    // The sizes take turns (rounds), so that all of them meet the same machine: on a shared machine
    // the speed drifts by tens of percent within a minute, which one size after the other would read
    // as growth. In each turn the first step is not timed (it finds the caches full of the other
    // sizes' meshes); the row's figure is the median of its timed steps, the phases their means.
    const int rounds = quick ? 2 : 9;
    for (int round = 0; round < rounds; ++round)
        for (ScalingCase& c : cases) {
            c.evolution->step();
            for (int i = 0; i < c.stepsPerRound; ++i) {
                const double t0 = now();
                const IterationStats::Phases p = c.evolution->step().phases;
                c.ms.push_back((now() - t0) * 1000.0);
                c.sum.forces += p.forces, c.sum.integration += p.integration, c.sum.regularity += p.regularity;
                c.sum.collisions += p.collisions, c.sum.topology += p.topology;
            }
            c.peer->update_normals();
            for (int i = 0; i < c.stepsPerRound; ++i) {
                const double t0 = now();
                c.peer->update_normals();
                c.peerMs.push_back((now() - t0) * 1000.0);
            }
        }
    std::printf("%12s %10s %12s %14s %7s %8s %8s %8s %8s %8s %10s\n", "target", "vertices", "ms/iter", "us/iter/vertex",
                "growth", "forces", "integr.", "regul.", "collis.", "topol.", "peer us/v");
    auto median = [](std::vector<double>& t) {
        std::nth_element(t.begin(), t.begin() + long(t.size() / 2), t.end());
        return t[t.size() / 2];
    };
    double firstUs = 0, firstPeerUs = 0, lastUs = 0, lastPeerUs = 0;
    double lastMs = 0, lastVertices = 0;
    for (ScalingCase& c : cases) {
        const double ms = median(c.ms);
        const double n = double(c.ms.size());
        const double vertices = double(c.mesh->n_vertices());
        const bool renumbered = c.options.renumber;
        const std::string growth = renumbered && lastMs > 0
            ? std::to_string(std::log(ms / lastMs) / std::log(vertices / lastVertices)).substr(0, 4) : "";
        const double peerUs = 1000.0 * median(c.peerMs) / vertices;
        std::printf("%12s %10zu %12.3f %14.4f %7s %8.2f %8.2f %8.2f %8.2f %8.2f %10.4f\n",
                    (std::to_string(c.target) + (renumbered ? "" : " as-is")).c_str(), c.mesh->n_vertices(), ms,
                    1000.0 * ms / vertices, growth.c_str(), c.sum.forces / n, c.sum.integration / n,
                    c.sum.regularity / n, c.sum.collisions / n, c.sum.topology / n, peerUs);
        if (!renumbered) continue;
        lastMs = ms, lastVertices = vertices;
        lastUs = 1000.0 * ms / vertices, lastPeerUs = peerUs;
        if (firstUs == 0) firstUs = lastUs, firstPeerUs = peerUs;
    }
    std::printf("(%d rounds, the sizes in turn; ms/iter: median step; phases: mean ms; peer: OpenMesh "
                "update_normals() on a copy of the mesh, median)\n", rounds);
    std::printf("per-vertex cost, largest over smallest size: riemesh iteration %.2fx, OpenMesh update_normals %.2fx\n",
                lastUs / firstUs, lastPeerUs / firstPeerUs);
}

/// Runs the calling thread on processor `cpu` only (-1: on all it may use); false when that is not
/// possible (not Linux, or fewer processors).
bool pinCallingThread(int cpu)
{
#ifdef __linux__
    static cpu_set_t all;
    static const bool saved = sched_getaffinity(0, sizeof all, &all) == 0;
    if (!saved) return false;
    if (cpu < 0) return sched_setaffinity(0, sizeof all, &all) == 0;
    if (!CPU_ISSET(cpu, &all)) return false;
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(cpu, &one);
    return sched_setaffinity(0, sizeof one, &one) == 0;
#else
    (void)cpu;
    return false;
#endif
}

/// The evolve step on 1 and on 2 threads (riemesh::setThreadCount) at 20k and 80k vertices, on the
/// converged sphere of the scaling table, Euclidean and with a NanoVDB contour metric (the
/// vdb2mesh code path). The thread counts take turns step by step on the same evolving mesh (an
/// iteration of a converged sphere costs about the same from one step to the next), in pairs whose
/// order alternates, so that both meet the same machine. This one is a virtual machine whose
/// processors are not equally fast (host contention: a 1-thread step took 9 ms in one run and 18 ms
/// in the next, using 1.00 cores both times), which gave speed-ups above 2 on 2 cores. So the
/// 1-thread steps run pinned to each processor in turn, and the 1-thread figure is the median on
/// the faster one: the speed-up is measured against the best single core. Figures are medians of
/// the timed steps, phases their means.
/// "cores" is the processor time the 2-thread steps used per second: on a busy machine it stays
/// near 1, and the speed-up then says little about the code. "ceiling" is the most two threads
/// could give on these two processors at their own 1-thread speeds (1T cpu0, 1T cpu1), perfectly
/// balanced: 1 + fast / slow; one processor 1.55x slower than the other (seen on 2026-11-27:
/// the phantom 200^3 on one thread, 1.03-1.08 s pinned to processor 0, 1.56-1.68 s on 1) caps
/// the speed-up at 1.65x.
void parallelScaling(bool quick)
{
    std::printf("\n# evolve step on 1 and 2 threads (ball image, converged sphere; %s)\n",
                isParallel() ? "TBB" : "built without TBB: both serial");
    std::printf("%8s %-11s %9s %9s %9s %8s %6s   %-34s %-34s %9s %9s %8s\n", "target", "metric", "vertices", "ms 1T", "ms 2T", "speedup", "cores",
                "1T: forces integr regul collis topol", "2T: forces integr regul collis topol", "1T cpu0", "1T cpu1",
                "ceiling");
    const auto ball = [](const Vec3& x) { return ballSdf(x, Vec3::Zero(), 30); };
    ContourMetric contour = contourMetric(ball, Box3(Vec3::Constant(-40), Vec3::Constant(40)), 4.0);
    EuclideanMetric euclidean;
    const std::vector<int> targets = quick ? std::vector<int>{5000} : std::vector<int>{20000, 80000};
    for (int riemannian = 0; riemannian < 2; ++riemannian) {
        const MetricField& metric = riemannian ? static_cast<const MetricField&>(*contour.metric) : euclidean;
        setThreadCount(0);
        std::vector<ScalingCase> cases = makeScalingCases(false, metric, targets);
        for (ScalingCase& c : cases) {
            std::vector<double> ms[2], onCpu[2];
            IterationStats::Phases sum[2];
            double cpu2 = 0, wall2 = 0; // processor and wall seconds of the 2-thread steps
            const int pairs = (quick ? 2 : 7) * c.stepsPerRound;
            c.evolution->step();
            for (int pair = 0; pair < pairs; ++pair)
                for (int k = 0; k < 2; ++k) {
                    const int t = pair % 2 == 0 ? k : 1 - k;
                    setThreadCount(t + 1);
                    const int cpu = (pair / 2) % 2;
                    const bool pinned = t == 0 && pinCallingThread(cpu);
                    const double t0 = now(), c0 = processorSeconds();
                    const IterationStats::Phases p = c.evolution->step().phases;
                    const double stepMs = (now() - t0) * 1000.0;
                    if (t == 0) pinCallingThread(-1);
                    ms[t].push_back(stepMs);
                    if (t == 0) onCpu[pinned ? cpu : 0].push_back(stepMs);
                    if (t == 1) cpu2 += processorSeconds() - c0, wall2 += now() - t0;
                    sum[t].forces += p.forces, sum[t].integration += p.integration, sum[t].regularity += p.regularity;
                    sum[t].collisions += p.collisions, sum[t].topology += p.topology;
                }
            setThreadCount(0);
            auto median = [](std::vector<double> v) {
                std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
                return v[v.size() / 2];
            };
            const double m1cpu0 = median(onCpu[0]), m1cpu1 = onCpu[1].empty() ? 0.0 : median(onCpu[1]);
            const double m1 = onCpu[1].empty() ? m1cpu0 : std::min(m1cpu0, m1cpu1);
            // What two threads could give at best on these two processors, each at its own
            // 1-thread speed, perfectly balanced: 1 + fast/slow (2 on equal processors).
            const double ceiling = onCpu[1].empty() ? 0.0 : 1.0 + m1 / std::max(m1cpu0, m1cpu1);
            const double m2 = median(ms[1]), speedup = m1 / m2;
            char phases[2][64];
            for (int t = 0; t < 2; ++t) {
                const double n = double(ms[t].size());
                std::snprintf(phases[t], sizeof phases[t], "%6.2f %6.2f %6.2f %6.2f %6.2f", sum[t].forces / n,
                              sum[t].integration / n, sum[t].regularity / n, sum[t].collisions / n, sum[t].topology / n);
            }
            std::printf("%8d %-11s %9zu %9.2f %9.2f %7.2fx %6.2f   %-34s %-34s %9.2f %9.2f %7.2fx\n", c.target,
                        riemannian ? "riemannian" : "euclidean", c.mesh->n_vertices(), m1, m2, speedup,
                        wall2 > 0 ? cpu2 / wall2 : 0.0, phases[0], phases[1], m1cpu0, m1cpu1, ceiling);
            std::fflush(stdout);
        }
    }
}

/// --instructions: the scaling table's sizes counted in instructions instead of seconds, which the
/// machine's load and caches do not move: the program runs itself under callgrind (Debian valgrind)
/// with instrumentation off except during kCountedSteps steps of each size, each dumped with its
/// size, then reads the dumps. Instructions per vertex and step that stay flat mean an iteration's
/// work is linear in the vertex count; the time per vertex then differs only by the memory
/// hierarchy's costs.
constexpr int kCountedSteps = 5;

#ifdef RIEMESH_CALLGRIND
/// The child run under callgrind: each size's counted steps, dumped with its size.
int instructionsChild()
{
    EuclideanMetric metric;
    std::vector<ScalingCase> cases = makeScalingCases(false, metric);
    for (ScalingCase& c : cases) {
        c.evolution->step();
        CALLGRIND_START_INSTRUMENTATION;
        CALLGRIND_ZERO_STATS;
        for (int i = 0; i < kCountedSteps; ++i) c.evolution->step();
        const std::string label = "target=" + std::to_string(c.target) + " vertices=" +
                                  std::to_string(c.mesh->n_vertices()) + " renumber=" +
                                  std::to_string(int(c.options.renumber));
        CALLGRIND_DUMP_STATS_AT(label.c_str());
        CALLGRIND_STOP_INSTRUMENTATION;
    }
    return 0;
}
#endif

int instructions(const char* self)
{
#ifndef RIEMESH_CALLGRIND
    (void)self;
    std::printf("core_bench --instructions: built without valgrind/callgrind.h (Debian package valgrind)\n");
    return 1;
#else
    if (RUNNING_ON_VALGRIND) return instructionsChild();
    char dir[] = "/tmp/core_bench_callgrind.XXXXXX";
    if (!mkdtemp(dir)) return 1;
    const std::string out = std::string(dir) + "/cg.out";
    const std::string command = std::string("valgrind --tool=callgrind --instr-atstart=no --callgrind-out-file=") +
                                out + " '" + self + "' --instructions >" + dir + "/log 2>&1";
    std::printf("\n# instructions per iteration against vertex count (the scaling sizes, %d steps each under "
                "callgrind)\n", kCountedSteps);
    std::fflush(stdout);
    const int rc = std::system(command.c_str());
    std::printf("%12s %10s %16s %16s %7s\n", "target", "vertices", "instr/iter", "instr/iter/vertex", "growth");
    double lastCount = 0, lastVertices = 0;
    int rows = 0;
    for (int dump = 1;; ++dump) {
        std::ifstream in(out + "." + std::to_string(dump));
        if (!in) break;
        std::string line, label;
        double count = -1;
        while (std::getline(in, line)) {
            const std::string trigger = "desc: Trigger: Client Request: ";
            if (line.rfind(trigger, 0) == 0) label = line.substr(trigger.size());
            if (line.rfind("summary: ", 0) == 0 || line.rfind("totals: ", 0) == 0)
                count = std::atof(line.c_str() + line.find(' ') + 1);
        }
        int target = 0, renumber = 1;
        double vertices = 0;
        if (count < 0 || std::sscanf(label.c_str(), "target=%d vertices=%lf renumber=%d", &target, &vertices, &renumber) != 3)
            continue;
        const double perStep = count / kCountedSteps;
        const std::string growth = renumber && lastCount > 0
            ? std::to_string(std::log(perStep / lastCount) / std::log(vertices / lastVertices)).substr(0, 4) : "";
        std::printf("%12s %10.0f %16.0f %16.0f %7s\n", (std::to_string(target) + (renumber ? "" : " as-is")).c_str(),
                    vertices, perStep, perStep / vertices, growth.c_str());
        if (renumber) lastCount = perStep, lastVertices = vertices;
        ++rows;
    }
    std::filesystem::remove_all(dir);
    if (rc != 0 || rows == 0) {
        std::printf("core_bench --instructions: callgrind failed (exit %d); is valgrind installed?\n", rc);
        return 1;
    }
    return 0;
#endif
}

/// Runs the scenes; returns the number of runs that did not end as one converged genus-0 surface.
int fullRuns(bool quick)
{
    int unexpected = 0;
    std::printf("\n# full runs from the default initialisation (box deflating)\n");
    // guard: EvolutionOptions::intersectionFree (on, the default, then off: same run, the ratio of
    // their times after the second); crossings: face pairs of the result that cross.
    std::printf("%-10s %-11s %6s %6s %-5s %9s %7s %9s %9s %5s %5s %9s %-10s\n", "scene", "metric", "scale", "delta",
                "guard", "vertices", "iters", "ms/iter", "seconds", "comp", "genus", "crossings", "stop");
    std::vector<double> scales = quick ? std::vector<double>{1.0} : std::vector<double>{1.0, 2.0};
    for (double scale : scales) {
        std::vector<Scene> scenes = {
            {"ball", [scale](const Vec3& x) { return ballSdf(x, Vec3::Constant(50 * scale), 30 * scale); },
             Box3(Vec3::Zero(), Vec3::Constant(100 * scale))},
            {"phantom", [scale](const Vec3& x) { return phantomSdf(x, scale); },
             Box3(Vec3::Zero(), Vec3::Constant(100 * scale))},
        };
        for (const auto& s : scenes) {
            const auto image = fog(s);
            for (int riemannian = 0; riemannian < 2; ++riemannian) {
                double guarded = 0;
                for (int guard = 1; guard >= 0; --guard) {
                    EvolutionOptions o;
                    o.intersectionFree = guard != 0;
                    o.delta = riemannian ? 3.0 * scale : 1.5 * scale;
                    o.maxIterations = 3000;
                    EuclideanMetric euclidean;
                    ContourMetric contour;
                    if (riemannian) contour = contourMetric(s.sdf, s.bounds, 4.0);
                    const MetricField& metric = riemannian ? static_cast<const MetricField&>(*contour.metric) : euclidean;
                    Mesh mesh = makeInitialBox(image, 2.0 * o.delta);
                    const auto stats = evolve(mesh, image, metric, o);
                    const auto t = topologyOf(mesh);
                    const std::size_t crossings = findSelfIntersections(mesh).count();
                    std::printf("%-10s %-11s %6.0f %6.2f %-5s %9zu %7zu %9.3f %9.3f %5d %5d %9zu %-10s\n", s.name.c_str(),
                                riemannian ? "riemannian" : "euclidean", scale, o.delta, guard ? "on" : "off", t.vertices,
                                stats.iterations.size(), 1000.0 * stats.seconds / std::max<size_t>(1, stats.iterations.size()),
                                stats.seconds, t.components, t.genus, crossings, toString(stats.reason));
                    if (guard) guarded = stats.seconds;
                    else std::printf("  guard on / off: %.2fx the time\n", guarded / std::max(stats.seconds, 1e-9));
                    if (t.components != 1 || t.genus != 0 || stats.reason != StopReason::Converged) {
                        std::printf("  ^ unexpected: the %s should end as one converged genus-0 surface\n", s.name.c_str());
                        ++unexpected;
                    }
                    std::fflush(stdout);
                }
            }
        }
    }
    return unexpected;
}

} // namespace

int main(int argc, char** argv)
{
    const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
    if (argc > 1 && std::strcmp(argv[1], "--instructions") == 0) return instructions(argv[0]);
    // --scaling-only: just the per-iteration cost table (for profilers such as callgrind).
    const bool scalingOnly = argc > 1 && std::strcmp(argv[argc - 1], "--scaling-only") == 0;
    // --parallel-only: just the table of 1 against 2 threads.
    const bool parallelOnly = argc > 1 && std::strcmp(argv[argc - 1], "--parallel-only") == 0;
    std::printf("riemesh core_bench%s (one thread but in the parallel table)\n", quick ? " --quick" : "");
    if (!parallelOnly) {
        setThreadCount(1);
        scaling(quick);
        if (scalingOnly) return 0;
    }
    parallelScaling(quick);
    if (parallelOnly) return 0;
    setThreadCount(1);
    const int unexpected = fullRuns(quick);
    if (unexpected) std::printf("\n%d run(s) did not end as expected\n", unexpected);
    return unexpected ? 1 : 0;
}
