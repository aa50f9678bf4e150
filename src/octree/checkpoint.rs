//! Checkpoints: an octree, its domain and its per-leaf data in one file,
//! written by all ranks together and read back on any number of ranks.
//!
//! [`LinearOctree::save`] writes each rank's leaves and data at their
//! global offsets ([`SharedFile`]: MPI-IO over MPI, a plain file on one
//! process). [`LinearOctree::load`] gives rank `q` of `M` the global leaves
//! `ceil(q N / M)..ceil((q + 1) N / M)`, the partition of
//! [`LinearOctree::partition`], with their data, whatever number of ranks
//! saved them.
//!
//! The file (all numbers little-endian; docs/formats.md has the byte
//! table):
//!
//! ```text
//!   header (128 bytes) | block checksums (8 per block) | leaves (8 each) | data (S each)
//! ```
//!
//! Checksums do not depend on the rank count: leaf `i`'s octant key is
//! word `i` of one stream, and its data, cut into `W` 8-byte words (the
//! last one padded with zeros), the words `N + i W ..` (`N` leaves); a
//! block of [`BLOCK_LEAVES`] leaves has the word sum of its keys' and
//! data's words (`geometry::hash::word_sum`, four lanes of one product
//! per word), which ranks holding pieces of the block add up. The table
//! of block sums has its keyed sum (`geometry::hash::keyed_sum`) in the
//! header, and the header its keyed sum in its last word. Any one changed
//! word changes a sum, so a flipped byte anywhere is found.

use std::path::Path;

use crate::error::{Error, ErrorKind, Result};
use crate::geometry::hash::{keyed_sum, word_sum};
use crate::octree::brick::Brick;
use crate::octree::domain::Domain;
use crate::octree::leaf_data::LeafData;
use crate::octree::octant::{Connectivity, Octant, MAX_LEVEL};
use crate::octree::LinearOctree;
use crate::parallel::comm::{agree, Comm, CommRef};
use crate::parallel::file::{Mode, SharedFile};

/// The file's first 8 bytes.
pub const MAGIC: [u8; 8] = *b"OCTMCKPT";

/// The layout version this code writes and reads.
pub const VERSION: u32 = 2;

/// The endianness marker: written little-endian, read back as this value
/// only by a reader of the same byte order.
pub const ENDIAN_MARK: u32 = 0x0A0B_0C0D;

/// Bytes of the header.
pub const HEADER_BYTES: u64 = 128;

/// Leaves per checksum block.
pub const BLOCK_LEAVES: u64 = 1 << 16;

/// What a checkpoint's header says besides the layout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CheckpointInfo {
    /// The domain: the cube, or the brick of root cells.
    pub domain: Domain,
    /// The connectivity the octree was balanced for, if any.
    pub balanced: Option<Connectivity>,
    /// Leaves over all ranks.
    pub leaves: u64,
    /// Bytes of data per leaf (0: none).
    pub data_size: u64,
    /// [`crate::Surface::hash`] of the surface the octree was built from; 0
    /// when none was recorded.
    pub surface_hash: u64,
}

/// A loaded checkpoint: the octree (in the equal-count partition), its
/// domain and header, and this rank's data.
#[derive(Debug)]
pub struct Loaded {
    /// The octree, balanced-flag and brick restored.
    pub tree: LinearOctree,
    /// The header.
    pub info: CheckpointInfo,
    /// This rank's data, when the file holds some.
    pub data: Option<LeafData>,
}

/// Byte offsets of the sections, from the header's counts.
#[derive(Clone, Copy, Debug)]
struct Layout {
    blocks: u64,
    table: u64,
    leaves: u64,
    data: u64,
    end: u64,
}

