//! The handle: options, creation over the caller's communicator, errors,
//! the domain cube, destruction.

use std::cell::{Cell, RefCell};
use std::ffi::{c_char, CString};
use std::rc::Rc;

use mpi::raw::FromRaw;
use mpi::topology::SimpleCommunicator;

use super::{
    c_string, catch, fail_without_handle, no_handle_error, non_null, octmesh_gloidx_t,
    octmesh_locidx_t, octmesh_status_t, octmesh_status_value, slice_arg, with_mut, with_ref,
    write_out,
};
use crate::config::Config;
use crate::error::{Error, ErrorKind, Result};
use crate::parallel::comm::{agree, CommRef, MpiComm};
use crate::pipeline::Session;
use crate::run::budget::ByteSize;

/// Options of a handle, read once by `octmesh_create`. Initialise with
/// `octmesh_options_default`, then change fields. They fill the same
/// configuration as the `octmesh` command's options of the same names.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct octmesh_options_t {
    /// Longest side of the surface's bounding box as a fraction of the cube
    /// side when the cube is fitted around the surface, in (0, 1]
    /// (default 0.7; `--fit`). Not used after `octmesh_domain_set`.
    pub fit: f64,
    /// Largest number of leaves (over all ranks) a refinement or a balance
    /// may create, at least 0; 0 means unlimited (default;
    /// `--max-octants`). Exceeding it fails with `OCTMESH_STATUS_LIMIT`.
    pub max_octants: octmesh_gloidx_t,
    /// 0 (default) prints nothing; 1 also prints the message of every
    /// failed call on stderr, one line per rank.
    pub verbosity: i32,
    /// Bytes of memory each rank may use (`--memory-budget`); 0 (default)
    /// means the node's available memory shared among its ranks. A
    /// refinement expected to need more fails with `OCTMESH_STATUS_LIMIT`
    /// before it starts, naming the largest level that fits.
    pub memory_budget: u64,
}

impl Default for octmesh_options_t {
    fn default() -> Self {
        let c = Config::default();
        octmesh_options_t {
            fit: c.domain.fit(),
            max_octants: c.octree.max_octants.map_or(0, |n| {
                octmesh_gloidx_t::try_from(n).unwrap_or(octmesh_gloidx_t::MAX)
            }),
            verbosity: 0,
            memory_budget: c.octree.memory_budget.map_or(0, |b| b.0),
        }
    }
}

impl octmesh_options_t {
    /// The configuration these options give.
    fn config(&self) -> Result<Config> {
        let mut c = Config::default();
        crate::config::options::check_key("domain.fit", "options: fit", self.fit)?;
        if self.max_octants < 0 {
            return Err(Error::invalid(format!(
                "options: max_octants must be at least 0, got {}",
                self.max_octants
            )));
        }
        c.domain.fit = Some(self.fit);
        c.octree.max_octants = (self.max_octants > 0).then_some(self.max_octants as u64);
        c.octree.memory_budget = (self.memory_budget > 0).then_some(ByteSize(self.memory_budget));
        c.output.quiet = true;
        Ok(c)
    }
}

/// C arrays derived from the mesh, made on first request.
pub(crate) type MeshArrays = super::mesh::MeshArrays;

/// Opaque handle: a communicator, the pipeline's session (surface, octree,
/// mesh) and the last error. Created by `octmesh_create`, freed by
/// `octmesh_destroy`. A handle must not be used by two threads at once.
pub struct octmesh_t {
    pub(crate) comm: CommRef,
    pub(crate) session: Session,
    verbosity: i32,
    /// The arrays handed out for the mesh of generation `arrays_of`.
    pub(crate) arrays: MeshArrays,
    arrays_of: u64,
    last_error: RefCell<CString>,
    poisoned: Cell<bool>,
}

