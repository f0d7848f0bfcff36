//! `cargo xtask synth`: run the truth world on a scenario file and write
//! the measurement bundle and, outside it, the ground truth.

use std::path::PathBuf;

use clap::Args;
use needle_synth::{Scenario, generate, load_scenario};

/// Options of `cargo xtask synth`.
#[derive(Args)]
pub struct SynthArgs {
    /// Scenario file (RON, see `fixtures/scenarios/`); default: the paper default.
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// The bundle folder to write (must not exist).
    #[arg(long)]
    out: PathBuf,
    /// The ground truth file (must not exist, outside the bundle);
    /// default: `<out>.truth.ron` beside the bundle.
    #[arg(long)]
    truth: Option<PathBuf>,
}

/// Generates the campaign.
pub fn run(args: &SynthArgs) -> Result<(), String> {
    let scenario = match &args.scenario {
        Some(path) => load_scenario(path).map_err(|e| e.to_string())?,
        None => Scenario::paper_default(),
    };
    let truth = args.truth.clone().unwrap_or_else(|| {
        let mut name = args.out.file_name().unwrap_or_default().to_os_string();
        name.push(".truth.ron");
        args.out.with_file_name(name)
    });
    let summary = generate(&scenario, &args.out, &truth, |stage| {
        eprintln!("truth world: {stage:?}")
    })
    .map_err(|e| e.to_string())?;
    println!(
        "{} trials, {} marker rows, {} tool rows in {:.1} s; bundle {}, truth {}",
        summary.trials,
        summary.marker_rows,
        summary.tool_rows,
        summary.seconds,
        args.out.display(),
        truth.display()
    );
    Ok(())
}
