//! The split STL read (each rank reads its share of the file, then the
//! ranks gather the triangles) against the whole-file read, on 1 to 4
//! ranks: the same triangles, order and solids for binary and multi-solid
//! ASCII files; the same leaves and mesh files from the command; and for a
//! file broken in one rank's share only (a truncated ASCII file, a
//! malformed facet, a truncated binary file) the one-process error on every
//! rank.
//!
//! Run by `cargo test`, this program launches itself under `mpirun`.

mod common;

use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::time::Duration;

use octmesh::internals::geometry::stl::{read_stl_file, read_stl_file_on, write_stl_binary};
use octmesh::internals::parallel::comm::{CommRef, MpiComm};

const LIMIT: Duration = Duration::from_secs(300);

fn main() {
    common::runner::main("stl_split", child, |r| {
        let dir = common::scratch("stl_split");
        let solids = dir.join("solids.stl");
        common::write_sphere_solids(
            &solids,
            &[
                ("top", Some(true)),
                ("bottom", Some(false)),
                ("top", Some(false)),
            ],
        );
        let halves = dir.join("halves.stl");
        common::write_sphere_solids(&halves, &[("top", Some(true)), ("bottom", Some(false))]);
        let sphere = dir.join("sphere.stl");
        let s = octmesh::internals::geometry::shapes::default_sphere();
        write_stl_binary(&sphere, &s).unwrap();
        let mut files = vec![solids.clone(), sphere.clone()];
        // The real models when the shared folder is there.
        let bunny = r.test("the shared models", || {
            ["bunny.stl", "dragon.stl"]
                .iter()
                .filter_map(|m| common::shared_model(m))
                .collect::<Vec<PathBuf>>()
        });
        files.extend(bunny.unwrap_or_default());

        for np in 1..=4 {
            r.test(
                &format!("surfaces on {}", common::runner::ranks(np)),
                || {
                    for f in &files {
                        let out =
                            common::runner::launch(np, &format!("surface:{}", f.display()), LIMIT);
                        assert!(
                            out.contains("split read matches"),
                            "{}:\n{out}",
                            f.display()
                        );
                    }
                },
            );
        }
        r.test(
            "the same mesh of a multi-solid ASCII file on 1 to 4 ranks",
            || same_outputs(&dir, &halves, "mesh", "--gmsh", "msh"),
        );
        r.test("the same leaves of a binary file on 1 to 4 ranks", || {
            same_outputs(&dir, &sphere, "octree", "--write-leaves", "txt")
        });

        let text = std::fs::read(&solids).unwrap();
        r.test("an ASCII file truncated in the last rank's share", || {
            for np in 2..=4 {
                let f = dir.join(format!("truncated{np}.stl"));
                // Nine tenths: inside the last share on 2 to 4 ranks.
                std::fs::write(&f, &text[..text.len() * 9 / 10]).unwrap();
                same_error(np, &f, "malformed ASCII STL");
            }
        });
        r.test("a malformed facet in rank 1's share", || {
            for np in 2..=4 {
                let f = dir.join(format!("malformed{np}.stl"));
                // Rank 1's share is [len / np, 2 len / np).
                let at = text.len() * 3 / (2 * np);
                let k = at + find(&text[at..], b"vertex");
                let mut b = text.clone();
                b[k..k + 6].copy_from_slice(b"vertez");
                std::fs::write(&f, &b).unwrap();
                same_error(np, &f, "vertez");
            }
        });
        r.test("a binary file truncated in the last rank's share", || {
            let b = std::fs::read(&sphere).unwrap();
            let f = dir.join("short.stl");
            std::fs::write(&f, &b[..b.len() - 75]).unwrap();
            for np in 2..=4 {
                same_error(np, &f, "truncated");
            }
        });
    });
}

fn find(hay: &[u8], needle: &[u8]) -> usize {
    hay.windows(needle.len())
        .position(|w| w == needle)
        .expect("the needle")
}

