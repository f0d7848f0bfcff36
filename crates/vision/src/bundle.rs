//! The camera side of a measurement bundle: calibrate from its
//! `calibration/` folder, track a trial's `frames/`, and give every trial
//! that has frames but no `markers.csv` the tracks of its frames.
//!
//! Format 1 lets a lab hand over raw frames instead of tracks ("the
//! pipeline then calibrates and tracks itself"), so whatever reads a
//! bundle for its markers (identification, diagnosis) must track those
//! trials first or it would fit them as force-only without saying so.
//!
//! A frame file carries a number, not a time. Frame $k$ is at $k / r$,
//! the rate $r$ taken, in this order, from the trial's own `markers.csv`
//! (frame number over time at its last frame), from any other trial's, or the paper's
//! camera (30 Hz); [`FrameRate`] says which.

use std::path::Path;

use nalgebra::Vector3;
use needle_data::{LoadedBundle, MarkerObservation, MarkerTrack, read_calibration_target};

use crate::{
    Calibration, DotGrid, FixedParameters, GreyFrame, Pose, SearchPolicy, TrackFramesOptions,
    TrackOptions, TrackedFrames, VisionError, calibrate_dot_grid, track_frames,
};

/// Blur margin (px) left around each calibration dot by the detector.
const DOT_BLUR_MARGIN: usize = 4;
/// Passes of the circle-centre perspective bias correction.
const BIAS_ITERATIONS: usize = 3;
/// The paper's camera rate (Hz), taken when no `markers.csv` gives one.
pub const DEFAULT_FRAME_RATE: f64 = 30.0;
/// Search radius (px) of the tracker between consecutive stored frames:
/// a bundle may keep only every n-th camera frame, so markers can move
/// several pixels between two of them.
const SEARCH_RADIUS: usize = 16;

/// The camera calibration from the bundle's `calibration/` folder (`None`
/// when it has none): the camera from every view of the dot grid, the top
/// face's pose from the view whose target lies on the face.
pub fn calibrate_from_bundle(root: &Path) -> Result<Option<Calibration>, VisionError> {
    let folder = root.join("calibration");
    let target = read_calibration_target(root).map_err(|source| VisionError::Bundle {
        context: folder.display().to_string(),
        source,
    })?;
    let Some(target) = target else {
        return Ok(None);
    };
    let images = target
        .images
        .iter()
        .map(|name| GreyFrame::read_png(&folder.join(name)))
        .collect::<Result<Vec<_>, _>>()?;
    let grid = DotGrid {
        columns: target.columns,
        rows: target.rows,
        pitch: target.pitch,
        dot_diameter: target.dot_diameter,
    };
    let fit = calibrate_dot_grid(
        &images,
        &grid,
        DOT_BLUR_MARGIN,
        &FixedParameters::default(),
        BIAS_ITERATIONS,
    )
    .map_err(|e| VisionError::Calibration(format!("{}: {e}", folder.display())))?;
    let view = fit.poses.get(target.face_view).ok_or_else(|| {
        VisionError::Calibration(format!(
            "{}: face_view {} but only {} views",
            folder.display(),
            target.face_view,
            fit.poses.len()
        ))
    })?;
    // Dot (0, 0) of the face view sits at `face_origin` on the face, so the
    // face frame is the target frame shifted back by it.
    let rotation = view.rotation_matrix();
    let origin = Vector3::new(target.face_origin.0, target.face_origin.1, 0.0);
    let face_pose =
        Pose::from_rotation_translation(&rotation, view.translation_vector() - rotation * origin);
    let (width, height) = images
        .first()
        .map(|f| (f.width as u32, f.height as u32))
        .unwrap_or_default();
    Ok(Some(Calibration {
        width,
        height,
        camera: fit.camera,
        face_pose,
        reprojection_rms: fit.reprojection_rms,
    }))
}

/// The camera rate a trial's frame numbers are read with, and where it
/// came from.
#[derive(Debug, Clone, PartialEq)]
pub enum FrameRate {
    /// From the trial's own `markers.csv` (Hz).
    OwnTrack(f64),
    /// From the `markers.csv` of another trial of the bundle (Hz).
    OtherTrial {
        /// The rate (Hz).
        rate: f64,
        /// The trial it came from.
        trial: String,
    },
    /// No `markers.csv` in the bundle gives one: [`DEFAULT_FRAME_RATE`].
    Assumed(f64),
}

impl FrameRate {
    /// The rate (Hz).
    pub fn hz(&self) -> f64 {
        match self {
            FrameRate::OwnTrack(rate) | FrameRate::Assumed(rate) => *rate,
            FrameRate::OtherTrial { rate, .. } => *rate,
        }
    }
}

