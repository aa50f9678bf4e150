/* Per-leaf user data through the C API, 16 bytes per leaf: each leaf stores
 * its own octant (x, y, z, level as int32). The replace callback computes
 * the children's octants from the parent's stored one and the parent's from
 * the first child's; balance's 1 -> n replacements take the incoming leaves
 * after checking they lie in the stored leaf. Ten steps of the moving sphere
 * of adapt.c (root to level 5): odd steps octmesh_octree_adapt_ext, even
 * steps _refine_once_ext then _coarsen_ext (recursive at step 10); then
 * _balance_ext, a partition by weight every third step, and
 * _partition_for_coarsening. After every call each leaf's data must be its
 * own octant. Also: the size rules (no octree, negative, another size while
 * attached, the same size kept, 0 detaches), NULL replace callbacks zero
 * the new data, a replace callback failing on the last rank only fails the
 * call on every rank with the leaves and the data as before and the handle
 * still working, and a refinement by callback detaches the data.
 * Usage: leaf_data */
#include <stdint.h>
#include <stdlib.h>
#include "check.h"

#define MAX_LEVEL 5

typedef struct {
  int32_t x, y, z, level;
} datum_t;

static int g_step, g_rank, g_size;
static long g_refines, g_coarsens, g_wide;

static int cut(const octmesh_octant_t *o) { return check_sphere_cuts(o, g_step); }

static int same(const datum_t *d, const octmesh_octant_t *o) {
  return d->x == o->x && d->y == o->y && d->z == o->z && d->level == o->level;
}

static int inside(const datum_t *d, const octmesh_octant_t *o) {
  const int32_t len = 1 << (19 - d->level);
  return o->level > d->level && o->x >= d->x && o->x < d->x + len && o->y >= d->y &&
         o->y < d->y + len && o->z >= d->z && o->z < d->z + len;
}

/* Returns non-zero (a failure) when the data does not belong to the
 * outgoing leaves or the result does not match the incoming ones. */
static int32_t replace(void *ctx, octmesh_locidx_t nout, const octmesh_octant_t *out,
                       const void *out_data, octmesh_locidx_t nin, const octmesh_octant_t *in,
                       void *in_data) {
  (void)ctx;
  const datum_t *od = out_data;
  datum_t *id = in_data;
  for (int i = 0; i < nout; i++)
    if (!same(&od[i], &out[i])) return 1;
  for (int i = 0; i < nin; i++) /* zeroed before the call */
    if (id[i].x || id[i].y || id[i].z || id[i].level) return 2;
  if (nout == 1 && nin == 8) {
    const int32_t half = 1 << (19 - od[0].level - 1);
    for (int i = 0; i < 8; i++)
      id[i] = (datum_t){od[0].x + (i & 1) * half, od[0].y + ((i >> 1) & 1) * half,
                        od[0].z + ((i >> 2) & 1) * half, od[0].level + 1};
    ++g_refines;
  } else if (nout == 8 && nin == 1) {
    id[0] = (datum_t){od[0].x, od[0].y, od[0].z, od[0].level - 1};
    ++g_coarsens;
  } else if (nout == 1 && nin > 8) { /* balance */
    for (int i = 0; i < nin; i++) {
      if (!inside(&od[0], &in[i])) return 3;
      id[i] = (datum_t){in[i].x, in[i].y, in[i].z, in[i].level};
    }
    ++g_wide;
  } else {
    return 4;
  }
  for (int i = 0; i < nin; i++)
    if (!same(&id[i], &in[i])) return 5;
  return 0;
}

/* Fails on the last rank at its first call. */
static int32_t fail_on_last(void *ctx, octmesh_locidx_t nout, const octmesh_octant_t *out,
                            const void *out_data, octmesh_locidx_t nin, const octmesh_octant_t *in,
                            void *in_data) {
  ++*(long *)ctx;
  if (g_rank == g_size - 1) return 42;
  return replace(NULL, nout, out, out_data, nin, in, in_data);
}

static bool refine_cut(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  return cut(o);
}

static bool coarsen_uncut(void *ctx, const octmesh_octant_t *family) {
  (void)ctx;
  for (int i = 0; i < 8; i++)
    if (family[i].level != family[0].level || cut(&family[i])) return false;
  return true;
}

static int32_t adapt_sphere(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  if (cut(o)) return o->level < MAX_LEVEL ? 1 : 0;
  return -1;
}

static bool all(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  return o->level < 1;
}

static bool everything(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  (void)o;
  return true;
}

static bool corner(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  return o->x == 0 && o->y == 0 && o->z == 0;
}

/* The leaf holding the point just below (2^17, 2^17, 2^17): refining it
 * several times unbalances the coarse leaves across the plane x = 2^17. */
static bool near_p(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  const int32_t q = 131071, len = 1 << (19 - o->level);
  return o->x <= q && q < o->x + len && o->y <= q && q < o->y + len && o->z <= q &&
         q < o->z + len;
}

