/* Full pipeline through the C API: built-in sphere, refine, balance,
 * partition, solid mesh, array checks, VTU (plain, and with point fields);
 * then refinement and weighted partition by C callbacks with a context.
 * Usage: pipeline OUT.pvtu FIELDS.pvtu
 * FIELDS.pvtu gets the point fields "x" (x coordinate of each node) and
 * "one"; the line "FIELDS points=... x_sum=... x_min=... x_max=..." gives
 * their expected statistics over all points written. */
#include <stdlib.h>
#include "check.h"

typedef struct {
  long calls;
  int max_level_seen;
} counter_t;

/* Refines the octants touching the lowest corner of the cube. */
static bool refine_corner(void *ctx, const octmesh_octant_t *o) {
  counter_t *c = (counter_t *)ctx;
  c->calls++;
  if (o->level > c->max_level_seen) c->max_level_seen = o->level;
  return o->x == 0 && o->y == 0 && o->z == 0;
}

static uint64_t weight_level(void *ctx, const octmesh_octant_t *o) {
  ((counter_t *)ctx)->calls++;
  return (uint64_t)(1 + o->level);
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank, size;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  CHECK(argc == 3, NULL);
  CHECK(OCTMESH_VERSION_MAJOR >= 0 && strlen(OCTMESH_VERSION_STRING) > 0, NULL);

  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, NULL, &h), NULL);
  CHECK(h != NULL, NULL);
  OK(octmesh_surface_builtin(h, "sphere"), h);
  OK(octmesh_octree_refine_surface(h, 5), h);
  octmesh_locidx_t nl = -1;
  octmesh_gloidx_t ng = -1;
  OK(octmesh_octree_get_num_leaves(h, &nl, &ng), h);
  CHECK(nl >= 0 && ng > 0, h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);
  OK(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);
  OK(octmesh_octree_get_num_leaves(h, &nl, &ng), h);
  octmesh_octant_t *leaves = malloc(sizeof(octmesh_octant_t) * (size_t)(nl + 1));
  OK(octmesh_octree_get_leaves(h, leaves, nl + 1), h);
  /* A buffer too small is refused, naming the size needed. */
  if (nl > 0) CHECK_STATUS(octmesh_octree_get_leaves(h, leaves, nl - 1), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  for (int64_t i = 0; i < nl; i++) CHECK(leaves[i].level >= 0 && leaves[i].level <= 5, h);
  free(leaves);
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_INSIDE, OCTMESH_CUT_RULE_CENTER), h);

  octmesh_mesh_counts_t c;
  OK(octmesh_mesh_get_counts(h, &c), h);
  CHECK(c.global_elements > 0 && c.global_independent > 0, h);
  CHECK(c.global_face_hanging + c.global_edge_hanging > 0, h);
  CHECK(c.num_owned <= c.num_independent && c.num_independent <= c.local_nodes, h);

  const octmesh_locidx_t *conn, *hcount, *hdeps, *soff;
  const int32_t *owners, *sranks;
  const double *xyz;
  const octmesh_gloidx_t *gid;
  const int8_t *cls, *lvl;
  OK(octmesh_mesh_get_connectivity(h, &conn), h);
  OK(octmesh_mesh_get_coordinates(h, &xyz), h);
  OK(octmesh_mesh_get_global_ids(h, &gid), h);
  OK(octmesh_mesh_get_owners(h, &owners), h);
  OK(octmesh_mesh_get_hanging(h, &hcount, &hdeps), h);
  OK(octmesh_mesh_get_sharers(h, &soff, &sranks), h);
  OK(octmesh_mesh_get_element_class(h, &cls), h);
  OK(octmesh_mesh_get_element_level(h, &lvl), h);
  for (int64_t e = 0; e < 8 * c.local_elements; e++)
    CHECK(conn[e] >= 0 && conn[e] < c.local_nodes, h);
  for (int64_t e = 0; e < c.local_elements; e++) {
    CHECK(cls[e] == OCTMESH_CLASS_INSIDE || cls[e] == OCTMESH_CLASS_CUT, h);
    CHECK(lvl[e] >= 1 && lvl[e] <= 5, h);
  }
  for (int64_t i = 0; i < 3 * c.local_nodes; i++) CHECK(xyz[i] > -2.0 && xyz[i] < 2.0, h);
  for (int64_t i = 0; i < c.num_independent; i++) {
    CHECK(gid[i] >= 0 && gid[i] < c.global_independent, h);
    CHECK(owners[i] >= 0 && owners[i] < size, h);
    CHECK((owners[i] == rank) == (i < c.num_owned), h);
    CHECK(soff[i + 1] > soff[i], h);
    int has_self = 0;
    for (int32_t k = soff[i]; k < soff[i + 1]; k++) has_self |= sranks[k] == rank;
    CHECK(has_self && sranks[soff[i]] == owners[i], h);
  }
  for (int64_t i = 0; i < c.num_owned; i++) CHECK(gid[i] == c.first_global + i, h);
  for (int64_t k = 0; k < c.local_nodes - c.num_independent; k++) {
    CHECK(hcount[k] == 2 || hcount[k] == 4, h);
    for (int j = 0; j < 4; j++) {
      if (j < hcount[k])
        CHECK(hdeps[4 * k + j] >= 0 && hdeps[4 * k + j] < c.num_independent, h);
      else
        CHECK(hdeps[4 * k + j] == -1, h);
    }
  }
  octmesh_locidx_t nn;
  const int32_t *xr;
  const octmesh_locidx_t *xo, *xn;
  OK(octmesh_mesh_get_exchange(h, &nn, &xr, &xo, &xn), h);
  CHECK(nn >= 0 && nn < size, h);
  for (int32_t k = 0; k < nn; k++) CHECK(xr[k] != rank && xo[k + 1] > xo[k], h);
  long owned = (long)c.num_owned, total = 0;
  MPI_Allreduce(&owned, &total, 1, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);
  CHECK(total == c.global_independent, h);
  OK(octmesh_mesh_write_vtu(h, argv[1]), h);
  /* The single-file finite-element meshes beside it: ARGV1.inp, .msh, .exo,
     .cgns. */
  char fe[4096];
  snprintf(fe, sizeof fe, "%s.inp", argv[1]);
  OK(octmesh_mesh_write_abaqus(h, fe), h);
  snprintf(fe, sizeof fe, "%s.msh", argv[1]);
  OK(octmesh_mesh_write_gmsh(h, fe), h);
  snprintf(fe, sizeof fe, "%s.exo", argv[1]);
  OK(octmesh_mesh_write_exodus(h, fe), h);
  snprintf(fe, sizeof fe, "%s.cgns", argv[1]);
  OK(octmesh_mesh_write_cgns(h, fe), h);
  /* The conforming mesh of this solid (ARGV1_conforming.msh, the bytes of
     the command's --conforming), then the hanging-node mesh again once
     conforming is off (ARGV1_hanging.msh). */
  snprintf(fe, sizeof fe, "%s_conforming.msh", argv[1]);
  OK(octmesh_mesh_set_conforming(h, true), h);
  OK(octmesh_mesh_write_gmsh(h, fe), h);
  OK(octmesh_mesh_set_conforming(h, false), h);
  snprintf(fe, sizeof fe, "%s_hanging.msh", argv[1]);
  OK(octmesh_mesh_write_gmsh(h, fe), h);
  /* The same mesh with two point fields: x of each node, and 1. */
  double *fx = malloc(sizeof(double) * (size_t)(c.local_nodes + 1));
  double *fone = malloc(sizeof(double) * (size_t)(c.local_nodes + 1));
  double st[3] = {0.0, 1e300, -1e300}; /* sum, min, max of x */
  for (int64_t i = 0; i < c.local_nodes; i++) {
    fx[i] = xyz[3 * i];
    fone[i] = 1.0;
    st[0] += fx[i];
    if (fx[i] < st[1]) st[1] = fx[i];
    if (fx[i] > st[2]) st[2] = fx[i];
  }
  const char *fnames[2] = {"x", "one"};
  const double *fvalues[2] = {fx, fone};
  /* Misuse first: bad count, NULL arrays (on one rank), a reserved name. */
  CHECK_STATUS(octmesh_mesh_write_vtu_fields(h, argv[2], -1, fnames, fvalues),
               OCTMESH_STATUS_INVALID_ARGUMENT, h);
  octmesh_status_t fs =
      octmesh_mesh_write_vtu_fields(h, argv[2], 2, fnames, rank == size - 1 ? NULL : fvalues);
  CHECK(fs == (rank == size - 1 ? OCTMESH_STATUS_INVALID_ARGUMENT
                                : OCTMESH_STATUS_REMOTE_FAILURE), h);
  const char *reserved[2] = {"x", "hanging"};
  CHECK_STATUS(octmesh_mesh_write_vtu_fields(h, argv[2], 2, reserved, fvalues),
               OCTMESH_STATUS_INVALID_ARGUMENT, h);
  const char *twice[2] = {"x", "x"};
  CHECK_STATUS(octmesh_mesh_write_vtu_fields(h, argv[2], 2, twice, fvalues),
               OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_mesh_write_vtu_fields(h, argv[2], 2, fnames, fvalues), h);
  double gst[3];
  long gnodes = 0, lnodes = (long)c.local_nodes;
  MPI_Allreduce(&st[0], &gst[0], 1, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  MPI_Allreduce(&st[1], &gst[1], 1, MPI_DOUBLE, MPI_MIN, MPI_COMM_WORLD);
  MPI_Allreduce(&st[2], &gst[2], 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
  MPI_Allreduce(&lnodes, &gnodes, 1, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);
  if (rank == 0)
    printf("FIELDS points=%ld x_sum=%.17g x_min=%.17g x_max=%.17g\n", gnodes, gst[0], gst[1],
           gst[2]);
  free(fx);
  free(fone);
  if (rank == 0)
    printf("SPHERE elements=%lld independent=%lld face=%lld edge=%lld leaves=%lld\n",
           (long long)c.global_elements, (long long)c.global_independent,
           (long long)c.global_face_hanging, (long long)c.global_edge_hanging, (long long)ng);
  /* The inside rule: auto chose parity for the closed sphere; the winding
   * number classifies it the same way. */
  octmesh_inside_rule_t used = -1;
  OK(octmesh_mesh_get_inside_rule(h, &used), h);
  CHECK(used == OCTMESH_INSIDE_RULE_PARITY, h);
  int64_t parity_elements = c.global_elements;
  OK(octmesh_mesh_set_inside_rule(h, OCTMESH_INSIDE_RULE_WINDING), h);
  OK(octmesh_mesh_get_inside_rule(h, &used), h);
  CHECK(used == OCTMESH_INSIDE_RULE_PARITY, h); /* until the next octmesh_mesh_build */
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_INSIDE, OCTMESH_CUT_RULE_CENTER), h);
  OK(octmesh_mesh_get_inside_rule(h, &used), h);
  CHECK(used == OCTMESH_INSIDE_RULE_WINDING, h);
  OK(octmesh_mesh_get_counts(h, &c), h);
  CHECK(c.global_elements == parity_elements, h);
  double origin[3], side;
  OK(octmesh_domain_get(h, origin, &side), h);
  CHECK(side > 2.0 && origin[0] < -1.0, h);
  /* A checkpoint of the octree with 8 bytes of data per leaf (its global
   * index): a missing file is refused with the handle intact, the saved
   * one gives the same leaves and data back. */
  octmesh_gloidx_t first = 0, mine = nl;
  MPI_Exscan(&mine, &first, 1, MPI_INT64_T, MPI_SUM, MPI_COMM_WORLD);
  if (rank == 0) first = 0;
  OK(octmesh_octree_data_set_size(h, 8), h);
  void *dp = NULL;
  octmesh_locidx_t dn = -1;
  OK(octmesh_octree_data_get(h, &dp, &dn), h);
  CHECK(dn == nl, h);
  for (int64_t i = 0; i < dn; i++) ((int64_t *)dp)[i] = first + i;
  snprintf(fe, sizeof fe, "%s.ckpt", argv[1]);
  OK(octmesh_octree_save(h, fe), h);
  CHECK_STATUS(octmesh_octree_load(h, "/nonexistent/octmesh.ckpt"), OCTMESH_STATUS_IO, h);
  octmesh_gloidx_t ng2 = -1;
  OK(octmesh_octree_get_num_leaves(h, &nl, &ng2), h);
  CHECK(ng2 == ng, h);
  OK(octmesh_octree_load(h, fe), h);
  OK(octmesh_octree_get_num_leaves(h, &nl, &ng2), h);
  CHECK(ng2 == ng, h);
  OK(octmesh_octree_data_get(h, &dp, &dn), h);
  CHECK(dn == nl, h);
  for (int64_t i = 0; i < dn; i++) CHECK(((int64_t *)dp)[i] == first + i, h);
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_INSIDE, OCTMESH_CUT_RULE_CENTER), h);
  OK(octmesh_mesh_get_counts(h, &c), h);
  CHECK(c.global_elements == parity_elements, h);
  octmesh_destroy(h);

  /* Callback refinement on the unit cube, counted through ctx. */
  counter_t ctr = {0, -1};
  OK(octmesh_create(MPI_COMM_WORLD, NULL, &h), NULL);
  OK(octmesh_octree_refine_callback(h, 4, refine_corner, &ctr), h);
  CHECK(ctr.calls > 0 && ctr.max_level_seen <= 3, h);
  OK(octmesh_octree_get_num_leaves(h, &nl, &ng), h);
  CHECK(ng == 1 + 7 * 4, h);
  OK(octmesh_octree_refine_callback(h, 6, refine_corner, &ctr), h); /* refines the tree */
  OK(octmesh_octree_get_num_leaves(h, &nl, &ng), h);
  CHECK(ng == 1 + 7 * 6, h);
  counter_t wctr = {0, 0};
  OK(octmesh_octree_partition(h, weight_level, &wctr), h);
  CHECK(wctr.calls == nl, h); /* once per local leaf before the move */
  OK(octmesh_octree_balance(h, OCTMESH_CONNECT_EDGE), h);
  CHECK_STATUS(octmesh_mesh_build(h, OCTMESH_KEEP_INSIDE, OCTMESH_CUT_RULE_CENTER),
               OCTMESH_STATUS_INVALID_ARGUMENT, h); /* no surface */
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER), h);
  OK(octmesh_mesh_get_inside_rule(h, &used), h);
  CHECK(used == OCTMESH_INSIDE_RULE_AUTO, h); /* nothing classified */
  OK(octmesh_mesh_get_counts(h, &c), h);
  OK(octmesh_octree_get_num_leaves(h, &nl, &ng), h);
  CHECK(c.global_elements == ng, h);
  OK(octmesh_mesh_get_coordinates(h, &xyz), h);
  for (int64_t i = 0; i < 3 * c.local_nodes; i++) CHECK(xyz[i] >= 0.0 && xyz[i] <= 1.0, h);
  if (rank == 0)
    printf("CALLBACK leaves=%lld elements=%lld independent=%lld\n", (long long)ng,
           (long long)c.global_elements, (long long)c.global_independent);
  octmesh_destroy(h);
  printf("PIPELINE OK rank %d\n", rank);
  MPI_Finalize();
  return 0;
}
