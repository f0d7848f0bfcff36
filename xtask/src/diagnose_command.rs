//! `cargo xtask diagnose`: compare a model with a bundle, see where it
//! fails, learn which effect is missing, and (with `--add-recommended`)
//! add it and watch the error fall. A thin wrapper over `needle-diagnose`;
//! trials with camera frames and no `markers.csv` are tracked first
//! (`needle-vision`).

use std::path::PathBuf;

use clap::Args;
use needle_data::{BundleError, read_bundle};
use needle_diagnose::{DiagnoseOptions, ModelSpec, diagnose_campaign, write_outputs};

use crate::camera::track_untracked;
use crate::diagnosis_report::{add_sections, print_ladder};
use crate::output::OutputFolder;
use crate::report::{Report, escape};

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
    /// At most this many camera frames of each trial enter the fit (0: all).
    #[arg(long, default_value_t = DiagnoseOptions::default().frames_per_trial)]
    frames_per_trial: usize,
    /// Model mesh: elements this many times smaller than the marker
    /// spacing (rerun with a larger value to check mesh convergence).
    #[arg(long, default_value_t = DiagnoseOptions::default().refinement)]
    refinement: usize,
    /// The `out_of_plane` slab: elements this many times smaller than the
    /// marker spacing in the plane.
    #[arg(long, default_value_t = DiagnoseOptions::default().slab_refinement)]
    slab_refinement: usize,
    /// Radius of the needle (m; the paper's 17 gauge needle: 0.000735).
    /// The `out_of_plane` slab reads the needle's drag on its surface; 0
    /// reads it on the axis.
    #[arg(long, default_value_t = DiagnoseOptions::default().needle_radius)]
    needle_radius: f64,
    /// Grade the `out_of_plane` slab towards the needles' lines and
    /// entries (about twice the slab's cost).
    #[arg(long)]
    slab_needle_grading: bool,
    /// Output folder (must not exist); default: a new folder under `out/`.
    #[arg(long)]
    out: Option<PathBuf>,
}

/// Makes faer's factorisations and solves single-threaded for the rest of
/// the process. The diagnosis already runs its fits, finite-difference
/// columns and candidate refits in parallel with rayon; faer's own threads
/// inside them oversubscribe the cores and spin at barriers (13% less CPU
/// on the quick campaign's diagnosis without them).
pub fn sequential_linear_algebra() {
    faer::set_global_parallelism(faer::Par::Seq);
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
        frames_per_trial: args.frames_per_trial,
        refinement: args.refinement,
        slab_refinement: args.slab_refinement,
        needle_radius: args.needle_radius,
        slab_needle_grading: args.slab_needle_grading,
        ..DiagnoseOptions::default()
    };
    options.validate().map_err(|e| e.to_string())?;
    let mut bundle = read_bundle(&args.bundle).map_err(|e| match e {
        BundleError::Invalid { report } => format!("{report}"),
        other => other.to_string(),
    })?;
    let from_frames = track_untracked(&mut bundle)?;
    sequential_linear_algebra();
    let result =
        diagnose_campaign(&bundle.campaign, &model, &options).map_err(|e| e.to_string())?;
    write_outputs(&result, &folder.file("")).map_err(|e| e.to_string())?;

    print_ladder(&result);
    println!("noise: {}", result.diagnosis.noise);
    let mut report = Report::default();
    if !from_frames.is_empty() {
        let lines: Vec<String> = from_frames.iter().map(|l| escape(l)).collect();
        report.section(
            "Trials tracked from their camera frames",
            &format!(
                "These trials have frames and no <code>markers.csv</code>; their markers were \
                 tracked (<code>needle_vision::track_untracked_trials</code>) and weighed like \
                 any marker row without <code>sx,sy</code>.<br>{}",
                lines.join("<br>")
            ),
            &[],
        );
    }
    add_sections(&mut report, &result, "1.")?;
    folder.write("report.html", &report.to_html("needle diagnosis"))?;
    let finished = folder.finish()?;
    println!(
        "verdict: {:?}; outputs in {}",
        result.diagnosis.verdict,
        finished.display()
    );
    Ok(())
}
