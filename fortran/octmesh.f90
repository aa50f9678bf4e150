!> Fortran interface of octmesh (module `octmesh`), through iso_c_binding.
!>
!> Every function returns the integer status of the C API (OCTMESH_STATUS_OK
!> on success); `octmesh_error(h)` gives the message of the last failure.
!> The communicator is a Fortran handle: an INTEGER with `use mpi`, or
!> `comm%MPI_VAL` with `use mpi_f08`.
!>
!>   type(c_ptr) :: h
!>   st = octmesh_create_f(MPI_COMM_WORLD, h)          ! use mpi
!>   st = octmesh_create_f(MPI_COMM_WORLD%MPI_VAL, h)  ! use mpi_f08
!>   st = octmesh_surface_builtin_f(h, "torus")
!>   st = octmesh_octree_refine_callback(h, 6, c_funloc(my_refine), c_null_ptr)
!>   ...
!>   call octmesh_destroy(h)
!>
!> A refinement callback is a bind(c) function answering .true. to refine
!> (C's bool is logical(c_bool)):
!>   logical(c_bool) function my_refine(ctx, o) bind(c)
!>     type(c_ptr), value :: ctx
!>     type(octmesh_octant_t), intent(in) :: o
!>
!> Local indices and counts (octmesh_locidx_t) are integer(c_int32_t),
!> global ones (octmesh_gloidx_t) integer(c_int64_t); the kinds
!> octmesh_locidx_kind and octmesh_gloidx_kind name them.
module octmesh
  use, intrinsic :: iso_c_binding
  implicit none
  private

  ! Status values (octmesh_status_t).
  integer(c_int), parameter, public :: OCTMESH_STATUS_OK = 0, &
       OCTMESH_STATUS_INVALID_ARGUMENT = 1, OCTMESH_STATUS_IO = 2, &
       OCTMESH_STATUS_FORMAT = 3, OCTMESH_STATUS_GEOMETRY = 4, &
       OCTMESH_STATUS_LIMIT = 5, OCTMESH_STATUS_STATE = 6, &
       OCTMESH_STATUS_MPI = 7, OCTMESH_STATUS_REMOTE_FAILURE = 8, &
       OCTMESH_STATUS_INTERNAL = 9, OCTMESH_STATUS_LEAK = 10
  ! Balance contacts (octmesh_connect_t).
  integer(c_int32_t), parameter, public :: OCTMESH_CONNECT_FACE = 1, &
       OCTMESH_CONNECT_EDGE = 2, OCTMESH_CONNECT_CORNER = 3
  ! Elements kept (octmesh_keep_t).
  integer(c_int32_t), parameter, public :: OCTMESH_KEEP_ALL = 0, &
       OCTMESH_KEEP_INSIDE = 1, OCTMESH_KEEP_OUTSIDE = 2
  ! Cut leaves (octmesh_cut_rule_t).
  integer(c_int32_t), parameter, public :: OCTMESH_CUT_RULE_CENTER = 0, &
       OCTMESH_CUT_RULE_ALL = 1, OCTMESH_CUT_RULE_NONE = 2
  ! Inside rules (octmesh_inside_rule_t).
  integer(c_int32_t), parameter, public :: OCTMESH_INSIDE_RULE_AUTO = 0, &
       OCTMESH_INSIDE_RULE_PARITY = 1, OCTMESH_INSIDE_RULE_WINDING = 2
  ! Element classes (octmesh_class_t, stored one byte each).
  integer(c_int8_t), parameter, public :: OCTMESH_CLASS_OUTSIDE = 0, &
       OCTMESH_CLASS_INSIDE = 1, OCTMESH_CLASS_CUT = 2
  ! OpenFOAM list encodings (octmesh_foam_format_t).
  integer(c_int32_t), parameter, public :: OCTMESH_FOAM_FORMAT_BINARY = 0, &
       OCTMESH_FOAM_FORMAT_ASCII = 1
  !> Kinds of octmesh_locidx_t (local indices and counts) and
  !> octmesh_gloidx_t (global ones).
  integer, parameter, public :: octmesh_locidx_kind = c_int32_t, octmesh_gloidx_kind = c_int64_t
  !> Lattice units per side of the root cube.
  integer(c_int32_t), parameter, public :: OCTMESH_ROOT_LEN = 2**19

  !> octmesh_options_t
  type, bind(c), public :: octmesh_options_t
     real(c_double) :: fit
     integer(c_int64_t) :: max_octants
     integer(c_int32_t) :: verbosity
     integer(c_int64_t) :: memory_budget
  end type octmesh_options_t

  !> octmesh_faces_t: the finite-volume faces and cells (see octmesh.h).
  !> Arrays are C pointers to 0-based data owned by the handle; read them
  !> with c_f_pointer, e.g. call c_f_pointer(f%owner, owner, [f%num_faces]).
  type, bind(c), public :: octmesh_faces_t
     integer(c_int32_t) :: num_faces, num_internal, num_patches
     type(c_ptr) :: owner, neighbour, area, centre, normal, patch_offsets
     type(c_ptr) :: cell_centre, cell_volume
     integer(c_int64_t) :: first_element, global_elements
  end type octmesh_faces_t

  !> octmesh_cell_halo_t: halo elements and the exchange lists per
  !> neighbour rank (0-based indices, see octmesh.h).
  type, bind(c), public :: octmesh_cell_halo_t
     integer(c_int32_t) :: num_halo
     type(c_ptr) :: halo_global, halo_rank
     integer(c_int32_t) :: num_ranks
     type(c_ptr) :: ranks, face_offsets, send_offsets, send, recv_offsets, recv
  end type octmesh_cell_halo_t

  !> octmesh_boundary_t: boundary element faces (element, face, patch) and
  !> each node's patches (0-based, see octmesh.h).
  type, bind(c), public :: octmesh_boundary_t
     integer(c_int32_t) :: num_faces
     type(c_ptr) :: faces, node_offsets, node_patches
  end type octmesh_boundary_t

  !> octmesh_snap_report_t (octmesh_mesh_get_snap_report)
  type, bind(c), public :: octmesh_snap_report_t
     integer(c_int64_t) :: surface_nodes, snapped, partial, unsnapped, feature_nodes, relaxed_nodes, &
          reported_elements
     real(c_double) :: min_scaled_jacobian
  end type octmesh_snap_report_t

  !> octmesh_element_map_t (octmesh_mesh_get_element_map): c_ptr arrays
  !> old_first (int64, -1 none), old_count (int32), level_change (int8).
  type, bind(c), public :: octmesh_element_map_t
     integer(c_int32_t) :: num_elements
     type(c_ptr) :: old_first, old_count, level_change
     integer(c_int64_t) :: uncovered
  end type octmesh_element_map_t

  !> octmesh_octant_t: lowest corner (lattice units) and level.
  type, bind(c), public :: octmesh_octant_t
     integer(c_int32_t) :: x, y, z, level
  end type octmesh_octant_t

  !> octmesh_mesh_counts_t
  type, bind(c), public :: octmesh_mesh_counts_t
     integer(c_int32_t) :: local_elements, local_nodes, num_owned, num_independent
     integer(c_int64_t) :: first_global, global_elements, global_independent, global_face_hanging, &
          global_edge_hanging
  end type octmesh_mesh_counts_t

  !> octmesh_mesh_quality_t (octmesh_mesh_get_quality)
  type, bind(c), public :: octmesh_mesh_quality_t
     integer(c_int64_t) :: elements
     real(c_double) :: scaled_jacobian_min
     integer(c_int64_t) :: inverted_elements
     integer(c_int64_t) :: scaled_jacobian_histogram(20)
     integer(c_int64_t) :: internal_faces
     real(c_double) :: non_orthogonality_max, non_orthogonality_average, skewness_max
     real(c_double) :: internal_skewness_max, boundary_skewness_max
     real(c_double) :: determinant_min, determinant_average
     real(c_double) :: face_weight_min, face_weight_average
     real(c_double) :: volume_ratio_min, volume_ratio_average
     real(c_double) :: face_flatness_min, face_flatness_average, face_twist_min
     integer(c_int64_t) :: non_orthogonal_faces, skewed_internal_faces, skewed_boundary_faces
     integer(c_int64_t) :: low_determinant_cells, low_weight_faces, low_volume_ratio_faces
     integer(c_int64_t) :: twisted_faces
  end type octmesh_mesh_quality_t

  public :: octmesh_create_f, octmesh_destroy, octmesh_error, octmesh_status_name_f
  public :: octmesh_options_default
  public :: octmesh_surface_builtin_f, octmesh_surface_from_stl_f, octmesh_surface_from_triangles
  public :: octmesh_domain_set, octmesh_domain_set_box, octmesh_domain_get
  public :: octmesh_octree_refine_surface, octmesh_octree_refine_callback, octmesh_octree_balance, octmesh_octree_partition
  public :: octmesh_octree_get_num_leaves, octmesh_octree_get_leaves, octmesh_octree_check_leak
  public :: octmesh_octree_refine_once, octmesh_octree_coarsen, octmesh_octree_adapt
  public :: octmesh_octree_partition_for_coarsening
  public :: octmesh_octree_locate_points, octmesh_mesh_locate_points
  public :: octmesh_octree_data_set_size, octmesh_octree_data_get_size, octmesh_octree_data_get
  public :: octmesh_octree_refine_once_ext, octmesh_octree_coarsen_ext, octmesh_octree_adapt_ext
  public :: octmesh_octree_balance_ext
  public :: octmesh_mesh_build, octmesh_mesh_get_counts, octmesh_mesh_write_vtu_f
  public :: octmesh_mesh_write_gmsh_f, octmesh_mesh_write_abaqus_f
  public :: octmesh_octree_save_f, octmesh_octree_load_f
  public :: octmesh_mesh_write_exodus_f, octmesh_mesh_write_cgns_f
  public :: octmesh_mesh_get_quality
  public :: octmesh_mesh_set_inside_rule, octmesh_mesh_get_inside_rule
  public :: octmesh_mesh_write_vtu_fields, octmesh_mesh_write_vtu_fields_f
  public :: octmesh_mesh_get_connectivity, octmesh_mesh_get_coordinates
  public :: octmesh_mesh_get_global_ids, octmesh_mesh_get_owners, octmesh_mesh_get_hanging
  public :: octmesh_mesh_get_element_class, octmesh_mesh_get_element_level
  public :: octmesh_mesh_set_zones, octmesh_mesh_get_zones, octmesh_mesh_get_zone_name_f
  public :: octmesh_mesh_set_conforming
  public :: octmesh_octree_refine_curvature, octmesh_octree_refine_regions_f
  public :: octmesh_octree_refine_surface_part_f, octmesh_surface_from_files_f
  public :: octmesh_mesh_build_faces, octmesh_mesh_get_faces, octmesh_mesh_get_cell_halo
  public :: octmesh_mesh_get_boundary, octmesh_mesh_get_patch_name_f
  public :: octmesh_mesh_rename_patch_f, octmesh_mesh_write_openfoam_f
  public :: octmesh_mesh_set_wall_layer, octmesh_mesh_set_layers
  public :: octmesh_mesh_snap, octmesh_mesh_get_snap_report
  public :: octmesh_mesh_keep_previous, octmesh_mesh_get_element_map
  public :: octmesh_mesh_transfer_elements, octmesh_mesh_transfer_nodes

  interface
     function octmesh_status_name(status) bind(c, name="octmesh_status_name")
       import :: c_ptr, c_int32_t
       integer(c_int32_t), value :: status
       type(c_ptr) :: octmesh_status_name
     end function octmesh_status_name

     function octmesh_options_default(out) bind(c, name="octmesh_options_default")
       import :: c_int, octmesh_options_t
       type(octmesh_options_t), intent(out) :: out
       integer(c_int) :: octmesh_options_default
     end function octmesh_options_default

     function c_octmesh_create_f(comm, opts, out) bind(c, name="octmesh_create_f")
       import :: c_int, c_ptr
       integer(c_int), value :: comm
       type(c_ptr), value :: opts
       type(c_ptr), intent(out) :: out
       integer(c_int) :: c_octmesh_create_f
     end function c_octmesh_create_f

     subroutine octmesh_destroy(h) bind(c, name="octmesh_destroy")
       import :: c_ptr
       type(c_ptr), value :: h
     end subroutine octmesh_destroy

     function octmesh_last_error(h) bind(c, name="octmesh_last_error")
       import :: c_ptr
       type(c_ptr), value :: h
       type(c_ptr) :: octmesh_last_error
     end function octmesh_last_error

     function octmesh_domain_set(h, origin, side) bind(c, name="octmesh_domain_set")
       import :: c_ptr, c_double, c_int
       type(c_ptr), value :: h
       real(c_double), intent(in) :: origin(3)
       real(c_double), value :: side
       integer(c_int) :: octmesh_domain_set
     end function octmesh_domain_set

     !> A box domain lo(3)..hi(3) of roots(1) x roots(2) x roots(3) cubic
     !> root cells (p4est brick order); levels count from the root cells.
     function octmesh_domain_set_box(h, lo, hi, roots) bind(c, name="octmesh_domain_set_box")
       import :: c_ptr, c_double, c_int
       type(c_ptr), value :: h
       real(c_double), intent(in) :: lo(3), hi(3)
       integer(c_int), intent(in) :: roots(3)
       integer(c_int) :: octmesh_domain_set_box
     end function octmesh_domain_set_box

     !> OCTMESH_STATUS_LEAK when the region outside the surface reaches
     !> point(3), known to be inside the body; octmesh_error(h) then
     !> describes the path.
     function octmesh_octree_check_leak(h, point) bind(c, name="octmesh_octree_check_leak")
       import :: c_ptr, c_double, c_int
       type(c_ptr), value :: h
       real(c_double), intent(in) :: point(3)
       integer(c_int) :: octmesh_octree_check_leak
     end function octmesh_octree_check_leak

     function octmesh_mesh_set_inside_rule(h, rule) bind(c, name="octmesh_mesh_set_inside_rule")
       import :: c_ptr, c_int32_t, c_int
       type(c_ptr), value :: h
       integer(c_int32_t), value :: rule
       integer(c_int) :: octmesh_mesh_set_inside_rule
     end function octmesh_mesh_set_inside_rule

     function octmesh_mesh_get_inside_rule(h, rule) bind(c, name="octmesh_mesh_get_inside_rule")
       import :: c_ptr, c_int32_t, c_int
       type(c_ptr), value :: h
       integer(c_int32_t), intent(out) :: rule
       integer(c_int) :: octmesh_mesh_get_inside_rule
     end function octmesh_mesh_get_inside_rule

     function octmesh_domain_get(h, origin, side) bind(c, name="octmesh_domain_get")
       import :: c_ptr, c_double, c_int
       type(c_ptr), value :: h
       real(c_double), intent(out) :: origin(3)
       real(c_double), intent(out) :: side
       integer(c_int) :: octmesh_domain_get
     end function octmesh_domain_get

     function c_octmesh_surface_builtin(h, name) bind(c, name="octmesh_surface_builtin")
       import :: c_ptr, c_char, c_int
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: name(*)
       integer(c_int) :: c_octmesh_surface_builtin
     end function c_octmesh_surface_builtin

     function c_octmesh_surface_from_files(h, n, specs) bind(c, name="octmesh_surface_from_files")
       import :: c_ptr, c_int, c_int32_t
       type(c_ptr), value :: h
       integer(c_int32_t), value :: n
       type(c_ptr), intent(in) :: specs(*)
       integer(c_int) :: c_octmesh_surface_from_files
     end function c_octmesh_surface_from_files

     function c_octmesh_surface_from_stl(h, path) bind(c, name="octmesh_surface_from_stl")
       import :: c_ptr, c_char, c_int
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: path(*)
       integer(c_int) :: c_octmesh_surface_from_stl
     end function c_octmesh_surface_from_stl

     !> xyz: 9 doubles per triangle.
     function octmesh_surface_from_triangles(h, ntri, xyz) &
          bind(c, name="octmesh_surface_from_triangles")
       import :: c_ptr, c_int64_t, c_double, c_int
       type(c_ptr), value :: h
       integer(c_int64_t), value :: ntri
       real(c_double), intent(in) :: xyz(*)
       integer(c_int) :: octmesh_surface_from_triangles
     end function octmesh_surface_from_triangles

     function octmesh_octree_refine_surface(h, level) bind(c, name="octmesh_octree_refine_surface")
       import :: c_ptr, c_int32_t, c_int
       type(c_ptr), value :: h
       integer(c_int32_t), value :: level
       integer(c_int) :: octmesh_octree_refine_surface
     end function octmesh_octree_refine_surface

     !> refine: c_funloc of a bind(c) function (ctx, octant) -> logical(c_bool);
     !> ctx: c_loc of anything, or c_null_ptr.
     function octmesh_octree_refine_callback(h, max_level, refine, ctx) &
          bind(c, name="octmesh_octree_refine_callback")
       import :: c_ptr, c_funptr, c_int32_t, c_int
       type(c_ptr), value :: h
       integer(c_int32_t), value :: max_level
       type(c_funptr), value :: refine
       type(c_ptr), value :: ctx
       integer(c_int) :: octmesh_octree_refine_callback
     end function octmesh_octree_refine_callback

     function octmesh_octree_balance(h, connect) bind(c, name="octmesh_octree_balance")
       import :: c_ptr, c_int32_t, c_int
       type(c_ptr), value :: h
       integer(c_int32_t), value :: connect
       integer(c_int) :: octmesh_octree_balance
     end function octmesh_octree_balance

     !> weight: c_null_funptr for equal counts, or c_funloc of a bind(c)
     !> function (ctx, octant) -> int64.
     function octmesh_octree_partition(h, weight, ctx) bind(c, name="octmesh_octree_partition")
       import :: c_ptr, c_funptr, c_int
       type(c_ptr), value :: h
       type(c_funptr), value :: weight
       type(c_ptr), value :: ctx
       integer(c_int) :: octmesh_octree_partition
     end function octmesh_octree_partition

     !> Adaptation (src/ffi/adapt.rs). refine: as for refine_callback;
     !> refined, coarsened: c_loc of an integer(c_int64_t), or c_null_ptr.
     function octmesh_octree_refine_once(h, max_level, refine, ctx, refined) &
          bind(c, name="octmesh_octree_refine_once")
       import :: c_ptr, c_funptr, c_int32_t, c_int
       type(c_ptr), value :: h
       integer(c_int32_t), value :: max_level
       type(c_funptr), value :: refine
       type(c_ptr), value :: ctx, refined
       integer(c_int) :: octmesh_octree_refine_once
     end function octmesh_octree_refine_once

     !> coarsen: c_funloc of a bind(c) function (ctx, family) ->
     !> logical(c_bool), family the 8 sibling octants.
     function octmesh_octree_coarsen(h, recursive, coarsen, ctx, coarsened) &
          bind(c, name="octmesh_octree_coarsen")
       import :: c_ptr, c_funptr, c_bool, c_int
       type(c_ptr), value :: h
       logical(c_bool), value :: recursive
       type(c_funptr), value :: coarsen
       type(c_ptr), value :: ctx, coarsened
       integer(c_int) :: octmesh_octree_coarsen
     end function octmesh_octree_coarsen

     !> adapt: c_funloc of a bind(c) function (ctx, octant) -> int32:
     !> > 0 refine, 0 keep, < 0 coarsen.
     function octmesh_octree_adapt(h, adapt, ctx, refined, coarsened) &
          bind(c, name="octmesh_octree_adapt")
       import :: c_ptr, c_funptr, c_int
       type(c_ptr), value :: h
       type(c_funptr), value :: adapt
       type(c_ptr), value :: ctx, refined, coarsened
       integer(c_int) :: octmesh_octree_adapt
     end function octmesh_octree_adapt

     !> weight: as for octmesh_octree_partition.
     function octmesh_octree_partition_for_coarsening(h, weight, ctx) &
          bind(c, name="octmesh_octree_partition_for_coarsening")
       import :: c_ptr, c_funptr, c_int
       type(c_ptr), value :: h
       type(c_funptr), value :: weight
       type(c_ptr), value :: ctx
       integer(c_int) :: octmesh_octree_partition_for_coarsening
     end function octmesh_octree_partition_for_coarsening

     !> Per-leaf user data (src/ffi/data.rs): bytes per leaf, 0 detaches.
     function octmesh_octree_data_set_size(h, bytes) bind(c, name="octmesh_octree_data_set_size")
       import :: c_ptr, c_int32_t, c_int
       type(c_ptr), value :: h
       integer(c_int32_t), value :: bytes
       integer(c_int) :: octmesh_octree_data_set_size
     end function octmesh_octree_data_set_size

     function octmesh_octree_data_get_size(h, bytes) bind(c, name="octmesh_octree_data_get_size")
       import :: c_ptr, c_int32_t, c_int
       type(c_ptr), value :: h
       integer(c_int32_t), intent(out) :: bytes
       integer(c_int) :: octmesh_octree_data_get_size
     end function octmesh_octree_data_get_size

     !> data: the local array (c_f_pointer it to the caller's type, shape
     !> (num_leaves)), valid until the leaves change.
     function octmesh_octree_data_get(h, data, num_leaves) bind(c, name="octmesh_octree_data_get")
       import :: c_ptr, c_int32_t, c_int
       type(c_ptr), value :: h
       type(c_ptr), intent(out) :: data
       integer(c_int32_t), intent(out) :: num_leaves
       integer(c_int) :: octmesh_octree_data_get
     end function octmesh_octree_data_get

     !> The _ext forms keep the user data: replace is c_funloc of a bind(c)
     !> function (ctx, num_outgoing, outgoing, outgoing_data, num_incoming,
     !> incoming, incoming_data) -> int32 (0 for success; the counts by
     !> value, the rest c_ptr by value), or c_null_funptr.
     function octmesh_octree_refine_once_ext(h, max_level, refine, replace, ctx, refined) &
          bind(c, name="octmesh_octree_refine_once_ext")
       import :: c_ptr, c_funptr, c_int32_t, c_int
       type(c_ptr), value :: h
       integer(c_int32_t), value :: max_level
       type(c_funptr), value :: refine, replace
       type(c_ptr), value :: ctx, refined
       integer(c_int) :: octmesh_octree_refine_once_ext
     end function octmesh_octree_refine_once_ext

     function octmesh_octree_coarsen_ext(h, recursive, coarsen, replace, ctx, coarsened) &
          bind(c, name="octmesh_octree_coarsen_ext")
       import :: c_ptr, c_funptr, c_bool, c_int
       type(c_ptr), value :: h
       logical(c_bool), value :: recursive
       type(c_funptr), value :: coarsen, replace
       type(c_ptr), value :: ctx, coarsened
       integer(c_int) :: octmesh_octree_coarsen_ext
     end function octmesh_octree_coarsen_ext

     function octmesh_octree_adapt_ext(h, adapt, replace, ctx, refined, coarsened) &
          bind(c, name="octmesh_octree_adapt_ext")
       import :: c_ptr, c_funptr, c_int
       type(c_ptr), value :: h
       type(c_funptr), value :: adapt, replace
       type(c_ptr), value :: ctx, refined, coarsened
       integer(c_int) :: octmesh_octree_adapt_ext
     end function octmesh_octree_adapt_ext

     function octmesh_octree_balance_ext(h, connect, replace, ctx) &
          bind(c, name="octmesh_octree_balance_ext")
       import :: c_ptr, c_funptr, c_int32_t, c_int
       type(c_ptr), value :: h
       integer(c_int32_t), value :: connect
       type(c_funptr), value :: replace
       type(c_ptr), value :: ctx
       integer(c_int) :: octmesh_octree_balance_ext
     end function octmesh_octree_balance_ext

     function octmesh_octree_get_num_leaves(h, nlocal, nglobal) bind(c, name="octmesh_octree_get_num_leaves")
       import :: c_ptr, c_int32_t, c_int64_t, c_int
       type(c_ptr), value :: h
       integer(c_int32_t), intent(out) :: nlocal
       integer(c_int64_t), intent(out) :: nglobal
       integer(c_int) :: octmesh_octree_get_num_leaves
     end function octmesh_octree_get_num_leaves

     function octmesh_octree_get_leaves(h, out, capacity) bind(c, name="octmesh_octree_get_leaves")
       import :: c_ptr, c_int, c_int32_t, octmesh_octant_t
       type(c_ptr), value :: h
       type(octmesh_octant_t), intent(out) :: out(*)
       integer(c_int32_t), value :: capacity
       integer(c_int) :: octmesh_octree_get_leaves
     end function octmesh_octree_get_leaves

     !> Collective: rank_out(i) and global_out(i) (0-based global leaf
     !> index) of the point xyz(:, i), -1 outside the domain.
     function octmesh_octree_locate_points(h, n, xyz, rank_out, global_out) &
          bind(c, name="octmesh_octree_locate_points")
       import :: c_ptr, c_int, c_int32_t, c_int64_t, c_double
       type(c_ptr), value :: h
       integer(c_int32_t), value :: n
       real(c_double), intent(in) :: xyz(3, *)
       integer(c_int32_t), intent(out) :: rank_out(*)
       integer(c_int64_t), intent(out) :: global_out(*)
       integer(c_int) :: octmesh_octree_locate_points
     end function octmesh_octree_locate_points

     !> Collective: rank_out(i) and element_out(i) (0-based global element
     !> number) of the point xyz(:, i); element -1 in a leaf that is no
     !> element, both -1 outside the domain.
     function octmesh_mesh_locate_points(h, n, xyz, rank_out, element_out) &
          bind(c, name="octmesh_mesh_locate_points")
       import :: c_ptr, c_int, c_int32_t, c_int64_t, c_double
       type(c_ptr), value :: h
       integer(c_int32_t), value :: n
       real(c_double), intent(in) :: xyz(3, *)
       integer(c_int32_t), intent(out) :: rank_out(*)
       integer(c_int64_t), intent(out) :: element_out(*)
       integer(c_int) :: octmesh_mesh_locate_points
     end function octmesh_mesh_locate_points

     function octmesh_mesh_build(h, keep, rule) bind(c, name="octmesh_mesh_build")
       import :: c_ptr, c_int32_t, c_int
       type(c_ptr), value :: h
       integer(c_int32_t), value :: keep, rule
       integer(c_int) :: octmesh_mesh_build
     end function octmesh_mesh_build

     function octmesh_mesh_get_counts(h, out) bind(c, name="octmesh_mesh_get_counts")
       import :: c_ptr, c_int, octmesh_mesh_counts_t
       type(c_ptr), value :: h
       type(octmesh_mesh_counts_t), intent(out) :: out
       integer(c_int) :: octmesh_mesh_get_counts
     end function octmesh_mesh_get_counts

     !> Collective: the mesh's quality (scaled Jacobian, checkMesh's
     !> non-orthogonality and skewness).
     function octmesh_mesh_get_quality(h, out) bind(c, name="octmesh_mesh_get_quality")
       import :: c_ptr, c_int, octmesh_mesh_quality_t
       type(c_ptr), value :: h
       type(octmesh_mesh_quality_t), intent(out) :: out
       integer(c_int) :: octmesh_mesh_get_quality
     end function octmesh_mesh_get_quality

     !> The arrays stay owned by the handle: convert with c_f_pointer
     !> (sizes from octmesh_mesh_get_counts).
     function octmesh_mesh_get_connectivity(h, out) bind(c, name="octmesh_mesh_get_connectivity")
       import :: c_ptr, c_int
       type(c_ptr), value :: h
       type(c_ptr), intent(out) :: out
       integer(c_int) :: octmesh_mesh_get_connectivity
     end function octmesh_mesh_get_connectivity

     function octmesh_mesh_get_coordinates(h, out) bind(c, name="octmesh_mesh_get_coordinates")
       import :: c_ptr, c_int
       type(c_ptr), value :: h
       type(c_ptr), intent(out) :: out
       integer(c_int) :: octmesh_mesh_get_coordinates
     end function octmesh_mesh_get_coordinates

     function octmesh_mesh_get_global_ids(h, out) bind(c, name="octmesh_mesh_get_global_ids")
       import :: c_ptr, c_int
       type(c_ptr), value :: h
       type(c_ptr), intent(out) :: out
       integer(c_int) :: octmesh_mesh_get_global_ids
     end function octmesh_mesh_get_global_ids

     function octmesh_mesh_get_owners(h, out) bind(c, name="octmesh_mesh_get_owners")
       import :: c_ptr, c_int
       type(c_ptr), value :: h
       type(c_ptr), intent(out) :: out
       integer(c_int) :: octmesh_mesh_get_owners
     end function octmesh_mesh_get_owners

     function octmesh_mesh_get_hanging(h, count, deps) bind(c, name="octmesh_mesh_get_hanging")
       import :: c_ptr, c_int
       type(c_ptr), value :: h
       type(c_ptr), intent(out) :: count, deps
       integer(c_int) :: octmesh_mesh_get_hanging
     end function octmesh_mesh_get_hanging

     function octmesh_mesh_get_element_class(h, out) bind(c, name="octmesh_mesh_get_element_class")
       import :: c_ptr, c_int
       type(c_ptr), value :: h
       type(c_ptr), intent(out) :: out
       integer(c_int) :: octmesh_mesh_get_element_class
     end function octmesh_mesh_get_element_class

     function octmesh_mesh_get_element_level(h, out) bind(c, name="octmesh_mesh_get_element_level")
       import :: c_ptr, c_int
       type(c_ptr), value :: h
       type(c_ptr), intent(out) :: out
       integer(c_int) :: octmesh_mesh_get_element_level
     end function octmesh_mesh_get_element_level

     !> Collective: whether the next octmesh_mesh_build gives every element
     !> a zone (needs OCTMESH_KEEP_ALL).
     function octmesh_mesh_set_zones(h, on) bind(c, name="octmesh_mesh_set_zones")
       import :: c_ptr, c_int, c_bool
       type(c_ptr), value :: h
       logical(c_bool), value :: on
       integer(c_int) :: octmesh_mesh_set_zones
     end function octmesh_mesh_set_zones

     !> Collective: whether the Gmsh, Abaqus, Exodus II and CGNS writers
     !> write a conforming all-hexahedral mesh.
     function octmesh_mesh_set_conforming(h, on) bind(c, name="octmesh_mesh_set_conforming")
       import :: c_ptr, c_int, c_bool
       type(c_ptr), value :: h
       logical(c_bool), value :: on
       integer(c_int) :: octmesh_mesh_set_conforming
     end function octmesh_mesh_set_conforming

     !> The number of zones and the zone (0-based) of each local element.
     function octmesh_mesh_get_zones(h, num_zones, zones) bind(c, name="octmesh_mesh_get_zones")
       import :: c_ptr, c_int, c_int32_t
       type(c_ptr), value :: h
       integer(c_int32_t), intent(out) :: num_zones
       type(c_ptr), intent(out) :: zones
       integer(c_int) :: octmesh_mesh_get_zones
     end function octmesh_mesh_get_zones

     function c_octmesh_mesh_get_zone_name(h, zone, name) &
          bind(c, name="octmesh_mesh_get_zone_name")
       import :: c_ptr, c_int, c_int32_t
       type(c_ptr), value :: h
       integer(c_int32_t), value :: zone
       type(c_ptr), intent(out) :: name
       integer(c_int) :: c_octmesh_mesh_get_zone_name
     end function c_octmesh_mesh_get_zone_name

     function c_octmesh_mesh_write_vtu(h, pvtu) bind(c, name="octmesh_mesh_write_vtu")
       import :: c_ptr, c_char, c_int
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: pvtu(*)
       integer(c_int) :: c_octmesh_mesh_write_vtu
     end function c_octmesh_mesh_write_vtu

     function c_octmesh_octree_save(h, path) bind(c, name="octmesh_octree_save")
       import :: c_ptr, c_char, c_int
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: path(*)
       integer(c_int) :: c_octmesh_octree_save
     end function c_octmesh_octree_save

     function c_octmesh_octree_load(h, path) bind(c, name="octmesh_octree_load")
       import :: c_ptr, c_char, c_int
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: path(*)
       integer(c_int) :: c_octmesh_octree_load
     end function c_octmesh_octree_load

     function c_octmesh_mesh_write_gmsh(h, path) bind(c, name="octmesh_mesh_write_gmsh")
       import :: c_ptr, c_char, c_int
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: path(*)
       integer(c_int) :: c_octmesh_mesh_write_gmsh
     end function c_octmesh_mesh_write_gmsh

     function c_octmesh_mesh_write_abaqus(h, path) bind(c, name="octmesh_mesh_write_abaqus")
       import :: c_ptr, c_char, c_int
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: path(*)
       integer(c_int) :: c_octmesh_mesh_write_abaqus
     end function c_octmesh_mesh_write_abaqus

     function c_octmesh_mesh_write_exodus(h, path) bind(c, name="octmesh_mesh_write_exodus")
       import :: c_ptr, c_char, c_int
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: path(*)
       integer(c_int) :: c_octmesh_mesh_write_exodus
     end function c_octmesh_mesh_write_exodus

     function c_octmesh_mesh_write_cgns(h, path) bind(c, name="octmesh_mesh_write_cgns")
       import :: c_ptr, c_char, c_int
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: path(*)
       integer(c_int) :: c_octmesh_mesh_write_cgns
     end function c_octmesh_mesh_write_cgns

     !> The C function: `names(k)` points to a NUL-terminated name and
     !> `values(k)` to `local_nodes` doubles (see octmesh.h).
     function octmesh_mesh_write_vtu_fields(h, pvtu, nfields, names, values) &
          bind(c, name="octmesh_mesh_write_vtu_fields")
       import :: c_ptr, c_char, c_int, c_int32_t
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: pvtu(*)
       integer(c_int32_t), value :: nfields
       type(c_ptr), intent(in) :: names(*), values(*)
       integer(c_int) :: octmesh_mesh_write_vtu_fields
     end function octmesh_mesh_write_vtu_fields

     function octmesh_octree_refine_curvature(h, min_level, max_level, feature_angle) &
          bind(c, name="octmesh_octree_refine_curvature")
       import :: c_ptr, c_int, c_int32_t, c_double
       type(c_ptr), value :: h
       integer(c_int32_t), value :: min_level, max_level
       real(c_double), value :: feature_angle
       integer(c_int) :: octmesh_octree_refine_curvature
     end function octmesh_octree_refine_curvature

     function c_octmesh_octree_refine_surface_part(h, name, min_level, max_level, &
          feature_angle) bind(c, name="octmesh_octree_refine_surface_part")
       import :: c_ptr, c_char, c_int, c_int32_t, c_double
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: name(*)
       integer(c_int32_t), value :: min_level, max_level
       real(c_double), value :: feature_angle
       integer(c_int) :: c_octmesh_octree_refine_surface_part
     end function c_octmesh_octree_refine_surface_part

     function c_octmesh_octree_refine_regions(h, min_level, nregions, regions, nbands, &
          distances, levels) bind(c, name="octmesh_octree_refine_regions")
       import :: c_ptr, c_int, c_int32_t, c_double
       type(c_ptr), value :: h
       integer(c_int32_t), value :: min_level, nregions, nbands
       type(c_ptr), intent(in) :: regions(*)
       real(c_double), intent(in) :: distances(*)
       integer(c_int32_t), intent(in) :: levels(*)
       integer(c_int) :: c_octmesh_octree_refine_regions
     end function c_octmesh_octree_refine_regions

     function octmesh_mesh_build_faces(h) bind(c, name="octmesh_mesh_build_faces")
       import :: c_ptr, c_int
       type(c_ptr), value :: h
       integer(c_int) :: octmesh_mesh_build_faces
     end function octmesh_mesh_build_faces

     function octmesh_mesh_get_faces(h, out) bind(c, name="octmesh_mesh_get_faces")
       import :: c_ptr, c_int, octmesh_faces_t
       type(c_ptr), value :: h
       type(octmesh_faces_t), intent(out) :: out
       integer(c_int) :: octmesh_mesh_get_faces
     end function octmesh_mesh_get_faces

     function octmesh_mesh_get_cell_halo(h, out) bind(c, name="octmesh_mesh_get_cell_halo")
       import :: c_ptr, c_int, octmesh_cell_halo_t
       type(c_ptr), value :: h
       type(octmesh_cell_halo_t), intent(out) :: out
       integer(c_int) :: octmesh_mesh_get_cell_halo
     end function octmesh_mesh_get_cell_halo

     function octmesh_mesh_get_boundary(h, out) bind(c, name="octmesh_mesh_get_boundary")
       import :: c_ptr, c_int, octmesh_boundary_t
       type(c_ptr), value :: h
       type(octmesh_boundary_t), intent(out) :: out
       integer(c_int) :: octmesh_mesh_get_boundary
     end function octmesh_mesh_get_boundary

     !> Collective: moves the surface nodes onto the surface (feature angle
     !> in degrees, relaxation layers and iterations, least scaled Jacobian
     !> kept: above 0, at most 0.5; 0.1 for OpenFOAM cases).
     function octmesh_mesh_snap(h, feature_angle, layers, iterations, min_jacobian) &
          bind(c, name="octmesh_mesh_snap")
       import :: c_ptr, c_int, c_int32_t, c_double
       type(c_ptr), value :: h
       real(c_double), value :: feature_angle, min_jacobian
       integer(c_int32_t), value :: layers, iterations
       integer(c_int) :: octmesh_mesh_snap
     end function octmesh_mesh_snap

     !> What the last snap did (global counts).
     function octmesh_mesh_get_snap_report(h, out) bind(c, name="octmesh_mesh_get_snap_report")
       import :: c_ptr, c_int, octmesh_snap_report_t
       type(c_ptr), value :: h
       type(octmesh_snap_report_t), intent(out) :: out
       integer(c_int) :: octmesh_mesh_get_snap_report
     end function octmesh_mesh_get_snap_report

     !> Keep (.true.) or drop (.false.) the mesh a change replaces, for the
     !> transfers.
     function octmesh_mesh_keep_previous(h, keep) bind(c, name="octmesh_mesh_keep_previous")
       import :: c_ptr, c_int, c_bool
       type(c_ptr), value :: h
       logical(c_bool), value :: keep
       integer(c_int) :: octmesh_mesh_keep_previous
     end function octmesh_mesh_keep_previous

     !> Collective on first call: where each element came from.
     function octmesh_mesh_get_element_map(h, map) bind(c, name="octmesh_mesh_get_element_map")
       import :: c_ptr, c_int, octmesh_element_map_t
       type(c_ptr), value :: h
       type(octmesh_element_map_t), intent(out) :: map
       integer(c_int) :: octmesh_mesh_get_element_map
     end function octmesh_mesh_get_element_map

     !> Collective: old_values(ncomp, old elements) to new_values(ncomp,
     !> new elements); capacity = size(new_values).
     function octmesh_mesh_transfer_elements(h, ncomp, old_values, new_values, capacity) &
          bind(c, name="octmesh_mesh_transfer_elements")
       import :: c_ptr, c_int, c_int32_t, c_double
       type(c_ptr), value :: h
       integer(c_int32_t), value :: ncomp, capacity
       real(c_double), intent(in) :: old_values(*)
       real(c_double), intent(out) :: new_values(*)
       integer(c_int) :: octmesh_mesh_transfer_elements
     end function octmesh_mesh_transfer_elements

     !> Collective: a trilinear nodal field old_values(ncomp, old nodes) at
     !> the new nodes; missing counts nodes in no old element.
     function octmesh_mesh_transfer_nodes(h, ncomp, old_values, new_values, capacity, missing) &
          bind(c, name="octmesh_mesh_transfer_nodes")
       import :: c_ptr, c_int, c_int32_t, c_int64_t, c_double
       type(c_ptr), value :: h
       integer(c_int32_t), value :: ncomp, capacity
       real(c_double), intent(in) :: old_values(*)
       real(c_double), intent(out) :: new_values(*)
       integer(c_int64_t), intent(out) :: missing
       integer(c_int) :: octmesh_mesh_transfer_nodes
     end function octmesh_mesh_transfer_nodes

     function c_octmesh_mesh_get_patch_name(h, patch, name) &
          bind(c, name="octmesh_mesh_get_patch_name")
       import :: c_ptr, c_int, c_int32_t
       type(c_ptr), value :: h
       integer(c_int32_t), value :: patch
       type(c_ptr), intent(out) :: name
       integer(c_int) :: c_octmesh_mesh_get_patch_name
     end function c_octmesh_mesh_get_patch_name

     function c_octmesh_mesh_rename_patch(h, from, to) bind(c, name="octmesh_mesh_rename_patch")
       import :: c_ptr, c_char, c_int
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: from(*), to(*)
       integer(c_int) :: c_octmesh_mesh_rename_patch
     end function c_octmesh_mesh_rename_patch

     !> Collective: whether the OpenFOAM case gets the wall layer.
     function octmesh_mesh_set_wall_layer(h, on) bind(c, name="octmesh_mesh_set_wall_layer")
       import :: c_ptr, c_int, c_bool
       type(c_ptr), value :: h
       logical(c_bool), value :: on
       integer(c_int) :: octmesh_mesh_set_wall_layer
     end function octmesh_mesh_set_wall_layer

     !> Collective: boundary layers on every wall patch of the OpenFOAM
     !> case; exactly one of first_layer, final_layer, thickness above 0.
     function octmesh_mesh_set_layers(h, layers, expansion, first_layer, final_layer, &
          thickness, relative) bind(c, name="octmesh_mesh_set_layers")
       import :: c_ptr, c_int, c_int32_t, c_double, c_bool
       type(c_ptr), value :: h
       integer(c_int32_t), value :: layers
       real(c_double), value :: expansion, first_layer, final_layer, thickness
       logical(c_bool), value :: relative
       integer(c_int) :: octmesh_mesh_set_layers
     end function octmesh_mesh_set_layers

     function c_octmesh_mesh_write_openfoam(h, dir, format, overwrite) &
          bind(c, name="octmesh_mesh_write_openfoam")
       import :: c_ptr, c_char, c_int, c_int32_t, c_bool
       type(c_ptr), value :: h
       character(kind=c_char), intent(in) :: dir(*)
       integer(c_int32_t), value :: format
       logical(c_bool), value :: overwrite
       integer(c_int) :: c_octmesh_mesh_write_openfoam
     end function c_octmesh_mesh_write_openfoam

     function c_strlen(s) bind(c, name="strlen")
       import :: c_ptr, c_size_t
       type(c_ptr), value :: s
       integer(c_size_t) :: c_strlen
     end function c_strlen
  end interface

