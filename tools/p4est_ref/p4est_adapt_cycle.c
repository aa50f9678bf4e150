/*
 * p4est_adapt_cycle: p4est's side of the adaptive-cycle benchmark (issue 23;
 * octmesh's side is tools/bench/adapt_cycle_octmesh.c, the driver
 * tools/bench/adapt_cycle.py).
 *
 * The moving sphere of octmesh_p4est_adapt.c (same exact cut test, same
 * S(t)), with 16 bytes of user data per quadrant: a double (a smooth
 * function of the centre at the start) and the level, int32, plus padding.
 *
 *   warm-up (not timed): uniform forest at LEVEL (p8est_new_ext, data
 *     size 16, init_fn), then for t = 1 .. WARMUP one step of the oracle's
 *     loop: p8est_refine_ext (non-recursive, up to MAX_LEVEL) and
 *     p8est_coarsen_ext (non-recursive) with replace_fn (copy on refine,
 *     mean on coarsen), p8est_balance_ext (corner, replace_fn: copy),
 *     p8est_partition_ext (partition_for_coarsening = 1);
 *   the timed cycle, step t = WARMUP + 1, each phase between barriers:
 *     refine     p8est_refine_ext   (replace_fn)
 *     coarsen    p8est_coarsen_ext  (replace_fn)
 *     balance    p8est_balance_ext  (corner, replace_fn)
 *     partition  p8est_partition_ext (1, NULL): the data moves with it
 *     ghost      p8est_ghost_new    (corner)
 *     lnodes     p8est_lnodes_new   (degree 1)
 *
 * Memory: the RSS before the cycle (VmRSS), the peak of the warm-up (VmHWM
 * before the cycle), and the peak during the cycle (VmHWM after resetting
 * it through /proc/self/clear_refs just before the cycle; if the reset
 * fails, getrusage's ru_maxrss, the peak of the whole run, and
 * "hwm_reset": 0), and VmHWM after each phase (where the peak is reached);
 * each the maximum over ranks, in bytes per rank.
 *
 * Rank 0 prints one line "RESULT {json}" with the phase times (seconds,
 * maximum over ranks), the leaf counts before and after the cycle, the
 * leaves refined and families coarsened (before balance), the leaves per
 * rank before and after the partition, lnodes' global node count, the
 * integral of the data (sum of volume * value, a check that the data went
 * through the cycle) and the memory figures.
 *
 * --dx DX: the centre's step along x in lattice units (default the
 * oracle's 20972); --z Z: the centre's z (default 262144, the middle, as
 * in the oracle).
 *
 * Usage: mpirun -np P p4est_adapt_cycle --level L --max-level M
 *          --warmup W [--dx DX] [--z Z]
 */

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>

#include <mpi.h>
#include <p8est.h>
#include <p8est_bits.h>
#include <p8est_extended.h>
#include <p8est_ghost.h>
#include <p8est_lnodes.h>

#include "moving_sphere.h"

#define ROOT_LEN 524288.0

typedef struct {
  double              value;
  int32_t             level;
  int32_t             spare;
} datum_t;

enum { REFINE, COARSEN, BALANCE, PARTITION, GHOST, LNODES, NPHASES };
static const char  *phase_names[NPHASES] = {
  "refine", "coarsen", "balance", "partition", "ghost", "lnodes"
};

static int          g_rank, g_size;
static int          g_step, g_max_level;
static int64_t      g_dx = STEP_X, g_z = ROOT_HALF;

static void
usage_error (const char *msg)
{
  if (g_rank == 0)
    fprintf (stderr, "p4est_adapt_cycle: %s\nusage: p4est_adapt_cycle"
             " --level L --max-level M --warmup W [--dx DX] [--z Z]\n", msg);
  finish (1);
}

/* The oracle's cut test, with the centre's step and height of this run. */
static int
is_cut (const p8est_quadrant_t * q)
{
  return sphere_cuts (q, START_X + g_dx * g_step, g_z);
}

