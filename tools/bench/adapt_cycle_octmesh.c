/*
 * adapt_cycle_octmesh: octmesh's side of the adaptive-cycle benchmark
 * (issue 23) through the C API; p4est's side is
 * tools/p4est_ref/p4est_adapt_cycle.c, the driver tools/bench/adapt_cycle.py,
 * which builds this file with mpicc against include/ and target/release.
 *
 * The same moving sphere (the exact cut test of
 * tools/p4est_ref/octmesh_p4est_adapt.c, centre x advancing DX lattice units
 * per step, centre z at Z, 262144 by default) and the same 16 bytes of data per leaf as the p4est program: a
 * double (a smooth function of the centre at the start), the level, int32,
 * and padding; copied on refinement and balance splits, the mean on
 * coarsening.
 *
 *   warm-up (not timed): uniform octree at LEVEL
 *     (octmesh_octree_refine_callback), octmesh_octree_data_set_size 16,
 *     then for t = 1 .. WARMUP: _refine_once_ext + _coarsen_ext
 *     (non-recursive), _balance_ext (corner), _partition_for_coarsening;
 *     the leaves are the same as p4est's after every step
 *     (tests/adapt_p4est.rs), the driver checks the counts;
 *   the timed cycle, step t = WARMUP + 1, each phase between barriers:
 *     adapt      octmesh_octree_adapt_ext (refine where cut below MAX_LEVEL,
 *                coarsen families with no leaf cut; p4est's refine then
 *                coarsen in one call), or with --split two phases, refine
 *                (_refine_once_ext) and coarsen (_coarsen_ext);
 *     balance    octmesh_octree_balance_ext (corner)
 *     partition  octmesh_octree_partition_for_coarsening (the data moves)
 *     mesh       octmesh_mesh_build (OCTMESH_KEEP_ALL): ghost layer, nodes
 *                with hanging constraints, numbering, connectivity
 *
 * Memory and output as in the p4est program: rank 0 prints one line
 * "RESULT {json}" with the phase times (seconds, maximum over ranks), leaf
 * counts, leaves refined and families coarsened, leaves per rank before
 * and after the partition, independent nodes, the integral of the data,
 * the RSS before the cycle, the peak of the warm-up, the peak during the cycle (VmHWM reset through
 * /proc/self/clear_refs just before it) and VmHWM after each phase (where
 * the peak is reached); bytes per rank, maximum over ranks.
 *
 * Usage: mpirun -np P adapt_cycle_octmesh --level L --max-level M
 *          --warmup W [--dx DX] [--z Z] [--split]
 */

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>

#include <mpi.h>
#include "octmesh.h"
#include "sphere_cut.h" /* tools/p4est_ref: the oracle's sphere */

#define ROOT_LEN 524288.0

typedef struct {
  double value;
  int32_t level;
  int32_t spare;
} datum_t;

/* The timed phases, in order. To time another call after the mesh build,
 * add its name here (before NPHASES) and to phase_names; the driver shows
 * every phase it finds. */
enum { ADAPT, REFINE, COARSEN, BALANCE, PARTITION, MESH, NPHASES };
static const char *phase_names[NPHASES] = {"adapt",     "refine", "coarsen", "balance",
                                           "partition", "mesh"};

static int g_rank, g_size, g_step, g_max_level;
static int64_t g_dx = STEP_X, g_z = ROOT_HALF;

static void fail(octmesh_t *h, const char *what, octmesh_status_t s) {
  fprintf(stderr, "adapt_cycle_octmesh: rank %d: %s failed: %s (%s)\n", g_rank, what,
          octmesh_status_name(s), octmesh_last_error(h));
  fflush(stderr);
  MPI_Abort(MPI_COMM_WORLD, 2);
}

