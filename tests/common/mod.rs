//! Helpers shared by the integration tests: running programs under `mpirun`
//! with a time limit, the oracles (outside programs and files) and what to
//! do when one is missing, the runner of the test programs that launch
//! themselves ([`runner`]), the finite-element codes that solve on the
//! written files ([`fe_oracle`]), and checks written independently of the
//! library's algorithms.
//!
//! # Oracles
//!
//! Every test that needs something from outside the repository gets it
//! through [`require`] (or [`shared_model`], [`openfoam`], [`python_with`],
//! [`p4est_ref`]): with `CI=true` or `OCTMESH_REQUIRE_ORACLES=1` a missing
//! oracle fails the test, naming what is missing and how to install it;
//! without them the test prints `skipped: ... missing (...)` and leaves out
//! the checks that need it. Locations, and the variables that move them:
//!
//! - `OCTMESH_SHARED_DIR`: the shared folder (models in `data/`, OpenFOAM
//!   reference cases in `openfoam/`); default `../shared` beside the
//!   repository.
//! - `OCTMESH_OPENFOAM_DIR`: OpenFOAM's installation folder, whose
//!   `etc/bashrc` sets up its environment; default `/usr/share/openfoam`
//!   (Debian's `openfoam` package). Its `checkMesh` must run after sourcing
//!   that file.
//! - `OCTMESH_PYTHON`: the Python that reads the written files (meshio,
//!   VTK); default `python3`, then `/usr/bin/python3`.
#![allow(dead_code)]

pub mod conformity;
pub mod fe_oracle;
pub mod runner;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use octmesh::Octant;

/// The `octmesh` command built for this test run.
pub fn octmesh_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_octmesh"))
}

/// The word printed right after `label` in a program's output (checkMesh's
/// figures, for example), without a trailing `,`, `;` or `.`.
pub fn word_after<'a>(text: &'a str, label: &str) -> &'a str {
    let at = text
        .find(label)
        .unwrap_or_else(|| panic!("no '{label}' in:\n{text}"));
    text[at + label.len()..]
        .split_whitespace()
        .next()
        .map(|w| w.trim_end_matches([',', ';', '.']))
        .unwrap_or_else(|| panic!("nothing after '{label}' in:\n{text}"))
}

/// The number printed right after `label` (see [`word_after`]).
pub fn number_after(text: &str, label: &str) -> f64 {
    let w = word_after(text, label);
    w.parse()
        .unwrap_or_else(|_| panic!("'{w}' after '{label}' is not a number"))
}

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A fresh scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let d = repo().join("target").join("test-scratch").join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("create scratch dir");
    d
}

/// Whether a missing oracle fails the test instead of skipping it:
/// `CI=true` (as CI services set it) or `OCTMESH_REQUIRE_ORACLES=1`.
pub fn oracles_required() -> bool {
    let set = |k: &str| std::env::var(k).is_ok_and(|v| v == "1" || v.eq_ignore_ascii_case("true"));
    set("CI") || set("OCTMESH_REQUIRE_ORACLES")
}

/// Skips counted in this process (see [`runner`]).
pub static SKIPS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Something a test compares against that comes from outside the
/// repository.
#[derive(Clone, Copy, Debug)]
pub enum Oracle<'a> {
    /// A file or folder of the shared folder (`data/bunny.stl`,
    /// `openfoam/sphere_castellated`).
    Shared(&'a str),
    /// OpenFOAM: its `etc/bashrc`, with `checkMesh` on the path after
    /// sourcing it.
    OpenFoam,
    /// A Python that can `import module`, from the Debian `package`.
    Python { module: &'a str, package: &'a str },
    /// A program in `PATH`, from the Debian `package`.
    Program { name: &'a str, package: &'a str },
}

