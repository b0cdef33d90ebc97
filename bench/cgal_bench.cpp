// cgal_bench: CGAL Mesh_3 as a peer of riemesh and volumeToMesh on the same images (issue 16).
//
//   cgal_bench IMAGE --facet-distance D [--facet-size S] [--facet-angle A] [--grid G] [--iso V]
//              [--gaussian W:I|none] [--reference FILE.vdb[:GRID]] [--out MESH.ply] [--label TEXT]
//              [--initial-points N] [--seed N] [--non-manifold] [--threads N]
//
// The image is smoothed exactly as vdb_bench mesh smooths it for volumeToMesh (OpenVDB
// tools::Filter::gaussian(W, I), default 1:1): on the raw noisy phantoms an implicit-function mesher
// makes garbage, and both peers must see the same image. The smoothed values are copied into a dense
// block (the active box plus 2 voxels of background) and CGAL meshes the implicit function
// f(x) = iso - (trilinear interpolation of the values at x) (negative inside; for level sets
// value - iso) with CGAL::Labeled_mesh_domain_3::create_implicit_mesh_domain, bounded by the sphere
// around the block. Criteria: facet_angle A (default 30 degrees), facet_size S (voxels; 0 = no bound,
// the default), facet_distance D (voxels); no cell criteria, and no perturbation or exudation (they
// only improve tetrahedra; the surface is what is compared). With the manifold() option (default:
// the boundary is a closed 2-manifold) unless --non-manifold. --initial-points N: the points CGAL
// shoots on the surface before refining (its default: 12); more of them let it find thin parts that
// coarse Delaunay balls step over (a thin plate). --seed fixes CGAL's random shooting.
//
// The boundary surface (facets between the inside subdomain and the outside, normals out) is
// measured with the same code as vdb2mesh --reference and vdb_bench (vdb/level_set.h surfaceError,
// two-sided, dense samples of both surfaces, the phantom's exact edges and corners included), its
// topology counted on the triangle arrays as vdb_bench counts its peers', and written as a binary
// PLY with --out. One CSV row on stdout with vdb_bench mesh's columns. Meshing is sequential (CGAL's
// Sequential_tag; smoothing uses TBB like vdb_bench). Lengths in voxels of the image (its voxel size
// along x).
//
// This file includes CGAL's Mesh_3 and OpenVDB: it takes minutes and GBs to compile; keep it one
// translation unit.
#include "bench_common.h"
#include "../vdb/apps/cli.h"
#include "riemesh/vdb/io.h"
#include "riemesh/vdb/level_set.h"
#include "riemesh/vdb/volume.h"

#include <openvdb/tools/Filter.h>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Labeled_mesh_domain_3.h>
#include <CGAL/Mesh_complex_3_in_triangulation_3.h>
#include <CGAL/Mesh_criteria_3.h>
#include <CGAL/Mesh_triangulation_3.h>
#include <CGAL/Random.h>
#include <CGAL/facets_in_complex_3_to_triangle_mesh.h>
#include <CGAL/make_mesh_3.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <functional>
#include <numeric>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

using namespace riemesh;
using apps::BadInput;

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_3;
using Domain = CGAL::Labeled_mesh_domain_3<K>;
using Tr = CGAL::Mesh_triangulation_3<Domain, CGAL::Default, CGAL::Sequential_tag>::type;
using C3t3 = CGAL::Mesh_complex_3_in_triangulation_3<Tr>;
using Criteria = CGAL::Mesh_criteria_3<Tr>;

using bench::Clock;
using bench::secondsSince;

struct Args {
    std::string image, grid, reference, referenceGrid = "sdf", out, label;
    std::optional<double> iso;
    int gaussianWidth = 1, gaussianIterations = 1; // width 0: no smoothing
    double facetDistance = 0, facetSize = 0, facetAngle = 30; // voxels, voxels, degrees
    int seed = 1, threads = 0, initialPoints = -1; // -1: CGAL's default
    bool manifold = true;
};

