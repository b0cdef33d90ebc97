#include "render.h"

#ifdef __EMSCRIPTEN__
#include <GLES3/gl3.h>
#else
#define GL_GLEXT_PROTOTYPES 1
#include <GL/gl.h>
#include <GL/glext.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <string>

namespace riemesh::viewer {

namespace {

const char* kMeshVertex = R"(
layout(location = 0) in vec3 aPosition;
layout(location = 1) in vec3 aNormal;
layout(location = 2) in vec3 aColour;
uniform mat4 uViewProjection;
out vec3 vNormal;
out vec3 vColour;
out vec3 vPosition;
void main() {
    vNormal = aNormal;
    vColour = aColour;
    vPosition = aPosition;
    gl_Position = uViewProjection * vec4(aPosition, 1.0);
    setCorner();
    setClip(aPosition);
}
)";

// The cut at the slice (CLIP defined): fragments on the eye's side of the plane uClipPlane
// (n . x > w) are discarded. Only the triangles that straddle the plane are drawn with it (see
// Renderer::cull): a discard costs software WebGL its early depth test.
const char* kClipVertex = R"(
#ifdef CLIP
uniform vec4 uClipPlane;
out float vClip;
void setClip(vec3 p) { vClip = dot(p, uClipPlane.xyz) - uClipPlane.w; }
#else
void setClip(vec3 p) {}
#endif
)";

const char* kClipFragment = R"(
#ifdef CLIP
in highp float vClip;
void clip() { if (vClip > 0.0) discard; }
#else
void clip() {}
#endif
)";

// The wireframe, drawn by the faces themselves (WIREFRAME defined): the triangles are drawn unrolled
// (vertex 3t + k is corner k of triangle t), each fragment gets its barycentric coordinates, and
// those within a pixel of an edge (b / |grad b|: the distance in pixels) take some of the line's
// colour (a one-pixel line, antialiased: half a pixel on each side). Software WebGL sets up and
// rasterises each line of a wireframe as much as a triangle; this costs a few operations per pixel.
const char* kWireframeVertex = R"(
#ifdef WIREFRAME
out vec3 vCorner;
void setCorner() {
    int k = gl_VertexID % 3;
    vCorner = vec3(k == 0 ? 1.0 : 0.0, k == 1 ? 1.0 : 0.0, k == 2 ? 1.0 : 0.0);
}
#else
void setCorner() {}
#endif
)";

const char* kWireframeFragment = R"(
#ifdef WIREFRAME
in highp vec3 vCorner;
vec3 withWire(vec3 shade) {
    highp vec3 dx = dFdx(vCorner), dy = dFdy(vCorner);
    highp vec3 pixels = vCorner * inversesqrt(max(dx * dx + dy * dy, vec3(1e-12)));
    float inside = clamp(min(min(pixels.x, pixels.y), pixels.z), 0.0, 1.0);
    return mix(vec3(0.08, 0.08, 0.1), shade, inside);
}
#else
vec3 withWire(vec3 shade) { return shade; }
#endif
)";

// The lighting, shared by the per-pixel and the per-vertex mesh programs: a two-sided headlight plus
// a little sky light; back faces (inside of a cut) darker. s^48 as products: pow() is a log and an
// exp per pixel in software WebGL.
const char* kLighting = R"(
vec3 lit(vec3 normal, vec3 colour, vec3 toEye) {
    vec3 n = normalize(normal);
    toEye = normalize(toEye);
    float facing = dot(n, toEye);
    vec3 base = facing < 0.0 ? colour * 0.45 : colour;
    n = facing < 0.0 ? -n : n;
    float diffuse = max(dot(n, toEye), 0.0);
    vec3 h = normalize(toEye + vec3(0.0, 0.0, 0.3));
    float s = max(dot(n, h), 0.0);
    float s2 = s * s, s4 = s2 * s2, s8 = s4 * s4, s16 = s8 * s8;
    float specular = s16 * s16 * s16 * 0.25;
    float sky = 0.5 + 0.5 * n.z;
    return base * (0.18 + 0.12 * sky + 0.72 * diffuse) + vec3(specular);
}
)";

