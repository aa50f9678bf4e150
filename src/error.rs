//! Error type shared by every subsystem.
//!
//! Each variant maps to one stable numeric [`ErrorKind`] so that the C ABI can
//! hand the same classification to C and Fortran callers, and so that a
//! collective operation can agree on one error across all ranks by reducing a
//! small integer.

use std::fmt;

/// Calls macro `$m` with the one list of error kinds: each as
/// `(Variant, code, C status name, doc)`. The Rust [`ErrorKind`] and the C
/// status enum (`octmesh_status_t`, its names and conversions) are both made
/// from this list, so they cannot drift apart.
#[macro_export]
macro_rules! for_each_error_kind {
    ($m:ident) => {
        $m! {
            (InvalidArgument, 1, OCTMESH_STATUS_INVALID_ARGUMENT,
             "An argument was out of range, inconsistent or NULL (a level above the maximum, a negative fit, ...)."),
            (Io, 2, OCTMESH_STATUS_IO,
             "A file could not be opened, read or written."),
            (Format, 3, OCTMESH_STATUS_FORMAT,
             "An input file exists but its content is not valid (truncated or malformed STL, leaf file syntax)."),
            (Geometry, 4, OCTMESH_STATUS_GEOMETRY,
             "The surface cannot be used: no triangles, non-finite coordinates, zero extent."),
            (Limit, 5, OCTMESH_STATUS_LIMIT,
             "A resource limit was reached (the octant limit or the memory budget)."),
            (State, 6, OCTMESH_STATUS_STATE,
             "The operations were called in an order that is not allowed (the message says what to call first)."),
            (Mpi, 7, OCTMESH_STATUS_MPI,
             "An MPI call failed, MPI is not initialised, or the ranks disagree."),
            (RemoteFailure, 8, OCTMESH_STATUS_REMOTE_FAILURE,
             "Another rank failed; this rank's own work was fine (the message is that rank's)."),
            (Internal, 9, OCTMESH_STATUS_INTERNAL,
             "A bug inside octmesh (a caught panic, a broken invariant)."),
            (Leak, 10, OCTMESH_STATUS_LEAK,
             "The region outside the surface reaches a point given as inside the body: the surface has a gap wider than the leaves around it."),
        }
    };
}

macro_rules! define_error_kind {
    ($(($variant:ident, $code:literal, $c:ident, $doc:literal)),+ $(,)?) => {
        /// Classification of an [`Error`], stable across releases (the C
        /// status enum uses the same numbers; see [`for_each_error_kind`]).
        #[repr(i32)]
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum ErrorKind {
            $(#[doc = $doc] $variant = $code,)+
        }

        impl ErrorKind {
            /// Every kind, in code order.
            pub const ALL: &'static [ErrorKind] = &[$(ErrorKind::$variant),+];

            /// Converts the numeric code back, for errors received from
            /// other ranks; an unknown code is [`ErrorKind::Internal`].
            pub fn from_code(code: i32) -> ErrorKind {
                match code {
                    $($code => ErrorKind::$variant,)+
                    _ => ErrorKind::Internal,
                }
            }

            /// The name of the C status of this kind (`OCTMESH_STATUS_IO`).
            pub fn status_name(self) -> &'static str {
                match self {
                    $(ErrorKind::$variant => stringify!($c),)+
                }
            }
        }
    };
}

for_each_error_kind!(define_error_kind);

/// An octmesh error: a kind plus a message meant for a human.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Error {
    kind: ErrorKind,
    message: String,
}

impl Error {
    /// Creates an error of the given kind.
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> Error {
        Error {
            kind,
            message: message.into(),
        }
    }

    /// Shorthand for [`ErrorKind::InvalidArgument`].
    pub fn invalid(message: impl Into<String>) -> Error {
        Error::new(ErrorKind::InvalidArgument, message)
    }

    /// Shorthand for [`ErrorKind::Format`].
    pub fn format(message: impl Into<String>) -> Error {
        Error::new(ErrorKind::Format, message)
    }

    /// Shorthand for [`ErrorKind::Geometry`].
    pub fn geometry(message: impl Into<String>) -> Error {
        Error::new(ErrorKind::Geometry, message)
    }

    /// Shorthand for [`ErrorKind::Io`].
    pub fn io(message: impl Into<String>) -> Error {
        Error::new(ErrorKind::Io, message)
    }

    /// The classification of this error.
    pub fn kind(&self) -> ErrorKind {
        self.kind
    }

    /// The human-readable message.
    pub fn message(&self) -> &str {
        &self.message
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Error {}

/// The message a panic carried (its payload, as `panic!` makes it), for
/// reports of internal errors at the C ABI's panic boundary and in the
/// command.
pub fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic payload".to_string()
    }
}

/// Result alias used throughout octmesh.
pub type Result<T> = std::result::Result<T, Error>;
