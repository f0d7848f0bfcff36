//! The typed errors of the crate.

use thiserror::Error;

use crate::uncertainty::ParameterStatus;

/// The error a [`Problem`](crate::Problem) returns when it cannot evaluate its
/// residuals or Jacobian at some parameters (e.g. a singular finite-element
/// system). Any error type converts into it with `?`.
pub type EvaluationError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Everything that can go wrong in a fit, a profile or a regularised solve.
#[derive(Debug, Error)]
pub enum LsqError {
    /// A parameter specification is unusable (bad bounds, non-finite value, ...).
    #[error("parameter `{name}`: {reason}")]
    InvalidParameter {
        /// The parameter's name.
        name: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The problem declares a different number of parameters than were given.
    #[error(
        "the problem has {expected} parameters but {given} parameter specifications were given"
    )]
    ParameterCount {
        /// `Problem::num_parameters()`.
        expected: usize,
        /// Length of the parameter list.
        given: usize,
    },
    /// Every parameter is fixed: there is nothing to fit.
    #[error("every parameter is fixed: nothing to fit")]
    NoFreeParameters,
    /// An option is out of its valid range.
    #[error("option `{field}`: {reason}")]
    InvalidOption {
        /// The option's field name.
        field: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// The residuals could not be evaluated at the starting point, so no
    /// fit can begin (failures at trial points are rejected steps instead).
    #[error("residual evaluation failed at the initial parameters: {source}")]
    InitialEvaluation {
        /// The problem's error.
        source: EvaluationError,
    },
    /// A residual is NaN or infinite at the starting point.
    #[error("residual {index} is not finite at the initial parameters (value {value})")]
    NonFiniteResidual {
        /// Index of the first bad residual.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// The Jacobian could not be evaluated at an accepted point.
    #[error("Jacobian evaluation failed at parameters {params:?}: {source}")]
    JacobianEvaluation {
        /// The external parameters where it failed.
        params: Vec<f64>,
        /// The problem's error.
        source: EvaluationError,
    },
    /// A parameter index beyond the parameter list.
    #[error("parameter index {index} is out of range (there are {count} parameters)")]
    UnknownParameter {
        /// The index asked for.
        index: usize,
        /// Number of parameters.
        count: usize,
    },
    /// A parameter has no standard error, so no Wald interval or profile
    /// span in standard errors can be formed.
    #[error("parameter `{name}` has no standard error: {status:?}")]
    NotEstimated {
        /// The parameter's name.
        name: String,
        /// Why it was not estimated.
        status: ParameterStatus,
    },
    /// Matrix or vector sizes disagree.
    #[error("dimension mismatch in {what}: expected {expected}, found {found}")]
    DimensionMismatch {
        /// Which operand.
        what: &'static str,
        /// The size required.
        expected: usize,
        /// The size given.
        found: usize,
    },
    /// `A` and the regulariser `L` share a null-space direction, so the
    /// Tikhonov problem has no unique solution for any lambda.
    #[error(
        "the data matrix and the regulariser share a null space: the regularised problem is singular"
    )]
    SingularRegularisation,
    /// The discrepancy principle cannot be satisfied on the admissible
    /// lambda range.
    #[error(
        "discrepancy principle unreachable: target residual norm {target:e} is outside [{smallest:e}, {largest:e}] attainable over lambda"
    )]
    DiscrepancyUnreachable {
        /// `sqrt(m) * sigma`.
        target: f64,
        /// The residual norm at the smallest lambda.
        smallest: f64,
        /// The residual norm at the largest lambda.
        largest: f64,
    },
}
