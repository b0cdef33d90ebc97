// render_mesh: a mesh as a PNG picture, for benchmark reports and for looking at results without a
// display (off-screen software rasteriser: no GL; zlib for the PNG deflate).
//
//   render_mesh MESH OUTPUT.png [--size WxH] [--view iso|front|top|side|AZ,EL] [--views 4]
//               [--wire] [--smooth] [--color none|edge-length|curvature] [--clip AXIS:VALUE]
//               [--title TEXT]
//   render_mesh --self-test OUTPUT.png
//
// MESH is anything readMesh() reads (.obj .ply .off .stl). The picture: z-buffered triangles,
// orthographic camera framing the mesh automatically, two-light Lambert + ambient shading (flat by
// default, --smooth interpolates vertex normals), white background, 2x2 supersampled.
//   Front faces are blue-grey (or coloured by --color), back faces orange: an inside-out or
//   mis-oriented part shows up orange.
//   --wire      dark triangle edges on the visible surface (depth tested), to see the sampling.
//   --color     edge-length: per face, mean edge length (world units);
//               curvature: per vertex, discrete mean curvature (1/world units, > 0 convex).
//               A colour bar with the 1st..99th percentile range goes in the footer.
//   --clip      a plane normal to an axis; AXIS:VALUE removes the half facing the camera,
//               AXIS>VALUE or AXIS<VALUE removes that half (quote it in a shell). The cut solid
//               shows as a hatched section (the mesh is closed, so a back face seen first means
//               the ray is inside the solid at the plane).
//   --view      camera direction: iso (from +x -y +z), front (from -y), top (from +z),
//               side (from +x), or AZ,EL in degrees (azimuth about +z from +x, elevation).
//   --views 4   a 2x2 montage of iso, front, top and side.
//   --size      output image in pixels (default 1024x768; 1600x1200 for --views 4).
// --self-test renders a built-in icosphere, checks the picture (not blank, shaded, section drawn,
// PNG round trip) and returns non-zero when a check fails (the ctest smoke test).
#include "riemesh/mesh.h"
#include "riemesh/mesh_io.h"
#include "riemesh/primitives.h"

#include <zlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <fstream>
#include <iterator>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <unordered_set>
#include <vector>

using namespace riemesh;

namespace {

// ---------------------------------------------------------------------------------------------
// Options

enum class ColorMode { None, EdgeLength, Curvature };

/// A camera direction: where the camera sits, seen from the mesh centre.
struct View {
    std::string name;
    double azimuth = -45;    ///< degrees about +z, from +x
    double elevation = 35.264; ///< degrees above the xy plane
};

/// A clipping plane normal to a coordinate axis.
struct ClipPlane {
    int axis = 0;        ///< 0 x, 1 y, 2 z
    double value = 0;    ///< world units
    int removed = 0;     ///< +1 removes axis > value, -1 removes axis < value, 0 the half facing the camera
};

struct RenderOptions {
    int width = 0, height = 0;       ///< output image, pixels (0: default for the view count)
    std::vector<View> views;         ///< one panel per view (empty: iso)
    bool wire = false;               ///< dark triangle edges over the surface
    bool smooth = false;             ///< interpolated vertex normals instead of flat faces
    ColorMode color = ColorMode::None;
    std::optional<ClipPlane> clip;
    std::string title;               ///< text above the picture (empty: none)
    std::string info;                ///< text in the footer (mesh name and counts)
    int supersample = 2;             ///< samples per pixel along each axis
    double wireWidth = 1.0;          ///< output pixels
};

View namedView(const std::string& name)
{
    if (name == "iso") return {"iso", -45, 35.264};
    if (name == "front") return {"front (from -y)", -90, 0};
    if (name == "top") return {"top (from +z)", -90, 90};
    if (name == "side") return {"side (from +x)", 0, 0};
    const auto comma = name.find(',');
    if (comma != std::string::npos) {
        char* end = nullptr;
        const double az = std::strtod(name.c_str(), &end);
        const bool azOk = end == name.c_str() + comma;
        const double el = std::strtod(name.c_str() + comma + 1, &end);
        if (azOk && *end == '\0' && std::isfinite(az) && std::isfinite(el) && std::abs(el) <= 90)
            return {"az " + name.substr(0, comma) + ", el " + name.substr(comma + 1), az, el};
    }
    throw std::invalid_argument("--view: expected iso, front, top, side or AZ,EL (degrees, |EL| <= 90), got '" +
                                name + "'");
}

ClipPlane parseClip(const std::string& text)
{
    ClipPlane clip;
    if (text.size() < 3 || text[0] < 'x' || text[0] > 'z' || std::strchr(":<>", text[1]) == nullptr)
        throw std::invalid_argument("--clip: expected AXIS:VALUE, AXIS>VALUE or AXIS<VALUE with AXIS x, y or z, got '" +
                                    text + "'");
    clip.axis = text[0] - 'x';
    clip.removed = text[1] == '>' ? 1 : text[1] == '<' ? -1 : 0;
    char* end = nullptr;
    clip.value = std::strtod(text.c_str() + 2, &end);
    if (*end != '\0' || !std::isfinite(clip.value))
        throw std::invalid_argument("--clip: '" + text.substr(2) + "' is not a number");
    return clip;
}

// ---------------------------------------------------------------------------------------------
// Images and PNG

struct Rgb {
    float r = 1, g = 1, b = 1;
};

Rgb mix(const Rgb& a, const Rgb& b, double t)
{
    const float s = static_cast<float>(t);
    return {a.r + (b.r - a.r) * s, a.g + (b.g - a.g) * s, a.b + (b.b - a.b) * s};
}

Rgb scaled(const Rgb& c, double k)
{
    const float s = static_cast<float>(k);
    return {std::min(1.0f, c.r * s), std::min(1.0f, c.g * s), std::min(1.0f, c.b * s)};
}

/// 8-bit RGB, rows top to bottom.
struct Image {
    int width = 0, height = 0;
    std::vector<std::uint8_t> rgb;

