//! needle-vision: the camera side of the needle-insertion experiments.
//!
//! The paper (DiMaio & Salcudean, section II-B) films 441 painted dots on
//! the top face of the phantom with a 2056 x 1544 camera at 30 Hz, corrects
//! the lens with the radial-decentering model of its equation (1), and tracks
//! the dots by correlation-based template matching. This crate does all of
//! that:
//!
//! - **Camera model** ([`Camera`], [`Pose`]): pinhole intrinsics, the
//!   distortion of equation (1), projection with analytic Jacobians, and
//!   undistortion by damped Newton iteration that refuses points outside the
//!   region where the distortion map is invertible ([`Distortion::undistort`]).
//! - **Rendering** ([`render_frame`]): synthetic frames of the dot pattern at
//!   given 3-D marker positions, with exact projection of each disc,
//!   analytic anti-aliasing, defocus blur, illumination gradient, shot and
//!   read noise, 8- or 16-bit PNG ([`GreyFrame`]); deterministic by seed.
//! - **Tracking** ([`track_marker`], [`track_markers`]): ZNCC integer search
//!   and inverse-compositional Gauss-Newton subpixel refinement on a cubic
//!   B-spline interpolant, with a quality report and typed lost-marker
//!   reasons ([`LostReason`]); precision within a few percent of the
//!   Cramer-Rao bound.
//! - **Calibration** ([`calibrate`]): Zhang's closed form from views of a
//!   planar target, refined by Levenberg-Marquardt (needle-lsq); from images
//!   of a dot grid ([`calibrate_dot_grid`]) with detection, ordering and the
//!   perspective bias of circle centres corrected.
//! - **Rectification** ([`Calibration`]): pixels to top-face metres and back;
//!   the calibration is stored as RON.
//! - **Frames to `markers.csv`** ([`track_frames`], [`track_frames_to_csv`]):
//!   the library side of `cargo xtask track`.
//! - **A bundle's camera side** ([`calibrate_from_bundle`],
//!   [`track_untracked_trials`]): calibrate from a bundle's `calibration/`
//!   folder and give every trial that has frames but no `markers.csv` the
//!   tracks of its frames, in memory, before anything fits its markers.
//!
//! ## Place in the chain
//!
//! Depends only on needle-data (the `markers.csv` rows and writer) and
//! needle-lsq (the least-squares engine). Used by the truth world
//! (needle-synth) to render camera frames and by the pipeline (xtask) to
//! track them.
//!
//! ## What it does not do
//!
//! No 3-D reconstruction (one camera sees the top face, which is a plane; a
//! marker's out-of-plane motion is not measured), no stereo, no deformable
//! (affine) template warps (translation only: dots are small and strains are
//! a few percent), no camera I/O, no checkerboard or coded targets (dot grids
//! only).
//!
//! ## The distortion model, equation (1)
//!
//! With $n = (x_n, y_n)$ the undistorted normalised coordinates
//! $(X_c/Z_c, Y_c/Z_c)$ and $r^2 = x_n^2 + y_n^2$, the distorted normalised
//! coordinates $d = (x_p, y_p)$ are
//!
//! $$ d = (1 + k_1 r^2 + k_2 r^4 + k_3 r^6)\, n + \begin{bmatrix} 2 p_1 x_n y_n + p_2 (r^2 + 2 x_n^2) \\ p_1 (r^2 + 2 y_n^2) + 2 p_2 x_n y_n \end{bmatrix}, $$
//!
//! the Brown-Conrady form (the paper's $(x_d, y_d)$ in the text is its
//! $(x_p, y_p)$), and the pixel is $u = f_x x_p + s\, y_p + c_x$,
//! $v = f_y y_p + c_y$.
//!
//! ## Example
//!
//! ```
//! use nalgebra::{Vector2, Vector3};
//! use needle_vision::{Calibration, MarkerTemplate, RenderOptions, TrackOptions, render_frame, track_marker};
//!
//! // A dot 2 mm across at (10 mm, 20 mm) on the top face, seen by the paper's camera.
//! let calibration = Calibration::paper();
//! let marker = Vector3::new(0.010, 0.020, 0.0);
//! let options = RenderOptions::paper();
//! let frame = render_frame(&calibration.camera, &calibration.face_pose, &[marker], &options, 42)?;
//!
//! // Track it with a synthetic template from a prediction 2 px off, and rectify.
//! let truth = calibration.face_to_pixel(marker.xy())?;
//! let template = MarkerTemplate::synthetic(25.3, 1.0, 220.0, 180.0, 16)?;
//! let outcome = track_marker(&frame, &template, truth + Vector2::new(2.0, -1.5), &TrackOptions::default());
//! let found = outcome.position.expect("tracked");
//! assert!((found - truth).norm() < 0.05);
//! let face = calibration.pixel_to_face(found)?;
//! assert!((face - marker.xy()).norm() < 5e-6);
//! # Ok::<(), needle_vision::VisionError>(())
//! ```

mod bundle;
mod calibrate;
mod camera;
mod detect;
mod error;
mod frame;
mod interpolate;
mod rectify;
mod render;
mod shift_sampler;
mod track;
mod track_frames;
mod undistort;

pub use bundle::{
    DEFAULT_FRAME_RATE, FrameRate, FromFrames, TrackedTrial, calibrate_from_bundle, frame_rate,
    track_trial, track_untracked_trials,
};
pub use calibrate::{
    CalibrationFit, CalibrationView, FixedParameters, calibrate, homography, initialise, refine,
};
pub use camera::{
    Camera, DISTORTION_COUNT, Distortion, INTRINSIC_COUNT, Intrinsics, POSE_COUNT, Pose,
    ProjectionJacobians,
};
pub use detect::{DotGrid, calibrate_dot_grid, circle_centre_bias, detect_dot_grid};
pub use error::VisionError;
pub use frame::{BitDepth, GreyFrame};
pub use rectify::Calibration;
pub use render::{RenderOptions, add_noise, pixel_space_view, render_frame, render_ideal};
pub use track::{
    LostReason, MarkerTemplate, SearchPolicy, TrackOptions, TrackOutcome, track_marker,
    track_markers,
};
pub use track_frames::{
    LostMarker, TemplateSource, TrackFramesOptions, TrackedFrames, list_frames, model_template,
    read_checked_frame, track_frames, track_frames_to_csv,
};
