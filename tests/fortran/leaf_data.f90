! Per-leaf user data from Fortran: one real(c_double) per leaf, prolonged
! by copy and restricted by the mean in a bind(c) replace function, through
! octmesh_octree_adapt_ext, _refine_once_ext, _balance_ext, _coarsen_ext
! and both partitions; the integral (volume x value) must stay the same to
! round-off, also through a checkpoint saved and loaded (its path is the
! first argument), and a failing replace must fail the call and change
! nothing.
! Prints FORTRAN LEAF DATA OK on every rank.
module leaf_data_callbacks
  use, intrinsic :: iso_c_binding
  use octmesh
  implicit none
contains
  function decide(ctx, o) bind(c) result(r)
    type(c_ptr), value :: ctx
    type(octmesh_octant_t), intent(in) :: o
    integer(c_int32_t) :: r
    r = -1
    if (o%x == 0 .and. o%level < 5) r = 1
  end function decide

  function near_origin(ctx, o) bind(c) result(r)
    type(c_ptr), value :: ctx
    type(octmesh_octant_t), intent(in) :: o
    logical(c_bool) :: r
    r = o%x == 0 .and. o%y == 0 .and. o%z == 0
  end function near_origin

  function every_family(ctx, family) bind(c) result(r)
    type(c_ptr), value :: ctx
    type(octmesh_octant_t), intent(in) :: family(8)
    logical(c_bool) :: r
    r = family(1)%x >= 2**17
  end function every_family

  function replace(ctx, nout, outgoing, out_data, nin, incoming, in_data) bind(c) result(r)
    type(c_ptr), value :: ctx, outgoing, out_data, incoming, in_data
    integer(octmesh_locidx_kind), value :: nout, nin
    integer(c_int32_t) :: r
    real(c_double), pointer :: od(:), id(:)
    call c_f_pointer(out_data, od, [nout])
    call c_f_pointer(in_data, id, [nin])
    if (nout == 1) then
      id = od(1)
    else
      id = sum(od) / nout
    end if
    r = 0
  end function replace

  function refuse(ctx, nout, outgoing, out_data, nin, incoming, in_data) bind(c) result(r)
    type(c_ptr), value :: ctx, outgoing, out_data, incoming, in_data
    integer(octmesh_locidx_kind), value :: nout, nin
    integer(c_int32_t) :: r
    r = 7
  end function refuse
end module leaf_data_callbacks

