//! The regularised linear least-squares step,
//!
//! $$\min_q\ |A q - b|^2 + \lambda\,|L q|^2,$$
//!
//! solved by `needle-lsq`'s Tikhonov solver with $\lambda$ from the
//! discrepancy principle ($|A q_\lambda - b|^2 = m\sigma^2$) or generalised
//! cross-validation ($\min_\lambda m|Aq_\lambda - b|^2/(m - \mathrm{tr}H_\lambda)^2$,
//! $H_\lambda = A(A^TA + \lambda L^TL)^{-1}A^T$). This module adds what the
//! force estimates need on top: the matrix $(A^TA + \lambda L^TL)^{-1}$ for
//! their noise covariance, and a flagged fall-back to GCV when the
//! discrepancy principle cannot be met (the model does not fit the data to
//! the stated noise), instead of an error or a silently wrong $\lambda$.
//! With a known noise, $\lambda$ (and the form of the prior, among
//! candidates) can instead be the most probable one
//! ([`Regularisation::MarginalLikelihood`], `crate::evidence`).

use nalgebra::{DMatrix, DVector};
use needle_lsq::{LsqError, tikhonov};
use serde::{Deserialize, Serialize};

use crate::error::ForceError;
use crate::evidence::Evidence;

/// How the regularisation weight is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Regularisation {
    /// Discrepancy principle for a known marker noise `sigma` (m, one
    /// standard deviation per coordinate): the residual is made equal to
    /// the noise, $|Gq - u|^2 = m\sigma^2$.
    Discrepancy {
        /// Marker noise, one standard deviation per coordinate (m).
        sigma: f64,
    },
    /// Generalised cross-validation (the noise need not be known).
    Gcv,
    /// Marginal likelihood for a known marker noise `sigma` (m): $\lambda$
    /// (and the estimator's tip prior, [`crate::TipPrior::Evidence`]) of
    /// largest evidence (`crate::evidence`); when the model cannot reach
    /// the noise, the discrepancy principle at the misfit floor, flagged.
    MarginalLikelihood {
        /// Marker noise, one standard deviation per coordinate (m).
        sigma: f64,
    },
    /// A given weight $\lambda$ on the whitened problem.
    Fixed {
        /// The weight.
        lambda: f64,
    },
}

/// How $\lambda$ was finally chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum LambdaChoice {
    /// The discrepancy principle was satisfied.
    Discrepancy,
    /// Generalised cross-validation.
    Gcv,
    /// The discrepancy principle could not be met because even the
    /// unregularised fit leaves a residual above the stated noise (the model
    /// does not fit the data to the noise: model error). The misfit floor
    /// was taken as the noise level instead: $|r| = \tau |r_{floor}|$.
    /// Flagged: the stated uncertainties miss the model error.
    DiscrepancyAtModelFloor,
    /// The discrepancy principle could not be met because the data are
    /// within the stated noise of the smoothest solution (noise overstated
    /// or no force); GCV was used instead. Flagged.
    GcvAfterUnreachableDiscrepancy,
    /// Given by the caller.
    Fixed,
    /// The marginal likelihood (the model reached the stated noise).
    MarginalLikelihood,
    /// The marginal likelihood of a tip-following fit pooled over frames
    /// (`crate::follow`) that does not explain this frame: the pooled fit
    /// misses it by more than Morozov's margin beyond the frame's own fit
    /// (the density is not steady behind the tip), or the pooled model is
    /// short of the noise. Flagged.
    PooledNotExplained,
}

/// Morozov's safety factor $\tau$: the residual is set to $\tau$ times the
/// noise level, $|Aq - b| = \tau\sqrt m\,\sigma$, so that a noise level met
/// only with $\lambda \to 0$ does not produce an unregularised solution.
pub const DISCREPANCY_SAFETY: f64 = 1.1;

/// A regularised solution.
#[derive(Debug, Clone, PartialEq)]
pub struct RegularisedFit {
    /// The solution $q_\lambda$.
    pub solution: DVector<f64>,
    /// The chosen weight $\lambda$.
    pub lambda: f64,
    /// How it was chosen.
    pub choice: LambdaChoice,
    /// $|Aq_\lambda - b|^2$.
    pub residual_squared: f64,
    /// Number of data $m$.
    pub data_count: usize,
    /// Effective number of parameters $\mathrm{tr}\,H_\lambda$.
    pub effective_parameters: f64,
    /// $C = (A^TA + \lambda L^TL)^{-1}$: for whitened data the covariance
    /// of the solution is $C A^T A C$.
    pub inverse_normal: DMatrix<f64>,
}

