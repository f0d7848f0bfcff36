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
//! columns of $J_\theta$ (the current parameters re-adjust, all but the
//! probe's contact width, which the refits hold as well). The statistic
//! $S = U^T I^{+} U$ is $\chi^2_k$ under the null (the model is right and
//! the noise as stated), $k$ the number of tested parameters. When the
//! only tested parameter sits on a bound at its null value and the score
//! points out of the feasible side, $S = 0$. $J_\psi$ uses forward
//! differences of $10^{-3}$ of the parameter's scale into the feasible side
//! (the support compliance, whose null is the rigid limit, needs a finite
//! step), re-placing the needle loads from the current fit's placements in
//! one round (`place::RANKING_NEAR_ROUNDS`), as the refits' columns do.
//! $J_\theta$ is the same for every candidate (each effect is silent at
//! its null): it is the current fit's own, the Jacobian its covariance
//! came from ([`needle_lsq::FitReport::jacobian`]), whose columns place the
//! loads in `place::NEAR_ROUNDS` rounds and lie nearer the model's own
//! derivatives than one round's (the test
//! `the_fit_s_own_jacobian_is_nearer_the_model_s_than_the_ranking_s_differences`).
//! Where a fit ended without one, $J_\theta$ is differenced with steps of
//! $10^{-6}$ of the scale, beside the candidates' columns. A column of
//! either that is, trial by trial, a multiple of a current baseline
//! parameter's ([`crate::effect::Effect::chain`]: the speed's friction
//! slope of the shaft density's, the stiffening rate of $E$'s) is taken
//! from that column instead.
//!
//! **Refit.** The best candidate by score is always refitted. Each other
//! is refitted only if its score p-value is below 0.05 *and* its score is
//! at least a tenth of the larger of the leader's likelihood ratio and the
//! least likelihood ratio the verdict names an effect with (its share
//! `min_explained` of the misfit left to explain): the score is the local
//! (quadratic) prediction of the likelihood ratio, so a candidate below
//! that bar would have to explain ten times what its score says to
//! overtake the leader or to be named at all (the ratio of the two stays
//! within 1.0 to 2.2 on the quick campaign, 0.99 to 1.09 on the default).
//! The rest keep their score alone (`refitted: false`), which saves the
//! costliest work of a step: a refit is a whole fit. The others that pass
//! the rule with the leader's score in place of its ratio are refitted
//! beside the leader, to keep both cores busy; one that the leader's
//! actual ratio rules out is then reported as not refitted, and one it
//! lets in is refitted after, so the outcome is the rule's.
//!
//! The model with the effect added is fitted from the score test's
//! Gauss-Newton step, $\Delta\psi = -I^{+}U$ with the current parameters
//! re-adjusting by $-C\,\Delta\psi$ ($C$ the coefficients of $J_\psi$ on
//! $J_\theta$), kept inside the bounds: where the score's local model holds,
//! that is close to the refit's optimum (on the default campaign's last
//! step the support compliance's refit started 340 times above the current
//! misfit from its initial value). Its first Jacobian is the score test's:
//! $J_\theta$ and $J_\psi$, taken one step away, with only the columns
//! they lack (untested parameters, current ones not estimated) differenced;
//! Broyden's updates follow (`fit::Precision::Candidate`). If that refit
//! ends above the current $\chi^2$, it is fitted again from
//! $(\hat\theta, \psi_\text{initial})$ and then from $\hat\theta$ with
//! $\psi$ next to its null (each from a new Jacobian, as the start has
//! moved); the likelihood ratio
//! $\Lambda = \chi^2_\text{now} - \chi^2_\text{with}$ is compared with
//! $\chi^2_{k'}$, $k'$ all the effect's parameters. AIC $= \chi^2 + 2 n_p$
//! and BIC $= \chi^2 + n_p \ln n$ are reported too.

use std::sync::Arc;

