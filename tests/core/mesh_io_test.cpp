#include "mesh_invariants.h"
#include "riemesh/mesh_io.h"
#include "riemesh/primitives.h"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <dirent.h>
#include <sys/stat.h>
#include <unistd.h>

using namespace riemesh;

namespace {

/// A fresh folder under $TMPDIR (or /tmp), removed with its files (one level of subfolders) at exit.
class TempFolder {
public:
    TempFolder()
    {
        const char* base = std::getenv("TMPDIR");
        std::string pattern = std::string(base && *base ? base : "/tmp") + "/riemesh-io-XXXXXX";
        std::vector<char> name(pattern.begin(), pattern.end());
        name.push_back('\0');
        REQUIRE(::mkdtemp(name.data()) != nullptr);
        mPath = name.data();
    }
    ~TempFolder() { removeTree(mPath); }
    TempFolder(const TempFolder&) = delete;
    TempFolder& operator=(const TempFolder&) = delete;

    std::string file(const std::string& name) const { return mPath + "/" + name; }
    const std::string& path() const { return mPath; }

    /// Names of the entries in the folder (no "." or "..").
    std::vector<std::string> entries() const { return list(mPath); }

private:
    static std::vector<std::string> list(const std::string& folder)
    {
        std::vector<std::string> names;
        if (DIR* dir = ::opendir(folder.c_str())) {
            while (dirent* e = ::readdir(dir)) {
                std::string n = e->d_name;
                if (n != "." && n != "..") names.push_back(n);
            }
            ::closedir(dir);
        }
        std::sort(names.begin(), names.end());
        return names;
    }
    static void removeTree(const std::string& folder)
    {
        for (const auto& n : list(folder)) {
            const std::string p = folder + "/" + n;
            struct stat st {};
            if (::lstat(p.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) removeTree(p);
            else ::unlink(p.c_str());
        }
        ::rmdir(folder.c_str());
    }
    std::string mPath;
};

void writeBytes(const std::string& path, const std::string& bytes)
{
    std::ofstream out(path, std::ios::binary);
    out.write(bytes.data(), std::streamsize(bytes.size()));
    REQUIRE(out.good());
}

std::string readBytes(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}


/// The message of the std::runtime_error that `f` throws ("" if it does not throw one).
template <class F> std::string runtimeErrorOf(F&& f)
{
    try {
        f();
    } catch (const std::runtime_error& e) {
        return e.what();
    }
    return "";
}

Mesh reversedCopy(const Mesh& mesh)
{
    Mesh flipped;
    std::vector<VertexHandle> vh(mesh.n_vertices());
    for (auto v : mesh.vertices()) vh[v.idx()] = flipped.add_vertex(mesh.point(v));
    for (auto f : mesh.faces()) {
        std::vector<VertexHandle> face;
        for (auto v : mesh.fv_range(f)) face.push_back(vh[v.idx()]);
        std::reverse(face.begin(), face.end());
        flipped.add_face(face);
    }
    return flipped;
}

void appendLE(std::string& out, const void* value, std::size_t n)
{
    // Test host is little-endian (x86 and wasm); the library itself does not assume it.
    out.append(static_cast<const char*>(value), n);
}
template <class T> void put(std::string& out, T value) { appendLE(out, &value, sizeof(T)); }

// Outward unit tetrahedron (volume 1/6).
const double kTetPoints[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
const int kTetFaces[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};

const MeshFormat kAllFormats[] = {MeshFormat::Obj, MeshFormat::Ply, MeshFormat::PlyAscii, MeshFormat::Off,
                                  MeshFormat::Stl};

const char* extensionOf(MeshFormat format)
{
    switch (format) {
    case MeshFormat::Obj: return ".obj";
    case MeshFormat::Ply: return ".ply";
    case MeshFormat::PlyAscii: return ".ply";
    case MeshFormat::Off: return ".off";
    case MeshFormat::Stl: return ".stl";
    }
    return "";
}

const char* nameOf(MeshFormat format)
{
    switch (format) {
    case MeshFormat::Obj: return "obj";
    case MeshFormat::Ply: return "binary ply";
    case MeshFormat::PlyAscii: return "ascii ply";
    case MeshFormat::Off: return "off";
    case MeshFormat::Stl: return "stl";
    }
    return "";
}

/// Checks that `read` has the vertices of `original` to float precision: index by index when the
/// format keeps the order, otherwise (STL) each read vertex has an original one at that position.
void checkSamePositions(const Mesh& original, const Mesh& read, bool sameOrder, double scale)
{
    const double tolerance = 4 * scale * double(std::numeric_limits<float>::epsilon());
    std::vector<Vec3> points;
    for (auto v : original.vertices()) points.push_back(position(original, v));
    std::size_t i = 0, bad = 0;
    for (auto v : read.vertices()) {
        const Vec3 p = position(read, v);
        double best = std::numeric_limits<double>::infinity();
        if (sameOrder) best = (p - points[i]).norm();
        else
            for (const Vec3& q : points) best = std::min(best, (p - q).norm());
        if (best > tolerance) ++bad;
        ++i;
    }
    CHECK(bad == 0);
}

} // namespace

TEST_CASE("mesh_io: the format follows the extension, case-insensitively")
{
    CHECK(meshFormatFromPath("a/b.obj") == MeshFormat::Obj);
    CHECK(meshFormatFromPath("B.PLY") == MeshFormat::Ply);
    CHECK(meshFormatFromPath("dir.v2/mesh.Off") == MeshFormat::Off);
    CHECK(meshFormatFromPath("x.StL") == MeshFormat::Stl);
    try {
        meshFormatFromPath("points.xyz");
        FAIL("no exception for .xyz");
    } catch (const std::invalid_argument& e) {
        CHECK(std::string(e.what()).find("'.xyz'") != std::string::npos);
    }
    CHECK_THROWS_AS(meshFormatFromPath("dir.obj/noextension"), std::invalid_argument);
}

TEST_CASE("mesh_io: an icosphere and a torus survive a round trip through every format")
{
    TempFolder folder;
    const Mesh sphere = makeIcosphere(Vec3(1, -2, 3), 2.5, 3);
    const Mesh torus = makeTorus(Vec3(0.5, 0, -1), 5.0, 2.0, 24, 12);
    for (const Mesh* original : {&sphere, &torus}) {
        const auto topology = topologyOf(*original);
        const double volume = signedVolume(*original);
        for (MeshFormat format : kAllFormats) {
            CAPTURE(nameOf(format));
            CAPTURE(topology.genus);
            const std::string path = folder.file(std::string("round_trip") + extensionOf(format));
            writeMesh(path, *original, format, "round trip test");
            const Mesh read = readMesh(path);
            REQUIRE_MESH_OK(read);
            const auto t = topologyOf(read);
            CHECK(t.vertices == topology.vertices);
            CHECK(t.faces == topology.faces);
            CHECK(t.euler == topology.euler);
            CHECK(t.components == topology.components);
            CHECK(signedVolume(read) > 0);
            CHECK(signedVolume(read) == doctest::Approx(volume).epsilon(1e-5));
            checkSamePositions(*original, read, format != MeshFormat::Stl, 10.0);
        }
    }
    CHECK(folder.entries() == std::vector<std::string>{"round_trip.obj", "round_trip.off", "round_trip.ply",
                                                       "round_trip.stl"});
}

TEST_CASE("mesh_io: obj and off keep double precision positions exactly")
{
    TempFolder folder;
    const Mesh sphere = makeIcosphere(Vec3(0.1, 0.2, 0.3), 1.0 / 3.0, 2);
    for (const char* name : {"exact.obj", "exact.off"}) {
        writeMesh(folder.file(name), sphere);
        const Mesh read = readMesh(folder.file(name));
        std::size_t differing = 0;
        for (auto v : sphere.vertices())
            if (read.point(VertexHandle(v.idx())) != sphere.point(v)) ++differing;
        CHECK(differing == 0);
    }
}

TEST_CASE("mesh_io: an inside-out mesh is written with outward normals")
{
    TempFolder folder;
    const Mesh inside = reversedCopy(makeIcosphere(Vec3(3, 3, 3), 1.0, 2));
    REQUIRE(signedVolume(inside) < 0);
    // Every stored STL facet normal points away from the sphere centre.
    const std::string path = folder.file("inside_out.stl");
    writeMesh(path, inside);
    const std::string bytes = readBytes(path);
    REQUIRE(bytes.size() == 84 + 50 * inside.n_faces());
    std::size_t inward = 0;
    for (std::size_t f = 0; f < inside.n_faces(); ++f) {
        float v[12];
        std::memcpy(v, bytes.data() + 84 + 50 * f, sizeof(v));
        const Vec3 normal(v[0], v[1], v[2]);
        const Vec3 centroid = (Vec3(v[3], v[4], v[5]) + Vec3(v[6], v[7], v[8]) + Vec3(v[9], v[10], v[11])) / 3.0;
        if (normal.dot(centroid - Vec3(3, 3, 3)) <= 0) ++inward;
    }
    CHECK(inward == 0);
    // Every format reads back outward.
    for (MeshFormat format : kAllFormats) {
        CAPTURE(nameOf(format));
        const std::string p = folder.file(std::string("inside_out") + extensionOf(format));
        writeMesh(p, inside, format);
        CHECK(signedVolume(readMesh(p)) > 0);
    }
}

TEST_CASE("mesh_io: a file wound inside-out is read outward")
{
    TempFolder folder;
    std::ostringstream obj;
    for (const auto& p : kTetPoints) obj << "v " << p[0] << ' ' << p[1] << ' ' << p[2] << '\n';
    for (const auto& f : kTetFaces) obj << "f " << f[0] + 1 << ' ' << f[2] + 1 << ' ' << f[1] + 1 << '\n';
    writeBytes(folder.file("inward.obj"), obj.str());
    const Mesh read = readMesh(folder.file("inward.obj"));
    REQUIRE_MESH_OK(read);
    CHECK(signedVolume(read) == doctest::Approx(1.0 / 6.0));
}

TEST_CASE("mesh_io: deleted elements are skipped and indices written densely")
{
    TempFolder folder;
    Mesh mesh = makeIcosphere(Vec3(10, 0, 0), 1.0, 1); // deleted below
    prepareMesh(mesh);
    appendMesh(mesh, makeIcosphere(Vec3::Zero(), 1.0, 2));
    const std::size_t firstVertices = makeIcosphere(Vec3::Zero(), 1.0, 1).n_vertices();
    for (std::size_t i = 0; i < firstVertices; ++i) mesh.delete_vertex(VertexHandle(int(i)), true);
    const auto expected = topologyOf(mesh);
    REQUIRE(expected.components == 1);
    for (MeshFormat format : kAllFormats) {
        CAPTURE(nameOf(format));
        const std::string path = folder.file(std::string("deleted") + extensionOf(format));
        writeMesh(path, mesh, format);
        const Mesh read = readMesh(path);
        REQUIRE_MESH_OK(read);
        CHECK(topologyOf(read).vertices == expected.vertices);
        CHECK(topologyOf(read).faces == expected.faces);
    }
}

TEST_CASE("mesh_io: the comment goes into the file header (obj, ply, stl) or after the data (off)")
{
    TempFolder folder;
    const Mesh sphere = makeIcosphere(Vec3::Zero(), 1.0, 1);
    writeMesh(folder.file("c.obj"), sphere, "made by riemesh");
    writeMesh(folder.file("c.off"), sphere, "made by riemesh");
    writeMesh(folder.file("c.ply"), sphere, "made by riemesh");
    writeMesh(folder.file("c.stl"), sphere, "made by riemesh");
    CHECK(readBytes(folder.file("c.obj")).rfind("# made by riemesh\n", 0) == 0);
    // OFF: after the data, where every reader tolerates it (many fail on a comment before the counts).
    const std::string off = readBytes(folder.file("c.off"));
    CHECK(off.rfind("OFF\n42 80 0\n", 0) == 0);
    CHECK(off.substr(off.size() - 18) == "# made by riemesh\n");
    CHECK(readBytes(folder.file("c.ply")).rfind("ply\nformat binary_little_endian 1.0\ncomment made by riemesh\n", 0) == 0);
    CHECK(readBytes(folder.file("c.stl")).rfind("made by riemesh", 0) == 0);
    // A binary STL header must not start with "solid" (readers would take it for ascii).
    writeMesh(folder.file("s.stl"), sphere, "solid thing");
    CHECK(readBytes(folder.file("s.stl")).rfind("solid", 0) != 0);
    CHECK(readMesh(folder.file("s.stl")).n_faces() == sphere.n_faces());
}

TEST_CASE("mesh_io: obj with v/vt/vn face corners, negative indices and quads parses")
{
    TempFolder folder;
    // Unit cube, quads (fanned into triangles), corners in every OBJ form.
    const std::string obj = "# cube\r\nmtllib cube.mtl\no cube\n"
                            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
                            "vt 0 0\nvn 0 0 1\ns off\n"
                            "f 1/1/1 4/1/1 3/1/1 2/1/1\n"
                            "f 5//1 6//1 7//1 8//1\n"
                            "f 1/1 2/1 6/1 5/1\n"
                            "f -6 -5 -1 -2\n" // relative: 3 4 8 7, the y = 1 side
                            "f 2 3 7 6\n"
                            "f 4 1 5 8   # trailing comment\n";
    writeBytes(folder.file("cube.obj"), obj);
    const Mesh cube = readMesh(folder.file("cube.obj"));
    REQUIRE_MESH_OK(cube);
    CHECK(cube.n_vertices() == 8);
    CHECK(cube.n_faces() == 12);
    CHECK(signedVolume(cube) == doctest::Approx(1.0));
}

TEST_CASE("mesh_io: ascii stl parses and merges duplicate corners")
{
    TempFolder folder;
    std::ostringstream stl;
    stl << "solid tetra with facet in its name\n";
    for (const auto& f : kTetFaces) {
        stl << "  facet normal 0 0 0\n    outer loop\n";
        for (int k : f)
            stl << "      vertex " << kTetPoints[k][0] << ' ' << kTetPoints[k][1] << ' ' << kTetPoints[k][2] << '\n';
        stl << "    endloop\n  endfacet\n";
    }
    stl << "endsolid tetra\n";
    writeBytes(folder.file("tetra.stl"), stl.str());
    const Mesh tet = readMesh(folder.file("tetra.stl"));
    REQUIRE_MESH_OK(tet);
    CHECK(tet.n_vertices() == 4);
    CHECK(tet.n_faces() == 4);
    CHECK(signedVolume(tet) == doctest::Approx(1.0 / 6.0));
}

TEST_CASE("mesh_io: ply with double coordinates, extra properties and vertex_index lists parses")
{
    TempFolder folder;
    SUBCASE("binary")
    {
        std::string ply = "ply\nformat binary_little_endian 1.0\ncomment hand made\nobj_info x\n"
                          "element vertex 4\nproperty double x\nproperty float nx\nproperty double y\n"
                          "property double z\nproperty uchar red\nproperty list uchar float texcoord\n"
                          "element material 2\nproperty int id\n"
                          "element face 4\nproperty uchar flags\nproperty list int uint vertex_index\n"
                          "property list uchar float texcoord\nend_header\n";
        for (const auto& p : kTetPoints) {
            put(ply, p[0]);
            put(ply, 0.5f);
            put(ply, p[1]);
            put(ply, p[2]);
            put(ply, std::uint8_t(200));
            put(ply, std::uint8_t(2));
            put(ply, 0.25f);
            put(ply, 0.75f);
        }
        put(ply, std::int32_t(7));
        put(ply, std::int32_t(8));
        for (const auto& f : kTetFaces) {
            put(ply, std::uint8_t(1));
            put(ply, std::int32_t(3));
            for (int k : f) put(ply, std::uint32_t(k));
            put(ply, std::uint8_t(0));
        }
        writeBytes(folder.file("tet.ply"), ply);
    }
    SUBCASE("ascii")
    {
        std::string ply = "ply\r\nformat ascii 1.0\r\nelement vertex 4\r\nproperty float x\r\nproperty float y\r\n"
                          "property float z\r\nproperty list uchar int extra\r\nelement face 4\r\n"
                          "property list uchar int vertex_indices\r\nproperty float quality\r\nend_header\r\n";
        for (const auto& p : kTetPoints)
            ply += std::to_string(p[0]) + " " + std::to_string(p[1]) + " " + std::to_string(p[2]) + " 2 5 6\r\n";
        for (const auto& f : kTetFaces)
            ply += "3 " + std::to_string(f[0]) + " " + std::to_string(f[1]) + " " + std::to_string(f[2]) + " 1.5\r\n";
        writeBytes(folder.file("tet.ply"), ply);
    }
    const Mesh tet = readMesh(folder.file("tet.ply"));
    REQUIRE_MESH_OK(tet);
    CHECK(tet.n_vertices() == 4);
    CHECK(signedVolume(tet) == doctest::Approx(1.0 / 6.0));
}

TEST_CASE("mesh_io: off with counts on the header line and colours parses")
{
    TempFolder folder;
    std::string off = "COFF 4 4 6\n# comment\n";
    for (const auto& p : kTetPoints)
        off += std::to_string(p[0]) + " " + std::to_string(p[1]) + " " + std::to_string(p[2]) + " 255 0 0 255\n";
    for (const auto& f : kTetFaces)
        off += "3 " + std::to_string(f[0]) + " " + std::to_string(f[1]) + " " + std::to_string(f[2]) + " 0.1 0.2 0.3\n";
    writeBytes(folder.file("tet.off"), off);
    const Mesh tet = readMesh(folder.file("tet.off"));
    REQUIRE_MESH_OK(tet);
    CHECK(signedVolume(tet) == doctest::Approx(1.0 / 6.0));
}

TEST_CASE("mesh_io: bad input files throw errors that name the file and the problem")
{
    TempFolder folder;
    const Mesh sphere = makeIcosphere(Vec3::Zero(), 1.0, 2);
    auto expectError = [&](const std::string& name, const std::string& fragment) {
        const std::string path = folder.file(name);
        const std::string message = runtimeErrorOf([&] { readMesh(path); });
        CAPTURE(message);
        CHECK(message.find(path) != std::string::npos);
        CHECK(message.find(fragment) != std::string::npos);
    };

    SUBCASE("missing file") { expectError("missing.obj", "No such file"); }
    SUBCASE("empty file")
    {
        writeBytes(folder.file("empty.ply"), "");
        expectError("empty.ply", "empty");
    }
    SUBCASE("truncated binary ply")
    {
        writeMesh(folder.file("full.ply"), sphere);
        const std::string bytes = readBytes(folder.file("full.ply"));
        writeBytes(folder.file("cut.ply"), bytes.substr(0, bytes.size() - 7));
        expectError("cut.ply", "truncated");
        writeBytes(folder.file("cut_vertices.ply"), bytes.substr(0, bytes.find("end_header") + 40));
        expectError("cut_vertices.ply", "declares");
    }
    SUBCASE("truncated binary stl")
    {
        writeMesh(folder.file("full.stl"), sphere);
        const std::string bytes = readBytes(folder.file("full.stl"));
        writeBytes(folder.file("cut.stl"), bytes.substr(0, bytes.size() - 20));
        expectError("cut.stl", "truncated");
        writeBytes(folder.file("header.stl"), bytes.substr(0, 50));
        expectError("header.stl", "truncated");
    }
    SUBCASE("a lying header does not allocate")
    {
        writeBytes(folder.file("huge.ply"), "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\n"
                                            "property double x\nproperty double y\nproperty double z\n"
                                            "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                                            "0123456789");
        expectError("huge.ply", "declares 4000000000");
        writeBytes(folder.file("huge.off"), "OFF\n2000000000 1 0\n0 0 0\n");
        expectError("huge.off", "declares 2000000000");
        std::string stl(80, ' ');
        put(stl, std::uint32_t(0xffffffffu));
        writeBytes(folder.file("huge.stl"), stl + std::string(100, '\0'));
        expectError("huge.stl", "truncated");
    }
    SUBCASE("two faces on the same three corners (a pillow)")
    {
        // Closed and manifold, but each vertex has two neighbours. The CI fuzz finding of
        // 2026-11-27 (fuzz_mesh_read): an ascii STL facet with a repeated corner, fanned into a
        // triangle and its reverse; the same as an OBJ.
        writeBytes(folder.file("pillow.stl"), "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n"
                                              "   vertex 5 1 0\n   vertex 1 0 0\n   vertex 5 1 0\n  endloop\n"
                                              " endfacet\nendsolid t\n");
        expectError("pillow.stl", "fewer than 3 neighbours");
        writeBytes(folder.file("pillow.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 3 2\n");
        expectError("pillow.obj", "fewer than 3 neighbours");
    }
    SUBCASE("nan coordinate")
    {
        writeBytes(folder.file("nan.obj"), "v 0 0 0\nv 1 0 0\nv nan 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n");
        expectError("nan.obj", "non-finite");
        writeBytes(folder.file("inf.off"), "OFF\n4 4 0\n0 0 0\n1 0 0\n0 inf 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n");
        expectError("inf.off", "non-finite");
    }
    SUBCASE("malformed number")
    {
        writeBytes(folder.file("bad.obj"), "v 0 0 0\nv 1 0 0\nv 0 1x 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n");
        expectError("bad.obj", "line 3: malformed number '1x'");
    }
    SUBCASE("index out of range")
    {
        writeBytes(folder.file("range.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 99\n");
        expectError("range.obj", "vertex 99");
        writeBytes(folder.file("range.off"), "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 -1\n3 1 2 3\n");
        expectError("range.off", "vertex -1");
    }
    SUBCASE("face with two vertices")
    {
        writeBytes(folder.file("two.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n");
        expectError("two.obj", "2 vertices");
    }
    SUBCASE("open mesh")
    {
        writeBytes(folder.file("open.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
        expectError("open.obj", "not closed");
    }
    SUBCASE("non-manifold edge")
    {
        // Tetrahedron plus a fin on edge 0-1: three faces share that edge.
        writeBytes(folder.file("fin.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 0 -1 -1\n"
                                           "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\nf 1 2 5\n");
        expectError("fin.obj", "1 of 5 triangles could not be added");
    }
    SUBCASE("two tetrahedra touching at a vertex")
    {
        std::string off = "OFF\n7 8 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n-1 0 0\n0 -1 0\n0 0 -1\n";
        for (const auto& f : kTetFaces) off += "3 " + std::to_string(f[0]) + " " + std::to_string(f[1]) + " " + std::to_string(f[2]) + "\n";
        // Mirror image through the origin (shares vertex 0); mirroring flips winding, so swap.
        for (const auto& f : kTetFaces) {
            auto m = [](int k) { return k == 0 ? 0 : k + 3; };
            off += "3 " + std::to_string(m(f[0])) + " " + std::to_string(m(f[2])) + " " + std::to_string(m(f[1])) + "\n";
        }
        writeBytes(folder.file("bowtie.off"), off);
        const std::string message = runtimeErrorOf([&] { readMesh(folder.file("bowtie.off")); });
        CAPTURE(message);
        CHECK(message.find("bowtie.off") != std::string::npos);
        CHECK((message.find("non-manifold") != std::string::npos || message.find("could not be added") != std::string::npos));
    }
    SUBCASE("not the format the extension says")
    {
        writeBytes(folder.file("text.ply"), "hello\n");
        expectError("text.ply", "not a PLY file");
    }
}

TEST_CASE("mesh_io: writing into a missing folder throws and creates nothing")
{
    TempFolder folder;
    const Mesh sphere = makeIcosphere(Vec3::Zero(), 1.0, 1);
    const std::string path = folder.file("no_such_dir/out.ply");
    const std::string message = runtimeErrorOf([&] { writeMesh(path, sphere); });
    CAPTURE(message);
    CHECK(message.find(path) != std::string::npos);
    CHECK(message.find("does not exist") != std::string::npos);
    CHECK(folder.entries().empty());
}

TEST_CASE("mesh_io: a failed write leaves the existing target intact and no temporary file")
{
    TempFolder folder;
    const Mesh sphere = makeIcosphere(Vec3::Zero(), 1.0, 1);
    SUBCASE("the target is a folder: the final rename fails")
    {
        REQUIRE(::mkdir(folder.file("taken.obj").c_str(), 0755) == 0);
        writeBytes(folder.file("taken.obj/keep.txt"), "precious");
        const std::string message = runtimeErrorOf([&] { writeMesh(folder.file("taken.obj"), sphere); });
        CAPTURE(message);
        CHECK(message.find(folder.file("taken.obj")) != std::string::npos);
        CHECK(readBytes(folder.file("taken.obj/keep.txt")) == "precious");
        CHECK(folder.entries() == std::vector<std::string>{"taken.obj"});
    }
    SUBCASE("the mesh cannot be written: the old file is kept")
    {
        const std::string path = folder.file("existing.stl");
        writeMesh(path, sphere);
        const std::string before = readBytes(path);
        Mesh broken = makeIcosphere(Vec3::Zero(), 1.0, 1);
        broken.point(VertexHandle(3))[1] = std::numeric_limits<double>::quiet_NaN();
        const std::string message = runtimeErrorOf([&] { writeMesh(path, broken); });
        CAPTURE(message);
        CHECK(message.find(path) != std::string::npos);
        CHECK(message.find("non-finite") != std::string::npos);
        CHECK(readBytes(path) == before);
        CHECK(folder.entries() == std::vector<std::string>{"existing.stl"});
    }
    SUBCASE("a successful write replaces the file and keeps nothing else")
    {
        const std::string path = folder.file("replace.off");
        writeBytes(path, "old contents");
        writeMesh(path, sphere);
        CHECK(readMesh(path).n_faces() == sphere.n_faces());
        CHECK(folder.entries() == std::vector<std::string>{"replace.off"});
    }
}
