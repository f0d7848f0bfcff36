//! Typed errors of the hyperelastic (nonlinear) model: everything
//! [`FemError`] covers, plus the ways a nonlinear solve can fail. A solve
//! that does not reach its tolerance is an error, never a returned
//! displacement.

use thiserror::Error;

use crate::error::FemError;
use crate::material::Formulation;

/// Everything that can go wrong in hyperelastic assembly and solves.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum NonlinearError {
    /// Bad input or a failed linear-algebra step (see [`FemError`]).
    #[error(transparent)]
    Fem(#[from] FemError),
    /// The neo-Hookean model exists in plane strain and 3-D only.
    #[error("the hyperelastic model needs plane strain or a 3-D solid, not {0:?}")]
    UnsupportedFormulation(Formulation),
    /// The displacement turns an element inside out ($\det F \le 0$ at a
    /// quadrature point), where the energy is infinite.
    #[error(
        "element {element} is inverted by the displacement (det F = {jacobian:e} at a quadrature point)"
    )]
    InvertedElement {
        /// Element index.
        element: usize,
        /// The offending $J = \det F$.
        jacobian: f64,
    },
    /// The iteration stopped before the residual fell below the tolerance.
    #[error(
        "nonlinear solve of load case {load_case} did not converge: relative residual {relative_residual:e} after {iterations} iterations (tolerance {tolerance:e}, load step {load_step})"
    )]
    NotConverged {
        /// Index of the load case (0 for a single solve).
        load_case: usize,
        /// Load step (1-based) in which the iteration stopped.
        load_step: usize,
        /// Iterations done in that step.
        iterations: usize,
        /// Last $\|r_f\| / \max(\|f_f\|, \|f_\text{int}\|)$.
        relative_residual: f64,
        /// The tolerance asked for.
        tolerance: f64,
    },
    /// No step length along the Newton direction reduced the residual.
    #[error(
        "line search failed in load step {load_step}, iteration {iteration}: relative residual {relative_residual:e} (increase the load steps)"
    )]
    LineSearchFailed {
        /// Load step (1-based).
        load_step: usize,
        /// Newton iteration within the step.
        iteration: usize,
        /// Relative residual at the start of the line search.
        relative_residual: f64,
    },
}
