# cmake -DROOT=<tree> -P check_external_refs.cmake
#
# A clone of the repository is complete on its own (docs/external-data.md). Reads every text
# file of the tree (sources, tests, docs, scripts, configuration; not build trees, .git or
# the fixtures here) and fails (FATAL_ERROR, listing file:line) when
#   - a file names the folder beside the repository that holds the external test data,
#     other than the one data-root helper (tests/support/CMakeLists.txt) and the page that
#     explains it (docs/external-data.md);
#   - a file cites a Markdown document that is not in the tree: a bare name must be in docs/,
#     at the root or beside the citing file; a path must exist from the root or from the
#     citing file (an installed path, absolute or from an @VARIABLE@: the same name in docs/).
cmake_minimum_required(VERSION 3.25)
if(NOT ROOT)
  message(FATAL_ERROR "usage: cmake -DROOT=DIR -P check_external_refs.cmake")
endif()

set(allowed "tests/support/CMakeLists.txt" "docs/external-data.md")
# Written in two parts so that this file does not match itself.
set(sibling "shared")
set(forbidden "\\.\\./${sibling}|(^|[^A-Za-z_])${sibling}/(spec|data|reference|hooks)")
set(text_ext "\\.(h|hpp|cc|cpp|c|cmake|txt|md|sh|py|json|proto|in|yaml|yml|js|html|css|service|csv)$")

file(GLOB_RECURSE all LIST_DIRECTORIES false RELATIVE "${ROOT}" "${ROOT}/*")
set(problems "")
set(checked 0)
foreach(rel IN LISTS all)
  if(rel MATCHES "^(\\.git/|build[^/]*/|tests/layering/fixture_)")
    continue()
  endif()
  get_filename_component(name "${rel}" NAME)
  if(NOT name MATCHES "${text_ext}" AND NOT name STREQUAL "CMakeLists.txt"
     AND NOT rel MATCHES "^(tools|\\.ci)/[^/.]+$")
    continue()
  endif()
  math(EXPR checked "${checked} + 1")
  get_filename_component(dir "${ROOT}/${rel}" DIRECTORY)
  file(STRINGS "${ROOT}/${rel}" lines)
  set(n 0)
  foreach(line IN LISTS lines)
    math(EXPR n "${n} + 1")
    if(line MATCHES "${forbidden}" AND NOT rel IN_LIST allowed)
      string(APPEND problems "\n  ${rel}:${n}: names the external data folder (use tests/support/external_data.h)")
    endif()
    if(NOT line MATCHES "\\.md")
      continue()
    endif()
    string(REGEX MATCHALL "[A-Za-z0-9_./@-]*[A-Za-z0-9_-]+\\.md" cited "${line}")
    foreach(c IN LISTS cited)
      get_filename_component(base "${c}" NAME)
      if(EXISTS "${ROOT}/${c}" OR EXISTS "${dir}/${c}")
        continue()
      elseif(NOT c MATCHES "/" AND EXISTS "${ROOT}/docs/${c}")
        continue()
      elseif(c MATCHES "^/|@/" AND EXISTS "${ROOT}/docs/${base}")
        continue()
      endif()
      string(APPEND problems "\n  ${rel}:${n}: cites ${c}, which is not in the repository")
    endforeach()
  endforeach()
endforeach()
if(problems)
  message(FATAL_ERROR "references outside the repository:${problems}")
endif()
message(STATUS "checked ${checked} files: no reference outside the repository")
