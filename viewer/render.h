// viewer/render.h: draws a Scene with OpenGL 3.3 core (native) or WebGL2 (OpenGL ES 3.0, emscripten).
//
// The only file of the viewer that calls GL besides the ImGui backend.
// Buffers are re-uploaded when the scene's versions change, the mesh's visible triangles also when the
// eye moves (back faces are culled on the CPU); drawing a frame issues a handful of draw calls.
#pragma once

#include "app.h"

#include <cstdint>
#include <vector>

namespace riemesh::viewer {

/// A mesh vertex as the renderer uploads it (24 bytes): world space position, unit normal
/// (16-bit normalized), colour (8-bit normalized); the 4th normal and colour components are padding.
struct MeshVertex {
    float position[3];
    std::int16_t normal[4];
    std::uint8_t colour[4];
};

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
    /// An offscreen layer the size of the framebuffer, for an image that changes less often than the
    /// scene (the UI): draw it between beginLayer() and endLayer() (premultiplied alpha: blend
    /// SRC_ALPHA, ONE_MINUS_SRC_ALPHA for colour and ONE, ONE_MINUS_SRC_ALPHA for alpha, as the ImGui
    /// backend does), then compositeLayer() puts its pixels in [x0,x1) x [y0,y1) (framebuffer pixels,
    /// origin bottom left) over the framebuffer: the same image as drawing it there directly.
    void beginLayer(int width, int height);
    void endLayer();
    void compositeLayer(int x0, int y0, int x1, int y1, int width, int height);
    /// Waits until every GL command issued so far has executed (a one-pixel read back; for draw-time
    /// benchmarks).
    void finish();

private:
    unsigned mMeshPrograms[2][2][2] = {}; ///< [per vertex][wireframe][cut at the slice]
    unsigned mLineProgram = 0, mSliceProgram = 0;
    unsigned mMeshVao = 0, mMeshVbo = 0, mTriangleIbo = 0, mWireVao = 0, mWireVbo = 0;
    unsigned mSectionVao = 0, mSectionVbo = 0;
    unsigned mSliceVao = 0, mSliceVbo = 0, mSliceTexture = 0;
    unsigned mLayerProgram = 0, mLayerVao = 0, mLayerVbo = 0, mLayerFbo = 0, mLayerTexture = 0;
    int mLayerWidth = 0, mLayerHeight = 0;
    std::uint64_t mMeshVersion = ~0ull, mSliceVersion = ~0ull;
    int mTriangleCount = 0, mSectionCount = 0; ///< vertices of the mesh's whole triangles; of the section's lines
    int mStraddleCount = 0; ///< vertices of the triangles across the cut, drawn after mTriangleCount
    float mMeanEdge = 0; ///< world units
    std::vector<MeshVertex> mVertices;    ///< the uploaded mesh's vertices
    // Back faces culled on the CPU (see cull()): the face planes of the uploaded mesh, the eye and
    // the display the visible triangles were last gathered for, and the work arrays.
    std::vector<float> mPlanes;           ///< per triangle: unit normal n, n . (a vertex)
    std::vector<std::uint32_t> mVisible;  ///< indices of the triangles to draw
    std::vector<MeshVertex> mUnrolled;    ///< with the wireframe: the triangles to draw, unrolled
    std::uint64_t mCulledVersion = ~0ull;
    float mCulledEye[3] = {0, 0, 0};
    bool mCulledWireframe = false;
    float mCulledPlane[4] = {0, 0, 0, 0}; ///< the cut (n, w) the triangles were gathered for; 0 for none
    void upload(const Scene& scene);
    void cull(const Scene& scene, const Vec3f& eye, const float* clipPlane);
};

} // namespace riemesh::viewer
