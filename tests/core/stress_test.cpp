// Stress of the whole model (issue 6, "the mesh never breaks"): random shapes (sums of balls and
// tori as analytic fog images, plus value noise), random valid parameters (delta, zeta, vmax,
// damping; Euclidean, constant anisotropic or position-dependent metric; box or bubble
// initialisation), evolved with Evolution::step and checked after EVERY iteration: closed,
// manifold, no degenerate face, finite positions (tests/support/mesh_invariants.h): these fail the
// test. The embedding is checked too: outward orientation after every iteration (a component with
// negative volume must be a cavity) and no self-intersection at the end of every run (converged or
// capped); these fail the test only in strict mode, since the model still lets some folds through.
//
// Modes (environment variables):
//   default                  a fixed set of cases from seed kCiSeed (CI; ~30 s in Release)
//   RIEMESH_STRESS_STRICT=1  embedding problems fail the test too (scripts/soak sets it)
//   RIEMESH_STRESS_DEFAULT=1 the default mode (no intersectionFree), embedded at the end only
//   RIEMESH_SOAK_SECONDS=S   random cases until S seconds have passed (scripts/soak)
//   RIEMESH_SOAK_SEED=N      base seed of the case sequence (default: kCiSeed in CI, the clock in soak)
//   RIEMESH_STRESS_CASE=N    replays the one case with case seed N (printed on failure)
//   RIEMESH_STRESS_DUMP=DIR  on failure writes DIR/stress_<case>_it<N>_before.ply (the mesh before the
//                            failing iteration) and _after.ply
//   RIEMESH_STRESS_VERBOSE=1 one line per case
//   RIEMESH_STRESS_SELF=K    also checks self-intersections every K iterations (not only at the end)
// A failure prints the case seed, every parameter and the iteration, so that it can be replayed.
#include "mesh_invariants.h"
#include "riemesh/evolution.h"
#include "riemesh/mesh_io.h"
#include "riemesh/self_intersection.h"

#include <doctest/doctest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

using namespace riemesh;

