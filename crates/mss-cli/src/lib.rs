//! # mss-cli
//!
//! The `mss` command: turns a surface mesh into a hexahedral mass-spring soft
//! body (Baudet et al. 2009) and simulates it.
//!
//! - `mss run [SCENE]`: runs a scene file (without one: the bundled default job).
//! - `mss voxelize MESH`: voxelizes a mesh and writes the lattice and its skins.
//! - `mss check SCENE`: validates a scene and estimates its cost.
//! - `mss init [FILE]`: writes a commented template scene.
//! - `mss experiment ...`: the paper's experiments.
//!
//! [`run_with_args`] runs the command line given to it, so everything the
//! binary does can be tested without a process:
//!
//! ```
//! let dir = tempfile::tempdir().unwrap();
//! let file = dir.path().join("scene.toml");
//! mss_cli::run_with_args(["mss", "-q", "init", file.to_str().unwrap()]).unwrap();
//! mss_cli::run_with_args(["mss", "-q", "init", file.to_str().unwrap()]).unwrap_err();
//! ```
//!
//! Errors come back as [`anyhow::Error`]; [`error_report`] renders one as the
//! single line the binary prints (or the chain of causes under `-v`), and
//! [`exit_code`] maps it to the process exit code.

use std::ffi::OsString;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU8, Ordering};

use anyhow::Context;
use clap::{Args, Parser};

pub mod commands;
pub mod progress;

/// Command-line interface of `mss`.
#[derive(Debug, Parser)]
#[command(
    name = "mss",
    version,
    about = "Hexahedral mass-spring soft bodies from surface meshes (Baudet et al. 2009)",
    long_about = "Turns a closed surface mesh (OBJ, STL, PLY, VTK) into a lattice of cubic cells, builds the \
                  hexahedral mass-spring system of Baudet et al. (WSCG 2009) whose springs and \
                  correction forces reproduce a given Young's modulus and Poisson's ratio, and \
                  simulates it. Results are VTK files (open the .pvd in ParaView) and OBJ skins."
)]
pub struct Cli {
    /// Options shared by every subcommand.
    #[command(flatten)]
    pub global: GlobalArgs,
    /// The subcommand.
    #[command(subcommand)]
    pub command: commands::Command,
}

/// Options shared by every subcommand.
#[derive(Debug, Clone, Args)]
pub struct GlobalArgs {
    /// More messages (-v: info and the chain of causes of an error, -vv: debug, -vvv: trace).
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    pub verbose: u8,
    /// Fewer messages (-q: no progress bars or summaries, only errors).
    #[arg(short, long, action = clap::ArgAction::Count, global = true, conflicts_with = "verbose")]
    pub quiet: u8,
    /// Worker threads for the parallel parts (default: one per core). Results do
    /// not depend on it.
    #[arg(long, value_name = "N", global = true)]
    pub threads: Option<usize>,
    /// Output folder: `run` writes there instead of the scene's `[output]
    /// folder` (and `check` estimates its free space); `voxelize` writes
    /// there (default ./MESH_lattice, named after the mesh); `experiment`
    /// (default out/experiments).
    /// `init` and `view` write nothing and ignore it.
    #[arg(long, value_name = "DIR", global = true)]
    pub out: Option<PathBuf>,
    /// Memory a job may use, like 8GiB or 500MB (default: three quarters of
    /// the machine's memory). Jobs estimated to need more are refused before
    /// they allocate it.
    #[arg(long, value_name = "SIZE", global = true, value_parser = mss_scene::limits::parse_size)]
    pub max_memory: Option<u64>,
}

impl GlobalArgs {
    /// The resource limits of the command line.
    pub fn limits(&self) -> mss_scene::limits::Limits {
        let mut limits = mss_scene::limits::Limits::default();
        if let Some(m) = self.max_memory {
            limits.memory_bytes = m;
        }
        limits
    }