/* Fails at every call. */
static int32_t fail_always(void *ctx, octmesh_locidx_t nout, const octmesh_octant_t *out,
                           const void *out_data, octmesh_locidx_t nin, const octmesh_octant_t *in,
                           void *in_data) {
  (void)out;
  (void)out_data;
  (void)in;
  (void)in_data;
  ++*(long *)ctx;
  return nout + nin;
}

static uint64_t by_level(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  return 1 + (uint64_t)o->level;
}

/* The local leaves, checked against their data (or, with zeros, leaves
 * whose data is all zero are also accepted and counted). Returns the
 * number of leaves; *copy gets the leaves and *dcopy the data if not
 * NULL. */
static long check_data(octmesh_t *h, long *zeros, octmesh_octant_t **copy, datum_t **dcopy) {
  octmesh_locidx_t nl, nd;
  octmesh_gloidx_t ng;
  OK(octmesh_octree_get_num_leaves(h, &nl, &ng), h);
  octmesh_octant_t *l = malloc(sizeof *l * (size_t)(nl > 0 ? nl : 1));
  OK(octmesh_octree_get_leaves(h, l, nl), h);
  void *p = NULL;
  int32_t size = 0;
  OK(octmesh_octree_data_get_size(h, &size), h);
  CHECK(size == 16, h);
  OK(octmesh_octree_data_get(h, &p, &nd), h);
  CHECK(nd == nl && (nl == 0 || p != NULL), h);
  const datum_t *d = p;
  for (int i = 0; i < nl; i++) {
    if (zeros != NULL && !d[i].x && !d[i].y && !d[i].z && !d[i].level) {
      ++*zeros;
      continue;
    }
    CHECK(same(&d[i], &l[i]), h);
  }
  if (copy != NULL) {
    *copy = l;
    *dcopy = malloc(sizeof **dcopy * (size_t)(nl > 0 ? nl : 1));
    memcpy(*dcopy, d, sizeof **dcopy * (size_t)nl);
  } else {
    free(l);
  }
  return nl;
}