namespace {

constexpr std::uint64_t kCiSeed = 20240606;
constexpr int kCiCases = 14;

std::uint64_t splitmix(std::uint64_t x)
{
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

/// A ball (radius `a`) or a torus (tube centre radius `a`, tube radius `b`, axis frame.col(2)).
struct Primitive {
    bool torus = false;
    Vec3 centre = Vec3::Zero();
    Mat3 frame = Mat3::Identity();
    double a = 1, b = 0;

    double sdf(const Vec3& x) const // > 0 inside
    {
        const Vec3 p = frame.transpose() * (x - centre);
        if (!torus) return a - p.norm();
        return b - std::hypot(std::hypot(p.x(), p.y()) - a, p.z());
    }
};

/// Value noise: uniform [-1, 1] on the integer lattice (voxels), trilinearly interpolated.
double latticeNoise(const Vec3& x, std::uint64_t seed)
{
    const Vec3 f = x.array().floor();
    const Vec3 t = x - f;
    const auto i0 = std::int64_t(f.x()), j0 = std::int64_t(f.y()), k0 = std::int64_t(f.z());
    double sum = 0;
    for (int c = 0; c < 8; ++c) {
        const int di = c & 1, dj = (c >> 1) & 1, dk = (c >> 2) & 1;
        std::uint64_t h = seed;
        h = splitmix(h ^ std::uint64_t(i0 + di));
        h = splitmix(h ^ std::uint64_t(j0 + dj));
        h = splitmix(h ^ std::uint64_t(k0 + dk));
        const double value = double(h >> 11) * (2.0 / 9007199254740992.0) - 1.0;
        sum += value * (di ? t.x() : 1 - t.x()) * (dj ? t.y() : 1 - t.y()) * (dk ? t.z() : 1 - t.z());
    }
    return sum;
}

enum class MetricKind { Euclidean, Constant, Radial, Contour };
const char* toString(MetricKind k)
{
    switch (k) {
    case MetricKind::Euclidean: return "euclidean";
    case MetricKind::Constant: return "constant";
    case MetricKind::Radial: return "radial";
    case MetricKind::Contour: return "contour";
    }
    return "?";
}

/// Everything one run depends on, drawn from its case seed.
struct StressCase {
    std::uint64_t seed = 0;
    std::vector<Primitive> parts;
    double width = 1;     ///< fog transition width (voxels)
    double noise = 0;     ///< value noise amplitude (intensity; the fog steps from 0 to 1)
    Box3 bounds;
    EvolutionOptions options;
    MetricKind metric = MetricKind::Euclidean;
    double muMax = 1;
    Mat3 metricFrame = Mat3::Identity();
    Vec3 metricEigen = Vec3::Ones();
    Vec3 metricCentre = Vec3::Zero();
    double metricSpread = 1;
    bool bubbles = false;
    std::vector<std::pair<Vec3, double>> spheres;
    bool schedule = false; ///< a coarse level first (delta x 2, same image; see EvolutionLevel)
    int iterations = 0; ///< cap

    std::string describe() const
    {
        std::ostringstream s;
        s.precision(6);
        s << "case seed " << seed << ": " << parts.size() << " part(s)";
        for (const auto& p : parts) {
            s << (p.torus ? " [torus c=(" : " [ball c=(") << p.centre.transpose() << ") ";
            if (p.torus) s << "R=" << p.a << " r=" << p.b << " axis=(" << p.frame.col(2).transpose() << ")]";
            else s << "r=" << p.a << "]";
        }
        s << "; width " << width << ", noise " << noise << "; delta " << options.delta << ", zeta " << options.zeta
          << ", vmax " << options.vmaxFraction << " delta, damping " << options.damping << "; metric "
          << toString(metric);
        if (metric != MetricKind::Euclidean) s << " (mu " << muMax << ")";
        if (metric == MetricKind::Constant) s << " eigenvalues (" << metricEigen.transpose() << ")";
        if (metric == MetricKind::Radial) s << " centre (" << metricCentre.transpose() << ") spread " << metricSpread;
        s << "; init " << (bubbles ? "bubbles" : "box") << (schedule ? ", coarse level first" : "");
        for (const auto& [c, r] : spheres) s << " (" << c.transpose() << " r " << r << ")";
        s << "; cap " << iterations << " iterations";
        return s.str();
    }
};

/// The case generator's random numbers, the same on every compiler and standard library: the
/// numbers libstdc++'s uniform_real_distribution and normal_distribution draw from mt19937_64 (the
/// soak's seeds were found with GCC), computed here, since libc++ (clang, WebAssembly) implements
/// those distributions differently, and drawn one per statement, since the evaluation order of
/// function arguments is up to the compiler (GCC went right to left: the z of a Vec3 first).
class Draws {
public:
    explicit Draws(std::uint64_t seed) : mRng(seed) {}

    /// In [0, 1): generate_canonical<double, 53> with a 64-bit engine.
    double canonical()
    {
        const double u = double(mRng()) / 18446744073709551616.0;
        return u >= 1.0 ? std::nextafter(1.0, 0.0) : u;
    }
    double uniform(double lo, double hi) { return canonical() * (hi - lo) + lo; }
    bool chance(double p) { return uniform(0, 1) < p; }
    /// Standard normal, Marsaglia's polar method, which yields two numbers per accepted pair.
    double normal()
    {
        if (mSaved) {
            mSaved = false;
            return mSavedValue;
        }
        double x, y, r2;
        do {
            x = 2.0 * canonical() - 1.0;
            y = 2.0 * canonical() - 1.0;
            r2 = x * x + y * y;
        } while (r2 > 1.0 || r2 == 0.0);
        const double mult = std::sqrt(-2 * std::log(r2) / r2);
        mSavedValue = x * mult;
        mSaved = true;
        return y * mult;
    }
    /// (uniform(lo.x, hi.x), uniform(lo.y, hi.y), uniform(lo.z, hi.z)), z drawn first.
    Vec3 uniform(const Vec3& lo, const Vec3& hi)
    {
        const double z = uniform(lo.z(), hi.z());
        const double y = uniform(lo.y(), hi.y());
        const double x = uniform(lo.x(), hi.x());
        return Vec3(x, y, z);
    }
    /// A uniformly random rotation (a normalised Gaussian quaternion).
    Mat3 rotation()
    {
        const double z = normal(), y = normal(), x = normal(), w = normal(); // z first, as drawn by GCC
        Eigen::Quaterniond q(w, x, y, z);
        q.normalize();
        return q.toRotationMatrix();
    }

private:
    std::mt19937_64 mRng;
    bool mSaved = false;
    double mSavedValue = 0;
};

StressCase makeCase(std::uint64_t seed)
{
    StressCase c;
    c.seed = seed;
    Draws draw(seed);

    const int parts = 1 + int(draw.uniform(0, 2.999));
    Box3 box;
    for (int i = 0; i < parts; ++i) {
        Primitive p;
        p.torus = draw.chance(0.4);
        p.centre = draw.uniform(Vec3(-8, -8, -6), Vec3(8, 8, 6));
        p.frame = draw.rotation();
        if (p.torus) {
            p.b = draw.uniform(1.8, 3.0);
            p.a = p.b + draw.uniform(2.0, 4.0);
            box.extend(p.centre - Vec3::Constant(p.a + p.b));
            box.extend(p.centre + Vec3::Constant(p.a + p.b));
        } else {
            p.a = draw.uniform(2.5, 5.5);
            box.extend(p.centre - Vec3::Constant(p.a));
            box.extend(p.centre + Vec3::Constant(p.a));
        }
        c.parts.push_back(p);
    }
    const double grow = draw.uniform(3, 5), shrink = draw.uniform(3, 5); // max side first
    c.bounds = Box3(box.min() - Vec3::Constant(shrink), box.max() + Vec3::Constant(grow));
    c.width = draw.uniform(0.5, 2.0);
    c.noise = draw.chance(0.25) ? 0.0 : draw.uniform(0.0, 0.35);

    // The model resolves features of about its longest edge (zeta * delta) and larger: the thinnest
    // part (a ball's radius, a tube's radius) spans one to two longest edges.
    double feature = 1e9;
    for (const auto& p : c.parts) feature = std::min(feature, p.torus ? p.b : p.a);
    EvolutionOptions& o = c.options;
    // Strict mode checks the guarantee (issue 17); RIEMESH_STRESS_DEFAULT=1 runs the default mode
    // instead, whose result must be embedded too (a tangled run starts again with the guarantee).
    o.intersectionFree = !std::getenv("RIEMESH_STRESS_DEFAULT");
    o.zeta = draw.uniform(2.0, 4.0);
    o.delta = std::max(0.5, draw.uniform(0.5, 1.0) * feature / o.zeta);
    o.vmaxFraction = draw.uniform(0.2, 1.0);
    o.damping = draw.uniform(0.3, 0.8);
    c.iterations = int(draw.uniform(100, 250));
    o.maxIterations = c.iterations;

    const double m = draw.uniform(0, 1);
    c.metric = m < 0.35 ? MetricKind::Euclidean : m < 0.6 ? MetricKind::Constant : m < 0.8 ? MetricKind::Radial
                                                                                           : MetricKind::Contour;
    c.muMax = draw.uniform(1.5, 6.0);
    c.metricFrame = draw.rotation();
    const double middle = draw.uniform(1.0, c.muMax);
    c.metricEigen = Vec3(1.0, middle, c.muMax);
    c.metricCentre = c.parts[0].centre + draw.uniform(Vec3::Constant(-3), Vec3::Constant(3));
    c.metricSpread = draw.uniform(3, 10);

    c.bubbles = draw.chance(0.4);
    if (c.bubbles) {
        // One bubble inside each part (the torus: on its tube's centre circle), none overlapping
        // another: an initial mesh must be embedded.
        for (const auto& p : c.parts) {
            double radius;
            Vec3 centre;
            if (p.torus) {
                const double angle = draw.uniform(0, 2 * M_PI);
                centre = p.centre + p.frame * Vec3(p.a * std::cos(angle), p.a * std::sin(angle), 0);
                radius = draw.uniform(0.45, 0.7) * p.b;
            } else {
                centre = p.centre;
                radius = draw.uniform(0.3, 0.6) * p.a;
            }
            bool apart = true;
            for (const auto& [q, r] : c.spheres) apart &= (q - centre).norm() > r + radius + 2 * o.delta;
            if (apart) c.spheres.push_back({centre, radius});
        }
    }
    // Drawn last, so that the other parameters of a seed stay what they were before it existed.
    c.schedule = !c.bubbles && draw.chance(0.35);
    return c;
}

/// The analytic image: sum of the parts' fog profiles plus value noise.
std::unique_ptr<FunctionImage> makeImage(const StressCase& c)
{
    const auto parts = c.parts;
    const double width = c.width, noise = c.noise;
    const std::uint64_t noiseSeed = splitmix(c.seed ^ 0x5eedull);
    return std::make_unique<FunctionImage>(
        [parts, width, noise, noiseSeed](const Vec3& x) {
            double v = 0;
            for (const auto& p : parts) v += 0.5 + 0.5 * std::tanh(p.sdf(x) / width);
            if (noise > 0) v += noise * latticeNoise(x, noiseSeed);
            return v;
        },
        c.bounds, 1.0);
}

std::unique_ptr<MetricField> makeMetric(const StressCase& c)
{
    switch (c.metric) {
    case MetricKind::Euclidean: return std::make_unique<EuclideanMetric>();
    case MetricKind::Constant: return std::make_unique<ConstantMetric>(metricFromEigen(c.metricFrame, c.metricEigen));
    case MetricKind::Radial: {
        // Stretched along the direction from a centre, strongest near it: eigenvalues 1, 1, 1 + (mu-1) w.
        const Vec3 centre = c.metricCentre;
        const double mu = c.muMax, spread = c.metricSpread;
        return std::make_unique<FunctionMetric>(
            [centre, mu, spread](const Vec3& x) {
                const Vec3 d = x - centre;
                const double r = d.norm();
                const Vec3 n = r > 1e-9 ? Vec3(d / r) : Vec3(0, 0, 1);
                const double w = std::exp(-0.5 * r * r / (spread * spread));
                return Mat3(Mat3::Identity() + (mu - 1) * w * n * n.transpose());
            },
            mu);
    }
    case MetricKind::Contour: {
        // Like the structure-tensor metric: stretched across the contours of the clean image, by
        // how steep they are (the noise-free fog's gradient, at most 0.5 / width per part).
        const auto parts = c.parts;
        const double mu = c.muMax, width = c.width;
        return std::make_unique<FunctionMetric>(
            [parts, mu, width](const Vec3& x) {
                Vec3 g = Vec3::Zero();
                for (const auto& p : parts) {
                    const double h = 1e-3;
                    Vec3 ds;
                    for (int k = 0; k < 3; ++k) {
                        Vec3 e = Vec3::Zero();
                        e[k] = h;
                        ds[k] = (p.sdf(x + e) - p.sdf(x - e)) / (2 * h);
                    }
                    const double t = std::tanh(p.sdf(x) / width);
                    g += 0.5 * (1 - t * t) / width * ds;
                }
                const double len = g.norm();
                if (!(len > 1e-12)) return Mat3(Mat3::Identity());
                const double w = std::min(1.0, len * 2 * width);
                const Vec3 n = g / len;
                return Mat3(Mat3::Identity() + (mu - 1) * w * n * n.transpose());
            },
            mu);
    }
    }
    return nullptr;
}

/// The structural invariants of tests/support: closed, 2-manifold, no degenerate face, finite
/// positions (orientation is judged by orientationProblem). Empty string when all hold.
std::string structuralProblem(const Mesh& mesh)
{
    if (mesh.n_faces() == 0) return "the mesh vanished";
    testing::InvariantOptions io;
    io.requireOutward = false;
    const auto report = testing::checkInvariants(mesh, io);
    return report.ok() ? std::string() : report.text();
}

/// Outward orientation: every component encloses positive volume, unless it is a cavity (nested
/// inside the rest of the surface: winding number 1 around it), as after merges that close a
/// pocket. A self-intersecting (tangled) mesh fails this too. Empty string when it holds.
std::string orientationProblem(const Mesh& mesh)
{
    int count = 0;
    const auto label = componentLabels(mesh, &count);
    std::vector<double> volume(count, 0.0);
    std::vector<VertexHandle> sample(count);
    for (auto f : mesh.faces()) {
        auto h = mesh.halfedge_handle(f);
        const VertexHandle va = mesh.from_vertex_handle(h);
        const Vec3 a = position(mesh, va), b = position(mesh, mesh.to_vertex_handle(h)),
                   c = position(mesh, mesh.to_vertex_handle(mesh.next_halfedge_handle(h)));
        volume[label[va.idx()]] += a.dot(b.cross(c)) / 6.0;
        sample[label[va.idx()]] = va;
    }
    for (int i = 0; i < count; ++i) {
        if (volume[i] > 0) continue;
        const double w = windingNumber(mesh, position(mesh, sample[i]), &label, i);
        if (std::abs(w - 1) > 0.1) {
            std::ostringstream s;
            s << "component " << i << " of " << count << " encloses volume " << volume[i]
              << " and is not a cavity (winding number " << w << " around it)";
            return s.str();
        }
    }
    return {};
}

/// Empty when the mesh has no self-intersection, else the counts and a few face pairs.
std::string selfIntersections(const Mesh& mesh)
{
    SelfIntersectionOptions so;
    so.collectPairs = true;
    so.maxPairs = 5;
    const auto self = findSelfIntersections(mesh, so);
    if (self.count() == 0) return {};
    std::ostringstream s;
    s << self.crossings << " crossing face pairs, " << self.vertexFolds << " vertex folds, " << self.edgeFolds
      << " edge folds";
    for (const auto& [f, g] : self.pairs) s << " (" << f.idx() << ", " << g.idx() << ")";
    return s.str();
}

struct RunResult {
    int iterations = 0;
    std::size_t vertices = 0;
    int merges = 0, cuts = 0;
    bool untangled = false; ///< the default mode tangled and started again with the guarantee
    std::string reason;
    std::string failure;   ///< structural (closed, manifold, non-degenerate, finite); empty: none
    std::string embedding; ///< the first orientation problem or self-intersection; empty: none
};

const char* env(const char* name)
{
    const char* v = std::getenv(name);
    return v && *v ? v : nullptr;
}

void dump(const std::string& tag, const StressCase& c, const Mesh& mesh, int iteration)
{
    const char* dir = env("RIEMESH_STRESS_DUMP");
    if (!dir || mesh.n_faces() == 0) return;
    Mesh copy = mesh;
    copy.garbage_collection();
    const std::string path = std::string(dir) + "/stress_" + std::to_string(c.seed) + "_it" + std::to_string(iteration) + "_" +
                             tag + ".ply";
    writeMesh(path, copy);
    std::fprintf(stderr, "stress: wrote %s\n", path.c_str());
}

/// "iteration N (events): problem".
std::string at(const IterationStats& it, const std::string& problem)
{
    std::ostringstream s;
    s << "iteration " << it.iteration << " (" << it.merges << " merges, " << it.cuts << " cuts, "
      << it.removedComponents << " specks removed this iteration): " << problem;
    return s.str();
}

/// Evolves one case with Evolution::step, checking the structural invariants after every
/// iteration (stops at the first failure), the orientation after every iteration and the
/// self-intersections at the end (and every RIEMESH_STRESS_SELF iterations); the first embedding
/// problem is recorded and the run goes on.
RunResult runCase(const StressCase& c)
{
    RunResult result;
    const auto image = makeImage(c);
    const auto metric = makeMetric(c);
    const double initEdge = 0.5 * (1.0 + c.options.zeta) * c.options.delta;
    Mesh mesh = c.spheres.empty() ? makeInitialBox(*image, initEdge) : makeBubbles(c.spheres, initEdge);
    const std::vector<EvolutionLevel> levels =
        c.schedule ? std::vector<EvolutionLevel>{{image.get(), 2.0}, {image.get(), 1.0}} : std::vector<EvolutionLevel>{{image.get(), 1.0}};
    Evolution evolution(mesh, levels, *metric, c.options);
    const bool dumping = env("RIEMESH_STRESS_DUMP") != nullptr;
    const int selfEvery = env("RIEMESH_STRESS_SELF") ? std::atoi(env("RIEMESH_STRESS_SELF")) : 0;
    Mesh before;
    while (!evolution.done()) {
        if (dumping) before = mesh;
        const IterationStats it = evolution.step();
        result.iterations = it.iteration;
        result.merges += it.merges;
        result.cuts += it.cuts;
        const std::string problem = structuralProblem(mesh);
        if (!problem.empty()) {
            result.failure = at(it, problem);
            dump("before", c, before, it.iteration);
            dump("after", c, mesh, it.iteration);
            return result;
        }
        // The default mode's iterations may cross (its result may not): checked at the end only.
        if (result.embedding.empty() && c.options.intersectionFree) {
            std::string embedding = orientationProblem(mesh);
            if (embedding.empty() && selfEvery > 0 && it.iteration % selfEvery == 0) embedding = selfIntersections(mesh);
            if (!embedding.empty()) {
                result.embedding = at(it, embedding);
                dump("before", c, before, it.iteration);
                dump("after", c, mesh, it.iteration);
            }
        }
    }
    result.reason = toString(evolution.reason());
    result.untangled = evolution.untangledAt() > 0;
    result.vertices = topologyOf(mesh).vertices;
    const std::string self = selfIntersections(mesh);
    if (env("RIEMESH_STRESS_VERBOSE") && !self.empty()) std::fprintf(stderr, "stress: at the end: %s\n", self.c_str());
    if (!self.empty() && result.embedding.empty()) {
        result.embedding = "after " + std::to_string(result.iterations) + " iterations (" + result.reason + "): " + self;
        dump("end", c, mesh, result.iterations);
    }
    return result;
}

/// Strict mode (RIEMESH_STRESS_STRICT=1, set by scripts/soak): embedding problems fail the test
/// too. Without it they are printed (with the replay line) but do not fail: the model still lets
/// some folds through (see the known weaknesses in the report of issue 6), and CI must stay green
/// on the structural invariants, which it guarantees.
bool strict() { return env("RIEMESH_STRESS_STRICT") != nullptr; }

/// Runs one case and reports a failure with everything needed to replay it.
RunResult runAndReport(const StressCase& c)
{
    RunResult r = runCase(c);
    if (env("RIEMESH_STRESS_VERBOSE"))
        std::fprintf(stderr, "stress: %s -> %d iterations (%s), %zu vertices, %d merges, %d cuts%s%s\n",
                     c.describe().c_str(), r.iterations, r.reason.c_str(), r.vertices, r.merges, r.cuts,
                     r.failure.empty() ? "" : ", FAILED", r.embedding.empty() ? "" : ", NOT EMBEDDED");
    for (const std::string* problem : {&r.failure, &r.embedding}) {
        if (problem->empty()) continue;
        const bool fatal = problem == &r.failure || strict();
        std::fprintf(stderr, "stress: %s %s\n  %s\n  replay: RIEMESH_STRESS_CASE=%llu riemesh_core_tests "
                             "--source-file=*stress_test.cpp\n",
                     problem == &r.failure ? "FAILED" : "NOT EMBEDDED", c.describe().c_str(), problem->c_str(),
                     (unsigned long long)c.seed);
        if (fatal) {
            INFO(c.describe());
            INFO(*problem);
            CHECK(problem->empty());
        }
    }
    return r;
}

} // namespace

TEST_CASE("stress: random shapes, parameters and metrics keep the mesh valid after every iteration")
{
    const auto start = std::chrono::steady_clock::now();
    auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(); };
    if (const char* one = env("RIEMESH_STRESS_CASE")) {
        const StressCase c = makeCase(std::strtoull(one, nullptr, 10));
        MESSAGE(c.describe());
        const RunResult r = runAndReport(c);
        MESSAGE(r.iterations << " iterations (" << r.reason << "), " << r.merges << " merges, " << r.cuts << " cuts");
        return;
    }
    const char* soak = env("RIEMESH_SOAK_SECONDS");
    const double seconds = soak ? std::atof(soak) : 0.0;
    std::uint64_t base = kCiSeed;
    if (const char* s = env("RIEMESH_SOAK_SEED")) base = std::strtoull(s, nullptr, 10);
    else if (soak) base = std::uint64_t(std::chrono::system_clock::now().time_since_epoch().count());
    int cases = 0, failures = 0, tangled = 0, untangled = 0, iterations = 0, merges = 0, cuts = 0, parts = 0;
    // RIEMESH_STRESS_CASES: fewer (or more) fixed-seed cases, e.g. under the sanitizers (10-20x slower).
    const int ciCases = env("RIEMESH_STRESS_CASES") ? std::max(1, std::atoi(env("RIEMESH_STRESS_CASES"))) : kCiCases;
    for (int i = 0; soak ? elapsed() < seconds : i < ciCases; ++i) {
        const StressCase c = makeCase(splitmix(base + std::uint64_t(i)));
        const RunResult r = runAndReport(c);
        ++cases;
        parts += int(c.parts.size());
        iterations += r.iterations;
        merges += r.merges;
        cuts += r.cuts;
        failures += !r.failure.empty();
        tangled += !r.embedding.empty();
        untangled += r.untangled;
    }
    std::ostringstream summary;
    summary << "stress (base seed " << base << "): " << cases << " cases (" << parts << " balls and tori), "
            << iterations << " iterations checked, " << merges << " merges, " << cuts << " cuts; " << failures
            << " structural failures, " << tangled << " runs not embedded";
    if (env("RIEMESH_STRESS_DEFAULT")) summary << " (default mode: " << untangled << " evolved again with the guarantee)";
    summary << "; " << elapsed() << " s";
    MESSAGE(summary.str());
    std::printf("%s\n", summary.str().c_str());
    CHECK(failures == 0);
}

