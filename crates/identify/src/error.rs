//! Typed errors of the crate.
//!
//! Each variant names what was wrong with the input (the trial, the frame,
//! the field) so that a lab engineer can fix it; nothing here is ever a
//! panic or a silent NaN.

use needle_fem::error::FemError;
use needle_lsq::LsqError;
use thiserror::Error;

/// Everything that can go wrong in a material identification.
#[derive(Debug, Error)]
pub enum IdentifyError {
    /// The bundle lists no trial of kind `Probe`.
    #[error(
        "the bundle has no Probe trial: material identification needs boundary probing (trial kind Probe)"
    )]
    NoProbeTrials,
    /// Too few markers to determine the parameters.
    #[error("{context}: {found} marker(s) usable, at least {needed} needed")]
    TooFewMarkers {
        /// Where the count was taken.
        context: String,
        /// Markers needed.
        needed: usize,
        /// Markers found.
        found: usize,
    },
    /// No trial has a camera frame with the probe in contact.
    #[error("no frame with the probe in contact: {reason}")]
    NoContactFrames {
        /// Why each trial contributed nothing.
        reason: String,
    },
    /// A trial's data cannot be used (missing file, bad geometry).
    #[error("trial `{trial}`: {reason}")]
    InvalidTrial {
        /// Trial id.
        trial: String,
        /// What is wrong.
        reason: String,
    },
    /// An input value is out of its valid range.
    #[error("invalid value for `{field}`: {value} ({reason})")]
    InvalidValue {
        /// Name of the field or option.
        field: &'static str,
        /// The rejected value.
        value: f64,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// Array inputs disagree in length or refer to missing items.
    #[error("inconsistent input: {0}")]
    Inconsistent(String),
    /// The probe tip is not on (or near) a loadable face of the phantom.
    #[error("trial `{trial}`, frame at t = {t} s: probe tip at ({x}, {y}) m is {reason}")]
    LoadPoint {
        /// Trial id.
        trial: String,
        /// Frame time (s).
        t: f64,
        /// Tip x (m).
        x: f64,
        /// Tip y (m).
        y: f64,
        /// Why it cannot carry the load.
        reason: &'static str,
    },
    /// The measured displacements do not respond to the force as an elastic
    /// body does (zero or opposite to the model's prediction for every
    /// Poisson's ratio), so no positive modulus explains them.
    #[error(
        "{context}: the marker displacements do not respond to the probe force like an elastic body (best scale factor {scale:e}); check force sign, units and marker ids"
    )]
    NoElasticResponse {
        /// Which fit.
        context: String,
        /// The least-squares compliance scale (must be positive).
        scale: f64,
    },
    /// The finite-element model could not be built or solved.
    #[error("finite-element model: {0}")]
    Model(#[from] FemError),
    /// The least-squares engine rejected the problem.
    #[error("least-squares fit: {0}")]
    Fit(#[from] LsqError),
    /// The sparse Cholesky factorisation of the stiffness matrix failed.
    #[error("stiffness factorisation: {0}")]
    Factorization(String),
}