impl Layout {
    /// `None` when the sizes overflow (a corrupt or hostile header).
    fn new(leaves: u64, data_size: u64, block: u64) -> Option<Layout> {
        let blocks = leaves.div_ceil(block);
        let table = HEADER_BYTES;
        let first_leaf = table.checked_add(blocks.checked_mul(8)?)?;
        let data = first_leaf.checked_add(leaves.checked_mul(8)?)?;
        let end = data.checked_add(leaves.checked_mul(data_size)?)?;
        Some(Layout {
            blocks,
            table,
            leaves: first_leaf,
            data,
            end,
        })
    }
}

fn connectivity_code(c: Option<Connectivity>) -> u32 {
    match c {
        None => 0,
        Some(Connectivity::Face) => 1,
        Some(Connectivity::Edge) => 2,
        Some(Connectivity::Corner) => 3,
    }
}

/// The header's 16 words: `block` leaves per checksum block, `table` the
/// sum of the block table; the last word is the sum of the others.
fn encode_header(info: &CheckpointInfo, block: u64, table: u64) -> [u8; HEADER_BYTES as usize] {
    let mut h = [0u8; HEADER_BYTES as usize];
    let d = &info.domain;
    let roots = d.brick.roots();
    h[0..8].copy_from_slice(&MAGIC);
    h[8..12].copy_from_slice(&VERSION.to_le_bytes());
    h[12..16].copy_from_slice(&ENDIAN_MARK.to_le_bytes());
    h[16..24].copy_from_slice(&HEADER_BYTES.to_le_bytes());
    for k in 0..3 {
        h[24 + 8 * k..32 + 8 * k].copy_from_slice(&d.origin[k].to_le_bytes());
        h[56 + 4 * k..60 + 4 * k].copy_from_slice(&roots[k].to_le_bytes());
    }
    h[48..56].copy_from_slice(&d.side.to_le_bytes());
    h[68..72].copy_from_slice(&connectivity_code(info.balanced).to_le_bytes());
    h[72..80].copy_from_slice(&info.leaves.to_le_bytes());
    h[80..88].copy_from_slice(&info.data_size.to_le_bytes());
    h[88..96].copy_from_slice(&info.surface_hash.to_le_bytes());
    h[96..104].copy_from_slice(&block.to_le_bytes());
    h[104..112].copy_from_slice(&table.to_le_bytes());
    let sum = header_sum(&h);
    h[120..128].copy_from_slice(&sum.to_le_bytes());
    h
}

fn word(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}

fn word32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

/// The keyed sum of the header's first 15 words.
fn header_sum(h: &[u8]) -> u64 {
    keyed_sum((0..15).map(|k| word(h, 8 * k)), 0)
}

/// Reads and checks a header; returns it with the block size and the
/// table's sum. Rank-local.
fn decode_header(h: &[u8], path: &str) -> Result<(CheckpointInfo, u64, u64)> {
    let bad =
        |what: String| Error::format(format!("{path} is not a valid octree checkpoint: {what}"));
    if h[0..8] != MAGIC {
        return Err(Error::format(format!(
            "{path} is not an octmesh octree checkpoint (its first bytes are not {:?})",
            String::from_utf8_lossy(&MAGIC)
        )));
    }
    let version = word32(h, 8);
    if version != VERSION {
        return Err(Error::format(format!(
            "{path} is an octree checkpoint of version {version}; this octmesh reads version \
             {VERSION}"
        )));
    }
    let mark = word32(h, 12);
    if mark != ENDIAN_MARK {
        return Err(bad(format!(
            "its endianness marker is {mark:#010x}, not {ENDIAN_MARK:#010x} (another byte \
             order, or a damaged header)"
        )));
    }
    let stored = word(h, 120);
    if header_sum(h) != stored {
        return Err(bad(
            "the header's checksum differs: the header is damaged".into()
        ));
    }
    let size = word(h, 16);
    if size != HEADER_BYTES {
        return Err(bad(format!(
            "its header has {size} bytes, not {HEADER_BYTES}"
        )));
    }
    let origin = std::array::from_fn(|k| {
        f64::from_le_bytes(h[24 + 8 * k..32 + 8 * k].try_into().expect("8"))
    });
    let side = f64::from_le_bytes(h[48..56].try_into().expect("8 bytes"));
    let roots = std::array::from_fn(|k| word32(h, 56 + 4 * k));
    let mut domain = Domain::cube(origin, side).map_err(|e| bad(e.message().to_string()))?;
    domain.brick = Brick::new(roots).map_err(|e| bad(e.message().to_string()))?;
    let balanced = match word32(h, 68) {
        0 => None,
        1 => Some(Connectivity::Face),
        2 => Some(Connectivity::Edge),
        3 => Some(Connectivity::Corner),
        c => return Err(bad(format!("unknown balance code {c}"))),
    };
    let block = word(h, 96);
    if block == 0 {
        return Err(bad("its checksum blocks hold no leaves".into()));
    }
    let info = CheckpointInfo {
        domain,
        balanced,
        leaves: word(h, 72),
        data_size: word(h, 80),
        surface_hash: word(h, 88),
    };
    Ok((info, block, word(h, 104)))
}

