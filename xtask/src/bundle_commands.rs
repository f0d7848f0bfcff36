//! `cargo xtask validate` and `cargo xtask track`: bundle checks and marker
//! tracking, thin wrappers over `needle-data` and `needle-vision`.

use std::path::PathBuf;

use clap::Args;
use needle_data::{BundleError, read_bundle, validate_bundle};
use needle_vision::{Calibration, TrackFramesOptions, track_frames_to_csv};

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
    /// Camera calibration (RON, as written by `needle_vision::Calibration::save`).
    #[arg(long)]
    calibration: PathBuf,
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
    let calibration = Calibration::load(&args.calibration).map_err(|e| e.to_string())?;
    let tracked = track_frames_to_csv(
        &bundle.frames_dir(&args.trial),
        &calibration,
        bundle.campaign.markers_rest.as_slice(),
        &args.out,
        &TrackFramesOptions::default(),
    )
    .map_err(|e| e.to_string())?;
    println!(
        "tracked {} marker positions into {}; {} marker-frames lost",
        tracked.observations.len(),
        args.out.display(),
        tracked.lost.len()
    );
    for lost in tracked.lost.iter().take(20) {
        println!("  lost: {lost:?}");
    }
    Ok(())
}