TEST_CASE("stress regressions: cases the soak broke stay valid and embedded")
{
    // Case seeds from `scripts/soak 400 777` that broke: two sheets joined by a merge's band passed
    // through each other (the neighbourhood path bound excluded them from collision detection, and
    // rejected merges let them keep moving); the tangled mesh turned inside out and was removed as
    // a speck ("the mesh vanished"). Fixed by the detour rule of findCollisions near fresh merges
    // (kMergedProperty) and by holding apart the sheets in contact that are not merged
    // (kHoldProperty).
    // (833718140080444770 from the same soak no longer breaks but still ends tangled: not listed.)
    // The soak found them with GCC; makeCase draws the same numbers on every compiler (see Draws),
    // which the first part's centre checks.
    struct Regression {
        std::uint64_t seed;
        const char* firstPart; ///< the start of the first part's description
        bool embedded = true;  ///< required to end without self-intersections too
    };
    const Regression cases[] = {
        {12291501983830112541ull, "[torus c=( 7.8985 3.97237 3.07016)"},
        {14864462764286680675ull, "[ball c=(-3.44249  7.06184 -4.38536)"},
        {8722947093428365254ull, "[ball c=( 1.74289 -6.30578  5.21372)"},
        // From `scripts/soak 150 4242`: a deflating box's sheets met at a sharp convex crease
        // (normals 104 degrees apart, 0.24 voxel across, less than two steps of vmax) and
        // crossed; the surface folded further and turned inside out ("the mesh vanished").
        // findCollisions skipped such crease pairs altogether; it now reports them as contacts,
        // held apart (never merged).
        {11703526993037608059ull, "[ball c=(-3.98367  1.43837  5.77631)"},
        // Valid everywhere; under WebAssembly's rounding it ends with crossing faces (a coarse
        // torus, zeta 3.95 and vmax 0.48 delta: the residual local folds of the issue 6 note).
        {9527717507708880390ull, "[torus c=( 4.43621  1.16331 -4.82283)", false},
        {5748219494722099803ull, "[torus c=( 5.83604 -6.60176  5.53602)"},
        // Same soak, vmax 0.29 delta, barely above free flight (0.25 delta): with the curvature term the faces
        // flew at vmax, a crease lagged into a fin (normals 156 degrees apart) and crossed. Fixed by
        // capping the push so that free flight stays under vmax / sqrt 2 (Evolution::step).
        {17823307871858972363ull, "[ball c=(-5.01469 -3.77032 -1.60074)"},
        // `scripts/soak 600 90210` (988 cases): a merge's band held a face of area 2e-16 (collinear
        // loop corners up to round-off, vmax ~ delta); isBandEmbedded refused only exactly flat
        // faces, now also those thinner than 1e-8 of their longest edge.
        {145331693200290732ull, "[ball c=( -6.5088 -5.72765 -3.15064)"},
        // `scripts/soak` seed 7101 (intersection-free evolution): a merge band left a vertex 9e-16
        // from a face it does not belong to; not crossing by the exact test, but a motion of 6e-17
        // (a step limited to almost nothing) put it on the other side. Edits now keep their new
        // faces 1e-6 delta from the rest (kEditSeparation).
        {7047475164732749801ull, "[ball c=(-4.86289  6.90223  1.51945)"}};
    for (const Regression& entry : cases) {
        const StressCase c = makeCase(entry.seed);
        INFO(c.describe());
        REQUIRE(c.describe().find(entry.firstPart) != std::string::npos);
        const RunResult r = runCase(c);
        INFO(r.failure);
        INFO(r.embedding);
        CHECK(r.failure.empty());
        if (entry.embedded) CHECK(r.embedding.empty());
    }
}
