/* Adaptation following a moving front, with a conserved quantity carried as
 * per-leaf data. A uniform octree of level 3 in the unit cube holds, per
 * leaf, the value of a smooth function at the leaf's centre. A sphere of
 * radius 0.25 (root units) moves along x for 50 steps; each step
 * octmesh_octree_adapt_ext refines the leaves its surface cuts (up to level
 * 6) and coarsens the families away from it (down to level 3), t8code's
 * convention (1 refine, 0 keep, -1 coarsen); octmesh_octree_balance_ext
 * 2:1-balances and octmesh_octree_partition_for_coarsening repartitions so
 * that the next step may coarsen every family. The replace callbacks
 * prolong by copy (balance splits; refinement with a zero-sum tilt) and
 * restrict by the mean (coarsening), which keeps the integral
 * sum(volume * value) to round-off.
 * Rank 0 prints one line per step and a final line
 *   ADAPT_FRONT steps 50 leaves N integral X relative_change Y
 * and the program exits non-zero when |Y| > 1e-12 or a call failed.
 * Usage: adapt_front [STEPS] */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <mpi.h>
#include "octmesh.h"

#define MIN_LEVEL 3
#define MAX_LEVEL 6
#define ROOT ((int64_t)1 << 19) /* the root cube's side in lattice units */
#define TILT 0.125 /* the refinement's tilt of the value, see replace */

/* 16 bytes per leaf: the quantity and the leaf's level, which the replace
 * callback checks against the outgoing leaves so that data shifted against
 * its leaves (a bug) fails the run instead of silently passing. */
typedef struct {
  double value;
  int32_t level;
  int32_t spare;
} datum_t;

typedef struct {
  int64_t centre[3]; /* the front's centre, lattice units */
  int64_t radius;    /* lattice units */
} front_t;

/* The front cuts the leaf's box when the sphere's surface passes through
 * it: the nearest point of the box is inside the sphere and the farthest
 * outside. Integer arithmetic (squares below 2^41) gives every rank the
 * same answer for the same leaf, whatever the partition. */
static int cut(const front_t *f, const octmesh_octant_t *o) {
  const int64_t len = (int64_t)1 << (19 - o->level);
  const int64_t lo[3] = {o->x, o->y, o->z};
  int64_t near = 0, far = 0;
  for (int k = 0; k < 3; k++) {
    const int64_t c = f->centre[k], hi = lo[k] + len;
    const int64_t a = c < lo[k] ? lo[k] - c : (c > hi ? c - hi : 0);
    const int64_t b = c - lo[k] > hi - c ? c - lo[k] : hi - c;
    near += a * a;
    far += b * b;
  }
  const int64_t r2 = f->radius * f->radius;
  return near <= r2 && r2 <= far;
}

static int32_t adapt_front(void *ctx, const octmesh_octant_t *o) {
  if (cut(ctx, o)) return o->level < MAX_LEVEL ? 1 : 0;
  /* A family is coarsened only when all eight ask, so a leaf next to the
   * front keeps its siblings when one of them is cut. */
  return o->level > MIN_LEVEL ? -1 : 0;
}

static bool uniform(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  (void)o;
  return true; /* max_level stops it at MIN_LEVEL */
}

/* Replace callback of adapt_ext and balance_ext. Balance splits (1 -> n)
 * copy the value: the incoming leaves tile the outgoing one, so their
 * volumes sum to its volume and the integral is unchanged. Refinement
 * (1 -> 8) copies it tilted along x, the front's direction: the four
 * children of the upper x half get value * (1 + TILT), the lower four
 * value * (1 - TILT), which sums to 8 * value. A plain copy would leave
 * every family uniform, so the field would never change and the mean below
 * would never be tested; the tilt makes the field evolve with the front.
 * Coarsening (8 -> 1) takes the mean: the parent's volume is 8 times a
 * child's, so volume * mean is the children's sum. */
