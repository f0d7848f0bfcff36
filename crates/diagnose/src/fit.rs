//! Fit a model to all trials jointly and measure its misfit per channel.
//!
//! Residuals are model minus data, whitened by the noise covariance of
//! `whiten` (independent marker and force noise, plus each probe frame's
//! force noise carried to its markers through the unit responses).

use std::sync::{Arc, Mutex};

use needle_lsq::{JacobianUpdates, LevenbergMarquardt, Problem};
use serde::{Deserialize, Serialize};

use crate::error::DiagnoseError;
use crate::forward::{Forward, Placements, Start};
use crate::model::{Model, PROBE_WIDTH};
use crate::observe::Observations;
use crate::place::{NEAR_ROUNDS, RANKING_NEAR_ROUNDS};
use crate::whiten::Whitening;

/// Misfit of a fitted model, per channel. A channel without data has `NaN`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Fit {
    /// RMS marker residual (m).
    pub rms_marker: f64,
    /// RMS base force residual (N).
    pub rms_force: f64,
    /// Chi-square per degree of freedom of the marker channel.
    pub chi2_marker: f64,
    /// Chi-square per degree of freedom of the force channel.
    pub chi2_force: f64,
}

/// The data and weights every fit of one diagnosis shares.
pub(crate) struct Context {
    pub forward: Forward,
    pub obs: Observations,
    pub measured: Vec<f64>,
    pub whitening: Whitening,
}

impl Context {
    /// Residuals model - data at `p` with the needle loads placed from
    /// `start`, not whitened, and where the loads ended up.
    pub fn evaluate(
        &self,
        model: &Model,
        p: &[f64],
        start: Start<'_>,
    ) -> Result<(Vec<f64>, Placements), DiagnoseError> {
        let (prediction, placements) = self.forward.predict_from(model, p, &self.obs, start)?;
        let residuals = prediction
            .values
            .iter()
            .zip(&self.measured)
            .map(|(m, y)| m - y)
            .collect();
        Ok((residuals, placements))
    }

    /// Whitened residuals at `p` with the loads placed from `placements`
    /// in `rounds` rounds: the map a finite-difference column around the
    /// point that `placements` come from differences.
    pub fn whitened_near(
        &self,
        model: &Model,
        placements: &Placements,
        p: &[f64],
        rounds: usize,
    ) -> Result<Vec<f64>, DiagnoseError> {
        let start = Start::Near { placements, rounds };
        Ok(self.whitening.apply(&self.evaluate(model, p, start)?.0))
    }
}

/// A fitted model.
pub(crate) struct Fitted {
    pub params: Vec<f64>,
    pub report: needle_lsq::FitReport,
    pub fit: Fit,
    /// $\sum r_i^2$ (whitened).
    pub chi2: f64,
    /// Unwhitened residuals model - data.
    pub residuals: Vec<f64>,
    /// Where the model placed the needle loads at `params`.
    pub placements: Arc<Placements>,
    /// Degrees of freedom of each channel (marker, force).
    pub dof: [f64; 2],
}

/// How many evaluations a fit keeps: the Jacobian is taken at the point
/// last accepted, which is the last or next-to-last evaluated, and the fit
/// ends at it or at the point of its last Jacobian (see
/// [`Precision::Model`]), as a rule among the last three evaluated (else
/// evaluated again).
const KEPT_EVALUATIONS: usize = 3;

/// One evaluation of the model proper: its parameters, its residuals
/// (model - data, not whitened) and where it placed the needle loads.
struct Evaluation {
    params: Vec<f64>,
    residuals: Vec<f64>,
    placements: Arc<Placements>,
}

pub(crate) struct FitProblem<'a> {
    pub context: &'a Context,
    pub model: &'a Model,
    /// Rounds of the Jacobian's columns from the base point's placements.
    near_rounds: usize,
    /// The last evaluations of the model proper.
    evaluations: Mutex<Vec<Evaluation>>,
    /// The columns' own map at the base point of the Jacobian being
    /// differenced: its parameters and solutions, which the columns of
    /// parameters acting after the solves take (`Start::Reuse`).
    near_base: Mutex<Option<(Vec<f64>, Arc<Placements>)>>,
    /// The trial of every residual.
    row_trials: Vec<usize>,
}

