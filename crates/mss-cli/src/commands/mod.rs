//! One module per subcommand; [`dispatch`] runs the one parsed.

use clap::Subcommand;

use crate::Cli;

pub mod check;
pub mod experiment;
pub mod init;
pub mod run;
pub mod view;
pub mod voxelize;

/// The subcommands of `mss`.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a scene (default: the bundled job, the critter sagging under gravity).
    Run(run::RunArgs),
    /// Voxelize a surface mesh: write the lattice (.vtu), its skin and the embedded surface (.obj) and stats.json.
    Voxelize(voxelize::VoxelizeArgs),
    /// Validate a scene and print its size, stable time step and cost estimates.
    Check(check::CheckArgs),
    /// Write a commented template scene.
    Init(init::InitArgs),
    /// Compare the model with the built-in FEM reference: the paper's beam and
    /// L-shape experiments and virtual material tests, or any scene (report, CSV, SVG, .vtu).
    Experiment(experiment::ExperimentArgs),
    /// Watch, drag and poke a scene live in the browser, or replay a run's
    /// folder (prints the page's address; Ctrl-C stops it).
    View(view::ViewArgs),
}

/// Runs the parsed subcommand.
pub fn dispatch(cli: &Cli) -> anyhow::Result<()> {
    match &cli.command {
        Command::Run(a) => run::run(a, &cli.global),
        Command::Voxelize(a) => voxelize::run(a, &cli.global),
        Command::Check(a) => check::run(a, &cli.global),
        Command::Init(a) => init::run(a, &cli.global),
        Command::View(a) => view::run(a, &cli.global),
        Command::Experiment(a) => {
            let out = cli
                .global
                .out
                .clone()
                .unwrap_or_else(|| "out/experiments".into());
            experiment::run(a, &out, cli.global.chatty(), cli.global.limits())
        }
    }
}
