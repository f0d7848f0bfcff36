//! Fit a model to all trials jointly and measure its misfit per channel.
//!
//! Residuals are model minus data, whitened by the noise covariance of
//! `whiten` (independent marker and force noise, plus each probe frame's
//! force noise carried to its markers through the unit responses).

use needle_lsq::{LevenbergMarquardt, Problem};
use serde::{Deserialize, Serialize};

use crate::error::DiagnoseError;
use crate::forward::Forward;
use crate::model::{Model, PROBE_WIDTH};
use crate::observe::Observations;
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
    /// Residuals model - data at `p`, not whitened.
    pub fn residuals(&self, model: &Model, p: &[f64]) -> Result<Vec<f64>, DiagnoseError> {
        let prediction = self.forward.predict(model, p, &self.obs)?;
        Ok(prediction
            .values
            .iter()
            .zip(&self.measured)
            .map(|(m, y)| m - y)
            .collect())
    }

    /// Whitened residuals of the model at `p`.
    pub fn whitened(&self, model: &Model, p: &[f64]) -> Result<Vec<f64>, DiagnoseError> {
        Ok(self.whitening.apply(&self.residuals(model, p)?))
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
    /// Degrees of freedom of each channel (marker, force).
    pub dof: [f64; 2],
}

pub(crate) struct FitProblem<'a> {
    pub context: &'a Context,
    pub model: &'a Model,
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
        let whitened = self.context.whitened(self.model, params)?;
        out.copy_from_slice(&whitened);
        Ok(())
    }
}

/// Relative tolerance (cost reduction, step, gradient) of the fits that
/// set the current model.
pub(crate) const MODEL_TOLERANCE: f64 = 1e-8;

/// Relative tolerance of a candidate's refit in the ranking. A refit
/// stopped early has a chi-square a little too high, so its likelihood
/// ratio is a lower bound: the ranking can only understate a candidate,
/// never name one the data do not support, and the candidate named is
/// refitted at [`MODEL_TOLERANCE`] before the next step. At 1e-5 a
/// further step would lower $\chi^2$ by less than $10^{-5}\chi^2$.
pub(crate) const CANDIDATE_TOLERANCE: f64 = 1e-5;

/// Fits `model` from `start` (its parameters' `initial` where `start` is
/// shorter) to the relative `tolerance`, holding the parameters flagged
/// in `fixed`, and the probe width when no frame has a probe (nothing
/// would determine it).
pub(crate) fn fit_model(
    context: &Context,
    model: &Model,
    start: &[f64],
    fixed: &[bool],
    tolerance: f64,
) -> Result<Fitted, DiagnoseError> {
    let problem = FitProblem { context, model };
    let mut fixed = fixed.to_vec();
    fixed.resize(model.len(), false);
    if !context.obs.has_probe_frames() {
        fixed[PROBE_WIDTH] = true;
    }
    let parameters = model.lsq_parameters(start, &fixed);
    let mut engine = LevenbergMarquardt::default();
    engine.options.function_tolerance = tolerance;
    engine.options.step_tolerance = tolerance;
    engine.options.gradient_tolerance = tolerance;
    engine.options.max_evaluations = 300;
    let report = engine.minimize(&problem, &parameters)?;
    let params: Vec<f64> = report.params.iter().copied().collect();
    let residuals = context.residuals(model, &params)?;
    let free = parameters.iter().filter(|p| !p.fixed).count();
    let (fit, chi2, dof) = misfit(context, &residuals, free);
    Ok(Fitted {
        params,
        report,
        fit,
        chi2,
        residuals,
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