/// The data words of each leaf in the checksum stream: its data cut into
/// 8-byte words, the last one padded with zero bytes.
fn data_words(data_size: u64) -> u64 {
    data_size.div_ceil(8)
}

/// Leaves whose data a padded copy holds at a time.
const PAD_LEAVES: usize = 4096;

/// Adds the word sums of leaves `first..` (global indices, of `n` in all;
/// `keys` and `data`, `size` bytes each) to the sums of their blocks,
/// `sums[b - first_block]`.
#[allow(clippy::too_many_arguments)]
fn add_block_sums(
    sums: &mut [u64],
    first_block: u64,
    block: u64,
    first: u64,
    n: u64,
    keys: &[Octant],
    data: &[u8],
    size: usize,
) {
    let w = data_words(size as u64);
    let key_bytes = key_bytes(keys);
    // Data of a size that is no multiple of 8, copied leaf by leaf into
    // padded words.
    let mut padded = vec![
        0u8;
        if size.is_multiple_of(8) {
            0
        } else {
            PAD_LEAVES * 8 * w as usize
        }
    ];
    let mut k = 0usize;
    // Block by block: no division per leaf.
    while k < keys.len() {
        let i = first + k as u64;
        let b = i / block;
        let end = (((b + 1) * block - first) as usize).min(keys.len());
        let mut s = word_sum(&key_bytes[8 * k..8 * end], i);
        if size.is_multiple_of(8) {
            s = s.wrapping_add(word_sum(&data[k * size..end * size], n + i * w));
        } else {
            let stride = 8 * w as usize;
            for from in (k..end).step_by(PAD_LEAVES) {
                let to = (from + PAD_LEAVES).min(end);
                for (j, d) in data[from * size..to * size].chunks_exact(size).enumerate() {
                    padded[j * stride..j * stride + size].copy_from_slice(d);
                }
                let at = n + (first + from as u64) * w;
                s = s.wrapping_add(word_sum(&padded[..(to - from) * stride], at));
            }
        }
        let at = (b - first_block) as usize;
        sums[at] = sums[at].wrapping_add(s);
        k = end;
    }
}

/// The block sums of the global leaves (`n` in all), each rank adding
/// those of its `keys` (from global index `first`). Collective.
#[allow(clippy::too_many_arguments)]
fn block_sums(
    comm: &dyn Comm,
    blocks: u64,
    block: u64,
    first: u64,
    n: u64,
    keys: &[Octant],
    data: &[u8],
    size: usize,
) -> Vec<u64> {
    let mut sums = vec![0u64; blocks as usize];
    add_block_sums(&mut sums, 0, block, first, n, keys, data, size);
    // Wrapping sums: MPI adds unsigned integers modulo 2^64.
    comm.sum_u64(&mut sums);
    sums
}

