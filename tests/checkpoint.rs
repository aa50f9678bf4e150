//! Octree checkpoints (`LinearOctree::save` / `load`, `octmesh octree
//! --save`, `octmesh mesh --load`) written on one number of ranks and read
//! on others.
//!
//! - The command: the sphere's octree and solid mesh saved on 2 ranks,
//!   loaded and meshed on 1, 3 and 4 ranks, and saved again on 4 ranks and
//!   loaded on 2: the balanced leaves (leaf files) and the Gmsh files of
//!   the meshes (gathered, the same bytes on any rank count) equal the
//!   original byte for byte, and so does the checkpoint saved on 4 ranks.
//!   A box of 6 x 2 x 1 root cells (the hull) the same way on 3 ranks. A
//!   checkpoint of another surface is refused on every rank.
//! - Leaf data (a launched program): an adapted octree of several
//!   checksum blocks with 12 bytes per leaf (its key and a value of its global index) saved on 2 ranks and
//!   loaded on 1, 3 and 4: every leaf's stored key is its own (the data
//!   came with its leaf), the ranks hold equal counts, and the leaves' and
//!   the data's checksums over all ranks equal the saver's.
//! - Damage: copies of the file truncated, with a byte flipped in the
//!   header, the block table, the leaves and the data, of another version
//!   and with another magic number, and a missing path (to load, and a
//!   directory that does not exist to save in), each refused on every
//!   rank of 3 with its message, the session's octree intact and a
//!   good file loading after.
//!
//! Run by `cargo test`, this program launches itself under `mpirun`.

mod common;

use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::time::Duration;

use octmesh::internals::octree::checkpoint::HEADER_BYTES;
use octmesh::internals::octree::leaf_data::LeafData;
use octmesh::internals::parallel::comm::{CommRef, MpiComm};
use octmesh::internals::refine::NO_LIMIT;
use octmesh::{Config, Connectivity, Domain, ErrorKind, LinearOctree, Octant, Session};

const LIMIT: Duration = Duration::from_secs(600);