contains

  !> Creates a handle over a duplicate of the Fortran communicator `comm`
  !> (INTEGER with `use mpi`, comm%MPI_VAL with `use mpi_f08`). `opts` is
  !> optional (defaults otherwise). Collective.
  function octmesh_create_f(comm, h, opts) result(status)
    integer, intent(in) :: comm
    type(c_ptr), intent(out) :: h
    type(octmesh_options_t), intent(in), optional, target :: opts
    integer(c_int) :: status
    h = c_null_ptr
    if (present(opts)) then
       status = c_octmesh_create_f(int(comm, c_int), c_loc(opts), h)
    else
       status = c_octmesh_create_f(int(comm, c_int), c_null_ptr, h)
    end if
  end function octmesh_create_f

  !> Copies a NUL-terminated C string into a Fortran string.
  function c_to_f_string(p) result(s)
    type(c_ptr), intent(in) :: p
    character(len=:), allocatable :: s
    character(kind=c_char), pointer :: chars(:)
    integer :: n, i
    if (.not. c_associated(p)) then
       s = ''
       return
    end if
    n = int(c_strlen(p))
    call c_f_pointer(p, chars, [n])
    allocate(character(len=n) :: s)
    do i = 1, n
       s(i:i) = chars(i)
    end do
  end function c_to_f_string

  !> NUL-terminated copies of `strings` in `buf` (each `len(strings) + 1`
  !> long) and their addresses in `ptrs` (at least one entry; a null
  !> pointer when there are no strings), for the C calls that take an array
  !> of strings. The caller's `buf` must have the target attribute and
  !> outlive the call.
  subroutine to_c_strings(strings, buf, ptrs)
    character(len=*), intent(in) :: strings(:)
    character(kind=c_char, len=*), target, intent(out) :: buf(:)
    type(c_ptr), intent(out) :: ptrs(:)
    integer :: k
    ptrs = c_null_ptr
    do k = 1, size(strings)
       buf(k) = trim(strings(k)) // c_null_char
       ptrs(k) = c_loc(buf(k))
    end do
  end subroutine to_c_strings

  !> The message of the last failed call on `h` (c_null_ptr: of the last
  !> failed octmesh_create_f on this thread).
  function octmesh_error(h) result(msg)
    type(c_ptr), intent(in) :: h
    character(len=:), allocatable :: msg
    msg = c_to_f_string(octmesh_last_error(h))
  end function octmesh_error

  !> The name of a status value, e.g. "OCTMESH_STATUS_IO".
  function octmesh_status_name_f(status) result(name)
    integer, intent(in) :: status
    character(len=:), allocatable :: name
    name = c_to_f_string(octmesh_status_name(int(status, c_int32_t)))
  end function octmesh_status_name_f

  !> Built-in surface: "sphere", "torus" or "hull". Collective.
  function octmesh_surface_builtin_f(h, name) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: name
    integer(c_int) :: status
    status = c_octmesh_surface_builtin(h, trim(name) // c_null_char)
  end function octmesh_surface_builtin_f

  !> One part of the surface (a solid, by its patch name) refined to its own
  !> levels min_level..max_level (curvature with feature_angle). Collective.
  function octmesh_octree_refine_surface_part_f(h, name, min_level, max_level, feature_angle) &
       result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: name
    integer(c_int32_t), intent(in) :: min_level, max_level
    real(c_double), intent(in) :: feature_angle
    integer(c_int) :: status
    status = c_octmesh_octree_refine_surface_part(h, trim(name) // c_null_char, min_level, &
         max_level, feature_angle)
  end function octmesh_octree_refine_surface_part_f

  !> Several surfaces (STL files or built-in names) as one, each a part with
  !> its own wall patch. Collective.
  function octmesh_surface_from_files_f(h, specs) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: specs(:)
    integer(c_int) :: status
    character(kind=c_char, len=len(specs) + 1), target :: cspecs(size(specs))
    type(c_ptr) :: ps(max(size(specs), 1))
    call to_c_strings(specs, cspecs, ps)
    status = c_octmesh_surface_from_files(h, int(size(specs), c_int32_t), ps)
  end function octmesh_surface_from_files_f

  !> Surface from an STL file (ASCII or binary). Collective.
  function octmesh_surface_from_stl_f(h, path) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: path
    integer(c_int) :: status
    status = c_octmesh_surface_from_stl(h, trim(path) // c_null_char)
  end function octmesh_surface_from_stl_f

  !> Writes the mesh as VTU pieces and the PVTU `pvtu`. Collective.
  function octmesh_mesh_write_vtu_f(h, pvtu) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: pvtu
    integer(c_int) :: status
    status = c_octmesh_mesh_write_vtu(h, trim(pvtu) // c_null_char)
  end function octmesh_mesh_write_vtu_f

  !> Saves the octree, its domain and its leaf data to one checkpoint file
  !> (octmesh_octree_save). Collective.
  function octmesh_octree_save_f(h, path) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: path
    integer(c_int) :: status
    status = c_octmesh_octree_save(h, trim(path) // c_null_char)
  end function octmesh_octree_save_f

  !> Loads the octree of a checkpoint on any number of ranks, with its leaf
  !> data (octmesh_octree_load). Collective.
  function octmesh_octree_load_f(h, path) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: path
    integer(c_int) :: status
    status = c_octmesh_octree_load(h, trim(path) // c_null_char)
  end function octmesh_octree_load_f

  !> Writes the mesh as one Gmsh MSH 4.1 file (octmesh_mesh_write_gmsh).
  !> Collective.
  function octmesh_mesh_write_gmsh_f(h, path) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: path
    integer(c_int) :: status
    status = c_octmesh_mesh_write_gmsh(h, trim(path) // c_null_char)
  end function octmesh_mesh_write_gmsh_f

  !> Writes the mesh as one Abaqus/CalculiX input file with the hanging
  !> nodes' equations (octmesh_mesh_write_abaqus). Collective.
  function octmesh_mesh_write_abaqus_f(h, path) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: path
    integer(c_int) :: status
    status = c_octmesh_mesh_write_abaqus(h, trim(path) // c_null_char)
  end function octmesh_mesh_write_abaqus_f

  !> Writes the mesh as one Exodus II file with the hanging nodes'
  !> constraints (octmesh_mesh_write_exodus). Collective.
  function octmesh_mesh_write_exodus_f(h, path) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: path
    integer(c_int) :: status
    status = c_octmesh_mesh_write_exodus(h, trim(path) // c_null_char)
  end function octmesh_mesh_write_exodus_f

  !> Writes the mesh as one CGNS file with the hanging nodes' constraints
  !> (octmesh_mesh_write_cgns). Collective.
  function octmesh_mesh_write_cgns_f(h, path) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: path
    integer(c_int) :: status
    status = c_octmesh_mesh_write_cgns(h, trim(path) // c_null_char)
  end function octmesh_mesh_write_cgns_f

  !> Writes the mesh as VTU pieces and the PVTU `pvtu` with point fields:
  !> `values(:, k)` (one value per local node, in local node order, hanging
  !> nodes included) is called `trim(names(k))`. `size(values, 2)` must
  !> equal `size(names)` (otherwise every rank gets
  !> OCTMESH_STATUS_INVALID_ARGUMENT) and `size(values, 1)` the number of
  !> local nodes. Collective.
  function octmesh_mesh_write_vtu_fields_f(h, pvtu, names, values) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: pvtu
    character(len=*), intent(in) :: names(:)
    real(c_double), intent(in), target, contiguous :: values(:, :)
    integer(c_int) :: status
    character(kind=c_char, len=len(names) + 1), target :: cnames(size(names))
    type(c_ptr) :: pn(max(size(names), 1)), pv(max(size(names), 1))
    integer :: k, n
    integer(c_int32_t) :: nfields
    n = size(names)
    call to_c_strings(names, cnames, pn)
    pv = c_null_ptr
    do k = 1, n
       if (k <= size(values, 2) .and. size(values, 1) > 0) pv(k) = c_loc(values(1, k))
    end do
    ! A shape mismatch is passed on as an invalid count, so that every rank
    ! still takes part in the collective call and fails with the others.
    nfields = int(n, c_int32_t)
    if (size(values, 2) /= n) nfields = -1_c_int32_t
    status = octmesh_mesh_write_vtu_fields(h, trim(pvtu) // c_null_char, nfields, pn, pv)
  end function octmesh_mesh_write_vtu_fields_f

  !> The name of patch `patch` (0-based: 0..5 the sides xmin..zmax, 6 the
  !> surface). `status` is the C call's.
  function octmesh_mesh_get_patch_name_f(h, patch, status) result(name)
    type(c_ptr), intent(in) :: h
    integer, intent(in) :: patch
    integer(c_int), intent(out) :: status
    character(len=:), allocatable :: name
    type(c_ptr) :: p
    p = c_null_ptr
    status = c_octmesh_mesh_get_patch_name(h, int(patch, c_int32_t), p)
    name = c_to_f_string(p)
  end function octmesh_mesh_get_patch_name_f

  !> The name of zone `zone` (0-based: 0 inside, 1 outside, then the
  !> regions' zones). `status` is the C call's.
  function octmesh_mesh_get_zone_name_f(h, zone, status) result(name)
    type(c_ptr), intent(in) :: h
    integer, intent(in) :: zone
    integer(c_int), intent(out) :: status
    character(len=:), allocatable :: name
    type(c_ptr) :: p
    p = c_null_ptr
    status = c_octmesh_mesh_get_zone_name(h, int(zone, c_int32_t), p)
    name = c_to_f_string(p)
  end function octmesh_mesh_get_zone_name_f

  !> Renames patch `from` to `to` (an OpenFOAM word). Collective.
  function octmesh_mesh_rename_patch_f(h, from, to) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: from, to
    integer(c_int) :: status
    status = c_octmesh_mesh_rename_patch(h, trim(from) // c_null_char, trim(to) // c_null_char)
  end function octmesh_mesh_rename_patch_f

  !> Writes the mesh as an OpenFOAM case in `dir` (format
  !> OCTMESH_FOAM_FORMAT_BINARY or _ASCII; an existing mesh is replaced only
  !> when `overwrite`). Collective.
  function octmesh_mesh_write_openfoam_f(h, dir, format, overwrite) result(status)
    type(c_ptr), intent(in) :: h
    character(len=*), intent(in) :: dir
    integer, intent(in) :: format
    logical, intent(in) :: overwrite
    integer(c_int) :: status
    status = c_octmesh_mesh_write_openfoam(h, trim(dir) // c_null_char, &
         int(format, c_int32_t), logical(overwrite, c_bool))
  end function octmesh_mesh_write_openfoam_f

  !> Region refinement (like the command's --min-level, --region and
  !> --distance): `regions(k)` in the command's form, e.g.
  !> "box:0,0,0,1,1,1:6" or "sphere:0,0,0,0.5:7:outside"; `distances` and
  !> `levels` the bands (same size, distances increasing). Collective.
  function octmesh_octree_refine_regions_f(h, min_level, regions, distances, levels) &
       result(status)
    type(c_ptr), intent(in) :: h
    integer, intent(in) :: min_level
    character(len=*), intent(in) :: regions(:)
    real(c_double), intent(in) :: distances(:)
    integer(c_int32_t), intent(in) :: levels(:)
    integer(c_int) :: status
    character(kind=c_char, len=len(regions) + 1), target :: cregions(size(regions))
    type(c_ptr) :: pr(max(size(regions), 1))
    real(c_double) :: d(max(size(distances), 1))
    integer(c_int32_t) :: l(max(size(levels), 1)), nbands
    call to_c_strings(regions, cregions, pr)
    d = 0
    l = 0
    d(1:size(distances)) = distances
    l(1:size(levels)) = levels
    ! Mismatched sizes go on as an invalid count: every rank still joins
    ! the collective call and fails with the others.
    nbands = int(size(distances), c_int32_t)
    if (size(levels) /= size(distances)) nbands = -1_c_int32_t
    status = c_octmesh_octree_refine_regions(h, int(min_level, c_int32_t), &
         int(size(regions), c_int32_t), pr, nbands, d, l)
  end function octmesh_octree_refine_regions_f

end module octmesh