const char* kMeshFragment = R"(
precision highp float;
in vec3 vNormal;
in vec3 vColour;
in vec3 vPosition;
uniform vec3 uEye;
out vec4 fragColour;
void main() {
    clip();
    fragColour = vec4(withWire(lit(vNormal, vColour, uEye - vPosition)), 1.0);
}
)";

// Per-vertex lighting (Gouraud): the same lighting at the vertices, interpolated. For a mesh whose
// triangles are a few pixels wide it gives the same image as the per-pixel program, and costs
// software WebGL much less: one interpolated colour instead of three vectors, no lighting per pixel.
const char* kVertexLitVertex = R"(
layout(location = 0) in vec3 aPosition;
layout(location = 1) in vec3 aNormal;
layout(location = 2) in vec3 aColour;
uniform mat4 uViewProjection;
uniform vec3 uEye;
out vec3 vShade;
void main() {
    vShade = lit(aNormal, aColour, uEye - aPosition);
    gl_Position = uViewProjection * vec4(aPosition, 1.0);
    setCorner();
    setClip(aPosition);
}
)";

const char* kVertexLitFragment = R"(
precision mediump float;
in vec3 vShade;
out vec4 fragColour;
void main() {
    clip();
    fragColour = vec4(withWire(vShade), 1.0);
}
)";

const char* kLineVertex = R"(
layout(location = 0) in vec3 aPosition;
uniform mat4 uViewProjection;
void main() { gl_Position = uViewProjection * vec4(aPosition, 1.0); }
)";

const char* kLineFragment = R"(
precision highp float;
uniform vec4 uColour;
out vec4 fragColour;
void main() { fragColour = uColour; }
)";

const char* kSliceVertex = R"(
layout(location = 0) in vec3 aPosition;
layout(location = 1) in vec2 aTexCoord;
uniform mat4 uViewProjection;
out vec2 vTexCoord;
void main() {
    vTexCoord = aTexCoord;
    gl_Position = uViewProjection * vec4(aPosition, 1.0);
}
)";

const char* kSliceFragment = R"(
precision highp float;
in vec2 vTexCoord;
uniform sampler2D uImage;
out vec4 fragColour;
void main() { fragColour = vec4(texture(uImage, vTexCoord).rgb, 1.0); }
)";

// The layer (see Renderer::beginLayer): its pixels copied as they are (premultiplied alpha).
const char* kLayerVertex = R"(
layout(location = 0) in vec2 aPosition;
uniform vec2 uScale;
void main() { gl_Position = vec4(aPosition * uScale - 1.0, 0.0, 1.0); }
)";

const char* kLayerFragment = R"(
uniform sampler2D uLayer;
out vec4 fragColour;
void main() { fragColour = texelFetch(uLayer, ivec2(gl_FragCoord.xy), 0); }
)";

unsigned compile(GLenum type, const std::string& source)
{
    const GLuint s = glCreateShader(type);
    const char* text = source.c_str();
    glShaderSource(s, 1, &text, nullptr);
    glCompileShader(s);
    GLint ok = 0;
    glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        char log[2048];
        glGetShaderInfoLog(s, sizeof log, nullptr, log);
        throw std::runtime_error(std::string("shader compilation failed: ") + log);
    }
    return s;
}

unsigned link(const char* version, const char* vertex, const char* fragment, const std::string& library = "",
              const std::string& vertexLibrary = "", const std::string& fragmentLibrary = "")
{
    const std::string head = std::string(version) + "\nprecision highp float;\n" + library;
    const GLuint vs = compile(GL_VERTEX_SHADER, head + vertexLibrary + vertex);
    const GLuint fs = compile(GL_FRAGMENT_SHADER, head + fragmentLibrary + fragment);
    const GLuint p = glCreateProgram();
    glAttachShader(p, vs);
    glAttachShader(p, fs);
    glLinkProgram(p);
    glDeleteShader(vs);
    glDeleteShader(fs);
    GLint ok = 0;
    glGetProgramiv(p, GL_LINK_STATUS, &ok);
    if (!ok) {
        char log[2048];
        glGetProgramInfoLog(p, sizeof log, nullptr, log);
        throw std::runtime_error(std::string("shader link failed: ") + log);
    }
    return p;
}