impl octmesh_t {
    /// Records `e` as the last error and returns its status.
    pub(crate) fn fail(&self, e: Error) -> octmesh_status_t {
        if self.verbosity > 0 {
            use std::io::Write;
            let line = format!(
                "octmesh: error [rank {} of {}]: {}\n",
                self.comm.rank(),
                self.comm.size(),
                e.message()
            );
            let _ = std::io::stderr().write_all(line.as_bytes());
        }
        *self.last_error.borrow_mut() = c_string(e.message());
        octmesh_status_t::from_kind(e.kind())
    }

    /// Marks the handle unusable after a panic.
    pub(crate) fn poison(&self) {
        self.poisoned.set(true);
    }

    /// Fails if a panic left the handle in an unknown state.
    pub(crate) fn usable(&self) -> Result<()> {
        if self.poisoned.get() {
            return Err(Error::new(
                ErrorKind::Internal,
                "the handle is unusable after an internal error: destroy it",
            ));
        }
        Ok(())
    }

    /// A rank-local check made collective.
    pub(crate) fn agree<T>(&self, local: Result<T>) -> Result<T> {
        agree(&*self.comm, local)
    }

    /// Drops the arrays made for a mesh the session no longer holds (the
    /// pointers handed out stay valid until the mesh changes).
    pub(crate) fn forget_stale_arrays(&mut self) {
        let now = self.session.mesh_generation();
        if now != self.arrays_of {
            self.arrays = MeshArrays::default();
            self.arrays_of = now;
        }
    }
}

/// Writes the default options (fit 0.7, no octant limit, verbosity 0, the
/// memory budget from the node's available memory) to `*out`. Not
/// collective.
///
/// \param[out] out  the options
#[no_mangle]
pub extern "C" fn octmesh_options_default(out: *mut octmesh_options_t) -> octmesh_status_t {
    if out.is_null() {
        return fail_without_handle(&Error::invalid("argument 'out' is NULL"));
    }
    write_out(out, octmesh_options_t::default());
    octmesh_status_t::OCTMESH_STATUS_OK
}

fn mpi_flag(f: unsafe extern "C" fn(*mut std::ffi::c_int) -> std::ffi::c_int) -> bool {
    let mut flag = 0;
    // SAFETY: MPI_Initialized and MPI_Finalized may be called at any time.
    unsafe { f(&mut flag) };
    flag != 0
}

fn create(comm: mpi_sys::MPI_Comm, opts: *const octmesh_options_t) -> Result<Box<octmesh_t>> {
    if !mpi_flag(mpi_sys::MPI_Initialized) || mpi_flag(mpi_sys::MPI_Finalized) {
        return Err(Error::new(
            ErrorKind::Mpi,
            "MPI is not initialised (or already finalised): call MPI_Init before octmesh_create",
        ));
    }
    // SAFETY: reading an MPI constant.
    if comm == unsafe { mpi_sys::RSMPI_COMM_NULL } {
        return Err(Error::invalid("the communicator is MPI_COMM_NULL"));
    }
    let mut dup = comm;
    // SAFETY: MPI is initialised and `comm` is a communicator of the caller.
    let rc = unsafe { mpi_sys::MPI_Comm_dup(comm, &mut dup) };
    if rc != 0 {
        return Err(Error::new(
            ErrorKind::Mpi,
            format!("MPI_Comm_dup failed with code {rc}"),
        ));
    }
    // SAFETY: `dup` is a live intra-communicator owned by nobody else; the
    // wrapper frees it when the handle is destroyed.
    let owned = unsafe { SimpleCommunicator::from_raw(dup) };
    let comm: CommRef = Rc::new(MpiComm::new(owned));
    // SAFETY: NULL or a valid options struct (requirement of the C API).
    let options = unsafe { opts.as_ref() }.copied().unwrap_or_default();
    let config = agree(&*comm, options.config())?;
    Ok(Box::new(octmesh_t {
        session: Session::new(comm.clone(), config),
        comm,
        verbosity: options.verbosity,
        arrays: MeshArrays::default(),
        arrays_of: 0,
        last_error: RefCell::new(CString::default()),
        poisoned: Cell::new(false),
    }))
}

