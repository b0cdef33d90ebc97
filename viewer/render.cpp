#include "render.h"

#ifdef __EMSCRIPTEN__
#include <GLES3/gl3.h>
#else
#define GL_GLEXT_PROTOTYPES 1
#include <GL/gl.h>
#include <GL/glext.h>
#endif

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
    vec3 n = normalize(vNormal);
    vec3 toEye = normalize(uEye - vPosition);
    // Two-sided headlight plus a little sky light; back faces (inside of a cut) darker.
    float facing = dot(n, toEye);
    vec3 base = facing < 0.0 ? vColour * 0.45 : vColour;
    n = facing < 0.0 ? -n : n;
    float diffuse = max(dot(n, toEye), 0.0);
    vec3 h = normalize(toEye + vec3(0.0, 0.0, 0.3));
    float specular = pow(max(dot(n, h), 0.0), 48.0) * 0.25;
    float sky = 0.5 + 0.5 * n.z;
    fragColour = vec4(base * (0.18 + 0.12 * sky + 0.72 * diffuse) + vec3(specular), 1.0);
}
)";

const char* kLineVertex = R"(
layout(location = 0) in vec3 aPosition;
uniform mat4 uViewProjection;
void main() {
    gl_Position = uViewProjection * vec4(aPosition, 1.0);
    gl_Position.z -= 0.0005 * gl_Position.w; // lines win over the faces they lie on
}
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

unsigned link(const char* version, const char* vertex, const char* fragment)
{
    const std::string head = std::string(version) + "\n";
    const GLuint vs = compile(GL_VERTEX_SHADER, head + vertex);
    const GLuint fs = compile(GL_FRAGMENT_SHADER, head + fragment);
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

} // namespace

Renderer::Renderer(const char* glslVersion)
{
    mMeshProgram = link(glslVersion, kMeshVertex, kMeshFragment);
    mLineProgram = link(glslVersion, kLineVertex, kLineFragment);
    mSliceProgram = link(glslVersion, kSliceVertex, kSliceFragment);

    glGenVertexArrays(1, &mMeshVao);
    glGenBuffers(1, &mMeshVbo);
    glGenBuffers(1, &mTriangleIbo);
    glGenBuffers(1, &mEdgeIbo);
    glBindVertexArray(mMeshVao);
    glBindBuffer(GL_ARRAY_BUFFER, mMeshVbo);
    const GLsizei stride = 9 * sizeof(float);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(0));
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(3 * sizeof(float)));
    glEnableVertexAttribArray(2);
    glVertexAttribPointer(2, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(6 * sizeof(float)));

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
    const GLuint buffers[] = {mMeshVbo, mTriangleIbo, mEdgeIbo, mSectionVbo, mSliceVbo};
    glDeleteBuffers(5, buffers);
    const GLuint arrays[] = {mMeshVao, mSectionVao, mSliceVao};
    glDeleteVertexArrays(3, arrays);
    glDeleteTextures(1, &mSliceTexture);
    glDeleteProgram(mMeshProgram);
    glDeleteProgram(mLineProgram);
    glDeleteProgram(mSliceProgram);
}

void Renderer::upload(const Scene& scene)
{
    if (scene.meshVersion != mMeshVersion) {
        mMeshVersion = scene.meshVersion;
        glBindVertexArray(mMeshVao);
        glBindBuffer(GL_ARRAY_BUFFER, mMeshVbo);
        glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(scene.vertices.size() * sizeof(float)), scene.vertices.data(),
                     GL_DYNAMIC_DRAW);
        glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, mTriangleIbo);
        glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(scene.triangles.size() * sizeof(std::uint32_t)),
                     scene.triangles.data(), GL_DYNAMIC_DRAW);
        glBindVertexArray(0);
        glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, mEdgeIbo);
        glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(scene.edges.size() * sizeof(std::uint32_t)),
                     scene.edges.data(), GL_DYNAMIC_DRAW);
        glBindBuffer(GL_ARRAY_BUFFER, mSectionVbo);
        glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(scene.section.size() * sizeof(float)), scene.section.data(),
                     GL_DYNAMIC_DRAW);
        mTriangleCount = int(scene.triangles.size());
        mEdgeCount = int(scene.edges.size());
        mSectionCount = int(scene.section.size() / 3);
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

    if (scene.showMesh && mTriangleCount > 0) {
        // The mesh is closed and oriented outward (counter-clockwise seen from outside): its back
        // faces are always hidden, and culling them halves what software WebGL rasterises.
        glEnable(GL_CULL_FACE);
        glCullFace(GL_BACK);
        glUseProgram(mMeshProgram);
        glUniformMatrix4fv(glGetUniformLocation(mMeshProgram, "uViewProjection"), 1, GL_FALSE, vp.data());
        glUniform3f(glGetUniformLocation(mMeshProgram, "uEye"), eye.x(), eye.y(), eye.z());
        glBindVertexArray(mMeshVao);
        glDrawElements(GL_TRIANGLES, mTriangleCount, GL_UNSIGNED_INT, nullptr);
        glDisable(GL_CULL_FACE);
    }
    glUseProgram(mLineProgram);
    glUniformMatrix4fv(glGetUniformLocation(mLineProgram, "uViewProjection"), 1, GL_FALSE, vp.data());
    const GLint colour = glGetUniformLocation(mLineProgram, "uColour");
    if (scene.showMesh && scene.wireframe && mEdgeCount > 0) {
        glUniform4f(colour, 0.08f, 0.08f, 0.1f, 1.f);
        glBindVertexArray(mMeshVao);
        glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, mEdgeIbo); // part of the VAO state: put the triangles back
        glDrawElements(GL_LINES, mEdgeCount, GL_UNSIGNED_INT, nullptr);
        glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, mTriangleIbo);
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
            glUniform4f(colour, 1.f, 0.35f, 0.2f, 1.f);
            glDisable(GL_DEPTH_TEST); // the cross-section stays visible through the mesh
            glBindVertexArray(mSectionVao);
            glDrawArrays(GL_LINES, 0, mSectionCount);
            glEnable(GL_DEPTH_TEST);
        }
    }
    glBindVertexArray(0);
    glUseProgram(0);
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