/// The octants as little-endian bytes.
fn key_bytes(leaves: &[Octant]) -> std::borrow::Cow<'_, [u8]> {
    let keys = Octant::as_keys(leaves);
    if cfg!(target_endian = "little") {
        // SAFETY: u64s viewed as their bytes, on a little-endian machine.
        std::borrow::Cow::Borrowed(unsafe {
            std::slice::from_raw_parts(keys.as_ptr() as *const u8, keys.len() * 8)
        })
    } else {
        std::borrow::Cow::Owned(keys.iter().flat_map(|k| k.to_le_bytes()).collect())
    }
}

impl LinearOctree {
    /// Saves the octree, its `domain` and this rank's `data` (one entry
    /// per local leaf, or none) to the checkpoint `path`, with
    /// `surface_hash` ([`crate::Surface::hash`] of the surface the octree
    /// came from, 0 for none). Each rank writes its leaves at their global
    /// offset, into one file (see the module documentation). Collective;
    /// an error on any rank (a path that cannot be written, data of
    /// another length or size, a domain whose brick is not the octree's)
    /// fails every rank.
    pub fn save(
        &self,
        path: &Path,
        domain: &Domain,
        data: Option<&LeafData>,
        surface_hash: u64,
    ) -> Result<()> {
        let comm = &**self.comm();
        let size = data.map_or(0, |d| d.size()) as u64;
        let checked = if domain.brick != self.brick() {
            Err(Error::invalid(
                "the domain's root cells are not those of the octree",
            ))
        } else {
            match data {
                Some(d) if d.len() != self.local_len() => Err(Error::invalid(format!(
                    "the leaf data has {} entries for {} local leaves",
                    d.len(),
                    self.local_len()
                ))),
                _ => Ok(()),
            }
        };
        agree(comm, checked)?;
        // Every rank must give the same data size.
        let mut sizes = [size, !size];
        comm.max_u64(&mut sizes);
        if sizes[0] != !sizes[1] {
            return Err(Error::invalid(
                "the ranks give leaf data of different sizes per leaf",
            ));
        }
        let n = self.global_len();
        let layout = Layout::new(n, size, BLOCK_LEAVES)
            .ok_or_else(|| Error::invalid("the checkpoint would exceed 2^64 bytes"))?;
        let first = self.global_offsets()[comm.rank()];
        let bytes = data.map_or(&[][..], |d| d.as_bytes());
        let sums = block_sums(
            comm,
            layout.blocks,
            BLOCK_LEAVES,
            first,
            n,
            self.leaves(),
            bytes,
            size as usize,
        );
        let info = CheckpointInfo {
            domain: *domain,
            balanced: self.balanced(),
            leaves: n,
            data_size: size,
            surface_hash,
        };
        let file = SharedFile::open(comm, path, Mode::Create(layout.end))?;
        let mut head = Vec::new();
        if comm.rank() == 0 {
            head.extend_from_slice(&encode_header(
                &info,
                BLOCK_LEAVES,
                keyed_sum(sums.iter().copied(), 0),
            ));
            head.extend(sums.iter().flat_map(|s| s.to_le_bytes()));
        }
        let written = file
            .write_at_all(0, &head)
            .and(file.write_at_all(layout.leaves + 8 * first, &key_bytes(self.leaves())))
            .and(file.write_at_all(layout.data + size * first, bytes));
        // `and` evaluated all three calls: every rank made them. Now agree,
        // then close.
        let written = agree(comm, written);
        let closed = file.close();
        written.and(closed)
    }

    /// Reads the header of the checkpoint `path`. Collective.
    pub fn checkpoint_info(comm: &dyn Comm, path: &Path) -> Result<CheckpointInfo> {
        let file = SharedFile::open(comm, path, Mode::Read)?;
        let (info, _, _, _) = read_head(comm, &file, &path.display().to_string())?;
        file.close()?;
        Ok(info)
    }

