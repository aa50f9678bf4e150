//! The C ABI: an opaque handle ([`octmesh_t`]) over a
//! [`crate::pipeline::Session`], driven through `extern "C"` functions by C,
//! C++ and Fortran callers.
//!
//! The layer is thin: every function checks its arguments, calls the
//! session's stage and translates the result. The command line and this API
//! run the same stages with the same checks. Conventions, the same for every
//! function:
//!
//! - Names go by subsystem, in pipeline order: the handle
//!   (`octmesh_create`, `octmesh_options_default`, `octmesh_domain_set`,
//!   ...), `octmesh_surface_*`, `octmesh_octree_*`, `octmesh_mesh_*`; the
//!   header's sections follow that order.
//! - Each function returns an [`octmesh_status_t`]; `OCTMESH_STATUS_OK` (0)
//!   means success, the other values are the codes of [`crate::ErrorKind`].
//!   [`handle::octmesh_last_error`] gives the message of the last failed
//!   call on a handle.
//! - Out-parameters are written only on success. An output buffer the caller
//!   allocates is followed by its capacity; a buffer too small fails with
//!   `OCTMESH_STATUS_INVALID_ARGUMENT` naming the size needed.
//! - Local counts and indices are [`octmesh_locidx_t`] (32-bit), global
//!   ones [`octmesh_gloidx_t`] (64-bit), as p4est's `p4est_locidx_t` and
//!   `p4est_gloidx_t`: every count, index, offset and capacity in the
//!   header is one of the two. A plain `int32_t` is a value that indexes
//!   nothing: an MPI rank, an octree level, a lattice coordinate, a byte
//!   size, a number of relaxation layers or iterations, a verbosity, a
//!   callback's verdict.
//! - Yes-or-no arguments and callback answers are `bool` (`<stdbool.h>`;
//!   Rust's `bool` is C's `_Bool`).
//! - No panic crosses the boundary: a panic becomes
//!   `OCTMESH_STATUS_INTERNAL` with a message starting with `panic: `, and
//!   the handle then refuses further work (destroy it).
//! - Collective functions (marked so) must be called by every rank of the
//!   handle's communicator in the same order. Their argument and state
//!   checks are agreed over the ranks, so a failure on one rank (a NULL
//!   pointer, an unreadable file) is reported on every rank instead of
//!   leaving the others waiting. A NULL handle cannot be agreed on: it fails
//!   on the calling rank only.
//! - A failed call leaves the handle as it was before the call.
//! - Every enumeration has one form, p4est's: `typedef enum { OCTMESH_X_A
//!   = 0, ... } octmesh_x_t;`, constants prefixed with the type's name in
//!   capitals, and functions take and give `octmesh_x_t`. On the Rust side
//!   an enumeration passed *to* octmesh arrives as an `i32` (the alias
//!   `octmesh_x_t` here, left out of the header, where the enum `octmesh_x`
//!   is renamed `octmesh_x_t`; see `cbindgen.toml`), so that a value outside
//!   the enumeration is an `OCTMESH_STATUS_INVALID_ARGUMENT`, never the
//!   undefined behaviour of an invalid Rust enum. C's enums of these
//!   values are `int`-sized, the size of `i32` (the C tests and the C++
//!   header assert it).
//! - Only `octmesh_`-prefixed types, the standard integer types, `bool`,
//!   `double`, `char`, `void` and `MPI_Comm` appear in the header.
//!
//! The header `include/octmesh.h` is generated from this module by cbindgen
//! (`tests/c_header.rs` checks that it is up to date and that every
//! parameter is documented `[in]`, `[out]` or `[in,out]`).

#![allow(non_camel_case_types)]
// The entry points are safe `extern "C"` functions, as in rustls-ffi: C
// callers see no `unsafe`, the API's documented contract (valid pointers of
// the stated lengths) is the safety condition, and every pointer goes
// through the checked helpers below (NULL, lengths, capacities) first.
#![allow(clippy::not_unsafe_ptr_arg_deref)]
// The docs carry the C header's doxygen markup (`\param[in] h`), which
// rustdoc would read as links.
#![allow(rustdoc::broken_intra_doc_links)]

pub mod faces;
pub mod handle;
pub mod mesh;
pub mod octree;
// After `octree`: cbindgen keeps declaration order, and these are octree functions.
pub mod adapt;
pub mod data;
pub mod quality;
pub mod search;
pub mod snap;
pub mod surface;
pub mod transfer;

