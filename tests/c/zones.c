/* Zones through the C API: the sphere at level 4 meshed keeping every leaf
 * with zones. Zones without OCTMESH_KEEP_ALL fail on every rank and leave
 * the handle usable; a refinement region's zone appears third and takes
 * the elements whose centre it holds, from the inside and the outside
 * (whose counts the meshes keeping inside and outside bound); the
 * OpenFOAM case and the Gmsh file are written.
 * Usage: zones CASE_DIR MSH_FILE
 * Prints "ZONES inside=N outside=M east=K" on rank 0. */
#include "check.h"

static long global_sum(long v) {
  long s = 0;
  MPI_Allreduce(&v, &s, 1, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);
  return s;
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  CHECK(argc == 3, NULL);
  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, NULL, &h), NULL);
  OK(octmesh_surface_builtin(h, "sphere"), h);
  OK(octmesh_octree_refine_surface(h, 4), h);
  const char *regions[1] = {"box:0.5,-9,-9,9,9,9:0:zone=east"};
  OK(octmesh_octree_refine_regions(h, 0, 1, regions, 0, NULL, NULL), h);
  OK(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);

  /* Without zones: the counts to compare with, and no zones to get. */
  octmesh_mesh_counts_t c;
  long kept[2];
  const octmesh_keep_t keeps[2] = {OCTMESH_KEEP_INSIDE, OCTMESH_KEEP_OUTSIDE};
  for (int k = 0; k < 2; k++) {
    OK(octmesh_mesh_build(h, keeps[k], OCTMESH_CUT_RULE_CENTER), h);
    OK(octmesh_mesh_get_counts(h, &c), h);
    kept[k] = (long)c.global_elements;
  }
  octmesh_locidx_t nz = -1;
  const octmesh_locidx_t *zone = NULL;
  CHECK_STATUS(octmesh_mesh_get_zones(h, &nz, &zone), OCTMESH_STATUS_STATE, h);

  OK(octmesh_mesh_set_zones(h, true), h);
  CHECK_STATUS(octmesh_mesh_build(h, OCTMESH_KEEP_INSIDE, OCTMESH_CUT_RULE_CENTER),
               OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK(strstr(octmesh_last_error(h), "keep all") != NULL, h);
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER), h);
  OK(octmesh_mesh_get_counts(h, &c), h);
  OK(octmesh_mesh_get_zones(h, &nz, &zone), h);
  CHECK(nz == 3, h);
  const char *want[3] = {"inside", "outside", "east"};
  for (int z = 0; z < 3; z++) {
    const char *name = NULL;
    OK(octmesh_mesh_get_zone_name(h, z, &name), h);
    CHECK(strcmp(name, want[z]) == 0, h);
  }
  const char *name = NULL;
  CHECK_STATUS(octmesh_mesh_get_zone_name(h, 3, &name), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_mesh_get_zones(h, NULL, &zone), OCTMESH_STATUS_INVALID_ARGUMENT, h);

  /* Each element's zone from its centre: east where x > 0.5, else the
   * zone the mesh gave it (inside or outside). */
  const double *xyz;
  const octmesh_locidx_t *conn;
  OK(octmesh_mesh_get_coordinates(h, &xyz), h);
  OK(octmesh_mesh_get_connectivity(h, &conn), h);
  long n[3] = {0, 0, 0};
  for (int64_t e = 0; e < c.local_elements; e++) {
    CHECK(zone[e] >= 0 && zone[e] < 3, h);
    double x = 0.0;
    for (int v = 0; v < 8; v++) x += xyz[3 * conn[8 * e + v]] / 8.0;
    CHECK((zone[e] == 2) == (x >= 0.5), h);
    n[zone[e]]++;
  }
  for (int z = 0; z < 3; z++) n[z] = global_sum(n[z]);
  CHECK(n[0] + n[1] + n[2] == (long)c.global_elements, h);
  CHECK(n[2] > 0 && n[0] < kept[0] && n[1] < kept[1], h);

  OK(octmesh_mesh_write_openfoam(h, argv[1], OCTMESH_FOAM_FORMAT_ASCII, true), h);
  OK(octmesh_mesh_write_gmsh(h, argv[2]), h);
  if (rank == 0) printf("ZONES inside=%ld outside=%ld east=%ld\n", n[0], n[1], n[2]);
  octmesh_destroy(h);
  MPI_Finalize();
  return 0;
}
