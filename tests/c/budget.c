/* The memory budget through the C API: octmesh_options_t.memory_budget.
 * Usage: budget IN_RUN_BUDGET_BYTES
 * 1. A budget of 80 MiB: the sphere at level 18 is refused before refining
 *    with OCTMESH_STATUS_LIMIT on every rank, naming the budget and the
 *    largest level that fits; the handle is still usable: level 4 meshes.
 * 2. A budget between the estimate and the real size of the sphere at level
 *    6 (given by the test): refinement passes the estimate check, and the
 *    in-run check stops balance with OCTMESH_STATUS_LIMIT ("grew past");
 *    the handle is still usable.
 * Prints "BUDGET OK" on every rank. */
#include <stdlib.h>
#include "check.h"

static void fails_with_budget(octmesh_status_t s, octmesh_t *h, const char *words) {
  CHECK(s == OCTMESH_STATUS_LIMIT, h);
  CHECK(strstr(octmesh_last_error(h), "memory budget") != NULL, h);
  CHECK(strstr(octmesh_last_error(h), words) != NULL, h);
}

static void still_meshes(octmesh_t *h) {
  OK(octmesh_octree_refine_surface(h, 4), h);
  OK(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h);
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_INSIDE, OCTMESH_CUT_RULE_CENTER), h);
  octmesh_mesh_counts_t c;
  OK(octmesh_mesh_get_counts(h, &c), h);
  CHECK(c.global_elements > 0, h);
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  CHECK(argc == 2, NULL);
  octmesh_options_t opts;
  OK(octmesh_options_default(&opts), NULL);

  opts.memory_budget = 80ll << 20;
  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, &opts, &h), NULL);
  OK(octmesh_surface_builtin(h, "sphere"), h);
  fails_with_budget(octmesh_octree_refine_surface(h, 18), h, "would fit");
  CHECK(strstr(octmesh_last_error(h), "80 MiB") != NULL, h);
  still_meshes(h);
  octmesh_destroy(h);

  opts.memory_budget = atoll(argv[1]);
  OK(octmesh_create(MPI_COMM_WORLD, &opts, &h), NULL);
  OK(octmesh_surface_builtin(h, "sphere"), h);
  octmesh_status_t s = octmesh_octree_refine_surface(h, 6);
  if (s == OCTMESH_STATUS_OK) {
    OK(octmesh_octree_partition(h, NULL, NULL), h);
    s = octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER);
  }
  fails_with_budget(s, h, "grew past");
  still_meshes(h);
  octmesh_destroy(h);

  printf("BUDGET OK\n");
  MPI_Finalize();
  return 0;
}