impl<'a> FitProblem<'a> {
    pub fn new(context: &'a Context, model: &'a Model, near_rounds: usize) -> Self {
        Self {
            context,
            model,
            near_rounds,
            evaluations: Mutex::new(Vec::new()),
            near_base: Mutex::new(None),
            row_trials: context.obs.row_trials(),
        }
    }

    fn keep(&self, params: &[f64], residuals: Vec<f64>, placements: Placements) -> Arc<Placements> {
        let placements = Arc::new(placements);
        let mut kept = self.evaluations.lock().unwrap_or_else(|e| e.into_inner());
        if kept.len() == KEPT_EVALUATIONS {
            kept.remove(0);
        }
        kept.push(Evaluation {
            params: params.to_vec(),
            residuals,
            placements: Arc::clone(&placements),
        });
        placements
    }

    /// The residuals and placements of the model proper at `params`: kept
    /// if evaluated lately, else evaluated (and kept).
    fn evaluated_at(&self, params: &[f64]) -> Result<(Vec<f64>, Arc<Placements>), DiagnoseError> {
        let kept = self.evaluations.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(found) = kept.iter().find(|e| e.params.as_slice() == params) {
            return Ok((found.residuals.clone(), Arc::clone(&found.placements)));
        }
        drop(kept);
        let (residuals, placements) = self.context.evaluate(self.model, params, Start::Cold)?;
        let placements = self.keep(params, residuals.clone(), placements);
        Ok((residuals, placements))
    }
}

impl Problem for FitProblem<'_> {
    fn num_parameters(&self) -> usize {
        self.model.len()
    }

    fn num_residuals(&self) -> usize {
        self.context.measured.len()
    }

    fn residuals(
        &self,
        params: &[f64],
        out: &mut [f64],
    ) -> Result<(), needle_lsq::EvaluationError> {
        let (residuals, placements) = self.context.evaluate(self.model, params, Start::Cold)?;
        out.copy_from_slice(&self.context.whitening.apply(&residuals));
        self.keep(params, residuals, placements);
        Ok(())
    }

    /// The Jacobian's columns place the needle loads from the base point's
    /// placements in a few rounds ([`Precision::near_rounds`]) instead of
    /// from the spatial line: 2 or 3 back-substitutions per needle frame
    /// instead of 5 on the plane body and 4 on the slab. The columns of
    /// parameters that act after the solves (`out_of_plane`'s weight,
    /// `lens_distortion`) take this map's solutions at the base point,
    /// which the engine evaluates first, and solve nothing.
    fn residuals_near(
        &self,
        base: &[f64],
        params: &[f64],
        out: &mut [f64],
    ) -> Option<Result<(), needle_lsq::EvaluationError>> {
        let mut evaluate = || -> Result<(), DiagnoseError> {
            let stored = self.near_base.lock().unwrap_or_else(|e| e.into_inner());
            let reusable = stored.as_ref().and_then(|(at, solved)| {
                (params != base
                    && at.as_slice() == base
                    && self.model.solves_alike(base, params)
                    && solved.serve(self.model, params))
                .then(|| Arc::clone(solved))
            });
            drop(stored);
            let (residuals, placements) = match reusable {
                Some(solved) => {
                    let start = Start::Reuse { solved: &solved };
                    self.context.evaluate(self.model, params, start)?
                }
                None => {
                    let (_, placements) = self.evaluated_at(base)?;
                    let start = Start::Near {
                        placements: &placements,
                        rounds: self.near_rounds,
                    };
                    self.context.evaluate(self.model, params, start)?
                }
            };
            out.copy_from_slice(&self.context.whitening.apply(&residuals));
            if params == base {
                let mut stored = self.near_base.lock().unwrap_or_else(|e| e.into_inner());
                *stored = Some((base.to_vec(), Arc::new(placements)));
            }
            Ok(())
        };
        Some(evaluate().map_err(Into::into))
    }

    /// The column of a parameter that acts only as the baseline's shaft
    /// density or Young's modulus would ([`Model::chain`]), trial by trial
    /// a multiple of that parameter's: one column fewer to solve for. The
    /// whitening's blocks lie within single frames, so a factor per trial
    /// commutes with it.
    fn chained_column(&self, params: &[f64], j: usize) -> Option<(usize, Vec<f64>)> {
        chained_rows(self.model, params, j, &self.context.obs, &self.row_trials)
    }
}

