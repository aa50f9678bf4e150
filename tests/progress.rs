//! Progress of long phases: a bar under a terminal, plain lines without
//! one, nothing with `--quiet` or for short phases.

mod common;

use std::process::Command;
use std::time::Duration;

use common::*;

/// Runs octmesh with progress shown at once, stderr captured.
fn run(args: &[&str], after: &str) -> (String, String) {
    let mut cmd = Command::new(octmesh_bin());
    cmd.args(args).env("OCTMESH_PROGRESS_AFTER", after);
    let out = run_with_limit(cmd, Duration::from_secs(120));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

#[test]
fn plain_lines_without_a_terminal() {
    let (stdout, stderr) = run(&["mesh", "sphere", "--level", "8"], "0");
    for phase in ["refine", "balance", "mesh"] {
        assert!(stderr.contains(&format!("progress: {phase}:")), "{stderr}");
    }
    assert!(
        !stderr.contains('\x1b'),
        "escape codes without a terminal: {stderr:?}"
    );
    // The table is unchanged on stdout.
    assert!(stdout.contains("connectivity"), "{stdout}");
}

#[test]
fn quiet_and_short_runs_show_no_progress() {
    let (stdout, stderr) = run(&["mesh", "sphere", "--level", "8", "--quiet"], "0");
    assert!(stdout.is_empty() && stderr.is_empty(), "{stdout}{stderr}");
    // The default delay: phases of a small run end before it.
    let (_, stderr) = run(&["mesh", "sphere", "--level", "5"], "1");
    assert!(!stderr.contains("progress"), "{stderr}");
}

#[test]
fn a_bar_on_a_terminal() {
    // A pseudo-terminal from Python's pty module, as a user's shell gives.
    let script =
        "import os, pty, sys\nos.environ['OCTMESH_PROGRESS_AFTER'] = '0'\npty.spawn(sys.argv[1:])";
    let bin = octmesh_bin();
    let mut cmd = Command::new(common::python_with("pty", "python3"));
    cmd.args([
        "-c",
        script,
        bin.to_str().unwrap(),
        "mesh",
        "sphere",
        "--level",
        "9",
    ]);
    let out = run_with_limit(cmd, Duration::from_secs(120));
    assert!(out.status.success());
    let screen = String::from_utf8_lossy(&out.stdout);
    assert!(
        screen.contains("octants/s") || screen.contains("octants,"),
        "{screen}"
    );
    assert!(
        screen.contains("refine") && screen.contains('['),
        "{screen}"
    );
    assert!(
        screen.contains("elements"),
        "the table still prints: {screen}"
    );
}
