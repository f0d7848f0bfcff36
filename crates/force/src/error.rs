//! Typed errors of the crate: every way bad input can reach a force estimate
//! names what was wrong and where.

use thiserror::Error;

/// Everything that can go wrong in `needle-force`.
#[derive(Debug, Error)]
pub enum ForceError {
    /// The trial id is not in the bundle.
    #[error("trial `{trial}` is not in the bundle")]
    UnknownTrial {
        /// The id asked for.
        trial: String,
    },
    /// The trial is not a needle insertion.
    #[error("trial `{trial}` is a {kind} trial, not a needle insertion")]
    NotANeedleTrial {
        /// The trial id.
        trial: String,
        /// Its kind, as the manifest gives it.
        kind: String,
    },
    /// The trial has no `markers.csv` (tracked markers are the input of every
    /// estimate here).
    #[error("trial `{trial}` has no tracked markers (trials/{trial}/markers.csv)")]
    NoMarkers {
        /// The trial id.
        trial: String,
    },
    /// The trial has no tool samples, so no needle position or base force.
    #[error("trial `{trial}` has no tool samples (trials/{trial}/tool.csv)")]
    NoToolSamples {
        /// The trial id.
        trial: String,
    },
    /// No camera frame of the trial has the needle inside the phantom.
    #[error(
        "trial `{trial}`: no frame has the needle tip inside the phantom (tip y > 0 within the tool samples' time span)"
    )]
    NoFramesInContact {
        /// The trial id.
        trial: String,
    },
    /// Too few markers to estimate anything.
    #[error("{context}: {found} markers, at least {required} are needed")]
    TooFewMarkers {
        /// What needed them.
        context: &'static str,
        /// How many were available.
        found: usize,
        /// How many are needed.
        required: usize,
    },
    /// The rest positions of the markers do not form a rectangular grid, which
    /// the marker-node meshes need.
    #[error("markers_rest.csv: the markers do not form a rectangular grid ({detail})")]
    NotAGrid {
        /// What broke the grid.
        detail: String,
    },
    /// A marker needed by the paper's node-force method was not tracked in a
    /// frame (every node's displacement must be measured for f = K u).
    #[error("frame at t = {t} s: marker {id} was not tracked, but f = K u needs every node")]
    MissingMarker {
        /// Frame time (s).
        t: f64,
        /// The marker id.
        id: u32,
    },
    /// A value is NaN, infinite or out of its range.
    #[error("invalid `{field}`: {value} ({reason})")]
    InvalidValue {
        /// The field or option.
        field: &'static str,
        /// The rejected value.
        value: f64,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// The needle path is too short (or leaves the phantom) for a shaft
    /// discretisation.
    #[error("needle path of length {length:e} m cannot carry a shaft discretisation ({reason})")]
    BadShaft {
        /// The path length (m).
        length: f64,
        /// Why.
        reason: &'static str,
    },
    /// Series to be averaged or compared do not line up.
    #[error("cannot combine: {0}")]
    Mismatch(String),
    /// Nothing to average, plot or fit.
    #[error("{0}: no data")]
    Empty(&'static str),
    /// The phantom has no fixed face, so the model is singular.
    #[error("the phantom has no fixed face: the elastic model would be singular")]
    NoFixedFace,
    /// A finite-element operation failed.
    #[error("finite element model: {0}")]
    Fem(#[from] needle_fem::error::FemError),
    /// The regularised least-squares solve failed.
    #[error("regularised least squares: {0}")]
    Lsq(#[from] needle_lsq::LsqError),
    /// Drawing a figure failed.
    #[error("plot `{figure}`: {message}")]
    Plot {
        /// Which figure.
        figure: &'static str,
        /// The backend's message.
        message: String,
    },
}

/// Checks that `value` is finite and positive, naming `field` otherwise.
pub(crate) fn positive(field: &'static str, value: f64) -> Result<f64, ForceError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(ForceError::InvalidValue {
            field,
            value,
            reason: "must be positive and finite",
        })
    }
}