    Image() = default;
    Image(int w, int h) : width(w), height(h), rgb(static_cast<std::size_t>(w) * h * 3, 255) {}

    void set(int x, int y, const Rgb& c)
    {
        if (x < 0 || y < 0 || x >= width || y >= height) return;
        std::uint8_t* p = &rgb[(static_cast<std::size_t>(y) * width + x) * 3];
        p[0] = toByte(c.r), p[1] = toByte(c.g), p[2] = toByte(c.b);
    }
    static std::uint8_t toByte(float v) { return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255)); }
};

void appendBigEndian(std::vector<std::uint8_t>& out, std::uint32_t v)
{
    for (int shift = 24; shift >= 0; shift -= 8) out.push_back(static_cast<std::uint8_t>(v >> shift));
}

void appendChunk(std::vector<std::uint8_t>& out, const char* type, const std::vector<std::uint8_t>& data)
{
    appendBigEndian(out, static_cast<std::uint32_t>(data.size()));
    const std::size_t typeAt = out.size();
    out.insert(out.end(), type, type + 4);
    out.insert(out.end(), data.begin(), data.end());
    const uLong crc = crc32(0L, &out[typeAt], static_cast<uInt>(out.size() - typeAt));
    appendBigEndian(out, static_cast<std::uint32_t>(crc));
}

const std::uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

/// PNG bytes of `image` (8-bit RGB, filter "none" on every row).
std::vector<std::uint8_t> encodePng(const Image& image)
{
    const std::size_t row = static_cast<std::size_t>(image.width) * 3;
    std::vector<std::uint8_t> raw;
    raw.reserve((row + 1) * image.height);
    for (int y = 0; y < image.height; ++y) {
        raw.push_back(0);
        raw.insert(raw.end(), image.rgb.begin() + y * row, image.rgb.begin() + (y + 1) * row);
    }
    uLongf packedSize = compressBound(static_cast<uLong>(raw.size()));
    std::vector<std::uint8_t> packed(packedSize);
    if (compress2(packed.data(), &packedSize, raw.data(), static_cast<uLong>(raw.size()), 6) != Z_OK)
        throw std::runtime_error("PNG: zlib compress2 failed");
    packed.resize(packedSize);

    std::vector<std::uint8_t> header;
    appendBigEndian(header, static_cast<std::uint32_t>(image.width));
    appendBigEndian(header, static_cast<std::uint32_t>(image.height));
    header.insert(header.end(), {8, 2, 0, 0, 0}); // 8 bits, RGB, deflate, adaptive filters, no interlace

    std::vector<std::uint8_t> png(std::begin(kPngSignature), std::end(kPngSignature));
    appendChunk(png, "IHDR", header);
    appendChunk(png, "IDAT", packed);
    appendChunk(png, "IEND", {});
    return png;
}

void writePng(const std::string& path, const Image& image)
{
    const std::vector<std::uint8_t> png = encodePng(image);
    std::ofstream out(path, std::ios::binary);
    if (!out) throw std::runtime_error("cannot open '" + path + "' for writing");
    out.write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
    if (!out.flush()) throw std::runtime_error("cannot write '" + path + "'");
}

/// Reads back a PNG as encodePng writes it (RGB, 8 bits, filter "none"): the self-test's round trip.
Image readOwnPng(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    auto fail = [&](const std::string& why) -> Image { throw std::runtime_error("PNG '" + path + "': " + why); };
    if (bytes.size() < 8 || !std::equal(std::begin(kPngSignature), std::end(kPngSignature), bytes.begin()))
        return fail("bad signature");
    auto be32 = [&](std::size_t at) {
        return static_cast<std::uint32_t>(bytes[at]) << 24 | static_cast<std::uint32_t>(bytes[at + 1]) << 16 |
               static_cast<std::uint32_t>(bytes[at + 2]) << 8 | bytes[at + 3];
    };
    Image image;
    std::vector<std::uint8_t> packed;
    for (std::size_t at = 8; at + 12 <= bytes.size();) {
        const std::uint32_t length = be32(at);
        if (at + 12 + length > bytes.size()) return fail("truncated chunk");
        const std::string type(bytes.begin() + at + 4, bytes.begin() + at + 8);
        if (crc32(0L, &bytes[at + 4], length + 4) != be32(at + 8 + length)) return fail("bad CRC in " + type);
        if (type == "IHDR") image = Image(static_cast<int>(be32(at + 8)), static_cast<int>(be32(at + 12)));
        if (type == "IDAT") packed.insert(packed.end(), bytes.begin() + at + 8, bytes.begin() + at + 8 + length);
        at += 12 + length;
    }
    const std::size_t row = static_cast<std::size_t>(image.width) * 3;
    std::vector<std::uint8_t> raw((row + 1) * image.height);
    uLongf rawSize = static_cast<uLongf>(raw.size());
    if (image.width == 0 || uncompress(raw.data(), &rawSize, packed.data(), static_cast<uLong>(packed.size())) != Z_OK ||
        rawSize != raw.size())
        return fail("bad image data");
    for (int y = 0; y < image.height; ++y) {
        if (raw[y * (row + 1)] != 0) return fail("unexpected row filter");
        std::copy_n(raw.begin() + y * (row + 1) + 1, row, image.rgb.begin() + y * row);
    }
    return image;
}

// ---------------------------------------------------------------------------------------------
// Text: a built-in 5x7 bitmap font (ASCII letters, digits and some punctuation).

struct Glyph {
    char c;
    const char* rows;                    ///< 7 rows of 5 columns, '#' set
    const char* descender = ".........."; ///< 2 more rows below the baseline (g j p q y)
};

