/* The mesh's quality through the C API, on the fluid mesh around the
 * built-in sphere (level 5, the command's defaults otherwise).
 * Usage: quality
 *
 * Checked on every rank: no mesh is a state error, a NULL out an invalid
 * argument; the histogram sums to the elements, which equal the mesh's
 * global count; every rank gets the same figures. Prints on rank 0
 * "QUALITY elements=... inverted=... internal_faces=... sj_min=...
 * nonorth_max=... nonorth_average=... skewness_max=... histogram=c0,c1,..."
 * (doubles with 17 digits) for comparison with the command's statistics,
 * and "QUALITY OK" on every rank. */
#include <stdlib.h>
#include "check.h"

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);

  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, NULL, &h), NULL);
  check_balanced_sphere(h, 5);

  octmesh_mesh_quality_t q;
  CHECK_STATUS(octmesh_mesh_get_quality(h, &q), OCTMESH_STATUS_STATE, h);
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_OUTSIDE, OCTMESH_CUT_RULE_CENTER), h);
  CHECK_STATUS(octmesh_mesh_get_quality(h, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_mesh_get_quality(NULL, &q), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_mesh_get_quality(h, &q), h);

  octmesh_mesh_counts_t mc;
  OK(octmesh_mesh_get_counts(h, &mc), h);
  CHECK(q.elements == mc.global_elements, h);
  int64_t sum = 0;
  for (int k = 0; k < 20; k++) sum += q.scaled_jacobian_histogram[k];
  CHECK(sum == q.elements, h);
  CHECK(q.internal_faces > 0 && q.inverted_elements == 0, h);

  /* The same figures on every rank: the largest and smallest of each. */
  double v[4] = {q.scaled_jacobian_min, q.non_orthogonality_max,
                 q.non_orthogonality_average, q.skewness_max};
  double hi[4], lo[4];
  MPI_Allreduce(v, hi, 4, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
  MPI_Allreduce(v, lo, 4, MPI_DOUBLE, MPI_MIN, MPI_COMM_WORLD);
  CHECK(memcmp(hi, lo, sizeof hi) == 0, h);

  if (rank == 0) {
    printf("QUALITY elements=%lld inverted=%lld internal_faces=%lld sj_min=%.17g "
           "nonorth_max=%.17g nonorth_average=%.17g skewness_max=%.17g histogram=",
           (long long)q.elements, (long long)q.inverted_elements,
           (long long)q.internal_faces, q.scaled_jacobian_min, q.non_orthogonality_max,
           q.non_orthogonality_average, q.skewness_max);
    for (int k = 0; k < 20; k++)
      printf("%lld%s", (long long)q.scaled_jacobian_histogram[k], k < 19 ? "," : "\n");
    fflush(stdout);
  }
  octmesh_destroy(h);
  printf("QUALITY OK\n");
  MPI_Finalize();
  return 0;
}
