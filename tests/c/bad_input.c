/* Bad input and one-rank faults through the C API. Every collective call
 * must return the expected status on every rank (the statuses are gathered
 * to check), leave a message, leave the handle as it was, and the handle
 * must keep working afterwards.
 *
 * Usage:
 *   bad_input file PATH STATUS WORD...   create -> surface_from_stl(PATH) ->
 *       refine -> balance -> mesh; the first failing call must return STATUS
 *       (a name such as OCTMESH_STATUS_FORMAT) with every WORD in its message
 *   bad_input cases GOOD.stl MISSING.stl DIRECTORY
 *       levels above the maximum, octant limits (before refining, while
 *       refining, while balancing, on one rank only), "" and directory
 *       paths, a file readable on some ranks only, NULL pointers */
#include <stdlib.h>
#include "check.h"

static int rank, size;

static octmesh_status_t status_named(const char *name) {
  for (int s = 0; s < 16; s++)
    if (strcmp(octmesh_status_name(s), name) == 0) return (octmesh_status_t)s;
  fprintf(stderr, "unknown status name %s\n", name);
  MPI_Abort(MPI_COMM_WORLD, 3);
  return OCTMESH_STATUS_INTERNAL;
}

/* Every rank r must have got want_fail if r == failing (or failing < 0)
 * and want_other otherwise; checked on the gathered statuses, so that a
 * rank that got something else is reported by every rank. */
static void expect(octmesh_status_t got, int failing, octmesh_status_t want_fail,
                   octmesh_status_t want_other, octmesh_t *h, const char *what) {
  int mine = (int)got;
  int *all = malloc(sizeof(int) * (size_t)size);
  MPI_Allgather(&mine, 1, MPI_INT, all, 1, MPI_INT, MPI_COMM_WORLD);
  for (int r = 0; r < size; r++) {
    int want = (failing < 0 || r == failing) ? (int)want_fail : (int)want_other;
    if (all[r] != want) {
      fprintf(stderr, "CHECK FAILED rank %d: %s: rank %d returned %s, expected %s (my last error: %s)\n",
              rank, what, r, octmesh_status_name(all[r]), octmesh_status_name(want),
              octmesh_last_error(h));
      fflush(stderr);
      MPI_Abort(MPI_COMM_WORLD, 3);
    }
  }
  free(all);
  if (got != OCTMESH_STATUS_OK) CHECK(strlen(octmesh_last_error(h)) > 0, h);
}

static void expect_all(octmesh_status_t got, octmesh_status_t want, octmesh_t *h, const char *what) {
  expect(got, -1, want, want, h, what);
}

static void says(octmesh_t *h, const char *word) {
  if (strstr(octmesh_last_error(h), word) == NULL) {
    fprintf(stderr, "CHECK FAILED rank %d: message '%s' does not mention '%s'\n", rank,
            octmesh_last_error(h), word);
    fflush(stderr);
    MPI_Abort(MPI_COMM_WORLD, 3);
  }
}

static int64_t global_leaves(octmesh_t *h) {
  octmesh_locidx_t l = -1;
  octmesh_gloidx_t g = -1;
  OK(octmesh_octree_get_num_leaves(h, &l, &g), h);
  return g;
}

static int64_t local_leaves(octmesh_t *h) {
  octmesh_locidx_t l = -1;
  octmesh_gloidx_t g = -1;
  OK(octmesh_octree_get_num_leaves(h, &l, &g), h);
  return l;
}

/* The handle still works: the built-in sphere refined at level 3. */
static void still_works(octmesh_t *h) {
  OK(octmesh_surface_builtin(h, "sphere"), h);
  OK(octmesh_octree_refine_surface(h, 3), h);
  CHECK(global_leaves(h) > 8, h);
}

static octmesh_t *create(uint64_t max_octants) {
  octmesh_options_t o;
  OK(octmesh_options_default(&o), NULL);
  o.max_octants = max_octants;
  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, &o, &h), NULL);
  return h;
}

