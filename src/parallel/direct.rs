//! Large files written and read around the page cache.
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
//!
//! A [`DirectReader`] reads the whole blocks of a large range the same way
//! (a thread reads the next aligned buffer while the caller copies the last
//! one into place), the partial blocks at its ends through the cache. The
//! kernel writes cached changes of a range back before reading it directly,
//! so a file just written through the cache reads back as written.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::os::unix::fs::FileExt;
use std::path::Path;
use std::sync::Arc;
use std::thread::JoinHandle;

use crate::parallel::cores::make_pages;

/// Alignment of direct writes, in memory and in the file: the largest
/// logical block size in common use.
const BLOCK: usize = 4096;

/// Bytes buffered between direct writes.
const CHUNK: usize = 8 << 20;

/// One aligned block of the buffer.
#[repr(C, align(4096))]
struct Block([u8; BLOCK]);

/// A direct write under way: its thread hands back the buffer and whether
/// the file system took the write directly.
type Job = JoinHandle<(Vec<Block>, io::Result<bool>)>;

/// A writer that sends the whole blocks of a file with `O_DIRECT`, the
/// rest through the page cache; see the module's documentation. Bytes are
/// written from a start offset on ([`DirectWriter::restart_at`] moves it);
/// call [`Write::flush`] when done: dropping the writer discards what is
/// still buffered.
///
/// A full buffer's blocks are written by a short-lived thread while the
/// caller fills a second buffer: the thread waits on the device (no
/// computing, no MPI), so the caller's work and the disk overlap. At most
/// one write is under way; an error comes back from the next call.
pub struct DirectWriter {
    /// The ordinary handle: the partial blocks, everything when `direct`
    /// is `None`.
    plain: Arc<File>,
    /// The same file opened with `O_DIRECT`, while the file system takes it.
    direct: Option<Arc<File>>,
    /// The buffer, `CHUNK` bytes; the pending bytes sit at
    /// `base % BLOCK ..`, so file offsets and buffer places agree modulo
    /// the block size and whole blocks of the file are aligned in memory.
    blocks: Vec<Block>,
    /// The other buffer, when no write holds it.
    spare: Option<Vec<Block>>,
    /// The write under way.
    job: Option<Job>,
    /// File offset of the first pending byte.
    base: u64,
    /// Pending bytes.
    len: usize,
}

/// A buffer of `CHUNK` bytes, zeroed by the allocator: the system hands
/// out zero pages untouched, so a small file's writer faults in only the
/// pages it fills, not 8 MiB.
fn new_blocks() -> Vec<Block> {
    let n = CHUNK / BLOCK;
    let layout = std::alloc::Layout::array::<Block>(n).expect("a fixed, small size");
    // SAFETY: the layout is that of `n` blocks (non-zero size); the
    // pointer, when not null, is a zeroed allocation of it by the global
    // allocator, and zero bytes are valid blocks, so it is a vector of
    // length and capacity `n`.
    unsafe {
        let p = std::alloc::alloc_zeroed(layout).cast::<Block>();
        if p.is_null() {
            std::alloc::handle_alloc_error(layout);
        }
        Vec::from_raw_parts(p, n, n)
    }
}

/// Writes `buf` (whole blocks) at `at` through `direct`, or through
/// `plain` when the file system refuses it (`Ok(false)`).
fn write_blocks(direct: &File, plain: &File, buf: &[u8], at: u64) -> io::Result<bool> {
    match direct.write_all_at(buf, at) {
        Ok(()) => Ok(true),
        // A file system that opens with O_DIRECT but refuses the write.
        Err(e) if e.raw_os_error() == Some(libc::EINVAL) => {
            plain.write_all_at(buf, at).map(|()| false)
        }
        Err(e) => Err(e),
    }
}

impl DirectWriter {
    /// Creates (or truncates) the file at `path`, writing from offset 0.
    pub fn create(path: &Path) -> io::Result<Self> {
        let plain = File::create(path)?;
        Ok(Self::around(plain, path))
    }

