# cmake -DPROGRAM=<exe> -DEXPECT=<regex> -P tests/run_expect.cmake
# Runs PROGRAM and fails unless it exits 0 AND its standard output matches EXPECT (a ctest
# PASS_REGULAR_EXPRESSION alone would ignore the exit code). Used for the quick-start programs.
execute_process(COMMAND "${PROGRAM}" RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
message("${out}${err}")
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${PROGRAM} exited with ${rc}")
endif()
if(NOT out MATCHES "${EXPECT}")
  message(FATAL_ERROR "${PROGRAM}: output does not match '${EXPECT}'")
endif()
