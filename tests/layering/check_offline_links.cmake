# cmake -DPROBE=<offline_link_probe> -P check_offline_links.cmake
#
# Fails when the program linked against only station/pipeline and station/sensors needs
# Aravis, gRPC or SQLite at run time: the offline pipeline and the decoders must build and
# run on a machine without the daemon's libraries (docs/conventions.md, "Map of the tree").
cmake_minimum_required(VERSION 3.25)
execute_process(COMMAND readelf -d "${PROBE}" OUTPUT_VARIABLE dynamic RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "readelf -d ${PROBE} failed (${rc})")
endif()
string(REGEX MATCHALL "Shared library: \\[[^]]*\\]" needed "${dynamic}")
list(LENGTH needed n)
if(n EQUAL 0)
  message(FATAL_ERROR "${PROBE} lists no shared library: not a dynamically linked program?")
endif()
set(bad "")
foreach(entry IN LISTS needed)
  if(entry MATCHES "(aravis|grpc|gpr|sqlite|protobuf)")
    string(APPEND bad "\n  ${entry}")
  endif()
endforeach()
if(bad)
  message(FATAL_ERROR "the offline libraries pull in the daemon's:${bad}")
endif()
message(STATUS "${PROBE}: ${n} shared libraries, none of Aravis, gRPC, protobuf or SQLite")
