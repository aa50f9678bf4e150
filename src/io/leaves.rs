//! Leaf files: the global leaves in Morton order, one per line as
//! `x y z level` in lattice units (the root cube has side 2^19, the same units
//! as p4est), comment lines starting with `#`. A file whose name ends in
//! `.bin` is binary instead: the magic `OCTLEAF1`, a little-endian `u64`
//! count, then four little-endian `i32` per leaf (x, y, z, level).
//!
//! An octree in a box domain ([`crate::octree::brick`]) is written as p4est's forest
//! of the brick: a `# brick NX NY NZ` line, then `tree x y z level` per leaf
//! with the tree in p4est's brick order, coordinates relative to the tree on
//! its own `2^19` lattice and the level counted from the tree; leaves in the
//! void are left out. Binary: `OCTLEAF2`, the `u64` count, three `i32` root
//! counts, then five `i32` per leaf (tree, x, y, z, level).

use std::fs::{File, OpenOptions};
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::Path;

use crate::error::{Error, Result};
use crate::octree::brick::{Brick, TreeMap};
use crate::octree::octant::Octant;
use crate::octree::LinearOctree;
use crate::parallel::comm::agree;

const MAGIC: &[u8; 8] = b"OCTLEAF1";
const MAGIC_BRICK: &[u8; 8] = b"OCTLEAF2";

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
    let brick = tree.brick();
    let map = (!brick.is_cube()).then(|| brick.tree_map());
    let mut count = [match &map {
        None => tree.local_len() as u64,
        Some(_) => tree.leaves().iter().filter(|o| !brick.is_void(**o)).count() as u64,
    }];
    comm.sum_u64(&mut count);
    let count = count[0];
    let header = if comm.rank() == 0 {
        (|| -> std::io::Result<()> {
            let mut f = BufWriter::new(File::create(path)?);
            let r = brick.roots();
            match (binary, map.is_some()) {
                (true, false) => {
                    f.write_all(MAGIC)?;
                    f.write_all(&count.to_le_bytes())?;
                }
                (true, true) => {
                    f.write_all(MAGIC_BRICK)?;
                    f.write_all(&count.to_le_bytes())?;
                    for n in r {
                        f.write_all(&(n as i32).to_le_bytes())?;
                    }
                }
                (false, brick_file) => {
                    writeln!(f, "# octmesh {title}")?;
                    writeln!(f, "# count {count}")?;
                    if brick_file {
                        writeln!(f, "# brick {} {} {}", r[0], r[1], r[2])?;
                        writeln!(
                            f,
                            "# tree x y z level (p4est brick order; tree-relative lattice \
                             units: a tree has side 2^19), Morton order"
                        )?;
                    } else {
                        writeln!(
                            f,
                            "# x y z level (lattice units: the root cube has side 2^19), Morton order"
                        )?;
                    }
                }
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
                    let ([x, y, z], level, t) = match &map {
                        None => (o.coords(), o.level(), None),
                        Some(m) => match m.to_tree(*o) {
                            Some((t, c, l)) => (c, l, Some(t)),
                            None => continue,
                        },
                    };
                    if binary {
                        let head = t.map(|t| t as i32).into_iter();
                        let rest = [x, y, z, level as u32].map(|v| v as i32);
                        for v in head.chain(rest) {
                            f.write_all(&v.to_le_bytes())?;
                        }
                    } else if let Some(t) = t {
                        writeln!(f, "{t} {x} {y} {z} {level}")?;
                    } else {
                        writeln!(f, "{x} {y} {z} {level}")?;
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
/// A brick's file gives its leaves as octants of the embedding cube, with
/// the brick. Not collective.
pub fn read_leaves_in_brick(path: &Path) -> Result<(Brick, Vec<Octant>)> {
    let name = path.display();
    let f = File::open(path).map_err(|e| Error::io(format!("cannot read '{name}': {e}")))?;
    let mut r = BufReader::new(f);
    let mut out = Vec::new();
    if is_binary(path) {
        let mut head = [0u8; 16];
        r.read_exact(&mut head)
            .map_err(|_| Error::format(format!("'{name}' is too short for a binary leaf file")))?;
        let in_brick = &head[..8] == MAGIC_BRICK;
        if &head[..8] != MAGIC && !in_brick {
            return Err(Error::format(format!(
                "'{name}' does not start with {MAGIC:?} or {MAGIC_BRICK:?}"
            )));
        }
        let n = u64::from_le_bytes(head[8..].try_into().unwrap_or_default());
        let mut brick = Brick::CUBE;
        if in_brick {
            let mut roots = [0u8; 12];
            r.read_exact(&mut roots)
                .map_err(|_| Error::format(format!("'{name}' ends in its header")))?;
            let v: [u32; 3] = std::array::from_fn(|k| {
                u32::from_le_bytes(roots[4 * k..4 * k + 4].try_into().unwrap_or_default())
            });
            brick = Brick::new(v).map_err(|e| Error::format(format!("'{name}': {e}")))?;
        }
        let map = brick.tree_map();
        let fields = if in_brick { 5 } else { 4 };
        let mut rec = [0u8; 20];
        for i in 0..n {
            r.read_exact(&mut rec[..4 * fields])
                .map_err(|_| Error::format(format!("'{name}' ends after {i} of {n} leaves")))?;
            let v: Vec<i32> = (0..fields)
                .map(|k| i32::from_le_bytes(rec[4 * k..4 * k + 4].try_into().unwrap_or_default()))
                .collect();
            if v.iter().any(|&c| c < 0) || v[fields - 1] > 255 {
                return Err(Error::format(format!(
                    "'{name}': leaf {i} has a negative or huge field"
                )));
            }
            let v: Vec<u32> = v.into_iter().map(|c| c as u32).collect();
            out.push(leaf_of(&map, in_brick, &v)?);
        }
        return Ok((brick, out));
    }
    let mut brick = Brick::CUBE;
    let mut map = brick.tree_map();
    let mut in_brick = false;
    for (ln, line) in r.lines().enumerate() {
        let line = line.map_err(|e| Error::io(format!("cannot read '{name}': {e}")))?;
        let t = line.trim();
        if let Some(roots) = t.strip_prefix("# brick ") {
            let v: Vec<u32> = roots
                .split_whitespace()
                .filter_map(|s| s.parse().ok())
                .collect();
            let roots: [u32; 3] = v.try_into().map_err(|_| {
                Error::format(format!(
                    "'{name}' line {}: expected `# brick NX NY NZ`",
                    ln + 1
                ))
            })?;
            brick = Brick::new(roots)
                .map_err(|e| Error::format(format!("'{name}' line {}: {e}", ln + 1)))?;
            map = brick.tree_map();
            in_brick = true;
            continue;
        }
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let fields = if in_brick { 5 } else { 4 };
        let what = if in_brick {
            "`tree x y z level`"
        } else {
            "`x y z level`"
        };
        let v: Vec<u32> = t
            .split_whitespace()
            .map(|s| s.parse::<u32>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| Error::format(format!("'{name}' line {}: expected {what}", ln + 1)))?;
        if v.len() != fields || v[fields - 1] > 255 {
            return Err(Error::format(format!(
                "'{name}' line {}: expected {what}",
                ln + 1
            )));
        }
        let o = leaf_of(&map, in_brick, &v)
            .map_err(|e| Error::format(format!("'{name}' line {}: {e}", ln + 1)))?;
        out.push(o);
    }
    Ok((brick, out))
}

/// The octant of one record: `x y z level`, or `tree x y z level` in a
/// brick.
fn leaf_of(map: &TreeMap, in_brick: bool, v: &[u32]) -> Result<Octant> {
    if in_brick {
        map.from_tree(v[0], [v[1], v[2], v[3]], v[4] as u8)
    } else {
        Octant::new(v[0], v[1], v[2], v[3] as u8)
    }
}

/// [`read_leaves_in_brick`] without the brick: the octants of the
/// embedding cube.
pub fn read_leaves(path: &Path) -> Result<Vec<Octant>> {
    read_leaves_in_brick(path).map(|(_, l)| l)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parallel::comm::{CommRef, SerialComm};
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

    #[test]
    fn brick_files_keep_trees_and_drop_the_void() {
        let comm: CommRef = Rc::new(SerialComm);
        let mut t = LinearOctree::new_uniform(comm, 3).unwrap();
        let brick = Brick::new([3, 1, 2]).unwrap();
        t.set_brick(brick);
        let inside: Vec<Octant> = t
            .leaves()
            .iter()
            .copied()
            .filter(|o| !brick.is_void(*o))
            .collect();
        assert_eq!(inside.len(), 6 * 8);
        for name in ["octmesh_brick_test.txt", "octmesh_brick_test.bin"] {
            let p = std::env::temp_dir().join(format!("{}_{name}", std::process::id()));
            write_leaves(&t, &p, "test").unwrap();
            let (b, back) = read_leaves_in_brick(&p).unwrap();
            assert_eq!(b, brick);
            assert_eq!(back, inside);
            if name.ends_with(".txt") {
                let text = std::fs::read_to_string(&p).unwrap();
                // Six trees, numbered 0 to 5; the first leaf of tree 0 first.
                assert!(text.contains("\n0 0 0 0 1\n"), "{text}");
                assert!(text.lines().any(|l| l.starts_with("5 ")), "{text}");
            }
            std::fs::remove_file(&p).ok();
        }
    }
}