    /// Opens the existing file at `path` (its bytes kept), writing from
    /// offset 0: a second writer of the same file, at another place.
    pub fn open(path: &Path) -> io::Result<Self> {
        let plain = OpenOptions::new().write(true).open(path)?;
        Ok(Self::around(plain, path))
    }

    /// A writer of `plain`, the file at `path` opened for writing, from
    /// offset 0.
    pub fn around(plain: File, path: &Path) -> Self {
        DirectWriter {
            plain: Arc::new(plain),
            direct: open_direct(path).map(Arc::new),
            blocks: new_blocks(),
            spare: None,
            job: None,
            base: 0,
            len: 0,
        }
    }

    /// Whether whole blocks go straight to the file.
    pub fn is_direct(&self) -> bool {
        self.direct.is_some()
    }

    /// The ordinary handle.
    pub fn file(&self) -> &File {
        &self.plain
    }

    /// Writes what is pending, then goes on from file offset `offset`.
    pub fn restart_at(&mut self, offset: u64) -> io::Result<()> {
        self.drain(true)?;
        self.base = offset;
        Ok(())
    }

    /// Writes what is pending and waits for the device to hold the file
    /// (`fsync`): late errors (a full disk, a quota) come back here.
    pub fn sync_all(&mut self) -> io::Result<()> {
        self.drain(true)?;
        self.plain.sync_all()
    }

    /// Waits for the write under way; its buffer becomes the spare.
    fn wait(&mut self) -> io::Result<()> {
        if let Some(job) = self.job.take() {
            let (buf, took) = job
                .join()
                .map_err(|_| io::Error::other("the writing thread failed"))?;
            self.spare = Some(buf);
            if !took? {
                self.direct = None;
            }
        }
        Ok(())
    }

    /// Writes the pending bytes' whole blocks directly (from a thread,
    /// unless `all`) and their partial first block through the page cache;
    /// the partial last block is written too when `all`, else kept at the
    /// buffer's front.
    fn drain(&mut self, all: bool) -> io::Result<()> {
        self.wait()?;
        let lead = (self.base % BLOCK as u64) as usize;
        let (base, end) = (self.base, self.base + self.len as u64);
        let down = |x: u64| x - x % BLOCK as u64;
        let (a0, a1) = (down(base + BLOCK as u64 - 1), down(end));
        let at = |x: u64| lead + (x - base) as usize;
        let Some(direct) = self.direct.clone().filter(|_| a0 < a1) else {
            self.plain
                .write_all_at(&bytes(&self.blocks)[lead..lead + self.len], base)?;
            self.base = end;
            self.len = 0;
            return Ok(());
        };
        let (p0, p1) = (at(a0), at(a1));
        if a0 > base {
            self.plain
                .write_all_at(&bytes(&self.blocks)[lead..p0], base)?;
        }
        // The partial last block goes to the front of the other buffer,
        // to a block of memory as `a1` starts a block of the file.
        let tail = (end - a1) as usize;
        let mut next = self.spare.take().unwrap_or_else(new_blocks);
        bytes_mut(&mut next)[..tail].copy_from_slice(&bytes(&self.blocks)[p1..p1 + tail]);
        let full = std::mem::replace(&mut self.blocks, next);
        let plain = Arc::clone(&self.plain);
        let job = move || {
            let took = write_blocks(&direct, &plain, &bytes(&full)[p0..p1], a0);
            (full, took)
        };
        if all {
            let (full, took) = job();
            self.spare = Some(full);
            if !took? {
                self.direct = None;
            }
            self.plain.write_all_at(&bytes(&self.blocks)[..tail], a1)?;
            self.base = end;
            self.len = 0;
        } else {
            self.job = Some(
                std::thread::Builder::new()
                    .name("octmesh-write".into())
                    .spawn(job)?,
            );
            self.base = a1;
            self.len = tail;
        }
        Ok(())
    }
}

