# Helpers shared by the module folders.

# linecal_module(NAME SOURCES ... PUBLIC_LIBS ... PRIVATE_LIBS ...)
# One static library per module folder. Includes are written from the repository root
# ("detectors/core/pose.h"), so every module exports the root as its include directory;
# which modules a target may use is decided by what it links, and checked by
# tests/layering.
function(linecal_module name)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_LIBS;PRIVATE_LIBS" ${ARGN})
  add_library(${name} STATIC ${ARG_SOURCES})
  target_include_directories(${name} PUBLIC ${PROJECT_SOURCE_DIR})
  target_link_libraries(${name} PUBLIC ${ARG_PUBLIC_LIBS} PRIVATE ${ARG_PRIVATE_LIBS})
endfunction()
