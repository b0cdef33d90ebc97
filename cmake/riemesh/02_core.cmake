# riemesh_core (alias riemesh::core): OpenMesh + Eigen + NanoVDB headers only.
# Under emscripten, RIEMESH_OPENMESH_SOURCES / RIEMESH_WASM_INCLUDE point at sources fetched by
# scripts/setup-web (set by 00_wasm.cmake): OpenMesh Core is compiled from its Debian source package.
if(EMSCRIPTEN)
  add_library(riemesh_openmesh STATIC ${RIEMESH_OPENMESH_SOURCES})
  target_include_directories(riemesh_openmesh SYSTEM PUBLIC ${RIEMESH_OPENMESH_INCLUDE})
  target_compile_definitions(riemesh_openmesh PUBLIC _USE_MATH_DEFINES OM_STATIC_BUILD)
  target_compile_features(riemesh_openmesh PUBLIC cxx_std_17)
  target_link_libraries(riemesh_openmesh PUBLIC riemesh_wasm)
  set(RIEMESH_OPENMESH_TARGET riemesh_openmesh)
  set(RIEMESH_THIRD_PARTY_INCLUDE ${RIEMESH_WASM_INCLUDE})
else()
  find_package(OpenMesh REQUIRED)
  find_package(Eigen3 3.3 REQUIRED NO_MODULE)
  set(RIEMESH_OPENMESH_TARGET OpenMeshCore Eigen3::Eigen)
  set(RIEMESH_THIRD_PARTY_INCLUDE "")
endif()

file(GLOB RIEMESH_CORE_SOURCES CONFIGURE_DEPENDS ${PROJECT_SOURCE_DIR}/core/src/*.cpp
     ${PROJECT_SOURCE_DIR}/core/src/detail/*.cpp)
add_library(riemesh_core STATIC ${RIEMESH_CORE_SOURCES})
add_library(riemesh::core ALIAS riemesh_core)
target_compile_features(riemesh_core PUBLIC cxx_std_17)
target_include_directories(riemesh_core PUBLIC ${PROJECT_SOURCE_DIR}/core/include
                           PRIVATE ${PROJECT_SOURCE_DIR}/core/src)
if(RIEMESH_THIRD_PARTY_INCLUDE)
  target_include_directories(riemesh_core SYSTEM PUBLIC ${RIEMESH_THIRD_PARTY_INCLUDE})
endif()
target_compile_definitions(riemesh_core PUBLIC _USE_MATH_DEFINES)
target_link_libraries(riemesh_core PUBLIC ${RIEMESH_OPENMESH_TARGET} PRIVATE riemesh_warnings)
# Natively the core's loops run on TBB when it is found (core/src/threads.cpp, the only file that
# includes it); under emscripten, or without TBB, they run serially (riemesh/threads.h).
option(RIEMESH_CORE_TBB "Run the core's loops on TBB when it is found (never under emscripten)" ON)
if(RIEMESH_CORE_TBB AND NOT EMSCRIPTEN)
  find_package(TBB CONFIG QUIET)
  if(TBB_FOUND)
    target_link_libraries(riemesh_core PRIVATE TBB::tbb)
    target_compile_definitions(riemesh_core PRIVATE RIEMESH_CORE_TBB)
  else()
    message(STATUS "riemesh core: TBB not found, the core runs on one thread")
  endif()
endif()
# The exact predicates' expansion arithmetic needs every product rounded on its own (no fused
# multiply-add contraction).
if(CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang")
  set_source_files_properties(${PROJECT_SOURCE_DIR}/core/src/detail/predicates.cpp
                              PROPERTIES COMPILE_OPTIONS -ffp-contract=off)
endif()
