// vdb_bench: riemesh's peers on the same images, and the cost of the structure-tensor metric.
//
//   vdb_bench mesh IMAGE [--grid G] [--iso V] [--reference FILE.vdb[:GRID]] [--gaussian W:I|none]
//                        [--adaptivity A,B,...] [--mc] [--obj-dir DIR] [--label TEXT] [--threads N]
//   vdb_bench metric IMAGE [--grid G] [--threads N] [--repeat R]
//
// `mesh` smooths the image with OpenVDB's tools::Filter::gaussian(W, I) (the usual pre-filter before
// meshing a noisy image), then meshes it with OpenVDB's tools::volumeToMesh at each adaptivity and,
// with --mc, with the plain marching cubes below. Quads are split in two triangles before anything is
// counted. Each mesh is measured with the same code as vdb2mesh --reference (vdb/level_set.h
// surfaceError: both ways from dense samples of both surfaces, voxels) and its topology is counted on the triangle
// arrays (components, genus, and whether it is a closed, oriented 2-manifold at all: the genus of
// anything else means nothing). One CSV row per mesh on stdout.
//
// `metric` times riemesh::vdb::computeMetric (structure tensor + metric, vdb2mesh's defaults) on the
// image with N threads: one CSV row, the fastest of R runs.
//
// This is the only bench file that includes OpenVDB (each such file costs ~35 s to compile).
#include "bench_common.h"
#include "../vdb/apps/cli.h"
#include "riemesh/mesh_io.h"
#include "riemesh/vdb/io.h"
#include "riemesh/vdb/level_set.h"
#include "riemesh/vdb/metric_grid.h"
#include "riemesh/vdb/volume.h"

#include <openvdb/tools/Filter.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <numeric>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

using namespace riemesh;
using apps::BadInput;
using apps::parseCount;

