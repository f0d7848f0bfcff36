//! Covariance of the estimate, standard errors, and identifiability.
//!
//! Near the optimum the cost is `½ |r(p̂) + J δ|²`, so with whitened
//! residuals the estimate is approximately Gaussian with covariance
//!
//! `C = s² (Jᵀ J)⁻¹`,
//!
//! `s² = 1` when the noise is known (residuals whitened by the true sigma)
//! or `s² = χ²/(m - n)` when only relative weights are known. `J` is the
//! Jacobian with respect to the external parameters that are free and not
//! on a bound (a parameter held by its bound has no Gaussian error).
//!
//! `Jᵀ J = Rᵀ R` is never formed: with the column-equilibrated triangular
//! factor `R E⁻¹ = U Σ Vᵀ` (E = column norms), the rank is the number of
//! singular values above `rank_tolerance · σ_max` and
//! `C = s² E⁻¹ V Σ⁻² Vᵀ E⁻¹` on the identifiable parameters. A parameter is
//! unidentifiable when the numerical null space has a component on it
//! (`Σ_null V_jk² > 1e-6`); it gets no standard error rather than an
//! infinite or arbitrary one.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Whether a parameter's error was estimated, and why not.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ParameterStatus {
    /// Free and identifiable: it has a standard error.
    Estimated,
    /// Held fixed by the caller.
    Fixed,
    /// Converged onto a bound.
    AtBound,
    /// In the numerical null space of the Jacobian: the data do not
    /// determine it (alone or in combination with others).
    Unidentifiable,
    /// Covariance scaled by `χ²/dof` was asked for with `dof = 0`.
    NoDegreesOfFreedom,
    /// Free, but the fit stopped without a Jacobian at its optimum
    /// ([`Options::uncertainty`](crate::Options::uncertainty) off).
    NotComputed,
}

/// How the covariance `(Jᵀ J)⁻¹` is scaled.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum CovarianceScaling {
    /// Residuals are whitened by the true noise: `C = (Jᵀ J)⁻¹`.
    #[default]
    KnownNoise,
    /// Only relative weights are known: `C = χ²/dof · (Jᵀ J)⁻¹`.
    ReducedChiSquare,
}

/// The uncertainty part of a [`FitReport`](crate::FitReport).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Uncertainty {
    /// Per parameter (all of them, in order): estimated or why not.
    pub status: Vec<ParameterStatus>,
    /// Per parameter: `sqrt(C_jj)` if estimated.
    pub standard_errors: Vec<Option<f64>>,
    /// Indices of the estimated parameters; the rows and columns of
    /// `covariance` and `correlation` follow this order.
    pub estimated: Vec<usize>,
    /// Covariance of the estimated parameters.
    pub covariance: DMatrix<f64>,
    /// Correlation of the estimated parameters.
    pub correlation: DMatrix<f64>,
    /// The factor `s²` applied to `(Jᵀ J)⁻¹`; `None` when `χ²/dof` was asked
    /// for without degrees of freedom.
    pub covariance_scale: Option<f64>,
    /// Numerical rank of the column-equilibrated Jacobian of the free,
    /// not-at-bound parameters.
    pub rank: usize,
    /// Number of columns analysed (free, not-at-bound parameters).
    pub columns: usize,
    /// `σ_max / σ_min` of the column-equilibrated Jacobian (infinite if a
    /// column is zero or exactly dependent; then `rank < columns`).
    pub condition_number: f64,
}

impl Uncertainty {
    /// Whether some free parameters are not determined by the data.
    pub fn is_rank_deficient(&self) -> bool {
        self.rank < self.columns
    }

    /// Indices of the unidentifiable parameters.
    pub fn unidentifiable(&self) -> Vec<usize> {
        self.indices_with(ParameterStatus::Unidentifiable)
    }

    /// No analysis: `free` parameters [`ParameterStatus::NotComputed`], the
    /// others [`ParameterStatus::Fixed`], of `total`; no covariance, rank 0
    /// of 0 columns, condition number NaN.
    pub(crate) fn not_computed(free: &[usize], total: usize) -> Self {
        let mut status = vec![ParameterStatus::Fixed; total];
        for &j in free {
            status[j] = ParameterStatus::NotComputed;
        }
        Self {
            status,
            standard_errors: vec![None; total],
            estimated: Vec::new(),
            covariance: DMatrix::zeros(0, 0),
            correlation: DMatrix::zeros(0, 0),
            covariance_scale: None,
            rank: 0,
            columns: 0,
            condition_number: f64::NAN,
        }
    }

    /// Indices of the parameters with a given status.
    pub fn indices_with(&self, status: ParameterStatus) -> Vec<usize> {
        (0..self.status.len())
            .filter(|&j| self.status[j] == status)
            .collect()
    }
}

/// Null-space weight above which a parameter counts as unidentifiable.
const NULL_SPACE_WEIGHT: f64 = 1e-6;

/// Inputs of [`estimate`], gathered at the optimum.
pub(crate) struct AtOptimum<'a> {
    /// Triangular factor of the internal Jacobian (columns = free params).
    pub r_factor: &'a DMatrix<f64>,
    /// `dp/du` of each free parameter.
    pub derivatives: &'a [f64],
    /// Index (in the full list) of each free parameter.
    pub free: &'a [usize],
    /// Whether each free parameter sits on a bound.
    pub at_bound: &'a [bool],
    /// Total number of parameters.
    pub total: usize,
    /// Degrees of freedom.
    pub dof: usize,
    /// `χ²` at the optimum.
    pub chi2: f64,
}

