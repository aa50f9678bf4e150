//! The handle: creation over the caller's communicator, options, errors,
//! the domain cube, destruction.

use std::cell::{Cell, OnceCell, RefCell};
use std::ffi::{c_char, CString};
use std::rc::Rc;

use mpi::raw::FromRaw;
use mpi::topology::SimpleCommunicator;

use super::{
    c_string, catch, fail_without_handle, no_handle_error, non_null, octmesh_status_t, with_mut,
    with_ref, write_out,
};
use crate::classify::InsideRule;
use crate::comm::{agree, CommRef, MpiComm};
use crate::domain::{Domain, DEFAULT_FIT};
use crate::error::{Error, ErrorKind, Result};
use crate::geometry::Surface;
use crate::mesh::Mesh;
use crate::octree::LinearOctree;
use crate::refine::{SurfaceIndex, NO_LIMIT};

/// Options of a handle, read once by `octmesh_create`. Initialise with
/// `octmesh_options_default`, then change fields.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct octmesh_options_t {
    /// Longest side of the surface's bounding box as a fraction of the cube
    /// side when the cube is fitted around the surface, in (0, 1]
    /// (default 0.7). Not used after `octmesh_set_domain`.
    pub fit: f64,
    /// Largest number of leaves (over all ranks) a refinement or a balance
    /// may create; 0 means unlimited (default). Exceeding it fails with
    /// `OCTMESH_STATUS_LIMIT`.
    pub max_octants: u64,
    /// 0 (default) prints nothing; 1 also prints the message of every
    /// failed call on stderr, one line per rank.
    pub verbosity: i32,
}

impl Default for octmesh_options_t {
    fn default() -> Self {
        octmesh_options_t {
            fit: DEFAULT_FIT,
            max_octants: 0,
            verbosity: 0,
        }
    }
}

/// The surface, with its index for the domain it was last mapped to.
pub(crate) struct SurfaceState {
    pub(crate) surface: Surface,
    pub(crate) index: SurfaceIndex,
    pub(crate) index_domain: Domain,
    /// The rule `InsideRule::Auto` picks for it, once diagnosed.
    pub(crate) auto_rule: OnceCell<InsideRule>,
}

/// The mesh and the C arrays made from it on demand.
pub(crate) struct MeshState {
    pub(crate) mesh: Mesh,
    /// The rule its leaves were classified with (none without a surface).
    pub(crate) inside_rule: Option<InsideRule>,
    pub(crate) cache: super::mesh::MeshArrays,
}

/// Opaque handle: a communicator, options, and the pipeline's current
/// surface, octree and mesh. Created by `octmesh_create`, freed by
/// `octmesh_destroy`. A handle must not be used by two threads at once.
pub struct octmesh_t {
    pub(crate) comm: CommRef,
    pub(crate) options: octmesh_options_t,
    pub(crate) explicit_domain: Option<Domain>,
    pub(crate) surface: Option<SurfaceState>,
    /// The octree and the domain it was built in.
    pub(crate) tree: Option<(LinearOctree, Domain)>,
    pub(crate) mesh: Option<MeshState>,
    /// The inside rule of the next meshes.
    pub(crate) inside_rule: InsideRule,
    last_error: RefCell<CString>,
    poisoned: Cell<bool>,
}