/// Runs `octmesh COMMAND FILE --level 4 OPTION OUT` on 1 to 4 ranks and
/// requires the same bytes in every OUT.
fn same_outputs(dir: &Path, file: &Path, command: &str, option: &str, ext: &str) {
    let mut first: Option<Vec<u8>> = None;
    for np in 1..=4 {
        let out = dir.join(format!("{command}{np}.{ext}"));
        common::octmesh_ok(
            np,
            &[
                command,
                file.to_str().unwrap(),
                "--level",
                "4",
                option,
                out.to_str().unwrap(),
                "--quiet",
            ],
        );
        let bytes = std::fs::read(&out).unwrap();
        assert!(bytes.len() > 1000, "{} is nearly empty", out.display());
        match &first {
            None => first = Some(bytes),
            Some(b) => assert!(
                *b == bytes,
                "{command} {} differs on 1 and {np} ranks",
                file.display()
            ),
        }
    }
}

/// The split read of `file` on `np` ranks fails on every rank with the
/// one-process error, which contains `word`; so does the command.
fn same_error(np: usize, file: &Path, word: &str) {
    let serial = read_stl_file(file).unwrap_err().to_string();
    assert!(serial.contains(word), "{serial}");
    let out = common::runner::launch(np, &format!("error:{}", file.display()), LIMIT);
    let lines: Vec<&str> = out.lines().filter(|l| l.starts_with("rank ")).collect();
    assert_eq!(lines.len(), np, "{out}");
    for (r, l) in lines.iter().enumerate() {
        assert!(
            l.ends_with(&format!(": {serial}")),
            "rank {r}: {l}, not {serial}"
        );
    }
    let out = common::mpirun(
        np,
        &common::octmesh_bin(),
        &["octree", file.to_str().unwrap(), "--level", "3"],
        LIMIT,
    );
    for l in common::rank_error_lines(&out, np, "octree") {
        assert!(l.contains(&serial), "{l}, not {serial}");
    }
}

fn child(mode: &str) {
    let universe = mpi::initialize().expect("MPI init");
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    let (what, path) = mode.split_once(':').expect("MODE:PATH");
    let path = Path::new(path);
    match what {
        "surface" => {
            let split = read_stl_file_on(&*comm, path).unwrap();
            let whole = read_stl_file(path).unwrap();
            // The others' triangles came through the exchange (nine f32
            // each; shares of an ASCII file are even in bytes, not in
            // triangles), not from reading the whole file here.
            let (n, p) = (split.len() as u64, comm.size() as u64);
            let got = comm.traffic().received;
            let problem = if p > 1 && got < 36 * n / (2 * p) {
                Some(format!("received {got} bytes for {n} triangles"))
            } else if split.triangles() != whole.triangles() {
                Some("other triangles than the whole-file read".to_string())
            } else if split.parts() != whole.parts() {
                Some(format!(
                    "parts {:?}, not {:?}",
                    split.parts(),
                    whole.parts()
                ))
            } else {
                None
            };
            // Every rank learns of a failure, so that none waits for one
            // that panicked.
            let mut failed = [u64::from(problem.is_some())];
            comm.max_u64(&mut failed);
            if let Some(why) = problem {
                panic!("rank {}, {}: {why}", comm.rank(), path.display());
            }
            assert_eq!(failed[0], 0, "another rank failed");
            if comm.rank() == 0 {
                println!(
                    "{}: {} triangles, {} parts: split read matches",
                    path.display(),
                    split.len(),
                    split.parts().names.len()
                );
            }
        }
        "error" => {
            let e = read_stl_file_on(&*comm, path).unwrap_err();
            // One line per rank, in rank order.
            for r in 0..comm.size() {
                comm.barrier();
                if r == comm.rank() {
                    println!("rank {r}: {e}");
                    use std::io::Write;
                    std::io::stdout().flush().unwrap();
                }
            }
        }
        _ => panic!("unknown mode {mode}"),
    }
}
