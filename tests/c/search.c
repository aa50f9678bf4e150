/* Point location through the C API, in the fluid mesh of the sphere at
 * level 4 in the cube [-2, 2]^3:
 * - every rank locates the lowest corners and the centres of its own
 *   leaves: a corner belongs to the leaf above it (half-open boxes), so both
 *   give this rank and the leaf's global index;
 * - every rank locates the same grid of points (the lattice of level 4, the
 *   cube's faces included) plus outside and NaN points; the answers are the
 *   same on every rank, outside points get -1, and a line of checksums is
 *   printed for the driver to compare between rank counts;
 * - the mesh variant: the centre of the sphere is in a leaf but no element,
 *   elements are numbered like the leaves they are;
 * - bad calls: no octree or mesh yet, a negative count, NULL arrays; a rank
 *   may pass no points (NULL arrays with n = 0).
 * Usage: search */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include "check.h"

#define GRID 17
#define EXTRA 4
#define NPTS (GRID * GRID * GRID + EXTRA)

static double user(int32_t lattice) { return -2.0 + lattice * (4.0 / 524288.0); }

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank, size;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);

  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, NULL, &h), NULL);
  const double origin[3] = {-2.0, -2.0, -2.0};
  OK(octmesh_domain_set(h, origin, 4.0), h);
  double one[3] = {0.0, 0.0, 0.0};
  int32_t r1;
  int64_t g1;
  CHECK_STATUS(octmesh_octree_locate_points(h, 1, one, &r1, &g1), OCTMESH_STATUS_STATE, h);
  check_balanced_sphere(h, 4);
  CHECK_STATUS(octmesh_mesh_locate_points(h, 1, one, &r1, &g1), OCTMESH_STATUS_STATE, h);
  /* A bad argument on one rank fails the call on every rank. */
  CHECK_STATUS(octmesh_octree_locate_points(h, rank == 0 ? -1 : 1, one, &r1, &g1),
               rank == 0 ? OCTMESH_STATUS_INVALID_ARGUMENT : OCTMESH_STATUS_REMOTE_FAILURE, h);
  CHECK_STATUS(octmesh_octree_locate_points(h, 1, one, NULL, &g1),
               OCTMESH_STATUS_INVALID_ARGUMENT, h);

  /* Own leaves: corners and centres. */
  int32_t nlocal;
  int64_t nglobal, first = 0;
  OK(octmesh_octree_get_num_leaves(h, &nlocal, &nglobal), h);
  int64_t n64 = nlocal;
  MPI_Exscan(&n64, &first, 1, MPI_INT64_T, MPI_SUM, MPI_COMM_WORLD);
  if (rank == 0) first = 0;
  octmesh_octant_t *leaves = malloc(sizeof *leaves * (size_t)(nlocal > 0 ? nlocal : 1));
  OK(octmesh_octree_get_leaves(h, leaves, nlocal), h);
  int n = 2 * nlocal;
  double *xyz = malloc(sizeof(double) * 3 * (size_t)(n > 0 ? n : 1));
  int32_t *ranks = malloc(sizeof(int32_t) * (size_t)(n > 0 ? n : 1));
  int64_t *ids = malloc(sizeof(int64_t) * (size_t)(n > 0 ? n : 1));
  for (int i = 0; i < nlocal; i++) {
    int32_t half = (int32_t)(1 << (19 - leaves[i].level)) / 2;
    int32_t c[3] = {leaves[i].x, leaves[i].y, leaves[i].z};
    for (int k = 0; k < 3; k++) {
      xyz[6 * i + k] = user(c[k]);
      xyz[6 * i + 3 + k] = user(c[k] + half);
    }
  }
  OK(octmesh_octree_locate_points(h, n, xyz, ranks, ids), h);
  for (int i = 0; i < n; i++) CHECK(ranks[i] == rank && ids[i] == first + i / 2, h);

  /* The same grid everywhere; the last rank of several passes nothing
   * first, then the grid. */
  double *grid = malloc(sizeof(double) * 3 * NPTS);
  int p = 0;
  for (int i = 0; i < GRID; i++)
    for (int j = 0; j < GRID; j++)
      for (int k = 0; k < GRID; k++) {
        grid[3 * p] = -2.0 + 0.25 * i;
        grid[3 * p + 1] = -2.0 + 0.25 * j;
        grid[3 * p + 2] = -2.0 + 0.25 * k;
        p++;
      }
  const double extra[EXTRA][3] = {{5.0, 0.0, 0.0}, {-2.0, -2.0, -2.0000001}, {NAN, 0.0, 0.0},
                                  {0.1, 0.2, 0.3}};
  for (int e = 0; e < EXTRA; e++)
    for (int k = 0; k < 3; k++) grid[3 * (p + e) + k] = extra[e][k];
  int32_t *gr = malloc(sizeof(int32_t) * NPTS);
  int64_t *gl = malloc(sizeof(int64_t) * NPTS);
  if (size > 1 && rank == size - 1)
    OK(octmesh_octree_locate_points(h, 0, NULL, NULL, NULL), h);
  else
    OK(octmesh_octree_locate_points(h, NPTS, grid, gr, gl), h);
  if (size > 1) {
    if (rank == size - 1) OK(octmesh_octree_locate_points(h, NPTS, grid, gr, gl), h);
    else OK(octmesh_octree_locate_points(h, 0, NULL, NULL, NULL), h);
  }
  CHECK(gr[NPTS - 4] == -1 && gl[NPTS - 4] == -1, h);
  CHECK(gr[NPTS - 3] == -1 && gl[NPTS - 3] == -1, h);
  CHECK(gr[NPTS - 2] == -1 && gl[NPTS - 2] == -1, h);
  int64_t sum = 0, outside = 0;
  for (int i = 0; i < NPTS; i++) {
    CHECK((gr[i] < 0) == (gl[i] < 0), h);
    CHECK(gr[i] < size && gl[i] < nglobal, h);
    if (gl[i] < 0) outside++;
    else sum += gl[i] * (i + 1);
  }
  CHECK(outside == 3, h);
  /* The grid's last point (2, 2, 2) is the cube's corner: the last leaf. */
  CHECK(gl[GRID * GRID * GRID - 1] == nglobal - 1 && gr[GRID * GRID * GRID - 1] == size - 1, h);
  int64_t sum0 = sum;
  MPI_Bcast(&sum0, 1, MPI_INT64_T, 0, MPI_COMM_WORLD);
  CHECK(sum0 == sum, h);

  /* Elements. */
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_OUTSIDE, OCTMESH_CUT_RULE_CENTER), h);
  int64_t *el = malloc(sizeof(int64_t) * NPTS);
  int32_t *er = malloc(sizeof(int32_t) * NPTS);
  OK(octmesh_mesh_locate_points(h, NPTS, grid, er, el), h);
  int64_t esum = 0, no_element = 0;
  for (int i = 0; i < NPTS; i++) {
    CHECK(er[i] == gr[i], h);
    if (er[i] >= 0 && el[i] < 0) no_element++;
    if (el[i] >= 0) esum += el[i] * (i + 1);
  }
  /* The origin (grid point 8, 8, 8) is inside the body. */
  int centre = (8 * GRID + 8) * GRID + 8;
  CHECK(er[centre] >= 0 && el[centre] == -1, h);
  CHECK(no_element > 0, h);
  /* The cube's corner is in an element, the last one. */
  octmesh_mesh_counts_t counts;
  OK(octmesh_mesh_get_counts(h, &counts), h);
  CHECK(el[GRID * GRID * GRID - 1] == counts.global_elements - 1, h);

  if (rank == 0)
    printf("SEARCH sum=%lld outside=%lld esum=%lld no_element=%lld\n", (long long)sum,
           (long long)outside, (long long)esum, (long long)no_element);
  free(leaves); free(xyz); free(ranks); free(ids); free(grid); free(gr); free(gl);
  free(el); free(er);
  octmesh_destroy(h);
  printf("SEARCH OK rank %d\n", rank);
  MPI_Finalize();
  return 0;
}
