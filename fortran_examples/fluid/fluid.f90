! Fluid mesh (elements outside the surface) around the built-in torus, with
! a Fortran refinement callback and a context, snapped onto the torus;
! prints the counts and the snap report and writes a VTU with the point
! field "z" (height of each node), and the mesh as OUT.pvtu.exo (Exodus II)
! and OUT.pvtu.cgns (CGNS). Usage: fluid [OUT.pvtu]
module fluid_refine
  use, intrinsic :: iso_c_binding
  use octmesh
  implicit none
  !> Context of the callback: refine the lower half (z below the middle of
  !> the cube) down to `level`; counts the calls.
  type, bind(c) :: half_ctx
     integer(c_int32_t) :: level
     integer(c_int64_t) :: calls
  end type half_ctx
contains
  logical(c_bool) function refine_lower_half(ctx, o) bind(c)
    type(c_ptr), value :: ctx
    type(octmesh_octant_t), intent(in) :: o
    type(half_ctx), pointer :: c
    call c_f_pointer(ctx, c)
    c%calls = c%calls + 1
    refine_lower_half = o%z < OCTMESH_ROOT_LEN / 2 .and. o%level < c%level
  end function refine_lower_half
end module fluid_refine

program fluid
  use, intrinsic :: iso_c_binding
  use mpi_f08
  use octmesh
  use fluid_refine
  implicit none
  type(c_ptr) :: h
  type(half_ctx), target :: ctx
  type(octmesh_mesh_counts_t) :: counts
  type(octmesh_snap_report_t) :: snapped
  integer :: rank, ierr
  integer(c_int64_t) :: calls
  character(len=256) :: out
  type(c_ptr) :: pxyz
  real(c_double), pointer :: xyz(:, :)
  real(c_double), allocatable :: height(:, :)

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank)
  out = ''
  if (command_argument_count() >= 1) call get_command_argument(1, out)

  call check(octmesh_create_f(MPI_COMM_WORLD%MPI_VAL, h), c_null_ptr)
  call check(octmesh_surface_builtin_f(h, "torus"), h)
  call check(octmesh_octree_refine_surface(h, 4_c_int32_t), h)
  ctx%level = 5
  ctx%calls = 0
  call check(octmesh_octree_refine_callback(h, 5_c_int32_t, c_funloc(refine_lower_half), c_loc(ctx)), h)
  call check(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h)
  call check(octmesh_octree_partition(h, c_null_funptr, c_null_ptr), h)
  call check(octmesh_mesh_build(h, OCTMESH_KEEP_OUTSIDE, OCTMESH_CUT_RULE_CENTER), h)
  call check(octmesh_mesh_get_counts(h, counts), h)
  ! Body-fitted: the wall's nodes onto the torus, elements kept valid.
  call check(octmesh_mesh_snap(h, 30.0_c_double, 2_c_int32_t, 3_c_int32_t, 0.1_c_double), h)
  call check(octmesh_mesh_get_snap_report(h, snapped), h)
  if (snapped%snapped <= 0 .or. snapped%min_scaled_jacobian < 0.1_c_double) &
       error stop 'snapping moved no node or left a poor element'
  if (len_trim(out) > 0) then
     call check(octmesh_mesh_get_coordinates(h, pxyz), h)
     call c_f_pointer(pxyz, xyz, [3_c_int64_t, int(counts%local_nodes, c_int64_t)])
     allocate(height(counts%local_nodes, 1))
     height(:, 1) = xyz(3, :)
     call check(octmesh_mesh_write_vtu_fields_f(h, trim(out), ['z'], height), h)
     ! The same mesh for Exodus II and CGNS readers (MOOSE, SU2, ...).
     call check(octmesh_mesh_write_exodus_f(h, trim(out) // '.exo'), h)
     call check(octmesh_mesh_write_cgns_f(h, trim(out) // '.cgns'), h)
  end if
  call MPI_Reduce(ctx%calls, calls, 1, MPI_INTEGER8, MPI_SUM, 0, MPI_COMM_WORLD)
  if (rank == 0) then
     write (*, '(a,i0,a,i0,a,i0,a,i0,a,i0)') 'FLUID calls=', calls, &
          ' elements=', counts%global_elements, ' independent=', counts%global_independent, &
          ' face_hanging=', counts%global_face_hanging, ' edge_hanging=', counts%global_edge_hanging
     write (*, '(a,i0,a,i0,a,i0,a,f6.3)') 'FLUID snapped=', snapped%snapped, ' of ', &
          snapped%surface_nodes, ' partial=', snapped%partial, ' min_scaled_jacobian=', &
          snapped%min_scaled_jacobian
  end if
  ! A failing call: the message comes back as a Fortran string.
  if (octmesh_surface_from_stl_f(h, "/nonexistent/torus.stl") /= OCTMESH_STATUS_OK) then
     if (rank == 0) print '(a,a)', 'FLUID expected error: ', octmesh_error(h)
  else
     error stop 'reading a missing file succeeded'
  end if
  call octmesh_destroy(h)
  call MPI_Finalize(ierr)

contains
  subroutine check(status, handle)
    integer(c_int), intent(in) :: status
    type(c_ptr), intent(in) :: handle
    if (status /= OCTMESH_STATUS_OK) then
       print '(a,a,a,a)', 'octmesh failed: ', octmesh_status_name_f(status), ': ', &
            octmesh_error(handle)
       call MPI_Abort(MPI_COMM_WORLD, 2)
    end if
  end subroutine check
end program fluid
