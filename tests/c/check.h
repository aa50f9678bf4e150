/* Shared helpers of the C API tests: CHECK aborts the whole job with a
 * message naming the failed condition, the rank and the last error. */
#ifndef OCTMESH_TEST_CHECK_H
#define OCTMESH_TEST_CHECK_H

#include <stdint.h>
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

/* The moving sphere of the adaptation tests (tools/p4est_ref's
 * octmesh_p4est_adapt): whether the closed box of o meets the surface of
 * the sphere of radius 131072 centred at (157286 + 20972 step, 262144,
 * 262144), lattice units, in exact integers. */
static inline int check_sphere_cuts(const octmesh_octant_t *o, int step) {
  const int64_t c[3] = {157286 + (int64_t)20972 * step, 262144, 262144};
  const int64_t r2 = (int64_t)131072 * 131072;
  const int64_t len = (int64_t)1 << (19 - o->level);
  const int64_t lo[3] = {o->x, o->y, o->z};
  int64_t near = 0, far = 0;
  for (int k = 0; k < 3; k++) {
    int64_t hi = lo[k] + len;
    int64_t a = c[k] < lo[k] ? lo[k] - c[k] : (c[k] > hi ? c[k] - hi : 0);
    int64_t b = c[k] - lo[k] > hi - c[k] ? c[k] - lo[k] : hi - c[k];
    near += a * a;
    far += b * b;
  }
  return near <= r2 && r2 <= far;
}

#endif
