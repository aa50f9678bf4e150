# Runs the adapt_front example on 1, 2 and 4 ranks: each run must succeed
# (it exits non-zero itself when the integral drifts by more than 1e-12 or
# the leaf data falls out of step with the leaves) and print its final
# ADAPT_FRONT line, and the leaf count and integral must be identical on
# every count of ranks: the adaptation, balance and data transfer do not
# depend on the partition, and the example sums the integral in global
# Morton order, so the digits printed must agree exactly.
# -DMPIRUN=... -DEXE=adapt_front
set(_first "")
foreach(np 1 2 4)
  execute_process(COMMAND ${MPIRUN} -np ${np} "${EXE}"
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT out MATCHES "ADAPT_FRONT steps ([0-9]+) leaves ([0-9]+) integral ([^ \n]+) relative_change ([^ \n]+)")
    message(FATAL_ERROR "no ADAPT_FRONT line on ${np} ranks (exit ${rc}):\n${out}\n${err}")
  endif()
  set(line "${CMAKE_MATCH_0}")
  set(result "steps ${CMAKE_MATCH_1} leaves ${CMAKE_MATCH_2} integral ${CMAKE_MATCH_3}")
  message("${np} ranks: ${line}")
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "adapt_front on ${np} ranks failed (${rc}):\n${err}")
  endif()
  if(NOT CMAKE_MATCH_2 GREATER 512)
    message(FATAL_ERROR "adapt_front on ${np} ranks: the front refined nothing (${line})")
  endif()
  if(_first STREQUAL "")
    set(_first "${result}")
  elseif(NOT result STREQUAL _first)
    message(FATAL_ERROR "adapt_front: '${result}' on ${np} ranks, '${_first}' on 1")
  endif()
endforeach()
