# cmake -DMODULE=detectors|station -DROOT=<tree> -P check_includes.cmake
#
# Reads every C/C++ file under ROOT/MODULE and fails (FATAL_ERROR, listing file:line) when
# an #include names something the module may not use (docs/conventions.md):
#   detectors: the C++ standard library, Eigen, libapriltag and detectors/ itself - an
#              allow-list, so any new library must be added here on purpose;
#   station:   anything but gRPC, protobuf, SQLite, sockets, OpenCV, daemon/, tools/, proto/.
cmake_minimum_required(VERSION 3.25)
if(NOT MODULE OR NOT ROOT)
  message(FATAL_ERROR "usage: cmake -DMODULE=detectors|station -DROOT=DIR -P check_includes.cmake")
endif()

# C++ standard library headers in use or plausible; anything else in <> is a library.
set(std_headers
  algorithm any array atomic bit bitset cassert cctype cerrno cfloat charconv chrono cinttypes
  climits cmath complex concepts cstddef cstdint cstdio cstdlib cstring ctime deque exception
  execution filesystem format functional initializer_list iomanip ios iosfwd iostream
  istream iterator limits list map memory memory_resource mutex new numbers numeric optional
  ostream queue random ranges ratio regex set shared_mutex source_location span sstream stack
  stdexcept string string_view system_error thread tuple type_traits typeindex typeinfo
  unordered_map unordered_set utility valarray variant vector version)

file(GLOB_RECURSE files "${ROOT}/${MODULE}/*.h" "${ROOT}/${MODULE}/*.hpp"
                        "${ROOT}/${MODULE}/*.cc" "${ROOT}/${MODULE}/*.cpp")
set(problems "")
foreach(f IN LISTS files)
  file(STRINGS "${f}" lines REGEX "^[ \t]*#[ \t]*include")
  foreach(line IN LISTS lines)
    string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]*([<\"])([^>\"]*)[>\"].*" "\\1;\\2" parsed "${line}")
    list(GET parsed 0 delim)
    list(GET parsed 1 header)
    set(bad FALSE)
    if(MODULE STREQUAL "detectors")
      if(delim STREQUAL "\"")
        if(NOT header MATCHES "^detectors/")
          set(bad TRUE)
        endif()
      elseif(NOT header IN_LIST std_headers AND NOT header MATCHES "^(Eigen/|unsupported/Eigen/|apriltag/)")
        set(bad TRUE)
      endif()
    elseif(MODULE STREQUAL "station")
      if(header MATCHES "^(grpc|grpcpp/|google/protobuf/|sqlite3|sys/socket|netinet/|arpa/|opencv2/|daemon/|tools/|proto/)")
        set(bad TRUE)
      endif()
    endif()
    if(bad)
      file(RELATIVE_PATH rel "${ROOT}" "${f}")
      if(delim STREQUAL "<")
        set(close ">")
      else()
        set(close "\"")
      endif()
      string(APPEND problems "\n  ${rel}: #include ${delim}${header}${close}")
    endif()
  endforeach()
endforeach()
if(problems)
  message(FATAL_ERROR "${MODULE}/ includes what docs/conventions.md forbids:${problems}")
endif()
list(LENGTH files n)
message(STATUS "${MODULE}/: ${n} files, includes within the rules")