// clang-format off
const Glyph kFont[] = {
    {' ', "..................................."},
    {'A', ".###.#...##...#######...##...##...#"}, {'B', "####.#...##...#####.#...##...#####."},
    {'C', ".###.#...##....#....#....#...#.###."}, {'D', "####.#...##...##...##...##...#####."},
    {'E', "######....#....####.#....#....#####"}, {'F', "######....#....####.#....#....#...."},
    {'G', ".###.#...##....#.####...##...#.####"}, {'H', "#...##...##...#######...##...##...#"},
    {'I', ".###...#....#....#....#....#...###."}, {'J', "..###...#....#....#....##..#..##..."},
    {'K', "#...##..#.#.#..##...#.#..#..#.#...#"}, {'L', "#....#....#....#....#....#....#####"},
    {'M', "#...###.###.#.##.#.##...##...##...#"}, {'N', "#...##...###..##.#.##..###...##...#"},
    {'O', ".###.#...##...##...##...##...#.###."}, {'P', "####.#...##...#####.#....#....#...."},
    {'Q', ".###.#...##...##...##.#.##..#..##.#"}, {'R', "####.#...##...#####.#.#..#..#.#...#"},
    {'S', ".#####....#.....###.....#....#####."}, {'T', "#####..#....#....#....#....#....#.."},
    {'U', "#...##...##...##...##...##...#.###."}, {'V', "#...##...##...##...##...#.#.#...#.."},
    {'W', "#...##...##...##.#.##.#.##.#.#.#.#."}, {'X', "#...##...#.#.#...#...#.#.#...##...#"},
    {'Y', "#...##...#.#.#...#....#....#....#.."}, {'Z', "#####....#...#...#...#...#....#####"},
    {'a', "...........###.....#.#####...#.####"}, {'b', "#....#....#.##.##..##...##...#####."},
    {'c', "...........###.#....#....#...#.###."}, {'d', "....#....#.##.##..###...##...#.####"},
    {'e', "...........###.#...#######.....###."}, {'f', "..##..#..#.#...###...#....#....#..."},
    {'g', "...........#####...##...##...#.####", "....#.###."}, {'h', "#....#....#.##.##..##...##...##...#"},
    {'i', "..#........##....#....#....#...###."}, {'j', "...#........##....#....#....#....#.", "#..#..##.."},
    {'k', "#....#....#..#.#.#..##...#.#..#..#."}, {'l', ".##....#....#....#....#....#...###."},
    {'m', "..........##.#.#.#.##.#.##...##...#"}, {'n', "..........#.##.##..##...##...##...#"},
    {'o', "...........###.#...##...##...#.###."}, {'p', "..........####.#...##...##...#####.", "#....#...."},
    {'q', "...........#####...##...##...#.####", "....#....#"}, {'r', "..........#.##.##..##....#....#...."},
    {'s', "...........###.#.....###.....#####."}, {'t', ".#....#...###...#....#....#..#..##."},
    {'u', "..........#...##...##...##..##.##.#"}, {'v', "..........#...##...##...#.#.#...#.."},
    {'w', "..........#...##...##.#.##.#.#.#.#."}, {'x', "..........#...#.#.#...#...#.#.#...#"},
    {'y', "..........#...##...##...##...#.####", "....#.###."}, {'z', "..........#####...#...#...#...#####"},
    {'0', ".###.#...##..###.#.###..##...#.###."}, {'1', "..#...##....#....#....#....#...###."},
    {'2', ".###.#...#....#...#...#...#...#####"}, {'3', "#####...#...#.....#.....##...#.###."},
    {'4', "...#...##..#.#.#..#.#####...#....#."}, {'5', "######....####.....#....##...#.###."},
    {'6', "..##..#...#....####.#...##...#.###."}, {'7', "#####....#...#...#...#....#....#..."},
    {'8', ".###.#...##...#.###.#...##...#.###."}, {'9', ".###.#...##...#.####....#...#..##.."},
    {'.', "..........................##...##.."}, {',', ".....................##....#...#..."},
    {':', "......##...##........##...##......."}, {'-', "...............#####..............."},
    {'+', "......#....#..#####..#....#........"}, {'_', "..............................#####"},
    {'/', ".........#...#...#...#...#........."}, {'(', "...#...#...#....#....#.....#.....#."},
    {')', ".#.....#.....#....#....#...#...#..."}, {'=', "..........#####.....#####.........."},
    {'%', "##...##..#...#...#...#...#..##...##"}, {'[', ".###..#....#....#....#....#....###."},
    {']', ".###....#....#....#....#....#..###."}, {'\'', "..#....#...#......................."},
    {'!', "..#....#....#....#....#.........#.."}, {'?', ".###.#...#....#...#...#.........#.."},
    {'#', ".#.#..#.#.#####.#.#.#####.#.#..#.#."}, {'*', ".......#..#.#.#.###.#.#.#..#......."},
    {'<', "...#...#...#...#.....#.....#.....#."}, {'>', ".#.....#.....#.....#...#...#...#..."},
    {'^', "..#...#.#.#...#...................."}, {'|', "..#....#....#....#....#....#....#.."},
};
// clang-format on

const Glyph& glyphOf(char c)
{
    for (const Glyph& g : kFont)
        if (g.c == c) return g;
    for (const Glyph& g : kFont)
        if (g.c == '?') return g;
    return kFont[0];
}

constexpr int kGlyphAdvance = 6; ///< font pixels per character, spacing included
constexpr int kGlyphHeight = 7;

int textWidth(const std::string& text, int scale) { return static_cast<int>(text.size()) * kGlyphAdvance * scale - scale; }

/// Draws `text` with its top-left corner at (x, y) (pixels), each font pixel `scale` pixels wide.
void drawText(Image& image, int x, int y, const std::string& text, int scale, const Rgb& color)
{
    for (std::size_t i = 0; i < text.size(); ++i) {
        const Glyph& glyph = glyphOf(text[i]);
        for (int r = 0; r < kGlyphHeight + 2; ++r)
            for (int c = 0; c < 5; ++c) {
                if ((r < kGlyphHeight ? glyph.rows[r * 5 + c] : glyph.descender[(r - kGlyphHeight) * 5 + c]) != '#') continue;
                for (int dy = 0; dy < scale; ++dy)
                    for (int dx = 0; dx < scale; ++dx)
                        image.set(x + (static_cast<int>(i) * kGlyphAdvance + c) * scale + dx, y + r * scale + dy, color);
            }
    }
}

// ---------------------------------------------------------------------------------------------
// Colour fields