/// Creates a handle over a duplicate of `comm`. MPI must be initialised by
/// the caller; octmesh never initialises or finalises it. Collective over
/// `comm`. Destroy the handle with `octmesh_destroy` before `MPI_Finalize`.
/// On failure `*out` is not written and `octmesh_last_error(NULL)` gives
/// the message.
///
/// \param[in]  comm  the communicator the handle works over (duplicated)
/// \param[in]  opts  options, or NULL for the defaults
/// \param[out] out   the new handle
#[no_mangle]
pub extern "C" fn octmesh_create(
    comm: mpi_sys::MPI_Comm,
    opts: *const octmesh_options_t,
    out: *mut *mut octmesh_t,
) -> octmesh_status_t {
    let r = catch(|| {
        non_null(out, "out")?;
        create(comm, opts)
    });
    match r {
        Ok(h) => {
            write_out(out, Box::into_raw(h));
            octmesh_status_t::OCTMESH_STATUS_OK
        }
        Err(e) => fail_without_handle(&e),
    }
}

/// Frees a handle and everything it holds (the communicator duplicate
/// included). NULL is accepted and ignored. Collective over the handle's
/// communicator (it frees a communicator); call it before `MPI_Finalize`
/// (after `MPI_Finalize` the memory is leaked instead).
///
/// \param[in] h  the handle, or NULL
#[no_mangle]
pub extern "C" fn octmesh_destroy(h: *mut octmesh_t) {
    if h.is_null() {
        return;
    }
    // SAFETY: a non-NULL handle comes from octmesh_create and is not used
    // after this call.
    let h = unsafe { Box::from_raw(h) };
    if mpi_flag(mpi_sys::MPI_Finalized) {
        // Freeing the communicator now would be an MPI error.
        std::mem::forget(h);
        return;
    }
    let _ = catch(|| {
        drop(h);
        Ok(())
    });
}

/// The message of the last failed call on `h`, or for NULL, of the last
/// failure on this thread that had no handle (a failed `octmesh_create`, a
/// NULL handle). Never NULL; the string stays valid until the next failed
/// call on the same handle (or thread) or `octmesh_destroy`. Not
/// collective.
///
/// \param[in] h  the handle, or NULL
#[no_mangle]
pub extern "C" fn octmesh_last_error(h: *const octmesh_t) -> *const c_char {
    // SAFETY: NULL or a live handle (requirement of the C API).
    match unsafe { h.as_ref() } {
        None => no_handle_error(),
        Some(h) => h.last_error.borrow().as_ptr(),
    }
}

/// The name of a status value, e.g. `"OCTMESH_STATUS_STATE"`, or
/// `"OCTMESH_STATUS_UNKNOWN"` for a value that is not a status. The string
/// is static. Not collective.
///
/// \param[in] status  a status value
#[no_mangle]
pub extern "C" fn octmesh_status_name(status: octmesh_status_value) -> *const c_char {
    octmesh_status_t::name_of(status).as_ptr()
}

/// Sets the cube of the next construction from the root (by
/// `octmesh_octree_refine_surface`, or `octmesh_octree_refine_callback`
/// without an octree). Without it the cube is fitted around the surface
/// (option `fit`), or is the unit cube when there is no surface. An
/// existing octree keeps its cube. Collective.
///
/// \param[in] h       the handle
/// \param[in] origin  lowest corner, 3 values, user units
/// \param[in] side    side, user units, > 0
#[no_mangle]
pub extern "C" fn octmesh_domain_set(
    h: *mut octmesh_t,
    origin: *const f64,
    side: f64,
) -> octmesh_status_t {
    with_mut(h, |h| {
        // SAFETY: NULL or 3 values (requirement of the C API).
        let d = unsafe { slice_arg(origin, 3, "origin") }
            .and_then(|o| crate::octree::domain::Domain::cube([o[0], o[1], o[2]], side));
        let d = h.agree(d)?;
        let c = h.session.config_mut();
        c.domain = crate::config::DomainConfig {
            cube: Some([d.origin[0], d.origin[1], d.origin[2], d.side]),
            ..Default::default()
        };
        Ok(())
    })
}