/// Solves $\min_q |Aq - b|^2 + \lambda |Lq|^2$ with $\lambda$ chosen by
/// `choice`.
///
/// Errors: sizes that disagree, fewer data than unknowns, non-finite
/// entries, or a singular problem ($A$ and $L$ share a null direction).
pub fn solve_regularised(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    l: &DMatrix<f64>,
    choice: Regularisation,
) -> Result<RegularisedFit, ForceError> {
    let (m, n) = a.shape();
    if m < n {
        return Err(ForceError::TooFewMarkers {
            context: "regularised least squares (data rows)",
            found: m,
            required: n,
        });
    }
    let gcv = needle_lsq::LambdaChoice::GeneralisedCrossValidation;
    let (fit, made) = match choice {
        Regularisation::Fixed { lambda } => (
            tikhonov(a, b, l, needle_lsq::LambdaChoice::Fixed(lambda))?,
            LambdaChoice::Fixed,
        ),
        Regularisation::Gcv => (tikhonov(a, b, l, gcv)?, LambdaChoice::Gcv),
        Regularisation::MarginalLikelihood { sigma } => {
            return Ok(solve_most_probable(a, b, std::slice::from_ref(l), sigma)?.0);
        }
        Regularisation::Discrepancy { sigma } => {
            let noise_sigma = DISCREPANCY_SAFETY * sigma;
            match tikhonov(
                a,
                b,
                l,
                needle_lsq::LambdaChoice::Discrepancy { noise_sigma },
            ) {
                Ok(fit) => (fit, LambdaChoice::Discrepancy),
                Err(LsqError::DiscrepancyUnreachable {
                    target, smallest, ..
                }) if smallest > target => {
                    // The misfit floor plays the noise: |r| = tau |r_floor|.
                    let floor = smallest / (m as f64).sqrt();
                    match tikhonov(
                        a,
                        b,
                        l,
                        needle_lsq::LambdaChoice::Discrepancy {
                            noise_sigma: DISCREPANCY_SAFETY * floor,
                        },
                    ) {
                        Ok(fit) => (fit, LambdaChoice::DiscrepancyAtModelFloor),
                        Err(LsqError::DiscrepancyUnreachable { .. }) => (
                            tikhonov(a, b, l, gcv)?,
                            LambdaChoice::GcvAfterUnreachableDiscrepancy,
                        ),
                        Err(other) => return Err(other.into()),
                    }
                }
                Err(LsqError::DiscrepancyUnreachable { .. }) => (
                    tikhonov(a, b, l, gcv)?,
                    LambdaChoice::GcvAfterUnreachableDiscrepancy,
                ),
                Err(other) => return Err(other.into()),
            }
        }
    };
    let normal = a.tr_mul(a) + l.tr_mul(l) * fit.lambda;
    let inverse_normal = normal.cholesky().map(|c| c.inverse()).ok_or_else(|| {
        ForceError::Mismatch("the data matrix and the regulariser share a null space".into())
    })?;
    Ok(RegularisedFit {
        residual_squared: fit.residual_norm.powi(2),
        solution: fit.x,
        lambda: fit.lambda,
        choice: made,
        data_count: m,
        effective_parameters: fit.effective_parameters,
        inverse_normal,
    })
}

/// The most probable of several priors `candidates` (difference operators
/// of one shape) and its $\lambda$, by the marginal likelihood of the data
/// with known noise `sigma` (`crate::evidence`); returns the fit and the
/// index of the prior. When the model does not reach the noise ($\hat s^2 >
/// \tau^2$ at the optimum), the evidence's noise model does not hold: the
/// fit is then the discrepancy principle's with the first candidate
/// (flagged when at the misfit floor).
pub(crate) fn solve_most_probable(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    candidates: &[DMatrix<f64>],
    sigma: f64,
) -> Result<(RegularisedFit, usize), ForceError> {
    crate::error::positive("marker sigma", sigma)?;
    if candidates.is_empty() {
        return Err(ForceError::Mismatch("no prior to choose from".into()));
    }
    let evidence = Evidence::new(&(a / sigma), &(b / sigma));
    let best = candidates
        .iter()
        .enumerate()
        .filter_map(|(k, l)| evidence.most_probable(l).map(|found| (k, found)))
        .min_by(|x, y| x.1.score.total_cmp(&y.1.score));
    match best {
        Some((k, found)) if found.noise_variance <= DISCREPANCY_SAFETY * DISCREPANCY_SAFETY => {
            // lambda of the whitened problem; the unwhitened one weighs the
            // penalty against |Aq - b|^2 = sigma^2 |A_w q - b_w|^2.
            let lambda = found.lambda * sigma * sigma;
            let mut fit =
                solve_regularised(a, b, &candidates[k], Regularisation::Fixed { lambda })?;
            fit.choice = LambdaChoice::MarginalLikelihood;
            Ok((fit, k))
        }
        _ => Ok((
            solve_regularised(a, b, &candidates[0], Regularisation::Discrepancy { sigma })?,
            0,
        )),
    }
}
