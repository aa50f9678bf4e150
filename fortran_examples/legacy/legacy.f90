! A legacy-style caller: `use mpi` with an INTEGER communicator (no
! mpi_f08), a solid mesh of the built-in sphere, counts printed on rank 0.
! Usage: legacy
program legacy
  use, intrinsic :: iso_c_binding
  use mpi
  use octmesh
  implicit none
  type(c_ptr) :: h
  type(octmesh_mesh_counts_t) :: counts
  integer :: rank, ierr, comm

  call MPI_Init(ierr)
  ! A communicator of its own, to show any INTEGER handle works.
  call MPI_Comm_dup(MPI_COMM_WORLD, comm, ierr)
  call MPI_Comm_rank(comm, rank, ierr)
  call check(octmesh_create_f(comm, h), c_null_ptr)
  call check(octmesh_surface_builtin_f(h, "sphere"), h)
  call check(octmesh_octree_refine_surface(h, 5_c_int32_t), h)
  call check(octmesh_octree_balance(h, OCTMESH_CONNECT_EDGE), h)
  call check(octmesh_octree_partition(h, c_null_funptr, c_null_ptr), h)
  call check(octmesh_mesh_build(h, OCTMESH_KEEP_INSIDE, OCTMESH_CUT_RULE_CENTER), h)
  call check(octmesh_mesh_get_counts(h, counts), h)
  if (rank == 0) then
     write (*, '(a,i0,a,i0,a,i0)') 'LEGACY elements=', counts%global_elements, &
          ' independent=', counts%global_independent, &
          ' hanging=', counts%global_face_hanging + counts%global_edge_hanging
  end if
  call octmesh_destroy(h)
  call MPI_Comm_free(comm, ierr)
  call MPI_Finalize(ierr)

contains
  subroutine check(status, handle)
    integer(c_int), intent(in) :: status
    type(c_ptr), intent(in) :: handle
    if (status /= OCTMESH_STATUS_OK) then
       print '(a,a,a,a)', 'octmesh failed: ', octmesh_status_name_f(status), ': ', &
            octmesh_error(handle)
       call MPI_Abort(MPI_COMM_WORLD, 2, ierr)
    end if
  end subroutine check
end program legacy
