//! Camera frames: the scenario section that asks for them, and the true
//! camera that films the top face and the calibration target.
//!
//! The true camera is the paper's (`needle_vision::Calibration::paper()`):
//! a 2056 x 1544 camera about 0.2 m above the top face with a mild barrel
//! distortion. Its face pose is the paper's, shifted so that the phantom's
//! centre sits where the paper phantom's does. The vision crate's face frame
//! has the top face as its plane $z = 0$ with x and y as in the bundle, and
//! its z axis points away from the camera, into the phantom: a marker lifted
//! by $u_z$ out of the top face is at face-frame $z = -u_z$.
//!
//! With `lens_distortion`, frames go through the camera model: the
//! experiment's camera has the radial coefficient
//! $k_1^{\text{exp}} = k_1^{\text{cal}} + k_1^{\text{face}}\,Z^2$, where
//! $k_1^{\text{face}}$ is the effect's coefficient (1/m²) and $Z$ the
//! distance from the camera to the top face along the optical axis. The
//! calibration images are taken with $k_1^{\text{cal}}$, so a calibration
//! misses the difference; rectifying with it moves a face point at
//! distance $\rho$ from the optical axis outward by about
//! $k_1^{\text{face}} \rho^3$, the effect's residual field about the
//! point where the optical axis meets the face (near the effect's `centre`
//! for the default phantom; frames do not use `centre`).

use nalgebra::{Vector2, Vector3};
use needle_vision::{BitDepth, Calibration, Camera, Pose, RenderOptions};
use serde::{Deserialize, Serialize};

use crate::error::SynthError;
use crate::scenario::{FieldChecker, Scenario};

/// Rendered camera frames of some trials, and images of a calibration
/// target, through the true camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFrames {
    /// Which probing trials get frames (the first `count` in campaign
    /// order) and how often.
    pub probes: FrameSelection,
    /// Which needle trials get frames and how often.
    pub needles: FrameSelection,
    /// Diameter of the painted marker dots (m).
    #[serde(default = "paper_dot_diameter")]
    pub dot_diameter: f64,
    /// Defocus blur, Gaussian standard deviation (px).
    #[serde(default = "paper_blur_sigma")]
    pub blur_sigma: f64,
    /// Gaussian read noise (grey levels).
    #[serde(default = "paper_read_noise_sigma")]
    pub read_noise_sigma: f64,
    /// Bit depth of the PNG files, `Eight` or `Sixteen`.
    #[serde(default = "paper_bit_depth")]
    pub bit_depth: BitDepth,
    /// Tilted views of the calibration target besides the one lying on the
    /// top face (at most [`MAX_TILTED_VIEWS`]).
    #[serde(default = "default_tilted_views")]
    pub tilted_views: usize,
}

/// Which trials of one kind get frames, and how often.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameSelection {
    /// The first `count` trials of this kind, in campaign order.
    pub count: usize,
    /// One camera frame in `every` is rendered: frame numbers 0, `every`,
    /// 2 `every`, ... up to the trial's last camera frame.
    pub every: usize,
}

/// The most tilted calibration views there are poses for.
pub const MAX_TILTED_VIEWS: usize = 6;

fn paper_dot_diameter() -> f64 {
    RenderOptions::paper().dot_diameter
}

fn paper_blur_sigma() -> f64 {
    RenderOptions::paper().blur_sigma
}

fn paper_read_noise_sigma() -> f64 {
    RenderOptions::paper().read_noise_sigma
}

fn paper_bit_depth() -> BitDepth {
    RenderOptions::paper().bit_depth
}

fn default_tilted_views() -> usize {
    5
}

impl CameraFrames {
    /// Frames of the first `probes` probing trials, one in `probe_every`,
    /// and of the first `needles` needle trials, one in `needle_every`,
    /// with the paper's rendering.
    pub fn paper(probes: usize, probe_every: usize, needles: usize, needle_every: usize) -> Self {
        Self {
            probes: FrameSelection {
                count: probes,
                every: probe_every,
            },
            needles: FrameSelection {
                count: needles,
                every: needle_every,
            },
            dot_diameter: paper_dot_diameter(),
            blur_sigma: paper_blur_sigma(),
            read_noise_sigma: paper_read_noise_sigma(),
            bit_depth: paper_bit_depth(),
            tilted_views: default_tilted_views(),
        }
    }

    /// How the frames are rendered.
    pub fn render_options(&self) -> RenderOptions {
        let calibration = Calibration::paper();
        RenderOptions {
            width: calibration.width as usize,
            height: calibration.height as usize,
            dot_diameter: self.dot_diameter,
            blur_sigma: self.blur_sigma,
            read_noise_sigma: self.read_noise_sigma,
            bit_depth: self.bit_depth,
            ..RenderOptions::paper()
        }
    }