/// Sets a box domain for the next octree instead of the cube: the box
/// `lo..hi` split into `roots[0] x roots[1] x roots[2]` cubic root cells
/// (the trees of a p4est brick, numbered in `p8est_connectivity_new_brick`
/// order). The box's sides divided by the root counts must be equal (else
/// OCTMESH_STATUS_INVALID_ARGUMENT naming boxes that divide). Levels then
/// count from the root cells: level `l` has cells of side `2^-l` of a root
/// cell, up to 18 less the log2 of the largest root count rounded up. The
/// mesh's side patches (`xmin` ... `zmax`) lie on the box. Callbacks of
/// `octmesh_octree_refine_callback` and the adaptation calls, and
/// `octmesh_octree_get_leaves`, still see the lattice of the smallest
/// power-of-two cube of root cells holding the box (levels counted from that
/// cube), the void octants around the box included; meshes, faces and files
/// see the box only. Collective.
///
/// ```text
///        +-----+-----+-----+  hi
///       /     /     /     /|
///      +-----+-----+-----+ |     roots = {3, 1, 1}
///      |  0  |  1  |  2  | +
///      |     |     |     |/
///  lo  +-----+-----+-----+
/// ```
///
/// \param[in] h      the handle
/// \param[in] lo     lowest corner, 3 values, user units
/// \param[in] hi     highest corner, 3 values, user units
/// \param[in] roots  root cells along x, y, z, 3 values, each 1 to 512
#[no_mangle]
pub extern "C" fn octmesh_domain_set_box(
    h: *mut octmesh_t,
    lo: *const f64,
    hi: *const f64,
    roots: *const octmesh_locidx_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        // SAFETY: NULL or 3 values each (requirement of the C API).
        let args = unsafe {
            (
                slice_arg(lo, 3, "lo"),
                slice_arg(hi, 3, "hi"),
                slice_arg(roots, 3, "roots"),
            )
        };
        let d = (|| {
            let (lo, hi, roots) = (args.0?, args.1?, args.2?);
            if roots.iter().any(|&n| n < 1) {
                return Err(crate::error::Error::invalid(format!(
                    "roots must be positive, got {roots:?}"
                )));
            }
            let r = [roots[0] as u32, roots[1] as u32, roots[2] as u32];
            let b = [lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]];
            crate::octree::domain::Domain::brick([b[0], b[1], b[2]], [b[3], b[4], b[5]], r)?;
            Ok((b, r))
        })();
        let (b, r) = h.agree(d)?;
        h.session.config_mut().domain = crate::config::DomainConfig {
            bbox: Some(b),
            roots: Some(r),
            ..Default::default()
        };
        Ok(())
    })
}

/// The cube of the current octree (or, without one, the cube the next
/// construction would use). Not collective.
///
/// \param[in]  h       the handle
/// \param[out] origin  lowest corner, 3 values, user units
/// \param[out] side    side, user units
#[no_mangle]
pub extern "C" fn octmesh_domain_get(
    h: *const octmesh_t,
    origin: *mut f64,
    side: *mut f64,
) -> octmesh_status_t {
    with_ref(h, |h| {
        // SAFETY: NULL or room for 3 values (requirement of the C API).
        let o = unsafe { super::out_slice(origin, 3, 3, "origin") }?;
        non_null(side, "side")?;
        let d = h.session.domain()?;
        o.copy_from_slice(&d.origin);
        write_out(side, d.side);
        Ok(())
    })
}
