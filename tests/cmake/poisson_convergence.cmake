# Runs the Poisson example at each of LEVELS on NP ranks and checks that the
# max nodal error falls with the level.
# -DMPIRUN=... -DNP=n -DEXE=poisson -DSTL=file -DLEVELS="L;L+1" -DOUT=file.pvtu
set(_prev "")
foreach(level ${LEVELS})
  execute_process(COMMAND ${MPIRUN} -np ${NP} "${EXE}" ${level} "${STL}" "${OUT}"
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  message("${out}")
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "poisson level ${level} on ${NP} ranks failed (${rc}):\n${err}")
  endif()
  if(NOT out MATCHES "max_error=([0-9.eE+-]+)")
    message(FATAL_ERROR "no max_error in the output:\n${out}")
  endif()
  set(e "${CMAKE_MATCH_1}")
  # Compare as numbers: CMake has no floats, so let the shell do it.
  if(_prev)
    execute_process(COMMAND awk "BEGIN { exit !(${e} < ${_prev}) }" RESULT_VARIABLE falls)
    if(NOT falls EQUAL 0)
      message(FATAL_ERROR "error does not fall: ${_prev} at the previous level, ${e} at level ${level}")
    endif()
    message("error falls: ${_prev} -> ${e}")
  endif()
  set(_prev "${e}")
endforeach()