#define OK(call, h)                                                                  \
  do {                                                                               \
    octmesh_status_t s_ = (call);                                                    \
    if (s_ != OCTMESH_STATUS_OK) fail(h, #call, s_);                                 \
  } while (0)

static void usage_error(const char *msg) {
  if (g_rank == 0)
    fprintf(stderr,
            "adapt_cycle_octmesh: %s\nusage: adapt_cycle_octmesh --level L --max-level M"
            " --warmup W [--dx DX] [--z Z] [--split]\n",
            msg);
  MPI_Finalize();
  exit(1);
}

/* The oracle's cut test: the closed box meets the sphere's surface. */
static int cut(const octmesh_octant_t *o) {
  return sphere_cuts_cube(o->x, o->y, o->z, (int64_t)1 << (19 - o->level),
                          START_X + g_dx * g_step, g_z);
}

static int32_t everything(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  (void)o;
  return 1;
}

static int32_t refine_cut(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  return cut(o); /* max_level is the call's argument */
}

static int32_t coarsen_uncut(void *ctx, const octmesh_octant_t *family) {
  (void)ctx;
  for (int i = 0; i < 8; i++)
    if (cut(&family[i])) return 0;
  return 1;
}

/* t8code's convention for the same rule: refine where cut (kept at the
 * maximum level), coarsen elsewhere (a family coarsens when all eight ask,
 * i.e. none is cut). */
static int32_t adapt_sphere(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  if (cut(o)) return o->level < g_max_level ? 1 : 0;
  return -1;
}

/* Refinement and balance splits (1 -> n) copy the value; coarsening
 * (8 -> 1) takes the mean, summed in child order as in p4est's program. */
static int32_t replace(void *ctx, int32_t nout, const octmesh_octant_t *out,
                       const void *out_data, int32_t nin, const octmesh_octant_t *in,
                       void *in_data) {
  (void)ctx;
  (void)out;
  const datum_t *od = out_data;
  datum_t *id = in_data;
  if (nout == 1) {
    for (int i = 0; i < nin; i++) id[i] = (datum_t){od[0].value, in[i].level, 0};
  } else {
    double s = 0;
    for (int i = 0; i < nout; i++) s += od[i].value;
    id[0] = (datum_t){s / nout, in[0].level, 0};
  }
  return 0;
}

/* One warm-up step, as the p4est program's (refine then coarsen). */
static void step(octmesh_t *h) {
  OK(octmesh_octree_refine_once_ext(h, g_max_level, refine_cut, replace, NULL, NULL), h);
  OK(octmesh_octree_coarsen_ext(h, 0, coarsen_uncut, replace, NULL, NULL), h);
  OK(octmesh_octree_balance_ext(h, OCTMESH_CONNECT_CORNER, replace, NULL), h);
  OK(octmesh_octree_partition_for_coarsening(h, NULL, NULL), h);
}

/* The local leaves, malloc'ed; *n their count. */
static octmesh_octant_t *leaves(octmesh_t *h, octmesh_locidx_t *n) {
  octmesh_gloidx_t ng;
  OK(octmesh_octree_get_num_leaves(h, n, &ng), h);
  octmesh_octant_t *l = malloc(sizeof *l * (size_t)(*n > 0 ? *n : 1));
  if (l == NULL) {
    fprintf(stderr, "adapt_cycle_octmesh: rank %d: out of memory\n", g_rank);
    MPI_Abort(MPI_COMM_WORLD, 2);
  }
  OK(octmesh_octree_get_leaves(h, l, *n), h);
  return l;
}

/* The initial value at every leaf's centre (p4est program's init_fn). */
static void fill(octmesh_t *h) {
  octmesh_locidx_t n, nd;
  octmesh_octant_t *l = leaves(h, &n);
  void *p = NULL;
  OK(octmesh_octree_data_get(h, &p, &nd), h);
  datum_t *d = p;
  for (octmesh_locidx_t i = 0; i < n; i++) {
    const double half = (double)((int64_t)1 << (19 - l[i].level)) / 2.0;
    const double x = (l[i].x + half) / ROOT_LEN, y = (l[i].y + half) / ROOT_LEN,
                 z = (l[i].z + half) / ROOT_LEN;
    d[i] = (datum_t){x * x + y + 0.5 * z, l[i].level, 0};
  }
  free(l);
}

/* Sum of volume * value over all leaves (Morton order per rank, then the
 * ranks' sums: the p4est program's order). */
static double integral(octmesh_t *h) {
  octmesh_locidx_t n, nd;
  octmesh_octant_t *l = leaves(h, &n);
  void *p = NULL;
  OK(octmesh_octree_data_get(h, &p, &nd), h);
  const datum_t *d = p;
  double s = 0, all;
  for (octmesh_locidx_t i = 0; i < n; i++) {
    const double e = (double)((int64_t)1 << (19 - l[i].level)) / ROOT_LEN;
    s += e * e * e * d[i].value;
  }
  free(l);
  MPI_Allreduce(&s, &all, 1, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  return all;
}

/* VmRSS or VmHWM from /proc/self/status, bytes (0 if unreadable). */
static long long status_bytes(const char *key) {
  char line[256];
  long long v = 0;
  size_t n = strlen(key);
  FILE *f = fopen("/proc/self/status", "r");
  if (f == NULL) return 0;
  while (fgets(line, sizeof line, f) != NULL)
    if (!strncmp(line, key, n) && line[n] == ':') {
      v = atoll(line + n + 1);
      break;
    }
  fclose(f);
  return v * 1024;
}

/* Resets VmHWM to the current RSS (Linux >= 4.0); 1 on success. */
static int reset_peak(void) {
  FILE *f = fopen("/proc/self/clear_refs", "w");
  if (f == NULL) return 0;
  int ok = fputs("5", f) >= 0;
  ok &= fclose(f) == 0;
  return ok;
}

static long long maxrss_bytes(void) {
  struct rusage ru;
  getrusage(RUSAGE_SELF, &ru);
  return (long long)ru.ru_maxrss * 1024;
}

static long int_arg(const char *s, long lo, long hi, const char *what) {
  char *end;
  long v = strtol(s, &end, 10);
  if (*end != '\0' || end == s || v < lo || v > hi) usage_error(what);
  return v;
}

int main(int argc, char **argv) {
  MPI_Comm comm = MPI_COMM_WORLD;
  MPI_Init(&argc, &argv);
  MPI_Comm_rank(comm, &g_rank);
  MPI_Comm_size(comm, &g_size);

  int level = -1, warmup = -1, split = 0;
  g_max_level = -1;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "--split")) {
      split = 1;
      continue;
    }
    if (i + 1 >= argc) usage_error("every option takes a value");
    if (!strcmp(a, "--level"))
      level = (int)int_arg(argv[++i], 0, 18, "--level: 0-18");
    else if (!strcmp(a, "--max-level"))
      g_max_level = (int)int_arg(argv[++i], 0, 18, "--max-level: 0-18");
    else if (!strcmp(a, "--dx"))
      g_dx = int_arg(argv[++i], 0, 262144, "--dx: 0 to 262144");
    else if (!strcmp(a, "--z"))
      g_z = int_arg(argv[++i], RADIUS, 524288 - RADIUS, "--z: 131072 to 393216");
    else if (!strcmp(a, "--warmup"))
      warmup = (int)int_arg(argv[++i], 0, 100000, "--warmup: 0-100000");
    else
      usage_error("unknown option");
  }
  if (level < 0 || g_max_level < 0 || warmup < 0)
    usage_error("--level, --max-level and --warmup are required");

  /* Warm-up, not timed. */
  octmesh_t *h = NULL;
  OK(octmesh_create(comm, NULL, &h), NULL);
  OK(octmesh_octree_refine_callback(h, level, everything, NULL), h);
  OK(octmesh_octree_data_set_size(h, (int32_t)sizeof(datum_t)), h);
  fill(h);
  for (g_step = 1; g_step <= warmup; g_step++) step(h);
  octmesh_locidx_t nl;
  octmesh_gloidx_t before, after, refined = 0, coarsened = 0;
  OK(octmesh_octree_get_num_leaves(h, &nl, &before), h);

  /* The cycle. */
  long long mem[3], memmax[3], hwm[NPHASES] = {0}, hwmmax[NPHASES];
  mem[0] = status_bytes("VmRSS");
  mem[2] = status_bytes("VmHWM");
  int hwm_reset = reset_peak(), all_reset;
  double t[NPHASES], tmax[NPHASES], t0;
  int done[NPHASES] = {0};
  for (int i = 0; i < NPHASES; i++) t[i] = 0;