/// Piecewise linear colour ramp through `stops` (evenly spaced), t in [0, 1].
Rgb ramp(const std::vector<Rgb>& stops, double t)
{
    t = std::clamp(t, 0.0, 1.0) * static_cast<double>(stops.size() - 1);
    const std::size_t i = std::min(static_cast<std::size_t>(t), stops.size() - 2);
    return mix(stops[i], stops[i + 1], t - static_cast<double>(i));
}

const std::vector<Rgb> kSequential = {{0.19f, 0.11f, 0.42f}, {0.16f, 0.38f, 0.62f}, {0.15f, 0.62f, 0.56f},
                                      {0.52f, 0.80f, 0.32f}, {0.98f, 0.88f, 0.22f}};
const std::vector<Rgb> kDiverging = {{0.16f, 0.30f, 0.78f}, {0.62f, 0.72f, 0.92f}, {0.93f, 0.93f, 0.91f},
                                     {0.94f, 0.66f, 0.52f}, {0.78f, 0.14f, 0.12f}};

/// A scalar per vertex or per face, with the range mapped onto a colour ramp.
struct ColorField {
    ColorMode mode = ColorMode::None;
    bool perFace = false;
    std::vector<double> values;   ///< per vertex or per face (triangle list order)
    double lo = 0, hi = 1;        ///< value range of the ramp
    std::string label;

    Rgb colorOf(double v) const
    {
        const double t = hi > lo ? (v - lo) / (hi - lo) : 0.5;
        return ramp(mode == ColorMode::Curvature ? kDiverging : kSequential, t);
    }
};

/// The `q` quantile (0..1) of `values`.
double quantile(std::vector<double> values, double q)
{
    if (values.empty()) return 0;
    const auto k = static_cast<std::size_t>(std::round(q * static_cast<double>(values.size() - 1)));
    std::nth_element(values.begin(), values.begin() + k, values.end());
    return values[k];
}

// ---------------------------------------------------------------------------------------------
// The triangle list the rasteriser draws

struct Surface {
    std::vector<Vec3> points;             ///< world units
    std::vector<Vec3> vertexNormals;      ///< unit, area weighted
    std::vector<std::array<int, 3>> triangles;
    std::vector<Vec3> faceNormals;        ///< unit (zero when degenerate)
    std::size_t vertexCount = 0, faceCount = 0;
};

Surface surfaceOf(const Mesh& mesh)
{
    Surface s;
    std::vector<int> index(mesh.n_vertices(), -1);
    for (VertexHandle v : mesh.vertices()) {
        if (mesh.status(v).deleted()) continue;
        index[v.idx()] = static_cast<int>(s.points.size());
        s.points.push_back(position(mesh, v));
    }
    s.vertexNormals.assign(s.points.size(), Vec3::Zero());
    for (FaceHandle f : mesh.faces()) {
        if (mesh.status(f).deleted()) continue;
        std::array<int, 3> t{};
        int k = 0;
        for (VertexHandle v : mesh.fv_range(f)) t[k++] = index[v.idx()];
        const Vec3 areaNormal = (s.points[t[1]] - s.points[t[0]]).cross(s.points[t[2]] - s.points[t[0]]);
        for (int i : t) s.vertexNormals[i] += areaNormal;
        s.triangles.push_back(t);
        const double twiceArea = areaNormal.norm();
        s.faceNormals.push_back(twiceArea > 0 ? Vec3(areaNormal / twiceArea) : Vec3::Zero());
    }
    for (Vec3& n : s.vertexNormals)
        if (n.norm() > 0) n.normalize();
    s.vertexCount = s.points.size();
    s.faceCount = s.triangles.size();
    return s;
}

/// Per face, the mean of its three edge lengths (world units), in the order of surfaceOf().
std::vector<double> faceEdgeLengths(const Surface& s)
{
    std::vector<double> lengths;
    lengths.reserve(s.triangles.size());
    for (const auto& t : s.triangles)
        lengths.push_back(((s.points[t[0]] - s.points[t[1]]).norm() + (s.points[t[1]] - s.points[t[2]]).norm() +
                           (s.points[t[2]] - s.points[t[0]]).norm()) / 3.0);
    return lengths;
}

/// Per vertex discrete mean curvature (1/world units, > 0 where convex): the edges' integrated
/// curvature |e| * dihedral / 2, half to each end, over a third of the incident face area.
std::vector<double> vertexMeanCurvatures(const Surface& s)
{
    std::vector<double> integrated(s.points.size(), 0.0), area(s.points.size(), 0.0);
    struct EdgeSide { int a, b, face; };
    std::vector<EdgeSide> sides;
    for (std::size_t f = 0; f < s.triangles.size(); ++f) {
        const auto& t = s.triangles[f];
        const double third = (s.points[t[1]] - s.points[t[0]]).cross(s.points[t[2]] - s.points[t[0]]).norm() / 6.0;
        for (int i = 0; i < 3; ++i) {
            area[t[i]] += third;
            sides.push_back({t[i], t[(i + 1) % 3], static_cast<int>(f)});
        }
    }
    // Pair each directed edge a->b with its twin b->a (closed, oriented mesh).
    auto key = [](int a, int b) { return std::make_pair(std::min(a, b), std::max(a, b)); };
    std::sort(sides.begin(), sides.end(), [&](const EdgeSide& l, const EdgeSide& r) {
        return key(l.a, l.b) < key(r.a, r.b) || (key(l.a, l.b) == key(r.a, r.b) && l.a < r.a);
    });
    for (std::size_t i = 0; i + 1 < sides.size(); ++i) {
        const EdgeSide& e = sides[i];
        const EdgeSide& twin = sides[i + 1];
        if (key(e.a, e.b) != key(twin.a, twin.b) || twin.a != e.b) continue;
        const Vec3 along = s.points[e.b] - s.points[e.a];
        const double length = along.norm();
        if (length == 0) continue;
        const Vec3& n0 = s.faceNormals[e.face];
        const Vec3& n1 = s.faceNormals[twin.face];
        // Signed dihedral angle: the normal turns about the edge, direction a->b in face 0.
        const double angle = std::atan2(n0.cross(n1).dot(along / length), n0.dot(n1));
        integrated[e.a] += length * angle / 4.0;
        integrated[e.b] += length * angle / 4.0;
        ++i;
    }
    std::vector<double> h(s.points.size(), 0.0);
    for (std::size_t v = 0; v < h.size(); ++v) h[v] = area[v] > 0 ? integrated[v] / area[v] : 0.0;
    return h;
}