namespace {

using bench::Clock;
using bench::csvField;
using bench::secondsSince;

/// A triangle mesh as arrays: world-space points and vertex indices (what peers produce).
struct Soup {
    std::vector<openvdb::Vec3d> points;
    std::vector<openvdb::Vec3I> triangles;
};

// ---- A compact marching cubes (a peer for comparison, not product code) -------------------------
//
// Table-free: in each cube, every face with a sign change contributes one or two segments joining
// the crossings on its edges, directed from where a walk around the face (counter-clockwise seen
// from outside the cube) leaves the inside to where it enters it again; the segments close into
// polygons, which are fanned into triangles. An ambiguous face (four crossings) joins its inside
// corners when the mean of its four values is inside (the "mean value" decider). Both cubes that
// share a face see the same values, so they make the same segments in opposite directions: the
// result is a closed, consistently oriented 2-manifold wherever the image is padded with outside
// values, with the vertex count of classic marching cubes (one vertex per crossed grid edge).

/// Corners of each cube face, counter-clockwise seen from outside; corner bits are x | y<<1 | z<<2.
constexpr int kFaces[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};

/// True when the cube edges with corner masks `a` and `b` lie on one face of the cube.
bool shareFace(int a, int b)
{
    for (const auto& f : kFaces) {
        const int face = (1 << f[0]) | (1 << f[1]) | (1 << f[2]) | (1 << f[3]);
        if ((face & a) == a && (face & b) == b) return true;
    }
    return false;
}

/// Triangulates one polygon as a fan from an apex none of whose diagonals joins two vertices on one
/// cube face: the neighbour cube across that face could make the same diagonal, and the edge would
/// then have four triangles. When every apex has such a diagonal (rare ambiguous configurations), the
/// fan goes around a new vertex at the polygon's centroid instead.
void fanPolygon(const std::vector<int>& polygon, const std::vector<int>& corners, Soup& soup)
{
    const std::size_t m = polygon.size();
    for (std::size_t apex = 0; apex < m; ++apex) {
        bool clean = true;
        for (std::size_t d = 2; d + 1 < m && clean; ++d) clean = !shareFace(corners[apex], corners[(apex + d) % m]);
        if (!clean) continue;
        for (std::size_t t = 1; t + 1 < m; ++t)
            soup.triangles.emplace_back(polygon[apex], polygon[(apex + t) % m], polygon[(apex + t + 1) % m]);
        return;
    }
    openvdb::Vec3d centroid(0.0);
    for (int v : polygon) centroid += soup.points[v];
    const auto centre = openvdb::Index32(soup.points.size());
    soup.points.push_back(centroid / double(m));
    for (std::size_t t = 0; t < m; ++t) soup.triangles.emplace_back(centre, polygon[t], polygon[(t + 1) % m]);
}

Soup marchingCubes(const openvdb::FloatGrid& grid, double iso, bool brighterInside)
{
    // Dense copy of the active box with one layer of outside padding, so every surface closes.
    openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
    box.expand(1);
    const openvdb::Coord lo = box.min(), dim = box.dim();
    const std::size_t nx = std::size_t(dim.x()), ny = std::size_t(dim.y()), nz = std::size_t(dim.z());
    std::vector<float> v(nx * ny * nz); // signed: > 0 inside
    auto acc = grid.getConstAccessor();
    const double sign = brighterInside ? 1.0 : -1.0;
    for (std::size_t k = 0; k < nz; ++k)
        for (std::size_t j = 0; j < ny; ++j)
            for (std::size_t i = 0; i < nx; ++i) {
                const bool pad = i == 0 || j == 0 || k == 0 || i + 1 == nx || j + 1 == ny || k + 1 == nz;
                const double value =
                    sign * (acc.getValue(lo.offsetBy(int(i), int(j), int(k))) - iso);
                v[(k * ny + j) * nx + i] = float(pad ? std::min(value, -1e-6) : value);
            }
    const auto at = [&](std::size_t i, std::size_t j, std::size_t k) { return v[(k * ny + j) * nx + i]; };

    Soup soup;
    std::unordered_map<std::uint64_t, int> edgeVertex; // (lower corner linear index) * 3 + axis
    const auto& xform = grid.transform();
    std::array<float, 8> c{};
    for (std::size_t k = 0; k + 1 < nz; ++k)
        for (std::size_t j = 0; j + 1 < ny; ++j)
            for (std::size_t i = 0; i + 1 < nx; ++i) {
                int insideCount = 0;
                for (int b = 0; b < 8; ++b) {
                    c[b] = at(i + (b & 1), j + ((b >> 1) & 1), k + ((b >> 2) & 1));
                    insideCount += c[b] > 0;
                }
                if (insideCount == 0 || insideCount == 8) continue;
                // Global vertex on the cube edge between corners a and b (one bit apart).
                const auto vertexOn = [&](int a, int b) {
                    const int lowBit = std::min(a, b), axis = (a ^ b) == 1 ? 0 : (a ^ b) == 2 ? 1 : 2;
                    const std::size_t li = i + (lowBit & 1), lj = j + ((lowBit >> 1) & 1), lk = k + ((lowBit >> 2) & 1);
                    const std::uint64_t key = ((lk * ny + lj) * nx + li) * 3 + std::uint64_t(axis);
                    const auto [it, inserted] = edgeVertex.try_emplace(key, int(soup.points.size()));
                    if (inserted) {
                        const int from = lowBit, to = std::max(a, b);
                        const double t = c[from] / double(c[from] - c[to]); // where the value crosses 0
                        openvdb::Vec3d p{double(li), double(lj), double(lk)};
                        p[axis] += t;
                        soup.points.push_back(xform.indexToWorld(p + openvdb::Vec3d(lo.asVec3d())));
                    }
                    return it->second;
                };
                std::array<int, 12> next; // local segment links, by global vertex (small linear map)
                std::array<int, 12> from;
                std::array<int, 12> fromCorners; // corner bit mask of the cube edge `from` lies on
                int links = 0;
                for (const auto& f : kFaces) {
                    int q[4], exits[4], corners[4], n = 0;
                    for (int e = 0; e < 4; ++e) {
                        const int a = f[e], b = f[(e + 1) % 4];
                        if ((c[a] > 0) == (c[b] > 0)) continue;
                        q[n] = vertexOn(a, b);
                        corners[n] = (1 << a) | (1 << b);
                        exits[n++] = c[a] > 0;
                    }
                    if (n == 0) continue;
                    const bool joinInside = n == 2 || (c[f[0]] + c[f[1]] + c[f[2]] + c[f[3]]) > 0;
                    for (int s = 0; s < n; ++s) {
                        if (!exits[s]) continue;
                        // An exit pairs with the next entry (cutting off outside corners) or the
                        // previous one (cutting off inside corners); always directed exit -> entry.
                        const int entry = joinInside ? q[(s + 1) % n] : q[(s + n - 1) % n];
                        fromCorners[links] = corners[s];
                        from[links] = q[s];
                        next[links++] = entry;
                    }
                }
                // Follow the links into closed polygons and fan them.
                std::array<bool, 12> used{};
                for (int s = 0; s < links; ++s) {
                    if (used[s]) continue;
                    std::vector<int> polygon, polygonCorners;
                    int link = s;
                    while (!used[link]) {
                        used[link] = true;
                        polygon.push_back(from[link]);
                        polygonCorners.push_back(fromCorners[link]);
                        const int target = next[link];
                        link = int(std::find(from.begin(), from.begin() + links, target) - from.begin());
                        if (link == links) throw std::logic_error("marching cubes: open polygon");
                    }
                    fanPolygon(polygon, polygonCorners, soup);
                }
            }
    return soup;
}

// ---- Measuring any triangle mesh -------------------------------------------------------------------


/// Drops unreferenced points (adaptive volumeToMesh leaves some) and turns the normals outward.
void tidy(Soup& soup)
{
    std::vector<int> remap(soup.points.size(), -1);
    std::vector<openvdb::Vec3d> points;
    for (auto& tri : soup.triangles)
        for (int e = 0; e < 3; ++e) {
            int& r = remap[tri[e]];
            if (r < 0) {
                r = int(points.size());
                points.push_back(soup.points[tri[e]]);
            }
            tri[e] = openvdb::Index32(r);
        }
    soup.points = std::move(points);
    double volume = 0;
    for (const auto& tri : soup.triangles)
        volume += soup.points[tri[0]].dot(soup.points[tri[1]].cross(soup.points[tri[2]]));
    if (volume < 0)
        for (auto& tri : soup.triangles) std::swap(tri[1], tri[2]);
}

void writeObj(const std::string& path, const Soup& soup)
{
    vdb::writeFileAtomically(path, [&](const std::string& temp) {
        std::ofstream out(temp);
        out.precision(9);
        for (const auto& p : soup.points) out << "v " << p.x() << ' ' << p.y() << ' ' << p.z() << '\n';
        for (const auto& t : soup.triangles) out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
        out.close();
        if (!out) throw std::runtime_error("'" + path + "': write failed");
    });
}

// ---- Command line ------------------------------------------------------------------------------------

struct Args {
    std::string mode, image, grid, reference, referenceGrid = "sdf", objDir, label;
    std::vector<std::string> meshes; ///< error: the mesh files to measure
    std::optional<double> iso;
    int gaussianWidth = 1, gaussianIterations = 1; // width 0: no smoothing
    std::vector<double> adaptivities;
    bool mc = false;
    int threads = 0, repeat = 1;
};

const char* kUsage =
    "usage: vdb_bench mesh IMAGE [--grid G] [--iso V] [--reference FILE.vdb[:GRID]] [--gaussian W:I|none]\n"
    "                 [--adaptivity A,B,...] [--mc] [--obj-dir DIR] [--label TEXT] [--threads N]\n"
    "       vdb_bench metric IMAGE [--grid G] [--threads N] [--repeat R]\n"
    "       vdb_bench error REFERENCE.vdb MESH... [--grid G] [--label TEXT]\n"
    "mesh: OpenVDB volumeToMesh (after tools::Filter::gaussian(W, I), default 1:1) at each adaptivity\n"
    "      (default 0) and, with --mc, marching cubes on the same smoothed image; one CSV row per mesh.\n"
    "metric: seconds of the structure tensor + metric (vdb2mesh's defaults) with N threads (0: all).\n"
    "error: each mesh file (.obj .ply .off .stl) against REFERENCE's signed distance grid (default \"sdf\";\n"
    "      exact for vdbphantom's shapes), measured as vdb2mesh --reference does; one CSV row per mesh.\n";

Args parseArgs(int argc, char** argv)
{
    Args a;
    std::vector<std::string> positional;
    for (int i = 1; i < argc; ++i) {
        const std::string f = argv[i];
        const auto value = [&]() -> std::string {
            if (i + 1 >= argc) throw BadInput(f + " needs a value");
            return argv[++i];
        };
        if (f == "-h" || f == "--help") {
            std::fputs(kUsage, stdout);
            std::exit(0);
        } else if (f == "--grid") a.grid = value();
        else if (f == "--iso") a.iso = apps::parseNumber(f, value());
        else if (f == "--reference") {
            a.reference = value();
            const auto colon = a.reference.rfind(':');
            if (colon != std::string::npos && vdb::fileExtension(a.reference.substr(0, colon)) == ".vdb") {
                a.referenceGrid = a.reference.substr(colon + 1);
                a.reference.resize(colon);
            }
        } else if (f == "--gaussian") {
            const std::string v = value();
            const auto colon = v.find(':');
            if (v == "none") a.gaussianWidth = 0;
            else if (colon == std::string::npos) throw BadInput("--gaussian: '" + v + "' is not W:I or none");
            else {
                a.gaussianWidth = parseCount(f, v.substr(0, colon), 1);
                a.gaussianIterations = parseCount(f, v.substr(colon + 1), 1);
            }
        } else if (f == "--adaptivity") {
            std::string list = value();
            for (std::size_t start = 0; start <= list.size();) {
                const auto comma = std::min(list.find(',', start), list.size());
                const std::string item = list.substr(start, comma - start);
                const double x = apps::parseNumber(f, item);
                if (x < 0 || x > 1) throw BadInput("--adaptivity: '" + item + "' is outside [0, 1]");
                a.adaptivities.push_back(x);
                start = comma + 1;
            }
        } else if (f == "--mc") a.mc = true;
        else if (f == "--obj-dir") a.objDir = value();
        else if (f == "--label") a.label = value();
        else if (f == "--threads") a.threads = parseCount(f, value(), 0);
        else if (f == "--repeat") a.repeat = parseCount(f, value(), 1);
        else if (!f.empty() && f[0] == '-') throw BadInput("unknown option '" + f + "' (see --help)");
        else positional.push_back(f);
    }
    if (positional.size() >= 3 && positional[0] == "error") {
        a.mode = "error";
        a.image = positional[1];
        if (a.grid.empty()) a.grid = a.referenceGrid;
        a.meshes.assign(positional.begin() + 2, positional.end());
        if (a.label.empty()) a.label = a.image;
        return a;
    }
    if (positional.size() != 2 || (positional[0] != "mesh" && positional[0] != "metric"))
        throw BadInput("expected 'mesh IMAGE', 'metric IMAGE' or 'error REFERENCE MESH...' (see --help)");
    a.mode = positional[0];
    a.image = positional[1];
    if (a.adaptivities.empty() && !a.mc) a.adaptivities.push_back(0.0);
    if (a.label.empty()) a.label = a.image;
    return a;
}

void printMeshRow(const Args& a, const std::string& tool, const std::string& setting, Soup soup,
                  const openvdb::FloatGrid* sdf, double smoothSeconds, double meshSeconds)
{
    tidy(soup);
    bench::printMeshCsvRow(a.label, tool, setting, soup.points, soup.triangles, sdf, smoothSeconds, meshSeconds);
    if (!a.objDir.empty()) {
        std::string name = tool + "_" + setting;
        for (char& ch : name)
            if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '.' && ch != '-') ch = '_';
        // An empty mesh (the smoothing erased the object) has nothing to show: said, not written
        // (an empty file would read as a broken one).
        if (soup.triangles.empty())
            std::fprintf(stderr, "vdb_bench: %s %s: an empty mesh, no %s.obj written\n", tool.c_str(), setting.c_str(), name.c_str());
        else
            writeObj(a.objDir + "/" + name + ".obj", soup);
    }
}

