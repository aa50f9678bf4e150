/*
 * octmesh_p4est_adapt: the p4est reference for octmesh's adaptation
 * (src/adapt.rs, LinearOctree::partition_for_coarsening).  A sphere moves
 * through the unit cube; each step adapts the forest to its surface:
 *
 *   start: uniform forest at LEVEL (p8est_new_ext, equal split);
 *   for t = 1 .. STEPS:
 *     p8est_refine (non-recursive): leaves below MAX_LEVEL cut by S(t);
 *     p8est_coarsen (non-recursive, or recursive with --recursive):
 *       families none of whose leaves is cut;
 *     p8est_balance (corner);
 *     p8est_partition_ext (partition_for_coarsening = 1, no weights, or
 *       with --weighted the leaf's level as its weight);
 *
 * "Cut" means the closed box meets the sphere's surface: the smallest
 * distance from the centre to the box is at most the radius and the largest
 * at least the radius, in exact integer arithmetic on lattice units (root
 * side 2^19).  S(t): centre (157286 + 20972 t, 262144, 262144), radius
 * 131072, i.e. about (0.3 + 0.04 t, 0.5, 0.5) and 0.25 of the root.
 *
 * Usage: mpirun -np P octmesh_p4est_adapt --steps S --level L
 *          --max-level M --out DIR [--weighted] [--recursive]
 *
 * Writes DIR/step_T.bin for T = 0 .. S (leaf files as in octmesh_p4est.c:
 * "OCTLEAF1", u64 LE count, count * 4 LE int32 x, y, z, level) and
 * DIR/counts.txt, one line per step: "T refined coarsened leaves n_0 ...
 * n_{P-1}" (leaves refined, families coarsened, leaves after the step,
 * leaves of each rank after the partition).
 */

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mpi.h>
#include <p8est.h>
#include <p8est_bits.h>
#include <p8est_extended.h>

#include "leaf_file.h"
#include "moving_sphere.h"


static int          g_rank, g_size;
static int          g_step, g_max_level;

static void
usage_error (const char *msg)
{
  if (g_rank == 0)
    fprintf (stderr, "octmesh_p4est_adapt: %s\nusage: octmesh_p4est_adapt"
             " --steps S --level L --max-level M --out DIR [--weighted]"
             " [--recursive]\n",
             msg);
  finish (1);
}

static int
is_cut (const p8est_quadrant_t * q)
{
  return sphere_cuts (q, START_X + (int64_t) STEP_X * g_step, ROOT_HALF);
}

static int
refine_fn (p8est_t * p8est, p4est_topidx_t which_tree, p8est_quadrant_t * q)
{
  (void) p8est;
  (void) which_tree;
  return q->level < g_max_level && is_cut (q);
}

static int
level_weight (p8est_t * p8est, p4est_topidx_t which_tree,
              p8est_quadrant_t * q)
{
  (void) p8est;
  (void) which_tree;
  return q->level;
}

static int
coarsen_fn (p8est_t * p8est, p4est_topidx_t which_tree,
            p8est_quadrant_t * q[])
{
  int                 i;
  (void) p8est;
  (void) which_tree;
  for (i = 0; i < P8EST_CHILDREN; ++i)
    if (is_cut (q[i]))
      return 0;
  return 1;
}

/* Ranks append their leaves in rank order: the global Morton order. */
static void
write_leaves (MPI_Comm comm, p8est_t * p8est, const char *path)
{
  if (leaf_file_write (comm, p8est, path, NULL)) {
    if (g_rank == 0)
      fprintf (stderr, "octmesh_p4est_adapt: failed writing %s\n", path);
    finish (1);
  }
}

static void
write_counts (FILE * f, p8est_t * p8est, int step, long long refined,
              long long coarsened)
{
  int                 r;
  if (f == NULL)
    return;
  fprintf (f, "%d %lld %lld %lld", step, refined, coarsened,
           (long long) p8est->global_num_quadrants);
  for (r = 0; r < g_size; ++r)
    fprintf (f, " %lld", (long long) (p8est->global_first_quadrant[r + 1] -
                                      p8est->global_first_quadrant[r]));
  fprintf (f, "\n");
}