ColorField colorFieldOf(const Surface& s, ColorMode mode)
{
    ColorField field;
    field.mode = mode;
    if (mode == ColorMode::None) return field;
    if (mode == ColorMode::EdgeLength) {
        field.perFace = true;
        field.values = faceEdgeLengths(s);
        field.lo = quantile(field.values, 0.01);
        field.hi = quantile(field.values, 0.99);
        field.label = "edge length";
    } else {
        field.values = vertexMeanCurvatures(s);
        std::vector<double> magnitudes;
        for (double v : field.values) magnitudes.push_back(std::abs(v));
        const double m = quantile(magnitudes, 0.99);
        field.lo = -m, field.hi = m;
        field.label = "mean curvature";
    }
    return field;
}

// ---------------------------------------------------------------------------------------------
// Rasteriser

/// Orthographic camera: world -> supersampled pixel coordinates of one panel.
struct Camera {
    Vec3 right, up, toward; ///< unit; `toward` points from the scene to the camera
    Vec3 center;            ///< world point at the panel centre
    double scale = 1;       ///< samples per world unit
    double cx = 0, cy = 0;  ///< panel centre in samples

    Eigen::Vector3d project(const Vec3& p) const
    {
        const Vec3 d = p - center;
        return {cx + d.dot(right) * scale, cy - d.dot(up) * scale, d.dot(toward)};
    }
};

/// The half `clip` removes seen from direction `toward`: +1 above the plane, -1 below, 0 none.
int removedHalf(const std::optional<ClipPlane>& clip, const Vec3& toward)
{
    if (!clip) return 0;
    if (clip->removed != 0) return clip->removed;
    return toward[clip->axis] >= -1e-9 ? 1 : -1;
}

