//! Mesh quality through the command (`--stats`, `--quality-out`):
//!
//! - OpenFOAM v1912's `checkMesh -allGeometry` as the judge: on the cases
//!   octmesh writes (sphere level 6 and the bunny level 7, fluid; sphere
//!   level 5, the whole cube; sphere level 4 in a box of 2 x 1 x 1 root
//!   cells, fluid) on 1 and 2 ranks (`-parallel` on the processor directories), octmesh's largest
//!   and average non-orthogonality and largest skewness equal what
//!   checkMesh prints, to the digits it prints.
//! - The scaled-Jacobian histogram in the statistics sums to the element
//!   count, and every figure is the same on 1 and 3 ranks, snapped
//!   (`--snap`: the figures of the moved points) or not.
//! - The worst elements' VTU, read by meshio: the requested count, worst
//!   first, the same elements on 1 and 3 ranks.
//! - Quality is measured only when asked; bad option values are refused.

mod common;

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use common::{foam, json_file, octmesh_bin, octmesh_ok, openfoam, scratch, shared_model};

/// Significant digits of a printed number (`25.239402` has 8).
fn significant_digits(s: &str) -> usize {
    let mantissa = s.split(['e', 'E']).next().unwrap_or(s);
    let digits: String = mantissa.chars().filter(|c| c.is_ascii_digit()).collect();
    digits.trim_start_matches('0').len().max(1)
}

/// Whether `value` prints as `printed` with `digits` significant digits:
/// within half a unit of the printed number's last place at that
/// precision (OpenFOAM drops trailing zeros, so `1` may stand for
/// `1.0000000`).
fn matches_printed(value: f64, printed: &str, digits: usize) -> bool {
    let p: f64 = printed.parse().unwrap();
    let magnitude = if p == 0.0 {
        0
    } else {
        p.abs().log10().floor() as i32
    };
    let half_ulp = 0.5 * 10f64.powi(magnitude - digits as i32 + 1);
    (value - p).abs() <= half_ulp * (1.0 + 1e-9) + 1e-12
}

/// Runs octmesh on `np` ranks with `--stats --quality` and returns the
/// statistics.
fn octmesh_stats(np: usize, args: &[&str], stats: &Path) -> serde_json::Value {
    let mut all = args.to_vec();
    all.extend(["--stats", stats.to_str().unwrap(), "--quiet", "--quality"]);
    octmesh_ok(np, &all);
    json_file(stats)
}

fn compare_with_checkmesh(
    rc: &Path,
    (surface, level, keep, extra): (&str, &str, &str, &[&str]),
    np: usize,
    dir: &Path,
) {
    let stem = Path::new(surface).file_stem().unwrap().to_string_lossy();
    let name = if extra.is_empty() {
        stem.into_owned()
    } else {
        format!("{stem}_box")
    };
    let tag = format!("{name} level {level} keep {keep} np {np}");
    let case = dir.join(format!("{name}_{level}_{keep}_{np}"));
    let stats = dir.join(format!("{name}_{level}_{keep}_{np}.json"));
    let mut args = vec![
        "mesh",
        surface,
        "--level",
        level,
        "--keep",
        keep,
        "--openfoam",
        case.to_str().unwrap(),
    ];
    args.extend(extra);
    let s = octmesh_stats(np, &args, &stats);
    let q = &s["quality"];
    let run = if np > 1 {
        format!("mpirun --oversubscribe -np {np} checkMesh -parallel -allGeometry")
    } else {
        "checkMesh -allGeometry".to_string()
    };
    let text = foam(rc, &case, &run);
    let max = common::word_after(&text, "Mesh non-orthogonality Max:");
    let average = common::word_after(&text, "average:");
    let skew = common::word_after(&text, "Max skewness =");
    let digits = [max, average, skew]
        .iter()
        .map(|s| significant_digits(s))
        .max()
        .unwrap()
        .max(6);
    for (what, key, printed) in [
        ("non-orthogonality max", "non_orthogonality_max", max),
        (
            "non-orthogonality average",
            "non_orthogonality_average",
            average,
        ),
        ("skewness max", "skewness_max", skew),
    ] {
        let mine = q[key].as_f64().unwrap_or_else(|| panic!("{tag}: no {key}"));
        assert!(
            matches_printed(mine, printed, digits),
            "{tag}: {what}: octmesh {mine} but checkMesh printed {printed}"
        );
    }
    println!(
        "{tag}: checkMesh non-orthogonality Max {max} average {average}, Max skewness {skew} \
         = octmesh's {} {} {} ({digits} digits)",
        q["non_orthogonality_max"], q["non_orthogonality_average"], q["skewness_max"]
    );
}

