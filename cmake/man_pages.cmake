# Man pages of `cdm` and every subcommand, by help2man from the command's own
# --help (CLI11's), so they say what the program does. Run at build time:
#   cmake -DCDM_EXE=... -DHELP2MAN=... -DGZIP=... -DVERSION=... -DOUT_DIR=... -P man_pages.cmake
# The tree of subcommands is walked from each help's "Subcommands:" list, so
# a new subcommand gets its page (cdm-calib-diagnose.1 for `cdm calib
# diagnose`). Each page is gzipped (-9n: no name or time stamp in the gzip
# header; the page's date is help2man's, SOURCE_DATE_EPOCH if set), as
# Debian installs man pages. help2man runs the program through /bin/sh: the
# caller passes a build path of plain characters only (CMakeLists.txt).
file(REMOVE_RECURSE "${OUT_DIR}")
file(MAKE_DIRECTORY "${OUT_DIR}")

# `cdm WORDS --help`, its subcommands and their one-line descriptions.
function(cdm_subcommands words out_names out_descs)
  execute_process(COMMAND "${CDM_EXE}" ${words} --help OUTPUT_VARIABLE help RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "man pages: cdm ${words} --help failed (${rc})")
  endif()
  string(REPLACE ";" "," help "${help}")
  string(REPLACE "\n" ";" lines "${help}")
  set(names "")
  set(descs "")
  set(in_subs FALSE)
  foreach(line IN LISTS lines)
    if(line STREQUAL "Subcommands:")
      set(in_subs TRUE)
    elseif(in_subs AND line MATCHES "^  ([a-z][a-z0-9-]*) +(.*)$")
      list(APPEND names "${CMAKE_MATCH_1}")
      list(APPEND descs "${CMAKE_MATCH_2}")
    elseif(in_subs AND NOT line MATCHES "^ ")
      set(in_subs FALSE)
    endif()
  endforeach()
  set(${out_names} "${names}" PARENT_SCOPE)
  set(${out_descs} "${descs}" PARENT_SCOPE)
endfunction()

function(cdm_man_page words page name)
  string(REPLACE ";" " " help_option "${words}")
  string(STRIP "${help_option} --help" help_option)
  # help2man names the page after the program it runs: a link named after
  # the page, to the one program.
  file(MAKE_DIRECTORY "${OUT_DIR}/bin")
  file(CREATE_LINK "${CDM_EXE}" "${OUT_DIR}/bin/${page}" SYMBOLIC)
  execute_process(
    COMMAND "${HELP2MAN}" --no-info --no-discard-stderr "--version-string=${VERSION}" "--name=${name}"
            "--help-option=${help_option}" "--source=cdm ${VERSION}" "--section=1" -o "${OUT_DIR}/${page}.1"
            "${OUT_DIR}/bin/${page}"
    RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "man pages: help2man for ${page} failed (${rc})")
  endif()
  execute_process(COMMAND "${GZIP}" -9nf "${OUT_DIR}/${page}.1" RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "man pages: gzip ${page}.1 failed (${rc})")
  endif()
endfunction()

function(cdm_man_tree words page name)
  cdm_man_page("${words}" "${page}" "${name}")
  cdm_subcommands("${words}" names descs)
  list(LENGTH names n)
  if(n EQUAL 0)
    return()
  endif()
  math(EXPR last "${n} - 1")
  foreach(i RANGE ${last})
    list(GET names ${i} sub)
    list(GET descs ${i} desc)
    set(sub_words ${words} ${sub})
    cdm_man_tree("${sub_words}" "${page}-${sub}" "${desc}")
  endforeach()
endfunction()

cdm_man_tree("" "cdm" "driver and model-debugging toolkit of a cable-driven haptic master")
file(REMOVE_RECURSE "${OUT_DIR}/bin")