/// Orthographic camera for `view` framing the vertices of `s` that `clip` keeps.
Camera frameCamera(const Surface& s, const View& view, const std::optional<ClipPlane>& clip, int width, int height)
{
    constexpr double kDeg = 3.14159265358979323846 / 180.0;
    const double az = view.azimuth * kDeg, el = view.elevation * kDeg;
    Camera cam;
    cam.toward = Vec3(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
    cam.right = Vec3(-std::sin(az), std::cos(az), 0);
    cam.up = cam.toward.cross(cam.right);
    const int removed = removedHalf(clip, cam.toward);
    double minR = std::numeric_limits<double>::max(), maxR = -minR, minU = minR, maxU = -minR;
    for (int pass = 0; pass < 2 && minR > maxR; ++pass) // all vertices when the clip removes every one
        for (const Vec3& p : s.points) {
            if (pass == 0 && removed != 0 && (p[clip->axis] - clip->value) * removed > 0) continue;
            minR = std::min(minR, p.dot(cam.right)), maxR = std::max(maxR, p.dot(cam.right));
            minU = std::min(minU, p.dot(cam.up)), maxU = std::max(maxU, p.dot(cam.up));
        }
    if (s.points.empty()) minR = maxR = minU = maxU = 0;
    cam.center = cam.right * (minR + maxR) / 2 + cam.up * (minU + maxU) / 2;
    constexpr double kFill = 0.88; // fraction of the panel the mesh may take
    const double extentR = std::max(maxR - minR, 1e-12), extentU = std::max(maxU - minU, 1e-12);
    cam.scale = std::min(kFill * width / extentR, kFill * height / extentU);
    cam.cx = width / 2.0, cam.cy = height / 2.0;
    return cam;
}

const Rgb kFrontColor{0.72f, 0.79f, 0.90f};
const Rgb kBackColor{0.96f, 0.58f, 0.26f};
const Rgb kSectionColor{0.80f, 0.76f, 0.72f};
const Rgb kSectionHatch{0.52f, 0.47f, 0.44f};
const Rgb kWireColor{0.08f, 0.09f, 0.13f};
const Rgb kTextColor{0.15f, 0.15f, 0.18f};
const Rgb kFaintTextColor{0.42f, 0.42f, 0.46f};

/// Renders `view` of `s` into the `width` x `height` pixel rectangle of `image` at (x0, y0).
void renderPanel(const Surface& s, const ColorField& field, const RenderOptions& options, const View& view,
                 Image& image, int x0, int y0, int width, int height)
{
    const int ss = options.supersample;
    const int W = width * ss, H = height * ss;
    const Camera cam = frameCamera(s, view, options.clip, W, H);

    std::vector<Eigen::Vector3d> screen(s.points.size());
    for (std::size_t i = 0; i < s.points.size(); ++i) screen[i] = cam.project(s.points[i]);

    // Which half the clip plane removes, and where the section is.
    const int removed = removedHalf(options.clip, cam.toward);

    // Visibility pass: per sample, the nearest face and its barycentric coordinates.
    std::vector<float> depth(static_cast<std::size_t>(W) * H, -std::numeric_limits<float>::infinity());
    std::vector<int> faceAt(depth.size(), -1);
    std::vector<std::array<float, 2>> bary(depth.size());
    for (std::size_t f = 0; f < s.triangles.size(); ++f) {
        const auto& t = s.triangles[f];
        const Eigen::Vector3d &a = screen[t[0]], &b = screen[t[1]], &c = screen[t[2]];
        const double area = (b.x() - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (b.y() - a.y());
        if (std::abs(area) < 1e-12) continue;
        const int xmin = std::max(0, static_cast<int>(std::floor(std::min({a.x(), b.x(), c.x()}))));
        const int xmax = std::min(W - 1, static_cast<int>(std::ceil(std::max({a.x(), b.x(), c.x()}))));
        const int ymin = std::max(0, static_cast<int>(std::floor(std::min({a.y(), b.y(), c.y()}))));
        const int ymax = std::min(H - 1, static_cast<int>(std::ceil(std::max({a.y(), b.y(), c.y()}))));
        for (int y = ymin; y <= ymax; ++y)
            for (int x = xmin; x <= xmax; ++x) {
                const double px = x + 0.5, py = y + 0.5;
                const double w0 = ((b.x() - px) * (c.y() - py) - (c.x() - px) * (b.y() - py)) / area;
                const double w1 = ((c.x() - px) * (a.y() - py) - (a.x() - px) * (c.y() - py)) / area;
                const double w2 = 1.0 - w0 - w1;
                if (w0 < 0 || w1 < 0 || w2 < 0) continue;
                const auto z = static_cast<float>(w0 * a.z() + w1 * b.z() + w2 * c.z());
                const std::size_t k = static_cast<std::size_t>(y) * W + x;
                if (z <= depth[k]) continue;
                if (removed != 0) {
                    const int ax = options.clip->axis;
                    const double coord = w0 * s.points[t[0]][ax] + w1 * s.points[t[1]][ax] + w2 * s.points[t[2]][ax];
                    if ((coord - options.clip->value) * removed > 0) continue;
                }
                depth[k] = z, faceAt[k] = static_cast<int>(f);
                bary[k] = {static_cast<float>(w0), static_cast<float>(w1)};
            }
    }

    // Lights in camera space: a key light from the upper left, a weaker fill from the right.
    const Vec3 key = (-0.45 * cam.right + 0.55 * cam.up + 0.70 * cam.toward).normalized();
    const Vec3 fill = (0.65 * cam.right - 0.15 * cam.up + 0.75 * cam.toward).normalized();
    constexpr double kAmbient = 0.30, kKey = 0.62, kFill = 0.24;
    const double halfWire = 0.5 * options.wireWidth * ss; // samples

    // Shading pass, then a box filter down to pixels.
    std::vector<Rgb> color(depth.size());
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const std::size_t k = static_cast<std::size_t>(y) * W + x;
            const int f = faceAt[k];
            if (f < 0) continue;
            const auto& t = s.triangles[f];
            const double b0 = bary[k][0], b1 = bary[k][1], b2 = 1.0 - b0 - b1;
            const bool back = s.faceNormals[f].dot(cam.toward) < 0;
            if (back && removed != 0) { // inside the solid at the plane: the section
                const bool hatch = ((x + y) / ss) % 9 < 1;
                color[k] = hatch ? kSectionHatch : kSectionColor;
                continue;
            }
            Vec3 n = s.faceNormals[f];
            if (options.smooth) {
                const Vec3 sn = b0 * s.vertexNormals[t[0]] + b1 * s.vertexNormals[t[1]] + b2 * s.vertexNormals[t[2]];
                if (sn.norm() > 0) n = sn.normalized();
            }
            if (back) n = -n;
            const double light = kAmbient + kKey * std::max(0.0, n.dot(key)) + kFill * std::max(0.0, n.dot(fill));
            Rgb base = kFrontColor;
            if (back) base = kBackColor;
            else if (field.mode != ColorMode::None)
                base = field.colorOf(field.perFace ? field.values[f]
                                                   : b0 * field.values[t[0]] + b1 * field.values[t[1]] +
                                                         b2 * field.values[t[2]]);
            Rgb c = scaled(base, light);
            if (options.wire) {
                // Distance (samples) to the nearest edge: barycentric coordinate times altitude.
                const Eigen::Vector3d &p0 = screen[t[0]], &p1 = screen[t[1]], &p2 = screen[t[2]];
                const double twiceArea = std::abs((p1.x() - p0.x()) * (p2.y() - p0.y()) - (p2.x() - p0.x()) * (p1.y() - p0.y()));
                const double e0 = (p2 - p1).head<2>().norm(), e1 = (p0 - p2).head<2>().norm(), e2 = (p1 - p0).head<2>().norm();
                const double dist = std::min({b0 * twiceArea / e0, b1 * twiceArea / e1, b2 * twiceArea / e2});
                const double coverage = std::clamp(halfWire + 0.5 - dist, 0.0, 1.0);
                c = mix(c, kWireColor, 0.7 * coverage);
            }
            color[k] = c;
        }
    const float norm = 1.0f / static_cast<float>(ss * ss);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            Rgb sum{0, 0, 0};
            for (int dy = 0; dy < ss; ++dy)
                for (int dx = 0; dx < ss; ++dx) {
                    const Rgb& c = color[static_cast<std::size_t>(y * ss + dy) * W + x * ss + dx];
                    sum.r += c.r, sum.g += c.g, sum.b += c.b;
                }
            image.set(x0 + x, y0 + y, {sum.r * norm, sum.g * norm, sum.b * norm});
        }
}

std::string formatNumber(double v)
{
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.3g", v);
    return buffer;
}