static void file_case(const char *path, octmesh_status_t want, int nwords, char **words) {
  octmesh_t *h = create(0);
  octmesh_status_t s = octmesh_surface_from_stl(h, path);
  const char *stage = "surface_from_stl";
  if (s == OCTMESH_STATUS_OK) {
    stage = "refine_surface";
    s = octmesh_octree_refine_surface(h, 3);
  }
  if (s == OCTMESH_STATUS_OK) {
    stage = "balance";
    s = octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER);
  }
  if (s == OCTMESH_STATUS_OK) {
    stage = "mesh";
    s = octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER);
  }
  expect_all(s, want, h, stage);
  for (int i = 0; i < nwords; i++) says(h, words[i]);
  /* Nothing was built from the bad file. */
  octmesh_locidx_t l;
  octmesh_gloidx_t g;
  CHECK_STATUS(octmesh_octree_get_num_leaves(h, &l, &g), OCTMESH_STATUS_STATE, h);
  still_works(h);
  octmesh_destroy(h);
}

/* Refines every octant on the rank whose flag is set, none elsewhere: the
 * work differs per rank, which is allowed when refining an existing octree
 * (each leaf is decided by its own rank only). */
static bool refine_if_flag(void *ctx, const octmesh_octant_t *o) {
  (void)o;
  return *(const int *)ctx;
}