static int
refine_fn (p8est_t * p8est, p4est_topidx_t which_tree, p8est_quadrant_t * q)
{
  (void) p8est;
  (void) which_tree;
  return q->level < g_max_level && is_cut (q);
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

/* The initial value: a smooth function of the quadrant's centre. */
static void
init_fn (p8est_t * p8est, p4est_topidx_t which_tree, p8est_quadrant_t * q)
{
  datum_t            *d = (datum_t *) q->p.user_data;
  const double        h = P8EST_QUADRANT_LEN (q->level) / 2.0;
  const double        x = (q->x + h) / ROOT_LEN, y = (q->y + h) / ROOT_LEN,
    z = (q->z + h) / ROOT_LEN;
  (void) p8est;
  (void) which_tree;
  d->value = x * x + y + 0.5 * z;
  d->level = q->level;
  d->spare = 0;
}

/* Refinement and balance splits (1 -> 8, p4est's balance splits one level
 * at a time) copy the value; coarsening (8 -> 1) takes the mean. */
static void
replace_fn (p8est_t * p8est, p4est_topidx_t which_tree, int num_outgoing,
            p8est_quadrant_t * outgoing[], int num_incoming,
            p8est_quadrant_t * incoming[])
{
  int                 i;
  (void) p8est;
  (void) which_tree;
  if (num_outgoing == 1) {
    const datum_t      *o = (const datum_t *) outgoing[0]->p.user_data;
    for (i = 0; i < num_incoming; ++i) {
      datum_t            *d = (datum_t *) incoming[i]->p.user_data;
      d->value = o->value;
      d->level = incoming[i]->level;
      d->spare = 0;
    }
  }
  else {
    datum_t            *d = (datum_t *) incoming[0]->p.user_data;
    double              s = 0;
    for (i = 0; i < num_outgoing; ++i)
      s += ((const datum_t *) outgoing[i]->p.user_data)->value;
    d->value = s / num_outgoing;
    d->level = incoming[0]->level;
    d->spare = 0;
  }
}

/* One step of the oracle's loop, with the data (warm-up only). */
static void
step (p8est_t * p8est)
{
  p8est_refine_ext (p8est, 0, g_max_level, refine_fn, NULL, replace_fn);
  p8est_coarsen_ext (p8est, 0, 0, coarsen_fn, NULL, replace_fn);
  p8est_balance_ext (p8est, P8EST_CONNECT_FULL, NULL, replace_fn);
  p8est_partition_ext (p8est, 1, NULL);
}

/* VmRSS or VmHWM from /proc/self/status in bytes (0 if unreadable). */
static long long
status_bytes (const char *key)
{
  char                line[256];
  long long           v = 0;
  size_t              n = strlen (key);
  FILE               *f = fopen ("/proc/self/status", "r");
  if (f == NULL)
    return 0;
  while (fgets (line, sizeof line, f) != NULL)
    if (!strncmp (line, key, n) && line[n] == ':') {
      v = atoll (line + n + 1);
      break;
    }
  fclose (f);
  return v * 1024;
}

/* Resets VmHWM to the current RSS (Linux >= 4.0); 1 on success. */
static int
reset_peak (void)
{
  FILE               *f = fopen ("/proc/self/clear_refs", "w");
  int                 ok;
  if (f == NULL)
    return 0;
  ok = fputs ("5", f) >= 0;
  ok &= fclose (f) == 0;
  return ok;
}

static long long
maxrss_bytes (void)
{
  struct rusage       ru;
  getrusage (RUSAGE_SELF, &ru);
  return (long long) ru.ru_maxrss * 1024;
}

static double
integral (p8est_t * p8est)
{
  sc_array_t         *qs = &p8est_tree_array_index (p8est->trees, 0)->quadrants;
  double              s = 0, all;
  size_t              i;
  for (i = 0; i < qs->elem_count; ++i) {
    const p8est_quadrant_t *q = p8est_quadrant_array_index (qs, i);
    const double        h = P8EST_QUADRANT_LEN (q->level) / ROOT_LEN;
    s += h * h * h * ((const datum_t *) q->p.user_data)->value;
  }
  MPI_Allreduce (&s, &all, 1, MPI_DOUBLE, MPI_SUM, p8est->mpicomm);
  return all;
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
  int                 level = -1, warmup = -1, i, r, hwm_reset, all_reset;
  double              t[NPHASES], tmax[NPHASES], t0, total = 0;
  long long           mem[3], memmax[3], hwm[NPHASES], hwmmax[NPHASES];
  long long           lnodes_owned, lnodes_global, ghosts, ghosts_all;
  p4est_gloidx_t      before, refined, coarsened;
  long long           balanced_local, *balanced = NULL;
  p8est_connectivity_t *conn;
  p8est_t            *p8est;
  p8est_ghost_t      *ghost;
  p8est_lnodes_t     *lnodes;

  MPI_Init (&argc, &argv);
  MPI_Comm_rank (comm, &g_rank);
  MPI_Comm_size (comm, &g_size);
  sc_init (comm, 1, 1, NULL, SC_LP_ESSENTIAL);
  p4est_init (NULL, SC_LP_ESSENTIAL);
  g_max_level = -1;

  for (i = 1; i < argc; ++i) {
    const char         *a = argv[i];
    if (i + 1 >= argc)
      usage_error ("every option takes a value");
    if (!strcmp (a, "--level"))
      level = (int) int_arg (argv[++i], 0, P8EST_QMAXLEVEL, "--level: 0-18");
    else if (!strcmp (a, "--max-level"))
      g_max_level = (int) int_arg (argv[++i], 0, P8EST_QMAXLEVEL,
                                   "--max-level: 0-18");
    else if (!strcmp (a, "--dx"))
      g_dx = int_arg (argv[++i], 0, 262144, "--dx: 0 to 262144");
    else if (!strcmp (a, "--z"))
      g_z = int_arg (argv[++i], RADIUS, 524288 - RADIUS,
                     "--z: 131072 to 393216");
    else if (!strcmp (a, "--warmup"))
      warmup = (int) int_arg (argv[++i], 0, 100000, "--warmup: 0-100000");
    else
      usage_error ("unknown option");
  }
  if (level < 0 || g_max_level < 0 || warmup < 0)
    usage_error ("--level, --max-level and --warmup are required");

  /* Warm-up, not timed. */
  conn = p8est_connectivity_new_unitcube ();
  p8est = p8est_new_ext (comm, conn, 0, level, 1, sizeof (datum_t), init_fn,
                         NULL);
  for (g_step = 1; g_step <= warmup; ++g_step)
    step (p8est);
  before = p8est->global_num_quadrants;

  /* The cycle. */
  mem[0] = status_bytes ("VmRSS");
  mem[2] = status_bytes ("VmHWM");
  hwm_reset = reset_peak ();
  for (i = 0; i < NPHASES; ++i)
    t[i] = 0;

/* The peak so far is read after each phase, outside its time. */
#define PHASE(k, call) \
  do { MPI_Barrier (comm); t0 = MPI_Wtime (); call; t[k] = MPI_Wtime () - t0; \
    hwm[k] = status_bytes ("VmHWM"); } while (0)

  PHASE (REFINE, p8est_refine_ext (p8est, 0, g_max_level, refine_fn, NULL,
                                   replace_fn));
  refined = (p8est->global_num_quadrants - before) / 7;
  PHASE (COARSEN, p8est_coarsen_ext (p8est, 0, 0, coarsen_fn, NULL,
                                     replace_fn));
  coarsened = (before + 7 * refined - p8est->global_num_quadrants) / 7;
  PHASE (BALANCE, p8est_balance_ext (p8est, P8EST_CONNECT_FULL, NULL,
                                     replace_fn));
  balanced_local = (long long) p8est->local_num_quadrants;
  PHASE (PARTITION, p8est_partition_ext (p8est, 1, NULL));
  PHASE (GHOST, ghost = p8est_ghost_new (p8est, P8EST_CONNECT_FULL));
  PHASE (LNODES, lnodes = p8est_lnodes_new (p8est, ghost, 1));
#undef PHASE
  MPI_Barrier (comm);

  mem[1] = hwm_reset ? status_bytes ("VmHWM") : maxrss_bytes ();
  MPI_Reduce (t, tmax, NPHASES, MPI_DOUBLE, MPI_MAX, 0, comm);
  MPI_Reduce (mem, memmax, 3, MPI_LONG_LONG, MPI_MAX, 0, comm);
  MPI_Reduce (hwm, hwmmax, NPHASES, MPI_LONG_LONG, MPI_MAX, 0, comm);
  MPI_Reduce (&hwm_reset, &all_reset, 1, MPI_INT, MPI_MIN, 0, comm);

  /* Counts and checks, after the measurements. */
  if (g_rank == 0)
    balanced = (long long *) malloc (sizeof *balanced * (size_t) g_size);
  MPI_Gather (&balanced_local, 1, MPI_LONG_LONG, balanced, 1, MPI_LONG_LONG,
              0, comm);
  lnodes_owned = lnodes->owned_count;
  MPI_Allreduce (&lnodes_owned, &lnodes_global, 1, MPI_LONG_LONG, MPI_SUM,
                 comm);
  ghosts = (long long) ghost->ghosts.elem_count;
  MPI_Allreduce (&ghosts, &ghosts_all, 1, MPI_LONG_LONG, MPI_SUM, comm);
  {
    double              integ = integral (p8est);
    if (g_rank == 0) {
      printf ("RESULT {\"tool\": \"p4est\", \"version\": \"%s\", "
              "\"ranks\": %d, \"level\": %d, \"max_level\": %d, "
              "\"warmup\": %d, \"dx\": %lld, \"z\": %lld, \"step\": %d, "
              "\"times\": {", P4EST_VERSION, g_size, level, g_max_level,
              warmup, (long long) g_dx, (long long) g_z, g_step);
      for (i = 0; i < NPHASES; ++i) {
        printf ("%s\"%s\": %.9f", i ? ", " : "", phase_names[i], tmax[i]);
        total += tmax[i];
      }
      printf ("}, \"total_of_max\": %.9f, \"leaves_before\": %lld, "
              "\"refined\": %lld, \"coarsened\": %lld, "
              "\"leaves_after\": %lld, \"per_rank\": [",
              total, (long long) before, (long long) refined,
              (long long) coarsened, (long long) p8est->global_num_quadrants);
      for (r = 0; r < g_size; ++r)
        printf ("%s%lld", r ? ", " : "",
                (long long) (p8est->global_first_quadrant[r + 1] -
                             p8est->global_first_quadrant[r]));
      printf ("], \"per_rank_before_partition\": [");
      for (r = 0; r < g_size; ++r)
        printf ("%s%lld", r ? ", " : "", balanced[r]);
      printf ("], \"nodes\": %lld, \"ghosts\": %lld, \"integral\": %.17g, "
              "\"rss_before_cycle\": %lld, \"peak_cycle\": %lld, "
              "\"peak_warmup\": %lld, \"hwm_reset\": %d, \"peak_after\": {",
              lnodes_global, ghosts_all, integ, memmax[0], memmax[1],
              memmax[2], all_reset);
      for (i = 0; i < NPHASES; ++i)
        printf ("%s\"%s\": %lld", i ? ", " : "", phase_names[i], hwmmax[i]);
      printf ("}}\n");
      fflush (stdout);
      free (balanced);
    }
  }

  p8est_lnodes_destroy (lnodes);
  p8est_ghost_destroy (ghost);
  p8est_destroy (p8est);
  p8est_connectivity_destroy (conn);
  finish (0);
  return 0;
}
