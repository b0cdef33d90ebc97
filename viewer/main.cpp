// riemesh-viewer: one main loop for the native window (GLFW + OpenGL 3.3) and the browser (emscripten,
// GLFW + WebGL2). Usage (native): riemesh-viewer [volume.nvdb] [--headless]
//   --headless   no window: evolve to convergence and print the stats lines (for timing).
// In the browser the page fetches the demo volume into /data/<name>.nvdb and passes it as argv[1].
#include "app.h"
#include "render.h"

#include <imgui.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#ifdef __EMSCRIPTEN__
#include <emscripten.h>
#include <emscripten/html5.h>
#endif

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <string>

namespace {

using riemesh::viewer::App;
using riemesh::viewer::Renderer;

struct Viewer {
    GLFWwindow* window = nullptr;
    App app;
    std::unique_ptr<Renderer> renderer;
    std::uint64_t shown = 0; ///< signature of the image on the canvas (web; 0: none)
    /// The UI drawn once into the renderer's layer and composited while it stays the same (see
    /// drawUi()): uiSignature() of the last frame's UI, of the layer's content (0: none), its bounds.
    std::uint64_t uiLast = 0, uiCached = 0;
    int uiBounds[4] = {0, 0, 0, 0};
};
Viewer* gViewer = nullptr;

#ifdef __EMSCRIPTEN__
constexpr const char* kGlslVersion = "#version 300 es";
constexpr const char* kDemoVolume = "/data/phantom.nvdb";
#else
constexpr const char* kGlslVersion = "#version 330 core";
constexpr const char* kDemoVolume = "";
#endif

bool fileExists(const std::string& path) { return !path.empty() && std::ifstream(path).good(); }

void onDrop(GLFWwindow*, int count, const char** paths)
{
    if (count > 0 && gViewer) gViewer->app.loadVolume(paths[count - 1]);
}

void onKey(GLFWwindow*, int key, int, int action, int)
{
    // Chained by the ImGui GLFW backend (installed before it), which then records the key itself.
    if (action == GLFW_PRESS && gViewer) gViewer->app.keyPressed(key);
}

void offerDownload(const std::string& path)
{
#ifdef __EMSCRIPTEN__
    // The file is in MEMFS: hand it to the browser as a download, then drop it.
    EM_ASM(
        {
            const path = UTF8ToString($0);
            const data = FS.readFile(path);
            const blob = new Blob([data], {type : 'application/octet-stream'});
            const a = document.createElement('a');
            a.href = URL.createObjectURL(blob);
            a.download = path.split('/').pop();
            document.body.appendChild(a);
            a.click();
            setTimeout(() => { URL.revokeObjectURL(a.href); a.remove(); }, 1000);
            FS.unlink(path);
        },
        path.c_str());
#else
    std::printf("riemesh: wrote %s\n", path.c_str());
#endif
}

/// 64-bit hashes of what the next image shows: the scene's inputs (mesh and slice versions, camera,
/// display flags, size) and, apart, ImGui's draw lists (vertices, indices, commands).
struct Hash {
    std::uint64_t h = 0x9e3779b97f4a7c15ull;
    void mix(const void* data, std::size_t bytes)
    {
        const auto* p = static_cast<const unsigned char*>(data);
        std::uint64_t word = 0;
        for (; bytes >= 8; bytes -= 8, p += 8) {
            std::memcpy(&word, p, 8);
            h = (h ^ word) * 0xff51afd7ed558ccdull;
            h ^= h >> 32;
        }
        word = 0;
        std::memcpy(&word, p, bytes);
        h = (h ^ word ^ (std::uint64_t(bytes) << 56)) * 0xc4ceb9fe1a85ec53ull;
        h ^= h >> 29;
    }
    std::uint64_t value() const { return h == 0 ? 1 : h; }
};

std::uint64_t sceneSignature(const riemesh::viewer::Scene& scene, int width, int height)
{
    Hash h;
    const auto& c = scene.camera;
    const float camera[] = {c.target.x(), c.target.y(), c.target.z(), c.yaw, c.pitch, c.distance, c.fovY,
                            scene.background.x(), scene.background.y(), scene.background.z()};
    const std::uint64_t other[] = {scene.meshVersion, scene.sliceVersion,
                                   std::uint64_t(scene.showMesh) | std::uint64_t(scene.wireframe) << 1 |
                                       std::uint64_t(scene.showSlice) << 2 | std::uint64_t(scene.lighting) << 3 |
                                       std::uint64_t(scene.clipAtSlice) << 5,
                                   std::uint64_t(std::uint32_t(width)) << 32 | std::uint32_t(height)};
    h.mix(camera, sizeof camera);
    h.mix(other, sizeof other);
    return h.value();
}

std::uint64_t uiSignature(const ImDrawData* ui)
{
    Hash h;
    if (!ui || !ui->Valid) return 1;
    const float display[] = {ui->DisplayPos.x, ui->DisplayPos.y, ui->DisplaySize.x, ui->DisplaySize.y,
                             ui->FramebufferScale.x, ui->FramebufferScale.y};
    h.mix(display, sizeof display);
    for (int i = 0; i < ui->CmdListsCount; ++i) {
        const ImDrawList* list = ui->CmdLists[i];
        h.mix(list->VtxBuffer.Data, std::size_t(list->VtxBuffer.Size) * sizeof(ImDrawVert));
        h.mix(list->IdxBuffer.Data, std::size_t(list->IdxBuffer.Size) * sizeof(ImDrawIdx));
        for (const ImDrawCmd& cmd : list->CmdBuffer) {
            const std::uint64_t fields[] = {std::uint64_t(reinterpret_cast<std::uintptr_t>(cmd.TextureId)),
                                            cmd.VtxOffset, cmd.IdxOffset, cmd.ElemCount,
                                            std::uint64_t(reinterpret_cast<std::uintptr_t>(cmd.UserCallback))};
            h.mix(&cmd.ClipRect, sizeof cmd.ClipRect);
            h.mix(fields, sizeof fields);
        }
    }
    return h.value();
}

/// Draws the UI over the scene. A UI drawn again and again the same (the camera orbits, the mesh
/// evolves under a still panel) is drawn once into the renderer's layer and then composited: one
/// textured rectangle instead of the panel's blended glyphs and shapes, which cost software WebGL
/// about as much as a 20k-vertex mesh. A UI that changed since the last frame is drawn directly
/// (drawing it into the layer would cost more, for nothing if it changes again).
void drawUi(Viewer& v, std::uint64_t signature, int width, int height)
{
    ImDrawData* ui = ImGui::GetDrawData();
    if (!ui || !ui->Valid || ui->TotalVtxCount == 0) {
        v.uiLast = signature;
        return;
    }
    if (signature != v.uiCached && signature == v.uiLast) {
        v.renderer->beginLayer(width, height);
        ImGui_ImplOpenGL3_RenderDrawData(ui);
        v.renderer->endLayer();
        v.uiCached = signature;
        // The layer's bounds: those of the UI's vertices, in framebuffer pixels (origin bottom left).
        float lo[2] = {FLT_MAX, FLT_MAX}, hi[2] = {-FLT_MAX, -FLT_MAX};
        for (int i = 0; i < ui->CmdListsCount; ++i)
            for (const ImDrawVert& p : ui->CmdLists[i]->VtxBuffer) {
                lo[0] = std::min(lo[0], p.pos.x);
                lo[1] = std::min(lo[1], p.pos.y);
                hi[0] = std::max(hi[0], p.pos.x);
                hi[1] = std::max(hi[1], p.pos.y);
            }
        const ImVec2 o = ui->DisplayPos, s = ui->FramebufferScale;
        v.uiBounds[0] = int(std::floor((lo[0] - o.x) * s.x)) - 1;
        v.uiBounds[1] = height - int(std::ceil((hi[1] - o.y) * s.y)) - 1;
        v.uiBounds[2] = int(std::ceil((hi[0] - o.x) * s.x)) + 1;
        v.uiBounds[3] = height - int(std::floor((lo[1] - o.y) * s.y)) + 1;
    }
    if (signature == v.uiCached)
        v.renderer->compositeLayer(v.uiBounds[0], v.uiBounds[1], v.uiBounds[2], v.uiBounds[3], width, height);
    else
        ImGui_ImplOpenGL3_RenderDrawData(ui);
    v.uiLast = signature;
}

void frame()
{
    Viewer& v = *gViewer;
#ifdef __EMSCRIPTEN__
    // The canvas follows the window: size the GLFW window (and so the canvas) to the CSS size.
    double cssW = 0, cssH = 0;
    emscripten_get_element_css_size("#canvas", &cssW, &cssH);
    int winW = 0, winH = 0;
    glfwGetWindowSize(v.window, &winW, &winH);
    // Not glfwSetWindowSize: emscripten 3.1.6's GLFW takes a size equal to the screen's for a
    // fullscreen request, which the browser refuses without a click, and the canvas kept its old
    // size (a browser in fullscreen mode, or a headless one whose screen is its window). Resizing
    // the canvas is what it does for any other size: GLFW's resize listener then takes the new size
    // as the window's and framebuffer's.
    if (int(cssW) > 0 && int(cssH) > 0 && (int(cssW) != winW || int(cssH) != winH))
        EM_ASM({ Browser.setCanvasSize($0, $1); }, int(cssW), int(cssH));
#endif
    glfwPollEvents();
    int width = 0, height = 0;
    glfwGetFramebufferSize(v.window, &width, &height);

    ImGui_ImplOpenGL3_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
    // Evolution steps for ~8 ms per frame (at least one): the UI stays responsive (a page that spent
    // 25 ms per frame on a small mesh ran at ~25 frames per second); see App::frame().
    v.app.frame(8.0, width, height);
    ImGui::Render();

    const std::uint64_t ui = uiSignature(ImGui::GetDrawData());
#ifdef __EMSCRIPTEN__
    // A frame that would show the same image as the canvas does is not drawn: the browser keeps
    // showing the last one (it presents a WebGL canvas only when it was drawn to). An idle viewer
    // then costs its UI logic only, whatever the size of the mesh; anything that changes the image
    // (camera, mesh, slice, display, the UI's text or hover state) draws the whole frame.
    const std::uint64_t signature = sceneSignature(v.app.scene(), width, height) * 0x9e3779b97f4a7c15ull ^ ui;
    const bool draw = signature != v.shown;
    v.shown = signature;
#else
    const bool draw = true;
#endif
    if (draw) {
        v.renderer->draw(v.app.scene(), width, height);
        drawUi(v, ui, width, height);
        glfwSwapBuffers(v.window);
    }
    v.app.frameShown(draw);

    if (auto path = v.app.takeDownload()) offerDownload(*path);
}

#ifdef __EMSCRIPTEN__
// The page's JS API (Module.ccall): state as JSON, play/pause, reset, parameters.
extern "C" {
EMSCRIPTEN_KEEPALIVE const char* riemesh_state()
{
    static std::string state;
    state = gViewer ? gViewer->app.stateJson() : "{}";
    return state.c_str();
}
EMSCRIPTEN_KEEPALIVE void riemesh_set_playing(int playing)
{
    if (gViewer) gViewer->app.setPlaying(playing != 0);
}
EMSCRIPTEN_KEEPALIVE void riemesh_reset()
{
    if (gViewer) gViewer->app.reset();
}
EMSCRIPTEN_KEEPALIVE int riemesh_set_parameter(const char* name, double value)
{
    return gViewer && gViewer->app.setParameter(name, value) ? 1 : 0;
}
EMSCRIPTEN_KEEPALIVE int riemesh_load(const char* path)
{
    return gViewer && gViewer->app.loadVolume(path) ? 1 : 0;
}
/// Writes the mesh as ".ply" or ".obj" and hands it to the browser as a download (the next frame),
/// as the Files panel's buttons do; 0 for another extension.
EMSCRIPTEN_KEEPALIVE int riemesh_download(const char* extension)
{
    return gViewer && gViewer->app.exportMesh(extension) ? 1 : 0;
}
/// Draw cost of a whole frame as the main loop draws it while the camera moves (the scene, then the
/// UI as it is drawn when it has not changed: composited from its layer), each render waited for as
/// in riemesh_time_draw; mean milliseconds per frame (benchmarks only).
EMSCRIPTEN_KEEPALIVE double riemesh_time_frame(int count)
{
    if (!gViewer || count <= 0) return -1;
    Viewer& v = *gViewer;
    int width = 0, height = 0;
    glfwGetFramebufferSize(v.window, &width, &height);
    const std::uint64_t ui = uiSignature(ImGui::GetDrawData());
    v.uiLast = ui; // as after a frame with the same UI: it is drawn into its layer, then composited
    v.renderer->draw(v.app.scene(), width, height);
    drawUi(v, ui, width, height);
    v.renderer->finish();
    const double start = emscripten_get_now();
    for (int i = 0; i < count; ++i) {
        v.renderer->draw(v.app.scene(), width, height);
        drawUi(v, ui, width, height);
        v.renderer->finish();
    }
    gViewer->shown = 0; // the next frame draws
    return (emscripten_get_now() - start) / count;
}
/// Draw cost of the current scene, apart from the browser's frame pacing and compositing: renders
/// it `count` times, each finished by a one-pixel read back (which waits for the GPU process), and
/// returns the mean milliseconds per render (benchmarks only).
EMSCRIPTEN_KEEPALIVE double riemesh_time_draw(int count)
{
    if (!gViewer || count <= 0) return -1;
    Viewer& v = *gViewer;
    int width = 0, height = 0;
    glfwGetFramebufferSize(v.window, &width, &height);
    v.renderer->finish();
    const double start = emscripten_get_now();
    for (int i = 0; i < count; ++i) {
        v.renderer->draw(v.app.scene(), width, height);
        v.renderer->finish();
    }
    gViewer->shown = 0; // the canvas now shows the scene without the UI: the next frame draws
    return (emscripten_get_now() - start) / count;
}
}
#endif

int run(int argc, char** argv)
{
    std::string volume = kDemoVolume;
    bool headless = false;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--headless") headless = true;
        else if (a == "--help" || a == "-h") {
            std::printf("usage: riemesh-viewer [volume.nvdb] [--headless]\n");
            return EXIT_SUCCESS;
        } else volume = a;
    }

