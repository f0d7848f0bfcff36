//! The camera side of a bundle: calibrate from its `calibration/` folder
//! and track the trials that carry camera frames. Used by the pipeline and
//! by `cargo xtask track`; the work is `needle-vision`'s, this only reads
//! the bundle's files into it.

use std::path::Path;

use nalgebra::Vector3;
use needle_data::{LoadedBundle, read_calibration_target};
use needle_vision::{
    Calibration, DotGrid, FixedParameters, GreyFrame, Pose, SearchPolicy, TrackFramesOptions,
    TrackOptions, TrackedFrames, calibrate_dot_grid, track_frames,
};

/// Blur margin (px) left around each calibration dot by the detector.
const DOT_BLUR_MARGIN: usize = 4;
/// Passes of the circle-centre perspective bias correction.
const BIAS_ITERATIONS: usize = 3;
/// Frame rate assumed when no `markers.csv` row gives one (Hz).
const DEFAULT_FRAME_RATE: f64 = 30.0;
/// Search radius (px) of the tracker between consecutive stored frames:
/// a bundle may keep only every n-th camera frame, so markers can move
/// several pixels between two of them.
const SEARCH_RADIUS: usize = 16;

/// The camera calibration from the bundle's `calibration/` folder (`None`
/// when it has none): the camera from every view of the dot grid, the top
/// face's pose from the view whose target lies on the face.
pub fn calibrate_from_bundle(root: &Path) -> Result<Option<Calibration>, String> {
    let Some(target) = read_calibration_target(root).map_err(|e| e.to_string())? else {
        return Ok(None);
    };
    let folder = root.join("calibration");
    let images = target
        .images
        .iter()
        .map(|name| GreyFrame::read_png(&folder.join(name)).map_err(|e| e.to_string()))
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
    .map_err(|e| format!("{}: {e}", folder.display()))?;
    let view = fit.poses.get(target.face_view).ok_or_else(|| {
        format!(
            "{}: face_view {} but only {} views",
            folder.display(),
            target.face_view,
            fit.poses.len()
        )
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

/// The camera frame rate of a trial, from its `markers.csv` rows (frame
/// number over time), else 30 Hz.
fn frame_rate(bundle: &LoadedBundle, id: &str) -> f64 {
    bundle
        .trial(id)
        .and_then(|t| t.markers.as_ref())
        .and_then(|track| track.frames().find(|f| f.frame > 0 && f.t > 0.0))
        .map_or(DEFAULT_FRAME_RATE, |f| f.frame as f64 / f.t)
}

/// Tracks every marker of `markers_rest.csv` through the frames of trial `id`.
pub fn track_trial(
    bundle: &LoadedBundle,
    id: &str,
    calibration: &Calibration,
) -> Result<TrackedFrames, String> {
    let options = TrackFramesOptions {
        frame_rate: frame_rate(bundle, id),
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
    .map_err(|e| format!("tracking trial {id}: {e}"))
}