impl Oracle<'_> {
    /// The oracle's path, or what is missing.
    pub fn find(self) -> Result<PathBuf, String> {
        match self {
            Oracle::Shared(rel) => {
                let p = shared_dir().join(rel);
                if p.exists() {
                    Ok(p)
                } else {
                    Err(p.display().to_string())
                }
            }
            Oracle::OpenFoam => openfoam_rc().clone(),
            Oracle::Python { module, .. } => {
                let candidates: Vec<String> = match std::env::var("OCTMESH_PYTHON") {
                    Ok(p) => vec![p],
                    Err(_) => vec!["python3".into(), "/usr/bin/python3".into()],
                };
                candidates
                    .iter()
                    .find(|c| {
                        Command::new(c)
                            .args(["-c", &format!("import {module}")])
                            .output()
                            .is_ok_and(|o| o.status.success())
                    })
                    .map(PathBuf::from)
                    .ok_or_else(|| format!("a Python with {module} (tried {candidates:?})"))
            }
            Oracle::Program { name, .. } => std::env::var_os("PATH")
                .iter()
                .flat_map(std::env::split_paths)
                .map(|d| d.join(name))
                .find(|p| p.is_file())
                .ok_or_else(|| format!("the program {name} (not in PATH)")),
        }
    }

    /// How to get the oracle.
    pub fn install(self) -> String {
        match self {
            Oracle::Shared(_) => format!(
                "put the shared folder (models in data/, OpenFOAM cases in openfoam/) beside \
                 the repository as ../shared, or set OCTMESH_SHARED_DIR to it (now {})",
                shared_dir().display()
            ),
            Oracle::OpenFoam => format!(
                "install Debian's openfoam package (scripts/setup.sh does), or set \
                 OCTMESH_OPENFOAM_DIR to an OpenFOAM folder with etc/bashrc (now {})",
                openfoam_dir().display()
            ),
            Oracle::Python { package, .. } => {
                format!("install Debian's {package} (scripts/setup.sh does) or set OCTMESH_PYTHON")
            }
            Oracle::Program { package, .. } => {
                format!("install Debian's {package} (scripts/setup.sh does)")
            }
        }
    }
}

/// The one place a test learns whether it may go on: the oracle's path, or
/// (when it is missing) a panic under [`oracles_required`], else `None`
/// after printing `skipped: ... missing (how to install it)`. The caller
/// leaves out the checks that need the oracle.
pub fn require(oracle: Oracle) -> Option<PathBuf> {
    match oracle.find() {
        Ok(p) => Some(p),
        Err(what) => {
            let install = oracle.install();
            if oracles_required() {
                panic!(
                    "oracle missing: {what}; {install}. CI=true or OCTMESH_REQUIRE_ORACLES=1 \
                     makes a missing oracle fail the test"
                );
            }
            SKIPS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            // Past libtest's capture of `println!`, so that a skip shows in
            // a plain `cargo test` run too.
            let line = format!("skipped: {what} missing ({install})\n");
            let _ = std::io::Write::write_all(&mut std::io::stdout(), line.as_bytes());
            None
        }
    }
}

/// The shared folder: `$OCTMESH_SHARED_DIR`, else `../shared` beside the
/// repository.
pub fn shared_dir() -> PathBuf {
    match std::env::var_os("OCTMESH_SHARED_DIR") {
        Some(d) => PathBuf::from(d),
        None => repo().join("..").join("shared"),
    }
}

/// A model of the shared folder's `data/` ([`require`]).
pub fn shared_model(name: &str) -> Option<PathBuf> {
    require(Oracle::Shared(&format!("data/{name}")))
}

/// Each rank's line of a failed command's error report
/// (`octmesh: error [rank r of np]: ...`), in rank order. Asserts that the
/// command failed, that no panic text appeared, and that every rank
/// printed its line; `what` names the command in the messages.
pub fn rank_error_lines(out: &Output, np: usize, what: &str) -> Vec<String> {
    let err = String::from_utf8_lossy(&out.stderr);
    let all = format!("{}{err}", String::from_utf8_lossy(&out.stdout));
    assert!(
        !out.status.success(),
        "{what} on {np} ranks should fail:\n{all}"
    );
    assert!(!all.contains("panicked"), "{what}: panic text:\n{all}");
    (0..np)
        .map(|r| {
            let head = format!("octmesh: error [rank {r} of {np}]:");
            err.lines()
                .find(|l| l.contains(&head))
                .unwrap_or_else(|| panic!("{what}: rank {r} printed no error:\n{all}"))
                .to_string()
        })
        .collect()
}

