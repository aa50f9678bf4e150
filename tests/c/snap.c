/* Snapping through the C API, on the fluid mesh around the built-in sphere
 * (level 5, the command's defaults otherwise).
 * Usage: snap
 *
 * Checked on every rank: no report before a snap (state error), bad
 * arguments are invalid and change nothing, the counts add up, no element
 * is inverted and the quality's smallest scaled Jacobian is the report's,
 * every rank gets the same report. Prints on rank 0 "SNAP surface=...
 * snapped=... partial=... unsnapped=... reported=... sj_min=..." for
 * comparison with the command's statistics, and "SNAP OK" on every rank. */
#include <stdlib.h>
#include "check.h"

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);

  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, NULL, &h), NULL);
  check_balanced_sphere(h, 5);

  octmesh_snap_report_t r;
  CHECK_STATUS(octmesh_mesh_snap(h, 30.0, 2, 3, 0.001), OCTMESH_STATUS_STATE, h);
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_OUTSIDE, OCTMESH_CUT_RULE_CENTER), h);
  CHECK_STATUS(octmesh_mesh_get_snap_report(h, &r), OCTMESH_STATUS_STATE, h);
  CHECK_STATUS(octmesh_mesh_snap(h, 30.0, -1, 3, 0.001), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_mesh_snap(h, 200.0, 2, 3, 0.001), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_mesh_snap(h, 30.0, 2, 3, 0.0), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_mesh_snap(h, 30.0, 2, 3, 0.001), h);
  CHECK_STATUS(octmesh_mesh_get_snap_report(h, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_mesh_get_snap_report(h, &r), h);
  CHECK(r.snapped + r.partial + r.unsnapped == r.surface_nodes, h);
  CHECK(r.snapped > r.surface_nodes / 3 && r.min_scaled_jacobian > 0.0, h);

  octmesh_mesh_quality_t q;
  OK(octmesh_mesh_get_quality(h, &q), h);
  CHECK(q.inverted_elements == 0, h);
  CHECK(q.scaled_jacobian_min == r.min_scaled_jacobian, h);
  const double *xyz = NULL;
  OK(octmesh_mesh_get_coordinates(h, &xyz), h);
  CHECK(xyz != NULL, h);

  /* The same report on every rank. */
  double v[6] = {(double)r.surface_nodes, (double)r.snapped, (double)r.partial,
                 (double)r.unsnapped, (double)r.reported_elements, r.min_scaled_jacobian};
  double hi[6], lo[6];
  MPI_Allreduce(v, hi, 6, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
  MPI_Allreduce(v, lo, 6, MPI_DOUBLE, MPI_MIN, MPI_COMM_WORLD);
  CHECK(memcmp(hi, lo, sizeof hi) == 0, h);

  if (rank == 0) {
    printf("SNAP surface=%lld snapped=%lld partial=%lld unsnapped=%lld reported=%lld "
           "sj_min=%.17g\n",
           (long long)r.surface_nodes, (long long)r.snapped, (long long)r.partial,
           (long long)r.unsnapped, (long long)r.reported_elements, r.min_scaled_jacobian);
    fflush(stdout);
  }
  octmesh_destroy(h);
  printf("SNAP OK\n");
  MPI_Finalize();
  return 0;
}
