# The results database has one owner: runner/. Every SQL statement (read or write) and every use of
# the SQLite wrapper lives there (runner/results_reader.h reads, runner/results_writer.h and
# runner/store.h write); the other stages get and give typed rows. This fails on a source file
# outside runner/ (tests/ excepted: tests build hand-made databases) that
#   - holds SQL in a string literal: a statement's keyword (SELECT, INSERT INTO, UPDATE ... SET,
#     DELETE FROM, CREATE/DROP/ALTER TABLE, PRAGMA, ...) after a quote on a line of code;
#   - includes runner/sqlite.h, or prepares or executes a statement (.prepare(, .exec(, Statement,
#     Transaction).
# Comment lines are not read. Run by ctest: cmake -DSOURCE_DIR=... -P sql_owner.cmake
cmake_minimum_required(VERSION 3.25)
if(NOT DEFINED SOURCE_DIR)
  message(FATAL_ERROR "sql_owner.cmake: give -DSOURCE_DIR=<the source tree>")
endif()

set(sql_keyword "SELECT[ \n]|INSERT (OR [A-Z]+ )?INTO|REPLACE INTO|UPDATE [A-Za-z_]+ SET|DELETE FROM|CREATE (TEMP |UNIQUE )?(TABLE|INDEX|VIEW|TRIGGER)|DROP (TABLE|INDEX|VIEW|TRIGGER)|ALTER TABLE|PRAGMA [a-z_]+|BEGIN (IMMEDIATE|EXCLUSIVE|DEFERRED|TRANSACTION)|ATTACH DATABASE")
# A quote, then the statement's keyword with nothing but other text of the literal between.
set(sql_in_literal "\"([^\"]*[^A-Za-z_])?(${sql_keyword})")
set(sql_calls "#include \"runner/sqlite.h\"|db\\)?(\\.|->)(prepare|exec)\\(|(^|[^A-Za-z_])(Statement|Transaction)[ &(]")

set(violations "")
set(checked 0)
# Every top-level folder but runner/, tests/, hidden ones and build trees (a CMakeCache.txt).
file(GLOB folders LIST_DIRECTORIES true "${SOURCE_DIR}/*")
set(files "")
foreach(d ${folders})
  get_filename_component(name "${d}" NAME)
  if(NOT IS_DIRECTORY "${d}" OR name MATCHES "^(runner|tests|\\..*)$" OR EXISTS "${d}/CMakeCache.txt")
    continue()
  endif()
  file(GLOB_RECURSE found "${d}/*.h" "${d}/*.cpp" "${d}/*.hpp" "${d}/*.cc")
  list(APPEND files ${found})
endforeach()
foreach(f ${files})
  file(RELATIVE_PATH rel "${SOURCE_DIR}" "${f}")
  math(EXPR checked "${checked} + 1")
  # One list element per line: the text's own ';' and brackets (which CMake's lists read) are
  # swapped out first; no pattern below looks for them.
  file(READ "${f}" text)
  string(REPLACE ";" "<semicolon>" text "${text}")
  string(REPLACE "[" "<open>" text "${text}")
  string(REPLACE "]" "<close>" text "${text}")
  string(REPLACE "\n" ";" lines "${text}")
  set(n 0)
  foreach(line IN LISTS lines)
    math(EXPR n "${n} + 1")
    if(line MATCHES "^[ \t]*(//|/\\*|\\*)")
      continue()
    endif()
    if(line MATCHES "${sql_in_literal}")
      list(APPEND violations "${rel}:${n}: SQL outside runner/: ${CMAKE_MATCH_2}")
    elseif(line MATCHES "${sql_calls}")
      list(APPEND violations "${rel}:${n}: runs SQL outside runner/: ${CMAKE_MATCH_0}")
    endif()
  endforeach()
endforeach()

if(checked EQUAL 0)
  message(FATAL_ERROR "sql_owner: no source file found under ${SOURCE_DIR}")
endif()
list(LENGTH violations count)
if(count GREATER 0)
  list(JOIN violations "\n  " report)
  message(FATAL_ERROR "sql_owner: ${count} line(s) outside runner/ hold or run SQL "
                      "(read through runner/results_reader.h, write through runner/results_writer.h):\n  ${report}")
endif()
message(STATUS "sql_owner: ${checked} source files outside runner/ and tests/, none holds or runs SQL")
