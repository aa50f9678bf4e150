// Header-only C++ wrapper of the octmesh C API (octmesh.h): an RAII handle
// whose methods throw octmesh::Error (a std::runtime_error carrying the
// status) with the library's message when a call fails.
//
//   octmesh::Mesher m(MPI_COMM_WORLD);
//   m.surface_builtin("sphere");
//   m.refine_surface(5);
//   m.balance(OCTMESH_CONNECT_CORNER);
//   m.partition();
//   m.mesh(OCTMESH_KEEP_INSIDE);
//   auto c = m.counts();
#ifndef OCTMESH_HPP
#define OCTMESH_HPP

#include <cstdint>
#include <stdexcept>
#include <type_traits>
#include <string>
#include <utility>
#include <vector>

// Only the C bindings of MPI are needed: skip the deprecated MPI C++
// bindings (which would need libmpi_cxx) unless the program asked for them
// by including mpi.h first.
#ifndef OMPI_SKIP_MPICXX
#define OMPI_SKIP_MPICXX 1
#endif
#ifndef MPICH_SKIP_MPICXX
#define MPICH_SKIP_MPICXX 1
#endif
#include "octmesh.h"

namespace octmesh {

// The library reads each enumeration passed to it as an int32_t (src/ffi).
static_assert(sizeof(octmesh_status_t) == sizeof(int32_t), "enum size");
static_assert(sizeof(octmesh_connect_t) == sizeof(int32_t), "enum size");
static_assert(sizeof(octmesh_keep_t) == sizeof(int32_t), "enum size");
static_assert(sizeof(octmesh_cut_rule_t) == sizeof(int32_t), "enum size");
static_assert(sizeof(octmesh_inside_rule_t) == sizeof(int32_t), "enum size");
static_assert(sizeof(octmesh_foam_format_t) == sizeof(int32_t), "enum size");

/// A failed octmesh call: what() is the library's message.
class Error : public std::runtime_error {
 public:
  Error(octmesh_status_t status, const std::string &what)
      : std::runtime_error(what), status_(status) {}
  octmesh_status_t status() const noexcept { return status_; }

 private:
  octmesh_status_t status_;
};

namespace detail {
inline void check(octmesh_status_t s, const octmesh_t *h, const char *call) {
  if (s != OCTMESH_STATUS_OK)
    throw Error(s, std::string(call) + ": " + octmesh_status_name(s) + ": " +
                       octmesh_last_error(h));
}
}  // namespace detail

/// Owns an octmesh handle (created in the constructor, destroyed in the
/// destructor, which is collective: destroy before MPI_Finalize). Movable,
/// not copyable.
class Mesher {
 public:
  explicit Mesher(MPI_Comm comm, const octmesh_options_t *opts = nullptr) {
    detail::check(octmesh_create(comm, opts, &h_), nullptr, "octmesh_create");
  }
  ~Mesher() { octmesh_destroy(h_); }
  Mesher(const Mesher &) = delete;
  Mesher &operator=(const Mesher &) = delete;
  Mesher(Mesher &&o) noexcept : h_(std::exchange(o.h_, nullptr)) {}
  Mesher &operator=(Mesher &&o) noexcept {
    if (this != &o) {
      octmesh_destroy(h_);
      h_ = std::exchange(o.h_, nullptr);
    }
    return *this;
  }

  /// The C handle, for calls this wrapper does not cover.
  octmesh_t *get() const noexcept { return h_; }

