/* Misuse of the C API: NULL arguments, calls out of order, bad values,
 * unreadable files (also on some ranks only), limits; after each failure
 * the handle must still work.
 * Usage: misuse GOOD.stl MISSING.stl */
#include <stdlib.h>
#include "check.h"

static int contains(const char *s, const char *what) { return strstr(s, what) != NULL; }

int main(int argc, char **argv) {
  octmesh_t *h = NULL;
  /* Before MPI_Init: a status, not a crash; out untouched. */
  CHECK_STATUS(octmesh_create(MPI_COMM_WORLD, NULL, &h), OCTMESH_STATUS_MPI, NULL);
  CHECK(h == NULL && contains(octmesh_last_error(NULL), "MPI_Init"), NULL);

  MPI_Init(&argc, &argv);
  int rank, size;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  CHECK(argc == 3, NULL);
  const char *good = argv[1], *missing = argv[2];

  /* NULL handle and out pointers; destroy(NULL). */
  octmesh_destroy(NULL);
  CHECK_STATUS(octmesh_create(MPI_COMM_WORLD, NULL, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, NULL);
  CHECK(contains(octmesh_last_error(NULL), "out"), NULL);
  CHECK_STATUS(octmesh_octree_balance(NULL, OCTMESH_CONNECT_FACE), OCTMESH_STATUS_INVALID_ARGUMENT, NULL);
  CHECK(contains(octmesh_last_error(NULL), "NULL"), NULL);
  CHECK_STATUS(octmesh_options_default(NULL), OCTMESH_STATUS_INVALID_ARGUMENT, NULL);
  CHECK(strcmp(octmesh_status_name(OCTMESH_STATUS_STATE), "OCTMESH_STATUS_STATE") == 0, NULL);
  CHECK(strcmp(octmesh_status_name(42), "OCTMESH_STATUS_UNKNOWN") == 0, NULL);

  /* Bad options. */
  octmesh_options_t opts;
  OK(octmesh_options_default(&opts), NULL);
  CHECK(opts.fit == 0.7 && opts.max_octants == 0, NULL);
  opts.fit = 2.0;
  CHECK_STATUS(octmesh_create(MPI_COMM_WORLD, &opts, &h), OCTMESH_STATUS_INVALID_ARGUMENT, NULL);
  CHECK(h == NULL && contains(octmesh_last_error(NULL), "fit"), NULL);

  opts.fit = 0.7;
  opts.max_octants = 2000;
  OK(octmesh_create(MPI_COMM_WORLD, &opts, &h), NULL);
  CHECK(strlen(octmesh_last_error(h)) == 0, h);

  /* Out of order. */
  octmesh_locidx_t nl = -7;
  octmesh_gloidx_t ng = -7;
  CHECK_STATUS(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), OCTMESH_STATUS_STATE, h);
  CHECK(contains(octmesh_last_error(h), "octmesh_octree_refine_surface"), h);
  CHECK_STATUS(octmesh_octree_partition(h, NULL, NULL), OCTMESH_STATUS_STATE, h);
  CHECK_STATUS(octmesh_octree_get_num_leaves(h, &nl, &ng), OCTMESH_STATUS_STATE, h);
  CHECK(nl == -7 && ng == -7, h); /* out-params untouched on failure */
  CHECK_STATUS(octmesh_octree_refine_surface(h, 3), OCTMESH_STATUS_STATE, h);
  CHECK(contains(octmesh_last_error(h), "octmesh_surface_from_stl"), h);
  CHECK_STATUS(octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER), OCTMESH_STATUS_STATE, h);
  octmesh_mesh_counts_t c;
  CHECK_STATUS(octmesh_mesh_get_counts(h, &c), OCTMESH_STATUS_STATE, h);
  CHECK(contains(octmesh_last_error(h), "octmesh_mesh_build"), h);
  /* Untouched on failure: a value outside the enumeration stays. */
  octmesh_inside_rule_t ir = (octmesh_inside_rule_t)42;
  CHECK_STATUS(octmesh_mesh_get_inside_rule(h, &ir), OCTMESH_STATUS_STATE, h);
  CHECK(ir == (octmesh_inside_rule_t)42, h);
  CHECK_STATUS(octmesh_mesh_set_inside_rule(h, 3), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK(contains(octmesh_last_error(h), "inside rule"), h);
  if (size > 1) /* different rules on different ranks: every rank fails */
    CHECK_STATUS(octmesh_mesh_set_inside_rule(h, rank == 0 ? OCTMESH_INSIDE_RULE_PARITY
                                                      : OCTMESH_INSIDE_RULE_WINDING),
                 OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_mesh_set_inside_rule(h, OCTMESH_INSIDE_RULE_WINDING), h);

  /* Missing file: IO with the path in the message. */
  CHECK_STATUS(octmesh_surface_from_stl(h, missing), OCTMESH_STATUS_IO, h);
  CHECK(contains(octmesh_last_error(h), missing), h);
  /* NULL path on the last rank only: every rank fails. */
  octmesh_status_t s = octmesh_surface_from_stl(h, rank == size - 1 ? NULL : good);
  CHECK(s != OCTMESH_STATUS_OK, h);
  if (rank == size - 1) CHECK(s == OCTMESH_STATUS_INVALID_ARGUMENT, h);
  /* A file readable on rank 0 only: every rank fails, nobody hangs. */
  s = octmesh_surface_from_stl(h, rank == 0 ? good : missing);
  if (size == 1) {
    CHECK(s == OCTMESH_STATUS_OK, h);
  } else {
    CHECK(s != OCTMESH_STATUS_OK, h);
    CHECK(contains(octmesh_last_error(h), missing), h);
  }
  /* Bad triangles. */
  double tri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  CHECK_STATUS(octmesh_surface_from_triangles(h, 0, tri), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_surface_from_triangles(h, 1, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  tri[4] = 0.0 / 0.0;
  CHECK_STATUS(octmesh_surface_from_triangles(h, 1, tri), OCTMESH_STATUS_GEOMETRY, h);
  CHECK_STATUS(octmesh_surface_builtin(h, "cube"), OCTMESH_STATUS_INVALID_ARGUMENT, h);

  /* The handle still works after the failures. */
  OK(octmesh_surface_from_stl(h, good), h);
  CHECK_STATUS(octmesh_octree_refine_surface(h, 19), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK(contains(octmesh_last_error(h), "19"), h);
  CHECK_STATUS(octmesh_octree_refine_surface(h, -1), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_octree_refine_callback(h, 3, NULL, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  /* The octant limit of the options. */
  CHECK_STATUS(octmesh_octree_refine_surface(h, 6), OCTMESH_STATUS_LIMIT, h);
  CHECK_STATUS(octmesh_octree_get_num_leaves(h, &nl, &ng), OCTMESH_STATUS_STATE, h);
  OK(octmesh_octree_refine_surface(h, 3), h);
  OK(octmesh_octree_get_num_leaves(h, &nl, &ng), h);
  CHECK(ng > 8 && ng <= 2000, h);
  CHECK_STATUS(octmesh_octree_get_num_leaves(h, NULL, &ng), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK(contains(octmesh_last_error(h), "local"), h);
  CHECK_STATUS(octmesh_octree_balance(h, 99), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  /* Face balance is not enough to mesh. */
  OK(octmesh_octree_balance(h, OCTMESH_CONNECT_FACE), h);
  CHECK_STATUS(octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER), OCTMESH_STATUS_STATE, h);
  OK(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h);
  CHECK_STATUS(octmesh_mesh_build(h, 7, OCTMESH_CUT_RULE_CENTER), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_mesh_build(h, OCTMESH_KEEP_OUTSIDE, -1), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_OUTSIDE, OCTMESH_CUT_RULE_NONE), h);
  CHECK_STATUS(octmesh_mesh_get_inside_rule(h, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_mesh_get_inside_rule(h, &ir), h);
  CHECK(ir == OCTMESH_INSIDE_RULE_WINDING, h);
  OK(octmesh_mesh_get_counts(h, &c), h);
  CHECK(c.global_elements > 0, h);
  CHECK_STATUS(octmesh_mesh_get_connectivity(h, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  /* NULL path on rank 0 only: every rank fails. */
  s = octmesh_mesh_write_vtu(h, rank == 0 ? NULL : "never-written.pvtu");
  CHECK(s == (rank == 0 ? OCTMESH_STATUS_INVALID_ARGUMENT : OCTMESH_STATUS_REMOTE_FAILURE), h);
  CHECK_STATUS(octmesh_mesh_write_vtu(h, "/nonexistent-dir/x.pvtu"), OCTMESH_STATUS_IO, h);
  /* Setting the domain: bad values fail, good ones apply to the next build. */
  double o[3] = {-2, -2, -2};
  CHECK_STATUS(octmesh_domain_set(h, o, -1.0), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_domain_set(h, NULL, 4.0), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_domain_set(h, o, 4.0), h);
  OK(octmesh_octree_refine_surface(h, 3), h);
  double o2[3], side = 0;
  OK(octmesh_domain_get(h, o2, &side), h);
  CHECK(side == 4.0 && o2[0] == -2.0, h);
  octmesh_destroy(h);
  printf("MISUSE OK rank %d\n", rank);
  MPI_Finalize();
  return 0;
}
