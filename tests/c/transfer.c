/* Fields across adaptation steps through the C API: the moving sphere of
 * adapt.c (level 3 to 6) for six steps, each one adapt, balance (corner),
 * partition for coarsening and a new mesh, with the previous mesh kept.
 * Each step moves
 *  - a trilinear nodal field with two components, which must arrive exactly
 *    (1e-12) at every new node, hanging nodes included;
 *  - an element field, whose integral (volume x value) must be conserved;
 * and checks the element map against the new levels (refined: one old
 * element, level change > 0; coarsened: at least 8 old ones, < 0). Also:
 * calls before a previous mesh exists fail; a buffer too small and a NULL
 * field on one rank fail there and with REMOTE_FAILURE on the others; ncomp
 * 0 fails everywhere; the handle stays usable; turning the keeping off
 * drops the previous mesh.
 * Usage: transfer */
#include <math.h>
#include <stdlib.h>
#include "check.h"

#define MAX_LEVEL 6

static int g_step;

static bool all(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  (void)o;
  return true;
}

static int32_t adapt_sphere(void *ctx, const octmesh_octant_t *o) {
  (void)ctx;
  if (check_sphere_cuts(o, g_step)) return o->level < MAX_LEVEL ? 1 : 0;
  return -1;
}

static void field(const double *p, double *out) {
  const double x = p[0], y = p[1], z = p[2];
  out[0] = 1 + 2 * x - 3 * y + 0.5 * z + 4 * x * y - 2 * y * z + 3 * x * z + 5 * x * y * z;
  out[1] = -2 + x * y * z - 0.25 * x;
}

/* Local nodes and elements of the current mesh. */
static void sizes(octmesh_t *h, int *nodes, int *elements) {
  octmesh_mesh_counts_t c;
  OK(octmesh_mesh_get_counts(h, &c), h);
  *nodes = c.local_nodes;
  *elements = c.local_elements;
}

/* The trilinear field at every local node, and the element field
 * 1 + level + (element index mod 3) with the local integral. */