/// The covariance analysis described in the module doc.
pub(crate) fn estimate(
    at: &AtOptimum<'_>,
    scaling: CovarianceScaling,
    rank_tolerance: f64,
) -> Uncertainty {
    let mut status = vec![ParameterStatus::Fixed; at.total];
    let mut candidates = Vec::new();
    for (local, &global) in at.free.iter().enumerate() {
        if at.at_bound[local] {
            status[global] = ParameterStatus::AtBound;
        } else {
            candidates.push(local);
        }
    }
    let columns = candidates.len();

    // External Jacobian factor R_ext = R diag(1/(dp/du)) on the candidates,
    // padded to square so that a wide problem still yields a full V.
    let rows = at.r_factor.nrows().max(columns);
    let mut r_ext = DMatrix::zeros(rows, columns);
    for (c, &local) in candidates.iter().enumerate() {
        let column = at.r_factor.column(local) / at.derivatives[local];
        r_ext.view_mut((0, c), (column.len(), 1)).copy_from(&column);
    }
    let norms: Vec<f64> = r_ext.column_iter().map(|c| c.norm()).collect();
    let identifiable: Vec<usize> = (0..columns)
        .filter(|&c| norms[c] > 0.0 && norms[c].is_finite())
        .collect();
    for c in (0..columns).filter(|c| !identifiable.contains(c)) {
        status[at.free[candidates[c]]] = ParameterStatus::Unidentifiable;
    }

    let covariance_scale = match scaling {
        CovarianceScaling::KnownNoise => 1.0,
        CovarianceScaling::ReducedChiSquare if at.dof > 0 => at.chi2 / at.dof as f64,
        CovarianceScaling::ReducedChiSquare => {
            for &local in &candidates {
                status[at.free[local]] = ParameterStatus::NoDegreesOfFreedom;
            }
            return Uncertainty {
                standard_errors: vec![None; at.total],
                status,
                estimated: Vec::new(),
                covariance: DMatrix::zeros(0, 0),
                correlation: DMatrix::zeros(0, 0),
                covariance_scale: None,
                rank: 0,
                columns,
                condition_number: f64::INFINITY,
            };
        }
    };

    let q = identifiable.len();
    let mut equilibrated = DMatrix::zeros(rows.max(q), q);
    for (k, &c) in identifiable.iter().enumerate() {
        equilibrated
            .column_mut(k)
            .rows_mut(0, rows)
            .copy_from(&(r_ext.column(c) / norms[c]));
    }
    let (singular, v) = if q == 0 {
        (Vec::new(), DMatrix::zeros(0, 0))
    } else {
        let svd = equilibrated.svd(false, true);
        let v_t = svd.v_t.expect("V requested");
        (
            svd.singular_values.iter().copied().collect::<Vec<_>>(),
            v_t.transpose(),
        )
    };
    let sigma_max = singular.iter().copied().fold(0.0, f64::max);
    let sigma_min = singular.iter().copied().fold(f64::INFINITY, f64::min);
    let kept: Vec<usize> = (0..singular.len())
        .filter(|&i| singular[i] > rank_tolerance * sigma_max)
        .collect();
    let rank = kept.len();
    let condition_number = if columns > q || sigma_min == 0.0 {
        f64::INFINITY
    } else {
        sigma_max / sigma_min
    };

    let mut estimated_local = Vec::new();
    for k in 0..q {
        let null_weight: f64 = (0..singular.len())
            .filter(|i| !kept.contains(i))
            .map(|i| v[(k, i)] * v[(k, i)])
            .sum();
        let global = at.free[candidates[identifiable[k]]];
        if null_weight > NULL_SPACE_WEIGHT {
            status[global] = ParameterStatus::Unidentifiable;
        } else {
            status[global] = ParameterStatus::Estimated;
            estimated_local.push(k);
        }
    }

    let size = estimated_local.len();
    let mut covariance = DMatrix::zeros(size, size);
    for (a, &ka) in estimated_local.iter().enumerate() {
        for (b, &kb) in estimated_local.iter().enumerate().skip(a) {
            let pseudo_inverse: f64 = kept
                .iter()
                .map(|&i| v[(ka, i)] * v[(kb, i)] / (singular[i] * singular[i]))
                .sum();
            let value = covariance_scale * pseudo_inverse
                / (norms[identifiable[ka]] * norms[identifiable[kb]]);
            covariance[(a, b)] = value;
            covariance[(b, a)] = value;
        }
    }
    let deviations: Vec<f64> = (0..size).map(|a| covariance[(a, a)].sqrt()).collect();
    let correlation = DMatrix::from_fn(size, size, |a, b| {
        covariance[(a, b)] / (deviations[a] * deviations[b])
    });
    let estimated: Vec<usize> = estimated_local
        .iter()
        .map(|&k| at.free[candidates[identifiable[k]]])
        .collect();
    let mut standard_errors = vec![None; at.total];
    for (a, &global) in estimated.iter().enumerate() {
        standard_errors[global] = Some(deviations[a]);
    }
    Uncertainty {
        status,
        standard_errors,
        estimated,
        covariance,
        correlation,
        covariance_scale: Some(covariance_scale),
        rank,
        columns,
        condition_number,
    }
}
