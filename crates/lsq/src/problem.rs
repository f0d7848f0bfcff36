//! The `Problem` trait: what a model must provide to be fitted.

use nalgebra::DMatrix;

use crate::error::EvaluationError;

/// A nonlinear least-squares problem `min_p ½ Σ_i r_i(p)²`.
///
/// The residuals must already be whitened by the caller: `r_i = (y_i -
/// model_i(p)) / sigma_i`, or more generally `r = W^{1/2} (y - model(p))`.
/// Then `chi2 = Σ r_i²` and, with [`CovarianceScaling::KnownNoise`](crate::CovarianceScaling),
/// the reported covariance is the statistical one.
///
/// `Sync` is required because finite-difference Jacobian columns are
/// evaluated in parallel (rayon), one column per parameter.
pub trait Problem: Sync {
    /// Number of parameters `n` (fixed ones included).
    fn num_parameters(&self) -> usize;

    /// Number of residuals `m`.
    fn num_residuals(&self) -> usize;

    /// Writes the `m` residuals at `params` (length `n`) into `out`.
    ///
    /// May fail (e.g. a singular finite-element system). A failure, or a
    /// non-finite residual, at a trial point is a rejected step; only at the
    /// starting point is it an error.
    fn residuals(&self, params: &[f64], out: &mut [f64]) -> Result<(), EvaluationError>;

    /// The analytic Jacobian `J_ij = ∂r_i/∂p_j` (an `m × n` matrix, already
    /// sized and zeroed) if it is cheap to compute; `None` (the default)
    /// means "use finite differences".
    fn jacobian(
        &self,
        params: &[f64],
        out: &mut DMatrix<f64>,
    ) -> Option<Result<(), EvaluationError>> {
        let _ = (params, out);
        None
    }

    /// The residuals at `params` as a finite-difference column of the
    /// Jacobian at `base` sees them, if the problem has a cheaper map for
    /// that; `None` (the default) means [`residuals`](Self::residuals).
    ///
    /// The engine differences this map only with itself (it evaluates it at
    /// `base` too), so it may differ from `residuals` by a smooth function
    /// of `params`: for example an inner fixed-point iteration started from
    /// its solution at `base` and run for fewer rounds. Its derivative then
    /// differs from the converged map's by the contraction of the rounds
    /// left out.
    fn residuals_near(
        &self,
        base: &[f64],
        params: &[f64],
        out: &mut [f64],
    ) -> Option<Result<(), EvaluationError>> {
        let _ = (base, params, out);
        None
    }

    /// Column `j` of the Jacobian at `params` as a row-by-row multiple of
    /// another column, where the problem knows one by the chain rule:
    /// `Some((i, factors))` means $\partial r / \partial p_j = f \odot
    /// \partial r / \partial p_i$, `factors` $f$ one per residual. `None`
    /// (the default) means "difference it".
    ///
    /// For example a parameter that acts on each group of residuals only
    /// through a quantity $q_g = p_i + p_j v_g$ has $f = v_g$ on the rows
    /// of group $g$. The engine then differences column `i` only (when it
    /// differences it at all, and it is not itself a multiple of another)
    /// and takes column `j` from it for no evaluation.
    fn chained_column(&self, params: &[f64], j: usize) -> Option<(usize, Vec<f64>)> {
        let _ = (params, j);
        None
    }
}
