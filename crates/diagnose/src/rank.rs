//! Rank the effects not in the model: score test at the current fit, then
//! a refit with the effect added.
//!
//! **Score test.** With the current fit $\hat\theta$ and the candidate's
//! tested parameters $\psi$ at their null values $\psi_0$ (its untested
//! shape parameters held at their initial values), let $r$ be the whitened
//! residuals and $J_\theta$, $J_\psi$ their Jacobians. The score is
//! $U = J_\psi^T r$ (the gradient of $\tfrac12|r|^2$) and the efficient
//! information $I = \tilde J_\psi^T \tilde J_\psi$ with
//! $\tilde J_\psi = (1 - P_\theta) J_\psi$, $P_\theta$ the projector on the
//! columns of $J_\theta$ (the current parameters re-adjust). The statistic
//! $S = U^T I^{+} U$ is $\chi^2_k$ under the null (the model is right and
//! the noise as stated), $k$ the number of tested parameters. When the
//! only tested parameter sits on a bound at its null value and the score
//! points out of the feasible side, $S = 0$. $J_\psi$ uses forward
//! differences of $10^{-3}$ of the parameter's scale into the feasible side
//! (the support compliance, whose null is the rigid limit, needs a finite
//! step); $J_\theta$ steps $10^{-6}$ of the scale.
//!
//! **Refit.** The model with the effect added is fitted from
//! $(\hat\theta, \psi_\text{initial})$; the likelihood ratio
//! $\Lambda = \chi^2_\text{now} - \chi^2_\text{with}$ is compared with
//! $\chi^2_{k'}$, $k'$ all the effect's parameters. AIC $= \chi^2 + 2 n_p$
//! and BIC $= \chi^2 + n_p \ln n$ are reported too.

use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::chi2::chi2_upper_tail;
use crate::error::DiagnoseError;
use crate::fit::{Context, Fit, Fitted, fit_model};
use crate::model::{Model, PROBE_WIDTH};
use crate::spec::ModelSpec;

/// One effect not in the model, with the evidence for it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// Effect id.
    pub effect: String,
    /// Score statistic $S$ at the current fit.
    pub score: f64,
    /// Its p-value, $P(\chi^2_k > S)$.
    pub score_p: f64,
    /// Number of tested parameters $k$.
    pub score_dof: usize,
    /// Likelihood-ratio statistic $\chi^2_\text{now} - \chi^2_\text{with}$.
    pub likelihood_ratio: f64,
    /// Its p-value with all the effect's parameters as dof.
    pub likelihood_ratio_p: f64,
    /// AIC of the model with the effect.
    pub aic: f64,
    /// BIC of the model with the effect.
    pub bic: f64,
    /// Misfit of the model with the effect.
    pub fit_with: Fit,
}

/// A candidate with its refitted model (kept to continue the ladder).
pub(crate) struct Ranked {
    pub candidate: Candidate,
    pub spec: ModelSpec,
    pub fitted: Fitted,
}