/// The whole picture: title, one panel per view (a 2x2 grid for four), footer with the mesh
/// counts, the clip plane and the colour bar.
Image render(const Surface& s, const RenderOptions& options)
{
    std::vector<View> views = options.views.empty() ? std::vector<View>{namedView("iso")} : options.views;
    const bool grid = views.size() > 1;
    const int width = options.width > 0 ? options.width : (grid ? 1600 : 1024);
    const int height = options.height > 0 ? options.height : (grid ? 1200 : 768);
    Image image(width, height);
    const ColorField field = colorFieldOf(s, options.color);

    const int text = std::max(1, (std::min(width, height) + 200) / 400); // font scale
    const int pad = 4 * text;
    const int lineHeight = kGlyphHeight * text + pad;

    // Footer: the mesh, view and clip plane on the left, the colour bar on the right (on a line of
    // its own when both do not fit).
    std::string info = options.info;
    if (!grid) info += (info.empty() ? "" : ", ") + std::string("view ") + views[0].name;
    if (options.clip) {
        const char axis = static_cast<char>('x' + options.clip->axis);
        const std::string cut = options.clip->removed > 0 ? " > " : options.clip->removed < 0 ? " < " : " = ";
        info += (info.empty() ? "" : ", ") + std::string("cut ") + axis + cut + formatNumber(options.clip->value) +
                (options.clip->removed != 0 ? " removed" : "");
    }
    const std::string lo = formatNumber(field.lo), hi = formatNumber(field.hi);
    const int gap = 3 * text, barWidth = 80 * text;
    const int legendWidth = field.mode == ColorMode::None
                                ? 0
                                : textWidth(field.label, text) + textWidth(lo, text) + textWidth(hi, text) + barWidth + 4 * gap;
    const bool legendLine = legendWidth > 0 && !info.empty() && textWidth(info, text) + 4 * gap + legendWidth > width - 2 * pad;
    const int footerHeight = (legendLine ? 2 : 1) * lineHeight + pad;
    const int titleHeight = options.title.empty() ? 0 : kGlyphHeight * text * 3 / 2 + 2 * pad;
    const int areaHeight = height - titleHeight - footerHeight;
    if (width < 16 || areaHeight < 16) throw std::invalid_argument("--size: image too small");

    const int columns = grid ? 2 : 1;
    const int rows = grid ? static_cast<int>((views.size() + 1) / 2) : 1;
    const int labelHeight = grid ? lineHeight : 0;
    for (std::size_t i = 0; i < views.size(); ++i) {
        const int c = static_cast<int>(i) % columns, r = static_cast<int>(i) / columns;
        const int px0 = c * width / columns, px1 = (c + 1) * width / columns;
        const int py0 = titleHeight + r * areaHeight / rows, py1 = titleHeight + (r + 1) * areaHeight / rows;
        renderPanel(s, field, options, views[i], image, px0, py0 + labelHeight, px1 - px0, py1 - py0 - labelHeight);
        if (grid) drawText(image, px0 + pad, py0 + pad, views[i].name, text, kFaintTextColor);
    }
    if (grid) { // thin separators between panels
        for (int y = titleHeight; y < titleHeight + areaHeight; ++y) image.set(width / 2, y, {0.85f, 0.85f, 0.87f});
        for (int r = 1; r < rows; ++r)
            for (int x = 0; x < width; ++x) image.set(x, titleHeight + r * areaHeight / rows, {0.85f, 0.85f, 0.87f});
    }
    if (!options.title.empty()) {
        const int titleScale = std::max(1, text * 3 / 2);
        const int tw = textWidth(options.title, titleScale);
        drawText(image, std::max(pad, (width - tw) / 2), pad + (titleHeight - 2 * pad - kGlyphHeight * titleScale) / 2,
                 options.title, titleScale, kTextColor);
    }

    const int infoY = height - lineHeight;
    if (!info.empty()) drawText(image, pad, infoY, info, text, kFaintTextColor);
    if (legendWidth > 0) {
        const int y = legendLine ? infoY - lineHeight : infoY;
        int x = width - pad - textWidth(hi, text);
        drawText(image, x, y, hi, text, kTextColor);
        x -= gap + barWidth;
        for (int bx = 0; bx < barWidth; ++bx)
            for (int by = 0; by < kGlyphHeight * text; ++by)
                image.set(x + bx, y + by, field.colorOf(field.lo + (field.hi - field.lo) * bx / (barWidth - 1.0)));
        x -= gap + textWidth(lo, text);
        drawText(image, x, y, lo, text, kTextColor);
        x -= 2 * gap + textWidth(field.label, text);
        drawText(image, x, y, field.label, text, kTextColor);
    }
    return image;
}

// ---------------------------------------------------------------------------------------------
// Command line

struct Command {
    bool selfTest = false;
    std::string meshPath, outputPath;
    RenderOptions render;
};

const char* kUsage =
    "usage: render_mesh MESH OUTPUT.png [--size WxH] [--view iso|front|top|side|AZ,EL] [--views 4]\n"
    "                   [--wire] [--smooth] [--color none|edge-length|curvature]\n"
    "                   [--clip AXIS:VALUE|AXIS>VALUE|AXIS<VALUE] [--title TEXT]\n"
    "       render_mesh --self-test OUTPUT.png\n";

Command parseCommand(int argc, char** argv)
{
    Command cmd;
    std::vector<std::string> positional;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) throw std::invalid_argument(arg + " needs a value");
            return argv[++i];
        };
        if (arg == "--self-test") cmd.selfTest = true;
        else if (arg == "--wire") cmd.render.wire = true;
        else if (arg == "--smooth") cmd.render.smooth = true;
        else if (arg == "--title") cmd.render.title = value();
        else if (arg == "--view") cmd.render.views = {namedView(value())};
        else if (arg == "--views") {
            const std::string n = value();
            if (n == "1") cmd.render.views = {namedView("iso")};
            else if (n == "4") cmd.render.views = {namedView("iso"), namedView("front"), namedView("top"), namedView("side")};
            else throw std::invalid_argument("--views: expected 1 or 4, got '" + n + "'");
        } else if (arg == "--size") {
            const std::string v = value();
            int w = 0, h = 0;
            char extra = 0;
            if (std::sscanf(v.c_str(), "%dx%d%c", &w, &h, &extra) != 2 || w < 16 || h < 16 || w > 16384 || h > 16384)
                throw std::invalid_argument("--size: expected WxH in 16..16384 pixels, got '" + v + "'");
            cmd.render.width = w, cmd.render.height = h;
        } else if (arg == "--color") {
            const std::string v = value();
            if (v == "none") cmd.render.color = ColorMode::None;
            else if (v == "edge-length") cmd.render.color = ColorMode::EdgeLength;
            else if (v == "curvature") cmd.render.color = ColorMode::Curvature;
            else throw std::invalid_argument("--color: expected none, edge-length or curvature, got '" + v + "'");
        } else if (arg == "--clip") cmd.render.clip = parseClip(value());
        else if (arg == "-h" || arg == "--help") {
            std::fputs(kUsage, stdout);
            std::exit(EXIT_SUCCESS);
        } else if (arg.size() > 1 && arg[0] == '-') throw std::invalid_argument("unknown option " + arg);
        else positional.push_back(arg);
    }
    if (cmd.selfTest) {
        if (positional.size() != 1) throw std::invalid_argument("--self-test takes one OUTPUT.png");
        cmd.outputPath = positional[0];
    } else {
        if (positional.size() != 2) throw std::invalid_argument("expected MESH and OUTPUT.png");
        cmd.meshPath = positional[0], cmd.outputPath = positional[1];
    }
    return cmd;
}