use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::chi2::chi2_upper_tail;
use crate::effect::EffectParameter;
use crate::error::DiagnoseError;
use crate::fit::{Context, Fit, Fitted, Precision, chained_rows, fit_model, fit_model_from};
use crate::forward::Placements;
use crate::model::{Model, PROBE_WIDTH};
use crate::place::RANKING_NEAR_ROUNDS;
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
    /// Whether the model with the effect was refitted (the best candidate
    /// by score always is, the others when their score could get them
    /// named); the fields below are `None` when not.
    pub refitted: bool,
    /// Likelihood-ratio statistic $\chi^2_\text{now} - \chi^2_\text{with}$.
    pub likelihood_ratio: Option<f64>,
    /// Its p-value with all the effect's parameters as dof.
    pub likelihood_ratio_p: Option<f64>,
    /// AIC of the model with the effect.
    pub aic: Option<f64>,
    /// BIC of the model with the effect.
    pub bic: Option<f64>,
    /// Misfit of the model with the effect; without a refit, the current
    /// fit (the effect at its null value).
    pub fit_with: Fit,
}

/// A candidate with its refitted model (kept to continue the ladder).
pub(crate) struct Ranked {
    pub candidate: Candidate,
    pub spec: ModelSpec,
    pub fitted: Option<Fitted>,
}

/// Candidates after the leader by score are refitted only with a score
/// p-value below this (far above any Bonferroni level, so no candidate that
/// could be named is skipped for want of a score) ...
const REFIT_SCORE_P: f64 = 0.05;
/// ... and a score at least this fraction of the larger of the leader's
/// likelihood ratio and the least one an effect is named with.
const REFIT_SCORE_FRACTION: f64 = 0.1;

/// The whitened residuals of the current fit, and where the Jacobian's
/// columns difference from: shared by every candidate's score test, since
/// each effect is silent at its null (`forward` tests this), so the
/// augmented models predict the same there.
///
/// The differences start the needle placement from the current fit's own
/// (see `fit`), so they difference the map that does that, whose value at
/// the fit is `near`; the score is taken on the model's residuals proper.
struct CurrentPoint {
    residuals: Vec<f64>,
    /// The current model's free parameters, in the order of the columns.
    free: Vec<usize>,
    placements: Arc<Placements>,
    near: Vec<f64>,
    /// The trial of every residual.
    row_trials: Vec<usize>,
}

impl CurrentPoint {
    fn new(context: &Context, current: &Model, fitted: &Fitted) -> Result<Self, DiagnoseError> {
        let residuals = context.whitening.apply(&fitted.residuals);
        let placements = Arc::clone(&fitted.placements);
        let near =
            context.whitened_near(current, &placements, &fitted.params, RANKING_NEAR_ROUNDS)?;
        // The refits hold the probe's contact width (see `refit_all`), so
        // the score test must not let it re-adjust either: the score is
        // then the local prediction of the refit's likelihood ratio, and
        // its step starts the refit at the width the refit keeps.
        let free: Vec<usize> = (0..current.len())
            .filter(|&k| {
                k != PROBE_WIDTH
                    && fitted.report.uncertainty.status[k] == needle_lsq::ParameterStatus::Estimated
            })
            .collect();
        Ok(Self {
            residuals,
            free,
            placements,
            near,
            row_trials: context.obs.row_trials(),
        })
    }

    /// Where parameter `k` of `model` at `at` acts only as a free
    /// parameter of the current model would ([`chained_rows`]): that
    /// parameter's position among the free ones, and the factors per
    /// residual.
    fn chain(
        &self,
        context: &Context,
        model: &Model,
        at: &[f64],
        k: usize,
    ) -> Option<(usize, Vec<f64>)> {
        let (source, factors) = chained_rows(model, at, k, &context.obs, &self.row_trials)?;
        let position = self.free.iter().position(|&f| f == source)?;
        Some((position, factors))
    }

