/* One meshing run from command-line-like settings, through the C API:
 *   settings SURFACE LEVEL KEEP CUT_RULE INSIDE_RULE CONNECT FIT
 *            [MAX_LEVEL ANGLE MIN_LEVEL BANDS [REGION ...]]
 * with KEEP, CUT_RULE, INSIDE_RULE and CONNECT as the C constants' values;
 * MAX_LEVEL and ANGLE for curvature refinement (MAX_LEVEL = LEVEL: none),
 * BANDS as "D1:L1,D2:L2" or "-", REGIONS in the command's form; FIT may be
 * "box:X0,Y0,Z0,X1,Y1,Z1:NX,NY,NZ" for a box domain instead; a REGION
 * "part:NAME=MIN:MAX" refines a part of the surface to its own levels
 * (octmesh_octree_refine_surface_part, with ANGLE).
 * Prints "COUNTS elements independent face_hanging edge_hanging" on rank 0,
 * for comparison with the octmesh command on the same settings. */
#include <stdlib.h>
#include "check.h"

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  if (argc != 8 && argc < 12) {
    fprintf(stderr, "usage: settings SURFACE LEVEL KEEP CUT_RULE INSIDE_RULE CONNECT FIT "
                    "[MAX_LEVEL ANGLE MIN_LEVEL BANDS [REGION ...]]\n");
    MPI_Abort(MPI_COMM_WORLD, 2);
  }
  octmesh_options_t opts;
  OK(octmesh_options_default(&opts), NULL);
  int box = strncmp(argv[7], "box:", 4) == 0;
  if (!box)
    opts.fit = atof(argv[7]);
  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, &opts, &h), NULL);
  if (box) {
    double lo[3], hi[3];
    int roots[3];
    if (sscanf(argv[7] + 4, "%lf,%lf,%lf,%lf,%lf,%lf:%d,%d,%d", &lo[0], &lo[1], &lo[2], &hi[0], &hi[1],
               &hi[2], &roots[0], &roots[1], &roots[2]) != 9) {
      fprintf(stderr, "settings: bad box '%s'\n", argv[7]);
      MPI_Abort(MPI_COMM_WORLD, 2);
    }
    /* A box whose cells are not cubes is refused, and the handle stays usable. */
    double tall[3] = {hi[0], hi[1], hi[2] + 0.5 * (hi[2] - lo[2])};
    CHECK_STATUS(octmesh_domain_set_box(h, lo, tall, roots), OCTMESH_STATUS_INVALID_ARGUMENT, h);
    CHECK(strstr(octmesh_last_error(h), "does not divide") != NULL, h);
    OK(octmesh_domain_set_box(h, lo, hi, roots), h);
  }
  if (strcmp(argv[1], "sphere") == 0 || strcmp(argv[1], "torus") == 0)
    OK(octmesh_surface_builtin(h, argv[1]), h);
  else
    OK(octmesh_surface_from_stl(h, argv[1]), h);
  OK(octmesh_octree_refine_surface(h, atoi(argv[2])), h);
  if (argc >= 12) {
    if (atoi(argv[8]) > atoi(argv[2]))
      OK(octmesh_octree_refine_curvature(h, atoi(argv[2]), atoi(argv[8]), atof(argv[9])), h);
    double d[16];
    int32_t l[16], nb = 0;
    for (char *t = strcmp(argv[11], "-") ? strtok(argv[11], ",") : NULL; t && nb < 16;
         t = strtok(NULL, ",")) {
      d[nb] = atof(t);
      l[nb++] = atoi(strchr(t, ':') + 1);
    }
    /* Parts first, as the command does (surface levels, then regions). */
    int nreg = 0;
    const char *regions[16];
    for (int a = 12; a < argc && nreg < 16; ++a) {
      char name[64];
      int lo, hi;
      if (sscanf(argv[a], "part:%63[^=]=%d:%d", name, &lo, &hi) == 3)
        OK(octmesh_octree_refine_surface_part(h, name, lo, hi, atof(argv[9])), h);
      else
        regions[nreg++] = argv[a];
    }
    OK(octmesh_octree_refine_regions(h, atoi(argv[10]), nreg, regions, nb, d, l), h);
  }
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