/// The scratch directory, made fresh by the parent (`common::scratch`).
fn dir() -> PathBuf {
    common::repo().join("target/test-scratch/checkpoint")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The value leaf `i` carries.
fn value(i: u64) -> u32 {
    (i.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 32) as u32
}

/// A checksum over all ranks that depends on each item's global index:
/// the sum of `f(global index, item)`.
fn global_sum(comm: &CommRef, first: u64, items: impl Iterator<Item = u64>) -> u64 {
    let mut s = [0u64];
    for (k, x) in items.enumerate() {
        let i = first + k as u64;
        let h = (x ^ i.wrapping_mul(0xff51_afd7_ed55_8ccd)).wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        s[0] = s[0].wrapping_add(h ^ (h >> 29));
    }
    comm.sum_u64(&mut s);
    s[0]
}

/// Prints the checksums of the leaves and of the data (`DATA ...`).
fn report(comm: &CommRef, tree: &LinearOctree, data: &LeafData) {
    let first = tree.global_offsets()[comm.rank()];
    let leaves = global_sum(comm, first, tree.leaves().iter().map(|o| o.key()));
    let words = (0..data.len()).map(|i| {
        let d = data.get(i);
        u64::from_le_bytes(d[..8].try_into().unwrap())
            ^ (u32::from_le_bytes(d[8..12].try_into().unwrap()) as u64) << 7
    });
    let sum = global_sum(comm, first, words);
    if comm.rank() == 0 {
        println!(
            "DATA leaves={} leaf_sum={leaves:016x} data_sum={sum:016x}",
            tree.global_len()
        );
    }
}

fn child(mode: &str) {
    let universe = mpi::initialize().expect("MPI init");
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    let path = dir().join("data.ckpt");
    let domain = Domain::cube([-2.0, -2.0, -2.0], 4.0).unwrap();
    match mode {
        "save" => {
            // Several checksum blocks, cut by the ranks' ranges elsewhere
            // on every rank count.
            let mut t = LinearOctree::new_uniform(comm.clone(), 5).unwrap();
            for _ in 0..2 {
                let x = common::SPHERE_START_X;
                t.refine_once(7, |o| common::sphere_cuts(o, x), NO_LIMIT)
                    .unwrap();
            }
            t.balance(Connectivity::Corner).unwrap();
            t.partition().unwrap();
            let first = t.global_offsets()[comm.rank()];
            let mut i = first;
            let data = LeafData::from_fn(&t, 12, |o: Octant, d| {
                d[..8].copy_from_slice(&o.key().to_le_bytes());
                d[8..].copy_from_slice(&value(i).to_le_bytes());
                i += 1;
            });
            t.save(&path, &domain, Some(&data), 7).unwrap();
            report(&comm, &t, &data);
        }
        "load" => {
            let l = LinearOctree::load(comm.clone(), &path, Some(7)).unwrap();
            let data = l.data.expect("the file holds data");
            let (t, n, p) = (&l.tree, l.tree.global_len(), comm.size() as u64);
            assert_eq!(l.info.domain, domain);
            assert_eq!(l.info.balanced, Some(Connectivity::Corner));
            assert_eq!(t.balanced(), Some(Connectivity::Corner));
            t.check().unwrap();
            // The equal-count partition.
            let r = comm.rank() as u64;
            assert_eq!(
                t.local_len() as u64,
                ((r + 1) * n).div_ceil(p) - (r * n).div_ceil(p)
            );
            let first = t.global_offsets()[comm.rank()];
            for (k, &o) in t.leaves().iter().enumerate() {
                let d = data.get(k);
                assert_eq!(u64::from_le_bytes(d[..8].try_into().unwrap()), o.key());
                assert_eq!(
                    u32::from_le_bytes(d[8..].try_into().unwrap()),
                    value(first + k as u64)
                );
            }
            report(&comm, t, &data);
        }
        "damage" => damage(&comm, &path),
        _ => panic!("unknown mode {mode}"),
    }
    comm.barrier();
    println!("DONE rank {}", comm.rank());
}

/// Each damaged copy is refused on every rank with `words` in the message
/// and `kind`, the session keeping its octree; the good file loads after.
fn damage(comm: &CommRef, good: &Path) {
    let bytes = std::fs::read(good).unwrap();
    let n = u64::from_le_bytes(bytes[72..80].try_into().unwrap()) as usize;
    let blocks = n.div_ceil(1 << 16);
    let leaves = HEADER_BYTES as usize + 8 * blocks;
    let data = leaves + 8 * n;
    let flip = |at: usize| {
        let mut b = bytes.clone();
        b[at] ^= 0x04;
        b
    };
    let mut version = bytes.clone();
    version[8] = 1;
    let mut magic = bytes.clone();
    magic[0] = b'X';
    let cases: Vec<(&str, Vec<u8>, ErrorKind, &str)> = vec![
        (
            "truncated",
            bytes[..bytes.len() - 5].to_vec(),
            ErrorKind::Format,
            "truncated",
        ),
        (
            "short",
            bytes[..100].to_vec(),
            ErrorKind::Format,
            "fewer than a checkpoint's header",
        ),
        (
            "header",
            flip(50),
            ErrorKind::Format,
            "header's checksum differs",
        ),
        (
            "table",
            flip(HEADER_BYTES as usize + 3),
            ErrorKind::Format,
            "checksum of the block checksums",
        ),
        (
            "leaves",
            flip(leaves + 8 * (n / 2) + 6),
            ErrorKind::Format,
            "the checksum of leaves",
        ),
        (
            "data",
            flip(data + 12 * (n - 1) + 11),
            ErrorKind::Format,
            "the checksum of leaves",
        ),
        (
            "version",
            version,
            ErrorKind::Format,
            "version 1; this octmesh reads version 2",
        ),
        (
            "magic",
            magic,
            ErrorKind::Format,
            "not an octmesh octree checkpoint",
        ),
    ];
    let mut session = Session::new(comm.clone(), Config::default());
    session.load_octree(good).unwrap();
    let count = session.tree().unwrap().global_len();
    assert!(blocks >= 2, "{count} leaves: one checksum block");
    for (name, content, kind, words) in cases {
        let path = dir().join(format!("bad_{name}.ckpt"));
        if comm.rank() == 0 {
            std::fs::write(&path, &content).unwrap();
        }
        comm.barrier();
        let e = session.load_octree(&path).unwrap_err();
        assert_eq!(e.kind(), kind, "{name}: {}", e.message());
        assert!(e.message().contains(words), "{name}: {}", e.message());
        assert_eq!(session.tree().unwrap().global_len(), count, "{name}");
        assert_eq!(session.leaf_data().map(|d| d.size()), Some(12), "{name}");
        if comm.rank() == 0 {
            println!("REFUSED {name}: {}", e.message());
        }
    }
    let e = session
        .save_octree(&dir().join("missing/none.ckpt"))
        .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Io, "{}", e.message());
    assert!(e.message().contains("cannot create"), "{}", e.message());
    let e = session
        .load_octree(&dir().join("missing/none.ckpt"))
        .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Io, "{}", e.message());
    assert!(e.message().contains("cannot open"), "{}", e.message());
    session.load_octree(good).unwrap();
    assert_eq!(session.tree().unwrap().global_len(), count);
}

