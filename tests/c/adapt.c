/* Adaptation through the C API: the moving sphere of
 * tools/p4est_ref/octmesh_p4est_adapt.c from the root down to level 5, odd
 * steps with octmesh_octree_adapt, even steps with octmesh_octree_refine_once
 * then octmesh_octree_coarsen; each step balanced (corner) and partitioned
 * for coarsening. Rank 0 writes DIR/step_T.txt (the leaves) and
 * DIR/counts.txt in the reference's format, which tests/c_api.rs compares
 * with p4est's. Also: NULL callbacks, a bad level and calls before an octree
 * are refused; partitions by weight (all zero: nothing moves); recursive
 * coarsening goes further than one level.
 * Usage: adapt DIR */
#include <stdint.h>
#include <stdlib.h>
#include "check.h"

#define STEPS 10
#define MAX_LEVEL 5

static int g_step;

/* The reference's test: the closed box meets the sphere's surface. */
static int cut(const octmesh_octant_t *o) { return check_sphere_cuts(o, g_step); }

static bool never(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  (void)o;
  return false;
}

static bool refine_cut(void *ctx, const octmesh_octant_t *o) {
  ++*(long *)ctx;
  return cut(o);
}

static bool coarsen_uncut(void *ctx, const octmesh_octant_t *family) {
  ++*(long *)ctx;
  for (int i = 0; i < 8; i++) {
    /* Siblings in child order: same level, one side apart. */
    if (family[i].level != family[0].level) return false;
    if (cut(&family[i])) return false;
  }
  return true;
}

static int32_t adapt_sphere(void *ctx, const octmesh_octant_t *o) {
  ++*(long *)ctx;
  if (cut(o)) return o->level < MAX_LEVEL ? 1 : 0;
  return -1;
}

static uint64_t zero(void *ctx, const octmesh_octant_t *o) {
  (void)o;
  ++*(long *)ctx;
  return 0;
}

static uint64_t by_level(void *ctx, const octmesh_octant_t *o) {
  ++*(long *)ctx;
  return (uint64_t)o->level;
}

static bool always(void *ctx, const octmesh_octant_t *family) {
  (void)ctx;
  (void)family;
  return true;
}