static long
int_arg (const char *s, long lo, long hi, const char *what)
{
  char               *end;
  long                v = strtol (s, &end, 10);
  if (*end != '\0' || end == s || v < lo || v > hi)
    usage_error (what);
  return v;
}

int
main (int argc, char **argv)
{
  MPI_Comm            comm = MPI_COMM_WORLD;
  const char         *dir = NULL;
  int                 steps = -1, level = -1, weighted = 0, recursive = 0;
  int                 i, bad;
  char                path[4096];
  FILE               *counts = NULL;
  p8est_connectivity_t *conn;
  p8est_t            *p8est;

  MPI_Init (&argc, &argv);
  MPI_Comm_rank (comm, &g_rank);
  MPI_Comm_size (comm, &g_size);
  sc_init (comm, 1, 1, NULL, SC_LP_ESSENTIAL);
  p4est_init (NULL, SC_LP_ESSENTIAL);
  g_max_level = -1;

  for (i = 1; i < argc; ++i) {
    const char         *a = argv[i];
    if (!strcmp (a, "--weighted")) {
      weighted = 1;
      continue;
    }
    if (!strcmp (a, "--recursive")) {
      recursive = 1;
      continue;
    }
    if (i + 1 >= argc)
      usage_error ("every option takes a value");
    if (!strcmp (a, "--steps"))
      steps = (int) int_arg (argv[++i], 0, 100000, "--steps: 0 to 100000");
    else if (!strcmp (a, "--level"))
      level = (int) int_arg (argv[++i], 0, P8EST_QMAXLEVEL, "--level: 0-18");
    else if (!strcmp (a, "--max-level"))
      g_max_level = (int) int_arg (argv[++i], 0, P8EST_QMAXLEVEL,
                                   "--max-level: 0-18");
    else if (!strcmp (a, "--out"))
      dir = argv[++i];
    else
      usage_error ("unknown option");
  }
  if (steps < 0 || level < 0 || g_max_level < 0 || dir == NULL)
    usage_error ("--steps, --level, --max-level and --out are required");

  if (g_rank == 0) {
    snprintf (path, sizeof path, "%s/counts.txt", dir);
    counts = fopen (path, "w");
  }
  bad = g_rank == 0 && counts == NULL;
  MPI_Bcast (&bad, 1, MPI_INT, 0, comm);
  if (bad)
    usage_error ("cannot write DIR/counts.txt");

  conn = p8est_connectivity_new_unitcube ();
  p8est = p8est_new_ext (comm, conn, 0, level, 1, 0, NULL, NULL);
  snprintf (path, sizeof path, "%s/step_0.bin", dir);
  write_leaves (comm, p8est, path);
  write_counts (counts, p8est, 0, 0, 0);
  for (g_step = 1; g_step <= steps; ++g_step) {
    p4est_gloidx_t      n0 = p8est->global_num_quadrants, n1, n2;
    p8est_refine (p8est, 0, refine_fn, NULL);
    n1 = p8est->global_num_quadrants;
    p8est_coarsen (p8est, recursive, coarsen_fn, NULL);
    n2 = p8est->global_num_quadrants;
    p8est_balance (p8est, P8EST_CONNECT_FULL, NULL);
    p8est_partition_ext (p8est, 1, weighted ? level_weight : NULL);
    snprintf (path, sizeof path, "%s/step_%d.bin", dir, g_step);
    write_leaves (comm, p8est, path);
    write_counts (counts, p8est, g_step, (long long) (n1 - n0) / 7,
                  (long long) (n1 - n2) / 7);
  }
  if (counts != NULL)
    fclose (counts);
  p8est_destroy (p8est);
  p8est_connectivity_destroy (conn);
  finish (0);
  return 0;
}
