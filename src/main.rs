//! The `octmesh` command: parses the command line (or case file) into a
//! configuration, runs the library's pipeline on it, prints the phase table
//! on rank 0 and exits 0, or 2 after an error reported on every rank.
//!
//! A panic (an internal bug) on any rank prints one line naming the rank,
//! `octmesh: internal error on rank r of P: <message> (at file:line)`, and
//! ends the whole job at once with `MPI_Abort(MPI_COMM_WORLD, 3)`: the
//! other ranks may be waiting in a collective for the panicking one. Run
//! without an MPI launcher the command exits with status 3. A panic the
//! library catches itself (around the STL parser) stays that call's error.

use std::io::Write;
use std::process::ExitCode;
use std::rc::Rc;

use octmesh::error::panic_message;
use octmesh::internals::classify::InsideRule;
use octmesh::internals::config::cli::{self, Invocation};
use octmesh::internals::geometry::diagnostics::diagnose;
use octmesh::internals::geometry::load_surface_on;
use octmesh::internals::parallel::comm::{agree, CommRef, MpiComm, SerialComm};
use octmesh::internals::pipeline::{Session, Table};
use octmesh::internals::run::progress::Style;
use octmesh::Result;

/// Prints to stdout, ignoring a closed pipe (`octmesh ... | head -1`).
macro_rules! say {
    ($($t:tt)*) => {{ let _ = writeln!(std::io::stdout(), $($t)*); }};
}

/// `octmesh check`: every rank diagnoses the surface (it is cheap); rank 0
/// prints the report and writes the JSON.
fn check(comm: &CommRef, file: &str, json: Option<&std::path::Path>, quiet: bool) -> Result<()> {
    let start = std::time::Instant::now();
    let surface = agree(&**comm, load_surface_on(&**comm, file))?;
    let read = start.elapsed().as_secs_f64();
    let report = diagnose(&surface);
    let diagnosed = start.elapsed().as_secs_f64() - read;
    let (rule, why) = InsideRule::auto_choice(&report);
    if comm.rank() == 0 && !quiet {
        say!(
            "octmesh check: {file} ({} triangles)\n{report}",
            report.triangles
        );
        say!("  inside rule auto: {rule} ({why})\n  read {read:.3} s | diagnose {diagnosed:.3} s (rank 0)");
    }
    match json {
        Some(path) => {
            let mut j = report.to_json_value();
            j["auto_inside_rule"] = rule.name().into();
            octmesh::internals::io::json::write_json(&**comm, path, &j)
        }
        None => Ok(()),
    }
}

fn run(comm: &CommRef, args: &[String]) -> Result<()> {
    match cli::parse(args)? {
        Invocation::Print(text) => {
            if comm.rank() == 0 {
                let _ = write!(std::io::stdout(), "{text}");
            }
            Ok(())
        }
        Invocation::Check {
            surface,
            json,
            quiet,
        } => check(comm, &surface, json.as_deref(), quiet),
        Invocation::Run {
            config,
            print_case: true,
            ..
        } => {
            if comm.rank() == 0 {
                let _ = write!(std::io::stdout(), "{}", config.resolved().to_toml());
            }
            Ok(())
        }
        Invocation::Run {
            config,
            dry_run: true,
            ..
        } => {
            let mut session = Session::new(comm.clone(), (*config).clone());
            let rows = session.estimate()?;
            if comm.rank() == 0 {
                let mut text = String::from(
                    "dry run: estimated octants after balance, per control (nothing built)\n",
                );
                for (what, n) in rows {
                    text.push_str(&format!("  {what:<48} {n:>16}\n"));
                }
                let _ = write!(std::io::stdout(), "{text}");
            }
            Ok(())
        }
        Invocation::Run {
            command, config, ..
        } => {
            let mut session = Session::new(comm.clone(), (*config).clone());
            if !config.output.quiet {
                session.set_progress(Some(Style::detect()));
            }
            if comm.rank() == 0 && !config.output.quiet {
                let ranks = comm.size();
                session.set_observer(Box::new(Table::new(command, *config, ranks)));
            }
            session.run(command).map(|_| ())
        }
    }
}

/// Keeps freed memory in the process: the pipeline frees and reallocates
/// arrays of several GB, and returning them to the kernel makes every
/// reuse pay for zeroing fresh pages again. No mmap for large blocks, and
/// no automatic trim at all (-1; `i32::MAX` still trimmed once more than 2
/// GB lay free at the top); the library's own `trim_heap` calls, placed
/// where a phase's peak is behind it, still return pages.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator tuning; called before any
    // threads exist.
    unsafe {
        libc::mallopt(libc::M_MMAP_MAX, 0);
        libc::mallopt(libc::M_TRIM_THRESHOLD, -1);
    }
}

/// Whether an MPI launcher (Open MPI's `mpirun`, a PMI or PMIx process
/// manager such as Slurm's or MPICH's) started this process. Run by itself
/// the command is one rank and skips MPI's start-up (a singleton
/// `MPI_Init` costs about 0.3 s here, more than meshing a small case);
/// `OCTMESH_MPI=1` initialises MPI anyway.
fn launched_by_mpi() -> bool {
    const LAUNCHER_VARS: [&str; 5] = [
        "OMPI_COMM_WORLD_SIZE",
        "PMIX_RANK",
        "PMI_RANK",
        "PMI_SIZE",
        "OCTMESH_MPI",
    ];
    LAUNCHER_VARS.iter().any(|v| std::env::var_os(v).is_some())
}