/// Mean edge length on the screen (pixels) under which the mesh is lit per vertex.
constexpr float kVertexLitPixels = 5.f;

/// The mesh programs: lit per pixel or per vertex, without or with the wireframe, without or with
/// the cut at the slice.
unsigned linkMesh(const char* version, bool perVertex, bool wireframe, bool clip)
{
    const std::string defines = std::string(wireframe ? "#define WIREFRAME 1\n" : "") + (clip ? "#define CLIP 1\n" : "");
    return link(version, perVertex ? kVertexLitVertex : kMeshVertex, perVertex ? kVertexLitFragment : kMeshFragment,
                defines + kLighting, std::string(kWireframeVertex) + kClipVertex,
                std::string(kWireframeFragment) + kClipFragment);
}

/// The mesh's vertex attributes (location 0 position, 1 normal, 2 colour) for a bound array buffer of
/// MeshVertex.
void setMeshAttributes()
{
    const GLsizei stride = sizeof(MeshVertex);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(offsetof(MeshVertex, position)));
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 3, GL_SHORT, GL_TRUE, stride, reinterpret_cast<void*>(offsetof(MeshVertex, normal)));
    glEnableVertexAttribArray(2);
    glVertexAttribPointer(2, 3, GL_UNSIGNED_BYTE, GL_TRUE, stride, reinterpret_cast<void*>(offsetof(MeshVertex, colour)));
}

} // namespace

Renderer::Renderer(const char* glslVersion)
{
    for (int perVertex = 0; perVertex < 2; ++perVertex)
        for (int wireframe = 0; wireframe < 2; ++wireframe)
            for (int clip = 0; clip < 2; ++clip)
                mMeshPrograms[perVertex][wireframe][clip] = linkMesh(glslVersion, perVertex, wireframe, clip);
    mLineProgram = link(glslVersion, kLineVertex, kLineFragment);
    mSliceProgram = link(glslVersion, kSliceVertex, kSliceFragment);

    glGenVertexArrays(1, &mMeshVao);
    glGenBuffers(1, &mMeshVbo);
    glGenBuffers(1, &mTriangleIbo);
    glBindVertexArray(mMeshVao);
    glBindBuffer(GL_ARRAY_BUFFER, mMeshVbo);
    setMeshAttributes();
    glGenVertexArrays(1, &mWireVao);
    glGenBuffers(1, &mWireVbo);
    glBindVertexArray(mWireVao);
    glBindBuffer(GL_ARRAY_BUFFER, mWireVbo);
    setMeshAttributes();

    glGenVertexArrays(1, &mSectionVao);
    glGenBuffers(1, &mSectionVbo);
    glBindVertexArray(mSectionVao);
    glBindBuffer(GL_ARRAY_BUFFER, mSectionVbo);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), reinterpret_cast<void*>(0));

    glGenVertexArrays(1, &mSliceVao);
    glGenBuffers(1, &mSliceVbo);
    glBindVertexArray(mSliceVao);
    glBindBuffer(GL_ARRAY_BUFFER, mSliceVbo);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 5 * sizeof(float), reinterpret_cast<void*>(0));
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 2, GL_FLOAT, GL_FALSE, 5 * sizeof(float), reinterpret_cast<void*>(3 * sizeof(float)));
    mLayerProgram = link(glslVersion, kLayerVertex, kLayerFragment);
    glGenVertexArrays(1, &mLayerVao);
    glGenBuffers(1, &mLayerVbo);
    glBindVertexArray(mLayerVao);
    glBindBuffer(GL_ARRAY_BUFFER, mLayerVbo);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, 2 * sizeof(float), reinterpret_cast<void*>(0));

    glGenTextures(1, &mSliceTexture);
    glBindTexture(GL_TEXTURE_2D, mSliceTexture);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    glBindVertexArray(0);
}