use std::cell::RefCell;
use std::ffi::{c_char, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;

use crate::error::{panic_message, Error, ErrorKind, Result};

pub use handle::octmesh_t;

/// A local count or index: of the elements, nodes, faces, leaves, halo
/// elements, patches or neighbour ranks of one rank, or of the values in
/// one of its arrays (offsets, capacities). 32 bits, as p4est's
/// `p4est_locidx_t`.
pub type octmesh_locidx_t = i32;

/// A global count or number (over all ranks): 64 bits, as p4est's
/// `p4est_gloidx_t`.
pub type octmesh_gloidx_t = i64;

/// An `octmesh_status_t` value as it arrives from C (any `int32_t`); in the
/// header it is `octmesh_status_t`.
pub type octmesh_status_value = i32;

/// Status returned by every octmesh function: `OCTMESH_STATUS_OK`, or the
/// code of what failed (the same numbers as the library's error kinds; the
/// list is `for_each_error_kind!` in `src/error.rs`, and the compiler checks
/// this enumeration against it).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum octmesh_status_t {
    /// Success.
    OCTMESH_STATUS_OK = 0,
    /// An argument was NULL, out of range or inconsistent.
    OCTMESH_STATUS_INVALID_ARGUMENT = 1,
    /// A file could not be opened, read or written.
    OCTMESH_STATUS_IO = 2,
    /// An input file's content is not valid (malformed STL).
    OCTMESH_STATUS_FORMAT = 3,
    /// The surface cannot be used (no triangles, non-finite coordinates,
    /// zero extent).
    OCTMESH_STATUS_GEOMETRY = 4,
    /// A resource limit was reached (the octant limit or the memory budget
    /// of the options).
    OCTMESH_STATUS_LIMIT = 5,
    /// Functions were called in an order that is not allowed (the message
    /// says what to call first).
    OCTMESH_STATUS_STATE = 6,
    /// An MPI call failed, MPI is not initialised, or ranks disagree.
    OCTMESH_STATUS_MPI = 7,
    /// Another rank failed; the message is that rank's.
    OCTMESH_STATUS_REMOTE_FAILURE = 8,
    /// A bug inside octmesh (a caught panic, a broken invariant).
    OCTMESH_STATUS_INTERNAL = 9,
    /// The region outside the surface reaches the point given as inside
    /// (`octmesh_octree_check_leak`); the message describes the path.
    OCTMESH_STATUS_LEAK = 10,
}

macro_rules! status_conversions {
    ($(($variant:ident, $code:literal, $c:ident, $doc:literal)),+ $(,)?) => {
        // The C enumeration above must hold the list's values.
        $(const _: () = assert!(octmesh_status_t::$c as i32 == $code);)+

        impl octmesh_status_t {
            /// The status of an error kind.
            pub fn from_kind(kind: ErrorKind) -> octmesh_status_t {
                match kind {
                    $(ErrorKind::$variant => octmesh_status_t::$c,)+
                }
            }

            /// The name of a status value, for `octmesh_status_name`.
            fn name_of(status: i32) -> &'static CStr {
                match status {
                    0 => c"OCTMESH_STATUS_OK",
                    $($code => {
                        // Built from the same identifier as the enumeration.
                        const NAME: &CStr = match CStr::from_bytes_with_nul(
                            concat!(stringify!($c), "\0").as_bytes(),
                        ) {
                            Ok(n) => n,
                            Err(_) => c"OCTMESH_STATUS_UNKNOWN",
                        };
                        NAME
                    })+
                    _ => c"OCTMESH_STATUS_UNKNOWN",
                }
            }
        }
    };
}

crate::for_each_error_kind!(status_conversions);

/// Declares the conversions between a C enumeration (`octmesh_keep_t`,
/// whose constants are the enum `octmesh_keep`) and a library type:
/// from the C integer (an unknown value is an error naming the allowed
/// constants) and back. The constants are named once, here.
macro_rules! c_enum_conversions {
    ($c_enum:ident, $what:literal, $rust:ty { $($c:ident <=> $value:expr),+ $(,)? }) => {
        impl FromC for $rust {
            fn from_c(x: i32) -> Result<$rust> {
                $(if x == $c_enum::$c as i32 { return Ok($value); })+
                Err(Error::invalid(format!(
                    "{} {x} is not one of {}",
                    $what,
                    [$(stringify!($c)),+].join(", ")
                )))
            }
            fn to_c(self) -> i32 {
                $(if self == $value { return $c_enum::$c as i32; })+
                unreachable!("every value has a C constant")
            }
        }
    };
}

/// A library type with a C enumeration.
pub(crate) trait FromC: Sized {
    /// The value of a C constant, or an error naming the allowed ones.
    fn from_c(x: i32) -> Result<Self>;
    /// The C constant of the value.
    fn to_c(self) -> i32;
}

