//! The project's task runner: `cargo xtask <command>`.
//!
//! A thin orchestrator over the library crates (in the style of
//! rust-analyzer's xtask): argument parsing, output folders, progress and the
//! HTML report live here; every computation lives in a library crate.
//!
//! - `cargo xtask pipeline`: the main job on the built-in default experiment.
//! - `cargo xtask synth --scenario FILE --out DIR`: the truth world writes a bundle.
//! - `cargo xtask validate --bundle DIR`: check a measurement bundle.
//! - `cargo xtask track ...`: track a trial's camera frames into `markers.csv`.
//! - `cargo xtask diagnose --bundle DIR ...`: the diagnosis loop.

mod bundle_commands;
mod camera;
mod diagnose_command;
mod diagnosis_report;
mod output;
mod pipeline;
mod plot;
mod report;
mod synth_command;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "cargo xtask",
    about = "needle: pipeline and developer commands"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the end-to-end pipeline on the built-in default experiment.
    Pipeline(pipeline::PipelineArgs),
    /// Generate a measurement bundle (and its ground truth) from a scenario.
    Synth(synth_command::SynthArgs),
    /// Check a measurement bundle and print every problem with its file and line.
    Validate(bundle_commands::ValidateArgs),
    /// Track a trial's camera frames into a `markers.csv` of format 1.
    Track(bundle_commands::TrackArgs),
    /// Fit a model to a bundle, find the missing effect, and show the error ladder.
    Diagnose(diagnose_command::DiagnoseArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Pipeline(args) => pipeline::run(&args),
        Command::Validate(args) => bundle_commands::validate(&args),
        Command::Track(args) => bundle_commands::track(&args),
        Command::Diagnose(args) => diagnose_command::run(&args),
        Command::Synth(args) => synth_command::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error}");
            ExitCode::FAILURE
        }
    }
}
