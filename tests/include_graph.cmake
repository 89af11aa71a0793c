# The include graph has no arrow back. Between the stages:
#   core <- accel <- sim <- runner <- analysis <- tuner <- cli.
# Inside core, folder by folder: base <- scene (generate/, import/) <- truth. Inside accel, room by
# room: model/ (counters, outcome predictors, cache model) <- interface/ (the structure interface,
# parameters, hit policy, cast arena) <- common/ and narrow/ (the narrow phase and leaf volumes,
# which wrap any structure) <- the families scan/, grid/, bvh/, peers/ (never each other) <- the
# registry in accel/ itself, the one list of structures, which alone includes the families and
# narrow/. Outside libraries stay where they belong: CLI11 in cli/ only, Embree and Bullet's
# collision library in accel/peers/ (Bullet's also in core/scene/bullet/, the recorder of a Bullet
# game), Bullet's dynamics world in core/scene/generate/ (the physics
# scenes), assimp and libzip in core/scene/import/, SQLite in runner/, Ceres and Eigen in
# analysis/, NLopt in tuner/.
# Run by ctest: cmake -DSOURCE_DIR=... -P include_graph.cmake
cmake_minimum_required(VERSION 3.25)
set(core_base "core/base")
set(core_scene "${core_base};core/scene")
set(core_truth "${core_scene};core/truth")
set(core_all "${core_truth};core/scene/generate;core/scene/import;core/scene/bullet")
set(accel_model "${core_all};accel/model")
set(accel_interface "${accel_model};accel/interface")
set(accel_common "${accel_interface};accel/common")
set(accel_families "accel/scan;accel/grid;accel/bvh;accel/peers")
set(accel_all "${accel_common};accel/narrow;${accel_families};accel")
set(sim_all "${accel_all};sim")
# What each folder may include (folders not named here take their stage's rule below).
set(allowed_core/base "${core_base}")
set(allowed_core/scene "${core_scene}")
set(allowed_core/scene/generate "${core_scene};core/scene/generate")
set(allowed_core/scene/import "${core_scene};core/scene/import")
set(allowed_core/scene/bullet "${core_scene};core/scene/bullet")
set(allowed_core/truth "${core_truth}")
set(allowed_accel/model "${accel_model}")
set(allowed_accel/interface "${accel_interface}")
set(allowed_accel/common "${accel_common}")
set(allowed_accel/narrow "${accel_interface};accel/narrow")
set(allowed_accel/scan "${accel_common};accel/scan")
set(allowed_accel/grid "${accel_common};accel/grid")
set(allowed_accel/bvh "${accel_common};accel/bvh")
set(allowed_accel/peers "${accel_common};accel/peers")
set(allowed_accel "${accel_all}")
set(allowed_sim "${sim_all}")
set(allowed_runner "${sim_all};runner")
# The conformance suite (rcbench::testing) is installed with rcbench::structures: it may include
# core, accel and sim only.
set(allowed_testing "${sim_all};testing")
set(allowed_analysis "${allowed_runner};analysis")
set(allowed_tuner "${allowed_analysis};tuner")
set(allowed_cli "${allowed_tuner};cli")
# Outside libraries: header prefix -> the one folder (and below) that may include it.
set(library_homes "CLI/=cli" "embree3/=accel/peers" "BulletCollision/=accel/peers,core/scene/bullet"
    "btBulletDynamicsCommon.h=core/scene/generate" "BulletDynamics/=core/scene/generate"
    "assimp/=core/scene/import" "zip.h=core/scene/import" "sqlite3.h=runner" "ceres/=analysis"
    "Eigen/=analysis" "nlopt=tuner")

set(violations "")
set(checked 0)
file(GLOB_RECURSE files "${SOURCE_DIR}/core/*.h" "${SOURCE_DIR}/core/*.cpp" "${SOURCE_DIR}/accel/*.h"
     "${SOURCE_DIR}/accel/*.cpp" "${SOURCE_DIR}/sim/*.h" "${SOURCE_DIR}/sim/*.cpp" "${SOURCE_DIR}/runner/*.h"
     "${SOURCE_DIR}/runner/*.cpp" "${SOURCE_DIR}/analysis/*.h" "${SOURCE_DIR}/analysis/*.cpp"
     "${SOURCE_DIR}/tuner/*.h" "${SOURCE_DIR}/tuner/*.cpp" "${SOURCE_DIR}/cli/*.h" "${SOURCE_DIR}/cli/*.cpp"
     "${SOURCE_DIR}/testing/*.h" "${SOURCE_DIR}/testing/*.cpp")
foreach(f ${files})
  file(RELATIVE_PATH rel "${SOURCE_DIR}" "${f}")
  get_filename_component(folder "${rel}" DIRECTORY)
  string(REGEX MATCH "^[a-z]+" stage "${rel}")
  if(DEFINED allowed_${folder})
    set(allowed "${allowed_${folder}}")
  elseif(stage STREQUAL "core" OR stage STREQUAL "accel")
    list(APPEND violations "${rel}: ${stage}/ folder ${folder} has no rule in tests/include_graph.cmake")
    continue()
  else()
    set(allowed "${allowed_${stage}}")
  endif()
  file(STRINGS "${f}" includes REGEX "^#include [\"<]")
  foreach(line ${includes})
    if(line MATCHES "^#include \"((core|accel|sim|runner|analysis|tuner|cli|testing)/[^\"]*)\"")
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
message(STATUS "include graph: ${checked} includes, core (base <- scene <- truth) <- accel (model <- interface <- common, narrow <- families <- registry) <- sim <- runner <- analysis <- tuner <- cli, no arrow back")
