# riemesh_warnings: an INTERFACE target carrying the project's warning flags.
add_library(riemesh_warnings INTERFACE)
if(CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang")
  target_compile_options(riemesh_warnings INTERFACE -Wall -Wextra -Wno-unused-parameter)
endif()
