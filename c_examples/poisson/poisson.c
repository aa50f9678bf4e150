/* Poisson problem -Δu = f on a solid meshed by octmesh, with trilinear
 * hexahedra, hanging nodes eliminated, and a matrix-free parallel
 * conjugate gradient.
 *
 * Usage: poisson [--snap | --band] [--min-jacobian J] [--rtol R]
 *                LEVEL [SURFACE.stl] [OUT.pvtu]
 *
 * The solid is the union of the kept elements (KEEP_INSIDE, cut leaves by
 * their centres) of the surface refined at LEVEL, with every leaf refined to
 * at least LEVEL-2 (LEVEL-1 with --snap or --band) so that the whole mesh
 * gets finer with LEVEL. Without a readable STL file the built-in sphere is
 * used (and said so).
 *
 * Options:
 *   --snap            body-fitted: every leaf refined to at least LEVEL-1 and
 *                     the leaves within 1.5 cells of the surface to LEVEL
 *                     (no 2:1 step on the surface, so every surface node can
 *                     reach it), then the mesh is snapped (octmesh_mesh_snap:
 *                     feature angle 30, 2 layers, 3 iterations, least scaled
 *                     Jacobian J)
 *   --band            the same octree as --snap, not snapped (its staircase,
 *                     for comparison)
 *   --min-jacobian J  the snap's least scaled Jacobian, (0, 0.5]; default
 *                     0.001, the library's: the most nodes on the surface
 *                     (0.1 leaves most of them partly snapped; the error is
 *                     within 2 % either way, see BENCHMARKS.md)
 *   --rtol R          conjugate gradient stops when the residual norm falls
 *                     below R times the first; default 1e-12
 *
 * Manufactured solution, in cube coordinates s = (x - origin) / side:
 *   u = sin(pi s_x) sin(pi s_y) sin(pi s_z),  f = 3 pi^2 / side^2 u,
 * with u = exact on the boundary nodes of the solid.
 *
 * Discretisation.
 * - Unknowns: the independent local nodes. A hanging node's value is the
 *   mean of its dependencies, u_full = P u (a snap keeps hanging nodes at
 *   the mean of their dependencies, so this stays exact); the operator is
 *   P^T K P, applied element by element and never assembled globally.
 * - Elements are isoparametric: the trilinear map from the reference cube
 *   to the 8 corners' positions (the octree's cubes, or the moved corners
 *   of a snapped mesh), with 2x2x2 Gauss points q:
 *   K_e = sum_q B_q^T B_q |J_q| w_q, B_q the gradients of the 8 shape
 *   functions in user coordinates (J_q^-T times the reference gradients).
 *   On an unsnapped mesh this is h K_ref, K_ref the unit cube's stiffness.
 * - Parallel sums: each rank adds its elements' contributions to its local
 *   nodes; the exchange lists then add the partial sums of the other ranks
 *   using the same nodes, so every rank holds full sums on all its
 *   independent nodes. Dot products run over owned nodes only.
 * - Boundary: the nodes octmesh puts on a patch (octmesh_mesh_get_boundary:
 *   the solid's surface and the cube's sides), the same on every rank that
 *   holds the node.
 * - Dirichlet: u = u_D + w, u_D = exact on boundary nodes (at their
 *   positions, moved ones on a snapped mesh) and 0 elsewhere, w solves the
 *   interior rows of (P^T K P) w = b - (P^T K P) u_D.
 * - Load: b = P^T (integrals of f N_i over the mapped elements, the same
 *   Gauss points).
 *
 * Output: one line "POISSON level=... mode=... max_error=..." (max over
 * independent nodes of |u - exact|; mode cube, band or snap), after a line
 * "SNAP ..." with the snap's counts. With OUT.pvtu, the mesh (moved nodes
 * after a snap) is written with the point fields "u" (computed solution),
 * "u_exact" and "error" (u - u_exact) on every local node, a hanging node's
 * u being the mean of its dependencies. Exits with 3 if an element has a
 * non-positive Jacobian at a Gauss point. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <mpi.h>
#include "octmesh.h"

static octmesh_t *g_handle = NULL;

#define TRY(call)                                                                       \
  do {                                                                                  \
    octmesh_status_t s_ = (call);                                                       \
    if (s_ != OCTMESH_STATUS_OK) {                                                      \
      fprintf(stderr, "%s failed: %s: %s\n", #call, octmesh_status_name(s_),            \
              octmesh_last_error(g_handle));                                            \
      MPI_Abort(MPI_COMM_WORLD, 2);                                                     \
    }                                                                                   \
  } while (0)

/* Corners of the unit cube in VTK hexahedron order. */
static const int CORNER[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                 {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};

static double g_origin[3], g_side;

static double exact(const double *x) {
  const double pi = acos(-1.0);
  double v = 1.0;
  for (int d = 0; d < 3; d++) v *= sin(pi * (x[d] - g_origin[d]) / g_side);
  return v;
}

static double rhs(const double *x) {
  const double pi = acos(-1.0);
  return 3.0 * pi * pi / (g_side * g_side) * exact(x);
}

/* Refinement context: every leaf below min_level is split. */
typedef struct {
  int min_level;
} uniform_ctx;

static bool refine_uniform(void *ctx, const octmesh_octant_t *o) {
  return o->level < ((const uniform_ctx *)ctx)->min_level;
}

/* The mesh and what the solver derives from it. */
typedef struct {
  int64_t ne, nl, ni, nown;
  const octmesh_locidx_t *conn, *hcount, *hdeps;
  const double *xyz;
  double *ke;         /* 64 per element: its stiffness matrix */
  unsigned char *bnd; /* per independent node: 1 on the boundary */
  double *ufull, *rfull;
  /* exchange */
  octmesh_locidx_t nnb;
  const int32_t *xr;               /* neighbour ranks */
  const octmesh_locidx_t *xo, *xn; /* offsets, local nodes */
  double *sendbuf, *recvbuf;
  MPI_Request *req;
} problem;

/* Shape functions of corner i at reference point s, and their reference
 * gradients. */
static double shape(int i, const double *s) {
  double n = 1.0;
  for (int d = 0; d < 3; d++) n *= CORNER[i][d] ? s[d] : 1.0 - s[d];
  return n;
}

static void shape_gradients(const double *s, double grad[8][3]) {
  for (int i = 0; i < 8; i++)
    for (int d = 0; d < 3; d++) {
      double v = 1.0;
      for (int e = 0; e < 3; e++) {
        if (e == d)
          v *= CORNER[i][e] ? 1.0 : -1.0;
        else
          v *= CORNER[i][e] ? s[e] : 1.0 - s[e];
      }
      grad[i][d] = v;
    }
}

/* Gauss point q (of 8) in the reference cube [0,1]^3. */
static void gauss_point(int q, double *s) {
  const double g[2] = {0.5 - 0.5 / sqrt(3.0), 0.5 + 0.5 / sqrt(3.0)};
  s[0] = g[q & 1];
  s[1] = g[(q >> 1) & 1];
  s[2] = g[(q >> 2) & 1];
}

/* At reference point s of the element with corners x (VTK order): the
 * mapped point, the shape functions' gradients in user coordinates and
 * det J. Returns det J (not positive: a folded element). */
static double map_point(const double x[8][3], const double *s, double *xq, double b[8][3]) {
  double gr[8][3], jac[3][3] = {{0}};
  shape_gradients(s, gr);
  for (int a = 0; a < 3; a++) xq[a] = 0.0;
  for (int i = 0; i < 8; i++) {
    double n = shape(i, s);
    for (int a = 0; a < 3; a++) {
      xq[a] += n * x[i][a];
      for (int d = 0; d < 3; d++) jac[a][d] += x[i][a] * gr[i][d];
    }
  }
  /* inv = J^-1 by cofactors; grad_x N = J^-T grad_s N. */
  double cof[3][3];
  for (int a = 0; a < 3; a++)
    for (int d = 0; d < 3; d++) {
      int a1 = (a + 1) % 3, a2 = (a + 2) % 3, d1 = (d + 1) % 3, d2 = (d + 2) % 3;
      cof[a][d] = jac[a1][d1] * jac[a2][d2] - jac[a1][d2] * jac[a2][d1];
    }
  double det = jac[0][0] * cof[0][0] + jac[0][1] * cof[0][1] + jac[0][2] * cof[0][2];
  if (det <= 0.0) return det;
  /* (J^-1)[d][a] = cof[a][d] / det, so (J^-T grad)[a] = sum_d cof[a][d] g[d] / det. */
  for (int i = 0; i < 8; i++)
    for (int a = 0; a < 3; a++)
      b[i][a] = (cof[a][0] * gr[i][0] + cof[a][1] * gr[i][1] + cof[a][2] * gr[i][2]) / det;
  return det;
}

static void element_corners(const problem *pb, int64_t e, double x[8][3]) {
  for (int i = 0; i < 8; i++)
    for (int a = 0; a < 3; a++) x[i][a] = pb->xyz[3 * pb->conn[8 * e + i] + a];
}

/* K_e = sum_q B^T B |J| w for every element. Returns the number of
 * elements with a non-positive det J at a Gauss point. */
static long element_matrices(problem *pb) {
  long folded = 0;
  for (int64_t e = 0; e < pb->ne; e++) {
    double x[8][3], *k = pb->ke + 64 * e;
    element_corners(pb, e, x);
    memset(k, 0, 64 * sizeof(double));
    for (int q = 0; q < 8; q++) {
      double s[3], xq[3], b[8][3];
      gauss_point(q, s);
      double det = map_point(x, s, xq, b);
      if (det <= 0.0) {
        folded++;
        break;
      }
      double w = det / 8.0;
      for (int i = 0; i < 8; i++)
        for (int j = 0; j < 8; j++)
          k[8 * i + j] += w * (b[i][0] * b[j][0] + b[i][1] * b[j][1] + b[i][2] * b[j][2]);
    }
  }
  return folded;
}

/* Adds the other ranks' partial sums to v on shared independent nodes. */
static void exchange_sum(problem *pb, double *v) {
  for (int32_t k = 0; k < pb->xo[pb->nnb]; k++) pb->sendbuf[k] = v[pb->xn[k]];
  for (int32_t k = 0; k < pb->nnb; k++) {
    int n = pb->xo[k + 1] - pb->xo[k];
    MPI_Irecv(pb->recvbuf + pb->xo[k], n, MPI_DOUBLE, pb->xr[k], 71, MPI_COMM_WORLD, &pb->req[2 * k]);
    MPI_Isend(pb->sendbuf + pb->xo[k], n, MPI_DOUBLE, pb->xr[k], 71, MPI_COMM_WORLD,
              &pb->req[2 * k + 1]);
  }
  MPI_Waitall(2 * pb->nnb, pb->req, MPI_STATUSES_IGNORE);
  for (int32_t k = 0; k < pb->xo[pb->nnb]; k++) v[pb->xn[k]] += pb->recvbuf[k];
}

/* Folds hanging-node entries of a full local vector onto their dependencies
 * (P^T) and writes the independent part to out. */
static void fold_hanging(const problem *pb, const double *full, double *out) {
  for (int64_t i = 0; i < pb->ni; i++) out[i] = full[i];
  for (int64_t k = 0; k < pb->nl - pb->ni; k++) {
    double share = full[pb->ni + k] / pb->hcount[k];
    for (int j = 0; j < pb->hcount[k]; j++) out[pb->hdeps[4 * k + j]] += share;
  }
}

/* y = P^T K P x on independent nodes (full sums); rows of boundary nodes
 * zeroed when mask is set. */
static void apply(problem *pb, const double *x, double *y, int mask) {
  for (int64_t i = 0; i < pb->ni; i++) pb->ufull[i] = x[i];
  for (int64_t k = 0; k < pb->nl - pb->ni; k++) {
    double s = 0.0;
    for (int j = 0; j < pb->hcount[k]; j++) s += x[pb->hdeps[4 * k + j]];
    pb->ufull[pb->ni + k] = s / pb->hcount[k];
  }
  memset(pb->rfull, 0, sizeof(double) * (size_t)pb->nl);
  for (int64_t e = 0; e < pb->ne; e++) {
    const octmesh_locidx_t *c = pb->conn + 8 * e;
    const double *k = pb->ke + 64 * e;
    double ue[8];
    for (int j = 0; j < 8; j++) ue[j] = pb->ufull[c[j]];
    for (int i = 0; i < 8; i++) {
      double s = 0.0;
      for (int j = 0; j < 8; j++) s += k[8 * i + j] * ue[j];
      pb->rfull[c[i]] += s;
    }
  }
  fold_hanging(pb, pb->rfull, y);
  exchange_sum(pb, y);
  if (mask)
    for (int64_t i = 0; i < pb->ni; i++)
      if (pb->bnd[i]) y[i] = 0.0;
}

static double dot(const problem *pb, const double *a, const double *b) {
  double s = 0.0, g = 0.0;
  for (int64_t i = 0; i < pb->nown; i++) s += a[i] * b[i];
  MPI_Allreduce(&s, &g, 1, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  return g;
}

/* Parses a number after an option; 0 on failure. */
static int parse_double(const char *text, double *out) {
  char *end = NULL;
  double v = strtod(text, &end);
  if (end == text || *end != '\0' || !(v == v)) return 0;
  *out = v;
  return 1;
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank, size;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  /* Options first, then up to three positional arguments. */
  int snap = 0, band = 0, npos = 0, bad = 0;
  double min_jacobian = 0.001, rtol = 1e-12;
  const char *pos[3] = {NULL, NULL, NULL};
  for (int a = 1; a < argc && !bad; a++) {
    if (strcmp(argv[a], "--snap") == 0) {
      snap = band = 1;
    } else if (strcmp(argv[a], "--band") == 0) {
      band = 1;
    } else if (strcmp(argv[a], "--min-jacobian") == 0 && a + 1 < argc) {
      bad = !parse_double(argv[++a], &min_jacobian);
    } else if (strcmp(argv[a], "--rtol") == 0 && a + 1 < argc) {
      bad = !parse_double(argv[++a], &rtol) || !(rtol > 0.0 && rtol < 1.0);
    } else if (argv[a][0] == '-' && argv[a][1] == '-') {
      bad = 1;
    } else if (npos < 3) {
      pos[npos++] = argv[a];
    } else {
      bad = 1;
    }
  }
  if (bad || npos < 1 || atoi(pos[0]) < 2 || atoi(pos[0]) > 12) {
    if (rank == 0)
      fprintf(stderr,
              "usage: %s [--snap | --band] [--min-jacobian J] [--rtol R] LEVEL(2-12) "
              "[SURFACE.stl] [OUT.pvtu]\n",
              argv[0]);
    MPI_Finalize();
    return 1;
  }
  int level = atoi(pos[0]);
  const char *stl = pos[1];
  const char *pvtu = pos[2];
  const char *mode = snap ? "snap" : band ? "band" : "cube";

  /* Every rank must take the same branch: rank 0 decides. */
  int have_stl = 0;
  if (rank == 0 && stl) {
    FILE *f = fopen(stl, "rb");
    if (f) {
      have_stl = 1;
      fclose(f);
    }
  }
  MPI_Bcast(&have_stl, 1, MPI_INT, 0, MPI_COMM_WORLD);

  TRY(octmesh_create(MPI_COMM_WORLD, NULL, &g_handle));
  octmesh_t *h = g_handle;
  if (have_stl) {
    TRY(octmesh_surface_from_stl(h, stl));
  } else {
    if (rank == 0)
      printf("surface %s not found: using the built-in sphere\n", stl ? stl : "(none given)");
    TRY(octmesh_surface_builtin(h, "sphere"));
  }
  TRY(octmesh_octree_refine_surface(h, level));
  TRY(octmesh_domain_get(h, g_origin, &g_side));
  if (band) {
    /* Leaves within 1.5 finest cells of the surface at LEVEL: no 2:1 step
     * on the surface, whose hanging nodes could not reach it. Every leaf
     * at least LEVEL-1: with LEVEL-2 the coarse interior's error dominates
     * and the sphere's mesh changes shape from level to level (almost all
     * fine at level 5, a coarse core from 6 on), so the error's rate
     * measures the mesh's shape, not the order. */
    double distance = 1.5 * g_side / (double)(1 << level);
    int32_t band_level = level;
    TRY(octmesh_octree_refine_regions(h, level - 1, 0, NULL, 1, &distance, &band_level));
  } else {
    uniform_ctx uctx = {level - 2};
    TRY(octmesh_octree_refine_callback(h, level - 2, refine_uniform, &uctx));
  }
  TRY(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER));
  TRY(octmesh_octree_partition(h, NULL, NULL));
  TRY(octmesh_mesh_build(h, OCTMESH_KEEP_INSIDE, OCTMESH_CUT_RULE_CENTER));
  octmesh_snap_report_t report;
  memset(&report, 0, sizeof report);
  if (snap) {
    TRY(octmesh_mesh_snap(h, 30.0, 2, 3, min_jacobian));
    TRY(octmesh_mesh_get_snap_report(h, &report));
  }

  octmesh_mesh_counts_t c;
  TRY(octmesh_mesh_get_counts(h, &c));
  problem pb;
  memset(&pb, 0, sizeof pb);
  pb.ne = c.local_elements;
  pb.nl = c.local_nodes;
  pb.ni = c.num_independent;
  pb.nown = c.num_owned;
  TRY(octmesh_mesh_get_connectivity(h, &pb.conn));
  /* After a snap: the moved positions. */
  TRY(octmesh_mesh_get_coordinates(h, &pb.xyz));
  TRY(octmesh_mesh_get_hanging(h, &pb.hcount, &pb.hdeps));
  TRY(octmesh_mesh_get_exchange(h, &pb.nnb, &pb.xr, &pb.xo, &pb.xn));

  size_t nl = (size_t)pb.nl + 1, ni = (size_t)pb.ni + 1, nx = (size_t)pb.xo[pb.nnb] + 1;
  pb.ke = malloc(sizeof(double) * 64 * ((size_t)pb.ne + 1));
  pb.bnd = malloc(ni);
  pb.ufull = malloc(sizeof(double) * nl);
  pb.rfull = malloc(sizeof(double) * nl);
  pb.sendbuf = malloc(sizeof(double) * nx);
  pb.recvbuf = malloc(sizeof(double) * nx);
  pb.req = malloc(sizeof(MPI_Request) * (2 * (size_t)pb.nnb + 1));
  double *b = malloc(sizeof(double) * ni), *x = malloc(sizeof(double) * ni);
  double *r = malloc(sizeof(double) * ni), *p = malloc(sizeof(double) * ni);
  double *ap = malloc(sizeof(double) * ni), *ud = malloc(sizeof(double) * ni);

  long folded = element_matrices(&pb), gfolded = 0;
  MPI_Allreduce(&folded, &gfolded, 1, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);
  if (gfolded > 0) {
    if (rank == 0) fprintf(stderr, "%ld elements have a non-positive Jacobian\n", gfolded);
    MPI_Abort(MPI_COMM_WORLD, 3);
  }

  /* Boundary: the nodes on any patch. */
  TRY(octmesh_mesh_build_faces(h));
  octmesh_boundary_t bd;
  TRY(octmesh_mesh_get_boundary(h, &bd));
  long nbnd = 0, gbnd = 0;
  for (int64_t i = 0; i < pb.ni; i++) {
    pb.bnd[i] = bd.node_offsets[i + 1] > bd.node_offsets[i];
    if (i < pb.nown) nbnd += pb.bnd[i];
  }
  MPI_Allreduce(&nbnd, &gbnd, 1, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);

  /* Load b = P^T (integrals of f N_i over the mapped elements). */
  memset(pb.rfull, 0, sizeof(double) * nl);
  for (int64_t e = 0; e < pb.ne; e++) {
    const octmesh_locidx_t *ce = pb.conn + 8 * e;
    double xe[8][3];
    element_corners(&pb, e, xe);
    for (int q = 0; q < 8; q++) {
      double s[3], xq[3], grad[8][3];
      gauss_point(q, s);
      double det = map_point(xe, s, xq, grad);
      double fq = rhs(xq) * det / 8.0;
      for (int i = 0; i < 8; i++) pb.rfull[ce[i]] += fq * shape(i, s);
    }
  }
  fold_hanging(&pb, pb.rfull, b);
  exchange_sum(&pb, b);

  /* r = b - A u_D on interior rows. */
  for (int64_t i = 0; i < pb.ni; i++) ud[i] = pb.bnd[i] ? exact(pb.xyz + 3 * i) : 0.0;
  apply(&pb, ud, ap, 1);
  for (int64_t i = 0; i < pb.ni; i++) {
    r[i] = pb.bnd[i] ? 0.0 : b[i] - ap[i];
    p[i] = r[i];
    x[i] = 0.0;
  }
  double rr = dot(&pb, r, r), rr0 = rr;
  int it = 0;
  const int max_it = 20000;
  while (it < max_it && rr > rtol * rtol * rr0 && rr > 0.0) {
    apply(&pb, p, ap, 1);
    double alpha = rr / dot(&pb, p, ap);
    for (int64_t i = 0; i < pb.ni; i++) {
      x[i] += alpha * p[i];
      r[i] -= alpha * ap[i];
    }
    double rr1 = dot(&pb, r, r);
    double beta = rr1 / rr;
    rr = rr1;
    for (int64_t i = 0; i < pb.ni; i++) p[i] = r[i] + beta * p[i];
    it++;
  }

  double err = 0.0, gerr = 0.0;
  for (int64_t i = 0; i < pb.nown; i++) {
    double e = fabs(ud[i] + x[i] - exact(pb.xyz + 3 * i));
    if (e > err) err = e;
  }
  MPI_Allreduce(&err, &gerr, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
  if (pvtu) {
    /* Point fields on all local nodes, hanging ones from their deps. */
    double *fu = malloc(sizeof(double) * nl), *fex = malloc(sizeof(double) * nl);
    double *ferr = malloc(sizeof(double) * nl);
    for (int64_t i = 0; i < pb.ni; i++) fu[i] = ud[i] + x[i];
    for (int64_t k = 0; k < pb.nl - pb.ni; k++) {
      double s = 0.0;
      for (int j = 0; j < pb.hcount[k]; j++) s += fu[pb.hdeps[4 * k + j]];
      fu[pb.ni + k] = s / pb.hcount[k];
    }
    for (int64_t i = 0; i < pb.nl; i++) {
      fex[i] = exact(pb.xyz + 3 * i);
      ferr[i] = fu[i] - fex[i];
    }
    const char *names[3] = {"u", "u_exact", "error"};
    const double *values[3] = {fu, fex, ferr};
    TRY(octmesh_mesh_write_vtu_fields(h, pvtu, 3, names, values));
    free(fu); free(fex); free(ferr);
  }
  if (rank == 0) {
    if (snap)
      printf("SNAP surface_nodes=%lld snapped=%lld partial=%lld unsnapped=%lld "
             "min_scaled_jacobian=%.4g\n",
             (long long)report.surface_nodes, (long long)report.snapped,
             (long long)report.partial, (long long)report.unsnapped, report.min_scaled_jacobian);
    printf("POISSON level=%d mode=%s ranks=%d elements=%lld independent=%lld hanging=%lld "
           "boundary=%ld iterations=%d residual=%.3e max_error=%.6e\n",
           level, mode, size, (long long)c.global_elements, (long long)c.global_independent,
           (long long)(c.global_face_hanging + c.global_edge_hanging), gbnd, it,
           rr0 > 0 ? sqrt(rr / rr0) : 0.0, gerr);
    if (pvtu) printf("mesh and fields u, u_exact, error written to %s\n", pvtu);
  }
  int failed = it >= max_it;
  free(pb.ke); free(pb.bnd); free(pb.ufull); free(pb.rfull); free(pb.sendbuf); free(pb.recvbuf);
  free(pb.req); free(b); free(x); free(r); free(p); free(ap); free(ud);
  octmesh_destroy(h);
  MPI_Finalize();
  return failed ? 1 : 0;
}