Renderer::~Renderer()
{
    const GLuint buffers[] = {mMeshVbo, mTriangleIbo, mWireVbo, mSectionVbo, mSliceVbo, mLayerVbo};
    glDeleteBuffers(6, buffers);
    const GLuint arrays[] = {mMeshVao, mWireVao, mSectionVao, mSliceVao, mLayerVao};
    glDeleteVertexArrays(5, arrays);
    const GLuint textures[] = {mSliceTexture, mLayerTexture};
    glDeleteTextures(mLayerTexture ? 2 : 1, textures);
    if (mLayerFbo) glDeleteFramebuffers(1, &mLayerFbo);
    glDeleteProgram(mLayerProgram);
    for (auto& byWireframe : mMeshPrograms)
        for (auto& programs : byWireframe)
            for (const GLuint p : programs) glDeleteProgram(p);
    glDeleteProgram(mLineProgram);
    glDeleteProgram(mSliceProgram);
}

void Renderer::upload(const Scene& scene)
{
    if (scene.meshVersion != mMeshVersion) {
        mMeshVersion = scene.meshVersion;
        // Packed (24 bytes a vertex instead of 36): 16-bit normals and 8-bit colours, as exact as the
        // 8-bit image they end in.
        const std::size_t nv = scene.vertices.size() / 9;
        mVertices.resize(nv);
        for (std::size_t i = 0; i < nv; ++i) {
            const float* f = &scene.vertices[9 * i];
            MeshVertex& m = mVertices[i];
            for (int k = 0; k < 3; ++k) {
                m.position[k] = f[k];
                m.normal[k] = std::int16_t(std::lround(std::clamp(f[3 + k], -1.f, 1.f) * 32767.f));
                m.colour[k] = std::uint8_t(std::lround(std::clamp(f[6 + k], 0.f, 1.f) * 255.f));
            }
            m.normal[3] = 0;
            m.colour[3] = 255;
        }
        glBindBuffer(GL_ARRAY_BUFFER, mMeshVbo);
        glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(nv * sizeof(MeshVertex)), mVertices.data(), GL_DYNAMIC_DRAW);
        glBindBuffer(GL_ARRAY_BUFFER, mSectionVbo);
        glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(scene.section.size() * sizeof(float)), scene.section.data(),
                     GL_DYNAMIC_DRAW);
        mSectionCount = int(scene.section.size() / 3);
        // The mean edge length, for the choice of lighting.
        double sum = 0;
        for (std::size_t e = 0; e + 1 < scene.edges.size(); e += 2) {
            const float* a = &scene.vertices[9 * scene.edges[e]];
            const float* b = &scene.vertices[9 * scene.edges[e + 1]];
            sum += std::sqrt(double((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2])));
        }
        mMeanEdge = scene.edges.empty() ? 0.f : float(sum / double(scene.edges.size() / 2));
        // The triangles' planes, for cull().
        const std::size_t nt = scene.triangles.size() / 3;
        mPlanes.resize(4 * nt);
        const float* v = scene.vertices.data();
        for (std::size_t t = 0; t < nt; ++t) {
            const float* a = v + 9 * scene.triangles[3 * t];
            const float* b = v + 9 * scene.triangles[3 * t + 1];
            const float* c = v + 9 * scene.triangles[3 * t + 2];
            const Vec3f pa(a[0], a[1], a[2]);
            Vec3f n = (Vec3f(b[0], b[1], b[2]) - pa).cross(Vec3f(c[0], c[1], c[2]) - pa);
            const float len = n.norm();
            n = len > 0 ? Vec3f(n / len) : Vec3f::Zero();
            float* p = &mPlanes[4 * t];
            p[0] = n.x();
            p[1] = n.y();
            p[2] = n.z();
            p[3] = n.dot(pa);
        }
        mCulledVersion = ~0ull;
    }
    if (scene.sliceVersion != mSliceVersion && scene.slice.width > 0) {
        mSliceVersion = scene.sliceVersion;
        const SliceImage& s = scene.slice;
        glBindTexture(GL_TEXTURE_2D, mSliceTexture);
        glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
        glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, s.width, s.height, 0, GL_RGBA, GL_UNSIGNED_BYTE, s.rgba.data());
        const float uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
        const int order[6] = {0, 1, 2, 0, 2, 3};
        float quad[6 * 5];
        for (int i = 0; i < 6; ++i) {
            const int c = order[i];
            quad[i * 5 + 0] = s.corners[c].x();
            quad[i * 5 + 1] = s.corners[c].y();
            quad[i * 5 + 2] = s.corners[c].z();
            quad[i * 5 + 3] = uv[c][0];
            quad[i * 5 + 4] = uv[c][1];
        }
        glBindBuffer(GL_ARRAY_BUFFER, mSliceVbo);
        glBufferData(GL_ARRAY_BUFFER, sizeof quad, quad, GL_DYNAMIC_DRAW);
    }
}