/// Fault injection for the tests, not a user option:
/// `OCTMESH_FAULT_PANIC_RANK=r` makes rank `r` panic before the run starts,
/// while the other ranks go on into the run's collectives.
fn inject_fault(rank: usize) {
    let target = std::env::var("OCTMESH_FAULT_PANIC_RANK").ok();
    if target.and_then(|r| r.trim().parse().ok()) == Some(rank) {
        panic!("fault injected by OCTMESH_FAULT_PANIC_RANK={rank}");
    }
}

/// Exit status (and `MPI_Abort` error code) after a panic on any rank.
const INTERNAL_ERROR: i32 = 3;

/// The last panic's message and place, kept by [`remember_panics`] for
/// [`abort_job`].
static LAST_PANIC: std::sync::Mutex<Option<String>> = std::sync::Mutex::new(None);

/// Replaces the default panic message by a note of the panic (a backtrace
/// is printed when `RUST_BACKTRACE` asks for one): a panic that the library
/// catches itself (the STL parser's) becomes its error message, and one that
/// reaches `main` is reported once, by [`abort_job`].
fn remember_panics() {
    std::panic::set_hook(Box::new(|info| {
        let message = panic_message(info.payload());
        let at = info
            .location()
            .map(|l| format!(" (at {}:{})", l.file(), l.line()))
            .unwrap_or_default();
        let trace = std::backtrace::Backtrace::capture();
        if trace.status() == std::backtrace::BacktraceStatus::Captured {
            let _ = writeln!(std::io::stderr(), "{trace}");
        }
        if let Ok(mut last) = LAST_PANIC.lock() {
            *last = Some(format!("{message}{at}"));
        }
    }));
}

/// Ends the job after a panic reached `main` on this rank: prints one line
/// naming the rank, then `MPI_Abort` on `MPI_COMM_WORLD` (the other ranks
/// may be waiting in a collective for this one; unwinding into
/// `MPI_Finalize` would hang them all), or a plain exit without MPI. It
/// calls the MPI C API directly: the communicator may be mid-operation.
fn abort_job(rank: usize, size: usize) -> ! {
    let what = LAST_PANIC
        .lock()
        .ok()
        .and_then(|mut l| l.take())
        .unwrap_or_else(|| "(no message)".to_string());
    let (mut initialized, mut finalized) = (0, 0);
    // SAFETY: both may be called at any time, before MPI_Init and after
    // MPI_Finalize too.
    unsafe {
        mpi::ffi::MPI_Initialized(&mut initialized);
        mpi::ffi::MPI_Finalized(&mut finalized);
    }
    let mpi_up = initialized != 0 && finalized == 0;
    let then = if mpi_up {
        "aborting the MPI job"
    } else {
        "exiting"
    };
    let line = format!("octmesh: internal error on rank {rank} of {size}: {what}; {then}\n");
    // One write, so that ranks' reports do not interleave.
    let _ = std::io::stderr().write_all(line.as_bytes());
    if mpi_up {
        // SAFETY: MPI is initialised and not finalised; MPI_Abort does not
        // return (Open MPI ends every process of the job).
        unsafe {
            mpi::ffi::MPI_Abort(mpi::ffi::RSMPI_COMM_WORLD, INTERNAL_ERROR);
        }
    }
    std::process::exit(INTERNAL_ERROR);
}

fn main() -> ExitCode {
    keep_freed_memory();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let universe = if launched_by_mpi() {
        let Some(universe) = mpi::initialize() else {
            eprintln!("octmesh: error: MPI was already initialised");
            return ExitCode::FAILURE;
        };
        Some(universe)
    } else {
        None
    };
    let comm: CommRef = match &universe {
        Some(u) => Rc::new(MpiComm::new(u.world())),
        None => Rc::new(SerialComm),
    };
    let (rank, size) = (comm.rank(), comm.size());
    remember_panics();
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        inject_fault(rank);
        run(&comm, &args)
    }));
    let Ok(result) = result else {
        abort_job(rank, size)
    };
    // Report before MPI_Finalize: once one rank exits non-zero, mpirun may
    // kill the others before they print.
    if let Err(e) = &result {
        let line = match e.message().strip_prefix("usage: ") {
            Some(usage) if rank == 0 => usage.to_string(),
            Some(_) => String::new(),
            None => format!("octmesh: error [rank {rank} of {size}]: {}\n", e.message()),
        };
        // One write per message so that ranks' lines do not interleave.
        let _ = std::io::stderr().write_all(line.as_bytes());
        let _ = std::io::stderr().flush();
        // Every rank has printed before any rank exits: mpirun stops the job
        // at the first non-zero exit.
        comm.barrier();
    }
    let _ = std::io::stdout().flush();
    drop(comm);
    drop(universe);
    if result.is_ok() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(2)
    }
}
