# Runs the Poisson example on the snapped solid sphere (`poisson --snap`,
# isoparametric elements) at each of LEVELS on each count of ranks in NPS,
# and checks that the max nodal error falls at least RATIO times per level
# (second order: about 4), and that every count of ranks gives the same
# error at each level (to 1e-6 relative; the solver stops at 1e-12).
# -DMPIRUN=... -DEXE=poisson -DNPS="1;2" -DLEVELS="4;5;6" -DRATIO=3
foreach(np ${NPS})
  set(_prev "")
  foreach(level ${LEVELS})
    execute_process(COMMAND ${MPIRUN} -np ${np} "${EXE}" --snap ${level}
      RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
    message("${out}")
    if(NOT rc EQUAL 0)
      message(FATAL_ERROR "poisson --snap ${level} on ${np} ranks failed (${rc}):\n${err}")
    endif()
    if(NOT out MATCHES "mode=snap [^\n]*max_error=([0-9.eE+-]+)")
      message(FATAL_ERROR "no snapped max_error in the output:\n${out}")
    endif()
    set(e "${CMAKE_MATCH_1}")
    # Compare as numbers: CMake has no floats, so let awk do it.
    if(_prev)
      execute_process(COMMAND awk "BEGIN { exit !(${_prev} >= ${RATIO} * ${e}) }"
        RESULT_VARIABLE falls)
      if(NOT falls EQUAL 0)
        message(FATAL_ERROR "snapped error falls less than ${RATIO} times: ${_prev} at the "
                            "previous level, ${e} at level ${level} (${np} ranks)")
      endif()
      message("snapped error falls: ${_prev} -> ${e} (${np} ranks)")
    endif()
    set(_prev "${e}")
    if(DEFINED _first_${level})
      set(f "${_first_${level}}")
      execute_process(COMMAND awk "BEGIN { d = ${e} - ${f}; if (d < 0) d = -d; exit !(d <= 1e-6 * ${f}) }"
        RESULT_VARIABLE same)
      if(NOT same EQUAL 0)
        message(FATAL_ERROR "level ${level}: error ${e} on ${np} ranks, ${f} on the first count")
      endif()
    else()
      set(_first_${level} "${e}")
    endif()
  endforeach()
endforeach()
