//! Leaf files: the global leaves in Morton order, one per line as
//! `x y z level` in lattice units (the root cube has side 2^19, the same units
//! as p4est), comment lines starting with `#`. A file whose name ends in
//! `.bin` is binary instead: the magic `OCTLEAF1`, a little-endian `u64`
//! count, then four little-endian `i32` per leaf (x, y, z, level).

use std::fs::{File, OpenOptions};
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::Path;

use crate::comm::agree;
use crate::error::{Error, Result};
use crate::octant::Octant;
use crate::octree::LinearOctree;

const MAGIC: &[u8; 8] = b"OCTLEAF1";

fn is_binary(path: &Path) -> bool {
    path.extension().is_some_and(|e| e == "bin")
}

fn io_err(path: &Path, e: std::io::Error) -> Error {
    Error::io(format!("cannot write '{}': {e}", path.display()))
}

/// Writes the global leaves of `tree` to `path`, ranks appending their runs
/// in rank order. Collective.
pub fn write_leaves(tree: &LinearOctree, path: &Path, title: &str) -> Result<()> {
    let comm = tree.comm().clone();
    let binary = is_binary(path);
    let header = if comm.rank() == 0 {
        (|| -> std::io::Result<()> {
            let mut f = BufWriter::new(File::create(path)?);
            if binary {
                f.write_all(MAGIC)?;
                f.write_all(&tree.global_len().to_le_bytes())?;
            } else {
                writeln!(f, "# octmesh {title}")?;
                writeln!(f, "# count {}", tree.global_len())?;
                writeln!(
                    f,
                    "# x y z level (lattice units: the root cube has side 2^19), Morton order"
                )?;
            }
            f.flush()
        })()
        .map_err(|e| io_err(path, e))
    } else {
        Ok(())
    };
    agree(&*comm, header)?;
    for r in 0..comm.size() {
        let mine = if r == comm.rank() {
            (|| -> std::io::Result<()> {
                let f = OpenOptions::new().append(true).open(path)?;
                let mut f = BufWriter::with_capacity(1 << 20, f);
                for o in tree.leaves() {
                    let [x, y, z] = o.coords();
                    if binary {
                        for v in [x, y, z, o.level() as u32] {
                            f.write_all(&(v as i32).to_le_bytes())?;
                        }
                    } else {
                        writeln!(f, "{x} {y} {z} {}", o.level())?;
                    }
                }
                f.flush()
            })()
            .map_err(|e| io_err(path, e))
        } else {
            Ok(())
        };
        agree(&*comm, mine)?;
    }
    Ok(())
}

/// Reads a leaf file (text or binary, by extension), checking each octant.
/// Not collective.
pub fn read_leaves(path: &Path) -> Result<Vec<Octant>> {
    let name = path.display();
    let f = File::open(path).map_err(|e| Error::io(format!("cannot read '{name}': {e}")))?;
    let mut r = BufReader::new(f);
    let mut out = Vec::new();
    if is_binary(path) {
        let mut head = [0u8; 16];
        r.read_exact(&mut head)
            .map_err(|_| Error::format(format!("'{name}' is too short for a binary leaf file")))?;
        if &head[..8] != MAGIC {
            return Err(Error::format(format!(
                "'{name}' does not start with {MAGIC:?}"
            )));
        }
        let n = u64::from_le_bytes(head[8..].try_into().unwrap_or_default());
        let mut rec = [0u8; 16];
        for i in 0..n {
            r.read_exact(&mut rec)
                .map_err(|_| Error::format(format!("'{name}' ends after {i} of {n} leaves")))?;
            let v: [i32; 4] = std::array::from_fn(|k| {
                i32::from_le_bytes(rec[4 * k..4 * k + 4].try_into().unwrap_or_default())
            });
            if v.iter().any(|&c| c < 0) || v[3] > 255 {
                return Err(Error::format(format!(
                    "'{name}': leaf {i} has a negative or huge field"
                )));
            }
            out.push(Octant::new(
                v[0] as u32,
                v[1] as u32,
                v[2] as u32,
                v[3] as u8,
            )?);
        }
        return Ok(out);
    }
    for (ln, line) in r.lines().enumerate() {
        let line = line.map_err(|e| Error::io(format!("cannot read '{name}': {e}")))?;
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let v: Vec<u32> = t
            .split_whitespace()
            .map(|s| s.parse::<u32>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| {
                Error::format(format!("'{name}' line {}: expected four integers", ln + 1))
            })?;
        if v.len() != 4 || v[3] > 255 {
            return Err(Error::format(format!(
                "'{name}' line {}: expected `x y z level`",
                ln + 1
            )));
        }
        let o = Octant::new(v[0], v[1], v[2], v[3] as u8)
            .map_err(|e| Error::format(format!("'{name}' line {}: {e}", ln + 1)))?;
        out.push(o);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::comm::{CommRef, SerialComm};
    use std::rc::Rc;

    #[test]
    fn text_and_binary_roundtrip() {
        let comm: CommRef = Rc::new(SerialComm);
        let t = LinearOctree::new_uniform(comm, 2).unwrap();
        for name in ["octmesh_leaves_test.txt", "octmesh_leaves_test.bin"] {
            let p = std::env::temp_dir().join(format!("{}_{name}", std::process::id()));
            write_leaves(&t, &p, "test").unwrap();
            assert_eq!(read_leaves(&p).unwrap(), t.leaves());
            std::fs::remove_file(&p).ok();
        }
    }
}
