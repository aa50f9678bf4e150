/* Custom refinement by a C callback with a context struct: refines the
 * octants within a distance of a point of the unit cube, counts the calls,
 * balances, partitions, meshes all leaves and writes a VTU.
 * Usage: refine_callback [MAX_LEVEL] [OUT.pvtu] */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <mpi.h>
#include "octmesh.h"

typedef struct {
  double centre[3]; /* lattice units */
  double radius;    /* lattice units */
  long calls;       /* this rank's calls */
} ball_ctx;

/* Split the octant when the ball touches it. */
static bool refine_ball(void *ctx, const octmesh_octant_t *o) {
  ball_ctx *b = (ball_ctx *)ctx;
  b->calls++;
  double len = (double)(1 << (19 - o->level)), d2 = 0.0;
  const int32_t lo[3] = {o->x, o->y, o->z};
  for (int i = 0; i < 3; i++) {
    double q = b->centre[i];
    double c = q < lo[i] ? lo[i] : (q > lo[i] + len ? lo[i] + len : q);
    d2 += (q - c) * (q - c);
  }
  return d2 <= b->radius * b->radius;
}

#define TRY(call)                                                                        \
  do {                                                                                   \
    octmesh_status_t s_ = (call);                                                        \
    if (s_ != OCTMESH_STATUS_OK) {                                                       \
      fprintf(stderr, "%s: %s: %s\n", #call, octmesh_status_name(s_), octmesh_last_error(h)); \
      MPI_Abort(MPI_COMM_WORLD, 2);                                                      \
    }                                                                                    \
  } while (0)

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  int max_level = argc > 1 ? atoi(argv[1]) : 6;
  octmesh_t *h = NULL;
  TRY(octmesh_create(MPI_COMM_WORLD, NULL, &h));
  const double root = (double)(1 << 19);
  ball_ctx ball = {{0.3 * root, 0.4 * root, 0.5 * root}, 0.1 * root, 0};
  TRY(octmesh_octree_refine_callback(h, max_level, refine_ball, &ball));
  TRY(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER));
  TRY(octmesh_octree_partition(h, NULL, NULL));
  TRY(octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER));
  octmesh_mesh_counts_t c;
  TRY(octmesh_mesh_get_counts(h, &c));
  long calls = 0;
  MPI_Reduce(&ball.calls, &calls, 1, MPI_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  if (argc > 2) TRY(octmesh_mesh_write_vtu(h, argv[2]));
  if (rank == 0)
    printf("REFINE_CALLBACK max_level=%d calls=%ld elements=%lld independent=%lld "
           "face_hanging=%lld edge_hanging=%lld\n",
           max_level, calls, (long long)c.global_elements, (long long)c.global_independent,
           (long long)c.global_face_hanging, (long long)c.global_edge_hanging);
  octmesh_destroy(h);
  MPI_Finalize();
  return c.global_elements > 1 ? 0 : 1;
}
