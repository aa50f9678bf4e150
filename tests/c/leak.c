/* The leak check through the C API: a closed sphere seals its centre; an
 * open box (a cube without its top) leaks to its centre with
 * OCTMESH_STATUS_LEAK and the same message on every rank; the closed cube
 * does not; bad points and calls out of order are refused.
 * Usage: leak */
#include <stdlib.h>
#include "check.h"

/* The 12 triangles of the cube [-0.5, 0.5]^3, outward; the last two are the
 * top face (z = 0.5). */
static void cube(double *xyz) {
  static const double v[8][3] = {{-.5, -.5, -.5}, {.5, -.5, -.5}, {-.5, .5, -.5}, {.5, .5, -.5},
                                 {-.5, -.5, .5},  {.5, -.5, .5},  {-.5, .5, .5},  {.5, .5, .5}};
  static const int t[12][3] = {{0, 2, 1}, {1, 2, 3}, {0, 1, 5}, {0, 5, 4}, {1, 3, 7}, {1, 7, 5},
                               {3, 2, 6}, {3, 6, 7}, {2, 0, 4}, {2, 4, 6}, {4, 5, 7}, {4, 7, 6}};
  for (int i = 0; i < 12; i++)
    for (int j = 0; j < 3; j++)
      for (int k = 0; k < 3; k++) xyz[9 * i + 3 * j + k] = v[t[i][j]][k];
}

static void build(octmesh_t *h, int level) {
  OK(octmesh_octree_refine_surface(h, level), h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);
  OK(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  const double centre[3] = {0.0, 0.0, 0.0};

  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, NULL, &h), NULL);
  /* No surface and no octree yet. */
  CHECK_STATUS(octmesh_octree_check_leak(h, centre), OCTMESH_STATUS_STATE, h);
  OK(octmesh_surface_builtin(h, "sphere"), h);
  CHECK_STATUS(octmesh_octree_check_leak(h, centre), OCTMESH_STATUS_STATE, h);
  build(h, 5);
  OK(octmesh_octree_check_leak(h, centre), h);
  CHECK_STATUS(octmesh_octree_check_leak(h, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  const double far[3] = {5.0, 0.0, 0.0};
  CHECK_STATUS(octmesh_octree_check_leak(h, far), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK(strstr(octmesh_last_error(h), "not in the cube") != NULL, h);

  /* The open box leaks. */
  double xyz[12 * 9];
  cube(xyz);
  OK(octmesh_surface_from_triangles(h, 10, xyz), h);
  build(h, 5);
  CHECK_STATUS(octmesh_octree_check_leak(h, centre), OCTMESH_STATUS_LEAK, h);
  const char *msg = octmesh_last_error(h);
  CHECK(strncmp(msg, "leak: ", 6) == 0 && strstr(msg, "a path of ") != NULL, h);
  CHECK(strcmp(octmesh_status_name(OCTMESH_STATUS_LEAK), "OCTMESH_STATUS_LEAK") == 0, h);
  /* The same message on every rank. */
  int len = (int)strlen(msg), len0 = len;
  MPI_Bcast(&len0, 1, MPI_INT, 0, MPI_COMM_WORLD);
  CHECK(len == len0, h);
  char *copy = malloc((size_t)len0 + 1);
  memcpy(copy, msg, (size_t)len0 + 1);
  MPI_Bcast(copy, len0 + 1, MPI_CHAR, 0, MPI_COMM_WORLD);
  CHECK(strcmp(copy, msg) == 0, h);
  free(copy);
  /* The handle still works: the fluid mesh can be built anyway. */
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_OUTSIDE, OCTMESH_CUT_RULE_CENTER), h);

  /* The closed cube seals its centre. */
  OK(octmesh_surface_from_triangles(h, 12, xyz), h);
  build(h, 5);
  OK(octmesh_octree_check_leak(h, centre), h);

  octmesh_destroy(h);
  printf("LEAK OK rank %d\n", rank);
  MPI_Finalize();
  return 0;
}