/* The peak so far is read after each phase, outside its time. */
#define PHASE(k, call)                                                               \
  do {                                                                               \
    MPI_Barrier(comm);                                                               \
    t0 = MPI_Wtime();                                                                \
    OK(call, h);                                                                     \
    t[k] = MPI_Wtime() - t0;                                                         \
    hwm[k] = status_bytes("VmHWM");                                                  \
    done[k] = 1;                                                                     \
  } while (0)

  if (split) {
    PHASE(REFINE, octmesh_octree_refine_once_ext(h, g_max_level, refine_cut, replace, NULL,
                                                 &refined));
    PHASE(COARSEN, octmesh_octree_coarsen_ext(h, 0, coarsen_uncut, replace, NULL, &coarsened));
  } else {
    PHASE(ADAPT,
          octmesh_octree_adapt_ext(h, adapt_sphere, replace, NULL, &refined, &coarsened));
  }
  PHASE(BALANCE, octmesh_octree_balance_ext(h, OCTMESH_CONNECT_CORNER, replace, NULL));
  octmesh_locidx_t balanced_local;
  OK(octmesh_octree_get_num_leaves(h, &balanced_local, &after), h);
  PHASE(PARTITION, octmesh_octree_partition_for_coarsening(h, NULL, NULL));
  PHASE(MESH, octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER));
  /* The data transfer onto the new mesh goes here, timed like the others:
   *   PHASE(TRANSFER, octmesh_mesh_transfer_...(h, ...));
   * with TRANSFER added to the enum and "transfer" to phase_names above
   * (and its buffers allocated before reset_peak if they are the caller's
   * and should not count in the cycle's peak). */