int runMesh(const Args& a, const openvdb::FloatGrid::Ptr& image)
{
    const std::string gclass = vdb::gridClassName(*image);
    const double iso = a.iso ? *a.iso : gclass == "fog" ? 0.5 : gclass == "levelset" ? 0.0 : NAN;
    if (std::isnan(iso)) throw BadInput("'" + a.image + "': not a fog volume or level set: give --iso");
    const bool brighterInside = gclass != "levelset";
    openvdb::FloatGrid::Ptr sdf;
    if (!a.reference.empty()) {
        try {
            sdf = vdb::readVdbImage(a.reference, a.referenceGrid);
        } catch (const std::exception& e) {
            throw BadInput(std::string("--reference: ") + e.what());
        }
    }
    auto t0 = Clock::now();
    openvdb::FloatGrid::Ptr smooth = image->deepCopy();
    if (a.gaussianWidth > 0) {
        openvdb::tools::Filter<openvdb::FloatGrid> filter(*smooth);
        filter.gaussian(a.gaussianWidth, a.gaussianIterations);
    }
    const double smoothSeconds = secondsSince(t0);
    const std::string smoothing =
        a.gaussianWidth > 0 ? "gauss " + std::to_string(a.gaussianWidth) + ":" + std::to_string(a.gaussianIterations) : "raw";

    std::printf("%s", bench::kMeshCsvHeader);
    for (double adaptivity : a.adaptivities) {
        t0 = Clock::now();
        std::vector<openvdb::Vec3s> points;
        std::vector<openvdb::Vec3I> triangles;
        std::vector<openvdb::Vec4I> quads;
        openvdb::tools::volumeToMesh(*smooth, points, triangles, quads, iso, adaptivity);
        Soup soup;
        soup.points.assign(points.begin(), points.end());
        soup.triangles = std::move(triangles);
        for (const auto& q : quads) { // split along the shorter diagonal
            const double d02 = (points[q[0]] - points[q[2]]).lengthSqr(), d13 = (points[q[1]] - points[q[3]]).lengthSqr();
            if (d02 <= d13) {
                soup.triangles.emplace_back(q[0], q[1], q[2]);
                soup.triangles.emplace_back(q[0], q[2], q[3]);
            } else {
                soup.triangles.emplace_back(q[0], q[1], q[3]);
                soup.triangles.emplace_back(q[1], q[2], q[3]);
            }
        }
        const double meshSeconds = secondsSince(t0);
        char setting[64];
        std::snprintf(setting, sizeof setting, "%s a=%.2f", smoothing.c_str(), adaptivity);
        printMeshRow(a, "openvdb", setting, std::move(soup), sdf.get(), smoothSeconds, meshSeconds);
    }
    if (a.mc) {
        t0 = Clock::now();
        Soup soup = marchingCubes(*smooth, iso, brighterInside);
        printMeshRow(a, "marching-cubes", smoothing, std::move(soup), sdf.get(), smoothSeconds, secondsSince(t0));
    }
    return 0;
}