/// Contacts the 2:1 balance applies to.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum octmesh_connect {
    /// Leaves sharing a face.
    OCTMESH_CONNECT_FACE = 1,
    /// Leaves sharing a face or an edge (enough for meshing).
    OCTMESH_CONNECT_EDGE = 2,
    /// Leaves sharing a face, an edge or a corner.
    OCTMESH_CONNECT_CORNER = 3,
}

/// An `octmesh_connect_t` value as it arrives from C (any `int32_t`, checked
/// by the functions); in the header it is the enum `octmesh_connect_t`.
pub type octmesh_connect_t = i32;

c_enum_conversions!(octmesh_connect, "connect", crate::Connectivity {
    OCTMESH_CONNECT_FACE <=> crate::Connectivity::Face,
    OCTMESH_CONNECT_EDGE <=> crate::Connectivity::Edge,
    OCTMESH_CONNECT_CORNER <=> crate::Connectivity::Corner,
});

/// Which leaves become elements.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum octmesh_keep {
    /// Every leaf (the only choice without a surface).
    OCTMESH_KEEP_ALL = 0,
    /// Leaves inside the surface (solid mesh).
    OCTMESH_KEEP_INSIDE = 1,
    /// Leaves outside the surface (fluid mesh).
    OCTMESH_KEEP_OUTSIDE = 2,
}

/// An `octmesh_keep_t` value as it arrives from C (any `int32_t`, checked
/// by the functions); in the header it is the enum `octmesh_keep_t`.
pub type octmesh_keep_t = i32;

c_enum_conversions!(octmesh_keep, "keep", crate::classify::Keep {
    OCTMESH_KEEP_ALL <=> crate::classify::Keep::All,
    OCTMESH_KEEP_INSIDE <=> crate::classify::Keep::Inside,
    OCTMESH_KEEP_OUTSIDE <=> crate::classify::Keep::Outside,
});

/// What happens to leaves touching the surface when keeping inside or
/// outside.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum octmesh_cut_rule {
    /// A cut leaf goes with its centre: inside and outside tile the cube.
    OCTMESH_CUT_RULE_CENTER = 0,
    /// Every cut leaf is kept.
    OCTMESH_CUT_RULE_ALL = 1,
    /// No cut leaf is kept.
    OCTMESH_CUT_RULE_NONE = 2,
}

/// An `octmesh_cut_rule_t` value as it arrives from C (any `int32_t`, checked
/// by the functions); in the header it is the enum `octmesh_cut_rule_t`.
pub type octmesh_cut_rule_t = i32;

c_enum_conversions!(octmesh_cut_rule, "rule", crate::classify::CutRule {
    OCTMESH_CUT_RULE_CENTER <=> crate::classify::CutRule::Center,
    OCTMESH_CUT_RULE_ALL <=> crate::classify::CutRule::All,
    OCTMESH_CUT_RULE_NONE <=> crate::classify::CutRule::None,
});

/// How a leaf's centre is found inside the surface when meshing (set by
/// `octmesh_mesh_set_inside_rule`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum octmesh_inside_rule {
    /// Parity for a surface made of one closed, consistently oriented
    /// component, winding number otherwise (the default).
    OCTMESH_INSIDE_RULE_AUTO = 0,
    /// Parity of surface crossings along a ray: exact for one closed surface,
    /// the exclusive or of overlapping parts, unreliable near holes.
    OCTMESH_INSIDE_RULE_PARITY = 1,
    /// Generalized winding number above 1/2, after orienting each component:
    /// the union of overlapping parts, holes closed smoothly, reversed
    /// facets repaired.
    OCTMESH_INSIDE_RULE_WINDING = 2,
}

/// An `octmesh_inside_rule_t` value as it arrives from C (any `int32_t`, checked
/// by the functions); in the header it is the enum `octmesh_inside_rule_t`.
pub type octmesh_inside_rule_t = i32;

c_enum_conversions!(octmesh_inside_rule, "inside rule", crate::classify::InsideRule {
    OCTMESH_INSIDE_RULE_AUTO <=> crate::classify::InsideRule::Auto,
    OCTMESH_INSIDE_RULE_PARITY <=> crate::classify::InsideRule::Parity,
    OCTMESH_INSIDE_RULE_WINDING <=> crate::classify::InsideRule::Winding,
});

/// List encoding of OpenFOAM files.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum octmesh_foam_format {
    /// Raw little-endian lists (OpenFOAM's `format binary`).
    OCTMESH_FOAM_FORMAT_BINARY = 0,
    /// Text.
    OCTMESH_FOAM_FORMAT_ASCII = 1,
}

