//! Rendering the camera frames of a trial and the calibration folder through
//! the true camera ([`crate::camera`]).
//!
//! Frames are rendered by `needle_vision::render_frame` with the markers at
//! their true 3-D positions (rest position plus displacement, the top-face
//! lift included in the slab truth) and written as `NNNNNN.png`, numbered
//! like the frame's rows in `markers.csv`. The files are rendered into a
//! staging folder beside the bundle, which the bundle writer copies from and
//! which is removed afterwards. Every frame has its own noise seed, mixed
//! from the scenario seed, the trial's place in the campaign and the frame
//! number, so a frame does not depend on which other frames are rendered.

use std::path::{Path, PathBuf};

use nalgebra::{Rotation3, Vector2, Vector3};
use needle_data::{CalibrationTarget, TrialData};
use needle_vision::{GreyFrame, Pose, RenderOptions, VisionError, render_frame};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::camera::{CameraFrames, TrueCamera, face_point};
use crate::error::SynthError;
use crate::scenario::Scenario;

/// Everything true about the camera of a campaign with frames, for the
/// ground truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraTruth {
    /// What a perfect calibration finds (frame size, camera, face pose).
    pub calibration: needle_vision::Calibration,
    /// The camera the trial frames were rendered with.
    pub experiment_camera: needle_vision::Camera,
    /// The calibration target as written to `calibration/target.ron`.
    pub target: CalibrationTarget,
    /// The true pose of the target in each calibration image.
    pub view_poses: Vec<Pose>,
}

/// Tilted calibration views: rotation vector (rad) of the target, and the
/// camera-frame position of its centre as multiples of the target's span
/// (x, y) and as a distance in units of the face distance (z).
const TILTED_VIEWS: [([f64; 3], [f64; 3]); crate::camera::MAX_TILTED_VIEWS] = [
    ([0.35, 0.0, 0.05], [-0.65, -0.3, 1.05]),
    ([-0.35, 0.1, -0.05], [0.65, 0.3, 1.05]),
    ([0.1, 0.35, 0.1], [0.65, -0.3, 1.0]),
    ([-0.1, -0.35, -0.1], [-0.65, 0.3, 1.0]),
    ([0.25, -0.25, 0.3], [0.0, 0.0, 1.15]),
    ([-0.25, 0.25, -0.3], [0.0, 0.0, 0.95]),
];

/// Dots per side of the calibration target.
const TARGET_DOTS: usize = 9;

/// The calibration target of a scenario: a 9 x 9 dot grid spanning at most
/// 85 % of the shorter side of the top face (pitch rounded down to 0.5 mm),
/// dots 0.4 pitch across, centred on the face in the face view.
pub fn calibration_target(s: &Scenario, views: usize) -> CalibrationTarget {
    let p = &s.phantom;
    let step = 0.0005;
    let pitch =
        ((0.85 * p.width.min(p.depth) / (TARGET_DOTS - 1) as f64 / step).floor() * step).max(step);
    let span = pitch * (TARGET_DOTS - 1) as f64;
    CalibrationTarget {
        columns: TARGET_DOTS,
        rows: TARGET_DOTS,
        pitch,
        dot_diameter: 0.4 * pitch,
        images: (0..views).map(|k| format!("view-{k:02}.png")).collect(),
        face_view: 0,
        face_origin: ((p.width - span) / 2.0, (p.depth - span) / 2.0),
    }
}

/// The true target pose of each calibration view: first the target lying
/// on the top face, then `tilted` tilted views.
pub fn view_poses(camera: &TrueCamera, target: &CalibrationTarget, tilted: usize) -> Vec<Pose> {
    let face = &camera.calibration.face_pose;
    let rotation = face.rotation_matrix();
    let origin = Vector3::new(target.face_origin.0, target.face_origin.1, 0.0);
    let mut poses = vec![Pose::from_rotation_translation(
        &rotation,
        face.translation_vector() + rotation * origin,
    )];
    let span = target.pitch * (target.columns - 1) as f64;
    let centre = Vector3::new(span / 2.0, span / 2.0, 0.0);
    let distance = crate::camera::axial_distance(face);
    for (w, at) in TILTED_VIEWS.iter().take(tilted) {
        let rotation = Rotation3::new(Vector3::from(*w));
        let position = Vector3::new(at[0] * span, at[1] * span, at[2] * distance);
        poses.push(Pose::from_rotation_translation(
            &rotation,
            position - rotation * centre,
        ));
    }
    poses
}