    /// The Jacobian of the residuals in the free parameters, with its
    /// pseudo-inverse: the current fit's own where it ended with one,
    /// differenced where not.
    fn jacobian(
        &self,
        context: &Context,
        current: &Model,
        fitted: &Fitted,
    ) -> Result<CurrentColumns, DiagnoseError> {
        let at = fitted.params.as_slice();
        let base = Base {
            at,
            placements: &self.placements,
            residuals: &self.near,
        };
        let kept: Vec<Option<&[f64]>> = self
            .free
            .iter()
            .map(|&k| {
                let column = fitted.report.jacobian.get(k)?.as_ref()?;
                Some(column.as_slice())
            })
            .collect();
        // A column that is a multiple of a baseline parameter's is taken
        // from it (the baseline's own never are).
        let chains: Vec<_> = self
            .free
            .iter()
            .zip(&kept)
            .map(|(&k, kept)| match kept {
                Some(_) => None,
                None => self.chain(context, current, at, k),
            })
            .collect();
        let differenced = self
            .free
            .par_iter()
            .zip(&chains)
            .zip(&kept)
            .map(|((&k, chain), kept)| match (chain, kept) {
                (None, None) => forward_difference(context, current, &base, k, 1e-6).map(Some),
                _ => Ok(None),
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut columns = DMatrix::zeros(self.residuals.len(), self.free.len());
        for (j, column) in differenced.iter().enumerate() {
            if let Some(column) = column.as_deref().or(kept[j]) {
                columns.column_mut(j).copy_from_slice(column);
            }
        }
        for (j, chain) in chains.iter().enumerate() {
            if let Some((source, factors)) = chain {
                let column = chained(&columns, *source, factors);
                columns.column_mut(j).copy_from_slice(&column);
            }
        }
        CurrentColumns::new(columns)
    }
}

impl CurrentColumns {
    /// `columns` with their pseudo-inverse.
    fn new(columns: DMatrix<f64>) -> Result<Self, DiagnoseError> {
        let pseudo_inverse = if columns.ncols() > 0 {
            let svd = columns.clone().svd(true, true);
            let tolerance = 1e-10 * svd.singular_values.max();
            svd.pseudo_inverse(tolerance)
                .map_err(|e| DiagnoseError::InvalidOption {
                    field: "score test",
                    reason: e.to_string(),
                })?
        } else {
            DMatrix::zeros(0, columns.nrows())
        };
        Ok(Self {
            columns,
            pseudo_inverse,
        })
    }
}

/// Column `source` of `columns` times `factors`, row by row.
fn chained(columns: &DMatrix<f64>, source: usize, factors: &[f64]) -> Vec<f64> {
    columns
        .column(source)
        .iter()
        .zip(factors)
        .map(|(d, f)| f * d)
        .collect()
}

/// The current parameters' Jacobian $J_\theta$ and its pseudo-inverse
/// (singular values below $10^{-10}$ of the largest dropped), which every
/// candidate's projection shares.
struct CurrentColumns {
    columns: DMatrix<f64>,
    pseudo_inverse: DMatrix<f64>,
}

/// The point a forward difference steps from: its parameters, needle
/// placements and whitened residuals from those placements.
struct Base<'a> {
    at: &'a [f64],
    placements: &'a Placements,
    residuals: &'a [f64],
}

/// $\partial r / \partial p_k$ by a forward difference of `relative` times
/// the parameter's scale (or value), stepping back from an upper bound.
fn forward_difference(
    context: &Context,
    model: &Model,
    base: &Base<'_>,
    k: usize,
    relative: f64,
) -> Result<Vec<f64>, DiagnoseError> {
    let at = base.at;
    let spec = &model.parameters[k];
    let mut h = relative * spec.scale.max(at[k].abs());
    if spec.upper.is_some_and(|u| at[k] + h > u) {
        h = -h;
    }
    let mut p = at.to_vec();
    p[k] += h;
    let r = context.whitened_near(model, base.placements, &p, RANKING_NEAR_ROUNDS)?;
    Ok(r.iter()
        .zip(base.residuals)
        .map(|(a, b)| (a - b) / h)
        .collect())
}

/// What the score test finds for one candidate.
struct Score {
    statistic: f64,
    /// The number of tested parameters that the data inform.
    rank: usize,
    /// The Gauss-Newton step from the current fit with the candidate at
    /// its null, kept inside the bounds: where its refit starts.
    one_step: Vec<f64>,
    /// The tested parameters and their columns.
    tested: Vec<(usize, Vec<f64>)>,
}

/// A candidate's tested parameters and the derivatives of the residuals
/// in them at its null, from the current fit.
struct TestedColumns {
    /// The augmented model's parameters at the current fit, the effect's at
    /// their null (tested) or initial value (untested).
    at: Vec<f64>,
    tested: Vec<usize>,
    /// Per tested parameter, its column; empty where it is a multiple of a
    /// current column, which `chains` gives.
    derivatives: Vec<Vec<f64>>,
    /// Per tested parameter, the current free parameter whose column it is
    /// a multiple of, and the factors ([`CurrentPoint::chain`]).
    chains: Vec<Option<(usize, Vec<f64>)>>,
}

impl TestedColumns {
    /// Fills the columns that are multiples of the current ones.
    fn complete(&mut self, current: &CurrentColumns) {
        for (derivative, chain) in self.derivatives.iter_mut().zip(&self.chains) {
            if let Some((source, factors)) = chain {
                *derivative = chained(&current.columns, *source, factors);
            }
        }
    }
}

/// The columns of the effect that extends the current model to `augmented`.
fn tested_columns(
    context: &Context,
    point: &CurrentPoint,
    fitted: &Fitted,
    augmented: &Model,
) -> Result<TestedColumns, DiagnoseError> {
    let n_current = fitted.params.len();
    let mut at: Vec<f64> = fitted.params.clone();
    at.extend(
        augmented.parameters[n_current..]
            .iter()
            .map(|p| if p.tested { p.null } else { p.initial }),
    );
    let tested: Vec<usize> = (n_current..augmented.len())
        .filter(|&k| augmented.parameters[k].tested)
        .collect();
    // Each effect is silent at its null, so the augmented model places the
    // loads where the current one does.
    let near = Base {
        at: &at,
        placements: &point.placements,
        residuals: &point.near,
    };
    let chains: Vec<_> = tested
        .iter()
        .map(|&k| point.chain(context, augmented, &at, k))
        .collect();
    let derivatives = tested
        .par_iter()
        .zip(&chains)
        .map(|(&k, chain)| match chain {
            Some(_) => Ok(Vec::new()),
            None => forward_difference(context, augmented, &near, k, 1e-3),
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(TestedColumns {
        at,
        tested,
        derivatives,
        chains,
    })
}

/// Score statistic of the effect whose columns are `columns`, with
/// `current` the current parameters' columns.
fn score_test(
    point: &CurrentPoint,
    current: &CurrentColumns,
    fitted: &Fitted,
    augmented: &Model,
    columns: TestedColumns,
) -> Result<Score, DiagnoseError> {
    let n_current = fitted.params.len();
    let mut columns = columns;
    columns.complete(current);
    let TestedColumns {
        at,
        tested,
        derivatives,
        ..
    } = columns;
    let base = &point.residuals;
    let m = base.len();
    let jp = DMatrix::from_fn(m, tested.len(), |i, j| derivatives[j][i]);
    let tested_columns: Vec<(usize, Vec<f64>)> = tested.iter().copied().zip(derivatives).collect();
    let coefficients = &current.pseudo_inverse * &jp;
    let projected = &jp - &current.columns * &coefficients;
    let r = nalgebra::DVector::from_column_slice(base);
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
    // The step minimises $|r + J_\theta \Delta\theta + J_\psi \Delta\psi|$:
    // $\Delta\psi = -I^{+} U$, and the current parameters re-adjust by
    // $\Delta\theta = -C \Delta\psi$ with $J_\psi = J_\theta C + \tilde J_\psi$
    // ($J_\theta^T r = 0$ at the current fit).
    let step_psi = -solved;
    let step_theta = &coefficients * &step_psi;
    let mut one_step = at;
    for (j, &k) in point.free.iter().enumerate() {
        one_step[k] -= step_theta[j];
    }
    for (j, &k) in tested.iter().enumerate() {
        one_step[k] += step_psi[j];
    }
    for (value, spec) in one_step.iter_mut().zip(&augmented.parameters) {
        *value = inside_bounds(*value, spec);
    }
    if one_step.iter().any(|v| !v.is_finite()) {
        one_step = augmented.parameters.iter().map(|p| p.initial).collect();
        one_step[..n_current].copy_from_slice(&fitted.params);
    }
    Ok(Score {
        statistic,
        rank,
        one_step,
        tested: tested_columns,
    })
}

/// `value` moved $10^{-3}$ of the parameter's scale inside a bound it
/// reaches or crosses (where the bound's transformation has no slope).
fn inside_bounds(value: f64, spec: &EffectParameter) -> f64 {
    let step = 1e-3 * spec.scale;
    match (spec.lower, spec.upper) {
        (Some(l), _) if value <= l => l + step,
        (_, Some(u)) if value >= u => u - step,
        _ => value,
    }
}

/// Scores every catalog effect not in `current`, refits those worth it
/// (the best by score, then any other with a score p-value below
/// [`REFIT_SCORE_P`] and a score of at least [`REFIT_SCORE_FRACTION`] of
/// the larger of the leader's likelihood ratio and `naming_ratio`, the
/// least likelihood ratio an effect is named with), and returns them all,
/// best first: refitted ones by likelihood-ratio p-value, then by score.
pub(crate) fn rank_candidates(
    context: &Context,
    current: &Model,
    fitted: &Fitted,
    naming_ratio: f64,
) -> Result<Vec<Ranked>, DiagnoseError> {
    let point = CurrentPoint::new(context, current, fitted)?;
    // Candidates are differenced side by side, and beside the current
    // parameters' columns: each has only its one or two tested columns to
    // run in parallel, and some solve bodies of their own (springs, the
    // whole slab under a foundation).
    let (jacobian, differenced) = rayon::join(
        || point.jacobian(context, current, fitted),
        || {
            crate::effect::catalog()
                .into_par_iter()
                .filter(|effect| !current.spec.effects.iter().any(|id| id == effect.id()))
                .map(|effect| -> Result<_, DiagnoseError> {
                    let spec = current.spec.with(effect.id());
                    let start = current.baseline(&fitted.params);
                    let augmented = Model::new(&spec, &context.forward.geometry, start)?;
                    let columns = tested_columns(context, &point, fitted, &augmented)?;
                    Ok((effect.id(), spec, augmented, columns))
                })
                .collect::<Result<Vec<_>, _>>()
        },
    );
    let jacobian = jacobian?;
    let mut scored = differenced?
        .into_par_iter()
        .map(
            |(id, spec, augmented, columns)| -> Result<_, DiagnoseError> {
                let Score {
                    statistic: score,
                    rank: score_dof,
                    one_step,
                    tested,
                } = score_test(&point, &jacobian, fitted, &augmented, columns)?;
                Ok(Scored {
                    candidate: Candidate {
                        effect: id.to_string(),
                        score,
                        score_p: chi2_upper_tail(score, score_dof),
                        score_dof,
                        refitted: false,
                        likelihood_ratio: None,
                        likelihood_ratio_p: None,
                        aic: None,
                        bic: None,
                        fit_with: fitted.fit,
                    },
                    spec,
                    augmented,
                    one_step,
                    tested,
                })
            },
        )
        .collect::<Result<Vec<_>, _>>()?;
    // p-values underflow to 0 for large scores: those tie-break by score.
    scored.sort_by(|a, b| {
        (a.candidate.score_p.total_cmp(&b.candidate.score_p))
            .then(b.candidate.score.total_cmp(&a.candidate.score))
    });
    let others = scored.split_off(1.min(scored.len()));
    // Refitted beside the leader: the others worth it with the leader's
    // score as the prediction of its ratio (see the module doc).
    let predicted = scored
        .iter()
        .map(|s| s.candidate.score)
        .fold(naming_ratio, f64::max);
    let mut first = scored;
    let mut as_scored = Vec::new();
    let mut held = Vec::new();
    for s in others {
        if worth_refitting(&s.candidate, predicted) {
            as_scored.push(s.candidate.clone());
            first.push(s);
        } else {
            held.push(s);
        }
    }
    let seed = Seed {
        free: &point.free,
        columns: &jacobian.columns,
    };
    let mut out = refit_all(context, current, fitted, &seed, first)?;
    let speculated = out.split_off(out.len() - as_scored.len());
    let bar = out
        .iter()
        .filter_map(|r| r.candidate.likelihood_ratio)
        .fold(naming_ratio, f64::max);
    for (ranked, candidate) in speculated.into_iter().zip(as_scored) {
        if worth_refitting(&candidate, bar) {
            out.push(ranked);
        } else {
            out.push(Ranked {
                candidate,
                spec: ranked.spec,
                fitted: None,
            });
        }
    }
    let (worth, rest): (Vec<Scored>, Vec<Scored>) = held
        .into_iter()
        .partition(|s| worth_refitting(&s.candidate, bar));
    out.extend(refit_all(context, current, fitted, &seed, worth)?);
    out.extend(rest.into_iter().map(|s| Ranked {
        candidate: s.candidate,
        spec: s.spec,
        fitted: None,
    }));
    out.sort_by(|a, b| {
        let p = |r: &Ranked| r.candidate.likelihood_ratio_p.unwrap_or(f64::INFINITY);
        p(a).total_cmp(&p(b))
            .then(b.candidate.score.total_cmp(&a.candidate.score))
    });
    Ok(out)
}

/// Whether a candidate after the leader is refitted, `bar` being the
/// larger of the leader's likelihood ratio and the least one an effect is
/// named with.
fn worth_refitting(candidate: &Candidate, bar: f64) -> bool {
    candidate.score_p < REFIT_SCORE_P && candidate.score >= REFIT_SCORE_FRACTION * bar
}

/// A candidate scored, with its augmented model.
struct Scored {
    candidate: Candidate,
    spec: ModelSpec,
    augmented: Model,
    /// Where its refit starts (see [`Score::one_step`]).
    one_step: Vec<f64>,
    /// Its tested parameters' columns (see [`Score::tested`]).
    tested: Vec<(usize, Vec<f64>)>,
}

/// The current fit's Jacobian, which starts each refit's: its columns for
/// the current model's free parameters `free`.
struct Seed<'a> {
    free: &'a [usize],
    columns: &'a DMatrix<f64>,
}

impl Seed<'_> {
    /// One entry per parameter of `augmented`: the current fit's column of
    /// each current free parameter, the score test's of each tested one,
    /// none for the rest.
    fn columns<'a>(
        &'a self,
        augmented: &Model,
        tested: &'a [(usize, Vec<f64>)],
    ) -> Vec<Option<&'a [f64]>> {
        let mut columns = vec![None; augmented.len()];
        // Column-major: column j is the j-th run of `nrows` values.
        let runs = self.columns.as_slice().chunks(self.columns.nrows().max(1));
        for (&k, column) in self.free.iter().zip(runs) {
            columns[k] = Some(column);
        }
        for (k, column) in tested {
            columns[*k] = Some(column.as_slice());
        }
        columns
    }
}

