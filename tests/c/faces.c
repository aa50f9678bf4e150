/* Finite-volume faces, cell halo, boundary and OpenFOAM output through the
 * C API, on the fluid mesh around the built-in torus (level 5).
 * Usage: faces CASE_DIR
 *
 * Checked on every rank, from the arrays alone:
 * - every cell closes (sum of area * normal over its faces is zero) and
 *   its volume is (1/3) sum of (centre . normal) area over its faces;
 * - the cell halo: both ranks of a pair list as many elements; sending the
 *   global numbers and centres of the send lists gives, in the receive
 *   lists, the halo elements' global numbers, and centres on the far side
 *   of each shared face;
 * - boundary nodes: an independent node has patches exactly when it is a
 *   corner of fewer than 8 kept elements (counted over all ranks), the
 *   Poisson example's old rule; each boundary face's element face is in
 *   the finite-element list with its patch;
 * - patch names and renames, bad names refused on every rank; the state
 *   and argument errors; the OpenFOAM case written, refused without
 *   overwrite, replaced with it.
 * Prints "FACES internal=... boundary=... per-patch... boundary_nodes=..."
 * (global, independent of the number of ranks) and "FACES OK". */
#include <math.h>
#include <stdlib.h>
#include <sys/stat.h>
#include "check.h"

