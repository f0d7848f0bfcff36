//! The crate's error type.

use std::path::PathBuf;

/// Why a scenario could not be loaded or a campaign not generated.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// The scenario file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file concerned.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The scenario file is not valid RON for a [`crate::Scenario`] (syntax,
    /// unknown or missing field); the message names the field and position.
    #[error("{path}:{line}:{column}: {message}")]
    Parse {
        /// The scenario file.
        path: PathBuf,
        /// 1-based line of the problem.
        line: usize,
        /// 1-based column of the problem.
        column: usize,
        /// What is wrong, with the field name when there is one.
        message: String,
    },
    /// A scenario field has a value outside its physical or practical range.
    #[error(
        "{source_name}{}: field `{field}`: {reason}",
        .line.map_or(String::new(), |line| format!(":{line}"))
    )]
    InvalidField {
        /// The scenario file, or the scenario's name when built in code.
        source_name: String,
        /// The field's line in the file, when read from one.
        line: Option<u64>,
        /// Dotted path of the field, e.g. `phantom.poisson_ratio`.
        field: String,
        /// Why the value is rejected.
        reason: String,
    },
    /// The finite element library rejected the discretisation.
    #[error("finite element setup: {0}")]
    Fem(#[from] needle_fem::error::FemError),
    /// A stiffness matrix could not be factorised (not positive definite:
    /// the body is not held against rigid motion).
    #[error("factorising the stiffness matrix of {what} failed: {reason}")]
    Factorisation {
        /// Which system.
        what: String,
        /// faer's or METIS's message.
        reason: String,
    },
    /// The Newton iteration of the nonlinear material did not converge.
    #[error(
        "Newton iteration did not converge in {what} (residual {residual:e} N after {iterations} iterations)"
    )]
    NoConvergence {
        /// Which solve.
        what: String,
        /// Final residual norm (N).
        residual: f64,
        /// Iterations done.
        iterations: usize,
    },
    /// Rendering or writing a camera frame or calibration image failed.
    #[error("rendering {what}: {reason}")]
    Render {
        /// Which image.
        what: String,
        /// The vision crate's message.
        reason: String,
    },
    /// Writing the bundle failed (or it would overwrite one).
    #[error("writing the bundle: {0}")]
    Bundle(#[from] needle_data::BundleError),
    /// The ground-truth file exists already or lies inside the bundle folder.
    #[error("ground truth file {path}: {reason}")]
    TruthPath {
        /// The requested path.
        path: PathBuf,
        /// Why it cannot be written.
        reason: String,
    },
}

impl SynthError {
    /// A Newton failure with the trial and state it happened in added to
    /// its `what` (the solver knows only the phantom); other errors as
    /// they are.
    pub(crate) fn during(self, context: impl FnOnce() -> String) -> Self {
        match self {
            SynthError::NoConvergence {
                what,
                residual,
                iterations,
            } => SynthError::NoConvergence {
                what: format!("{what}, {}", context()),
                residual,
                iterations,
            },
            other => other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_newton_failure_names_the_trial_it_happened_in() {
        let failed = SynthError::NoConvergence {
            what: "the neo-Hookean phantom".into(),
            residual: 1e-4,
            iterations: 200,
        };
        let text = failed
            .during(|| "pressed by the probe at x = 0.012 m".into())
            .to_string();
        assert_eq!(
            text,
            "Newton iteration did not converge in the neo-Hookean phantom, pressed by the \
             probe at x = 0.012 m (residual 1e-4 N after 200 iterations)"
        );
        // Other errors pass through unchanged.
        let other = SynthError::Fem(needle_fem::FemError::InvalidMesh("x".into()));
        let before = other.to_string();
        assert_eq!(other.during(|| "context".into()).to_string(), before);
    }
}