/// Score statistic of `candidate` at the current fit.
fn score_test(
    context: &Context,
    current: &Model,
    fitted: &Fitted,
    augmented: &Model,
) -> Result<(f64, usize), DiagnoseError> {
    let n_current = current.len();
    let mut at: Vec<f64> = fitted.params.clone();
    at.extend(
        augmented.parameters[n_current..]
            .iter()
            .map(|p| if p.tested { p.null } else { p.initial }),
    );
    let base = context.whitened(augmented, &at)?;
    // Columns: free current parameters (those not on a bound), tested new ones.
    let current_columns: Vec<usize> = (0..n_current)
        .filter(|&k| fitted.report.uncertainty.status[k] == needle_lsq::ParameterStatus::Estimated)
        .collect();
    let tested: Vec<usize> = (n_current..augmented.len())
        .filter(|&k| augmented.parameters[k].tested)
        .collect();
    let columns: Vec<(usize, f64)> = current_columns
        .iter()
        .map(|&k| (k, 1e-6))
        .chain(tested.iter().map(|&k| (k, 1e-3)))
        .collect();
    let derivatives: Vec<Result<Vec<f64>, DiagnoseError>> = columns
        .par_iter()
        .map(|&(k, relative)| {
            let spec = &augmented.parameters[k];
            let mut h = relative * spec.scale.max(at[k].abs());
            if spec.upper.is_some_and(|u| at[k] + h > u) {
                h = -h;
            }
            let mut p = at.clone();
            p[k] += h;
            let r = context.whitened(augmented, &p)?;
            Ok(r.iter().zip(&base).map(|(a, b)| (a - b) / h).collect())
        })
        .collect();
    let derivatives = derivatives.into_iter().collect::<Result<Vec<_>, _>>()?;
    let m = base.len();
    let nc = current_columns.len();
    let jt = DMatrix::from_fn(m, nc, |i, j| derivatives[j][i]);
    let jp = DMatrix::from_fn(m, tested.len(), |i, j| derivatives[nc + j][i]);
    let projected = if nc > 0 {
        let svd = jt.clone().svd(true, true);
        let coefficients = svd
            .solve(&jp, 1e-10 * svd.singular_values.max())
            .map_err(|e| DiagnoseError::InvalidOption {
                field: "score test",
                reason: e.to_string(),
            })?;
        &jp - &jt * coefficients
    } else {
        jp
    };
    let r = nalgebra::DVector::from_vec(base);
    let score = projected.transpose() * &r;
    let information = projected.transpose() * &projected;
    let svd = information.svd(true, true);
    let tolerance = 1e-10 * svd.singular_values.max();
    let rank = svd
        .singular_values
        .iter()
        .filter(|&&s| s > tolerance)
        .count();
    let solved = svd
        .solve(&score, tolerance)
        .map_err(|e| DiagnoseError::InvalidOption {
            field: "score test",
            reason: e.to_string(),
        })?;
    let mut statistic = score.dot(&solved).max(0.0);
    // One tested parameter on a bound at its null: only the feasible side counts.
    if tested.len() == 1 {
        let spec = &augmented.parameters[tested[0]];
        let descent = -score[0];
        let blocked_below = spec.lower.is_some_and(|l| spec.null <= l) && descent < 0.0;
        let blocked_above = spec.upper.is_some_and(|u| spec.null >= u) && descent > 0.0;
        if blocked_below || blocked_above {
            statistic = 0.0;
        }
    }
    Ok((statistic, rank))
}

/// Scores and refits every catalog effect not in `current`, best first
/// (by likelihood-ratio p-value, then by score).
pub(crate) fn rank_candidates(
    context: &Context,
    current: &Model,
    fitted: &Fitted,
) -> Result<Vec<Ranked>, DiagnoseError> {
    let n = context.measured.len() as f64;
    let missing: Vec<_> = crate::effect::catalog()
        .into_iter()
        .filter(|effect| !current.spec.effects.iter().any(|id| id == effect.id()))
        .collect();
    // Candidates are independent refits: one per thread.
    let mut out = missing
        .par_iter()
        .map(|effect| -> Result<Ranked, DiagnoseError> {
            let spec = current.spec.with(effect.id());
            let start = current.baseline(&fitted.params);
            let augmented = Model::new(&spec, &context.forward.geometry, start)?;
            let (score, score_dof) = score_test(context, current, fitted, &augmented)?;
            // The probe's contact width is the apparatus, not physics an
            // effect could explain: it stays at the current fit's value.
            let mut hold = vec![false; augmented.len()];
            hold[PROBE_WIDTH] = true;
            let refit = fit_model(context, &augmented, &fitted.params, &hold)?;
            let added = augmented.len() - current.len();
            let likelihood_ratio = (fitted.chi2 - refit.chi2).max(0.0);
            let free = refit.report.params.len() as f64;
            Ok(Ranked {
                candidate: Candidate {
                    effect: effect.id().to_string(),
                    score,
                    score_p: chi2_upper_tail(score, score_dof),
                    score_dof,
                    likelihood_ratio,
                    likelihood_ratio_p: chi2_upper_tail(likelihood_ratio, added),
                    aic: refit.chi2 + 2.0 * free,
                    bic: refit.chi2 + free * n.ln(),
                    fit_with: refit.fit,
                },
                spec,
                fitted: refit,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    out.sort_by(|a, b| {
        a.candidate
            .likelihood_ratio_p
            .total_cmp(&b.candidate.likelihood_ratio_p)
            .then(
                b.candidate
                    .likelihood_ratio
                    .total_cmp(&a.candidate.likelihood_ratio),
            )
    });
    Ok(out)
}