void Renderer::cull(const Scene& scene, const Vec3f& eye, const float* clipPlane)
{
    // Software WebGL (SwiftShader) shades the vertices and sets up every triangle of a draw before it
    // culls the back faces: half the mesh's triangles cost that for nothing. So only the triangles
    // that face the eye are drawn (as indices, or unrolled with the wireframe), refilled when the eye
    // or the mesh moves (a pass over the triangles' planes). GL still culls back faces; the margin
    // keeps the triangles seen edge-on (the float test may disagree with the rasteriser's about them),
    // so the image is the same.
    // With a cut (clipPlane: n, w; the eye's side n . x > w goes), triangles wholly on the eye's side
    // are dropped too, and those across the plane are put last (mStraddleCount corners), for the
    // program that discards the cut-away part of them.
    const bool wireframe = scene.wireframe;
    const float noPlane[4] = {0, 0, 0, 0};
    const float* plane = clipPlane ? clipPlane : noPlane;
    if (mCulledVersion == mMeshVersion && mCulledEye[0] == eye.x() && mCulledEye[1] == eye.y() &&
        mCulledEye[2] == eye.z() && mCulledWireframe == wireframe && std::equal(plane, plane + 4, mCulledPlane))
        return;
    mCulledVersion = mMeshVersion;
    mCulledEye[0] = eye.x();
    mCulledEye[1] = eye.y();
    mCulledEye[2] = eye.z();
    mCulledWireframe = wireframe;
    std::copy(plane, plane + 4, mCulledPlane);
    const std::size_t nt = mPlanes.size() / 4;
    float extent = 0;
    for (int k = 0; k < 3; ++k) extent = std::max(extent, std::abs(eye[k]));
    const float margin = 1e-4f * std::max(extent, 1.f);
    if (wireframe) mUnrolled.resize(scene.triangles.size());
    else mVisible.resize(scene.triangles.size());
    std::size_t n = 0, straddle = 0; // corners kept whole from the front, across the cut from the back
    const std::size_t total = scene.triangles.size();
    for (std::size_t t = 0; t < nt; ++t) {
        const float* p = &mPlanes[4 * t];
        if (p[0] * eye.x() + p[1] * eye.y() + p[2] * eye.z() - p[3] <= -margin) continue;
        const std::uint32_t* corner = &scene.triangles[3 * t];
        bool across = false;
        if (clipPlane) {
            int gone = 0;
            for (int k = 0; k < 3; ++k) {
                const float* x = mVertices[corner[k]].position;
                gone += plane[0] * x[0] + plane[1] * x[1] + plane[2] * x[2] > plane[3];
            }
            if (gone == 3) continue;
            across = gone > 0;
        }
        const std::size_t at = across ? total - (straddle += 3) : (n += 3) - 3;
        for (int k = 0; k < 3; ++k) {
            if (wireframe) mUnrolled[at + std::size_t(k)] = mVertices[corner[k]];
            else mVisible[at + std::size_t(k)] = corner[k];
        }
    }
    // The triangles across the cut follow the others directly.
    if (wireframe) std::copy(mUnrolled.begin() + long(total - straddle), mUnrolled.end(), mUnrolled.begin() + long(n));
    else std::copy(mVisible.begin() + long(total - straddle), mVisible.end(), mVisible.begin() + long(n));
    mTriangleCount = int(n);
    mStraddleCount = int(straddle);
    const std::size_t corners = n + straddle;
    if (wireframe) {
        glBindBuffer(GL_ARRAY_BUFFER, mWireVbo);
        glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(corners * sizeof(MeshVertex)), mUnrolled.data(), GL_STREAM_DRAW);
    } else {
        glBindVertexArray(mMeshVao); // the triangles are the element buffer of the mesh's vertex array
        glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, mTriangleIbo);
        glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(corners * sizeof(std::uint32_t)), mVisible.data(), GL_STREAM_DRAW);
        glBindVertexArray(0);
    }
}

