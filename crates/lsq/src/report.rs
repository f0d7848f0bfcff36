//! What a fit returns: the optimum, how it was reached, and its uncertainty.

use nalgebra::DVector;
use serde::{Deserialize, Serialize};

use crate::error::LsqError;
use crate::quantile::two_sided_normal;
use crate::uncertainty::Uncertainty;

/// Why the iteration stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Termination {
    /// Actual and predicted relative cost reductions both below
    /// `function_tolerance`.
    CostReduction,
    /// Trust radius `Δ` (bound on the scaled step `|D δ|`) below
    /// `step_tolerance · |D u|`.
    StepSize,
    /// Every scaled gradient component `|J_jᵀ r| / (|J_j| |r|)` below
    /// `gradient_tolerance`.
    Gradient,
    /// The cost is exactly zero.
    ZeroCost,
    /// `max_evaluations` residual evaluations were spent (not converged).
    MaxEvaluations,
    /// The trust region collapsed to rounding level: no trial step reduces
    /// the cost (not converged; typically residuals failing everywhere
    /// around the point).
    DampingExhausted,
}

impl Termination {
    /// Whether the stop is a convergence criterion rather than a limit.
    pub fn is_converged(self) -> bool {
        !matches!(self, Self::MaxEvaluations | Self::DampingExhausted)
    }
}

/// Work spent by a fit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Evaluations {
    /// Residual evaluations at the start and at trial points (finite
    /// differences excluded).
    pub residuals: usize,
    /// Jacobian evaluations (analytic or finite-difference).
    pub jacobians: usize,
    /// Residual evaluations spent on finite-difference Jacobians.
    pub finite_difference_residuals: usize,
}

/// The result of [`LevenbergMarquardt::minimize`](crate::LevenbergMarquardt::minimize).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FitReport {
    /// Parameter names, in the order given.
    pub names: Vec<String>,
    /// Optimal parameters (fixed ones at their held values).
    pub params: DVector<f64>,
    /// `½ Σ r_i²` at the optimum.
    pub cost: f64,
    /// `Σ r_i²` at the optimum (`2 · cost`).
    pub chi2: f64,
    /// Degrees of freedom `m - n_free` (saturating at 0).
    pub dof: usize,
    /// Outer iterations (one Jacobian each).
    pub iterations: usize,
    /// Work spent.
    pub evaluations: Evaluations,
    /// Why it stopped.
    pub termination: Termination,
    /// `max_j |∂cost/∂u_j|` at the optimum, in the internal coordinates
    /// (see [`transform`](crate::transform)), whose unit is the parameter
    /// scale; zero at an interior optimum and at a bound alike. NaN when the
    /// fit stopped without a Jacobian at the optimum (see
    /// [`Options::uncertainty`](crate::Options::uncertainty)).
    pub gradient_norm: f64,
    /// Covariance, standard errors, identifiability.
    pub uncertainty: Uncertainty,
    /// The Jacobian $\partial r_i/\partial p_j$ the covariance comes from,
    /// evaluated (not updated) at `params`, one column per parameter:
    /// `None` for a held parameter and for one on a bound, where the
    /// internal coordinate has no slope to divide by. Empty when the fit
    /// did not end with such a Jacobian (no covariance asked for, or a
    /// stop on an updated one). Another fit from `params` can start from
    /// it ([`LevenbergMarquardt::minimize_with_columns`](crate::LevenbergMarquardt::minimize_with_columns)).
    /// Not serialised: it has one row per residual.
    #[serde(skip)]
    pub jacobian: Vec<Option<DVector<f64>>>,
}

impl FitReport {
    /// Index of the parameter called `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Standard error of parameter `index`, `None` unless it was estimated.
    pub fn standard_error(&self, index: usize) -> Option<f64> {
        self.uncertainty
            .standard_errors
            .get(index)
            .copied()
            .flatten()
    }

    /// `chi2 / dof`, or `None` without degrees of freedom.
    pub fn reduced_chi2(&self) -> Option<f64> {
        (self.dof > 0).then(|| self.chi2 / self.dof as f64)
    }

    /// The Wald (normal) interval `p ± z σ` at confidence `level`.
    /// Errors name the parameter when it has no standard error (fixed, at
    /// a bound, unidentifiable, or no degrees of freedom).
    pub fn confidence_interval(&self, index: usize, level: f64) -> Result<(f64, f64), LsqError> {
        let z = two_sided_normal(level)?;
        let status = *self
            .uncertainty
            .status
            .get(index)
            .ok_or(LsqError::UnknownParameter {
                index,
                count: self.names.len(),
            })?;
        let sigma = self
            .standard_error(index)
            .ok_or_else(|| LsqError::NotEstimated {
                name: self.names[index].clone(),
                status,
            })?;
        let centre = self.params[index];
        Ok((centre - z * sigma, centre + z * sigma))
    }
}