#[test]
fn face_figures_equal_checkmesh() {
    let Some(rc) = openfoam() else { return };
    let dir = scratch("quality_checkmesh");
    // Fluid meshes, whose surface patch has faces partly covered by finer
    // elements (skewness 1 there), and a whole cube, whose largest
    // skewness is that of the 2:1 faces inside.
    // A box of 2 x 1 x 1 root cells around the sphere, too.
    let box_args: &[&str] = &["--box", "-1.5,-1.5,-1.5,4.5,1.5,1.5", "--roots", "2,1,1"];
    let mut cases = vec![
        ("sphere".to_string(), "6", "outside", &[][..]),
        ("sphere".to_string(), "5", "all", &[][..]),
        ("sphere".to_string(), "4", "outside", box_args),
    ];
    if let Some(p) = shared_model("bunny.stl") {
        cases.push((p.to_string_lossy().into_owned(), "7", "outside", &[][..]));
    }
    for (surface, level, keep, extra) in &cases {
        for np in [1, 2] {
            compare_with_checkmesh(&rc, (surface, level, keep, extra), np, &dir);
        }
    }
}

#[test]
fn histogram_and_figures_are_the_same_on_1_and_3_ranks() {
    let dir = scratch("quality_ranks");
    let args = ["mesh", "sphere", "--level", "6", "--keep", "outside"];
    let mut seen = Vec::new();
    for np in [1, 3] {
        let s = octmesh_stats(np, &args, &dir.join(format!("np{np}.json")));
        let q = s["quality"].clone();
        let counts: Vec<u64> = q["scaled_jacobian_histogram"]["counts"]
            .as_array()
            .expect("histogram counts")
            .iter()
            .map(|c| c.as_u64().unwrap())
            .collect();
        let edges = q["scaled_jacobian_histogram"]["edges"].as_array().unwrap();
        assert_eq!(counts.len(), 20);
        assert_eq!(edges.len(), 21);
        assert_eq!(edges[0].as_f64(), Some(-1.0));
        assert_eq!(edges[20].as_f64(), Some(1.0));
        let elements = s["elements"].as_u64().unwrap();
        assert_eq!(counts.iter().sum::<u64>(), elements, "np {np}");
        assert_eq!(q["elements"].as_u64(), Some(elements));
        // An octree mesh: every element a cube.
        assert_eq!(counts[19], elements);
        assert!(s["timings"]["quality"].as_f64().is_some(), "np {np}");
        seen.push(q);
    }
    assert_eq!(
        seen[0], seen[1],
        "the quality differs between 1 and 3 ranks"
    );
}

#[test]
fn snapped_figures_are_the_same_on_1_and_3_ranks() {
    // On a snapped mesh the face figures come from the moved points, the
    // cell centres from each cell's faces and the halo's centres from
    // their ranks: still the same bits on any number of ranks, and no
    // longer the octree's (whose largest skewness is 1 here).
    let dir = scratch("quality_snapped_ranks");
    let args = [
        "mesh", "sphere", "--level", "5", "--keep", "outside", "--snap",
    ];
    let one = octmesh_stats(1, &args, &dir.join("np1.json"))["quality"].clone();
    let three = octmesh_stats(3, &args, &dir.join("np3.json"))["quality"].clone();
    assert_eq!(
        one, three,
        "the snapped quality differs between 1 and 3 ranks"
    );
    let skew = one["skewness_max"].as_f64().unwrap();
    assert!(
        skew > 1.0 + 1e-9,
        "skewness {skew}: the octree's, not the moved points'"
    );
}

