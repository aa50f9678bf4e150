// The C++ wrapper (octmesh.hpp): a solid sphere mesh refined by a lambda,
// written with a point field (and as OUT.pvtu.exo, OUT.pvtu.cgns), and an
// error reported as an exception.
// Usage: mesher [OUT.pvtu]
// octmesh.hpp first: it includes mpi.h without the MPI C++ bindings.
#include <octmesh.hpp>

#include <cstdio>
#include <string>
#include <vector>

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  int status = 0;
  try {
    octmesh::Mesher m(MPI_COMM_WORLD);
    m.surface_builtin("sphere");
    m.refine_surface(4);
    long calls = 0;
    // Also refine the octants in the half x < centre to level 5.
    m.refine(5, [&calls](const octmesh_octant_t &o) {
      ++calls;
      return o.x < (1 << 18) && o.level < 5;
    });
    m.balance(OCTMESH_CONNECT_CORNER);
    m.partition();
    m.mesh(OCTMESH_KEEP_INSIDE);
    octmesh_mesh_counts_t c = m.counts();
    auto leaves = m.num_leaves();
    if (argc > 1) {
      // The mesh with one point field: the x coordinate of each node.
      const double *xyz = m.coordinates();
      std::vector<double> x(static_cast<size_t>(c.local_nodes));
      for (size_t i = 0; i < x.size(); i++) x[i] = xyz[3 * i];
      m.write_vtu(argv[1], {{"x", x.data()}});
      // The same mesh for Exodus II and CGNS readers (MOOSE, SU2, ...).
      m.write_exodus(std::string(argv[1]) + ".exo");
      m.write_cgns(std::string(argv[1]) + ".cgns");
    }
    if (rank == 0)
      std::printf("CPP leaves=%lld elements=%lld independent=%lld hanging=%lld\n",
                  (long long)leaves.second, (long long)c.global_elements,
                  (long long)c.global_independent,
                  (long long)(c.global_face_hanging + c.global_edge_hanging));

    // Refining to a surface without one is an error: it throws.
    octmesh::Mesher plain(MPI_COMM_WORLD);
    plain.refine_surface(3);
  } catch (const octmesh::Error &e) {
    if (rank == 0) std::printf("CPP expected error (%s): %s\n", octmesh_status_name(e.status()), e.what());
    status = e.status() == OCTMESH_STATUS_STATE || e.status() == OCTMESH_STATUS_INVALID_ARGUMENT ? 0 : 1;
  }
  MPI_Finalize();
  return status;
}
