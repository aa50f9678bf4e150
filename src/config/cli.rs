//! The `octmesh` command line: parsed with clap into a [`Config`], on top
//! of a case file when one is given.
//!
//! The arguments of `octree` and `mesh` come from the one declaration of
//! the options ([`super::options::OPTIONS`]); each fills keys of the
//! configuration, so an error about a key names the option when it came
//! from the command line, and the file, line and key when it came from a
//! case file.

use std::path::PathBuf;

use clap::error::{ContextKind, ContextValue, ErrorKind as ClapKind};
use clap::parser::ValueSource;
use clap::{Arg, ArgAction};

use super::case::CaseFile;
use super::options::{self, Scope, OPTIONS};
use super::{Command, Config, ConfigError};
use crate::error::{Error, Result};

/// The option that fills each key, as an error message names it.
pub fn option_of(key: &str) -> String {
    options::option_of(key)
}

/// The whole command line: `octree`, `mesh` and `check`.
pub fn command() -> clap::Command {
    let run = |name: &'static str, about: &'static str, mesh: bool| {
        clap::Command::new(name)
            .about(about)
            .args(options::clap_args(mesh))
    };
    clap::Command::new("octmesh")
        .version(env!("CARGO_PKG_VERSION"))
        .about("Parallel 2:1-balanced linear octrees and hexahedral meshes from STL surfaces")
        .long_about(
            "Parallel 2:1-balanced linear octrees and hexahedral meshes from STL surfaces. Run \
             it directly or under mpirun; every rank takes part.",
        )
        .after_help(
            "Lattice units: the root cube is [0, 2^19]^3; a leaf at level l has side 2^(19-l). \
             User units are the STL file's.",
        )
        .subcommand_required(true)
        .arg_required_else_help(true)
        .subcommand(run(
            "octree",
            "Builds the surface-refined linear octree, partitions it over the MPI ranks and \
             2:1-balances it",
            false,
        ))
        .subcommand(run(
            "mesh",
            "Builds the octree, then the trilinear hexahedral mesh (ghost layer, independent \
             and hanging nodes, global numbering) of the kept leaves",
            true,
        ))
        .subcommand(
            clap::Command::new("check")
                .about(
                    "Prints the surface diagnostics (welded vertices, boundary and non-manifold \
                     edges, components, degenerate and duplicate facets, genus, volume) and the \
                     inside rule auto would pick",
                )
                .arg(
                    Arg::new("surface")
                        .required(true)
                        .value_name("SURFACE")
                        .help("An STL file or the built-in `sphere`, `torus` or `hull`"),
                )
                .arg(
                    Arg::new("json")
                        .long("json")
                        .value_name("FILE")
                        .help("Also write the diagnostics as JSON"),
                )
                .arg(
                    Arg::new("quiet")
                        .long("quiet")
                        .action(ArgAction::SetTrue)
                        .help("Print nothing but errors"),
                ),
        )
}

/// What a command line asks for.
#[derive(Clone, Debug)]
pub enum Invocation {
    /// Build an octree or a mesh with this configuration.
    Run {
        /// What to build.
        command: Command,
        /// Every setting.
        config: Box<Config>,
        /// Print the case file instead of running.
        print_case: bool,
        /// Print the estimates instead of running.
        dry_run: bool,
    },
    /// Diagnose a surface.
    Check {
        /// The surface.
        surface: String,
        /// JSON output.
        json: Option<PathBuf>,
        /// Print nothing but errors.
        quiet: bool,
    },
    /// Print this text (help or version) and succeed.
    Print(String),
}

/// Parses the arguments after the program name. Errors are
/// [`crate::ErrorKind::InvalidArgument`] and name the option (or the case
/// file's line and key).
pub fn parse(args: &[String]) -> Result<Invocation> {
    let argv = std::iter::once("octmesh".to_string()).chain(args.iter().cloned());
    let matches = match command().try_get_matches_from(argv) {
        Ok(m) => m,
        Err(e) => return clap_error(e),
    };
    let (name, m) = matches
        .subcommand()
        .ok_or_else(|| Error::invalid("no command given"))?;
    let command = match name {
        "check" => {
            return Ok(Invocation::Check {
                surface: m.get_one::<String>("surface").cloned().unwrap_or_default(),
                json: m.get_one::<String>("json").map(PathBuf::from),
                quiet: m.get_flag("quiet"),
            })
        }
        "octree" => Command::Octree,
        _ => Command::Mesh,
    };
    let input = m.get_one::<String>("input").cloned().unwrap_or_default();
    let case = if input.ends_with(".toml") {
        Some(CaseFile::read(input.as_ref())?)
    } else {
        None
    };
    let mut config = case.as_ref().map(|c| c.config.clone()).unwrap_or_default();
    let mut given = Vec::new();
    if case.is_none() {
        config.surface.file = input;
        given.push("surface.file");
    }
    let on_line = |name: &str| m.value_source(name) == Some(ValueSource::CommandLine);
    let domains: Vec<String> = ["fit", "domain", "box"]
        .into_iter()
        .filter(|n| on_line(n))
        .map(|n| format!("--{n}"))
        .collect();
    if domains.len() > 1 {
        return Err(Error::invalid(format!(
            "{} exclude each other: give one",
            domains.join(" and ")
        )));
    }
    let mesh = command == Command::Mesh;
    for o in OPTIONS.iter().filter(|o| mesh || o.scope == Scope::Octree) {
        o.apply(m, &mut config, &mut given)?;
    }
    let label = |key: &str| match &case {
        Some(c) if !given.contains(&key) => c.label(key),
        _ => option_of(key),
    };
    config
        .validate(command)
        .map_err(|e: ConfigError| Error::invalid(e.render(label)))?;
    Ok(Invocation::Run {
        command,
        config: Box::new(config),
        print_case: m.get_flag("print-case"),
        dry_run: m.get_flag("dry-run"),
    })
}

