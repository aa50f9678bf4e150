//! Finite-element oracles: outside codes that solve on the files octmesh
//! writes, and the errors they report. Each takes a file path, so any mesh
//! written with `--abaqus` or `--gmsh` (with or without hanging nodes,
//! `--conforming` ones included) goes through the same judges.
//!
//! - CalculiX (`ccx`, Debian `calculix-ccx`) on an `.inp` deck: the
//!   displacement patch test ([`calculix_patch_test`]), with the deck's
//!   `*EQUATION`s or without them ([`Equations`]).
//! - dolfinx (Debian `python3-dolfinx`, reading through `python3-gmsh`) on
//!   an `.msh` file: `tools/fe_oracle/poisson_dolfinx.py` solves a Poisson
//!   problem in the trilinear space for a linear (patch test) and a smooth
//!   manufactured solution ([`poisson_dolfinx`]). dolfinx has no
//!   hanging-node constraints: it solves the mesh as the file gives it.
//!
//! [`assert_patch_test_exact`] and [`assert_patch_test_fails`] pick the
//! judge by the file's extension; [`assert_second_order`] checks the smooth
//! solution's convergence over meshes of successive levels. Each returns
//! `None` after a skip when its program is missing ([`require`]).

use std::collections::{BTreeSet, HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use super::{number_after, repo, require, run_with_limit, word_after, Oracle};

/// The patch test's bound for "exact": relative to the field's largest
/// value, past the rounding of CalculiX's printed digits (dolfinx's values
/// are read at full precision).
pub const EXACT: f64 = 1e-8;

/// The smallest error of a patch test that counts as failed: far above
/// any rounding, far below what loose hanging corners give.
pub const FAILED: f64 = 1e-3;

/// `ccx`, or `None` after a skip.
pub fn ccx() -> Option<PathBuf> {
    require(Oracle::Program {
        name: "ccx",
        package: "calculix-ccx",
    })
}

/// A Python with dolfinx and Gmsh's API, or `None` after a skip.
pub fn dolfinx_python() -> Option<PathBuf> {
    require(Oracle::Python {
        module: "dolfinx, gmsh",
        package: "python3-dolfinx and python3-gmsh",
    })
}

/// What the CalculiX tests read from a deck.
pub struct Deck {
    pub coords: HashMap<u64, [f64; 3]>,
    /// Nodes of the patch node sets (NALL left out).
    pub boundary: BTreeSet<u64>,
    /// The nodes the equations eliminate.
    pub hanging: HashSet<u64>,
    /// Every node of an equation.
    pub in_equations: HashSet<u64>,
    /// Each element's 8 nodes.
    pub elements: Vec<[u64; 8]>,
    /// Faces listed in the `*SURFACE`s.
    pub surfaces: usize,
}

/// Reads the nodes, elements, node sets, surfaces and equations of `text`.
pub fn read_deck(text: &str) -> Deck {
    let mut d = Deck {
        coords: HashMap::new(),
        boundary: BTreeSet::new(),
        hanging: HashSet::new(),
        in_equations: HashSet::new(),
        elements: Vec::new(),
        surfaces: 0,
    };
    enum Mode {
        Node,
        Element,
        Set,
        Surface,
        EquationCount,
        /// Terms left, whether the next line is the equation's first.
        Equation(usize, bool),
        Other,
    }
    let mut mode = Mode::Other;
    for line in text.lines() {
        if line.starts_with("**") || line.trim().is_empty() {
            continue;
        }
        if line.starts_with('*') {
            let u = line.to_uppercase();
            mode = if u.starts_with("*NODE PRINT") {
                Mode::Other
            } else if u.starts_with("*NODE") {
                Mode::Node
            } else if u.starts_with("*ELEMENT") {
                Mode::Element
            } else if u.starts_with("*NSET") && !u.contains("GENERATE") {
                Mode::Set
            } else if u.starts_with("*SURFACE") {
                Mode::Surface
            } else if u.starts_with("*EQUATION") {
                Mode::EquationCount
            } else {
                Mode::Other
            };
            continue;
        }
        let f: Vec<&str> = line
            .split(',')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .collect();
        match mode {
            Mode::Node => {
                let p = [1, 2, 3].map(|k| f[k].parse::<f64>().unwrap());
                d.coords.insert(f[0].parse().unwrap(), p);
            }
            Mode::Element => {
                let n: Vec<u64> = f[1..].iter().map(|s| s.parse().unwrap()).collect();
                d.elements.push(n.try_into().unwrap());
            }
            Mode::Set => d
                .boundary
                .extend(f.iter().map(|s| s.parse::<u64>().unwrap())),
            Mode::Surface => d.surfaces += 1,
            Mode::EquationCount => mode = Mode::Equation(f[0].parse().unwrap(), true),
            Mode::Equation(left, first) => {
                // The first term of an equation is the node it eliminates.
                if first {
                    d.hanging.insert(f[0].parse().unwrap());
                }
                for t in f.chunks(3) {
                    d.in_equations.insert(t[0].parse().unwrap());
                }
                let left = left - f.len() / 3;
                mode = match left {
                    0 => Mode::EquationCount,
                    l => Mode::Equation(l, false),
                };
            }
            _ => {}
        }
    }
    d
}

/// The linear field of the patch test: short decimals on the lattices of
/// the tests' boxes, so that most printed values are exact.
const A: [[f64; 3]; 3] = [[1e-3, 2e-3, -1e-3], [5e-4, -1e-3, 3e-3], [2e-3, 1e-3, 1e-3]];
const B: [f64; 3] = [1e-3, -2e-3, 3e-3];

/// The patch test's displacement at `p`.
pub fn field(p: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| A[i][0] * p[0] + A[i][1] * p[1] + A[i][2] * p[2] + B[i])
}