/// Runs the command and returns nothing; panics on failure.
fn octmesh(np: usize, args: &[&str]) {
    common::octmesh_ok(np, args);
}

fn same_bytes(a: &Path, b: &Path) {
    let (x, y) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    assert!(!x.is_empty(), "{} is empty", a.display());
    assert!(x == y, "{} and {} differ", a.display(), b.display());
}

fn command_tests(r: &mut common::runner::Runner) {
    let d = dir();
    let p = |name: &str| d.join(name);
    let mesh = |np: usize, extra: &[&str], tag: &str| {
        let (leaves, msh) = (p(&format!("{tag}.bin")), p(&format!("{tag}.msh")));
        let mut args = vec![
            "mesh",
            "sphere",
            "--keep",
            "inside",
            "--write-leaves",
            s(&leaves),
        ];
        args.extend(["--gmsh", s(&msh)]);
        args.extend(extra);
        octmesh(np, &args);
    };
    let saved = r.test("sphere saved on 2 ranks", || {
        mesh(2, &["--level", "6", "--save", s(&p("sphere.ckpt"))], "orig");
        let l = common::leaves(&p("orig.bin"));
        common::assert_complete_linear(&l);
    });
    if saved.is_none() {
        return;
    }
    for np in [1, 3, 4] {
        r.test(
            &format!("loaded and meshed on {}", common::runner::ranks(np)),
            || {
                let tag = format!("load{np}");
                mesh(np, &["--load", s(&p("sphere.ckpt"))], &tag);
                same_bytes(&p("orig.bin"), &p(&format!("{tag}.bin")));
                same_bytes(&p("orig.msh"), &p(&format!("{tag}.msh")));
            },
        );
    }
    r.test("saved again on 4 ranks, loaded on 2", || {
        mesh(
            4,
            &["--load", s(&p("sphere.ckpt")), "--save", s(&p("four.ckpt"))],
            "via4",
        );
        // The file does not depend on the rank count that wrote it.
        same_bytes(&p("sphere.ckpt"), &p("four.ckpt"));
        mesh(2, &["--load", s(&p("four.ckpt"))], "four2");
        same_bytes(&p("orig.bin"), &p("four2.bin"));
        same_bytes(&p("orig.msh"), &p("four2.msh"));
    });
    r.test("a box of root cells on 3 ranks", || {
        let base = [
            "mesh",
            "hull",
            "--box",
            "-1.5,-1,-0.6,4.5,1,0.4",
            "--roots",
            "6,2,1",
            "--keep",
            "outside",
        ];
        let run = |np: usize, extra: &[&str], tag: &str| {
            let mut args = base.to_vec();
            let (leaves, msh) = (p(&format!("{tag}.bin")), p(&format!("{tag}.msh")));
            args.extend(["--write-leaves", s(&leaves), "--gmsh", s(&msh)]);
            args.extend(extra);
            octmesh(np, &args);
        };
        run(2, &["--level", "4", "--save", s(&p("hull.ckpt"))], "hull");
        run(3, &["--load", s(&p("hull.ckpt"))], "hull3");
        same_bytes(&p("hull.bin"), &p("hull3.bin"));
        same_bytes(&p("hull.msh"), &p("hull3.msh"));
    });
    r.test("another surface is refused on every rank", || {
        let ckpt = p("sphere.ckpt");
        let args = ["mesh", "torus", "--load", s(&ckpt), "--keep", "inside"];
        let out = common::mpirun(3, &common::octmesh_bin(), &args, LIMIT);
        for line in common::rank_error_lines(&out, 3, "mesh torus --load") {
            assert!(line.contains("saved from another surface"), "{line}");
        }
    });
}

fn main() {
    common::runner::main("checkpoint", child, |r| {
        common::scratch("checkpoint");
        command_tests(r);
        let saved = r.test("leaf data saved on 2 ranks", || {
            let out = common::runner::launch(2, "save", LIMIT);
            print!("{out}");
            out.lines()
                .find(|l| l.starts_with("DATA"))
                .unwrap()
                .to_string()
        });
        if let Some(want) = saved {
            for (np, out) in r.on_ranks([1, 3, 4], "load", "DONE", LIMIT) {
                r.test(
                    &format!("the same leaves and data on {}", common::runner::ranks(np)),
                    || {
                        assert!(
                            out.contains(&want),
                            "on {np} ranks, expected '{want}' in\n{out}"
                        );
                    },
                );
            }
            r.on_ranks([3], "damage", "REFUSED magic", LIMIT);
        }
    });
}
