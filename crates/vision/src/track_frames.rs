//! Tracking a folder of frames into `markers.csv` rows: the library side of
//! `cargo xtask track`.
//!
//! 1. Frames are the files `NNNNNN.png` of the folder, in frame-number order;
//!    frame `k` is at time `k / frame_rate`. Each must be 8- or 16-bit grey,
//!    of the calibration's size, and not flat.
//! 2. Acquisition, in the first frame: every rest marker is projected
//!    through the calibration; a model template (the dot rendered through the
//!    calibrated camera, so it carries the perspective and distortion of that
//!    spot and its reference is the projection of the dot's centre, not the
//!    centroid of its image) is searched for around the projection.
//! 3. Tracking: by default each marker's template is then cut from the first
//!    frame (the real appearance of the painted dot), and every frame is
//!    tracked from the marker's last position; a lost marker is searched for
//!    again in a wider window in the next frames (re-acquisition).
//! 4. Tracked pixels are rectified onto the top face; the tracking standard
//!    deviation is carried through the rectification Jacobian.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix2, Vector2, Vector3};
use needle_data::{MarkerObservation, MarkerRest, WriteOptions, write_markers_csv};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::{
    BitDepth, Calibration, GreyFrame, LostReason, MarkerTemplate, RenderOptions, SearchPolicy,
    TrackOptions, VisionError, render_ideal, track_marker,
};

/// A marker's pixel and its standard deviation (px), or why it was lost.
type PixelOutcome = Result<(Vector2<f64>, Vector2<f64>), LostReason>;

/// Where the templates tracked after the first frame come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum TemplateSource {
    /// Cut from the first frame around each acquired marker (real dot
    /// appearance; the template's noise adds to the frame's).
    FirstFrame,
    /// The rendered model dot used for acquisition (noise-free; assumes the
    /// painted dots are the discs of `dot_diameter`).
    Model,
}

/// Options of [`track_frames`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrackFramesOptions {
    /// Camera frame rate (Hz).
    pub frame_rate: f64,
    /// Diameter of the painted dots (m), for the model template.
    pub dot_diameter: f64,
    /// Defocus blur of the model template (px).
    pub blur_sigma: f64,
    /// Template half-width (px); the template is `2 h + 1` pixels square.
    pub template_half_width: usize,
    /// Search radius around the projected rest positions in the first frame
    /// and when re-acquiring a lost marker (px).
    pub acquisition_radius: usize,
    /// Frame-to-frame tracking options.
    pub track: TrackOptions,
    /// Template source after the first frame.
    pub template_source: TemplateSource,
    /// Smallest grey-level standard deviation of a whole frame.
    pub min_frame_contrast: f64,
}

impl Default for TrackFramesOptions {
    fn default() -> TrackFramesOptions {
        TrackFramesOptions {
            frame_rate: 30.0,
            dot_diameter: 0.002,
            blur_sigma: 1.0,
            template_half_width: 16,
            acquisition_radius: 15,
            track: TrackOptions::default(),
            template_source: TemplateSource::FirstFrame,
            min_frame_contrast: 3.0,
        }
    }
}

/// A marker that has no row in one frame, and why.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LostMarker {
    /// Frame number.
    pub frame: u64,
    /// Marker id.
    pub id: u32,
    /// Why.
    pub reason: LostReason,
}

/// The result of [`track_frames`].
#[derive(Debug, Clone, PartialEq)]
pub struct TrackedFrames {
    /// `markers.csv` rows, frame by frame, ids in rest order.
    pub observations: Vec<MarkerObservation>,
    /// Every (frame, marker) without a row.
    pub lost: Vec<LostMarker>,
}

/// The `NNNNNN.png` files of a folder, sorted by frame number.
pub fn list_frames(frames_dir: &Path) -> Result<Vec<(u64, PathBuf)>, VisionError> {
    let entries = std::fs::read_dir(frames_dir).map_err(|source| VisionError::Io {
        path: frames_dir.to_path_buf(),
        source,
    })?;
    let mut frames = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|source| VisionError::Io {
            path: frames_dir.to_path_buf(),
            source,
        })?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if let Some(stem) = name.strip_suffix(".png")
            && stem.len() == 6
            && stem.bytes().all(|b| b.is_ascii_digit())
            && let Ok(number) = stem.parse::<u64>()
        {
            frames.push((number, entry.path()));
        }
    }
    if frames.is_empty() {
        return Err(VisionError::NoFrames {
            path: frames_dir.to_path_buf(),
        });
    }
    frames.sort();
    Ok(frames)
}