/// Runs `prog args` under `mpirun -np np`, killing it after `limit`.
/// Returns the output, or panics on a hang.
pub fn mpirun(np: usize, prog: &Path, args: &[&str], limit: Duration) -> Output {
    mpirun_env(np, prog, args, &[], limit)
}

/// [`mpirun`] with extra environment variables for the launched processes.
pub fn mpirun_env(
    np: usize,
    prog: &Path,
    args: &[&str],
    env: &[(&str, &str)],
    limit: Duration,
) -> Output {
    let mut cmd = Command::new("mpirun");
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env("OMPI_MCA_rmaps_base_oversubscribe", "1")
        .arg("--oversubscribe")
        .arg("-np")
        .arg(np.to_string())
        .arg(prog)
        .args(args);
    run_with_limit(cmd, limit)
}

/// Runs a command with a time limit; panics if it does not finish.
pub fn run_with_limit(mut cmd: Command, limit: Duration) -> Output {
    let desc = format!("{cmd:?}");
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| {
            let hint = if e.kind() == std::io::ErrorKind::NotFound {
                " (not installed? scripts/setup.sh installs the test dependencies)"
            } else {
                ""
            };
            panic!("cannot start {desc}: {e}{hint}")
        });
    // Drain the pipes in threads so a chatty child cannot block on them.
    let mut so = child.stdout.take().expect("stdout");
    let mut se = child.stderr.take().expect("stderr");
    let t1 = std::thread::spawn(move || {
        let mut b = Vec::new();
        std::io::Read::read_to_end(&mut so, &mut b).ok();
        b
    });
    let t2 = std::thread::spawn(move || {
        let mut b = Vec::new();
        std::io::Read::read_to_end(&mut se, &mut b).ok();
        b
    });
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break s;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{desc} did not finish within {limit:?} (hang?)");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Output {
        status,
        stdout: t1.join().unwrap_or_default(),
        stderr: t2.join().unwrap_or_default(),
    }
}

