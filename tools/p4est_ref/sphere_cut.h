/*
 * sphere_cut.h: the moving sphere of the adaptation tests and benchmarks,
 * without p4est, so that the p4est programs (through moving_sphere.h), the
 * C API tests (tests/c/check.h) and the octmesh side of the adaptive-cycle
 * benchmark (tools/bench/adapt_cycle_octmesh.c) apply the same test.
 *
 * The sphere has radius RADIUS (a quarter of the root) and its centre at
 * (x, ROOT_HALF, z) in lattice units (root side 2^19); the oracle starts
 * it at x = START_X and moves it STEP_X a step.  A box is cut when its
 * closed box meets the sphere's surface: the smallest squared distance from
 * the centre to the box is at most RADIUS^2 and the largest at least
 * RADIUS^2, in exact integers.
 */
#ifndef OCTMESH_SPHERE_CUT_H
#define OCTMESH_SPHERE_CUT_H

#include <stdint.h>

#define ROOT_HALF 262144
#define RADIUS 131072
#define START_X 157286
#define STEP_X 20972

/* Whether the closed cube with lowest corner (x, y, z) and side len meets
 * the surface of the sphere centred at (cx, ROOT_HALF, cz). */
static inline int
sphere_cuts_cube (int64_t x, int64_t y, int64_t z, int64_t len, int64_t cx,
                  int64_t cz)
{
  const int64_t       c[3] = { cx, ROOT_HALF, cz }, lo[3] = { x, y, z };
  const int64_t       r2 = (int64_t) RADIUS * RADIUS;
  int64_t             near = 0, far = 0;
  int                 k;
  for (k = 0; k < 3; k++) {
    const int64_t       hi = lo[k] + len;
    const int64_t       a =
      c[k] < lo[k] ? lo[k] - c[k] : (c[k] > hi ? c[k] - hi : 0);
    const int64_t       b = c[k] - lo[k] > hi - c[k] ? c[k] - lo[k] : hi - c[k];
    near += a * a;
    far += b * b;
  }
  return near <= r2 && r2 <= far;
}

#endif