static void cases(const char *good, const char *missing, const char *dir) {
  int last = size - 1;
  octmesh_t *h = create(0);

  /* NULL pointers. */
  CHECK_STATUS(octmesh_create(MPI_COMM_WORLD, NULL, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, NULL);
  CHECK_STATUS(octmesh_surface_from_stl(NULL, good), OCTMESH_STATUS_INVALID_ARGUMENT, NULL);
  CHECK(strstr(octmesh_last_error(NULL), "NULL") != NULL, NULL);
  expect_all(octmesh_surface_from_stl(h, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h, "NULL path");
  says(h, "path");
  expect(octmesh_surface_from_stl(h, rank == 0 ? NULL : good), 0, OCTMESH_STATUS_INVALID_ARGUMENT,
         OCTMESH_STATUS_REMOTE_FAILURE, h, "NULL path on rank 0");
  expect_all(octmesh_surface_from_triangles(h, 1, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h,
             "NULL triangles");
  expect_all(octmesh_surface_builtin(h, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h, "NULL name");
  expect_all(octmesh_domain_set(h, NULL, 1.0), OCTMESH_STATUS_INVALID_ARGUMENT, h, "NULL origin");
  still_works(h);
  int64_t g = -5;
  CHECK_STATUS(octmesh_octree_get_num_leaves(h, NULL, &g), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK(g == -5, h);
  octmesh_mesh_counts_t mc;
  CHECK_STATUS(octmesh_mesh_get_counts(h, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_mesh_get_counts(h, &mc), OCTMESH_STATUS_STATE, h);

  /* Paths: "", a directory, a file missing on the last rank only. */
  expect_all(octmesh_surface_from_stl(h, ""), OCTMESH_STATUS_INVALID_ARGUMENT, h, "empty path");
  says(h, "empty");
  expect_all(octmesh_surface_from_stl(h, dir), OCTMESH_STATUS_IO, h, "directory");
  says(h, "directory");
  OK(octmesh_surface_from_stl(h, good), h);
  OK(octmesh_octree_refine_surface(h, 3), h);
  int64_t before = global_leaves(h);
  expect(octmesh_surface_from_stl(h, rank == last ? missing : good), last, OCTMESH_STATUS_IO,
         OCTMESH_STATUS_REMOTE_FAILURE, h, "file missing on the last rank");
  says(h, missing);
  if (rank != last) {
    char who[32];
    snprintf(who, sizeof who, "rank %d", last);
    says(h, who);
  }
  /* The failed load kept the octree and the surface. */
  CHECK(global_leaves(h) == before, h);
  OK(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h);
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_INSIDE, OCTMESH_CUT_RULE_CENTER), h);
  OK(octmesh_mesh_get_counts(h, &mc), h);
  CHECK(mc.global_elements > 0, h);

  /* Levels above the maximum. */
  before = global_leaves(h);
  expect_all(octmesh_octree_refine_surface(h, 19), OCTMESH_STATUS_INVALID_ARGUMENT, h, "level 19");
  says(h, "19");
  expect_all(octmesh_octree_refine_surface(h, 1000000), OCTMESH_STATUS_INVALID_ARGUMENT, h, "level 1e6");
  int flag = 1;
  expect_all(octmesh_octree_refine_callback(h, 25, refine_if_flag, &flag), OCTMESH_STATUS_INVALID_ARGUMENT, h,
             "callback level 25");
  CHECK(global_leaves(h) == before, h);
  /* The mesh survived the failed calls. */
  OK(octmesh_mesh_get_counts(h, &mc), h);
  still_works(h);
  octmesh_destroy(h);

  /* Reference counts of the sphere at level 5, without a limit. */
  h = create(0);
  OK(octmesh_surface_builtin(h, "sphere"), h);
  OK(octmesh_octree_refine_surface(h, 5), h);
  int64_t refined5 = global_leaves(h);
  OK(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h);
  int64_t balanced5 = global_leaves(h);
  CHECK(balanced5 > refined5, h);
  octmesh_destroy(h);

  /* A limit far below the estimate: refused before refining, with the
   * estimate and a level that fits; the previous octree is kept. */
  h = create(400);
  OK(octmesh_surface_builtin(h, "sphere"), h);
  OK(octmesh_octree_refine_surface(h, 2), h);
  before = global_leaves(h);
  CHECK(before <= 400, h);
  expect_all(octmesh_octree_refine_surface(h, 6), OCTMESH_STATUS_LIMIT, h, "limit 400 at level 6");
  says(h, "limit of 400 octants");
  says(h, "estimated");
  says(h, "would fit");
  CHECK(global_leaves(h) == before, h);
  still_works(h);
  octmesh_destroy(h);

  /* A limit just below the count: fails while refining. */
  h = create((uint64_t)refined5 - 1);
  OK(octmesh_surface_builtin(h, "sphere"), h);
  OK(octmesh_octree_refine_surface(h, 3), h);
  before = global_leaves(h);
  expect_all(octmesh_octree_refine_surface(h, 5), OCTMESH_STATUS_LIMIT, h, "limit just below at level 5");
  says(h, "while refining");
  CHECK(global_leaves(h) == before, h);
  octmesh_destroy(h);

  /* A limit between the refined and the balanced count: the refinement
   * fits, the balance fails on every rank and keeps the octree. */
  h = create((uint64_t)refined5);
  OK(octmesh_surface_builtin(h, "sphere"), h);
  OK(octmesh_octree_refine_surface(h, 5), h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);
  int64_t local_before = local_leaves(h);
  expect_all(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), OCTMESH_STATUS_LIMIT, h, "balance limit");
  says(h, "balancing");
  CHECK(global_leaves(h) == refined5 && local_leaves(h) == local_before, h);
  /* Still unbalanced, so no mesh. */
  expect_all(octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER), OCTMESH_STATUS_STATE, h,
             "mesh after failed balance");
  still_works(h);
  octmesh_destroy(h);

  /* A limit hit on one rank only: the last rank refines all its leaves to
   * level 6, the others nothing. The last rank stops at the limit while
   * the others finish; every rank must still take part in the same
   * collectives and fail. */
  h = create(3000);
  OK(octmesh_surface_builtin(h, "sphere"), h);
  OK(octmesh_octree_refine_surface(h, 3), h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);
  local_before = local_leaves(h);
  before = global_leaves(h);
  flag = rank == last;
  expect_all(octmesh_octree_refine_callback(h, 6, refine_if_flag, &flag), OCTMESH_STATUS_LIMIT, h,
             "limit on the last rank");
  says(h, "limit of 3000 octants");
  CHECK(local_leaves(h) == local_before && global_leaves(h) == before, h);
  /* The same refinement on no rank succeeds and changes nothing. */
  flag = 0;
  OK(octmesh_octree_refine_callback(h, 6, refine_if_flag, &flag), h);
  CHECK(global_leaves(h) == before, h);
  still_works(h);
  octmesh_destroy(h);
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  CHECK(argc >= 2, NULL);
  if (strcmp(argv[1], "file") == 0) {
    CHECK(argc >= 4, NULL);
    file_case(argv[2], status_named(argv[3]), argc - 4, argv + 4);
  } else {
    CHECK(strcmp(argv[1], "cases") == 0 && argc == 5, NULL);
    cases(argv[2], argv[3], argv[4]);
  }
  printf("BAD INPUT OK rank %d\n", rank);
  MPI_Finalize();
  return 0;
}