#undef PHASE
  MPI_Barrier(comm);

  mem[1] = hwm_reset ? status_bytes("VmHWM") : maxrss_bytes();
  MPI_Reduce(t, tmax, NPHASES, MPI_DOUBLE, MPI_MAX, 0, comm);
  MPI_Reduce(mem, memmax, 3, MPI_LONG_LONG, MPI_MAX, 0, comm);
  MPI_Reduce(hwm, hwmmax, NPHASES, MPI_LONG_LONG, MPI_MAX, 0, comm);
  MPI_Reduce(&hwm_reset, &all_reset, 1, MPI_INT, MPI_MIN, 0, comm);

  /* Counts and checks, after the measurements. */
  octmesh_mesh_counts_t c;
  OK(octmesh_mesh_get_counts(h, &c), h);
  OK(octmesh_octree_get_num_leaves(h, &nl, &after), h);
  long long mine[2] = {nl, balanced_local}, *per = malloc(sizeof *per * 2 * (size_t)g_size);
  MPI_Gather(mine, 2, MPI_LONG_LONG, per, 2, MPI_LONG_LONG, 0, comm);
  double integ = integral(h);
  if (g_rank == 0) {
    double total = 0;
    printf("RESULT {\"tool\": \"octmesh\", \"ranks\": %d, \"level\": %d, \"max_level\": %d, "
           "\"warmup\": %d, \"dx\": %lld, \"z\": %lld, \"step\": %d, \"split\": %d, "
           "\"times\": {",
           g_size, level, g_max_level, warmup, (long long)g_dx, (long long)g_z, g_step, split);
    for (int i = 0, first = 1; i < NPHASES; i++)
      if (done[i]) {
        printf("%s\"%s\": %.9f", first ? "" : ", ", phase_names[i], tmax[i]);
        total += tmax[i];
        first = 0;
      }
    printf("}, \"total_of_max\": %.9f, \"leaves_before\": %lld, \"refined\": %lld, "
           "\"coarsened\": %lld, \"leaves_after\": %lld, \"per_rank\": [",
           total, (long long)before, (long long)refined, (long long)coarsened,
           (long long)after);
    for (int r = 0; r < g_size; r++) printf("%s%lld", r ? ", " : "", per[2 * r]);
    printf("], \"per_rank_before_partition\": [");
    for (int r = 0; r < g_size; r++) printf("%s%lld", r ? ", " : "", per[2 * r + 1]);
    printf("], \"nodes\": %lld, \"face_hanging\": %lld, \"edge_hanging\": %lld, "
           "\"integral\": %.17g, \"rss_before_cycle\": %lld, \"peak_cycle\": %lld, "
           "\"peak_warmup\": %lld, \"hwm_reset\": %d, \"peak_after\": {",
           (long long)c.global_independent, (long long)c.global_face_hanging,
           (long long)c.global_edge_hanging, integ, memmax[0], memmax[1], memmax[2],
           all_reset);
    for (int i = 0, first = 1; i < NPHASES; i++)
      if (done[i]) {
        printf("%s\"%s\": %lld", first ? "" : ", ", phase_names[i], hwmmax[i]);
        first = 0;
      }
    printf("}}\n");
    fflush(stdout);
  }
  free(per);
  octmesh_destroy(h);
  MPI_Finalize();
  return 0;
}
