# cmake -DROOT=<tree> -P check_folders.cmake
#
# The one-way map of docs/conventions.md ("Map of the tree") inside station/, daemon/ and
# tools/: fails (FATAL_ERROR, listing file:line) when a folder includes a station/ folder it
# may not, or when anything but the simulator's own users includes the simulator. The
# per-module rules (what detectors/ and station/ may use at all) are check_includes.cmake's.
cmake_minimum_required(VERSION 3.25)
if(NOT ROOT)
  message(FATAL_ERROR "usage: cmake -DROOT=DIR -P check_folders.cmake")
endif()

# station/ folders, each with the station/ folders it may include (its own is always allowed).
set(base io camera sensors/lidar)
set(allowed_io "")
set(allowed_camera io)
set(allowed_sensors/lidar io)
set(allowed_model ${base})
set(allowed_sensors/radar ${base} model)
set(allowed_capture ${base} model sensors/radar)
set(allowed_solvers ${base} model sensors/radar capture)
set(allowed_pipeline ${allowed_solvers} solvers)
set(allowed_sim ${allowed_solvers} solvers)
set(allowed_aftersale ${allowed_solvers} solvers)
set(allowed_planner ${allowed_solvers} solvers sim)
set(allowed_health ${base} model)

# The folder of station/ a path is in: sensors/lidar and sensors/radar count on their own.
function(station_folder path out)
  if(path MATCHES "^station/(sensors/[a-z_]+)/")
    set(${out} "${CMAKE_MATCH_1}" PARENT_SCOPE)
  elseif(path MATCHES "^station/([a-z_]+)/")
    set(${out} "${CMAKE_MATCH_1}" PARENT_SCOPE)
  else()
    set(${out} "" PARENT_SCOPE)
  endif()
endfunction()

# Whether the file at `rel` may include `header`; the reason in `why` when not.
function(check_include rel header why)
  set(${why} "" PARENT_SCOPE)
  station_folder("${rel}" from)
  station_folder("${header}" to)
  if(from AND to AND NOT from STREQUAL to)
    if(NOT DEFINED allowed_${from})
      set(${why} "station/${from}/ is not on the map" PARENT_SCOPE)
    elseif(NOT to IN_LIST allowed_${from})
      set(${why} "station/${from}/ may not include station/${to}/" PARENT_SCOPE)
    endif()
    return()
  endif()
  # The simulator is for the simulated station and the commands that simulate.
  if(to STREQUAL "sim" AND rel MATCHES "^(daemon|tools)/")
    if(NOT rel MATCHES "^daemon/simstation/"
       AND NOT rel MATCHES "^tools/linecal/cmd_(sim|sim_lanes|serve_sensors|eval_[a-z_]+)[.]cc$")
      set(${why} "only daemon/simstation/ and the sim, serve-sensors and eval commands include the simulator" PARENT_SCOPE)
    endif()
  endif()
  if(rel MATCHES "^daemon/drivers/" AND header MATCHES "^daemon/" AND NOT header MATCHES "^daemon/drivers/")
    set(${why} "daemon/drivers/ (real I/O only) may not include the daemon above it" PARENT_SCOPE)
  endif()
endfunction()

file(GLOB_RECURSE files RELATIVE "${ROOT}"
  "${ROOT}/station/*.h" "${ROOT}/station/*.cc" "${ROOT}/daemon/*.h" "${ROOT}/daemon/*.cc"
  "${ROOT}/tools/*.h" "${ROOT}/tools/*.cc")
set(problems "")
foreach(rel IN LISTS files)
  file(STRINGS "${ROOT}/${rel}" lines REGEX "^[ \t]*#[ \t]*include[ \t]*\"")
  foreach(line IN LISTS lines)
    string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]*\"([^\"]*)\".*" "\\1" header "${line}")
    check_include("${rel}" "${header}" why)
    if(why)
      string(APPEND problems "\n  ${rel}: #include \"${header}\": ${why}")
    endif()
  endforeach()
endforeach()
if(problems)
  message(FATAL_ERROR "includes against the map of docs/conventions.md:${problems}")
endif()
list(LENGTH files n)
message(STATUS "station/, daemon/, tools/: ${n} files, includes follow the map")
