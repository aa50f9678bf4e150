//! One file that every rank of a communicator opens, reads and writes
//! together, each rank at its own offsets.
//!
//! Over MPI this is MPI-IO (`MPI_File_open`, `MPI_File_write_at_all`,
//! `MPI_File_read_at_all`) through the raw bindings, since rsmpi has no
//! safe MPI-IO; the MPI library then gathers the ranks' pieces into large
//! requests to the file system. On a [`SerialComm`](super::comm::SerialComm)
//! (one process, no MPI) it is a plain file with positioned reads and
//! writes.
//!
//! Opening and closing are collective and agree on failure; reads and
//! writes are collective too but return this rank's own result, for the
//! caller to agree on once after all its transfers (a rank that failed
//! keeps taking part in the remaining collective calls, so none waits for
//! it).

use std::ffi::CString;
use std::fs::{File, OpenOptions};
use std::os::raw::{c_char, c_int, c_void};
use std::os::unix::fs::FileExt;
use std::path::Path;

use crate::error::{Error, ErrorKind, Result};
use crate::parallel::comm::{agree, Comm};

/// Bytes per MPI-IO call: MPI counts are `int`.
const CHUNK: usize = 1 << 30;

/// How a [`SharedFile`] is opened.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Created with this many bytes, for writing: the caller writes every
    /// byte. An existing file is cut to (or extended to) that length, not
    /// emptied first, so that the blocks of a file saved over again are
    /// written over rather than freed and allocated anew.
    Create(u64),
    /// An existing file, for reading.
    Read,
}

enum Handle {
    Plain(File),
    Mpi(mpi_sys::MPI_File),
    Closed,
}

/// A file shared by the ranks of a communicator (see the module
/// documentation). Dropping it closes it, collectively; call
/// [`SharedFile::close`] to see the error of a close.
pub struct SharedFile<'a> {
    comm: &'a dyn Comm,
    path: String,
    handle: Handle,
}

/// The message of an MPI error code.
fn mpi_message(code: c_int) -> String {
    let mut buf = vec![0 as c_char; mpi_sys::MPI_MAX_ERROR_STRING as usize + 1];
    let mut len: c_int = 0;
    // SAFETY: the buffer holds MPI_MAX_ERROR_STRING characters and a nul.
    let rc = unsafe { mpi_sys::MPI_Error_string(code, buf.as_mut_ptr(), &mut len) };
    if rc != 0 {
        return format!("MPI error {code}");
    }
    let bytes: Vec<u8> = buf[..len.max(0) as usize]
        .iter()
        .map(|&c| c as u8)
        .collect();
    String::from_utf8_lossy(&bytes).trim().to_string()
}

