//! Large files written around the page cache.
//!
//! A buffered write first copies every byte into the kernel's page cache,
//! into pages the kernel must find and fill; on a host whose free memory
//! is not at hand (a virtual machine's, a node after a large job) that runs
//! far below the disk: writing a 2 GB mesh through the cache took 6.2 s
//! here, the same bytes with `O_DIRECT` 0.9-1.1 s (see BENCHMARKS.md). A
//! [`DirectWriter`] collects bytes into a block-aligned buffer and writes
//! the whole blocks of each full buffer straight to the file; the pieces
//! of a block at either end of a run of bytes go through an ordinary
//! handle, so a stream may start and stop anywhere. A file system that
//! refuses `O_DIRECT` (or a system without it) gets ordinary writes only.
//!
//! ```text
//!   file:  |  block  |  block  |  block  |  block  |
//!               ^base                          ^base + len
//!               [plain][ direct, whole blocks ][plain]
//! ```
//!
//! Direct and ordinary writes never share a block, so no cached page ever
//! holds stale bytes of a block written directly.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::os::unix::fs::FileExt;
use std::path::Path;

/// Alignment of direct writes, in memory and in the file: the largest
/// logical block size in common use.
const BLOCK: usize = 4096;

/// Bytes buffered between direct writes.
const CHUNK: usize = 8 << 20;

/// One aligned block of the buffer.
#[repr(C, align(4096))]
struct Block([u8; BLOCK]);

/// A writer that sends the whole blocks of a file with `O_DIRECT`, the
/// rest through the page cache; see the module's documentation. Bytes are
/// written from a start offset on ([`DirectWriter::restart_at`] moves it);
/// call [`Write::flush`] when done: dropping the writer discards what is
/// still buffered.
pub struct DirectWriter {
    /// The ordinary handle: the partial blocks, everything when `direct`
    /// is `None`.
    plain: File,
    /// The same file opened with `O_DIRECT`, while the file system takes it.
    direct: Option<File>,
    /// The buffer, `CHUNK` bytes; the pending bytes sit at
    /// `base % BLOCK ..`, so file offsets and buffer places agree modulo
    /// the block size and whole blocks of the file are aligned in memory.
    blocks: Vec<Block>,
    /// File offset of the first pending byte.
    base: u64,
    /// Pending bytes.
    len: usize,
}

impl DirectWriter {
    /// Creates (or truncates) the file at `path`, writing from offset 0.
    pub fn create(path: &Path) -> io::Result<Self> {
        let plain = File::create(path)?;
        Ok(Self::around(plain, path))
    }

    /// A writer of `plain`, the file at `path`.
    fn around(plain: File, path: &Path) -> Self {
        let direct = open_direct(path);
        let mut blocks = Vec::with_capacity(CHUNK / BLOCK);
        blocks.resize_with(CHUNK / BLOCK, || Block([0; BLOCK]));
        DirectWriter {
            plain,
            direct,
            blocks,
            base: 0,
            len: 0,
        }
    }

    /// Opens the existing file at `path` (its bytes kept), writing from
    /// offset 0: a second writer of the same file, at another place.
    pub fn open(path: &Path) -> io::Result<Self> {
        let plain = OpenOptions::new().write(true).open(path)?;
        Ok(Self::around(plain, path))
    }

    /// Whether whole blocks go straight to the file.
    pub fn is_direct(&self) -> bool {
        self.direct.is_some()
    }

    /// Writes what is pending, then goes on from file offset `offset`.
    pub fn restart_at(&mut self, offset: u64) -> io::Result<()> {
        self.drain(true)?;
        self.base = offset;
        Ok(())
    }