/// An `octmesh_foam_format_t` value as it arrives from C (any `int32_t`, checked
/// by the functions); in the header it is the enum `octmesh_foam_format_t`.
pub type octmesh_foam_format_t = i32;

c_enum_conversions!(octmesh_foam_format, "format", crate::io::openfoam::FoamFormat {
    OCTMESH_FOAM_FORMAT_BINARY <=> crate::io::openfoam::FoamFormat::Binary,
    OCTMESH_FOAM_FORMAT_ASCII <=> crate::io::openfoam::FoamFormat::Ascii,
});

/// Class of an element, as stored (one `int8_t` each) in the array of
/// `octmesh_mesh_get_element_class`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum octmesh_class {
    /// Does not touch the surface, centre outside (every element when there
    /// is no surface).
    OCTMESH_CLASS_OUTSIDE = 0,
    /// Does not touch the surface, centre inside.
    OCTMESH_CLASS_INSIDE = 1,
    /// Touches the surface.
    OCTMESH_CLASS_CUT = 2,
}

// The class bytes of the mesh are handed out as they are stored.
const _: () = {
    use crate::classify::LeafClass;
    assert!(octmesh_class::OCTMESH_CLASS_OUTSIDE as u8 == LeafClass::Outside as u8);
    assert!(octmesh_class::OCTMESH_CLASS_INSIDE as u8 == LeafClass::Inside as u8);
    assert!(octmesh_class::OCTMESH_CLASS_CUT as u8 == LeafClass::Cut as u8);
};

/// An octant as seen by callbacks: its lowest corner in lattice units (the
/// root cube is `[0, 2^19]^3`; lattice point `q` is the user point
/// `origin + q * side / 2^19`, see `octmesh_domain_get`) and its level
/// (side `2^(19 - level)` lattice units).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct octmesh_octant_t {
    /// Lowest x corner, lattice units.
    pub x: i32,
    /// Lowest y corner, lattice units.
    pub y: i32,
    /// Lowest z corner, lattice units.
    pub z: i32,
    /// Level, 0 (root) to 18.
    pub level: i32,
}

impl octmesh_octant_t {
    pub(crate) fn of(o: crate::Octant) -> octmesh_octant_t {
        let c = o.coords();
        octmesh_octant_t {
            x: c[0] as i32,
            y: c[1] as i32,
            z: c[2] as i32,
            level: o.level() as i32,
        }
    }
}

thread_local! {
    /// Message of the last failure that had no handle to store it in.
    static NO_HANDLE_ERROR: RefCell<CString> = RefCell::new(CString::new(
        "no error recorded without a handle").unwrap_or_default());
}

/// Text made safe for a C string (interior NUL bytes replaced).
pub(crate) fn c_string(text: &str) -> CString {
    CString::new(text.replace('\0', "?")).unwrap_or_default()
}

/// Records the message of a failure that has no handle (NULL handle,
/// failed creation) and returns its status.
pub(crate) fn fail_without_handle(e: &Error) -> octmesh_status_t {
    NO_HANDLE_ERROR.with(|m| *m.borrow_mut() = c_string(e.message()));
    octmesh_status_t::from_kind(e.kind())
}

/// The message of the last failure without a handle (thread-local; valid
/// until the next such failure on this thread).
pub(crate) fn no_handle_error() -> *const c_char {
    NO_HANDLE_ERROR.with(|m| m.borrow().as_ptr())
}

/// Runs `f`; `Err` carries the message of a panic.
fn catch_panic<T>(f: impl FnOnce() -> T) -> std::result::Result<T, Error> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|p| {
        Error::new(
            ErrorKind::Internal,
            format!("panic: {}", panic_message(&*p)),
        )
    })
}

/// Runs `f`, turning a panic into an [`ErrorKind::Internal`] error.
pub(crate) fn catch<T>(f: impl FnOnce() -> Result<T>) -> Result<T> {
    catch_panic(f).and_then(|r| r)
}

fn null_handle() -> Error {
    Error::invalid("the octmesh handle is NULL")
}