static double dot3(const double *a, const double *b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank, size;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  CHECK(argc == 2, NULL);

  octmesh_t *h = NULL;
  OK(octmesh_create(MPI_COMM_WORLD, NULL, &h), NULL);
  OK(octmesh_surface_builtin(h, "torus"), h);
  OK(octmesh_octree_refine_surface(h, 5), h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);
  OK(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h);
  OK(octmesh_octree_partition(h, NULL, NULL), h);

  /* Faces need a mesh, then octmesh_mesh_build_faces. */
  CHECK_STATUS(octmesh_mesh_build_faces(h), OCTMESH_STATUS_STATE, h);
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_OUTSIDE, OCTMESH_CUT_RULE_CENTER), h);
  octmesh_faces_t f;
  CHECK_STATUS(octmesh_mesh_get_faces(h, &f), OCTMESH_STATUS_STATE, h);
  OK(octmesh_mesh_build_faces(h), h);
  CHECK_STATUS(octmesh_mesh_get_faces(h, NULL), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_mesh_get_faces(NULL, &f), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_mesh_get_faces(h, &f), h);
  octmesh_cell_halo_t c;
  OK(octmesh_mesh_get_cell_halo(h, &c), h);
  octmesh_boundary_t b;
  OK(octmesh_mesh_get_boundary(h, &b), h);
  octmesh_mesh_counts_t mc;
  OK(octmesh_mesh_get_counts(h, &mc), h);
  const int32_t ne = mc.local_elements;
  CHECK(f.num_patches == 7 && f.global_elements == mc.global_elements, h);
  CHECK(f.patch_offsets[0] == f.num_internal, h);
  CHECK(f.patch_offsets[f.num_patches] == c.face_offsets[0], h);
  CHECK(c.face_offsets[c.num_ranks] == f.num_faces, h);

  /* Closure and volume of every cell. */
  double *sum = calloc(4 * (size_t)ne + 1, sizeof(double));
  double h_min = INFINITY;
  for (int32_t e = 0; e < ne; e++) h_min = fmin(h_min, cbrt(f.cell_volume[e]));
  for (int32_t i = 0; i < f.num_faces; i++) {
    const double *n = f.normal + 3 * i, *x = f.centre + 3 * i;
    double a = f.area[i];
    CHECK(fabs(dot3(n, n) - 1.0) < 1e-14 && a > 0.0, h);
    int32_t o = f.owner[i], k = f.neighbour[i];
    CHECK(o >= 0 && o < ne, h);
    if (i < f.num_internal) CHECK(k > o && k < ne, h);
    else if (i < f.patch_offsets[f.num_patches]) {
      int32_t p = -1 - k;
      CHECK(p >= 0 && p < f.num_patches, h);
      CHECK(i >= f.patch_offsets[p] && i < f.patch_offsets[p + 1], h);
    } else CHECK(k >= 0 && k < c.num_halo, h);
    for (int d = 0; d < 3; d++) sum[4 * o + d] += a * n[d];
    sum[4 * o + 3] += dot3(x, n) * a / 3.0;
    if (i < f.num_internal) {
      for (int d = 0; d < 3; d++) sum[4 * k + d] -= a * n[d];
      sum[4 * k + 3] -= dot3(x, n) * a / 3.0;
    }
  }
  for (int32_t e = 0; e < ne; e++) {
    double s2 = h_min * h_min;
    for (int d = 0; d < 3; d++) CHECK(fabs(sum[4 * e + d]) < 1e-9 * s2, h);
    CHECK(fabs(sum[4 * e + 3] - f.cell_volume[e]) < 1e-9 * f.cell_volume[e], h);
  }
  free(sum);

  /* The cell halo: exchange global numbers and centres. */
  for (int k = 0; k < c.num_ranks; k++) {
    int32_t ns = c.send_offsets[k + 1] - c.send_offsets[k];
    int32_t nr = c.recv_offsets[k + 1] - c.recv_offsets[k], theirs = -1;
    MPI_Sendrecv(&ns, 1, MPI_INT32_T, c.ranks[k], 0, &theirs, 1, MPI_INT32_T, c.ranks[k], 0,
                 MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    CHECK(theirs == nr, h);
  }
  int32_t nsend = c.send_offsets[c.num_ranks], nrecv = c.recv_offsets[c.num_ranks];
  double *sbuf = malloc(sizeof(double) * (4 * (size_t)nsend + 1));
  double *rbuf = malloc(sizeof(double) * (4 * (size_t)nrecv + 1));
  for (int32_t j = 0; j < nsend; j++) {
    int32_t e = c.send[j];
    sbuf[4 * j] = (double)(f.first_element + e);
    for (int d = 0; d < 3; d++) sbuf[4 * j + 1 + d] = f.cell_centre[3 * e + d];
  }
  MPI_Request *req = malloc(sizeof(MPI_Request) * (2 * (size_t)c.num_ranks + 1));
  for (int k = 0; k < c.num_ranks; k++) {
    MPI_Irecv(rbuf + 4 * c.recv_offsets[k], 4 * (c.recv_offsets[k + 1] - c.recv_offsets[k]),
              MPI_DOUBLE, c.ranks[k], 1, MPI_COMM_WORLD, &req[2 * k]);
    MPI_Isend(sbuf + 4 * c.send_offsets[k], 4 * (c.send_offsets[k + 1] - c.send_offsets[k]),
              MPI_DOUBLE, c.ranks[k], 1, MPI_COMM_WORLD, &req[2 * k + 1]);
  }
  MPI_Waitall(2 * c.num_ranks, req, MPI_STATUSES_IGNORE);
  double *halo_centre = malloc(sizeof(double) * (3 * (size_t)c.num_halo + 1));
  char *got = calloc((size_t)c.num_halo + 1, 1);
  for (int k = 0; k < c.num_ranks; k++)
    for (int32_t j = c.recv_offsets[k]; j < c.recv_offsets[k + 1]; j++) {
      int32_t q = c.recv[j];
      CHECK(c.halo_rank[q] == c.ranks[k], h);
      CHECK((double)c.halo_global[q] == rbuf[4 * j], h);
      for (int d = 0; d < 3; d++) halo_centre[3 * q + d] = rbuf[4 * j + 1 + d];
      got[q] = 1;
    }
  for (int k = 0; k < c.num_ranks; k++)
    for (int32_t i = c.face_offsets[k]; i < c.face_offsets[k + 1]; i++) {
      int32_t q = f.neighbour[i];
      CHECK(got[q] && c.halo_rank[q] == c.ranks[k], h);
      /* The halo element lies beyond the face, the owner before it. */
      double before[3], beyond[3];
      for (int d = 0; d < 3; d++) {
        before[d] = f.centre[3 * i + d] - f.cell_centre[3 * f.owner[i] + d];
        beyond[d] = halo_centre[3 * q + d] - f.centre[3 * i + d];
      }
      CHECK(dot3(before, f.normal + 3 * i) > 0 && dot3(beyond, f.normal + 3 * i) > 0, h);
    }
  free(sbuf);
  free(rbuf);
  free(req);
  free(halo_centre);
  free(got);

  /* Boundary nodes against corner counts summed over the ranks. */
  const octmesh_locidx_t *conn = NULL;
  OK(octmesh_mesh_get_connectivity(h, &conn), h);
  octmesh_locidx_t nnb = 0;
  const int32_t *xr = NULL;
  const octmesh_locidx_t *xo = NULL, *xn = NULL;
  OK(octmesh_mesh_get_exchange(h, &nnb, &xr, &xo, &xn), h);
  double *count = calloc((size_t)mc.local_nodes + 1, sizeof(double));
  for (int64_t k = 0; k < 8 * (int64_t)ne; k++) count[conn[k]] += 1.0;
  double *xs = malloc(sizeof(double) * ((size_t)xo[nnb] + 1));
  double *xg = malloc(sizeof(double) * ((size_t)xo[nnb] + 1));
  MPI_Request *xq = malloc(sizeof(MPI_Request) * (2 * (size_t)nnb + 1));
  for (int32_t j = 0; j < xo[nnb]; j++) xs[j] = count[xn[j]];
  for (int k = 0; k < nnb; k++) {
    MPI_Irecv(xg + xo[k], xo[k + 1] - xo[k], MPI_DOUBLE, xr[k], 2, MPI_COMM_WORLD, &xq[2 * k]);
    MPI_Isend(xs + xo[k], xo[k + 1] - xo[k], MPI_DOUBLE, xr[k], 2, MPI_COMM_WORLD,
              &xq[2 * k + 1]);
  }
  MPI_Waitall(2 * nnb, xq, MPI_STATUSES_IGNORE);
  for (int32_t j = 0; j < xo[nnb]; j++) count[xn[j]] += xg[j];
  long owned_boundary = 0;
  for (int32_t n = 0; n < mc.num_independent; n++) {
    int32_t np = b.node_offsets[n + 1] - b.node_offsets[n];
    CHECK((np > 0) == (count[n] < 7.5), h);
    for (int32_t j = b.node_offsets[n]; j < b.node_offsets[n + 1]; j++) {
      CHECK(b.node_patches[j] >= 0 && b.node_patches[j] < f.num_patches, h);
      if (j > b.node_offsets[n]) CHECK(b.node_patches[j] > b.node_patches[j - 1], h);
    }
    if (n < mc.num_owned && np > 0) owned_boundary++;
  }
  free(count);
  free(xs);
  free(xg);
  free(xq);
  /* Each boundary face's element face is listed with its patch. */
  for (int32_t i = f.num_internal; i < f.patch_offsets[f.num_patches]; i++) {
    int axis = fabs(f.normal[3 * i]) > 0.5 ? 0 : fabs(f.normal[3 * i + 1]) > 0.5 ? 1 : 2;
    int32_t face = 2 * axis + (f.normal[3 * i + axis] > 0), patch = -1 - f.neighbour[i];
    int found = 0;
    for (int32_t j = 0; j < b.num_faces && !found; j++)
      found = b.faces[3 * j] == f.owner[i] && b.faces[3 * j + 1] == face &&
              b.faces[3 * j + 2] == patch;
    CHECK(found, h);
  }

  /* Global counts, the same for any number of ranks. */
  long loc[10] = {0}, glob[10];
  /* Shared faces are listed by both of their ranks: counted in halves. */
  loc[0] = 2L * f.num_internal + (f.num_faces - c.face_offsets[0]);
  for (int p = 0; p < 7; p++) loc[1 + p] = f.patch_offsets[p + 1] - f.patch_offsets[p];
  loc[8] = owned_boundary;
  loc[9] = b.num_faces;
  MPI_Allreduce(loc, glob, 10, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);
  CHECK(glob[0] % 2 == 0, h);
  if (rank == 0)
    printf("FACES internal=%ld patches=%ld,%ld,%ld,%ld,%ld,%ld,%ld boundary_nodes=%ld "
           "boundary_element_faces=%ld\n",
           glob[0] / 2, glob[1], glob[2], glob[3], glob[4], glob[5], glob[6], glob[7], glob[8],
           glob[9]);

  /* Patch names and renames. */
  const char *name = NULL;
  OK(octmesh_mesh_get_patch_name(h, 0, &name), h);
  CHECK(strcmp(name, "xmin") == 0, h);
  OK(octmesh_mesh_get_patch_name(h, 6, &name), h);
  CHECK(strcmp(name, "torus") == 0, h);
  CHECK_STATUS(octmesh_mesh_get_patch_name(h, 7, &name), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_mesh_rename_patch(h, "xmin", "inlet"), h);
  OK(octmesh_mesh_rename_patch(h, "torus", "body"), h);
  OK(octmesh_mesh_get_patch_name(h, 0, &name), h);
  CHECK(strcmp(name, "inlet") == 0, h);
  /* A bad name on one rank only fails on every rank. */
  CHECK_STATUS(octmesh_mesh_rename_patch(h, "xmax", rank == size - 1 ? "2bad" : "outlet"),
               rank == size - 1 ? OCTMESH_STATUS_INVALID_ARGUMENT : OCTMESH_STATUS_REMOTE_FAILURE,
               h);
  CHECK_STATUS(octmesh_mesh_rename_patch(h, "xmax", "inlet"), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  CHECK_STATUS(octmesh_mesh_rename_patch(h, "nowhere", "x"), OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_mesh_get_patch_name(h, 1, &name), h);
  CHECK(strcmp(name, "xmax") == 0, h);
  /* The arrays survive a rename. */
  octmesh_faces_t f2;
  OK(octmesh_mesh_get_faces(h, &f2), h);
  CHECK(f2.owner == f.owner && f2.num_faces == f.num_faces, h);

  /* OpenFOAM output: written, refused without overwrite, replaced. */
  CHECK_STATUS(octmesh_mesh_write_openfoam(h, argv[1], 7, false), OCTMESH_STATUS_INVALID_ARGUMENT,
               h);
  OK(octmesh_mesh_write_openfoam(h, argv[1], OCTMESH_FOAM_FORMAT_ASCII, false), h);
  CHECK_STATUS(octmesh_mesh_write_openfoam(h, argv[1], OCTMESH_FOAM_FORMAT_ASCII, false),
               OCTMESH_STATUS_INVALID_ARGUMENT, h);
  OK(octmesh_mesh_write_openfoam(h, argv[1], OCTMESH_FOAM_FORMAT_ASCII, true), h);
  char path[4096];
  if (size == 1)
    snprintf(path, sizeof path, "%s/constant/polyMesh/boundary", argv[1]);
  else
    snprintf(path, sizeof path, "%s/processor%d/constant/polyMesh/boundary", argv[1], rank);
  FILE *fb = fopen(path, "r");
  CHECK(fb != NULL, h);
  char text[1 << 16];
  size_t len = fread(text, 1, sizeof text - 1, fb);
  text[len] = '\0';
  fclose(fb);
  CHECK(strstr(text, "inlet") && strstr(text, "body") && strstr(text, "outlet") == NULL, h);

  /* Boundary layers: bad settings refused, then three layers on the wall
     layer of the staircase kept off the surface: each wall face gets four
     cells (the buffer and the layers). */
  const octmesh_status_t bad = OCTMESH_STATUS_INVALID_ARGUMENT;
  CHECK_STATUS(octmesh_mesh_set_layers(h, -1, 1.2, 0.01, 0, 0, false), bad, h);
  CHECK_STATUS(octmesh_mesh_set_layers(h, 3, 0.0, 0.01, 0, 0, false), bad, h);
  CHECK_STATUS(octmesh_mesh_set_layers(h, 3, 1.2, 0.01, 0.02, 0, false), bad, h);
  CHECK_STATUS(octmesh_mesh_set_layers(h, 3, 1.2, -0.01, 0, 0, false), bad, h);
  CHECK_STATUS(octmesh_mesh_set_layers(h, 3, 1.2, 1.5, 0, 0, true), bad, h);
  CHECK_STATUS(octmesh_mesh_set_layers(h, 3, 1.2, 0, 0, 0, false), bad, h);
  CHECK_STATUS(octmesh_mesh_set_layers(h, rank == 0 ? 3 : 2, 1.2, 0.002, 0, 0, false),
               size > 1 ? bad : OCTMESH_STATUS_OK, h);
  /* The mesh keeps the cut leaves (OCTMESH_CUT_RULE_CENTER): no wall layer. */
  OK(octmesh_mesh_set_wall_layer(h, true), h);
  CHECK_STATUS(octmesh_mesh_write_openfoam(h, argv[1], OCTMESH_FOAM_FORMAT_ASCII, true), bad, h);
  OK(octmesh_mesh_set_wall_layer(h, false), h);
  OK(octmesh_mesh_build(h, OCTMESH_KEEP_OUTSIDE, OCTMESH_CUT_RULE_NONE), h);
  OK(octmesh_mesh_build_faces(h), h);
  octmesh_faces_t f3;
  OK(octmesh_mesh_get_faces(h, &f3), h);
  octmesh_mesh_counts_t counts;
  OK(octmesh_mesh_get_counts(h, &counts), h);
  long wall = f3.patch_offsets[7] - f3.patch_offsets[6];
  long expected = (long)counts.local_elements + 4 * wall;
  OK(octmesh_mesh_set_layers(h, 3, 1.2, 0.002, 0, 0, false), h);
  OK(octmesh_mesh_write_openfoam(h, argv[1], OCTMESH_FOAM_FORMAT_ASCII, true), h);
  if (size == 1)
    snprintf(path, sizeof path, "%s/constant/polyMesh/owner", argv[1]);
  else
    snprintf(path, sizeof path, "%s/processor%d/constant/polyMesh/owner", argv[1], rank);
  fb = fopen(path, "r");
  CHECK(fb != NULL, h);
  len = fread(text, 1, sizeof text - 1, fb);
  text[len] = '\0';
  fclose(fb);
  const char *note = strstr(text, "nCells:");
  CHECK(note != NULL && atol(note + 7) == expected, h);
  OK(octmesh_mesh_set_layers(h, 0, 1.0, 0, 0, 0, false), h);

  octmesh_destroy(h);
  printf("FACES OK\n");
  MPI_Finalize();
  return 0;
}
