# The emscripten build (included first, only when EMSCRIPTEN): where the fetched third-party sources
# are, and the flags every WebAssembly target carries.
#
# scripts/setup-web unpacks the Debian source packages `openmesh` and `imgui` into
# RIEMESH_THIRD_PARTY_DIR and links the header-only dependencies (Eigen, NanoVDB, doctest) into
# RIEMESH_THIRD_PARTY_DIR/wasm-include: em++ must never see -I/usr/include.
set(RIEMESH_THIRD_PARTY_DIR ${PROJECT_SOURCE_DIR}/third_party CACHE PATH
    "Sources fetched by scripts/setup-web (openmesh/, imgui/, wasm-include/)")
set(_tp ${RIEMESH_THIRD_PARTY_DIR})
foreach(_dir openmesh/src/OpenMesh/Core imgui wasm-include/Eigen wasm-include/nanovdb)
  if(NOT EXISTS ${_tp}/${_dir})
    message(FATAL_ERROR "riemesh (wasm): ${_tp}/${_dir} is missing; run scripts/setup-web")
  endif()
endforeach()

if(NOT RIEMESH_OPENMESH_SOURCES)
  file(GLOB_RECURSE RIEMESH_OPENMESH_SOURCES ${_tp}/openmesh/src/OpenMesh/Core/*.cc)
endif()
set(RIEMESH_OPENMESH_INCLUDE ${_tp}/openmesh/src CACHE PATH "OpenMesh include dir (wasm)")
set(RIEMESH_WASM_INCLUDE ${_tp}/wasm-include CACHE PATH "Eigen/NanoVDB headers for em++")
set(RIEMESH_DOCTEST_INCLUDE ${_tp}/wasm-include CACHE PATH "doctest headers for em++")
set(RIEMESH_IMGUI_DIR ${_tp}/imgui CACHE PATH "Dear ImGui sources (wasm)")

# emscripten 3.1.6 runs acorn (Debian's node-acorn) at link time: give every link its NODE_PATH, so
# that a plain `cmake --build build-wasm` works too.
if(NOT CMAKE_CXX_LINKER_LAUNCHER)
  set(CMAKE_CXX_LINKER_LAUNCHER ${CMAKE_COMMAND} -E env NODE_PATH=/usr/share/nodejs)
endif()

# riemesh_wasm: flags every WebAssembly target needs, compile and link alike (C++ exceptions are
# off by default in emscripten and must be on in every object).
add_library(riemesh_wasm INTERFACE)
target_compile_options(riemesh_wasm INTERFACE -fexceptions)
target_link_options(riemesh_wasm INTERFACE -fexceptions -sALLOW_MEMORY_GROWTH=1)

# riemesh_wasm_node: link flags of programs run under node (the unit suites): synchronous
# compilation (Node 20 would otherwise exit before the module is instantiated), the exit code of
# main() as the process's, and the real file system.
add_library(riemesh_wasm_node INTERFACE)
target_link_options(riemesh_wasm_node INTERFACE -sWASM_ASYNC_COMPILATION=0 -sEXIT_RUNTIME=1
                    -sNODERAWFS=1 -sINITIAL_MEMORY=64MB)

# Applies the node link flags to every test executable (called after tests/ is added).
function(riemesh_wasm_node_tests)
  if(TARGET riemesh_test_support)
    target_link_libraries(riemesh_test_support INTERFACE riemesh_wasm_node)
  endif()
endfunction()
