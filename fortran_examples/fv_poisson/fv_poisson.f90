! Cell-centred finite-volume Poisson solve, -lap(u) = f, on the fluid mesh
! around the built-in torus, with a manufactured solution.
!
! Usage: fv_poisson LEVEL
!
! The mesh: the torus refined at LEVEL, every leaf refined to at least
! LEVEL - 2 (so the whole mesh gets finer with LEVEL), kept outside (fluid),
! 2:1 balanced.
! octmesh_mesh_build_faces gives the faces (owner, other side, area, centre,
! unit normal), the cell centres and volumes, and the cell halo (the
! elements of other ranks sharing a face, with send and receive lists).
!
! Discretisation (two-point flux): through a face between cells O and N,
!   flux = area * (u_N - u_O) / d,   d = (x_N - x_O) . normal,
! and on a boundary face u_N = exact(face centre), x_N = the face centre
! (Dirichlet everywhere: the cube's sides and the torus). The matrix is
! symmetric positive definite; conjugate gradients, matrix-free, with the
! halo values exchanged by MPI_Isend/MPI_Irecv on the cell halo lists before
! each product. Exact solution u = exp(x/2) sin(0.7 y) cos(0.3 z), so
! f = (0.49 + 0.09 - 0.25) u.
!
! Output on rank 0: "FVPOISSON level=... ranks=... cells=... iterations=...
! l2_error=... max_error=..." (volume-weighted L2 and max over cells of
! u - exact at the cell centres).
program fv_poisson
  use, intrinsic :: iso_c_binding
  use mpi_f08
  use octmesh
  implicit none
  type(c_ptr) :: h
  type(octmesh_faces_t) :: fc
  type(octmesh_cell_halo_t) :: hl
  integer :: rank, nranks, ierr, level, it, i, o, nc, nf, nh, nr
  character(len=32) :: arg
  integer(c_int32_t), pointer :: owner(:), nbr(:), send(:), recv(:), soff(:), roff(:), hranks(:)
  real(c_double), pointer :: area(:), fcen(:, :), fnrm(:, :), ccen(:, :), vol(:)
  real(c_double), allocatable :: t(:), b(:), x(:), r(:), p(:), ap(:), ph(:), hcen(:, :)
  real(c_double) :: rr, rr0, alpha, beta, pap, d, e2, emax, vsum, loc(3), glob(3), ue
  type(MPI_Request), allocatable :: req(:)
  real(c_double), allocatable :: sbuf(:), rbuf(:)

  call MPI_Init(ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks)
  level = 4
  if (command_argument_count() >= 1) then
     call get_command_argument(1, arg)
     read (arg, *) level
  end if

  call check(octmesh_create_f(MPI_COMM_WORLD%MPI_VAL, h), c_null_ptr)
  call check(octmesh_surface_builtin_f(h, "torus"), h)
  call check(octmesh_octree_refine_surface(h, int(level, c_int32_t)), h)
  ! Every leaf at least level - 2 (no regions, no distance bands).
  call check(octmesh_octree_refine_regions_f(h, max(level - 2, 0), [character(len=1) ::], &
       [real(c_double) ::], [integer(c_int32_t) ::]), h)
  call check(octmesh_octree_partition(h, c_null_funptr, c_null_ptr), h)
  call check(octmesh_octree_balance(h, OCTMESH_CONNECT_CORNER), h)
  call check(octmesh_octree_partition(h, c_null_funptr, c_null_ptr), h)
  call check(octmesh_mesh_build(h, OCTMESH_KEEP_OUTSIDE, OCTMESH_CUT_RULE_CENTER), h)
  call check(octmesh_mesh_build_faces(h), h)
  call check(octmesh_mesh_get_faces(h, fc), h)
  call check(octmesh_mesh_get_cell_halo(h, hl), h)

  ! The C arrays, 0-based values, seen as Fortran arrays (1-based indices).
  nf = fc%num_faces
  call check(octmesh_mesh_get_counts_cells(h, nc), h)
  nh = hl%num_halo
  nr = hl%num_ranks
  call c_f_pointer(fc%owner, owner, [nf])
  call c_f_pointer(fc%neighbour, nbr, [nf])
  call c_f_pointer(fc%area, area, [nf])
  call c_f_pointer(fc%centre, fcen, [3, nf])
  call c_f_pointer(fc%normal, fnrm, [3, nf])
  call c_f_pointer(fc%cell_centre, ccen, [3, nc])
  call c_f_pointer(fc%cell_volume, vol, [nc])
  call c_f_pointer(hl%ranks, hranks, [nr])
  call c_f_pointer(hl%send_offsets, soff, [nr + 1])
  call c_f_pointer(hl%recv_offsets, roff, [nr + 1])
  call c_f_pointer(hl%send, send, [max(soff(nr + 1), 1)])
  call c_f_pointer(hl%recv, recv, [max(roff(nr + 1), 1)])
  allocate(req(max(2 * nr, 1)), sbuf(3 * soff(nr + 1) + 3), rbuf(3 * roff(nr + 1) + 3))

  ! Halo cell centres, once, through the same exchange as the unknowns.
  allocate(hcen(3, max(nh, 1)))
  call exchange(ccen, hcen, 3)

  ! Face coefficients area / d, and the right-hand side.
  allocate(t(nf), b(nc), x(nc), r(nc), p(nc), ap(nc), ph(max(nh, 1)))
  do i = 1, nc
     b(i) = 0.33d0 * exact(ccen(:, i)) * vol(i)
  end do
  do i = 1, nf
     o = owner(i) + 1
     if (i <= fc%num_internal) then
        d = dot_product(ccen(:, nbr(i) + 1) - ccen(:, o), fnrm(:, i))
     else if (nbr(i) < 0) then
        d = dot_product(fcen(:, i) - ccen(:, o), fnrm(:, i))
        b(o) = b(o) + area(i) / d * exact(fcen(:, i))
     else
        d = dot_product(hcen(:, nbr(i) + 1) - ccen(:, o), fnrm(:, i))
     end if
     t(i) = area(i) / d
  end do

  ! Conjugate gradients from zero.
  x = 0
  r = b
  p = r
  rr = dot(r, r)
  rr0 = rr
  it = 0
  do while (it < 5000 .and. rr > 1d-26 * rr0)
     call apply(p, ap)
     pap = dot(p, ap)
     alpha = rr / pap
     x = x + alpha * p
     r = r - alpha * ap
     beta = rr
     rr = dot(r, r)
     beta = rr / beta
     p = r + beta * p
     it = it + 1
  end do

  ! Errors at the cell centres.
  e2 = 0
  emax = 0
  vsum = 0
  do i = 1, nc
     ue = x(i) - exact(ccen(:, i))
     e2 = e2 + vol(i) * ue * ue
     vsum = vsum + vol(i)
     emax = max(emax, abs(ue))
  end do
  loc = [e2, vsum, 0d0]
  call MPI_Allreduce(loc, glob, 3, MPI_DOUBLE_PRECISION, MPI_SUM, MPI_COMM_WORLD)
  call MPI_Allreduce(MPI_IN_PLACE, emax, 1, MPI_DOUBLE_PRECISION, MPI_MAX, MPI_COMM_WORLD)
  if (rank == 0) then
     write (*, '(a,i0,a,i0,a,i0,a,i0,a,es13.6,a,es13.6)') 'FVPOISSON level=', level, &
          ' ranks=', nranks, ' cells=', fc%global_elements, ' iterations=', it, &
          ' l2_error=', sqrt(glob(1) / glob(2)), ' max_error=', emax
  end if
  call octmesh_destroy(h)
  call MPI_Finalize(ierr)

