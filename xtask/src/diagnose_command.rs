//! `cargo xtask diagnose`: compare a model with a bundle, see where it
//! fails, learn which effect is missing, and (with `--add-recommended`)
//! add it and watch the error fall. A thin wrapper over `needle-diagnose`.

use std::path::PathBuf;

use clap::Args;
use needle_diagnose::{DiagnoseOptions, ModelSpec, diagnose, write_outputs};

use crate::output::OutputFolder;
use crate::report::Report;

/// Options of `cargo xtask diagnose`.
#[derive(Args)]
pub struct DiagnoseArgs {
    /// The measurement bundle (format 1).
    #[arg(long)]
    bundle: PathBuf,
    /// The model to fit: a RON file listing effect ids.
    #[arg(long, conflicts_with = "effects")]
    model: Option<PathBuf>,
    /// The model to fit, as comma-separated effect ids (default: the paper's baseline).
    #[arg(long, value_delimiter = ',')]
    effects: Option<Vec<String>>,
    /// Add the recommended effect, refit and diagnose again, until the
    /// residual is consistent with noise or unexplained.
    #[arg(long)]
    add_recommended: bool,
    /// Output folder (must not exist); default: a new folder under `out/`.
    #[arg(long)]
    out: Option<PathBuf>,
}

/// Runs the diagnosis and writes `diagnosis.ron`, `model.ron`, `ladder.csv`,
/// the residual tables and `report.html` into a fresh folder.
pub fn run(args: &DiagnoseArgs) -> Result<(), String> {
    let model = match (&args.model, &args.effects) {
        (Some(path), _) => ModelSpec::read(path).map_err(|e| e.to_string())?,
        (None, Some(ids)) => ModelSpec::from_ids(ids).map_err(|e| e.to_string())?,
        (None, None) => ModelSpec::baseline(),
    };
    let folder = OutputFolder::create(args.out.as_deref(), "diagnose")?;
    let options = DiagnoseOptions {
        add_recommended: args.add_recommended,
        ..DiagnoseOptions::default()
    };
    let result = diagnose(&args.bundle, &model, &options).map_err(|e| e.to_string())?;
    write_outputs(&result, &folder.file("")).map_err(|e| e.to_string())?;

    let header = [
        "step",
        "added",
        "parameters",
        "rms marker (m)",
        "rms force (N)",
        "chi2/dof marker",
        "chi2/dof force",
        "verdict",
    ];
    let rows: Vec<Vec<String>> = result
        .ladder
        .rows
        .iter()
        .map(|row| {
            vec![
                row.step.to_string(),
                row.added.clone().unwrap_or_else(|| "(baseline)".into()),
                row.parameters.to_string(),
                format!("{:.3e}", row.fit.rms_marker),
                format!("{:.3e}", row.fit.rms_force),
                format!("{:.2}", row.fit.chi2_marker),
                format!("{:.2}", row.fit.chi2_force),
                format!("{:?}", row.verdict),
            ]
        })
        .collect();
    println!("{}", header.join(" | "));
    for row in &rows {
        println!("{}", row.join(" | "));
    }
    let mut report = Report::default();
    report.section(
        "Diagnosis",
        &format!(
            "Bundle {}; final model {:?}; verdict <b>{:?}</b>. Candidates are ranked by a \
             score test and confirmed by refitting; an effect is named only when its \
             likelihood-ratio p-value is below {:.2e}.",
            result.diagnosis.bundle,
            result.diagnosis.model,
            result.diagnosis.verdict,
            result.diagnosis.threshold_p
        ),
        &[],
    );
    report.table("The error ladder", &header, &rows);
    folder.write("report.html", &report.to_html("needle diagnosis"))?;
    let finished = folder.finish()?;
    println!(
        "verdict: {:?}; outputs in {}",
        result.diagnosis.verdict,
        finished.display()
    );
    Ok(())
}