    gViewer = new Viewer; // lives as long as the page (emscripten_set_main_loop never returns)
    Viewer& v = *gViewer;
    auto load = [&] {
        if (fileExists(volume) && v.app.loadVolume(volume)) return;
        if (!volume.empty()) std::fprintf(stderr, "riemesh: cannot use %s: the analytic phantom instead\n", volume.c_str());
        v.app.loadAnalyticPhantom();
    };
    if (headless) {
        load();
        v.app.runToConvergence();
        return EXIT_SUCCESS;
    }

    if (!glfwInit()) throw std::runtime_error("glfwInit failed (no display?)");
#ifdef __EMSCRIPTEN__
    glfwWindowHint(GLFW_CLIENT_API, GLFW_OPENGL_ES_API);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 0);
#else
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
#endif
#ifdef __EMSCRIPTEN__
    // An opaque canvas (alpha: false: the browser need not blend it over the page) without stencil.
    glfwWindowHint(GLFW_ALPHA_BITS, 0);
    glfwWindowHint(GLFW_STENCIL_BITS, 0);
#else
    glfwWindowHint(GLFW_SAMPLES, 4); // (not on the web: multisampling is slow in software WebGL)
#endif
    v.window = glfwCreateWindow(1280, 800, "riemesh", nullptr, nullptr);
    if (!v.window) throw std::runtime_error("cannot create an OpenGL 3.3 window");
    glfwMakeContextCurrent(v.window);
    glfwSwapInterval(1);
    glfwSetDropCallback(v.window, onDrop);
    glfwSetKeyCallback(v.window, onKey); // before ImGui_ImplGlfw_InitForOpenGL, which chains it

    IMGUI_CHECKVERSION();
    ImGui::CreateContext();
    ImGuiIO& io = ImGui::GetIO();
    io.IniFilename = nullptr;
    ImGui::StyleColorsDark();
    ImGui::GetStyle().WindowRounding = 4.f;
    ImGui_ImplGlfw_InitForOpenGL(v.window, true);
    ImGui_ImplOpenGL3_Init(kGlslVersion);
    v.renderer = std::make_unique<Renderer>(kGlslVersion);

    load();

#ifdef __EMSCRIPTEN__
    emscripten_set_main_loop(frame, 0, true);
#else
    while (!glfwWindowShouldClose(v.window)) frame();
    v.renderer.reset();
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
    glfwDestroyWindow(v.window);
    glfwTerminate();
#endif
    return EXIT_SUCCESS;
}

} // namespace

int main(int argc, char** argv)
{
    try {
        return run(argc, argv);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "riemesh-viewer: %s\n", e.what());
        return EXIT_FAILURE;
    }
}