contains

  pure function exact(q) result(u)
    real(c_double), intent(in) :: q(3)
    real(c_double) :: u
    u = exp(0.5d0 * q(1)) * sin(0.7d0 * q(2)) * cos(0.3d0 * q(3))
  end function exact

  !> Dot product over all ranks (every local cell is owned by its rank).
  function dot(a, c) result(s)
    real(c_double), intent(in) :: a(:), c(:)
    real(c_double) :: s
    s = dot_product(a, c)
    call MPI_Allreduce(MPI_IN_PLACE, s, 1, MPI_DOUBLE_PRECISION, MPI_SUM, MPI_COMM_WORLD)
  end function dot

  !> Sends `m` values per cell of the send lists, receives those of the
  !> halo cells: local(:, cell) to halo(:, halo cell).
  subroutine exchange(local, halo, m)
    integer, intent(in) :: m
    real(c_double), intent(in) :: local(m, *)
    real(c_double), intent(inout) :: halo(m, *)
    integer :: q, j
    do q = 1, nr
       do j = soff(q) + 1, soff(q + 1)
          sbuf(m * (j - 1) + 1:m * j) = local(:, send(j) + 1)
       end do
       call MPI_Irecv(rbuf(m * roff(q) + 1), m * (roff(q + 1) - roff(q)), MPI_DOUBLE_PRECISION, &
            hranks(q), 7, MPI_COMM_WORLD, req(2 * q - 1))
       call MPI_Isend(sbuf(m * soff(q) + 1), m * (soff(q + 1) - soff(q)), MPI_DOUBLE_PRECISION, &
            hranks(q), 7, MPI_COMM_WORLD, req(2 * q))
    end do
    call MPI_Waitall(2 * nr, req, MPI_STATUSES_IGNORE)
    do q = 1, nr
       do j = roff(q) + 1, roff(q + 1)
          halo(:, recv(j) + 1) = rbuf(m * (j - 1) + 1:m * j)
       end do
    end do
  end subroutine exchange

  !> y = A v: the sum over each cell's faces of area / d (v_O - v_N).
  subroutine apply(v, y)
    real(c_double), intent(in) :: v(:)
    real(c_double), intent(out) :: y(:)
    integer :: f, a
    call exchange(v, ph, 1)
    y = 0
    do f = 1, nf
       a = owner(f) + 1
       if (f <= fc%num_internal) then
          y(a) = y(a) + t(f) * (v(a) - v(nbr(f) + 1))
          y(nbr(f) + 1) = y(nbr(f) + 1) + t(f) * (v(nbr(f) + 1) - v(a))
       else if (nbr(f) < 0) then
          y(a) = y(a) + t(f) * v(a)
       else
          y(a) = y(a) + t(f) * (v(a) - ph(nbr(f) + 1))
       end if
    end do
  end subroutine apply

  !> The number of local cells.
  function octmesh_mesh_get_counts_cells(handle, cells) result(status)
    type(c_ptr), intent(in) :: handle
    integer, intent(out) :: cells
    integer(c_int) :: status
    type(octmesh_mesh_counts_t) :: counts
    status = octmesh_mesh_get_counts(handle, counts)
    cells = counts%local_elements
  end function octmesh_mesh_get_counts_cells

  subroutine check(status, handle)
    integer(c_int), intent(in) :: status
    type(c_ptr), intent(in) :: handle
    if (status /= OCTMESH_STATUS_OK) then
       print '(a,a,a,a)', 'octmesh failed: ', octmesh_status_name_f(status), ': ', &
            octmesh_error(handle)
       call MPI_Abort(MPI_COMM_WORLD, 2)
    end if
  end subroutine check
end program fv_poisson
