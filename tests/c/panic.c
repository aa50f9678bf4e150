/* The panic boundary (library built with the cargo feature
 * ffi-test-panic): a panic becomes OCTMESH_STATUS_INTERNAL, the handle
 * then refuses work, and destroy still works. */
#include "check.h"

octmesh_status_t octmesh_test_panic(octmesh_t *h);

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, NULL, &h), NULL);
  CHECK_STATUS(octmesh_test_panic(h), OCTMESH_STATUS_INTERNAL, h);
  CHECK(strncmp(octmesh_last_error(h), "panic: ", 7) == 0, h);
  CHECK(strstr(octmesh_last_error(h), "test panic requested") != NULL, h);
  CHECK_STATUS(octmesh_surface_builtin(h, "sphere"), OCTMESH_STATUS_INTERNAL, h);
  CHECK(strstr(octmesh_last_error(h), "destroy") != NULL, h);
  octmesh_destroy(h);
  printf("PANIC OK rank %d\n", rank);
  MPI_Finalize();
  return 0;
}