static void sample(octmesh_t *h, double **nodal, double **elem, double *integral) {
  int nn, ne;
  sizes(h, &nn, &ne);
  const double *xyz;
  const int8_t *level;
  OK(octmesh_mesh_get_coordinates(h, &xyz), h);
  OK(octmesh_mesh_get_element_level(h, &level), h);
  *nodal = malloc(sizeof **nodal * (size_t)(2 * nn + 1));
  *elem = malloc(sizeof **elem * (size_t)(ne + 1));
  for (int i = 0; i < nn; i++) field(xyz + 3 * i, *nodal + 2 * i);
  *integral = 0;
  for (int e = 0; e < ne; e++) {
    (*elem)[e] = 1.0 + level[e] + e % 3;
    *integral += ldexp(1.0, -3 * level[e]) * (*elem)[e];
  }
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  (void)argv;
  CHECK(argc == 1, NULL);
  int rank;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, NULL, &h), NULL);
  const double origin[3] = {0, 0, 0};
  OK(octmesh_domain_set(h, origin, 1.0), h);
  OK(octmesh_octree_refine_callback(h, 3, all, NULL), h);
  OK(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h);
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER), h);

  /* Nothing kept yet. */
  double dummy[2] = {0, 0};
  octmesh_element_map_t map;
  CHECK_STATUS(octmesh_mesh_transfer_nodes(h, 1, dummy, dummy, 2, NULL), OCTMESH_STATUS_STATE, h);
  CHECK_STATUS(octmesh_mesh_get_element_map(h, &map), OCTMESH_STATUS_STATE, h);
  OK(octmesh_mesh_keep_previous(h, true), h);

  long refined = 0, coarsened = 0;
  for (g_step = 1; g_step <= 6; g_step++) {
    double *nodal_old, *elem_old, integral_old;
    sample(h, &nodal_old, &elem_old, &integral_old);
    OK(octmesh_octree_adapt(h, adapt_sphere, NULL, NULL, NULL), h);
    OK(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h);
    OK(octmesh_octree_partition_for_coarsening(h, NULL, NULL), h);
    /* The octree changed and there is no new mesh yet. */
    CHECK_STATUS(octmesh_mesh_transfer_nodes(h, 2, nodal_old, dummy, 2, NULL), OCTMESH_STATUS_STATE,
                 h);
    OK(octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER), h);
    int nn, ne;
    sizes(h, &nn, &ne);

    /* Bad arguments: on every rank, the handle still usable. */
    double *nodal = malloc(sizeof *nodal * (size_t)(2 * nn + 1));
    const octmesh_status_t on_rank_0 =
        rank == 0 ? OCTMESH_STATUS_INVALID_ARGUMENT : OCTMESH_STATUS_REMOTE_FAILURE;
    CHECK_STATUS(octmesh_mesh_transfer_nodes(h, 2, nodal_old, nodal, rank == 0 ? 2 * nn - 1 : 2 * nn,
                                             NULL),
                 on_rank_0, h);
    CHECK_STATUS(octmesh_mesh_transfer_nodes(h, 0, nodal_old, nodal, 2 * nn, NULL),
                 OCTMESH_STATUS_INVALID_ARGUMENT, h);
    CHECK_STATUS(octmesh_mesh_transfer_elements(h, 1, rank == 0 ? NULL : elem_old, nodal, ne),
                 on_rank_0, h);

    /* The trilinear field arrives exactly. */
    octmesh_gloidx_t missing = -1;
    OK(octmesh_mesh_transfer_nodes(h, 2, nodal_old, nodal, 2 * nn, &missing), h);
    CHECK(missing == 0, h);
    const double *xyz;
    OK(octmesh_mesh_get_coordinates(h, &xyz), h);
    double worst = 0;
    for (int i = 0; i < nn; i++) {
      double want[2];
      field(xyz + 3 * i, want);
      for (int c = 0; c < 2; c++) worst = fmax(worst, fabs(nodal[2 * i + c] - want[c]));
    }
    CHECK(worst < 1e-12, h);

    /* The element field's integral is conserved. */
    double *elem = malloc(sizeof *elem * (size_t)(ne + 1));
    OK(octmesh_mesh_transfer_elements(h, 1, elem_old, elem, ne), h);
    const int8_t *level;
    OK(octmesh_mesh_get_element_level(h, &level), h);
    double sums[2] = {integral_old, 0};
    for (int e = 0; e < ne; e++) sums[1] += ldexp(1.0, -3 * level[e]) * elem[e];
    MPI_Allreduce(MPI_IN_PLACE, sums, 2, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
    CHECK(fabs(sums[0] - sums[1]) < 1e-12 * sums[0], h);

    /* The map agrees with the levels. */
    OK(octmesh_mesh_get_element_map(h, &map), h);
    CHECK(map.num_elements == ne && map.uncovered == 0, h);
    for (int e = 0; e < ne; e++) {
      CHECK(map.old_first[e] >= 0 && map.old_count[e] >= 1, h);
      if (map.level_change[e] > 0) {
        CHECK(map.old_count[e] == 1, h);
        ++refined;
      } else if (map.level_change[e] < 0) {
        CHECK(map.old_count[e] >= 8, h);
        ++coarsened;
      } else {
        CHECK(map.old_count[e] == 1, h);
      }
    }
    free(nodal_old);
    free(elem_old);
    free(nodal);
    free(elem);
  }
  long counts[2] = {refined, coarsened};
  MPI_Allreduce(MPI_IN_PLACE, counts, 2, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);
  CHECK(counts[0] > 0 && counts[1] > 0, h);

  /* Turning the keeping off drops the previous mesh. */
  OK(octmesh_mesh_keep_previous(h, false), h);
  CHECK_STATUS(octmesh_mesh_get_element_map(h, &map), OCTMESH_STATUS_STATE, h);
  if (rank == 0) printf("TRANSFER refined %ld coarsened %ld\n", counts[0], counts[1]);
  printf("TRANSFER OK\n");
  octmesh_destroy(h);
  MPI_Finalize();
  return 0;
}