const char* kUsage =
    "usage: cgal_bench IMAGE --facet-distance D [--facet-size S] [--facet-angle A] [--grid G] [--iso V]\n"
    "                  [--gaussian W:I|none] [--reference FILE.vdb[:GRID]] [--out MESH.ply] [--label TEXT]\n"
    "                  [--initial-points N] [--seed N] [--non-manifold] [--threads N]\n"
    "CGAL Mesh_3 on the implicit function iso - trilinear(image) after OpenVDB's Gaussian (W:I, default 1:1,\n"
    "as vdb_bench mesh). D, S in voxels (S 0: no size bound, the default), A in degrees (default 30).\n"
    "One CSV row with vdb_bench mesh's columns; errors (with --reference) by vdb/level_set.h surfaceError.\n";

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
        const auto positive = [&](double lo) {
            const double x = apps::parseNumber(f, value());
            if (!(x >= lo)) throw BadInput(f + ": must be >= " + std::to_string(lo));
            return x;
        };
        if (f == "-h" || f == "--help") {
            std::fputs(kUsage, stdout);
            std::exit(0);
        } else if (f == "--grid") a.grid = value();
        else if (f == "--iso") a.iso = apps::parseNumber(f, value());
        else if (f == "--facet-distance") a.facetDistance = positive(1e-6);
        else if (f == "--facet-size") a.facetSize = positive(0);
        else if (f == "--facet-angle") {
            a.facetAngle = positive(0);
            if (a.facetAngle > 30) throw BadInput("--facet-angle: above 30 degrees the mesher may not terminate");
        } else if (f == "--reference") {
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
                a.gaussianWidth = apps::parseCount(f, v.substr(0, colon), 1);
                a.gaussianIterations = apps::parseCount(f, v.substr(colon + 1), 1);
            }
        } else if (f == "--out") {
            a.out = value();
            if (vdb::fileExtension(a.out) != ".ply") throw BadInput("--out: '" + a.out + "' is not a .ply file");
        } else if (f == "--label") a.label = value();
        else if (f == "--initial-points") a.initialPoints = apps::parseCount(f, value(), 1);
        else if (f == "--seed") a.seed = apps::parseCount(f, value(), 0);
        else if (f == "--threads") a.threads = apps::parseCount(f, value(), 0);
        else if (f == "--non-manifold") a.manifold = false;
        else if (!f.empty() && f[0] == '-') throw BadInput("unknown option '" + f + "' (see --help)");
        else positional.push_back(f);
    }
    if (positional.size() != 1) throw BadInput("expected one IMAGE (see --help)");
    if (a.facetDistance <= 0) throw BadInput("--facet-distance is required (voxels)");
    a.image = positional[0];
    if (a.label.empty()) a.label = a.image;
    return a;
}

/// The smoothed image as a dense block with trilinear interpolation in world space: the implicit
/// function CGAL meshes (negative inside).
class DenseImage {
public:
    DenseImage(const openvdb::FloatGrid& grid, double iso, bool brighterInside)
        : mXform(grid.transform().copy()), mSign(brighterInside ? -1.0 : 1.0), mIso(iso)
    {
        openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
        box.expand(2); // background around the object, so the surface closes inside the block
        mLo = box.min();
        const openvdb::Coord dim = box.dim();
        mNx = dim.x();
        mNy = dim.y();
        mNz = dim.z();
        mValues.resize(std::size_t(mNx) * mNy * mNz);
        auto acc = grid.getConstAccessor();
        for (int k = 0; k < mNz; ++k)
            for (int j = 0; j < mNy; ++j)
                for (int i = 0; i < mNx; ++i)
                    mValues[(std::size_t(k) * mNy + j) * mNx + i] = acc.getValue(mLo.offsetBy(i, j, k));
        mBackground = grid.background();
        const double sign = mSign, level = mIso;
        mInside = std::count_if(mValues.begin(), mValues.end(), [&](float v) { return sign * (v - level) < 0; });
    }

    /// Voxels inside the surface (f < 0): with none, CGAL's search for initial points never ends.
    std::size_t insideVoxels() const { return mInside; }