    /// Loads the checkpoint `path` on the ranks of `comm`, in the
    /// equal-count partition, with the data of the leaves when the file
    /// holds some. With `surface_hash`, refuses a checkpoint recorded from
    /// another surface (one recorded without a surface is accepted).
    /// Collective: a missing or unreadable file, a file that is not a
    /// checkpoint, of another version, truncated or damaged (a checksum
    /// differs) fails every rank with the same message.
    pub fn load(comm: CommRef, path: &Path, surface_hash: Option<u64>) -> Result<Loaded> {
        let shown = path.display().to_string();
        let c = &*comm;
        let file = SharedFile::open(c, path, Mode::Read)?;
        let (info, block, table_sum, layout) = read_head(c, &file, &shown)?;
        if let Some(h) = surface_hash {
            if info.surface_hash != 0 && info.surface_hash != h {
                return Err(Error::invalid(format!(
                    "{shown} was saved from another surface (its surface hash is {:016x}, this \
                     surface's {h:016x})",
                    info.surface_hash
                )));
            }
        }
        let damaged = |what: String| Error::format(format!("{shown} is damaged: {what}"));
        // The table, on every rank (8 bytes per block of leaves).
        let mut raw = vec![0u8; 8 * layout.blocks as usize];
        let read = file.read_at_all(layout.table, &mut raw);
        agree(c, read)?;
        let table: Vec<u64> = raw.chunks(8).map(|w| word(w, 0)).collect();
        drop(raw);
        if keyed_sum(table.iter().copied(), 0) != table_sum {
            return Err(damaged(
                "the checksum of the block checksums differs".into(),
            ));
        }
        // This rank's share: the partition's equal counts.
        let (n, p, r) = (info.leaves, c.size() as u128, c.rank() as u128);
        let start = |q: u128| (q * n as u128).div_ceil(p) as u64;
        let (first, last) = (start(r), start(r + 1));
        let count = (last - first) as usize;
        let size = info.data_size as usize;
        // Zeroed allocations take fresh pages, which the reads make in bulk
        // (`SharedFile::read_at_all`) as the device fills them.
        let mut keys = vec![0u64; count];
        let mut bytes = vec![0u8; count * size];
        let read = file
            .read_at_all(layout.leaves + 8 * first, words_as_bytes_mut(&mut keys))
            .and(file.read_at_all(layout.data + info.data_size * first, &mut bytes));
        agree(c, read)?;
        file.close()?;
        let leaves: Vec<Octant> = keys
            .into_iter()
            .map(|k| Octant::from_key(u64::from_le(k)))
            .collect();
        let sums = block_sums(c, layout.blocks, block, first, n, &leaves, &bytes, size);
        if let Some(b) = (0..table.len()).find(|&b| sums[b] != table[b]) {
            let lo = b as u64 * block;
            let hi = (lo + block).min(n) - 1;
            return Err(damaged(format!(
                "the checksum of leaves {lo} to {hi} (block {b}) differs"
            )));
        }
        // The deepest level first, in a pass without branches.
        let deepest = leaves.iter().fold(0, |m, o| m.max(o.level()));
        let bad_level = (deepest > MAX_LEVEL)
            .then(|| leaves.iter().position(|o| o.level() > MAX_LEVEL))
            .flatten();
        let levels = match bad_level {
            Some(i) => Err(damaged(format!(
                "leaf {} has level {}",
                first + i as u64,
                leaves[i].level()
            ))),
            None => Ok(()),
        };
        agree(c, levels)?;
        let mut tree = LinearOctree::from_local_leaves(comm.clone(), leaves).map_err(|e| {
            Error::new(
                ErrorKind::Format,
                format!("{shown} does not hold a complete octree: {}", e.message()),
            )
        })?;
        tree.set_brick(info.domain.brick);
        tree.set_balanced(info.balanced);
        let data = (size > 0).then(|| LeafData::from_bytes(size, bytes));
        Ok(Loaded { tree, info, data })
    }
}