    /// Checks the values; the phantom must fit in the camera's view.
    pub(crate) fn check(&self, c: &FieldChecker<'_>, s: &Scenario) -> Result<(), SynthError> {
        for (selection, name) in [(&self.probes, "probes"), (&self.needles, "needles")] {
            c.check(
                selection.every >= 1,
                &format!("frames.{name}.every"),
                || "must be at least 1".into(),
            )?;
        }
        let p = &s.phantom;
        let spacing = (p.width / (p.markers.0 - 1) as f64).min(p.depth / (p.markers.1 - 1) as f64);
        c.positive(self.dot_diameter, "frames.dot_diameter")?;
        c.check(
            self.dot_diameter < 0.75 * spacing,
            "frames.dot_diameter",
            || {
                format!(
                    "{} leaves less than a quarter of the marker spacing {spacing} between dots",
                    self.dot_diameter
                )
            },
        )?;
        c.non_negative(self.blur_sigma, "frames.blur_sigma")?;
        c.non_negative(self.read_noise_sigma, "frames.read_noise_sigma")?;
        c.check(
            self.tilted_views <= MAX_TILTED_VIEWS,
            "frames.tilted_views",
            || format!("at most {MAX_TILTED_VIEWS}, got {}", self.tilted_views),
        )?;
        let camera = TrueCamera::new(s);
        let margin = self.dot_diameter + 0.02 * p.width.max(p.depth);
        for corner in [
            [-margin, -margin],
            [p.width + margin, -margin],
            [-margin, p.depth + margin],
            [p.width + margin, p.depth + margin],
        ] {
            let seen = camera
                .experiment()
                .face_to_pixel(Vector2::new(corner[0], corner[1]))
                .ok()
                .filter(|px| {
                    px.x >= 0.0
                        && px.y >= 0.0
                        && px.x <= camera.calibration.width as f64 - 1.0
                        && px.y <= camera.calibration.height as f64 - 1.0
                });
            c.check(seen.is_some(), "frames", || {
                format!(
                    "the phantom ({} x {} m) does not fit in the camera's view",
                    p.width, p.depth
                )
            })?;
        }
        let target = crate::frames::calibration_target(s, self.tilted_views + 1);
        let poses = crate::frames::view_poses(&camera, &target, self.tilted_views);
        c.check(
            crate::frames::views_fit(&camera, &target, &poses),
            "frames.tilted_views",
            || "a calibration view leaves the frame for this phantom size".into(),
        )
    }
}

/// The true camera of a scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct TrueCamera {
    /// What a perfect calibration finds: frame size, the camera the
    /// calibration images are taken with, the top face's pose.
    pub calibration: Calibration,
    /// The camera the trial frames are taken with: the calibrated one,
    /// unless `lens_distortion` adds its residual.
    pub experiment_camera: Camera,
}

impl TrueCamera {
    /// The paper's camera over the scenario's phantom.
    pub fn new(s: &Scenario) -> Self {
        let mut calibration = Calibration::paper();
        // Keep the phantom centre where the paper phantom's centre is seen:
        // R c' + t' = R c + t.
        let rotation = calibration.face_pose.rotation_matrix();
        let paper_centre = Vector3::new(0.0375, 0.0375, 0.0);
        let centre = Vector3::new(s.phantom.width / 2.0, s.phantom.depth / 2.0, 0.0);
        let translation =
            calibration.face_pose.translation_vector() + rotation * (paper_centre - centre);
        calibration.face_pose = Pose::from_rotation_translation(&rotation, translation);
        let mut experiment_camera = calibration.camera;
        if let Some(lens) = &s.effects.lens_distortion {
            let z = axial_distance(&calibration.face_pose);
            experiment_camera.distortion.k1 += lens.k1 * z * z;
        }
        Self {
            calibration,
            experiment_camera,
        }
    }

    /// The calibration of the camera that films the trials (the truth the
    /// frames follow; equal to [`TrueCamera::calibration`] without
    /// `lens_distortion`).
    pub fn experiment(&self) -> Calibration {
        Calibration {
            camera: self.experiment_camera,
            ..self.calibration.clone()
        }
    }
}

/// Distance from the camera centre to the face plane along the optical
/// axis: the ray $s\,(0, 0, 1)$ meets the plane $n \cdot X_c = n \cdot t$,
/// $n = R e_z$, at $s = n \cdot t / n_z$.
pub fn axial_distance(face_pose: &Pose) -> f64 {
    let normal = face_pose.rotation_matrix() * Vector3::z();
    normal.dot(&face_pose.translation_vector()) / normal.z
}

/// The face-frame position of a top-face marker at bundle position
/// `(x, y)` lifted by `uz` out of the top face (see the module notes).
pub fn face_point(position: [f64; 3]) -> Vector3<f64> {
    Vector3::new(position[0], position[1], -position[2])
}
