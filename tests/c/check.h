/* Shared helpers of the C API tests: CHECK aborts the whole job with a
 * message naming the failed condition, the rank and the last error. */
#ifndef OCTMESH_TEST_CHECK_H
#define OCTMESH_TEST_CHECK_H

#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <mpi.h>
#include "octmesh.h"
#include "sphere_cut.h"

/* The library reads every enumeration passed to it as an int32_t (so that a
 * value outside it is an error, src/ffi/mod.rs) and gives back bools as
 * C's _Bool: the sizes this relies on, checked wherever a test compiles. */
#define OCTMESH_SAME_SIZE(t, u) _Static_assert(sizeof(t) == sizeof(u), #t " is not " #u "-sized")
OCTMESH_SAME_SIZE(octmesh_status_t, int32_t);
OCTMESH_SAME_SIZE(octmesh_connect_t, int32_t);
OCTMESH_SAME_SIZE(octmesh_keep_t, int32_t);
OCTMESH_SAME_SIZE(octmesh_cut_rule_t, int32_t);
OCTMESH_SAME_SIZE(octmesh_inside_rule_t, int32_t);
OCTMESH_SAME_SIZE(octmesh_class_t, int32_t);
OCTMESH_SAME_SIZE(octmesh_foam_format_t, int32_t);
OCTMESH_SAME_SIZE(bool, uint8_t);

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
 * octmesh_p4est_adapt, sphere_cut.h): whether the closed box of o meets
 * its surface at step `step`, in exact integers. */
static inline int check_sphere_cuts(const octmesh_octant_t *o, int step) {
  return sphere_cuts_cube(o->x, o->y, o->z, (int64_t)1 << (19 - o->level),
                          START_X + (int64_t)STEP_X * step, ROOT_HALF);
}

/* The built-in sphere refined at `level`, partitioned, balanced (corner)
 * and partitioned again: the octree the mesh tests start from. */
static inline void check_balanced_sphere(octmesh_t *h, int level) {
  OK(octmesh_surface_builtin(h, "sphere"), h);
  OK(octmesh_octree_refine_surface(h, level), h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);
  OK(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);
}

#endif