/// The target's dot centres on its plane, row-major.
fn target_dots(target: &CalibrationTarget) -> Vec<Vector3<f64>> {
    (0..target.rows)
        .flat_map(|j| {
            (0..target.columns)
                .map(move |i| Vector3::new(i as f64 * target.pitch, j as f64 * target.pitch, 0.0))
        })
        .collect()
}

/// Whether every dot of every view lies inside the frame, a dot diameter
/// from its edge.
pub(crate) fn views_fit(camera: &TrueCamera, target: &CalibrationTarget, poses: &[Pose]) -> bool {
    let c = &camera.calibration;
    let margin = 2.0 * target.dot_diameter / target.pitch; // in pitches, generous
    let dots = target_dots(target);
    poses.iter().all(|pose| {
        dots.iter().all(|d| {
            let pitch_px = c
                .camera
                .project(pose, &(d + Vector3::new(target.pitch, 0.0, 0.0)))
                .ok();
            match (c.camera.project(pose, d).ok(), pitch_px) {
                (Some(p), Some(q)) => {
                    let m = margin * (q - p).norm();
                    p.x >= m
                        && p.y >= m
                        && p.x <= c.width as f64 - 1.0 - m
                        && p.y <= c.height as f64 - 1.0 - m
                }
                _ => false,
            }
        })
    })
}

/// A noise seed for one rendered image from the scenario seed, a stream
/// (the trial's place in the campaign, or the calibration) and the image's
/// number: SplitMix64 finalisers chained over the three.
pub(crate) fn image_seed(seed: u64, stream: u64, number: u64) -> u64 {
    fn mix(mut z: u64) -> u64 {
        z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    mix(mix(mix(seed) ^ stream) ^ number)
}

/// The stream of the calibration images' seeds (trial streams count up
/// from zero).
const CALIBRATION_STREAM: u64 = u64::MAX - 1;

/// A folder beside the bundle where frames and calibration images are
/// rendered before the bundle writer copies them; removed when dropped.
pub(crate) struct Staging {
    path: PathBuf,
}

impl Staging {
    /// A new folder `.NAME.rendering-PID-N` beside `bundle_out`, `N` the
    /// first number whose folder does not exist: whatever is there already
    /// (another run's, or a user's) is left alone.
    pub fn beside(bundle_out: &Path) -> Result<Self, SynthError> {
        let name = bundle_out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "bundle".into());
        let io = |path: &Path, source| SynthError::Io {
            path: path.to_path_buf(),
            source,
        };
        let parent = bundle_out.parent().unwrap_or(Path::new(""));
        if !parent.as_os_str().is_empty() {
            std::fs::create_dir_all(parent).map_err(|source| io(parent, source))?;
        }
        let pid = std::process::id();
        for n in 0.. {
            let path = bundle_out.with_file_name(format!(".{name}.rendering-{pid}-{n}"));
            match std::fs::create_dir(&path) {
                Ok(()) => return Ok(Self { path }),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                Err(source) => return Err(io(&path, source)),
            }
        }
        unreachable!("some number names no folder yet")
    }

    /// The staging folder.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        // Best effort: a leftover staging folder is hidden and harmless.
        let _ = std::fs::remove_dir_all(&self.path);
    }
}

fn vision(what: String) -> impl FnOnce(VisionError) -> SynthError {
    move |e| SynthError::Render {
        what,
        reason: e.to_string(),
    }
}