/// Read a frame and check its size and contrast against the calibration.
pub fn read_checked_frame(
    path: &Path,
    calibration: &Calibration,
    min_contrast: f64,
) -> Result<GreyFrame, VisionError> {
    let frame = GreyFrame::read_png(path)?;
    if frame.width != calibration.width as usize || frame.height != calibration.height as usize {
        return Err(VisionError::FrameSize {
            path: path.to_path_buf(),
            found_width: frame.width as u32,
            found_height: frame.height as u32,
            width: calibration.width,
            height: calibration.height,
        });
    }
    let spread = frame.grey_level_spread();
    if spread < min_contrast {
        return Err(VisionError::LowContrast {
            path: path.to_path_buf(),
            found: spread,
            minimum: min_contrast,
        });
    }
    Ok(frame)
}

/// The model template of a marker at a top-face point: the dot rendered
/// through the calibrated camera into a crop around its projection.
pub fn model_template(
    calibration: &Calibration,
    point: Vector2<f64>,
    options: &TrackFramesOptions,
) -> Result<(MarkerTemplate, Vector2<f64>), VisionError> {
    let pixel = calibration.face_to_pixel(point)?;
    let half = options.template_half_width;
    // Margin for the spline prefilter and rounding of the crop position.
    let size = 2 * half + 2 * 8 + 1;
    let corner = pixel.map(f64::round) - Vector2::repeat(((size - 1) / 2) as f64);
    let mut camera = calibration.camera;
    camera.intrinsics.cx -= corner.x;
    camera.intrinsics.cy -= corner.y;
    let render = RenderOptions {
        width: size,
        height: size,
        dot_diameter: options.dot_diameter,
        background: 200.0,
        contrast: 150.0,
        blur_sigma: options.blur_sigma,
        illumination_gradient: [0.0; 2],
        read_noise_sigma: 0.0,
        electrons_per_grey: None,
        bit_depth: BitDepth::Sixteen,
    };
    let crop = render_ideal(
        &camera,
        &calibration.face_pose,
        &[Vector3::new(point.x, point.y, 0.0)],
        &render,
    )?;
    let template = MarkerTemplate::from_frame(&crop, pixel - corner, half)?;
    Ok((template, pixel))
}

