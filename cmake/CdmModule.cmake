# cdm_module(NAME
#            SOURCES     files...              (relative to the module's folder)
#            PUBLIC_HEADERS headers...         (what other modules may include)
#            DEPS        modules...            (cdm modules this one is built on)
#            LIBS        targets...            (third-party libraries, PUBLIC if
#                                              its public headers need them)
#            PRIVATE_LIBS targets...)
#
# The layering the build enforces. No include path points at src/: each
# module sees
#   - its own folder, through layers/private/NAME/NAME -> src/NAME, and
#   - the PUBLIC_HEADERS of the modules it depends on (directly or through
#     another module's public interface), through layers/public/DEP/DEP/,
#     which holds links to those headers and nothing else.
# So `#include "calib/fit/fit.h"` in src/device fails to compile (device does
# not depend on calib), and so does `#include "model/model_impl.h"` in
# src/calib (not a public header of model).
#
# A module in a folder of a folder of src/ is named by its path: `calib/fit` is the
# target cdm_calib_fit, its headers are included as "calib/fit/x.h", and
# other modules name it so in DEPS. Its layer folders are
# layers/{public,private}/calib_fit, holding calib/fit/. The sub-modules of
# a folder are layers like any other: calib/search sees calib/evaluation's
# public headers only if it depends on it.
#
# tests/layering checks both ways of cheating that the compiler cannot see
# ("../" includes across modules) and that a reach into another module's
# private header does fail to build.
set(CDM_LAYERS_DIR ${CMAKE_BINARY_DIR}/layers)

function(cdm_module name)
  cmake_parse_arguments(M "" "" "SOURCES;PUBLIC_HEADERS;DEPS;LIBS;PRIVATE_LIBS" ${ARGN})
  string(REPLACE "/" "_" id ${name})
  set(pub ${CDM_LAYERS_DIR}/public/${id})
  set(priv ${CDM_LAYERS_DIR}/private/${id})
  file(REMOVE_RECURSE ${pub} ${priv})
  get_filename_component(priv_parent ${priv}/${name} DIRECTORY)
  file(MAKE_DIRECTORY ${pub}/${name} ${priv_parent})
  foreach(h IN LISTS M_PUBLIC_HEADERS)
    if(NOT EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/${h})
      message(FATAL_ERROR "cdm_module(${name}): public header ${h} does not exist")
    endif()
    get_filename_component(d ${pub}/${name}/${h} DIRECTORY)
    file(MAKE_DIRECTORY ${d})
    file(CREATE_LINK ${CMAKE_CURRENT_SOURCE_DIR}/${h} ${pub}/${name}/${h} SYMBOLIC)
  endforeach()
  file(CREATE_LINK ${CMAKE_CURRENT_SOURCE_DIR} ${priv}/${name} SYMBOLIC)

  add_library(cdm_${id} STATIC ${M_SOURCES})
  # Own folder first, so a module's sources always resolve its own headers
  # there; the public headers of its dependencies arrive through DEPS.
  target_include_directories(cdm_${id} BEFORE PRIVATE ${priv})
  target_include_directories(cdm_${id} PUBLIC
    $<BUILD_INTERFACE:${pub}> $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/include>)
  set(deps)
  foreach(d IN LISTS M_DEPS)
    string(REPLACE "/" "_" d ${d})
    list(APPEND deps cdm_${d})
  endforeach()
  target_link_libraries(cdm_${id} PUBLIC ${deps} ${M_LIBS} PRIVATE ${M_PRIVATE_LIBS})
  target_compile_definitions(cdm_${id} PUBLIC CDM_EXPERIMENTAL PRIVATE CDM_BUILDING_LIBRARY)
  target_compile_options(cdm_${id} PRIVATE ${CDM_WARNINGS})
  set_target_properties(cdm_${id} PROPERTIES C_VISIBILITY_PRESET hidden CXX_VISIBILITY_PRESET hidden
                        VISIBILITY_INLINES_HIDDEN ON)
  set_property(GLOBAL APPEND PROPERTY CDM_MODULES ${id})
endfunction()

# White-box tests, benchmarks and fuzzers see a module's private headers too.
function(cdm_see_inside target)
  foreach(m IN LISTS ARGN)
    string(REPLACE "/" "_" m ${m})
    target_link_libraries(${target} PRIVATE cdm_${m})
    target_include_directories(${target} BEFORE PRIVATE ${CMAKE_BINARY_DIR}/layers/private/${m}) # (CDM_LAYERS_DIR: src/'s scope only)
  endforeach()
endfunction()