impl std::fmt::Display for FrameRate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FrameRate::OwnTrack(rate) => write!(f, "{rate:.3} Hz from its markers.csv"),
            FrameRate::OtherTrial { rate, trial } => {
                write!(f, "{rate:.3} Hz from trial {trial}'s markers.csv")
            }
            FrameRate::Assumed(rate) => {
                write!(f, "{rate:.3} Hz assumed (no markers.csv gives a rate)")
            }
        }
    }
}

/// Frame number over time of the last frame, if `track` has one after
/// the start (the last, since times are written rounded: 0.033333 s for
/// frame 1 at 30 Hz).
fn rate_of(track: &MarkerTrack) -> Option<f64> {
    track
        .frames()
        .filter(|f| f.frame > 0 && f.t > 0.0)
        .last()
        .map(|f| f.frame as f64 / f.t)
        .filter(|rate| rate.is_finite() && *rate > 0.0)
}

/// The camera rate for trial `id` (see the module's doc).
pub fn frame_rate(bundle: &LoadedBundle, id: &str) -> FrameRate {
    if let Some(rate) = bundle
        .trial(id)
        .and_then(|t| t.markers.as_ref())
        .and_then(rate_of)
    {
        return FrameRate::OwnTrack(rate);
    }
    bundle
        .campaign
        .trials
        .iter()
        .find_map(|t| {
            let rate = rate_of(t.markers.as_ref()?)?;
            Some(FrameRate::OtherTrial {
                rate,
                trial: t.trial.id.clone(),
            })
        })
        .unwrap_or(FrameRate::Assumed(DEFAULT_FRAME_RATE))
}

/// Tracks every marker of `markers_rest.csv` through the frames of trial
/// `id`, reading frame numbers at `rate`.
pub fn track_trial(
    bundle: &LoadedBundle,
    id: &str,
    calibration: &Calibration,
    rate: &FrameRate,
) -> Result<TrackedFrames, VisionError> {
    let options = TrackFramesOptions {
        frame_rate: rate.hz(),
        track: TrackOptions {
            search_radius: SEARCH_RADIUS,
            search: SearchPolicy::Always,
            ..TrackOptions::default()
        },
        ..TrackFramesOptions::default()
    };
    track_frames(
        &bundle.frames_dir(id),
        calibration,
        bundle.campaign.markers_rest.as_slice(),
        &options,
    )
}

/// One trial whose tracks now come from its frames.
#[derive(Debug, Clone)]
pub struct TrackedTrial {
    /// The trial's id.
    pub id: String,
    /// Frames tracked.
    pub frames: usize,
    /// Marker rows tracked.
    pub rows: usize,
    /// Marker-frames without a row (lost, occluded, out of frame).
    pub lost: usize,
    /// The rate its frame numbers were read with.
    pub rate: FrameRate,
}

/// What [`track_untracked_trials`] did.
#[derive(Debug, Clone, Default)]
pub struct FromFrames {
    /// The calibration used, if any trial needed one.
    pub calibration: Option<Calibration>,
    /// Trials given the tracks of their frames.
    pub tracked: Vec<TrackedTrial>,
    /// Trials with frames and no `markers.csv` that could not be tracked
    /// because the bundle has no `calibration/` folder: they stay
    /// force-only.
    pub uncalibrated: Vec<String>,
}

impl FromFrames {
    /// One line per trial, for a run's log.
    pub fn summary(&self) -> Vec<String> {
        let mut lines = Vec::new();
        if let Some(calibration) = &self.calibration {
            lines.push(format!(
                "camera calibrated from calibration/ (reprojection RMS {:.4} px)",
                calibration.reprojection_rms
            ));
        }
        for t in &self.tracked {
            lines.push(format!(
                "trial {}: no markers.csv; {} rows tracked from its {} frames ({} marker-frames lost), frame numbers read at {}",
                t.id, t.rows, t.frames, t.lost, t.rate
            ));
        }
        for id in &self.uncalibrated {
            lines.push(format!(
                "trial {id}: frames but no markers.csv, and the bundle has no calibration/ folder: not tracked, its markers are not used"
            ));
        }
        lines
    }
}