/// Renders the frames `numbers` of one trial, each with the marker positions
/// `positions(number)` (bundle frame: x, y on the top face and the lift z),
/// into `dir`, and adds them to `trial`.
pub(crate) fn render_trial_frames(
    camera: &TrueCamera,
    options: &RenderOptions,
    seed: u64,
    stream: u64,
    numbers: &[u64],
    positions: impl Fn(u64) -> Vec<[f64; 3]> + Sync,
    dir: &Path,
    trial: &mut TrialData,
) -> Result<(), SynthError> {
    std::fs::create_dir_all(dir).map_err(|source| SynthError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let id = trial.trial.id.clone();
    let paths = numbers
        .par_iter()
        .map(|&number| {
            let markers: Vec<Vector3<f64>> =
                positions(number).into_iter().map(face_point).collect();
            let what = format!("frame {number} of {id}");
            let frame = render_frame(
                &camera.experiment_camera,
                &camera.calibration.face_pose,
                &markers,
                options,
                image_seed(seed, stream, number),
            )
            .map_err(vision(what.clone()))?;
            let path = dir.join(format!("{number:06}.png"));
            frame.write_png(&path).map_err(vision(what))?;
            Ok((number, path))
        })
        .collect::<Result<Vec<_>, SynthError>>()?;
    for (number, path) in paths {
        trial.add_frame_file(number, path)?;
    }
    Ok(())
}

/// Renders the calibration images and writes `target.ron` into `dir`;
/// returns the camera truth.
pub(crate) fn write_calibration(
    s: &Scenario,
    frames: &CameraFrames,
    camera: &TrueCamera,
    dir: &Path,
) -> Result<CameraTruth, SynthError> {
    let target = calibration_target(s, frames.tilted_views + 1);
    let poses = view_poses(camera, &target, frames.tilted_views);
    let options = RenderOptions {
        dot_diameter: target.dot_diameter,
        ..frames.render_options()
    };
    let dots = target_dots(&target);
    std::fs::create_dir_all(dir).map_err(|source| SynthError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    poses
        .par_iter()
        .zip(&target.images)
        .enumerate()
        .try_for_each(|(k, (pose, name))| {
            let what = format!("calibration image {name}");
            let image: GreyFrame = render_frame(
                &camera.calibration.camera,
                pose,
                &dots,
                &options,
                image_seed(s.seed, CALIBRATION_STREAM, k as u64),
            )
            .map_err(vision(what.clone()))?;
            image.write_png(&dir.join(name)).map_err(vision(what))
        })?;
    let text = ron::ser::to_string_pretty(
        &target,
        ron::ser::PrettyConfig::default().struct_names(true),
    )
    .expect("a target description always serialises");
    let path = dir.join(needle_data::layout::CALIBRATION_TARGET);
    std::fs::write(&path, text).map_err(|source| SynthError::Io { path, source })?;
    Ok(CameraTruth {
        calibration: camera.calibration.clone(),
        experiment_camera: camera.experiment_camera,
        target,
        view_poses: poses,
    })
}

/// The frame numbers rendered among `count` camera frames, one in `every`.
pub fn selected_frames(count: usize, every: usize) -> Vec<u64> {
    (0..count as u64).step_by(every.max(1)).collect()
}

/// Pixel of a bundle-frame marker position in the experiment camera (for
/// tests and checks).
pub fn marker_pixel(camera: &TrueCamera, position: [f64; 3]) -> Result<Vector2<f64>, SynthError> {
    camera
        .experiment_camera
        .project(&camera.calibration.face_pose, &face_point(position))
        .map_err(vision("a marker's pixel".into()))
}

#[cfg(test)]
mod tests {
    use super::Staging;

    #[test]
    fn a_staging_folder_is_new_and_leaves_what_was_there() {
        let dir = tempfile::tempdir().unwrap();
        let bundle = dir.path().join("not-yet/bundle");
        let first = Staging::beside(&bundle).unwrap();
        let kept = first.path().join("mine.txt");
        std::fs::write(&kept, "precious").unwrap();
        let second = Staging::beside(&bundle).unwrap();
        assert_ne!(first.path(), second.path());
        assert!(second.path().is_dir());
        assert_eq!(std::fs::read_to_string(&kept).unwrap(), "precious");
        assert!(first.path().starts_with(dir.path().join("not-yet")));
        let second_path = second.path().to_path_buf();
        drop(second);
        assert!(!second_path.exists(), "a staging folder goes with its run");
        assert!(kept.exists());
    }
}