std::string baseName(const std::string& path)
{
    const auto slash = path.find_last_of('/');
    return slash == std::string::npos ? path : path.substr(slash + 1);
}

std::string countsOf(const Surface& s)
{
    return std::to_string(s.vertexCount) + " vertices, " + std::to_string(s.faceCount) + " faces";
}

// ---------------------------------------------------------------------------------------------
// Self-test: the smoke test ctest runs.

struct PictureCounts {
    std::size_t distinctColors = 0;
    double coveredFraction = 0; ///< pixels not white
    double minLuma = 1, maxLuma = 0; ///< over covered pixels
};

PictureCounts countsOf(const Image& image)
{
    PictureCounts c;
    std::unordered_set<std::uint32_t> colors;
    std::size_t covered = 0;
    for (std::size_t i = 0; i < image.rgb.size(); i += 3) {
        const std::uint8_t r = image.rgb[i], g = image.rgb[i + 1], b = image.rgb[i + 2];
        colors.insert(static_cast<std::uint32_t>(r) << 16 | static_cast<std::uint32_t>(g) << 8 | b);
        if (r == 255 && g == 255 && b == 255) continue;
        ++covered;
        const double luma = (0.3 * r + 0.59 * g + 0.11 * b) / 255.0;
        c.minLuma = std::min(c.minLuma, luma), c.maxLuma = std::max(c.maxLuma, luma);
    }
    c.distinctColors = colors.size();
    c.coveredFraction = static_cast<double>(covered) / (image.rgb.size() / 3.0);
    return c;
}

std::size_t pixelsOfColor(const Image& image, const Rgb& color)
{
    const std::uint8_t r = Image::toByte(color.r), g = Image::toByte(color.g), b = Image::toByte(color.b);
    std::size_t n = 0;
    for (std::size_t i = 0; i < image.rgb.size(); i += 3)
        n += image.rgb[i] == r && image.rgb[i + 1] == g && image.rgb[i + 2] == b;
    return n;
}

int runSelfTest(const std::string& outputPath)
{
    int failures = 0;
    auto check = [&](bool ok, const std::string& what) {
        std::printf("%s  %s\n", ok ? "ok  " : "FAIL", what.c_str());
        failures += ok ? 0 : 1;
    };
    const double radius = 2.0;
    const Surface sphere = surfaceOf(makeIcosphere(Vec3(1, 2, 3), radius, 3));

    std::vector<double> h = vertexMeanCurvatures(sphere);
    double mean = 0;
    for (double v : h) mean += v / static_cast<double>(h.size());
    check(std::abs(mean * radius - 1.0) < 0.05, "icosphere mean curvature " + formatNumber(mean) + " ~ 1/r = " +
                                                    formatNumber(1.0 / radius));

    RenderOptions options;
    options.views = {namedView("iso"), namedView("front"), namedView("top"), namedView("side")};
    options.width = 640, options.height = 480;
    options.wire = true;
    options.color = ColorMode::Curvature;
    options.title = "render_mesh --self-test";
    options.info = "icosphere, " + countsOf(sphere);
    const Image picture = render(sphere, options);
    const PictureCounts counts = countsOf(picture);
    check(counts.distinctColors > 200, std::to_string(counts.distinctColors) + " distinct colours > 200");
    check(counts.coveredFraction > 0.15 && counts.coveredFraction < 0.9,
          "covered fraction " + formatNumber(counts.coveredFraction) + " in (0.15, 0.9)");
    check(counts.maxLuma - counts.minLuma > 0.4, "shading spans luma " + formatNumber(counts.minLuma) + " .. " +
                                                     formatNumber(counts.maxLuma));

    writePng(outputPath, picture);
    const Image back = readOwnPng(outputPath);
    check(back.width == picture.width && back.height == picture.height && back.rgb == picture.rgb,
          "PNG round trip through " + outputPath);

    RenderOptions clipped;
    clipped.width = 320, clipped.height = 240;
    clipped.clip = parseClip("x:1"); // through the centre
    const Image section = render(sphere, clipped);
    const std::size_t sectionPixels = pixelsOfColor(section, kSectionColor);
    check(sectionPixels > 320 * 240 / 50, "clip x:1 shows a section (" + std::to_string(sectionPixels) + " pixels)");
    check(pixelsOfColor(render(sphere, RenderOptions{}), kSectionColor) == 0, "no section without --clip");

    std::printf("%s\n", failures == 0 ? "render_mesh self-test passed" : "render_mesh self-test FAILED");
    return failures == 0 ? EXIT_SUCCESS : EXIT_FAILURE;
}

int run(int argc, char** argv)
{
    const Command cmd = parseCommand(argc, argv);
    if (cmd.selfTest) return runSelfTest(cmd.outputPath);
    const Surface surface = surfaceOf(readMesh(cmd.meshPath));
    RenderOptions options = cmd.render;
    options.info = baseName(cmd.meshPath) + ": " + countsOf(surface);
    writePng(cmd.outputPath, render(surface, options));
    std::printf("%s: %s -> %s\n", baseName(cmd.meshPath).c_str(), countsOf(surface).c_str(), cmd.outputPath.c_str());
    return EXIT_SUCCESS;
}

} // namespace

int main(int argc, char** argv)
{
    try {
        return run(argc, argv);
    } catch (const std::invalid_argument& e) {
        std::fprintf(stderr, "render_mesh: %s\n%s", e.what(), kUsage);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "render_mesh: %s\n", e.what());
    }
    return EXIT_FAILURE;
}
