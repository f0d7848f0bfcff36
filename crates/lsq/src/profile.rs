//! Profile likelihood of one parameter.
//!
//! With whitened residuals, `χ²(p) = -2 log L(p) + const`. The profile of
//! parameter `k` is `χ²_prof(v) = min_{p: p_k = v} χ²(p)`: the fit repeated
//! with `p_k` held at each grid value `v`. By Wilks' theorem the
//! likelihood-ratio interval at level `α` is
//!
//! `{ v : χ²_prof(v) - χ²_min <= s² · χ²_{1}(α) }`,
//!
//! `χ²_{1}(0.95) = 3.8415`, `s²` the fit's covariance scale (1 for known
//! noise). Unlike the Wald interval `p̂ ± z σ` it follows the curvature of the
//! model, so it is asymmetric for nonlinear parameters; for a linear model
//! the profile is an exact parabola and both intervals coincide.

use serde::{Deserialize, Serialize};

use crate::error::LsqError;
use crate::minimize::LevenbergMarquardt;
use crate::parameter::Parameter;
use crate::problem::Problem;
use crate::quantile::chi_square_one_dof;
use crate::report::FitReport;

/// Where to put the profile grid.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum ProfileSpan {
    /// `p̂ ± k σ`, using the fit's standard error.
    StandardErrors(f64),
    /// An explicit range of values.
    Range {
        /// Smallest value.
        lower: f64,
        /// Largest value.
        upper: f64,
    },
}

/// How to profile.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfileOptions {
    /// Confidence level of the interval.
    pub level: f64,
    /// Grid points on each side of the optimum (the grid has `2 · points + 1`).
    pub points: usize,
    /// Grid extent; it is clipped to the parameter's bounds.
    pub span: ProfileSpan,
}

impl Default for ProfileOptions {
    fn default() -> Self {
        Self {
            level: 0.95,
            points: 10,
            span: ProfileSpan::StandardErrors(3.0),
        }
    }
}

/// A computed profile and its likelihood-ratio interval.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Profile {
    /// Profiled parameter's index.
    pub index: usize,
    /// Profiled parameter's name.
    pub name: String,
    /// Grid values, increasing.
    pub values: Vec<f64>,
    /// `χ²_prof` at each grid value.
    pub chi2: Vec<f64>,
    /// Smallest `χ²` seen (fit or profile).
    pub minimum_chi2: f64,
    /// The threshold `s² χ²_1(level)` on `Δχ²`.
    pub threshold: f64,
    /// Lower end of the interval (linear interpolation of the crossing);
    /// `None` if the profile stays below threshold down to the grid's end.
    pub lower: Option<f64>,
    /// Upper end of the interval, as `lower`.
    pub upper: Option<f64>,
}

impl LevenbergMarquardt {
    /// Profiles parameter `index` around the optimum `fit` (obtained with
    /// the same `problem` and `parameters`). Each grid point is a fit with
    /// the parameter held, warm-started from its neighbour nearer to the
    /// optimum.
    pub fn profile<P: Problem + ?Sized>(
        &self,
        problem: &P,
        parameters: &[Parameter],
        fit: &FitReport,
        index: usize,
        options: &ProfileOptions,
    ) -> Result<Profile, LsqError> {
        let count = parameters.len();
        let spec = parameters
            .get(index)
            .ok_or(LsqError::UnknownParameter { index, count })?;
        if spec.fixed {
            return Err(LsqError::InvalidParameter {
                name: spec.name.clone(),
                reason: "a fixed parameter cannot be profiled".into(),
            });
        }
        if fit.params.len() != count {
            return Err(LsqError::DimensionMismatch {
                what: "fit report parameters",
                expected: count,
                found: fit.params.len(),
            });
        }
        if options.points == 0 {
            return Err(LsqError::InvalidOption {
                field: "points",
                reason: "at least one point per side is needed".into(),
            });
        }
        let delta = chi_square_one_dof(options.level)?;
        let scale = fit
            .uncertainty
            .covariance_scale
            .ok_or_else(|| LsqError::NotEstimated {
                name: spec.name.clone(),
                status: crate::ParameterStatus::NoDegreesOfFreedom,
            })?;
        let centre = fit.params[index];
        let (mut lower, mut upper) = match options.span {
            ProfileSpan::StandardErrors(k) => {
                let sigma = fit
                    .standard_error(index)
                    .ok_or_else(|| LsqError::NotEstimated {
                        name: spec.name.clone(),
                        status: fit.uncertainty.status[index],
                    })?;
                (centre - k * sigma, centre + k * sigma)
            }
            ProfileSpan::Range { lower, upper } => (lower, upper),
        };
        if !(lower.is_finite()
            && upper.is_finite()
            && lower <= centre
            && centre <= upper
            && lower < upper)
        {
            return Err(LsqError::InvalidOption {
                field: "span",
                reason: format!(
                    "profile range [{lower}, {upper}] must be finite and contain the optimum {centre}"
                ),
            });
        }
        lower = spec.lower.map_or(lower, |bound| lower.max(bound));
        upper = spec.upper.map_or(upper, |bound| upper.min(bound));

        let points = options.points;
        let mut values = Vec::with_capacity(2 * points + 1);
        for i in (1..=points).rev() {
            values.push(centre + (lower - centre) * i as f64 / points as f64);
        }
        values.push(centre);
        for i in 1..=points {
            values.push(centre + (upper - centre) * i as f64 / points as f64);
        }

        let mut chi2 = vec![0.0; values.len()];
        let held = |value: f64, start: &[f64]| -> Vec<Parameter> {
            parameters
                .iter()
                .zip(start)
                .enumerate()
                .map(|(j, (parameter, &x))| {
                    let mut parameter = parameter.clone();
                    if j == index {
                        parameter.initial = value;
                        parameter.fixed = true;
                    } else if !parameter.fixed {
                        parameter.initial = x;
                    }
                    parameter
                })
                .collect()
        };
        let optimum: Vec<f64> = fit.params.iter().copied().collect();
        let mut centre_fit = optimum.clone();
        {
            let report = self.minimize(problem, &held(centre, &optimum))?;
            chi2[points] = report.chi2;
            centre_fit.copy_from_slice(report.params.as_slice());
        }
        for side in [-1isize, 1] {
            let mut start = centre_fit.clone();
            for step in 1..=points as isize {
                let slot = (points as isize + side * step) as usize;
                let report = self.minimize(problem, &held(values[slot], &start))?;
                chi2[slot] = report.chi2;
                start.copy_from_slice(report.params.as_slice());
            }
        }

        let minimum_chi2 = chi2.iter().copied().fold(fit.chi2, f64::min);
        let threshold = scale * delta;
        let level = minimum_chi2 + threshold;
        let crossing = |inner: usize, outer: usize| {
            let (a, b) = (chi2[inner], chi2[outer]);
            values[inner] + (values[outer] - values[inner]) * (level - a) / (b - a)
        };
        let lower_end = (0..points)
            .rev()
            .find(|&i| chi2[i] > level && chi2[i + 1] <= level)
            .map(|i| crossing(i + 1, i));
        let upper_end = (points + 1..values.len())
            .find(|&i| chi2[i] > level && chi2[i - 1] <= level)
            .map(|i| crossing(i - 1, i));
        Ok(Profile {
            index,
            name: spec.name.clone(),
            values,
            chi2,
            minimum_chi2,
            threshold,
            lower: lower_end,
            upper: upper_end,
        })
    }
}