/// Runs CalculiX `ccx` on the input `job` in `dir` (one thread); its
/// printed results (`job.dat`). Fails unless ccx succeeds without an error.
pub fn run_ccx(ccx: &Path, dir: &Path, job: &str) -> String {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("job.inp"), job).unwrap();
    let mut cmd = Command::new(ccx);
    cmd.args(["-i", "job"])
        .current_dir(dir)
        .env("OMP_NUM_THREADS", "1");
    let out = run_with_limit(cmd, Duration::from_secs(600));
    let log = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && !log.contains("*ERROR"),
        "ccx failed in {}:\n{}",
        dir.display(),
        &log[log.len().saturating_sub(3000)..]
    );
    std::fs::read_to_string(dir.join("job.dat")).unwrap()
}

/// Half a unit in the last printed digit of `s` (CalculiX prints
/// `%13.6E`: 7 significant digits).
fn half_unit(s: &str) -> f64 {
    let exp: i32 = s
        .rsplit(['E', 'e'])
        .next()
        .and_then(|e| e.parse().ok())
        .unwrap_or_else(|| panic!("'{s}' is not in E notation"));
    let digits = s
        .split(['E', 'e'])
        .next()
        .and_then(|m| m.split('.').nth(1))
        .map_or(0, str::len) as i32;
    0.5 * 10f64.powi(exp - digits)
}

/// Runs the patch test in `dir` on the deck `text` with CalculiX `ccx`:
/// the linear field [`field`] prescribed on every node of the patch node
/// sets, the largest error of an interior independent node relative to
/// the field's largest value (past half a unit in the printed 7th digit),
/// and how many interior independent nodes there were.
pub fn patch_test(ccx: &Path, dir: &Path, text: &str) -> (f64, usize) {
    let deck = read_deck(text);
    let mut job = String::from(text);
    job.push_str(
        "*MATERIAL, NAME=STEEL\n*ELASTIC\n210000., 0.3\n\
         *SOLID SECTION, ELSET=EALL, MATERIAL=STEEL\n*STEP\n*STATIC\n*BOUNDARY\n",
    );
    for n in &deck.boundary {
        let u = field(deck.coords[n]);
        for (i, v) in u.iter().enumerate() {
            job.push_str(&format!("{n}, {}, {}, {v:.12e}\n", i + 1, i + 1));
        }
    }
    job.push_str("*NODE PRINT, NSET=NALL\nU\n*END STEP\n");
    let dat = run_ccx(ccx, dir, &job);
    let scale = deck
        .coords
        .values()
        .flat_map(|&p| field(p))
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let mut printed = HashMap::new();
    for line in dat.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() != 4 {
            continue;
        }
        let Ok(n) = f[0].parse::<u64>() else {
            continue;
        };
        let u: Result<Vec<(f64, f64)>, _> = f[1..]
            .iter()
            .map(|s| s.parse::<f64>().map(|v| (v, half_unit(s))))
            .collect();
        if let Ok(u) = u {
            printed.insert(n, u);
        }
    }
    assert_eq!(printed.len(), deck.coords.len(), "a displacement per node");
    let (mut worst, mut interior) = (0.0f64, 0);
    for (n, p) in &deck.coords {
        if deck.boundary.contains(n) || deck.hanging.contains(n) {
            continue;
        }
        interior += 1;
        let exact = field(*p);
        for i in 0..3 {
            let (v, half) = printed[n][i];
            worst = worst.max(((v - exact[i]).abs() - half).max(0.0) / scale);
        }
    }
    (worst, interior)
}

