/*
 * moving_sphere.h: shared by the p4est adaptation programs
 * (octmesh_p4est_adapt.c, p4est_adapt_cycle.c): ending a run, and the
 * moving sphere's cut test.
 *
 * The sphere has radius RADIUS (a quarter of the root) and its centre at
 * (x, ROOT_HALF, z) in lattice units (root side 2^19); it starts at
 * x = START_X.  A quadrant is cut when its closed box meets the sphere's
 * surface: the smallest squared distance from the centre to the box is at
 * most RADIUS^2 and the largest at least RADIUS^2, in exact integers.
 */
#ifndef OCTMESH_MOVING_SPHERE_H
#define OCTMESH_MOVING_SPHERE_H

#include <stdint.h>
#include <stdlib.h>

#include <mpi.h>
#include <p8est.h>

#define ROOT_HALF 262144
#define RADIUS 131072
#define START_X 157286

/* Finalizes libsc and MPI and exits with code. */
static void
finish (int code)
{
  sc_finalize ();
  MPI_Finalize ();
  exit (code);
}

/* Adds the smallest and largest squared distance from c to [lo, hi]. */
static void
axis_dist (int64_t c, int64_t lo, int64_t hi, int64_t * dmin, int64_t * dmax)
{
  int64_t             a = c < lo ? lo - c : (c > hi ? c - hi : 0);
  int64_t             b = c - lo > hi - c ? c - lo : hi - c;
  *dmin += a * a;
  *dmax += b * b;
}

/* Whether the closed box of q meets the surface of the sphere centred at
 * (x, ROOT_HALF, z). */
static int
sphere_cuts (const p8est_quadrant_t * q, int64_t x, int64_t z)
{
  int64_t             len = P8EST_QUADRANT_LEN (q->level);
  int64_t             dmin = 0, dmax = 0;
  const int64_t       r2 = (int64_t) RADIUS * RADIUS;

  axis_dist (x, q->x, q->x + len, &dmin, &dmax);
  axis_dist (ROOT_HALF, q->y, q->y + len, &dmin, &dmax);
  axis_dist (z, q->z, q->z + len, &dmin, &dmax);
  return dmin <= r2 && r2 <= dmax;
}

#endif