  void set_domain(const double origin[3], double side) {
    detail::check(octmesh_domain_set(h_, origin, side), h_, "octmesh_domain_set");
  }
  void set_domain_box(const double lo[3], const double hi[3], const octmesh_locidx_t roots[3]) {
    detail::check(octmesh_domain_set_box(h_, lo, hi, roots), h_, "octmesh_domain_set_box");
  }
  void get_domain(double origin[3], double &side) const {
    detail::check(octmesh_domain_get(h_, origin, &side), h_, "octmesh_domain_get");
  }
  void surface_builtin(const std::string &name) {
    detail::check(octmesh_surface_builtin(h_, name.c_str()), h_, "octmesh_surface_builtin");
  }
  void surface_from_files(const std::vector<std::string> &specs) {
    std::vector<const char *> p;
    for (const auto &s : specs) p.push_back(s.c_str());
    detail::check(octmesh_surface_from_files(h_, static_cast<octmesh_locidx_t>(p.size()), p.data()), h_,
                  "octmesh_surface_from_files");
  }
  void surface_from_stl(const std::string &path) {
    detail::check(octmesh_surface_from_stl(h_, path.c_str()), h_, "octmesh_surface_from_stl");
  }
  /// xyz: 9 doubles per triangle.
  void surface_from_triangles(const std::vector<double> &xyz) {
    if (xyz.size() % 9 != 0)
      throw std::invalid_argument("surface_from_triangles: size is not a multiple of 9");
    detail::check(octmesh_surface_from_triangles(h_, (int64_t)(xyz.size() / 9), xyz.data()), h_,
                  "octmesh_surface_from_triangles");
  }
  void refine_surface(int level) {
    detail::check(octmesh_octree_refine_surface(h_, level), h_, "octmesh_octree_refine_surface");
  }
  /// Refines while `f(octant)` is true (below max_level). `f` must give the
  /// same answer on every rank and must not throw.
  template <class F>
  void refine(int max_level, F &&f) {
    auto tramp = [](void *ctx, const octmesh_octant_t *o) -> bool {
      return static_cast<bool>((*static_cast<typename std::remove_reference<F>::type *>(ctx))(*o));
    };
    detail::check(octmesh_octree_refine_callback(h_, max_level, tramp, (void *)&f), h_,
                  "octmesh_octree_refine_callback");
  }
  void refine_surface_part(const std::string &name, int min_level, int max_level,
                           double feature_angle = 30.0) {
    detail::check(octmesh_octree_refine_surface_part(h_, name.c_str(), min_level, max_level,
                                                     feature_angle),
                  h_, "octmesh_octree_refine_surface_part");
  }
  void refine_curvature(int min_level, int max_level, double feature_angle = 30.0) {
    detail::check(octmesh_octree_refine_curvature(h_, min_level, max_level, feature_angle), h_,
                  "octmesh_octree_refine_curvature");
  }
  /// Regions in the command's form ("box:X0,Y0,Z0,X1,Y1,Z1:LEVEL[:outside]", ...)
  /// and distance bands (distance, level), increasing.
  void refine_regions(int min_level, const std::vector<std::string> &regions = {},
                      const std::vector<std::pair<double, int32_t>> &bands = {}) {
    std::vector<const char *> r;
    for (const auto &x : regions) r.push_back(x.c_str());
    std::vector<double> d;
    std::vector<int32_t> l;
    for (const auto &b : bands) {
      d.push_back(b.first);
      l.push_back(b.second);
    }
    detail::check(octmesh_octree_refine_regions(h_, min_level, (octmesh_locidx_t)r.size(),
                                                r.data(), (octmesh_locidx_t)d.size(), d.data(),
                                                l.data()),
                  h_, "octmesh_octree_refine_regions");
  }
  void balance(octmesh_connect_t connect = OCTMESH_CONNECT_CORNER) {
    detail::check(octmesh_octree_balance(h_, connect), h_, "octmesh_octree_balance");
  }
  void partition() {
    detail::check(octmesh_octree_partition(h_, nullptr, nullptr), h_, "octmesh_octree_partition");
  }
  /// octmesh_octree_save: the octree, its domain and its leaf data in one
  /// checkpoint file, written by all ranks.
  void save(const std::string &path) {
    detail::check(octmesh_octree_save(h_, path.c_str()), h_, "octmesh_octree_save");
  }
  /// octmesh_octree_load: the octree of a checkpoint, on any number of
  /// ranks, with its leaf data (data<T>() reads it).
  void load(const std::string &path) {
    detail::check(octmesh_octree_load(h_, path.c_str()), h_, "octmesh_octree_load");
  }
  /// Partitions by `w(octant)` (a uint64_t; must not throw).
  template <class W>
  void partition(W &&w) {
    auto tramp = [](void *ctx, const octmesh_octant_t *o) -> uint64_t {
      return (*static_cast<typename std::remove_reference<W>::type *>(ctx))(*o);
    };
    detail::check(octmesh_octree_partition(h_, tramp, (void *)&w), h_, "octmesh_octree_partition");
  }
  /// Attaches `bytes` of zeroed user data per leaf (0 detaches; another
  /// size while attached throws with OCTMESH_STATUS_STATE).
  void set_data_size(int32_t bytes) {
    detail::check(octmesh_octree_data_set_size(h_, bytes), h_, "octmesh_octree_data_set_size");
  }
  /// Bytes of user data per leaf, 0 when none is attached.
  int32_t data_size() const {
    int32_t n = 0;
    detail::check(octmesh_octree_data_get_size(h_, &n), h_, "octmesh_octree_data_get_size");
    return n;
  }
  /// The local user data as `T` (sizeof(T) must be the data size), one per
  /// leaf in Morton order: {pointer, count}, valid until the leaves change.
  template <class T>
  std::pair<T *, octmesh_locidx_t> data() {
    static_assert(std::is_trivially_copyable<T>::value, "leaf data is raw bytes");
    if ((int32_t)sizeof(T) != data_size())
      throw std::invalid_argument("data: sizeof(T) differs from the leaf data size");
    void *p = nullptr;
    octmesh_locidx_t n = 0;
    detail::check(octmesh_octree_data_get(h_, &p, &n), h_, "octmesh_octree_data_get");
    return {static_cast<T *>(p), n};
  }
  /// A replace callback for the calls below: `r(nout, out, out_data, nin,
  /// in, in_data)` (see octmesh_replace_fn) returning nothing; an exception
  /// it throws fails the call on every rank (as a non-zero return in C).
  struct NoReplace {};
  /// Refines each leaf where `f(&octant)` is true once (below max_level),
  /// keeping the user data through `r`; returns the leaves split. The
  /// callables must give the same answer on every rank; `f` must not throw.
  template <class F, class R = NoReplace>
  octmesh_gloidx_t refine_once(int max_level, F &&f, R &&r = R()) {
    Ctx<F, R> c{&f, &r};
    octmesh_gloidx_t n = 0;
    detail::check(octmesh_octree_refine_once_ext(h_, max_level, &Ctx<F, R>::decide, replace_of<F, R>(),
                                                 &c, &n),
                  h_, "octmesh_octree_refine_once_ext");
    return n;
  }
  /// Coarsens families where `f(family)` (a pointer to 8 octants) is true, keeping the
  /// user data through `r`; returns the families coarsened.
  template <class F, class R = NoReplace>
  octmesh_gloidx_t coarsen(bool recursive, F &&f, R &&r = R()) {
    Ctx<F, R> c{&f, &r};
    octmesh_gloidx_t n = 0;
    detail::check(octmesh_octree_coarsen_ext(h_, recursive, &Ctx<F, R>::decide, replace_of<F, R>(),
                                             &c, &n),
                  h_, "octmesh_octree_coarsen_ext");
    return n;
  }
  /// Adapts by `f(&octant)` (> 0 refine, 0 keep, < 0 coarsen), keeping the
  /// user data through `r`; returns {leaves split, families coarsened}.
  template <class F, class R = NoReplace>
  std::pair<octmesh_gloidx_t, octmesh_gloidx_t> adapt(F &&f, R &&r = R()) {
    Ctx<F, R> c{&f, &r};
    octmesh_gloidx_t a = 0, b = 0;
    detail::check(octmesh_octree_adapt_ext(h_, &Ctx<F, R>::verdict, replace_of<F, R>(), &c, &a, &b),
                  h_, "octmesh_octree_adapt_ext");
    return {a, b};
  }
  /// Balances, keeping the user data through `r` (1 -> n replacements).
  template <class R>
  void balance(octmesh_connect_t connect, R &&r) {
    Ctx<int, R> c{nullptr, &r};
    detail::check(octmesh_octree_balance_ext(h_, connect, replace_of<int, R>(), &c), h_,
                  "octmesh_octree_balance_ext");
  }
  /// Partitions keeping families together (the user data moves along).
  void partition_for_coarsening() {
    detail::check(octmesh_octree_partition_for_coarsening(h_, nullptr, nullptr), h_,
                  "octmesh_octree_partition_for_coarsening");
  }
  std::pair<octmesh_locidx_t, octmesh_gloidx_t> num_leaves() const {
    octmesh_locidx_t l = 0;
    octmesh_gloidx_t g = 0;
    detail::check(octmesh_octree_get_num_leaves(h_, &l, &g), h_, "octmesh_octree_get_num_leaves");
    return {l, g};
  }
  std::vector<octmesh_octant_t> leaves() const {
    octmesh_locidx_t n = num_leaves().first;
    std::vector<octmesh_octant_t> v((size_t)n);
    detail::check(octmesh_octree_get_leaves(h_, v.data(), n), h_, "octmesh_octree_get_leaves");
    return v;
  }
  // Throws Error with status OCTMESH_STATUS_LEAK when the region outside
  // the surface reaches point[3], a point inside the body.
  void check_leak(const double point[3]) {
    detail::check(octmesh_octree_check_leak(h_, point), h_, "octmesh_octree_check_leak");
  }
  /// Collective: the rank and global leaf index holding each of this
  /// rank's points (x, y, z per point, user units); -1 outside the domain.
  std::pair<std::vector<int32_t>, std::vector<octmesh_gloidx_t>> locate_points(
      const std::vector<double> &xyz) const {
    octmesh_locidx_t n = (octmesh_locidx_t)(xyz.size() / 3);
    std::vector<int32_t> r((size_t)n);
    std::vector<octmesh_gloidx_t> g((size_t)n);
    detail::check(octmesh_octree_locate_points(h_, n, xyz.data(), r.data(), g.data()), h_,
                  "octmesh_octree_locate_points");
    return {r, g};
  }
  /// Collective: the rank and global element number holding each point;
  /// element -1 in a leaf the mesh did not keep, both -1 outside.
  std::pair<std::vector<int32_t>, std::vector<octmesh_gloidx_t>> locate_elements(
      const std::vector<double> &xyz) const {
    octmesh_locidx_t n = (octmesh_locidx_t)(xyz.size() / 3);
    std::vector<int32_t> r((size_t)n);
    std::vector<octmesh_gloidx_t> e((size_t)n);
    detail::check(octmesh_mesh_locate_points(h_, n, xyz.data(), r.data(), e.data()), h_,
                  "octmesh_mesh_locate_points");
    return {r, e};
  }
  void mesh(octmesh_keep_t keep = OCTMESH_KEEP_ALL,
            octmesh_cut_rule_t rule = OCTMESH_CUT_RULE_CENTER) {
    detail::check(octmesh_mesh_build(h_, keep, rule), h_, "octmesh_mesh_build");
  }
  /// How the next meshes find leaf centres inside (octmesh_inside_rule_t).
  void set_inside_rule(octmesh_inside_rule_t rule) {
    detail::check(octmesh_mesh_set_inside_rule(h_, rule), h_, "octmesh_mesh_set_inside_rule");
  }
  /// The rule the current mesh was classified with.
  octmesh_inside_rule_t inside_rule() const {
    octmesh_inside_rule_t r = OCTMESH_INSIDE_RULE_AUTO;
    detail::check(octmesh_mesh_get_inside_rule(h_, &r), h_, "octmesh_mesh_get_inside_rule");
    return r;
  }
  octmesh_mesh_counts_t counts() const {
    octmesh_mesh_counts_t c;
    detail::check(octmesh_mesh_get_counts(h_, &c), h_, "octmesh_mesh_get_counts");
    return c;
  }
  /// Measures the mesh's quality (collective): scaled Jacobian, checkMesh's
  /// non-orthogonality and skewness.
  octmesh_mesh_quality_t quality() {
    octmesh_mesh_quality_t q;
    detail::check(octmesh_mesh_get_quality(h_, &q), h_, "octmesh_mesh_get_quality");
    return q;
  }
  /// Snaps the mesh to the surface (collective): surface nodes onto it,
  /// scaled back where an element's corner would fall below min_jacobian,
  /// the layers next to it relaxed. Returns what it did.
  octmesh_snap_report_t snap(double feature_angle = 30.0, int layers = 2, int iterations = 3,
                             double min_jacobian = 0.001) {
    detail::check(octmesh_mesh_snap(h_, feature_angle, layers, iterations, min_jacobian), h_,
                  "octmesh_mesh_snap");
    octmesh_snap_report_t r;
    detail::check(octmesh_mesh_get_snap_report(h_, &r), h_, "octmesh_mesh_get_snap_report");
    return r;
  }
  /// 8 local node numbers per element (VTK hexahedron order); owned by the handle.
  const octmesh_locidx_t *connectivity() const {
    const octmesh_locidx_t *p = nullptr;
    detail::check(octmesh_mesh_get_connectivity(h_, &p), h_, "octmesh_mesh_get_connectivity");
    return p;
  }
  /// x, y, z per local node; owned by the handle.
  const double *coordinates() const {
    const double *p = nullptr;
    detail::check(octmesh_mesh_get_coordinates(h_, &p), h_, "octmesh_mesh_get_coordinates");
    return p;
  }
  /// Extracts the faces, cell halo and boundary (collective); then the
  /// three getters below.
  void build_faces() {
    detail::check(octmesh_mesh_build_faces(h_), h_, "octmesh_mesh_build_faces");
  }
  octmesh_faces_t faces() const {
    octmesh_faces_t f;
    detail::check(octmesh_mesh_get_faces(h_, &f), h_, "octmesh_mesh_get_faces");
    return f;
  }
  octmesh_cell_halo_t cell_halo() const {
    octmesh_cell_halo_t c;
    detail::check(octmesh_mesh_get_cell_halo(h_, &c), h_, "octmesh_mesh_get_cell_halo");
    return c;
  }
  octmesh_boundary_t boundary() const {
    octmesh_boundary_t b;
    detail::check(octmesh_mesh_get_boundary(h_, &b), h_, "octmesh_mesh_get_boundary");
    return b;
  }
  std::string patch_name(octmesh_locidx_t patch) const {
    const char *name = nullptr;
    detail::check(octmesh_mesh_get_patch_name(h_, patch, &name), h_,
                  "octmesh_mesh_get_patch_name");
    return name;
  }
  /// octmesh_mesh_set_zones: whether the next build gives every element a
  /// zone (needs OCTMESH_KEEP_ALL; collective).
  void set_zones(bool on = true) {
    detail::check(octmesh_mesh_set_zones(h_, on), h_, "octmesh_mesh_set_zones");
  }
  /// octmesh_mesh_set_conforming: whether the Gmsh, Abaqus, Exodus II and
  /// CGNS writers write a conforming all-hexahedral mesh (collective).
  void set_conforming(bool on = true) {
    detail::check(octmesh_mesh_set_conforming(h_, on), h_, "octmesh_mesh_set_conforming");
  }
  /// The zone of each local element (octmesh_mesh_get_zones), a copy.
  std::vector<octmesh_locidx_t> zones() const {
    octmesh_locidx_t n = 0;
    const octmesh_locidx_t *p = nullptr;
    detail::check(octmesh_mesh_get_zones(h_, &n, &p), h_, "octmesh_mesh_get_zones");
    return std::vector<octmesh_locidx_t>(p, p + counts().local_elements);
  }
  /// The zones' names by zone index: inside, outside, then the regions'.
  std::vector<std::string> zone_names() const {
    octmesh_locidx_t n = 0;
    const octmesh_locidx_t *p = nullptr;
    detail::check(octmesh_mesh_get_zones(h_, &n, &p), h_, "octmesh_mesh_get_zones");
    std::vector<std::string> out;
    for (octmesh_locidx_t z = 0; z < n; ++z) {
      const char *name = nullptr;
      detail::check(octmesh_mesh_get_zone_name(h_, z, &name), h_, "octmesh_mesh_get_zone_name");
      out.push_back(name);
    }
    return out;
  }
  void rename_patch(const std::string &from, const std::string &to) {
    detail::check(octmesh_mesh_rename_patch(h_, from.c_str(), to.c_str()), h_,
                  "octmesh_mesh_rename_patch");
  }
  /// octmesh_mesh_set_wall_layer: whether write_openfoam gives the case a
  /// wall layer (the staircase kept off the surface, OCTMESH_CUT_RULE_NONE).
  void set_wall_layer(bool on = true) {
    detail::check(octmesh_mesh_set_wall_layer(h_, on), h_, "octmesh_mesh_set_wall_layer");
  }
  /// octmesh_mesh_set_layers: boundary layers on every wall patch of the
  /// OpenFOAM case; exactly one of first_layer, final_layer and thickness
  /// above 0 (layers 0: none).
  void set_layers(int layers, double expansion, double first_layer, double final_layer = 0.0,
                  double thickness = 0.0, bool relative = false) {
    detail::check(octmesh_mesh_set_layers(h_, layers, expansion, first_layer, final_layer,
                                          thickness, relative),
                  h_, "octmesh_mesh_set_layers");
  }
  void write_openfoam(const std::string &dir,
                      octmesh_foam_format_t format = OCTMESH_FOAM_FORMAT_BINARY,
                      bool overwrite = false) {
    detail::check(octmesh_mesh_write_openfoam(h_, dir.c_str(), format, overwrite), h_,
                  "octmesh_mesh_write_openfoam");
  }
  /// Keeps the mesh that a change of the octree replaces, for the
  /// transfers below (off by default).
  void keep_previous(bool keep = true) {
    detail::check(octmesh_mesh_keep_previous(h_, keep), h_, "octmesh_mesh_keep_previous");
  }
  /// Where each element came from in the previous mesh (collective on the
  /// first call); arrays owned by the handle.
  octmesh_element_map_t element_map() {
    octmesh_element_map_t m;
    detail::check(octmesh_mesh_get_element_map(h_, &m), h_, "octmesh_mesh_get_element_map");
    return m;
  }
  /// An element field of the previous mesh (ncomp values per element) on
  /// the current elements: copy on refinement, volume mean on coarsening.
  std::vector<double> transfer_elements(const std::vector<double> &old_values,
                                        octmesh_locidx_t ncomp = 1) {
    std::vector<double> out(static_cast<size_t>(ncomp) * counts().local_elements);
    detail::check(octmesh_mesh_transfer_elements(h_, ncomp, old_values.data(), out.data(),
                                                 static_cast<octmesh_locidx_t>(out.size())),
                  h_, "octmesh_mesh_transfer_elements");
    return out;
  }
  /// A trilinear nodal field of the previous mesh (ncomp values per node)
  /// at the current nodes; NaN at nodes in no old element.
  std::vector<double> transfer_nodes(const std::vector<double> &old_values,
                                     octmesh_locidx_t ncomp = 1) {
    std::vector<double> out(static_cast<size_t>(ncomp) * counts().local_nodes);
    detail::check(octmesh_mesh_transfer_nodes(h_, ncomp, old_values.data(), out.data(),
                                              static_cast<octmesh_locidx_t>(out.size()), nullptr),
                  h_, "octmesh_mesh_transfer_nodes");
    return out;
  }
  void write_vtu(const std::string &pvtu) {
    detail::check(octmesh_mesh_write_vtu(h_, pvtu.c_str()), h_, "octmesh_mesh_write_vtu");
  }
  /// octmesh_mesh_write_gmsh: one Gmsh MSH 4.1 file, gathered on rank 0.
  void write_gmsh(const std::string &path) {
    detail::check(octmesh_mesh_write_gmsh(h_, path.c_str()), h_, "octmesh_mesh_write_gmsh");
  }
  /// octmesh_mesh_write_abaqus: one Abaqus/CalculiX input file with an *EQUATION per hanging
  /// node and degree of freedom, gathered on rank 0.
  void write_abaqus(const std::string &path) {
    detail::check(octmesh_mesh_write_abaqus(h_, path.c_str()), h_, "octmesh_mesh_write_abaqus");
  }
  /// octmesh_mesh_write_exodus: one Exodus II file (netCDF) with the hanging nodes' constraints,
  /// gathered on rank 0.
  void write_exodus(const std::string &path) {
    detail::check(octmesh_mesh_write_exodus(h_, path.c_str()), h_, "octmesh_mesh_write_exodus");
  }
  /// octmesh_mesh_write_cgns: one CGNS file (HDF5) with the hanging nodes' constraints, gathered
  /// on rank 0.
  void write_cgns(const std::string &path) {
    detail::check(octmesh_mesh_write_cgns(h_, path.c_str()), h_, "octmesh_mesh_write_cgns");
  }
  /// Writes the mesh with point fields: each pair is a field name and a
  /// pointer to one double per local node (local node order, hanging nodes
  /// included). Collective; every rank passes the same names.
  void write_vtu(const std::string &pvtu,
                 const std::vector<std::pair<std::string, const double *>> &fields) {
    std::vector<const char *> names;
    std::vector<const double *> values;
    names.reserve(fields.size());
    values.reserve(fields.size());
    for (const auto &f : fields) {
      names.push_back(f.first.c_str());
      values.push_back(f.second);
    }
    // More fields than octmesh_locidx_t holds: -1, which every rank rejects.
    const octmesh_locidx_t n = fields.size() <= static_cast<size_t>(INT32_MAX)
                                   ? static_cast<octmesh_locidx_t>(fields.size())
                                   : -1;
    detail::check(octmesh_mesh_write_vtu_fields(h_, pvtu.c_str(), n, names.data(), values.data()),
                  h_, "octmesh_mesh_write_vtu_fields");
  }