/// Where parameter `k` acts only as a baseline parameter would
/// ([`Model::chain`]): that parameter and, per residual (`row_trials` its
/// trial), the factor from its whitened column to `k`'s.
pub(crate) fn chained_rows(
    model: &Model,
    params: &[f64],
    k: usize,
    obs: &Observations,
    row_trials: &[usize],
) -> Option<(usize, Vec<f64>)> {
    let (source, per_trial) = model.chain(params, k, &obs.trials)?;
    Some((source, row_trials.iter().map(|&t| per_trial[t]).collect()))
}

/// How precisely a fit is carried out. Both difference the model with
/// the needle loads placed from the base point's placements (see
/// [`FitProblem::residuals_near`]), in more rounds for the model proper.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Precision {
    /// The fits that set the current model: relative tolerance (cost
    /// reduction, step, gradient) 1e-8, columns in [`NEAR_ROUNDS`] rounds,
    /// whose derivatives are within 1% of the model's own differences. A
    /// fit whose last step lowers $\chi^2$ by less than the tolerance ends
    /// where that step started, at its last Jacobian
    /// ([`needle_lsq::Options::end_at_last_jacobian`]): one Jacobian fewer
    /// per fit, with $\chi^2$ within $10^{-8}$ of the step's end and the
    /// parameters within $\sqrt{10^{-8}\chi^2}$ standard errors of it
    /// (0.03 on the default campaign's last fit). That Jacobian gives
    /// the covariance and the ranking's $J_\theta$ (`rank`).
    Model,
    /// A candidate's refit in the ranking: relative tolerance 1e-4 on the
    /// cost reduction, 1e-5 on the gradient, 1e-8 on the step, and
    /// columns in [`RANKING_NEAR_ROUNDS`] round, within 2.5%. The step's
    /// test compares the trust region with the scaled norm of the
    /// internal coordinates, which a parameter near one end of a wide
    /// interval inflates (its coordinate near $-\pi/2$ stands for a value
    /// near the bound): at 1e-5, on the probing campaign of the test
    /// `an_added_effect_weighs_the_probe_frames_by_its_own_responses`,
    /// three rejected steps in a row stopped the `platform_friction`
    /// refit at 23 times its optimum's chi-square (20,409 against 901;
    /// `docs/benchmarks.md`, session 32). A refit stopped early has a
    /// chi-square a little too high, so its likelihood ratio is a
    /// lower bound: the ranking can only understate a candidate, never
    /// name one the data do not support, and the candidate named is
    /// refitted at [`Precision::Model`] before the next step. It stops
    /// once a step lowers $\chi^2$, and its model predicted it to lower
    /// it, by less than $10^{-4}\chi^2$. The least ratio the verdict names
    /// an effect with is at least `min_explained` $\cdot z\sqrt{2\nu}$
    /// (0.2, 3, and $\nu$ the markers' degrees of freedom), about
    /// $0.85\,\chi^2/\sqrt\nu$ near the noise: $3 \cdot 10^{-3}\chi^2$
    /// on the default campaign, thirty times the tolerance. There the
    /// cost tolerance's step from 1e-5 to 1e-4 took two Jacobians off the
    /// last step's `layered_stiffness` refit and understated its ratio by
    /// 0.9% (session 22).
    /// Only the refit's misfit and parameters are used, so it takes no
    /// Jacobian at its optimum for a covariance
    /// ([`needle_lsq::Options::uncertainty`]). For the same reason its
    /// Jacobian is updated by Broyden's formula after a step it predicted
    /// well instead of differenced again, and it may stop on an updated one
    /// ([`JacobianUpdates::BroydenStopOnUpdate`]): like the early stop,
    /// that can only leave its chi-square a little high. A step whose
    /// actual and predicted changes of $\chi^2$ are both below the
    /// tolerance ends it, however poor their ratio (on the default
    /// campaign's ladder four refits had taken a new Jacobian after such a
    /// step, one of them the last step's `compliant_support`: eight spring
    /// factorisations of the slab). Its first Jacobian is the score
    /// test's (`rank`). On the default campaign's ladder the refits took
    /// 72 model evaluations instead of 167 (session 30), and ended at most
    /// 2.9e-5 of their chi-square above the refits with a new Jacobian
    /// after every step (23 on 802,257), some below them.
    Candidate,
}

impl Precision {
    /// Relative tolerances on the cost reduction, the step and the
    /// gradient.
    fn tolerances(self) -> [f64; 3] {
        match self {
            Precision::Model => [1e-8, 1e-8, 1e-8],
            Precision::Candidate => [1e-4, 1e-8, 1e-5],
        }
    }