impl Drop for DirectWriter {
    fn drop(&mut self) {
        // No write may land after the caller has moved on (and perhaps
        // removed the file).
        let _ = self.wait();
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

/// The file at `path` opened again for direct writes (or reads), if this
/// system and file system offer them.
fn open_direct(path: &Path) -> Option<File> {
    open_direct_for(path, true)
}

fn open_direct_for(path: &Path, write: bool) -> Option<File> {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::OpenOptionsExt;
        OpenOptions::new()
            .write(write)
            .read(!write)
            .custom_flags(libc::O_DIRECT)
            .open(path)
            .ok()
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (path, write, OpenOptions::new());
        None
    }
}

/// Whole blocks below which a read goes through the page cache: a direct
/// read always waits on the device, worth it for large ranges only.
const DIRECT_READ_MIN: u64 = 1 << 20;

/// Reads of a file with `O_DIRECT` for the whole blocks of large ranges,
/// the rest through the page cache; see the module's documentation.
#[derive(Debug)]
pub struct DirectReader {
    plain: File,
    /// The same file opened with `O_DIRECT`, while the file system takes it.
    direct: Option<File>,
}

impl DirectReader {
    /// Opens the file at `path` for reading.
    pub fn open(path: &Path) -> io::Result<Self> {
        let plain = File::open(path)?;
        Ok(DirectReader {
            plain,
            direct: open_direct_for(path, false),
        })
    }

    /// The ordinary handle.
    pub fn file(&self) -> &File {
        &self.plain
    }

    /// Whether whole blocks come straight from the file.
    pub fn is_direct(&self) -> bool {
        self.direct.is_some()
    }

    /// Fills `buf` from file offset `at`; an `UnexpectedEof` error when the
    /// file ends before. The pages of `buf` are made in bulk
    /// (`cores::make_pages`; a fresh buffer's pages, made one by one by
    /// the copies, cost as much as the reads here), those of a direct read
    /// while the device works. A large range whose first page the cache
    /// holds comes from the cache, the rest directly.
    pub fn read_exact_at(&mut self, buf: &mut [u8], at: u64) -> io::Result<()> {
        let end = at + buf.len() as u64;
        let block = BLOCK as u64;
        let (a0, a1) = (at.div_ceil(block) * block, end - end % block);
        let whole = |buf: &mut [u8]| make_pages(&[(buf.as_ptr() as usize, buf.len())]);
        let Some(direct) = self.direct.as_ref().filter(|_| a1 >= a0 + DIRECT_READ_MIN) else {
            whole(buf);
            return self.plain.read_exact_at(buf, at);
        };
        // What the page cache holds already is copied from there (a file
        // just written through the cache): the device is far slower. The
        // first page tells.
        let first = buf.len().min(BLOCK);
        let cached = read_cached(&self.plain, &mut buf[..first], at);
        if cached > 0 {
            whole(buf);
            let more = read_cached(&self.plain, &mut buf[cached..], at + cached as u64);
            let done = cached + more;
            return match done == buf.len() {
                true => Ok(()),
                false => self.read_exact_at(&mut buf[done..], at + done as u64),
            };
        }
        let (p0, p1) = ((a0 - at) as usize, (a1 - at) as usize);
        // The end first: a file that ends early fails before the long read.
        self.plain.read_exact_at(&mut buf[p1..], a1)?;
        self.plain.read_exact_at(&mut buf[..p0], at)?;
        if !read_blocks(direct, &mut buf[p0..p1], a0)? {
            self.direct = None;
            self.plain.read_exact_at(&mut buf[p0..p1], a0)?;
        }
        Ok(())
    }
}

/// Reads from the start of `buf` (file offset `at`) what the page cache
/// holds without waiting on the device (`RWF_NOWAIT`); the bytes read.
fn read_cached(file: &File, buf: &mut [u8], at: u64) -> usize {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        use std::os::fd::AsRawFd;
        let mut done = 0usize;
        while done < buf.len() {
            let rest = &mut buf[done..];
            let iov = libc::iovec {
                iov_base: rest.as_mut_ptr().cast(),
                iov_len: rest.len().min(1 << 30),
            };
            // SAFETY: one vector over the unread part of `buf`, an open
            // descriptor; the kernel writes at most `iov_len` bytes.
            let n = unsafe {
                libc::preadv2(
                    file.as_raw_fd(),
                    &iov,
                    1,
                    (at + done as u64) as libc::off_t,
                    libc::RWF_NOWAIT,
                )
            };
            if n <= 0 {
                break;
            }
            done += n as usize;
        }
        done
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        let _ = (file, buf, at);
        0
    }
}