/* Writes every leaf's own octant into its data. */
static void fill(octmesh_t *h) {
  octmesh_locidx_t nl, nd;
  octmesh_gloidx_t ng;
  OK(octmesh_octree_get_num_leaves(h, &nl, &ng), h);
  octmesh_octant_t *l = malloc(sizeof *l * (size_t)(nl > 0 ? nl : 1));
  OK(octmesh_octree_get_leaves(h, l, nl), h);
  void *p = NULL;
  OK(octmesh_octree_data_get(h, &p, &nd), h);
  datum_t *d = p;
  for (int i = 0; i < nl; i++) d[i] = (datum_t){l[i].x, l[i].y, l[i].z, l[i].level};
  free(l);
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  MPI_Comm_rank(MPI_COMM_WORLD, &g_rank);
  MPI_Comm_size(MPI_COMM_WORLD, &g_size);
  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, NULL, &h), NULL);
  void *p = NULL;
  octmesh_locidx_t nd;
  int32_t size = -1;

  /* No octree yet; then the root. */
  CHECK_STATUS(octmesh_octree_data_set_size(h, 16), OCTMESH_STATUS_STATE, h);
  OK(octmesh_octree_refine_callback(h, 0, all, NULL), h);
  OK(octmesh_octree_data_get_size(h, &size), h);
  CHECK(size == 0, h);
  CHECK_STATUS(octmesh_octree_data_get(h, &p, &nd), OCTMESH_STATUS_STATE, h);
  CHECK_STATUS(octmesh_octree_data_set_size(h, -1), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_octree_data_set_size(h, 16), h);
  fill(h);
  check_data(h, NULL, NULL, NULL);
  /* The same size keeps the data; another one is refused, data kept. */
  OK(octmesh_octree_data_set_size(h, 16), h);
  CHECK_STATUS(octmesh_octree_data_set_size(h, 8), OCTMESH_STATUS_STATE, h);
  CHECK(strstr(octmesh_last_error(h), "detach") != NULL, h);
  check_data(h, NULL, NULL, NULL);

  for (g_step = 1; g_step <= 10; g_step++) {
    octmesh_gloidx_t refined = 0, coarsened = 0;
    long before = g_refines + g_coarsens;
    if (g_step % 2 == 1) {
      OK(octmesh_octree_adapt_ext(h, adapt_sphere, replace, NULL, &refined, &coarsened), h);
    } else {
      OK(octmesh_octree_refine_once_ext(h, MAX_LEVEL, refine_cut, replace, NULL, &refined), h);
      check_data(h, NULL, NULL, NULL);
      OK(octmesh_octree_coarsen_ext(h, g_step == 10, coarsen_uncut, replace, NULL, &coarsened),
         h);
    }
    check_data(h, NULL, NULL, NULL);
    long calls = g_refines + g_coarsens - before, all_calls;
    MPI_Allreduce(&calls, &all_calls, 1, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);
    CHECK(all_calls == refined + coarsened, h);
    OK(octmesh_octree_balance_ext(h, OCTMESH_CONNECT_CORNER, replace, NULL), h);
    check_data(h, NULL, NULL, NULL);
    if (g_step % 3 == 0) {
      OK(octmesh_octree_partition(h, by_level, NULL), h);
      check_data(h, NULL, NULL, NULL);
    }
    OK(octmesh_octree_partition_for_coarsening(h, NULL, NULL), h);
    check_data(h, NULL, NULL, NULL);
  }
  long counts[3] = {g_refines, g_coarsens, g_wide}, sums[3];
  MPI_Allreduce(counts, sums, 3, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);
  CHECK(sums[0] > 0 && sums[1] > 0, h);

  /* Balance splitting a leaf more than once: refine around p three times. */
  for (int i = 0; i < 3; i++)
    OK(octmesh_octree_refine_once_ext(h, 18, near_p, replace, NULL, NULL), h);
  g_wide = 0;
  OK(octmesh_octree_balance_ext(h, OCTMESH_CONNECT_CORNER, replace, NULL), h);
  check_data(h, NULL, NULL, NULL);
  long wide = g_wide, all_wide;
  MPI_Allreduce(&wide, &all_wide, 1, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);
  CHECK(all_wide > 0, h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);

  /* A replace failing on the last rank only: every rank fails, nothing
   * changes, the handle still works. */
  octmesh_octant_t *l0;
  datum_t *d0;
  long n0 = check_data(h, NULL, &l0, &d0);
  long tried = 0;
  octmesh_status_t s =
      octmesh_octree_refine_once_ext(h, 18, everything, fail_on_last, &tried, NULL);
  CHECK(s == (g_rank == g_size - 1 ? OCTMESH_STATUS_INVALID_ARGUMENT
                                   : OCTMESH_STATUS_REMOTE_FAILURE),
        h);
  CHECK(strstr(octmesh_last_error(h), "returned 42") != NULL, h);
  CHECK(g_rank != g_size - 1 || tried == 1, h);
  octmesh_octant_t *l1;
  datum_t *d1;
  long n1 = check_data(h, NULL, &l1, &d1);
  CHECK(n1 == n0, h);
  CHECK(memcmp(l0, l1, sizeof *l0 * (size_t)n0) == 0, h);
  CHECK(memcmp(d0, d1, sizeof *d0 * (size_t)n0) == 0, h);
  free(l1);
  free(d1);
  /* The same for balance, failing on the ranks that split a leaf. */
  for (int i = 0; i < 3; i++)
    OK(octmesh_octree_refine_once_ext(h, 18, near_p, replace, NULL, NULL), h);
  n0 = check_data(h, NULL, &l1, &d1);
  tried = 0;
  s = octmesh_octree_balance_ext(h, OCTMESH_CONNECT_CORNER, fail_always, &tried);
  CHECK(s == (tried > 0 ? OCTMESH_STATUS_INVALID_ARGUMENT : OCTMESH_STATUS_REMOTE_FAILURE), h);
  free(l0);
  free(d0);
  n1 = check_data(h, NULL, &l0, &d0);
  CHECK(n1 == n0, h);
  CHECK(memcmp(l0, l1, sizeof *l0 * (size_t)n0) == 0, h);
  CHECK(memcmp(d0, d1, sizeof *d0 * (size_t)n0) == 0, h);
  free(l0);
  free(d0);
  free(l1);
  free(d1);
  OK(octmesh_octree_balance_ext(h, OCTMESH_CONNECT_CORNER, replace, NULL), h);
  check_data(h, NULL, NULL, NULL);

  /* Without a replace callback, new leaves' data is zero. */
  octmesh_gloidx_t refined = 0;
  OK(octmesh_octree_refine_once(h, 18, corner, NULL, &refined), h);
  long zeros = 0, all_zeros;
  check_data(h, &zeros, NULL, NULL);
  MPI_Allreduce(&zeros, &all_zeros, 1, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);
  CHECK(all_zeros == 8 * refined, h);

  /* A recursive refinement by callback detaches the data; 0 too. */
  OK(octmesh_octree_refine_callback(h, 3, everything, NULL), h);
  OK(octmesh_octree_data_get_size(h, &size), h);
  CHECK(size == 0, h);
  CHECK_STATUS(octmesh_octree_data_get(h, &p, &nd), OCTMESH_STATUS_STATE, h);
  OK(octmesh_octree_data_set_size(h, 8), h);
  OK(octmesh_octree_data_set_size(h, 0), h);
  OK(octmesh_octree_data_get_size(h, &size), h);
  CHECK(size == 0, h);

  octmesh_destroy(h);
  if (g_rank == 0)
    printf("LEAF DATA refines %ld coarsens %ld wide %ld\n", sums[0], sums[1], all_wide);
  printf("LEAF DATA OK rank %d\n", g_rank);
  MPI_Finalize();
  return 0;
}
