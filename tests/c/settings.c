/* One meshing run from command-line-like settings, through the C API:
 *   settings SURFACE LEVEL KEEP CUT_RULE INSIDE_RULE CONNECT FIT
 * with KEEP, CUT_RULE, INSIDE_RULE and CONNECT as the C constants' values.
 * Prints "COUNTS elements independent face_hanging edge_hanging" on rank 0,
 * for comparison with the octmesh command on the same settings. */
#include <stdlib.h>
#include "check.h"

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  if (argc != 8) {
    fprintf(stderr, "usage: settings SURFACE LEVEL KEEP CUT_RULE INSIDE_RULE CONNECT FIT\n");
    MPI_Abort(MPI_COMM_WORLD, 2);
  }
  octmesh_options_t opts;
  OK(octmesh_options_default(&opts), NULL);
  opts.fit = atof(argv[7]);
  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, &opts, &h), NULL);
  if (strcmp(argv[1], "sphere") == 0 || strcmp(argv[1], "torus") == 0)
    OK(octmesh_surface_builtin(h, argv[1]), h);
  else
    OK(octmesh_surface_from_stl(h, argv[1]), h);
  OK(octmesh_octree_refine_surface(h, atoi(argv[2])), h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);
  OK(octmesh_octree_balance(h, atoi(argv[6])), h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);
  OK(octmesh_mesh_set_inside_rule(h, atoi(argv[5])), h);
  OK(octmesh_mesh_build(h, atoi(argv[3]), atoi(argv[4])), h);
  octmesh_mesh_counts_t c;
  OK(octmesh_mesh_get_counts(h, &c), h);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  if (rank == 0)
    printf("COUNTS %lld %lld %lld %lld\n", (long long)c.global_elements, (long long)c.global_independent,
           (long long)c.global_face_hanging, (long long)c.global_edge_hanging);
  octmesh_destroy(h);
  MPI_Finalize();
  return 0;
}