int runMetric(const Args& a, const openvdb::FloatGrid::Ptr& image)
{
    const openvdb::Coord dim = image->evalActiveVoxelDim();
    // Processor time beside wall time: on a shared machine a run that gets less than its threads'
    // worth of cores shows it (cpu < threads x wall), and a speed-up from it means little.
    double best = INFINITY, bestCpu = 0;
    for (int r = 0; r < a.repeat; ++r) {
        const auto t0 = Clock::now();
        const std::clock_t c0 = std::clock();
        const vdb::MetricGrids m = vdb::computeMetric(*image);
        const double wall = secondsSince(t0), cpu = double(std::clock() - c0) / CLOCKS_PER_SEC;
        if (wall < best) {
            best = wall;
            bestCpu = cpu;
        }
        if (m.totalVoxels == 0) throw std::runtime_error("metric: empty image");
    }
    std::printf("image,voxels,dims,threads,seconds,cpu_seconds\n%s,%lld,%dx%dx%d,%d,%.4f,%.4f\n",
                csvField(a.label).c_str(), static_cast<long long>(dim.x()) * dim.y() * dim.z(), dim.x(), dim.y(),
                dim.z(), a.threads, best, bestCpu);
    return 0;
}

/// error: every mesh file against the reference's distance (the image read is the sdf grid).
int runError(const Args& a, const openvdb::FloatGrid::Ptr& sdf)
{
    std::printf("%s", bench::kMeshCsvHeader);
    for (const std::string& path : a.meshes) {
        const Mesh mesh = [&] {
            try {
                return readMesh(path);
            } catch (const std::exception& e) {
                throw BadInput(e.what());
            }
        }();
        std::vector<openvdb::Vec3d> points;
        std::vector<openvdb::Vec3I> triangles;
        vdb::meshArrays(mesh, points, triangles);
        bench::printMeshCsvRow(a.label, "file", path, points, triangles, sdf.get(), 0, 0);
    }
    return 0;
}

} // namespace

int main(int argc, char** argv)
{
    return bench::benchMain("vdb_bench", argc, argv, parseArgs, [](const Args& args, const openvdb::FloatGrid::Ptr& image) {
        if (args.mode == "error") return runError(args, image);
        return args.mode == "mesh" ? runMesh(args, image) : runMetric(args, image);
    });
}
