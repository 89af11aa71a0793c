# The include graph has no arrow back. Between the stages: core <- runner <- analysis <- tuner <- cli.
# Inside core, folder by folder: base <- scene (generate/, import/) <- truth <- accel (the interface
# in accel/ itself, then common/, then the families scan/, grid/, bvh/, peers/) <- sim; accel/ never
# includes common/ (common/ includes the interface), and only accel/registry.cpp, the one list of
# structures, includes the families. Outside libraries stay where they belong: CLI11 in cli/ only,
# Embree and Bullet's collision library in core/accel/peers/ (Bullet's also in core/scene/bullet/,
# the recorder of a Bullet game), Bullet's dynamics world in
# core/scene/generate/ (the physics scenes), assimp and libzip in core/scene/import/, SQLite in
# runner/, Ceres and Eigen in analysis/, NLopt in tuner/.
# Run by ctest: cmake -DSOURCE_DIR=... -P include_graph.cmake
cmake_minimum_required(VERSION 3.25)
set(core_base "core/base")
set(core_scene "${core_base};core/scene")
set(core_truth "${core_scene};core/truth")
set(core_interface "${core_truth};core/accel")
set(core_accel "${core_interface};core/accel/common")
set(core_families "core/accel/scan;core/accel/grid;core/accel/bvh;core/accel/peers")
set(core_all "${core_accel};${core_families};core/scene/generate;core/scene/import;core/scene/bullet;core/sim")
# What each folder may include (folders not named here take their stage's rule below).
set(allowed_core/base "${core_base}")
set(allowed_core/scene "${core_scene}")
set(allowed_core/scene/generate "${core_scene};core/scene/generate")
set(allowed_core/scene/import "${core_scene};core/scene/import")
set(allowed_core/scene/bullet "${core_scene};core/scene/bullet")
set(allowed_core/truth "${core_truth}")
set(allowed_core/accel "${core_interface}")
set(allowed_core/accel/common "${core_accel}")
set(allowed_core/accel/scan "${core_accel};core/accel/scan")
set(allowed_core/accel/grid "${core_accel};core/accel/grid")
set(allowed_core/accel/bvh "${core_accel};core/accel/bvh")
set(allowed_core/accel/peers "${core_accel};core/accel/peers")
set(allowed_core/sim "${core_all}")
set(allowed_runner "${core_all};runner")
# The conformance suite (rcbench::testing) is installed with core: it may include core only.
set(allowed_testing "${core_all};testing")
set(allowed_analysis "${allowed_runner};analysis")
set(allowed_tuner "${allowed_analysis};tuner")
set(allowed_cli "${allowed_tuner};cli")
# Outside libraries: header prefix -> the one folder (and below) that may include it.
set(library_homes "CLI/=cli" "embree3/=core/accel/peers" "BulletCollision/=core/accel/peers,core/scene/bullet"
    "btBulletDynamicsCommon.h=core/scene/generate" "BulletDynamics/=core/scene/generate"
    "assimp/=core/scene/import" "zip.h=core/scene/import" "sqlite3.h=runner" "ceres/=analysis"
    "Eigen/=analysis" "nlopt=tuner")

set(violations "")
set(checked 0)
file(GLOB_RECURSE files "${SOURCE_DIR}/core/*.h" "${SOURCE_DIR}/core/*.cpp" "${SOURCE_DIR}/runner/*.h"
     "${SOURCE_DIR}/runner/*.cpp" "${SOURCE_DIR}/analysis/*.h" "${SOURCE_DIR}/analysis/*.cpp"
     "${SOURCE_DIR}/tuner/*.h" "${SOURCE_DIR}/tuner/*.cpp" "${SOURCE_DIR}/cli/*.h" "${SOURCE_DIR}/cli/*.cpp"
     "${SOURCE_DIR}/testing/*.h" "${SOURCE_DIR}/testing/*.cpp")
foreach(f ${files})
  file(RELATIVE_PATH rel "${SOURCE_DIR}" "${f}")
  get_filename_component(folder "${rel}" DIRECTORY)
  string(REGEX MATCH "^[a-z]+" stage "${rel}")
  if(DEFINED allowed_${folder})
    set(allowed "${allowed_${folder}}")
  elseif(stage STREQUAL "core")
    list(APPEND violations "${rel}: core/ folder ${folder} has no rule in tests/include_graph.cmake")
    continue()
  else()
    set(allowed "${allowed_${stage}}")
  endif()
  if(rel STREQUAL "core/accel/registry.cpp")
    list(APPEND allowed ${core_families})
  endif()
  file(STRINGS "${f}" includes REGEX "^#include [\"<]")
  foreach(line ${includes})
    if(line MATCHES "^#include \"((core|runner|analysis|tuner|cli|testing)/[^\"]*)\"")
      get_filename_component(target "${CMAKE_MATCH_1}" DIRECTORY)
      math(EXPR checked "${checked} + 1")
      if(NOT target IN_LIST allowed)
        list(JOIN allowed ", " may)
        list(APPEND violations "${rel}: ${line} (${folder} may include ${may})")
      endif()
    elseif(line MATCHES "^#include <([^>]*)>")
      set(header "${CMAKE_MATCH_1}")
      foreach(home ${library_homes})
        string(REPLACE "=" ";" home "${home}")
        list(GET home 0 prefix)
        list(GET home 1 place)
        string(FIND "${header}" "${prefix}" at)
        set(inside FALSE)
        string(REPLACE "," ";" places "${place}")  # a library with several homes lists them
        foreach(p ${places})
          string(FIND "${rel}" "${p}/" in_p)
          if(in_p EQUAL 0)
            set(inside TRUE)
          endif()
        endforeach()
        if(at EQUAL 0 AND NOT inside)
          string(REPLACE "," "/ or " place "${place}")
          list(APPEND violations "${rel}: ${line} (only ${place}/ includes ${prefix})")
        endif()
      endforeach()
    endif()
  endforeach()
endforeach()
if(violations)
  list(JOIN violations "\n" text)
  message(FATAL_ERROR "include graph violations:\n${text}")
endif()
if(checked LESS 100)
  message(FATAL_ERROR "include graph: only ${checked} project includes found under ${SOURCE_DIR}")
endif()
message(STATUS "include graph: ${checked} includes, base <- scene <- truth <- accel (interface <- common <- families) <- sim <- runner <- analysis <- tuner <- cli, no arrow back")