    /// Writes the pending bytes' whole blocks directly and their partial
    /// first block through the page cache; the partial last block is
    /// written too when `all`, else kept at the buffer's front.
    fn drain(&mut self, all: bool) -> io::Result<()> {
        let lead = (self.base % BLOCK as u64) as usize;
        let (base, end) = (self.base, self.base + self.len as u64);
        let down = |x: u64| x - x % BLOCK as u64;
        let (a0, a1) = (down(base + BLOCK as u64 - 1), down(end));
        let mut from = base;
        if self.direct.is_some() && a0 < a1 {
            let at = |x: u64| lead + (x - base) as usize;
            let (p0, p1) = (at(a0), at(a1));
            let buf = bytes(&self.blocks);
            if a0 > base {
                self.plain.write_all_at(&buf[lead..p0], base)?;
            }
            let direct = self.direct.take().expect("checked above");
            match direct.write_all_at(&buf[p0..p1], a0) {
                Ok(()) => self.direct = Some(direct),
                // A file system that opens with O_DIRECT but refuses the
                // write: ordinary writes from here on.
                Err(e) if e.raw_os_error() == Some(libc::EINVAL) => {
                    self.plain.write_all_at(&buf[p0..p1], a0)?;
                }
                Err(e) => return Err(e),
            }
            from = a1;
        }
        let keep = if all || self.direct.is_none() {
            let at = lead + (from - base) as usize;
            self.plain
                .write_all_at(&bytes(&self.blocks)[at..lead + self.len], from)?;
            0
        } else {
            // The partial last block, now at the start of a block of
            // memory as `from` is at the start of one in the file.
            let at = lead + (from - base) as usize;
            let n = (end - from) as usize;
            bytes_mut(&mut self.blocks).copy_within(at..at + n, 0);
            n
        };
        self.base = end - keep as u64;
        self.len = keep;
        Ok(())
    }
}

impl Write for DirectWriter {
    fn write(&mut self, data: &[u8]) -> io::Result<usize> {
        let lead = (self.base % BLOCK as u64) as usize;
        let room = CHUNK - lead - self.len;
        let n = room.min(data.len());
        let at = lead + self.len;
        bytes_mut(&mut self.blocks)[at..at + n].copy_from_slice(&data[..n]);
        self.len += n;
        if n == room {
            self.drain(false)?;
        }
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.drain(true)
    }
}

/// The bytes of `blocks`.
fn bytes(blocks: &[Block]) -> &[u8] {
    // SAFETY: `Block` is a plain array of bytes with no padding (its size
    // is its alignment), so the blocks are contiguous initialised bytes,
    // borrowed as long as `blocks`.
    unsafe {
        std::slice::from_raw_parts(blocks.as_ptr().cast::<u8>(), std::mem::size_of_val(blocks))
    }
}

/// The bytes of `blocks`, to write into.
fn bytes_mut(blocks: &mut [Block]) -> &mut [u8] {
    // SAFETY: as in `bytes`, every bit pattern is a byte, and the borrow
    // is the only one of `blocks`.
    unsafe {
        std::slice::from_raw_parts_mut(
            blocks.as_mut_ptr().cast::<u8>(),
            std::mem::size_of_val(blocks),
        )
    }
}

/// The file at `path` opened again for direct writes, if this system and
/// file system offer them.
fn open_direct(path: &Path) -> Option<File> {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::OpenOptionsExt;
        OpenOptions::new()
            .write(true)
            .custom_flags(libc::O_DIRECT)
            .open(path)
            .ok()
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (path, OpenOptions::new());
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Streams of every awkward length and start land byte for byte, with
    /// a second stream written before the first's start.
    #[test]
    fn streams_land_where_they_were_sent() {
        let dir = std::env::temp_dir().join(format!("octmesh_direct_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("f");
        let byte = |i: u64| (i.wrapping_mul(2_654_435_761) >> 13) as u8;
        for (direct, start, len, piece) in [
            (true, 0u64, 0usize, 7usize),
            (true, 0, 100, 7),
            (true, 5000, 3 * CHUNK + 12_345, 1 << 20),
            (true, 4096, CHUNK, 65_536),
            (true, 123, 2 * CHUNK - 123, 3 * CHUNK),
            (false, 123, 2 * CHUNK - 123, 3 * CHUNK),
        ] {
            let mut w = DirectWriter::create(&path).unwrap();
            if !direct {
                w.direct = None;
            }
            println!("direct writes: {}", w.is_direct());
            w.restart_at(start).unwrap();
            let body: Vec<u8> = (start..start + len as u64).map(byte).collect();
            for p in body.chunks(piece) {
                w.write_all(p).unwrap();
            }
            w.restart_at(0).unwrap();
            let head: Vec<u8> = (0..start).map(byte).collect();
            w.write_all(&head).unwrap();
            w.flush().unwrap();
            drop(w);
            let got = std::fs::read(&path).unwrap();
            assert_eq!(got.len() as u64, start + len as u64, "{start} {len}");
            let want: Vec<u8> = (0..start + len as u64).map(byte).collect();
            assert!(got == want, "{start} {len} {piece}: bytes differ");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