/// Words as bytes to read into.
fn words_as_bytes_mut(words: &mut [u64]) -> &mut [u8] {
    // SAFETY: every byte pattern is a u64, and u8 has no alignment.
    unsafe { std::slice::from_raw_parts_mut(words.as_mut_ptr() as *mut u8, words.len() * 8) }
}

/// Reads and checks the header and the file's size. Collective.
fn read_head(
    comm: &dyn Comm,
    file: &SharedFile,
    shown: &str,
) -> Result<(CheckpointInfo, u64, u64, Layout)> {
    // Measured first: MPI-IO does not always report a read past the end.
    let size = agree(comm, file.size())?;
    if size < HEADER_BYTES {
        return Err(Error::format(format!(
            "{shown} has {size} bytes, fewer than a checkpoint's header ({HEADER_BYTES}): it is \
             truncated or not a checkpoint"
        )));
    }
    let mut h = vec![0u8; HEADER_BYTES as usize];
    let got = file.read_at_all(0, &mut h);
    agree(comm, got)?;
    let head = decode_header(&h, shown).and_then(|(info, block, table)| {
        let layout = Layout::new(info.leaves, info.data_size, block)
            .ok_or_else(|| Error::format(format!("{shown} is damaged: its sizes overflow")))?;
        if size < layout.end {
            return Err(Error::format(format!(
                "{shown} is truncated: it has {size} bytes, its header announces {}",
                layout.end
            )));
        }
        if size > layout.end {
            return Err(Error::format(format!(
                "{shown} has {} bytes after the end its header announces ({}): it is damaged",
                size - layout.end,
                layout.end
            )));
        }
        Ok((info, block, table, layout))
    });
    agree(comm, head)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parallel::comm::SerialComm;
    use std::rc::Rc;

    fn dir() -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("octmesh-ckpt-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn saves_and_loads_on_one_process() {
        let comm: CommRef = Rc::new(SerialComm);
        let mut t = LinearOctree::new_uniform(comm.clone(), 2).unwrap();
        for _ in 0..2 {
            t.refine_once(4, |o| o.coords()[0] == 0, u64::MAX).unwrap();
        }
        let data = LeafData::from_fn(&t, 5, |o, b| b.copy_from_slice(&o.key().to_le_bytes()[..5]));
        let domain = Domain::cube([1.0, 2.0, 3.0], 4.0).unwrap();
        let path = dir().join("t.ckpt");
        t.save(&path, &domain, Some(&data), 42).unwrap();
        let len = std::fs::metadata(&path).unwrap().len();
        let n = t.global_len();
        assert_eq!(len, HEADER_BYTES + 8 + 8 * n + 5 * n);
        let got = LinearOctree::load(comm.clone(), &path, Some(42)).unwrap();
        assert_eq!(got.tree.leaves(), t.leaves());
        assert_eq!(got.data.as_ref(), Some(&data));
        assert_eq!(got.info.domain, domain);
        assert_eq!(got.info.surface_hash, 42);
        let info = LinearOctree::checkpoint_info(&SerialComm, &path).unwrap();
        assert_eq!((info.leaves, info.data_size), (n, 5));
        let e = LinearOctree::load(comm.clone(), &path, Some(43)).unwrap_err();
        assert!(e.message().contains("another surface"), "{}", e.message());
        // Every byte matters.
        let bytes = std::fs::read(&path).unwrap();
        for at in [0usize, 9, 13, 30, 100, 121, 130, 140, 1000, bytes.len() - 1] {
            let mut b = bytes.clone();
            b[at] ^= 0x10;
            std::fs::write(&path, &b).unwrap();
            let e = LinearOctree::load(comm.clone(), &path, None).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::Format, "byte {at}: {}", e.message());
        }
        std::fs::write(&path, &bytes[..bytes.len() - 3]).unwrap();
        let e = LinearOctree::load(comm.clone(), &path, None).unwrap_err();
        assert!(e.message().contains("truncated"), "{}", e.message());
        std::fs::remove_file(&path).unwrap();
    }
}