 private:
  // The callables of one call, passed as the C context.
  template <class F, class R>
  struct Ctx {
    typename std::remove_reference<F>::type *f;
    typename std::remove_reference<R>::type *r;
    // A yes-or-no callback (octmesh_refine_fn, octmesh_coarsen_fn).
    static bool decide(void *ctx, const octmesh_octant_t *o) {
      return static_cast<bool>((*static_cast<Ctx *>(ctx)->f)(o));
    }
    // The adaptation callback (octmesh_adapt_fn): > 0 refine, 0 keep, < 0 coarsen.
    static int32_t verdict(void *ctx, const octmesh_octant_t *o) {
      return static_cast<int32_t>((*static_cast<Ctx *>(ctx)->f)(o));
    }
    static int32_t replace(void *ctx, octmesh_locidx_t nout, const octmesh_octant_t *out,
                           const void *out_data, octmesh_locidx_t nin, const octmesh_octant_t *in,
                           void *in_data) {
      try {
        (*static_cast<Ctx *>(ctx)->r)(nout, out, out_data, nin, in, in_data);
        return 0;
      } catch (...) {
        return 1;  // no exception crosses the C library
      }
    }
  };
  // NULL for NoReplace (C++14: overloads rather than if constexpr).
  template <class F, class R>
  static octmesh_replace_fn replace_of(std::false_type) {
    return &Ctx<F, R>::replace;
  }
  template <class F, class R>
  static octmesh_replace_fn replace_of(std::true_type) {
    return nullptr;
  }
  template <class F, class R>
  static octmesh_replace_fn replace_of() {
    return replace_of<F, R>(std::is_same<typename std::decay<R>::type, NoReplace>{});
  }
  octmesh_t *h_ = nullptr;
};

}  // namespace octmesh

#endif
