// bench/bench_common.h: what vdb_bench and cgal_bench share: timing, the CSV row of a measured mesh
// (topology counted on its index arrays, errors by the same code as vdb2mesh --reference), and the
// main() that reads the image and maps failures to exit codes (1 bad input, 2 internal).
#pragma once

#include "../vdb/apps/cli.h"
#include "riemesh/vdb/io.h"
#include "riemesh/vdb/level_set.h"
#include "riemesh/vdb/volume.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <numeric>
#include <string>
#include <unordered_map>
#include <vector>

namespace riemesh::bench {

using Clock = std::chrono::steady_clock;

inline double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

/// A CSV field, quoted when it holds a comma.
inline std::string csvField(const std::string& s) { return s.find(',') == std::string::npos ? s : "\"" + s + "\""; }

struct SoupTopology {
    std::size_t vertices = 0, triangles = 0;
    int components = 0, euler = 0, genus = 0;
    std::size_t boundaryEdges = 0, nonManifoldEdges = 0, misorientedEdges = 0;
    bool closedManifold() const { return boundaryEdges == 0 && nonManifoldEdges == 0 && misorientedEdges == 0; }
};

/// Counts on index arrays, so that open or non-manifold output (which OpenMesh would refuse) is still
/// counted and flagged rather than silently repaired.
inline SoupTopology topologyOf(std::size_t pointCount, const std::vector<openvdb::Vec3I>& triangles)
{
    SoupTopology t;
    t.triangles = triangles.size();
    std::vector<int> parent(pointCount);
    std::iota(parent.begin(), parent.end(), 0);
    const auto find = [&](int x) {
        while (parent[x] != x) x = parent[x] = parent[parent[x]];
        return x;
    };
    std::vector<bool> used(pointCount, false);
    // Directed edges: a closed oriented manifold has each (a,b) once and its reverse once.
    std::unordered_map<std::uint64_t, std::array<int, 2>> edges; // key min<<32|max -> (forward, backward)
    for (const auto& tri : triangles)
        for (int e = 0; e < 3; ++e) {
            const std::uint32_t a = tri[e], b = tri[(e + 1) % 3];
            used[a] = true;
            parent[find(int(a))] = find(int(b));
            ++edges[(std::uint64_t(std::min(a, b)) << 32) | std::max(a, b)][a < b ? 0 : 1];
        }
    for (const auto& [key, count] : edges) {
        const int faces = count[0] + count[1];
        if (faces == 1) ++t.boundaryEdges;
        else if (faces > 2) ++t.nonManifoldEdges;
        else if (count[0] != 1) ++t.misorientedEdges;
    }
    for (std::size_t i = 0; i < used.size(); ++i)
        if (used[i]) {
            ++t.vertices;
            t.components += find(int(i)) == int(i);
        }
    t.euler = int(t.vertices) - int(edges.size()) + int(t.triangles);
    t.genus = (2 * t.components - t.euler) / 2;
    return t;
}

/// The header of the mesh rows.
inline constexpr const char* kMeshCsvHeader =
    "image,tool,setting,vertices,triangles,mean_voxels,hausdorff_voxels,components,genus,closed_manifold,"
    "boundary_edges,bad_edges,seconds,smooth_seconds,surface_mean_voxels\n";

/// Prints one mesh row: its topology and, against `sdf` when given, its errors in voxels (as
/// vdb2mesh --reference measures them).
inline void printMeshCsvRow(const std::string& label, const std::string& tool, const std::string& setting,
                            const std::vector<openvdb::Vec3d>& points, const std::vector<openvdb::Vec3I>& triangles,
                            const openvdb::FloatGrid* sdf, double smoothSeconds, double meshSeconds)
{
    const SoupTopology t = topologyOf(points.size(), triangles);
    std::string mean, hausdorff, surfaceMean;
    if (sdf) {
        const vdb::SurfaceError e = vdb::surfaceError(points, triangles, *sdf, vdb::phantomReferenceDistance(*sdf));
        const double h = sdf->transform().voxelSize()[0];
        char buf[64];
        std::snprintf(buf, sizeof buf, "%.4f", e.meanMeshToSurface / h);
        mean = buf;
        std::snprintf(buf, sizeof buf, "%.4f", e.hausdorff / h);
        hausdorff = buf;
        std::snprintf(buf, sizeof buf, "%.4f", e.meanSurfaceToMesh / h);
        surfaceMean = buf;
    }
    std::printf("%s,%s,%s,%zu,%zu,%s,%s,%d,%d,%d,%zu,%zu,%.4f,%.4f,%s\n", csvField(label).c_str(), tool.c_str(),
                csvField(setting).c_str(), t.vertices, t.triangles, mean.c_str(), hausdorff.c_str(), t.components,
                t.genus, t.closedManifold() ? 1 : 0, t.boundaryEdges, t.nonManifoldEdges + t.misorientedEdges,
                smoothSeconds + meshSeconds, smoothSeconds, surfaceMean.c_str());
    std::fflush(stdout);
}

/// main() of a bench tool: parse(argc, argv) gives the arguments (with .image, .grid, .threads),
/// the image is read, then run(args, image) works with the thread limit. BadInput and unreadable
/// images: exit 1; anything else: exit 2; one line "NAME: error: ..." on stderr.
template<typename Parse, typename Run>
int benchMain(const char* name, int argc, char** argv, Parse parse, Run run)
{
    decltype(parse(argc, argv)) args;
    openvdb::FloatGrid::Ptr image;
    try {
        args = parse(argc, argv);
        try {
            image = vdb::readImage(args.image, args.grid);
        } catch (const std::exception& e) {
            throw apps::BadInput(e.what());
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: error: %s\n", name, e.what());
        return 1;
    }
    try {
        auto threadLimit = vdb::limitThreads(args.threads);
        return run(args, image);
    } catch (const apps::BadInput& e) {
        std::fprintf(stderr, "%s: error: %s\n", name, e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: error: %s\n", name, e.what());
        return 2;
    }
}

} // namespace riemesh::bench
