// viewer/render.h: draws a Scene with OpenGL 3.3 core (native) or WebGL2 (OpenGL ES 3.0, emscripten).
//
// The only file of the viewer that calls GL besides the ImGui backend. Buffers are re-uploaded when
// the scene's versions change; drawing a frame issues a handful of draw calls.
#pragma once

#include "app.h"

#include <cstdint>

namespace riemesh::viewer {

class Renderer {
public:
    /// Compiles the shaders; needs a current GL context. `glslVersion` is the first shader line
    /// ("#version 330 core" or "#version 300 es"). Throws std::runtime_error on a shader error.
    explicit Renderer(const char* glslVersion);
    ~Renderer();
    Renderer(const Renderer&) = delete;
    Renderer& operator=(const Renderer&) = delete;

    /// Clears the framebuffer (width x height pixels) and draws the scene's mesh and slice.
    void draw(const Scene& scene, int width, int height);
    /// Waits until every GL command issued so far has executed (a one-pixel read back; for draw-time
    /// benchmarks).
    void finish();

private:
    unsigned mMeshProgram = 0, mLineProgram = 0, mSliceProgram = 0;
    unsigned mMeshVao = 0, mMeshVbo = 0, mTriangleIbo = 0, mEdgeIbo = 0;
    unsigned mSectionVao = 0, mSectionVbo = 0;
    unsigned mSliceVao = 0, mSliceVbo = 0, mSliceTexture = 0;
    std::uint64_t mMeshVersion = ~0ull, mSliceVersion = ~0ull;
    int mTriangleCount = 0, mEdgeCount = 0, mSectionCount = 0;
    void upload(const Scene& scene);
};

} // namespace riemesh::viewer