/// The worst elements' file: (element numbers, their scaled Jacobians),
/// read by meshio.
fn read_worst(path: &Path) -> (Vec<u64>, Vec<f64>) {
    let py = common::python_with_meshio();
    let script = [
        "import meshio, sys",
        "m = meshio.read(sys.argv[1])",
        "d = {k: v.ravel() for k, v in m.point_data.items()}",
        "e, j, c = d['element'], d['scaled_jacobian'], d['corner_scaled_jacobian']",
        "hexes = m.cells_dict['hexahedron']",
        "assert len(m.points) == 8 * len(hexes)",
        "for h in hexes:",
        "    assert min(c[h]) == j[h[0]] and len(set(e[h].tolist())) == 1",
        "    print(int(e[h[0]]), repr(float(j[h[0]])))",
    ]
    .join("\n");
    let out = Command::new(py)
        .args(["-c", &script, path.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "meshio on {}: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| {
            let (e, j) = l.split_once(' ').unwrap();
            (e.parse::<u64>().unwrap(), j.parse::<f64>().unwrap())
        })
        .unzip()
}

#[test]
fn worst_elements_file_is_rank_independent() {
    let dir = scratch("quality_worst");
    let mut seen = Vec::new();
    for np in [1, 3] {
        let vtu = dir.join(format!("worst{np}.vtu"));
        let out = octmesh_ok(
            np,
            &[
                "mesh",
                "sphere",
                "--level",
                "5",
                "--keep",
                "outside",
                "--quality-out",
                vtu.to_str().unwrap(),
                "--quality-worst",
                "7",
            ],
        );
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains("quality: scaled Jacobian min"), "{text}");
        assert!(
            text.contains("scaled Jacobian histogram: [0.9, 1.0]"),
            "{text}"
        );
        let (elements, values) = read_worst(&vtu);
        assert_eq!(elements.len(), 7);
        assert!(values.windows(2).all(|w| w[0] <= w[1]), "{values:?}");
        assert!(values.iter().all(|&j| (j - 1.0).abs() < 1e-12));
        seen.push(elements);
    }
    assert_eq!(seen[0], seen[1]);
}

#[test]
fn quality_only_when_asked_and_bad_values_refused() {
    let dir = scratch("quality_options");
    let out = octmesh_ok(1, &["mesh", "sphere", "--level", "4", "--keep", "outside"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(!text.contains("quality"), "{text}");
    let vtu = dir.join("w.vtu");
    let vtu = vtu.to_str().unwrap();
    for (args, wanted) in [
        (
            vec!["--quality-out", "w.pvtu"],
            "--quality-out expects a file name ending in .vtu",
        ),
        (
            vec!["--quality-out", vtu, "--quality-worst", "0"],
            "--quality-worst must be at least 1",
        ),
        (
            vec!["--quality-worst", "5"],
            "--quality-worst needs --quality-out",
        ),
    ] {
        let mut all = vec!["mesh", "sphere", "--level", "3"];
        all.extend(&args);
        let out = common::mpirun(1, &octmesh_bin(), &all, Duration::from_secs(60));
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} accepted");
        assert!(err.contains(wanted), "{args:?}: {err}");
    }
    // A case file takes the same keys.
    let case = dir.join("case.toml");
    std::fs::write(
        &case,
        format!(
            "[surface]\nfile = \"sphere\"\n[octree]\nlevel = 4\n[mesh]\nkeep = \"outside\"\n\
             [output]\nquality_out = \"{vtu}\"\nquality_worst = 3\n"
        ),
    )
    .unwrap();
    octmesh_ok(1, &["mesh", case.to_str().unwrap(), "--quiet"]);
    let (elements, _) = read_worst(Path::new(vtu));
    assert_eq!(elements.len(), 3);
}