    /// Whether progress bars and summaries are shown.
    pub fn chatty(&self) -> bool {
        self.quiet == 0
    }
}

/// A command line that clap refused (unknown option, missing argument, ...):
/// exit code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

static VERBOSITY: AtomicU8 = AtomicU8::new(0);

/// Most `--threads` per core: beyond a few, threads only contend.
const MAX_THREADS_PER_CORE: usize = 4;

/// Stack of the worker threads the command runs on.
const WORKER_STACK_BYTES: usize = 64 << 20;

/// Runs `mss` with the process's command line.
pub fn run() -> anyhow::Result<()> {
    run_with_args(std::env::args_os())
}

/// Runs `mss` with the given command line (the first item is the program name).
/// `--help` and `--version` print and return `Ok`.
pub fn run_with_args<I, T>(args: I) -> anyhow::Result<()>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            return match e.kind() {
                ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
                    // Bare `mss`: the help, on standard error, then one line
                    // saying what was missing.
                    use std::io::Write;
                    let _ = write!(std::io::stderr(), "{}", e.render());
                    return Err(UsageError(
                        "no subcommand given: `mss run` runs the bundled scene; the others are listed above"
                            .into(),
                    )
                    .into());
                }
                ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
                    e.print().map_err(|io| match io.kind() {
                        std::io::ErrorKind::BrokenPipe => StdoutError::BrokenPipe,
                        _ => StdoutError::Write(io),
                    })?;
                    Ok(())
                }
                _ => Err(UsageError(clap_error_line(&e)).into()),
            };
        }
    };
    VERBOSITY.store(cli.global.verbose, Ordering::Relaxed);
    init_logger(&cli.global);
    let threads = cli.global.threads.unwrap_or(0);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    match cli.global.threads {
        Some(0) => {
            return Err(UsageError(
                "--threads 0: give at least 1 thread (or leave --threads out for one per core)"
                    .into(),
            )
            .into());
        }
        Some(n) if n > MAX_THREADS_PER_CORE * cores => {
            return Err(UsageError(format!(
                "--threads {n}: this machine has {cores} cores; more than {} threads only \
                 slow the run down (leave --threads out for one per core)",
                MAX_THREADS_PER_CORE * cores
            ))
            .into());
        }
        _ => {}
    }
    // A local pool (not the global one) so that several runs in one process,
    // as in tests, can each choose their thread count. The whole command runs
    // on it, scene parsing included: a deeply nested (hostile) scene file
    // must meet the parser's own limit, not a 2 MiB worker stack.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .stack_size(WORKER_STACK_BYTES)
        .build()
        .context("cannot start the worker threads")?;
    pool.install(|| commands::dispatch(&cli))
}

fn clap_error_line(e: &clap::Error) -> String {
    let text = e.render().to_string();
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    let first = lines.next().unwrap_or("invalid command line");
    let first = first.strip_prefix("error: ").unwrap_or(first);
    // "the following required arguments were not provided:" names them on
    // the next line.
    let first = match (first.strip_suffix(':'), lines.next()) {
        (Some(head), Some(next)) if !next.starts_with("Usage:") => format!("{head}: {next}"),
        _ => first.to_owned(),
    };
    // clap's suggestions ("a similar subcommand exists: 'run'") follow on
    // lines of their own: keep them on the one line.
    let tips: Vec<&str> = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("tip: "))
        .filter(|t| !t.starts_with("to pass"))
        .collect();
    // The help of the subcommand the error is about, when there is one.
    let help = text
        .lines()
        .find_map(|l| l.trim().strip_prefix("Usage: mss "))
        .and_then(|u| {
            u.split_whitespace()
                .find(|w| !w.starts_with('[') && !w.starts_with('-') && !w.starts_with('<'))
        })
        .map_or("mss --help".to_owned(), |sub| format!("mss {sub} --help"));
    if tips.is_empty() {
        format!("{first} (see `{help}`)")
    } else {
        format!("{first}; {} (see `{help}`)", tips.join("; "))
    }
}

