//! The source layout's rules, checked on the files as they are:
//!
//! - no module loose at the root of `src/` but `lib.rs`, `main.rs` and the
//!   error type: every other concept lives in the folder of its stage;
//! - no source file over 1,000 lines, its unit tests not counted;
//! - no import runs back up the layers: a module uses only its own layer
//!   and the ones below (the order is `LAYERS`, bottom first).

use std::fs;
use std::path::{Path, PathBuf};

/// The folders of `src/`, bottom layer first.
const LAYERS: &[&str] = &[
    "error", "parallel", "run", "geometry", "octree", "refine", "classify", "leak", "mesh", "io",
    "config", "pipeline", "ffi",
];

/// Files at the root of `src/` that are not a stage's folder.
const ROOT_FILES: &[&str] = &["lib.rs", "main.rs", "error.rs"];

/// Folders of `src/` that are not layers: helpers of the unit tests only.
const TEST_ONLY: &[&str] = &["testutil"];

const MAX_LINES: usize = 1000;

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The file's text before its unit tests (`#[cfg(test)] mod tests`), or
/// none for a file that holds only tests.
fn without_tests(path: &Path) -> String {
    let text = fs::read_to_string(path).unwrap();
    if path.file_name().unwrap() == "tests.rs" {
        return String::new();
    }
    let lines: Vec<&str> = text.lines().collect();
    let end = (0..lines.len())
        .find(|&i| {
            lines[i].trim() == "#[cfg(test)]"
                && lines
                    .get(i + 1)
                    .is_some_and(|l| l.trim_start().starts_with("mod tests"))
        })
        .unwrap_or(lines.len());
    lines[..end].join("\n")
}

/// The layer of a file: the folder (or root file) of `src/` it is in.
fn layer_of(path: &Path) -> String {
    let rel = path.strip_prefix(src()).unwrap();
    let first = rel
        .components()
        .next()
        .unwrap()
        .as_os_str()
        .to_string_lossy();
    first.trim_end_matches(".rs").to_string()
}

#[test]
fn no_loose_module_at_the_root_of_src() {
    let mut loose = Vec::new();
    for e in fs::read_dir(src()).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        if p.is_dir() {
            if !LAYERS.contains(&name.as_str()) && !TEST_ONLY.contains(&name.as_str()) {
                loose.push(format!(
                    "{name}/ (a folder that is not a layer: add it to LAYERS)"
                ));
            }
        } else if !ROOT_FILES.contains(&name.as_str()) {
            loose.push(name);
        }
    }
    assert!(loose.is_empty(), "loose at the root of src/: {loose:?}");
}

#[test]
fn no_source_file_over_the_limit_without_its_tests() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut long: Vec<String> = files
        .iter()
        .filter_map(|p| {
            let n = without_tests(p).lines().count();
            (n > MAX_LINES).then(|| format!("{} ({n} lines)", p.display()))
        })
        .collect();
    long.sort();
    assert!(
        long.is_empty(),
        "over {MAX_LINES} lines without tests: {long:#?}"
    );
}

#[test]
fn no_import_runs_back_up_the_layers() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut up = Vec::new();
    for p in &files {
        let layer = layer_of(p);
        let Some(own) = LAYERS.iter().position(|l| *l == layer) else {
            continue; // lib.rs, main.rs and the test helpers sit above every layer
        };
        for (i, line) in without_tests(p).lines().enumerate() {
            let code = line.trim_start();
            if code.starts_with("//") {
                continue; // documentation may point anywhere
            }
            for (k, _) in code.match_indices("crate::") {
                let before = code[..k].chars().last();
                if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                    continue; // `$crate::`, `octmesh_crate::`
                }
                let name: String = code[k + 7..]
                    .chars()
                    .take_while(|c| c.is_ascii_lowercase() || *c == '_')
                    .collect();
                if let Some(to) = LAYERS.iter().position(|l| *l == name) {
                    if to > own {
                        up.push(format!(
                            "{}:{}: {layer} uses {name}",
                            p.strip_prefix(src()).unwrap().display(),
                            i + 1
                        ));
                    }
                }
            }
        }
    }
    assert!(
        up.is_empty(),
        "imports that run up the layers {LAYERS:?}: {up:#?}"
    );
}

/// The checker itself: a file that only holds tests counts as empty, and
/// the tests block of a file is not counted.
#[test]
fn the_line_count_skips_unit_tests() {
    let dir = std::env::temp_dir().join(format!("octmesh_layout_{}", std::process::id()));
    fs::create_dir_all(&dir).unwrap();
    let f = dir.join("a.rs");
    fs::write(
        &f,
        "fn a() {}\n#[cfg(test)]\nmod tests {\n    fn t() {}\n}\n",
    )
    .unwrap();
    assert_eq!(without_tests(&f).lines().count(), 1);
    let t = dir.join("tests.rs");
    fs::write(&t, "fn t() {}\n").unwrap();
    assert_eq!(without_tests(&t), "");
    fs::remove_dir_all(&dir).unwrap();
}