/* Gathers the leaves on rank 0 and writes them, and a line of counts. */
static void write_step(octmesh_t *h, const char *dir, FILE *counts, int64_t refined,
                       int64_t coarsened) {
  int rank, size;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  octmesh_locidx_t nl;
  octmesh_gloidx_t ng;
  OK(octmesh_octree_get_num_leaves(h, &nl, &ng), h);
  octmesh_octant_t *mine = malloc(sizeof *mine * (size_t)(nl > 0 ? nl : 1));
  OK(octmesh_octree_get_leaves(h, mine, nl), h);
  int n = 4 * nl, *per = NULL, *displ = NULL;
  octmesh_octant_t *all = NULL;
  if (rank == 0) {
    per = malloc(sizeof *per * (size_t)size);
    displ = malloc(sizeof *displ * (size_t)size);
    all = malloc(sizeof *all * (size_t)(ng > 0 ? ng : 1));
  }
  MPI_Gather(&n, 1, MPI_INT, per, 1, MPI_INT, 0, MPI_COMM_WORLD);
  if (rank == 0)
    for (int r = 0, d = 0; r < size; d += per[r], r++) displ[r] = d;
  MPI_Gatherv(mine, n, MPI_INT32_T, all, per, displ, MPI_INT32_T, 0, MPI_COMM_WORLD);
  if (rank == 0) {
    char path[4096];
    snprintf(path, sizeof path, "%s/step_%d.txt", dir, g_step);
    FILE *f = fopen(path, "w");
    CHECK(f != NULL, h);
    for (int64_t i = 0; i < ng; i++)
      fprintf(f, "%d %d %d %d\n", all[i].x, all[i].y, all[i].z, all[i].level);
    CHECK(fclose(f) == 0, h);
    fprintf(counts, "%d %lld %lld %lld", g_step, (long long)refined, (long long)coarsened,
            (long long)ng);
    for (int r = 0; r < size; r++) fprintf(counts, " %d", per[r] / 4);
    fprintf(counts, "\n");
  }
  free(mine);
  free(per);
  free(displ);
  free(all);
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  CHECK(argc == 2, NULL);
  const char *dir = argv[1];
  FILE *counts = NULL;
  if (rank == 0) {
    char path[4096];
    snprintf(path, sizeof path, "%s/counts.txt", dir);
    counts = fopen(path, "w");
    CHECK(counts != NULL, NULL);
  }

  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, NULL, &h), NULL);
  long calls = 0;
  int64_t refined = -1, coarsened = -1;
  /* No octree yet. */
  CHECK_STATUS(octmesh_octree_adapt(h, adapt_sphere, &calls, NULL, NULL), OCTMESH_STATUS_STATE, h);
  CHECK_STATUS(octmesh_octree_coarsen(h, false, coarsen_uncut, &calls, NULL), OCTMESH_STATUS_STATE, h);
  CHECK_STATUS(octmesh_octree_refine_once(h, 5, refine_cut, &calls, NULL), OCTMESH_STATUS_STATE, h);
  CHECK_STATUS(octmesh_octree_partition_for_coarsening(h, NULL, NULL), OCTMESH_STATUS_STATE, h);
  CHECK(calls == 0, h);
  /* The root alone. */
  OK(octmesh_octree_refine_callback(h, 0, never, NULL), h);
  CHECK_STATUS(octmesh_octree_adapt(h, NULL, NULL, NULL, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_octree_coarsen(h, true, NULL, NULL, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_octree_refine_once(h, 19, refine_cut, &calls, NULL),
               OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_octree_refine_once(h, 5, NULL, NULL, NULL), OCTMESH_STATUS_INVALID_ARGUMENT,
               h);
  CHECK(calls == 0, h);

  for (g_step = 1; g_step <= STEPS; g_step++) {
    octmesh_locidx_t nl;
    octmesh_gloidx_t ng;
    OK(octmesh_octree_get_num_leaves(h, &nl, &ng), h);
    calls = 0;
    if (g_step % 2 == 1) {
      OK(octmesh_octree_adapt(h, adapt_sphere, &calls, &refined, &coarsened), h);
      CHECK(calls == nl, h); /* once per local leaf */
    } else {
      OK(octmesh_octree_refine_once(h, MAX_LEVEL, refine_cut, &calls, &refined), h);
      OK(octmesh_octree_coarsen(h, false, coarsen_uncut, &calls, &coarsened), h);
    }
    OK(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h);
    OK(octmesh_octree_partition_for_coarsening(h, NULL, NULL), h);
    write_step(h, dir, counts, refined, coarsened);
  }

  /* By weight: called once per local leaf; all zero moves nothing. */
  {
    octmesh_locidx_t nl0, nl1;
    octmesh_gloidx_t ng0, ng1;
    OK(octmesh_octree_get_num_leaves(h, &nl0, &ng0), h);
    calls = 0;
    OK(octmesh_octree_partition_for_coarsening(h, zero, &calls), h);
    OK(octmesh_octree_get_num_leaves(h, &nl1, &ng1), h);
    CHECK(calls == nl0 && nl1 == nl0 && ng1 == ng0, h);
    calls = 0;
    OK(octmesh_octree_partition_for_coarsening(h, by_level, &calls), h);
    OK(octmesh_octree_get_num_leaves(h, &nl1, &ng1), h);
    CHECK(calls == nl0 && ng1 == ng0, h);
  }

  /* Recursive coarsening of everything: more than one level at once (the
   * root on one rank; families split across ranks stay). */
  octmesh_locidx_t nl;
  octmesh_gloidx_t before, after, once;
  OK(octmesh_octree_get_num_leaves(h, &nl, &before), h);
  OK(octmesh_octree_coarsen(h, true, always, NULL, &coarsened), h);
  OK(octmesh_octree_get_num_leaves(h, &nl, &after), h);
  CHECK(after == before - 7 * coarsened, h);
  int size;
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  if (size == 1) CHECK(after == 1, h);
  OK(octmesh_octree_coarsen(h, false, always, NULL, NULL), h);
  OK(octmesh_octree_get_num_leaves(h, &nl, &once), h);
  CHECK(once == after, h); /* nothing left that a rank can coarsen */

  octmesh_destroy(h);
  if (counts != NULL) fclose(counts);
  printf("ADAPT OK rank %d\n", rank);
  MPI_Finalize();
  return 0;
}
