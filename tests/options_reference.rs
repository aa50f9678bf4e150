//! `docs/options.md`, the reference of every option and case-file key, is
//! generated from the one declaration of the options
//! (`octmesh::internals::config::options`): it must be up to date, and list exactly
//! the options the command's `--help` shows.
//!
//! After changing an option: `OCTMESH_BLESS=1 cargo test --release --test
//! options_reference` writes the file again.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::process::Command;

fn reference_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("docs/options.md")
}

#[test]
fn the_committed_reference_is_the_generated_one() {
    let want = octmesh::internals::config::options::markdown();
    let path = reference_path();
    if std::env::var_os("OCTMESH_BLESS").is_some() {
        std::fs::write(&path, &want).unwrap();
    }
    let have = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        have == want,
        "{} is not the generated reference: run OCTMESH_BLESS=1 cargo test --release --test \
         options_reference and commit it",
        path.display()
    );
}

/// The options of a `--help` text: the first word of each line of its
/// `Arguments:` and `Options:` sections (`<INPUT>` as `INPUT`), without
/// `--help` and `--version`.
fn help_options(text: &str) -> BTreeSet<String> {
    text.lines()
        .filter(|l| l.starts_with("  ") && !l.starts_with("          "))
        .filter_map(|l| l.split_whitespace().next())
        .map(|w| w.trim_start_matches('<').trim_end_matches('>').to_string())
        .filter(|w| w.starts_with("--") || w.chars().all(|c| c.is_ascii_uppercase()))
        .filter(|w| !["--help", "--version"].contains(&w.as_str()))
        .collect()
}

/// The options of the reference's sections whose titles hold `command`:
/// the first word of each table row's first cell.
fn reference_options(text: &str, command: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut inside = false;
    for l in text.lines() {
        if let Some(title) = l.strip_prefix("## ") {
            inside = title.contains(&format!("`octmesh {command}`"));
        } else if inside && l.starts_with("| `") {
            let cell = l.trim_start_matches("| `");
            let word = cell.split([' ', '`']).next().unwrap_or_default();
            out.insert(word.to_string());
        }
    }
    out
}

#[test]
fn the_reference_lists_the_options_of_the_help() {
    let reference = octmesh::internals::config::options::markdown();
    for command in ["octree", "mesh", "check"] {
        let out = Command::new(env!("CARGO_BIN_EXE_octmesh"))
            .args([command, "--help"])
            .output()
            .unwrap();
        assert!(out.status.success(), "{command} --help failed");
        let help = help_options(&String::from_utf8_lossy(&out.stdout));
        let documented = reference_options(&reference, command);
        assert!(help.len() > 1, "{command} --help: {help:?}");
        assert_eq!(
            help, documented,
            "{command}: the options of --help (left) and of docs/options.md (right) differ"
        );
    }
}