fn init_logger(g: &GlobalArgs) {
    use log::LevelFilter;
    let level = match (g.quiet, g.verbose) {
        (q, _) if q >= 2 => LevelFilter::Off,
        (1, _) => LevelFilter::Error,
        (_, 0) => LevelFilter::Warn,
        (_, 1) => LevelFilter::Info,
        (_, 2) => LevelFilter::Debug,
        _ => LevelFilter::Trace,
    };
    // The logger can be installed once per process; later calls (tests running
    // several command lines) only change the level.
    let _ = env_logger::Builder::new()
        .filter_level(LevelFilter::Trace)
        .format_timestamp(None)
        .format_target(false)
        .try_init();
    log::set_max_level(level);
}

/// The text the binary prints for an error: one line `error: ...` with every
/// cause joined by ": ", or under `-v` the error followed by one line per
/// cause. A cause whose text the message before it already contains (library
/// errors include their cause's text) is not repeated, so the operating
/// system's reason appears once.
pub fn error_report(e: &anyhow::Error) -> String {
    let parts = mss_scene::error::causes(e.as_ref());
    if VERBOSITY.load(Ordering::Relaxed) == 0 {
        return format!("error: {}", parts.join(": "));
    }
    let mut out = format!("error: {}", parts.first().map_or("", String::as_str));
    for cause in parts.iter().skip(1) {
        out.push_str(&format!("\n  caused by: {cause}"));
    }
    out
}

/// Printing to standard output failed.
#[derive(Debug, thiserror::Error)]
pub enum StdoutError {
    /// The reader went away (`mss check | head -1`): not worth a message.
    #[error("standard output was closed")]
    BrokenPipe,
    /// Standard output cannot take more (`>/dev/full`).
    #[error("cannot print to standard output: {0}")]
    Write(std::io::Error),
}

/// Writes to standard output, returning an error where `print!` would
/// panic (a closed pipe, a full disk).
pub fn write_stdout(args: std::fmt::Arguments<'_>) -> Result<(), StdoutError> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    out.write_fmt(args).map_err(|e| match e.kind() {
        std::io::ErrorKind::BrokenPipe => StdoutError::BrokenPipe,
        _ => StdoutError::Write(e),
    })
}

/// `println!` for the subcommands: a failed print is an error that the
/// command returns (through `?`), never a panic.
#[macro_export]
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::write_stdout(format_args!("{}\n", format_args!($($arg)*)))?
    };
}

/// Exit status of a process whose output pipe was closed (128 + SIGPIPE),
/// as the shell reports a program that SIGPIPE ended.
pub const BROKEN_PIPE_EXIT: u8 = 141;

/// Process exit code for an error: 2 for a refused command line,
/// [`BROKEN_PIPE_EXIT`] when standard output was closed, 1 otherwise.
pub fn exit_code(e: &anyhow::Error) -> u8 {
    if e.downcast_ref::<UsageError>().is_some() {
        2
    } else if is_broken_pipe(e) {
        BROKEN_PIPE_EXIT
    } else {
        1
    }
}

/// Whether the error is a closed standard output, which ends `mss`
/// quietly.
pub fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        matches!(
            c.downcast_ref::<StdoutError>(),
            Some(StdoutError::BrokenPipe)
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cause_already_in_the_message_is_not_repeated() {
        let os = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file or directory");
        let lib = mss_scene::mss_io::IoError::io(std::path::Path::new("out/a.vtu"), os);
        let e = anyhow::Error::new(lib).context("frame 3");
        let line = error_report(&e);
        assert_eq!(
            line.matches("No such file or directory").count(),
            1,
            "{line}"
        );
        assert!(
            line.starts_with("error: frame 3: cannot write out/a.vtu"),
            "{line}"
        );
        assert!(!line.contains('\n'));
    }
}