impl<'a> SharedFile<'a> {
    /// Opens `path` on every rank of `comm`. Collective: if any rank
    /// fails, every rank returns an error naming the path.
    pub fn open(comm: &'a dyn Comm, path: &Path, mode: Mode) -> Result<SharedFile<'a>> {
        let shown = path.display().to_string();
        let verb = match mode {
            Mode::Create(_) => "create",
            Mode::Read => "open",
        };
        let local = match comm.mpi_raw() {
            None => {
                let f = match mode {
                    Mode::Create(len) => OpenOptions::new()
                        .write(true)
                        .create(true)
                        .truncate(false)
                        .open(path)
                        .and_then(|f| f.set_len(len).map(|_| f)),
                    Mode::Read => OpenOptions::new().read(true).open(path),
                };
                f.map(Handle::Plain)
                    .map_err(|e| Error::io(format!("cannot {verb} {shown}: {e}")))
            }
            Some(raw) => {
                let name = CString::new(path.as_os_str().as_encoded_bytes())
                    .map_err(|_| Error::invalid(format!("the path {shown:?} holds a nul byte")));
                name.and_then(|name| {
                    let amode = match mode {
                        Mode::Create(_) => mpi_sys::MPI_MODE_CREATE | mpi_sys::MPI_MODE_WRONLY,
                        Mode::Read => mpi_sys::MPI_MODE_RDONLY,
                    } as c_int;
                    let mut fh: mpi_sys::MPI_File = std::ptr::null_mut();
                    // SAFETY: a valid communicator, a nul-terminated name, and
                    // an out-pointer to a handle.
                    let rc = unsafe {
                        mpi_sys::MPI_File_open(
                            raw,
                            name.as_ptr(),
                            amode,
                            mpi_sys::RSMPI_INFO_NULL,
                            &mut fh,
                        )
                    };
                    if rc != 0 {
                        return Err(Error::io(format!(
                            "cannot {verb} {shown}: {}",
                            mpi_message(rc)
                        )));
                    }
                    Ok(Handle::Mpi(fh))
                })
            }
        };
        // A rank whose open worked while another's failed leaves its MPI
        // handle unclosed: closing is collective, and the others have none.
        let handle = agree(comm, local)?;
        let file = SharedFile {
            comm,
            path: shown,
            handle,
        };
        if let Mode::Create(len) = mode {
            // MPI_MODE_CREATE keeps an existing file's bytes and length.
            if let Handle::Mpi(fh) = file.handle {
                // SAFETY: an open handle; collective, as every rank got here.
                let rc = unsafe { mpi_sys::MPI_File_set_size(fh, len as mpi_sys::MPI_Offset) };
                let local = if rc == 0 {
                    Ok(())
                } else {
                    Err(file.error("size", rc))
                };
                agree(comm, local)?;
            }
        }
        Ok(file)
    }

    fn error(&self, what: &str, rc: c_int) -> Error {
        Error::io(format!("cannot {what} {}: {}", self.path, mpi_message(rc)))
    }

    /// The rounds of calls of at most [`CHUNK`] bytes every rank makes for
    /// transfers of `len` bytes here: the most any rank needs.
    fn rounds(&self, len: usize) -> usize {
        let mut n = [len.div_ceil(CHUNK) as u64];
        self.comm.max_u64(&mut n);
        n[0] as usize
    }

    /// Writes `bytes` at `offset`. Collective (every rank calls it, with
    /// its own piece, possibly empty); returns this rank's result.
    pub fn write_at_all(&self, offset: u64, bytes: &[u8]) -> Result<()> {
        match &self.handle {
            Handle::Plain(f) => f
                .write_all_at(bytes, offset)
                .map_err(|e| Error::io(format!("cannot write {}: {e}", self.path))),
            Handle::Mpi(fh) => {
                let mut result = Ok(());
                for k in 0..self.rounds(bytes.len()) {
                    let piece = bytes.get(k * CHUNK..).unwrap_or(&[]);
                    let piece = &piece[..piece.len().min(CHUNK)];
                    // A failed rank still takes part, with nothing.
                    let piece = if result.is_ok() { piece } else { &[] };
                    // SAFETY: an open handle and a buffer of `piece.len()`
                    // bytes; the status is ignored.
                    let rc = unsafe {
                        mpi_sys::MPI_File_write_at_all(
                            *fh,
                            (offset + (k * CHUNK) as u64) as mpi_sys::MPI_Offset,
                            piece.as_ptr() as *const c_void,
                            piece.len() as c_int,
                            mpi_sys::RSMPI_UINT8_T,
                            mpi_sys::RSMPI_STATUS_IGNORE,
                        )
                    };
                    if rc != 0 && result.is_ok() {
                        result = Err(self.error("write", rc));
                    }
                }
                result
            }
            Handle::Closed => Err(Error::new(ErrorKind::Internal, "the file is closed")),
        }
    }

    /// Reads `buf.len()` bytes at `offset`. Collective (every rank calls
    /// it, possibly with an empty buffer); returns this rank's result, an
    /// error if the file ends before.
    pub fn read_at_all(&self, offset: u64, buf: &mut [u8]) -> Result<()> {
        let end = offset + buf.len() as u64;
        let short = || {
            Error::format(format!(
                "{} ends before byte {end}: it is truncated",
                self.path
            ))
        };
        match &self.handle {
            Handle::Plain(f) => f.read_exact_at(buf, offset).map_err(|e| {
                if e.kind() == std::io::ErrorKind::UnexpectedEof {
                    short()
                } else {
                    Error::io(format!("cannot read {}: {e}", self.path))
                }
            }),
            Handle::Mpi(fh) => {
                let mut result = Ok(());
                let len = buf.len();
                for k in 0..self.rounds(len) {
                    let (lo, hi) = ((k * CHUNK).min(len), ((k + 1) * CHUNK).min(len));
                    let piece = if result.is_ok() {
                        &mut buf[lo..hi]
                    } else {
                        &mut buf[..0]
                    };
                    // SAFETY: zeroed below; an open handle, a buffer of
                    // `piece.len()` bytes and a status to read the count from.
                    let mut status: mpi_sys::MPI_Status = unsafe { std::mem::zeroed() };
                    let rc = unsafe {
                        mpi_sys::MPI_File_read_at_all(
                            *fh,
                            (offset + lo as u64) as mpi_sys::MPI_Offset,
                            piece.as_mut_ptr() as *mut c_void,
                            piece.len() as c_int,
                            mpi_sys::RSMPI_UINT8_T,
                            &mut status,
                        )
                    };
                    if result.is_err() {
                        continue;
                    }
                    if rc != 0 {
                        result = Err(self.error("read", rc));
                        continue;
                    }
                    let mut got: c_int = 0;
                    // SAFETY: the status of the read above.
                    unsafe { mpi_sys::MPI_Get_count(&status, mpi_sys::RSMPI_UINT8_T, &mut got) };
                    if got as usize != piece.len() {
                        result = Err(short());
                    }
                }
                result
            }
            Handle::Closed => Err(Error::new(ErrorKind::Internal, "the file is closed")),
        }
    }

    /// The file's size in bytes. Rank-local.
    pub fn size(&self) -> Result<u64> {
        match &self.handle {
            Handle::Plain(f) => f
                .metadata()
                .map(|m| m.len())
                .map_err(|e| Error::io(format!("cannot read {}: {e}", self.path))),
            Handle::Mpi(fh) => {
                let mut n: mpi_sys::MPI_Offset = 0;
                // SAFETY: an open handle and an out-pointer.
                let rc = unsafe { mpi_sys::MPI_File_get_size(*fh, &mut n) };
                if rc != 0 {
                    return Err(self.error("measure", rc));
                }
                Ok(n as u64)
            }
            Handle::Closed => Err(Error::new(ErrorKind::Internal, "the file is closed")),
        }
    }

    /// Closes the file, flushing what was written. Collective; agrees on
    /// failure.
    pub fn close(mut self) -> Result<()> {
        let local = self.close_handle();
        agree(self.comm, local)
    }

    fn close_handle(&mut self) -> Result<()> {
        match std::mem::replace(&mut self.handle, Handle::Closed) {
            Handle::Plain(f) => f
                .sync_data()
                .or_else(|e| match e.raw_os_error() {
                    // Special files (a pipe, /dev/null) cannot be synced.
                    Some(libc::EINVAL) | Some(libc::EROFS) => Ok(()),
                    _ => Err(e),
                })
                .map_err(|e| Error::io(format!("cannot write {}: {e}", self.path))),
            Handle::Mpi(mut fh) => {
                // SAFETY: an open handle, closed once (the handle is now
                // `Closed`); collective, as every rank closes it.
                let rc = unsafe { mpi_sys::MPI_File_close(&mut fh) };
                if rc != 0 {
                    return Err(self.error("close", rc));
                }
                Ok(())
            }
            Handle::Closed => Ok(()),
        }
    }
}

impl std::fmt::Debug for SharedFile<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SharedFile")
            .field("path", &self.path)
            .finish()
    }
}

impl Drop for SharedFile<'_> {
    fn drop(&mut self) {
        let _ = self.close_handle();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parallel::comm::SerialComm;

    #[test]
    fn serial_files_write_and_read_at_offsets() {
        let dir = std::env::temp_dir().join(format!("octmesh-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("f.bin");
        let comm = SerialComm;
        std::fs::write(&path, b"a longer file than the new one").unwrap();
        let f = SharedFile::open(&comm, &path, Mode::Create(8)).unwrap();
        f.write_at_all(4, b"5678").unwrap();
        f.write_at_all(0, b"1234").unwrap();
        f.close().unwrap();
        let f = SharedFile::open(&comm, &path, Mode::Read).unwrap();
        assert_eq!(f.size().unwrap(), 8);
        let mut b = [0u8; 3];
        f.read_at_all(3, &mut b).unwrap();
        assert_eq!(&b, b"456");
        let e = f.read_at_all(6, &mut b).unwrap_err();
        assert!(e.message().contains("truncated"), "{}", e.message());
        drop(f);
        let e = SharedFile::open(&comm, &dir.join("missing"), Mode::Read).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Io);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
