# cmake -DCXX=<compiler> -DFLAGS=<;-list> -DSOURCE=<probe> -DCASE=<n> -DEXPECT=<;-list> -P tests/term_concept_expect.cmake
# Compiles the term-concept probe (tests/probes/term_concept_probe.cpp) with PROBE_CASE=CASE and
# fails unless the compiler refuses it AND its messages contain every string of EXPECT (each a
# member the concept names) and every error is one of smg's static_asserts, none a template error
# deep in the driver.
execute_process(COMMAND ${CXX} ${FLAGS} -DPROBE_CASE=${CASE} -fsyntax-only ${SOURCE}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
set(all "${out}${err}")
if(rc EQUAL 0)
  message(FATAL_ERROR "term concept probe case ${CASE} compiled; it must not")
endif()
foreach(e IN LISTS EXPECT)
  string(FIND "${all}" "smg term concept: ${e}" at)
  if(at EQUAL -1)
    message("${all}")
    message(FATAL_ERROR "term concept probe case ${CASE}: no static_assert naming '${e}'")
  endif()
endforeach()
string(REGEX MATCHALL "error: [^\n]*" errors "${all}")
foreach(e IN LISTS errors)
  if(NOT e MATCHES "smg term concept")
    message("${all}")
    message(FATAL_ERROR "term concept probe case ${CASE}: an error that is not the concept's: ${e}")
  endif()
endforeach()
message("term concept probe case ${CASE}: refused, naming ${EXPECT}")