void Renderer::draw(const Scene& scene, int width, int height)
{
    upload(scene);
    glViewport(0, 0, width, height);
    glClearColor(scene.background.x(), scene.background.y(), scene.background.z(), 1.f);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    if (width <= 0 || height <= 0) return;
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LEQUAL);
    glDisable(GL_CULL_FACE);
    glDisable(GL_BLEND);

    const Mat4f vp = scene.camera.projection(float(width) / float(height)) * scene.camera.view();
    const Vec3f eye = scene.camera.eye();
    // The cut at the slice: the plane through its corners, its normal toward the eye.
    float plane[4] = {0, 0, 0, 0};
    const bool clip = scene.clipAtSlice && scene.showSlice && mSliceVersion != ~0ull;
    if (clip) {
        const Vec3f* c = scene.slice.corners;
        Vec3f n = (c[1] - c[0]).cross(c[3] - c[0]);
        n = n.norm() > 0 ? Vec3f(n.normalized()) : Vec3f::UnitZ();
        if (n.dot(eye - c[0]) < 0) n = -n;
        plane[0] = n.x();
        plane[1] = n.y();
        plane[2] = n.z();
        plane[3] = n.dot(c[0]);
    }
    if (scene.showMesh) cull(scene, eye, clip ? plane : nullptr);

    if (scene.showMesh && mTriangleCount + mStraddleCount > 0) {
        // The mesh is closed and oriented outward (counter-clockwise seen from outside): its back
        // faces are always hidden, and culling them halves what software WebGL rasterises.
        glEnable(GL_CULL_FACE);
        glCullFace(GL_BACK);
        // Lighting per pixel, or per vertex when the mesh's edges are a few pixels long on the screen
        // (the mean edge at the camera's target distance under kVertexLitPixels).
        const float pixelsPerUnit = float(height) / (2.f * scene.camera.distance * std::tan(scene.camera.fovY / 2));
        const bool perVertex = scene.lighting == 2 || (scene.lighting == 0 && mMeanEdge * pixelsPerUnit < kVertexLitPixels);
        // The whole triangles, then those across the cut with the program that discards its far part.
        const int first[2] = {0, mTriangleCount}, count[2] = {mTriangleCount, mStraddleCount};
        for (int cut = 0; cut < 2; ++cut) {
            if (count[cut] == 0) continue;
            const GLuint prog = mMeshPrograms[perVertex][mCulledWireframe][cut];
            glUseProgram(prog);
            glUniformMatrix4fv(glGetUniformLocation(prog, "uViewProjection"), 1, GL_FALSE, vp.data());
            glUniform3f(glGetUniformLocation(prog, "uEye"), eye.x(), eye.y(), eye.z());
            if (cut) glUniform4f(glGetUniformLocation(prog, "uClipPlane"), plane[0], plane[1], plane[2], plane[3]);
            if (mCulledWireframe) {
                glBindVertexArray(mWireVao);
                glDrawArrays(GL_TRIANGLES, first[cut], count[cut]);
            } else {
                glBindVertexArray(mMeshVao);
                glDrawElements(GL_TRIANGLES, count[cut], GL_UNSIGNED_INT,
                               reinterpret_cast<void*>(std::size_t(first[cut]) * sizeof(std::uint32_t)));
            }
        }
        glDisable(GL_CULL_FACE);
    }
    if (scene.showSlice && mSliceVersion != ~0ull) {
        glUseProgram(mSliceProgram);
        glUniformMatrix4fv(glGetUniformLocation(mSliceProgram, "uViewProjection"), 1, GL_FALSE, vp.data());
        glActiveTexture(GL_TEXTURE0);
        glBindTexture(GL_TEXTURE_2D, mSliceTexture);
        glUniform1i(glGetUniformLocation(mSliceProgram, "uImage"), 0);
        glBindVertexArray(mSliceVao);
        glDrawArrays(GL_TRIANGLES, 0, 6);
        if (mSectionCount > 0) {
            glUseProgram(mLineProgram);
            glUniformMatrix4fv(glGetUniformLocation(mLineProgram, "uViewProjection"), 1, GL_FALSE, vp.data());
            glUniform4f(glGetUniformLocation(mLineProgram, "uColour"), 1.f, 0.35f, 0.2f, 1.f);
            glDisable(GL_DEPTH_TEST); // the cross-section stays visible through the mesh
            glBindVertexArray(mSectionVao);
            glDrawArrays(GL_LINES, 0, mSectionCount);
            glEnable(GL_DEPTH_TEST);
        }
    }
    glBindVertexArray(0);
    glUseProgram(0);
}

