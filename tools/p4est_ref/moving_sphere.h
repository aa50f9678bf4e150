/*
 * moving_sphere.h: shared by the p4est adaptation programs
 * (octmesh_p4est_adapt.c, p4est_adapt_cycle.c): ending a run, and the
 * moving sphere's cut test (sphere_cut.h) on a quadrant.
 */
#ifndef OCTMESH_MOVING_SPHERE_H
#define OCTMESH_MOVING_SPHERE_H

#include <stdint.h>
#include <stdlib.h>

#include <mpi.h>
#include <p8est.h>

#include "sphere_cut.h"

/* Finalizes libsc and MPI and exits with code. */
static void
finish (int code)
{
  sc_finalize ();
  MPI_Finalize ();
  exit (code);
}

/* Whether the closed box of q meets the surface of the sphere centred at
 * (x, ROOT_HALF, z). */
static int
sphere_cuts (const p8est_quadrant_t * q, int64_t x, int64_t z)
{
  return sphere_cuts_cube (q->x, q->y, q->z, P8EST_QUADRANT_LEN (q->level),
                           x, z);
}

#endif