impl octmesh_t {
    /// Records `e` as the last error and returns its status.
    pub(crate) fn fail(&self, e: Error) -> octmesh_status_t {
        if self.options.verbosity > 0 {
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

    /// The refinement limit from the options.
    pub(crate) fn limit(&self) -> u64 {
        match self.options.max_octants {
            0 => NO_LIMIT,
            n => n,
        }
    }

    /// The cube a construction from the root uses: the explicit domain, else
    /// the cube fitted around the surface, else the unit cube.
    pub(crate) fn new_tree_domain(&self) -> Result<Domain> {
        if let Some(d) = self.explicit_domain {
            return Ok(d);
        }
        match &self.surface {
            Some(s) => {
                let b = s.surface.bbox();
                Domain::around(b.min, b.max, self.options.fit)
            }
            None => Domain::cube([0.0; 3], 1.0),
        }
    }

    /// The surface index mapped to `domain` (rebuilt if it was mapped to
    /// another cube), or a state error saying how to give a surface.
    pub(crate) fn index_for(&mut self, domain: &Domain) -> Result<&SurfaceIndex> {
        let s = self.surface.as_mut().ok_or_else(|| {
            Error::new(
                ErrorKind::State,
                "there is no surface: call octmesh_surface_from_stl, \
                 octmesh_surface_from_triangles or octmesh_surface_builtin first",
            )
        })?;
        if s.index_domain != *domain {
            s.index = SurfaceIndex::new(&s.surface, domain);
            s.index_domain = *domain;
        }
        Ok(&s.index)
    }

    /// The octree, or a state error saying how to make one.
    pub(crate) fn tree_or_state(&self) -> Result<&(LinearOctree, Domain)> {
        self.tree.as_ref().ok_or_else(no_tree)
    }

    /// [`Handle::tree_or_state`], mutable.
    pub(crate) fn tree_mut_or_state(&mut self) -> Result<&mut (LinearOctree, Domain)> {
        self.tree.as_mut().ok_or_else(no_tree)
    }
}

fn no_tree() -> Error {
    Error::new(
        ErrorKind::State,
        "there is no octree yet: call octmesh_refine_surface or \
         octmesh_refine_callback first",
    )
}

/// Writes the default options (fit 0.7, no octant limit, verbosity 0) to
/// `*out`. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_options_default(out: *mut octmesh_options_t) -> octmesh_status_t {
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
    let local = match unsafe { opts.as_ref() } {
        None => Ok(octmesh_options_t::default()),
        Some(o) if !(o.fit > 0.0 && o.fit <= 1.0) => Err(Error::invalid(format!(
            "options: fit must be in (0, 1], got {}",
            o.fit
        ))),
        Some(o) => Ok(*o),
    };
    let options = agree(&*comm, local)?;
    Ok(Box::new(octmesh_t {
        comm,
        options,
        explicit_domain: None,
        surface: None,
        tree: None,
        mesh: None,
        inside_rule: InsideRule::Auto,
        last_error: RefCell::new(CString::default()),
        poisoned: Cell::new(false),
    }))
}

/// Creates a handle over a duplicate of `comm` and writes it to `*out`.
/// `opts` may be NULL for the defaults. MPI must be initialised by the
/// caller; octmesh never initialises or finalises it. Collective over
/// `comm`. Destroy the handle with `octmesh_destroy` before
/// `MPI_Finalize`.
///
/// On failure `*out` is not written and `octmesh_last_error(NULL)`
/// gives the message.
#[no_mangle]
pub unsafe extern "C" fn octmesh_create(
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
#[no_mangle]
pub unsafe extern "C" fn octmesh_destroy(h: *mut octmesh_t) {
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
/// failure on this thread that had no handle (a failed
/// `octmesh_create`, a NULL handle). Never NULL; the string stays valid
/// until the next failed call on the same handle (or thread) or
/// `octmesh_destroy`. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_last_error(h: *const octmesh_t) -> *const c_char {
    // SAFETY: NULL or a live handle (requirement of the C API).
    match unsafe { h.as_ref() } {
        None => no_handle_error(),
        Some(h) => h.last_error.borrow().as_ptr(),
    }
}

/// Sets the cube of the next construction from the root (by
/// `octmesh_refine_surface`, or
/// `octmesh_refine_callback` without an octree): lowest
/// corner `origin[3]` and side `side > 0`, in user units. Without it the
/// cube is fitted around the surface (option `fit`), or is the unit cube
/// when there is no surface. An existing octree keeps its cube.
/// Collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_set_domain(
    h: *mut octmesh_t,
    origin: *const f64,
    side: f64,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let d = non_null(origin, "origin").and_then(|_| {
            // SAFETY: non-NULL, 3 values (requirement of the C API).
            let o = unsafe { std::slice::from_raw_parts(origin, 3) };
            Domain::cube([o[0], o[1], o[2]], side)
        });
        let d = h.agree(d)?;
        h.explicit_domain = Some(d);
        Ok(())
    })
}

/// Writes the cube of the current octree (or, without one, the cube the
/// next construction would use) to `origin[3]` and `*side`, user units.
/// Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_get_domain(
    h: *const octmesh_t,
    origin: *mut f64,
    side: *mut f64,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(origin, "origin")?;
        non_null(side, "side")?;
        let d = match &h.tree {
            Some((_, d)) => *d,
            None => h.new_tree_domain()?,
        };
        for k in 0..3 {
            // SAFETY: non-NULL, room for 3 values (requirement of the C API).
            write_out(unsafe { origin.add(k) }, d.origin[k]);
        }
        write_out(side, d.side);
        Ok(())
    })
}