static int32_t replace(void *ctx, octmesh_locidx_t nout, const octmesh_octant_t *out,
                       const void *out_data, octmesh_locidx_t nin, const octmesh_octant_t *in,
                       void *in_data) {
  const datum_t *od = out_data;
  datum_t *id = in_data;
  for (int i = 0; i < nout; i++)
    if (od[i].level != out[i].level) return 1;
  /* ctx is the front in adapt_ext and NULL in balance_ext, whose splits
   * may also be 1 -> 8 but are to be plain copies. */
  if (ctx != NULL && nout == 1 && nin == 8) {
    for (int i = 0; i < 8; i++) /* child i's x bit is i & 1 (Morton order) */
      id[i] = (datum_t){od[0].value * (i & 1 ? 1.0 + TILT : 1.0 - TILT), in[i].level, 0};
  } else if (nout == 1) {
    for (int i = 0; i < nin; i++) id[i] = (datum_t){od[0].value, in[i].level, 0};
  } else if (nout == 8 && nin == 1) {
    double sum = 0.0;
    for (int i = 0; i < 8; i++) sum += od[i].value;
    id[0] = (datum_t){sum / 8.0, in[0].level, 0};
  } else {
    return 2;
  }
  return 0;
}

#define TRY(call)                                                                        \
  do {                                                                                   \
    octmesh_status_t s_ = (call);                                                        \
    if (s_ != OCTMESH_STATUS_OK) {                                                       \
      fprintf(stderr, "%s: %s: %s\n", #call, octmesh_status_name(s_), octmesh_last_error(h)); \
      MPI_Abort(MPI_COMM_WORLD, 2);                                                      \
    }                                                                                    \
  } while (0)

/* The local leaves (a buffer grown as needed); returns their count. */
static octmesh_locidx_t get_leaves(octmesh_t *h, octmesh_octant_t **leaves, size_t *cap) {
  octmesh_locidx_t nl;
  octmesh_gloidx_t ng;
  TRY(octmesh_octree_get_num_leaves(h, &nl, &ng));
  if ((size_t)nl > *cap) {
    *cap = (size_t)nl;
    free(*leaves);
    *leaves = malloc(sizeof **leaves * *cap);
    if (*leaves == NULL) MPI_Abort(MPI_COMM_WORLD, 3);
  }
  TRY(octmesh_octree_get_leaves(h, *leaves, nl));
  return nl;
}

/* The integral sum(volume * value) over all leaves, on every rank, and
 * fails (returns -1) when a leaf's data does not carry its level. The terms
 * are gathered to rank 0 and summed there in global Morton order: a
 * reduction of per-rank partial sums would add in an order that depends on
 * the partition, and the integral printed must be bit-identical on 1, 2 and
 * 4 ranks. */
static int integral(octmesh_t *h, int size, double *result) {
  static octmesh_octant_t *leaves = NULL;
  static size_t cap = 0;
  octmesh_locidx_t nl = get_leaves(h, &leaves, &cap), nd;
  void *p = NULL;
  TRY(octmesh_octree_data_get(h, &p, &nd));
  const datum_t *d = p;
  int bad = nd != nl;
  double *terms = malloc(sizeof *terms * (size_t)(nl > 0 ? nl : 1));
  if (terms == NULL) MPI_Abort(MPI_COMM_WORLD, 3);
  for (octmesh_locidx_t i = 0; i < nl && !bad; i++) {
    if (d[i].level != leaves[i].level) bad = 1;
    /* The volume 8^-level is exact in binary. */
    terms[i] = ldexp(d[i].value, -3 * leaves[i].level);
  }
  int rank, n = (int)nl;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  int *counts = NULL, *displs = NULL;
  double *all = NULL;
  if (rank == 0) {
    counts = malloc(sizeof *counts * (size_t)size);
    displs = malloc(sizeof *displs * (size_t)size);
    if (counts == NULL || displs == NULL) MPI_Abort(MPI_COMM_WORLD, 3);
  }
  MPI_Gather(&n, 1, MPI_INT, counts, 1, MPI_INT, 0, MPI_COMM_WORLD);
  double sum = 0.0;
  if (rank == 0) {
    long total = 0;
    for (int r = 0; r < size; r++) {
      displs[r] = (int)total;
      total += counts[r];
    }
    all = malloc(sizeof *all * (size_t)(total > 0 ? total : 1));
    if (all == NULL) MPI_Abort(MPI_COMM_WORLD, 3);
    MPI_Gatherv(terms, n, MPI_DOUBLE, all, counts, displs, MPI_DOUBLE, 0, MPI_COMM_WORLD);
    for (long i = 0; i < total; i++) sum += all[i];
  } else {
    MPI_Gatherv(terms, n, MPI_DOUBLE, NULL, NULL, NULL, MPI_DOUBLE, 0, MPI_COMM_WORLD);
  }
  MPI_Bcast(&sum, 1, MPI_DOUBLE, 0, MPI_COMM_WORLD);
  int any_bad = 0;
  MPI_Allreduce(&bad, &any_bad, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  free(all);
  free(displs);
  free(counts);
  free(terms);
  *result = sum;
  return any_bad ? -1 : 0;
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank, size;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  const int steps = argc > 1 ? atoi(argv[1]) : 50;
  octmesh_t *h = NULL;
  TRY(octmesh_create(MPI_COMM_WORLD, NULL, &h));

  /* The unit cube, uniform at MIN_LEVEL; then the data, set from the
   * leaves' centres. */
  const double origin[3] = {0.0, 0.0, 0.0};
  TRY(octmesh_domain_set(h, origin, 1.0));
  TRY(octmesh_octree_refine_callback(h, MIN_LEVEL, uniform, NULL));
  TRY(octmesh_octree_partition_for_coarsening(h, NULL, NULL));
  TRY(octmesh_octree_data_set_size(h, (int32_t)sizeof(datum_t)));
  {
    octmesh_octant_t *leaves = NULL;
    size_t cap = 0;
    octmesh_locidx_t nl = get_leaves(h, &leaves, &cap), nd;
    void *p = NULL;
    TRY(octmesh_octree_data_get(h, &p, &nd));
    datum_t *d = p;
    for (octmesh_locidx_t i = 0; i < nl; i++) {
      const double half = 0.5 * (double)((int64_t)1 << (19 - leaves[i].level));
      const double x = (leaves[i].x + half) / (double)ROOT, y = (leaves[i].y + half) / (double)ROOT,
                   z = (leaves[i].z + half) / (double)ROOT;
      const double pi = 3.14159265358979323846;
      d[i] = (datum_t){1.0 + 0.5 * sin(2.0 * pi * x) * cos(pi * y) + 0.25 * z * z,
                       leaves[i].level, 0};
    }
    free(leaves);
  }
  double first = 0.0, now = 0.0;
  int failed = integral(h, size, &first) != 0;
  octmesh_gloidx_t global = 0;
  octmesh_locidx_t local = 0;
  TRY(octmesh_octree_get_num_leaves(h, &local, &global));
  if (rank == 0) printf("step 0 leaves %lld integral %.17g\n", (long long)global, first);

  /* The front's centre moves from x = 0.25 to x = 0.75 (y = z = 0.5). */
  front_t f = {{0, ROOT / 2, ROOT / 2}, ROOT / 4};
  for (int step = 1; step <= steps && !failed; step++) {
    f.centre[0] = ROOT / 4 + ROOT / 2 * step / (steps > 0 ? steps : 1);
    octmesh_gloidx_t refined = 0, coarsened = 0;
    TRY(octmesh_octree_adapt_ext(h, adapt_front, replace, &f, &refined, &coarsened));
    TRY(octmesh_octree_balance_ext(h, OCTMESH_CONNECT_CORNER, replace, NULL));
    TRY(octmesh_octree_partition_for_coarsening(h, NULL, NULL));
    TRY(octmesh_octree_get_num_leaves(h, &local, &global));
    failed = integral(h, size, &now) != 0;
    if (rank == 0)
      printf("step %d leaves %lld refined %lld coarsened %lld integral %.17g\n", step,
             (long long)global, (long long)refined, (long long)coarsened, now);
  }
  const double change = (now - first) / first;
  if (rank == 0) {
    if (failed) fprintf(stderr, "adapt_front: leaf data does not match its leaves\n");
    printf("ADAPT_FRONT steps %d leaves %lld integral %.17g relative_change %.3e\n", steps,
           (long long)global, now, change);
  }
  octmesh_destroy(h);
  MPI_Finalize();
  return failed || !(fabs(change) <= 1e-12) ? 1 : 0;
}