/// Runs the octmesh command and asserts success.
pub fn octmesh_ok(np: usize, args: &[&str]) -> Output {
    let out = mpirun(np, &octmesh_bin(), args, Duration::from_secs(600));
    assert!(
        out.status.success(),
        "octmesh {args:?} on {np} ranks failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Reads a leaf file written by octmesh or by the p4est reference program.
pub fn leaves(path: &Path) -> Vec<Octant> {
    octmesh::internals::io::leaves::read_leaves(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Completeness and linearity, checked by volume and order only: sorted,
/// pairwise disjoint, and the volumes add up to the root cube.
pub fn assert_complete_linear(l: &[Octant]) {
    let mut vol: u128 = 0;
    for w in l.windows(2) {
        assert!(w[0] < w[1], "not sorted: {:?} {:?}", w[0], w[1]);
        assert!(!w[0].overlaps(w[1]), "overlap: {:?} {:?}", w[0], w[1]);
    }
    for o in l {
        vol += (o.side() as u128).pow(3);
    }
    assert_eq!(
        vol,
        (octmesh::internals::octree::octant::ROOT_LEN as u128).pow(3),
        "volumes do not fill the root"
    );
}

/// Brute-force 2:1 check written without the balance code: every pair of
/// leaves whose closed boxes touch with a contact of the counted dimension
/// differs by at most one level. Pairs are found through a uniform grid of
/// buckets; within a bucket every pair is compared directly.
pub fn assert_balanced(l: &[Octant], conn: octmesh::Connectivity) {
    const G: i64 = 16; // buckets per side
    let root = octmesh::internals::octree::octant::ROOT_LEN as i64;
    let cell = root / G;
    let mut buckets: Vec<Vec<usize>> = vec![Vec::new(); (G * G * G) as usize];
    for (i, o) in l.iter().enumerate() {
        let c = o.coords();
        let len = o.side() as i64;
        // Closed box: include the buckets the upper faces touch.
        let lo: Vec<i64> = (0..3).map(|k| (c[k] as i64 / cell).max(0)).collect();
        let hi: Vec<i64> = (0..3)
            .map(|k| ((c[k] as i64 + len) / cell).min(G - 1))
            .collect();
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    buckets[(x + G * (y + G * z)) as usize].push(i);
                }
            }
        }
    }
    for b in &buckets {
        for (ii, &i) in b.iter().enumerate() {
            for &j in &b[ii + 1..] {
                let (a, c) = (l[i], l[j]);
                let (pa, la) = (a.coords(), a.side() as i64);
                let (pc, lc) = (c.coords(), c.side() as i64);
                let mut touching = true;
                let mut dim = 0;
                for k in 0..3 {
                    let (a0, a1) = (pa[k] as i64, pa[k] as i64 + la);
                    let (c0, c1) = (pc[k] as i64, pc[k] as i64 + lc);
                    if a1 < c0 || c1 < a0 {
                        touching = false;
                    } else if a1 > c0 && c1 > a0 {
                        dim += 1;
                    }
                }
                let counted = match conn {
                    octmesh::Connectivity::Face => dim == 2,
                    octmesh::Connectivity::Edge => dim == 1 || dim == 2,
                    octmesh::Connectivity::Corner => dim <= 2,
                };
                if touching && counted {
                    assert!(
                        a.level().abs_diff(c.level()) <= 1,
                        "{conn:?} balance violated between {a:?} and {c:?}"
                    );
                }
            }
        }
    }
}

/// The p4est reference program, built on first use.
pub fn p4est_ref() -> PathBuf {
    let dir = repo().join("tools").join("p4est_ref");
    let st = Command::new("make")
        .arg("-s")
        .arg("-C")
        .arg(&dir)
        .status()
        .expect("run make for tools/p4est_ref");
    assert!(
        st.success(),
        "building tools/p4est_ref failed: it needs Debian's libp4est-dev and Open MPI's mpicc \
         (scripts/setup.sh installs them)"
    );
    dir.join("octmesh_p4est")
}

/// Runs the p4est reference program on `np` ranks and asserts success.
pub fn p4est_ref_ok(np: usize, args: &[&str], tag: &str) {
    let out = mpirun(np, &p4est_ref(), args, Duration::from_secs(600));
    assert!(
        out.status.success(),
        "p4est reference failed on {tag}:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Writes a binary STL (normals zero) for tests.
pub fn write_stl(path: &Path, tris: &[[[f32; 3]; 3]], header: &[u8]) {
    let mut b = Vec::new();
    let mut h = [b' '; 80];
    h[..header.len()].copy_from_slice(header);
    b.extend_from_slice(&h);
    b.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in tris {
        b.extend_from_slice(&[0u8; 12]);
        for v in t {
            for c in v {
                b.extend_from_slice(&c.to_le_bytes());
            }
        }
        b.extend_from_slice(&[0u8; 2]);
    }
    std::fs::write(path, b).expect("write stl");
}

/// A Python that can `import module` ([`Oracle::Python`]) for the
/// independent readers; panics, never skips, when there is none: the tests
/// that read files back have no other check to fall back on.
pub fn python_with(module: &str, package: &str) -> String {
    let oracle = Oracle::Python { module, package };
    match oracle.find() {
        Ok(p) => p.to_string_lossy().into_owned(),
        Err(what) => panic!("oracle missing: {what}; {}", oracle.install()),
    }
}

/// A Python that can import meshio.
pub fn python_with_meshio() -> String {
    python_with("meshio", "python3-meshio")
}

/// Parses a JSON file.
pub fn json_file(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("bad JSON in {}: {e}", path.display()))
}

/// `target/<profile>/deps`, where `cargo test` puts the `liboctmesh.so`
/// built with this test (`cargo build` also copies it one level up).
pub fn deps_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    exe.parent().expect("target/<profile>/deps").to_path_buf()
}

/// Copies `liboctmesh.so` from `from` into `dir` under its SONAME too.
pub fn stage_library(from: &Path, dir: &Path) {
    let so = from.join("liboctmesh.so");
    assert!(
        so.is_file(),
        "{} not found: the cdylib is built with the library (crate-type in Cargo.toml)",
        so.display()
    );
    std::fs::create_dir_all(dir).unwrap();
    for name in ["liboctmesh.so", "liboctmesh.so.0"] {
        std::fs::copy(&so, dir.join(name)).expect("copy liboctmesh.so");
    }
}

/// Compiles `tests/c/<name>.c` with mpicc against `include/octmesh.h` and
/// the library in `lib`.
pub fn compile_c_test(name: &str, lib: &Path, out_dir: &Path) -> PathBuf {
    let root = repo();
    let exe = out_dir.join(name);
    let mut cmd = Command::new("mpicc");
    cmd.arg("-std=c11")
        .arg("-Wall")
        .arg("-Wextra")
        .arg("-Werror")
        .arg("-I")
        .arg(root.join("include"))
        .arg("-I")
        .arg(root.join("tests/c"))
        // The adaptation oracle's sphere (check.h includes sphere_cut.h).
        .arg("-I")
        .arg(root.join("tools/p4est_ref"))
        .arg(root.join("tests/c").join(format!("{name}.c")))
        .arg("-o")
        .arg(&exe)
        .arg("-L")
        .arg(lib)
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-loctmesh")
        .arg("-lm");
    let out = run_with_limit(cmd, Duration::from_secs(120));
    assert!(
        out.status.success(),
        "mpicc {name}.c failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    exe
}

/// Integer field `k` of a stats object.
pub fn int(v: &serde_json::Value, k: &str) -> u64 {
    v[k].as_u64()
        .unwrap_or_else(|| panic!("no integer '{k}' in {v}"))
}

/// Number field `k` of a stats object.
pub fn num(v: &serde_json::Value, k: &str) -> f64 {
    v[k].as_f64()
        .unwrap_or_else(|| panic!("no number '{k}' in {v}"))
}

/// Gathers every rank's `v` on rank 0 (one vector per rank there, empty
/// vectors elsewhere).
pub fn gather(comm: &octmesh::internals::parallel::comm::CommRef, v: Vec<u64>) -> Vec<Vec<u64>> {
    let p = comm.size();
    let mut counts = vec![0; p];
    counts[0] = v.len();
    let (all, c) = comm.alltoallv_u64(&v, &counts);
    let mut out = Vec::new();
    let mut at = 0;
    for n in c {
        out.push(all[at..at + n].to_vec());
        at += n;
    }
    out
}

/// Writes the built-in sphere as ASCII STL, one `solid` block per entry of
/// `parts`: its name and the triangles it holds, by the centroid's z
/// (`Some(true)`: above 0, `Some(false)`: at or below, `None`: all).
pub fn write_sphere_solids(path: &Path, parts: &[(&str, Option<bool>)]) {
    let s = octmesh::internals::geometry::shapes::default_sphere();
    let mut text = String::new();
    for (name, upper) in parts {
        text.push_str(&format!("solid {name}\n"));
        for t in s.triangles() {
            if upper.is_some_and(|u| u != (t.centroid()[2] > 0.0)) {
                continue;
            }
            text.push_str("facet normal 0 0 0\n outer loop\n");
            for v in &t.v {
                text.push_str(&format!("  vertex {:e} {:e} {:e}\n", v[0], v[1], v[2]));
            }
            text.push_str(" endloop\nendfacet\n");
        }
        text.push_str(&format!("endsolid {name}\n"));
    }
    std::fs::write(path, text).unwrap();
}

/// OpenFOAM's installation folder: `$OCTMESH_OPENFOAM_DIR`, else Debian's
/// `/usr/share/openfoam`.
pub fn openfoam_dir() -> PathBuf {
    match std::env::var_os("OCTMESH_OPENFOAM_DIR") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from("/usr/share/openfoam"),
    }
}

/// OpenFOAM's environment file, checked once per process: `etc/bashrc` in
/// [`openfoam_dir`], after which `checkMesh` runs.
fn openfoam_rc() -> &'static Result<PathBuf, String> {
    static RC: std::sync::OnceLock<Result<PathBuf, String>> = std::sync::OnceLock::new();
    RC.get_or_init(|| {
        let rc = openfoam_dir().join("etc").join("bashrc");
        if !rc.is_file() {
            return Err(format!("OpenFOAM ({} is not there)", rc.display()));
        }
        let script = format!(
            "set +u; source '{}' >/dev/null 2>&1; command -v checkMesh",
            rc.display()
        );
        let found = Command::new("bash")
            .arg("-c")
            .arg(script)
            .output()
            .is_ok_and(|o| o.status.success());
        if found {
            Ok(rc)
        } else {
            Err(format!(
                "OpenFOAM's checkMesh (not found after sourcing {})",
                rc.display()
            ))
        }
    })
}

