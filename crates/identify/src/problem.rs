//! The least-squares problems handed to the `needle-lsq` engine: equation
//! (5) itself (whitened), a single trial's modulus with the displacement
//! pattern held, and the drift line of the per-trial moduli.

use std::sync::Mutex;

use nalgebra::DMatrix;
use needle_fem::material::Materials;
use needle_lsq::{EvaluationError, Problem};

use crate::fe::Response;
use crate::model::ProbeModel;
use crate::observe::Observations;

/// Equation (5) with whitened residuals
/// $r_i = w_i\,(d_i - [P\,K(\theta)^{-1} b(a)\,f]_i)$ and the analytic
/// Jacobian $\partial r_i/\partial\theta_p = -w_i\,[P\,\partial U/\partial\theta_p\,f]_i$
/// (the width's column by a difference of the load, see
/// [`ProbeModel::width_sensitivity`]).
///
/// Parameters: `tied`: $(E, \nu, a)$ with one modulus for every region;
/// otherwise $(E_0, \dots, E_{R-1}, \nu, a)$. The contact width $a$ is
/// always the last; held (its column left zero) unless `width_free`.
pub(crate) struct ProbeProblem<'a> {
    model: &'a ProbeModel,
    observations: &'a Observations,
    tied: bool,
    width_free: bool,
    /// The unit-load response at the last residual point, reused by the
    /// Jacobian at the same point (the engine asks for both in turn).
    last: Mutex<Option<(Vec<f64>, Response)>>,
}

impl<'a> ProbeProblem<'a> {
    pub fn new(
        model: &'a ProbeModel,
        observations: &'a Observations,
        tied: bool,
        width_free: bool,
    ) -> Self {
        Self {
            model,
            observations,
            tied,
            width_free,
            last: Mutex::new(None),
        }
    }

    /// Materials for the parameter vector.
    pub fn materials(&self, params: &[f64]) -> Result<Materials, EvaluationError> {
        let nu = params[params.len() - 2];
        let regions = self.model.region_count();
        let pairs: Vec<(f64, f64)> = (0..regions)
            .map(|r| (if self.tied { params[0] } else { params[r] }, nu))
            .collect();
        Ok(Materials::from_parameters(&pairs)?)
    }

    fn response(&self, params: &[f64]) -> Result<Response, EvaluationError> {
        let cached = self.last.lock().map_err(|_| "cache poisoned")?.take();
        match cached {
            Some((at, response)) if at == params => Ok(response),
            _ => Ok(self
                .model
                .respond(&self.materials(params)?, width(params))?),
        }
    }
}

/// The contact width of a parameter vector.
fn width(params: &[f64]) -> f64 {
    params[params.len() - 1]
}

impl Problem for ProbeProblem<'_> {
    fn num_parameters(&self) -> usize {
        if self.tied {
            3
        } else {
            self.model.region_count() + 2
        }
    }

    fn num_residuals(&self) -> usize {
        self.observations.rows.len()
    }

    fn residuals(&self, params: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        let response = self
            .model
            .respond(&self.materials(params)?, width(params))?;
        for (r, row) in out.iter_mut().zip(&self.observations.rows) {
            *r = row.weight * (row.value - self.observations.predict(row, &response.markers));
        }
        *self.last.lock().map_err(|_| "cache poisoned")? = Some((params.to_vec(), response));
        Ok(())
    }

    fn jacobian(
        &self,
        params: &[f64],
        out: &mut DMatrix<f64>,
    ) -> Option<Result<(), EvaluationError>> {
        Some((|| {
            let response = self.response(params)?;
            let materials = self.materials(params)?;
            let mut sensitivities = self.model.sensitivities(&materials, &response, self.tied)?;
            if self.width_free {
                sensitivities.push(self.model.width_sensitivity(&materials, width(params))?);
            }
            out.fill(0.0);
            for (j, derivative) in sensitivities.iter().enumerate() {
                for (i, row) in self.observations.rows.iter().enumerate() {
                    out[(i, j)] = -row.weight * self.observations.predict(row, derivative);
                }
            }
            *self.last.lock().map_err(|_| "cache poisoned")? = Some((params.to_vec(), response));
            Ok(())
        })())
    }
}

/// One trial's modulus with Poisson's ratio held: the prediction is the
/// held pattern $g$ (computed at modulus $E_\text{ref}$) scaled by
/// $E_\text{ref}/E$, so $r_i = w_i (d_i - E_\text{ref} g_i / E)$.
pub(crate) struct ScaleProblem {
    /// `(weight, measured, pattern)` per row.
    pub rows: Vec<(f64, f64, f64)>,
    /// The modulus at which the pattern was computed.
    pub reference: f64,
}

impl Problem for ScaleProblem {
    fn num_parameters(&self) -> usize {
        1
    }

    fn num_residuals(&self) -> usize {
        self.rows.len()
    }

    fn residuals(&self, params: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        let scale = self.reference / params[0];
        for (r, &(w, d, g)) in out.iter_mut().zip(&self.rows) {
            *r = w * (d - scale * g);
        }
        Ok(())
    }

    fn jacobian(
        &self,
        params: &[f64],
        out: &mut DMatrix<f64>,
    ) -> Option<Result<(), EvaluationError>> {
        let factor = self.reference / (params[0] * params[0]);
        for (i, &(w, _, g)) in self.rows.iter().enumerate() {
            out[(i, 0)] = w * factor * g;
        }
        Some(Ok(()))
    }
}

/// The drift line $E(t) = a + b\,(t - t_\text{ref})$ through the per-trial
/// moduli, each weighted by its standard error.
pub(crate) struct LineProblem {
    /// `(day - reference day, modulus, standard error)` per trial.
    pub points: Vec<(f64, f64, f64)>,
}

impl Problem for LineProblem {
    fn num_parameters(&self) -> usize {
        2
    }

    fn num_residuals(&self) -> usize {
        self.points.len()
    }

    fn residuals(&self, params: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        for (r, &(t, e, se)) in out.iter_mut().zip(&self.points) {
            *r = (e - params[0] - params[1] * t) / se;
        }
        Ok(())
    }

    fn jacobian(
        &self,
        _params: &[f64],
        out: &mut DMatrix<f64>,
    ) -> Option<Result<(), EvaluationError>> {
        for (i, &(t, _, se)) in self.points.iter().enumerate() {
            out[(i, 0)] = -1.0 / se;
            out[(i, 1)] = -t / se;
        }
        Some(Ok(()))
    }
}