/// The candidate's parameters next to their null: stepped $10^{-3}$ of
/// the scale inside a bound the null sits on (where the bound's
/// transformation has no slope), untested ones at `initial`, after the
/// current fit's.
fn near_null_start(augmented: &Model, current: &[f64]) -> Vec<f64> {
    let added = augmented.parameters[current.len()..].iter().map(|p| {
        if !p.tested {
            return p.initial;
        }
        let step = 1e-3 * p.scale;
        if p.lower.is_some_and(|l| p.null <= l) {
            p.null + step
        } else if p.upper.is_some_and(|u| p.null >= u) {
            p.null - step
        } else {
            p.null
        }
    });
    current.iter().copied().chain(added).collect()
}

/// Refits every candidate of `scored` (one per thread) and fills in its
/// likelihood ratio and information criteria.
fn refit_all(
    context: &Context,
    current: &Model,
    fitted: &Fitted,
    seed: &Seed<'_>,
    scored: Vec<Scored>,
) -> Result<Vec<Ranked>, DiagnoseError> {
    let n = context.measured.len() as f64;
    scored
        .into_par_iter()
        .map(|s| {
            let Scored {
                mut candidate,
                spec,
                augmented,
                one_step,
                tested,
            } = s;
            // The probe's contact width is the apparatus, not physics an
            // effect could explain: it stays at the current fit's value.
            let mut hold = vec![false; augmented.len()];
            hold[PROBE_WIDTH] = true;
            // From the score test's step, then, if a refit ends above the
            // current fit, from the effect's initial values (some start
            // away from their null, `out_of_plane` at the full slab) and
            // from next to its null, which cannot end much above it.
            // Its first Jacobian is the current fit's with the tested
            // columns beside it, taken one step away.
            let columns = seed.columns(&augmented, &tested);
            let mut with = fit_model_from(
                context,
                &augmented,
                &one_step,
                &hold,
                Precision::Candidate,
                &columns,
            )?;
            for start in [
                fitted.params.clone(),
                near_null_start(&augmented, &fitted.params),
            ] {
                if with.chi2 <= fitted.chi2 {
                    break;
                }
                let again = fit_model(context, &augmented, &start, &hold, Precision::Candidate)?;
                if again.chi2 < with.chi2 {
                    with = again;
                }
            }
            let added = augmented.len() - current.len();
            let likelihood_ratio = (fitted.chi2 - with.chi2).max(0.0);
            let free = with.report.params.len() as f64;
            candidate.refitted = true;
            candidate.likelihood_ratio = Some(likelihood_ratio);
            candidate.likelihood_ratio_p = Some(chi2_upper_tail(likelihood_ratio, added));
            candidate.aic = Some(with.chi2 + 2.0 * free);
            candidate.bic = Some(with.chi2 + free * n.ln());
            candidate.fit_with = with.fit;
            Ok(Ranked {
                candidate,
                spec,
                fitted: Some(with),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use needle_data::TrialKind;

    use super::*;
    use crate::forward::Start;
    use crate::forward::tests::{observations_of, paper_forward_of};
    use crate::model::test_model;
    use crate::whiten::Whitening;

    /// The weights and data of `trials` as the model makes them with
    /// `effect`'s first parameter at `value` (the rest at their initial
    /// values), without noise; and models of the paper's phantom with
    /// the effects given.
    fn made_by_the_model(
        trials: &[(&str, TrialKind, f64, f64)],
        effect: &str,
        value: f64,
    ) -> (Context, impl Fn(&[&str]) -> Model) {
        let (obs, forward, start) = paper_forward_of(observations_of(trials));
        let geometry = forward.geometry;
        let model = move |ids: &[&str]| {
            Model::new(&ModelSpec::from_ids(ids).unwrap(), &geometry, start).unwrap()
        };
        let truth = model(&[effect]);
        let mut p_true: Vec<f64> = truth.parameters.iter().map(|p| p.initial).collect();
        p_true[crate::model::BASELINE_PARAMETERS] = value;
        let measured = forward.predict(&truth, &p_true, &obs).unwrap().values;
        let context = Context {
            whitening: Whitening::independent(obs.marker_count(), 1e-6, &obs.row_sigmas(), 1e-4),
            forward,
            obs,
            measured,
        };
        (context, model)
    }

    #[test]
    fn the_score_test_s_step_explains_most_of_an_effect_linear_in_its_parameter() {
        // Data made by the model itself with a tip peak (at a given shaft
        // density the load is linear in its excess length): from the
        // baseline's fit, one Gauss-Newton step of the excess, with the
        // baseline's parameters re-adjusting, must remove nearly all the
        // misfit the missing peak leaves.
        // A peak 1.5 times the shaft density over the initial 5 mm width.
        let excess = 1.5 * 0.005 / 2.0;
        let trials = [
            ("probe", TrialKind::Probe, 2.0, 0.0),
            ("shallow", TrialKind::Needle, 3.0, 0.03),
            ("deep", TrialKind::Needle, 3.0, 0.05),
        ];
        let (context, model) = made_by_the_model(&trials, "tip_cutting_force", excess);
        let truth = model(&["tip_cutting_force"]);
        let baseline = model(&[]);
        let fitted = fit_model(&context, &baseline, &[], &[], Precision::Model).unwrap();
        assert!(fitted.chi2 > 100.0, "the effect is seen: {}", fitted.chi2);
        let point = CurrentPoint::new(&context, &baseline, &fitted).unwrap();
        let jacobian = point.jacobian(&context, &baseline, &fitted).unwrap();
        let columns = tested_columns(&context, &point, &fitted, &truth).unwrap();
        let score = score_test(&point, &jacobian, &fitted, &truth, columns).unwrap();
        let chi2 = |p: &[f64]| -> f64 {
            let (residuals, _) = context.evaluate(&truth, p, Start::Cold).unwrap();
            context
                .whitening
                .apply(&residuals)
                .iter()
                .map(|r| r * r)
                .sum()
        };
        let stepped = chi2(&score.one_step);
        assert!(
            stepped < 0.05 * fitted.chi2,
            "one step leaves {stepped} of {}",
            fitted.chi2
        );
        let stepped_excess = score.one_step[crate::model::BASELINE_PARAMETERS];
        assert!(
            (stepped_excess - excess).abs() < 0.1 * excess,
            "excess {stepped_excess} against {excess}"
        );
    }

    #[test]
    fn the_fit_s_own_jacobian_is_nearer_the_model_s_than_the_ranking_s_differences() {
        // The ranking takes $J_\theta$ from the current fit, where its
        // covariance came from (columns in `NEAR_ROUNDS` placement rounds,
        // within 1 % of the model's own); the ranking's own differences (one
        // round, within 2.5 %) are further from the model's, and so are the
        // candidates' scores taken with them. A weak candidate's score is
        // the most sensitive: here 181.3 with the model's columns, 183.7
        // with the fit's, 170.6 with the ranking's.
        let trials = [
            ("probe", TrialKind::Probe, 2.0, 0.0),
            ("early", TrialKind::Needle, 1.0, 0.04),
            ("late", TrialKind::Needle, 5.0, 0.05),
        ];
        let (context, model) = made_by_the_model(&trials, "material_stiffening", 0.01);
        let baseline = model(&[]);
        let mut fitted = fit_model(&context, &baseline, &[], &[], Precision::Model).unwrap();
        let point = CurrentPoint::new(&context, &baseline, &fitted).unwrap();
        assert!(
            point
                .free
                .iter()
                .all(|&k| fitted.report.jacobian[k].is_some()),
            "the fit ends with a Jacobian in every parameter the ranking uses"
        );
        let kept = point.jacobian(&context, &baseline, &fitted).unwrap();
        fitted.report.jacobian.clear();
        let differenced = point.jacobian(&context, &baseline, &fitted).unwrap();
        // The model's own central differences, each load placed from the
        // spatial line.
        let whitened = |p: &[f64]| {
            let (residuals, _) = context.evaluate(&baseline, p, Start::Cold).unwrap();
            nalgebra::DVector::from_vec(context.whitening.apply(&residuals))
        };
        let mut reference = DMatrix::zeros(point.residuals.len(), point.free.len());
        for (j, &k) in point.free.iter().enumerate() {
            let h = 1e-5 * baseline.parameters[k].scale.max(fitted.params[k].abs());
            let mut plus = fitted.params.clone();
            let mut minus = fitted.params.clone();
            plus[k] += h;
            minus[k] -= h;
            reference.set_column(j, &((whitened(&plus) - whitened(&minus)) / (2.0 * h)));
        }
        let reference = CurrentColumns::new(reference).unwrap();
        for j in 0..point.free.len() {
            let exact = reference.columns.column(j);
            let gap = |c: &CurrentColumns| (c.columns.column(j) - exact).norm() / exact.norm();
            let (a, b) = (gap(&kept), gap(&differenced));
            assert!(a < 0.01 && b < 0.025 && a <= b, "column {j}: {a}, {b}");
        }
        for id in [
            "material_stiffening",
            "tip_cutting_force",
            "layered_stiffness",
        ] {
            let augmented = model(&[id]);
            let score = |current: &CurrentColumns| {
                let columns = tested_columns(&context, &point, &fitted, &augmented).unwrap();
                score_test(&point, current, &fitted, &augmented, columns)
                    .unwrap()
                    .statistic
            };
            let (a, b, c) = (score(&kept), score(&differenced), score(&reference));
            let summary = format!("{id}: {a}, differenced {b}, model's {c}");
            assert!((a - c).abs() <= (0.02 * c).min((b - c).abs()), "{summary}");
        }
    }

    #[test]
    fn only_candidates_within_a_tenth_of_the_bar_by_score_are_refitted() {
        let fit = Fit {
            rms_marker: 1.0,
            rms_force: 1.0,
            chi2_marker: 1.0,
            chi2_force: 1.0,
        };
        let candidate = |score: f64, score_p: f64| Candidate {
            effect: "layered_stiffness".into(),
            score,
            score_p,
            score_dof: 1,
            refitted: false,
            likelihood_ratio: None,
            likelihood_ratio_p: None,
            aic: None,
            bic: None,
            fit_with: fit,
        };
        // The default campaign's last step: the least ratio named is 870
        // (0.2 of the misfit left), above the leader's 322; behind the
        // leader, scores of 183 and 47.
        let bar = 870.0;
        assert!(worth_refitting(&candidate(183.0, 1e-41), bar));
        assert!(worth_refitting(&candidate(87.0, 1e-20), bar));
        assert!(!worth_refitting(&candidate(86.9, 1e-20), bar));
        assert!(!worth_refitting(&candidate(47.0, 1e-12), bar));
        // Significant enough by score, but not below the refit p-value.
        assert!(!worth_refitting(&candidate(3.0, 0.08), 20.0));
        assert!(worth_refitting(&candidate(4.0, 0.045), 20.0));
    }

    #[test]
    fn a_null_on_a_bound_starts_just_inside_it() {
        let current = [25e3, 0.45, 10.0, 0.002];
        for (id, inside) in [
            ("out_of_plane", true),
            ("velocity_dependent_friction", false),
        ] {
            let model = test_model(&[id]);
            let p = &model.parameters[current.len()];
            let at = near_null_start(&model, &current);
            assert_eq!(&at[..current.len()], &current);
            // out_of_plane's null (0) is its lower bound; the velocity slope's is free.
            let expected = if inside {
                p.null + 1e-3 * p.scale
            } else {
                p.null
            };
            assert_eq!(at[current.len()], expected, "{id}");
        }
    }
}