/// The boundary of a function that may change the handle: NULL check, panic
/// boundary, error recording.
pub(crate) fn with_mut(
    h: *mut octmesh_t,
    f: impl FnOnce(&mut octmesh_t) -> Result<()>,
) -> octmesh_status_t {
    // SAFETY: a non-NULL handle comes from octmesh_create and is not used
    // concurrently (documented requirement of the C API).
    let Some(h) = (unsafe { h.as_mut() }) else {
        return fail_without_handle(&null_handle());
    };
    if let Err(e) = h.usable() {
        return h.fail(e);
    }
    let result = catch_panic(|| f(&mut *h));
    h.forget_stale_arrays();
    match result {
        Ok(Ok(())) => octmesh_status_t::OCTMESH_STATUS_OK,
        Ok(Err(e)) => h.fail(e),
        Err(panic) => {
            // The panic may have left the handle half-updated.
            h.poison();
            h.fail(panic)
        }
    }
}

/// The boundary of a function that only reads the handle.
pub(crate) fn with_ref(
    h: *const octmesh_t,
    f: impl FnOnce(&octmesh_t) -> Result<()>,
) -> octmesh_status_t {
    // SAFETY: as in `with_mut`.
    let Some(h) = (unsafe { h.as_ref() }) else {
        return fail_without_handle(&null_handle());
    };
    if let Err(e) = h.usable() {
        return h.fail(e);
    }
    match catch(|| f(h)) {
        Ok(()) => octmesh_status_t::OCTMESH_STATUS_OK,
        Err(e) => h.fail(e),
    }
}

/// Fails unless `p` is non-NULL.
pub(crate) fn non_null<T>(p: *const T, name: &str) -> Result<()> {
    if p.is_null() {
        Err(Error::invalid(format!("argument '{name}' is NULL")))
    } else {
        Ok(())
    }
}

/// The caller's array `p` of `len` values, read-only.
///
/// # Safety
/// `p` is NULL (an error) or points to `len` initialised values that stay
/// valid and unchanged for `'a` (requirement of the C API).
pub(crate) unsafe fn slice_arg<'a, T>(p: *const T, len: usize, name: &str) -> Result<&'a [T]> {
    non_null(p, name)?;
    if len == 0 {
        return Ok(&[]);
    }
    // SAFETY: non-NULL and `len` values long, by the caller's contract.
    Ok(unsafe { std::slice::from_raw_parts(p, len) })
}

/// The caller's output buffer `p` with room for `capacity` values, of
/// which `needed` are written: fails, naming the size needed, when it is
/// too small.
///
/// # Safety
/// `p` is NULL (an error) or valid for writes of `capacity` values
/// (requirement of the C API).
pub(crate) unsafe fn out_slice<'a, T>(
    p: *mut T,
    capacity: octmesh_locidx_t,
    needed: usize,
    name: &str,
) -> Result<&'a mut [T]> {
    non_null(p, name)?;
    if capacity < 0 || (capacity as usize) < needed {
        return Err(Error::invalid(format!(
            "argument '{name}' has room for {capacity} values, {needed} are needed"
        )));
    }
    // SAFETY: non-NULL and valid for `capacity >= needed` values.
    Ok(unsafe { std::slice::from_raw_parts_mut(p, needed) })
}

/// A path from a NUL-terminated C string.
pub(crate) fn path_arg(p: *const c_char, name: &str) -> Result<PathBuf> {
    non_null(p, name)?;
    // SAFETY: non-NULL and NUL-terminated (requirement of the C API).
    let s = unsafe { CStr::from_ptr(p) };
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        Ok(PathBuf::from(std::ffi::OsStr::from_bytes(s.to_bytes())))
    }
    #[cfg(not(unix))]
    {
        s.to_str()
            .map(PathBuf::from)
            .map_err(|_| Error::invalid(format!("argument '{name}' is not UTF-8")))
    }
}

/// A NUL-terminated UTF-8 argument called `name` in errors.
pub(crate) fn str_arg<'a>(p: *const c_char, name: &str) -> Result<&'a str> {
    non_null(p, name)?;
    // SAFETY: non-NULL and NUL-terminated (requirement of the C API).
    unsafe { CStr::from_ptr(p) }
        .to_str()
        .map_err(|_| Error::invalid(format!("argument '{name}' is not UTF-8")))
}

/// Writes `value` through an out-pointer already checked to be non-NULL.
pub(crate) fn write_out<T>(p: *mut T, value: T) {
    // SAFETY: checked non-NULL by the caller; the C API requires it to be
    // valid for writes.
    unsafe { p.write(value) }
}

/// Panics inside the boundary; for testing that no panic crosses it. Only
/// built with the cargo feature `ffi-test-panic`, and not in the header.
#[cfg(feature = "ffi-test-panic")]
#[no_mangle]
pub extern "C" fn octmesh_test_panic(h: *mut octmesh_t) -> octmesh_status_t {
    with_mut(h, |_| panic!("test panic requested"))
}
