// Per-leaf user data from C++ (include/octmesh.hpp): each leaf stores its
// own octant; lambdas refine, coarsen, adapt and balance with a replace
// callable that computes the new leaves' octants; after each call every
// leaf's data is its own. A replace callable that throws makes the call
// throw octmesh::Error on every rank with the data unchanged. Then fields
// across one step with the previous mesh kept (transfer_nodes,
// transfer_elements, element_map), zones, and a checkpoint saved and loaded
// back with the data (argv[1] is its path). Prints
// CPP LEAF DATA OK on every rank.
// First: it keeps mpi.h from pulling in the MPI C++ bindings.
#include "octmesh.hpp"

#include <cmath>
#include <cstdio>
#include <vector>
#include <stdexcept>

struct Datum {
  int32_t x, y, z, level;
};

static int g_rank;

static void require(bool ok, const char *what) {
  if (!ok) {
    std::fprintf(stderr, "FAILED rank %d: %s\n", g_rank, what);
    MPI_Abort(MPI_COMM_WORLD, 3);
  }
}

static void check_own(octmesh::Mesher &m) {
  auto d = m.data<Datum>();
  auto l = m.leaves();
  require(d.second == (octmesh_locidx_t)l.size(), "one datum per leaf");
  for (size_t i = 0; i < l.size(); i++)
    require(d.first[i].x == l[i].x && d.first[i].y == l[i].y && d.first[i].z == l[i].z &&
                d.first[i].level == l[i].level,
            "a leaf's data is its own octant");
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  MPI_Comm_rank(MPI_COMM_WORLD, &g_rank);
  {
    octmesh::Mesher m(MPI_COMM_WORLD);
    m.refine(2, [](const octmesh_octant_t &) { return true; });
    m.set_data_size(sizeof(Datum));
    require(m.data_size() == (int32_t)sizeof(Datum), "data size");
    {
      auto d = m.data<Datum>();
      auto l = m.leaves();
      for (int i = 0; i < d.second; i++) d.first[i] = Datum{l[i].x, l[i].y, l[i].z, l[i].level};
    }
    // Children from the parent's stored octant, parents from the first
    // child's; balance's leaves as given.
    auto replace = [](octmesh_locidx_t nout, const octmesh_octant_t *, const void *od, octmesh_locidx_t nin,
                      const octmesh_octant_t *in, void *id) {
      const Datum *o = static_cast<const Datum *>(od);
      Datum *n = static_cast<Datum *>(id);
      if (nout == 1 && nin == 8) {
        int32_t half = 1 << (19 - o[0].level - 1);
        for (int i = 0; i < 8; i++)
          n[i] = Datum{o[0].x + (i & 1) * half, o[0].y + ((i >> 1) & 1) * half,
                       o[0].z + ((i >> 2) & 1) * half, o[0].level + 1};
      } else if (nout == 8) {
        n[0] = Datum{o[0].x, o[0].y, o[0].z, o[0].level - 1};
      } else {
        for (int i = 0; i < nin; i++) n[i] = Datum{in[i].x, in[i].y, in[i].z, in[i].level};
      }
    };
    auto origin = [](const octmesh_octant_t *o) { return o->x == 0 && o->y == 0 && o->z == 0; };
    octmesh_gloidx_t r = 0;
    for (int i = 0; i < 3; i++) r += m.refine_once(18, origin, replace);
    require(r == 3, "three leaves split");
    check_own(m);
    m.balance(OCTMESH_CONNECT_CORNER, replace);
    check_own(m);
    auto a = m.adapt([](const octmesh_octant_t *o) { return o->level > 2 ? -1 : (o->y == 0); },
                     replace);
    require(a.first > 0 && a.second > 0, "adapt refined and coarsened");
    check_own(m);
    m.partition_for_coarsening();
    check_own(m);
    octmesh_gloidx_t c =
        m.coarsen(true, [](const octmesh_octant_t *f) { return f[0].level > 2; }, replace);
    (void)c;
    check_own(m);
    m.partition();
    check_own(m);
    // A throwing replace: every rank throws, nothing changes.
    auto before = m.leaves();
    bool threw = false;
    try {
      m.refine_once(18, [](const octmesh_octant_t *) { return true; },
                    [](octmesh_locidx_t, const octmesh_octant_t *, const void *, octmesh_locidx_t,
                       const octmesh_octant_t *, void *) { throw std::runtime_error("no"); });
    } catch (const octmesh::Error &) {
      threw = true;
    }
    require(threw, "a throwing replace fails the call");
    require(m.leaves().size() == before.size(), "leaves unchanged");
    check_own(m);
    // A checkpoint (argv[1]): a missing file throws with the leaves
    // intact; the saved one brings every leaf back with its own data.
    require(argc == 2, "usage: leaf_data_cpp CHECKPOINT");
    m.save(argv[1]);
    threw = false;
    try {
      m.load(std::string(argv[1]) + ".missing");
    } catch (const octmesh::Error &) {
      threw = true;
    }
    require(threw, "a missing checkpoint throws");
    require(m.leaves().size() == before.size(), "leaves unchanged");
    m.load(argv[1]);
    require(m.data_size() == (int32_t)sizeof(Datum), "the data size comes back");
    check_own(m);
  }
  {
    // Fields across one step with the previous mesh kept: a trilinear field
    // moves exactly, a constant element field stays.
    octmesh::Mesher m(MPI_COMM_WORLD);
    m.refine(3, [](const octmesh_octant_t &) { return true; });
    m.balance();
    m.keep_previous();
    m.mesh();
    auto f = [](const double *p) { return 1 + p[0] - 2 * p[1] * p[2] + p[0] * p[1] * p[2]; };
    std::vector<double> u_old(m.counts().local_nodes);
    for (size_t i = 0; i < u_old.size(); i++) u_old[i] = f(m.coordinates() + 3 * i);
    std::vector<double> e_old(m.counts().local_elements, 3.0);
    m.refine_once(18, [](const octmesh_octant_t *o) { return o->x == 0; });
    m.balance();
    m.partition();
    m.mesh();
    auto u = m.transfer_nodes(u_old);
    const double *x = m.coordinates();
    for (size_t i = 0; i < u.size(); i++)
      require(std::fabs(u[i] - f(x + 3 * i)) < 1e-12, "trilinear field moved exactly");
    for (double v : m.transfer_elements(e_old)) require(v == 3.0, "constant element field");
    require(m.element_map().uncovered == 0, "every element covered");
    // Zones without a surface: every element is outside.
    m.set_zones();
    m.mesh(OCTMESH_KEEP_ALL);
    auto names = m.zone_names();
    require(names.size() == 2 && names[0] == "inside" && names[1] == "outside", "zone names");
    for (auto z : m.zones()) require(z == 1, "every element outside");
  }
  std::printf("CPP LEAF DATA OK rank %d\n", g_rank);
  MPI_Finalize();
  return 0;
}