    /// f(x) at a world-space point: sign * (value - iso), value trilinear between voxel centres.
    double operator()(const Point& p) const
    {
        const openvdb::Vec3d x = mXform->worldToIndex(openvdb::Vec3d(p.x(), p.y(), p.z())) - mLo.asVec3d();
        const double fx = std::floor(x[0]), fy = std::floor(x[1]), fz = std::floor(x[2]);
        const int i = int(fx), j = int(fy), k = int(fz);
        if (i < 0 || j < 0 || k < 0 || i + 1 >= mNx || j + 1 >= mNy || k + 1 >= mNz)
            return mSign * (mBackground - mIso);
        const double tx = x[0] - fx, ty = x[1] - fy, tz = x[2] - fz;
        const float* c = &mValues[(std::size_t(k) * mNy + j) * mNx + i];
        const std::size_t sy = std::size_t(mNx), sz = std::size_t(mNx) * mNy;
        const auto lerp = [](double a, double b, double t) { return a + (b - a) * t; };
        const double v = lerp(lerp(lerp(c[0], c[1], tx), lerp(c[sy], c[sy + 1], tx), ty),
                              lerp(lerp(c[sz], c[sz + 1], tx), lerp(c[sz + sy], c[sz + sy + 1], tx), ty), tz);
        return mSign * (v - mIso);
    }

    /// The block's world-space centre and the radius of a sphere that contains it.
    Point centre() const
    {
        const openvdb::Vec3d c = mXform->indexToWorld(mLo.asVec3d() + 0.5 * openvdb::Vec3d(mNx - 1, mNy - 1, mNz - 1));
        return Point(c.x(), c.y(), c.z());
    }
    double radius() const
    {
        double r = 0;
        const openvdb::Vec3d c(centre().x(), centre().y(), centre().z());
        for (int b = 0; b < 8; ++b) {
            const openvdb::Vec3d corner(b & 1 ? mNx - 1 : 0, b & 2 ? mNy - 1 : 0, b & 4 ? mNz - 1 : 0);
            r = std::max(r, (mXform->indexToWorld(mLo.asVec3d() + corner) - c).length());
        }
        return r * 1.01;
    }

private:
    openvdb::math::Transform::Ptr mXform;
    double mSign, mIso;
    float mBackground = 0;
    openvdb::Coord mLo;
    int mNx = 0, mNy = 0, mNz = 0;
    std::vector<float> mValues;
    std::size_t mInside = 0;
};

/// Topology counted on the index arrays, as vdb_bench counts its peers' (open or non-manifold output
/// is counted and flagged, never repaired).

void writePly(const std::string& path, const std::vector<openvdb::Vec3d>& points,
              const std::vector<openvdb::Vec3I>& triangles, const std::string& comment)
{
    vdb::writeFileAtomically(path, [&](const std::string& temp) {
        std::ofstream out(temp, std::ios::binary);
        out << "ply\nformat binary_little_endian 1.0\ncomment " << comment << "\nelement vertex " << points.size()
            << "\nproperty float x\nproperty float y\nproperty float z\nelement face " << triangles.size()
            << "\nproperty list uchar int vertex_indices\nend_header\n";
        for (const auto& p : points) {
            const float xyz[3] = {float(p.x()), float(p.y()), float(p.z())};
            out.write(reinterpret_cast<const char*>(xyz), sizeof xyz);
        }
        for (const auto& t : triangles) {
            const unsigned char n = 3;
            const std::int32_t idx[3] = {std::int32_t(t[0]), std::int32_t(t[1]), std::int32_t(t[2])};
            out.write(reinterpret_cast<const char*>(&n), 1);
            out.write(reinterpret_cast<const char*>(idx), sizeof idx);
        }
        out.close();
        if (!out) throw std::runtime_error("'" + path + "': write failed");
    });
}


