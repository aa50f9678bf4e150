/* Shared helpers of the C API tests: CHECK aborts the whole job with a
 * message naming the failed condition, the rank and the last error. */
#ifndef OCTMESH_TEST_CHECK_H
#define OCTMESH_TEST_CHECK_H

#include <stdio.h>
#include <string.h>
#include <mpi.h>
#include "octmesh.h"

#define CHECK(cond, h)                                                            \
  do {                                                                            \
    if (!(cond)) {                                                                \
      int r_ = -1;                                                                \
      MPI_Comm_rank(MPI_COMM_WORLD, &r_);                                         \
      fprintf(stderr, "CHECK FAILED rank %d %s:%d: %s (last error: %s)\n", r_,    \
              __FILE__, __LINE__, #cond, octmesh_last_error(h));                  \
      fflush(stderr);                                                             \
      MPI_Abort(MPI_COMM_WORLD, 3);                                               \
    }                                                                             \
  } while (0)

#define CHECK_STATUS(call, expected, h)                                           \
  do {                                                                            \
    octmesh_status_t s_ = (call);                                                 \
    if (s_ != (expected)) {                                                       \
      int r_ = -1;                                                                \
      MPI_Comm_rank(MPI_COMM_WORLD, &r_);                                         \
      fprintf(stderr, "CHECK FAILED rank %d %s:%d: %s returned %s, expected %s "  \
              "(last error: %s)\n", r_, __FILE__, __LINE__, #call,                \
              octmesh_status_name(s_), octmesh_status_name(expected),             \
              octmesh_last_error(h));                                             \
      fflush(stderr);                                                             \
      MPI_Abort(MPI_COMM_WORLD, 3);                                               \
    }                                                                             \
  } while (0)

#define OK(call, h) CHECK_STATUS(call, OCTMESH_STATUS_OK, h)

#endif