/// Fills `dst` (whole blocks long) from the aligned offset `at` of
/// `direct`: a thread reads each aligned buffer while this one copies the
/// one before into place. `Ok(false)` when the file system refuses direct
/// reads (nothing read then counts).
fn read_blocks(direct: &File, dst: &mut [u8], at: u64) -> io::Result<bool> {
    use std::sync::mpsc::channel;
    let n = dst.len();
    std::thread::scope(|s| {
        let (give, take) = channel::<Vec<Block>>();
        let (done, filled) = channel::<(Vec<Block>, io::Result<()>)>();
        for _ in 0..2 {
            give.send(new_blocks()).expect("the receiver is here");
        }
        s.spawn(move || {
            for lo in (0..n).step_by(CHUNK) {
                let Ok(mut b) = take.recv() else { return };
                let len = (n - lo).min(CHUNK);
                let r = direct.read_exact_at(&mut bytes_mut(&mut b)[..len], at + lo as u64);
                let failed = r.is_err();
                if done.send((b, r)).is_err() || failed {
                    return;
                }
            }
        });
        for lo in (0..n).step_by(CHUNK) {
            let len = (n - lo).min(CHUNK);
            // The destination's fresh pages made while the device reads.
            make_pages(&[(dst[lo..].as_ptr() as usize, len)]);
            let (b, r) = filled
                .recv()
                .map_err(|_| io::Error::other("the reading thread failed"))?;
            match r {
                Ok(()) => {}
                Err(e) if e.raw_os_error() == Some(libc::EINVAL) => return Ok(false),
                Err(e) => return Err(e),
            }
            dst[lo..lo + len].copy_from_slice(&bytes(&b)[..len]);
            // The thread may have stopped at the last buffer.
            let _ = give.send(b);
        }
        Ok(true)
    })
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

    /// Ranges of every awkward start and length read back byte for byte,
    /// directly or not, and a range past the end fails as truncated.
    #[test]
    fn ranges_read_back_as_written() {
        let dir = std::env::temp_dir().join(format!("octmesh_dread_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("f");
        let byte = |i: u64| (i.wrapping_mul(2_654_435_761) >> 13) as u8;
        let len = 3 * CHUNK as u64 + 5_000;
        let all: Vec<u8> = (0..len).map(byte).collect();
        std::fs::write(&path, &all).unwrap();
        for direct in [true, false] {
            let mut r = DirectReader::open(&path).unwrap();
            if !direct {
                r.direct = None;
            }
            println!("direct reads: {}", r.is_direct());
            for (at, n) in [
                (0u64, 0usize),
                (7, 100),
                (4096, 1 << 20),
                (123, CHUNK + 4096),
                (5000, 2 * CHUNK + 77),
                (len - CHUNK as u64 - 3, CHUNK + 3),
            ] {
                let mut buf = vec![0u8; n];
                r.read_exact_at(&mut buf, at).unwrap();
                assert!(buf[..] == all[at as usize..at as usize + n], "{at} {n}");
            }
            let mut buf = vec![0u8; 2 * CHUNK];
            let e = r.read_exact_at(&mut buf, len - CHUNK as u64).unwrap_err();
            assert_eq!(e.kind(), io::ErrorKind::UnexpectedEof);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
