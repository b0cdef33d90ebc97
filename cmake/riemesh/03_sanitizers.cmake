# Instrumented builds (never the default): RIEMESH_SANITIZE=address,undefined for the sanitizer suites
# (scripts/test-sanitize, build-asan/), and RIEMESH_FUZZ for the libFuzzer targets in fuzz/ (clang only,
# scripts/fuzz, build-fuzz/), which also instruments every library for coverage.
#
# Every riemesh target links riemesh_warnings, so the flags ride on it: libraries, apps and tests are
# all instrumented, and no global CMAKE_CXX_FLAGS are touched. Reports abort (no recovery), so a
# sanitizer finding fails the run.
set(RIEMESH_SANITIZE "" CACHE STRING "Sanitizers for every riemesh target, e.g. address,undefined (empty: none)")
option(RIEMESH_FUZZ "Build the libFuzzer targets in fuzz/ (clang; implies address,undefined)" OFF)

set(_riemesh_sanitizers ${RIEMESH_SANITIZE})
if(RIEMESH_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID MATCHES "Clang")
    message(FATAL_ERROR "riemesh: RIEMESH_FUZZ needs clang (libFuzzer), e.g. -DCMAKE_CXX_COMPILER=clang++-14")
  endif()
  set(_riemesh_sanitizers address,undefined)
endif()

if(_riemesh_sanitizers)
  add_library(riemesh_sanitizers INTERFACE)
  # -O1 (last, so it wins over the build type's -O3): the usual level for sanitizers, and it halves
  # the compile time of the files that include OpenVDB.
  set(_compile -fsanitize=${_riemesh_sanitizers} -fno-sanitize-recover=all -fno-omit-frame-pointer -g -O1)
  if(CMAKE_CXX_COMPILER_ID MATCHES "Clang")
    list(APPEND _compile -fsanitize-ignorelist=${CMAKE_CURRENT_LIST_DIR}/sanitizer_ignorelist.txt)
  endif()
  if(RIEMESH_FUZZ)
    # Coverage instrumentation for the fuzzer in every object; only fuzz targets link libFuzzer's main.
    list(APPEND _compile -fsanitize=fuzzer-no-link)
  endif()
  target_compile_options(riemesh_sanitizers INTERFACE ${_compile})
  target_link_options(riemesh_sanitizers INTERFACE -fsanitize=${_riemesh_sanitizers})
  target_link_libraries(riemesh_warnings INTERFACE riemesh_sanitizers)
endif()