void Renderer::beginLayer(int width, int height)
{
    if (!mLayerFbo) {
        glGenFramebuffers(1, &mLayerFbo);
        glGenTextures(1, &mLayerTexture);
    }
    glBindFramebuffer(GL_FRAMEBUFFER, mLayerFbo);
    if (width != mLayerWidth || height != mLayerHeight) {
        mLayerWidth = width;
        mLayerHeight = height;
        glBindTexture(GL_TEXTURE_2D, mLayerTexture);
        glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, std::max(width, 1), std::max(height, 1), 0, GL_RGBA,
                     GL_UNSIGNED_BYTE, nullptr);
        glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
        glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
        glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, mLayerTexture, 0);
    }
    glViewport(0, 0, width, height);
    glDisable(GL_SCISSOR_TEST);
    glClearColor(0.f, 0.f, 0.f, 0.f);
    glClear(GL_COLOR_BUFFER_BIT);
}

void Renderer::endLayer() { glBindFramebuffer(GL_FRAMEBUFFER, 0); }

void Renderer::compositeLayer(int x0, int y0, int x1, int y1, int width, int height)
{
    x0 = std::max(x0, 0);
    y0 = std::max(y0, 0);
    x1 = std::min({x1, width, mLayerWidth});
    y1 = std::min({y1, height, mLayerHeight});
    if (!mLayerFbo || x1 <= x0 || y1 <= y0) return;
    const float quad[12] = {float(x0), float(y0), float(x1), float(y0), float(x1), float(y1),
                            float(x0), float(y0), float(x1), float(y1), float(x0), float(y1)};
    glViewport(0, 0, width, height);
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_CULL_FACE);
    glDisable(GL_SCISSOR_TEST);
    glEnable(GL_BLEND);
    glBlendEquation(GL_FUNC_ADD);
    glBlendFunc(GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
    glUseProgram(mLayerProgram);
    glUniform2f(glGetUniformLocation(mLayerProgram, "uScale"), 2.f / float(width), 2.f / float(height));
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, mLayerTexture);
    glUniform1i(glGetUniformLocation(mLayerProgram, "uLayer"), 0);
    glBindVertexArray(mLayerVao);
    glBindBuffer(GL_ARRAY_BUFFER, mLayerVbo);
    glBufferData(GL_ARRAY_BUFFER, sizeof quad, quad, GL_STREAM_DRAW);
    glDrawArrays(GL_TRIANGLES, 0, 6);
    glBindVertexArray(0);
    glUseProgram(0);
    glDisable(GL_BLEND);
}

void Renderer::finish()
{
    // glFinish alone does not wait in WebGL (Chromium returns at once); reading a pixel back does:
    // the GPU process must execute everything before it.
    unsigned char pixel[4];
    glFinish();
    glReadPixels(0, 0, 1, 1, GL_RGBA, GL_UNSIGNED_BYTE, pixel);
}

} // namespace riemesh::viewer