    /// How the fit's Jacobian follows its steps.
    fn jacobian_updates(self) -> JacobianUpdates {
        match self {
            Precision::Model => JacobianUpdates::Never,
            Precision::Candidate => JacobianUpdates::BroydenStopOnUpdate,
        }
    }

    /// Placement rounds of the Jacobian's columns.
    pub fn near_rounds(self) -> usize {
        match self {
            Precision::Model => NEAR_ROUNDS,
            Precision::Candidate => RANKING_NEAR_ROUNDS,
        }
    }
}

/// Fits `model` from `start` (its parameters' `initial` where `start` is
/// shorter) with `precision`, holding the parameters flagged
/// in `fixed`, and the probe width when no frame has a probe (nothing
/// would determine it).
pub(crate) fn fit_model(
    context: &Context,
    model: &Model,
    start: &[f64],
    fixed: &[bool],
    precision: Precision,
) -> Result<Fitted, DiagnoseError> {
    fit_model_from(context, model, start, fixed, precision, &[])
}

/// [`fit_model`] with the first Jacobian's whitened columns taken from
/// `start_columns` where given (one entry per parameter, or none at all),
/// as [`LevenbergMarquardt::minimize_with_columns`] does.
pub(crate) fn fit_model_from(
    context: &Context,
    model: &Model,
    start: &[f64],
    fixed: &[bool],
    precision: Precision,
    start_columns: &[Option<&[f64]>],
) -> Result<Fitted, DiagnoseError> {
    let problem = FitProblem::new(context, model, precision.near_rounds());
    let [cost_tolerance, step_tolerance, gradient_tolerance] = precision.tolerances();
    let mut fixed = fixed.to_vec();
    fixed.resize(model.len(), false);
    if !context.obs.has_probe_frames() {
        fixed[PROBE_WIDTH] = true;
    }
    let parameters = model.lsq_parameters(start, &fixed);
    let mut engine = LevenbergMarquardt::default();
    engine.options.function_tolerance = cost_tolerance;
    engine.options.step_tolerance = step_tolerance;
    engine.options.gradient_tolerance = gradient_tolerance;
    engine.options.max_evaluations = 300;
    engine.options.uncertainty = precision == Precision::Model;
    engine.options.end_at_last_jacobian = precision == Precision::Model;
    engine.options.jacobian_updates = precision.jacobian_updates();
    let report = engine.minimize_with_columns(&problem, &parameters, start_columns)?;
    let params: Vec<f64> = report.params.iter().copied().collect();
    // The fit ends at a point it evaluated.
    let (residuals, placements) = problem.evaluated_at(&params)?;
    let free = parameters.iter().filter(|p| !p.fixed).count();
    let (fit, chi2, dof) = misfit(context, &residuals, free);
    Ok(Fitted {
        params,
        report,
        fit,
        chi2,
        residuals,
        placements,
        dof,
    })
}

/// Per-channel RMS and chi-square per dof. The `free` fitted parameters
/// are charged to the channels in proportion to their sizes.
pub(crate) fn misfit(context: &Context, residuals: &[f64], free: usize) -> (Fit, f64, [f64; 2]) {
    let m = context.obs.marker_count();
    let total = residuals.len() as f64;
    let whitened = context.whitening.apply(residuals);
    let channel = |range: std::ops::Range<usize>| -> (f64, f64, f64) {
        let n = range.len() as f64;
        if range.is_empty() {
            return (f64::NAN, f64::NAN, 0.0);
        }
        let sum2: f64 = residuals[range.clone()].iter().map(|r| r * r).sum();
        let chi2: f64 = whitened[range.clone()].iter().map(|r| r * r).sum();
        let dof = (n - free as f64 * n / total).max(1.0);
        ((sum2 / n).sqrt(), chi2, dof)
    };
    let (rms_marker, chi2_m, dof_m) = channel(0..m);
    let (rms_force, chi2_f, dof_f) = channel(m..residuals.len());
    let fit = Fit {
        rms_marker,
        rms_force,
        chi2_marker: chi2_m / dof_m,
        chi2_force: chi2_f / dof_f,
    };
    let chi2 = [chi2_m, chi2_f].iter().filter(|c| c.is_finite()).sum();
    (fit, chi2, [dof_m, dof_f])
}
