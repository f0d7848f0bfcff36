//! The one error type of the crate.

use std::path::PathBuf;

/// Everything that can go wrong in needle-vision, each variant naming what was
/// wrong and where.
#[derive(Debug, thiserror::Error)]
pub enum VisionError {
    /// A distorted point has no preimage in the region where the distortion
    /// map is invertible (or Newton's method did not converge to one).
    #[error(
        "undistortion failed at normalised point ({x:.6}, {y:.6}): {reason}; the point lies outside the region where the distortion model is invertible"
    )]
    NotInvertible {
        /// Distorted normalised x.
        x: f64,
        /// Distorted normalised y.
        y: f64,
        /// Why the iteration stopped.
        reason: String,
    },
    /// A point lies behind the camera or on its focal plane.
    #[error("point ({x}, {y}, {z}) in the camera frame is not in front of the camera")]
    BehindCamera {
        /// Camera-frame x.
        x: f64,
        /// Camera-frame y.
        y: f64,
        /// Camera-frame z.
        z: f64,
    },
    /// A ray does not meet the plane in front of the camera.
    #[error(
        "the ray through pixel ({u:.3}, {v:.3}) does not meet the phantom top face in front of the camera"
    )]
    RayMissesPlane {
        /// Pixel column.
        u: f64,
        /// Pixel row.
        v: f64,
    },
    /// A numeric option or model parameter is out of its valid range.
    #[error("invalid {field}: {reason}")]
    InvalidParameter {
        /// The field or option.
        field: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A PNG could not be decoded or encoded.
    #[error("{path}: not a readable PNG: {reason}")]
    Png {
        /// The file.
        path: PathBuf,
        /// The decoder's message.
        reason: String,
    },
    /// A frame has a pixel format other than 8- or 16-bit grey.
    #[error("{path}: pixel format {found} is not 8- or 16-bit grey")]
    PixelFormat {
        /// The file.
        path: PathBuf,
        /// The format found.
        found: String,
    },
    /// A frame does not have the size the calibration expects.
    #[error(
        "{path}: frame is {found_width} x {found_height} px, the calibration expects {width} x {height} px"
    )]
    FrameSize {
        /// The file.
        path: PathBuf,
        /// Size found.
        found_width: u32,
        /// Size found.
        found_height: u32,
        /// Size expected.
        width: u32,
        /// Size expected.
        height: u32,
    },
    /// A frame's contrast is too low to track in.
    #[error(
        "{path}: grey-level standard deviation {found:.2} is below the minimum {minimum:.2}: frame too dark, flat or saturated to track"
    )]
    LowContrast {
        /// The file.
        path: PathBuf,
        /// The measured spread.
        found: f64,
        /// The required spread.
        minimum: f64,
    },
    /// A frames folder holds no frame.
    #[error("{path}: no frame named NNNNNN.png")]
    NoFrames {
        /// The folder.
        path: PathBuf,
    },
    /// A calibration has too few usable data.
    #[error("calibration: {0}")]
    Calibration(String),
    /// A calibration target's dots could not be found or ordered.
    #[error("dot grid detection: {0}")]
    DotGrid(String),
    /// A RON file could not be parsed or written.
    #[error("{path}: {reason}")]
    Ron {
        /// The file.
        path: PathBuf,
        /// The parser's message, with line and column.
        reason: String,
    },
    /// A bundle's calibration description could not be read, or tracks
    /// could not become a trial's marker track.
    #[error("{context}: {source}")]
    Bundle {
        /// What was being read or built.
        context: String,
        /// The bundle error.
        source: needle_data::BundleError,
    },
    /// A markers.csv could not be written.
    #[error("{path}: {reason}")]
    Csv {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}