/// The OpenFOAM environment file ([`require`]).
pub fn openfoam() -> Option<PathBuf> {
    require(Oracle::OpenFoam)
}

/// Runs an OpenFOAM command line in `case` with its environment.
pub fn foam(rc: &Path, case: &Path, line: &str) -> String {
    let script = format!(
        "set +u; source {} >/dev/null 2>&1; cd '{}' && {line}",
        rc.display(),
        case.display()
    );
    let mut cmd = Command::new("bash");
    cmd.arg("-c")
        .arg(script)
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1");
    let out = run_with_limit(cmd, Duration::from_secs(600));
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.status.success(),
        "{line} failed in {}:\n{text}",
        case.display()
    );
    text
}

/// The moving sphere of the adaptation tests and `tools/p4est_ref`'s
/// adapt oracle, in lattice units: radius 131072 (a quarter of the root),
/// centre `(x, 262144, 262144)`, `x` starting at 157286.
pub const SPHERE_START_X: i64 = 157_286;

/// Whether the closed box of `o` meets the surface of the moving sphere
/// centred at `(x, 262144, 262144)` (exact integer distances).
pub fn sphere_cuts(o: octmesh::Octant, x: i64) -> bool {
    const HALF: i64 = 262_144;
    const RADIUS: i64 = 131_072;
    let centre = [x, HALF, HALF];
    let c = o.coords();
    let len = o.side() as i64;
    let (mut near, mut far) = (0i64, 0i64);
    for k in 0..3 {
        let (lo, hi) = (c[k] as i64, c[k] as i64 + len);
        let a = (lo - centre[k]).max(centre[k] - hi).max(0);
        let b = (centre[k] - lo).max(hi - centre[k]);
        near += a * a;
        far += b * b;
    }
    near <= RADIUS * RADIUS && RADIUS * RADIUS <= far
}

/// Requires octmesh's leaves `ours` to equal p4est's `theirs` one for one
/// (any leaf representation), naming the first difference.
pub fn assert_same_leaves<T: PartialEq + std::fmt::Debug>(ours: &[T], theirs: &[T], tag: &str) {
    assert_eq!(
        ours.len(),
        theirs.len(),
        "{tag}: octmesh {} leaves, p4est {}",
        ours.len(),
        theirs.len()
    );
    if let Some(i) = (0..ours.len()).find(|&i| ours[i] != theirs[i]) {
        panic!(
            "{tag}: first difference at leaf {i}: octmesh {:?}, p4est {:?}",
            ours[i], theirs[i]
        );
    }
}