int run(const Args& a, const openvdb::FloatGrid::Ptr& image)
{
    const std::string gclass = vdb::gridClassName(*image);
    const double iso = a.iso ? *a.iso : gclass == "fog" ? 0.5 : gclass == "levelset" ? 0.0 : NAN;
    if (std::isnan(iso)) throw BadInput("'" + a.image + "': not a fog volume or level set: give --iso");
    openvdb::FloatGrid::Ptr sdf;
    if (!a.reference.empty()) {
        try {
            sdf = vdb::readVdbImage(a.reference, a.referenceGrid);
        } catch (const std::exception& e) {
            throw BadInput(std::string("--reference: ") + e.what());
        }
    }
    const double h = image->transform().voxelSize()[0]; // voxels -> world units

    // The same smoothing as vdb_bench mesh.
    auto t0 = Clock::now();
    openvdb::FloatGrid::Ptr smooth = image->deepCopy();
    if (a.gaussianWidth > 0) {
        openvdb::tools::Filter<openvdb::FloatGrid> filter(*smooth);
        filter.gaussian(a.gaussianWidth, a.gaussianIterations);
    }
    const double smoothSeconds = secondsSince(t0);

    t0 = Clock::now();
    const DenseImage dense(*smooth, iso, gclass != "levelset");
    smooth.reset();
    if (dense.insideVoxels() == 0)
        throw std::runtime_error("no voxel is inside the surface at iso " + std::to_string(iso) + " after smoothing");
    CGAL::Random rng(unsigned(a.seed));
    CGAL::get_default_random() = CGAL::Random(unsigned(a.seed));
    namespace params = CGAL::parameters;
    const Domain domain = Domain::create_implicit_mesh_domain(
        std::function<double(const Point&)>(std::cref(dense)),
        K::Sphere_3(dense.centre(), dense.radius() * dense.radius()), params::relative_error_bound = 1e-6,
        params::p_rng = &rng);
    const Criteria criteria(params::facet_angle = a.facetAngle, params::facet_size = a.facetSize * h,
                            params::facet_distance = a.facetDistance * h);
    const auto options = params::mesh_3_options(params::number_of_initial_points = a.initialPoints);
    const C3t3 c3t3 = a.manifold ? CGAL::make_mesh_3<C3t3>(domain, criteria, params::no_perturb(), params::no_exude(),
                                                         params::manifold(), options)
                                 : CGAL::make_mesh_3<C3t3>(domain, criteria, params::no_perturb(), params::no_exude(),
                                                         params::non_manifold(), options);

    // The boundary of the inside subdomain (index 1), normals pointing out of it.
    std::vector<Point> cgalPoints;
    std::vector<std::array<std::size_t, 3>> faces;
    CGAL::Mesh_3::internal::facets_in_complex_3_to_triangle_soup(c3t3, C3t3::Subdomain_index(1), cgalPoints, faces,
                                                                  true, false);
    const double meshSeconds = secondsSince(t0);
    std::vector<openvdb::Vec3d> points;
    points.reserve(cgalPoints.size());
    for (const Point& p : cgalPoints) points.emplace_back(p.x(), p.y(), p.z());
    std::vector<openvdb::Vec3I> triangles;
    triangles.reserve(faces.size());
    for (const auto& f : faces) triangles.emplace_back(openvdb::Index32(f[0]), openvdb::Index32(f[1]), openvdb::Index32(f[2]));

    if (triangles.empty()) throw std::runtime_error("CGAL Mesh_3 found no surface");
    const std::string smoothing = a.gaussianWidth > 0
        ? "gauss " + std::to_string(a.gaussianWidth) + ":" + std::to_string(a.gaussianIterations) : "raw";
    char setting[160];
    std::snprintf(setting, sizeof setting, "%s d=%g s=%g angle=%g%s%s", smoothing.c_str(), a.facetDistance,
                  a.facetSize, a.facetAngle, a.initialPoints > 0 ? (" ip=" + std::to_string(a.initialPoints)).c_str() : "",
                  a.manifold ? "" : " non-manifold");
    std::printf("%s", bench::kMeshCsvHeader);
    bench::printMeshCsvRow(a.label, "cgal-mesh3", setting, points, triangles, sdf.get(), smoothSeconds, meshSeconds);
    if (!a.out.empty()) writePly(a.out, points, triangles, std::string("cgal_bench Mesh_3 ") + setting);
    return 0;
}

} // namespace

int main(int argc, char** argv) { return bench::benchMain("cgal_bench", argc, argv, parseArgs, run); }