/// The deck without its equations (they are its last keyword block).
pub fn without_equations(text: &str) -> String {
    match text.find("\n*EQUATION") {
        Some(k) => text[..=k].to_string(),
        None => text.to_string(),
    }
}

/// Whether CalculiX solves a deck with the `*EQUATION`s it has or with
/// them stripped (as a code without hanging-node support reads it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Equations {
    Keep,
    Strip,
}

/// A CalculiX patch test's outcome.
#[derive(Clone, Copy, Debug)]
pub struct PatchTest {
    /// The largest interior error relative to the field's largest value.
    pub error: f64,
    /// Interior nodes judged (neither on a patch set nor eliminated by an
    /// equation that was kept).
    pub interior: usize,
    /// The hanging nodes the deck's equations eliminate (0 for a
    /// conforming deck).
    pub equations: usize,
}

/// CalculiX's patch test on the deck `inp`, in a folder beside it.
pub fn calculix_patch_test(inp: &Path, equations: Equations) -> Option<PatchTest> {
    let ccx = ccx()?;
    let text = std::fs::read_to_string(inp)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", inp.display()));
    let hanging = read_deck(&text).hanging.len();
    let (job, tag) = match equations {
        Equations::Keep => (text, "ccx_patch"),
        Equations::Strip => (without_equations(&text), "ccx_patch_stripped"),
    };
    let dir = inp.with_extension(tag);
    let (error, interior) = patch_test(&ccx, &dir, &job);
    assert!(interior > 0, "{}: no interior node to judge", inp.display());
    Some(PatchTest {
        error,
        interior,
        equations: hanging,
    })
}

/// One manufactured solution's errors from `poisson_dolfinx.py`.
#[derive(Clone, Copy, Debug)]
pub struct Poisson {
    pub cells: u64,
    pub dofs: u64,
    /// Degrees of freedom on the physical surfaces, prescribed.
    pub fixed: u64,
    /// The largest nodal error relative to the largest nodal value.
    pub max_nodal_error: f64,
    /// The L2 error relative to the exact solution's L2 norm.
    pub l2_error: f64,
}

/// dolfinx's Poisson solutions on the Gmsh file `msh`: (linear, smooth).
/// `frame` (`x0, y0, z0, L`, as `--domain`) places the manufactured
/// solutions; by default the nodes' bounding box.
pub fn poisson_dolfinx(msh: &Path, frame: Option<[f64; 4]>) -> Option<(Poisson, Poisson)> {
    let python = dolfinx_python()?;
    let script = repo().join("tools/fe_oracle/poisson_dolfinx.py");
    let mut cmd = Command::new(python);
    cmd.arg(script).arg(msh);
    if let Some(f) = frame {
        cmd.arg(format!("--frame={},{},{},{}", f[0], f[1], f[2], f[3]));
    }
    let out = run_with_limit(cmd, Duration::from_secs(600));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "poisson_dolfinx.py failed on {}:\n{text}\n{}",
        msh.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let solution = |name: &str| {
        let line = text
            .lines()
            .filter(|l| l.starts_with("poisson_dolfinx:"))
            .find(|l| word_after(l, "field") == name)
            .unwrap_or_else(|| panic!("no field {name} in:\n{text}"));
        Poisson {
            cells: number_after(line, "cells") as u64,
            dofs: number_after(line, "dofs") as u64,
            fixed: number_after(line, "fixed") as u64,
            max_nodal_error: number_after(line, "max_nodal_error"),
            l2_error: number_after(line, "l2_error"),
        }
    };
    Some((solution("linear"), solution("smooth")))
}