program leaf_data
  use mpi
  use leaf_data_callbacks
  implicit none
  type(c_ptr) :: h
  integer :: ierr, rank, i
  integer(c_int) :: s
  integer(c_int32_t) :: sz
  integer(c_int64_t), target :: refined, coarsened
  real(c_double) :: start
  real(c_double), allocatable :: before(:)
  character(len=4096) :: path
  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call ok(octmesh_create_f(MPI_COMM_WORLD, h))
  call ok(octmesh_octree_refine_callback(h, 2, c_funloc(near_origin), c_null_ptr))
  call ok(octmesh_octree_data_set_size(h, 8))
  call ok(octmesh_octree_data_get_size(h, sz))
  if (sz /= 8) call fail("data size")
  call fill()
  start = integral()
  call ok(octmesh_octree_adapt_ext(h, c_funloc(decide), c_funloc(replace), c_null_ptr, &
                                   c_loc(refined), c_loc(coarsened)))
  call same(start)
  do i = 1, 3
    call ok(octmesh_octree_refine_once_ext(h, 18, c_funloc(near_origin), c_funloc(replace), &
                                           c_null_ptr, c_loc(refined)))
  end do
  call same(start)
  call ok(octmesh_octree_balance_ext(h, OCTMESH_CONNECT_CORNER, c_funloc(replace), c_null_ptr))
  call same(start)
  call ok(octmesh_octree_partition_for_coarsening(h, c_null_funptr, c_null_ptr))
  call same(start)
  call ok(octmesh_octree_coarsen_ext(h, .true._c_bool, c_funloc(every_family), c_funloc(replace), c_null_ptr, &
                                     c_loc(coarsened)))
  call same(start)
  call ok(octmesh_octree_partition(h, c_null_funptr, c_null_ptr))
  call same(start)
  ! A checkpoint (the first argument): saved, a missing file refused, and
  ! loaded back with the data.
  call get_command_argument(1, path)
  call ok(octmesh_octree_save_f(h, path))
  if (octmesh_octree_load_f(h, trim(path) // ".missing") /= OCTMESH_STATUS_IO) &
       call fail("a missing checkpoint was not refused")
  call same(start)
  call ok(octmesh_octree_load_f(h, path))
  call same(start)
  ! A failing replace: an error on every rank, the data as it was.
  allocate(before(0))
  before = values()
  s = octmesh_octree_refine_once_ext(h, 18, c_funloc(near_origin), c_funloc(refuse), c_null_ptr, &
                                     c_null_ptr)
  if (s == OCTMESH_STATUS_OK) call fail("a failing replace succeeded")
  if (any(values() /= before)) call fail("data changed by a failed call")
  call transfer_step()
  call octmesh_destroy(h)
  print '(a,i2)', 'FORTRAN LEAF DATA OK rank', rank
  call MPI_Finalize(ierr)
contains
  subroutine ok(status)
    integer(c_int), intent(in) :: status
    if (status /= OCTMESH_STATUS_OK) call fail("a call failed")
  end subroutine ok

  subroutine fail(what)
    character(*), intent(in) :: what
    print *, 'FAILED rank', rank, ': ', what
    call MPI_Abort(MPI_COMM_WORLD, 3, ierr)
  end subroutine fail

  function values() result(v)
    real(c_double), allocatable :: v(:)
    type(c_ptr) :: p
    integer(c_int32_t) :: n
    real(c_double), pointer :: d(:)
    call ok(octmesh_octree_data_get(h, p, n))
    call c_f_pointer(p, d, [n])
    v = d
  end function values

  ! The value 1 + x + y^2 / 2 at each leaf's corner, the cube of side 1.
  subroutine fill()
    type(c_ptr) :: p
    integer(c_int32_t) :: n
    integer(c_int64_t) :: g
    real(c_double), pointer :: d(:)
    type(octmesh_octant_t), allocatable :: l(:)
    call ok(octmesh_octree_get_num_leaves(h, n, g))
    allocate(l(max(n, 1)))
    call ok(octmesh_octree_get_leaves(h, l, n))
    call ok(octmesh_octree_data_get(h, p, n))
    call c_f_pointer(p, d, [n])
    d = 1 + l(1:n)%x / 2.0d0**19 + 0.5d0 * (l(1:n)%y / 2.0d0**19)**2
  end subroutine fill

  function integral() result(total)
    real(c_double) :: total, mine
    type(c_ptr) :: p
    integer(c_int32_t) :: n
    integer(c_int64_t) :: g
    real(c_double), pointer :: d(:)
    type(octmesh_octant_t), allocatable :: l(:)
    call ok(octmesh_octree_get_num_leaves(h, n, g))
    allocate(l(max(n, 1)))
    call ok(octmesh_octree_get_leaves(h, l, n))
    call ok(octmesh_octree_data_get(h, p, n))
    call c_f_pointer(p, d, [n])
    mine = sum(d * (0.5d0**l(1:n)%level)**3)
    call MPI_Allreduce(mine, total, 1, MPI_DOUBLE_PRECISION, MPI_SUM, MPI_COMM_WORLD, ierr)
  end function integral

  ! A field across one adaptation step with the previous mesh kept: the
  ! trilinear 1 + x + y z moves exactly, an element field's sum of volume
  ! x value is conserved.
  subroutine transfer_step()
    type(octmesh_mesh_counts_t) :: c
    type(octmesh_element_map_t) :: map
    type(c_ptr) :: p
    real(c_double), pointer :: x(:, :)
    real(c_double), allocatable :: u_old(:), u(:), e_old(:), e(:)
    integer(c_int64_t) :: missing
    real(c_double) :: sums(2), all(2)
    call ok(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER))
    call ok(octmesh_mesh_keep_previous(h, .true._c_bool))
    call ok(octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER))
    call ok(octmesh_mesh_get_counts(h, c))
    call ok(octmesh_mesh_get_coordinates(h, p))
    call c_f_pointer(p, x, [3, c%local_nodes])
    u_old = 1 + x(1, :) + x(2, :) * x(3, :)
    allocate(e_old(c%local_elements))
    e_old = 2
    call ok(octmesh_octree_refine_once(h, 18, c_funloc(near_origin), c_null_ptr, c_null_ptr))
    call ok(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER))
    call ok(octmesh_octree_partition(h, c_null_funptr, c_null_ptr))
    call ok(octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER))
    call ok(octmesh_mesh_get_counts(h, c))
    allocate(u(c%local_nodes), e(c%local_elements))
    call ok(octmesh_mesh_transfer_nodes(h, 1, u_old, u, c%local_nodes, missing))
    if (missing /= 0) call fail("nodes without a value")
    call ok(octmesh_mesh_get_coordinates(h, p))
    call c_f_pointer(p, x, [3, c%local_nodes])
    if (maxval(abs(u - (1 + x(1, :) + x(2, :) * x(3, :))), mask=c%local_nodes > 0) > 1d-12) &
         call fail("trilinear field changed")
    call ok(octmesh_mesh_transfer_elements(h, 1, e_old, e, c%local_elements))
    if (any(e /= 2)) call fail("a constant element field changed")
    call ok(octmesh_mesh_get_element_map(h, map))
    if (map%num_elements /= c%local_elements .or. map%uncovered /= 0) call fail("element map")
    sums = [real(size(e_old), c_double), real(size(e), c_double)]
    call MPI_Allreduce(sums, all, 2, MPI_DOUBLE_PRECISION, MPI_SUM, MPI_COMM_WORLD, ierr)
    if (all(2) <= all(1)) call fail("the refinement added no element")
    call zones_step()
  end subroutine transfer_step

  ! Zones without a surface: two zones, every element outside.
  subroutine zones_step()
    type(octmesh_mesh_counts_t) :: c
    type(c_ptr) :: p
    integer(c_int32_t) :: nz
    integer(c_int32_t), pointer :: zone(:)
    integer(c_int) :: st
    call ok(octmesh_mesh_set_zones(h, .true._c_bool))
    call ok(octmesh_mesh_build(h, OCTMESH_KEEP_ALL, OCTMESH_CUT_RULE_CENTER))
    call ok(octmesh_mesh_get_counts(h, c))
    call ok(octmesh_mesh_get_zones(h, nz, p))
    if (nz /= 2) call fail("two zones")
    call c_f_pointer(p, zone, [c%local_elements])
    if (any(zone /= 1)) call fail("every element outside")
    if (octmesh_mesh_get_zone_name_f(h, 1, st) /= "outside") call fail("zone name")
    call ok(st)
  end subroutine zones_step

  subroutine same(want)
    real(c_double), intent(in) :: want
    if (abs(integral() - want) > 1d-13 * abs(want)) call fail("integral changed")
  end subroutine same
end program leaf_data
