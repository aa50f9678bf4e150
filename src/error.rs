//! Error type shared by every subsystem.
//!
//! Each variant maps to one stable numeric [`ErrorKind`] so that the C ABI can
//! hand the same classification to C and Fortran callers, and so that a
//! collective operation can agree on one error across all ranks by reducing a
//! small integer.

use std::fmt;

/// Classification of an [`Error`], stable across releases (the C status enum
/// uses the same numbers).
#[repr(i32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// An argument was out of range or inconsistent (a level above
    /// [`crate::octant::MAX_LEVEL`], a negative fit, ...).
    InvalidArgument = 1,
    /// A file could not be opened or read.
    Io = 2,
    /// An input file exists but its content is not valid (truncated or
    /// malformed STL, leaf file syntax).
    Format = 3,
    /// The surface cannot be used: no triangles, non-finite coordinates,
    /// zero extent.
    Geometry = 4,
    /// A resource limit was reached (octant limit).
    Limit = 5,
    /// The operations were called in an order that is not allowed.
    State = 6,
    /// An MPI call failed or ranks disagree.
    Mpi = 7,
    /// Another rank failed; this rank's own work was fine.
    RemoteFailure = 8,
    /// A bug inside octmesh (a caught panic, a broken invariant).
    Internal = 9,
    /// The region outside the surface reaches a point given as inside the
    /// body (see [`crate::leak`]): the surface has a gap wider than the
    /// leaves around it.
    Leak = 10,
}

impl ErrorKind {
    /// Converts the numeric code back, for errors received from other ranks.
    pub fn from_code(code: i32) -> ErrorKind {
        match code {
            1 => ErrorKind::InvalidArgument,
            2 => ErrorKind::Io,
            3 => ErrorKind::Format,
            4 => ErrorKind::Geometry,
            5 => ErrorKind::Limit,
            6 => ErrorKind::State,
            7 => ErrorKind::Mpi,
            8 => ErrorKind::RemoteFailure,
            10 => ErrorKind::Leak,
            _ => ErrorKind::Internal,
        }
    }
}

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

/// Result alias used throughout octmesh.
pub type Result<T> = std::result::Result<T, Error>;
