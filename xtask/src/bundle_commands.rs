//! `cargo xtask validate` and `cargo xtask track`: bundle checks and marker
//! tracking, thin wrappers over `needle-data` and `needle-vision`.

use std::path::PathBuf;

use clap::Args;
use needle_data::{BundleError, WriteOptions, read_bundle, validate_bundle, write_markers_csv};
use needle_vision::{Calibration, calibrate_from_bundle, frame_rate, track_trial};

/// Options of `cargo xtask validate`.
#[derive(Args)]
pub struct ValidateArgs {
    /// The bundle folder to check.
    #[arg(long)]
    bundle: PathBuf,
}

/// Validates a whole bundle and prints every problem found.
pub fn validate(args: &ValidateArgs) -> Result<(), String> {
    let report = validate_bundle(&args.bundle);
    println!("{report}");
    if report.has_errors() {
        Err(format!("{} is not a valid bundle", args.bundle.display()))
    } else {
        Ok(())
    }
}

/// Options of `cargo xtask track`.
#[derive(Args)]
pub struct TrackArgs {
    /// The bundle whose trial has camera frames (`trials/ID/frames/`).
    #[arg(long)]
    bundle: PathBuf,
    /// The trial to track.
    #[arg(long)]
    trial: String,
    /// Camera calibration (RON, as written by `needle_vision::Calibration::save`);
    /// default: calibrate from the bundle's `calibration/` folder.
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// The `markers.csv` to write (format 1, with `sx,sy`); must not exist.
    #[arg(long)]
    out: PathBuf,
}

/// Tracks every marker of `markers_rest.csv` through a trial's frames.
pub fn track(args: &TrackArgs) -> Result<(), String> {
    let bundle = read_bundle(&args.bundle).map_err(|e| match e {
        BundleError::Invalid { report } => format!("{report}"),
        other => other.to_string(),
    })?;
    if bundle.trial(&args.trial).is_none() {
        return Err(format!(
            "{}: the manifest lists no trial {:?}",
            args.bundle.display(),
            args.trial
        ));
    }
    let calibration = match &args.calibration {
        Some(path) => Calibration::load(path).map_err(|e| e.to_string())?,
        None => calibrate_from_bundle(&bundle.root)
            .map_err(|e| e.to_string())?
            .ok_or_else(|| {
                format!(
                    "{}: no --calibration given and the bundle has no calibration/ folder",
                    args.bundle.display()
                )
            })?,
    };
    let rate = frame_rate(&bundle, &args.trial);
    let tracked =
        track_trial(&bundle, &args.trial, &calibration, &rate).map_err(|e| e.to_string())?;
    write_markers_csv(&args.out, &tracked.observations, WriteOptions::default())
        .map_err(|e| e.to_string())?;
    println!(
        "tracked {} marker positions into {}; {} marker-frames lost; frame numbers read at {rate}",
        tracked.observations.len(),
        args.out.display(),
        tracked.lost.len()
    );
    for lost in tracked.lost.iter().take(20) {
        println!("  lost: {lost:?}");
    }
    Ok(())
}