/// Track the markers of a folder of frames; see the module documentation.
pub fn track_frames(
    frames_dir: &Path,
    calibration: &Calibration,
    rest: &[MarkerRest],
    options: &TrackFramesOptions,
) -> Result<TrackedFrames, VisionError> {
    calibration.validate()?;
    if !(options.frame_rate > 0.0 && options.frame_rate.is_finite()) {
        return Err(VisionError::InvalidParameter {
            field: "frame_rate",
            reason: format!("{} must be positive", options.frame_rate),
        });
    }
    let frames = list_frames(frames_dir)?;
    let acquire = TrackOptions {
        search_radius: options.acquisition_radius,
        search: SearchPolicy::Always,
        ..options.track.clone()
    };

    // Acquisition in the first frame with model templates.
    let (_, first_path) = &frames[0];
    let first = read_checked_frame(first_path, calibration, options.min_frame_contrast)?;
    let models: Vec<Option<(MarkerTemplate, Vector2<f64>)>> = rest
        .par_iter()
        .map(|m| model_template(calibration, Vector2::new(m.x, m.y), options).ok())
        .collect();
    // Each marker's pixel and standard deviation in the first frame.
    let acquired: Vec<PixelOutcome> = models
        .par_iter()
        .map(|model| match model {
            Some((template, predicted)) => {
                let outcome = track_marker(&first, template, *predicted, &acquire);
                outcome.position.map(|p| (p, outcome.standard_deviation))
            }
            None => Err(LostReason::OutOfFrame),
        })
        .collect();
    let templates: Vec<Option<MarkerTemplate>> = models
        .into_par_iter()
        .zip(acquired.par_iter())
        .map(
            |(model, found)| match (options.template_source, model, found) {
                (TemplateSource::Model, Some((template, _)), Ok(_)) => Some(template),
                (TemplateSource::FirstFrame, Some(_), Ok((position, _))) => {
                    MarkerTemplate::from_frame(&first, *position, options.template_half_width).ok()
                }
                _ => None,
            },
        )
        .collect();

    let mut result = TrackedFrames {
        observations: Vec::new(),
        lost: Vec::new(),
    };
    let mut last: Vec<Option<Vector2<f64>>> =
        acquired.iter().map(|a| a.ok().map(|(p, _)| p)).collect();
    let mut was_lost: Vec<bool> = vec![false; rest.len()];
    let record = |number: u64, outcomes: &[PixelOutcome], result: &mut TrackedFrames| {
        for (m, outcome) in rest.iter().zip(outcomes) {
            match outcome.and_then(|(pixel, std)| rectify(calibration, pixel, std)) {
                Ok((face, sigma)) => result.observations.push(MarkerObservation {
                    frame: number,
                    t: number as f64 / options.frame_rate,
                    id: m.id,
                    x: face.x,
                    y: face.y,
                    sigma: Some(sigma),
                }),
                Err(reason) => result.lost.push(LostMarker {
                    frame: number,
                    id: m.id,
                    reason,
                }),
            }
        }
    };
    // The first frame's rows come from the acquisition (a template cut
    // from that frame would match it with zero residual and say nothing
    // about the position's uncertainty).
    record(frames[0].0, &acquired, &mut result);
    for (number, path) in &frames[1..] {
        let frame = read_checked_frame(path, calibration, options.min_frame_contrast)?;
        let outcomes: Vec<PixelOutcome> = templates
            .par_iter()
            .zip(last.par_iter())
            .zip(was_lost.par_iter())
            .zip(acquired.par_iter())
            .map(|(((template, previous), lost), acquired)| {
                let (Some(template), Some(previous)) = (template, previous) else {
                    return Err(acquired.err().unwrap_or(LostReason::OutOfFrame));
                };
                let track_options = if *lost { &acquire } else { &options.track };
                let outcome = track_marker(&frame, template, *previous, track_options);
                outcome.position.map(|p| (p, outcome.standard_deviation))
            })
            .collect();
        for (i, outcome) in outcomes.iter().enumerate() {
            match outcome {
                Ok((pixel, _)) => {
                    last[i] = Some(*pixel);
                    was_lost[i] = false;
                }
                Err(_) => was_lost[i] = last[i].is_some(),
            }
        }
        record(*number, &outcomes, &mut result);
    }
    Ok(result)
}

fn rectify(
    calibration: &Calibration,
    pixel: Vector2<f64>,
    std: Vector2<f64>,
) -> Result<(Vector2<f64>, [f64; 2]), LostReason> {
    let face = calibration
        .pixel_to_face(pixel)
        .map_err(|_| LostReason::OutOfFrame)?;
    let jacobian = calibration
        .face_per_pixel(face)
        .map_err(|_| LostReason::OutOfFrame)?;
    let covariance =
        jacobian * Matrix2::from_diagonal(&std.component_mul(&std)) * jacobian.transpose();
    Ok((face, [covariance[(0, 0)].sqrt(), covariance[(1, 1)].sqrt()]))
}

/// [`track_frames`], then write the rows as `markers.csv` (format 1, with
/// `sx,sy`) at `output`, which must not exist yet.
pub fn track_frames_to_csv(
    frames_dir: &Path,
    calibration: &Calibration,
    rest: &[MarkerRest],
    output: &Path,
    options: &TrackFramesOptions,
) -> Result<TrackedFrames, VisionError> {
    let tracked = track_frames(frames_dir, calibration, rest, options)?;
    write_markers_csv(output, &tracked.observations, WriteOptions::default()).map_err(|e| {
        VisionError::Csv {
            path: output.to_path_buf(),
            reason: e.to_string(),
        }
    })?;
    Ok(tracked)
}