/// A clap error in octmesh's words: help and version are printed, a value
/// that does not parse names its option, the rest keeps clap's text (with
/// its "a similar argument exists" tips).
fn clap_error(e: clap::Error) -> Result<Invocation> {
    match e.kind() {
        ClapKind::DisplayHelp | ClapKind::DisplayVersion => {
            return Ok(Invocation::Print(e.render().to_string()))
        }
        ClapKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            return Err(Error::invalid(format!("usage: {}", e.render())))
        }
        _ => {}
    }
    let arg = match e.get(ContextKind::InvalidArg) {
        Some(ContextValue::String(a)) => a.split([' ', '=']).next().map(str::to_string),
        _ => None,
    };
    let source = std::error::Error::source(&e).map(|s| s.to_string());
    let message = match (e.kind(), arg, source) {
        (ClapKind::ValueValidation, Some(arg), Some(why)) => {
            let sep = if why.starts_with("unknown") {
                ": "
            } else {
                " "
            };
            format!("{arg}{sep}{why}")
        }
        _ => {
            let text = e.render().to_string();
            let text = text.strip_prefix("error: ").unwrap_or(&text);
            text.trim_end().to_string()
        }
    };
    Err(Error::invalid(message))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::{InsideRule, Keep};
    use crate::config::Balance;

    fn run(args: &[&str]) -> Result<Config> {
        let args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
        match parse(&args)? {
            Invocation::Run { config, .. } => Ok(*config),
            other => panic!("{other:?}"),
        }
    }

    fn fails(args: &[&str], needle: &str) {
        let e = run(args).unwrap_err();
        assert!(e.message().contains(needle), "{args:?}: {}", e.message());
    }

    #[test]
    fn options_fill_the_config() {
        let c = run(&[
            "mesh",
            "bunny.stl",
            "--level",
            "7",
            "--keep",
            "inside",
            "--fit",
            "0.5",
            "--balance",
            "edge",
            "--inside",
            "winding",
            "--quiet",
            "--out",
            "m.pvtu",
        ])
        .unwrap();
        assert_eq!(c.surface.file, "bunny.stl");
        assert_eq!(c.octree.level, Some(7));
        assert_eq!(c.octree.balance, Balance::Edge);
        assert_eq!(c.domain.fit, Some(0.5));
        assert_eq!(c.mesh.keep, Keep::Inside);
        assert_eq!(c.classify.inside, Some(InsideRule::Winding));
        assert!(c.output.quiet);
        assert_eq!(c.output.vtu, Some("m.pvtu".into()));
    }

    #[test]
    fn errors_name_the_option() {
        fails(
            &["octree", "sphere", "--level", "x"],
            "--level expects an integer",
        );
        fails(
            &["octree", "sphere", "--level", "19"],
            "above the maximum level 18",
        );
        fails(
            &["octree", "sphere", "--level", "4", "--fit", "2"],
            "--fit must be in (0, 1]",
        );
        fails(
            &["octree", "sphere", "--level", "4", "--balance", "diagonal"],
            "--balance: unknown connectivity 'diagonal'",
        );
        fails(&["octree", "sphere"], "--level is required");
        let c = run(&[
            "octree",
            "sphere",
            "--level",
            "3",
            "--inside-point",
            "-0.5,0,-1e-3",
        ]);
        assert_eq!(c.unwrap().leak.inside_point, Some([-0.5, 0.0, -1e-3]));
        fails(
            &["octree", "sphere", "--level", "3", "--fit", "-1"],
            "--fit must be in (0, 1]",
        );
        fails(&["octree", "sphere", "--levl", "3"], "--level");
        fails(
            &[
                "octree", "sphere", "--level", "3", "--fit", "0.5", "--domain", "0,0,0,1",
            ],
            "--fit and --domain exclude each other",
        );
        fails(
            &["octree", "sphere", "--level", "3", "--leak-path", "x.vtk"],
            "--leak-path needs --inside-point",
        );
        fails(
            &["octree", "sphere", "--level", "3", "--keep", "inside"],
            "--keep",
        );
        fails(
            &["mesh", "sphere", "--level", "3", "--out", "m.vtu"],
            "ending in .pvtu",
        );
    }
}