/// Gives every trial of `bundle` that has camera frames but no
/// `markers.csv` the tracks of its frames (in memory: nothing is written
/// to the bundle). Calibrates only if some trial needs it.
///
/// The rows carry no `sx,sy`: they are measurements of the markers like
/// any `markers.csv` row without them, to be weighed by the bundle's
/// stated marker noise (or one estimated from the data). The tracker's own
/// standard deviation counts the image noise only, not the calibration,
/// the painted dots or the surface they sit on: on the truth world's
/// noise-free rendered frames it is a fraction of a micrometre, and the
/// quick campaign's one probe tracked from its 6 frames and weighed by it
/// pulled the diagnosis's Poisson's ratio to 0.379 and ended its ladder
/// `Unexplained` at marker chi2/dof 5.6. `cargo xtask track` still writes
/// it, as information.
pub fn track_untracked_trials(bundle: &mut LoadedBundle) -> Result<FromFrames, VisionError> {
    let untracked: Vec<String> = bundle
        .campaign
        .trials
        .iter()
        .filter(|t| t.markers.is_none() && !t.frames.is_empty())
        .map(|t| t.trial.id.clone())
        .collect();
    let mut out = FromFrames::default();
    if untracked.is_empty() {
        return Ok(out);
    }
    let Some(calibration) = calibrate_from_bundle(&bundle.root)? else {
        out.uncalibrated = untracked;
        return Ok(out);
    };
    // Rates first: a trial tracked below must not lend its rate, which is
    // itself borrowed or assumed, to the next.
    let rates: Vec<FrameRate> = untracked.iter().map(|id| frame_rate(bundle, id)).collect();
    for (id, rate) in untracked.into_iter().zip(rates) {
        let tracked = track_trial(bundle, &id, &calibration, &rate)?;
        let rows: Vec<MarkerObservation> = tracked
            .observations
            .into_iter()
            .map(|row| MarkerObservation { sigma: None, ..row })
            .collect();
        let track =
            MarkerTrack::from_observations(&rows).map_err(|source| VisionError::Bundle {
                context: format!("the tracks of trial {id}"),
                source,
            })?;
        let trial = bundle
            .campaign
            .trials
            .iter_mut()
            .find(|t| t.trial.id == id)
            .expect("the id was taken from the bundle's trials");
        out.tracked.push(TrackedTrial {
            frames: trial.frames.len(),
            rows: rows.len(),
            lost: tracked.lost.len(),
            rate,
            id,
        });
        trial.markers = Some(track);
    }
    out.calibration = Some(calibration);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use needle_data::{
        Campaign, Face, MarkerObservation, Phantom, Trial, TrialData, TrialKind, ValidationReport,
    };

    use super::*;

    fn trial(id: &str, track: Option<(u64, f64)>) -> TrialData {
        let mut data = TrialData::new(Trial {
            id: id.into(),
            kind: TrialKind::Needle,
            velocity: 1e-3,
            day: 0.0,
        });
        // Frames 0 and `last`, the last written at time `t` (rounded as
        // a bundle writes it).
        data.markers = track.map(|(last, t)| {
            let mut frames = vec![(0, 0.0)];
            if last > 0 {
                frames.push((last, t));
            }
            let rows: Vec<MarkerObservation> = frames
                .into_iter()
                .map(|(frame, t)| MarkerObservation {
                    frame,
                    t,
                    id: 0,
                    x: 0.0,
                    y: 0.0,
                    sigma: None,
                })
                .collect();
            MarkerTrack::from_observations(&rows).unwrap()
        });
        data
    }

    fn bundle(trials: Vec<TrialData>) -> LoadedBundle {
        let phantom = Phantom {
            width: 0.075,
            depth: 0.075,
            thickness: 0.0075,
            fixed: vec![Face::Back],
        };
        let mut campaign = Campaign::new("rates", phantom);
        campaign.trials = trials;
        LoadedBundle {
            root: "rates".into(),
            campaign,
            warnings: ValidationReport {
                root: "rates".into(),
                issues: Vec::new(),
            },
        }
    }

    #[test]
    fn frame_numbers_are_read_at_the_first_rate_a_track_gives() {
        let b = bundle(vec![
            trial("a", None),
            trial("b", Some((1500, 50.0))),
            trial("c", Some((1000, 40.0))),
        ]);
        assert_eq!(frame_rate(&b, "c"), FrameRate::OwnTrack(25.0));
        assert_eq!(
            frame_rate(&b, "a"),
            FrameRate::OtherTrial {
                rate: 30.0,
                trial: "b".into()
            }
        );
        // The last frame is read, not the first after the start: frame 1
        // at 0.033333 s would give 30.0003 Hz.
        let rounded = bundle(vec![trial("d", Some((1, 0.033333)))]);
        assert!((frame_rate(&rounded, "d").hz() - 30.0003).abs() < 1e-4);
        // A track of the first frame alone gives no rate.
        let none = bundle(vec![trial("a", None), trial("e", Some((0, 0.0)))]);
        assert_eq!(
            frame_rate(&none, "a"),
            FrameRate::Assumed(DEFAULT_FRAME_RATE)
        );
        assert!(frame_rate(&none, "a").to_string().contains("assumed"));
    }
}
