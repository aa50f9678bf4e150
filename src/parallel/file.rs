//! One file that every rank of a communicator opens, reads and writes
//! together, each rank at its own offsets.
//!
//! Each rank opens the file itself and moves its own bytes with positioned
//! reads and writes, the whole blocks of large pieces with `O_DIRECT`
//! ([`super::direct`]): on a host whose free memory the hypervisor has taken
//! back, every fresh page-cache page of a new file costs a trip to the host,
//! and a file written through the cache ran at a twentieth of the disk's
//! speed (MPI-IO's collective writes as much as plain ones; see
//! BENCHMARKS.md). Rank 0 sets a new file's length before any rank writes.
//!
//! Opening and closing are collective and agree on failure; reads and
//! writes are collective too but return this rank's own result, for the
//! caller to agree on once after all its transfers.

use std::fs::OpenOptions;
use std::io::Write;
use std::os::unix::fs::FileExt;
use std::path::Path;

use crate::error::{Error, ErrorKind, Result};
use crate::parallel::comm::{agree, Comm};
use crate::parallel::direct::{DirectReader, DirectWriter};

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
    Write(Box<DirectWriter>),
    Read(DirectReader),
    Closed,
}

/// A file shared by the ranks of a communicator (see the module
/// documentation). Dropping it closes it; call [`SharedFile::close`] to
/// see the error of a close.
pub struct SharedFile<'a> {
    comm: &'a dyn Comm,
    path: String,
    handle: std::cell::RefCell<Handle>,
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
        let failed = |e: std::io::Error| Error::io(format!("cannot {verb} {shown}: {e}"));
        let local = match mode {
            // Every rank creates the file (so that each sees its own
            // error); rank 0 alone sets the length, before any rank
            // writes, so that no rank cuts what another has written.
            Mode::Create(len) => OpenOptions::new()
                .write(true)
                .create(true)
                .truncate(false)
                .open(path)
                .and_then(|f| {
                    if comm.rank() == 0 {
                        f.set_len(len)?;
                    }
                    Ok(Handle::Write(Box::new(DirectWriter::around(f, path))))
                }),
            Mode::Read => DirectReader::open(path).map(Handle::Read),
        };
        let handle = agree(comm, local.map_err(failed))?;
        Ok(SharedFile {
            comm,
            path: shown,
            handle: std::cell::RefCell::new(handle),
        })
    }

    /// Writes `bytes` at `offset`. Collective (every rank calls it, with
    /// its own piece, possibly empty); returns this rank's result.
    pub fn write_at_all(&self, offset: u64, bytes: &[u8]) -> Result<()> {
        let failed = |e: std::io::Error| Error::io(format!("cannot write {}: {e}", self.path));
        match &mut *self.handle.borrow_mut() {
            Handle::Write(w) => {
                if bytes.is_empty() {
                    return Ok(());
                }
                if cached(w.file(), offset, bytes.len()) {
                    // Over pages the cache holds (a file saved over
                    // again): no fresh pages to make, and the cache takes
                    // the bytes faster than the device.
                    return w.file().write_all_at(bytes, offset).map_err(failed);
                }
                w.restart_at(offset).map_err(failed)?;
                w.write_all(bytes).map_err(failed)?;
                // The partial last block now, so that the next piece may
                // start anywhere.
                w.flush().map_err(failed)
            }
            Handle::Read(_) => Err(Error::new(
                ErrorKind::Internal,
                "the file is open for reading",
            )),
            Handle::Closed => Err(Error::new(ErrorKind::Internal, "the file is closed")),
        }
    }

    /// Reads `buf.len()` bytes at `offset`. Collective (every rank calls
    /// it, possibly with an empty buffer); returns this rank's result, an
    /// error if the file ends before. The pages of `buf` are made in bulk
    /// as it is filled (see `DirectReader::read_exact_at`).
    pub fn read_at_all(&self, offset: u64, buf: &mut [u8]) -> Result<()> {
        match &mut *self.handle.borrow_mut() {
            Handle::Read(r) => r.read_exact_at(buf, offset).map_err(|e| {
                if e.kind() == std::io::ErrorKind::UnexpectedEof {
                    Error::format(format!(
                        "{} ends before byte {}: it is truncated",
                        self.path,
                        offset + buf.len() as u64
                    ))
                } else {
                    Error::io(format!("cannot read {}: {e}", self.path))
                }
            }),
            Handle::Write(_) => Err(Error::new(
                ErrorKind::Internal,
                "the file is open for writing",
            )),
            Handle::Closed => Err(Error::new(ErrorKind::Internal, "the file is closed")),
        }
    }

    /// The file's size in bytes. Rank-local.
    pub fn size(&self) -> Result<u64> {
        let got = match &*self.handle.borrow() {
            Handle::Read(r) => r.file().metadata(),
            Handle::Write(w) => w.file().metadata(),
            Handle::Closed => {
                return Err(Error::new(ErrorKind::Internal, "the file is closed"));
            }
        };
        got.map(|m| m.len())
            .map_err(|e| Error::io(format!("cannot read {}: {e}", self.path)))
    }

    /// Closes the file. Collective; agrees on failure. Whole blocks
    /// written directly are on the device; the rest is not synced.
    pub fn close(self) -> Result<()> {
        let local = self.close_handle();
        agree(self.comm, local)
    }

    fn close_handle(&self) -> Result<()> {
        let failed = |e: std::io::Error| Error::io(format!("cannot write {}: {e}", self.path));
        match self.handle.replace(Handle::Closed) {
            Handle::Write(mut w) => w.flush().map_err(failed),
            Handle::Read(_) | Handle::Closed => Ok(()),
        }
    }
}

/// Whether the page cache holds every page of `len` bytes of `file` from
/// `at` (`cachestat`, Linux 6.5; false where it is missing).
fn cached(file: &std::fs::File, at: u64, len: usize) -> bool {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        #[repr(C)]
        struct Range {
            off: u64,
            len: u64,
        }
        #[repr(C)]
        #[derive(Default)]
        struct Stat {
            cache: u64,
            dirty: u64,
            writeback: u64,
            evicted: u64,
            recently_evicted: u64,
        }
        const SYS_CACHESTAT: libc::c_long = 451;
        let page = 4096u64;
        let (a, b) = (at - at % page, (at + len as u64).div_ceil(page) * page);
        let range = Range { off: a, len: b - a };
        let mut stat = Stat::default();
        // SAFETY: cachestat reads the range and fills the stat, both
        // live here; an unknown system call returns -1 (ENOSYS).
        let rc = unsafe {
            libc::syscall(
                SYS_CACHESTAT,
                file.as_raw_fd(),
                &range as *const Range,
                &mut stat as *mut Stat,
                0u32,
            )
        };
        rc == 0 && len > 0 && stat.cache == (b - a) / page
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (file, at, len);
        false
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
