//! The typed errors of the crate.

use std::path::PathBuf;

use thiserror::Error;

/// Everything that can go wrong in a diagnosis.
#[derive(Debug, Error)]
pub enum DiagnoseError {
    /// The bundle could not be read or is invalid.
    #[error(transparent)]
    Bundle(#[from] needle_data::BundleError),
    /// The finite-element model failed (a load outside the mesh, a singular system).
    #[error("finite-element model: {0}")]
    Fem(#[from] needle_fem::FemError),
    /// The neo-Hookean internal force could not be evaluated.
    #[error("hyperelastic model: {0}")]
    Nonlinear(#[from] needle_fem::NonlinearError),
    /// The least-squares engine failed.
    #[error("fit: {0}")]
    Fit(#[from] needle_lsq::LsqError),
    /// A model names an effect the catalog does not have.
    #[error("unknown effect `{id}` (the catalog has: {known})")]
    UnknownEffect {
        /// The id given.
        id: String,
        /// The ids the catalog has, comma separated.
        known: String,
    },
    /// A model names the same effect twice.
    #[error("effect `{0}` is listed twice in the model")]
    DuplicateEffect(String),
    /// A model file could not be parsed.
    #[error("model file {path}: {message}")]
    ModelFile {
        /// The file.
        path: PathBuf,
        /// What is wrong, with line and column.
        message: String,
    },
    /// A trial's tool pose cannot be turned into a load.
    #[error("bundle {bundle}, trial `{trial}`: {message}")]
    TrialGeometry {
        /// Bundle name.
        bundle: String,
        /// Trial id.
        trial: String,
        /// What is wrong.
        message: String,
    },
    /// The bundle has no marker track and no needle force to compare with.
    #[error("bundle {0} has nothing the model predicts (no tracked markers, no needle trial)")]
    NoObservations(String),
    /// An option is out of range.
    #[error("option `{field}`: {reason}")]
    InvalidOption {
        /// The option.
        field: &'static str,
        /// Why.
        reason: String,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Serialising an output failed.
    #[error("writing {path}: {message}")]
    Serialize {
        /// The file.
        path: PathBuf,
        /// The cause.
        message: String,
    },
}