/// The patch test's error on `path` by the judge its extension names:
/// dolfinx's largest nodal error for `.msh`, CalculiX's (with the
/// deck's equations, `strip` = false) for `.inp`.
fn patch_error(path: &Path, strip: bool) -> Option<f64> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("msh") => {
            let (linear, _) = poisson_dolfinx(path, None)?;
            assert!(
                linear.dofs > linear.fixed,
                "{}: every degree of freedom is prescribed",
                path.display()
            );
            Some(linear.max_nodal_error)
        }
        Some("inp") => {
            let how = if strip {
                Equations::Strip
            } else {
                Equations::Keep
            };
            Some(calculix_patch_test(path, how)?.error)
        }
        _ => panic!("{}: neither a .msh nor an .inp file", path.display()),
    }
}

/// The patch test passes on `path` (a `.msh` through dolfinx, an `.inp`
/// through CalculiX as written): the linear field exact at every interior
/// node to [`EXACT`]. Returns the error, or `None` after a skip.
pub fn assert_patch_test_exact(path: &Path) -> Option<f64> {
    let error = patch_error(path, false)?;
    assert!(
        error <= EXACT,
        "{}: the patch test is off by {error:e}",
        path.display()
    );
    Some(error)
}

/// The patch test fails on `path` by more than [`FAILED`]: a `.msh`
/// through dolfinx, an `.inp` through CalculiX without its equations. The
/// negative control on a mesh with hanging nodes.
pub fn assert_patch_test_fails(path: &Path) -> Option<f64> {
    let error = patch_error(path, true)?;
    assert!(
        error > FAILED,
        "{}: the patch test should fail, its error is only {error:e}",
        path.display()
    );
    Some(error)
}

/// dolfinx's L2 error of the smooth solution on `meshes` (Gmsh files of
/// successive levels, coarse first, one `frame` for all) falls at least
/// `min_ratio` times per level (4 at second order). Returns the errors.
pub fn assert_second_order(meshes: &[&Path], frame: [f64; 4], min_ratio: f64) -> Option<Vec<f64>> {
    let mut errors = Vec::new();
    for m in meshes {
        errors.push(poisson_dolfinx(m, Some(frame))?.1.l2_error);
    }
    for (k, w) in errors.windows(2).enumerate() {
        assert!(
            w[0] >= min_ratio * w[1],
            "{}: the L2 error falls from {:e} only to {:e}",
            meshes[k + 1].display(),
            w[0],
            w[1]
        );
    }
    Some(errors)
}

/// Gmsh's smallest IGE measure (for hexahedra the scaled Jacobian at the
/// corners) of the `.msh` at `msh`: (hexahedra, minimum).
pub fn gmsh_min_scaled_jacobian(python: &Path, msh: &Path) -> (u64, f64) {
    let script = r#"
import sys, gmsh
gmsh.initialize()
gmsh.option.setNumber("General.Terminal", 0)
gmsh.open(sys.argv[1])
gmsh.plugin.setNumber("AnalyseMeshQuality", "IGEMeasure", 1)
gmsh.plugin.setNumber("AnalyseMeshQuality", "CreateView", 1)
gmsh.plugin.setNumber("AnalyseMeshQuality", "DimensionOfElements", 3)
gmsh.plugin.run("AnalyseMeshQuality")
for v in gmsh.view.getTags():
    name = gmsh.option.getString("View[%d].Name" % gmsh.view.getIndex(v))
    if name.startswith("IGE"):
        _, tags, data, _, _ = gmsh.view.getModelData(v, 0)
        print("ige %d %.17g" % (len(tags), min(d[0] for d in data)))
gmsh.finalize()
"#;
    let out = Command::new(python)
        .args(["-c", script, msh.to_str().unwrap()])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "gmsh failed:\n{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let line = text
        .lines()
        .find(|l| l.starts_with("ige "))
        .unwrap_or_else(|| panic!("no IGE view:\n{text}"));
    let f: Vec<&str> = line.split_whitespace().collect();
    (f[1].parse().unwrap(), f[2].parse().unwrap())
}
