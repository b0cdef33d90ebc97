// collision_bench: cost of findCollisions against the vertex count.
//
//   collision_bench [--quick] [--calls N] [--threads T] [--cache DIR] [target ...]
//
// For each target vertex count (default 1k, 5k, 20k, 80k; --quick: 1k, 5k) a sphere of radius 30
// is evolved for 40 iterations on a ball image with delta chosen for ~target vertices (edges
// ~1.6 delta, as in core_bench), then findCollisions (Euclidean, and a constant anisotropic
// metric) is called N times (default 200) on the settled mesh: ms per call (best and mean) and ns
// per vertex. A regular sphere has no collisions: the figure is the pure broad-phase cost.
// --cache DIR keeps the settled spheres as DIR/collision_sphere_<target>.ply (read back when
// present), so that runs under valgrind skip the evolution.
//
// Instruction counts (deterministic on a loaded machine):
//   valgrind --tool=callgrind --callgrind-out-file=cg.out collision_bench --calls 5 --cache /tmp/c 5000
//   callgrind_annotate --inclusive=yes cg.out | grep 'riemesh::findCollisions(.*) \['
// then divide that inclusive Ir by twice the number of calls (Euclidean and anisotropic runs).
// (Not --toggle-collect='riemesh::findCollisions*': the pair-scan lambda's symbol matches the
// pattern too, so entering it toggles collection off and its cost goes uncounted.)
// Columns: wall-clock best and mean ms per call, processor-time ms per call (mean), ns per vertex
// (best wall clock).
#include "riemesh/collision.h"
#include "riemesh/evolution.h"
#include "riemesh/mesh_io.h"
#include "riemesh/primitives.h"
#include "riemesh/threads.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>
#include <string>
#include <vector>

using namespace riemesh;

namespace {

double now()
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// Processor time of this process (seconds): on a loaded machine, time spent waiting for a core
/// does not count.
double cpuNow() { return double(std::clock()) / CLOCKS_PER_SEC; }

struct Timing {
    double best = 1e30, mean = 0; ///< wall clock, ms per call
    double cpu = 0;               ///< processor time, ms per call (mean)
    std::size_t pairs = 0;
};

Timing timeCalls(const Mesh& mesh, const MetricField& metric, const CollisionOptions& o, int calls)
{
    Timing t;
    const double c0 = cpuNow();
    for (int i = 0; i < calls; ++i) {
        const double t0 = now();
        const auto found = findCollisions(mesh, metric, o);
        const double ms = (now() - t0) * 1000.0;
        t.best = std::min(t.best, ms);
        t.mean += ms / calls;
        t.pairs = found.size();
    }
    t.cpu = (cpuNow() - c0) * 1000.0 / calls;
    return t;
}

/// A sphere of radius `radius` evolved for 40 iterations on a ball image (as core_bench).
Mesh settledSphere(int target, double radius, double delta)
{
    const FunctionImage image([radius](const Vec3& x) { return 0.5 + 0.5 * std::tanh(radius - x.norm()); },
                              Box3(Vec3::Constant(-40), Vec3::Constant(40)), 1.0);
    const EuclideanMetric euclidean;
    int sub = 0;
    while (20.0 * std::pow(4.0, sub) < 2.0 * target && sub < 8) ++sub;
    Mesh mesh = makeIcosphere(Vec3::Zero(), radius, sub);
    EvolutionOptions eo;
    eo.delta = delta;
    eo.maxIterations = 1000000;
    Evolution evolution(mesh, image, euclidean, eo);
    for (int i = 0; i < 40; ++i) evolution.step(); // settle the sampling
    return mesh;
}

} // namespace

int main(int argc, char** argv)
{
    bool quick = false;
    int calls = 200;
    int threads = 1;
    std::string cache;
    std::vector<int> targets;
    for (int i = 1; i < argc; ++i) {
        if (std::strcmp(argv[i], "--quick") == 0) quick = true;
        else if (std::strcmp(argv[i], "--calls") == 0 && i + 1 < argc) calls = std::max(1, std::atoi(argv[++i]));
        else if (std::strcmp(argv[i], "--threads") == 0 && i + 1 < argc) threads = std::max(1, std::atoi(argv[++i]));
        else if (std::strcmp(argv[i], "--cache") == 0 && i + 1 < argc) cache = argv[++i];
        else targets.push_back(std::atoi(argv[i]));
    }
    if (targets.empty()) targets = quick ? std::vector<int>{1000, 5000} : std::vector<int>{1000, 5000, 20000, 80000};

    setThreadCount(threads);
    std::printf("riemesh collision_bench (%d thread%s, %d calls per size and metric)\n", threads,
                threads == 1 ? "" : "s", calls);
    std::printf("%8s %9s %7s | %-37s | %-37s\n", "target", "vertices", "delta", "euclidean: best/mean/cpu ms, ns/v",
                "anisotropic: best/mean/cpu ms, ns/v");
    const double radius = 30;
    const EuclideanMetric euclidean;
    const ConstantMetric aniso(metricFromEigen(
        (Eigen::AngleAxisd(0.3, Vec3::UnitX()) * Eigen::AngleAxisd(0.7, Vec3::UnitY())).toRotationMatrix(),
        Vec3(1, 1.5, 2)));
    for (int target : targets) {
        // Area per vertex on a regular mesh with edges ~1.6 delta: ~ 2.2 delta^2.
        const double delta = std::sqrt(4 * M_PI * radius * radius / (2.2 * target));
        const std::string cached =
            cache.empty() ? std::string() : cache + "/collision_sphere_" + std::to_string(target) + ".ply";
        const bool haveCached = !cached.empty() && std::ifstream(cached).good();
        const Mesh mesh = haveCached ? readMesh(cached) : settledSphere(target, radius, delta);
        if (!cached.empty() && !haveCached) writeMesh(cached, mesh);

        CollisionOptions co;
        co.delta = delta;
        co.zeta = EvolutionOptions().zeta;
        co.vmax = EvolutionOptions().vmaxFraction * delta;
        const Timing e = timeCalls(mesh, euclidean, co, calls);
        const Timing a = timeCalls(mesh, aniso, co, calls);
        const double nv = double(mesh.n_vertices());
        std::printf("%8d %9zu %7.3f | %8.4f %8.4f %8.4f %8.1f | %8.4f %8.4f %8.4f %8.1f | pairs %zu/%zu\n", target,
                    mesh.n_vertices(), delta, e.best, e.mean, e.cpu, 1e6 * e.best / nv, a.best, a.mean, a.cpu,
                    1e6 * a.best / nv, e.pairs, a.pairs);
        std::fflush(stdout);
    }
    return 0;
}
