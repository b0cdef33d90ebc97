// self_intersection_bench: cost of findSelfIntersections against the face count.
//
//   self_intersection_bench [--quick] [--calls N]
//
// For icospheres of 20k, 80k and 320k faces (--quick: 20k, 80k), a torus of ~100k faces, and two
// interpenetrating 80k-face spheres, runs findSelfIntersections N times (default 5): ms per call
// (best and mean), ns per face (best), the box-overlapping pairs tested and the offending pairs.
// Embedded inputs should report 0; the overlapping spheres report their crossings.
#include "riemesh/primitives.h"
#include "riemesh/self_intersection.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

using namespace riemesh;

namespace {

double now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

void run(const char* name, const Mesh& mesh, int calls)
{
    double best = 1e30, mean = 0;
    SelfIntersectionStats stats;
    for (int i = 0; i < calls; ++i) {
        const double t0 = now();
        stats = findSelfIntersections(mesh);
        const double ms = (now() - t0) * 1000.0;
        best = std::min(best, ms);
        mean += ms / calls;
    }
    std::printf("%-28s %8zu faces  best %8.2f ms  mean %8.2f ms  %6.0f ns/face  tested %9zu  offending %zu "
                "(crossings %zu, vertex folds %zu, edge folds %zu)\n",
                name, mesh.n_faces(), best, mean, best * 1e6 / double(mesh.n_faces()), stats.testedPairs,
                stats.count(), stats.crossings, stats.vertexFolds, stats.edgeFolds);
}

} // namespace

int main(int argc, char** argv)
{
    bool quick = false;
    int calls = 5;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--quick") quick = true;
        else if (a == "--calls" && i + 1 < argc) calls = std::max(1, std::atoi(argv[++i]));
        else {
            std::fprintf(stderr, "self_intersection_bench: unknown argument '%s' (usage: [--quick] [--calls N])\n", argv[i]);
            return 1;
        }
    }
    const int top = quick ? 6 : 7;
    for (int s = 5; s <= top; ++s) {
        const std::string name = "icosphere subdivision " + std::to_string(s);
        run(name.c_str(), makeIcosphere(Vec3(0.1, 0.2, 0.3), 10.0, s), calls);
    }
    run("torus 500 x 100", makeTorus(Vec3::Zero(), 5, 1.5, 500, 100), calls);
    Mesh two = makeIcosphere(Vec3::Zero(), 10.0, 6);
    appendMesh(two, makeIcosphere(Vec3(10, 0, 0), 10.0, 6));
    run("two overlapping spheres", two, calls);
    return 0;
}
